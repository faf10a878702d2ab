//! Sensor health from the stance history: which rows and columns of the skin are dead.
//!
//! The paper's repair filter (section 8) fills every all-zero line of each image. That also
//! fills lines that are legitimately empty: the rows between the stones of gravel, or the edge
//! of a small footprint. A dead line is different in that it stays at zero stance after stance
//! while the load around it changes. [`LineHealth`] therefore calls a line dead only after it
//! read zero *inside the footprint* in `k` stances in a row, and forgets it as soon as it
//! reads anything again.
//!
//! "Inside the footprint" means two things at once:
//! - in this image, a neighbour carries load, or loaded lines lie on both sides of it (the
//!   second half matters at high damage: with half of the lines dead, dead lines come in runs,
//!   and the middle of a run has no loaded neighbour);
//! - over the stances, the line carried load in at least [`FOOTPRINT_SHARE`] of them: the
//!   model's training images (a healthy sensor's footprint, [`LineHealth::with_footprint`])
//!   and the stances seen since.
//!
//! Why the second: a footprint that does not fill the array has lines that read zero in every
//! stance beside loaded ones (its edge, a foot's arch), and without it those were taken for
//! dead. Measured on real plantar-pressure time series (the `jiku-data` package's SpeedPP2DS,
//! 10 people, 600 stances, sent as a foot's CAN traffic by `scripts/speedpp2d_stream.py` and
//! read by `presrs capture` and `presrs node --replay`): without it a healthy sensor showed dead
//! lines in 451-570 of 600 captured stances (up to 25% damage) and the node refitted its model
//! 53 times in 150 stances; with it, 0 (share 0.8; 0.5 left 1-29 stances with a dead line, in a
//! replica of the rule over the captured images). On the
//! simulator's foot, whose footprint fills the working image, every line carries load in
//! 99.4-100% of the training images, so nothing there changes. The cost: a line dead since
//! before the model was trained, or (without a model, as in `presrs capture`) since the first
//! stance, is never learned; the model was trained with it dead, or the set captured so.

use crate::classifier::repair;

/// The least share of stances (training images included) in which a line carried load for it
/// to be one that can die (see the module's docs; measured there).
pub const FOOTPRINT_SHARE: f64 = 0.8;

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
    /// Per line, the stances (training images included) in which it carried load, and the
    /// stances in all: the footprint.
    row_loaded: Vec<u32>,
    col_loaded: Vec<u32>,
    stances: u32,
    /// Every line is taken to lie in the footprint (see [`LineHealth::with_full_footprint`]).
    full: bool,
}

impl LineHealth {
    /// Health of a `rows` x `cols` working image, all lines alive; the footprint is learned
    /// from the stances it observes.
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
            row_loaded: vec![0; rows],
            col_loaded: vec![0; cols],
            stances: 0,
            full: false,
        }
    }

    /// The health a node keeps for `model`'s working images: the footprint of the model's
    /// training images, or every line for a model file without them.
    pub fn for_model(model: &crate::classifier::Model) -> Self {
        let (rows, cols) = model.work_size().unwrap_or((1, 1));
        let h = Self::new(rows, cols);
        match &model.images {
            Some(images) => h.with_footprint(images.pixels.iter().map(Vec::as_slice)),
            None => h.with_full_footprint(),
        }
    }

    /// Every line taken to lie in the footprint, as before the footprint was learned: for a
    /// model file without its training images (an older `presrs train`), whose node would
    /// otherwise never learn a line dead since its first stance (measured, 50% damage from the
    /// start on the simulated foot: 31 of 76 steps right with it, 0 without).
    pub fn with_full_footprint(mut self) -> Self {
        self.full = true;
        self
    }

    /// The footprint of a healthy sensor from its images (a model's training images, in the
    /// working image's size; others are passed over): a line loaded in them can be learned
    /// dead from the first stance on.
    pub fn with_footprint<'a>(mut self, images: impl IntoIterator<Item = &'a [u16]>) -> Self {
        for img in images {
            if self.line_sums(img) {
                self.tally();
            }
        }
        self
    }

    /// Sums each line of `img` into the buffers; false for an image of another size.
    fn line_sums(&mut self, img: &[u16]) -> bool {
        if img.len() != self.rows * self.cols || self.cols == 0 {
            return false;
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
        true
    }

    /// Counts the summed image into the footprint.
    fn tally(&mut self) {
        for (n, &s) in self.row_loaded.iter_mut().zip(&self.row_sums) {
            *n = n.saturating_add(u32::from(s > 0));
        }
        for (n, &s) in self.col_loaded.iter_mut().zip(&self.col_sums) {
            *n = n.saturating_add(u32::from(s > 0));
        }
        self.stances = self.stances.saturating_add(1);
    }

    /// (rows, cols) of the images this tracks.
    pub fn size(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }

    /// One stance's image: a line that reads zero inside the footprint is a suspect; `k`
    /// suspect stances in a row make it dead; any reading brings it back at once.
    pub fn observe(&mut self, img: &[u16], k: u32) {
        if !self.line_sums(img) {
            return;
        }
        let footprint = Footprint {
            full: self.full,
            stances: self.stances,
            loaded: &self.row_loaded,
        };
        observe_lines(
            &self.row_sums,
            footprint,
            &mut self.row_runs,
            &mut self.dead_rows,
            k,
        );
        let footprint = Footprint {
            full: self.full,
            stances: self.stances,
            loaded: &self.col_loaded,
        };
        observe_lines(
            &self.col_sums,
            footprint,
            &mut self.col_runs,
            &mut self.dead_cols,
            k,
        );
        self.tally();
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

/// One direction's lines over the stances before this one.
#[derive(Clone, Copy)]
struct Footprint<'a> {
    full: bool,
    stances: u32,
    loaded: &'a [u32],
}

impl Footprint<'_> {
    /// Line `i` carried load in at least [`FOOTPRINT_SHARE`] of the stances.
    fn covers(&self, i: usize) -> bool {
        self.full
            || self.stances > 0
                && self
                    .loaded
                    .get(i)
                    .is_some_and(|&n| f64::from(n) >= FOOTPRINT_SHARE * f64::from(self.stances))
    }
}

