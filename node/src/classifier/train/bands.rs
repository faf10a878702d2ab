//! The load and texture bands: per class, the range a known image's load or texture falls in.

use super::preprocess;
use crate::classifier::image::PressureImage;
use crate::classifier::model::Model;

/// Adds the texture check (`TrainOptions::check_texture`) to `m`: per class, the roughness
/// band of `images` (each with its class index) through the model's crop and downsampling,
/// calibrated with its `unknown_rate`. Pass every image of the class the model may meet as
/// known: the training run's and the calibration run's (`TrainingSet::train_calibrated` does).
pub fn add_texture_check<'a>(
    m: &mut Model,
    images: impl IntoIterator<Item = (&'a PressureImage, usize)>,
) {
    m.unknown.texture_bands = Some(bands_of(m, images, |w| {
        crate::classifier::texture::roughness(&w.pixels, w.rows, w.cols)
    }));
}

/// Per class of `m`, the band of `value` over `images` (each with its class index) through
/// the model's crop and downsampling, calibrated with its `unknown_rate`: the load and texture
/// checks' bands.
pub(crate) fn bands_of<'a>(
    m: &Model,
    images: impl IntoIterator<Item = (&'a PressureImage, usize)>,
    value: impl Fn(&PressureImage) -> f64,
) -> Vec<[f64; 2]> {
    let mut per: Vec<Vec<f64>> = vec![Vec::new(); m.classes.len()];
    for (img, k) in images {
        if let (Some(v), Some(w)) = (per.get_mut(k), preprocess(img, &m.crop, m.downsample)) {
            v.push(value(&w));
        }
    }
    crate::order_stats::class_bands(per, m.unknown.rate)
}

/// Adds the load check to `m` with bands drawn over `images` (each with its class index),
/// through the model's crop and downsampling, calibrated with its `unknown_rate`: pass the
/// training run's and the calibration run's images, as for [`add_texture_check`], so that the
/// bands hold the next run's spread, not only the stored samples'.
pub fn add_load_check_on<'a>(
    m: &mut Model,
    images: impl IntoIterator<Item = (&'a PressureImage, usize)>,
) {
    m.unknown.load_bands = Some(bands_of(m, images, |w| {
        w.pixels.iter().map(|&p| p as f64).sum()
    }));
}

/// Adds the load check (`TrainOptions::check_load`) to a trained model from its stored images,
/// calibrated with its `unknown_rate`; `false` when the model holds no images (older files).
pub fn add_load_check(m: &mut Model) -> bool {
    let Some(imgs) = &m.images else {
        return false;
    };
    m.unknown.load_bands = Some(load_ranges(&imgs.pixels, &m.sample_classes, m.unknown.rate));
    true
}

/// Per class, the band of load (summed working image) its images showed at the sample time
/// ([`crate::order_stats::class_bands`]): an image whose load lies outside its best class's band is
/// unknown, however its texture matches. It also carries the hopper's history (the steps after
/// sand are light too): docs/decisions/unknown-load-check.md.
pub(crate) fn load_ranges(work: &[Vec<u16>], labels: &[usize], rate: f64) -> Vec<[f64; 2]> {
    let n_classes = labels.iter().max().map_or(0, |m| m + 1);
    let mut per: Vec<Vec<f64>> = vec![Vec::new(); n_classes];
    for (p, &k) in work.iter().zip(labels) {
        per[k].push(p.iter().map(|&v| v as f64).sum());
    }
    crate::order_stats::class_bands(per, rate)
}

/// Moves a class's calibrated threshold `q` so that images DISTANCE_MARGIN farther from the
/// class's samples than the calibration's own held-out ones still pass. The log density is
/// `c - d^2 / (2 sigma^2)` near a sample at distance `d` (`c` the class's density at a sample),
/// so a distance scaled by `1 + m` moves `c - q` by `(1 + m)^2`.
///
/// Why: held-out training images come from the same recording as the stored samples; the
/// robot's next run does not. Measured: docs/decisions/calibration-distance-margin.md.
pub(crate) fn widen(m: &Model, k: usize, q: f64) -> f64 {
    let n_k = m.sample_classes.iter().filter(|&&c| c == k).count().max(1) as f64;
    let s2 = 2.0 * m.kernel_width * m.kernel_width;
    let c = -n_k.ln() - 0.5 * m.h as f64 * (std::f64::consts::PI * s2).ln();
    let f = (1.0 + DISTANCE_MARGIN) * (1.0 + DISTANCE_MARGIN);
    if q < c { c - f * (c - q) } else { q }
}

/// See [`widen`].
pub(crate) const DISTANCE_MARGIN: f64 = 0.1;
