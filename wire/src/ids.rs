//! CAN identifiers: the default map, relocation by configuration, and 29-bit extended IDs.
//!
//! Every message has a *base* identifier; per-foot messages occupy `base + f` for foot
//! `f = 0..7`. Lower identifiers win arbitration, so the defaults order the traffic as
//! control (leg commands) before sensing (contact, leg state), results (terrain class), status,
//! and bulk tactile data last. On a bus shared with CANopen devices the defaults overlap some
//! predefined CANopen ranges (see `docs/protocol.md`); move them with an [`IdConfig`].

#[cfg(feature = "alloc")]
use alloc::vec::Vec;

use serde::{Deserialize, Serialize};

use crate::error::ConfigError;

/// Feet served by one bus (`f = 0..MAX_FEET-1`).
pub const MAX_FEET: u8 = 8;

/// Which message an identifier carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum MessageKind {
    /// Controller -> leg set points.
    LegCommand,
    /// Foot switch state.
    FootContact,
    /// Leg angle and length.
    LegState,
    /// Leg -> all: the leg bridge's state, its faulted joint and the command's age.
    LegStatus,
    /// Node -> all: the terrain of one step.
    TerrainClass,
    /// Node heartbeat.
    NodeStatus,
    /// Controller -> all: the gait in force.
    GaitStatus,
    /// Controller -> all: each hop as measured (speed, stance and flight time, angles).
    StepState,
    /// Tactile image segments, CAN FD variant (64-byte frames).
    TactileFrame,
    /// Tactile image segments, classic CAN variant (8-byte frames).
    TactileFrameClassic,
}

impl MessageKind {
    /// Every kind, in priority order (lowest identifier first).
    pub const ALL: [MessageKind; 10] = [
        MessageKind::LegCommand,
        MessageKind::FootContact,
        MessageKind::LegState,
        MessageKind::LegStatus,
        MessageKind::TerrainClass,
        MessageKind::NodeStatus,
        MessageKind::GaitStatus,
        MessageKind::StepState,
        MessageKind::TactileFrame,
        MessageKind::TactileFrameClassic,
    ];

    /// Messages sent once per foot (`base + f`); the others have a single identifier.
    pub fn per_foot(self) -> bool {
        !matches!(self, MessageKind::NodeStatus | MessageKind::GaitStatus)
    }

    /// The message's name as in the DBC.
    pub fn name(self) -> &'static str {
        match self {
            MessageKind::LegCommand => "LegCommand",
            MessageKind::FootContact => "FootContact",
            MessageKind::LegState => "LegState",
            MessageKind::LegStatus => "LegStatus",
            MessageKind::TerrainClass => "TerrainClass",
            MessageKind::NodeStatus => "NodeStatus",
            MessageKind::GaitStatus => "GaitStatus",
            MessageKind::StepState => "StepState",
            MessageKind::TactileFrame => "TactileFrame",
            MessageKind::TactileFrameClassic => "TactileFrameClassic",
        }
    }

    /// Payload length on the bus (the DBC's message size).
    pub fn dlc(self) -> usize {
        match self {
            MessageKind::TactileFrame => 64,
            _ => 8,
        }
    }

    /// Sent as CAN FD frames.
    pub fn is_fd(self) -> bool {
        matches!(self, MessageKind::TactileFrame)
    }
}

/// The identifier map. Every base is configurable; `extended` switches all of them to 29-bit
/// identifiers (the bases are then read as 29-bit values).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IdConfig {
    /// 29-bit identifiers (CAN 2.0B); default 11-bit.
    pub extended: bool,
    /// Base identifier of LegCommand (foot 0; foot i adds i).
    pub leg_command: u32,
    /// Base identifier of FootContact.
    pub foot_contact: u32,
    /// Base identifier of LegState.
    pub leg_state: u32,
    /// Base identifier of LegStatus.
    pub leg_status: u32,
    /// Base identifier of TerrainClass.
    pub terrain_class: u32,
    /// Identifier of NodeStatus.
    pub node_status: u32,
    /// Base identifier of GaitStatus.
    pub gait_status: u32,
    /// Base identifier of StepState (foot i adds i).
    pub step_state: u32,
    /// Base identifier of the CAN FD tactile segments.
    pub tactile_frame: u32,
    /// Base identifier of the classic-CAN tactile segments.
    pub tactile_frame_classic: u32,
}

impl Default for IdConfig {
    fn default() -> Self {
        Self {
            extended: false,
            leg_command: 0x0A0,
            foot_contact: 0x100,
            leg_state: 0x120,
            leg_status: 0x140,
            terrain_class: 0x200,
            node_status: 0x280,
            gait_status: 0x290,
            step_state: 0x220,
            tactile_frame: 0x600,
            tactile_frame_classic: 0x680,
        }
    }
}

impl IdConfig {
    /// A map for buses shared with CANopen devices (CiA 301 predefined connection set): the
    /// control and sensing messages move to the unused 0x040-0x07F block (high priority, below
    /// SYNC 0x080), the tactile stream to the unused 0x6C0 block and classic tactile to 0x6E0.
    pub fn canopen_friendly() -> Self {
        Self {
            extended: false,
            leg_command: 0x040,
            foot_contact: 0x048,
            leg_state: 0x050,
            leg_status: 0x068,
            terrain_class: 0x058,
            node_status: 0x060,
            gait_status: 0x061,
            step_state: 0x070,
            tactile_frame: 0x6C0,
            tactile_frame_classic: 0x6E0,
        }
    }

