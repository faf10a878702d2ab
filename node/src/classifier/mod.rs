//! The terrain classifier of the paper (sections 4, 5, 7.2, 8).
//!
//! Per image: [`image`] crop and downsampling, the [`features`] vector (eqs. 1-3), PCA
//! projection and the Parzen-window decision ([`pwe`]); the [`repair`] filter for dead sensor
//! lines; [`train`]ing with the paper's 13/7 split; the [`model`] file; [`dataset`] readers.

pub mod dataset;
pub mod features;
pub mod image;
pub mod model;
pub mod pwe;
pub mod repair;
pub mod train;

pub use image::{Crop, PressureImage};
pub use model::{ClassInfo, Model};
pub use pwe::{Classifier, Decision};

/// True when this x86-64 CPU has AVX2 and FMA. The portable build targets baseline x86-64
/// (SSE2); the per-image loops that are worth it (PCA projection, spectrum split) also have a
/// copy compiled for AVX2/FMA and pick it with this check (std caches the answer).
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx2_fma() -> bool {
    std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
}
