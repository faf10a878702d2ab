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

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::bus::{
    Backoff, BusHealth, BusSource, CanBus, HealthWatch, InProcBus, InProcEndpoint, Tap,
    after_bus_error, open_with_retry,
};
use crate::clock::{Clock, ManualClock};
use crate::error::BusError;
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

    /// The frames queued so far.
    pub fn frames(&self) -> &[CanFrame] {
        &self.frames
    }

    /// Takes the frames queued, oldest first.
    pub fn drain(&mut self) -> std::vec::Drain<'_, CanFrame> {
        self.frames.drain(..)
    }

    /// Nothing queued.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
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
    /// active). The runner logs the change with its fix; a component reports it on the bus.
    fn on_health(&mut self, health: &BusHealth, now_us: u64) {
        let _ = (health, now_us);
    }

    /// The run ends; frames written here are sent if the bus is open (a last status).
    fn stop(&mut self, now_us: u64, out: &mut Outbox) {
        let _ = (now_us, out);
    }

    /// True when it has finished on its own (a simulation of a set duration, a capture whose
    /// disk failed): the runner stops it.
    fn done(&self) -> bool {
        false
    }
}

/// How [`run`] drives a component.
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
}

impl Default for RunOptions {
    fn default() -> Self {
        Self {
            time_scale: 1.0,
            tick: Duration::from_millis(1),
            max_burst: 256,
            tap: None,
            clock: None,
        }
    }
}

/// What one [`run`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RunStats {
    /// Frames received and given to the component.
    pub received: u64,
    /// Frames sent.
    pub sent: u64,
    /// Frames the bus refused (a full queue), dropped and counted.
    pub send_errors: u64,
    /// Times the bus was reopened after an error.
    pub reopens: u64,
    /// Robot time when the run ended, µs.
    pub end_us: u64,
}

/// Runs `component` on `source` until `stop` is set or the component is [`Component::done`].
///
/// A bus that fails to open, fails to receive, or goes down while sending is reopened with
/// backoff, and the component is started again; a frame the bus refuses for a full queue is
/// dropped and counted (waiting for room would stall every other frame). Returns what it did.
pub fn run(
    component: &mut dyn Component,
    source: &BusSource,
    opts: &RunOptions,
    stop: &AtomicBool,
) -> RunStats {
    run_opened(component, None, source, opts, stop)
}

