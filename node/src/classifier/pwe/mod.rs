//! The classifier at run time: crop, downsample, (repair), feature vector, PCA projection and the
//! Parzen-window (Gaussian kernel density) decision. Every buffer is allocated when the
//! classifier is built; classifying an image allocates nothing.
//!
//! The run-time classifier's buffers and the steps that share them are one file: split, each
//! step would reach into the others' buffers. How the buffers are sized and filled from a
//! model is `build.rs`; what a decision returns, [`Decision`], is in `decision.rs`.

use super::Kernels;
use super::features::FeatureExtractor;
use super::kernels::{centre, load_area, project, quad_form, sq_dists};
use super::model::{MinContact, Model};
use super::repair;
use crate::unknown::novelty::MAX_K;
use crate::unknown::{self, Measured};

mod build;

pub use super::decision::Decision;
pub use super::model::{DepthMismatch, ImageMismatch, SizeMismatch};

/// A model ready to classify: planned FFT and scratch buffers sized once, so that a decision allocates nothing.
pub struct Classifier {
    model: Model,
    fx: FeatureExtractor,
    work: Vec<u16>,
    work_rows: usize,
    work_cols: usize,
    feat: Vec<f32>,
    /// U mean, so that projecting needs no centred copy of the feature vector.
    projected_mean: Vec<f32>,
    /// The PCA matrix in half precision (empty without AVX2/FMA/F16C): the projection streams
    /// 52 x 1025 weights per image from L2, and half the bytes is most of its time.
    w16: Vec<u16>,
    /// The projection, padded with zeros to `stride` lanes.
    q: Vec<f32>,
    /// F - mean (models with a novelty score).
    centred: Vec<f32>,
    /// (U U^T)^-1 - I for the half-precision weights the projection runs with, h x h padded to
    /// stride x stride with zeros (empty for
    /// the f32 weights, orthonormal to 1e-7, and for models without a novelty score).
    gram_corr: Vec<f32>,
    /// The stored samples, each padded with zeros to `stride` (h rounded up to 8) so that the
    /// distances run in whole 8-lane vectors.
    samples: Vec<f32>,
    /// Per stored sample: -|q - x_i|^2 / (2 s^2), the log of its kernel up to a constant.
    log_kernel: Vec<f64>,
    /// The novelty's reference images (other runs' known images), padded as `samples` and
    /// sorted by class: only the best class's are measured.
    reference: Vec<f32>,
    /// Per class, its range of reference images.
    reference_of: Vec<std::ops::Range<usize>>,
    /// Per reference image, its squared distance to the image (the best class's only).
    reference_d2: Vec<f64>,
    /// The novelty's nuisance directions in half precision (as `w16`: empty without
    /// AVX2/FMA/F16C), and the centred feature vector's coordinates along them.
    nuisance16: Vec<u16>,
    nuisance_q: Vec<f32>,
    dead_rows: Vec<bool>,
    dead_cols: Vec<bool>,
    inv_two_s2: f64,
    /// Per class, sized once: the density's normalisation, and the last decision's working
    /// values and log posteriors.
    log_norm: Vec<f64>,
    log_dens: Vec<f64>,
    max_e: Vec<f64>,
    sums: Vec<f64>,
    log_posteriors: Vec<f64>,
    /// The best class's `MAX_K` smallest squared distances to the image, ascending (the kNN
    /// ratio of the novelty score).
    knn: [f64; MAX_K],
    /// Per class, the indices of its stored samples.
    samples_of: Vec<Vec<usize>>,
    /// A stored sample left out of the kNN distances (calibrating on the stored samples
    /// themselves); `usize::MAX` otherwise.
    exclude: usize,
    /// The last decision's kNN distance and residual length (the novelty's parts).
    parts: (f64, f64),
    contact: MinContact,
    kernels: Kernels,
    avx2_fma: bool,
}

impl Classifier {
    /// Builds the run-time buffers, with the fastest kernels this CPU has; the model must have
    /// passed `Model::validate` (as `Model::load` does).
    pub fn new(model: Model) -> Self {
        Self::with_kernels(model, Kernels::Native)
    }

