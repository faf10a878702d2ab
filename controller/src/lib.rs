#![forbid(unsafe_code)]
#![warn(missing_docs)]
//! # presrs-controller: the hopper's control laws and per-terrain gait switching
//!
//! - [`laws`]: eq. (4), the AER stance leg length, and eq. (5), the flight touchdown angle;
//! - [`gait`]: gaits `G_i(omega, phi, c, beta_des)`, the paper's G1..G3 as defaults;
//! - [`machine`]: the state machine that runs the laws and switches gait per terrain;
//! - [`service`]: its loop on a bus, as `presrs controller` runs it;
//! - [`stride`]: each hop measured from the foot switch and LegState (speed, stance, flight).

pub mod config;
pub mod gait;
pub mod laws;
pub mod machine;
pub mod service;
pub mod stride;

pub use config::ControllerConfig;
pub use gait::Gait;
pub use machine::Controller;
