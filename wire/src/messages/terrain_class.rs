//! TerrainClass: the node's decision per step, its flags and why an unknown step is unknown.

use crate::error::DecodeError;

use super::{PERCENT_SCALE, TERRAIN_UNKNOWN, need, sat_u, u16_at};

/// Bits of [`TerrainClass::flags`].
pub mod flags {
    /// Sensor lines known dead were filled by the repair filter.
    pub const REPAIRED: u8 = 1 << 0;
    /// The best class's confidence was below the configured threshold.
    pub const LOW_CONFIDENCE: u8 = 1 << 1;
    /// No usable pressure image arrived in the stance window.
    pub const NO_SAMPLE: u8 = 1 << 2;
    /// Decided from several frames of the stance (sum of log-posteriors).
    pub const MULTI_FRAME: u8 = 1 << 3;
    /// The stance's sampled image showed no foot on the ground (too little load or pressed
    /// area for the model's training images): the terrain is unknown.
    pub const NO_CONTACT: u8 = 1 << 4;
    /// The texture's terrain took energy out of the foot's last hop (the flight after that
    /// stance, given the flight before) that the terrain does not: other ground that looks
    /// like it. The terrain is unknown.
    pub const ENERGY: u8 = 1 << 5;
    /// Bits 6-7: which check of the stance image called the step unknown, an
    /// [`super::UnknownReason`] code (0: none of them; see [`super::TerrainClass::unknown_reason`]).
    pub const REASON_MASK: u8 = 0b11 << REASON_SHIFT;
    /// The lowest bit of [`REASON_MASK`].
    pub const REASON_SHIFT: u8 = 6;
}

/// Why a step is unknown (`TerrainId` [`TERRAIN_UNKNOWN`]): one reason per step, the first that
/// applies in this order. A monitor counts unknowns per reason with
/// [`TerrainClass::unknown_reason`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum UnknownReason {
    /// No image arrived in the stance ([`flags::NO_SAMPLE`]).
    NoSample,
    /// The image showed no foot on the ground ([`flags::NO_CONTACT`]).
    NoContact,
    /// The image is unlike every known terrain (its novelty score above its class's threshold;
    /// `UnknownReason` code 1).
    Novelty,
    /// The image's load lies outside its terrain's trained band (code 2).
    Load,
    /// The image's roughness lies outside its terrain's trained band (code 3).
    Texture,
    /// The terrain the image shows took energy out of the foot's last hop that it does not
    /// ([`flags::ENERGY`]).
    Energy,
}

impl UnknownReason {
    /// Every reason, in the order [`TerrainClass::unknown_reason`] reports them.
    pub const ALL: [UnknownReason; 6] = [
        UnknownReason::NoSample,
        UnknownReason::NoContact,
        UnknownReason::Novelty,
        UnknownReason::Load,
        UnknownReason::Texture,
        UnknownReason::Energy,
    ];

    /// The name in logs, JSON and the DBC's `UnknownReason` table.
    pub fn name(self) -> &'static str {
        match self {
            UnknownReason::NoSample => "no_sample",
            UnknownReason::NoContact => "no_contact",
            UnknownReason::Novelty => "novelty",
            UnknownReason::Load => "load",
            UnknownReason::Texture => "texture",
            UnknownReason::Energy => "energy",
        }
    }

    /// The image checks' 2-bit code in [`flags::REASON_MASK`] (1 novelty, 2 load, 3 texture);
    /// 0 for the reasons that have a flag of their own.
    pub fn code(self) -> u8 {
        match self {
            UnknownReason::Novelty => 1,
            UnknownReason::Load => 2,
            UnknownReason::Texture => 3,
            _ => 0,
        }
    }

    /// The flag bits that carry this reason.
    pub fn flag_bits(self) -> u8 {
        match self {
            UnknownReason::NoSample => flags::NO_SAMPLE,
            UnknownReason::NoContact => flags::NO_CONTACT,
            UnknownReason::Energy => flags::ENERGY,
            r => r.code() << flags::REASON_SHIFT,
        }
    }
}

/// Largest value of `TerrainClass::latency_us` (its 16-bit CAN field): longer latencies read as
/// this.
pub const LATENCY_MAX_US: u32 = 65_535;

/// Node -> all: the terrain under one foot, once per step.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct TerrainClass {
    /// Step counter of this foot (wrapping).
    pub step: u16,
    /// Terrain id (a `protocol::terrain::TerrainCatalog`'s), [`TERRAIN_UNKNOWN`] when not classified.
    pub terrain: u8,
    /// Posterior of the chosen class, 0..=100 %.
    pub confidence_pct: f64,
    /// Sensor damage, paper eq. (6), 0..=100 %.
    pub damage_pct: f64,
    /// [`flags`] bits.
    pub flags: u8,
    /// From the receipt of the sampled frame's last segment to this message, µs (saturates at 65535).
    pub latency_us: u32,
}

impl TerrainClass {
    /// The 8 data bytes (layout in docs/protocol.md).
    pub fn encode(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d[0..2].copy_from_slice(&self.step.to_le_bytes());
        d[2] = self.terrain;
        d[3] = sat_u(self.confidence_pct / PERCENT_SCALE, 200.0) as u8;
        d[4] = sat_u(self.damage_pct / PERCENT_SCALE, 200.0) as u8;
        d[5] = self.flags;
        d[6..8].copy_from_slice(&(self.latency_us.min(65535) as u16).to_le_bytes());
        d
    }

    /// Decodes the data bytes; a short payload or an invalid field is an error.
    pub fn decode(d: &[u8]) -> Result<Self, DecodeError> {
        need("TerrainClass", d, 8)?;
        Ok(Self {
            step: u16_at(d, 0),
            terrain: d[2],
            confidence_pct: d[3] as f64 * PERCENT_SCALE,
            damage_pct: d[4] as f64 * PERCENT_SCALE,
            flags: d[5],
            latency_us: u16_at(d, 6) as u32,
        })
    }

    /// Why the step is unknown, from its flags; `None` for a terrain (or an unknown step sent
    /// without a reason, as nodes before the reason field did).
    pub fn unknown_reason(&self) -> Option<UnknownReason> {
        if self.terrain != TERRAIN_UNKNOWN {
            return None;
        }
        let f = self.flags;
        if f & flags::NO_SAMPLE != 0 {
            Some(UnknownReason::NoSample)
        } else if f & flags::NO_CONTACT != 0 {
            Some(UnknownReason::NoContact)
        } else if f & flags::ENERGY != 0 {
            Some(UnknownReason::Energy)
        } else {
            match (f & flags::REASON_MASK) >> flags::REASON_SHIFT {
                1 => Some(UnknownReason::Novelty),
                2 => Some(UnknownReason::Load),
                3 => Some(UnknownReason::Texture),
                _ => None,
            }
        }
    }
}
