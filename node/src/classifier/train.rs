//! Training, as in sections 4.2 and 7.2: per class, `per_class` random samples, `train` of them
//! for the training set T and the rest for the validation set V; PCA on the feature vectors of
//! T and V; the kernel width chosen by the accuracy on V with T as the stored samples; then all
//! of T and V are stored as the model's samples P.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::seq::SliceRandom;

use super::features::{FeatureExtractor, fft_len};
use super::image::{Crop, PressureImage};
use super::model::{
    ClassInfo, MAX_CLASSES, MAX_DOWNSAMPLE, MODEL_VERSION, MinContact, Model, StoredImages,
};

/// How to train: the paper's split and the preprocessing.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Images drawn per class (section 7.2: 20).
    pub per_class: usize,
    /// Of those, images to train on; the rest validate the kernel width (13 of 20).
    pub train: usize,
    /// Crop before the features.
    pub crop: Crop,
    /// Downsampling factor after the crop (1 = full resolution).
    pub downsample: usize,
    /// Scale each image to the training set's mean total intensity (the paper's intensity scaling).
    pub normalize_load: bool,
    /// PCA dimensions; `None`: the paper's 52, or as many as the samples support.
    pub h: Option<usize>,
    /// Seed of the random split.
    pub seed: u64,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            per_class: 20,
            train: 13,
            crop: Crop::default(),
            downsample: 1,
            normalize_load: false,
            h: None,
            seed: 1,
        }
    }
}

/// Why a training request cannot be met.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
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

/// One labelled image.
pub struct Labelled<'a> {
    /// The image.
    pub image: &'a PressureImage,
    /// Its class index.
    pub class: usize,
}

/// What was used for what, by index into the input.
#[derive(Clone, Debug, Default)]
pub struct Split {
    /// Indices of the training images.
    pub train: Vec<usize>,
    /// Indices of the validation images.
    pub validation: Vec<usize>,
    /// Indices of the images left for testing.
    pub test: Vec<usize>,
}

fn preprocess(img: &PressureImage, o: &TrainOptions) -> Option<PressureImage> {
    let c = img.crop(&o.crop)?;
    Some(if o.downsample > 1 {
        c.downsample(o.downsample)
    } else {
        c
    })
}

