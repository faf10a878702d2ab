#![warn(missing_docs)]
//! # presrs-sim: the simulated hopper and foot
pub mod dataset;
pub mod faults;
pub mod field;
pub mod fixed_gait;
pub mod hopper;
pub mod runner;
pub mod service;
pub mod skin;
pub mod terrain;

/// Changes whenever the simulator's output for a given seed changes (hopper parameters, terrain
/// textures, skin), so that models trained and cached from simulated data can tell they are stale.
pub const SIM_VERSION: u32 = 4;

/// The serial number of the simulated foot sensor when none is given: datasets and simulated
/// runs use the same sensor unless told otherwise, as a real robot's training data comes from
/// its own foot. (Foot `i` of a multi-legged run wears sensor `serial + i`.)
pub const DEFAULT_SENSOR: u64 = 1;
