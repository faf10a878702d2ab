//! A terrain added to a trained model from stances the node kept as unknown (`presrs discover
//! --add`): the known terrains' stored stances kept as they are, the new terrain's split into
//! T and V in the model's proportion, PCA, dimensions and kernel width fitted again on all of
//! them as [`train`] fits them, and the unknown checks drawn again on the stored images as
//! `train` draws them for one session (time blocks, the one-session margin, the model's score).
//!
//! Why from the stored images and not the lab's first recording: a model file carries its
//! working images (`Model::images`), so adding a terrain needs nothing but the model and the
//! kept stances; the recording may be gone or on another machine.

use super::{
    CalibrationSource, ClassInfo, DMatrix, MAX_CLASSES, Model, PressureImage, StoredImages,
    TrainError, add_load_check, fit, preprocess, set_novelty, unknown_thresholds,
};

/// Why a terrain cannot be added.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ExtendError {
    /// The model file holds no stored images (written before they were kept).
    #[error("the model holds no stored images (an older file): retrain it with `presrs train`")]
    NoImages,
    /// Too few stances for a T and V of the new terrain.
    #[error("{have} stances of `{name}`: a terrain needs at least {need} (T and V)")]
    TooFew {
        /// The new terrain.
        name: String,
        /// Stances given.
        have: usize,
        /// Stances needed.
        need: usize,
    },
    /// A stance does not fit the model's sensor (size, depth or crop).
    #[error("stance {index}: {msg}")]
    Stance {
        /// Its index among those given.
        index: usize,
        /// What does not fit.
        msg: String,
    },
    /// The model already has the name or id, or holds the most classes.
    #[error("{0}")]
    Class(String),
    /// Fitting failed.
    #[error(transparent)]
    Train(#[from] TrainError),
}

/// The fewest stances a terrain is added from: two for T, two for V.
pub const MIN_NEW_STANCES: usize = 4;

/// How the PCA subspace takes the new terrain in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Basis {
    /// The model's own rows kept, the directions in which the new terrain leaves them added:
    /// every known stance projects as before.
    Extend,
    /// PCA fitted again on every stored image, at the model's dimensions and as many again
    /// per terrain for the new one.
    Refit,
}

impl Basis {
    /// The name `presrs discover --add` prints.
    pub fn name(self) -> &'static str {
        match self {
            Basis::Extend => "extend",
            Basis::Refit => "refit",
        }
    }
}

/// `model` with `class` added, fitted on its stored images and `images` (full sensor images,
/// as the node receives them), its subspace grown as `basis` says; `session` (images with a
/// known class index) are stored as samples of their classes too: the same run's known
/// ground, so that what the run shares with the new terrain is not the new terrain's alone.
/// See the module docs.
pub fn add_class(
    model: &Model,
    class: ClassInfo,
    images: &[PressureImage],
    session: &[(&PressureImage, usize)],
    basis: Basis,
) -> Result<Model, ExtendError> {
    let stored = model.images.as_ref().ok_or(ExtendError::NoImages)?;
    if let Some(c) = model
        .classes
        .iter()
        .find(|c| c.name == class.name || c.terrain_id == class.terrain_id)
    {
        return Err(ExtendError::Class(format!(
            "the model already has terrain `{}` (id {}): name the new ground otherwise",
            c.name, c.terrain_id
        )));
    }
    if model.classes.len() >= MAX_CLASSES {
        return Err(ExtendError::Class(format!(
            "the model holds {MAX_CLASSES} terrains, the most a model holds"
        )));
    }
    if images.len() < MIN_NEW_STANCES {
        return Err(ExtendError::TooFew {
            name: class.name,
            have: images.len(),
            need: MIN_NEW_STANCES,
        });
    }
    let work = images
        .iter()
        .enumerate()
        .map(|(i, img)| working(model, img, i))
        .collect::<Result<Vec<_>, _>>()?;
    let mut extra = Vec::with_capacity(session.len());
    for (i, (img, k)) in session.iter().enumerate() {
        if *k >= model.classes.len() {
            return Err(ExtendError::Stance {
                index: images.len() + i,
                msg: format!("class {k}: the model has {}", model.classes.len()),
            });
        }
        extra.push((working(model, img, images.len() + i)?, *k));
    }
    let k_new = model.classes.len();
    // The new terrain's T share as the model's: its first stances T, the rest V.
    let share = stored.n_train as f64 / stored.pixels.len().max(1) as f64;
    let n_t_new = ((work.len() as f64 * share).round() as usize).clamp(2, work.len() - 2);
    let (t_old, v_old) = stored.pixels.split_at(stored.n_train);
    let (c_t, c_v) = model.sample_classes.split_at(stored.n_train);
    let pixels: Vec<Vec<u16>> = t_old
        .iter()
        .cloned()
        .chain(work[..n_t_new].iter().cloned())
        .chain(v_old.iter().cloned())
        .chain(work[n_t_new..].iter().cloned())
        .chain(extra.iter().map(|(p, _)| p.clone()))
        .collect();
    let labels: Vec<usize> = c_t
        .iter()
        .copied()
        .chain(std::iter::repeat_n(k_new, n_t_new))
        .chain(c_v.iter().copied())
        .chain(std::iter::repeat_n(k_new, work.len() - n_t_new))
        .chain(extra.iter().map(|(_, k)| *k))
        .collect();
    let n_t = stored.n_train + n_t_new;
    let mut m = model.clone();
    m.classes.push(class);
    m.sample_classes = labels.clone();
    m.images = Some(StoredImages {
        n_train: n_t,
        pixels: pixels.clone(),
    });
    for (i, img) in images.iter().enumerate() {
        if i < n_t_new {
            m.train_hashes.push(img.content_hash());
        } else {
            m.val_hashes.push(img.content_hash());
        }
    }
    m.val_hashes
        .extend(session.iter().map(|(img, _)| img.content_hash()));
    if basis == Basis::Refit {
        let (fitted, _) = fit(
            &pixels,
            &labels,
            n_t,
            k_new + 1,
            model.normalize_load.is_some(),
            Some(dims_with_one_more(model)),
        )?;
        fitted.install(&mut m);
    } else {
        extend_basis(&mut m, model, &work, &pixels)?;
    }
    redraw_checks(&mut m, model, pixels, labels);
    Ok(m)
}

