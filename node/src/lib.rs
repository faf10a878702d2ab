//! # presrs-node: terrain classification from a tactile foot
//!
//! The [`classifier`] implements the method of Shill et al. 2014 (PreSRS): a pressure image
//! taken ~70 ms after touchdown, cropped, rows concatenated and zero-padded to a power of two,
//! FFT magnitude as the feature vector, PCA, and a Parzen-window classifier; plus the paper's
//! repair filter for dead sensor rows and columns.

pub mod classifier;
pub mod config;
pub mod health;
pub mod stance;

pub use config::{NodeConfig, RefitMode, RepairMode};
pub use stance::StancePipeline;
