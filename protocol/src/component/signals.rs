//! The process's signals as the flags a runner reads: SIGINT and SIGTERM set `stop` (the flag
//! [`run`](super::run) and [`spawn`](super::spawn) end on), SIGHUP sets `reload` (`presrs
//! node` reloads its model file, as a daemon does under systemd's `ExecReload`).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set by SIGINT/SIGTERM (`stop`) and SIGHUP (`reload`, cleared by whoever acts on it).
#[derive(Clone, Debug)]
pub struct Signals {
    /// Set once SIGINT or SIGTERM arrived: every runner of the process ends its loop.
    pub stop: Arc<AtomicBool>,
    /// Set by each SIGHUP; [`Signals::take_reload`] reads and clears it.
    pub reload: Arc<AtomicBool>,
}

/// A signal handler the operating system refused.
#[derive(Debug, thiserror::Error)]
#[error("installing the handler for signal {signal}: {source}")]
pub struct SignalError {
    /// The signal's number.
    pub signal: i32,
    /// Why it was refused.
    #[source]
    pub source: std::io::Error,
}

impl Signals {
    /// Installs the handlers: from here on the process's SIGINT, SIGTERM and SIGHUP set flags
    /// instead of ending it.
    pub fn install() -> Result<Self, SignalError> {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let s = Self {
            stop: Arc::new(AtomicBool::new(false)),
            reload: Arc::new(AtomicBool::new(false)),
        };
        for (signal, flag) in [(SIGINT, &s.stop), (SIGTERM, &s.stop), (SIGHUP, &s.reload)] {
            signal_hook::flag::register(signal, flag.clone())
                .map_err(|source| SignalError { signal, source })?;
        }
        Ok(s)
    }

    /// True once SIGINT or SIGTERM arrived.
    pub fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// True once per SIGHUP.
    pub fn take_reload(&self) -> bool {
        self.reload.swap(false, Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sighup_asks_for_one_reload_and_does_not_stop() {
        let s = Signals::install().unwrap();
        signal_hook::low_level::raise(signal_hook::consts::SIGHUP).unwrap();
        assert!(s.take_reload());
        assert!(!s.take_reload(), "one reload per SIGHUP");
        assert!(!s.stopping());
    }
}
