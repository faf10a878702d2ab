//! A recording at a glance, without Foxglove: one foot's pressure image (with a colour bar in
//! pressure counts) beside a panel per kind of data the recording holds (terrain, the foot
//! switch, the gait, the speed), drawn from the messages of an MCAP recording
//! ([`record::read::read_json`]).
//!
//! What is drawn is decided first ([`plan::plan`]): a panel only for data the recording has,
//! a legend entry only for a series with points, legends beside the plots (never over the
//! data), and the image of the step that says most about the run (its first unknown step, else
//! its middle one), named in the title. A foot-only log (the foot board's frames, run through
//! a model with `presrs mcap --model`) shows its contact, image and the model's terrain; a
//! demo recording every panel.

pub mod plan;

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use record::read::Recorded;

use crate::plot::{PlotError, pe, register_font};
pub use plan::{FootData, Layout, PanelKind, Shown};

/// What the view shows, for the caller to print.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewSummary {
    /// Seconds of recording.
    pub span_s: f64,
    /// Pressure images of the foot.
    pub images: usize,
    /// TerrainClass of the foot on the bus (`/footN/terrain`).
    pub steps: usize,
    /// TerrainClass a model decided while recording (`/footN/terrain/model`, `presrs mcap
    /// --model`).
    pub model_steps: usize,
    /// Time of the image shown, s from the start, and why it was chosen.
    pub image: Option<(f64, Shown)>,
    /// The panels drawn, with their legends.
    pub layout: Layout,
    /// The foot shown.
    pub foot: u8,
}

impl std::fmt::Display for ViewSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.1} s, {} images, {} TerrainClass of foot {}{}; panels: {}; image: ",
            self.span_s,
            self.images,
            self.steps,
            self.foot,
            if self.model_steps > 0 {
                format!(" and {} decided by the model", self.model_steps)
            } else {
                String::new()
            },
            self.layout
                .panels
                .iter()
                .map(|p| p.kind.title())
                .collect::<Vec<_>>()
                .join(", "),
        )?;
        match &self.image {
            Some((t, why)) => write!(f, "{why} at {t:.2} s"),
            None => write!(f, "none"),
        }
    }
}

/// Pressure 0..1 to colour: dark blue through green to yellow-red, as Foxglove's "turbo".
fn heat(v: f64) -> RGBColor {
    let v = v.clamp(0.0, 1.0);
    let hue = (1.0 - v) * 240.0 / 360.0;
    let c: RGBAColor = HSLColor(hue, 0.9, 0.12 + 0.43 * v.sqrt()).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// The legend column beside each panel, px.
const LEGEND_W: u32 = 300;
const GREY: RGBColor = RGBColor(120, 120, 120);

/// How a series is drawn, for its legend entry.
#[derive(Clone, Copy)]
enum Mark {
    Line(RGBColor),
    Dot(RGBColor),
    Cross(RGBColor),
}

/// Draws `foot`'s view of `recording` into `png` (1400 x 760): see the module docs. `at_s`
/// (seconds from the start) shows the image nearest that time instead of the chosen step's.
pub fn render(
    recording: &[Recorded],
    foot: u8,
    at_s: Option<f64>,
    title: &str,
    png: &Path,
) -> Result<ViewSummary, PlotError> {
    register_font()?;
    let d = FootData::of(recording, foot);
    let layout = plan::plan(&d, at_s);
    let shown = layout
        .image
        .as_ref()
        .map(|(i, why)| (d.images[*i], why.clone()));
    let title = match &shown {
        Some(((t, _), why)) => format!("{title}; image: {why}, {t:.2} s"),
        None => title.to_string(),
    };
    let root = BitMapBackend::new(png, (1400, 760)).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    let root = root.titled(&title, ("sans-serif", 20)).map_err(pe)?;
    let (left, right) = root.split_horizontally(520);
    // Square sensels: the image's chart as tall as it is wide (the colour bar beside it).
    let (left, _) = left.split_vertically(480);
    match &shown {
        Some(((t, m), _)) => draw_image(&left, foot, *t, m, decision_at(&d, *t))?,
        None => {
            left.draw(&Text::new(
                format!("no /foot{foot}/image in this recording"),
                (40, 300),
                ("sans-serif", 18),
            ))
            .map_err(pe)?;
        }
    }
    let cursor = shown.as_ref().map(|((t, _), _)| *t);
    if !layout.panels.is_empty() {
        let areas = right.split_evenly((layout.panels.len(), 1));
        for (i, (p, area)) in layout.panels.iter().zip(&areas).enumerate() {
            let last = i + 1 == layout.panels.len();
            let (plot, legend_area) = area.split_horizontally(area.dim_in_pixel().0 - LEGEND_W);
            let marks = draw_panel(&plot, p.kind, &d, cursor, last)?;
            draw_legend(&legend_area, p, &marks)?;
        }
    }
    root.present().map_err(pe)?;
    Ok(ViewSummary {
        span_s: d.span,
        images: d.images.len(),
        steps: d.classes.len(),
        model_steps: d.model.len(),
        image: shown.map(|((t, _), why)| (t, why)),
        layout,
        foot,
    })
}

/// The decision made of the stance whose image is at `t` (the first after it; the model's
/// if the recording has them).
fn decision_at<'a>(d: &FootData<'a>, t: f64) -> Option<&'a Recorded> {
    let decisions = if d.model.is_empty() {
        &d.classes
    } else {
        &d.model
    };
    decisions.iter().find(|(td, _)| *td >= t).map(|(_, m)| *m)
}

