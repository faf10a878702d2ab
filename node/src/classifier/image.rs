//! Pressure images: the sensor's 2-D array of sensel readings.

use serde::{Deserialize, Serialize};

/// Crop margins: rows removed at the top and bottom, columns at the left and right.
/// The paper crops 2,2,2,2 for the static set (44x44 -> 40x40) and 0,3,6,0 for the foot
/// (44x44 -> 41x38).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Crop {
    /// Rows removed at the top.
    pub top: usize,
    /// Rows removed at the bottom.
    pub bottom: usize,
    /// Columns removed at the left.
    pub left: usize,
    /// Columns removed at the right.
    pub right: usize,
}

/// A crop that is not four whole numbers.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[error("crop `{0}`: expected four whole numbers T,B,L,R such as 2,2,2,2 (or `auto`)")]
pub struct ParseCropError(pub String);

impl std::str::FromStr for Crop {
    type Err = ParseCropError;
    /// `T,B,L,R`, e.g. `2,2,2,2`.
    fn from_str(s: &str) -> Result<Self, ParseCropError> {
        let v: Vec<usize> = s
            .split(',')
            .map(|x| x.trim().parse::<usize>())
            .collect::<Result<_, _>>()
            .map_err(|_| ParseCropError(s.to_string()))?;
        match v[..] {
            [top, bottom, left, right] => Ok(Crop {
                top,
                bottom,
                left,
                right,
            }),
            _ => Err(ParseCropError(s.to_string())),
        }
    }
}

/// The crop `train` is asked for: measured from the lab's own footprint, or given.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CropSpec {
    /// The rows and columns that carry the stances' load ([`crate::training::footprint`]).
    #[default]
    Auto,
    /// This crop.
    Fixed(Crop),
}

impl From<Crop> for CropSpec {
    fn from(c: Crop) -> Self {
        CropSpec::Fixed(c)
    }
}

impl std::str::FromStr for CropSpec {
    type Err = ParseCropError;
    /// `auto`, or `T,B,L,R`.
    fn from_str(s: &str) -> Result<Self, ParseCropError> {
        if s.trim() == "auto" {
            return Ok(CropSpec::Auto);
        }
        s.parse::<Crop>()
            .map(CropSpec::Fixed)
            .map_err(|_| ParseCropError(s.to_string()))
    }
}

impl std::fmt::Display for Crop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{},{},{},{}",
            self.top, self.bottom, self.left, self.right
        )
    }
}

impl Crop {
    /// Size after cropping an image of `rows` x `cols`; `None` when nothing would remain.
    pub fn output_size(&self, rows: usize, cols: usize) -> Option<(usize, usize)> {
        let r = rows.checked_sub(self.top + self.bottom)?;
        let c = cols.checked_sub(self.left + self.right)?;
        (r > 0 && c > 0).then_some((r, c))
    }
}

/// A pressure image: `rows` x `cols` row-major 16-bit sensel values (8-bit sensors use 0..255).
/// `outside` marks sensels that are not part of the sensor (TekScan's `B`): read as 0, never
/// taken for damage, never filled by the repair filter.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PressureImage {
    /// Rows of sensels.
    pub rows: usize,
    /// Columns of sensels.
    pub cols: usize,
    /// 8 or 16: the depth to write the image back with.
    pub bits: u8,
    /// Row-major sensel values.
    pub pixels: Vec<u16>,
    /// Sensels that are not part of the sensor, if any.
    pub outside: Option<Vec<bool>>,
}

impl PressureImage {
    /// An image of `pixels` (`rows * cols`, row-major) at `bits` depth.
    pub fn new(rows: usize, cols: usize, bits: u8, pixels: Vec<u16>) -> Self {
        debug_assert_eq!(pixels.len(), rows * cols);
        Self {
            rows,
            cols,
            bits,
            pixels,
            outside: None,
        }
    }

