//! Typed messages: physical values in, bytes out, and back.
//!
//! All multi-byte fields are little-endian. Physical values are kept in SI units (m, rad,
//! rad/s, percent, µs) in the structs and scaled to integers on the wire; out-of-range values
//! saturate at the field's limits rather than wrap. `docs/protocol.md` has the bit layouts and
//! `presrs.dbc` describes the same layouts for third-party tools.
//!
//! One concept in one file (over 600 lines): the message set, each message's struct beside its
//! encoding, so that the wire layout reads in one place.

use crate::error::DecodeError;
use crate::frame::{CanFrame, make_id};
use crate::ids::{IdConfig, MessageKind};

/// Terrain id meaning "not classified" (no sample, or below the unknown threshold).
pub const TERRAIN_UNKNOWN: u8 = 0xFF;

/// Rounds half away from zero, as `f64::round` does; `core` has no `round` without std, and
/// the firmware build encodes messages too. Exact for the field ranges (below 2^52).
fn round(v: f64) -> f64 {
    let t = v as i64 as f64; // toward zero, saturating; the callers clamp afterwards
    let frac = v - t;
    if frac >= 0.5 {
        t + 1.0
    } else if frac <= -0.5 {
        t - 1.0
    } else {
        t
    }
}

fn sat_u(v: f64, max: f64) -> f64 {
    if v.is_nan() {
        0.0
    } else {
        round(v).clamp(0.0, max)
    }
}

fn sat_i12(v: f64) -> i32 {
    if v.is_nan() {
        0
    } else {
        round(v).clamp(-2048.0, 2047.0) as i32
    }
}

fn sat_i16(v: f64) -> i16 {
    if v.is_nan() {
        0
    } else {
        round(v).clamp(i16::MIN as f64, i16::MAX as f64) as i16
    }
}

fn need(message: &'static str, data: &[u8], n: usize) -> Result<(), DecodeError> {
    if data.len() < n {
        Err(DecodeError::TooShort {
            message,
            need: n,
            got: data.len(),
        })
    } else {
        Ok(())
    }
}

fn u16_at(d: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([d[i], d[i + 1]])
}
fn i16_at(d: &[u8], i: usize) -> i16 {
    i16::from_le_bytes([d[i], d[i + 1]])
}
fn u32_at(d: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([d[i], d[i + 1], d[i + 2], d[i + 3]])
}

/// Scale of leg lengths on the wire: 0.1 mm per bit (0 to 6.5535 m).
pub const LENGTH_SCALE_M: f64 = 1e-4;
/// Scale of angles on the wire: 0.1 mrad per bit (±3.2767 rad).
pub const ANGLE_SCALE_RAD: f64 = 1e-4;
/// Scale of angular frequencies: 1 mrad/s per bit.
pub const OMEGA_SCALE: f64 = 1e-3;
/// Scale of percentages (confidence, damage): 0.5 % per bit (0 to 100 % in 0..200).
pub const PERCENT_SCALE: f64 = 0.5;

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

/// Node state in [`NodeStatus`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum NodeState {
    /// Loading the model, opening the bus.
    #[default]
    Starting = 0,
    /// Classifying.
    Running = 1,
    /// Running, but the bus reported errors or the interface is being reopened.
    Degraded = 2,
    /// No usable model loaded.
    NoModel = 3,
    /// Shutting down: the last status.
    Stopping = 4,
    /// Running, but a foot's latest images are of a size the model does not take: its steps
    /// are not classified (the log says which size; train a model on that foot's images).
    WrongImageSize = 5,
    /// The CAN controller is error-passive (an error counter past 127): frames may be delayed
    /// or lost. From the kernel's error frames; ends with a restart report, or traffic half a
    /// second after the last error frame.
    ErrorPassive = 6,
    /// The CAN controller went bus-off: the node is off the bus until the controller restarts
    /// (`restart-ms`). Seen on the bus only once it is back (this heartbeat is the first after
    /// the episode), and in the node's log at once.
    BusOff = 7,
}

impl NodeState {
    /// The state with wire value `v`.
    pub fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            0 => Self::Starting,
            1 => Self::Running,
            2 => Self::Degraded,
            3 => Self::NoModel,
            4 => Self::Stopping,
            5 => Self::WrongImageSize,
            6 => Self::ErrorPassive,
            7 => Self::BusOff,
            _ => return None,
        })
    }
}

