//! What the CAN processes (`presrs node`, `sim`, `controller`) share: signal flags and opening an
//! interface with retry and backoff. A process on a robot must outlive a CAN interface that is
//! missing at boot or goes down: it waits and reopens, it never exits on a bus error.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, Result};
use protocol::BusError;
use protocol::bus::{CanBus, InProcBus, SocketCanBus};

/// Set by SIGINT/SIGTERM (`stop`) and SIGHUP (`reload`, cleared by whoever acts on it).
#[derive(Clone)]
pub struct Signals {
    pub stop: Arc<AtomicBool>,
    pub reload: Arc<AtomicBool>,
}

impl Signals {
    pub fn install() -> Result<Self> {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let s = Self {
            stop: Arc::new(AtomicBool::new(false)),
            reload: Arc::new(AtomicBool::new(false)),
        };
        for sig in [SIGINT, SIGTERM] {
            signal_hook::flag::register(sig, s.stop.clone())
                .with_context(|| format!("installing the handler for signal {sig}"))?;
        }
        signal_hook::flag::register(SIGHUP, s.reload.clone())
            .context("installing the SIGHUP handler")?;
        Ok(s)
    }

    /// Flags no signal sets: a caller in this process (the node benchmark) stops the threads.
    pub fn manual() -> Self {
        Self {
            stop: Arc::new(AtomicBool::new(false)),
            reload: Arc::new(AtomicBool::new(false)),
        }
    }

    pub fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// True once per SIGHUP.
    pub fn take_reload(&self) -> bool {
        self.reload.swap(false, Ordering::Relaxed)
    }
}

/// Exponential backoff from 100 ms to 5 s, reset after a success.
pub struct Backoff {
    next: Duration,
}

impl Default for Backoff {
    fn default() -> Self {
        Self {
            next: Duration::from_millis(100),
        }
    }
}

impl Backoff {
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Sleeps the current delay in short slices (so a stop is seen quickly) and doubles it.
    /// Returns false when asked to stop.
    pub fn wait(&mut self, stop: &AtomicBool) -> bool {
        let end = std::time::Instant::now() + self.next;
        while std::time::Instant::now() < end {
            if stop.load(Ordering::Relaxed) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        self.next = (self.next * 2).min(Duration::from_secs(5));
        !stop.load(Ordering::Relaxed)
    }

    pub fn delay(&self) -> Duration {
        self.next
    }
}

/// After a bus error on an open interface: logs it with the delay, waits (growing the backoff so
/// that a flapping interface is not hammered), and returns false when asked to stop. The caller
/// then reopens with [`open_source_with_retry`].
pub fn after_bus_error(
    role: &str,
    e: &protocol::BusError,
    backoff: &mut Backoff,
    stop: &AtomicBool,
) -> bool {
    tracing::warn!(role, "{e}; reopening in {:?}", backoff.delay());
    backoff.wait(stop)
}

/// Where a process's threads get their bus handles: a CAN interface, or an in-process bus (the
/// node benchmark runs the node's own threads on one).
#[derive(Clone)]
pub enum BusSource {
    Iface(String),
    InProc(InProcBus),
}

impl BusSource {
    pub fn open(&self) -> Result<Box<dyn CanBus>, BusError> {
        match self {
            BusSource::Iface(i) => Ok(Box::new(SocketCanBus::open(i)?)),
            BusSource::InProc(b) => Ok(Box::new(b.endpoint())),
        }
    }

    pub fn label(&self) -> &str {
        match self {
            BusSource::Iface(i) => i,
            BusSource::InProc(_) => "inproc",
        }
    }
}

/// Opens `source`, retrying with backoff until it opens or `stop` is set. Each failure is
/// logged once per attempt with the fix the error names; `on_fail` sees it (for a status flag).
pub fn open_source_with_retry(
    source: &BusSource,
    stop: &AtomicBool,
    role: &str,
    on_fail: &mut dyn FnMut(),
) -> Option<Box<dyn CanBus>> {
    let mut backoff = Backoff::default();
    let iface = source.label();
    loop {
        match source.open() {
            Ok(b) => {
                tracing::info!(%iface, role, "CAN interface open");
                return Some(b);
            }
            Err(e) => {
                on_fail();
                tracing::warn!(role, "{e}; retrying in {:?}", backoff.delay());
                if !backoff.wait(stop) {
                    return None;
                }
            }
        }
    }
}
