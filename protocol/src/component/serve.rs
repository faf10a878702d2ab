//! One opened bus served by [`run_with`](super::run::run_with): each pass takes a burst of
//! frames (or polls for the one the component expects), then the bus's health, then the tick;
//! after a stop, what is still queued. The runner around it opens, filters and reopens.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::options::{DRAIN_QUIET, RunOptions};
use super::wake::{COALESCE_US, Plan, Wake};
use super::{Component, LinkStats, Outbox};
use crate::bus::{CanBus, HealthWatch};
use crate::error::BusError;
use crate::frame::Stamped;

/// What [`serve`] needs of its run: the options, the link's counters, the names its logs and
/// health reports use, the stop flag and the run's clock.
pub(super) struct Served<'a> {
    pub(super) opts: &'a RunOptions,
    pub(super) link: &'a LinkStats,
    pub(super) name: &'a str,
    pub(super) iface: &'a str,
    pub(super) stop: &'a AtomicBool,
    pub(super) now_us: &'a dyn Fn() -> u64,
    pub(super) scale: f64,
}

/// One opened bus served until the run stops or the component is done (`Ok`), or until the
/// bus fails (the error: [`run_with`] reopens it). Each pass takes a burst of frames (or
/// polls for the one the component expects), then the bus's health, then the tick.
pub(super) fn serve<C: Component + ?Sized>(
    component: &mut C,
    b: &mut dyn CanBus,
    c: &Served<'_>,
    out: &mut Outbox,
    watch: &mut HealthWatch,
    between: &mut dyn FnMut(&mut C),
) -> Result<(), BusError> {
    let mut next_tick = Instant::now();
    let mut wake = Wake::default();
    // The last burst took `max_burst` frames: more may be queued.
    let mut backlog = false;
    // Error frames of this handle already in `bus_errors`.
    let mut counted = 0u64;
    while !c.stop.load(Ordering::Relaxed) && !component.done() {
        between(component);
        // Everything queued (up to a burst), then the tick: a burst never waits one tick
        // per frame, and a stream never holds the tick back.
        let tick_wait = match c.opts.idle_wait {
            // Ticks come after frames; with none, after `idle_wait`.
            Some(idle) => (next_tick + idle).saturating_duration_since(Instant::now()),
            None => next_tick.saturating_duration_since(Instant::now()),
        };
        let Waiting {
            mut wait,
            poll_until,
            woken_for,
            coalesce,
        } = waiting(component, &mut wake, tick_wait, c.now_us, c.scale);
        // Not while frames are left from the last batch: a stream faster than a burst per
        // batch (classic frames on vcan, which has no bit rate) would fall behind.
        if coalesce && !backlog && !wait.is_zero() {
            std::thread::sleep(wait.min(Duration::from_micros(COALESCE_US)));
            wait = Duration::ZERO;
        }
        let mut taken = 0;
        while taken < c.opts.max_burst.max(1) {
            match b.recv(wait) {
                Ok(Some(st)) => {
                    taken += 1;
                    deliver(component, &st, c.opts, c.link, (c.now_us)(), out);
                    wait = Duration::ZERO;
                    // An answer goes out at once, not after the rest of the burst.
                    if !out.is_empty()
                        && let Err(e) = flush(out, b, c.opts, c.link, (c.now_us)(), c.name)
                    {
                        return Err(e);
                    }
                }
                // Polling for the expected frame (a tick waits for the poll: at most
                // POLL_LEAD_US plus the oversleep plus POLL_AFTER_US). A yield, not a spin:
                // a spin kept a sender on the core from running (node-wake.md), and on a
                // robot the controller shares the core.
                Ok(None) if taken == 0 && poll_until.is_some_and(|u| Instant::now() < u) => {
                    std::thread::yield_now();
                }
                Ok(None) => {
                    // A sleep before a poll that ran out: how late did it end?
                    if taken == 0
                        && let Some(until) = woken_for
                    {
                        wake.slept(until, (c.now_us)());
                    }
                    break;
                }
                Err(e) => {
                    return Err(e);
                }
            }
        }
        backlog = taken >= c.opts.max_burst.max(1);
        let now = (c.now_us)();
        let health = b.health();
        if health.error_frames != counted {
            LinkStats::add(
                &c.link.bus_errors,
                health.error_frames.saturating_sub(counted),
            );
            counted = health.error_frames;
        }
        if let Some(state) = watch.update(c.name, c.iface, &health) {
            c.link.set_controller(state);
            component.on_health(state, now);
        }
        if Instant::now() >= next_tick {
            component.tick(now, out);
            next_tick = Instant::now() + c.opts.tick;
        }
        flush(out, b, c.opts, c.link, now, c.name)?;
    }
    Ok(())
}

