//! The loop every process runs a component with: [`run`].

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::options::RunOptions;
use super::serve::{Served, drain, flush, serve};
use super::{Component, Link, LinkStats, Outbox};
use crate::bus::{Backoff, BusSource, CanBus, HealthWatch, after_bus_error, open_with_retry};
use crate::error::BusError;

/// What one [`run`] did (the frame counts are its share of [`LinkStats`]).
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
    opened: Option<Box<dyn CanBus>>,
    source: &BusSource,
    opts: &RunOptions,
    stop: &AtomicBool,
) -> RunStats {
    run_with(component, opened, source, opts, stop, &mut |_| {})
}

/// [`run_opened`], calling `between` with the component before each burst of frames is taken
/// (the one-thread [`spawn_one`](super::spawn_one) runs its callers' work there).
pub(crate) fn run_with<C: Component + ?Sized>(
    component: &mut C,
    mut opened: Option<Box<dyn CanBus>>,
    source: &BusSource,
    opts: &RunOptions,
    stop: &AtomicBool,
    between: &mut dyn FnMut(&mut C),
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
    let link = opts.link.clone().unwrap_or_default();
    // The run's counts are the link's, from here on (a caller's link may count from before).
    let load = |c: &std::sync::atomic::AtomicU64| c.load(Ordering::Relaxed);
    let (rx0, tx0, dropped0) = (
        load(&link.rx_frames),
        load(&link.tx_frames),
        load(&link.tx_dropped),
    );
    let failed = |e: &BusError, backoff: &mut Backoff, stats: &mut RunStats| {
        LinkStats::add(&link.bus_errors, 1);
        link.set_link(Link::Failing);
        after_bus_error(name, e, backoff, stop);
        stats.reopens += 1;
    };
    let mut bus: Option<Box<dyn CanBus>> = None;
    'open: while !stopping() && !component.done() {
        bus = None;
        let Some(mut b) = opened
            .take()
            .or_else(|| open_with_retry(source, stop, name, &mut || link.set_link(Link::Failing)))
        else {
            break;
        };
        if let Err(e) = b.set_filters(&filters) {
            // Unfiltered, a component that does not read the tactile stream falls behind it.
            failed(&e, &mut backoff, &mut stats);
            continue 'open;
        }
        backoff.reset();
        link.set_link(Link::Open);
        component.start(now_us(), &mut out);
        if let Err(e) = flush(&mut out, b.as_mut(), opts, &link, now_us(), name) {
            failed(&e, &mut backoff, &mut stats);
            continue 'open;
        }
        let served = serve(
            component,
            b.as_mut(),
            &Served {
                opts,
                link: &link,
                name,
                iface: &iface,
                stop,
                now_us: &now_us,
                scale,
            },
            &mut out,
            &mut watch,
            between,
        );
        if let Err(e) = served {
            failed(&e, &mut backoff, &mut stats);
            continue 'open;
        }
        if let Some(limit) = opts.drain_on_stop {
            drain(component, b.as_mut(), limit, opts, &link, &now_us, &mut out);
        }
        bus = Some(b);
        break;
    }
    let end = now_us();
    component.stop(end, &mut out);
    match bus.as_mut() {
        Some(b) => {
            let _ = flush(&mut out, b.as_mut(), opts, &link, end, name);
        }
        None => out.drain().for_each(drop),
    }
    stats.received = load(&link.rx_frames) - rx0;
    stats.sent = load(&link.tx_frames) - tx0;
    stats.send_errors = load(&link.tx_dropped) - dropped0;
    stats.end_us = end;
    stats
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CanFrame;
    use crate::bus::InProcBus;
    use crate::component::Component;
    use crate::frame::Stamped;
    use std::sync::Arc;
    use std::time::Duration;

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
        // 60 ms at a 1 ms tick: dozens of ticks on an idle machine, each one frame the peer
        // heard. With both cores busy (a CI run beside it) 12 came, so the bound asks only for
        // ticks that repeat; that each one is sent and heard is what is checked.
        assert!(probe.ticks >= 5, "{}", probe.ticks);
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

    /// Expects one frame at `at` µs on the run's clock; records what happened, in order.
    struct Expects {
        at: u64,
        events: Vec<&'static str>,
        cpu_us: u64,
    }

    impl Component for Expects {
        fn name(&self) -> &'static str {
            "expects"
        }
        fn filters(&self) -> Vec<(u32, u32)> {
            Vec::new()
        }
        fn on_frame(&mut self, _: &Stamped, _: u64, _: &mut Outbox) {
            self.events.push("frame");
        }
        fn tick(&mut self, _: u64, _: &mut Outbox) {}
        fn expected_frame_us(&self) -> Option<u64> {
            (!self.events.contains(&"frame")).then_some(self.at)
        }
        fn warm_up(&mut self) {
            self.events.push("warm-up");
        }
    }

    fn expects(
        clock: Arc<dyn crate::clock::Clock>,
        at_us: u64,
        send_at_ms: Option<u64>,
        run_ms: u64,
    ) -> Expects {
        let bus = InProcBus::new();
        let mut peer = bus.endpoint();
        let mut c = Expects {
            at: at_us,
            events: Vec::new(),
            cpu_us: 0,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let stopper = stop.clone();
        let feeder = std::thread::spawn(move || {
            if let Some(ms) = send_at_ms {
                std::thread::sleep(Duration::from_millis(ms));
                send(&mut peer, 0x200, 1);
            }
            std::thread::sleep(Duration::from_millis(run_ms - send_at_ms.unwrap_or(0)));
            stopper.store(true, Ordering::Relaxed);
        });
        let opts = RunOptions {
            clock: Some(clock),
            // Without the expectation, the runner would sleep through it.
            idle_wait: Some(Duration::from_millis(200)),
            ..RunOptions::default()
        };
        let cpu0 = thread_cpu_us();
        run(&mut c, &BusSource::InProc(bus), &opts, &stop);
        c.cpu_us = thread_cpu_us() - cpu0;
        feeder.join().unwrap();
        c
    }

    fn thread_cpu_us() -> u64 {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `ts` is a valid timespec for the call to fill.
        unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
        ts.tv_sec as u64 * 1_000_000 + ts.tv_nsec as u64 / 1000
    }

    #[test]
    fn an_expected_frame_is_warmed_up_for_once_before_it_comes() {
        // The run's clock stands 300 us before the expected time (between the warm-up and the
        // poll): on a machine however loaded, the runner warms up, then waits for the frame.
        let at = 1_000_000;
        let c = expects(
            Arc::new(crate::clock::ManualClock::new(at - 300)),
            at,
            Some(30),
            60,
        );
        assert_eq!(c.events, ["warm-up", "frame"]);
        // Earlier than PRE_WAKE_US before the time: no warm-up yet.
        let c = expects(
            Arc::new(crate::clock::ManualClock::new(
                at - crate::component::PRE_WAKE_US - 100,
            )),
            at,
            Some(30),
            60,
        );
        assert_eq!(c.events, ["frame"]);
    }

    /// Takes frames while it says none is due for an instant answer (`u64::MAX`), noting when
    /// each came to it.
    struct Batched {
        taken: Vec<(u8, Instant)>,
        batch: bool,
    }

    impl Component for Batched {
        fn name(&self) -> &'static str {
            "batched"
        }
        fn filters(&self) -> Vec<(u32, u32)> {
            Vec::new()
        }
        fn on_frame(&mut self, st: &Stamped, _: u64, _: &mut Outbox) {
            self.taken.push((st.frame.data()[0], Instant::now()));
        }
        fn tick(&mut self, _: u64, _: &mut Outbox) {}
        fn expected_frame_us(&self) -> Option<u64> {
            self.batch.then_some(u64::MAX)
        }
    }

    /// How many groups the frames came to the component in (a group: within 150 us).
    fn batches(batch: bool) -> (Vec<u8>, usize) {
        let bus = InProcBus::new();
        let mut peer = bus.endpoint();
        let mut c = Batched {
            taken: Vec::new(),
            batch,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let stopper = stop.clone();
        let feeder = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            for b in 0..20 {
                send(&mut peer, 0x200, b);
                std::thread::sleep(Duration::from_micros(500));
            }
            std::thread::sleep(Duration::from_millis(30));
            stopper.store(true, Ordering::Relaxed);
        });
        let opts = RunOptions {
            idle_wait: Some(Duration::from_millis(200)),
            ..RunOptions::default()
        };
        run(&mut c, &BusSource::InProc(bus), &opts, &stop);
        feeder.join().unwrap();
        let groups = 1 + c
            .taken
            .windows(2)
            .filter(|w| w[1].1 - w[0].1 > Duration::from_micros(150))
            .count();
        (c.taken.iter().map(|t| t.0).collect(), groups)
    }

    #[test]
    fn frames_none_of_which_is_due_are_taken_in_batches_and_none_is_lost() {
        // Twenty frames 0.5 ms apart: a runner woken by each takes them one by one (a loaded
        // machine can only make fewer groups); in COALESCE_US batches, about three groups.
        let (got, groups) = batches(true);
        assert_eq!(got, (0..20).collect::<Vec<u8>>());
        assert!(groups <= 8, "{groups} groups");
    }

    #[test]
    fn a_batch_that_fills_the_burst_is_followed_at_once_not_after_another_sleep() {
        // Forty frames at once, four a burst: ten bursts back to back (under a millisecond);
        // a sleep between them would take ten batches (36 ms or more).
        let bus = InProcBus::new();
        let mut peer = bus.endpoint();
        let mut c = Batched {
            taken: Vec::new(),
            batch: true,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let stopper = stop.clone();
        let feeder = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            for b in 0..40 {
                send(&mut peer, 0x200, b);
            }
            std::thread::sleep(Duration::from_millis(80));
            stopper.store(true, Ordering::Relaxed);
        });
        let opts = RunOptions {
            idle_wait: Some(Duration::from_millis(200)),
            max_burst: 4,
            ..RunOptions::default()
        };
        run(&mut c, &BusSource::InProc(bus), &opts, &stop);
        feeder.join().unwrap();
        assert_eq!(c.taken.len(), 40);
        let span = c.taken[39].1 - c.taken[0].1;
        assert!(span < Duration::from_millis(20), "{span:?}");
    }

    #[test]
    fn a_frame_that_does_not_come_is_polled_for_a_bounded_time_then_slept_through() {
        // (A thread woken later than the poll's end on a loaded machine skips the warm-up.)
        let c = expects(
            Arc::new(crate::clock::MonotonicClock::new()),
            20_000,
            None,
            120,
        );
        assert!(c.events.len() <= 1 && !c.events.contains(&"frame"));
        // The runner's thread polled for at most POLL_LEAD_US, its oversleep and POLL_AFTER_US
        // (650 us) and slept the rest of the 120 ms: polling on would have taken about 100 ms of CPU.
        assert!(c.cpu_us < 30_000, "{} us of CPU", c.cpu_us);
    }

    /// Stops the run (its flag) on its first frame.
    struct StopsAtFirst {
        frames: Vec<u8>,
        stop: Arc<AtomicBool>,
    }

    impl Component for StopsAtFirst {
        fn name(&self) -> &'static str {
            "stops-at-first"
        }
        fn filters(&self) -> Vec<(u32, u32)> {
            Vec::new()
        }
        fn on_frame(&mut self, st: &Stamped, _: u64, _: &mut Outbox) {
            self.frames.push(st.frame.data()[0]);
            self.stop.store(true, Ordering::Relaxed);
        }
        fn tick(&mut self, _: u64, _: &mut Outbox) {}
    }

    #[test]
    fn a_drain_reads_what_reached_the_socket_before_the_stop() {
        for (drain, want) in [(None, 1), (Some(Duration::from_millis(500)), 10)] {
            let bus = InProcBus::new();
            let mut peer = bus.endpoint();
            let stop = Arc::new(AtomicBool::new(false));
            let mut c = StopsAtFirst {
                frames: Vec::new(),
                stop: stop.clone(),
            };
            let feeder = std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(30));
                for i in 0..10 {
                    send(&mut peer, 0x200, i);
                }
            });
            let opts = RunOptions {
                max_burst: 1,
                drain_on_stop: drain,
                ..RunOptions::default()
            };
            let stats = run(&mut c, &BusSource::InProc(bus), &opts, &stop);
            feeder.join().unwrap();
            assert_eq!(c.frames.len(), want, "{drain:?}: {:?}", c.frames);
            assert_eq!(stats.received, want as u64);
        }
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
