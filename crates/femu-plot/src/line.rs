//! Line plots: curves, markers, optional log-log axes (convergence plots), a legend.

use crate::axis::Log10Axis;
use crate::colormap::SERIES;
use crate::text::{draw_title, font, log_tick_label, tick_label, Sizes};
use crate::{check_range, check_size, de, finite_min_max, widen, Canvas, PlotError};
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LineStyle {
    /// A line through the points.
    #[default]
    Line,
    /// A marker at each point.
    Markers,
    /// Both.
    LineAndMarkers,
}

/// One curve of a line plot.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Its name in the legend.
    pub label: String,
    /// `(x, y)` points, drawn in the given order; non-finite points are left out.
    pub points: Vec<(f64, f64)>,
    pub style: LineStyle,
}

impl Series {
    /// A series of `style` from its label and points.
    pub fn new(label: &str, points: Vec<(f64, f64)>, style: LineStyle) -> Self {
        Series {
            label: label.to_string(),
            points,
            style,
        }
    }
}

/// The corner of the plot that holds the legend.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LegendPosition {
    /// The corner with the fewest data points (upper right on a tie).
    #[default]
    Auto,
    UpperLeft,
    UpperRight,
    LowerLeft,
    LowerRight,
}

/// Options of [`line_plot_png`].
#[derive(Debug, Clone, PartialEq)]
pub struct LinePlot {
    pub title: String,
    /// Axis descriptions with units, e.g. `"element size h (mm)"`.
    pub x_label: String,
    pub y_label: String,
    /// Logarithmic axes (every value on such an axis must then be positive).
    pub log_x: bool,
    pub log_y: bool,
    /// Axis ranges; by default the data's, padded.
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// Where the legend goes (drawn when there is more than one series); by default the
    /// corner with the fewest points.
    pub legend: LegendPosition,
    /// Picture size (px).
    pub width: u32,
    pub height: u32,
}

impl Default for LinePlot {
    fn default() -> Self {
        LinePlot {
            title: String::new(),
            x_label: String::new(),
            y_label: String::new(),
            log_x: false,
            log_y: false,
            x_range: None,
            y_range: None,
            legend: LegendPosition::Auto,
            width: crate::DEFAULT_WIDTH,
            height: crate::DEFAULT_HEIGHT,
        }
    }
}

/// Writes a line plot of `series` to `path`; a legend is drawn when there is more than one
/// series. Series are told apart by colour (colour-blind-safe palette) and marker shape.
pub fn line_plot_png(path: &Path, series: &[Series], opts: &LinePlot) -> Result<(), PlotError> {
    check_size(opts.width, opts.height)?;
    check_range("x range", opts.x_range)?;
    check_range("y range", opts.y_range)?;
    if series.is_empty() {
        return Err(PlotError::Empty("no series".into()));
    }
    let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
    if series
        .iter()
        .all(|s| s.points.iter().filter(finite).count() == 0)
    {
        return Err(PlotError::Empty("no finite point in any series".into()));
    }
    for (axis, log, get) in [
        (
            "x",
            opts.log_x,
            (|p: &(f64, f64)| p.0) as fn(&(f64, f64)) -> f64,
        ),
        ("y", opts.log_y, |p: &(f64, f64)| p.1),
    ] {
        if !log {
            continue;
        }
        for s in series {
            if let Some(p) = s.points.iter().filter(finite).find(|p| get(p) <= 0.0) {
                return Err(PlotError::InvalidData(format!(
                    "series '{}': point ({}, {}) is not positive on the logarithmic {axis} axis",
                    s.label, p.0, p.1
                )));
            }
        }
    }
    let user = [opts.x_range, opts.y_range];
    for (range, log) in user.iter().zip([opts.log_x, opts.log_y]) {
        if log && range.is_some_and(|r| r.0 <= 0.0) {
            return Err(PlotError::InvalidOption(
                "a logarithmic axis range must be positive".into(),
            ));
        }
    }
    let pts = || series.iter().flat_map(|s| s.points.iter().filter(finite));
    let xr = opts.x_range.unwrap_or_else(|| {
        let (lo, hi) = finite_min_max(pts().map(|p| p.0)).unwrap_or((0.0, 1.0));
        padded(lo, hi, opts.log_x)
    });
    let yr = opts.y_range.unwrap_or_else(|| {
        let (lo, hi) = finite_min_max(pts().map(|p| p.1)).unwrap_or((0.0, 1.0));
        padded(lo, hi, opts.log_y)
    });

    let s = Sizes::new(opts.width, opts.height);
    Canvas::new(opts.width, opts.height).draw_and_save(path, |root| {
        draw_title(root, &opts.title, s)?;
        let area = root.clone().shrink(
            (0, s.title_band()),
            (opts.width, opts.height - s.title_band()),
        );
        let (x0, x1, y0, y1) = (xr.0, xr.1, yr.0, yr.1);
        let lin_x = move |v: &f64| tick_label(*v, x0, x1);
        let lin_y = move |v: &f64| tick_label(*v, y0, y1);
        let log = |v: &f64| log_tick_label(*v);
        let (lx, ly) = (Log10Axis { lo: x0, hi: x1 }, Log10Axis { lo: y0, hi: y1 });
        match (opts.log_x, opts.log_y) {
            (false, false) => draw(&area, x0..x1, y0..y1, &lin_x, &lin_y, series, opts, s),
            (true, false) => draw(&area, lx, y0..y1, &log, &lin_y, series, opts, s),
            (false, true) => draw(&area, x0..x1, ly, &lin_x, &log, series, opts, s),
            (true, true) => draw(&area, lx, ly, &log, &log, series, opts, s),
        }
    })
}

