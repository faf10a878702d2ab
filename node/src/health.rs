//! Sensor health from the stance history: which rows and columns of the skin are dead.
//!
//! The paper's repair filter (section 8) fills every all-zero line of each image. That also
//! fills lines that are legitimately empty: the rows between the stones of gravel, or the edge
//! of a small footprint. A dead line is different in that it stays at zero stance after stance
//! while the load around it changes. [`LineHealth`] therefore calls a line dead only after it
//! read zero *inside the footprint* in `k` stances in a row, and forgets it as soon as it
//! reads anything again.
//!
//! "Inside the footprint" means: a neighbour carries load, or loaded lines lie on both sides of
//! it. The second half matters at high damage: with half of the lines dead, dead lines come in
//! runs, and the middle of a run has no loaded neighbour.

use crate::classifier::repair;

/// Learns dead lines of an image (rows x cols, row-major) from a sequence of stances.
#[derive(Clone, Debug)]
pub struct LineHealth {
    rows: usize,
    cols: usize,
    row_runs: Vec<u32>,
    col_runs: Vec<u32>,
    dead_rows: Vec<bool>,
    dead_cols: Vec<bool>,
    /// Line sums of the image being observed (sized once, reused: `observe` allocates nothing).
    row_sums: Vec<u32>,
    col_sums: Vec<u32>,
}

impl LineHealth {
    /// Health of a `rows` x `cols` working image, all lines alive.
    pub fn new(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            row_runs: vec![0; rows],
            col_runs: vec![0; cols],
            dead_rows: vec![false; rows],
            dead_cols: vec![false; cols],
            row_sums: vec![0; rows],
            col_sums: vec![0; cols],
        }
    }

    /// (rows, cols) of the images this tracks.
    pub fn size(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }

    /// One stance's image: a line that reads zero inside the footprint is a suspect; `k`
    /// suspect stances in a row make it dead; any reading brings it back at once.
    pub fn observe(&mut self, img: &[u16], k: u32) {
        if img.len() != self.rows * self.cols || self.cols == 0 {
            return;
        }
        self.row_sums.fill(0);
        self.col_sums.fill(0);
        for (r, row) in img.chunks_exact(self.cols).enumerate() {
            let mut s = 0u32;
            for (cs, &v) in self.col_sums.iter_mut().zip(row) {
                *cs += v as u32;
                s += v as u32;
            }
            self.row_sums[r] = s;
        }
        observe_lines(&self.row_sums, &mut self.row_runs, &mut self.dead_rows, k);
        observe_lines(&self.col_sums, &mut self.col_runs, &mut self.dead_cols, k);
    }

    /// Rows taken for dead.
    pub fn dead_rows(&self) -> &[bool] {
        &self.dead_rows
    }

    /// Columns taken for dead.
    pub fn dead_cols(&self) -> &[bool] {
        &self.dead_cols
    }

    /// Any line taken for dead.
    pub fn any_dead(&self) -> bool {
        self.dead_rows.iter().chain(&self.dead_cols).any(|&d| d)
    }

    /// Damage in percent of the sensels (the paper's eq. 6) from the lines learnt dead.
    pub fn damage_pct(&self) -> f64 {
        let dr = self.dead_rows.iter().filter(|&&d| d).count();
        let dc = self.dead_cols.iter().filter(|&&d| d).count();
        repair::damage_percent(dr, dc, self.rows, self.cols)
    }

    /// Fills the lines learnt dead with the paper's rule (previous line; a leading dead line
    /// takes the next live one). Returns how many lines were filled.
    pub fn repair(&self, img: &mut [u16]) -> usize {
        if img.len() != self.rows * self.cols || !self.any_dead() {
            return 0;
        }
        repair::repair_lines(
            img,
            self.rows,
            self.cols,
            &self.dead_rows,
            &self.dead_cols,
            None,
        );
        self.dead_rows
            .iter()
            .chain(&self.dead_cols)
            .filter(|&&d| d)
            .count()
    }
}

/// Updates the runs and dead flags of one direction's lines from their sums.
fn observe_lines(sums: &[u32], runs: &mut [u32], dead: &mut [bool], k: u32) {
    let first = sums.iter().position(|&s| s > 0);
    let last = sums.iter().rposition(|&s| s > 0);
    for i in 0..sums.len() {
        if sums[i] > 0 {
            runs[i] = 0;
            dead[i] = false;
            continue;
        }
        let neighbour = (i > 0 && sums[i - 1] > 0) || sums.get(i + 1).is_some_and(|&s| s > 0);
        let inside = first.is_some_and(|f| f < i) && last.is_some_and(|l| l > i);
        if neighbour || inside {
            runs[i] = runs[i].saturating_add(1);
            if runs[i] >= k {
                dead[i] = true;
            }
        }
        // A zero line outside the footprint tells nothing either way: its run and flag stay.
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6x6 footprint covering the whole image, with the given rows and columns dead.
    fn image(dead_rows: &[usize], dead_cols: &[usize]) -> Vec<u16> {
        let mut img = vec![0u16; 36];
        for r in 0..6 {
            for c in 0..6 {
                if !dead_rows.contains(&r) && !dead_cols.contains(&c) {
                    img[r * 6 + c] = 10 + (r * 6 + c) as u16;
                }
            }
        }
        img
    }

    #[test]
    fn a_run_of_dead_lines_is_learnt_after_k_stances_and_forgotten_when_it_reads_again() {
        let mut h = LineHealth::new(6, 6);
        // Rows 2-4 are a run: row 3 has no loaded neighbour, only load on both sides.
        let img = image(&[2, 3, 4], &[0]);
        for _ in 0..2 {
            h.observe(&img, 3);
        }
        assert!(!h.any_dead(), "dead before k stances");
        h.observe(&img, 3);
        assert_eq!(h.dead_rows(), &[false, false, true, true, true, false]);
        assert_eq!(h.dead_cols(), &[true, false, false, false, false, false]);
        let pct = h.damage_pct();
        assert!((pct - repair::damage_percent(3, 1, 6, 6)).abs() < 1e-9);
        let mut fixed = img.clone();
        assert_eq!(h.repair(&mut fixed), 4);
        assert!(fixed.iter().all(|&p| p > 0), "{fixed:?}");
        // Row 3 comes back: forgotten at once.
        h.observe(&image(&[2, 4], &[0]), 3);
        assert_eq!(h.dead_rows(), &[false, false, true, false, true, false]);
    }

    #[test]
    fn lines_outside_the_footprint_and_changing_gaps_are_not_dead() {
        let mut h = LineHealth::new(6, 6);
        for s in 0..20 {
            // A footprint on rows 0-2 only (rows 4 and 5 lie beyond it), with a gap in a
            // different column each stance, like gravel.
            h.observe(&image(&[3, 4, 5], &[1 + s % 4]), 5);
        }
        assert_eq!(h.dead_rows()[4..], [false, false]);
        assert!(h.dead_cols().iter().all(|&d| !d), "{:?}", h.dead_cols());
    }
}
