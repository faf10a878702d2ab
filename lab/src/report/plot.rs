//! The figures' drawing: the bundled font, feature-vector plots and the legend every figure uses.

use std::path::Path;

use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;

use super::ReportError;

pub(crate) use tools::plot::{pe, register_font};

/// A figure of feature vectors, one line per series.
pub(super) fn feature_plot(
    path: &Path,
    title: &str,
    series: &[(String, Vec<f32>)],
) -> Result<(), ReportError> {
    let root = BitMapBackend::new(path, (1000, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(pe)?;
    draw_features(&root, title, 22, 1e6, series)?;
    Ok(root.present().map_err(pe)?)
}

/// Feature vectors (bins 0-1024 of the 2048-point FFT) on a log axis up to `y_max`, one line
/// per series, with a legend.
pub(super) fn draw_features<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    caption: &str,
    caption_px: u32,
    y_max: f64,
    series: &[(String, Vec<f32>)],
) -> Result<(), ReportError>
where
    DB::ErrorType: 'static,
{
    let colors = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", caption_px))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..1025f64, (1f64..y_max).log_scale())
        .map_err(pe)?;
    chart
        .configure_mesh()
        .x_desc("Frequency bin (of 2048)")
        .y_desc("Magnitude (counts)")
        .draw()
        .map_err(pe)?;
    for (i, (name, v)) in series.iter().enumerate() {
        let color = colors[i % colors.len()];
        chart
            .draw_series(LineSeries::new(
                v.iter()
                    .enumerate()
                    .map(|(k, x)| (k as f64, (*x as f64).max(1.0))),
                color.stroke_width(1),
            ))
            .map_err(pe)?
            .label(name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight)
}

/// The legend every figure uses: boxed, on a nearly opaque white background.
pub(crate) fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), ReportError>
where
    DB::ErrorType: 'static,
{
    Ok(chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()
        .map_err(pe)?)
}
