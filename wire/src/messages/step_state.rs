//! StepState: one hop as the controller measured it, and its wire units.

use crate::error::DecodeError;

use super::{i16_at, need, sat_i12, sat_i16, sat_u};

/// Controller -> all: one hop, touchdown to the next touchdown, measured from the foot switch
/// and LegState (the bus carries no speed sensor; the estimate is the controller's
/// `stride` module's). Sent at the touchdown that closes the hop, on the foot's identifier.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct StepState {
    /// Forward speed over the hop, m/s.
    pub speed_m_s: f64,
    /// Stance time, s (0 to 0.51 on the wire).
    pub stance_s: f64,
    /// Flight time, s (0 to 0.51 on the wire).
    pub flight_s: f64,
    /// Leg angle at touchdown, rad (positive with the foot ahead of the hip; ±2.047 on the
    /// wire).
    pub touchdown_angle_rad: f64,
    /// Leg angle at liftoff, rad (negative with the foot behind).
    pub liftoff_angle_rad: f64,
    /// The body's energy at liftoff over that at touchdown: above 1 the stance put energy
    /// in (0 to 1.99 on the wire).
    pub energy_ratio: f64,
}

/// StepState's speed unit, m/s (1 mm/s).
pub const SPEED_SCALE_M_S: f64 = 1e-3;
/// StepState's stance and flight time unit, s (2 ms: a byte holds up to 0.51 s).
pub const PHASE_TIME_SCALE_S: f64 = 2e-3;
/// StepState's angle unit, rad (1 mrad in 12 bits: the hop's angles are well inside ±2 rad).
pub const STEP_ANGLE_SCALE_RAD: f64 = 1e-3;
/// StepState's energy ratio unit (1/128 in a byte).
pub const ENERGY_RATIO_SCALE: f64 = 1.0 / 128.0;

impl StepState {
    /// The 8 data bytes (layout in docs/protocol.md).
    pub fn encode(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d[0..2].copy_from_slice(&sat_i16(self.speed_m_s / SPEED_SCALE_M_S).to_le_bytes());
        d[2] = sat_u(self.stance_s / PHASE_TIME_SCALE_S, 255.0) as u8;
        d[3] = sat_u(self.flight_s / PHASE_TIME_SCALE_S, 255.0) as u8;
        // Two signed 12-bit angles in bytes 4-6, little-endian bit order as the DBC says.
        let angle = |a: f64| (sat_i12(a / STEP_ANGLE_SCALE_RAD) as u32) & 0xFFF;
        let packed = angle(self.touchdown_angle_rad) | angle(self.liftoff_angle_rad) << 12;
        d[4..7].copy_from_slice(&packed.to_le_bytes()[..3]);
        d[7] = sat_u(self.energy_ratio / ENERGY_RATIO_SCALE, 255.0) as u8;
        d
    }

    /// Decodes the data bytes; a short payload is an error.
    pub fn decode(d: &[u8]) -> Result<Self, DecodeError> {
        need("StepState", d, 8)?;
        let packed = u32::from_le_bytes([d[4], d[5], d[6], 0]);
        // The 12-bit field's sign bit carried up: shifted to the top and back.
        let i12 = |v: u32| ((v << 20) as i32) >> 20;
        Ok(Self {
            speed_m_s: i16_at(d, 0) as f64 * SPEED_SCALE_M_S,
            stance_s: d[2] as f64 * PHASE_TIME_SCALE_S,
            flight_s: d[3] as f64 * PHASE_TIME_SCALE_S,
            touchdown_angle_rad: i12(packed & 0xFFF) as f64 * STEP_ANGLE_SCALE_RAD,
            liftoff_angle_rad: i12(packed >> 12) as f64 * STEP_ANGLE_SCALE_RAD,
            energy_ratio: d[7] as f64 * ENERGY_RATIO_SCALE,
        })
    }
}