/// The data range with a margin: 4 % of the span on a linear axis, 4 % of the decades on a
/// logarithmic one.
fn padded(lo: f64, hi: f64, log: bool) -> (f64, f64) {
    if log {
        let (a, b) = (lo.log10(), hi.log10());
        let (a, b) = if b > a { (a, b) } else { (a - 0.5, b + 0.5) };
        let m = 0.04 * (b - a);
        (10f64.powf(a - m), 10f64.powf(b + m))
    } else {
        let (lo, hi) = widen(lo, hi);
        let m = 0.04 * (hi - lo);
        (lo - m, hi + m)
    }
}

/// An upward triangle marker about the origin (pixel offsets, y down).
fn triangle(r: i32) -> Vec<(i32, i32)> {
    let h = (r as f64 * 1.25).round() as i32;
    vec![(0, -h), (h, h * 3 / 4), (-h, h * 3 / 4)]
}

/// A diamond marker about the origin.
fn diamond(r: i32) -> Vec<(i32, i32)> {
    let h = (r as f64 * 1.35).round() as i32;
    vec![(0, -h), (h, 0), (0, h), (-h, 0)]
}

#[allow(clippy::too_many_arguments)]
fn draw<X, Y>(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    xr: X,
    yr: Y,
    fx: &dyn Fn(&f64) -> String,
    fy: &dyn Fn(&f64) -> String,
    series: &[Series],
    opts: &LinePlot,
    s: Sizes,
) -> Result<(), String>
where
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let mut chart = ChartBuilder::on(area)
        .margin_left(s.px(16.0))
        .margin_right(s.px(40.0))
        .margin_top(s.px(10.0))
        .margin_bottom(s.px(10.0))
        .x_label_area_size(s.px(80.0))
        .y_label_area_size(s.px(120.0))
        .build_cartesian_2d(xr, yr)
        .map_err(de)?;
    let (pw, ph) = chart.plotting_area().dim_in_pixel();
    chart
        .configure_mesh()
        .set_all_tick_mark_size(s.px(7.0))
        .x_desc(opts.x_label.as_str())
        .y_desc(opts.y_label.as_str())
        .label_style(font(s.tick()))
        .axis_desc_style(font(s.desc()))
        .x_labels(((pw / s.px(110.0)) as usize).clamp(3, 12))
        .y_labels(((ph / s.px(70.0)) as usize).clamp(3, 12))
        .x_label_formatter(fx)
        .y_label_formatter(fy)
        .bold_line_style(RGBColor(215, 215, 215).stroke_width(1))
        .light_line_style(RGBColor(238, 238, 238).stroke_width(1))
        .max_light_lines(4)
        .draw()
        .map_err(de)?;

    let lw = s.px(2.5);
    let r = s.px(6.0) as i32;
    for (i, ser) in series.iter().enumerate() {
        let colour = SERIES[i % SERIES.len()];
        let pts: Vec<(f64, f64)> = ser
            .points
            .iter()
            .copied()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect();
        let line = ser.style != LineStyle::Markers;
        let marks = ser.style != LineStyle::Line;
        if line {
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(lw)))
                .map_err(de)?;
        }
        if marks {
            let st: ShapeStyle = colour.filled();
            let (tri, dia) = (triangle(r), diamond(r));
            match i % 4 {
                0 => chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, r, st)))
                    .map(|_| ()),
                1 => chart
                    .draw_series(
                        pts.iter()
                            .map(|&p| EmptyElement::at(p) + Rectangle::new([(-r, -r), (r, r)], st)),
                    )
                    .map(|_| ()),
                2 => chart
                    .draw_series(
                        pts.iter()
                            .map(|&p| EmptyElement::at(p) + Polygon::new(tri.clone(), st)),
                    )
                    .map(|_| ()),
                _ => chart
                    .draw_series(
                        pts.iter()
                            .map(|&p| EmptyElement::at(p) + Polygon::new(dia.clone(), st)),
                    )
                    .map(|_| ()),
            }
            .map_err(de)?;
        }
        // A zero-length series carries the legend entry (line and/or marker, like the curve).
        let half = s.px(18.0) as i32;
        let seg = if line {
            vec![(-half, 0), (half, 0)]
        } else {
            vec![(0, 0), (0, 0)]
        };
        let lstyle: ShapeStyle = if line {
            colour.stroke_width(lw)
        } else {
            TRANSPARENT.into()
        };
        let mstyle: ShapeStyle = if marks {
            colour.filled()
        } else {
            TRANSPARENT.into()
        };
        let anno = chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(de)?;
        anno.label(ser.label.as_str());
        let base = move |x: i32, y: i32| {
            EmptyElement::at((x + half, y)) + PathElement::new(seg.clone(), lstyle)
        };
        let (tri, dia) = (triangle(r), diamond(r));
        match i % 4 {
            0 => anno.legend(move |(x, y)| base(x, y) + Circle::new((0, 0), r, mstyle)),
            1 => anno.legend(move |(x, y)| base(x, y) + Rectangle::new([(-r, -r), (r, r)], mstyle)),
            2 => anno.legend(move |(x, y)| base(x, y) + Polygon::new(tri.clone(), mstyle)),
            _ => anno.legend(move |(x, y)| base(x, y) + Polygon::new(dia.clone(), mstyle)),
        };
    }
    if series.len() > 1 {
        let pos = match opts.legend {
            LegendPosition::Auto => emptiest_corner(series, &chart),
            LegendPosition::UpperLeft => SeriesLabelPosition::UpperLeft,
            LegendPosition::UpperRight => SeriesLabelPosition::UpperRight,
            LegendPosition::LowerLeft => SeriesLabelPosition::LowerLeft,
            LegendPosition::LowerRight => SeriesLabelPosition::LowerRight,
        };
        chart
            .configure_series_labels()
            .position(pos)
            .margin(s.px(14.0))
            .legend_area_size(s.px(44.0))
            .label_font(font(s.legend()))
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(120, 120, 120))
            .draw()
            .map_err(de)?;
    }
    Ok(())
}

