//! Calibrating the rejection on images the fit never saw: the novelty score's threshold per
//! class, from a second run or held-out images of the training run.

use super::{class_spreads, cross_fit, nuisance_directions, positive, preprocess, residual_vector};
use crate::classifier::image::PressureImage;
use crate::classifier::model::Model;
use crate::order_stats::{median, upper_quantile};
use crate::unknown::novelty::{
    Calibration, CalibrationSource, HELD_OUT_RATE_FACTOR, NOVELTY_K, NUISANCE_DIRECTIONS, Novelty,
    NoveltyScore, SHRINK_IMAGES,
};

/// Most calibration images per class kept in a model file (each is a working image: 41x38
/// pixels are about 6 kB of JSON).
pub const MAX_CALIBRATION_PER_CLASS: usize = 40;

/// Fewest unused images of the training run per class for `SameRun` calibration; below, the
/// stored samples calibrate, each left out of its own neighbours.
pub const MIN_SAME_RUN_PER_CLASS: usize = 5;

/// Why calibration images cannot calibrate a model.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum CalibrateError {
    /// No images.
    #[error(
        "calibration run {run} holds no images of the model's terrains: give a run (a capture \
         folder or candump capture) of terrains the model knows"
    )]
    Empty {
        /// The run(s), as named by the caller.
        run: String,
    },
    /// An image of a terrain the model does not know.
    #[error(
        "calibration run {run} has images of `{class}`, which the model was not trained on: \
         calibrate only on terrains the model knows (remove that folder, or retrain with it)"
    )]
    UnknownClass {
        /// The run(s).
        run: String,
        /// The class.
        class: String,
    },
    /// An image of another size or depth.
    #[error(
        "calibration run {run}: a {rows}x{cols} {bits}-bit image, but the model takes \
         {want_rows}x{want_cols} {want_bits}-bit images: calibrate on the robot's own sensor"
    )]
    Size {
        /// The run(s).
        run: String,
        /// Rows of the image.
        rows: usize,
        /// Columns.
        cols: usize,
        /// Bits.
        bits: u8,
        /// Rows the model takes.
        want_rows: usize,
        /// Columns the model takes.
        want_cols: usize,
        /// Bits the model takes.
        want_bits: u8,
    },
    /// No image shows contact.
    #[error(
        "calibration run {run}: none of its {n} images shows a foot on the ground (the model's \
         minimum contact): are they stance images of the same foot?"
    )]
    NoContact {
        /// The run(s).
        run: String,
        /// Images given.
        n: usize,
    },
}

/// Calibrates `model`'s novelty thresholds on images of other runs than its stored samples (the
/// robot's next recording of the same terrains): `images` with their class names, `runs` the
/// runs' names (kept in the model and named in errors). The thresholds are the model's
/// `unknown_rate` quantile of these images' novelty and of the training run's unused ones, with
/// no margin; at most [`MAX_CALIBRATION_PER_CLASS`] images per terrain are used (the model
/// file keeps them), the first ones given. Returns the calibration's check (the share of the
/// images classified right that are called unknown).
///
/// The first images, not ones spread through the run: docs/decisions/unknown-calibration.md.
pub fn calibrate_on_runs(
    model: &mut Model,
    images: &[(&PressureImage, &str)],
    runs: &[String],
) -> Result<f64, CalibrateError> {
    let run = if runs.is_empty() {
        "(unnamed)".to_string()
    } else {
        runs.join(", ")
    };
    if images.is_empty() {
        return Err(CalibrateError::Empty { run });
    }
    let want_bits = model.bits.unwrap_or(images[0].0.bits);
    let mut pixels = Vec::with_capacity(images.len());
    let mut classes = Vec::with_capacity(images.len());
    let mut per_class = vec![0usize; model.classes.len()];
    for (img, name) in images {
        let k = model
            .classes
            .iter()
            .position(|c| c.name == *name)
            .ok_or_else(|| CalibrateError::UnknownClass {
                run: run.clone(),
                class: name.to_string(),
            })?;
        let size_err = || CalibrateError::Size {
            run: run.clone(),
            rows: img.rows,
            cols: img.cols,
            bits: img.bits,
            want_rows: model.input_rows,
            want_cols: model.input_cols,
            want_bits,
        };
        if (img.rows, img.cols, img.bits) != (model.input_rows, model.input_cols, want_bits) {
            return Err(size_err());
        }
        if per_class[k] >= MAX_CALIBRATION_PER_CLASS {
            continue;
        }
        per_class[k] += 1;
        pixels.push(
            preprocess(img, &model.crop, model.downsample)
                .ok_or_else(size_err)?
                .pixels,
        );
        classes.push(k);
    }
    let held_out = pixels.len();
    // With the training run's unused images too: more images for the tails, and both kinds
    // of spread (within a run, across runs) in one calibration. (Not again after an earlier
    // calibration on runs: those images would count twice.)
    let (extra, extra_classes) = training_run_unused(model);
    pixels.extend(extra);
    classes.extend(extra_classes);
    let n = pixels.len();
    let score = model
        .unknown
        .novelty
        .as_ref()
        .map_or(NoveltyScore::KnnResidual, |nv| nv.score);
    set_novelty(
        model,
        pixels,
        classes,
        CalibrationSource::HeldOutRuns,
        runs.to_vec(),
        1.0,
        held_out,
        score,
    );
    match &model.unknown.novelty {
        Some(nv) => Ok(nv.calibration.called_unknown),
        None => Err(CalibrateError::NoContact { run, n }),
    }
}

