//! How a component is driven: its clock, tick, burst, tap and drain, shared by the runner that
//! opens the bus (`run`) and the loop that serves it (`serve`).

use std::sync::Arc;
use std::time::Duration;

use super::LinkStats;
use crate::bus::Tap;
use crate::clock::Clock;

/// How [`run`](super::run) drives a component.
#[derive(Clone)]
pub struct RunOptions {
    /// Robot time per wall time: 1 on a robot; a simulator's `--speed` when the robot's time
    /// runs slower than the wall's (under emulation).
    pub time_scale: f64,
    /// The longest wall time between two ticks.
    pub tick: Duration,
    /// The most frames taken in one go before the component is ticked, so a stream it reads
    /// cannot hold its clock back.
    pub max_burst: usize,
    /// Keeps a copy of every frame received and sent (a recorder's queue).
    pub tap: Option<Arc<dyn Tap>>,
    /// The component's clock, when it is not the default (wall time since the run began,
    /// times `time_scale`): the node reads the bus's ([`BusSource::clock`]), so that its
    /// deadlines compare with the frames' receive times; a test passes a
    /// [`ManualClock`](crate::clock::ManualClock).
    pub clock: Option<Arc<dyn Clock>>,
    /// Counts frames in and out, errors and the link's state, for a status the component
    /// reports or a watcher reads.
    pub link: Option<Arc<LinkStats>>,
    /// After the stop, go on reading what reached the socket, until it has been quiet for
    /// [`DRAIN_QUIET`] or for at most this long: for a recorder beside a process that stops
    /// it when done, whose last frames are otherwise in the socket and lost to the recording
    /// (docs/decisions/figures-behind-comments.md, drain-after-stop).
    /// `None` (the default): the run ends at the stop.
    pub drain_on_stop: Option<Duration>,
    /// Without frames, wake to tick only after this long, not every `tick`: a component whose
    /// frames come often (the node: a tactile stream per foot) ticks after them, at `tick`
    /// grain, and an idle wait does not wake it a thousand times a second. `None`: every `tick`.
    pub idle_wait: Option<Duration>,
}

/// How long a socket must stay quiet for a drain ([`RunOptions::drain_on_stop`]) to end.
pub const DRAIN_QUIET: Duration = Duration::from_millis(20);

impl Default for RunOptions {
    fn default() -> Self {
        Self {
            time_scale: 1.0,
            tick: Duration::from_millis(1),
            max_burst: 256,
            tap: None,
            clock: None,
            link: None,
            drain_on_stop: None,
            idle_wait: None,
        }
    }
}