/// Node -> all, 10 Hz: heartbeat and health. Counters are the low 8 bits of running totals, so a
/// monitor takes differences (mod 256) between messages.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct NodeStatus {
    /// Counts up by one per status (wrapping): a stuck value means a stuck node.
    pub heartbeat: u8,
    /// The node's state.
    pub state: NodeState,
    /// Low 16 bits of the loaded model's content hash.
    pub model_id: u16,
    /// Tactile transfers that failed their CRC (saturating).
    pub crc_failures: u8,
    /// Tactile transfers never completed (saturating).
    pub incomplete_frames: u8,
    /// Bus errors on receive or send (saturating).
    pub bus_errors: u8,
    /// Largest sensor damage over the feet, 0..=100 %.
    pub damage_pct: f64,
}

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

impl NodeStatus {
    /// The 8 data bytes (layout in docs/protocol.md).
    pub fn encode(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d[0] = self.heartbeat;
        d[1] = self.state as u8;
        d[2..4].copy_from_slice(&self.model_id.to_le_bytes());
        d[4] = self.crc_failures;
        d[5] = self.incomplete_frames;
        d[6] = self.bus_errors;
        d[7] = sat_u(self.damage_pct / PERCENT_SCALE, 200.0) as u8;
        d
    }

    /// Decodes the data bytes; a short payload or an invalid field is an error.
    pub fn decode(d: &[u8]) -> Result<Self, DecodeError> {
        need("NodeStatus", d, 8)?;
        let state = NodeState::from_u8(d[1]).ok_or(DecodeError::BadValue {
            message: "NodeStatus",
            field: "State",
            value: d[1] as u32,
        })?;
        Ok(Self {
            heartbeat: d[0],
            state,
            model_id: u16_at(d, 2),
            crc_failures: d[4],
            incomplete_frames: d[5],
            bus_errors: d[6],
            damage_pct: d[7] as f64 * PERCENT_SCALE,
        })
    }
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

/// Any message of the protocol. Tactile segments are not decoded here: their payload goes to
/// [`crate::tactile::Reassembler`] straight from the frame, so nothing is copied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Message {
    /// Controller -> leg set points.
    LegCommand(LegCommand),
    /// Foot switch state.
    FootContact(FootContact),
    /// Leg angle and length.
    LegState(LegState),
    /// The leg bridge's health.
    LegStatus(LegStatus),
    /// The terrain of one step.
    TerrainClass(TerrainClass),
    /// Node heartbeat.
    NodeStatus(NodeStatus),
    /// The gait in force.
    GaitStatus(GaitStatus),
    /// One hop as measured.
    StepState(StepState),
    /// A tactile segment (FD or classic variant); read the payload from the frame.
    TactileSegment(crate::tactile::Variant),
}

impl Message {
    /// The kind, which picks the identifier.
    pub fn kind(&self) -> MessageKind {
        match self {
            Message::LegCommand(_) => MessageKind::LegCommand,
            Message::FootContact(_) => MessageKind::FootContact,
            Message::LegState(_) => MessageKind::LegState,
            Message::LegStatus(_) => MessageKind::LegStatus,
            Message::TerrainClass(_) => MessageKind::TerrainClass,
            Message::NodeStatus(_) => MessageKind::NodeStatus,
            Message::GaitStatus(_) => MessageKind::GaitStatus,
            Message::StepState(_) => MessageKind::StepState,
            Message::TactileSegment(crate::tactile::Variant::Fd) => MessageKind::TactileFrame,
            Message::TactileSegment(crate::tactile::Variant::Classic) => {
                MessageKind::TactileFrameClassic
            }
        }
    }

    /// Builds the frame for this message, from `foot` (ignored by single-ID messages).
    /// Tactile segments are built by [`crate::tactile::Segmenter`]; this returns `None` for them.
    pub fn to_frame(&self, ids: &IdConfig, foot: u8) -> Option<CanFrame> {
        let data = match self {
            Message::LegCommand(m) => m.encode(),
            Message::FootContact(m) => m.encode(),
            Message::LegState(m) => m.encode(),
            Message::LegStatus(m) => m.encode(),
            Message::TerrainClass(m) => m.encode(),
            Message::NodeStatus(m) => m.encode(),
            Message::GaitStatus(m) => m.encode(),
            Message::StepState(m) => m.encode(),
            Message::TactileSegment(_) => return None,
        };
        let id = make_id(ids.id(self.kind(), foot), ids.extended)?;
        CanFrame::classic(id, &data)
    }
}

