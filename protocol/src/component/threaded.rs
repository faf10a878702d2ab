//! A component on threads of its own: [`spawn`] (three: receive, the component, send) or
//! [`spawn_one`] (one).
//!
//! The node runs this way. Its receive thread only reads the socket into a queue, so that
//! while the component classifies one foot's image (a millisecond or more) the socket's
//! buffer does not overflow with the other feet's tactile streams; its send thread only
//! writes, so that a bus that pushes back never stalls a decision. `presrs lab bench-node --feet
//! 6` measures what this buys. The component itself sees the same calls as under [`run`]
//! (frames, ticks, health, stop) on its own thread.
//!
//! [`run`]: super::run

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError, bounded};

use super::{Component, Outbox, RunOptions};
use crate::bus::{
    Backoff, BusSource, ControllerState, HealthWatch, after_bus_error, open_with_retry,
};
use crate::frame::{CanFrame, Stamped};

/// The state of a runner's bus handles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Link {
    /// Not opened yet.
    Starting = 0,
    /// Open and working.
    Open = 1,
    /// A handle failed to open, receive or send: being reopened with backoff.
    Failing = 2,
}

/// What a runner's bus threads count, shared lock-free with the component (a status message
/// reports it) and with whoever watches the process.
#[derive(Debug, Default)]
pub struct LinkStats {
    /// Frames read from the bus.
    pub rx_frames: AtomicU64,
    /// Frames read but dropped because the component's thread was behind.
    pub rx_dropped: AtomicU64,
    /// Frames written to the bus.
    pub tx_frames: AtomicU64,
    /// Frames not sent: the send queue was full, or the bus refused them.
    pub tx_dropped: AtomicU64,
    /// Errors on receive or send, and error frames from the CAN controller.
    pub bus_errors: AtomicU64,
    link: AtomicU8,
    controller: AtomicU8,
}

impl LinkStats {
    /// The state of the bus handles.
    pub fn link(&self) -> Link {
        match self.link.load(Ordering::Relaxed) {
            1 => Link::Open,
            2 => Link::Failing,
            _ => Link::Starting,
        }
    }

    /// Sets the state of the bus handles.
    pub fn set_link(&self, l: Link) {
        self.link.store(l as u8, Ordering::Relaxed);
    }

    /// The CAN controller's error state, as its error frames last said.
    pub fn controller(&self) -> ControllerState {
        match self.controller.load(Ordering::Relaxed) {
            c if c == ControllerState::BusOff as u8 => ControllerState::BusOff,
            c if c == ControllerState::Passive as u8 => ControllerState::Passive,
            c if c == ControllerState::Warning as u8 => ControllerState::Warning,
            _ => ControllerState::Active,
        }
    }

    pub(crate) fn set_controller(&self, c: ControllerState) {
        self.controller.store(c as u8, Ordering::Relaxed);
    }

    /// Adds `n` to `counter`; returns its new value.
    pub(crate) fn add(counter: &AtomicU64, n: u64) -> u64 {
        counter.fetch_add(n, Ordering::Relaxed) + n
    }
}

/// Work handed to the component's thread, run between two frames (a model reload).
type Call<C> = Box<dyn FnOnce(&mut C) + Send>;

/// A component running on its threads ([`spawn`]).
pub struct Threaded<C> {
    stop: Arc<AtomicBool>,
    calls: Sender<Call<C>>,
    component: Option<JoinHandle<C>>,
    io: Vec<(&'static str, JoinHandle<()>)>,
}

impl<C> Threaded<C> {
    /// Runs `f` on the component's thread between two frames. False when it has stopped.
    pub fn call(&self, f: impl FnOnce(&mut C) + Send + 'static) -> bool {
        self.calls.send(Box::new(f)).is_ok()
    }

    /// True while every thread runs.
    pub fn is_running(&self) -> bool {
        self.component.as_ref().is_some_and(|h| !h.is_finished())
            && self.io.iter().all(|(_, h)| !h.is_finished())
    }