/// `img` as the model's working image; `index` names it in the error.
fn working(model: &Model, img: &PressureImage, index: usize) -> Result<Vec<u16>, ExtendError> {
    let bad = |msg: String| ExtendError::Stance { index, msg };
    if (img.rows, img.cols) != (model.input_rows, model.input_cols)
        || model.bits.is_some_and(|b| b != img.bits)
    {
        return Err(bad(format!(
            "a {}x{} {}-bit image; the model takes {}x{}{}",
            img.rows,
            img.cols,
            img.bits,
            model.input_rows,
            model.input_cols,
            model.bits.map_or(String::new(), |b| format!(" {b}-bit"))
        )));
    }
    preprocess(img, &model.crop, model.downsample)
        .map(|w| w.pixels)
        .ok_or_else(|| bad("the model's crop leaves nothing of it".into()))
}

/// The known terrains' references kept: `old`'s PCA rows stay as they are, and the directions
/// in which the new terrain's stances (`new`, working images) leave that subspace are added
/// (the leading ones of their residuals, at most `old`'s dimensions per terrain), so every
/// known stance projects as before plus a little; the stored samples (`pixels`, in `m`'s
/// order) are projected on the longer basis and the kernel width stays.
fn extend_basis(
    m: &mut Model,
    old: &Model,
    new: &[Vec<u16>],
    pixels: &[Vec<u16>],
) -> Result<(), ExtendError> {
    let (h, n) = (old.h, old.pca_mean.len());
    let mut c = crate::classifier::Classifier::new(old.clone());
    let mut centred = |w: &[u16]| -> Vec<f64> {
        c.classify_work(w);
        c.features()
            .iter()
            .zip(&old.pca_mean)
            .map(|(f, mu)| (*f - *mu) as f64)
            .collect()
    };
    let rows: Vec<Vec<f64>> = old
        .pca_matrix
        .chunks_exact(n)
        .map(|r| r.iter().map(|&x| x as f64).collect())
        .collect();
    let outside = |v: &mut Vec<f64>, basis: &[Vec<f64>]| {
        for u in basis {
            let d: f64 = u.iter().zip(v.iter()).map(|(a, b)| a * b).sum();
            v.iter_mut().zip(u).for_each(|(x, a)| *x -= d * a);
        }
    };
    let residuals: Vec<Vec<f64>> = new
        .iter()
        .map(|w| {
            let mut r = centred(w);
            outside(&mut r, &rows);
            r
        })
        .collect();
    let want = old
        .h
        .div_ceil(old.classes.len().max(1))
        .min(new.len().saturating_sub(1));
    // The residuals' principal directions from their Gram matrix (a few dozen stances, not
    // a thousand features): v = R^T u / s.
    let r = DMatrix::<f64>::from_fn(residuals.len(), n, |i, j| residuals[i][j]);
    let eig = (&r * r.transpose()).symmetric_eigen();
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let mut basis = rows.clone();
    for &e in order.iter().take(want) {
        if eig.eigenvalues[e] <= 1e-9 * eig.eigenvalues[order[0]].max(f64::MIN_POSITIVE) {
            break;
        }
        let mut v: Vec<f64> = (r.transpose() * eig.eigenvectors.column(e))
            .iter()
            .copied()
            .collect();
        outside(&mut v, &basis);
        let len = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if len <= f64::EPSILON {
            continue;
        }
        v.iter_mut().for_each(|x| *x /= len);
        basis.push(v);
    }
    let h2 = basis.len();
    let _ = h;
    m.h = h2;
    m.pca_matrix = basis.iter().flatten().map(|&x| x as f32).collect();
    m.samples = Vec::with_capacity(pixels.len() * h2);
    for p in pixels {
        let v = centred(p);
        for u in &basis {
            m.samples
                .push(u.iter().zip(&v).map(|(a, b)| a * b).sum::<f64>() as f32);
        }
    }
    m.unknown.density_thresholds = unknown_thresholds(m);
    Ok(())
}

