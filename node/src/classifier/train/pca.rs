//! The principal axes of centred rows (images x features), from the smaller Gram matrix.
//!
//! PCA needs the leading right singular vectors of X. A stance set has a few hundred images and
//! 1,936 features; nalgebra's SVD, asked for V^T, rotates rows that long through every sweep,
//! and did so in three quarters of `train`'s time. The same axes come from the eigenvectors of
//! the n x n matrix X X^T: with `X X^T u = s^2 u`, the axis is `v = X^T u / s`. With more images
//! than features, the d x d matrix X^T X gives them directly. The axes and their order are the
//! SVD's (each up to its sign, which no distance sees); what squaring costs is precision in the
//! smallest singular values, below [`REL_EIGEN_FLOOR`] of the largest's square, which count as
//! zero (the rank): the paper keeps at most 52 axes, far above that floor.

use nalgebra::DMatrix;

/// An eigenvalue of the Gram matrix below this share of the largest is zero: the eigensolver's
/// rounding is about n * 2.2e-16 of the largest (1.3e-13 for 600 images), so the floor sits
/// above it; as a singular value, 1e-6 of the largest.
pub(crate) const REL_EIGEN_FLOOR: f64 = 1e-12;

/// The leading principal axes of `x` (rows already centred).
pub(crate) struct Axes {
    /// Up to the `k` asked for and the rank (the singular values above the floor), by
    /// decreasing singular value, each `x.ncols()` long, unit length.
    pub axes: Vec<Vec<f64>>,
}

/// The `k` leading axes of `x` (fewer when its rank is lower).
pub(crate) fn principal_axes(x: &DMatrix<f64>, k: usize) -> Axes {
    let (n, d) = x.shape();
    if n == 0 || d == 0 {
        return Axes { axes: Vec::new() };
    }
    let wide = n < d;
    let gram = if wide {
        x * x.transpose()
    } else {
        x.transpose() * x
    };
    let eig = gram.symmetric_eigen();
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let top = eig.eigenvalues[order[0]].max(0.0);
    let floor = top * REL_EIGEN_FLOOR;
    let rank = if top > 0.0 {
        order
            .iter()
            .filter(|&&i| eig.eigenvalues[i] > floor)
            .count()
    } else {
        0
    };
    let kept = &order[..k.min(rank)];
    let u = DMatrix::<f64>::from_fn(eig.eigenvectors.nrows(), kept.len(), |r, c| {
        eig.eigenvectors[(r, kept[c])]
    });
    // Wide: v = X^T u, one product for every axis (normalised below rather than divided by s).
    let v = if wide { x.tr_mul(&u) } else { u };
    let axes = v
        .column_iter()
        .map(|c| {
            let len = c.norm();
            c.iter().map(|a| a / len).collect()
        })
        .collect();
    Axes { axes }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The axes agree with the SVD's (up to sign) on wide and tall matrices, and the rank of
    /// rows that span fewer directions than they have is found.
    #[test]
    fn the_axes_are_the_svds_up_to_sign() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        for (n, d) in [(30, 200), (200, 30), (12, 12)] {
            let mut x = DMatrix::<f64>::from_fn(n, d, |_, j| rnd() * (1.0 + j as f64 % 7.0));
            let mean = x.row_mean();
            for mut r in x.row_iter_mut() {
                r -= &mean;
            }
            let svd = x.clone().svd(false, true);
            let v_t = svd.v_t.unwrap();
            let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
            order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
            let rank = principal_axes(&x, 1000).axes.len();
            assert_eq!(rank, n.min(d).min(n - 1), "{n}x{d}");
            let got = principal_axes(&x, 8);
            for (j, axis) in got.axes.iter().enumerate() {
                let dot: f64 = (0..d).map(|k| axis[k] * v_t[(order[j], k)]).sum();
                assert!((dot.abs() - 1.0).abs() < 1e-8, "{n}x{d} axis {j}: {dot}");
            }
        }
        // Rows in a 3-dimensional subspace of 50: rank 3, three axes however many are asked.
        let basis = DMatrix::<f64>::from_fn(3, 50, |_, _| rnd());
        let coef = DMatrix::<f64>::from_fn(20, 3, |_, _| rnd());
        let x = coef * basis;
        assert_eq!(principal_axes(&x, 10).axes.len(), 3);
        assert!(principal_axes(&DMatrix::zeros(4, 5), 3).axes.is_empty());
    }
}
