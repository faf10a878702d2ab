//! # presrs-sim: the simulated hopper and foot
pub mod dataset;
pub mod faults;
pub mod field;
pub mod fixed_gait;
pub mod hopper;
pub mod runner;
pub mod skin;
pub mod terrain;