/// The training run's images its model does not store, from its calibration on that run
/// (every class with [`MIN_SAME_RUN_PER_CLASS`] or more of them, else none), with their
/// classes: what a calibration on another run adds.
fn training_run_unused(model: &Model) -> (Vec<Vec<u16>>, Vec<usize>) {
    let Some(c) = model.unknown.novelty.as_ref().map(|n| &n.calibration) else {
        return Default::default();
    };
    let stored: std::collections::HashSet<&[u16]> = match (&model.images, c.source) {
        (_, CalibrationSource::SameRun) => Default::default(),
        (Some(im), CalibrationSource::TimeBlocks) => im.pixels.iter().map(Vec::as_slice).collect(),
        _ => return Default::default(),
    };
    let unused: Vec<(Vec<u16>, usize)> = c
        .pixels
        .iter()
        .zip(&c.classes)
        .filter(|(p, _)| !stored.contains(p.as_slice()))
        .map(|(p, &k)| (p.clone(), k))
        .collect();
    let enough = (0..model.classes.len())
        .all(|k| unused.iter().filter(|u| u.1 == k).count() >= MIN_SAME_RUN_PER_CLASS);
    if !enough {
        return Default::default();
    }
    unused.into_iter().unzip()
}

/// Calibrates `model`'s novelty again, on the images it was calibrated on, for another
/// `score` (nothing without a novelty score).
pub fn rescore(model: &mut Model, score: NoveltyScore) {
    if let Some(nv) = model.unknown.novelty.clone() {
        let c = nv.calibration;
        set_novelty(
            model,
            c.pixels,
            c.classes,
            c.source,
            c.runs,
            c.margin,
            c.held_out_images,
            score,
        );
    }
}

