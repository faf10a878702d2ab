//! Fitting a model to labelled images: the split, PCA, the kernel width chosen on V, the stored
//! samples (sections 4.2 and 7.2).

use super::{
    CalibrationSource, Checks, ClassInfo, Crop, CropSpec, DMatrix, FeatureExtractor,
    MAX_CALIBRATION_PER_CLASS, MAX_CLASSES, MODEL_VERSION, Margin, MinContact, Model,
    PressureImage, StoredImages, TrainError, TrainOptions, UnknownChecks, add_load_check,
    add_texture_check, fft_len, set_novelty, unknown_thresholds,
};
use rand::SeedableRng;
use rand::seq::SliceRandom;

/// One labelled image.
#[derive(Clone, Copy)]
pub struct Labelled<'a> {
    /// The image.
    pub image: &'a PressureImage,
    /// Its class index.
    pub class: usize,
    /// The flights before and after its stance, µs, where known (the energy check's input).
    pub flights: [Option<u32>; 2],
}

impl<'a> Labelled<'a> {
    /// `image` of `class`, its flights not known.
    pub fn new(image: &'a PressureImage, class: usize) -> Self {
        Self {
            image,
            class,
            flights: [None, None],
        }
    }
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

/// The crop `spec` asks for: as given, or the footprint's of `images`
/// ([`crate::training::footprint`]; none without a loaded image).
pub fn resolve_crop<'a>(
    spec: CropSpec,
    images: impl IntoIterator<Item = &'a PressureImage>,
) -> Crop {
    match spec {
        CropSpec::Fixed(c) => c,
        CropSpec::Auto => crate::training::footprint::Footprint::of(images)
            .map(|f| f.crop())
            .unwrap_or_default(),
    }
}

