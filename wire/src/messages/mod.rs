//! Typed messages: physical values in, bytes out, and back.
//!
//! All multi-byte fields are little-endian. Physical values are kept in SI units (m, rad,
//! rad/s, percent, µs) in the structs and scaled to integers on the wire; out-of-range values
//! saturate at the field's limits rather than wrap. `docs/protocol.md` has the bit layouts and
//! `presrs.dbc` describes the same layouts for third-party tools.
//!
//! One file per message (its struct beside its encoding, so that its wire layout reads in one
//! place); here the shared scales and saturating conversions, [`Message`] and [`decode`].

use crate::error::DecodeError;
use crate::frame::{CanFrame, make_id};
use crate::ids::{IdConfig, MessageKind};

mod foot_contact;
mod gait_status;
mod leg;
mod node_status;
mod step_state;
mod terrain_class;

pub use foot_contact::FootContact;
pub use gait_status::{GaitReason, GaitStatus};
pub use leg::{LegCommand, LegMode, LegState, LegStatus, Phase};
pub use node_status::{NodeState, NodeStatus};
pub use step_state::{
    ENERGY_RATIO_SCALE, PHASE_TIME_SCALE_S, SPEED_SCALE_M_S, STEP_ANGLE_SCALE_RAD, StepState,
};
pub use terrain_class::{LATENCY_MAX_US, TerrainClass, UnknownReason, flags};

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