/// The pressure image and its colour bar, in counts.
fn draw_image(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    foot: u8,
    t: f64,
    m: &Recorded,
    decided: Option<&Recorded>,
) -> Result<(), PlotError> {
    let Some((w, h, px)) = record::read::mono8_image(&m.json) else {
        return Ok(());
    };
    let caption = match decided {
        Some(c) => {
            let terrain = c.json["Terrain"].as_str().unwrap_or("?");
            match c.json["Confidence"].as_f64() {
                Some(conf) => format!("/foot{foot}/image at {t:.2} s -> {terrain} ({conf:.0}%)"),
                None => format!("/foot{foot}/image at {t:.2} s -> {terrain}"),
            }
        }
        None => format!("/foot{foot}/image at {t:.2} s"),
    };
    let (img_area, bar_area) = area.split_horizontally(area.dim_in_pixel().0 - 110);
    let max = px.iter().copied().max().unwrap_or(1).max(1) as f64;
    let mut c = ChartBuilder::on(&img_area)
        .caption(caption, ("sans-serif", 16))
        .margin(12)
        .build_cartesian_2d(0..w as i32, 0..h as i32)
        .map_err(pe)?;
    c.configure_mesh().disable_mesh().draw().map_err(pe)?;
    c.draw_series((0..h).flat_map(|r| {
        let px = &px;
        (0..w).map(move |col| {
            let v = px[r * w + col] as f64 / max;
            // Row 0 at the top, as the Image panel shows it.
            let y = (h - 1 - r) as i32;
            Rectangle::new([(col as i32, y), (col as i32 + 1, y + 1)], heat(v).filled())
        })
    }))
    .map_err(pe)?;
    // The colour bar: the same scale, 0 to the image's largest count.
    let mut bar = ChartBuilder::on(&bar_area)
        .margin_top(40)
        .margin_bottom(30)
        .margin_right(8)
        .y_label_area_size(64)
        .build_cartesian_2d(0f64..1f64, 0f64..max)
        .map_err(pe)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc("pressure (counts)")
        .axis_desc_style(("sans-serif", 14))
        .y_labels(6)
        .y_label_style(("sans-serif", 13))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(pe)?;
    let n = 64;
    bar.draw_series((0..n).map(|k| {
        let (a, b) = (max * k as f64 / n as f64, max * (k + 1) as f64 / n as f64);
        Rectangle::new([(0.0, a), (1.0, b)], heat(k as f64 / n as f64).filled())
    }))
    .map_err(pe)?;
    Ok(())
}

/// The frame every time panel is drawn in.
struct PanelArea<'a, 'b> {
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    span: f64,
    /// Height of the time axis' labels (the last panel names the axis).
    x_area: u32,
    last: bool,
    /// The shown image's time, marked on every panel.
    cursor: Option<f64>,
}

