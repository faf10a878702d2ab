//! The checks a model file passes before a node runs it: sizes, indexes, finite numbers; each
//! names the field at fault.

use super::{Invalid, MAX_CLASSES, MAX_DOWNSAMPLE, Model};

impl Model {
    /// Checks that the model's parts fit together (sizes, indexes, finite numbers).
    pub fn validate(&self) -> Result<(), Invalid> {
        let (r, c) = self.validate_input()?;
        let n = self.feature_len();
        self.validate_projection(n)?;
        self.validate_labels()?;
        self.unknown
            .validate(self.classes.len(), n, self.h, r * c)
            .map_err(|(key, msg)| Invalid::new(key, format!("{key}: {msg}")))?;
        self.validate_images(r * c)
    }

    /// The image the model takes and what its crop leaves: the working size.
    fn validate_input(&self) -> Result<(usize, usize), Invalid> {
        if let Some(b) = self.bits
            && b != 8
            && b != 16
        {
            return Err(Invalid::range("bits", b, "8 or 16"));
        }
        if self.classes.is_empty() || self.classes.len() > MAX_CLASSES {
            return Err(Invalid::new(
                "classes",
                format!("{} classes (1..={MAX_CLASSES} allowed)", self.classes.len()),
            ));
        }
        if !(1..=MAX_DOWNSAMPLE).contains(&self.downsample) {
            return Err(Invalid::range(
                "downsample",
                self.downsample,
                format!("1..={MAX_DOWNSAMPLE} (1 = full resolution)"),
            ));
        }
        if !(1..=64).contains(&self.input_rows) || !(1..=64).contains(&self.input_cols) {
            return Err(Invalid::new(
                "input_rows",
                format!(
                    "input_rows x input_cols = {}x{}: the protocol carries 1x1 to 64x64 images",
                    self.input_rows, self.input_cols
                ),
            ));
        }
        let (r, c) = self
            .work_size()
            .ok_or_else(|| Invalid::new("crop", "crop leaves no pixels"))?;
        if crate::classifier::features::fft_len(r * c) != self.n_fft {
            return Err(Invalid::new(
                "n_fft",
                format!("n_fft {} does not fit {r}x{c} images", self.n_fft),
            ));
        }
        Ok((r, c))
    }

    /// The PCA and the stored samples for feature vectors of `n` values: sizes, class
    /// indexes, finite numbers, a positive kernel width.
    fn validate_projection(&self, n: usize) -> Result<(), Invalid> {
        if self.pca_mean.len() != n {
            return Err(Invalid::new(
                "pca_mean",
                format!("pca_mean has {} values, expected {n}", self.pca_mean.len()),
            ));
        }
        if self.h == 0 || self.pca_matrix.len() != self.h * n {
            return Err(Invalid::new(
                "pca_matrix",
                format!(
                    "pca_matrix has {} values, expected h x n = {} x {n}",
                    self.pca_matrix.len(),
                    self.h
                ),
            ));
        }
        if self.samples.len() != self.n_samples() * self.h || self.n_samples() == 0 {
            return Err(Invalid::new(
                "samples",
                format!(
                    "samples has {} values for {} labels and h = {}",
                    self.samples.len(),
                    self.n_samples(),
                    self.h
                ),
            ));
        }
        if let Some(bad) = self
            .sample_classes
            .iter()
            .find(|&&k| k >= self.classes.len())
        {
            return Err(Invalid::new(
                "sample_classes",
                format!("sample class {bad} is not a class index"),
            ));
        }
        if !(self.kernel_width.is_finite() && self.kernel_width > 0.0) {
            return Err(Invalid::new(
                "kernel_width",
                format!("kernel_width {} must be positive", self.kernel_width),
            ));
        }
        let finite = self
            .pca_mean
            .iter()
            .chain(&self.pca_matrix)
            .chain(&self.samples)
            .all(|v| v.is_finite());
        if !finite {
            return Err(Invalid::new(
                "pca_matrix",
                "non-finite numbers in the PCA or samples",
            ));
        }
        Ok(())
    }

    /// What the model says of its terrains and stances: gaits, the deciding frame, the load
    /// normalisation, terrain ids.
    fn validate_labels(&self) -> Result<(), Invalid> {
        if let Some(g) = &self.gaits
            && (g.contains(&0) || g.windows(2).any(|w| w[0] >= w[1]))
        {
            return Err(Invalid::new(
                "gaits",
                format!(
                    "gaits {g:?}: want gait numbers 1..=255, sorted, each once; or drop the field"
                ),
            ));
        }
        if self.confidence.as_ref().is_some_and(|c| !c.is_valid()) {
            return Err(Invalid::new(
                "confidence",
                "the confidence map's weights must be finite numbers (retrain to measure it again)",
            ));
        }
        if let Some(ms) = self.sample_ms
            && !(1..=1000).contains(&ms)
        {
            return Err(Invalid::range(
                "sample_ms",
                ms,
                "1..=1000 ms after touchdown",
            ));
        }
        if let Some(v) = self.normalize_load
            && !(v.is_finite() && v > 0.0)
        {
            return Err(Invalid::new(
                "normalize_load",
                format!("normalize_load {v} must be a positive total intensity"),
            ));
        }
        if let Some(c) = self
            .classes
            .iter()
            .find(|c| c.terrain_id == protocol::messages::TERRAIN_UNKNOWN)
        {
            return Err(Invalid::new(
                "classes",
                format!(
                    "class `{}` sends terrain id 255, which means unknown",
                    c.name
                ),
            ));
        }
        Ok(())
    }

    /// The stored working images, one per stored sample, each of `px` pixels.
    fn validate_images(&self, px: usize) -> Result<(), Invalid> {
        if let Some(im) = &self.images {
            if im.pixels.len() != self.n_samples()
                || im.n_train == 0
                || im.n_train >= im.pixels.len()
            {
                return Err(Invalid::new(
                    "images",
                    format!(
                        "images holds {} images ({} for training) for {} stored samples",
                        im.pixels.len(),
                        im.n_train,
                        self.n_samples()
                    ),
                ));
            }
            if let Some(i) = im.pixels.iter().position(|p| p.len() != px) {
                return Err(Invalid::new(
                    "images",
                    format!(
                        "stored image {i} has {} pixels, expected {px} (the crop's working size)",
                        im.pixels[i].len()
                    ),
                ));
            }
        }
        Ok(())
    }
}
