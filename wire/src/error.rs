//! The wire format's errors: an identifier map that cannot work, a frame that does not decode.

use thiserror::Error;

/// An identifier map that cannot work on a bus.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum ConfigError {
    #[error(
        "{message}: base 0x{base:X} puts its last identifier at 0x{last:X}, above 0x{max:X}; \
         lower the base, or set `extended = true` for 29-bit identifiers"
    )]
    /// A message kind's identifier range does not fit the identifier width.
    IdOutOfRange {
        /// The message kind.
        message: &'static str,
        /// Its base identifier.
        base: u32,
        /// Its last identifier (base plus the largest foot).
        last: u32,
        /// The largest identifier of the width (0x7FF or 0x1FFFFFFF).
        max: u32,
    },
    #[error("identifier ranges of {a} and {b} overlap; give one of them another base")]
    /// Two message kinds' identifier ranges overlap.
    IdOverlap {
        /// One kind.
        a: &'static str,
        /// The other.
        b: &'static str,
    },
}

/// A frame whose payload does not decode as the message its identifier names.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum DecodeError {
    /// The payload is shorter than the message.
    #[error("{message} needs at least {need} data bytes, the frame has {got}")]
    TooShort {
        /// The message kind.
        message: &'static str,
        /// Bytes the message needs.
        need: usize,
        /// Bytes the frame has.
        got: usize,
    },
    /// A field holds a value the message does not define.
    #[error("{message}: field {field} has the invalid value {value}")]
    BadValue {
        /// The message kind.
        message: &'static str,
        /// The field.
        field: &'static str,
        /// The value received.
        value: u32,
    },
    /// A fixed-layout message at another length than the DBC's, or as CAN FD where the DBC
    /// says classic: a sender that does not follow the layout, whatever the bytes say.
    #[error(
        "{message} must be a classic CAN frame of {want} data bytes (the DBC's size); got {got} bytes{}",
        if *fd { " as CAN FD" } else { "" }
    )]
    WrongLength {
        /// The message kind.
        message: &'static str,
        /// The DBC's length.
        want: usize,
        /// Bytes the frame has.
        got: usize,
        /// The frame was CAN FD.
        fd: bool,
    },
    #[error("{message} was sent as a remote frame; it carries data")]
    /// A remote (RTR) frame where data was expected.
    Remote {
        /// The message kind.
        message: &'static str,
    },
}
