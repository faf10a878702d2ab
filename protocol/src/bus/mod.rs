//! The bus abstraction: send and receive timestamped frames.
//!
//! Two implementations with the same semantics: [`SocketCanBus`] on a Linux CAN interface (real
//! `can0` or virtual `vcan0`) and [`InProcBus`], a broadcast bus between threads of one process for
//! host tests and the demo. On both, every endpoint sees every frame sent by every *other*
//! endpoint; an endpoint does not receive its own frames (SocketCAN's default).

mod errors;
mod inproc;
mod retry;
mod socket;

pub use errors::{BusHealth, ControllerState, ERROR_STATE_HOLD_US, ErrorClasses, HealthWatch};
pub use inproc::{InProcBus, InProcEndpoint};
pub use retry::{Backoff, BusSource, after_bus_error, open_with_retry, reopen_after_error};
pub use socket::{SocketCanBus, interface_mtu, send_error_frame};

use std::time::Duration;

use crate::error::BusError;
use crate::frame::{CanFrame, Stamped};

/// One handle on a CAN bus. A thread owns its handle; [`CanBus::try_clone`] gives another thread
/// its own (a second socket on SocketCAN).
pub trait CanBus: Send {
    /// Queues a frame for transmission. Never blocks for long: a full queue is an error.
    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError>;

    /// The next received frame, or `None` after `timeout` without one.
    fn recv(&mut self, timeout: Duration) -> Result<Option<Stamped>, BusError>;

    /// Passes only frames whose `id & mask == filter_id & mask` (all frames when empty).
    fn set_filters(&mut self, filters: &[(u32, u32)]) -> Result<(), BusError>;

    /// Another handle on the same bus.
    fn try_clone(&self) -> Result<Box<dyn CanBus>, BusError>;

    /// A name for logs ("vcan0", "inproc").
    fn name(&self) -> &str;

    /// What the CAN controller's error frames have said on this handle so far (counted as
    /// [`CanBus::recv`] reads them; they are never returned as frames).
    fn health(&self) -> BusHealth {
        BusHealth::default()
    }
}

impl CanBus for Box<dyn CanBus> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
        (**self).send(frame)
    }
    fn recv(&mut self, timeout: Duration) -> Result<Option<Stamped>, BusError> {
        (**self).recv(timeout)
    }
    fn set_filters(&mut self, filters: &[(u32, u32)]) -> Result<(), BusError> {
        (**self).set_filters(filters)
    }
    fn try_clone(&self) -> Result<Box<dyn CanBus>, BusError> {
        (**self).try_clone()
    }
    fn name(&self) -> &str {
        (**self).name()
    }
    fn health(&self) -> BusHealth {
        (**self).health()
    }
}

/// Keeps a copy of the traffic a process sees, for a recorder. Called on the threads that
/// receive and send, per frame: an implementation never blocks and never allocates (a full
/// queue drops the frame and counts it).
pub trait Tap: Send + Sync {
    /// A frame received from, or sent to, the bus (sent frames stamped with the sender's clock).
    fn offer(&self, frame: &Stamped);
    /// Frames dropped so far because the recorder was behind.
    fn dropped(&self) -> u64;
    /// How full its queue is, 0..=1. A run with no real time to keep (the lock-step demo)
    /// waits while it is over half full, so that its recording is whole; a robot never does.
    fn backlog(&self) -> f64 {
        0.0
    }
}

/// True when a frame passes a filter list (empty list: everything passes).
pub fn passes(filters: &[(u32, u32)], frame: &CanFrame) -> bool {
    filters.is_empty()
        || filters
            .iter()
            .any(|(id, mask)| frame.raw_id() & mask == id & mask)
}
