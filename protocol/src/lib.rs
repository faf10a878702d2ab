#![warn(missing_docs)]
//! # presrs-protocol: the PreSRS terrain node's CAN protocol on a computer (std)
//!
//! A legged robot's foot carries PreSRS, a 44x44 tactile array sampled at 100 Hz. The foot
//! broadcasts its micro-switch ([`messages::FootContact`]) and its pressure images
//! ([`tactile`], segmented over CAN FD); the node classifies the terrain once per step and
//! broadcasts [`messages::TerrainClass`]; the controller turns terrain into gait parameters
//! ([`messages::GaitStatus`]) and leg set points ([`messages::LegCommand`]).
//!
//! One module per concept:
//! - [`frame`]: the frame type ([`CanFrame`], classic or FD, `embedded-can` compatible) and
//!   [`Stamped`] frames with their receive time;
//! - [`ids`]: the identifier map, relocatable per message, 11- or 29-bit;
//! - [`messages`]: typed messages and their byte layouts;
//! - [`tactile`]: segmentation and reassembly of pressure images; [`foot`]: the foot's sender,
//!   over any `embedded-can` driver (firmware);
//! - [`terrain`]: the terrain type and the catalog of terrain ids (the paper's and a lab's own);
//! - [`dbc`]: the DBC file for any CAN tool; [`candump`]: can-utils log files;
//! - [`bus`]: SocketCAN and an in-process bus behind one trait; [`clock`]: time sources;
//! - [`component`]: the one shape of every part on the bus (node, controller, simulated
//!   robot, capture, recorder) and the one loop that runs it on a bus;
//! - [`emit`]: the one way a part hands on what it makes ([`emit::Emit`]);
//! - [`config`]: the one config-file loader and its errors; [`error`]: the error types.
//!
//! ## On the foot's microcontroller
//!
//! The wire format (frames, identifiers, messages, tactile segments, the foot's sender, the
//! errors) is the `no_std` crate `presrs-wire`, re-exported here module by module: a foot's
//! firmware links that crate alone (`examples/foot_firmware.rs` is a foot written that way);
//! this one is the std runtime around it.
//!
//! ```
//! use presrs_protocol::{bus::{CanBus, InProcBus}, ids::IdConfig, messages::*};
//! let bus = InProcBus::new();
//! let (mut foot, mut node) = (bus.endpoint(), bus.endpoint());
//! let ids = IdConfig::default();
//! let touchdown = Message::FootContact(FootContact { stance: true, seq: 1, timestamp_us: 0 });
//! foot.send(&touchdown.to_frame(&ids, 0).unwrap()).unwrap();
//! let rx = node.recv(std::time::Duration::from_millis(100)).unwrap().unwrap();
//! assert_eq!(decode(&rx.frame, &ids).unwrap(), Some((0, touchdown)));
//! ```

pub mod bus;
pub mod candump;
pub mod clock;
pub mod component;
pub mod config;
pub mod dbc;
pub mod error;
pub mod terrain;
pub mod traffic;

pub use wire::{emit, foot, frame, ids, messages, quantile, tactile};

pub use error::{BusError, ConfigError, DecodeError};
pub use frame::{CanFrame, Stamped};
pub use ids::{IdConfig, MessageKind};
pub use messages::Message;
pub use terrain::{Terrain, TerrainCatalog, TerrainsArg};
