//! Novelty: how unlike every known terrain an image is, and the per-class thresholds above
//! which it is unknown ([`super::Reason::Novelty`]).
//!
//! The score has two parts, both from numbers the classifier computes anyway:
//!
//! - **kNN ratio**: the mean distance, in the model's PCA space, from the image to the
//!   [`Novelty::k`] nearest stored samples (and held-out references) of its best class, divided
//!   by that class's own spread. Unlike the Parzen density it does not reward the empty space
//!   between classes: an image half-way between two classes is far from both.
//! - **residual ratio**: the length of the feature vector's part outside the PCA subspace,
//!   divided by the class's typical residual on calibration images. PCA fitted on the known
//!   terrains drops the directions in which a new one differs; the residual is where it goes.
//!
//! The novelty is the larger ratio ([`NoveltyScore::KnnResidual`]) or the kNN ratio alone
//! ([`NoveltyScore::Knn`]); `train` measures which finds more left-out ground on the lab's own
//! runs and keeps that one ([`crate::training::choice`]).
//!
//! **Calibration.** The thresholds are the `1 - rate` quantile of the novelty of known images
//! the stored samples do not include: at best another run of the same terrains
//! ([`CalibrationSource::HeldOutRuns`]), whose known images also become references of the kNN
//! ratio and whose residual directions ([`Novelty::nuisance`]) the residual leaves out: how a
//! run of known ground differs from the training run is not novelty. Without a second run, the
//! training run's unused images calibrate, widened by [`SAME_RUN_MARGIN`].
//!
//! Why this score, these constants and not nine others: docs/decisions/unknown-novelty-score.md.

use serde::{Deserialize, Serialize};

/// Neighbours averaged in the kNN ratio (1, the plain nearest neighbour, lets one stray stored
/// sample decide).
pub const NOVELTY_K: usize = 3;

/// Most neighbours a model may ask for (the classifier keeps them in a fixed array).
pub const MAX_K: usize = 8;

/// Threshold multiplier when the calibration images come from the training run itself: the
/// robot's next run scatters more than its own recording.
pub const SAME_RUN_MARGIN: f64 = 1.15;

/// Most nuisance directions a model keeps (each costs one more projection row per image).
pub const NUISANCE_DIRECTIONS: usize = 8;

/// With held-out runs, the thresholds are the `1 - rate * HELD_OUT_RATE_FACTOR` quantile of the
/// calibration images' novelty: they are scored as a run the model has never seen, while the
/// next run is scored with them as references, and comes out less novel.
pub const HELD_OUT_RATE_FACTOR: f64 = 1.5;

/// A class's threshold is its own quantile weighted `n / (n + SHRINK_IMAGES)` (`n` its
/// calibration images) and the quantile over all classes' images for the rest.
pub const SHRINK_IMAGES: f64 = 30.0;

/// Which score a model's novelty is (kept in the file, so that a later score is a new name).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum NoveltyScore {
    /// The larger of the kNN ratio and the residual ratio (this module's docs).
    #[serde(rename = "knn-residual")]
    KnnResidual,
    /// The kNN ratio alone: where the known terrains' runs differ outside the PCA subspace
    /// more than a new terrain does, the residual only adds noise.
    #[serde(rename = "knn")]
    Knn,
}

/// Where the calibration images came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CalibrationSource {
    /// Whole runs (recordings) none of the stored samples came from.
    HeldOutRuns,
    /// Images of the training run that the model does not store.
    SameRun,
    /// The stored samples, each left out of its own neighbours (too few other images).
    LeaveOneOut,
    /// The training session itself in time blocks, each scored by a model fitted without it
    /// (`classifier::train::CROSS_FIT_BLOCKS`): one session, every image stored or not.
    TimeBlocks,
}

impl CalibrationSource {
    /// For reports.
    pub fn describe(self) -> &'static str {
        match self {
            CalibrationSource::HeldOutRuns => "held-out runs",
            CalibrationSource::SameRun => "the training run's unused images, with a margin",
            CalibrationSource::LeaveOneOut => "the stored samples, leave-one-out, with a margin",
            CalibrationSource::TimeBlocks => {
                "the session itself in time blocks, each scored by a model fitted without it"
            }
        }
    }
}

/// How the thresholds were set, and the calibration's own check.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Where the images came from.
    pub source: CalibrationSource,
    /// The runs held out (their `source` in the capture manifest), for `HeldOutRuns`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub runs: Vec<String>,
    /// Calibration images used.
    pub images: usize,
    /// The share of known images the thresholds were set to call unknown.
    pub rate: f64,
    /// The multiplier applied to the quantile (1 for held-out runs).
    pub margin: f64,
    /// The check: the share of the calibration images classified right that lie above their
    /// class's threshold.
    pub called_unknown: f64,
    /// The share of the calibration images classified as another known terrain (left out of
    /// the thresholds: see `train::set_novelty`).
    #[serde(default)]
    pub misclassified: f64,
    /// The calibration images' working images and classes, so that a refit to dead sensor
    /// lines can calibrate again on the same images with the same lines dead.
    pub pixels: Vec<Vec<u16>>,
    /// Class index of each of `pixels`.
    pub classes: Vec<usize>,
    /// The first this many of `pixels` come from held-out runs (the rest from the training
    /// run); those classified right are the novelty's reference images.
    #[serde(default)]
    pub held_out_images: usize,
}

