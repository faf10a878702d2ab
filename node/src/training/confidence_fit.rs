//! `train`'s measurement of a decision's chance of being right
//! ([`crate::classifier::confidence`]): each known terrain left out in turn, a model of the
//! others (the kept options, its novelty calibrated on the calibration run's other terrains)
//! classifies the whole calibration run. A known image is right when its nearest terrain is
//! its own; an image of the left-out terrain is wrong whatever its nearest (new ground taken
//! for a known terrain, had it been accepted). Images the novelty rejects are kept, with a
//! negative room: most of the left-out terrain's lie there, and they set how seldom an image
//! near the threshold is a known terrain's. The load, texture and energy checks are not
//! refitted per fold: their rejections only lower the share of wrong decisions the curve sees.

use crate::classifier::confidence::{ConfidenceMap, features};
use crate::classifier::train::{Labelled, TrainOptions, calibrate_on_runs, train};
use crate::classifier::{ClassInfo, Classifier, PressureImage};

/// The map fitted on the folds (see the module docs); `None` without a calibration run, or
/// with too few decisions to fit.
pub fn fit(
    training: &[Labelled<'_>],
    calibration: &[Labelled<'_>],
    runs: &[String],
    classes: &[ClassInfo],
    opts: &TrainOptions,
) -> Option<ConfidenceMap> {
    if calibration.is_empty() || classes.len() < 3 {
        return None;
    }
    // Per decision: its figures, right or not, and whether it is the left-out terrain's.
    let mut samples: Vec<([f64; 2], bool, bool)> = Vec::new();
    for out in 0..classes.len() {
        let keep: Vec<usize> = (0..classes.len()).filter(|&k| k != out).collect();
        let relabel = |k: usize| keep.iter().position(|&c| c == k);
        let fold_classes: Vec<ClassInfo> = keep.iter().map(|&k| classes[k].clone()).collect();
        let train_set: Vec<Labelled<'_>> = training
            .iter()
            .filter_map(|l| relabel(l.class).map(|class| Labelled { class, ..*l }))
            .collect();
        let Ok((mut model, _)) = train(&train_set, &fold_classes, opts) else {
            continue;
        };
        let cal: Vec<(&PressureImage, &str)> = calibration
            .iter()
            .filter(|l| l.class != out)
            .map(|l| (l.image, classes[l.class].name.as_str()))
            .collect();
        if calibrate_on_runs(&mut model, &cal, runs).is_err() {
            continue;
        }
        let mut cls = Classifier::new(model);
        for l in calibration {
            let img = l.image;
            let Ok(d) = cls.classify(&img.pixels, img.rows, img.cols, false) else {
                continue;
            };
            if !d.contact {
                continue;
            }
            // Every image, accepted or not: the rejected ones (most of the left-out terrain's)
            // say how seldom an image near the threshold is a known terrain's.
            let k = d.best;
            let lp = cls.log_posteriors();
            let next = (0..lp.len())
                .filter(|&j| j != k)
                .map(|j| lp[j])
                .fold(f64::NEG_INFINITY, f64::max);
            let f = features(lp[k] - next, d.novelty, d.threshold);
            samples.push((f, relabel(l.class) == Some(k), l.class == out));
        }
    }
    // New ground weighed as a robot meets it: [`NEW_GROUND_SHARE`] of its steps, not a
    // left-out terrain's share of the folds.
    let known = samples.iter().filter(|s| !s.2).count() as f64;
    let new = samples.iter().filter(|s| s.2).count().max(1) as f64;
    let w_new = known / new * NEW_GROUND_SHARE / (1.0 - NEW_GROUND_SHARE);
    let weighted: Vec<([f64; 2], bool, f64)> = samples
        .iter()
        .map(|&(f, r, novel)| (f, r, if novel { w_new } else { 1.0 }))
        .collect();
    // Its table on the known images the folds accepted: the decisions a next session makes.
    let judged: Vec<([f64; 2], bool)> = samples
        .iter()
        .filter(|s| !s.2 && s.0[1] >= 0.0)
        .map(|s| (s.0, s.1))
        .collect();
    ConfidenceMap::fit_weighted(&weighted, &judged)
}

/// The share of a robot's steps on new ground the confidence is measured for: one in ten.
pub const NEW_GROUND_SHARE: f64 = 0.03;