/// Updates the runs and dead flags of one direction's lines from their sums.
fn observe_lines(sums: &[u32], footprint: Footprint, runs: &mut [u32], dead: &mut [bool], k: u32) {
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
        // A run of zero stances starts only on a line of the footprint, and goes on though
        // its own zeros lower the line's share.
        if (neighbour || inside) && (runs[i] > 0 || footprint.covers(i)) {
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
        // The healthy sensor's footprint (the model's training images) fills the image.
        let healthy = image(&[], &[]);
        let mut h = LineHealth::new(6, 6).with_footprint([healthy.as_slice()]);
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
        assert_eq!(h.dead_rows()[3..], [false, false, false]);
        assert!(h.dead_cols().iter().all(|&d| !d), "{:?}", h.dead_cols());
    }

    #[test]
    fn lines_a_footprint_never_loads_are_not_dead_but_lines_that_stop_are() {
        // A foot's print: rows 1 and 4 loaded, rows 2-3 between them never (an arch), row 0
        // and row 5 beside it never. Every zero row has a loaded neighbour or lies inside.
        let mut print = vec![0u16; 36];
        for c in 0..6 {
            print[6 + c] = 50;
            print[4 * 6 + c] = 50;
        }
        let mut h = LineHealth::new(6, 6).with_footprint([print.as_slice(); 10]);
        for _ in 0..20 {
            h.observe(&print, 5);
        }
        assert!(!h.any_dead(), "{:?}", h.dead_rows());
        // Row 4 stops reading while load lies beyond it (row 5 at one sensel, row 0 now
        // too): dead after 5 stances. Rows 0, 2, 3 and 5, which the print seldom loads, stay
        // alive.
        let mut broken = print.clone();
        for c in 0..6 {
            broken[c] = 40;
            broken[4 * 6 + c] = 0;
        }
        broken[5 * 6] = 30;
        for _ in 0..4 {
            h.observe(&broken, 5);
        }
        assert!(!h.dead_rows()[4], "dead before 5 stances");
        h.observe(&broken, 5);
        assert_eq!(h.dead_rows(), &[false, false, false, false, true, false]);
        // Without the training images' footprint a line dead from the first stance on
        // cannot be told from one outside the print: it is not learned.
        let mut fresh = LineHealth::new(6, 6);
        for _ in 0..20 {
            fresh.observe(&image(&[2], &[]), 5);
        }
        assert!(!fresh.any_dead());
        let mut seeded = LineHealth::new(6, 6).with_footprint([image(&[], &[]).as_slice()]);
        for _ in 0..5 {
            seeded.observe(&image(&[2], &[]), 5);
        }
        assert_eq!(
            seeded.dead_rows(),
            &[false, false, true, false, false, false]
        );
    }
}
