//! Sensor damage and the repair filter of section 8.
//!
//! Fatigue tears a whole row or column trace; the acquisition reads it as zeros. The paper's
//! repair filter scans rows top to bottom and replaces each dead row with the previous (live or
//! already repaired) row, then does the same for columns left to right; a leading dead line
//! takes the next live one. It restores the image's intensity, and with it the magnitude of the
//! feature vector's spikes.

use rand::Rng;
use rand::seq::SliceRandom;

use super::image::PressureImage;

/// Sensor damage in percent, paper eq. (6).
pub fn damage_percent(dead_rows: usize, dead_cols: usize, rows: usize, cols: usize) -> f64 {
    if rows == 0 || cols == 0 {
        return 0.0;
    }
    let (dr, dc, nr, nc) = (dead_rows as f64, dead_cols as f64, rows as f64, cols as f64);
    (dr * nc + dc * nr - dr * dc) / (nr * nc) * 100.0
}

/// Marks the rows and columns that read zero across the whole line (sensels outside the sensor
/// ignored; a line made only of outside sensels is never dead). Writes into the caller's
/// buffers, so the classifier's hot path allocates nothing. Returns the number of lines marked.
pub fn find_zero_lines(
    pixels: &[u16],
    rows: usize,
    cols: usize,
    outside: Option<&[bool]>,
    dead_rows: &mut [bool],
    dead_cols: &mut [bool],
) -> usize {
    let inside = |i: usize| !outside.is_some_and(|m| m[i]);
    // First: a line is a candidate when it has at least one sensel inside the sensor.
    let candidate = outside.is_none();
    dead_rows.fill(candidate);
    dead_cols.fill(candidate);
    if !candidate {
        for i in (0..rows * cols).filter(|&i| inside(i)) {
            dead_rows[i / cols] = true;
            dead_cols[i % cols] = true;
        }
    }
    // Then: any load inside the sensor makes its row and column live. Row by row, with no
    // division per pixel (that made this scan cost as much as the FFT).
    for (r, row) in pixels[..rows * cols].chunks_exact(cols.max(1)).enumerate() {
        let mut row_live = false;
        match outside {
            None => {
                for (d, &p) in dead_cols.iter_mut().zip(row) {
                    *d &= p == 0;
                    row_live |= p != 0;
                }
            }
            Some(m) => {
                let mrow = &m[r * cols..(r + 1) * cols];
                for ((d, &p), &out) in dead_cols.iter_mut().zip(row).zip(mrow) {
                    let live = p != 0 && !out;
                    *d &= !live;
                    row_live |= live;
                }
            }
        }
        if row_live {
            dead_rows[r] = false;
        }
    }
    dead_rows
        .iter()
        .chain(dead_cols.iter())
        .filter(|d| **d)
        .count()
}

/// [`find_zero_lines`] into fresh vectors: (dead rows, dead columns).
pub fn zero_lines(img: &PressureImage) -> (Vec<bool>, Vec<bool>) {
    let mut rows = vec![false; img.rows];
    let mut cols = vec![false; img.cols];
    find_zero_lines(
        &img.pixels,
        img.rows,
        img.cols,
        img.outside.as_deref(),
        &mut rows,
        &mut cols,
    );
    (rows, cols)
}

/// Fills the given dead rows, then dead columns, in place (pixels and outside-mask aware).
/// Returns false when every row or every column is dead (nothing to copy from).
pub fn repair_lines(
    pixels: &mut [u16],
    rows: usize,
    cols: usize,
    dead_rows: &[bool],
    dead_cols: &[bool],
    outside: Option<&[bool]>,
) -> bool {
    let mut ok = true;
    // Rows, top to bottom.
    if let Some(first_live) = dead_rows.iter().position(|d| !d) {
        for r in (0..rows).filter(|&r| dead_rows[r]) {
            let src = if r < first_live { first_live } else { r - 1 };
            for c in 0..cols {
                let (d, s) = (r * cols + c, src * cols + c);
                if !outside.is_some_and(|m| m[d]) {
                    pixels[d] = pixels[s];
                }
            }
        }
    } else if rows > 0 {
        ok = false;
    }
    // Columns, left to right.
    if let Some(first_live) = dead_cols.iter().position(|d| !d) {
        for c in (0..cols).filter(|&c| dead_cols[c]) {
            let src = if c < first_live { first_live } else { c - 1 };
            for r in 0..rows {
                let (d, s) = (r * cols + c, r * cols + src);
                if !outside.is_some_and(|m| m[d]) {
                    pixels[d] = pixels[s];
                }
            }
        }
    } else if cols > 0 {
        ok = false;
    }
    ok
}

