//! Figure 19: gait adaptation on a closed loop over changing terrain.

use std::fmt::Write as _;

use node::classifier::Model;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{Report, ReportError, legend, pct, pe};
use crate::StepRecord;

pub(super) fn adaptation(ctx: &Report, model: Model) -> Result<String, ReportError> {
    let steps = if ctx.quick { 30 } else { 120 };
    let track = sim::runner::Track::default();
    let cfg = controller::ControllerConfig::default();
    let lp = crate::LoopParams::with_controller(&cfg, steps, ctx.seed);
    let rows = crate::closed_loop::run(&track, model, &lp, |_| {})?.rows;
    let path = ctx.figures.join("adaptation.png");
    let root = BitMapBackend::new(&path, (1100, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    let root = root
        .titled(
            "Gait adaptation on the default track (simulator, node and controller in the loop)",
            ("sans-serif", 22),
        )
        .map_err(pe)?;
    let panels = root.split_evenly((3, 1));
    let t_end = rows.last().map_or(1.0, |r| r.t_s);
    terrain_panel(&panels[0], &rows, t_end)?;
    gait_panel(&panels[1], &rows, t_end)?;
    speed_panel(&panels[2], &rows, t_end)?;
    root.present().map_err(pe)?;
    let sum = crate::Summary::of(&rows, &cfg.terrain_gaits);
    let (correct, switches) = (sum.correct, sum.switches);
    let mut md = String::from("## Gait adaptation on a mixed track\n\n");
    let _ = writeln!(
        md,
        "`presrs demo --steps {steps}`'s loop (simulator, node and controller on the in-process \
         bus; the demo's model, trained on G1-G3 stances): {} of {} steps classified correctly \
         ({}), {switches} gait switches. The controller starts bumplessly (it listens \
         to the leg's first step, which the simulator's own G2 laws run, and takes over at the \
         next touchdown); commanding from t = 0, the same run had 117 of 120 at commit bcbb78f.\n\n\
         ![Adaptation](figures/adaptation.png)\n",
        correct,
        rows.len(),
        pct(sum.accuracy)
    );
    Ok(md)
}

/// The top panel: the true terrain and the one classified at each step.
fn terrain_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    rows: &[StepRecord],
    t_end: f64,
) -> Result<(), ReportError> {
    let terrains = ["wood", "grass", "clay", "carpet"];
    let ti = |s: &str| {
        terrains
            .iter()
            .position(|t| *t == s)
            .map_or(-1.0, |i| i as f64)
    };
    let mut c = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..t_end, -1.5f64..3.5f64)
        .map_err(pe)?;
    c.configure_mesh()
        .y_labels(6)
        .y_label_formatter(&|v| {
            let i = v.round() as i64;
            if (0..4).contains(&i) && (v - i as f64).abs() < 0.01 {
                terrains[i as usize].to_string()
            } else if i == -1 && (v + 1.0).abs() < 0.01 {
                "unknown".into()
            } else {
                String::new()
            }
        })
        .y_desc("Terrain")
        .x_desc("Time (s)")
        .draw()
        .map_err(pe)?;
    c.draw_series(LineSeries::new(
        rows.iter().map(|r| (r.t_s, ti(&r.truth))),
        BLACK.stroke_width(2),
    ))
    .map_err(pe)?
    .label("true terrain")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    c.draw_series(
        rows.iter()
            .map(|r| Circle::new((r.t_s, ti(&r.classified)), 3, RED.filled())),
    )
    .map_err(pe)?
    .label("classified (one per step)")
    .legend(|(x, y)| Circle::new((x + 10, y), 3, RED.filled()));
    legend(&mut c, SeriesLabelPosition::UpperRight)?;
    Ok(())
}

/// The middle panel: the gait in effect.
fn gait_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    rows: &[StepRecord],
    t_end: f64,
) -> Result<(), ReportError> {
    let mut c = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..t_end, 0.5f64..3.5f64)
        .map_err(pe)?;
    c.configure_mesh()
        .y_labels(3)
        .y_label_formatter(&|v| format!("G{}", v.round()))
        .y_desc("Gait")
        .x_desc("Time (s)")
        .draw()
        .map_err(pe)?;
    c.draw_series(LineSeries::new(
        rows.iter().map(|r| (r.t_s, r.gait as f64)),
        BLUE.stroke_width(2),
    ))
    .map_err(pe)?
    .label("gait in effect")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    legend(&mut c, SeriesLabelPosition::UpperRight)?;
    Ok(())
}

/// The bottom panel: the forward speed at each step.
fn speed_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    rows: &[StepRecord],
    t_end: f64,
) -> Result<(), ReportError> {
    let vmax = rows.iter().map(|r| r.speed_m_s).fold(0.5, f64::max) * 1.1;
    let mut c = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..t_end, 0f64..vmax)
        .map_err(pe)?;
    c.configure_mesh()
        .y_desc("Speed (m/s)")
        .x_desc("Time (s)")
        .draw()
        .map_err(pe)?;
    c.draw_series(LineSeries::new(
        rows.iter().map(|r| (r.t_s, r.speed_m_s)),
        GREEN.stroke_width(2),
    ))
    .map_err(pe)?
    .label("forward speed")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], GREEN));
    legend(&mut c, SeriesLabelPosition::UpperRight)?;
    Ok(())
}
