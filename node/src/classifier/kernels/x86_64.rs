//! x86-64 kernels: AVX2 with FMA (and F16C for the half-precision weights), run only when
//! the CPU has them (SSE2, which every x86-64 CPU has, is in `baseline`).

use super::portable;

#[target_feature(enable = "avx,f16c")]
pub(super) fn to_half_f16c(w: &[f32], out: &mut [u16]) {
    use std::arch::x86_64::*;
    for (src, dst) in w.chunks_exact(8).zip(out.chunks_exact_mut(8)) {
        // SAFETY: both chunks hold eight elements; unaligned loads and stores are allowed.
        unsafe {
            let h = _mm256_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(_mm256_loadu_ps(src.as_ptr()));
            _mm_storeu_si128(dst.as_mut_ptr() as *mut __m128i, h);
        }
    }
    let done = w.len() - w.len() % 8;
    let mut tail = [0.0f32; 8];
    tail[..w.len() - done].copy_from_slice(&w[done..]);
    let mut half = [0u16; 8];
    // SAFETY: as above, on local arrays of eight.
    unsafe {
        let h = _mm256_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(_mm256_loadu_ps(tail.as_ptr()));
        _mm_storeu_si128(half.as_mut_ptr() as *mut __m128i, h);
    }
    out[done..].copy_from_slice(&half[..w.len() - done]);
}

/// The sum of an AVX vector's eight lanes.
#[target_feature(enable = "avx")]
pub(super) fn hsum(v: std::arch::x86_64::__m256) -> f32 {
    let mut lanes = [0.0f32; 8];
    // SAFETY: `lanes` holds eight f32; an unaligned store is allowed.
    unsafe { std::arch::x86_64::_mm256_storeu_ps(lanes.as_mut_ptr(), v) };
    lanes.iter().sum()
}

/// AVX2 + FMA: four rows of W at a time, two 8-lane accumulators each. Eight independent FMA
/// chains hide the FMA latency (the compiler's own vectorisation kept two and was latency-bound),
/// and each load of `c` serves four rows.
#[target_feature(enable = "avx2,fma")]
pub(super) fn project_avx2(w: &[f32], c: &[f32], q: &mut [f32]) {
    use std::arch::x86_64::*;
    let n = c.len();
    let n16 = n - n % 16;
    let rows = q.len();
    let mut j = 0;
    while j + 4 <= rows {
        let r: [&[f32]; 4] = std::array::from_fn(|i| &w[(j + i) * n..(j + i + 1) * n]);
        let mut acc = [_mm256_setzero_ps(); 8];
        let mut k = 0;
        while k < n16 {
            // SAFETY: k + 16 <= n16 <= n = each slice's length, so every 8-lane load is in bounds.
            unsafe {
                let c0 = _mm256_loadu_ps(c.as_ptr().add(k));
                let c1 = _mm256_loadu_ps(c.as_ptr().add(k + 8));
                for i in 0..4 {
                    let p = r[i].as_ptr().add(k);
                    acc[2 * i] = _mm256_fmadd_ps(_mm256_loadu_ps(p), c0, acc[2 * i]);
                    acc[2 * i + 1] = _mm256_fmadd_ps(_mm256_loadu_ps(p.add(8)), c1, acc[2 * i + 1]);
                }
            }
            k += 16;
        }
        for i in 0..4 {
            let mut s = hsum(_mm256_add_ps(acc[2 * i], acc[2 * i + 1]));
            for kk in n16..n {
                s += r[i][kk] * c[kk];
            }
            q[j + i] = s;
        }
        j += 4;
    }
    for (jj, qj) in q.iter_mut().enumerate().skip(j) {
        *qj = portable::dot(&w[jj * n..(jj + 1) * n], c);
    }
}

/// [`project_avx2`] reading the half-precision copy of W; the last `n % 16` columns come
/// from the f32 W.
#[target_feature(enable = "avx2,fma,f16c")]
pub(super) fn project_f16c(w: &[f32], w16: &[u16], c: &[f32], q: &mut [f32]) {
    use std::arch::x86_64::*;
    let n = c.len();
    let n16 = n - n % 16;
    let rows = q.len();
    let mut j = 0;
    while j < rows {
        let m = (rows - j).min(4);
        let r: [&[u16]; 4] = std::array::from_fn(|i| {
            let jj = j + i.min(m - 1);
            &w16[jj * n..(jj + 1) * n]
        });
        let mut acc = [_mm256_setzero_ps(); 8];
        let mut k = 0;
        while k < n16 {
            // SAFETY: k + 16 <= n16 <= n = each slice's length, so every 8-lane load is in bounds.
            unsafe {
                let c0 = _mm256_loadu_ps(c.as_ptr().add(k));
                let c1 = _mm256_loadu_ps(c.as_ptr().add(k + 8));
                for i in 0..4 {
                    let p = r[i].as_ptr().add(k) as *const __m128i;
                    let w0 = _mm256_cvtph_ps(_mm_loadu_si128(p));
                    let w1 = _mm256_cvtph_ps(_mm_loadu_si128(p.add(1)));
                    acc[2 * i] = _mm256_fmadd_ps(w0, c0, acc[2 * i]);
                    acc[2 * i + 1] = _mm256_fmadd_ps(w1, c1, acc[2 * i + 1]);
                }
            }
            k += 16;
        }
        for i in 0..m {
            let mut s = hsum(_mm256_add_ps(acc[2 * i], acc[2 * i + 1]));
            for kk in n16..n {
                s += w[(j + i) * n + kk] * c[kk];
            }
            q[j + i] = s;
        }
        j += m;
    }
}

/// [`portable::quad_form`] compiled for AVX2/FMA: the compiler's own 8-lane code (measured with
/// `cargo bench --bench classify`: this and [`portable::centre`] in AVX2 took the decision with the
/// novelty score from 5.89 to 5.61 us, against 4.80 without it).
#[target_feature(enable = "avx2,fma")]
pub(super) fn quad_form_avx2(e: &[f32], q: &[f32]) -> f64 {
    portable::quad_form(e, q)
}

#[target_feature(enable = "avx2,fma")]
pub(super) fn roughness_sums_avx2(work: &[u16], rows: usize, cols: usize) -> [u64; 3] {
    portable::roughness_sums(work, rows, cols)
}

#[target_feature(enable = "avx2,fma")]
pub(super) fn centre_avx2(f: &[f32], mean: &[f32], out: &mut [f32]) -> f64 {
    portable::centre(f, mean, out)
}

#[target_feature(enable = "avx2,fma")]
pub(super) fn sq_dists_avx2(samples: &[f32], q: &[f32], out: &mut [f64]) {
    portable::sq_dists(samples, q, out);
}

#[target_feature(enable = "avx2,fma")]
pub(super) fn load_area_avx2(work: &[u16]) -> (u64, u32) {
    portable::load_area(work)
}
