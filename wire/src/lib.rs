#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
//! # presrs-wire: the PreSRS terrain node's CAN wire format
//!
//! What every part on the bus agrees on, and all a foot's firmware links: `#![no_std]`, and
//! without its default `alloc` feature it allocates nothing.
//!
//! - [`frame`]: the frame type ([`CanFrame`], classic or FD, `embedded-can` compatible) and
//!   [`Stamped`] frames with their receive time;
//! - [`ids`]: the identifier map, relocatable per message, 11- or 29-bit;
//! - [`messages`]: typed messages and their byte layouts;
//! - [`tactile`]: segmentation (and, with `alloc`, reassembly) of pressure images;
//! - [`foot`]: the foot's sender, over any `embedded-can` driver;
//! - [`emit`]: the one way a part hands on what it makes; [`quantile`]: the one percentile rule;
//! - [`error`]: an identifier map that cannot work, a frame that does not decode.
//!
//! The std runtime (SocketCAN and the in-process bus, components, clocks, config files, candump
//! logs, the DBC, the terrain catalog) is `presrs-protocol`, which re-exports these modules.
//! The test command builds this crate for a Cortex-M4F:
//! `cargo build -p presrs-wire --no-default-features --target thumbv7em-none-eabihf`;
//! `protocol/examples/foot_firmware.rs` is a foot written that way.

#[cfg(feature = "alloc")]
extern crate alloc;

pub mod emit;
pub mod error;
pub mod foot;
pub mod frame;
pub mod ids;
pub mod messages;
pub mod quantile;
pub mod tactile;

pub use error::{ConfigError, DecodeError};
pub use frame::{CanFrame, Stamped};
pub use ids::{IdConfig, MessageKind};
pub use messages::Message;