/// Decodes a received frame. `Ok(None)`: the identifier is not one of ours (not an error: the
/// bus is shared). `Err`: ours but malformed; the caller counts it and goes on.
pub fn decode(frame: &CanFrame, ids: &IdConfig) -> Result<Option<(u8, Message)>, DecodeError> {
    let Some((kind, foot)) = ids.lookup(frame.raw_id(), frame.is_extended()) else {
        return Ok(None);
    };
    if frame.is_remote() {
        return Err(DecodeError::Remote {
            message: kind.name(),
        });
    }
    let d = frame.data();
    let tactile = matches!(
        kind,
        MessageKind::TactileFrame | MessageKind::TactileFrameClassic
    );
    // Tactile segments' lengths are the reassembler's to judge (and count).
    if !tactile && (d.len() != kind.dlc() || frame.is_fd() != kind.is_fd()) {
        return Err(DecodeError::WrongLength {
            message: kind.name(),
            want: kind.dlc(),
            got: d.len(),
            fd: frame.is_fd(),
        });
    }
    let msg = match kind {
        MessageKind::LegCommand => Message::LegCommand(LegCommand::decode(d)?),
        MessageKind::FootContact => Message::FootContact(FootContact::decode(d)?),
        MessageKind::LegState => Message::LegState(LegState::decode(d)?),
        MessageKind::LegStatus => Message::LegStatus(LegStatus::decode(d)?),
        MessageKind::TerrainClass => Message::TerrainClass(TerrainClass::decode(d)?),
        MessageKind::NodeStatus => Message::NodeStatus(NodeStatus::decode(d)?),
        MessageKind::GaitStatus => Message::GaitStatus(GaitStatus::decode(d)?),
        MessageKind::StepState => Message::StepState(StepState::decode(d)?),
        MessageKind::TactileFrame => Message::TactileSegment(crate::tactile::Variant::Fd),
        MessageKind::TactileFrameClassic => {
            Message::TactileSegment(crate::tactile::Variant::Classic)
        }
    };
    Ok(Some((foot, msg)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_matches_std_round() {
        for v in [
            0.0, 0.49, 0.5, 0.51, 1.5, 2.5, -0.5, -0.49, -1.5, -2.5, 32767.4, -32768.6, 1e9,
        ] {
            assert_eq!(round(v), v.round(), "{v}");
        }
    }

    fn rt(m: Message, foot: u8) -> Message {
        let ids = IdConfig::default();
        let f = m.to_frame(&ids, foot).unwrap();
        let (gf, got) = decode(&f, &ids).unwrap().unwrap();
        if m.kind().per_foot() {
            assert_eq!(gf, foot);
        }
        got
    }

    #[test]
    fn fixed_layout_messages_are_taken_only_at_their_dbc_length_as_classic_frames() {
        let ids = IdConfig::default();
        let m = Message::FootContact(FootContact {
            stance: true,
            seq: 3,
            timestamp_us: 1234,
        });
        let good = m.to_frame(&ids, 2).unwrap();
        assert_eq!(good.data().len(), 8);
        assert!(matches!(
            decode(&good, &ids),
            Ok(Some((2, Message::FootContact(_))))
        ));
        for n in [0, 6, 7] {
            let f = CanFrame::classic(good.id(), &good.data()[..n]).unwrap();
            assert_eq!(
                decode(&f, &ids),
                Err(DecodeError::WrongLength {
                    message: "FootContact",
                    want: 8,
                    got: n,
                    fd: false
                }),
                "{n} bytes"
            );
        }
        for n in [8, 12, 64] {
            let mut data = [0u8; 64];
            data[..8].copy_from_slice(good.data());
            let f = CanFrame::fd(good.id(), &data[..n], true).unwrap();
            let e = decode(&f, &ids).unwrap_err();
            assert!(e.to_string().contains("as CAN FD"), "{n} bytes: {e}");
        }
    }

    #[test]
    fn round_trips_within_resolution() {
        let lc = LegCommand {
            leg_length_m: 0.3512,
            touchdown_angle_rad: -0.4213,
            gait: 2,
            phase: Phase::Stance,
            seq: 200,
        };
        let Message::LegCommand(g) = rt(Message::LegCommand(lc), 3) else {
            panic!()
        };
        assert!((g.leg_length_m - lc.leg_length_m).abs() <= 0.5e-4);
        assert!((g.touchdown_angle_rad - lc.touchdown_angle_rad).abs() <= 0.5e-4);
        assert_eq!((g.gait, g.phase, g.seq), (2, Phase::Stance, 200));

        let fc = FootContact {
            stance: true,
            seq: 9,
            timestamp_us: 0xDEAD_BEEF,
        };
        assert_eq!(rt(Message::FootContact(fc), 7), Message::FootContact(fc));

        let tc = TerrainClass {
            step: 65000,
            terrain: 11,
            confidence_pct: 97.5,
            damage_pct: 7.0,
            flags: flags::REPAIRED | flags::LOW_CONFIDENCE,
            latency_us: 812,
        };
        assert_eq!(rt(Message::TerrainClass(tc), 0), Message::TerrainClass(tc));

        let ns = NodeStatus {
            heartbeat: 255,
            state: NodeState::Degraded,
            model_id: 0xBEEF,
            crc_failures: 1,
            incomplete_frames: 2,
            bus_errors: 3,
            damage_pct: 12.5,
        };
        assert_eq!(rt(Message::NodeStatus(ns), 0), Message::NodeStatus(ns));

        let gs = GaitStatus {
            gait: 3,
            terrain: 9,
            omega_rad_s: 7.0,
            beta_des_rad: 0.57,
            reason: GaitReason::Terrain,
            foot: 1,
        };
        let Message::GaitStatus(g) = rt(Message::GaitStatus(gs), 0) else {
            panic!()
        };
        assert!((g.omega_rad_s - 7.0).abs() < 1e-9 && (g.beta_des_rad - 0.57).abs() < 1e-9);
    }

    #[test]
    fn saturates_instead_of_wrapping() {
        let tc = TerrainClass {
            confidence_pct: 180.0,
            latency_us: 1_000_000,
            ..Default::default()
        };
        let d = TerrainClass::decode(&tc.encode()).unwrap();
        assert_eq!(d.confidence_pct, 100.0);
        assert_eq!(d.latency_us, 65535);
        let lc = LegCommand {
            leg_length_m: -1.0,
            touchdown_angle_rad: 10.0,
            ..Default::default()
        };
        let d = LegCommand::decode(&lc.encode()).unwrap();
        assert_eq!(d.leg_length_m, 0.0);
        assert!((d.touchdown_angle_rad - 3.2767).abs() < 1e-9);
    }

    #[test]
    fn malformed_frames_are_errors_not_panics() {
        let ids = IdConfig::default();
        let id = make_id(0x100, false).unwrap();
        let short = CanFrame::classic(id, &[1, 2]).unwrap();
        let e = decode(&short, &ids).unwrap_err();
        assert!(
            e.to_string()
                .contains("FootContact must be a classic CAN frame of 8 data bytes"),
            "{e}"
        );
        let bad = CanFrame::classic(id, &[7, 0, 0, 0, 0, 0, 0, 0]).unwrap();
        assert!(matches!(
            decode(&bad, &ids),
            Err(DecodeError::BadValue { .. })
        ));
        let rem = CanFrame::remote(id, 8).unwrap();
        assert!(matches!(
            decode(&rem, &ids),
            Err(DecodeError::Remote { .. })
        ));
        let other = CanFrame::classic(make_id(0x7E5, false).unwrap(), &[]).unwrap();
        assert_eq!(decode(&other, &ids), Ok(None));
        let st =
            CanFrame::classic(make_id(0x280, false).unwrap(), &[0, 9, 0, 0, 0, 0, 0, 0]).unwrap();
        assert!(decode(&st, &ids).is_err());
    }

    #[test]
    fn an_unknown_step_says_why_in_its_flags() {
        let mut tc = TerrainClass {
            terrain: TERRAIN_UNKNOWN,
            ..TerrainClass::default()
        };
        assert_eq!(tc.unknown_reason(), None, "a node before the reason field");
        for r in UnknownReason::ALL {
            tc.flags = r.flag_bits() | flags::REPAIRED;
            let back = TerrainClass::decode(&tc.encode()).unwrap();
            assert_eq!(back.unknown_reason(), Some(r), "{r:?}");
        }
        // A terrain has no reason, whatever bits it carries.
        tc.terrain = 3;
        assert_eq!(tc.unknown_reason(), None);
        // The image checks' codes fit the two bits and keep clear of the other flags.
        for r in [
            UnknownReason::Novelty,
            UnknownReason::Load,
            UnknownReason::Texture,
        ] {
            assert_eq!(r.flag_bits() & !flags::REASON_MASK, 0);
            assert_ne!(r.code(), 0);
        }
    }
}
