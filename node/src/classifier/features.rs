//! The feature vector of the paper's eqs. (1)-(3): rows concatenated (vec(I)), zero-padded to
//! N = the next power of two at or above the pixel count, the FFT magnitude |Y|, and its first
//! N/2 + 1 bins (the rest mirror them for a real input).

use std::sync::Arc;

use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

/// N for an image of `n_pixels`: 2048 for 40x40 (1600) and 41x38 (1558), 128 for 10x10.
pub fn fft_len(n_pixels: usize) -> usize {
    n_pixels.max(1).next_power_of_two()
}

/// Feature length n = N/2 + 1 (1025 for N = 2048).
pub fn feature_len(n_pixels: usize) -> usize {
    fft_len(n_pixels) / 2 + 1
}

/// Computes feature vectors. The FFT is planned once and its buffers reused: extracting a
/// feature vector allocates nothing.
pub struct FeatureExtractor {
    n_pixels: usize,
    fft: Arc<dyn Fft<f32>>,
    buf: Vec<Complex<f32>>,
    scratch: Vec<Complex<f32>>,
}

impl FeatureExtractor {
    pub fn new(n_pixels: usize) -> Self {
        let n = fft_len(n_pixels);
        let fft = FftPlanner::<f32>::new().plan_fft_forward(n);
        let scratch = vec![Complex::default(); fft.get_inplace_scratch_len()];
        Self {
            n_pixels,
            fft,
            buf: vec![Complex::default(); n],
            scratch,
        }
    }

    pub fn n_pixels(&self) -> usize {
        self.n_pixels
    }

    pub fn feature_len(&self) -> usize {
        self.buf.len() / 2 + 1
    }

    /// Writes the feature vector of `pixels` (row-major, already cropped) into `out`, each pixel
    /// scaled by `scale` (1.0, or the load-normalisation factor).
    ///
    /// Panics if the lengths do not match this extractor: callers size both from the model.
    pub fn extract(&mut self, pixels: &[u16], scale: f32, out: &mut [f32]) {
        assert_eq!(
            pixels.len(),
            self.n_pixels,
            "image size does not match the feature extractor"
        );
        assert_eq!(
            out.len(),
            self.feature_len(),
            "feature buffer of the wrong length"
        );
        for (b, &p) in self.buf.iter_mut().zip(pixels) {
            *b = Complex::new(p as f32 * scale, 0.0);
        }
        for b in &mut self.buf[pixels.len()..] {
            *b = Complex::default();
        }
        self.fft
            .process_with_scratch(&mut self.buf, &mut self.scratch);
        for (o, y) in out.iter_mut().zip(&self.buf) {
            *o = y.norm();
        }
    }

    /// Convenience for tools: a fresh feature vector.
    pub fn features(&mut self, pixels: &[u16], scale: f32) -> Vec<f32> {
        let mut out = vec![0.0; self.feature_len()];
        self.extract(pixels, scale, &mut out);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_follow_the_paper() {
        assert_eq!(fft_len(1600), 2048);
        assert_eq!(fft_len(1558), 2048);
        assert_eq!(fft_len(100), 128);
        assert_eq!(feature_len(1600), 1025);
    }

    #[test]
    fn matches_a_direct_dft() {
        let n_px = 41 * 38;
        let px: Vec<u16> = (0..n_px)
            .map(|i| ((i * 37 + (i / 38) * 11) % 256) as u16)
            .collect();
        let mut fx = FeatureExtractor::new(n_px);
        let f = fx.features(&px, 1.0);
        let n = fft_len(n_px);
        assert_eq!(f.len(), n / 2 + 1);
        let mut worst: f64 = 0.0;
        for (k, &fk) in f.iter().enumerate() {
            let (mut re, mut im) = (0.0f64, 0.0f64);
            for (l, &p) in px.iter().enumerate() {
                let a = -2.0 * std::f64::consts::PI * (k * l % n) as f64 / n as f64;
                re += p as f64 * a.cos();
                im += p as f64 * a.sin();
            }
            let direct = (re * re + im * im).sqrt();
            worst = worst.max((direct - fk as f64).abs() / direct.max(1.0));
        }
        assert!(worst < 1e-4, "relative error {worst}");
        assert!((f[0] as f64 - px.iter().map(|&p| p as f64).sum::<f64>()).abs() < 1.0);
    }

    #[test]
    fn scale_scales_linearly() {
        let px: Vec<u16> = (0..100).map(|i| (i * 3 % 50) as u16).collect();
        let mut fx = FeatureExtractor::new(100);
        let a = fx.features(&px, 1.0);
        let b = fx.features(&px, 2.0);
        for (x, y) in a.iter().zip(&b) {
            assert!((2.0 * x - y).abs() <= 1e-3 * y.abs().max(1.0));
        }
    }
}
