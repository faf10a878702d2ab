//! The CAN frame type every other module uses.
//!
//! [`CanFrame`] is a plain `Copy` value (no heap) that holds either a classic CAN 2.0 frame (up to
//! 8 data bytes) or a CAN FD frame (up to 64 bytes, with the bit-rate-switch flag). It implements
//! [`embedded_can::Frame`], so code written against the `embedded-can` traits can build and read
//! our frames, and it converts to and from the `socketcan` crate's frame types.

use embedded_can::{ExtendedId, Id, StandardId};

/// Largest CAN FD payload.
pub const FD_MAX_LEN: usize = 64;
/// Largest classic CAN payload.
pub const CLASSIC_MAX_LEN: usize = 8;

/// The lengths a CAN FD frame may carry (DLC 0..15 map onto these).
pub const FD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// True when `len` is a payload length a CAN FD frame can carry.
pub fn is_valid_fd_len(len: usize) -> bool {
    FD_LENGTHS.contains(&len)
}

/// A classic or FD data frame (remote frames are classic only).
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct CanFrame {
    id: Id,
    len: u8,
    fd: bool,
    brs: bool,
    remote: bool,
    data: [u8; FD_MAX_LEN],
}

impl CanFrame {
    /// A classic CAN 2.0 data frame; `None` if `data` is longer than 8 bytes.
    pub fn classic(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        if data.len() > CLASSIC_MAX_LEN {
            return None;
        }
        Some(Self::build(id.into(), data, false, false))
    }

    /// A CAN FD frame; `None` if `data.len()` is not a valid FD length. `brs` asks the controller
    /// to switch to the data bit rate for the payload.
    pub fn fd(id: impl Into<Id>, data: &[u8], brs: bool) -> Option<Self> {
        if !is_valid_fd_len(data.len()) {
            return None;
        }
        Some(Self::build(id.into(), data, true, brs))
    }

    fn build(id: Id, data: &[u8], fd: bool, brs: bool) -> Self {
        let mut buf = [0u8; FD_MAX_LEN];
        buf[..data.len()].copy_from_slice(data);
        Self {
            id,
            len: data.len() as u8,
            fd,
            brs,
            remote: false,
            data: buf,
        }
    }

    /// A classic remote frame with the given DLC (0..=8).
    pub fn remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        if dlc > CLASSIC_MAX_LEN {
            return None;
        }
        Some(Self {
            id: id.into(),
            len: dlc as u8,
            fd: false,
            brs: false,
            remote: true,
            data: [0; FD_MAX_LEN],
        })
    }

    /// The identifier (standard or extended).
    pub fn id(&self) -> Id {
        self.id
    }

    /// The identifier as a plain number (11 or 29 bits).
    pub fn raw_id(&self) -> u32 {
        id_raw(self.id)
    }

    /// A 29-bit identifier.
    pub fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }

    /// A CAN FD frame.
    pub fn is_fd(&self) -> bool {
        self.fd
    }

    /// CAN FD with bit-rate switch.
    pub fn is_brs(&self) -> bool {
        self.brs
    }

    /// A remote (RTR) frame: no data.
    pub fn is_remote(&self) -> bool {
        self.remote
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }

    /// Number of data bytes.
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// No data bytes.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl core::fmt::Debug for CanFrame {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:03X}", self.raw_id())?;
        if self.fd {
            write!(f, "##{}", if self.brs { 1 } else { 0 })?;
        } else {
            write!(f, "#")?;
        }
        if self.remote {
            return write!(f, "R{}", self.len);
        }
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// The numeric value of an `embedded_can` identifier.
pub fn id_raw(id: Id) -> u32 {
    match id {
        Id::Standard(s) => s.as_raw() as u32,
        Id::Extended(e) => e.as_raw(),
    }
}

/// Builds an identifier: standard when `extended` is false (`None` if `raw` > 0x7FF).
pub fn make_id(raw: u32, extended: bool) -> Option<Id> {
    if extended {
        ExtendedId::new(raw).map(Id::Extended)
    } else {
        u16::try_from(raw)
            .ok()
            .and_then(StandardId::new)
            .map(Id::Standard)
    }
}

impl embedded_can::Frame for CanFrame {
    /// Classic for up to 8 bytes, FD (with BRS) for the longer FD lengths.
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        if data.len() <= CLASSIC_MAX_LEN {
            Self::classic(id, data)
        } else {
            Self::fd(id, data, true)
        }
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        Self::remote(id, dlc)
    }

    fn is_extended(&self) -> bool {
        CanFrame::is_extended(self)
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> Id {
        self.id
    }

    fn dlc(&self) -> usize {
        self.len as usize
    }

    fn data(&self) -> &[u8] {
        CanFrame::data(self)
    }
}

/// A frame with the time it was received (or, in a log, recorded), in microseconds.
///
/// On SocketCAN the time is the kernel's receive timestamp (`SO_TIMESTAMPNS`, µs since the UNIX
/// epoch); on the in-process bus it is the bus clock at the send; in a replayed candump log it is
/// the log's timestamp. Consumers measure time between frames only, never against a wall clock, so
/// a replay reproduces a live run exactly.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Stamped {
    /// Receive time, µs on the bus's clock (kernel timestamp on SocketCAN, the log's on replay).
    pub t_us: u64,
    /// The frame.
    pub frame: CanFrame,
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::Frame as _;

    #[test]
    fn classic_and_fd_lengths() {
        let id = make_id(0x123, false).unwrap();
        assert!(CanFrame::classic(id, &[0; 9]).is_none());
        assert!(CanFrame::fd(id, &[0; 9], true).is_none());
        let f = CanFrame::fd(id, &[7; 64], true).unwrap();
        assert_eq!(f.len(), 64);
        assert!(f.is_fd() && f.is_brs());
        let g = <CanFrame as embedded_can::Frame>::new(id, &[1, 2, 3]).unwrap();
        assert!(!g.is_fd());
        assert_eq!(g.dlc(), 3);
        assert_eq!(format!("{g:?}"), "123#010203");
    }

    #[test]
    fn ids() {
        assert!(make_id(0x800, false).is_none());
        assert!(make_id(0x800, true).is_some());
        assert!(make_id(0x2000_0000, true).is_none());
        assert_eq!(id_raw(make_id(0x1ABC_DEF0, true).unwrap()), 0x1ABC_DEF0);
    }
}
