//! The classifier at run time: crop, downsample, (repair), feature vector, PCA projection and the
//! Parzen-window (Gaussian kernel density) decision. Every buffer is allocated when the
//! classifier is built; classifying an image allocates nothing.

use super::Kernels;
use super::features::FeatureExtractor;
use super::model::{MinContact, Model};
use super::novelty::MAX_K;
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
    /// Log Parzen density of the best class (-inf without contact).
    pub log_density: f64,
    /// The image shows a foot on the ground (see [`MinContact`]). Without contact nothing else
    /// was computed: the decision is unknown, confidence 0, and no class is "best".
    pub contact: bool,
    /// How unlike any known terrain the image is, larger = less like (see
    /// [`super::novelty`]); for a model without a novelty score, the negated log density.
    /// +inf without contact.
    pub novelty: f64,
    /// The best class's threshold the novelty was held against: above it, unknown. (For a
    /// model without a novelty score, the negated density threshold.)
    pub threshold: f64,
}

impl Decision {
    /// The decision for an image without contact: unknown, confidence 0.
    pub const NO_CONTACT: Decision = Decision {
        class: None,
        best: 0,
        terrain_id: protocol::messages::TERRAIN_UNKNOWN,
        confidence: 0.0,
        log_density: f64::NEG_INFINITY,
        contact: false,
        novelty: f64::INFINITY,
        threshold: f64::INFINITY,
    };
}

/// An image of another bit depth than the model's training images.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error(
    "a {bits}-bit image, but the model was trained on {want_bits}-bit images: pixel values of \
     one depth mean nothing on the other's scale (docs/protocol.md); train a model on \
     {bits}-bit images"
)]
pub struct DepthMismatch {
    /// Bits per pixel of the image given.
    pub bits: u8,
    /// Bits per pixel of the model's training images.
    pub want_bits: u8,
}

