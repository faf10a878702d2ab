//! What the node says, as messages: one decision per step, and the heartbeat. The step table
//! and the replay read it as the bus would carry it.

use protocol::messages::{Message, NodeStatus, TerrainClass};
use protocol::{CanFrame, IdConfig};

use crate::stance::Decided;

/// What the node says: frames for the bus, as messages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Output {
    /// One step's decision (exactly one per step).
    Class {
        /// The foot that stepped.
        foot: u8,
        /// The decision.
        class: TerrainClass,
        /// The gait in force when it was decided (the controller's last GaitStatus; `None`
        /// before any): not on the bus frame, which carries the decision alone.
        gait: Option<u8>,
        /// The step's touchdown on the receiver's clock (µs; a replay's: the log's
        /// timestamps): see [`crate::stance::Decided::touchdown_us`].
        touchdown_us: u64,
    },
    /// The heartbeat, at `status_hz`.
    Status(NodeStatus),
}

impl Output {
    /// The step `d` decided with `gait` in force.
    pub(super) fn class(d: Decided, gait: Option<u8>) -> Self {
        Output::Class {
            foot: d.foot,
            class: d.class,
            gait,
            touchdown_us: d.touchdown_us,
        }
    }

    /// The frame that carries this on `ids`: TerrainClass on its foot's id, NodeStatus on
    /// the node's.
    pub fn to_frame(&self, ids: &IdConfig) -> Option<CanFrame> {
        match *self {
            Output::Class { foot, class, .. } => Message::TerrainClass(class).to_frame(ids, foot),
            Output::Status(s) => Message::NodeStatus(s).to_frame(ids, 0),
        }
    }
}
