//! The foot's own crop: the rows and columns of the array that carry the stances' load.
//!
//! The paper cropped its foot's array to 41x38 (`0,3,6,0`): lines at the edge that the foot
//! never loads carry only the sensor's noise into the feature vector, and a line a crop cuts
//! that does carry load takes texture away. Which lines those are is the lab's foot's, not
//! the paper's: `train` measures it on the lab's stances. Each image's load is split over its
//! rows and its columns as shares of its total (so every stance counts the same, whatever its
//! load), the shares are averaged over the stances, and the crop keeps the rows and columns
//! from the first to the last that carry at least [`LOADED_SHARE`] of the load. On the
//! simulator's foot that is the paper's own crop (docs/decisions/foot-settings.md).
//!
//! A crop given with `--crop` that cuts a line carrying that much is warned about, with the
//! share of the load it cuts.

use crate::classifier::{Crop, PressureImage};

/// A line (row or column) carries the footprint's load when it holds at least this share of
/// it: 0.25%, about a ninth of an average line's on a 44-line array; between the simulator's
/// cut lines and a walking foot's outline (docs/decisions/foot-settings.md).
pub const LOADED_SHARE: f64 = 0.0025;

/// Per row and per column of the array, the mean share of a stance's load it carries.
#[derive(Clone, Debug, PartialEq)]
pub struct Footprint {
    /// Rows, top to bottom.
    pub rows: Vec<f64>,
    /// Columns, left to right.
    pub cols: Vec<f64>,
    /// Stances it was measured on (those with any load).
    pub stances: usize,
}

impl Footprint {
    /// The footprint of `images` (one array size: the first image's; others and blank ones
    /// are not counted); `None` without a loaded image.
    pub fn of<'a>(images: impl IntoIterator<Item = &'a PressureImage>) -> Option<Self> {
        let mut it = images.into_iter().peekable();
        let (r, c) = it.peek().map(|i| (i.rows, i.cols))?;
        let (mut rows, mut cols, mut n) = (vec![0.0; r], vec![0.0; c], 0usize);
        for img in it.filter(|i| (i.rows, i.cols) == (r, c)) {
            let total: f64 = img.pixels.iter().map(|&p| p as f64).sum();
            if total <= 0.0 {
                continue;
            }
            for (i, row) in img.pixels.chunks_exact(c).enumerate() {
                for (j, &p) in row.iter().enumerate() {
                    let s = p as f64 / total;
                    rows[i] += s;
                    cols[j] += s;
                }
            }
            n += 1;
        }
        if n == 0 {
            return None;
        }
        for v in rows.iter_mut().chain(cols.iter_mut()) {
            *v /= n as f64;
        }
        Some(Self {
            rows,
            cols,
            stances: n,
        })
    }

    /// The crop that keeps the loaded lines (see the module docs); none where no line is.
    pub fn crop(&self) -> Crop {
        let span = |v: &[f64]| {
            let first = v.iter().position(|&s| s >= LOADED_SHARE);
            let last = v.iter().rposition(|&s| s >= LOADED_SHARE);
            match (first, last) {
                (Some(a), Some(b)) => (a, v.len() - 1 - b),
                _ => (0, 0),
            }
        };
        let (top, bottom) = span(&self.rows);
        let (left, right) = span(&self.cols);
        Crop {
            top,
            bottom,
            left,
            right,
        }
    }

    /// What `crop` cuts of the footprint: the share of the load in the lines it removes, and
    /// how many of them are loaded lines.
    pub fn cut_by(&self, crop: &Crop) -> (f64, usize) {
        let (r, c) = (self.rows.len(), self.cols.len());
        let cut_rows: Vec<usize> = (0..crop.top.min(r))
            .chain(r.saturating_sub(crop.bottom)..r)
            .collect();
        let cut_cols: Vec<usize> = (0..crop.left.min(c))
            .chain(c.saturating_sub(crop.right)..c)
            .collect();
        let rows: f64 = cut_rows.iter().map(|&i| self.rows[i]).sum();
        let cols: f64 = cut_cols.iter().map(|&j| self.cols[j]).sum();
        let loaded = cut_rows
            .iter()
            .map(|&i| self.rows[i])
            .chain(cut_cols.iter().map(|&j| self.cols[j]))
            .filter(|&s| s >= LOADED_SHARE)
            .count();
        // A pixel in a cut row and a cut column is counted in both sums: the share is at most
        // their sum (an upper bound; exact where the corners carry nothing).
        ((rows + cols).min(1.0), loaded)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `rows` x `cols` image loaded only inside `[r0, r1) x [c0, c1)`.
    fn patch(
        rows: usize,
        cols: usize,
        r: (usize, usize),
        c: (usize, usize),
        v: u16,
    ) -> PressureImage {
        let px = (0..rows * cols)
            .map(|i| {
                let (y, x) = (i / cols, i % cols);
                if (r.0..r.1).contains(&y) && (c.0..c.1).contains(&x) {
                    v
                } else {
                    0
                }
            })
            .collect();
        PressureImage::new(rows, cols, 8, px)
    }

    #[test]
    fn the_crop_keeps_the_loaded_lines_and_a_given_one_is_told_what_it_cuts() {
        // A footprint offset to the bottom right of a 44x44 array: rows 10-43, columns 15-43.
        let imgs = [
            patch(44, 44, (10, 44), (15, 44), 100),
            patch(44, 44, (12, 44), (15, 40), 60),
        ];
        let f = Footprint::of(&imgs).unwrap();
        assert_eq!(f.stances, 2);
        assert_eq!(
            f.crop(),
            Crop {
                top: 10,
                bottom: 0,
                left: 15,
                right: 0
            }
        );
        let (share, loaded) = f.cut_by(&f.crop());
        assert_eq!((share, loaded), (0.0, 0), "its own crop cuts nothing");
        // The paper's crop cuts three loaded bottom rows of this foot.
        let paper = "0,3,6,0".parse::<Crop>().unwrap();
        let (share, loaded) = f.cut_by(&paper);
        assert_eq!(loaded, 3);
        assert!((0.08..0.1).contains(&share), "{share}");
        // Blank stances do not count; none loaded, no footprint.
        assert!(Footprint::of(&[patch(4, 4, (0, 0), (0, 0), 0)]).is_none());
    }
}