/// Crop, then keep every `downsample`-th row and column: the working image.
pub(crate) fn preprocess(
    img: &PressureImage,
    crop: &Crop,
    downsample: usize,
) -> Option<PressureImage> {
    let c = img.crop(crop)?;
    Some(if downsample > 1 {
        c.downsample(downsample)
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
    let (m, _, split) = train_variants(data, classes, o, false)?;
    Ok((m, split))
}

/// [`train`], and the same model at the most PCA dimensions (`Dims::Max`: `o` with `--dims
/// 52`), from one PCA: what `crate::training::choice` compares, at the cost of one fit. The
/// second is `None` where `o` fixes the dimensions.
pub fn train_with_max_dims(
    data: &[Labelled<'_>],
    classes: &[ClassInfo],
    o: &TrainOptions,
) -> Result<(Model, Option<Model>, Split), TrainError> {
    train_variants(data, classes, o, true)
}

pub(crate) fn train_variants(
    data: &[Labelled<'_>],
    classes: &[ClassInfo],
    o: &TrainOptions,
    with_max: bool,
) -> Result<(Model, Option<Model>, Split), TrainError> {
    if classes.len() < 2 || classes.len() > MAX_CLASSES {
        return Err(TrainError::Classes(classes.len()));
    }
    o.check()?;
    // An expert's `--unknown-checks` list sets its parts (the flags' pins stay on).
    let with_list;
    let o = match &o.unknown_checks {
        crate::classifier::options::UnknownChecks::Fixed(c) => {
            with_list = o.with_candidate(c);
            &with_list
        }
        crate::classifier::options::UnknownChecks::Auto => o,
    };
    let (rows, cols, bits) = one_size(data)?;
    // `auto`: the footprint of these images (a caller that trains several models of one set,
    // as `TrainingSet::train_calibrated` does, measures it once on the whole set).
    let crop = resolve_crop(o.crop, data.iter().map(|l| l.image));
    let split = split_classes(data, classes, o)?;
    let prep = |i: usize| {
        preprocess(data[i].image, &crop, o.downsample).ok_or(TrainError::Crop { crop, rows, cols })
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
        crop,
        downsample: o.downsample,
        normalize_load: None,
        n_fft: 0,
        h: 0,
        pca_mean: Vec::new(),
        pca_matrix: Vec::new(),
        samples: Vec::new(),
        sample_classes: labels,
        kernel_width: 1.0,
        train_hashes: hash(&split.train),
        val_hashes: hash(&split.validation),
        contact: Some(MinContact::of_training(&work)),
        bits: Some(bits),
        images: Some(StoredImages {
            n_train: split.train.len(),
            pixels: work,
        }),
        gaits: None,
        sample_ms: None,
        confidence: None,
        unknown: Checks {
            rate: o.unknown_rate,
            ..Checks::none(classes.len())
        },
    };
    let (fitted, fitted_max) = fitted?;
    let max_model = (with_max && o.h.is_none()).then(|| {
        let mut m = model.clone();
        fitted_max.install(&mut m);
        m
    });
    fitted.install(&mut model);
    let model = finish(model, data, classes, o, &split, &prep)?;
    let max_model = match max_model {
        Some(m) => Some(finish(m, data, classes, o, &split, &prep)?),
        None => None,
    };
    Ok((model, max_model, split))
}

/// The images' one size and depth; two that differ are an error naming both.
fn one_size(data: &[Labelled<'_>]) -> Result<(usize, usize, u8), TrainError> {
    let (rows, cols, bits) = (data[0].image.rows, data[0].image.cols, data[0].image.bits);
    for d in data {
        if (d.image.rows, d.image.cols, d.image.bits) != (rows, cols, bits) {
            return Err(TrainError::Sizes {
                a: format!("{rows}x{cols} {bits}-bit"),
                b: format!("{}x{} {}-bit", d.image.rows, d.image.cols, d.image.bits),
            });
        }
    }
    Ok((rows, cols, bits))
}

/// Each class's images shuffled (seeded by `o.seed`) into T (`o.train`), V (up to
/// `o.per_class`) and the rest; a class with too few images, or none with load, is an error.
fn split_classes(
    data: &[Labelled<'_>],
    classes: &[ClassInfo],
    o: &TrainOptions,
) -> Result<Split, TrainError> {
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
        if idx
            .iter()
            .all(|&i| data[i].image.pixels.iter().all(|&p| p == 0))
        {
            return Err(TrainError::NoLoad {
                class: c.name.clone(),
            });
        }
        idx.shuffle(&mut rng);
        split.train.extend_from_slice(&idx[..o.train]);
        split
            .validation
            .extend_from_slice(&idx[o.train..o.per_class]);
        split.test.extend_from_slice(&idx[o.per_class..]);
    }
    Ok(split)
}

/// What [`train`] adds to a fitted model: the checks `o` asks for and the novelty's
/// calibration on the training run's unused images (`split.test`).
pub(crate) fn finish(
    mut model: Model,
    data: &[Labelled<'_>],
    classes: &[ClassInfo],
    o: &TrainOptions,
    split: &Split,
    prep: &dyn Fn(usize) -> Result<PressureImage, TrainError>,
) -> Result<Model, TrainError> {
    if o.check_load {
        add_load_check(&mut model);
    }
    if o.check_texture {
        add_texture_check(&mut model, data.iter().map(|l| (l.image, l.class)));
    }
    // The paper's classifier had no rejection: a rate of 0 keeps the density rule, which
    // rejects almost nothing.
    if o.unknown_rate > 0.0 {
        // The session itself in time blocks (`calibrate::cross_fit`): every stored image, and
        // as many of the unused ones per class as fit in the file (the split's first), in
        // recording order.
        let mut keep: std::collections::BTreeSet<usize> = split
            .train
            .iter()
            .chain(&split.validation)
            .copied()
            .collect();
        let mut unused = vec![0usize; classes.len()];
        for &i in &split.test {
            let k = data[i].class;
            if unused[k] < MAX_CALIBRATION_PER_CLASS {
                unused[k] += 1;
                keep.insert(i);
            }
        }
        let cal: Vec<(Vec<u16>, usize)> = keep
            .iter()
            .map(|&i| Ok((prep(i)?.pixels, data[i].class)))
            .collect::<Result<_, TrainError>>()?;
        let margin = match o.unknown_checks {
            UnknownChecks::Fixed(c) => c.margin,
            UnknownChecks::Auto => Margin::ONE_SESSION,
        };
        let (pixels, cls): (Vec<_>, Vec<_>) = cal.into_iter().unzip();
        set_novelty(
            &mut model,
            pixels,
            cls,
            CalibrationSource::TimeBlocks,
            Vec::new(),
            margin.factor(),
            0,
            o.score(),
        );
    }
    Ok(model)
}

/// What [`fit`] computes: everything of a model that depends on the stored images.
pub(crate) struct Fitted {
    normalize_load: Option<f64>,
    n_fft: usize,
    h: usize,
    pca_mean: Vec<f32>,
    pca_matrix: Vec<f32>,
    samples: Vec<f32>,
    kernel_width: f64,
}

impl Fitted {
    pub(crate) fn install(self, m: &mut Model) {
        m.normalize_load = self.normalize_load;
        m.n_fft = self.n_fft;
        m.h = self.h;
        m.pca_mean = self.pca_mean;
        m.pca_matrix = self.pca_matrix;
        m.samples = self.samples;
        m.kernel_width = self.kernel_width;
        m.unknown.density_thresholds = unknown_thresholds(m);
    }
}

/// Features, PCA, and the choice of h and kernel width on V, for working images `work` (T then
/// V; the first `n_t` are T) with class `labels`; second, the model at the most dimensions
/// (`Dims::Max`, with its own best kernel width), from the same SVD and the same search.
pub(crate) fn fit(
    work: &[Vec<u16>],
    labels: &[usize],
    n_t: usize,
    n_classes: usize,
    normalize: bool,
    dims: Option<usize>,
) -> Result<(Fitted, Fitted), TrainError> {
    let n_px = work[0].len();
    let (x, mean, normalize_load) = centred_features(work, normalize);
    let n = x.ncols();
    // PCA axes up to the paper's 52 (or --dims), as far as the rank allows.
    let pca = super::pca::principal_axes(&x, dims.unwrap_or(52));
    if pca.axes.is_empty() {
        return Err(TrainError::Pca);
    }
    let h_max = pca.axes.len();
    let mut u = vec![0f32; h_max * n];
    for (j, axis) in pca.axes.iter().enumerate() {
        for k in 0..n {
            u[j * n + k] = axis[k] as f32;
        }
    }
    // Project T and V on all h_max axes once (on the axes as the model stores them, f32, as the
    // node projects); a smaller h uses the leading coordinates.
    let axes = DMatrix::<f64>::from_fn(n, h_max, |k, j| u[j * n + k] as f64);
    let projected = &x * axes;
    let mut proj = vec![0f32; work.len() * h_max];
    for row in 0..work.len() {
        for j in 0..h_max {
            proj[row * h_max + j] = projected[(row, j)] as f32;
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
    let (best, best_max) = select(&proj, h_max, &candidates, labels, n_t, n_classes);
    let fitted = |(_, h, sigma): (f64, usize, f64)| Fitted {
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
    };
    Ok((fitted(best), fitted(best_max)))
}

/// The feature vectors of `work` (rows), centred, their mean, and the mean load they were
/// scaled to (with `normalize`; a blank image, no contact, is not scaled).
fn centred_features(
    work: &[Vec<u16>],
    normalize: bool,
) -> (DMatrix<f64>, nalgebra::RowDVector<f64>, Option<f64>) {
    let n_px = work[0].len();
    let total = |p: &[u16]| p.iter().map(|&v| v as f64).sum::<f64>();
    // The mean load of the loaded images (a blank one, no contact, is not scaled either).
    let loaded: Vec<f64> = work.iter().map(|p| total(p)).filter(|&t| t > 0.0).collect();
    let normalize_load =
        (normalize && !loaded.is_empty()).then(|| loaded.iter().sum::<f64>() / loaded.len() as f64);
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
    (x, mean, normalize_load)
}

/// The best (score, h, kernel width) on V over `candidates` and a log-spaced grid of widths,
/// and the best at `h_max` alone; `proj` holds every image's `h_max` coordinates, T first.
fn select(
    proj: &[f32],
    h_max: usize,
    candidates: &[usize],
    labels: &[usize],
    n_t: usize,
    n_classes: usize,
) -> ((f64, usize, f64), (f64, usize, f64)) {
    let n_all = proj.len() / h_max;
    let mut best = (f64::NEG_INFINITY, h_max, 1.0f64);
    // The best kernel width at h_max alone: the `Dims::Max` model, from the same SVD.
    let mut best_max = (f64::NEG_INFINITY, h_max, 1.0f64);
    for &h in candidates {
        let t_proj: Vec<f32> = (0..n_t)
            .flat_map(|r| proj[r * h_max..r * h_max + h].iter().copied())
            .collect();
        let nn = median_nn_distance(&t_proj, h);
        // Each validation image's squared distances to T, once per h: the kernel widths below
        // only rescale them.
        let d2: Vec<f64> = (n_t..n_all)
            .flat_map(|v| {
                let q = &proj[v * h_max..v * h_max + h];
                (0..n_t).map(|i| sq_dist(&t_proj[i * h..(i + 1) * h], q))
            })
            .collect();
        for step in -16..=8 {
            let sigma = nn * 2f64.powf(step as f64 / 2.0);
            let mut correct = 0;
            let mut margin = 0.0;
            for (row, v) in (n_t..n_all).enumerate() {
                let d2 = &d2[row * n_t..(row + 1) * n_t];
                let (best_k, lp) = parzen(d2, &labels[..n_t], sigma, n_classes, labels[v]);
                correct += (best_k == labels[v]) as usize;
                margin += lp.max(-50.0);
            }
            let score = correct as f64 + margin * 1e-6;
            if score >= best.0 {
                best = (score, h, sigma);
            }
            if h == h_max && score >= best_max.0 {
                best_max = (score, h, sigma);
            }
        }
    }
    (best, best_max)
}

/// The Parzen decision for one projected vector from its squared distances `d2` to the stored
/// samples of classes `labels` (equal class priors, as in [`crate::classifier::Classifier`]):
/// the best class and the log-posterior of class `truth`.
pub(crate) fn parzen(
    d2: &[f64],
    labels: &[usize],
    sigma: f64,
    n_classes: usize,
    truth: usize,
) -> (usize, f64) {
    let inv = 1.0 / (2.0 * sigma * sigma);
    let mut e = vec![f64::NEG_INFINITY; labels.len()];
    let mut mx = [f64::NEG_INFINITY; MAX_CLASSES];
    let mut cnt = [0usize; MAX_CLASSES];
    for (i, &k) in labels.iter().enumerate() {
        e[i] = -d2[i] * inv;
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

/// Squared Euclidean distance of two projected samples. (`d * d`, not `powi(2)`: this build
/// called libgcc's `__powidf2` for it, half of `train`'s time; the same value.)
pub(crate) fn sq_dist(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let d = (x - y) as f64;
            d * d
        })
        .sum()
}

/// Median over stored samples of the distance to the nearest other sample.
pub(crate) fn median_nn_distance(p: &[f32], h: usize) -> f64 {
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
