//! Clocks. Code that needs "now" takes a [`Clock`], so tests and replays can drive time.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// A source of microsecond time. Monotonic: never goes backwards.
pub trait Clock: Send + Sync {
    /// Microseconds since the clock's origin.
    fn now_us(&self) -> u64;
}

/// The process's monotonic clock, counted from its creation.
#[derive(Clone, Debug)]
pub struct MonotonicClock {
    start: Instant,
    offset_us: u64,
}

impl MonotonicClock {
    /// A clock reading 0 now.
    pub fn new() -> Self {
        Self {
            start: Instant::now(),
            offset_us: 0,
        }
    }

    /// A monotonic clock that reads UNIX-epoch microseconds at creation, so its readings can be
    /// compared with SocketCAN receive timestamps.
    pub fn unix() -> Self {
        let offset_us = epoch_us();
        Self {
            start: Instant::now(),
            offset_us,
        }
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for MonotonicClock {
    fn now_us(&self) -> u64 {
        self.offset_us + self.start.elapsed().as_micros() as u64
    }
}

/// UNIX-epoch microseconds from the system's real-time clock: the clock of SocketCAN's receive
/// timestamps (`SO_TIMESTAMP`), so a reading minus a frame's [`crate::Stamped::t_us`] is how
/// long ago the kernel received it, however long the process was stopped or behind. Held
/// monotonic: a clock set backwards reads its last value until it catches up.
#[derive(Debug, Default)]
pub struct WallClock {
    last: AtomicU64,
}

impl Clock for WallClock {
    fn now_us(&self) -> u64 {
        let now = epoch_us();
        self.last.fetch_max(now, Ordering::Relaxed).max(now)
    }
}

/// The system's real-time clock, µs since the UNIX epoch (0 if the clock is before it): the
/// time base of SocketCAN's receive timestamps and of recordings stamped on the wall clock.
pub fn epoch_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// The robot's clock as one runner keeps it, to share between runners: wall time since its
/// creation times `scale` (a simulator slower than real time), in µs.
#[derive(Clone, Debug)]
pub struct ScaledClock {
    start: Instant,
    scale: f64,
}

impl ScaledClock {
    /// A clock reading 0 now and running at `scale` of the wall clock.
    pub fn new(scale: f64) -> Self {
        Self {
            start: Instant::now(),
            scale,
        }
    }
}

impl Clock for ScaledClock {
    fn now_us(&self) -> u64 {
        (self.start.elapsed().as_secs_f64() * self.scale * 1e6) as u64
    }
}

/// A clock that only moves when told to: for tests and simulation faster than real time.
#[derive(Clone, Debug, Default)]
pub struct ManualClock(Arc<AtomicU64>);

impl ManualClock {
    /// A clock reading `start_us` until moved.
    pub fn new(start_us: u64) -> Self {
        Self(Arc::new(AtomicU64::new(start_us)))
    }
    /// Moves the clock to `t` (µs); never backwards.
    pub fn set_us(&self, t: u64) {
        self.0.fetch_max(t, Ordering::SeqCst);
    }
    /// Moves the clock forward by `dt` µs.
    pub fn advance_us(&self, dt: u64) {
        self.0.fetch_add(dt, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now_us(&self) -> u64 {
        self.0.load(Ordering::SeqCst)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_clock_is_shared_and_monotonic() {
        let c = ManualClock::new(10);
        let d = c.clone();
        c.advance_us(5);
        assert_eq!(d.now_us(), 15);
        d.set_us(3);
        assert_eq!(c.now_us(), 15);
        let m = MonotonicClock::new();
        let a = m.now_us();
        assert!(m.now_us() >= a);
        let w = WallClock::default();
        let a = w.now_us();
        // Within a second of the monotonic clock anchored to the epoch now.
        assert!(a.abs_diff(MonotonicClock::unix().now_us()) < 1_000_000);
        assert!(w.now_us() >= a);
    }
}