    /// Stops it ([`Component::stop`] runs and what it sends goes out), joins the threads and
    /// gives the component back (`None` if its thread panicked).
    pub fn stop(mut self) -> Option<C> {
        self.stop.store(true, Ordering::Relaxed);
        let c = self.component.take().and_then(|h| h.join().ok());
        for (name, h) in self.io.drain(..) {
            if h.join().is_err() {
                tracing::error!(thread = name, "thread panicked");
            }
        }
        c
    }
}

impl<C> Drop for Threaded<C> {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// How long the component's thread waits for a frame before it looks at its clock anyway.
const IDLE_WAIT: Duration = Duration::from_millis(20);

/// Runs `component` on `source` on three threads (receive, the component, send) until
/// [`Threaded::stop`]. `queue` frames may wait between the receive thread and the
/// component; more are dropped and counted ([`LinkStats::rx_dropped`]). `opts.tick` is the
/// shortest time between ticks (checked after each frame, and every 20 ms without one);
/// `opts.link` gets the counters. Handles are opened (and reopened) on the threads, with
/// backoff.
pub fn spawn<C: Component + Send + 'static>(
    mut component: C,
    source: BusSource,
    opts: RunOptions,
    queue: usize,
) -> std::io::Result<Threaded<C>> {
    let stop = Arc::new(AtomicBool::new(false));
    let link = opts.link.clone().unwrap_or_default();
    link.set_link(Link::Starting);
    let (rx_tx, rx_rx) = bounded::<Stamped>(queue.max(1));
    let (out_tx, out_rx) = bounded::<CanFrame>(256);
    let (calls_tx, calls_rx) = bounded::<Call<C>>(4);
    let filters = component.filters();
    let name = component.name();
    let spawn = |n: &str| std::thread::Builder::new().name(n.into());
    let mut io = Vec::new();
    let stopper = |io: Vec<(&'static str, JoinHandle<()>)>, stop: &AtomicBool| {
        stop.store(true, Ordering::Relaxed);
        for (_, h) in io {
            let _ = h.join();
        }
    };
    {
        let (source, stop, link) = (source.clone(), stop.clone(), link.clone());
        let h = spawn("receive")
            .spawn(move || receive_loop(&source, &filters, &stop, &link, name, rx_tx))?;
        io.push(("receive", h));
    }
    let comp = {
        let (stop, link, opts) = (stop.clone(), link.clone(), opts.clone());
        let clock = opts.clock.clone();
        spawn(name).spawn(move || {
            let start = Instant::now();
            let now_us = || match &clock {
                Some(c) => c.now_us(),
                None => (start.elapsed().as_secs_f64() * opts.time_scale * 1e6) as u64,
            };
            component_loop(
                &mut component,
                &now_us,
                &stop,
                &link,
                &opts,
                rx_rx,
                calls_rx,
                out_tx,
            );
            component
        })
    };
    let comp = match comp {
        Ok(h) => h,
        Err(e) => {
            stopper(io, &stop);
            return Err(e);
        }
    };
    {
        let (st, link) = (stop.clone(), link.clone());
        match spawn("send").spawn(move || send_loop(&source, &st, &link, name, out_rx)) {
            Ok(h) => io.push(("send", h)),
            Err(e) => {
                stop.store(true, Ordering::Relaxed);
                let _ = comp.join();
                stopper(io, &stop);
                return Err(e);
            }
        }
    }
    Ok(Threaded {
        stop,
        calls: calls_tx,
        component: Some(comp),
        io,
    })
}

/// Runs `component` on `source` on one thread until [`Threaded::stop`]: [`run`](super::run)'s
/// loop (receive a burst, tick, send, reopen after an error), with [`Threaded::call`]'s work run
/// between two bursts. No hand-off between threads: a frame is read, decided on and answered
/// by the thread it woke. What it costs against [`spawn`]'s three threads:
/// docs/decisions/node-threads.md.
pub fn spawn_one<C: Component + Send + 'static>(
    mut component: C,
    source: BusSource,
    opts: RunOptions,
) -> std::io::Result<Threaded<C>> {
    let stop = Arc::new(AtomicBool::new(false));
    let (calls_tx, calls_rx) = bounded::<Call<C>>(4);
    let name = component.name();
    let handle = {
        let stop = stop.clone();
        std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                super::run::run_with(&mut component, None, &source, &opts, &stop, &mut |c| {
                    while let Ok(f) = calls_rx.try_recv() {
                        f(c);
                    }
                });
                component
            })?
    };
    Ok(Threaded {
        stop,
        calls: calls_tx,
        component: Some(handle),
        io: Vec::new(),
    })
}

