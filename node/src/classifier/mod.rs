//! The terrain classifier of the paper (sections 4, 5, 7.2, 8).
//!
//! Per image: [`image`] crop and downsampling, the [`features`] vector (eqs. 1-3), PCA
//! projection and the Parzen-window decision ([`pwe`]); the [`repair`] filter for dead sensor
//! lines; [`train`]ing with the paper's 13/7 split; the [`model`] file; [`dataset`] readers.

pub mod dataset;
pub mod features;
pub mod image;
pub mod model;
pub mod pwe;
pub mod repair;
pub mod train;

pub use image::{Crop, PressureImage};
pub use model::{ClassInfo, Model};
pub use pwe::{Classifier, Decision};
