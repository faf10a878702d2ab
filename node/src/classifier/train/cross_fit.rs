//! The session scoring itself: its images cut into time blocks, each block scored by a model
//! fitted without it, so that one session calibrates as the next session would.

use nalgebra::DMatrix;

use super::{Model, Parts, class_spreads, fit};
use crate::unknown::novelty::Novelty;

/// Time blocks a session is cut into to calibrate on itself ([`CalibrationSource::TimeBlocks`]).
pub const TIME_BLOCKS: usize = 4;

/// The time block of each of `classes` (the session's images in recording order): per class,
/// its images cut into [`TIME_BLOCKS`] runs of consecutive stances.
pub fn time_blocks(classes: &[usize], n_classes: usize) -> Vec<u8> {
    time_blocks_of(classes, n_classes, TIME_BLOCKS)
}

/// [`time_blocks`] in `blocks` blocks.
pub fn time_blocks_of(classes: &[usize], n_classes: usize, blocks: usize) -> Vec<u8> {
    let mut count = vec![0usize; n_classes];
    for &k in classes {
        if let Some(c) = count.get_mut(k) {
            *c += 1;
        }
    }
    let mut seen = vec![0usize; n_classes];
    classes
        .iter()
        .map(|&k| {
            let (i, n) = (seen[k], count[k].max(1));
            seen[k] += 1;
            (i * blocks / n) as u8
        })
        .collect()
}

/// Time blocks the session's own calibration cross-fits over: each block is scored by a model
/// of the other nine, whose stored samples are nine tenths of the deployed model's (with four,
/// three quarters: on a noisy foot the held-out scores then sat lower than the deployed
/// model's scores of new stances; docs/decisions/unknown-one-session.md).
pub const CROSS_FIT_BLOCKS: usize = 10;

/// Each calibration image scored as the next session's would be: `pixels` (the session's
/// working images, every one, in recording order, of classes `classes`) in time blocks; per
/// block, a model fitted as `model` (its dimensions, normalisation) on the stored samples of
/// the other blocks scores the block's images, and their kNN distances are put in `model`'s
/// units (`provisional`'s class spreads) by the ratio of the spreads. No image is scored by a
/// model that saw it or its neighbours in time: the stored samples span the PCA, so their own
/// residuals are near zero (why leave-one-out failed: docs/decisions/unknown-one-session.md).
pub(crate) fn cross_fit(
    model: &Model,
    pixels: &[Vec<u16>],
    classes: &[usize],
    provisional: &Novelty,
) -> Parts {
    let n_classes = model.classes.len();
    let mut out = Parts {
        parts: Vec::new(),
        wrong: 0,
        reference: Vec::new(),
        reference_classes: Vec::new(),
        residuals: Vec::new(),
    };
    let Some(stored) = model.images.as_ref() else {
        return out;
    };
    // Which block each image is in; a stored sample is found among the images by content.
    let n_blocks = CROSS_FIT_BLOCKS;
    let blocks = time_blocks_of(classes, n_classes, n_blocks);
    let block_of: std::collections::HashMap<&[u16], u8> = pixels
        .iter()
        .zip(&blocks)
        .map(|(p, &b)| (p.as_slice(), b))
        .collect();
    for b in 0..n_blocks as u8 {
        let keep: Vec<usize> = (0..stored.pixels.len())
            .filter(|&i| block_of.get(stored.pixels[i].as_slice()) != Some(&b))
            .collect();
        let (t, v): (Vec<usize>, Vec<usize>) = keep.iter().partition(|&&i| i < stored.n_train);
        let work: Vec<Vec<u16>> = t
            .iter()
            .chain(&v)
            .map(|&i| stored.pixels[i].clone())
            .collect();
        let labels: Vec<usize> = t
            .iter()
            .chain(&v)
            .map(|&i| model.sample_classes[i])
            .collect();
        // Every class needs stored samples of its own outside the block.
        if (0..n_classes).any(|k| !t.iter().any(|&i| model.sample_classes[i] == k)) {
            continue;
        }
        let Ok((fitted, _)) = fit(
            &work,
            &labels,
            t.len(),
            n_classes,
            model.normalize_load.is_some(),
            Some(model.h),
        ) else {
            continue;
        };
        let mut fold = model.clone();
        fold.images = None;
        fold.unknown.novelty = None;
        fold.sample_classes = labels;
        fitted.install(&mut fold);
        let spread = class_spreads(&fold, provisional.k);
        let mut nv = provisional.clone();
        nv.class_spread = spread.clone();
        fold.unknown.novelty = Some(nv);
        let mut cls = crate::classifier::Classifier::new(fold);
        for (p, &k) in pixels
            .iter()
            .zip(classes)
            .zip(&blocks)
            .filter(|(_, bk)| **bk == b)
            .map(|(pk, _)| pk)
        {
            let d = cls.classify_work(p);
            if !d.contact {
                continue;
            }
            if d.best != k {
                out.wrong += 1;
                continue;
            }
            let (knn, res) = cls.novelty_parts();
            if knn.is_finite() && res.is_finite() {
                let to_model = provisional.class_spread[k] / spread[k];
                out.parts.push((k, knn * to_model, res));
            }
        }
    }
    out
}

/// The part of the centred feature vector `c` outside the span of the PCA rows `u` (h rows),
/// in f64: the nuisance directions are fitted on it once per calibration.
pub(crate) fn residual_vector(u: &[f32], h: usize, c: &[f32]) -> Vec<f64> {
    let n = c.len();
    let mut e: Vec<f64> = c.iter().map(|&v| v as f64).collect();
    for j in 0..h {
        let row = &u[j * n..(j + 1) * n];
        let a: f64 = row.iter().zip(c).map(|(&w, &v)| w as f64 * v as f64).sum();
        for (x, &w) in e.iter_mut().zip(row) {
            *x -= a * w as f64;
        }
    }
    e
}

/// The `r` leading right singular vectors of the residual vectors (rows), as f32 rows: the
/// directions outside the PCA subspace along which the held-out runs' known images lie (no more
/// than there are images: their span is all they show).
pub(crate) fn nuisance_directions(residuals: &[Vec<f64>], r: usize) -> Vec<f32> {
    if r == 0 || residuals.is_empty() {
        return Vec::new();
    }
    let n = residuals[0].len();
    let e = DMatrix::<f64>::from_fn(residuals.len(), n, |i, j| residuals[i][j]);
    let pca = super::pca::principal_axes(&e, r);
    let mut out = Vec::with_capacity(r * n);
    for axis in &pca.axes {
        out.extend(axis.iter().map(|&v| v as f32));
    }
    out
}
