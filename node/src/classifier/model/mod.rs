//! The model file: versioned JSON holding everything needed to classify, and the names of the
//! images it was trained on.

mod validate;

use std::path::Path;

use protocol::config::Invalid;
use serde::{Deserialize, Serialize};

use super::image::Crop;

/// Format version written by this build. 3: every unknown-ground check in one `unknown`
/// section ([`crate::unknown::checks::Checks`]); 2: the novelty score may be `knn`, and the
/// file keeps how its checks were chosen. A build that reads only an older version refuses a
/// newer file, naming the retrain, rather than misread it.
pub const MODEL_VERSION: u32 = 3;
/// The oldest format version this build reads: version 1 and 2 files load with the decisions
/// they had (`node/tests/fixtures/model-v1` and `model-v2`, written by those builds, check it).
pub const OLDEST_MODEL_VERSION: u32 = 1;
/// Largest downsampling factor (a 44x44 image at 8 keeps 6x6 pixels).
pub const MAX_DOWNSAMPLE: usize = 8;

pub use crate::unknown::MAX_UNKNOWN_RATE;
pub use crate::unknown::checks::Checks;
/// Most classes a model may have: one per terrain id of a catalog (0-254; 255 is "unknown").
/// The classifier's per-class buffers are sized to the model's classes when it is built.
pub const MAX_CLASSES: usize = 255;

/// The least a stance image shows of a foot on the ground, in the working image (after crop and
/// downsampling): below either, the image is "no contact" and never a terrain.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MinContact {
    /// Sum of the pixel values.
    pub load: u64,
    /// Pixels above zero.
    pub area: u32,
}

impl MinContact {
    /// A tenth of the smallest load and area among `images` (the training images): a foot
    /// pressing on any ground the model knows leaves more. Measured on the simulated sets:
    /// smallest static press 11,304 load over 248 pixels, smallest dynamic stance 56,744 over
    /// 1,165; a blank frame leaves 0, a stuck line of 44 pixels at 255 covers 44.
    pub fn of_training(images: &[Vec<u16>]) -> Self {
        let (mut load, mut area) = (u64::MAX, u32::MAX);
        for img in images {
            let (l, a) = Self::measure(img);
            load = load.min(l);
            area = area.min(a);
        }
        Self {
            load: load / 10,
            area: area / 10,
        }
    }

    /// Load and area of a working image.
    pub fn measure(work: &[u16]) -> (u64, u32) {
        crate::classifier::kernels::load_area(work, false)
    }

    /// The image shows a foot on the ground: at least this load and area, and never blank.
    pub fn holds(&self, work: &[u16]) -> bool {
        let (l, a) = Self::measure(work);
        self.holds_for(l, a)
    }

    /// [`MinContact::holds`] for a working image's load and area, measured by the caller.
    pub fn holds_for(&self, load: u64, area: u32) -> bool {
        area > 0 && load >= self.load && area >= self.area
    }
}

/// One class of a model: its name and the terrain id it sends.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClassInfo {
    /// The terrain's catalog name.
    pub name: String,
    /// Terrain id sent in `TerrainClass`.
    pub terrain_id: u8,
}

/// A model whose classes name terrains differently from the catalog the node runs with.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum CatalogMismatch {
    /// The model sends an id the catalog does not know.
    #[error(
        "model class `{name}` sends terrain id {id}, which the terrain catalog does not have: run \
         with the terrains file the model was trained with (--terrains FILE, or `terrains = \"FILE\"` \
         in the config)"
    )]
    MissingId {
        /// The class's name in the model.
        name: String,
        /// The id the model sends for it.
        id: u8,
    },
    /// The model and the catalog give one id two names.
    #[error(
        "model class `{name}` sends terrain id {id}, but the terrain catalog calls id {id} \
         `{catalog_name}`: the model and the bus would disagree on what it means; use the \
         terrains file the model was trained with, or retrain"
    )]
    NameDiffers {
        /// The class's name in the model.
        name: String,
        /// The id the model sends for it.
        id: u8,
        /// What the catalog calls that id.
        catalog_name: String,
    },
}

