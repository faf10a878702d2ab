//! Why a training request cannot be met: one error for every training entry point, and for
//! `TrainOptions::check`, which refuses the options before any image is read.

use crate::classifier::image::Crop;
use crate::classifier::model::{MAX_CLASSES, MAX_DOWNSAMPLE, MAX_UNKNOWN_RATE};

/// Why a training request cannot be met.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TrainError {
    /// A class has too few images.
    #[error("class `{class}` has {have} images; training needs at least --per-class {need}")]
    TooFew {
        /// The class.
        class: String,
        /// Images it has.
        have: usize,
        /// Images needed (`per_class`).
        need: usize,
    },
    /// Every image of a class is blank: no stance's load, nothing to learn a terrain from.
    #[error(
        "every image of class `{class}` is blank (no load on any sensel): not a stance image; \
         capture stances with the foot on the ground"
    )]
    NoLoad {
        /// The class.
        class: String,
    },
    #[error(
        "--train {train} must be at least 1 and below --per-class {per_class} (the rest validate)"
    )]
    /// `train` is 0 or not below `per_class`.
    BadSplit {
        /// Images to train on.
        train: usize,
        /// Images per class.
        per_class: usize,
    },
    /// A downsampling factor outside 1..=MAX_DOWNSAMPLE.
    #[error("--downsample {0}: use 1 (full resolution) to {MAX_DOWNSAMPLE}")]
    Downsample(usize),
    /// An unknown rate outside 0..=MAX_UNKNOWN_RATE (the model file would not load).
    #[error("--unknown-rate {0}: use a share from 0 to {MAX_UNKNOWN_RATE} (0.02 is 2%)")]
    UnknownRate(f64),
    /// Too few or too many classes.
    #[error("{0} classes; a model holds 2 to {MAX_CLASSES}")]
    Classes(usize),
    #[error(
        "images of {a} and {b} differ in size; give a --crop that makes them equal, or use one sensor size"
    )]
    /// Two images differ in size after the crop.
    Sizes {
        /// One image.
        a: String,
        /// The other.
        b: String,
    },
    /// The crop removes the whole image.
    #[error("crop {crop:?} leaves nothing of a {rows}x{cols} image")]
    Crop {
        /// The crop.
        crop: Crop,
        /// Image rows.
        rows: usize,
        /// Image columns.
        cols: usize,
    },
    /// The PCA did not converge.
    #[error("the PCA did not converge (are all images identical?)")]
    Pca,
}
