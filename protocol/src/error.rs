//! The runtime's errors ([`BusError`]) beside the wire format's, re-exported.

use thiserror::Error;

pub use wire::error::{ConfigError, DecodeError};

/// A failure of the CAN interface.
#[derive(Debug, Error)]
pub enum BusError {
    #[error(
        "cannot open CAN interface `{iface}`: {source}. Is it up? (`ip link show {iface}`; \
         for a virtual bus run `sudo ./vcan-setup.sh {iface}`)"
    )]
    /// The interface cannot be opened.
    Open {
        /// The interface.
        iface: String,
        /// What the OS said.
        source: std::io::Error,
    },
    #[error(
        "interface `{iface}` rejected a CAN FD frame (MTU 16: classic CAN only). Set it up for FD \
         (`ip link set {iface} mtu 72`, or for real hardware `ip link set {iface} type can bitrate \
         1000000 dbitrate 5000000 fd on`), or select the classic tactile variant"
    )]
    /// The interface carries classic CAN only (MTU 16).
    FdNotSupported {
        /// The interface.
        iface: String,
    },
    #[error("interface `{iface}`: the transmit queue is full (bus off or no other node acking?)")]
    /// The transmit queue is full.
    TxQueueFull {
        /// The interface.
        iface: String,
    },
    /// The interface went down or was removed.
    #[error("interface `{iface}` went down or vanished: {source}")]
    Down {
        /// The interface.
        iface: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// Any other socket error.
    #[error("CAN I/O on `{iface}`: {source}")]
    Io {
        /// The interface.
        iface: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// Every other endpoint of the in-process bus is gone.
    #[error("the in-process bus has no other endpoint left")]
    Closed,
}
