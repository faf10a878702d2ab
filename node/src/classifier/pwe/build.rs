//! Building a [`Classifier`] from a model: every buffer sized once, the PCA matrix in half
//! precision where the CPU has F16C, the stored samples and the novelty's references padded to
//! whole 8-lane vectors, so that a decision allocates nothing and its loops have no tails.

use super::super::Kernels;
use super::super::features::FeatureExtractor;
use super::super::kernels::{gram_inverse, half_matrix, project};
use super::super::model::{MinContact, Model};
use super::Classifier;
use crate::unknown::novelty::MAX_K;

impl Classifier {
    /// [`Classifier::new`] with the given kernels ([`Kernels::Portable`]: what an ARM computer
    /// runs, and the reference the native kernels are checked against).
    pub fn with_kernels(model: Model, kernels: Kernels) -> Self {
        let (work_rows, work_cols) = model.work_size().unwrap_or((1, 1));
        let n = model.feature_len();
        let fx = FeatureExtractor::with_kernels(work_rows * work_cols, kernels);
        let avx2_fma = kernels.avx2_fma();
        let s = model.kernel_width;
        let n_classes = model.classes.len();
        let log_norm = log_norms(&model);
        let mut projected_mean = vec![0.0; model.h];
        let mut w16 = Vec::new();
        if model.pca_matrix.len() == model.h * model.pca_mean.len() {
            if avx2_fma {
                w16 = half_matrix(&model.pca_matrix);
            }
            // With the same weights as the images, so that U F - U mean = U (F - mean) holds
            // for the rounded U too (F and mean are large and close).
            project(
                &model.pca_matrix,
                &w16,
                &model.pca_mean,
                &mut projected_mean,
                avx2_fma,
            );
        }
        let stride = model.h.div_ceil(8) * 8;
        let gram_corr = if model.unknown.novelty.is_some() && !w16.is_empty() {
            gram_correction(&model.pca_matrix, &w16, model.h, stride)
        } else {
            Vec::new()
        };
        let samples = padded_rows(&model.samples, model.h, stride, model.n_samples());
        let (reference, reference_of) = padded_references(&model, stride);
        let nuisance16 = match &model.unknown.novelty {
            Some(nv) if model.h > 0 && avx2_fma && !w16.is_empty() => half_matrix(&nv.nuisance),
            _ => Vec::new(),
        };
        let mut samples_of = vec![Vec::new(); n_classes];
        for (i, &c) in model.sample_classes.iter().enumerate() {
            if let Some(v) = samples_of.get_mut(c) {
                v.push(i);
            }
        }
        let most_references = reference_of.iter().map(|r| r.len()).max().unwrap_or(0);
        Self {
            fx,
            work: vec![0; work_rows * work_cols],
            work_rows,
            work_cols,
            feat: vec![0.0; n],
            projected_mean,
            w16,
            q: vec![0.0; stride],
            centred: vec![
                0.0;
                if model.unknown.novelty.is_some() {
                    n
                } else {
                    0
                }
            ],
            gram_corr,
            samples,
            log_kernel: vec![0.0; model.n_samples()],
            reference,
            reference_of,
            reference_d2: vec![0.0; most_references],
            nuisance16,
            nuisance_q: vec![
                0.0;
                model
                    .unknown
                    .novelty
                    .as_ref()
                    .map_or(0, |nv| nv.nuisance.len() / n.max(1))
            ],
            dead_rows: vec![false; work_rows],
            dead_cols: vec![false; work_cols],
            inv_two_s2: 1.0 / (2.0 * s * s),
            log_norm,
            log_dens: vec![0.0; n_classes],
            max_e: vec![0.0; n_classes],
            sums: vec![0.0; n_classes],
            log_posteriors: vec![0.0; n_classes],
            knn: [f64::INFINITY; MAX_K],
            samples_of,
            exclude: usize::MAX,
            parts: (f64::NAN, f64::NAN),
            // Older model files carry no contact figures: then only a blank image is refused.
            contact: model.contact.unwrap_or(MinContact { load: 0, area: 0 }),
            kernels,
            avx2_fma,
            model,
        }
    }
}

/// Each class's Parzen normaliser: -ln n_k - h/2 ln(2 pi s^2), the kernel width s.
fn log_norms(model: &Model) -> Vec<f64> {
    let (s, h) = (model.kernel_width, model.h as f64);
    (0..model.classes.len())
        .map(|k| {
            let n_k = model.sample_classes.iter().filter(|&&c| c == k).count();
            -(n_k.max(1) as f64).ln() - 0.5 * h * (2.0 * std::f64::consts::PI * s * s).ln()
        })
        .collect()
}

/// The rounded projection's Gram inverse minus the identity, padded to stride x stride with
/// zeros, as the projection is.
fn gram_correction(pca: &[f32], w16: &[u16], h: usize, stride: usize) -> Vec<f32> {
    let g = gram_inverse(pca, w16, h);
    let mut e = vec![0.0f32; stride * stride];
    for a in 0..h {
        for b in 0..h {
            e[a * stride + b] = (g[a * h + b] - if a == b { 1.0 } else { 0.0 }) as f32;
        }
    }
    e
}

/// `n` rows of `width` values, each padded with zeros to `stride`.
fn padded_rows(rows: &[f32], width: usize, stride: usize, n: usize) -> Vec<f32> {
    let mut out = vec![0.0; stride * n];
    if width > 0 {
        for (dst, src) in out.chunks_exact_mut(stride).zip(rows.chunks_exact(width)) {
            dst[..width].copy_from_slice(src);
        }
    }
    out
}

/// The novelty check's references, padded to `stride` and grouped by class, with each class's
/// row range.
fn padded_references(model: &Model, stride: usize) -> (Vec<f32>, Vec<std::ops::Range<usize>>) {
    let mut reference = Vec::new();
    let mut reference_of = vec![0..0; model.classes.len()];
    let Some(nv) = model.unknown.novelty.as_ref().filter(|_| model.h > 0) else {
        return (reference, reference_of);
    };
    for (k, range) in reference_of.iter_mut().enumerate() {
        let start = reference.len() / stride;
        for (src, _) in nv
            .reference
            .chunks_exact(model.h)
            .zip(&nv.reference_classes)
            .filter(|(_, c)| **c == k)
        {
            reference.extend_from_slice(src);
            reference.resize(reference.len() + stride - model.h, 0.0);
        }
        *range = start..reference.len() / stride;
    }
    (reference, reference_of)
}
