#![warn(missing_docs)]
//! # presrs-lab: the closed loop and the scoring, as a library
//!
//! What a gait-adaptation experiment needs besides the robot: [`closed_loop::run`] puts the
//! simulated hopper ([`sim`]), the terrain node ([`node::NodeService`]) and the gait controller
//! ([`controller::Controller`]) on one in-process bus in lock-step simulated time, and
//! [`score`] turns its steps into the numbers the paper reports (per-step accuracy, confusion,
//! steps from a terrain change to its gait, speed per terrain and gait). The demo, the
//! experiments and the benchmarks all score with these functions, so a number means the same
//! thing wherever it is printed.
//!
//! Also here: [`study`] (the damage study, the per-gait tables, speeds: data, not text),
//! [`open_set`] (unknown ground: leave one class out per source of images, judged on a fresh
//! run),
//! [`model`] (the simulator model the demo caches), [`load`] (the load `presrs lab bench-node`
//! plays: feet at 100 Hz on a known schedule, the node under it in this process or as a
//! process, and `/proc` CPU and memory readers) and, with the default `report` feature,
//! [`report`] (the paper's experiments as Markdown and PNG figures, on the simulator or on a
//! lab's own dataset). The lab's tools for a real robot (`eval`, a candump log to MCAP, the
//! recording's picture) are the `presrs-tools` crate, which needs no simulator.
//!
//! ```no_run
//! use presrs_lab::{closed_loop, model, score};
//!
//! let catalog = protocol::TerrainCatalog::paper();
//! let track = sim::runner::Track::from_toml(
//!     "diameter_m = 2.8\n[[segments]]\nterrain = \"wood\"\nlength_m = 2.0\n\
//!      [[segments]]\nterrain = \"clay\"\nlength_m = 2.0\n",
//!     "track.toml",
//!     &catalog,
//! )?;
//! let (model, _) = model::load_or_train(None, || {})?;
//! let cfg = controller::ControllerConfig::default();
//! let run = closed_loop::run(&track, model, &closed_loop::LoopParams::with_controller(&cfg, 60, 1), |_| {})?;
//! let s = score::Summary::of(&run.rows, &cfg.terrain_gaits);
//! println!("{:.1}% of steps right, switches after {:?} steps", s.accuracy * 100.0, s.steps_to_switch);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod closed_loop;
pub mod feet;
pub mod gait_table;
pub mod load;
pub mod model;
pub mod open_set;
#[cfg(feature = "report")]
pub mod report;
pub mod score;
pub mod simdata;
pub mod study;

pub use closed_loop::{LoopParams, LoopRun};
pub use score::Summary;
pub use sim::service::StepRecord;
pub use tools::eval::Confusion;

/// Why a lab run could not run.
#[derive(Debug, thiserror::Error)]
pub enum LabError {
    /// The in-process bus.
    #[error("in-process bus: {0}")]
    Bus(#[from] protocol::BusError),
    /// The node refused its config or model.
    #[error(transparent)]
    Node(#[from] node::ServiceError),
    /// A terrains file.
    #[error(transparent)]
    Catalog(#[from] protocol::terrain::CatalogError),
    /// Training a model.
    #[error("training: {0}")]
    Train(#[from] node::classifier::train::TrainError),
    /// Calibrating a model's rejection on another run.
    #[error("calibrating: {0}")]
    Calibrate(#[from] node::classifier::train::CalibrateError),
    /// Training a model and calibrating it.
    #[error(transparent)]
    TrainCalibrated(#[from] crate::simdata::TrainCalibratedError),
    /// A model file.
    #[error(transparent)]
    Model(#[from] node::classifier::model::ModelError),
    /// A labels file.
    #[error(transparent)]
    Capture(#[from] node::capture::CaptureError),
    /// Fitting a model's energy check.
    #[error("fitting the energy check: {0}")]
    Energy(#[from] node::unknown::energy_fit::EnergyFitError),
    /// A thread could not be started.
    #[error("starting a thread: {0}")]
    Thread(std::io::Error),
    /// Writing a run's candump log ([`closed_loop::LoopRecording::log`]).
    #[error("writing the candump log: {0}")]
    Log(std::io::Error),
    /// A class index past the source's classes ([`open_set::leave_class_out`]).
    #[error("class {0} left out, but the source has only {1} classes")]
    NoSuchClass(usize, usize),
    /// A thread of the loop panicked.
    #[error("the {0} thread panicked")]
    Panicked(&'static str),
}
