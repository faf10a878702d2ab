//! One shape for every part that lives on the bus, and one loop that runs it.
//!
//! The node, the controller, the simulated robot, a training-set capture and a recorder all do
//! the same four things: they say which frames they read, take them one at a time, act when
//! time passes, and send frames. A [`Component`] is that shape, with a lifecycle in the
//! spirit of a robot task (made from its config, started when its bus opens, stopped once):
//!
//! - [`Component::filters`]: what it reads, as kernel filters, so that a process which
//!   does not read the tactile stream (about 2,600 frames/s per foot) never wakes for it;
//! - [`Component::start`]: its bus opened, the first time or again after an error;
//! - [`Component::on_frame`]: one received frame;
//! - [`Component::tick`]: time passed;
//! - [`Component::on_health`]: the CAN controller's error state changed;
//! - [`Component::stop`]: the run ends (a signal, or [`Component::done`]).
//!
//! It writes what it sends into an [`Outbox`]; it never touches the bus. That keeps it free of
//! I/O, so a test drives it frame by frame on a clock it sets, and so the same component runs
//! on `can0`, on `vcan0` in CI and on an [`InProcBus`](crate::bus::InProcBus).
//!
//! [`LockStep`] runs several components on one simulated clock in one thread (the demo,
//! tests, experiments). [`run`] is the loop every process uses: it opens the bus with retry and backoff, sets the
//! filters, receives, ticks on the robot's clock (wall time times a scale, for a simulator
//! slower than real time), sends, keeps a recording tap, reopens the bus after an error
//! (never exiting for one) and stops on a flag.
//!
//! ```
//! use std::sync::atomic::AtomicBool;
//! use presrs_protocol::bus::{BusSource, CanBus, InProcBus};
//! use presrs_protocol::component::{Component, Outbox, RunOptions, run};
//! use presrs_protocol::{CanFrame, Stamped};
//!
//! /// Answers every frame with id 0x100 by the same data on 0x101, and stops after three.
//! struct Echo(usize);
//! impl Component for Echo {
//!     fn name(&self) -> &'static str { "echo" }
//!     fn filters(&self) -> Vec<(u32, u32)> { vec![(0x100, 0x7ff)] }
//!     fn on_frame(&mut self, st: &Stamped, _now_us: u64, out: &mut Outbox) {
//!         if let Some(f) = CanFrame::classic(embedded_can::StandardId::new(0x101).unwrap(), st.frame.data()) { out.push(f); }
//!         self.0 += 1;
//!     }
//!     fn tick(&mut self, _now_us: u64, _out: &mut Outbox) {}
//!     fn done(&self) -> bool { self.0 == 3 }
//! }
//!
//! let bus = InProcBus::new();
//! let mut peer = bus.endpoint();
//! let feeder = std::thread::spawn(move || {
//!     for i in 0..3u8 {
//!         std::thread::sleep(std::time::Duration::from_millis(20));
//!         peer.send(&CanFrame::classic(embedded_can::StandardId::new(0x100).unwrap(), &[i]).unwrap()).unwrap();
//!     }
//!     peer
//! });
//! let mut echo = Echo(0);
//! let stats = run(&mut echo, &BusSource::InProc(bus), &RunOptions::default(), &AtomicBool::new(false));
//! let mut peer = feeder.join().unwrap();
//! assert_eq!((stats.received, stats.sent), (3, 3));
//! let back = peer.recv(std::time::Duration::from_secs(1)).unwrap().unwrap();
//! assert_eq!(back.frame.raw_id(), 0x101);
//! ```

mod lockstep;
mod options;
mod run;
mod serve;
mod signals;
mod threaded;
mod wake;

pub use lockstep::LockStep;
pub use options::{DRAIN_QUIET, RunOptions};
pub use run::{RunStats, run, run_opened};
pub use signals::{SignalError, Signals};
pub use threaded::{Link, LinkStats, Threaded, spawn, spawn_one};
pub use wake::{COALESCE_US, POLL_AFTER_US, POLL_LEAD_US, PRE_WAKE_US};

use crate::bus::ControllerState;
use crate::frame::{CanFrame, Stamped};

