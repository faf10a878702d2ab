//! Training, as in sections 4.2 and 7.2: per class, `per_class` random samples, `train` of them
//! for the training set T and the rest for the validation set V; PCA on the feature vectors of
//! T and V; the kernel width chosen by the accuracy on V with T as the stored samples; then all
//! of T and V are stored as the model's samples P.

//! `fit` trains, `refit` follows a damaged sensor; the unknown-ground checks a model carries
//! are fitted in `crate::unknown` (`calibrate`: the thresholds, `bands`: the load and texture
//! bands), re-exported here for the training pipeline.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::seq::SliceRandom;

use super::features::{FeatureExtractor, fft_len};
use super::image::{Crop, CropSpec, PressureImage};
use super::model::{
    Checks, ClassInfo, MAX_CLASSES, MAX_DOWNSAMPLE, MAX_UNKNOWN_RATE, MODEL_VERSION, MinContact,
    Model, StoredImages,
};
use crate::unknown::novelty::CalibrationSource;

pub use super::options::{DEFAULT_UNKNOWN_RATE, TrainOptions};
use super::options::{Margin, UnknownChecks};

mod fit;
mod refit;

pub use crate::unknown::bands::*;
pub use crate::unknown::calibrate::*;
pub use fit::*;
pub use refit::*;
