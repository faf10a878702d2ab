//! Figures 17-18: accuracy as sensor lines die, with and without the repair filter, and the sensor's lifespan.

use super::{
    BLACK, BLUE, BitMapBackend, ChartBuilder, Curves, DAMAGE_PCT_PER_STEP, DEAD_AFTER_STANCES,
    FOOT_CROP, GREEN, Kind, LineSeries, MAGENTA, PathElement, RED, Report, ReportError,
    SeriesLabelPosition, WHITE, dataset, legend, pct, pe, train_on,
};
use plotters::drawing::IntoDrawingArea;
use plotters::style::Color;
use std::fmt::Write;

pub(super) const ARMS: [&str; 4] = [
    "without repair",
    "with the paper's repair filter",
    "with the node's history-based repair",
    "history-based repair, model refitted to the dead lines",
];

pub(super) fn damage(ctx: &Report) -> Result<(String, Curves), ReportError> {
    let n = if ctx.quick { 25 } else { 60 };
    let sim_set;
    let (set, crop, what) = match &ctx.user {
        Some(u) => (&u.set, u.crop, format!("`{}`", u.dir.display())),
        None => {
            sim_set = dataset(Kind::Dynamic, n, controller::Gait::g2(), ctx.seed + 30);
            (
                &sim_set,
                FOOT_CROP,
                "C2 (trained on undamaged G2 stances, as the paper's: no load normalisation)"
                    .to_string(),
            )
        }
    };
    // Without load normalisation: with it, a dead line also lowers the image's total and so
    // brightens every live sensel (docs/decisions/figures-behind-comments.md).
    let (model, test) = train_on(set, crop, 1, ctx.seed, false)?;
    let levels: Vec<f64> = if ctx.quick {
        vec![0.0, 20.0, 50.0, 80.0]
    } else {
        (0..=18).map(|i| i as f64 * 5.0).collect()
    };
    let sensors = if ctx.quick { 2 } else { 8 };
    let (wr, wc) = model.work_size().unwrap_or((0, 0));
    let curves = crate::study::damage(&model, set, &test, &levels, sensors, ctx.seed);
    plot_damage(ctx, &curves)?;
    let mut md = String::from("## Figure 16: accuracy against sensor damage\n\n");
    let _ = writeln!(
        md,
        "{what} on the {n_test} test stances, seen by {sensors} damaged sensors per level: \
         each sensor has its own random set of dead rows and columns of the {wr}x{wc} crop, up \
         to the damage level (eq. 6), and walks the test stances in a \
         random order. Every stance is classified four ways on the same damaged image: without \
         repair, with the paper's per-image repair filter (section 8), with the node's \
         history-based repair (`node::health::LineHealth`: a line is dead after reading zero \
         inside the footprint, the image's and the model's training images', for \
         {DEAD_AFTER_STANCES} stances in a row; it starts each sensor knowing no dead line, so \
         a sensor's first stances go unrepaired), and with the history-based \
         repair and the model refitted to the dead lines learned so far (`train::refit`: the \
         stored training images get the same dead lines and repair, and PCA and kernel are \
         fitted again; the node does this when a foot's dead lines change). Percentages are of \
         all {sensors} x {n_test} stances.\n\n\
         ![Figure 16](figures/fig16-damage.png)\n\n\
         | damage | without repair | paper's filter | history-based repair | history + refit |\n|---|---|---|---|---|",
        n_test = test.len(),
    );
    for (d, a) in &curves {
        let _ = writeln!(
            md,
            "| {d:.0}% | {} | {} | {} | {} |",
            pct(a[0]),
            pct(a[1]),
            pct(a[2]),
            pct(a[3])
        );
    }
    Ok((md, curves))
}

/// Figure 16's plot: accuracy against damage for each repair arm, and the 90% line.
fn plot_damage(ctx: &Report, curves: &Curves) -> Result<(), ReportError> {
    let path = ctx.figures.join("fig16-damage.png");
    let root = BitMapBackend::new(&path, (900, 540)).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            &if ctx.user.is_some() {
                "Figure 16: accuracy against sensor damage".to_string()
            } else {
                "Figure 16: accuracy against sensor damage (G2, classifier C2)".to_string()
            },
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..100f64, 0f64..100f64)
        .map_err(pe)?;
    chart
        .configure_mesh()
        .x_desc("Sensor damage (% of sensels, eq. 6)")
        .y_desc("Accuracy (%)")
        .draw()
        .map_err(pe)?;
    for (arm, color) in [RED, BLUE, GREEN, MAGENTA].into_iter().enumerate() {
        let label = ARMS[arm];
        chart
            .draw_series(LineSeries::new(
                curves.iter().map(|c| (c.0, 100.0 * c.1[arm])),
                color.stroke_width(2),
            ))
            .map_err(pe)?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
    }
    chart
        .draw_series(LineSeries::new(
            [(0.0, 90.0), (100.0, 90.0)],
            BLACK.stroke_width(3),
        ))
        .map_err(pe)?
        .label("90% (acceptable)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(3)));
    legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    root.present().map_err(pe)?;
    Ok(())
}

pub(super) fn lifespan(ctx: &Report, curves: &Curves) -> Result<String, ReportError> {
    let horizon = if ctx.quick { 10.0 } else { 30.0 };
    let (period_s, m_per_step) =
        crate::study::cadence(&controller::Gait::g2(), horizon).ok_or(ReportError::Fell)?;
    let arm = |k: usize| -> Vec<(f64, f64)> { curves.iter().map(|c| (c.0, c.1[k])).collect() };
    let (d0, d1, d2, d3) = (
        crate::study::damage_at_90(&arm(0)),
        crate::study::damage_at_90(&arm(1)),
        crate::study::damage_at_90(&arm(2)),
        crate::study::damage_at_90(&arm(3)),
    );
    let life = |d: f64| {
        let steps = d / DAMAGE_PCT_PER_STEP;
        (steps * period_s / 60.0, steps * m_per_step / 1000.0)
    };
    let ((min0, km0), (min1, km1), (min2, km2), (min3, km3)) =
        (life(d0), life(d1), life(d2), life(d3));
    let factor = |d: f64| {
        if d0 > 0.0 {
            format!("{:.2}", d / d0)
        } else {
            "n/a (below 90% without damage)".into()
        }
    };
    let mut md = String::from("## Table 6: life span at >= 90% accuracy\n\n");
    let _ = writeln!(
        md,
        "Damage at which accuracy falls below 90% (from Figure 16): {d0:.1}% without repair, \
         {d1:.1}% with the paper's filter, {d2:.1}% with the node's history-based repair, \
         {d3:.1}% with the history-based repair and the refitted model. At the paper's damage \
         rate (7% in 961 steps) and the simulated G2 hopper's {:.2} s and {:.2} m per step:\n\n\
         | metric | without repair | paper's filter | history-based repair | history + refit | paper without | paper with |\n\
         |---|---|---|---|---|---|---|\n\
         | minutes | {min0:.1} | {min1:.1} | {min2:.1} | {min3:.1} | 7.52 | 54.7 |\n\
         | km | {km0:.3} | {km1:.3} | {km2:.3} | {km3:.3} | 0.352 | 2.56 |\n\n\
         Improvement factor: **{}** with the paper's filter, **{}** with the history-based \
         repair, **{}** with the refit (paper: 6.27).\n",
        period_s,
        m_per_step,
        factor(d1),
        factor(d2),
        factor(d3),
    );
    Ok(md)
}