impl Calibration {
    /// Calibration images of the training run (the images after the held-out runs'): none
    /// when the model stores every image of that run. Older files, which do not say how many
    /// came from held-out runs, count all of them.
    pub fn training_run_images(&self) -> usize {
        self.pixels.len().saturating_sub(self.held_out_images)
    }
}

/// A model file's `novelty` entry that cannot be right (sizes, ranges, numbers): the message
/// names the key.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[error("{0}")]
pub struct InvalidNovelty(pub String);

/// A model's novelty score and its calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Novelty {
    /// The score.
    pub score: NoveltyScore,
    /// Neighbours in the kNN ratio.
    pub k: usize,
    /// Per class: the median kNN distance of its stored samples to the class's others.
    pub class_spread: Vec<f64>,
    /// Per class: the median residual of its calibration images.
    pub residual_scale: Vec<f64>,
    /// Per class: the novelty above which an image decided as that class is unknown.
    pub thresholds: Vec<f64>,
    /// How the thresholds were set.
    pub calibration: Calibration,
    /// Known images of other runs than the stored samples' (the held-out calibration runs'
    /// images classified right), in the model's PCA space, h values each: the kNN ratio
    /// measures an image's distance to its best class's stored samples *and* these. Empty in
    /// older files and for a model calibrated on its training run only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub reference: Vec<f32>,
    /// Class index of each reference image.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub reference_classes: Vec<usize>,
    /// Unit directions of feature space outside the PCA subspace in which the held-out runs'
    /// known images differ from the training run (feature-length rows): the residual leaves
    /// them out. Empty in older files.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub nuisance: Vec<f32>,
}

impl Novelty {
    /// Checks sizes and numbers against a model of `n_classes` classes.
    pub fn validate(&self, n_classes: usize) -> Result<(), InvalidNovelty> {
        if !(1..=MAX_K).contains(&self.k) {
            return Err(InvalidNovelty(format!(
                "novelty.k {} is not in 1..={MAX_K}",
                self.k
            )));
        }
        for (name, v) in [
            ("class_spread", &self.class_spread),
            ("residual_scale", &self.residual_scale),
            ("thresholds", &self.thresholds),
        ] {
            if v.len() != n_classes {
                return Err(InvalidNovelty(format!(
                    "novelty.{name} has {} values for {n_classes} classes",
                    v.len()
                )));
            }
            if let Some(x) = v.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
                return Err(InvalidNovelty(format!(
                    "novelty.{name} holds {x}: want positive numbers"
                )));
            }
        }
        if self.reference_classes.iter().any(|&k| k >= n_classes)
            || self.reference.iter().any(|v| !v.is_finite())
        {
            return Err(InvalidNovelty(
                "novelty.reference holds a class or number out of range".into(),
            ));
        }
        let c = &self.calibration;
        if c.pixels.len() != c.classes.len() || c.classes.iter().any(|&k| k >= n_classes) {
            return Err(InvalidNovelty(
                "novelty.calibration's images and classes do not match".into(),
            ));
        }
        if !((0.0..=super::MAX_UNKNOWN_RATE).contains(&c.rate)
            && c.margin.is_finite()
            && c.margin >= 1.0)
        {
            return Err(InvalidNovelty(
                "novelty.calibration's rate or margin is out of range".into(),
            ));
        }
        Ok(())
    }

    /// The novelty of an image from its parts: the mean distance to the `k` nearest stored
    /// samples of `class` and the residual length.
    #[inline]
    pub fn score_of(&self, class: usize, knn_dist: f64, residual: f64) -> f64 {
        let zk = knn_dist / self.class_spread[class];
        match self.score {
            NoveltyScore::KnnResidual => zk.max(residual / self.residual_scale[class]),
            NoveltyScore::Knn => zk,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_score_is_the_larger_ratio() {
        let n = Novelty {
            score: NoveltyScore::KnnResidual,
            k: 3,
            class_spread: vec![2.0, 10.0],
            residual_scale: vec![4.0, 1.0],
            thresholds: vec![1.5, 1.5],
            calibration: Calibration {
                source: CalibrationSource::SameRun,
                runs: vec![],
                images: 0,
                rate: 0.02,
                margin: 1.3,
                called_unknown: 0.0,
                misclassified: 0.0,
                pixels: vec![],
                classes: vec![],
                held_out_images: 0,
            },
            reference: vec![],
            reference_classes: vec![],
            nuisance: vec![],
        };
        assert_eq!(n.score_of(0, 4.0, 4.0), 2.0);
        assert_eq!(n.score_of(1, 4.0, 4.0), 4.0);
        assert!(n.validate(2).is_ok());
        assert!(n.validate(3).is_err());
        let mut bad = n.clone();
        bad.thresholds[1] = f64::NAN;
        assert!(bad.validate(2).unwrap_err().0.contains("thresholds"));
    }
}
