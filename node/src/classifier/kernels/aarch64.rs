//! aarch64 kernels: NEON (every aarch64 CPU) for the portable projection's four rows.

/// Four dot products `rows[i] . c` (each row as long as `c`) with NEON fused multiply-adds.
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
