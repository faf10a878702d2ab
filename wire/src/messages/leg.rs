//! The leg's messages: the controller's set points (LegCommand), the measured leg
//! (LegState) and the leg bridge's health (LegStatus, LegMode).

use crate::error::DecodeError;

use super::{ANGLE_SCALE_RAD, LENGTH_SCALE_M, i16_at, need, sat_i16, sat_u, u16_at, u32_at};

/// Stance or flight.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Phase {
    /// Foot off the ground.
    #[default]
    Flight = 0,
    /// Foot on the ground.
    Stance = 1,
}

/// Controller -> leg: set points for the next control period.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct LegCommand {
    /// Leg length set point zeta (m), eq. (4) in stance.
    pub leg_length_m: f64,
    /// Touchdown angle set point beta_TD (rad), eq. (5) in flight.
    pub touchdown_angle_rad: f64,
    /// Gait in force (1..=3 for G1..G3; 0 none).
    pub gait: u8,
    /// Stance or flight.
    pub phase: Phase,
    /// Wrapping counter, one per command.
    pub seq: u8,
}

impl LegCommand {
    /// The 8 data bytes (layout in docs/protocol.md).
    pub fn encode(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d[0..2].copy_from_slice(
            &(sat_u(self.leg_length_m / LENGTH_SCALE_M, 65535.0) as u16).to_le_bytes(),
        );
        d[2..4].copy_from_slice(&sat_i16(self.touchdown_angle_rad / ANGLE_SCALE_RAD).to_le_bytes());
        d[4] = self.gait;
        d[5] = self.phase as u8;
        d[6] = self.seq;
        d
    }

    /// Decodes the data bytes; a short payload or an invalid field is an error.
    pub fn decode(d: &[u8]) -> Result<Self, DecodeError> {
        need("LegCommand", d, 7)?;
        let phase = match d[5] {
            0 => Phase::Flight,
            1 => Phase::Stance,
            v => {
                return Err(DecodeError::BadValue {
                    message: "LegCommand",
                    field: "Phase",
                    value: v as u32,
                });
            }
        };
        Ok(Self {
            leg_length_m: u16_at(d, 0) as f64 * LENGTH_SCALE_M,
            touchdown_angle_rad: i16_at(d, 2) as f64 * ANGLE_SCALE_RAD,
            gait: d[4],
            phase,
            seq: d[6],
        })
    }
}

/// Leg -> all: measured leg angle and length.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct LegState {
    /// Leg angle beta from the vertical (rad), positive with the foot ahead of the hip.
    pub leg_angle_rad: f64,
    /// Leg length, m.
    pub leg_length_m: f64,
    /// Sender clock, µs, wrapping.
    pub timestamp_us: u32,
}

impl LegState {
    /// The 8 data bytes (layout in docs/protocol.md).
    pub fn encode(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d[0..2].copy_from_slice(&sat_i16(self.leg_angle_rad / ANGLE_SCALE_RAD).to_le_bytes());
        d[2..4].copy_from_slice(
            &(sat_u(self.leg_length_m / LENGTH_SCALE_M, 65535.0) as u16).to_le_bytes(),
        );
        d[4..8].copy_from_slice(&self.timestamp_us.to_le_bytes());
        d
    }

    /// Decodes the data bytes; a short payload or an invalid field is an error.
    pub fn decode(d: &[u8]) -> Result<Self, DecodeError> {
        need("LegState", d, 8)?;
        Ok(Self {
            leg_angle_rad: i16_at(d, 0) as f64 * ANGLE_SCALE_RAD,
            leg_length_m: u16_at(d, 2) as f64 * LENGTH_SCALE_M,
            timestamp_us: u32_at(d, 4),
        })
    }
}

/// What the leg bridge is doing with its motors.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LegMode {
    /// No LegCommand yet: no joint has been moved since start-up.
    #[default]
    Waiting = 0,
    /// Following fresh LegCommands.
    Running = 1,
    /// Damped stop: no LegCommand for the command timeout; fresh commands resume.
    CommandTimeout = 2,
    /// Damped stop: a driver reported a fault (its code in FaultCode).
    DriverFault = 3,
    /// Damped stop: a driver stopped replying.
    DriverSilent = 4,
    /// Every motor stopped at exit.
    Stopped = 5,
    /// `presrs leg --check`: reading the joints, moving nothing.
    Check = 6,
}

impl LegMode {
    /// The mode with wire value `v`.
    pub fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            0 => Self::Waiting,
            1 => Self::Running,
            2 => Self::CommandTimeout,
            3 => Self::DriverFault,
            4 => Self::DriverSilent,
            5 => Self::Stopped,
            6 => Self::Check,
            _ => return None,
        })
    }

    /// True where every joint is held in the damped stop (or never moved).
    pub fn is_stopped(self) -> bool {
        !matches!(self, Self::Running)
    }
}

/// Leg -> all, 10 Hz and at every change: the leg bridge's health.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct LegStatus {
    /// What the bridge does with the motors.
    pub mode: LegMode,
    /// The joint at fault: 0 none, 1 the hip, 2 the length joint (knee or screw).
    pub joint: u8,
    /// Age of the last LegCommand, ms (saturating; 65535: none yet).
    pub command_age_ms: u16,
    /// The driver's own fault code (moteus fault, ODrive axis error, MIT error byte); 0 none.
    pub fault_code: u32,
}

impl LegStatus {
    /// The 8 data bytes (layout in docs/protocol.md).
    pub fn encode(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d[0] = self.mode as u8;
        d[1] = self.joint;
        d[2..4].copy_from_slice(&self.command_age_ms.to_le_bytes());
        d[4..8].copy_from_slice(&self.fault_code.to_le_bytes());
        d
    }

    /// Decodes the data bytes; a short payload or an invalid field is an error.
    pub fn decode(d: &[u8]) -> Result<Self, DecodeError> {
        need("LegStatus", d, 8)?;
        let mode = LegMode::from_u8(d[0]).ok_or(DecodeError::BadValue {
            message: "LegStatus",
            field: "Mode",
            value: d[0] as u32,
        })?;
        if d[1] > 2 {
            return Err(DecodeError::BadValue {
                message: "LegStatus",
                field: "Joint",
                value: d[1] as u32,
            });
        }
        Ok(Self {
            mode,
            joint: d[1],
            command_age_ms: u16_at(d, 2),
            fault_code: u32_at(d, 4),
        })
    }
}
