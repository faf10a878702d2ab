//! The classifier at run time: crop, downsample, (repair), feature vector, PCA projection and the
//! Parzen-window (Gaussian kernel density) decision. Every buffer is allocated when the
//! classifier is built; classifying an image allocates nothing.

use super::features::FeatureExtractor;
use super::model::{MAX_CLASSES, Model};
use super::repair;

/// The outcome for one image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decision {
    /// The class, or `None` when the best class's density is below the model's unknown threshold.
    pub class: Option<usize>,
    /// The most probable class, known or not.
    pub best: usize,
    /// Terrain id of `class` (0xFF when unknown).
    pub terrain_id: u8,
    /// Posterior of the best class (equal priors), 0..=1.
    pub confidence: f64,
    /// Log Parzen density of the best class.
    pub log_density: f64,
    /// Log posterior per class (first `n_classes` entries).
    pub log_posteriors: [f64; MAX_CLASSES],
    pub n_classes: usize,
}

/// An image that does not fit the model.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("image is {rows}x{cols} but the model takes {want_rows}x{want_cols} images")]
pub struct SizeMismatch {
    pub rows: usize,
    pub cols: usize,
    pub want_rows: usize,
    pub want_cols: usize,
}

pub struct Classifier {
    model: Model,
    fx: FeatureExtractor,
    work: Vec<u16>,
    work_rows: usize,
    work_cols: usize,
    feat: Vec<f32>,
    centered: Vec<f32>,
    q: Vec<f32>,
    d2: Vec<f64>,
    dead_rows: Vec<bool>,
    dead_cols: Vec<bool>,
    inv_two_s2: f64,
    log_norm: [f64; MAX_CLASSES],
}

