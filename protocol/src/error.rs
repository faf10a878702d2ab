//! Error types of the protocol crate.

use thiserror::Error;

/// An identifier map that cannot work on a bus.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum ConfigError {
    #[error(
        "{message}: base 0x{base:X} puts its last identifier at 0x{last:X}, above 0x{max:X}; \
         lower the base, or set `extended = true` for 29-bit identifiers"
    )]
    IdOutOfRange {
        message: &'static str,
        base: u32,
        last: u32,
        max: u32,
    },
    #[error("identifier ranges of {a} and {b} overlap; give one of them another base")]
    IdOverlap { a: &'static str, b: &'static str },
}

/// A frame whose payload does not decode as the message its identifier names.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum DecodeError {
    #[error("{message} needs at least {need} data bytes, the frame has {got}")]
    TooShort {
        message: &'static str,
        need: usize,
        got: usize,
    },
    #[error("{message}: field {field} has the invalid value {value}")]
    BadValue {
        message: &'static str,
        field: &'static str,
        value: u32,
    },
    #[error("{message} was sent as a remote frame; it carries data")]
    Remote { message: &'static str },
}

/// A failure of the CAN interface.
#[derive(Debug, Error)]
pub enum BusError {
    #[error(
        "cannot open CAN interface `{iface}`: {source}. Is it up? (`ip link show {iface}`; \
         for a virtual bus run `sudo ./vcan-setup.sh {iface}`)"
    )]
    Open {
        iface: String,
        source: std::io::Error,
    },
    #[error(
        "interface `{iface}` rejected a CAN FD frame (MTU 16: classic CAN only). Set it up for FD \
         (`ip link set {iface} mtu 72`, or for real hardware `ip link set {iface} type can bitrate \
         1000000 dbitrate 5000000 fd on`), or select the classic tactile variant"
    )]
    FdNotSupported { iface: String },
    #[error("interface `{iface}`: the transmit queue is full (bus off or no other node acking?)")]
    TxQueueFull { iface: String },
    #[error("interface `{iface}` went down or vanished: {source}")]
    Down {
        iface: String,
        source: std::io::Error,
    },
    #[error("CAN I/O on `{iface}`: {source}")]
    Io {
        iface: String,
        source: std::io::Error,
    },
    #[error("the in-process bus has no other endpoint left")]
    Closed,
}