    /// The model it classifies with.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The kernels this classifier was built with.
    pub fn kernels(&self) -> Kernels {
        self.kernels
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
        if k == 1 {
            // Full resolution: whole cropped rows as slice copies (memcpy), not pixel by pixel.
            let w = self.work_cols;
            for (dst, r) in self.work.chunks_exact_mut(w).zip(c.top..rows - c.bottom) {
                dst.copy_from_slice(&pixels[r * cols + c.left..r * cols + c.left + w]);
            }
            return Ok(());
        }
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

    /// The working image shows a foot on the ground (the model's [`MinContact`]).
    pub fn in_contact(&self) -> bool {
        let (load, area) = load_area(&self.work, self.avx2_fma);
        self.contact.holds_for(load, area)
    }

    /// Log posterior per class of the last decision (equal priors; all -inf after a decision
    /// without contact).
    pub fn log_posteriors(&self) -> &[f64] {
        &self.log_posteriors
    }

    /// Features, projection and decision for the working image; an image without contact is
    /// "unknown" without features (a blank or nearly blank frame lay nearest one class's
    /// samples and came out as that terrain at confidence 1.0).
    pub fn decide(&mut self) -> Decision {
        let (load, area) = load_area(&self.work, self.avx2_fma);
        if !self.contact.holds_for(load, area) {
            self.log_posteriors.fill(f64::NEG_INFINITY);
            return Decision::NO_CONTACT;
        }
        self.decide_with_load(load)
    }

    /// [`Classifier::decide`] for a working image the caller has found in contact
    /// ([`Classifier::in_contact`]), without checking it again. Its load is measured here: the
    /// caller may have repaired the image since.
    pub fn decide_in_contact(&mut self) -> Decision {
        let m = &self.model;
        let load = if m.normalize_load.is_some() || m.unknown.load_bands.is_some() {
            load_area(&self.work, self.avx2_fma).0
        } else {
            0
        };
        self.decide_with_load(load)
    }

    /// The decision for a working image in contact whose load is `load`: the feature vector
    /// and its projection, the residual, the Parzen posterior, then what the unknown-ground
    /// checks say of the best class ([`crate::unknown::checks::Checks::judge`]).
    fn decide_with_load(&mut self, load: u64) -> Decision {
        let m = &self.model;
        // Only when the model scales or checks the load.
        let total = if m.normalize_load.is_some() || m.unknown.load_bands.is_some() {
            load as f64
        } else {
            0.0
        };
        let c2 = self.project_image(total);
        self.parts.1 = self.residual(c2);
        let best = self.posterior();
        let measured = self.measure(best, total);
        let reason = self.verdict(measured);
        let m = &self.model;
        let known = reason.is_none();
        // The measured chance of being right where `train` measured it, else the posterior.
        let confidence = match &m.confidence {
            Some(map) => {
                let lp = &self.log_posteriors;
                let next = (0..lp.len())
                    .filter(|&k| k != best)
                    .map(|k| lp[k])
                    .fold(f64::NEG_INFINITY, f64::max);
                let f = super::confidence::features(
                    lp[best] - next,
                    measured.novelty,
                    measured.threshold,
                );
                map.chance(f)
            }
            None => self.log_posteriors[best].exp(),
        };
        Decision {
            class: known.then_some(best),
            best,
            terrain_id: if known {
                m.classes[best].terrain_id
            } else {
                protocol::messages::TERRAIN_UNKNOWN
            },
            confidence,
            log_density: self.log_dens[best],
            contact: true,
            novelty: measured.novelty,
            threshold: measured.threshold,
            reason,
        }
    }

    /// The unknown-ground checks' verdict on the working image measured as `m` (its roughness
    /// measured only if the other checks call it known: it is the dearest).
    #[inline]
    fn verdict(&self, m: Measured) -> Option<unknown::Reason> {
        let (w, rows, cols, avx2) = (&self.work, self.work_rows, self.work_cols, self.avx2_fma);
        self.model
            .unknown
            .judge(m, || super::texture::roughness_with(w, rows, cols, avx2))
    }

    /// After a decision: the verdict of the checks on the same image had its class been each
    /// of the model's in turn, into `out` (one per class). The multi-frame rule decides a
    /// step's terrain from its frames' summed posterior, and judges that class, not the one
    /// its sample-time frame would have picked alone. No allocation.
    pub fn verdicts_per_class(&mut self, out: &mut [Option<unknown::Reason>]) {
        let m = &self.model;
        let total = if m.normalize_load.is_some() || m.unknown.load_bands.is_some() {
            load_area(&self.work, self.avx2_fma).0 as f64
        } else {
            0.0
        };
        for (k, v) in out.iter_mut().enumerate().take(self.model.classes.len()) {
            let m = self.measure(k, total);
            *v = self.verdict(m);
        }
        // The decision's own parts are the best class's: put them back.
        let best = (0..self.log_dens.len())
            .max_by(|&a, &b| self.log_dens[a].total_cmp(&self.log_dens[b]))
            .unwrap_or(0);
        self.measure(best, total);
    }

    /// The feature vector of the working image (scaled to the model's load when it
    /// normalises; `total` is the image's) and its projection `q`; returns |F - mean|^2 for the
    /// residual (0 for models without a novelty score).
    fn project_image(&mut self, total: f64) -> f64 {
        let m = &self.model;
        let scale = match m.normalize_load {
            Some(target) if total > 0.0 => (target / total) as f32,
            _ => 1.0,
        };
        self.fx.extract(&self.work, scale, &mut self.feat);
        let h = m.h;
        if m.unknown.novelty.is_some() {
            // Q = U (F - mean) from the centred vector: the residual is a difference of
            // |F - mean|^2 and |Q|^2, and U F - U mean loses Q's low digits to F's large mean
            // in f32 (measured: the residual off by a factor 4 on the synthetic textures).
            let c2 = centre(&self.feat, &m.pca_mean, &mut self.centred, self.avx2_fma);
            project(
                &m.pca_matrix,
                &self.w16,
                &self.centred,
                &mut self.q[..h],
                self.avx2_fma,
            );
            return c2;
        }
        // U (F - mean) = U F - U mean, with U mean computed once in `new`.
        project(
            &m.pca_matrix,
            &self.w16,
            &self.feat,
            &mut self.q[..h],
            self.avx2_fma,
        );
        for (q, b) in self.q.iter_mut().zip(&self.projected_mean) {
            *q -= b;
        }
        0.0
    }

    /// The length of F - mean outside the PCA rows' span and the nuisance directions (0 for a
    /// `knn` score, which does not use it; NaN without a novelty score).
    fn residual(&mut self, c2: f64) -> f64 {
        let m = &self.model;
        let Some(nv) = &m.unknown.novelty else {
            return f64::NAN;
        };
        if nv.score == crate::unknown::novelty::NoveltyScore::Knn {
            // The kNN ratio alone: the residual is not part of the score, and not computed.
            return 0.0;
        }
        // |F - mean|^2 less the squared length of its projection, Q^T G^-1 Q with G = U U^T of
        // the weights the kernel used. The half-precision rows are not orthonormal enough for
        // |Q|^2 alone: measured on the synthetic textures, the residual came out 1034 where it
        // is 235.
        let q = &self.q[..m.h];
        let mut q2: f64 = q.iter().map(|&v| v as f64 * v as f64).sum();
        // G^-1 = I + E with E of order 1e-3: Q^T E Q in f32 is exact enough, and vectorises
        // (3,136 multiply-adds for h = 52 padded to 56).
        q2 += quad_form(&self.gram_corr, &self.q, self.avx2_fma);
        // Less its length along the nuisance directions (orthogonal to the rows): where the
        // known terrains' runs differ, not the terrain.
        let mut nuisance = 0.0;
        if !self.nuisance_q.is_empty() {
            project(
                &nv.nuisance,
                &self.nuisance16,
                &self.centred,
                &mut self.nuisance_q,
                self.avx2_fma,
            );
            nuisance = self.nuisance_q.iter().map(|&v| v as f64 * v as f64).sum();
        }
        (c2 - q2 - nuisance).max(0.0).sqrt()
    }

    /// The Parzen posterior of the projection against the stored samples (equal priors):
    /// `log_kernel`, `log_dens` and `log_posteriors`; returns the best class.
    fn posterior(&mut self) -> usize {
        let m = &self.model;
        sq_dists(&self.samples, &self.q, &mut self.log_kernel, self.avx2_fma);
        let n_classes = m.classes.len();
        let (log_dens, max_e, sums) = (&mut self.log_dens, &mut self.max_e, &mut self.sums);
        max_e.fill(f64::NEG_INFINITY);
        sums.fill(0.0);
        for (e, &k) in self.log_kernel.iter_mut().zip(&m.sample_classes) {
            *e *= -self.inv_two_s2;
            let mk = &mut max_e[k];
            if *e > *mk {
                *mk = *e;
            }
        }
        for (e, &k) in self.log_kernel.iter().zip(&m.sample_classes) {
            let x = e - max_e[k];
            // Each class's sum holds its largest term, exp(0) = 1; a term below e^-40 (4e-18)
            // cannot change it in f64, and skipping it avoids libm's slow underflow path.
            if x > -40.0 {
                sums[k] += x.exp();
            }
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
        for ld in log_dens.iter() {
            z += (ld - log_dens[best]).exp();
        }
        let log_z = log_dens[best] + z.ln();
        for (lp, ld) in self.log_posteriors.iter_mut().zip(log_dens.iter()) {
            *lp = ld - log_z;
        }
        best
    }

    /// What the unknown-ground checks judge of the last projection as class `class`: its
    /// novelty against the class's threshold (the negated log density for a model without a
    /// novelty score) and the image's load `total`. Sets the kNN part of `novelty_parts`.
    fn measure(&mut self, class: usize, total: f64) -> Measured {
        let (novelty, threshold) = match self.model.unknown.novelty.is_some() {
            true => {
                let knn_dist = self.knn_distance(class);
                self.parts.0 = knn_dist;
                self.model
                    .unknown
                    .novelty
                    .as_ref()
                    .map_or((f64::NAN, f64::NAN), |nv| {
                        (
                            nv.score_of(class, knn_dist, self.parts.1),
                            nv.thresholds[class],
                        )
                    })
            }
            false => (
                -self.log_dens[class],
                -self.model.unknown.density_thresholds[class],
            ),
        };
        Measured {
            best: class,
            novelty,
            threshold,
            load: total,
        }
    }

    /// The mean distance from the projection to the `k` nearest stored samples (and
    /// references) of `class`, from the posterior's `log_kernel`; +inf for a class with no
    /// other stored sample (calibrating on its only one: nothing is known about it).
    fn knn_distance(&mut self, class: usize) -> f64 {
        let Some(nv) = &self.model.unknown.novelty else {
            return f64::NAN;
        };
        // The class's stored samples and references only: the kNN ratio looks at no other.
        let b = &mut self.knn[..nv.k];
        b.fill(f64::INFINITY);
        let to_d2 = -1.0 / self.inv_two_s2;
        for &i in &self.samples_of[class] {
            if i != self.exclude {
                insert_smallest(b, self.log_kernel[i] * to_d2);
            }
        }
        let range = self.reference_of[class].clone();
        if !range.is_empty() {
            let stride = self.q.len();
            let d2 = &mut self.reference_d2[..range.len()];
            let refs = &self.reference[range.start * stride..range.end * stride];
            sq_dists(refs, &self.q, d2, self.avx2_fma);
            for &v in d2.iter() {
                insert_smallest(b, v);
            }
        }
        let (mut sum, mut n) = (0.0, 0usize);
        for &d2 in b.iter().take_while(|d| d.is_finite()) {
            sum += d2.sqrt();
            n += 1;
        }
        if n > 0 { sum / n as f64 } else { f64::INFINITY }
    }

    /// The last decision's projection into the model's PCA space (h values; meaningful after a
    /// decision in contact). For calibration.
    pub fn projection(&self) -> &[f32] {
        &self.q[..self.model.h]
    }

    /// The last decision's feature vector F (scaled to the model's load when it normalises):
    /// the whole of what the image shows the model, inside its PCA subspace and out.
    pub fn features(&self) -> &[f32] {
        &self.feat
    }

    /// The last decision's centred feature vector, F - mean (models with a novelty score). For
    /// calibration.
    pub fn centred(&self) -> &[f32] {
        &self.centred
    }

    /// The last decision's novelty parts: the mean distance to the best class's k nearest
    /// stored samples and the residual length outside the PCA subspace (NaN for a model
    /// without a novelty score). For calibration.
    pub fn novelty_parts(&self) -> (f64, f64) {
        self.parts
    }

    /// The last decision's distance, in PCA space, to the nearest stored sample of any class
    /// (the plain nearest-neighbour score reports compare the novelty with); NaN before a
    /// decision in contact. From the decision's own distances: nothing is computed again.
    pub fn nearest_sample_distance(&self) -> f64 {
        let e = self
            .log_kernel
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        (-e / self.inv_two_s2).max(0.0).sqrt()
    }

    /// Leaves stored sample `i` out of the kNN distances of the decisions that follow
    /// (`None`: none left out), to score a stored sample as if it were new.
    pub fn exclude_sample(&mut self, i: Option<usize>) {
        self.exclude = i.unwrap_or(usize::MAX);
    }

    /// Decision for an already cropped and downsampled image (training's validation pass).
    pub fn classify_work(&mut self, work: &[u16]) -> Decision {
        self.work.copy_from_slice(work);
        self.decide()
    }

    /// The whole pipeline for one image file's image: its size and bit depth checked against
    /// the model's.
    pub fn classify_image(
        &mut self,
        img: &super::PressureImage,
        repair: bool,
    ) -> Result<Decision, ImageMismatch> {
        self.model.check_depth(img.bits)?;
        Ok(self.classify(&img.pixels, img.rows, img.cols, repair)?)
    }

    /// The whole pipeline for one sensor image (its bit depth is the caller's to check, see
    /// [`Model::check_depth`]).
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

/// Inserts `d2` into `b`, the ascending smallest values so far, when it is smaller than the
/// largest of them.
#[inline]
fn insert_smallest(b: &mut [f64], d2: f64) {
    let k = b.len();
    if d2 < b[k - 1] {
        let mut j = k - 1;
        while j > 0 && b[j - 1] > d2 {
            b[j] = b[j - 1];
            j -= 1;
        }
        b[j] = d2;
    }
}