/// Trains a model on `data` (the paper's section 4 and 7.2): per class `per_class` random images, `train` of them for PCA and the Parzen samples, the rest to choose the kernel width; returns the model and the split.
pub fn train(
    data: &[Labelled<'_>],
    classes: &[ClassInfo],
    o: &TrainOptions,
) -> Result<(Model, Split), TrainError> {
    if classes.len() < 2 || classes.len() > MAX_CLASSES {
        return Err(TrainError::Classes(classes.len()));
    }
    if !(1..=MAX_DOWNSAMPLE).contains(&o.downsample) {
        return Err(TrainError::Downsample(o.downsample));
    }
    if o.train == 0 || o.train >= o.per_class {
        return Err(TrainError::BadSplit {
            train: o.train,
            per_class: o.per_class,
        });
    }
    let (rows, cols, bits) = (data[0].image.rows, data[0].image.cols, data[0].image.bits);
    for d in data {
        if (d.image.rows, d.image.cols, d.image.bits) != (rows, cols, bits) {
            return Err(TrainError::Sizes {
                a: format!("{rows}x{cols} {bits}-bit"),
                b: format!("{}x{} {}-bit", d.image.rows, d.image.cols, d.image.bits),
            });
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(o.seed);
    let mut split = Split::default();
    for (k, c) in classes.iter().enumerate() {
        let mut idx: Vec<usize> = (0..data.len()).filter(|&i| data[i].class == k).collect();
        if idx.len() < o.per_class {
            return Err(TrainError::TooFew {
                class: c.name.clone(),
                have: idx.len(),
                need: o.per_class,
            });
        }
        idx.shuffle(&mut rng);
        split.train.extend_from_slice(&idx[..o.train]);
        split
            .validation
            .extend_from_slice(&idx[o.train..o.per_class]);
        split.test.extend_from_slice(&idx[o.per_class..]);
    }
    let prep = |i: usize| {
        preprocess(data[i].image, o).ok_or(TrainError::Crop {
            crop: o.crop,
            rows,
            cols,
        })
    };
    let tv: Vec<usize> = split
        .train
        .iter()
        .chain(&split.validation)
        .copied()
        .collect();
    let work: Vec<Vec<u16>> = tv
        .iter()
        .map(|&i| prep(i).map(|p| p.pixels))
        .collect::<Result<_, _>>()?;
    let labels: Vec<usize> = tv.iter().map(|&i| data[i].class).collect();
    let fitted = fit(
        &work,
        &labels,
        split.train.len(),
        classes.len(),
        o.normalize_load,
        o.h,
    );
    let hash = |is: &[usize]| {
        is.iter()
            .map(|&i| data[i].image.content_hash())
            .collect::<Vec<_>>()
    };
    let mut model = Model {
        version: MODEL_VERSION,
        classes: classes.to_vec(),
        input_rows: rows,
        input_cols: cols,
        crop: o.crop,
        downsample: o.downsample,
        normalize_load: None,
        n_fft: 0,
        h: 0,
        pca_mean: Vec::new(),
        pca_matrix: Vec::new(),
        samples: Vec::new(),
        sample_classes: labels,
        kernel_width: 1.0,
        unknown_threshold: f64::NEG_INFINITY,
        train_hashes: hash(&split.train),
        val_hashes: hash(&split.validation),
        contact: Some(MinContact::of_training(&work)),
        bits: Some(bits),
        images: Some(StoredImages {
            n_train: split.train.len(),
            pixels: work,
        }),
    };
    fitted?.install(&mut model);
    Ok((model, split))
}

/// The model refitted to a sensor with dead lines: its stored images get the same dead rows and
/// columns (of the working image) and the same repair as the node gives a live image, and PCA,
/// stored samples, dimensions and kernel width are fitted again on T and V as in [`train`].
///
/// A filled dead line is a copy of its neighbour: the texture it carried is gone from the image
/// and its copy adds spectral lines the training images never had. A model fitted on equally
/// damaged images compares like with like; at 50% damage that is the difference between about
/// 70% and 90% of steps classified right (see the node's notes).
pub fn refit(model: &Model, dead_rows: &[bool], dead_cols: &[bool]) -> Result<Model, RefitError> {
    let images = model.images.as_ref().ok_or(RefitError::NoImages)?;
    let (rows, cols) = model.work_size().ok_or(RefitError::Size)?;
    if dead_rows.len() != rows || dead_cols.len() != cols {
        return Err(RefitError::Size);
    }
    let work: Vec<Vec<u16>> = images
        .pixels
        .iter()
        .map(|p| {
            let mut img = p.clone();
            for (r, line) in img.chunks_exact_mut(cols).enumerate() {
                if dead_rows[r] {
                    line.fill(0);
                } else {
                    for (v, &d) in line.iter_mut().zip(dead_cols) {
                        if d {
                            *v = 0;
                        }
                    }
                }
            }
            super::repair::repair_lines(&mut img, rows, cols, dead_rows, dead_cols, None);
            img
        })
        .collect();
    let fitted = fit(
        &work,
        &model.sample_classes,
        images.n_train,
        model.classes.len(),
        model.normalize_load.is_some(),
        None,
    )
    .map_err(|_| RefitError::Pca)?;
    let mut m = model.clone();
    fitted.install(&mut m);
    Ok(m)
}

/// Why a model could not be refitted to the sensor's dead lines.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum RefitError {
    #[error(
        "the model file holds no training images (written by an older presrs); retrain it with `presrs train` to let the node adapt to dead sensor lines"
    )]
    /// The model holds no training images.
    NoImages,
    /// The masks do not fit the model's working image.
    #[error("the dead-line masks do not match the model's working image size")]
    Size,
    /// The PCA did not converge.
    #[error("the PCA did not converge on the damaged images")]
    Pca,
}

/// What [`fit`] computes: everything of a model that depends on the stored images.
struct Fitted {
    normalize_load: Option<f64>,
    n_fft: usize,
    h: usize,
    pca_mean: Vec<f32>,
    pca_matrix: Vec<f32>,
    samples: Vec<f32>,
    kernel_width: f64,
}

