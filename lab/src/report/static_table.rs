//! Table 1 and Figure 5: the static classifier on the paper's six terrains.

use super::{
    FeatureExtractor, Kind, Report, ReportError, STATIC_CROP, confusion, dataset, feature_plot,
    pct, train_on,
};
use std::fmt::Write;

pub(super) fn static_table(ctx: &Report) -> Result<String, ReportError> {
    let n = if ctx.quick { 30 } else { 80 };
    let sim_set;
    let (set, crop, what) = match &ctx.user {
        Some(u) => (&u.set, u.crop, format!("`{}`", u.dir.display())),
        None => {
            sim_set = dataset(Kind::Static, n, controller::Gait::g2(), ctx.seed);
            (
                &sim_set,
                STATIC_CROP,
                format!(
                    "`presrs lab dataset static` ({n} presses per terrain at the platform load)"
                ),
            )
        }
    };
    let (model, test) = train_on(set, crop, 1, ctx.seed, false)?;
    let c = confusion(&model, set, &test, |_| {}, false);
    let (accuracy_c, c) = (c.accuracy(), c.counts);
    let (wr, wc) = model.work_size().unwrap_or((0, 0));
    let mut md = String::from(if ctx.user.is_some() {
        "## Table 1: confusion matrix\n\n"
    } else {
        "## Table 1: static classification\n\n"
    });
    let _ = writeln!(
        md,
        "{what}, cropped {},{},{},{} to {wr}x{wc}, 13 training and 7 validation images per \
         class, the other {} tested. Detected (rows) against actual (columns).\n",
        crop.top,
        crop.bottom,
        crop.left,
        crop.right,
        test.len()
    );
    let names: Vec<&str> = set.classes.iter().map(|c| c.name.as_str()).collect();
    let _ = writeln!(md, "| detected \\ actual | {} |", names.join(" | "));
    let _ = writeln!(md, "|---|{}", "---|".repeat(names.len()));
    for (det, name) in names.iter().enumerate() {
        let cells: Vec<String> = (0..names.len())
            .map(|act| {
                let tot: usize = c[act].iter().sum();
                pct(c[act][det] as f64 / tot.max(1) as f64)
            })
            .collect();
        let _ = writeln!(md, "| {name} | {} |", cells.join(" | "));
    }
    let _ = writeln!(
        md,
        "\nOverall accuracy: **{}** (paper, on the hardware: 99.7%).\n",
        pct(accuracy_c)
    );
    // Figure 5: a feature vector per terrain.
    let path = ctx.figures.join("fig05-static-features.png");
    let mut fx = FeatureExtractor::new(wr * wc);
    let series: Vec<(String, Vec<f32>)> = (0..names.len())
        .filter_map(|k| {
            let i = set.labels.iter().position(|&l| l == k)?;
            let img = set.images[i].crop(&crop)?;
            Some((names[k].to_string(), fx.features(&img.pixels, 1.0)))
        })
        .collect();
    feature_plot(
        &path,
        "Figure 5: static feature vectors (one press per terrain)",
        &series,
    )?;
    let _ = writeln!(
        md,
        "![Figure 5](figures/fig05-static-features.png)\n\nFigure 5: the feature vector \
         (FFT magnitude of the {wr}x{wc} image's rows, concatenated, zero-padded to {}; bins \
         0-{}) of one image per class.\n",
        fx.feature_len() * 2 - 2,
        fx.feature_len() - 1
    );
    Ok(md)
}