/// A trained classifier: crop, FFT length, PCA and the Parzen samples, with each class's terrain.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// Model file format version ([`MODEL_VERSION`]).
    pub version: u32,
    /// The classes, in the order of the class indices.
    pub classes: Vec<ClassInfo>,
    /// Size of the images the model takes (before crop).
    pub input_rows: usize,
    /// Width of the images the model takes (before crop).
    pub input_cols: usize,
    /// Crop applied before the features.
    pub crop: Crop,
    /// 1 = full resolution.
    pub downsample: usize,
    /// Mean total intensity of the training images when load normalisation is on: each image is
    /// scaled to this total before its features are taken.
    pub normalize_load: Option<f64>,
    /// FFT length N (feature length N/2 + 1).
    pub n_fft: usize,
    /// PCA dimensions h.
    pub h: usize,
    /// Mean feature vector (length N/2 + 1).
    pub pca_mean: Vec<f32>,
    /// U, h x (N/2 + 1), row-major: Q = U (F - mean).
    pub pca_matrix: Vec<f32>,
    /// Stored samples P, m x h row-major (training and validation images, projected).
    pub samples: Vec<f32>,
    /// Class index of each stored sample.
    pub sample_classes: Vec<usize>,
    /// Gaussian kernel width sigma, chosen on the validation split.
    pub kernel_width: f64,
    /// Content hashes of the training images (to keep test images out).
    pub train_hashes: Vec<String>,
    /// Content hashes of the validation images.
    pub val_hashes: Vec<String>,
    /// The stored samples' images after crop and downsampling, so that the node can refit the
    /// model to its sensor's dead lines (see `train::refit`). Absent in older model files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub images: Option<StoredImages>,
    /// The least contact an image must show to be classified (see [`MinContact`]). Absent in
    /// older model files: then only a blank image is "no contact".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact: Option<MinContact>,
    /// Bits per pixel of the training images (8 or 16): the model takes images of this depth
    /// only, as 16-bit pixels have no defined scale to 8 bits. Absent in older model files:
    /// any depth.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bits: Option<u8>,
    /// The gaits its training and calibration images touched down in (the capture manifest's
    /// `gait`, see [`crate::gait_status`]), sorted: a stance in another gait may look new to it
    /// (`presrs node --replay` counts unknowns per gait and names those). Absent in older model
    /// files and where no image's gait was known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gaits: Option<Vec<u8>>,
    /// The stance's deciding frame, ms after touchdown, as `train` measured it on the lab's
    /// stances (the frame that classified its held-out stances best); the node samples at it.
    /// Absent in older files and for sets captured without their stances' frames: the node's
    /// `sample_ms` (the paper's 70).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_ms: Option<u32>,
    /// The measured chance that a decision is right, from its margin and its room under the
    /// novelty threshold ([`super::confidence`]): the decision's confidence. Absent in older
    /// files and where `train` had nothing to measure it on: the Parzen posterior.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<super::confidence::ConfidenceMap>,
    /// Everything that calls a stance unknown ground: format 3's one `unknown` section
    /// ([`crate::unknown::checks`]; format 1 and 2 files have it made from their keys).
    pub unknown: crate::unknown::checks::Checks,
}

/// The working images of the stored samples, in the order of `Model::samples`: the training
/// set T first, then the validation set V.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoredImages {
    /// How many of them are T (the rest are V).
    pub n_train: usize,
    /// One row-major working image per stored sample.
    pub pixels: Vec<Vec<u16>>,
}

/// A model file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The file cannot be read.
    #[error("cannot read model {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The file cannot be written.
    #[error("cannot write model {path}: {source}{hint}")]
    Write {
        /// The file.
        path: String,
        /// What the OS said.
        source: std::io::Error,
        /// How to fix it, when known (a missing folder).
        hint: &'static str,
    },
    #[error("model {path} is not a PreSRS model file (JSON): {msg}")]
    /// The file is not a model's JSON.
    Parse {
        /// The file.
        path: String,
        /// What the parser said.
        msg: String,
    },
    #[error(
        "model {path} has format version {found}; this build reads versions {OLDEST_MODEL_VERSION} to {MODEL_VERSION}. Retrain it with `presrs train`"
    )]
    /// The file has another format version.
    Version {
        /// The file.
        path: String,
        /// Its version.
        found: u64,
    },
    #[error("model {path} is inconsistent: {msg}. Retrain it with `presrs train`")]
    /// The file's fields do not fit together.
    Invalid {
        /// The file.
        path: String,
        /// What does not fit.
        msg: String,
    },
}

