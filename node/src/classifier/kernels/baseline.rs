//! The portable projection's four rows in the vector instructions every CPU of its
//! architecture has (SSE2 on x86-64, NEON on aarch64; plain Rust elsewhere): no detection
//! needed, so `portable` calls them directly, and the AVX2 kernels build on `portable`.

/// Four dot products `rows[i] . c` (each row as long as `c`) with SSE2.
#[cfg(target_arch = "x86_64")]
pub(super) fn rows4(rows: [&[f32]; 4], c: &[f32]) -> [f32; 4] {
    use std::arch::x86_64::*;
    let n = c.len();
    let n8 = n - n % 8;
    let mut out = [0.0f32; 4];
    // SAFETY: SSE2 is part of every x86-64 CPU; each 4-lane load reads k..k+8 <= n8 <= n
    // elements of `c` or of a row, both n long.
    unsafe {
        let mut acc = [_mm_setzero_ps(); 8];
        let mut k = 0;
        while k < n8 {
            let c0 = _mm_loadu_ps(c.as_ptr().add(k));
            let c1 = _mm_loadu_ps(c.as_ptr().add(k + 4));
            for i in 0..4 {
                let p = rows[i].as_ptr().add(k);
                acc[2 * i] = _mm_add_ps(acc[2 * i], _mm_mul_ps(_mm_loadu_ps(p), c0));
                acc[2 * i + 1] = _mm_add_ps(acc[2 * i + 1], _mm_mul_ps(_mm_loadu_ps(p.add(4)), c1));
            }
            k += 8;
        }
        for (i, o) in out.iter_mut().enumerate() {
            let mut lanes = [0.0f32; 4];
            _mm_storeu_ps(lanes.as_mut_ptr(), _mm_add_ps(acc[2 * i], acc[2 * i + 1]));
            *o = lanes.iter().sum();
        }
    }
    for (i, o) in out.iter_mut().enumerate() {
        for (x, y) in rows[i][n8..].iter().zip(&c[n8..]) {
            *o += x * y;
        }
    }
    out
}

/// Four dot products `rows[i] . c` (each row as long as `c`) with NEON fused multiply-adds.
#[cfg(target_arch = "aarch64")]
pub(super) fn rows4(rows: [&[f32]; 4], c: &[f32]) -> [f32; 4] {
    use std::arch::aarch64::*;
    let n = c.len();
    let n8 = n - n % 8;
    let mut out = [0.0f32; 4];
    // SAFETY: NEON is part of every aarch64 CPU; each 4-lane load reads k..k+8 <= n8 <= n
    // elements of `c` or of a row, both n long.
    unsafe {
        let mut acc = [vdupq_n_f32(0.0); 8];
        let mut k = 0;
        while k < n8 {
            let c0 = vld1q_f32(c.as_ptr().add(k));
            let c1 = vld1q_f32(c.as_ptr().add(k + 4));
            for i in 0..4 {
                let p = rows[i].as_ptr().add(k);
                acc[2 * i] = vfmaq_f32(acc[2 * i], vld1q_f32(p), c0);
                acc[2 * i + 1] = vfmaq_f32(acc[2 * i + 1], vld1q_f32(p.add(4)), c1);
            }
            k += 8;
        }
        for (i, o) in out.iter_mut().enumerate() {
            *o = vaddvq_f32(vaddq_f32(acc[2 * i], acc[2 * i + 1]));
        }
    }
    for (i, o) in out.iter_mut().enumerate() {
        for (x, y) in rows[i][n8..].iter().zip(&c[n8..]) {
            *o += x * y;
        }
    }
    out
}