/// After a stop, the frames still queued (until `limit`, or a quiet gap of `DRAIN_QUIET`).
pub(super) fn drain<C: Component + ?Sized>(
    component: &mut C,
    b: &mut dyn CanBus,
    limit: Duration,
    opts: &RunOptions,
    link: &LinkStats,
    now_us: &dyn Fn() -> u64,
    out: &mut Outbox,
) {
    let until = Instant::now() + limit;
    loop {
        let left = until.saturating_duration_since(Instant::now());
        let Ok(Some(st)) = b.recv(DRAIN_QUIET.min(left)) else {
            break;
        };
        deliver(component, &st, opts, link, now_us(), out);
        if left.is_zero() {
            break;
        }
    }
}

/// How one pass of [`run_with`]'s loop waits before it takes frames.
struct Waiting {
    /// The first receive's timeout.
    wait: Duration,
    /// Polling for the expected frame until then.
    poll_until: Option<Instant>,
    /// A sleep planned to end at this time (runner's clock, µs), to measure the oversleep.
    woken_for: Option<u64>,
    /// Sleep in a batch first, without watching the bus.
    coalesce: bool,
}

/// The tick's `wait`, shortened where a frame to answer at once is due
/// ([`Component::expected_frame_us`]): the plan says whether to sleep in batches, warm up,
/// sleep to the poll, or poll (`wake.rs`). Warms the component up when that is due.
fn waiting<C: Component + ?Sized>(
    component: &mut C,
    wake: &mut Wake,
    wait: Duration,
    now_us: &dyn Fn() -> u64,
    scale: f64,
) -> Waiting {
    let mut w = Waiting {
        wait,
        poll_until: None,
        woken_for: None,
        coalesce: false,
    };
    let Some(at) = component.expected_frame_us() else {
        return w;
    };
    if wake.warm_up_due(at, now_us()) {
        component.warm_up();
    }
    let wall = |us: u64| Duration::from_secs_f64(us as f64 / scale.max(1e-9) * 1e-6);
    match wake.plan(at, now_us()) {
        Plan::Batch { for_us } => {
            w.wait = w.wait.min(wall(for_us));
            w.coalesce = true;
        }
        Plan::Sleep { for_us, until_us } => {
            if wall(for_us) <= w.wait {
                w.woken_for = Some(until_us);
            }
            w.wait = w.wait.min(wall(for_us));
        }
        Plan::Poll { for_us } => {
            w.poll_until = Some(Instant::now() + wall(for_us));
            w.wait = Duration::ZERO;
        }
        Plan::AsUsual => {}
    }
    w
}

/// One received frame: counted, copied to the tap (unless the component's own), handed over.
fn deliver<C: Component + ?Sized>(
    component: &mut C,
    st: &Stamped,
    opts: &RunOptions,
    link: &LinkStats,
    now_us: u64,
    out: &mut Outbox,
) {
    LinkStats::add(&link.rx_frames, 1);
    if let Some(t) = &opts.tap
        && !component.is_own(&st.frame)
    {
        t.offer(st);
    }
    component.on_frame(st, now_us, out);
}

/// Sends what the component wrote. A refused frame is dropped and counted; a bus that is down
/// is the caller's to reopen (the frames not yet sent are dropped with it: stale by then).
pub(super) fn flush(
    out: &mut Outbox,
    bus: &mut dyn CanBus,
    opts: &RunOptions,
    link: &LinkStats,
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
                LinkStats::add(&link.tx_frames, 1);
                if let Some(t) = &opts.tap {
                    t.offer(&Stamped {
                        t_us: now_us,
                        frame: f,
                    });
                }
            }
            Err(e @ (BusError::Down { .. } | BusError::Closed)) => down = Some(e),
            Err(e) => {
                let dropped = LinkStats::add(&link.tx_dropped, 1);
                if dropped.is_power_of_two() {
                    tracing::warn!(role = name, "send: {e} ({dropped} send errors so far)");
                }
            }
        }
    }
    down.map_or(Ok(()), Err)
}