/// An image that does not fit the model.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ImageMismatch {
    /// Another size.
    #[error(transparent)]
    Size(#[from] SizeMismatch),
    /// Another bit depth.
    #[error(transparent)]
    Depth(#[from] DepthMismatch),
}

/// An image that does not fit the model.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("image is {rows}x{cols} but the model takes {want_rows}x{want_cols} images")]
pub struct SizeMismatch {
    /// Rows of the image given.
    pub rows: usize,
    /// Columns of the image given.
    pub cols: usize,
    /// Rows the model takes.
    pub want_rows: usize,
    /// Columns the model takes.
    pub want_cols: usize,
}

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
    /// (U U^T)^-1 - I for the half-precision weights the projection runs with, h x h (empty for
    /// the f32 weights, orthonormal to 1e-7, and for models without a novelty score).
    gram_corr: Vec<f32>,
    /// The stored samples, each padded with zeros to `stride` (h rounded up to 8) so that the
    /// distances run in whole 8-lane vectors.
    samples: Vec<f32>,
    /// Per stored sample: -|q - x_i|^2 / (2 s^2), the log of its kernel up to a constant.
    log_kernel: Vec<f64>,
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
    /// Per class, its `MAX_K` smallest squared distances to the image, ascending (the kNN
    /// ratio of the novelty score); sized once.
    knn: Vec<[f64; MAX_K]>,
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

    /// [`Classifier::new`] with the given kernels ([`Kernels::Portable`]: what an ARM computer
    /// runs, and the reference the native kernels are checked against).
    pub fn with_kernels(model: Model, kernels: Kernels) -> Self {
        let (work_rows, work_cols) = model.work_size().unwrap_or((1, 1));
        let n = model.feature_len();
        let fx = FeatureExtractor::with_kernels(work_rows * work_cols, kernels);
        let avx2_fma = kernels.avx2_fma();
        let s = model.kernel_width;
        let h = model.h as f64;
        let n_classes = model.classes.len();
        let mut log_norm = vec![0.0; n_classes];
        for (k, ln) in log_norm.iter_mut().enumerate() {
            let n_k = model
                .sample_classes
                .iter()
                .filter(|&&c| c == k)
                .count()
                .max(1) as f64;
            *ln = -n_k.ln() - 0.5 * h * (2.0 * std::f64::consts::PI * s * s).ln();
        }
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
        let gram_corr = if model.novelty.is_some() && !w16.is_empty() {
            let h = model.h;
            let mut g = gram_inverse(&model.pca_matrix, &w16, h);
            for a in 0..h {
                g[a * h + a] -= 1.0;
            }
            g.into_iter().map(|v| v as f32).collect()
        } else {
            Vec::new()
        };
        let stride = model.h.div_ceil(8) * 8;
        let mut samples = vec![0.0; stride * model.n_samples()];
        if model.h > 0 {
            for (dst, src) in samples
                .chunks_exact_mut(stride)
                .zip(model.samples.chunks_exact(model.h))
            {
                dst[..model.h].copy_from_slice(src);
            }
        }
        Self {
            fx,
            work: vec![0; work_rows * work_cols],
            work_rows,
            work_cols,
            feat: vec![0.0; n],
            projected_mean,
            w16,
            q: vec![0.0; stride],
            centred: vec![0.0; if model.novelty.is_some() { n } else { 0 }],
            gram_corr,
            samples,
            log_kernel: vec![0.0; model.n_samples()],
            dead_rows: vec![false; work_rows],
            dead_cols: vec![false; work_cols],
            inv_two_s2: 1.0 / (2.0 * s * s),
            log_norm,
            log_dens: vec![0.0; n_classes],
            max_e: vec![0.0; n_classes],
            sums: vec![0.0; n_classes],
            log_posteriors: vec![0.0; n_classes],
            knn: vec![[f64::INFINITY; MAX_K]; n_classes],
            exclude: usize::MAX,
            parts: (f64::NAN, f64::NAN),
            // Older model files carry no contact figures: then only a blank image is refused.
            contact: model.contact.unwrap_or(MinContact { load: 0, area: 0 }),
            kernels,
            avx2_fma,
            model,
        }
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
        self.contact.holds(&self.work)
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
        if !self.in_contact() {
            self.log_posteriors.fill(f64::NEG_INFINITY);
            return Decision::NO_CONTACT;
        }
        self.decide_in_contact()
    }

    /// [`Classifier::decide`] for a working image the caller has found in contact
    /// ([`Classifier::in_contact`]), without measuring it again.
    pub fn decide_in_contact(&mut self) -> Decision {
        let m = &self.model;
        // An integer sum: exact, and it vectorises (an f64 running sum is one long dependency
        // chain). Only when the model scales or checks the load.
        let total = if m.normalize_load.is_some() || m.load_ranges.is_some() {
            self.work.iter().map(|&p| p as u64).sum::<u64>() as f64
        } else {
            0.0
        };
        let scale = match m.normalize_load {
            Some(target) if total > 0.0 => (target / total) as f32,
            _ => 1.0,
        };
        self.fx.extract(&self.work, scale, &mut self.feat);
        let h = m.h;
        let mut c2 = 0.0;
        if m.novelty.is_some() {
            // Q = U (F - mean) from the centred vector: the residual below is a difference of
            // |F - mean|^2 and |Q|^2, and U F - U mean loses Q's low digits to F's large mean
            // in f32 (measured: the residual off by a factor 4 on the synthetic textures).
            c2 = centre(&self.feat, &m.pca_mean, &mut self.centred, self.avx2_fma);
            project(
                &m.pca_matrix,
                &self.w16,
                &self.centred,
                &mut self.q[..h],
                self.avx2_fma,
            );
        } else {
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
        }
        sq_dists(&self.samples, &self.q, &mut self.log_kernel, self.avx2_fma);
        let n_classes = m.classes.len();
        if let Some(nv) = &m.novelty {
            // The part of F - mean outside the rows' span: |F - mean|^2 less the squared length
            // of its projection, Q^T G^-1 Q with G = U U^T of the weights the kernel used. The
            // half-precision rows are not orthonormal enough for |Q|^2 alone: measured on the
            // synthetic textures, the residual came out 1034 where it is 235.
            let q = &self.q[..h];
            let mut q2: f64 = q.iter().map(|&v| v as f64 * v as f64).sum();
            // G^-1 = I + E with E of order 1e-3: Q^T E Q in f32 is exact enough, and
            // vectorises (2,700 multiply-adds for h = 52).
            q2 += quad_form(&self.gram_corr, q, self.avx2_fma);
            let residual = (c2 - q2).max(0.0).sqrt();
            let k = nv.k;
            for b in self.knn.iter_mut() {
                b[..k].fill(f64::INFINITY);
            }
            for (i, (&d2, &c)) in self.log_kernel.iter().zip(&m.sample_classes).enumerate() {
                let b = &mut self.knn[c];
                if d2 < b[k - 1] && i != self.exclude {
                    // Insertion into the class's k smallest, ascending.
                    let mut j = k - 1;
                    while j > 0 && b[j - 1] > d2 {
                        b[j] = b[j - 1];
                        j -= 1;
                    }
                    b[j] = d2;
                }
            }
            self.parts.1 = residual;
        }
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
        let threshold = match &m.unknown_thresholds {
            Some(t) => t[best],
            None => m.unknown_threshold,
        };
        let in_range = m
            .load_ranges
            .as_ref()
            .is_none_or(|r| (r[best][0]..=r[best][1]).contains(&total));
        let (novelty, threshold) = match &m.novelty {
            Some(nv) => {
                let b = &self.knn[best][..nv.k];
                let (mut sum, mut n) = (0.0, 0usize);
                for &d2 in b.iter().take_while(|d| d.is_finite()) {
                    sum += d2.sqrt();
                    n += 1;
                }
                // A class with no other stored sample (calibrating on its only one): no
                // distance to judge by, so nothing is known about it.
                let knn_dist = if n > 0 { sum / n as f64 } else { f64::INFINITY };
                self.parts.0 = knn_dist;
                (
                    nv.score_of(best, knn_dist, self.parts.1),
                    nv.thresholds[best],
                )
            }
            None => (-log_dens[best], -threshold),
        };
        let known = novelty <= threshold && in_range;
        Decision {
            class: known.then_some(best),
            best,
            terrain_id: if known {
                m.classes[best].terrain_id
            } else {
                protocol::messages::TERRAIN_UNKNOWN
            },
            confidence: self.log_posteriors[best].exp(),
            log_density: log_dens[best],
            contact: true,
            novelty,
            threshold,
        }
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

/// `W` in IEEE half precision when this CPU converts it in hardware (F16C), else nothing.
/// A weight of W (a unit vector's component) keeps 11 significant bits: the projection of a
/// feature vector moves by about 5e-4 of its length, far below the distances between samples.
/// Called only when the AVX2/FMA kernels run.
fn half_matrix(w: &[f32]) -> Vec<u16> {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = w;
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("f16c") {
        let mut out = vec![0u16; w.len()];
        // SAFETY: the CPU supports the features the function was compiled for.
        unsafe { to_half_f16c(w, &mut out) };
        return out;
    }
    Vec::new()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,f16c")]
fn to_half_f16c(w: &[f32], out: &mut [u16]) {
    use std::arch::x86_64::*;
    for (src, dst) in w.chunks_exact(8).zip(out.chunks_exact_mut(8)) {
        // SAFETY: both chunks hold eight elements; unaligned loads and stores are allowed.
        unsafe {
            let h = _mm256_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(_mm256_loadu_ps(src.as_ptr()));
            _mm_storeu_si128(dst.as_mut_ptr() as *mut __m128i, h);
        }
    }
    let done = w.len() - w.len() % 8;
    let mut tail = [0.0f32; 8];
    tail[..w.len() - done].copy_from_slice(&w[done..]);
    let mut half = [0u16; 8];
    // SAFETY: as above, on local arrays of eight.
    unsafe {
        let h = _mm256_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(_mm256_loadu_ps(tail.as_ptr()));
        _mm_storeu_si128(half.as_mut_ptr() as *mut __m128i, h);
    }
    out[done..].copy_from_slice(&half[..w.len() - done]);
}

/// `q = W c` for the row-major PCA matrix `W` (h x n): the bulk of the per-image arithmetic
/// (52 x 1025 multiply-adds for the paper's sizes). `w16` is `W` in half precision, or empty;
/// `avx2_fma` says the CPU has both ([`Kernels::avx2_fma`]).
fn project(w: &[f32], w16: &[u16], c: &[f32], q: &mut [f32], avx2_fma: bool) {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (w16, avx2_fma);
    #[cfg(target_arch = "x86_64")]
    if avx2_fma && !w16.is_empty() {
        // SAFETY: `w16` is only filled when the CPU has AVX2, FMA and F16C.
        unsafe { project_f16c(w, w16, c, q) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        unsafe { project_avx2(w, c, q) };
        return;
    }
    project_portable(w, c, q);
}

/// The sum of an AVX vector's eight lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn hsum(v: std::arch::x86_64::__m256) -> f32 {
    let mut lanes = [0.0f32; 8];
    // SAFETY: `lanes` holds eight f32; an unaligned store is allowed.
    unsafe { std::arch::x86_64::_mm256_storeu_ps(lanes.as_mut_ptr(), v) };
    lanes.iter().sum()
}

/// AVX2 + FMA: four rows of W at a time, two 8-lane accumulators each. Eight independent FMA
/// chains hide the FMA latency (the compiler's own vectorisation kept two and was latency-bound),
/// and each load of `c` serves four rows.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn project_avx2(w: &[f32], c: &[f32], q: &mut [f32]) {
    use std::arch::x86_64::*;
    let n = c.len();
    let n16 = n - n % 16;
    let rows = q.len();
    let mut j = 0;
    while j + 4 <= rows {
        let r: [&[f32]; 4] = std::array::from_fn(|i| &w[(j + i) * n..(j + i + 1) * n]);
        let mut acc = [_mm256_setzero_ps(); 8];
        let mut k = 0;
        while k < n16 {
            // SAFETY: k + 16 <= n16 <= n = each slice's length, so every 8-lane load is in bounds.
            unsafe {
                let c0 = _mm256_loadu_ps(c.as_ptr().add(k));
                let c1 = _mm256_loadu_ps(c.as_ptr().add(k + 8));
                for i in 0..4 {
                    let p = r[i].as_ptr().add(k);
                    acc[2 * i] = _mm256_fmadd_ps(_mm256_loadu_ps(p), c0, acc[2 * i]);
                    acc[2 * i + 1] = _mm256_fmadd_ps(_mm256_loadu_ps(p.add(8)), c1, acc[2 * i + 1]);
                }
            }
            k += 16;
        }
        for i in 0..4 {
            let mut s = hsum(_mm256_add_ps(acc[2 * i], acc[2 * i + 1]));
            for kk in n16..n {
                s += r[i][kk] * c[kk];
            }
            q[j + i] = s;
        }
        j += 4;
    }
    for (jj, qj) in q.iter_mut().enumerate().skip(j) {
        *qj = dot(&w[jj * n..(jj + 1) * n], c);
    }
}

/// [`project_avx2`] reading the half-precision copy of W; the last `n % 16` columns come
/// from the f32 W.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,f16c")]
fn project_f16c(w: &[f32], w16: &[u16], c: &[f32], q: &mut [f32]) {
    use std::arch::x86_64::*;
    let n = c.len();
    let n16 = n - n % 16;
    let rows = q.len();
    let mut j = 0;
    while j < rows {
        let m = (rows - j).min(4);
        let r: [&[u16]; 4] = std::array::from_fn(|i| {
            let jj = j + i.min(m - 1);
            &w16[jj * n..(jj + 1) * n]
        });
        let mut acc = [_mm256_setzero_ps(); 8];
        let mut k = 0;
        while k < n16 {
            // SAFETY: k + 16 <= n16 <= n = each slice's length, so every 8-lane load is in bounds.
            unsafe {
                let c0 = _mm256_loadu_ps(c.as_ptr().add(k));
                let c1 = _mm256_loadu_ps(c.as_ptr().add(k + 8));
                for i in 0..4 {
                    let p = r[i].as_ptr().add(k) as *const __m128i;
                    let w0 = _mm256_cvtph_ps(_mm_loadu_si128(p));
                    let w1 = _mm256_cvtph_ps(_mm_loadu_si128(p.add(1)));
                    acc[2 * i] = _mm256_fmadd_ps(w0, c0, acc[2 * i]);
                    acc[2 * i + 1] = _mm256_fmadd_ps(w1, c1, acc[2 * i + 1]);
                }
            }
            k += 16;
        }
        for i in 0..m {
            let mut s = hsum(_mm256_add_ps(acc[2 * i], acc[2 * i + 1]));
            for kk in n16..n {
                s += w[(j + i) * n + kk] * c[kk];
            }
            q[j + i] = s;
        }
        j += m;
    }
}

/// The projection with the target's baseline SIMD: the AVX2 kernel's shape (four rows of W per
/// pass over `c`, so that each load of `c` serves four rows; two 4-lane accumulators per row)
/// in SSE2 on x86-64 and NEON on aarch64, which every CPU of those targets has. Elsewhere,
/// one dot product per row.
///
/// Plain Rust over `[f32; 8]` lanes was tried first: LLVM's SLP vectoriser then packed the four
/// rows' lanes into one register (the reduction at the end is cheaper that way) and paid a
/// shuffle per load, 3x slower than these loops (measured with `cargo bench --bench classify`).
fn project_portable(w: &[f32], c: &[f32], q: &mut [f32]) {
    let n = c.len();
    let full = q.len() - q.len() % 4;
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    for (j4, q4) in q[..full].chunks_exact_mut(4).enumerate() {
        let j = 4 * j4;
        let rows: [&[f32]; 4] = std::array::from_fn(|i| &w[(j + i) * n..(j + i + 1) * n]);
        let sums = rows4(rows, c);
        q4.copy_from_slice(&sums);
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let full = 0;
    for (jj, qj) in q.iter_mut().enumerate().skip(full) {
        *qj = dot(&w[jj * n..(jj + 1) * n], c);
    }
}

/// Four dot products `rows[i] . c` (each row as long as `c`) with SSE2.
#[cfg(target_arch = "x86_64")]
fn rows4(rows: [&[f32]; 4], c: &[f32]) -> [f32; 4] {
    use std::arch::x86_64::*;
    let n = c.len();
    let n8 = n - n % 8;
    let mut out = [0.0f32; 4];
    // SAFETY: SSE2 is part of every x86-64 CPU; each 4-lane load reads k..k+8 <= n8 <= n
    // elements of `c` or of a row, both n long.
    unsafe {
        let mut acc = [_mm_setzero_ps(); 8];
        let mut k = 0;
        while k < n8 {
            let c0 = _mm_loadu_ps(c.as_ptr().add(k));
            let c1 = _mm_loadu_ps(c.as_ptr().add(k + 4));
            for i in 0..4 {
                let p = rows[i].as_ptr().add(k);
                acc[2 * i] = _mm_add_ps(acc[2 * i], _mm_mul_ps(_mm_loadu_ps(p), c0));
                acc[2 * i + 1] = _mm_add_ps(acc[2 * i + 1], _mm_mul_ps(_mm_loadu_ps(p.add(4)), c1));
            }
            k += 8;
        }
        for (i, o) in out.iter_mut().enumerate() {
            let mut lanes = [0.0f32; 4];
            _mm_storeu_ps(lanes.as_mut_ptr(), _mm_add_ps(acc[2 * i], acc[2 * i + 1]));
            *o = lanes.iter().sum();
        }
    }
    for (i, o) in out.iter_mut().enumerate() {
        for (x, y) in rows[i][n8..].iter().zip(&c[n8..]) {
            *o += x * y;
        }
    }
    out
}

/// Four dot products `rows[i] . c` (each row as long as `c`) with NEON fused multiply-adds.
#[cfg(target_arch = "aarch64")]
fn rows4(rows: [&[f32]; 4], c: &[f32]) -> [f32; 4] {
    use std::arch::aarch64::*;
    let n = c.len();
    let n8 = n - n % 8;
    let mut out = [0.0f32; 4];
    // SAFETY: NEON is part of every aarch64 CPU; each 4-lane load reads k..k+8 <= n8 <= n
    // elements of `c` or of a row, both n long.
    unsafe {
        let mut acc = [vdupq_n_f32(0.0); 8];
        let mut k = 0;
        while k < n8 {
            let c0 = vld1q_f32(c.as_ptr().add(k));
            let c1 = vld1q_f32(c.as_ptr().add(k + 4));
            for i in 0..4 {
                let p = rows[i].as_ptr().add(k);
                acc[2 * i] = vfmaq_f32(acc[2 * i], vld1q_f32(p), c0);
                acc[2 * i + 1] = vfmaq_f32(acc[2 * i + 1], vld1q_f32(p.add(4)), c1);
            }
            k += 8;
        }
        for (i, o) in out.iter_mut().enumerate() {
            *o = vaddvq_f32(vaddq_f32(acc[2 * i], acc[2 * i + 1]));
        }
    }
    for (i, o) in out.iter_mut().enumerate() {
        for (x, y) in rows[i][n8..].iter().zip(&c[n8..]) {
            *o += x * y;
        }
    }
    out
}

/// `q^T E q` for the h x h matrix `E` (empty: 0), in f32.
fn quad_form(e: &[f32], q: &[f32], avx2_fma: bool) -> f64 {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        return unsafe { quad_form_avx2(e, q) };
    }
    quad_form_portable(e, q)
}

/// [`quad_form_portable`] compiled for AVX2/FMA: the compiler's own 8-lane code (measured with
/// `cargo bench --bench classify`: this and [`centre`] in AVX2 took the decision with the
/// novelty score from 5.89 to 5.61 us, against 4.80 without it).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn quad_form_avx2(e: &[f32], q: &[f32]) -> f64 {
    quad_form_portable(e, q)
}

#[inline(always)]
fn quad_form_portable(e: &[f32], q: &[f32]) -> f64 {
    if q.is_empty() {
        return 0.0;
    }
    let mut s = 0.0f64;
    for (row, &qi) in e.chunks_exact(q.len()).zip(q) {
        s += (dot(row, q) * qi) as f64;
    }
    s
}

/// `out = f - mean` and `|f - mean|^2` (in f64).
fn centre(f: &[f32], mean: &[f32], out: &mut [f32], avx2_fma: bool) -> f64 {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        return unsafe { centre_avx2(f, mean, out) };
    }
    centre_portable(f, mean, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn centre_avx2(f: &[f32], mean: &[f32], out: &mut [f32]) -> f64 {
    centre_portable(f, mean, out)
}

/// [`centre`]: four independent lanes so that the compiler vectorises it.
#[inline(always)]
fn centre_portable(f: &[f32], mean: &[f32], out: &mut [f32]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (cf, cm, co) = (
        f.chunks_exact(4),
        mean.chunks_exact(4),
        out.chunks_exact_mut(4),
    );
    let (rf, rm) = (cf.remainder(), cm.remainder());
    for ((x, y), o) in cf.zip(cm).zip(co) {
        for i in 0..4 {
            o[i] = x[i] - y[i];
            acc[i] += o[i] as f64 * o[i] as f64;
        }
    }
    let mut s: f64 = acc.iter().sum();
    let done = f.len() - rf.len();
    for (i, (x, y)) in rf.iter().zip(rm).enumerate() {
        let t = x - y;
        out[done + i] = t;
        s += t as f64 * t as f64;
    }
    s
}

/// `(W W^T)^-1` (h x h, row-major) for the rows `W` the projection runs with: the half-precision
/// copy when there is one (`w16`), else `w`. The identity if it cannot be inverted.
fn gram_inverse(w: &[f32], w16: &[u16], h: usize) -> Vec<f64> {
    if h == 0 || !w.len().is_multiple_of(h) {
        return Vec::new();
    }
    let n = w.len() / h;
    let row = |j: usize, k: usize| -> f64 {
        if w16.is_empty() {
            w[j * n + k] as f64
        } else {
            half_to_f64(w16[j * n + k])
        }
    };
    let mut g = nalgebra::DMatrix::<f64>::zeros(h, h);
    for a in 0..h {
        for b in a..h {
            let v: f64 = (0..n).map(|k| row(a, k) * row(b, k)).sum();
            g[(a, b)] = v;
            g[(b, a)] = v;
        }
    }
    let inv = g
        .try_inverse()
        .unwrap_or_else(|| nalgebra::DMatrix::identity(h, h));
    let mut out = vec![0.0; h * h];
    for a in 0..h {
        for b in 0..h {
            out[a * h + b] = inv[(a, b)];
        }
    }
    out
}

/// An IEEE half-precision number's value (the weights' f16 copy, decoded exactly).
fn half_to_f64(x: u16) -> f64 {
    let sign = if x & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((x >> 10) & 0x1f) as i32;
    let frac = (x & 0x3ff) as f64;
    match exp {
        0 => sign * frac * 2f64.powi(-24),
        31 if frac == 0.0 => sign * f64::INFINITY,
        31 => f64::NAN,
        e => sign * (1.0 + frac / 1024.0) * 2f64.powi(e - 15),
    }
}

#[inline(always)]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    // Sixteen independent accumulators let the compiler vectorise the reduction (two vectors
    // of eight with AVX, four of four with SSE) without a dependency chain on one register.
    let mut acc = [0.0f32; 16];
    let ca = a.chunks_exact(16);
    let cb = b.chunks_exact(16);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..16 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s: f32 = acc.iter().sum();
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// `out[i] = |x_i - q|^2` for the stored samples `x_i`, each `q.len()` long (a multiple of 8,
/// zero-padded past h, so the padding adds nothing).
fn sq_dists(samples: &[f32], q: &[f32], out: &mut [f64], avx2_fma: bool) {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        unsafe { sq_dists_avx2(samples, q, out) };
        return;
    }
    sq_dists_portable(samples, q, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn sq_dists_avx2(samples: &[f32], q: &[f32], out: &mut [f64]) {
    sq_dists_portable(samples, q, out);
}

#[inline(always)]
fn sq_dists_portable(samples: &[f32], q: &[f32], out: &mut [f64]) {
    if q.is_empty() {
        out.fill(0.0);
        return;
    }
    for (o, x) in out.iter_mut().zip(samples.chunks_exact(q.len())) {
        // Eight lanes per chunk: the compiler keeps `acc` in one vector register.
        let mut acc = [0.0f32; 8];
        for (xc, qc) in x.chunks_exact(8).zip(q.chunks_exact(8)) {
            for i in 0..8 {
                let t = xc[i] - qc[i];
                acc[i] += t * t;
            }
        }
        *o = acc.iter().sum::<f32>() as f64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_are_exact_sums_of_squares() {
        // Two samples of h = 52 padded to 56; the padding must add nothing.
        let pad = |v: Vec<f32>| -> Vec<f32> { v.into_iter().chain([0.0; 4]).collect() };
        let a: Vec<f32> = (0..52).map(|i| i as f32 * 0.5).collect();
        let b: Vec<f32> = (0..52).map(|i| (i % 7) as f32).collect();
        let want: f32 = a.iter().zip(&b).map(|(x, y)| (x - y) * (x - y)).sum();
        let samples: Vec<f32> = pad(a.clone()).into_iter().chain(pad(b.clone())).collect();
        for avx2_fma in [false, Kernels::Native.avx2_fma()] {
            let mut d = [0.0f64; 2];
            sq_dists(&samples, &pad(b.clone()), &mut d, avx2_fma);
            assert!(
                (d[0] - want as f64).abs() <= 1e-3 * want as f64,
                "{d:?} vs {want}"
            );
            assert_eq!(d[1], 0.0);
        }
        // Seven rows of 1025: the four-row block, three single rows and a ragged tail.
        let n = 1025;
        let w: Vec<f32> = (0..7 * n)
            .map(|i| ((i * 7919) % 101) as f32 * 0.01 - 0.5)
            .collect();
        let c: Vec<f32> = (0..n).map(|i| ((i * 31) % 17) as f32 - 8.0).collect();
        for avx2_fma in [false, Kernels::Native.avx2_fma()] {
            let mut q = [0.0f32; 7];
            project(&w, &[], &c, &mut q, avx2_fma);
            for (j, qj) in q.iter().enumerate() {
                let want: f64 = (0..n).map(|k| w[j * n + k] as f64 * c[k] as f64).sum();
                assert!(
                    (*qj as f64 - want).abs() <= 1e-3 * want.abs().max(1.0),
                    "row {j}, avx2_fma {avx2_fma}: {qj} vs {want}"
                );
            }
        }
        // The half-precision copy: each weight within 2^-11 of its own magnitude, so each
        // product too; the sum is then within 2^-11 of the sum of |w c|.
        if Kernels::Native.avx2_fma() {
            let w16 = half_matrix(&w);
            let mut q16 = [0.0f32; 7];
            project(&w, &w16, &c, &mut q16, true);
            for (j, qj) in q16.iter().enumerate() {
                let want: f64 = (0..n).map(|k| w[j * n + k] as f64 * c[k] as f64).sum();
                let abs: f64 = (0..n)
                    .map(|k| (w[j * n + k] as f64 * c[k] as f64).abs())
                    .sum();
                assert!(
                    (*qj as f64 - want).abs() <= abs / 2048.0 + 1e-3,
                    "row {j}: {qj} vs {want}"
                );
            }
        }
    }

    #[test]
    fn half_precision_decodes_exactly() {
        assert_eq!(half_to_f64(0x3c00), 1.0);
        assert_eq!(half_to_f64(0xc000), -2.0);
        assert_eq!(half_to_f64(0x7bff), 65504.0);
        assert_eq!(half_to_f64(0x0001), 2f64.powi(-24));
        assert_eq!(half_to_f64(0x3555), 0.333251953125);
        assert!(half_to_f64(0x7e00).is_nan());
        // The Gram inverse of orthonormal rows is the identity.
        let w = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        assert_eq!(gram_inverse(&w, &[], 2), vec![1.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn portable_rows_match_a_dot_product_for_every_row_count() {
        // 0 to 9 rows: no block, one block with 0-3 single rows, two blocks; n not a multiple of 8.
        let n = 37;
        for rows in 0..10 {
            let w: Vec<f32> = (0..rows * n).map(|i| (i % 13) as f32 - 6.0).collect();
            let c: Vec<f32> = (0..n).map(|i| (i % 5) as f32 * 0.25).collect();
            let mut q = vec![f32::NAN; rows];
            project_portable(&w, &c, &mut q);
            for (j, qj) in q.iter().enumerate() {
                // Small integers and quarters: every partial sum is exact in f32.
                let want: f32 = (0..n).map(|k| w[j * n + k] * c[k]).sum();
                assert_eq!(*qj, want, "{rows} rows, row {j}");
            }
        }
    }
}
