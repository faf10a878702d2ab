//! GaitStatus: the gait in force and why the controller runs it.

use crate::error::DecodeError;

use super::{ANGLE_SCALE_RAD, OMEGA_SCALE, i16_at, need, sat_i16, sat_u, u16_at};

/// Why the controller runs the gait it runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum GaitReason {
    /// Configured start gait, no terrain seen yet.
    #[default]
    Initial = 0,
    /// Chosen from the terrain table.
    Terrain = 1,
    /// Safe gait: terrain unknown.
    Unknown = 2,
    /// Safe gait: node heartbeat lost.
    NodeLost = 3,
}

impl GaitReason {
    /// The reason with wire value `v`.
    pub fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            0 => Self::Initial,
            1 => Self::Terrain,
            2 => Self::Unknown,
            3 => Self::NodeLost,
            _ => return None,
        })
    }
}

/// Controller -> all: the gait in force (at every switch and at 10 Hz).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct GaitStatus {
    /// 1..=3 for G1..G3 (configurable gaits may use more).
    pub gait: u8,
    /// The terrain the gait was chosen for.
    pub terrain: u8,
    /// Stance frequency omega of eq. (4), rad/s.
    pub omega_rad_s: f64,
    /// Desired liftoff angle beta_des of eq. (5), rad.
    pub beta_des_rad: f64,
    /// Why this gait.
    pub reason: GaitReason,
    /// The foot whose terrain decided it.
    pub foot: u8,
}

impl GaitStatus {
    /// The 8 data bytes (layout in docs/protocol.md).
    pub fn encode(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d[0] = self.gait;
        d[1] = self.terrain;
        d[2..4].copy_from_slice(
            &(sat_u(self.omega_rad_s / OMEGA_SCALE, 65535.0) as u16).to_le_bytes(),
        );
        d[4..6].copy_from_slice(&sat_i16(self.beta_des_rad / ANGLE_SCALE_RAD).to_le_bytes());
        d[6] = self.reason as u8;
        d[7] = self.foot;
        d
    }

    /// Decodes the data bytes; a short payload or an invalid field is an error.
    pub fn decode(d: &[u8]) -> Result<Self, DecodeError> {
        need("GaitStatus", d, 8)?;
        let reason = GaitReason::from_u8(d[6]).ok_or(DecodeError::BadValue {
            message: "GaitStatus",
            field: "Reason",
            value: d[6] as u32,
        })?;
        Ok(Self {
            gait: d[0],
            terrain: d[1],
            omega_rad_s: u16_at(d, 2) as f64 * OMEGA_SCALE,
            beta_des_rad: i16_at(d, 4) as f64 * ANGLE_SCALE_RAD,
            reason,
            foot: d[7],
        })
    }
}
