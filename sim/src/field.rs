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
        let (rows, cols) = (self.rows, self.cols);
        let r = radius;
        scratch.resize(self.v.len(), 0.0);
        // Each output sums its taps in kernel order, as a tap-by-tap loop per output would
        // (the same f32 result to the bit), but one tap at a time across a whole row, which
        // the compiler vectorises: 0.46 s -> 0.07 s of `presrs lab sim --log F --duration 20`
        // (perf), where the simulator spent most of its time once the contact solve was fast.
        for (src, out) in self
            .v
            .chunks_exact(cols)
            .zip(scratch.chunks_exact_mut(cols))
        {
            out.fill(0.0);
            for (k, &w) in kernel.iter().enumerate() {
                let off = k as isize - r;
                // Columns whose tap stays inside the row; the rest take the edge sensel.
                let lo = (-off).clamp(0, cols as isize) as usize;
                let hi = (cols as isize - off).clamp(lo as isize, cols as isize) as usize;
                for o in &mut out[..lo] {
                    *o += w * src[0];
                }
                if hi > lo {
                    let shifted = &src[(lo as isize + off) as usize..(hi as isize + off) as usize];
                    for (o, &x) in out[lo..hi].iter_mut().zip(shifted) {
                        *o += w * x;
                    }
                }
                for o in &mut out[hi..] {
                    *o += w * src[cols - 1];
                }
            }
            for o in out.iter_mut() {
                *o /= norm;
            }
        }
        for row in 0..rows {
            let out = &mut self.v[row * cols..(row + 1) * cols];
            out.fill(0.0);
            for (k, &w) in kernel.iter().enumerate() {
                let rr = (row as isize + k as isize - r).clamp(0, rows as isize - 1) as usize;
                for (o, &x) in out.iter_mut().zip(&scratch[rr * cols..(rr + 1) * cols]) {
                    *o += w * x;
                }
            }
            for o in out.iter_mut() {
                *o /= norm;
            }
        }
    }

    /// Adds `other` (a field on the same grid) cell by cell: one surface laid on another.
    pub fn add(&mut self, other: &Field) {
        debug_assert_eq!((self.rows, self.cols), (other.rows, other.cols));
        for (a, b) in self.v.iter_mut().zip(&other.v) {
            *a += b;
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// The blur as first written: per output, its taps in kernel order, edges clamped.
    fn blur_reference(f: &Field, sigma_mm: f64) -> Vec<f32> {
        let s = sigma_mm / f.cell_mm;
        let radius = (3.0 * s).ceil() as isize;
        let kernel: Vec<f32> = (-radius..=radius)
            .map(|i| (-(i * i) as f64 / (2.0 * s * s)).exp() as f32)
            .collect();
        let norm: f32 = kernel.iter().sum();
        let (rows, cols) = (f.rows as isize, f.cols as isize);
        let mut tmp = vec![0.0f32; f.v.len()];
        let mut out = vec![0.0f32; f.v.len()];
        for r in 0..rows {
            for c in 0..cols {
                let mut acc = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    let cc = (c + k as isize - radius).clamp(0, cols - 1);
                    acc += w * f.v[(r * cols + cc) as usize];
                }
                tmp[(r * cols + c) as usize] = acc / norm;
            }
        }
        for r in 0..rows {
            for c in 0..cols {
                let mut acc = 0.0;
                for (k, w) in kernel.iter().enumerate() {
                    let rr = (r + k as isize - radius).clamp(0, rows - 1);
                    acc += w * tmp[(rr * cols + c) as usize];
                }
                out[(r * cols + c) as usize] = acc / norm;
            }
        }
        out
    }

    #[test]
    fn the_row_wise_blur_equals_the_per_output_one_to_the_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // Kernels narrower and wider than the field, square and not.
        for (rows, cols, sigma) in [(132, 132, 1.2), (20, 7, 0.9), (5, 40, 3.0), (9, 9, 10.0)] {
            let mut f = Field::zeros(rows, cols, 0.33);
            for x in f.v.iter_mut() {
                *x = rng.random::<f32>() * 100.0 - 20.0;
            }
            let want = blur_reference(&f, sigma);
            f.blur(sigma, &mut Vec::new());
            assert!(
                f.v.iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{rows}x{cols}, sigma {sigma}"
            );
        }
    }
}
