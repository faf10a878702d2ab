//! Training, as in sections 4.2 and 7.2: per class, `per_class` random samples, `train` of them
//! for the training set T and the rest for the validation set V; PCA on the feature vectors of
//! T and V; the kernel width chosen by the accuracy on V with T as the stored samples; then all
//! of T and V are stored as the model's samples P.

//! `fit` trains, `refit` follows a damaged sensor; the unknown-ground checks a model carries
//! (`crate::unknown`, what the node runs) are fitted here: `calibrate` the novelty thresholds,
//! `cross_fit` the session scoring itself, `density` the leave-one-out densities, `bands` the
//! load and texture bands.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::seq::SliceRandom;

use super::features::{FeatureExtractor, fft_len};
use super::image::{Crop, CropSpec, PressureImage};
use super::model::{
    Checks, ClassInfo, MAX_CLASSES, MODEL_VERSION, MinContact, Model, StoredImages,
};
use crate::unknown::novelty::CalibrationSource;

pub use super::options::{DEFAULT_UNKNOWN_RATE, TrainOptions};
use super::options::{Margin, UnknownChecks};

mod bands;
mod calibrate;
mod cross_fit;
mod density;
pub mod error;
mod fit;
mod refit;

pub use bands::*;
pub use calibrate::*;
pub use cross_fit::*;
pub use density::*;
pub use error::TrainError;
pub use fit::*;
pub use refit::*;
