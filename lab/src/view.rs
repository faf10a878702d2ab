//! A recording at a glance, without Foxglove: one foot's pressure image beside its terrain,
//! the gait and the speed against time, the panels of `docs/foxglove-layout.json`, drawn
//! from the messages of an MCAP recording ([`record::read::read_json`]).

use std::collections::BTreeMap;
use std::path::Path;

use plotters::prelude::*;
use record::read::Recorded;

use crate::report::{ReportError, legend, pe, register_font};

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
    /// Time of the image shown, s from the start.
    pub image_t_s: Option<f64>,
    /// Whether the recording holds the simulator's truth (speed, true terrain).
    pub has_truth: bool,
    /// The foot shown.
    pub foot: u8,
}

impl std::fmt::Display for ViewSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.1} s, {} images, {} TerrainClass of foot {}{}{}; image at ",
            self.span_s,
            self.images,
            self.steps,
            self.foot,
            if self.model_steps > 0 {
                format!(" and {} decided by the model", self.model_steps)
            } else {
                String::new()
            },
            if self.has_truth {
                ", with the simulator's truth"
            } else {
                ""
            },
        )?;
        match self.image_t_s {
            Some(t) => write!(f, "{t:.2} s"),
            None => write!(f, "-"),
        }
    }
}

struct Image {
    t: f64,
    w: usize,
    h: usize,
    px: Vec<u8>,
}

