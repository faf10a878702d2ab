//! The classifier's arithmetic kernels, one module per instruction set, chosen here and
//! nowhere else: each function below picks the AVX2/FMA (and F16C) kernel when the caller's
//! [`Kernels`](super::Kernels) says the CPU has them, else the portable one (SSE2 on x86-64,
//! NEON on aarch64, plain Rust elsewhere). The callers in [`super::pwe`] see one function per
//! operation.

mod baseline;
mod portable;
#[cfg(target_arch = "x86_64")]
mod x86_64;

pub(super) use portable::gram_inverse;

/// `W` in IEEE half precision when this CPU converts it in hardware (F16C), else nothing.
/// A weight of W (a unit vector's component) keeps 11 significant bits: the projection of a
/// feature vector moves by about 5e-4 of its length, far below the distances between samples.
/// Called only when the AVX2/FMA kernels run.
pub(super) fn half_matrix(w: &[f32]) -> Vec<u16> {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = w;
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("f16c") {
        let mut out = vec![0u16; w.len()];
        // SAFETY: the CPU supports the features the function was compiled for.
        unsafe { x86_64::to_half_f16c(w, &mut out) };
        return out;
    }
    Vec::new()
}

/// `q = W c` for the row-major PCA matrix `W` (h x n): the bulk of the per-image arithmetic
/// (52 x 1025 multiply-adds for the paper's sizes). `w16` is `W` in half precision, or empty;
/// `avx2_fma` says the CPU has both ([`Kernels::avx2_fma`](super::Kernels::avx2_fma)).
pub(super) fn project(w: &[f32], w16: &[u16], c: &[f32], q: &mut [f32], avx2_fma: bool) {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (w16, avx2_fma);
    #[cfg(target_arch = "x86_64")]
    if avx2_fma && !w16.is_empty() {
        // SAFETY: `w16` is only filled when the CPU has AVX2, FMA and F16C.
        unsafe { x86_64::project_f16c(w, w16, c, q) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        unsafe { x86_64::project_avx2(w, c, q) };
        return;
    }
    portable::project(w, c, q);
}

/// `q^T E q` for the symmetric matrix `E`, `q.len()` rows of `q.len()` (a multiple of 8: `q`
/// zero-padded past h), in f32; 0 for an empty `E`.
pub(super) fn quad_form(e: &[f32], q: &[f32], avx2_fma: bool) -> f64 {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        return unsafe { x86_64::quad_form_avx2(e, q) };
    }
    portable::quad_form(e, q)
}

/// The roughness's sums over a working image (`rows`, `cols` at least 3; see
/// [`super::texture::roughness`]): squared Laplacian over loaded sensels, their count, load.
pub(super) fn roughness_sums(work: &[u16], rows: usize, cols: usize, avx2_fma: bool) -> [u64; 3] {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        return unsafe { x86_64::roughness_sums_avx2(work, rows, cols) };
    }
    portable::roughness_sums(work, rows, cols)
}

/// A working image's load (the sum of its pixels) and area (pixels above zero): exact.
pub(super) fn load_area(work: &[u16], avx2_fma: bool) -> (u64, u32) {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        return unsafe { x86_64::load_area_avx2(work) };
    }
    portable::load_area(work)
}

/// `out = f - mean` and `|f - mean|^2` (in f64).
pub(super) fn centre(f: &[f32], mean: &[f32], out: &mut [f32], avx2_fma: bool) -> f64 {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        return unsafe { x86_64::centre_avx2(f, mean, out) };
    }
    portable::centre(f, mean, out)
}