    /// The base identifier of `kind` (foot 0's).
    pub fn base(&self, kind: MessageKind) -> u32 {
        match kind {
            MessageKind::LegCommand => self.leg_command,
            MessageKind::FootContact => self.foot_contact,
            MessageKind::LegState => self.leg_state,
            MessageKind::LegStatus => self.leg_status,
            MessageKind::TerrainClass => self.terrain_class,
            MessageKind::NodeStatus => self.node_status,
            MessageKind::GaitStatus => self.gait_status,
            MessageKind::StepState => self.step_state,
            MessageKind::TactileFrame => self.tactile_frame,
            MessageKind::TactileFrameClassic => self.tactile_frame_classic,
        }
    }

    /// The identifiers a message occupies: `[base, base + span)`.
    pub fn span(kind: MessageKind) -> u32 {
        if kind.per_foot() { MAX_FEET as u32 } else { 1 }
    }

    /// The identifier of `kind` for foot `foot` (ignored for single-ID messages).
    pub fn id(&self, kind: MessageKind, foot: u8) -> u32 {
        if kind.per_foot() {
            self.base(kind) + (foot % MAX_FEET) as u32
        } else {
            self.base(kind)
        }
    }

    /// What a received identifier carries, and for which foot. `None`: not ours.
    pub fn lookup(&self, raw_id: u32, extended: bool) -> Option<(MessageKind, u8)> {
        if extended != self.extended {
            return None;
        }
        MessageKind::ALL.into_iter().find_map(|kind| {
            let base = self.base(kind);
            (raw_id >= base && raw_id < base + Self::span(kind))
                .then(|| (kind, (raw_id - base) as u8))
        })
    }

    /// Checks that every range fits the identifier width and that no two ranges overlap.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let max = self.id_mask();
        for kind in MessageKind::ALL {
            let last = self.base(kind) + Self::span(kind) - 1;
            if last > max {
                return Err(ConfigError::IdOutOfRange {
                    message: kind.name(),
                    base: self.base(kind),
                    last,
                    max,
                });
            }
        }
        for (i, a) in MessageKind::ALL.iter().enumerate() {
            for b in &MessageKind::ALL[i + 1..] {
                let (a0, b0) = (self.base(*a), self.base(*b));
                let (a1, b1) = (a0 + Self::span(*a), b0 + Self::span(*b));
                if a0 < b1 && b0 < a1 {
                    return Err(ConfigError::IdOverlap {
                        a: a.name(),
                        b: b.name(),
                    });
                }
            }
        }
        Ok(())
    }

    /// Every bit of an identifier of this map's width (29 or 11 bits).
    pub fn id_mask(&self) -> u32 {
        if self.extended { 0x1FFF_FFFF } else { 0x7FF }
    }

    /// The receive filter `(id, mask)` that passes exactly `kind` of foot `foot`.
    pub fn foot_filter(&self, kind: MessageKind, foot: u8) -> (u32, u32) {
        (self.id(kind, foot), self.id_mask())
    }

    /// The receive filter `(id, mask)` list that passes exactly the given messages.
    #[cfg(feature = "alloc")]
    pub fn filters(&self, kinds: &[MessageKind]) -> Vec<(u32, u32)> {
        let width = self.id_mask();
        let mut out = Vec::new();
        for &kind in kinds {
            let base = self.base(kind);
            if kind.per_foot() && base.is_multiple_of(MAX_FEET as u32) {
                out.push((base, width & !(MAX_FEET as u32 - 1)));
            } else {
                for f in 0..Self::span(kind) {
                    out.push((base + f, width));
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_ordered_by_priority() {
        let c = IdConfig::default();
        c.validate().unwrap();
        assert!(c.leg_command < c.foot_contact);
        assert!(c.foot_contact < c.terrain_class);
        assert!(c.terrain_class < c.tactile_frame);
        IdConfig::canopen_friendly().validate().unwrap();
    }

    #[test]
    fn lookup_maps_every_id_back() {
        for c in [IdConfig::default(), IdConfig::canopen_friendly()] {
            for kind in MessageKind::ALL {
                for f in 0..IdConfig::span(kind) as u8 {
                    assert_eq!(c.lookup(c.id(kind, f), false), Some((kind, f)));
                }
            }
            assert_eq!(c.lookup(0x7FF, false), None);
            assert_eq!(c.lookup(c.foot_contact, true), None);
        }
    }

    #[test]
    fn overlap_and_range_rejected() {
        let c = IdConfig {
            leg_state: 0x104,
            ..IdConfig::default()
        };
        assert!(matches!(c.validate(), Err(ConfigError::IdOverlap { .. })));
        let c = IdConfig {
            tactile_frame: 0x7FC,
            ..IdConfig::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("TactileFrame"), "{e}");
        let c = IdConfig {
            extended: true,
            tactile_frame: 0x1234_5600,
            ..IdConfig::default()
        };
        c.validate().unwrap();
    }

    #[test]
    fn filters_pass_the_ranges() {
        let c = IdConfig::default();
        let f = c.filters(&[MessageKind::FootContact, MessageKind::NodeStatus]);
        let pass = |id: u32| f.iter().any(|(fid, m)| id & m == fid & m);
        assert!(pass(0x100) && pass(0x107) && pass(0x280));
        assert!(!pass(0x108) && !pass(0x281) && !pass(0x0A0));
    }
}