/// Pressure 0..1 to colour: dark blue through green to yellow-red, as Foxglove's "turbo".
fn heat(v: f64) -> RGBColor {
    let v = v.clamp(0.0, 1.0);
    let hue = (1.0 - v) * 240.0 / 360.0;
    let c: RGBAColor = HSLColor(hue, 0.9, 0.12 + 0.43 * v.sqrt()).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// Draws `foot`'s view of `recording` into `png` (1400 x 760). The image shown is the most
/// loaded one of the last stance the node decided (or `at_s`, seconds from the start: the
/// image nearest that time).
pub fn render(
    recording: &[Recorded],
    foot: u8,
    at_s: Option<f64>,
    title: &str,
    png: &Path,
) -> Result<ViewSummary, ReportError> {
    register_font()?;
    let t0 = recording.iter().map(|m| m.log_time_ns).min().unwrap_or(0);
    let t = |m: &Recorded| (m.log_time_ns - t0) as f64 * 1e-9;
    let on = |topic: String| {
        recording
            .iter()
            .filter(move |m| m.topic == topic)
            .collect::<Vec<_>>()
    };
    let images: Vec<Image> = on(format!("/foot{foot}/image"))
        .into_iter()
        .filter_map(|m| {
            record::read::mono8_image(&m.json).map(|(w, h, px)| Image { t: t(m), w, h, px })
        })
        .collect();
    let classes = on(format!("/foot{foot}/terrain"));
    let model = on(format!("/foot{foot}/terrain/model"));
    let truth = on(format!("/sim/leg{foot}"));
    let gait = on("/gait".into());
    let span = recording.iter().map(t).fold(1e-3, f64::max);

    // The image: the most loaded of the 200 ms before the last decision, or the one at `at_s`.
    let load = |i: &Image| i.px.iter().map(|&p| p as u64).sum::<u64>();
    let shown = match at_s {
        Some(a) => images
            .iter()
            .min_by(|x, y| (x.t - a).abs().total_cmp(&(y.t - a).abs())),
        None => {
            let tc = classes.last().map_or(span, |m| t(m));
            images
                .iter()
                .filter(|i| i.t <= tc && i.t >= tc - 0.2)
                .max_by_key(|i| load(i))
                .or(images.last())
        }
    };
    let decided = shown.and_then(|i| classes.iter().find(|m| t(m) >= i.t));

    let root = BitMapBackend::new(png, (1400, 760)).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(pe)?;
    let (left, right) = root.split_horizontally(520);
    // Square sensels: the array is as tall as it is wide.
    let (left, _) = left.split_vertically(540);

    // Left: the pressure image.
    match shown {
        Some(img) => {
            let caption = match decided {
                Some(m) => format!(
                    "/foot{foot}/image at {:.2} s -> {} ({}%)",
                    img.t,
                    m.json["Terrain"].as_str().unwrap_or("?"),
                    m.json["Confidence"]
                ),
                None => format!("/foot{foot}/image at {:.2} s", img.t),
            };
            let mut c = ChartBuilder::on(&left)
                .caption(caption, ("sans-serif", 18))
                .margin(16)
                .build_cartesian_2d(0..img.w as i32, 0..img.h as i32)
                .map_err(pe)?;
            c.configure_mesh().disable_mesh().draw().map_err(pe)?;
            let max = img.px.iter().copied().max().unwrap_or(1).max(1) as f64;
            c.draw_series((0..img.h).flat_map(|r| {
                let px = &img.px;
                (0..img.w).map(move |col| {
                    let v = px[r * img.w + col] as f64 / max;
                    // Row 0 at the top, as the Image panel shows it.
                    let y = (img.h - 1 - r) as i32;
                    Rectangle::new([(col as i32, y), (col as i32 + 1, y + 1)], heat(v).filled())
                })
            }))
            .map_err(pe)?;
        }
        None => {
            left.draw(&Text::new(
                format!("no /foot{foot}/image in this recording"),
                (40, 300),
                ("sans-serif", 18),
            ))
            .map_err(pe)?;
        }
    }

    let panels = right.split_evenly((3, 1));
    let cursor = shown.map(|i| i.t);
    // Terrain: one row per name seen.
    let mut names: BTreeMap<String, usize> = BTreeMap::new();
    for m in truth.iter().chain(&classes).chain(&model) {
        if let Some(n) = m.json["Terrain"].as_str() {
            let k = names.len();
            names.entry(n.to_string()).or_insert(k);
        }
    }
    let row = |m: &Recorded| {
        m.json["Terrain"]
            .as_str()
            .and_then(|n| names.get(n))
            .map(|&i| i as f64)
    };
    let labels: Vec<String> = {
        let mut v: Vec<(usize, String)> = names.iter().map(|(n, &i)| (i, n.clone())).collect();
        v.sort();
        v.into_iter().map(|(_, n)| n).collect()
    };
    {
        let mut c = ChartBuilder::on(&panels[0])
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(80)
            .build_cartesian_2d(0f64..span, -0.5f64..(names.len().max(1) as f64 - 0.5))
            .map_err(pe)?;
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
            .y_desc("Terrain")
            .draw()
            .map_err(pe)?;
        if !truth.is_empty() {
            c.draw_series(LineSeries::new(
                truth.iter().filter_map(|m| Some((t(m), row(m)?))),
                BLACK.stroke_width(2),
            ))
            .map_err(pe)?
            .label("true (/sim/leg)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        }
        c.draw_series(
            classes
                .iter()
                .filter_map(|m| Some(Circle::new((t(m), row(m)?), 4, RED.filled()))),
        )
        .map_err(pe)?
        .label("TerrainClass (one per step)")
        .legend(|(x, y)| Circle::new((x + 10, y), 4, RED.filled()));
        if !model.is_empty() {
            c.draw_series(
                model
                    .iter()
                    .filter_map(|m| Some(Cross::new((t(m), row(m)? + 0.15), 4, BLUE))),
            )
            .map_err(pe)?
            .label("model on the way (/terrain/model)")
            .legend(|(x, y)| Cross::new((x + 10, y), 4, BLUE));
        }
        if let Some(x) = cursor {
            c.draw_series(std::iter::once(PathElement::new(
                vec![(x, -0.5), (x, names.len() as f64 - 0.5)],
                RGBColor(120, 120, 120),
            )))
            .map_err(pe)?;
        }
        legend(&mut c, SeriesLabelPosition::LowerRight)?;
    }
    // Gait in force.
    {
        let mut c = ChartBuilder::on(&panels[1])
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(80)
            .build_cartesian_2d(0f64..span, 0.5f64..3.5f64)
            .map_err(pe)?;
        c.configure_mesh()
            .y_labels(3)
            .y_label_formatter(&|v| format!("G{}", v.round()))
            .y_desc("Gait")
            .draw()
            .map_err(pe)?;
        let pts: Vec<(f64, f64)> = gait
            .iter()
            .filter_map(|m| Some((t(m), m.json["ActiveGait"].as_f64()?)))
            .collect();
        c.draw_series(LineSeries::new(pts, BLUE.stroke_width(2)))
            .map_err(pe)?
            .label("/gait ActiveGait")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
        if let Some(x) = cursor {
            c.draw_series(std::iter::once(PathElement::new(
                vec![(x, 0.5), (x, 3.5)],
                RGBColor(120, 120, 120),
            )))
            .map_err(pe)?;
        }
        legend(&mut c, SeriesLabelPosition::LowerRight)?;
    }
    // Speed: the simulator's truth; a robot's recording has no speed on the bus.
    {
        let pts: Vec<(f64, f64)> = truth
            .iter()
            .filter_map(|m| Some((t(m), m.json["SpeedMps"].as_f64()?)))
            .collect();
        let vmax = pts.iter().map(|p| p.1).fold(0.5, f64::max) * 1.1;
        let mut c = ChartBuilder::on(&panels[2])
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(80)
            .build_cartesian_2d(0f64..span, 0f64..vmax)
            .map_err(pe)?;
        c.configure_mesh()
            .y_desc("Speed (m/s)")
            .x_desc("Time (s)")
            .draw()
            .map_err(pe)?;
        if pts.is_empty() {
            c.draw_series(std::iter::once(Text::new(
                "no /sim/leg speed in this recording (a robot's bus carries none)",
                (span * 0.05, vmax * 0.5),
                ("sans-serif", 16),
            )))
            .map_err(pe)?;
        } else {
            c.draw_series(LineSeries::new(pts, GREEN.stroke_width(2)))
                .map_err(pe)?
                .label("/sim/leg SpeedMps")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], GREEN));
            legend(&mut c, SeriesLabelPosition::LowerRight)?;
        }
    }
    root.present().map_err(pe)?;
    Ok(ViewSummary {
        span_s: span,
        images: images.len(),
        steps: classes.len(),
        model_steps: model.len(),
        image_t_s: cursor,
        has_truth: !truth.is_empty(),
        foot,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heat_runs_from_dark_to_bright() {
        let (lo, hi) = (heat(0.0), heat(1.0));
        assert!(lo.0 as u32 + lo.1 as u32 + lo.2 as u32 <= hi.0 as u32 + hi.1 as u32 + hi.2 as u32);
    }

    #[test]
    fn the_summary_says_what_the_view_shows() {
        let mut s = ViewSummary {
            span_s: 12.34,
            images: 1200,
            steps: 40,
            model_steps: 0,
            image_t_s: Some(11.5),
            has_truth: true,
            foot: 1,
        };
        assert_eq!(
            s.to_string(),
            "12.3 s, 1200 images, 40 TerrainClass of foot 1, with the simulator's truth; image \
             at 11.50 s"
        );
        (s.has_truth, s.image_t_s) = (false, None);
        assert!(s.to_string().ends_with("of foot 1; image at -"), "{s}");
        // A recording of a log with a model's decisions beside it (`presrs mcap --model`)
        // counts those too: it used to say 0 while it plotted them.
        (s.steps, s.model_steps) = (0, 15);
        assert!(
            s.to_string()
                .contains("0 TerrainClass of foot 1 and 15 decided by the model;"),
            "{s}"
        );
    }
}
