//! CAN error frames: what the CAN controller says about the bus, and the state it is in.
//!
//! A CAN controller counts transmit and receive errors. Past 96 it warns, past 127 it is
//! *error-passive* (it may no longer signal errors actively, and its frames can be delayed),
//! and past 255 transmit errors it goes *bus-off*: it takes no part in the bus until it is
//! restarted (by the driver after `restart-ms`, or by hand). Linux reports these events as
//! error frames to sockets that ask for them with an error mask (`CAN_RAW_ERR_FILTER`);
//! [`super::SocketCanBus`] asks for all of them and keeps a [`BusHealth`] per handle.
//!
//! On a robot a bus-off is the first thing to know: the node's NodeStatus carries it in its
//! state ([`crate::messages::NodeState::BusOff`], [`crate::messages::NodeState::ErrorPassive`])
//! and its log says it once per episode with the fix.
//!
//! ```
//! use presrs_protocol::bus::{BusHealth, ControllerState, ErrorClasses};
//!
//! let mut h = BusHealth::default();
//! h.on_error_frame(&ErrorClasses { bus_off: true, ..Default::default() }, 1_000);
//! assert_eq!(h.state, ControllerState::BusOff);
//! // Traffic again, well after the last error frame: the controller is back.
//! h.on_traffic(2_000_000);
//! assert_eq!(h.state, ControllerState::Active);
//! ```

/// The CAN controller's error state, from the error frames heard.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub enum ControllerState {
    /// Error-active: the normal state.
    #[default]
    Active,
    /// An error counter passed the warning level (96).
    Warning,
    /// An error counter passed 127: frames may be delayed or lost.
    Passive,
    /// Too many transmit errors: the controller is off the bus until restarted.
    BusOff,
}

impl ControllerState {
    /// A lower-case name for logs.
    pub fn name(self) -> &'static str {
        match self {
            ControllerState::Active => "error-active",
            ControllerState::Warning => "error-warning",
            ControllerState::Passive => "error-passive",
            ControllerState::BusOff => "bus-off",
        }
    }
}

/// The classes one error frame reports (several may come in one frame), as in
/// `linux/can/error.h`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ErrorClasses {
    /// `CAN_ERR_TX_TIMEOUT`.
    pub tx_timeout: bool,
    /// `CAN_ERR_LOSTARB`.
    pub lost_arbitration: bool,
    /// `CAN_ERR_CRTL` with a warning level (rx or tx).
    pub warning: bool,
    /// `CAN_ERR_CRTL` with error-passive (rx or tx).
    pub passive: bool,
    /// `CAN_ERR_CRTL_ACTIVE`: back to error-active.
    pub active: bool,
    /// `CAN_ERR_CRTL` with an rx or tx buffer overflow.
    pub overflow: bool,
    /// `CAN_ERR_PROT`: a protocol violation (bit, form, stuff, CRC...).
    pub protocol: bool,
    /// `CAN_ERR_TRX`: a transceiver fault.
    pub transceiver: bool,
    /// `CAN_ERR_ACK`: nobody acknowledged a frame (alone on the bus, or unpowered peers).
    pub no_ack: bool,
    /// `CAN_ERR_BUSOFF`.
    pub bus_off: bool,
    /// `CAN_ERR_BUSERROR`.
    pub bus_error: bool,
    /// `CAN_ERR_RESTARTED`: the controller restarted after bus-off.
    pub restarted: bool,
    /// `CAN_ERR_CNT`: the transmit and receive error counters.
    pub counters: Option<(u8, u8)>,
}

/// Warning level of the error counters (ISO 11898-1).
const WARNING_LEVEL: u8 = 96;
/// Error-passive level of the error counters.
const PASSIVE_LEVEL: u8 = 128;

/// How long a warning, error-passive or bus-off state is held after its last error frame
/// before traffic alone returns it to active, µs. Drivers do not all report the way back
/// down, so traffic must end an episode; but on a bus that still carries frames (vcan, or a
/// controller that recovered at once) an instant return would hide the episode from a 10 Hz
/// NodeStatus. Half a second shows it in about five.
pub const ERROR_STATE_HOLD_US: u64 = 500_000;

/// Error frames counted per class, and the controller state they imply.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BusHealth {
    /// The state now.
    pub state: ControllerState,
    /// Error frames heard.
    pub error_frames: u64,
    /// Bus-off reports.
    pub bus_off: u64,
    /// Error-passive reports.
    pub passive: u64,
    /// Warning reports.
    pub warning: u64,
    /// Protocol violations.
    pub protocol: u64,
    /// Frames nobody acknowledged.
    pub no_ack: u64,
    /// Lost arbitrations.
    pub lost_arbitration: u64,
    /// Transceiver faults.
    pub transceiver: u64,
    /// Controller buffer overflows.
    pub overflow: u64,
    /// Transmit timeouts.
    pub tx_timeout: u64,
    /// Bus errors.
    pub bus_error: u64,
    /// Restarts after bus-off.
    pub restarted: u64,
    /// Receive time of the last error frame, µs (the bus's clock).
    pub last_error_us: Option<u64>,
}

