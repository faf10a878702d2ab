//! An in-process broadcast bus between threads.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};

use super::{BusHealth, CanBus, ErrorClasses, passes};
use crate::clock::{Clock, MonotonicClock};
use crate::error::BusError;
use crate::frame::{CanFrame, Stamped};

struct Member {
    id: u64,
    tx: Sender<Stamped>,
}

struct Shared {
    members: Mutex<Vec<Member>>,
    next_id: AtomicU64,
    /// Frames an endpoint could not take because its queue was full (like a socket overrun).
    overruns: AtomicU64,
    clock: Arc<dyn Clock>,
    depth: usize,
    /// Error frames reported on the bus ([`InProcBus::report_error`]), in order, with their
    /// count for a lock-free check per receive.
    errors: Mutex<Vec<(u64, ErrorClasses)>>,
    n_errors: AtomicU64,
    /// False while the link is down ([`InProcBus::set_link`]).
    up: AtomicBool,
}

/// A broadcast bus: every endpoint receives what every other endpoint sends. Each endpoint has a
/// bounded receive queue (like a socket's receive buffer); a frame that finds it full is dropped
/// for that endpoint and counted in [`InProcBus::overruns`], so a slow reader never stalls a sender.
#[derive(Clone)]
pub struct InProcBus {
    shared: Arc<Shared>,
}

impl InProcBus {
    /// A bus stamped by the process's monotonic clock, 4096 frames of queue per endpoint.
    pub fn new() -> Self {
        Self::with_clock(Arc::new(MonotonicClock::new()), 4096)
    }

    /// A bus whose receive timestamps come from `clock` (a `ManualClock` in tests).
    pub fn with_clock(clock: Arc<dyn Clock>, depth: usize) -> Self {
        Self {
            shared: Arc::new(Shared {
                members: Mutex::new(Vec::new()),
                next_id: AtomicU64::new(0),
                overruns: AtomicU64::new(0),
                clock,
                depth,
                errors: Mutex::new(Vec::new()),
                n_errors: AtomicU64::new(0),
                up: AtomicBool::new(true),
            }),
        }
    }

    /// The clock that stamps the bus's frames.
    pub fn clock(&self) -> Arc<dyn Clock> {
        self.shared.clock.clone()
    }

    /// A new endpoint on the bus.
    pub fn endpoint(&self) -> InProcEndpoint {
        let (tx, rx) = bounded(self.shared.depth);
        let id = self.shared.next_id.fetch_add(1, Ordering::Relaxed);
        if let Ok(mut m) = self.shared.members.lock() {
            m.push(Member { id, tx });
        }
        InProcEndpoint {
            bus: self.clone(),
            id,
            rx,
            filters: Vec::new(),
            errors_seen: 0,
            health: BusHealth::default(),
        }
    }

    /// Every endpoint hears an error frame of `classes` now, as sockets with an error mask
    /// hear the CAN controller's (for tests and fault drills: a bus-off without hardware).
    pub fn report_error(&self, classes: ErrorClasses) {
        let s = &self.shared;
        if let Ok(mut e) = s.errors.lock() {
            e.push((s.clock.now_us(), classes));
            s.n_errors.store(e.len() as u64, Ordering::Release);
        }
    }

    /// Takes the link down or brings it up, as `ip link set vcan0 down|up` does: while it is
    /// down every endpoint's send and receive, and every open, fail with [`BusError::Down`],
    /// and nothing sent before is delivered after (for tests and fault drills).
    pub fn set_link(&self, up: bool) {
        self.shared.up.store(up, Ordering::Release);
    }

    /// Whether the link is up.
    pub fn link_up(&self) -> bool {
        self.shared.up.load(Ordering::Acquire)
    }

    pub(crate) fn down_error() -> BusError {
        BusError::Down {
            iface: "inproc".into(),
            source: std::io::ErrorKind::NotConnected.into(),
        }
    }

    /// Frames dropped because a receiver's queue was full.
    pub fn overruns(&self) -> u64 {
        self.shared.overruns.load(Ordering::Relaxed)
    }
}

impl Default for InProcBus {
    fn default() -> Self {
        Self::new()
    }
}

/// One endpoint of an [`InProcBus`].
pub struct InProcEndpoint {
    bus: InProcBus,
    id: u64,
    rx: Receiver<Stamped>,
    filters: Vec<(u32, u32)>,
    errors_seen: usize,
    health: BusHealth,
}