/// [`run`] on a handle the caller opened already: so that a process fails at once on an
/// interface name that does not exist, or is listening before it starts the thread that runs
/// the component (no early frame missed). Reopened from `source` after an error, as in [`run`].
pub fn run_opened(
    component: &mut dyn Component,
    mut opened: Option<Box<dyn CanBus>>,
    source: &BusSource,
    opts: &RunOptions,
    stop: &AtomicBool,
) -> RunStats {
    let start = Instant::now();
    let scale = opts.time_scale;
    let clock = opts.clock.clone();
    let now_us = || match &clock {
        Some(c) => c.now_us(),
        None => (start.elapsed().as_secs_f64() * scale * 1e6) as u64,
    };
    let stopping = || stop.load(Ordering::Relaxed);
    let name = component.name();
    let iface = source.label().to_string();
    let mut out = Outbox::with_capacity(64);
    let mut stats = RunStats::default();
    let mut backoff = Backoff::default();
    let mut watch = HealthWatch::default();
    let filters = component.filters();
    let mut bus: Option<Box<dyn CanBus>> = None;
    'open: while !stopping() && !component.done() {
        bus = None;
        let Some(mut b) = opened
            .take()
            .or_else(|| open_with_retry(source, stop, name, &mut || {}))
        else {
            break;
        };
        if let Err(e) = b.set_filters(&filters) {
            // Unfiltered, a component that does not read the tactile stream falls behind it.
            after_bus_error(name, &e, &mut backoff, stop);
            stats.reopens += 1;
            continue 'open;
        }
        backoff.reset();
        component.start(now_us(), &mut out);
        if let Err(e) = flush(&mut out, b.as_mut(), opts, &mut stats, now_us(), name) {
            after_bus_error(name, &e, &mut backoff, stop);
            stats.reopens += 1;
            continue 'open;
        }
        let mut next_tick = Instant::now();
        while !stopping() && !component.done() {
            // Everything queued (up to a burst), then the tick: a burst never waits one tick
            // per frame, and a stream never holds the tick back.
            let mut wait = next_tick.saturating_duration_since(Instant::now());
            for _ in 0..opts.max_burst.max(1) {
                match b.recv(wait) {
                    Ok(Some(st)) => {
                        stats.received += 1;
                        if let Some(t) = &opts.tap {
                            t.offer(&st);
                        }
                        component.on_frame(&st, now_us(), &mut out);
                        wait = Duration::ZERO;
                    }
                    Ok(None) => break,
                    Err(e) => {
                        after_bus_error(name, &e, &mut backoff, stop);
                        stats.reopens += 1;
                        continue 'open;
                    }
                }
            }
            let now = now_us();
            let health = b.health();
            if watch.update(name, &iface, &health).is_some() {
                component.on_health(&health, now);
            }
            if Instant::now() >= next_tick {
                component.tick(now, &mut out);
                next_tick = Instant::now() + opts.tick;
            }
            if let Err(e) = flush(&mut out, b.as_mut(), opts, &mut stats, now, name) {
                after_bus_error(name, &e, &mut backoff, stop);
                stats.reopens += 1;
                continue 'open;
            }
        }
        bus = Some(b);
        break;
    }
    let end = now_us();
    component.stop(end, &mut out);
    match bus.as_mut() {
        Some(b) => {
            let _ = flush(&mut out, b.as_mut(), opts, &mut stats, end, name);
        }
        None => out.drain().for_each(drop),
    }
    stats.end_us = end;
    stats
}

/// Sends what the component wrote. A refused frame is dropped and counted; a bus that is down
/// is the caller's to reopen (the frames not yet sent are dropped with it: stale by then).
fn flush(
    out: &mut Outbox,
    bus: &mut dyn CanBus,
    opts: &RunOptions,
    stats: &mut RunStats,
    now_us: u64,
    name: &str,
) -> Result<(), BusError> {
    let mut down = None;
    for f in out.drain() {
        if down.is_some() {
            continue;
        }
        match bus.send(&f) {
            Ok(()) => {
                stats.sent += 1;
                if let Some(t) = &opts.tap {
                    t.offer(&Stamped {
                        t_us: now_us,
                        frame: f,
                    });
                }
            }
            Err(e @ (BusError::Down { .. } | BusError::Closed)) => down = Some(e),
            Err(e) => {
                stats.send_errors += 1;
                if stats.send_errors.is_power_of_two() {
                    tracing::warn!(
                        role = name,
                        "send: {e} ({} send errors so far)",
                        stats.send_errors
                    );
                }
            }
        }
    }
    down.map_or(Ok(()), Err)
}

/// Every component on one simulated clock, on one in-process bus: the demo's, the tests' and
/// the experiments' loop. Each [`LockStep::step`] sets the clock and gives each part, in a
/// fixed order, the frames queued for it and then its tick; what a part sends is on the bus
/// before the next part's turn. A run is the same on every machine for a seed, as fast as the
/// machine goes, and the parts talk only through frames, as they do as processes on vcan.
pub struct LockStep {
    clock: ManualClock,
    bus: InProcBus,
    endpoints: Vec<InProcEndpoint>,
    out: Outbox,
    t_us: u64,
    link_up: bool,
}

impl LockStep {
    /// A bus for `parts` parts (part `i` is the `i`-th of [`LockStep::step`]'s slice), each
    /// with a queue of `depth` frames, the clock at 0.
    pub fn new(parts: usize, depth: usize) -> Self {
        let clock = ManualClock::new(0);
        let bus = InProcBus::with_clock(Arc::new(clock.clone()), depth);
        let endpoints = (0..parts).map(|_| bus.endpoint()).collect();
        Self {
            clock,
            bus,
            endpoints,
            out: Outbox::with_capacity(256),
            t_us: 0,
            link_up: true,
        }
    }