/// Fits the novelty `score` of `model` (class spreads from its stored samples) and calibrates
/// its thresholds on the working images `pixels` of classes `classes` (empty with
/// `LeaveOneOut`: the stored images, each left out of its own neighbours). Images without
/// contact are left out; with none left, the model keeps no novelty score (the density rule
/// decides).
#[allow(clippy::too_many_arguments)]
pub(crate) fn set_novelty(
    model: &mut Model,
    pixels: Vec<Vec<u16>>,
    classes: Vec<usize>,
    source: CalibrationSource,
    runs: Vec<String>,
    margin: f64,
    held_out: usize,
    score: NoveltyScore,
) {
    let rate = model.unknown.rate;
    let provisional = provisional(model, score, source, runs, margin);
    if source == CalibrationSource::TimeBlocks {
        let measured = cross_fit(model, &pixels, &classes, &provisional);
        finish_novelty(
            model,
            provisional,
            measured,
            margin,
            (pixels, classes, 0),
            rate,
        );
        return;
    }
    let mut m = model.clone();
    m.unknown.novelty = Some(provisional.clone());
    m.images = None;
    let mut cls = crate::classifier::Classifier::new(m);
    // (best class, kNN distance, residual) per calibration image in contact and classified
    // right. A known image taken for another terrain is an error of the classifier, not a
    // known image that looks unusual: kept, it set its wrong class's threshold
    // (docs/decisions/unknown-calibration.md).
    let mut parts: Vec<(usize, f64, f64)> = Vec::new();
    let mut wrong = 0usize;
    let (mut reference, mut reference_classes) = (Vec::new(), Vec::new());
    let mut residuals: Vec<Vec<f64>> = Vec::new();
    let loo = source == CalibrationSource::LeaveOneOut;
    let labels: &[usize] = if loo { &model.sample_classes } else { &classes };
    let images: &[Vec<u16>] = match (&model.images, loo) {
        (Some(stored), true) => &stored.pixels,
        (None, true) => &[],
        (_, false) => &pixels,
    };
    for (i, p) in images.iter().enumerate() {
        cls.exclude_sample(loo.then_some(i));
        let d = cls.classify_work(p);
        if d.contact && d.best != labels[i] {
            wrong += 1;
        } else if d.contact {
            let (knn, res) = cls.novelty_parts();
            if knn.is_finite() && res.is_finite() {
                parts.push((d.best, knn, res));
            }
            // A held-out run's known image: a reference for the next run (see the module docs
            // of `novelty`). Scored above without the references: conservatively, as an image
            // of a run the model has not seen.
            if !loo && i < held_out && source == CalibrationSource::HeldOutRuns {
                reference.extend_from_slice(cls.projection());
                reference_classes.push(d.best);
                residuals.push(residual_vector(&model.pca_matrix, model.h, cls.centred()));
            }
        }
    }
    let measured = Parts {
        parts,
        wrong,
        reference,
        reference_classes,
        residuals,
    };
    let kept = if loo {
        (Vec::new(), Vec::new(), 0)
    } else {
        (pixels, classes, held_out)
    };
    finish_novelty(model, provisional, measured, margin, kept, rate);
}

/// The novelty check before its thresholds are measured: every threshold open, no references.
fn provisional(
    model: &Model,
    score: NoveltyScore,
    source: CalibrationSource,
    runs: Vec<String>,
    margin: f64,
) -> Novelty {
    let n_classes = model.classes.len();
    Novelty {
        score,
        k: NOVELTY_K,
        class_spread: class_spreads(model, NOVELTY_K),
        residual_scale: vec![1.0; n_classes],
        thresholds: vec![f64::MAX; n_classes],
        calibration: Calibration {
            source,
            runs,
            images: 0,
            rate: model.unknown.rate,
            margin,
            called_unknown: 0.0,
            misclassified: 0.0,
            pixels: Vec::new(),
            classes: Vec::new(),
            held_out_images: 0,
        },
        reference: Vec::new(),
        reference_classes: Vec::new(),
        nuisance: Vec::new(),
    }
}

/// What calibration images measured: per image in contact and classified right, (best class,
/// kNN distance, residual); the images taken for another class; and a held-out run's
/// references and residual vectors.
pub(crate) struct Parts {
    pub(crate) parts: Vec<(usize, f64, f64)>,
    pub(crate) wrong: usize,
    pub(crate) reference: Vec<f32>,
    pub(crate) reference_classes: Vec<usize>,
    pub(crate) residuals: Vec<Vec<f64>>,
}

