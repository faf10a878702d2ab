//! Table 5 and Figure 16: the dynamic features while hopping.

use super::{
    BitMapBackend, FOOT_CROP, FeatureExtractor, Kind, Report, ReportError, WHITE, dataset,
    draw_features, pe,
};
use plotters::drawing::IntoDrawingArea;
use std::fmt::Write;

/// Mean feature vector per terrain and gait (Figure 13).
pub(super) fn dynamic_features(ctx: &Report) -> Result<String, ReportError> {
    let n = if ctx.quick { 5 } else { 20 };
    let gaits = controller::Gait::paper_gaits();
    let mut per_gait = Vec::new();
    let (rows, cols) = (41, 38);
    let mut fx = FeatureExtractor::new(rows * cols);
    for g in &gaits {
        let set = dataset(Kind::Dynamic, n, g.clone(), ctx.seed + 10 + g.id as u64);
        let mut series = Vec::new();
        for (k, c) in set.classes.iter().enumerate() {
            let mut mean = vec![0f32; fx.feature_len()];
            let mut count = 0f32;
            for (img, _) in set.images.iter().zip(&set.labels).filter(|(_, l)| **l == k) {
                if let Some(c) = img.crop(&FOOT_CROP) {
                    for (m, v) in mean.iter_mut().zip(fx.features(&c.pixels, 1.0)) {
                        *m += v;
                    }
                    count += 1.0;
                }
            }
            mean.iter_mut().for_each(|m| *m /= count.max(1.0));
            series.push((c.name.clone(), mean));
        }
        per_gait.push((format!("G{}", g.id), series));
    }
    // One panel per terrain, the three gaits overlaid.
    let path = ctx.figures.join("fig13-dynamic-features.png");
    let root = BitMapBackend::new(&path, (1200, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    let root = root
        .titled(
            "Figure 13: mean feature vector per terrain, gaits G1-G3 overlaid",
            ("sans-serif", 24),
        )
        .map_err(pe)?;
    for (t, panel) in root.split_evenly((2, 2)).iter().enumerate() {
        let gaits_of_terrain: Vec<(String, Vec<f32>)> = per_gait
            .iter()
            .map(|(gait, series)| (gait.clone(), series[t].1.clone()))
            .collect();
        draw_features(panel, &per_gait[0].1[t].0, 18, 1e5, &gaits_of_terrain)?;
    }
    root.present().map_err(pe)?;
    let mut md = String::from("## Figure 13: dynamic feature vectors per gait\n\n");
    let _ = writeln!(
        md,
        "Mean of {n} stance images (the frame nearest 70 ms after touchdown, cropped 0,3,6,0 to \
         41x38) per terrain and gait. As in the paper, the spikes sit at the same frequencies \
         for every gait; the magnitudes differ with the load at 70 ms.\n\n\
         ![Figure 13](figures/fig13-dynamic-features.png)\n"
    );
    Ok(md)
}