impl Fitted {
    fn install(self, m: &mut Model) {
        m.normalize_load = self.normalize_load;
        m.n_fft = self.n_fft;
        m.h = self.h;
        m.pca_mean = self.pca_mean;
        m.pca_matrix = self.pca_matrix;
        m.samples = self.samples;
        m.kernel_width = self.kernel_width;
        m.unknown_threshold = unknown_threshold(m);
    }
}

/// Features, PCA, and the choice of h and kernel width on V, for working images `work` (T then
/// V; the first `n_t` are T) with class `labels`.
fn fit(
    work: &[Vec<u16>],
    labels: &[usize],
    n_t: usize,
    n_classes: usize,
    normalize: bool,
    dims: Option<usize>,
) -> Result<Fitted, TrainError> {
    let n_px = work[0].len();
    let total = |p: &[u16]| p.iter().map(|&v| v as f64).sum::<f64>();
    let normalize_load =
        normalize.then(|| work.iter().map(|p| total(p)).sum::<f64>() / work.len() as f64);
    let mut fx = FeatureExtractor::new(n_px);
    let n = fx.feature_len();
    let mut x = DMatrix::<f64>::zeros(work.len(), n);
    for (row, p) in work.iter().enumerate() {
        let scale = match normalize_load {
            Some(t) if total(p) > 0.0 => (t / total(p)) as f32,
            _ => 1.0,
        };
        let f = fx.features(p, scale);
        for (j, v) in f.iter().enumerate() {
            x[(row, j)] = *v as f64;
        }
    }
    let mean = x.row_mean();
    for mut r in x.row_iter_mut() {
        r -= &mean;
    }
    let svd = x.clone().svd(false, true);
    let v_t = svd.v_t.ok_or(TrainError::Pca)?;
    let tol = svd.singular_values.max() * 1e-9;
    let rank = svd
        .singular_values
        .iter()
        .filter(|s| **s > tol)
        .count()
        .max(1);
    // PCA axes up to the paper's 52 (or --dims), as far as the rank allows.
    let h_max = dims.unwrap_or(52).min(rank).max(1);
    // Rows of V^T are the principal axes, sorted by singular value.
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let mut u = vec![0f32; h_max * n];
    for (j, &axis) in order.iter().take(h_max).enumerate() {
        for k in 0..n {
            u[j * n + k] = v_t[(axis, k)] as f32;
        }
    }
    // Project T and V on all h_max axes once; a smaller h uses the leading coordinates.
    let mut proj = vec![0f32; work.len() * h_max];
    for row in 0..work.len() {
        for j in 0..h_max {
            let mut acc = 0.0f64;
            for k in 0..n {
                acc += x[(row, k)] * u[j * n + k] as f64;
            }
            proj[row * h_max + j] = acc as f32;
        }
    }
    // Model selection on V (section 4.2: training determines h and the kernel): every candidate
    // h (or only --dims), and for each a log-spaced grid of kernel widths around the typical
    // nearest-neighbour distance in T. Score: validation accuracy, then the summed validation
    // log-posterior of the true class; ties go to the wider kernel.
    let candidates: Vec<usize> = match dims {
        Some(_) => vec![h_max],
        None => {
            let mut c: Vec<usize> = [1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 52]
                .into_iter()
                .filter(|&h| h < h_max)
                .collect();
            c.push(h_max);
            c
        }
    };
    let mut best = (f64::NEG_INFINITY, h_max, 1.0f64);
    for &h in &candidates {
        let t_proj: Vec<f32> = (0..n_t)
            .flat_map(|r| proj[r * h_max..r * h_max + h].iter().copied())
            .collect();
        let nn = median_nn_distance(&t_proj, h);
        for step in -16..=8 {
            let sigma = nn * 2f64.powf(step as f64 / 2.0);
            let mut correct = 0;
            let mut margin = 0.0;
            for v in n_t..work.len() {
                let q = &proj[v * h_max..v * h_max + h];
                let (best_k, lp) =
                    parzen(&t_proj, &labels[..n_t], q, h, sigma, n_classes, labels[v]);
                correct += (best_k == labels[v]) as usize;
                margin += lp.max(-50.0);
            }
            let score = correct as f64 + margin * 1e-6;
            if score >= best.0 {
                best = (score, h, sigma);
            }
        }
    }
    let (_, h, sigma) = best;
    Ok(Fitted {
        normalize_load,
        n_fft: fft_len(n_px),
        h,
        pca_mean: mean.iter().map(|v| *v as f32).collect(),
        pca_matrix: u[..h * n].to_vec(),
        // The stored samples are T and V (the paper's P has p + q columns).
        samples: (0..work.len())
            .flat_map(|r| proj[r * h_max..r * h_max + h].iter().copied())
            .collect(),
        kernel_width: sigma,
    })
}

