//! Scalar fields on the fine grid under the sensor, and the few operations the physics needs.

use rand::Rng;
use rand_distr::{Distribution, Normal, StandardNormal};

/// A row-major field of `rows x cols` cells of `cell_mm` mm.
#[derive(Clone, Debug)]
pub struct Field {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Cell size, mm.
    pub cell_mm: f64,
    /// Row-major values.
    pub v: Vec<f32>,
}

impl Field {
    /// A field of zeros.
    pub fn zeros(rows: usize, cols: usize, cell_mm: f64) -> Self {
        Self {
            rows,
            cols,
            cell_mm,
            v: vec![0.0; rows * cols],
        }
    }

    /// Centre of cell (r, c) in mm from the grid's top-left corner.
    pub fn pos(&self, r: usize, c: usize) -> (f64, f64) {
        (
            (r as f64 + 0.5) * self.cell_mm,
            (c as f64 + 0.5) * self.cell_mm,
        )
    }

    /// Gaussian blur with standard deviation `sigma_mm` (separable, edges clamped), using
    /// `scratch` (resized as needed) so a caller can reuse it.
    pub fn blur(&mut self, sigma_mm: f64, scratch: &mut Vec<f32>) {
        let s = sigma_mm / self.cell_mm;
        if s < 0.3 {
            return;
        }
        let radius = (3.0 * s).ceil() as isize;
        let kernel: Vec<f32> = (-radius..=radius)
            .map(|i| (-(i * i) as f64 / (2.0 * s * s)).exp() as f32)
            .collect();
        let norm: f32 = kernel.iter().sum();
        let (rows, cols) = (self.rows as isize, self.cols as isize);
        scratch.resize(self.v.len(), 0.0);
        for r in 0..rows {
            for c in 0..cols {
                let mut acc = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    let cc = (c + k as isize - radius).clamp(0, cols - 1);
                    acc += w * self.v[(r * cols + cc) as usize];
                }
                scratch[(r * cols + c) as usize] = acc / norm;
            }
        }
        for r in 0..rows {
            for c in 0..cols {
                let mut acc = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    let rr = (r + k as isize - radius).clamp(0, rows - 1);
                    acc += w * scratch[(rr * cols + c) as usize];
                }
                self.v[(r * cols + c) as usize] = acc / norm;
            }
        }
    }

    /// Smooth Gaussian random field with standard deviation `sd` and correlation length
    /// `corr_mm` (white noise, blurred, rescaled).
    pub fn random_smooth(
        rows: usize,
        cols: usize,
        cell_mm: f64,
        sd: f64,
        corr_mm: f64,
        rng: &mut impl Rng,
    ) -> Self {
        let mut f = Self::zeros(rows, cols, cell_mm);
        for x in f.v.iter_mut() {
            let n: f64 = StandardNormal.sample(rng);
            *x = n as f32;
        }
        let mut scratch = Vec::new();
        f.blur(corr_mm, &mut scratch);
        let m = f.v.iter().map(|&x| x as f64).sum::<f64>() / f.v.len() as f64;
        let var = f.v.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / f.v.len() as f64;
        let k = if var > 0.0 { sd / var.sqrt() } else { 0.0 };
        for x in f.v.iter_mut() {
            *x = ((*x as f64 - m) * k) as f32;
        }
        f
    }
}

/// A normal distribution; a negative or NaN deviation (a bad config value) counts as 0.
pub fn normal(mean: f64, sd: f64) -> Normal<f64> {
    let sd = if sd.is_finite() && sd > 0.0 { sd } else { 0.0 };
    let mean = if mean.is_finite() { mean } else { 0.0 };
    // Normal::new fails only for a negative or non-finite deviation, excluded just above.
    Normal::new(mean, sd).unwrap_or_else(|_| unreachable!("finite, non-negative deviation"))
}