/// The paper's per-image filter: every all-zero line is taken for dead and filled.
/// Returns the number of (rows, columns) filled.
pub fn repair(img: &mut PressureImage) -> (usize, usize) {
    let (dr, dc) = zero_lines(img);
    let n = (
        dr.iter().filter(|d| **d).count(),
        dc.iter().filter(|d| **d).count(),
    );
    let (rows, cols) = (img.rows, img.cols);
    repair_lines(
        &mut img.pixels,
        rows,
        cols,
        &dr,
        &dc,
        img.outside.as_deref(),
    );
    n
}

/// Simulated fatigue damage: whole random rows and columns set to zero until eq. (6) reaches
/// `target_pct`. Returns the damage actually reached (the first value at or above the target).
pub fn damage(img: &mut PressureImage, target_pct: f64, rng: &mut impl Rng) -> f64 {
    let mut lines: Vec<(bool, usize)> = (0..img.rows)
        .map(|r| (true, r))
        .chain((0..img.cols).map(|c| (false, c)))
        .collect();
    lines.shuffle(rng);
    let (mut dr, mut dc) = (0, 0);
    let mut pct = 0.0;
    for (is_row, i) in lines {
        if pct >= target_pct {
            break;
        }
        if is_row {
            for c in 0..img.cols {
                img.pixels[i * img.cols + c] = 0;
            }
            dr += 1;
        } else {
            for r in 0..img.rows {
                img.pixels[r * img.cols + i] = 0;
            }
            dc += 1;
        }
        pct = damage_percent(dr, dc, img.rows, img.cols);
    }
    pct
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn eq6_matches_the_paper() {
        // One dead row and two dead columns on the 41x38 foot image: ~7 %.
        let d = damage_percent(1, 2, 41, 38);
        assert!((d - 7.5).abs() < 0.1, "{d}");
        assert_eq!(damage_percent(41, 0, 41, 38), 100.0);
    }

    #[test]
    fn repair_copies_previous_and_leading_takes_next() {
        // 4x3, row 0 and row 2 dead, column 1 dead.
        let mut img = PressureImage::new(4, 3, 8, vec![0, 0, 0, 4, 0, 6, 0, 0, 0, 10, 0, 12]);
        let (r, c) = repair(&mut img);
        assert_eq!((r, c), (2, 1));
        // rows: row0 <- row1 (first live), row2 <- row1; then col1 <- col0.
        assert_eq!(img.pixels, vec![4, 4, 6, 4, 4, 6, 4, 4, 6, 10, 10, 12]);
    }

    #[test]
    fn repair_leaves_live_pixels_and_outside_alone() {
        let mut img = PressureImage::new(3, 3, 8, vec![1, 2, 3, 0, 0, 0, 7, 8, 9]);
        img.outside = Some(vec![
            false, false, false, true, false, false, false, false, false,
        ]);
        repair(&mut img);
        assert_eq!(img.pixels, vec![1, 2, 3, 0, 2, 3, 7, 8, 9]);
    }

    #[test]
    fn damage_reaches_the_target() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let mut img = PressureImage::new(41, 38, 8, vec![9; 41 * 38]);
        let d = damage(&mut img, 50.0, &mut rng);
        assert!((50.0..56.0).contains(&d), "{d}");
        let (dr, dc) = zero_lines(&img);
        let got = damage_percent(
            dr.iter().filter(|x| **x).count(),
            dc.iter().filter(|x| **x).count(),
            41,
            38,
        );
        assert!((got - d).abs() < 1e-9);
        let zeros = img.pixels.iter().filter(|p| **p == 0).count() as f64 / (41.0 * 38.0) * 100.0;
        assert!((zeros - d).abs() < 1e-9);
    }
}