/// The corner of the plotting area with the fewest data points in a box of 40 % x 35 % of
/// the area (upper right, upper left, lower right, lower left on a tie).
fn emptiest_corner<DB: DrawingBackend, X: Ranged<ValueType = f64>, Y: Ranged<ValueType = f64>>(
    series: &[Series],
    chart: &ChartContext<'_, DB, Cartesian2d<X, Y>>,
) -> SeriesLabelPosition {
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let (w, h) = ((xr.end - xr.start) as f64, (yr.end - yr.start) as f64);
    let mut count = [0usize; 4];
    for p in series.iter().flat_map(|s| s.points.iter()) {
        if !(p.0.is_finite() && p.1.is_finite()) {
            continue;
        }
        let (px, py) = chart.backend_coord(p);
        let (u, v) = ((px - xr.start) as f64 / w, (py - yr.start) as f64 / h);
        let (right, left, top, bottom) = (u > 0.6, u < 0.4, v < 0.35, v > 0.65);
        count[0] += usize::from(right && top);
        count[1] += usize::from(left && top);
        count[2] += usize::from(right && bottom);
        count[3] += usize::from(left && bottom);
    }
    let best = (0..4).min_by_key(|&i| (count[i], i)).unwrap_or(0);
    match best {
        0 => SeriesLabelPosition::UpperRight,
        1 => SeriesLabelPosition::UpperLeft,
        2 => SeriesLabelPosition::LowerRight,
        _ => SeriesLabelPosition::LowerLeft,
    }
}