/// The Parzen decision for one projected vector `q` against stored samples `t` (equal class
/// priors, as in [`super::Classifier`]): the best class and the log-posterior of class `truth`.
fn parzen(
    t: &[f32],
    labels: &[usize],
    q: &[f32],
    h: usize,
    sigma: f64,
    n_classes: usize,
    truth: usize,
) -> (usize, f64) {
    let inv = 1.0 / (2.0 * sigma * sigma);
    let mut e = vec![f64::NEG_INFINITY; labels.len()];
    let mut mx = [f64::NEG_INFINITY; MAX_CLASSES];
    let mut cnt = [0usize; MAX_CLASSES];
    for (i, &k) in labels.iter().enumerate() {
        let d2 = sq_dist(&t[i * h..(i + 1) * h], q);
        e[i] = -d2 * inv;
        mx[k] = mx[k].max(e[i]);
        cnt[k] += 1;
    }
    let mut sum = [0.0f64; MAX_CLASSES];
    for (i, &k) in labels.iter().enumerate() {
        sum[k] += (e[i] - mx[k]).exp();
    }
    let mut ld = [f64::NEG_INFINITY; MAX_CLASSES];
    let mut best = 0;
    for k in 0..n_classes {
        if cnt[k] > 0 {
            ld[k] = mx[k] + sum[k].ln() - (cnt[k] as f64).ln();
        }
        if ld[k] > ld[best] {
            best = k;
        }
    }
    let z: f64 = (0..n_classes).map(|k| (ld[k] - ld[best]).exp()).sum();
    (best, ld[truth] - ld[best] - z.ln())
}

/// Squared Euclidean distance of two projected samples.
fn sq_dist(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum()
}

/// Median over stored samples of the distance to the nearest other sample.
fn median_nn_distance(p: &[f32], h: usize) -> f64 {
    let m = p.len() / h;
    let mut d: Vec<f64> = (0..m)
        .map(|i| {
            (0..m)
                .filter(|&j| j != i)
                .map(|j| sq_dist(&p[i * h..(i + 1) * h], &p[j * h..(j + 1) * h]))
                .fold(f64::INFINITY, f64::min)
                .sqrt()
        })
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    if d.is_empty() {
        return 1.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// The unknown threshold: the lowest leave-one-out log density of a stored sample under its own
/// class, less 10 nats (a density 22,000 times lower than the least typical training image).
fn unknown_threshold(m: &Model) -> f64 {
    let h = m.h;
    let s2 = 2.0 * m.kernel_width * m.kernel_width;
    let mut lowest = f64::INFINITY;
    for i in 0..m.n_samples() {
        let k = m.sample_classes[i];
        let others: Vec<f64> = (0..m.n_samples())
            .filter(|&j| j != i && m.sample_classes[j] == k)
            .map(|j| {
                -sq_dist(
                    &m.samples[i * h..(i + 1) * h],
                    &m.samples[j * h..(j + 1) * h],
                ) / s2
            })
            .collect();
        if others.is_empty() {
            continue;
        }
        let mx = others.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let ld = mx + others.iter().map(|e| (e - mx).exp()).sum::<f64>().ln()
            - (others.len() as f64).ln()
            - 0.5 * h as f64 * (std::f64::consts::PI * s2).ln();
        lowest = lowest.min(ld);
    }
    if lowest.is_finite() {
        lowest - 10.0
    } else {
        f64::NEG_INFINITY
    }
}
