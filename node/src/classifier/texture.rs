//! Roughness: how bumpy an image's contact is, one number per image, and the per-class ranges
//! of it that `train --check-texture` keeps (an image whose roughness lies outside its best
//! class's range is unknown).
//!
//! Why a number beside the feature vector: the feature vector is the FFT magnitude of the
//! concatenated rows, which the footprint's outline dominates; PCA keeps the directions along
//! which the *known* terrains differ. A left-out terrain that is smoother than every known one
//! (planed wood among carpet, clay and grass) or whose grit only a sensel or two resolves (220
//! against 150 grit) lands among the known images in that space: no distance there finds it
//! (leave-one-class-out AUROC of our score and of a plain nearest neighbour both 0.27-0.67,
//! `presrs experiment open-set --seeds 10`). Its roughness does differ: on the simulator's
//! hopping stances wood reads 0.20-0.22, clay 0.27-0.30, carpet 0.32-0.36, grass 0.39-0.61 (60
//! stances each, sensor 1; sensor 3 within 0.01 of it), and each grit has its own.
//!
//! What it is worth where we did not make the data: nothing found, nothing lost. On the real
//! SpeedPP2D plantar-pressure maps the people differ in shape, not in roughness: a left-out
//! person was called unknown exactly as often with the check as without, and so were the next
//! run's known images, on every seed (docs/real-robot.md, "The texture check"). On a set
//! captured through the bus from short runs (`scripts/captured_set.sh`) it missed the sand
//! that texture cannot tell from clay and cost 1.4 points more of known images. Its benefit is
//! measured on the simulator alone, so it is opt-in.

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

/// Per class, the band of its images' roughness that lets `rate` of them out, widened by a
/// quarter of its width each side ([`super::train::widened_band`], as the load check's):
/// `per_class[k]` are class k's values (NaN ones are left out). A class without values
/// accepts any roughness.
pub fn ranges(per_class: Vec<Vec<f64>>, rate: f64) -> Vec<[f64; 2]> {
    per_class
        .into_iter()
        .map(|mut v| {
            v.retain(|x| x.is_finite());
            if v.is_empty() {
                return [f64::NEG_INFINITY, f64::INFINITY];
            }
            v.sort_by(f64::total_cmp);
            super::train::widened_band(&v, rate)
        })
        .collect()
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

    #[test]
    fn ranges_let_the_rate_out_widened_and_accept_anything_without_values() {
        let r = ranges(
            vec![(0..100).map(|i| i as f64).collect(), vec![f64::NAN]],
            0.02,
        );
        // 1 of 100 out each side: 1..=98, widened by 97 / 4.
        assert_eq!(r[0], [1.0 - 24.25, 98.0 + 24.25]);
        assert_eq!(r[1], [f64::NEG_INFINITY, f64::INFINITY]);
    }
}
