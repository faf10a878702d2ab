//! The leg: LegCommand to the motor drivers labs build hoppers from, LegState from their
//! encoders.
//!
//! Our controller speaks [`LegCommand`](protocol::messages::LegCommand) (leg length and
//! touchdown angle set points, with the phase) and reads
//! [`LegState`](protocol::messages::LegState). No motor driver understands either. This crate
//! is the bridge between them, in the same shape as every other part on the bus (a
//! [`Component`](protocol::component::Component)):
//!
//! - [`config`]: `leg.toml`, the leg's geometry, joints, drivers, impedance and timeouts,
//!   checked key by key (a joint without a driver id, a link length <= 0, a stiffness over the
//!   driver's range, two joints on one id, a driver id that is one of ours on a shared bus);
//! - [`kinematics`]: prismatic and two-link legs, inverse and forward;
//! - [`driver`]: moteus (through mjbots' `moteus-protocol`), ODrive CANSimple and the MIT
//!   protocol, each with the motor's side the simulator answers with;
//! - [`bridge`]: [`LegService`], the component: impedance at `rate_hz`, the damped stop on a
//!   stale command or a driver fault, LegState and LegStatus;
//! - [`simulated`]: a simulated leg's two motors, for `presrs lab sim --leg`.
#![forbid(unsafe_code)]

pub mod bridge;
pub mod config;
pub mod driver;
pub mod kinematics;
pub mod simulated;

pub use bridge::{LegCounters, LegService};
pub use config::{DriverKind, LegConfig};
pub use kinematics::Kinematics;
