//! Training, as in sections 4.2 and 7.2: per class, `per_class` random samples, `train` of them
//! for the training set T and the rest for the validation set V; PCA on the feature vectors of
//! T and V; the kernel width chosen by the accuracy on V with T as the stored samples; then all
//! of T and V are stored as the model's samples P.

//! `fit` trains, `refit` follows a damaged sensor; the unknown-ground checks a model carries
//! (`crate::unknown`, what the node runs) are fitted here: `calibrate` the novelty thresholds,
//! `cross_fit` the session scoring itself, `density` the leave-one-out densities, `bands` the
//! load and texture bands.

use nalgebra::DMatrix;

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
mod extend;
mod fit;
mod pca;
mod refit;

pub use bands::{add_load_check, add_load_check_on, add_texture_check};
pub use calibrate::{
    CalibrateError, MAX_CALIBRATION_PER_CLASS, MIN_SAME_RUN_PER_CLASS, calibrate_on_runs, rescore,
};
pub use cross_fit::{CROSS_FIT_BLOCKS, TIME_BLOCKS, time_blocks, time_blocks_of};
pub use density::loo_log_densities;
pub use error::TrainError;
pub use extend::{Basis, ExtendError, MIN_NEW_STANCES, ToldApart, add_class, told_apart};
pub use fit::{Labelled, Split, resolve_crop, train, train_with_max_dims};
pub use refit::{RefitError, refit};
// What the modules share among themselves and with the rest of the crate.
pub(crate) use bands::{load_ranges, widen};
pub(crate) use calibrate::{Parts, set_novelty};
pub(crate) use cross_fit::{cross_fit, nuisance_directions, residual_vector};
pub(crate) use density::{class_spreads, positive, unknown_thresholds};
pub(crate) use fit::{fit, preprocess, sq_dist};