impl Model {
    /// Length of the feature vector (N/2 + 1).
    pub fn feature_len(&self) -> usize {
        self.n_fft / 2 + 1
    }

    /// Stored samples (training and validation images).
    pub fn n_samples(&self) -> usize {
        self.sample_classes.len()
    }

    /// Size after crop and downsampling.
    pub fn work_size(&self) -> Option<(usize, usize)> {
        let (r, c) = self.crop.output_size(self.input_rows, self.input_cols)?;
        let k = self.downsample.max(1);
        Some((r.div_ceil(k), c.div_ceil(k)))
    }

    /// A short id: the low 16 bits go out in `NodeStatus`.
    pub fn id(&self) -> u64 {
        let text = serde_json::to_string(self).unwrap_or_default();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in text.bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        h
    }

    /// Checks every dimension, so a hand-edited or truncated file fails here, not mid-flight.
    /// Checks that every class's terrain id means the same terrain in `catalog` (the node's),
    /// so that what the node sends is what the controller and the DBC read.
    pub fn check_catalog(&self, catalog: &protocol::TerrainCatalog) -> Result<(), CatalogMismatch> {
        for c in &self.classes {
            match catalog.by_id(c.terrain_id) {
                None => {
                    return Err(CatalogMismatch::MissingId {
                        name: c.name.clone(),
                        id: c.terrain_id,
                    });
                }
                Some(t) if t.name() != c.name => {
                    return Err(CatalogMismatch::NameDiffers {
                        name: c.name.clone(),
                        id: c.terrain_id,
                        catalog_name: t.name().to_string(),
                    });
                }
                Some(_) => {}
            }
        }
        Ok(())
    }

    /// An image of `bits` per pixel is of the model's depth.
    pub fn check_depth(&self, bits: u8) -> Result<(), DepthMismatch> {
        match self.bits {
            Some(want) if want != bits => Err(DepthMismatch {
                bits,
                want_bits: want,
            }),
            _ => Ok(()),
        }
    }

    /// Reads and checks a model file.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let p = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ModelError::Io {
            path: p.clone(),
            source,
        })?;
        Self::from_json(&text, &p)
    }

    /// Parses and checks a model from its JSON; `path` names it in errors.
    pub fn from_json(text: &str, path: &str) -> Result<Self, ModelError> {
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| ModelError::Parse {
            path: path.into(),
            msg: e.to_string(),
        })?;
        let found = v
            .get("version")
            .and_then(|x| x.as_u64())
            .ok_or_else(|| ModelError::Parse {
                path: path.into(),
                msg: "no `version` field".into(),
            })?;
        if !(OLDEST_MODEL_VERSION as u64..=MODEL_VERSION as u64).contains(&found) {
            return Err(ModelError::Version {
                path: path.into(),
                found,
            });
        }
        let mut v = v;
        if found < 3
            && let Some(obj) = v.as_object_mut()
        {
            crate::unknown::checks::upgrade_v2(obj).map_err(|msg| ModelError::Parse {
                path: path.into(),
                msg,
            })?;
            // Read as this build writes it: saved again, it is a format 3 file.
            obj.insert("version".into(), MODEL_VERSION.into());
        }
        let m: Model = serde_json::from_value(v).map_err(|e| ModelError::Parse {
            path: path.into(),
            msg: e.to_string(),
        })?;
        m.validate().map_err(|e| ModelError::Invalid {
            path: path.into(),
            msg: e.to_string(),
        })?;
        Ok(m)
    }

    /// Writes the model as JSON.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        let text = serde_json::to_string(self).map_err(|e| ModelError::Parse {
            path: path.display().to_string(),
            msg: e.to_string(),
        })?;
        std::fs::write(path, text).map_err(|source| ModelError::Write {
            path: path.display().to_string(),
            hint: match path.parent() {
                Some(d) if !d.as_os_str().is_empty() && !d.exists() => {
                    " (its folder does not exist: create it first)"
                }
                _ => "",
            },
            source,
        })
    }
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