/// The PCA dimensions of `model` with one terrain more: its own, and its dimensions per
/// terrain for the new one, up to the most there are.
fn dims_with_one_more(model: &Model) -> usize {
    let k = model.classes.len().max(1);
    let want = model.h + model.h.div_ceil(k);
    want.min(crate::classifier::options::MAX_DIMS.max(model.h))
}

/// The unknown checks of `m` (just fitted, one class more than `old`) drawn again on its
/// stored images: the load band from them, a texture band for the new class from its own
/// stances (the known ones' kept: their images are not all stored), no energy map for it (its
/// flights are not kept), the novelty as `train` calibrates a single session.
fn redraw_checks(m: &mut Model, old: &Model, pixels: Vec<Vec<u16>>, labels: Vec<usize>) {
    let k_new = old.classes.len();
    if old.unknown.load_bands.is_some() {
        add_load_check(m);
    }
    if let Some(bands) = &old.unknown.texture_bands {
        let rough: Vec<f64> = pixels
            .iter()
            .zip(&labels)
            .filter(|(_, k)| **k == k_new)
            .filter_map(|(p, _)| {
                let (rows, cols) = m.work_size()?;
                Some(crate::classifier::texture::roughness(p, rows, cols))
            })
            .collect();
        let mut per = vec![Vec::new(); k_new + 1];
        per[k_new] = rough;
        let new_band = crate::order_stats::class_bands(per, m.unknown.rate)
            .get(k_new)
            .copied()
            .filter(|b| b.iter().all(|x| x.is_finite()))
            .unwrap_or([0.0, f64::MAX]);
        let mut b = bands.clone();
        b.push(new_band);
        m.unknown.texture_bands = Some(b);
    }
    if let Some(e) = &mut m.unknown.energy {
        e.push(None);
    }
    if let Some(nv) = &old.unknown.novelty {
        // The images the model was calibrated on, in recording order as the time blocks need
        // them, and the new terrain's stances in the order they were kept; the stored images
        // (in the split's order) only where the file carries no calibration images.
        let cal = &nv.calibration;
        let (pixels, labels) = if !cal.pixels.is_empty() && cal.pixels.len() == cal.classes.len() {
            // The new terrain's and the session's, stored after the model's own.
            let n_old = old.images.as_ref().map_or(0, |s| s.pixels.len());
            let first_session = n_old + labels.iter().filter(|&&k| k == k_new).count();
            let new = pixels
                .iter()
                .zip(&labels)
                .enumerate()
                .filter(|(i, (_, k))| **k == k_new || *i >= first_session)
                .map(|(_, pk)| pk);
            let (p, c): (Vec<Vec<u16>>, Vec<usize>) = cal
                .pixels
                .iter()
                .cloned()
                .zip(cal.classes.iter().copied())
                .chain(new.map(|(p, &k)| (p.clone(), k)))
                .unzip();
            (p, c)
        } else {
            (pixels, labels)
        };
        set_novelty(
            m,
            pixels,
            labels,
            CalibrationSource::TimeBlocks,
            Vec::new(),
            nv.calibration.margin,
            0,
            nv.score,
        );
        // Never stricter on ground the model knew: its thresholds were drawn on more images
        // (the training run's unused ones too) than the stored ones drawn on here; thresholds
        // are ratios to each class's own spread, so the old ones carry over.
        if let Some(new) = &mut m.unknown.novelty {
            for (t, old) in new.thresholds.iter_mut().zip(&nv.thresholds) {
                *t = t.max(*old);
            }
        }
    }
}

/// Per class of `m`, its stored stances decided each with itself left out of the stored
/// samples: how well the model is expected to tell its terrains apart, measured on its own
/// data (`presrs discover --add` prints it for the terrain it adds).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ToldApart {
    /// Stored stances of the class.
    pub stances: usize,
    /// Decided as the class.
    pub right: usize,
    /// Called unknown.
    pub unknown: usize,
    /// Decided as another class.
    pub wrong: usize,
}

/// [`ToldApart`] for each class of `m`; empty for a model without stored images.
pub fn told_apart(m: &Model) -> Vec<ToldApart> {
    let mut out = vec![ToldApart::default(); m.classes.len()];
    let Some(stored) = &m.images else {
        return Vec::new();
    };
    let mut c = crate::classifier::Classifier::new(m.clone());
    for (i, (p, &k)) in stored.pixels.iter().zip(&m.sample_classes).enumerate() {
        let Some(t) = out.get_mut(k) else { continue };
        c.exclude_sample(Some(i));
        let d = c.classify_work(p);
        t.stances += 1;
        match d.class {
            Some(x) if x == k => t.right += 1,
            Some(_) => t.wrong += 1,
            None => t.unknown += 1,
        }
    }
    out
}