impl BusHealth {
    /// Counts one error frame received at `t_us` and moves the state as it says.
    pub fn on_error_frame(&mut self, e: &ErrorClasses, t_us: u64) {
        self.error_frames += 1;
        self.last_error_us = Some(t_us);
        let n = |c: &mut u64, b: bool| *c += b as u64;
        n(&mut self.bus_off, e.bus_off);
        n(&mut self.passive, e.passive);
        n(&mut self.warning, e.warning);
        n(&mut self.protocol, e.protocol);
        n(&mut self.no_ack, e.no_ack);
        n(&mut self.lost_arbitration, e.lost_arbitration);
        n(&mut self.transceiver, e.transceiver);
        n(&mut self.overflow, e.overflow);
        n(&mut self.tx_timeout, e.tx_timeout);
        n(&mut self.bus_error, e.bus_error);
        n(&mut self.restarted, e.restarted);
        let from_counters = e.counters.map(|(tx, rx)| {
            let worst = tx.max(rx);
            if worst >= PASSIVE_LEVEL {
                ControllerState::Passive
            } else if worst >= WARNING_LEVEL {
                ControllerState::Warning
            } else {
                ControllerState::Active
            }
        });
        self.state = if e.bus_off {
            ControllerState::BusOff
        } else if e.restarted || e.active {
            ControllerState::Active
        } else if e.passive {
            ControllerState::Passive
        } else if e.warning {
            ControllerState::Warning
        } else if let Some(s) = from_counters {
            s
        } else {
            self.state
        };
    }

    /// A data frame received at `t_us`: a controller that receives again, long enough after
    /// its last error frame ([`ERROR_STATE_HOLD_US`]), is back to active.
    pub fn on_traffic(&mut self, t_us: u64) {
        if self.state != ControllerState::Active
            && self
                .last_error_us
                .is_none_or(|t| t_us.saturating_sub(t) >= ERROR_STATE_HOLD_US)
        {
            self.state = ControllerState::Active;
        }
    }
}

/// Follows a handle's [`BusHealth`] and logs each episode once: on entering error-passive or
/// bus-off, with the fix, and on the way back.
#[derive(Clone, Debug, Default)]
pub struct HealthWatch {
    seen: BusHealth,
}

impl HealthWatch {
    /// Takes the handle's health now; returns the new state when it changed.
    pub fn update(&mut self, role: &str, iface: &str, h: &BusHealth) -> Option<ControllerState> {
        if *h == self.seen {
            return None;
        }
        let before = self.seen.state;
        self.seen = *h;
        if h.state == before {
            return None;
        }
        match h.state {
            ControllerState::BusOff | ControllerState::Passive => tracing::error!(
                role,
                iface,
                error_frames = h.error_frames,
                bus_off = h.bus_off,
                passive = h.passive,
                protocol = h.protocol,
                no_ack = h.no_ack,
                "CAN controller {}: check the wiring, the termination and that every node \
                 has the same bitrate (`ip -details -statistics link show {iface}`); a bus-off \
                 controller rejoins only when restarted (`ip link set {iface} type can \
                 restart-ms 100`, or down and up)",
                h.state.name()
            ),
            ControllerState::Warning => tracing::warn!(
                role,
                iface,
                error_frames = h.error_frames,
                "CAN controller at the error-warning level"
            ),
            ControllerState::Active => tracing::info!(
                role,
                iface,
                error_frames = h.error_frames,
                "CAN controller back to error-active (was {})",
                before.name()
            ),
        }
        Some(h.state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn e(f: impl FnOnce(&mut ErrorClasses)) -> ErrorClasses {
        let mut c = ErrorClasses::default();
        f(&mut c);
        c
    }

    #[test]
    fn states_follow_the_reports_and_return_on_restart_or_later_traffic() {
        let mut h = BusHealth::default();
        h.on_error_frame(&e(|c| c.warning = true), 0);
        assert_eq!(h.state, ControllerState::Warning);
        h.on_error_frame(&e(|c| c.passive = true), 10);
        assert_eq!(h.state, ControllerState::Passive);
        // A protocol error alone does not change the state.
        h.on_error_frame(&e(|c| c.protocol = true), 20);
        assert_eq!(h.state, ControllerState::Passive);
        // Traffic within the hold keeps the episode visible.
        h.on_traffic(20 + ERROR_STATE_HOLD_US - 1);
        assert_eq!(h.state, ControllerState::Passive);
        h.on_traffic(20 + ERROR_STATE_HOLD_US);
        assert_eq!(h.state, ControllerState::Active);
        h.on_error_frame(&e(|c| c.bus_off = true), 1_000_000);
        assert_eq!(h.state, ControllerState::BusOff);
        h.on_error_frame(&e(|c| c.restarted = true), 1_000_100);
        assert_eq!(h.state, ControllerState::Active);
        h.on_error_frame(&e(|c| c.counters = Some((130, 0))), 1_000_200);
        assert_eq!(h.state, ControllerState::Passive);
        h.on_error_frame(&e(|c| c.counters = Some((0, 100))), 1_000_300);
        assert_eq!(h.state, ControllerState::Warning);
        assert_eq!(
            (h.error_frames, h.bus_off, h.passive, h.warning, h.protocol),
            (7, 1, 1, 1, 1)
        );
    }

    #[test]
    fn the_watch_reports_each_state_change_once() {
        let mut w = HealthWatch::default();
        let mut h = BusHealth::default();
        assert_eq!(w.update("t", "vcan0", &h), None);
        h.on_error_frame(&e(|c| c.bus_off = true), 0);
        assert_eq!(w.update("t", "vcan0", &h), Some(ControllerState::BusOff));
        h.on_error_frame(&e(|c| c.bus_off = true), 5);
        assert_eq!(w.update("t", "vcan0", &h), None);
        h.on_traffic(ERROR_STATE_HOLD_US + 5);
        assert_eq!(w.update("t", "vcan0", &h), Some(ControllerState::Active));
    }
}
