//! NodeStatus: the node's heartbeat and health, and its state.

use crate::error::DecodeError;

use super::{PERCENT_SCALE, need, sat_u, u16_at};

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