    /// The simulated time, µs.
    pub fn now_us(&self) -> u64 {
        self.t_us
    }

    /// Part `i` (re)starts: its filters are set, frames queued for it are dropped (a new
    /// process hears only what comes after it), and it is [`Component::start`]ed now.
    pub fn start(
        &mut self,
        i: usize,
        part: &mut dyn Component,
        sent: &mut dyn FnMut(u64, &CanFrame),
    ) -> Result<(), BusError> {
        let Some(ep) = self.endpoints.get_mut(i) else {
            return Ok(());
        };
        ep.set_filters(&part.filters())?;
        while ep.recv(Duration::ZERO)?.is_some() {}
        part.start(self.t_us, &mut self.out);
        self.send(i, sent)
    }

    /// While the link is down every frame sent is lost, as on an interface that is down (the
    /// observer of [`LockStep::step`] still sees it: the sender did send it).
    pub fn set_link(&mut self, up: bool) {
        self.link_up = up;
    }

    /// Moves the clock to `t_us` and runs each part in order: its frames, then its tick. A
    /// part that is `None` (a process killed) loses what was queued for it. `sent` sees every
    /// frame sent, with the time.
    pub fn step(
        &mut self,
        t_us: u64,
        parts: &mut [Option<&mut dyn Component>],
        sent: &mut dyn FnMut(u64, &CanFrame),
    ) -> Result<(), BusError> {
        self.t_us = t_us;
        self.clock.set_us(t_us);
        for (i, part) in parts.iter_mut().enumerate() {
            let Some(ep) = self.endpoints.get_mut(i) else {
                break;
            };
            match part {
                None => while ep.recv(Duration::ZERO)?.is_some() {},
                Some(p) => {
                    while let Some(st) = ep.recv(Duration::ZERO)? {
                        p.on_frame(&st, t_us, &mut self.out);
                    }
                    p.tick(t_us, &mut self.out);
                    self.send(i, sent)?;
                }
            }
        }
        Ok(())
    }

    fn send(&mut self, i: usize, sent: &mut dyn FnMut(u64, &CanFrame)) -> Result<(), BusError> {
        let (t, up) = (self.t_us, self.link_up);
        let ep = &mut self.endpoints[i];
        for f in self.out.drain() {
            sent(t, &f);
            if up {
                ep.send(&f)?;
            }
        }
        Ok(())
    }

    /// Frames dropped because a part's queue was full.
    pub fn overruns(&self) -> u64 {
        self.bus.overruns()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::InProcBus;

    /// Counts what the runner does to it; sends one frame per tick with the tick count.
    #[derive(Default)]
    struct Probe {
        starts: Vec<u64>,
        frames: Vec<u8>,
        ticks: u64,
        stopped: bool,
        until_frames: usize,
    }

    impl Component for Probe {
        fn name(&self) -> &'static str {
            "probe"
        }
        fn filters(&self) -> Vec<(u32, u32)> {
            vec![(0x200, 0x7ff)]
        }
        fn start(&mut self, now_us: u64, _: &mut Outbox) {
            self.starts.push(now_us);
        }
        fn on_frame(&mut self, st: &Stamped, _: u64, _: &mut Outbox) {
            self.frames.push(st.frame.data()[0]);
        }
        fn tick(&mut self, _: u64, out: &mut Outbox) {
            self.ticks += 1;
            if let Some(f) = CanFrame::classic(std_id(0x300), &self.ticks.to_le_bytes()) {
                out.push(f);
            }
        }
        fn stop(&mut self, _: u64, _: &mut Outbox) {
            self.stopped = true;
        }
        fn done(&self) -> bool {
            self.frames.len() >= self.until_frames
        }
    }