impl InProcEndpoint {
    fn take_errors(&mut self) {
        let s = &self.bus.shared;
        if s.n_errors.load(Ordering::Acquire) as usize == self.errors_seen {
            return;
        }
        if let Ok(e) = s.errors.lock() {
            for (t, c) in &e[self.errors_seen..] {
                self.health.on_error_frame(c, *t);
            }
            self.errors_seen = e.len();
        }
    }
}

impl Drop for InProcEndpoint {
    fn drop(&mut self) {
        if let Ok(mut m) = self.bus.shared.members.lock() {
            m.retain(|x| x.id != self.id);
        }
    }
}

impl CanBus for InProcEndpoint {
    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
        let s = &self.bus.shared;
        if !self.bus.link_up() {
            return Err(InProcBus::down_error());
        }
        let st = Stamped {
            t_us: s.clock.now_us(),
            frame: *frame,
        };
        let members = s.members.lock().map_err(|_| BusError::Closed)?;
        for m in members.iter().filter(|m| m.id != self.id) {
            if let Err(TrySendError::Full(_)) = m.tx.try_send(st) {
                s.overruns.fetch_add(1, Ordering::Relaxed);
            }
        }
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Stamped>, BusError> {
        let deadline = std::time::Instant::now() + timeout;
        self.take_errors();
        if !self.bus.link_up() {
            // What a socket on a downed interface does: its queue is gone.
            while self.rx.try_recv().is_ok() {}
            return Err(InProcBus::down_error());
        }
        loop {
            // A poll (no timeout) only looks: crossbeam's timed receive spins and yields the
            // CPU several times before it gives up, even for a deadline already past, and a
            // runner polls after every frame of a burst (docs/decisions/node-threads.md).
            let got = if timeout.is_zero() {
                self.rx.try_recv().ok()
            } else {
                self.rx.recv_deadline(deadline).ok()
            };
            match got {
                Some(st) if passes(&self.filters, &st.frame) => {
                    self.take_errors();
                    self.health.on_traffic(st.t_us);
                    return Ok(Some(st));
                }
                Some(_) => continue,
                None => return Ok(None),
            }
        }
    }

    fn health(&self) -> BusHealth {
        self.health
    }

    fn set_filters(&mut self, filters: &[(u32, u32)]) -> Result<(), BusError> {
        self.filters = filters.to_vec();
        Ok(())
    }

    fn try_clone(&self) -> Result<Box<dyn CanBus>, BusError> {
        Ok(Box::new(self.bus.endpoint()))
    }

    fn name(&self) -> &str {
        "inproc"
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::ManualClock;
    use crate::frame::make_id;

    fn f(id: u32) -> CanFrame {
        CanFrame::classic(make_id(id, false).unwrap(), &[1, 2]).unwrap()
    }

    #[test]
    fn broadcast_to_others_not_self_with_clock_stamps() {
        let clock = ManualClock::new(100);
        let bus = InProcBus::with_clock(Arc::new(clock.clone()), 8);
        let mut a = bus.endpoint();
        let mut b = bus.endpoint();
        let mut c = bus.endpoint();
        c.set_filters(&[(0x200, 0x7F8)]).unwrap();
        a.send(&f(0x123)).unwrap();
        clock.advance_us(50);
        a.send(&f(0x201)).unwrap();
        let z = Duration::from_millis(10);
        assert_eq!(b.recv(z).unwrap().unwrap().t_us, 100);
        assert_eq!(b.recv(z).unwrap().unwrap().t_us, 150);
        assert_eq!(c.recv(z).unwrap().unwrap().frame.raw_id(), 0x201);
        assert!(a.recv(z).unwrap().is_none());
        assert!(c.recv(z).unwrap().is_none());
    }

    #[test]
    fn full_queue_drops_and_counts_without_blocking() {
        let bus = InProcBus::with_clock(Arc::new(ManualClock::new(0)), 2);
        let mut a = bus.endpoint();
        let _b = bus.endpoint();
        for _ in 0..5 {
            a.send(&f(1)).unwrap();
        }
        assert_eq!(bus.overruns(), 3);
        drop(_b);
        a.send(&f(1)).unwrap();
        assert_eq!(bus.overruns(), 3);
    }
}