/// Sets `model`'s novelty from what its calibration images measured: residual scales, each
/// part stretched to its tail, per-class thresholds; keeps `kept` (the images, their classes
/// and how many came from held-out runs) for a later refit.
fn finish_novelty(
    model: &mut Model,
    provisional: Novelty,
    measured: Parts,
    margin: f64,
    kept: (Vec<Vec<u16>>, Vec<usize>, usize),
    rate: f64,
) {
    let Parts {
        parts,
        wrong,
        reference,
        reference_classes,
        residuals,
    } = measured;
    if parts.is_empty() {
        model.unknown.novelty = None;
        return;
    }
    // Calibration images of a held-out run are scored as a run the model has never seen; the
    // next run is scored with them as references, and comes out less novel: the quantile is
    // taken at a measured multiple of the rate asked (see [`HELD_OUT_RATE_FACTOR`]).
    let cal_rate = if reference_classes.is_empty() {
        rate
    } else {
        (rate * HELD_OUT_RATE_FACTOR).min(crate::classifier::model::MAX_UNKNOWN_RATE)
    };
    let mut nv = provisional;
    set_units(&mut nv, &parts, cal_rate);
    let scores: Vec<f64> = parts
        .iter()
        .map(|&(b, knn, res)| nv.score_of(b, knn, res))
        .collect();
    set_thresholds(&mut nv, &parts, &scores, 1.0 - cal_rate, margin);
    let above = parts
        .iter()
        .zip(&scores)
        .filter(|(p, s)| !crate::unknown::within_threshold(**s, nv.thresholds[p.0]))
        .count();
    nv.calibration.images = parts.len() + wrong;
    nv.calibration.called_unknown = above as f64 / parts.len() as f64;
    nv.calibration.misclassified = wrong as f64 / (parts.len() + wrong) as f64;
    (
        nv.calibration.pixels,
        nv.calibration.classes,
        nv.calibration.held_out_images,
    ) = kept;
    nv.calibration.rate = cal_rate;
    nv.reference = reference;
    nv.reference_classes = reference_classes;
    nv.nuisance = nuisance_directions(&residuals, NUISANCE_DIRECTIONS);
    model.unknown.novelty = Some(nv);
}

/// The novelty check's units: each class's residual scale (its median, the pooled one for a
/// class of fewer than 3 images), then each part stretched to its own tail, so that the
/// `1 - rate` quantile of either part alone is 1: neither decides by its tail alone
/// (docs/decisions/unknown-calibration.md).
fn set_units(nv: &mut Novelty, parts: &[(usize, f64, f64)], cal_rate: f64) {
    let mut all_res: Vec<f64> = parts.iter().map(|p| p.2).collect();
    let pooled_res = median(&mut all_res);
    for (kk, scale) in nv.residual_scale.iter_mut().enumerate() {
        let mut r: Vec<f64> = parts.iter().filter(|p| p.0 == kk).map(|p| p.2).collect();
        let m = if r.len() >= 3 {
            median(&mut r)
        } else {
            pooled_res
        };
        *scale = positive(m, pooled_res);
    }
    let q = 1.0 - cal_rate;
    let mut zk: Vec<f64> = parts
        .iter()
        .map(|&(b, knn, _)| knn / nv.class_spread[b])
        .collect();
    let mut zr: Vec<f64> = parts
        .iter()
        .map(|&(b, _, r)| r / nv.residual_scale[b])
        .collect();
    let (qk, qr) = (upper_quantile(&mut zk, q), upper_quantile(&mut zr, q));
    for v in nv.class_spread.iter_mut() {
        *v *= positive(qk, 1.0);
    }
    for v in nv.residual_scale.iter_mut() {
        *v *= positive(qr, 1.0);
    }
}

/// Each class's threshold: its own `q` quantile of the scores, shrunk toward the pooled one by
/// its count, times the margin. With 30 images the 98% quantile is the largest one, and a
/// class's threshold was then as noisy as its one most unusual image
/// (docs/decisions/unknown-calibration.md).
fn set_thresholds(
    nv: &mut Novelty,
    parts: &[(usize, f64, f64)],
    scores: &[f64],
    q: f64,
    margin: f64,
) {
    let pooled = upper_quantile(&mut scores.to_vec(), q);
    for (kk, threshold) in nv.thresholds.iter_mut().enumerate() {
        let mut v: Vec<f64> = parts
            .iter()
            .zip(scores)
            .filter(|(p, _)| p.0 == kk)
            .map(|(_, s)| *s)
            .collect();
        let t = if v.is_empty() {
            pooled
        } else {
            let w = v.len() as f64 / (v.len() as f64 + SHRINK_IMAGES);
            w * upper_quantile(&mut v, q) + (1.0 - w) * pooled
        };
        *threshold = margin * positive(t, 1.0);
    }
}
