//! The figures of `femu` as PNG files, for reports and papers.
//!
//! The last stage of the pipeline (geometry and mesh → mechanics → DIC → identification →
//! report and plots). Every function writes one PNG (1200 x 900 px by default) with a title, axes
//! with units, and a colour bar wherever colours carry values:
//!
//! - [`mesh_field_png`]: one value per element on the (optionally deformed) mesh;
//! - [`node_field_png`]: one value per node, interpolated linearly over each triangle (a quad is
//!   split along its 1–3 diagonal);
//! - [`line_plot_png`]: curves with optional log-log axes (convergence plots);
//! - [`bar_chart_png`]: grouped bars with optional error bars (identified parameters per tissue);
//! - [`histogram_png`]: grey levels, errors;
//! - [`image_field_png`]: a per-pixel field over a grey image (DIC maps);
//! - [`box_plot_png`]: distributions per group (DIC random error per pair, a population's
//!   parameters per tissue);
//! - [`forest_plot_png`]: estimates with their intervals, one row each (per-subject results);
//! - [`overlay::outline_overlay_png`]: outlines (solid or dashed, one colour per set) over a
//!   grey image, axes in mm (an image's pose in a model, before and after a refinement).
//!
//! Drawing uses `plotters`' bitmap backend; text uses the DejaVu Sans font embedded by the
//! `dejavu` crate (no system font library needed), registered once per process; the PNG is
//! encoded by `image`. Colour maps are perceptual: viridis for one-sided data and a blue–white–red
//! map (ColorBrewer RdBu) symmetric about zero for signed data.
//!
//! Bad input (empty data, mismatched lengths, invalid ranges, non-positive values on a log axis)
//! is a [`PlotError`], never a panic. NaN values are skipped (cells drawn grey, points left out).

#![forbid(unsafe_code)]

mod axis;
mod boxplot;
mod chart;
mod colorbar;
pub mod colormap;
mod field;
mod forest;
mod image_field;
mod line;
pub mod overlay;
mod text;
mod tile;

pub use boxplot::{box_plot_png, quantile, BoxPlot};
pub use chart::{bar_chart_png, histogram_png, BarChart, Histogram};
pub use field::{mesh_field_png, node_field_png, FieldPlot, Overlay};
pub use forest::{forest_plot_png, ForestPlot, ForestRow};
pub use image_field::{image_field_png, ImageField};
pub use line::{line_plot_png, LegendPosition, LinePlot, LineStyle, Series};
pub use tile::tile_png;

use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Default picture width (px).
pub const DEFAULT_WIDTH: u32 = 1200;
/// Default picture height (px).
pub const DEFAULT_HEIGHT: u32 = 900;
/// Smallest accepted picture size (px): below it the text would not fit.
pub const MIN_SIZE: (u32, u32) = (320, 240);

/// Errors of the plotting functions.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Nothing to draw: no element, no series, no value, no category.
    #[error("nothing to plot: {0}")]
    Empty(String),
    /// An input slice does not have the length the others imply.
    #[error("{what}: expected {expected} values, got {found}")]
    LengthMismatch {
        what: String,
        expected: usize,
        found: usize,
    },
    /// Input data that cannot be drawn (a node index out of range, a non-finite coordinate,
    /// a non-positive value on a log axis, every value NaN, ...).
    #[error("invalid data: {0}")]
    InvalidData(String),
    /// An option out of its range (picture size, value range, number of bins, ...).
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// The embedded font could not be registered.
    #[error("cannot register the embedded DejaVu Sans font: {0}")]
    Font(String),
    /// Drawing failed (the plotting backend reported an error).
    #[error("{path}: drawing failed: {message}")]
    Draw { path: PathBuf, message: String },
    /// The PNG could not be encoded or written.
    #[error("{path}: cannot write the PNG: {message}")]
    Write { path: PathBuf, message: String },
}

/// Registers DejaVu Sans as plotters' "sans-serif" font, once per process; later calls return
/// the first outcome.
pub(crate) fn ensure_font() -> Result<(), PlotError> {
    static FONT: OnceLock<Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .map_err(|_| "the font data is not a valid TrueType font".to_string())
    })
    .clone()
    .map_err(PlotError::Font)
}