    fn std_id(id: u16) -> embedded_can::StandardId {
        embedded_can::StandardId::new(id).unwrap()
    }

    fn send(peer: &mut impl CanBus, id: u16, b: u8) {
        peer.send(&CanFrame::classic(std_id(id), &[b]).unwrap())
            .unwrap();
    }

    #[test]
    fn filters_ticks_sends_and_stops_when_done() {
        let bus = InProcBus::new();
        let mut peer = bus.endpoint();
        let mut probe = Probe {
            until_frames: 2,
            ..Probe::default()
        };
        let feeder = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(30));
            // Not ours: filtered out in the "kernel".
            send(&mut peer, 0x201, 9);
            send(&mut peer, 0x200, 1);
            std::thread::sleep(Duration::from_millis(30));
            send(&mut peer, 0x200, 2);
            let mut ticks = 0;
            while let Ok(Some(_)) = peer.recv(Duration::from_millis(100)) {
                ticks += 1;
            }
            ticks
        });
        let stats = run(
            &mut probe,
            &BusSource::InProc(bus),
            &RunOptions::default(),
            &AtomicBool::new(false),
        );
        let heard = feeder.join().unwrap();
        assert_eq!(probe.frames, vec![1, 2]);
        assert_eq!(probe.starts.len(), 1);
        assert!(probe.stopped);
        // 60 ms at a 1 ms tick: dozens of ticks, each one frame the peer heard.
        assert!(probe.ticks >= 20, "{}", probe.ticks);
        assert_eq!(stats.sent, probe.ticks);
        assert_eq!(heard, probe.ticks);
        assert_eq!(stats.received, 2);
    }

    #[test]
    fn a_link_that_goes_down_is_reopened_and_the_component_started_again() {
        let bus = InProcBus::new();
        let mut peer = bus.endpoint();
        let mut probe = Probe {
            until_frames: 2,
            ..Probe::default()
        };
        let b2 = bus.clone();
        let feeder = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            send(&mut peer, 0x200, 1);
            std::thread::sleep(Duration::from_millis(20));
            b2.set_link(false);
            assert!(
                peer.send(&CanFrame::classic(std_id(0x200), &[7]).unwrap())
                    .is_err()
            );
            std::thread::sleep(Duration::from_millis(150));
            b2.set_link(true);
            // The runner reopens after its 100 ms backoff; the frame comes after that.
            std::thread::sleep(Duration::from_millis(300));
            let mut peer = b2.endpoint();
            send(&mut peer, 0x200, 2);
        });
        let stats = run(
            &mut probe,
            &BusSource::InProc(bus),
            &RunOptions::default(),
            &AtomicBool::new(false),
        );
        feeder.join().unwrap();
        assert_eq!(probe.frames, vec![1, 2]);
        assert_eq!(probe.starts.len(), 2, "started again after the reopen");
        assert!(stats.reopens >= 1);
        assert!(probe.starts[1] >= probe.starts[0] + 150_000);
    }

    #[test]
    fn a_stop_flag_ends_the_run_and_the_robot_clock_follows_the_scale() {
        let bus = InProcBus::new();
        let stop = Arc::new(AtomicBool::new(false));
        let s2 = stop.clone();
        let stopper = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(100));
            s2.store(true, Ordering::Relaxed);
        });
        let mut probe = Probe {
            until_frames: usize::MAX,
            ..Probe::default()
        };
        let opts = RunOptions {
            time_scale: 0.5,
            ..RunOptions::default()
        };
        let t = Instant::now();
        let stats = run(&mut probe, &BusSource::InProc(bus), &opts, &stop);
        let wall_us = t.elapsed().as_micros() as u64;
        stopper.join().unwrap();
        assert!(probe.stopped);
        // At least 100 ms of wall time at half speed: half of it in robot time.
        assert!(stats.end_us >= 50_000, "{}", stats.end_us);
        assert!(
            stats.end_us <= wall_us / 2 + 1,
            "{} {wall_us}",
            stats.end_us
        );
    }
}
