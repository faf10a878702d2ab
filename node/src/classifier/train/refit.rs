//! Refitting a model to a damaged sensor: the repair filter's dead lines taken out of the
//! features, the stored samples' features recomputed.

use super::{Model, StoredImages, fit, load_ranges, set_novelty};

/// The model refitted to a sensor with dead lines: its stored images get the same dead rows and
/// columns (of the working image) and the same repair as the node gives a live image, and PCA,
/// stored samples, dimensions and kernel width are fitted again on T and V as in [`train`].
///
/// A filled dead line is a copy of its neighbour: the texture it carried is gone from the image
/// and its copy adds spectral lines the training images never had. A model fitted on equally
/// damaged images compares like with like (docs/decisions/figures-behind-comments.md,
/// refit-on-damage).
pub fn refit(model: &Model, dead_rows: &[bool], dead_cols: &[bool]) -> Result<Model, RefitError> {
    let images = model.images.as_ref().ok_or(RefitError::NoImages)?;
    let (rows, cols) = model.work_size().ok_or(RefitError::Size)?;
    if dead_rows.len() != rows || dead_cols.len() != cols {
        return Err(RefitError::Size);
    }
    let damage = |p: &Vec<u16>| {
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
        crate::classifier::repair::repair_lines(&mut img, rows, cols, dead_rows, dead_cols, None);
        img
    };
    let work: Vec<Vec<u16>> = images.pixels.iter().map(damage).collect();
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
    // At the dimensions the model was chosen with.
    let max_dims = model
        .unknown
        .choice
        .as_ref()
        .and_then(|c| c.chosen.parse::<crate::classifier::options::UnknownChecks>().ok())
        .is_some_and(|c| {
            matches!(c, crate::classifier::options::UnknownChecks::Fixed(c) if c.dims == crate::classifier::options::Dims::Max)
        });
    let (accuracy, most) = fitted;
    if max_dims { most } else { accuracy }.install(&mut m);
    // The damaged images carry less load: the ranges follow them.
    // The texture ranges were drawn on a whole sensor: filled lines are smoother and dead ones
    // edged, and the stored images alone are too few to draw them again. A refitted model
    // goes without the check rather than call a damaged sensor's known steps unknown.
    if m.unknown.texture_bands.take().is_some() {
        tracing::info!("refit to dead lines: the texture check is off for this model");
    }
    if m.unknown.load_bands.is_some() {
        m.unknown.load_bands = Some(load_ranges(&work, &m.sample_classes, m.unknown.rate));
    }
    m.images = Some(StoredImages {
        n_train: images.n_train,
        pixels: work,
    });
    // The novelty is calibrated again, on the same calibration images with the same lines dead
    // (the new PCA and samples move every distance), then the undamaged images are put back:
    // a later refit starts from them again.
    if let Some(nv) = model.unknown.novelty.clone() {
        let c = nv.calibration;
        let damaged: Vec<Vec<u16>> = c.pixels.iter().map(damage).collect();
        set_novelty(
            &mut m,
            damaged,
            c.classes.clone(),
            c.source,
            c.runs,
            c.margin,
            c.held_out_images,
            nv.score,
        );
        if let Some(n) = m.unknown.novelty.as_mut() {
            n.calibration.pixels = c.pixels;
            n.calibration.classes = c.classes;
        }
    }
    m.images = model.images.clone();
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
