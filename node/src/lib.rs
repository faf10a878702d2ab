#![warn(missing_docs)]
//! # presrs-node: terrain classification from a tactile foot
//!
//! The [`classifier`] implements the method of Shill et al. 2014 (PreSRS): a pressure image
//! taken ~70 ms after touchdown, cropped, rows concatenated and zero-padded to a power of two,
//! FFT magnitude as the feature vector, PCA, and a Parzen-window classifier; plus the paper's
//! repair filter for dead sensor rows and columns.
//!
//! The [`NodeService`] is the node: stance tracking, the sampled frame, the decision and the
//! heartbeat, on its own threads on a bus or driven in lock-step by a caller's clock. The
//! `presrs node` process is this program plus signal handling:
//!
//! ```no_run
//! use std::path::Path;
//! use std::time::Duration;
//!
//! use presrs_node::classifier::Model;
//! use presrs_node::{NodeConfig, NodeService};
//! use protocol::bus::BusSource; // the presrs-protocol crate
//!
//! fn main() -> Result<(), Box<dyn std::error::Error>> {
//!     let config = NodeConfig::load(Path::new("/etc/presrs/node.toml"))?;
//!     let model = Model::load(Path::new("/var/lib/presrs/model.json"))?;
//!     // Checks the model's terrains against the config's catalog, then opens can0 (waiting
//!     // for it if it is not up yet) and answers every step with one TerrainClass.
//!     let node = NodeService::new(config, model)?.start(BusSource::Iface("can0".into()))?;
//!     for _ in 0..600 {
//!         std::thread::sleep(Duration::from_millis(100));
//!         let s = node.stats();
//!         println!("{:?}: {} steps, {} classified", s.state, s.steps, s.classified);
//!     }
//!     node.stop();
//!     Ok(())
//! }
//! ```

pub mod capture;
pub mod classifier;
pub mod config;
pub mod gait_status;
pub mod health;
pub mod order_stats;
pub mod replay;
pub mod service;
pub mod stance;
pub mod step_table;
pub mod training;
pub mod truth;
pub mod unknown;

pub use config::{NodeConfig, RefitMode, RepairMode};
pub use service::{
    NodeService, NodeStats, NodeThreads, Output, RunningNode, ServiceError, StageTimes,
};
pub use stance::StancePipeline;