impl PanelArea<'_, '_> {
    /// The cursor's line from `lo` to `hi`.
    fn cursor_line(&self, lo: f64, hi: f64) -> Option<PathElement<(f64, f64)>> {
        self.cursor
            .map(|x| PathElement::new(vec![(x, lo), (x, hi)], GREY))
    }

    fn x_desc(&self) -> &'static str {
        if self.last { "Time (s)" } else { "" }
    }
}

/// One time panel; returns how each of its series was drawn (in the layout's order).
fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    kind: PanelKind,
    d: &FootData<'_>,
    cursor: Option<f64>,
    last: bool,
) -> Result<Vec<Mark>, PlotError> {
    let p = PanelArea {
        area,
        span: d.span,
        x_area: if last { 40 } else { 24 },
        last,
        cursor,
    };
    match kind {
        PanelKind::Terrain => terrain_panel(&p, d),
        PanelKind::Contact => contact_panel(&p, d),
        PanelKind::Gait => gait_panel(&p, d),
        PanelKind::Speed => speed_panel(&p, d),
    }
}

/// Terrain: one row per name seen; the truth as a line, the bus's decisions as dots, a
/// model's as crosses.
fn terrain_panel(p: &PanelArea<'_, '_>, d: &FootData<'_>) -> Result<Vec<Mark>, PlotError> {
    // One row per terrain name seen, in the order met.
    let mut names: BTreeMap<String, usize> = BTreeMap::new();
    for (_, m) in d.truth.iter().chain(&d.classes).chain(&d.model) {
        if let Some(n) = m.json["Terrain"].as_str() {
            let k = names.len();
            names.entry(n.to_string()).or_insert(k);
        }
    }
    let mut labels: Vec<(usize, String)> = names.iter().map(|(n, &i)| (i, n.clone())).collect();
    labels.sort();
    let labels: Vec<String> = labels.into_iter().map(|(_, n)| n).collect();
    let row = |m: &Recorded| {
        m.json["Terrain"]
            .as_str()
            .and_then(|n| names.get(n))
            .map(|&i| i as f64)
    };
    let top = names.len().max(1) as f64 - 0.5;
    let mut c = time_chart(p.area, p.span, -0.5f64..top, p.x_area)?;
    c.configure_mesh()
        .y_labels(names.len().max(1))
        .y_label_formatter(&|v| {
            let i = v.round();
            if (v - i).abs() < 0.01 && i >= 0.0 {
                labels.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .x_desc(p.x_desc())
        .draw()
        .map_err(pe)?;
    let mut marks = Vec::new();
    let with_terrain: Vec<_> = d
        .truth
        .iter()
        .filter_map(|(t, m)| Some((*t, row(m)?)))
        .collect();
    if !with_terrain.is_empty() {
        c.draw_series(LineSeries::new(with_terrain, BLACK.stroke_width(2)))
            .map_err(pe)?;
        marks.push(Mark::Line(BLACK));
    }
    if !d.classes.is_empty() {
        c.draw_series(
            d.classes
                .iter()
                .filter_map(|(t, m)| Some(Circle::new((*t, row(m)?), 4, RED.filled()))),
        )
        .map_err(pe)?;
        marks.push(Mark::Dot(RED));
    }
    if !d.model.is_empty() {
        // Just above the bus's dots where both are drawn.
        let lift = if d.classes.is_empty() { 0.0 } else { 0.15 };
        c.draw_series(
            d.model
                .iter()
                .filter_map(|(t, m)| Some(Cross::new((*t, row(m)? + lift), 4, BLUE))),
        )
        .map_err(pe)?;
        marks.push(Mark::Cross(BLUE));
    }
    c.draw_series(p.cursor_line(-0.5, top)).map_err(pe)?;
    Ok(marks)
}

/// The foot switch as a step line: stance or flight.
fn contact_panel(p: &PanelArea<'_, '_>, d: &FootData<'_>) -> Result<Vec<Mark>, PlotError> {
    let mut c = time_chart(p.area, p.span, -0.2f64..1.2f64, p.x_area)?;
    c.configure_mesh()
        .y_labels(2)
        .y_label_formatter(&|v| match v.round() as i32 {
            0 => "flight".into(),
            1 => "stance".into(),
            _ => String::new(),
        })
        .x_desc(p.x_desc())
        .draw()
        .map_err(pe)?;
    // A step line: each report holds until the next.
    let mut pts = Vec::with_capacity(2 * d.contact.len());
    let mut last_v = None;
    for (t, m) in &d.contact {
        let v = if plan::in_stance(m) { 1.0 } else { 0.0 };
        if let Some(p) = last_v {
            pts.push((*t, p));
        }
        pts.push((*t, v));
        last_v = Some(v);
    }
    let color = RGBColor(0, 128, 128);
    c.draw_series(LineSeries::new(pts, color.stroke_width(2)))
        .map_err(pe)?;
    c.draw_series(p.cursor_line(-0.2, 1.2)).map_err(pe)?;
    Ok(vec![Mark::Line(color)])
}

/// The gait in force.
fn gait_panel(p: &PanelArea<'_, '_>, d: &FootData<'_>) -> Result<Vec<Mark>, PlotError> {
    let pts: Vec<(f64, f64)> = d
        .gait
        .iter()
        .filter_map(|(t, m)| Some((*t, m.json["ActiveGait"].as_f64()?)))
        .collect();
    let hi = pts.iter().map(|p| p.1).fold(3.0, f64::max) + 0.5;
    let mut c = time_chart(p.area, p.span, 0.5f64..hi, p.x_area)?;
    c.configure_mesh()
        .y_labels((hi - 0.5) as usize)
        .y_label_formatter(&|v| format!("G{}", v.round()))
        .x_desc(p.x_desc())
        .draw()
        .map_err(pe)?;
    c.draw_series(LineSeries::new(pts, BLUE.stroke_width(2)))
        .map_err(pe)?;
    c.draw_series(p.cursor_line(0.5, hi)).map_err(pe)?;
    Ok(vec![Mark::Line(BLUE)])
}

/// The simulator's true speed.
fn speed_panel(p: &PanelArea<'_, '_>, d: &FootData<'_>) -> Result<Vec<Mark>, PlotError> {
    let pts: Vec<(f64, f64)> = d
        .truth
        .iter()
        .filter_map(|(t, m)| Some((*t, m.json["SpeedMps"].as_f64()?)))
        .collect();
    let vmax = pts.iter().map(|p| p.1).fold(0.5, f64::max) * 1.1;
    let mut c = time_chart(p.area, p.span, 0f64..vmax, p.x_area)?;
    c.configure_mesh().x_desc(p.x_desc()).draw().map_err(pe)?;
    let green = RGBColor(0, 150, 0);
    c.draw_series(LineSeries::new(pts, green.stroke_width(2)))
        .map_err(pe)?;
    c.draw_series(p.cursor_line(0.0, vmax)).map_err(pe)?;
    Ok(vec![Mark::Line(green)])
}

/// A panel's chart: time from 0 to `span` s against `y`, labels as every panel has them.
fn time_chart<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    span: f64,
    y: std::ops::Range<f64>,
    x_label_area: u32,
) -> Result<
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    PlotError,
> {
    ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(x_label_area)
        .y_label_area_size(90)
        .build_cartesian_2d(0f64..span, y)
        .map_err(pe)
}

/// The panel's title and legend, in the column beside its plot.
fn draw_legend(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    p: &plan::Panel,
    marks: &[Mark],
) -> Result<(), PlotError> {
    area.draw(&Text::new(p.kind.title(), (12, 14), ("sans-serif", 17)))
        .map_err(pe)?;
    for (k, (s, m)) in p.series.iter().zip(marks).enumerate() {
        let y = 44 + 24 * k as i32;
        match *m {
            Mark::Line(c) => {
                area.draw(&PathElement::new(vec![(12, y), (34, y)], c.stroke_width(2)))
            }
            Mark::Dot(c) => area.draw(&Circle::new((23, y), 4, c.filled())),
            Mark::Cross(c) => area.draw(&Cross::new((23, y), 4, c)),
        }
        .map_err(pe)?;
        area.draw(&Text::new(
            format!("{} ({})", s.label, s.points),
            (42, y - 8),
            ("sans-serif", 14),
        ))
        .map_err(pe)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heat_runs_from_dark_to_bright() {
        let (lo, hi) = (heat(0.0), heat(1.0));
        assert!(lo.0 as u32 + lo.1 as u32 + lo.2 as u32 <= hi.0 as u32 + hi.1 as u32 + hi.2 as u32);
    }
}