fn receive_loop(
    source: &BusSource,
    filters: &[(u32, u32)],
    stop: &AtomicBool,
    link: &LinkStats,
    name: &str,
    to_component: Sender<Stamped>,
) {
    let mut backoff = Backoff::default();
    let failing = &mut || link.set_link(Link::Failing);
    let mut watch = HealthWatch::default();
    while !stop.load(Ordering::Relaxed) {
        let Some(mut rx) = open_with_retry(source, stop, "receive", failing) else {
            break;
        };
        if let Err(e) = rx.set_filters(filters) {
            link.set_link(Link::Failing);
            if !after_bus_error("receive", &e, &mut backoff, stop) {
                return;
            }
            continue;
        }
        backoff.reset();
        link.set_link(Link::Open);
        // Error frames of this handle already in `bus_errors`.
        let mut counted = 0u64;
        while !stop.load(Ordering::Relaxed) {
            let got = rx.recv(Duration::from_millis(20));
            let h = rx.health();
            if h.error_frames != counted {
                LinkStats::add(&link.bus_errors, h.error_frames.saturating_sub(counted));
                counted = h.error_frames;
            }
            if let Some(state) = watch.update(name, source.label(), &h) {
                link.set_controller(state);
            }
            match got {
                Ok(Some(st)) => {
                    LinkStats::add(&link.rx_frames, 1);
                    match to_component.try_send(st) {
                        Ok(()) => {}
                        Err(TrySendError::Full(_)) => {
                            LinkStats::add(&link.rx_dropped, 1);
                        }
                        Err(TrySendError::Disconnected(_)) => return,
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    LinkStats::add(&link.bus_errors, 1);
                    link.set_link(Link::Failing);
                    if !after_bus_error("receive", &e, &mut backoff, stop) {
                        return;
                    }
                    break;
                }
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn component_loop<C: Component>(
    c: &mut C,
    now_us: &dyn Fn() -> u64,
    stop: &AtomicBool,
    link: &LinkStats,
    opts: &RunOptions,
    from_receive: Receiver<Stamped>,
    calls: Receiver<Call<C>>,
    to_send: Sender<CanFrame>,
) {
    let mut out = Outbox::with_capacity(64);
    let tick_us = opts.tick.as_micros() as u64;
    let mut next_tick_us = 0u64;
    let mut seen = link.controller();
    let send = |out: &mut Outbox, t_us: u64| {
        for f in out.drain() {
            if let Some(tap) = &opts.tap {
                tap.offer(&Stamped { t_us, frame: f });
            }
            if to_send.try_send(f).is_err() {
                LinkStats::add(&link.tx_dropped, 1);
            }
        }
    };
    c.start(now_us(), &mut out);
    send(&mut out, now_us());
    let mut t_out = 0;
    loop {
        while let Ok(f) = calls.try_recv() {
            f(c);
        }
        match from_receive.recv_timeout(IDLE_WAIT) {
            Ok(st) => {
                // A frame this component sent comes back through the receive handle
                // (SocketCAN loops it to every other socket): the tap has it as sent.
                if let Some(tap) = &opts.tap
                    && !c.is_own(&st.frame)
                {
                    tap.offer(&st);
                }
                c.on_frame(&st, now_us(), &mut out);
                send(&mut out, st.t_us);
                t_out = st.t_us;
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                if !stop.load(Ordering::Relaxed) {
                    // The receive thread ended by itself: say so, then stop like a signal.
                    tracing::error!("the receive thread has exited; stopping");
                }
                break;
            }
        }
        if stop.load(Ordering::Relaxed) || c.done() {
            break;
        }
        let health = link.controller();
        if health != seen {
            seen = health;
            c.on_health(health, now_us());
        }
        // Ticks at most once per `tick` of its clock, not per frame (about 20,000 frames/s
        // for six feet): deadlines and heartbeats need no finer grain. A clock that jumped
        // back (a new bus clock) ticks at once.
        let now = now_us();
        if now >= next_tick_us || now + 1_000_000 < next_tick_us {
            next_tick_us = now + tick_us;
            c.tick(now, &mut out);
            send(&mut out, now);
            t_out = now;
        }
    }
    c.stop(t_out, &mut out);
    send(&mut out, t_out);
}

fn send_loop(
    source: &BusSource,
    stop: &AtomicBool,
    link: &LinkStats,
    name: &str,
    from_component: Receiver<CanFrame>,
) {
    let mut backoff = Backoff::default();
    let failing = &mut || link.set_link(Link::Failing);
    // Runs until the component has stopped and its last frames (a final status) are out.
    'open: loop {
        let Some(mut tx) = open_with_retry(source, stop, "send", failing) else {
            break;
        };
        backoff.reset();
        loop {
            let f = match from_component.recv_timeout(Duration::from_millis(50)) {
                Ok(f) => f,
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => break 'open,
            };
            match tx.send(&f) {
                Ok(()) => {
                    LinkStats::add(&link.tx_frames, 1);
                }
                Err(e) => {
                    LinkStats::add(&link.bus_errors, 1);
                    LinkStats::add(&link.tx_dropped, 1);
                    link.set_link(Link::Failing);
                    if !after_bus_error(name, &e, &mut backoff, stop) {
                        break 'open;
                    }
                    continue 'open;
                }
            }
        }
    }
}
