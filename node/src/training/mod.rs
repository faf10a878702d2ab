//! The robot's training path beyond the paper's fit ([`crate::classifier::train`]): how a
//! model's unknown-ground checks are chosen on the lab's own runs ([`choice`]), the labelled
//! set a lab captured ([`TrainingSet`]) and what `presrs train` reports ([`Trained`]). The
//! deployed path depends on no simulator or lab code.

pub mod choice;
mod confidence_fit;
pub mod footprint;
pub mod frame;
pub mod held_out;
mod report;
mod set;
mod summary;

pub use report::{SessionCount, Trained, no_training_run_images_note};
pub use set::{LoadError, NotInCatalog, RunSplit, TrainCalibratedError, TrainingSet};