/// `out[i] = |x_i - q|^2` for the stored samples `x_i`, each `q.len()` long (a multiple of 8,
/// zero-padded past h, so the padding adds nothing).
pub(super) fn sq_dists(samples: &[f32], q: &[f32], out: &mut [f64], avx2_fma: bool) {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2_fma;
    #[cfg(target_arch = "x86_64")]
    if avx2_fma {
        // SAFETY: the CPU supports the features the function was compiled for.
        unsafe { x86_64::sq_dists_avx2(samples, q, out) };
        return;
    }
    portable::sq_dists(samples, q, out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classifier::Kernels;
    use portable::half_to_f64;

    #[test]
    fn the_quadratic_form_is_q_e_q() {
        // h = 13 padded to 16; E symmetric, zero past h.
        let (h, n) = (13, 16);
        let mut e = vec![0.0f32; n * n];
        for a in 0..h {
            for b in 0..h {
                e[a * n + b] = ((a + b) % 5) as f32 * 1e-3 - 2e-3;
            }
        }
        let q: Vec<f32> = (0..n)
            .map(|i| if i < h { i as f32 - 6.0 } else { 0.0 })
            .collect();
        let mut want = 0.0f64;
        for a in 0..h {
            for b in 0..h {
                want += (q[a] * e[a * n + b] * q[b]) as f64;
            }
        }
        for avx2_fma in [false, Kernels::Native.avx2_fma()] {
            let got = quad_form(&e, &q, avx2_fma);
            assert!(
                (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                "{got} vs {want}"
            );
        }
        assert_eq!(quad_form(&[], &q, false), 0.0);
    }

    #[test]
    fn distances_are_exact_sums_of_squares() {
        // Two samples of h = 52 padded to 56; the padding must add nothing.
        let pad = |v: Vec<f32>| -> Vec<f32> { v.into_iter().chain([0.0; 4]).collect() };
        let a: Vec<f32> = (0..52).map(|i| i as f32 * 0.5).collect();
        let b: Vec<f32> = (0..52).map(|i| (i % 7) as f32).collect();
        let want: f32 = a.iter().zip(&b).map(|(x, y)| (x - y) * (x - y)).sum();
        let samples: Vec<f32> = pad(a.clone()).into_iter().chain(pad(b.clone())).collect();
        for avx2_fma in [false, Kernels::Native.avx2_fma()] {
            let mut d = [0.0f64; 2];
            sq_dists(&samples, &pad(b.clone()), &mut d, avx2_fma);
            assert!(
                (d[0] - want as f64).abs() <= 1e-3 * want as f64,
                "{d:?} vs {want}"
            );
            assert_eq!(d[1], 0.0);
        }
        // Seven rows of 1025: the four-row block, three single rows and a ragged tail.
        let n = 1025;
        let w: Vec<f32> = (0..7 * n)
            .map(|i| ((i * 7919) % 101) as f32 * 0.01 - 0.5)
            .collect();
        let c: Vec<f32> = (0..n).map(|i| ((i * 31) % 17) as f32 - 8.0).collect();
        for avx2_fma in [false, Kernels::Native.avx2_fma()] {
            let mut q = [0.0f32; 7];
            project(&w, &[], &c, &mut q, avx2_fma);
            for (j, qj) in q.iter().enumerate() {
                let want: f64 = (0..n).map(|k| w[j * n + k] as f64 * c[k] as f64).sum();
                assert!(
                    (*qj as f64 - want).abs() <= 1e-3 * want.abs().max(1.0),
                    "row {j}, avx2_fma {avx2_fma}: {qj} vs {want}"
                );
            }
        }
        // The half-precision copy: each weight within 2^-11 of its own magnitude, so each
        // product too; the sum is then within 2^-11 of the sum of |w c|.
        if Kernels::Native.avx2_fma() {
            let w16 = half_matrix(&w);
            let mut q16 = [0.0f32; 7];
            project(&w, &w16, &c, &mut q16, true);
            for (j, qj) in q16.iter().enumerate() {
                let want: f64 = (0..n).map(|k| w[j * n + k] as f64 * c[k] as f64).sum();
                let abs: f64 = (0..n)
                    .map(|k| (w[j * n + k] as f64 * c[k] as f64).abs())
                    .sum();
                assert!(
                    (*qj as f64 - want).abs() <= abs / 2048.0 + 1e-3,
                    "row {j}: {qj} vs {want}"
                );
            }
        }
    }

    #[test]
    fn load_and_area_are_exact_past_a_u32_block() {
        // 70,000 pixels at the top of u16: the sum overflows one u32 block, not two.
        let mut work = vec![u16::MAX; 70_000];
        work[3] = 0;
        work[69_999] = 0;
        let want_load: u64 = work.iter().map(|&p| p as u64).sum();
        for avx2_fma in [false, Kernels::Native.avx2_fma()] {
            assert_eq!(load_area(&work, avx2_fma), (want_load, 69_998));
            assert_eq!(load_area(&work[..1600], avx2_fma), (1599 * 65_535, 1599));
            assert_eq!(load_area(&[], avx2_fma), (0, 0));
        }
    }

    #[test]
    fn half_precision_decodes_exactly() {
        assert_eq!(half_to_f64(0x3c00), 1.0);
        assert_eq!(half_to_f64(0xc000), -2.0);
        assert_eq!(half_to_f64(0x7bff), 65504.0);
        assert_eq!(half_to_f64(0x0001), 2f64.powi(-24));
        assert_eq!(half_to_f64(0x3555), 0.333251953125);
        assert!(half_to_f64(0x7e00).is_nan());
        // The Gram inverse of orthonormal rows is the identity.
        let w = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        assert_eq!(gram_inverse(&w, &[], 2), vec![1.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn portable_rows_match_a_dot_product_for_every_row_count() {
        // 0 to 9 rows: no block, one block with 0-3 single rows, two blocks; n not a multiple of 8.
        let n = 37;
        for rows in 0..10 {
            let w: Vec<f32> = (0..rows * n).map(|i| (i % 13) as f32 - 6.0).collect();
            let c: Vec<f32> = (0..n).map(|i| (i % 5) as f32 * 0.25).collect();
            let mut q = vec![f32::NAN; rows];
            portable::project(&w, &c, &mut q);
            for (j, qj) in q.iter().enumerate() {
                // Small integers and quarters: every partial sum is exact in f32.
                let want: f32 = (0..n).map(|k| w[j * n + k] * c[k]).sum();
                assert_eq!(*qj, want, "{rows} rows, row {j}");
            }
        }
    }
}
