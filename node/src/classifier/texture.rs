//! Roughness: how bumpy an image's contact is, one number per image. The texture check
//! ([`crate::unknown`], [`crate::unknown::Reason::Texture`]) holds it against a band per
//! terrain: the feature vector is dominated by the footprint's outline, so a terrain that
//! differs from a known one only in fine texture lands among the known images in feature
//! space, while its roughness differs (docs/decisions/unknown-texture-check.md).

/// The roughness of a working image (`rows` x `cols`, row-major): the root-mean-square
/// discrete Laplacian over the loaded interior sensels, divided by their mean load, so that
/// neither the load nor the sensor's gain moves it. NaN when no interior sensel is loaded.
///
/// One pass over the image, no allocation: it runs per stance beside the features.
pub fn roughness(work: &[u16], rows: usize, cols: usize) -> f64 {
    roughness_with(work, rows, cols, false)
}

/// [`roughness`] with the AVX2 kernel when `avx2_fma` says the CPU has it (the classifier's
/// [`super::Kernels`]); the same value either way (integer sums).
pub(super) fn roughness_with(work: &[u16], rows: usize, cols: usize, avx2_fma: bool) -> f64 {
    if rows < 3 || cols < 3 || work.len() < rows * cols {
        return f64::NAN;
    }
    let [e, n, load] = super::kernels::roughness_sums(work, rows, cols, avx2_fma);
    if n == 0 {
        return f64::NAN;
    }
    let n = n as f64;
    (e as f64 / n).sqrt() / (load as f64 / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roughness_is_zero_on_flat_contact_and_ignores_load_and_gain() {
        let flat = vec![100u16; 25];
        assert_eq!(roughness(&flat, 5, 5), 0.0);
        // A checkerboard: every interior Laplacian is +-4 (hi - lo).
        let board: Vec<u16> = (0..36)
            .map(|i| if (i / 6 + i % 6) % 2 == 0 { 120 } else { 80 })
            .collect();
        let r = roughness(&board, 6, 6);
        let doubled: Vec<u16> = board.iter().map(|v| v * 2).collect();
        assert!(r > 1.0, "{r}");
        assert!((roughness(&doubled, 6, 6) - r).abs() < 1e-12);
        // No load, or too small an image: no roughness.
        assert!(roughness(&[0; 25], 5, 5).is_nan());
        assert!(roughness(&[1; 4], 2, 2).is_nan());
        assert!(
            roughness(&[1; 4], 3, 3).is_nan(),
            "fewer pixels than rows x cols"
        );
    }

    #[test]
    fn the_avx2_kernel_gives_the_portable_value() {
        if !crate::classifier::Kernels::Native.avx2_fma() {
            return;
        }
        let img: Vec<u16> = (0..41 * 38u32)
            .map(|i| {
                if i % 7 == 0 {
                    0
                } else {
                    (i * 37 % 4001) as u16
                }
            })
            .collect();
        for (rows, cols) in [(41, 38), (3, 3), (38, 41)] {
            let a = roughness_with(&img, rows, cols, false);
            assert_eq!(
                a.to_bits(),
                roughness_with(&img, rows, cols, true).to_bits()
            );
            assert!(a.is_finite());
        }
    }
}
