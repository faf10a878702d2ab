//! Figure 12 and Table 3: accuracy against the sensor's resolution.

use super::{
    BLACK, BLUE, BitMapBackend, ChartBuilder, Kind, PathElement, RED, Rectangle, Report,
    ReportError, STATIC_CROP, SeriesLabelPosition, WHITE, legend, pct, pe,
};
use plotters::drawing::IntoDrawingArea;
use plotters::style::Color;
use std::fmt::Write;

pub(super) fn resolution(ctx: &Report) -> Result<String, ReportError> {
    let seeds: Vec<u64> = (0..if ctx.quick { 2 } else { 5 })
        .map(|i| ctx.seed + i)
        .collect();
    let mut md = String::from("## Resolution: full (40x40) against 10x10\n\n");
    let _ = writeln!(
        md,
        "The paper's protocol (section 5): 50 presses per sandpaper surface, 100 per static \
         terrain, at 10 N; per terrain 13 training and 7 validation images, the rest tested; \
         rejection off. Trained and tested at each resolution (10x10: every 4th sensel of the \
         40x40 crop). Sandpaper grits 220, 150, 100, 60 and polished aluminum are the similar \
         terrains; the static set's four are the dissimilar ones. Seeds {}-{} (a fresh dataset \
         and split each): mean, and the range in parentheses.\n",
        seeds[0],
        seeds[seeds.len() - 1]
    );
    let _ = writeln!(
        md,
        "| terrains | 40x40 | 10x10 | loss at 10x10 | paper 40x40 | paper 10x10 | paper loss |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    let mut bars = Vec::new();
    let mut losses = Vec::new();
    let mut per_terrain = String::new();
    for (label, kind, paper) in [
        ("similar (sandpaper)", Kind::Sandpaper, (0.967, 0.580)),
        ("dissimilar (static set)", Kind::Static, (0.997, 0.988)),
    ] {
        let confusions = crate::study::resolution(kind, STATIC_CROP, 4, &seeds)?;
        let runs: Vec<(f64, f64)> = confusions
            .iter()
            .map(|(f, l)| (f.accuracy(), l.accuracy()))
            .collect();
        let terrains = kind.terrains();
        let recall = |i: usize, low: bool| {
            confusions
                .iter()
                .map(|(f, l)| if low { l.recall(i) } else { f.recall(i) })
                .sum::<f64>()
                / confusions.len().max(1) as f64
        };
        let _ = write!(per_terrain, "| {label} |");
        for (i, t) in terrains.iter().enumerate() {
            let _ = write!(
                per_terrain,
                " {} {} / {} |",
                t.name(),
                pct(recall(i, false)),
                pct(recall(i, true))
            );
        }
        let _ = writeln!(per_terrain);
        let stat = |f: fn(&(f64, f64)) -> f64| {
            let v: Vec<f64> = runs.iter().map(f).collect();
            let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
            let (lo, hi) = v
                .iter()
                .fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
            (mean, lo, hi)
        };
        let full = stat(|r| r.0);
        let low = stat(|r| r.1);
        let loss = stat(|r| r.0 - r.1);
        let cell = |(m, l, h): (f64, f64, f64)| format!("{} ({}-{})", pct(m), pct(l), pct(h));
        let points = |(m, l, h): (f64, f64, f64)| {
            format!("{:.1} ({:.1} to {:.1})", m * 100.0, l * 100.0, h * 100.0)
        };
        let _ = writeln!(
            md,
            "| {label} | {} | {} | {} | {} | {} | {:.1} |",
            cell(full),
            cell(low),
            points(loss),
            pct(paper.0),
            pct(paper.1),
            (paper.0 - paper.1) * 100.0
        );
        bars.push((full, low, paper));
        losses.push(loss.0);
    }
    let _ = writeln!(
        md,
        "\nSimilar textures lose {:.1} points at 10x10, {:.1} times what the dissimilar ones \
         lose (the paper: 38.7 points, 43 times). What makes the grits differ at the scale of \
         a sensel, and why subsampling loses it, is in `sim/src/terrain.rs` \
         (`BACKING_RELIEF_MM`).",
        losses[0] * 100.0,
        losses[0] / losses[1].max(1e-3)
    );
    let _ = writeln!(
        md,
        "\nPer terrain, the share of its test images classified right at 40x40 / 10x10 (mean \
         of the seeds):\n\n| set | | | | | |\n|---|---|---|---|---|---|\n{per_terrain}"
    );
    figure(&ctx.figures.join("resolution.png"), &bars)?;
    let _ = writeln!(md, "\n![Resolution](figures/resolution.png)\n");
    Ok(md)
}

/// Mean, lowest and highest accuracy over the seeds.
type Spread = (f64, f64, f64);

/// Figure 12: per set of terrains, a bar per resolution (the mean over the seeds, whiskers
/// their range) and the paper's accuracy as a black tick.
fn figure(
    path: &std::path::Path,
    bars: &[(Spread, Spread, (f64, f64))],
) -> Result<(), ReportError> {
    let root = BitMapBackend::new(path, (800, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Accuracy at full resolution and at 10x10 (black: the paper)",
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0f64..4.0, 0.0f64..100.0)
        .map_err(pe)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc("Accuracy (%)")
        .x_desc("similar (sandpaper)                                dissimilar (static set)")
        .draw()
        .map_err(pe)?;
    // Bars: the mean over the seeds; whiskers: their range; black ticks: the paper's figure.
    for (i, (full, low, paper)) in bars.iter().enumerate() {
        let x = i as f64 * 2.0;
        for (dx, (m, lo, hi), p, color) in [(0.3, *full, paper.0, BLUE), (1.0, *low, paper.1, RED)]
        {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x + dx, 0.0), (x + dx + 0.6, m * 100.0)],
                    color.filled(),
                )))
                .map_err(pe)?;
            let mid = x + dx + 0.3;
            chart
                .draw_series([
                    PathElement::new(vec![(mid, lo * 100.0), (mid, hi * 100.0)], BLACK),
                    PathElement::new(
                        vec![(x + dx - 0.05, p * 100.0), (x + dx + 0.65, p * 100.0)],
                        BLACK.stroke_width(3),
                    ),
                ])
                .map_err(pe)?;
        }
    }
    for (label, color) in [("40x40", BLUE), ("10x10", RED)] {
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(0.0, -1.0), (0.0, -1.0)],
                color.filled(),
            )))
            .map_err(pe)?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 15, y + 5)], color.filled()));
    }
    legend(&mut chart, SeriesLabelPosition::LowerRight)?;
    root.present().map_err(pe)?;
    Ok(())
}
