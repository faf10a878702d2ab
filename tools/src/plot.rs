//! What every figure shares: the bundled font (plotters finds no system fonts on a robot's
//! computer or a CI machine) and the one error a drawing returns.

use plotters::style::FontStyle;

/// Why a figure could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Drawing or writing the figure.
    #[error("drawing a figure: {0}")]
    Draw(String),
    /// The bundled font.
    #[error("the bundled font tools/assets/fonts/DejaVuSans.ttf is unreadable")]
    Font,
}

/// Registers the bundled font as "sans-serif".
pub fn register_font() -> Result<(), PlotError> {
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        include_bytes!("../assets/fonts/DejaVuSans.ttf"),
    )
    .map_err(|_| PlotError::Font)
}

/// A plotters error as a [`PlotError`].
pub fn pe(e: impl std::fmt::Display) -> PlotError {
    PlotError::Draw(e.to_string())
}