/// Checks the picture size of an options struct.
pub(crate) fn check_size(width: u32, height: u32) -> Result<(), PlotError> {
    if width < MIN_SIZE.0 || height < MIN_SIZE.1 || width > 16384 || height > 16384 {
        return Err(PlotError::InvalidOption(format!(
            "picture size {width} x {height} px is outside {} x {} .. 16384 x 16384",
            MIN_SIZE.0, MIN_SIZE.1
        )));
    }
    Ok(())
}

/// Checks an optional user range `(lo, hi)`: finite and `lo < hi`.
pub(crate) fn check_range(name: &str, range: Option<(f64, f64)>) -> Result<(), PlotError> {
    if let Some((lo, hi)) = range {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(PlotError::InvalidOption(format!(
                "{name} ({lo}, {hi}) must be finite with lo < hi"
            )));
        }
    }
    Ok(())
}

/// An RGB picture being drawn: the buffer and its size.
pub(crate) struct Canvas {
    pub buf: Vec<u8>,
    pub width: u32,
    pub height: u32,
}

impl Canvas {
    pub fn new(width: u32, height: u32) -> Self {
        Canvas {
            buf: vec![255u8; width as usize * height as usize * 3],
            width,
            height,
        }
    }

    /// Runs `draw` on a white drawing area over the buffer, then writes the PNG to `path`.
    pub fn draw_and_save<F>(mut self, path: &Path, draw: F) -> Result<(), PlotError>
    where
        F: FnOnce(&DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>) -> Result<(), String>,
    {
        ensure_font()?;
        let draw_err = |message: String| PlotError::Draw {
            path: path.to_path_buf(),
            message,
        };
        {
            let root = BitMapBackend::with_buffer(&mut self.buf, (self.width, self.height))
                .into_drawing_area();
            root.fill(&WHITE).map_err(|e| draw_err(e.to_string()))?;
            draw(&root).map_err(draw_err)?;
            root.present().map_err(|e| draw_err(e.to_string()))?;
        }
        let write_err = |message: String| PlotError::Write {
            path: path.to_path_buf(),
            message,
        };
        let img = image::RgbImage::from_raw(self.width, self.height, self.buf)
            .ok_or_else(|| write_err("picture buffer has the wrong size".into()))?;
        save_png(path, &img).map_err(|e| write_err(e.to_string()))
    }
}

/// Writes `img` as a PNG file, whole or not at all ([`femu_mesh::atomic`]): fast deflate, each
/// row filtered against the row above ("Up"). The figures' rows mostly repeat the row above (a
/// white margin, an enlarged image's repeated rows, the axes), which Up turns into zeros at a
/// fraction of the cost of trying every filter on every row; the files are about a quarter
/// larger than with that adaptive choice.
pub fn save_png<P, C>(path: &Path, img: &image::ImageBuffer<P, C>) -> Result<(), image::ImageError>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::{EncodableLayout, ImageEncoder};
    let samples: &[P::Subpixel] = img;
    femu_mesh::atomic::write_with(path, |f| {
        PngEncoder::new_with_quality(f, CompressionType::Fast, FilterType::Up).write_image(
            samples.as_bytes(),
            img.width(),
            img.height(),
            P::COLOR_TYPE,
        )
    })
}

/// Converts any displayable drawing error into the message carried by [`PlotError::Draw`].
pub(crate) fn de<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// The scale of fonts and line widths: 1 at the default 1200 x 900 px.
pub(crate) fn scale_of(width: u32, height: u32) -> f64 {
    (width as f64 / DEFAULT_WIDTH as f64).min(height as f64 / DEFAULT_HEIGHT as f64)
}

/// Minimum and maximum of the finite values, `None` if there is none.
pub(crate) fn finite_min_max(values: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
}

/// Widens a degenerate range (`lo == hi`) so that it can be drawn.
pub(crate) fn widen(lo: f64, hi: f64) -> (f64, f64) {
    if hi > lo {
        (lo, hi)
    } else {
        let d = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        (lo - d, hi + d)
    }
}
