//! FootContact: the foot's micro-switch, as the foot sends it.

use crate::error::DecodeError;

use super::{need, u32_at};

/// Foot -> all: the micro-switch in the foot (debounced by the receiver, not the sender).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct FootContact {
    /// Switch closed: the foot is on the ground.
    pub stance: bool,
    /// Wrapping counter, one per message.
    pub seq: u8,
    /// Sender clock, µs, wrapping (low 32 bits; 71.6 min period).
    pub timestamp_us: u32,
}

impl FootContact {
    /// The 8 data bytes (layout in docs/protocol.md).
    pub fn encode(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d[0] = self.stance as u8;
        d[1] = self.seq;
        d[2..6].copy_from_slice(&self.timestamp_us.to_le_bytes());
        d
    }

    /// Decodes the data bytes; a short payload or an invalid field is an error.
    pub fn decode(d: &[u8]) -> Result<Self, DecodeError> {
        need("FootContact", d, 6)?;
        if d[0] > 1 {
            return Err(DecodeError::BadValue {
                message: "FootContact",
                field: "Contact",
                value: d[0] as u32,
            });
        }
        Ok(Self {
            stance: d[0] == 1,
            seq: d[1],
            timestamp_us: u32_at(d, 2),
        })
    }
}
