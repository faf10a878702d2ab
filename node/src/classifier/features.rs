//! The feature vector of the paper's eqs. (1)-(3): rows concatenated (vec(I)), zero-padded to
//! N = the next power of two at or above the pixel count, the FFT magnitude |Y|, and its first
//! N/2 + 1 bins (the rest mirror them for a real input).

use std::sync::Arc;

use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

use super::Kernels;

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
///
/// The input is real, so the N-point transform is done as an N/2-point complex FFT of the
/// even/odd samples packed as real/imaginary parts, then split into the spectrum's first
/// N/2 + 1 bins (the standard "two real halves" identity): half the work of a complex N-point FFT
/// and the same numbers (a test compares with a direct DFT).
pub struct FeatureExtractor {
    n_pixels: usize,
    /// N, the zero-padded length.
    n: usize,
    fft: Arc<dyn Fft<f32>>,
    buf: Vec<Complex<f32>>,
    scratch: Vec<Complex<f32>>,
    /// e^{-2 pi i k / N} for k = 0..=N/2.
    twiddles: Vec<Complex<f32>>,
    avx2_fma: bool,
}

impl FeatureExtractor {
    /// An extractor for images of `n_pixels`, with the fastest kernels this CPU has.
    pub fn new(n_pixels: usize) -> Self {
        Self::with_kernels(n_pixels, Kernels::Native)
    }

    /// An extractor with the given kernels ([`Kernels::Portable`]: what an ARM computer runs).
    pub fn with_kernels(n_pixels: usize, kernels: Kernels) -> Self {
        // N >= 2 so that the half-length transform has at least one point.
        let n = fft_len(n_pixels).max(2);
        let half = n / 2;
        let fft = match kernels {
            Kernels::Native => FftPlanner::<f32>::new().plan_fft_forward(half),
            Kernels::Portable => portable_fft(half),
        };
        let scratch = vec![Complex::default(); fft.get_inplace_scratch_len()];
        let twiddles = (0..=half)
            .map(|k| {
                let a = -2.0 * std::f64::consts::PI * k as f64 / n as f64;
                Complex::new(a.cos() as f32, a.sin() as f32)
            })
            .collect();
        Self {
            n_pixels,
            n,
            fft,
            buf: vec![Complex::default(); half],
            scratch,
            twiddles,
            avx2_fma: kernels.avx2_fma(),
        }
    }

    /// Pixels of the images this extractor takes.
    pub fn n_pixels(&self) -> usize {
        self.n_pixels
    }

    /// Length of the feature vector (N/2 + 1).
    pub fn feature_len(&self) -> usize {
        self.n / 2 + 1
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
        let pairs = pixels.chunks_exact(2);
        let odd_tail = pairs.remainder().first().copied();
        let mut used = 0;
        for (b, p) in self.buf.iter_mut().zip(pairs) {
            *b = Complex::new(p[0] as f32 * scale, p[1] as f32 * scale);
            used += 1;
        }
        if let Some(p) = odd_tail {
            self.buf[used] = Complex::new(p as f32 * scale, 0.0);
            used += 1;
        }
        for b in &mut self.buf[used..] {
            *b = Complex::default();
        }
        self.fft
            .process_with_scratch(&mut self.buf, &mut self.scratch);
        // X[k] = E[k] + w^k O[k], with E = (Z[k] + conj Z[N/2-k]) / 2 the even samples' spectrum
        // and O = (Z[k] - conj Z[N/2-k]) / 2i the odd samples'; Z[N/2] = Z[0].
        let half = self.buf.len();
        let z0 = self.buf[0];
        // k = 0 and k = N/2 pair Z[0] with itself: X[0] = Re + Im, X[N/2] = Re - Im.
        out[0] = (z0.re + z0.im).abs();
        out[half] = (z0.re - z0.im).abs();
        split_spectrum(&self.buf, &self.twiddles, out, self.avx2_fma);
    }

    /// Convenience for tools: a fresh feature vector.
    pub fn features(&mut self, pixels: &[u16], scale: f32) -> Vec<f32> {
        let mut out = vec![0.0; self.feature_len()];
        self.extract(pixels, scale, &mut out);
        out
    }
}

/// rustfft's 128-bit planner: NEON on aarch64 (which `FftPlanner::new` picks there anyway),
/// SSE4.1 on x86-64 as its nearest equivalent, scalar where neither exists.
fn portable_fft(len: usize) -> Arc<dyn Fft<f32>> {
    #[cfg(target_arch = "x86_64")]
    if let Ok(mut p) = rustfft::FftPlannerSse::<f32>::new() {
        return p.plan_fft_forward(len);
    }
    #[cfg(target_arch = "aarch64")]
    if let Ok(mut p) = rustfft::FftPlannerNeon::<f32>::new() {
        return p.plan_fft_forward(len);
    }
    rustfft::FftPlannerScalar::<f32>::new().plan_fft_forward(len)
}

/// X[k] for 0 < k < N/2 from the half-length transform Z, as magnitudes into `out[1..N/2]`.
fn split_spectrum(z: &[Complex<f32>], twiddles: &[Complex<f32>], out: &mut [f32], avx2_fma: bool) {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        unsafe { split_spectrum_avx2(z, twiddles, out) };
        return;
    }
    split_spectrum_portable(z, twiddles, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn split_spectrum_avx2(z: &[Complex<f32>], twiddles: &[Complex<f32>], out: &mut [f32]) {
    split_spectrum_portable(z, twiddles, out);
}

#[inline(always)]
fn split_spectrum_portable(z: &[Complex<f32>], twiddles: &[Complex<f32>], out: &mut [f32]) {
    let half = z.len();
    // Iterators over Z[k] and Z[N/2-k] (no index arithmetic, no bounds checks), so that the
    // compiler vectorises the split.
    let lower = z[1..].iter();
    let upper = z[1..].iter().rev();
    for ((o, (zk, zm)), w) in out[1..half]
        .iter_mut()
        .zip(lower.zip(upper))
        .zip(&twiddles[1..half])
    {
        let zm = zm.conj();
        let e = (zk + zm) * 0.5;
        let d = (zk - zm) * 0.5;
        let odd = Complex::new(d.im, -d.re);
        // sqrt of norm_sqr, not `norm()`: that is libm `hypot`, several times slower here
        // and guarding an overflow that 8-bit pixel sums cannot reach.
        *o = (e + w * odd).norm_sqr().sqrt();
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
        // The foot's area, the paper's 10x10, an odd count and the degenerate single pixel.
        for n_px in [41 * 38, 40 * 40, 100, 7, 1] {
            check_against_dft(n_px);
        }
    }

    fn check_against_dft(n_px: usize) {
        let px: Vec<u16> = (0..n_px)
            .map(|i| ((i * 37 + (i / 38) * 11) % 256 + 1) as u16)
            .collect();
        let mut fx = FeatureExtractor::new(n_px);
        let f = fx.features(&px, 1.0);
        let n = fft_len(n_px).max(2);
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
        assert!(worst < 1e-4, "{n_px} pixels: relative error {worst}");
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