    /// An 8-bit image of zeros.
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Self::new(rows, cols, 8, vec![0; rows * cols])
    }

    /// The sensel at row `r`, column `c`.
    pub fn get(&self, r: usize, c: usize) -> u16 {
        self.pixels[r * self.cols + c]
    }

    /// Sensel `i` is not part of the sensor.
    pub fn is_outside(&self, i: usize) -> bool {
        self.outside.as_ref().is_some_and(|m| m[i])
    }

    /// The cropped image; `None` when the crop leaves nothing.
    pub fn crop(&self, c: &Crop) -> Option<PressureImage> {
        let (r, k) = c.output_size(self.rows, self.cols)?;
        let mut px = Vec::with_capacity(r * k);
        let mut mask = self.outside.as_ref().map(|_| Vec::with_capacity(r * k));
        for row in c.top..c.top + r {
            let s = row * self.cols + c.left;
            px.extend_from_slice(&self.pixels[s..s + k]);
            if let (Some(m), Some(o)) = (mask.as_mut(), self.outside.as_ref()) {
                m.extend_from_slice(&o[s..s + k]);
            }
        }
        Some(PressureImage {
            rows: r,
            cols: k,
            bits: self.bits,
            pixels: px,
            outside: mask,
        })
    }

    /// Every `k`-th pixel of every `k`-th row (the paper's low-resolution test: 40x40 -> 10x10
    /// with k = 4).
    pub fn downsample(&self, k: usize) -> PressureImage {
        let k = k.max(1);
        let rows = self.rows.div_ceil(k);
        let cols = self.cols.div_ceil(k);
        let mut px = Vec::with_capacity(rows * cols);
        let mut mask = self
            .outside
            .as_ref()
            .map(|_| Vec::with_capacity(rows * cols));
        for r in (0..self.rows).step_by(k) {
            for c in (0..self.cols).step_by(k) {
                px.push(self.get(r, c));
                if let (Some(m), Some(o)) = (mask.as_mut(), self.outside.as_ref()) {
                    m.push(o[r * self.cols + c]);
                }
            }
        }
        PressureImage {
            rows,
            cols,
            bits: self.bits,
            pixels: px,
            outside: mask,
        }
    }

    /// Sum of all sensel values: proportional to the load on the sensor.
    pub fn total(&self) -> f64 {
        self.pixels.iter().map(|&p| p as f64).sum()
    }

    /// A content hash (FNV-1a 64 over size and pixels), so a model can name its training images.
    pub fn content_hash(&self) -> String {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |b: u8| {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        };
        for b in (self.rows as u32)
            .to_le_bytes()
            .into_iter()
            .chain((self.cols as u32).to_le_bytes())
        {
            eat(b);
        }
        for p in &self.pixels {
            for b in p.to_le_bytes() {
                eat(b);
            }
        }
        format!("{h:016x}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(rows: usize, cols: usize) -> PressureImage {
        PressureImage::new(rows, cols, 8, (0..rows * cols).map(|i| i as u16).collect())
    }

    #[test]
    fn crop_like_the_paper() {
        let img = ramp(44, 44);
        let c: Crop = "2,2,2,2".parse().unwrap();
        let out = img.crop(&c).unwrap();
        assert_eq!((out.rows, out.cols), (40, 40));
        assert_eq!(out.get(0, 0), img.get(2, 2));
        assert_eq!(out.get(39, 39), img.get(41, 41));
        let foot = img
            .crop(&Crop {
                top: 0,
                bottom: 3,
                left: 6,
                right: 0,
            })
            .unwrap();
        assert_eq!(
            (foot.rows, foot.cols, foot.rows * foot.cols),
            (41, 38, 1558)
        );
        assert!(
            img.crop(&Crop {
                top: 30,
                bottom: 14,
                left: 0,
                right: 0
            })
            .is_none()
        );
        assert!("1,2,3".parse::<Crop>().is_err());
        assert!(
            "a,b,c,d"
                .parse::<Crop>()
                .unwrap_err()
                .to_string()
                .contains("T,B,L,R")
        );
    }

    #[test]
    fn downsample_takes_every_kth() {
        let img = ramp(40, 40);
        let d = img.downsample(4);
        assert_eq!((d.rows, d.cols), (10, 10));
        assert_eq!(d.get(1, 2), img.get(4, 8));
    }

    #[test]
    fn hash_depends_on_content_and_shape() {
        let a = ramp(4, 4);
        let mut b = a.clone();
        assert_eq!(a.content_hash(), b.content_hash());
        b.pixels[3] += 1;
        assert_ne!(a.content_hash(), b.content_hash());
        let c = PressureImage::new(2, 8, 8, a.pixels.clone());
        assert_ne!(a.content_hash(), c.content_hash());
    }
}