impl Classifier {
    /// Builds the run-time buffers; the model must have passed `Model::validate` (as `Model::load` does).
    pub fn new(model: Model) -> Self {
        let (work_rows, work_cols) = model.work_size().unwrap_or((1, 1));
        let n = model.feature_len();
        let fx = FeatureExtractor::new(work_rows * work_cols);
        let s = model.kernel_width;
        let h = model.h as f64;
        let mut log_norm = [0.0; MAX_CLASSES];
        for (k, ln) in log_norm.iter_mut().enumerate().take(model.classes.len()) {
            let n_k = model
                .sample_classes
                .iter()
                .filter(|&&c| c == k)
                .count()
                .max(1) as f64;
            *ln = -n_k.ln() - 0.5 * h * (2.0 * std::f64::consts::PI * s * s).ln();
        }
        Self {
            fx,
            work: vec![0; work_rows * work_cols],
            work_rows,
            work_cols,
            feat: vec![0.0; n],
            centered: vec![0.0; n],
            q: vec![0.0; model.h],
            d2: vec![0.0; model.n_samples()],
            dead_rows: vec![false; work_rows],
            dead_cols: vec![false; work_cols],
            inv_two_s2: 1.0 / (2.0 * s * s),
            log_norm,
            model,
        }
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Size of the working image (after crop and downsampling).
    pub fn work_size(&self) -> (usize, usize) {
        (self.work_rows, self.work_cols)
    }

    /// Crops and downsamples a sensor image into the working buffer.
    pub fn prepare(
        &mut self,
        pixels: &[u16],
        rows: usize,
        cols: usize,
    ) -> Result<(), SizeMismatch> {
        let m = &self.model;
        if rows != m.input_rows || cols != m.input_cols || pixels.len() != rows * cols {
            return Err(SizeMismatch {
                rows,
                cols,
                want_rows: m.input_rows,
                want_cols: m.input_cols,
            });
        }
        let k = m.downsample.max(1);
        let c = m.crop;
        let mut i = 0;
        for r in (c.top..rows - c.bottom).step_by(k) {
            for col in (c.left..cols - c.right).step_by(k) {
                self.work[i] = pixels[r * cols + col];
                i += 1;
            }
        }
        Ok(())
    }

    /// The working image, for a repair done by the caller (the node's history-based repair).
    pub fn work_mut(&mut self) -> &mut [u16] {
        &mut self.work
    }

    /// The paper's per-image repair filter on the working image; returns lines filled.
    pub fn repair_work(&mut self) -> usize {
        let (rows, cols) = (self.work_rows, self.work_cols);
        let n = repair::find_zero_lines(
            &self.work,
            rows,
            cols,
            None,
            &mut self.dead_rows,
            &mut self.dead_cols,
        );
        if n > 0 {
            repair::repair_lines(
                &mut self.work,
                rows,
                cols,
                &self.dead_rows,
                &self.dead_cols,
                None,
            );
        }
        n
    }

    /// Features, projection and decision for the working image.
    pub fn decide(&mut self) -> Decision {
        let m = &self.model;
        let scale = match m.normalize_load {
            Some(target) => {
                let total: f64 = self.work.iter().map(|&p| p as f64).sum();
                if total > 0.0 {
                    (target / total) as f32
                } else {
                    1.0
                }
            }
            None => 1.0,
        };
        self.fx.extract(&self.work, scale, &mut self.feat);
        for ((c, f), mu) in self.centered.iter_mut().zip(&self.feat).zip(&m.pca_mean) {
            *c = f - mu;
        }
        let n = self.feat.len();
        for (j, q) in self.q.iter_mut().enumerate() {
            *q = dot(&m.pca_matrix[j * n..(j + 1) * n], &self.centered);
        }
        let h = m.h;
        for (i, d) in self.d2.iter_mut().enumerate() {
            let s = &m.samples[i * h..(i + 1) * h];
            let mut acc = 0.0f32;
            for (a, b) in s.iter().zip(&self.q) {
                let t = a - b;
                acc += t * t;
            }
            *d = acc as f64;
        }
        let n_classes = m.classes.len();
        let mut log_dens = [f64::NEG_INFINITY; MAX_CLASSES];
        let mut max_e = [f64::NEG_INFINITY; MAX_CLASSES];
        for (d, &k) in self.d2.iter().zip(&m.sample_classes) {
            let e = -d * self.inv_two_s2;
            if e > max_e[k] {
                max_e[k] = e;
            }
        }
        let mut sums = [0.0f64; MAX_CLASSES];
        for (d, &k) in self.d2.iter().zip(&m.sample_classes) {
            sums[k] += (-d * self.inv_two_s2 - max_e[k]).exp();
        }
        for k in 0..n_classes {
            log_dens[k] = max_e[k] + sums[k].ln() + self.log_norm[k];
        }
        let mut best = 0;
        for k in 1..n_classes {
            if log_dens[k] > log_dens[best] {
                best = k;
            }
        }
        let mut z = 0.0;
        for ld in log_dens.iter().take(n_classes) {
            z += (ld - log_dens[best]).exp();
        }
        let log_z = log_dens[best] + z.ln();
        let mut log_posteriors = [f64::NEG_INFINITY; MAX_CLASSES];
        for k in 0..n_classes {
            log_posteriors[k] = log_dens[k] - log_z;
        }
        let known = log_dens[best] >= m.unknown_threshold;
        Decision {
            class: known.then_some(best),
            best,
            terrain_id: if known {
                m.classes[best].terrain_id
            } else {
                protocol::messages::TERRAIN_UNKNOWN
            },
            confidence: log_posteriors[best].exp(),
            log_density: log_dens[best],
            log_posteriors,
            n_classes,
        }
    }

    /// Decision for an already cropped and downsampled image (training's validation pass).
    pub fn classify_work(&mut self, work: &[u16]) -> Decision {
        self.work.copy_from_slice(work);
        self.decide()
    }

    /// The whole pipeline for one sensor image.
    pub fn classify(
        &mut self,
        pixels: &[u16],
        rows: usize,
        cols: usize,
        repair: bool,
    ) -> Result<Decision, SizeMismatch> {
        self.prepare(pixels, rows, cols)?;
        if repair {
            self.repair_work();
        }
        Ok(self.decide())
    }
}

#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    // Eight independent accumulators let the compiler vectorise the reduction.
    let mut acc = [0.0f32; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s: f32 = acc.iter().sum();
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}
