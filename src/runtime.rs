//! Signal flags for the CAN processes (`presrs node`, `sim`, `controller`). Opening an interface
//! with retry and backoff lives in [`protocol::bus::open_with_retry`].

use anyhow::{Context, Result};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

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

    pub fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// True once per SIGHUP.
    pub fn take_reload(&self) -> bool {
        self.reload.swap(false, Ordering::Relaxed)
    }
}

/// The wall clock, µs since the Unix epoch (0 if the clock is before it).
pub fn epoch_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}