/// The frames a component sends, collected during one call and sent by the runner after it.
/// Its buffer is kept between calls: sending allocates nothing once it has grown to the
/// largest burst.
#[derive(Debug, Default)]
pub struct Outbox {
    frames: Vec<CanFrame>,
}

impl Outbox {
    /// An outbox with room for `n` frames before it grows.
    pub fn with_capacity(n: usize) -> Self {
        Self {
            frames: Vec::with_capacity(n),
        }
    }

    /// Queues a frame to send.
    pub fn push(&mut self, frame: CanFrame) {
        self.frames.push(frame);
    }

    /// True when nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Takes the frames queued, oldest first.
    pub fn drain(&mut self) -> std::vec::Drain<'_, CanFrame> {
        self.frames.drain(..)
    }
}

/// A component's frames go where every part's output goes: a segmenter writes an image's
/// frames straight into it.
impl crate::emit::Emit<CanFrame> for Outbox {
    fn emit(&mut self, frame: CanFrame) {
        self.push(frame)
    }
}

/// A part that lives on the bus. See the [module docs](self).
///
/// Times are robot time in microseconds, from the runner's clock ([`run`]: wall time since
/// the run began, times [`RunOptions::time_scale`], or [`RunOptions::clock`]); a test or a
/// lock-step loop passes its own.
pub trait Component {
    /// A short name for logs: "node", "controller", "sim", "capture", "record".
    fn name(&self) -> &'static str;

    /// The frames it reads, as `(id, mask)` kernel filters; empty: every frame.
    fn filters(&self) -> Vec<(u32, u32)>;

    /// Its bus opened at `now_us`: the first time, or again after an error (a component that
    /// judges silence, such as a heartbeat watch, does not count the time the bus was down).
    fn start(&mut self, now_us: u64, out: &mut Outbox) {
        let _ = (now_us, out);
    }

    /// One frame received (and passed by [`Component::filters`]).
    fn on_frame(&mut self, frame: &Stamped, now_us: u64, out: &mut Outbox);

    /// Time passed: it is now `now_us`. Called at least every [`RunOptions::tick`] of wall
    /// time, and after every burst of frames.
    fn tick(&mut self, now_us: u64, out: &mut Outbox);

    /// The CAN controller under its bus handle changed state (error-passive, bus-off, back to
    /// active). The runner logs the change with its fix and keeps it in
    /// [`LinkStats::controller`]; a component reports it on the bus.
    fn on_health(&mut self, state: ControllerState, now_us: u64) {
        let _ = (state, now_us);
    }

    /// The run ends; frames written here are sent if the bus is open (a last status).
    fn stop(&mut self, now_us: u64, out: &mut Outbox) {
        let _ = (now_us, out);
    }

    /// True for a frame of a kind this component is the one sender of. Such a frame comes
    /// back through a second handle of the same process (SocketCAN loops every frame to every
    /// other socket); a recording keeps it once, as sent.
    fn is_own(&self, frame: &CanFrame) -> bool {
        let _ = frame;
        false
    }

    /// When (µs on the runner's clock) a frame is due that this component answers at once,
    /// or `None`: the node's next image that decides a step. [`run`] wakes [`PRE_WAKE_US`]
    /// before it, calls [`Component::warm_up`] and polls the bus from [`POLL_LEAD_US`] before
    /// it until a frame comes (for at most [`POLL_AFTER_US`] past the time), instead of being
    /// woken by the frame: a thread woken from sleep started 40-90 µs after the frame, with its
    /// data out of cache (docs/decisions/node-wake.md). The time is when the frame is expected,
    /// not the earliest it can come: measured, where the frames come from elsewhere. Until
    /// [`PRE_WAKE_US`] before it, no frame needs an instant answer: `run` takes them in
    /// batches ([`COALESCE_US`]); `u64::MAX` says so with no frame due. `None`: any frame may
    /// need an instant answer (each wakes the runner).
    fn expected_frame_us(&self) -> Option<u64> {
        None
    }

    /// The expected frame ([`Component::expected_frame_us`]) is near: bring what answering it
    /// reads into cache. Must not change what the component decides.
    fn warm_up(&mut self) {}

    /// True when it has finished on its own (a simulation of a set duration, a capture whose
    /// disk failed): the runner stops it.
    fn done(&self) -> bool {
        false
    }
}
