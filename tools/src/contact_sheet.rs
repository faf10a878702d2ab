//! A contact sheet: example stance images of one proposed terrain side by side, as a PNG
//! (`presrs discover --out DIR`), so that a lab looks at what the robot stood on before it
//! names it.

use std::path::Path;

use node::classifier::PressureImage;
use plotters::prelude::*;

use crate::plot::{PlotError, pe, register_font};

/// Images on one sheet at most (evenly spread over those given).
pub const SHEET_IMAGES: usize = 24;
const COLUMNS: usize = 6;
const TILE: u32 = 150;
const CAPTION: u32 = 40;

/// Draws up to [`SHEET_IMAGES`] of `images` (each with its label) under `title` into `png`.
pub fn contact_sheet(
    images: &[(&PressureImage, String)],
    title: &str,
    png: &Path,
) -> Result<(), PlotError> {
    register_font()?;
    let n = images.len().min(SHEET_IMAGES);
    let picked: Vec<&(&PressureImage, String)> = (0..n)
        .map(|i| &images[i * images.len() / n.max(1)])
        .collect();
    let rows = n.div_ceil(COLUMNS).max(1);
    let size = (COLUMNS as u32 * TILE, CAPTION + rows as u32 * TILE);
    let root = BitMapBackend::new(png, size).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    root.draw(&Text::new(title.to_string(), (10, 10), ("sans-serif", 18)))
        .map_err(pe)?;
    for (k, (img, label)) in picked.into_iter().enumerate() {
        let (x0, y0) = (
            (k % COLUMNS) as i32 * TILE as i32,
            CAPTION as i32 + (k / COLUMNS) as i32 * TILE as i32,
        );
        let side = img.rows.max(img.cols).max(1) as i32;
        let cell = ((TILE as i32 - 24) / side).max(1);
        let max = img.pixels.iter().copied().max().unwrap_or(1).max(1) as f64;
        for r in 0..img.rows {
            for c in 0..img.cols {
                // Pressure as brightness, row 0 at the top.
                let v = (255.0 * img.pixels[r * img.cols + c] as f64 / max) as u8;
                let (x, y) = (x0 + 4 + c as i32 * cell, y0 + 2 + r as i32 * cell);
                root.draw(&Rectangle::new(
                    [(x, y), (x + cell, y + cell)],
                    RGBColor(v, v, v).filled(),
                ))
                .map_err(pe)?;
            }
        }
        root.draw(&Text::new(
            label.clone(),
            (x0 + 4, y0 + TILE as i32 - 20),
            ("sans-serif", 12),
        ))
        .map_err(pe)?;
    }
    root.present().map_err(pe)
}
