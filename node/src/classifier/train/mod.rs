//! Training, as in sections 4.2 and 7.2: per class, `per_class` random samples, `train` of them
//! for the training set T and the rest for the validation set V; PCA on the feature vectors of
//! T and V; the kernel width chosen by the accuracy on V with T as the stored samples; then all
//! of T and V are stored as the model's samples P.

//! `fit` trains, `calibrate` sets the rejection from other images, `bands` adds the load and
//! texture checks, `refit` follows a damaged sensor.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::seq::SliceRandom;

use super::features::{FeatureExtractor, fft_len};
use super::image::{Crop, PressureImage};
use super::model::{
    ClassInfo, MAX_CLASSES, MAX_DOWNSAMPLE, MAX_UNKNOWN_RATE, MODEL_VERSION, MinContact, Model,
    StoredImages,
};
use crate::stats::{median, upper_quantile};
use crate::unknown::novelty::{
    Calibration, CalibrationSource, HELD_OUT_RATE_FACTOR, NOVELTY_K, NUISANCE_DIRECTIONS, Novelty,
    NoveltyScore, SAME_RUN_MARGIN, SHRINK_IMAGES,
};

pub use super::options::{DEFAULT_UNKNOWN_RATE, TrainOptions};

mod bands;
mod calibrate;
mod fit;
mod refit;

pub use bands::*;
pub use calibrate::*;
pub use fit::*;
pub use refit::*;
