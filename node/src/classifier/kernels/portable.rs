//! Kernels every CPU of the target runs: the AVX2 kernels' shapes in the baseline SIMD of
//! x86-64 (SSE2) and aarch64 (NEON) where it pays, plain Rust written so that the compiler
//! vectorises it elsewhere. The AVX2/FMA builds of `quad_form`, `centre` and `sq_dists` are
//! these functions compiled for AVX2 (see `x86_64.rs`).

#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
use super::baseline::rows4;

/// The projection with the target's baseline SIMD: the AVX2 kernel's shape (four rows of W per
/// pass over `c`, so that each load of `c` serves four rows; two 4-lane accumulators per row)
/// in SSE2 on x86-64 and NEON on aarch64, which every CPU of those targets has. Elsewhere,
/// one dot product per row.
///
/// Plain Rust over `[f32; 8]` lanes was tried first: LLVM's SLP vectoriser then packed the four
/// rows' lanes into one register (the reduction at the end is cheaper that way) and paid a
/// shuffle per load, 3x slower than these loops (measured with `cargo bench --bench classify`).
pub(crate) fn project(w: &[f32], c: &[f32], q: &mut [f32]) {
    let n = c.len();
    let full = q.len() - q.len() % 4;
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    for (j4, q4) in q[..full].chunks_exact_mut(4).enumerate() {
        let j = 4 * j4;
        let rows: [&[f32]; 4] = std::array::from_fn(|i| &w[(j + i) * n..(j + i + 1) * n]);
        let sums = rows4(rows, c);
        q4.copy_from_slice(&sums);
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let full = 0;
    for (jj, qj) in q.iter_mut().enumerate().skip(full) {
        *qj = dot(&w[jj * n..(jj + 1) * n], c);
    }
}

#[inline(always)]
pub(crate) fn quad_form(e: &[f32], q: &[f32]) -> f64 {
    let n = q.len();
    if e.len() != n * n || !n.is_multiple_of(8) {
        return 0.0;
    }
    // E q as the sum of E's rows scaled by q's entries (E is symmetric), 8 columns at a time:
    // one accumulator register and no reduction per row. (A dot product per row, 52 of them
    // each with its own reduction, took 0.3 us of a 5.7 us decision: `perf record` on
    // `cargo bench --bench classify`.)
    let mut s = 0.0f64;
    for b in (0..n).step_by(8) {
        let mut acc = [0.0f32; 8];
        for (row, &qi) in e.chunks_exact(n).zip(q) {
            let r = &row[b..b + 8];
            for l in 0..8 {
                acc[l] += qi * r[l];
            }
        }
        for l in 0..8 {
            s += (acc[l] * q[b + l]) as f64;
        }
    }
    s
}

/// `centre`: four independent lanes so that the compiler vectorises it.
#[inline(always)]
pub(crate) fn centre(f: &[f32], mean: &[f32], out: &mut [f32]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (cf, cm, co) = (
        f.chunks_exact(4),
        mean.chunks_exact(4),
        out.chunks_exact_mut(4),
    );
    let (rf, rm) = (cf.remainder(), cm.remainder());
    for ((x, y), o) in cf.zip(cm).zip(co) {
        for i in 0..4 {
            o[i] = x[i] - y[i];
            acc[i] += o[i] as f64 * o[i] as f64;
        }
    }
    let mut s: f64 = acc.iter().sum();
    let done = f.len() - rf.len();
    for (i, (x, y)) in rf.iter().zip(rm).enumerate() {
        let t = x - y;
        out[done + i] = t;
        s += t as f64 * t as f64;
    }
    s
}

/// Load and area of a working image, in u32 lanes over blocks that cannot overflow them
/// (65,536 pixels of at most 65,535), which vectorise (docs/decisions/node-wake.md, "Third stop").
#[inline(always)]
pub(crate) fn load_area(work: &[u16]) -> (u64, u32) {
    let (mut load, mut area) = (0u64, 0u32);
    for block in work.chunks(1 << 16) {
        let (mut l, mut a) = (0u32, 0u32);
        for &p in block {
            l += p as u32;
            a += (p > 0) as u32;
        }
        load += l as u64;
        area += a;
    }
    (load, area)
}

#[inline(always)]
pub(crate) fn sq_dists(samples: &[f32], q: &[f32], out: &mut [f64]) {
    if q.is_empty() {
        out.fill(0.0);
        return;
    }
    for (o, x) in out.iter_mut().zip(samples.chunks_exact(q.len())) {
        // Eight lanes per chunk: the compiler keeps `acc` in one vector register.
        let mut acc = [0.0f32; 8];
        for (xc, qc) in x.chunks_exact(8).zip(q.chunks_exact(8)) {
            for i in 0..8 {
                let t = xc[i] - qc[i];
                acc[i] += t * t;
            }
        }
        *o = acc.iter().sum::<f32>() as f64;
    }
}

#[inline(always)]
pub(crate) fn dot(a: &[f32], b: &[f32]) -> f32 {
    // Sixteen independent accumulators let the compiler vectorise the reduction (two vectors
    // of eight with AVX, four of four with SSE) without a dependency chain on one register.
    let mut acc = [0.0f32; 16];
    let ca = a.chunks_exact(16);
    let cb = b.chunks_exact(16);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..16 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s: f32 = acc.iter().sum();
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// `(W W^T)^-1` (h x h, row-major) for the rows `W` the projection runs with: the half-precision
/// copy when there is one (`w16`), else `w`. The identity if it cannot be inverted.
pub(crate) fn gram_inverse(w: &[f32], w16: &[u16], h: usize) -> Vec<f64> {
    if h == 0 || !w.len().is_multiple_of(h) {
        return Vec::new();
    }
    let n = w.len() / h;
    // Decoded once: decoding per product made building a classifier half of `train`'s time
    // (h^2 n / 2 decodes, each with a power of two).
    let rows: Vec<f64> = if w16.is_empty() {
        w.iter().map(|&v| v as f64).collect()
    } else {
        w16.iter().map(|&x| half_to_f64(x)).collect()
    };
    let mut g = nalgebra::DMatrix::<f64>::zeros(h, h);
    for a in 0..h {
        let ra = &rows[a * n..(a + 1) * n];
        for b in a..h {
            let rb = &rows[b * n..(b + 1) * n];
            let v: f64 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
            g[(a, b)] = v;
            g[(b, a)] = v;
        }
    }
    let inv = g
        .try_inverse()
        .unwrap_or_else(|| nalgebra::DMatrix::identity(h, h));
    let mut out = vec![0.0; h * h];
    for a in 0..h {
        for b in 0..h {
            out[a * h + b] = inv[(a, b)];
        }
    }
    out
}

/// An IEEE half-precision number's value (the weights' f16 copy, decoded exactly).
pub(crate) fn half_to_f64(x: u16) -> f64 {
    let sign = if x & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((x >> 10) & 0x1f) as i32;
    let frac = (x & 0x3ff) as f64;
    // 2^p built from its bits (exact, as powi is, without a libgcc call).
    let pow2 = |p: i32| f64::from_bits(((p + 1023) as u64) << 52);
    match exp {
        0 => sign * frac * pow2(-24),
        31 if frac == 0.0 => sign * f64::INFINITY,
        31 => f64::NAN,
        e => sign * (1.0 + frac / 1024.0) * pow2(e - 15),
    }
}

/// Over the interior sensels of a `rows` x `cols` image (at least 3 x 3): the sum of the
/// squared discrete Laplacian over the loaded ones, their count, and the load of all of them
/// ([`super::super::texture::roughness`]).
///
/// Integers, exact and branch-free (a 16-bit Laplacian is at most 4 * 65535, its square below
/// 2^36, a sum of 2^20 of them below 2^56), so that the baseline and the AVX2 build agree to
/// the bit, and faster than floats (docs/decisions/figures-behind-comments.md).
#[inline(always)]
pub(super) fn roughness_sums(work: &[u16], rows: usize, cols: usize) -> [u64; 3] {
    let (mut e, mut n, mut load) = (0u64, 0u64, 0u64);
    let m = cols - 2;
    for r in 1..rows - 1 {
        let row = &work[r * cols..(r + 1) * cols];
        let (left, mid, right) = (&row[..m], &row[1..m + 1], &row[2..m + 2]);
        let up = &work[(r - 1) * cols + 1..][..m];
        let down = &work[(r + 1) * cols + 1..][..m];
        for i in 0..m {
            let p = mid[i] as i32;
            let lap = 4 * p - up[i] as i32 - down[i] as i32 - left[i] as i32 - right[i] as i32;
            let a = lap.unsigned_abs() as u64;
            // All ones where the sensel is loaded: a mask, not a branch.
            let on = 0u64.wrapping_sub((p != 0) as u64);
            e += (a * a) & on;
            n += on & 1;
            load += p as u64;
        }
    }
    [e, n, load]
}
