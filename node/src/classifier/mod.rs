//! The terrain classifier of the paper (sections 4, 5, 7.2, 8).
//!
//! Per image: [`image`] crop and downsampling, the [`features`] vector (eqs. 1-3), PCA
//! projection and the Parzen-window decision ([`pwe`]), whose unknown-ground verdict is
//! [`crate::unknown`]'s; the image's roughness ([`texture`]); the [`repair`] filter for dead
//! sensor lines; [`train`]ing with the paper's 13/7 split; the [`model`] file; [`dataset`]
//! readers.

pub mod confidence;
pub mod dataset;
mod decision;
pub mod features;
pub mod image;
mod kernels;
pub mod model;
pub mod options;
pub mod pwe;
pub mod repair;
pub mod texture;
pub mod train;

pub use image::{Crop, CropSpec, PressureImage};
pub use model::{ClassInfo, Model};
pub use pwe::{Classifier, Decision};

/// Which per-image kernels a [`Classifier`] (and its [`features::FeatureExtractor`]) runs.
///
/// Both give the same terrain: the portable code is the reference, and the native kernels differ
/// only in rounding (fused multiply-adds, the PCA weights in half precision).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kernels {
    /// The fastest this CPU runs: on x86-64 with AVX2 and FMA, the hand-written AVX2 projection
    /// (half-precision weights with F16C) and rustfft's AVX planner; otherwise [`Kernels::Portable`].
    #[default]
    Native,
    /// Only the target's baseline SIMD: loops written so that the compiler vectorises them for
    /// any target (SSE2 on x86-64, NEON on aarch64, which every 64-bit ARM has), and rustfft's
    /// 128-bit planner (SSE4.1 on x86-64, NEON on aarch64). This is what runs on a robot's ARM
    /// computer; on x86-64 it measures what the portable formulation is worth.
    Portable,
}

impl Kernels {
    /// True when the AVX2/FMA kernels run (x86-64 CPUs that have both, [`Kernels::Native`] only).
    pub(crate) fn avx2_fma(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self == Kernels::Native {
            return std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma");
        }
        false
    }

    /// The instruction sets that run, for reports and benchmarks ("avx2+fma+f16c", "portable (neon)").
    pub fn describe(self) -> &'static str {
        #[cfg(target_arch = "x86_64")]
        if self.avx2_fma() {
            return if std::is_x86_feature_detected!("f16c") {
                "avx2+fma+f16c"
            } else {
                "avx2+fma"
            };
        }
        if cfg!(target_arch = "aarch64") {
            "portable (neon)"
        } else if cfg!(target_arch = "x86_64") {
            "portable (sse2)"
        } else {
            "portable"
        }
    }
}

/// A kernel choice other than `native` or `portable`.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[error("`{0}` is not a kernel choice: use native or portable")]
pub struct ParseKernelsError(pub String);

impl std::str::FromStr for Kernels {
    type Err = ParseKernelsError;
    fn from_str(s: &str) -> Result<Self, ParseKernelsError> {
        match s {
            "native" => Ok(Kernels::Native),
            "portable" => Ok(Kernels::Portable),
            _ => Err(ParseKernelsError(s.to_string())),
        }
    }
}
