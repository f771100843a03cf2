//! Bar charts (grouped, with error bars) and histograms.

use crate::colormap::SERIES;
use crate::text::{draw_title, fitting_size, font, tick_label, Sizes};
use crate::{check_range, check_size, de, finite_min_max, widen, Canvas, PlotError};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// Options of [`bar_chart_png`].
#[derive(Debug, Clone, PartialEq)]
pub struct BarChart {
    pub title: String,
    /// Description of the categories (may be empty).
    pub x_label: String,
    /// Description of the values with their unit, e.g. `"relative error (%)"`.
    pub y_label: String,
    /// Value axis range; by default from 0 (or the lowest bar) to the highest bar, with room
    /// for the legend.
    pub y_range: Option<(f64, f64)>,
    /// Picture size (px).
    pub width: u32,
    pub height: u32,
}

impl Default for BarChart {
    fn default() -> Self {
        BarChart {
            title: String::new(),
            x_label: String::new(),
            y_label: String::new(),
            y_range: None,
            width: crate::DEFAULT_WIDTH,
            height: crate::DEFAULT_HEIGHT,
        }
    }
}

/// Options of [`histogram_png`].
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    pub title: String,
    /// Description of the values with their unit, e.g. `"grey level (-)"`.
    pub x_label: String,
    /// Description of the counts (default `"count"`).
    pub y_label: String,
    /// The binned range; by default the finite values' minimum and maximum. Values outside
    /// it are not counted.
    pub range: Option<(f64, f64)>,
    /// Write `n`, mean and standard deviation of the counted values in the upper right.
    pub stats: bool,
    /// Picture size (px).
    pub width: u32,
    pub height: u32,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            title: String::new(),
            x_label: String::new(),
            y_label: "count".into(),
            range: None,
            stats: true,
            width: crate::DEFAULT_WIDTH,
            height: crate::DEFAULT_HEIGHT,
        }
    }
}

/// A chart with one x-axis category per integer `0..n` (x from -0.5 to n - 0.5) and a linear
/// value axis, under the title; returns the chart.
fn category_chart<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    x: (f64, f64),
    y: (f64, f64),
    s: Sizes,
) -> Result<ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>, String>
{
    ChartBuilder::on(area)
        .margin_left(s.px(16.0))
        .margin_right(s.px(40.0))
        .margin_top(s.px(10.0))
        .margin_bottom(s.px(10.0))
        .x_label_area_size(s.px(90.0))
        .y_label_area_size(s.px(120.0))
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(de)
}

/// Writes a grouped bar chart to `path`: one group of bars per category, one bar per series
/// of `groups` (`(label, one value per category)`), with optional symmetric error bars
/// (`error_bars[g][c]` is the half-length for group `g`, category `c`). NaN values are left out.
pub fn bar_chart_png(
    path: &Path,
    categories: &[String],
    groups: &[(String, Vec<f64>)],
    error_bars: Option<&[Vec<f64>]>,
    opts: &BarChart,
) -> Result<(), PlotError> {
    check_size(opts.width, opts.height)?;
    check_range("y range", opts.y_range)?;
    if categories.is_empty() {
        return Err(PlotError::Empty("no category".into()));
    }
    if groups.is_empty() {
        return Err(PlotError::Empty("no group of bars".into()));
    }
    let nc = categories.len();
    for (label, v) in groups {
        if v.len() != nc {
            return Err(PlotError::LengthMismatch {
                what: format!("bar group '{label}' (one value per category)"),
                expected: nc,
                found: v.len(),
            });
        }
    }
    if let Some(err) = error_bars {
        if err.len() != groups.len() {
            return Err(PlotError::LengthMismatch {
                what: "error bars (one list per group)".into(),
                expected: groups.len(),
                found: err.len(),
            });
        }
        for (g, e) in err.iter().enumerate() {
            if e.len() != nc {
                return Err(PlotError::LengthMismatch {
                    what: format!("error bars of group '{}'", groups[g].0),
                    expected: nc,
                    found: e.len(),
                });
            }
            if let Some(bad) = e.iter().find(|x| **x < 0.0 || x.is_infinite()) {
                return Err(PlotError::InvalidData(format!(
                    "error bar {bad} of group '{}' is negative or infinite",
                    groups[g].0
                )));
            }
        }
    }
    let err_of = |g: usize, c: usize| {
        error_bars
            .map(|e| e[g][c])
            .filter(|e| e.is_finite())
            .unwrap_or(0.0)
    };
    let mut tops = Vec::new();
    for (g, (_, v)) in groups.iter().enumerate() {
        for (c, &x) in v.iter().enumerate() {
            if x.is_finite() {
                tops.push(x + err_of(g, c));
                tops.push(x - err_of(g, c));
            }
        }
    }
    let (dlo, dhi) = finite_min_max(tops)
        .ok_or_else(|| PlotError::Empty("every bar value is NaN or infinite".into()))?;
    let s = Sizes::new(opts.width, opts.height);
    let legend = groups.len() > 1;
    let yr = opts.y_range.unwrap_or_else(|| {
        let (lo, hi) = widen(dlo.min(0.0), dhi.max(0.0));
        let span = hi - lo;
        // Room above the bars for the legend (about 34 px per entry on ~650 px of plot).
        let head = if legend {
            0.08 + 0.055 * groups.len() as f64
        } else {
            0.06
        };
        let lo = if lo < 0.0 { lo - 0.06 * span } else { lo };
        (lo, hi + head * span / (1.0 - head))
    });

    Canvas::new(opts.width, opts.height).draw_and_save(path, |root| {
        draw_title(root, &opts.title, s)?;
        let area = root.clone().shrink(
            (0, s.title_band()),
            (opts.width, opts.height - s.title_band()),
        );
        let (y0, y1) = yr;
        let mut chart = category_chart(&area, (-0.5, nc as f64 - 0.5), yr, s)?;
        let (_, ph) = chart.plotting_area().dim_in_pixel();
        chart
            .configure_mesh()
            .set_all_tick_mark_size(s.px(7.0))
            .disable_x_mesh()
            .x_labels(0)
            .x_desc(opts.x_label.as_str())
            .y_desc(opts.y_label.as_str())
            .label_style(font(s.tick()))
            .axis_desc_style(font(s.desc()))
            .y_labels(((ph / s.px(70.0)) as usize).clamp(3, 12))
            .y_label_formatter(&|v| tick_label(*v, y0, y1))
            .bold_line_style(RGBColor(220, 220, 220).stroke_width(1))
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(de)?;

        let ng = groups.len();
        let bw = 0.8 / ng as f64;
        let x_of = |g: usize, c: usize| c as f64 - 0.4 + (g as f64 + 0.5) * bw;
        for (g, (label, v)) in groups.iter().enumerate() {
            let colour = SERIES[g % SERIES.len()];
            let bars = v.iter().enumerate().filter(|(_, x)| x.is_finite());
            chart
                .draw_series(bars.clone().map(|(c, &x)| {
                    let xm = x_of(g, c);
                    Rectangle::new([(xm - 0.5 * bw, 0.0), (xm + 0.5 * bw, x)], colour.filled())
                }))
                .map_err(de)?
                .label(label.as_str())
                .legend(move |(x, y)| {
                    let h = s.px(9.0) as i32;
                    Rectangle::new([(x, y - h), (x + 2 * h + 4, y + h)], colour.filled())
                });
            chart
                .draw_series(bars.map(|(c, &x)| {
                    let xm = x_of(g, c);
                    Rectangle::new(
                        [(xm - 0.5 * bw, 0.0), (xm + 0.5 * bw, x)],
                        BLACK.stroke_width(1),
                    )
                }))
                .map_err(de)?;
            if error_bars.is_some() {
                // A vertical line with caps (plotters' ErrorBar also draws a circle at the mean).
                let cap = 0.2 * bw;
                let stroke = BLACK.stroke_width(s.px(2.0));
                let whiskers = v
                    .iter()
                    .enumerate()
                    .filter(|(c, x)| x.is_finite() && err_of(g, *c) > 0.0)
                    .flat_map(|(c, &x)| {
                        let (xm, e) = (x_of(g, c), err_of(g, c));
                        [
                            vec![(xm, x - e), (xm, x + e)],
                            vec![(xm - cap, x - e), (xm + cap, x - e)],
                            vec![(xm - cap, x + e), (xm + cap, x + e)],
                        ]
                    });
                chart
                    .draw_series(whiskers.map(|p| PathElement::new(p, stroke)))
                    .map_err(de)?;
            }
        }
        // The zero line, when bars go both ways.
        if y0 < 0.0 && y1 > 0.0 {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(-0.5, 0.0), (nc as f64 - 0.5, 0.0)],
                    BLACK.stroke_width(1),
                )))
                .map_err(de)?;
        }
        // Category names under the axis, shrunk to fit their slot.
        let slot = {
            let a = chart.backend_coord(&(0.0, y0));
            let b = chart.backend_coord(&(1.0, y0));
            (b.0 - a.0).max(10) as u32
        };
        let size = fitting_size(root, categories, s.legend(), slot.saturating_sub(s.px(8.0)))?;
        for (c, name) in categories.iter().enumerate() {
            let (x, y) = chart.backend_coord(&(c as f64, y0));
            root.draw(&Text::new(
                name.clone(),
                (x, y + s.px(12.0) as i32),
                font(size).pos(Pos::new(HPos::Center, VPos::Top)),
            ))
            .map_err(de)?;
        }
        if legend {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .margin(s.px(12.0))
                .legend_area_size(s.px(34.0))
                .label_font(font(s.legend()))
                .background_style(WHITE.mix(0.9))
                .border_style(RGBColor(120, 120, 120))
                .draw()
                .map_err(de)?;
        }
        Ok(())
    })
}

/// Writes a histogram of the finite `values` in `bins` equal bins to `path`.
pub fn histogram_png(
    path: &Path,
    values: &[f64],
    bins: usize,
    opts: &Histogram,
) -> Result<(), PlotError> {
    check_size(opts.width, opts.height)?;
    check_range("range", opts.range)?;
    if bins == 0 || bins > 100_000 {
        return Err(PlotError::InvalidOption(format!(
            "{bins} bins: give 1 to 100000"
        )));
    }
    if values.is_empty() {
        return Err(PlotError::Empty("no value".into()));
    }
    let (lo, hi) = match opts.range {
        Some(r) => r,
        None => {
            let (lo, hi) = finite_min_max(values.iter().copied())
                .ok_or_else(|| PlotError::Empty("every value is NaN or infinite".into()))?;
            widen(lo, hi)
        }
    };
    let width = (hi - lo) / bins as f64;
    let mut counts = vec![0usize; bins];
    let (mut n, mut sum, mut sum2) = (0usize, 0.0, 0.0);
    for &v in values {
        if v.is_finite() && v >= lo && v <= hi {
            let b = (((v - lo) / width) as usize).min(bins - 1);
            counts[b] += 1;
            n += 1;
            sum += v;
            sum2 += v * v;
        }
    }
    let cmax = counts.iter().copied().max().unwrap_or(0).max(1) as f64;
    let s = Sizes::new(opts.width, opts.height);
    let head = if opts.stats { 0.16 } else { 0.06 };
    let yr = (0.0, cmax / (1.0 - head));

    Canvas::new(opts.width, opts.height).draw_and_save(path, |root| {
        draw_title(root, &opts.title, s)?;
        let area = root.clone().shrink(
            (0, s.title_band()),
            (opts.width, opts.height - s.title_band()),
        );
        let mut chart = ChartBuilder::on(&area)
            .margin_left(s.px(16.0))
            .margin_right(s.px(40.0))
            .margin_top(s.px(10.0))
            .margin_bottom(s.px(10.0))
            .x_label_area_size(s.px(80.0))
            .y_label_area_size(s.px(120.0))
            .build_cartesian_2d(lo..hi, yr.0..yr.1)
            .map_err(de)?;
        let (pw, ph) = chart.plotting_area().dim_in_pixel();
        chart
            .configure_mesh()
            .set_all_tick_mark_size(s.px(7.0))
            .disable_x_mesh()
            .x_desc(opts.x_label.as_str())
            .y_desc(opts.y_label.as_str())
            .label_style(font(s.tick()))
            .axis_desc_style(font(s.desc()))
            .x_labels(((pw / s.px(110.0)) as usize).clamp(3, 12))
            .y_labels(((ph / s.px(70.0)) as usize).clamp(3, 12))
            .x_label_formatter(&|v| tick_label(*v, lo, hi))
            .y_label_formatter(&|v| {
                if v.fract() == 0.0 {
                    format!("{v:.0}")
                } else {
                    String::new()
                }
            })
            .bold_line_style(RGBColor(220, 220, 220).stroke_width(1))
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(de)?;
        let fill = RGBColor(70, 120, 170);
        let edge = if bins as u32 * 4 <= pw {
            RGBColor(30, 55, 85).stroke_width(1)
        } else {
            fill.stroke_width(1)
        };
        let rect = |b: usize| {
            [
                (lo + b as f64 * width, 0.0),
                (lo + (b + 1) as f64 * width, counts[b] as f64),
            ]
        };
        let nonzero = (0..bins).filter(|&b| counts[b] > 0);
        chart
            .draw_series(
                nonzero
                    .clone()
                    .map(|b| Rectangle::new(rect(b), fill.filled())),
            )
            .map_err(de)?;
        chart
            .draw_series(nonzero.map(|b| Rectangle::new(rect(b), edge)))
            .map_err(de)?;
        if opts.stats && n > 0 {
            let mean = sum / n as f64;
            let var = (sum2 / n as f64 - mean * mean).max(0.0) * n as f64 / (n.max(2) - 1) as f64;
            let fmt = |v: f64| tick_label(v, lo.min(0.0) - (hi - lo), hi + (hi - lo));
            let text = [
                format!("n = {n}"),
                format!("mean = {}", fmt(mean)),
                format!("sd = {}", fmt(var.sqrt())),
            ];
            let (px, py) = chart.plotting_area().get_pixel_range();
            let line = s.px(26.0) as i32;
            for (i, t) in text.iter().enumerate() {
                root.draw(&Text::new(
                    t.clone(),
                    (
                        px.end - s.px(14.0) as i32,
                        py.start + s.px(12.0) as i32 + i as i32 * line,
                    ),
                    font(s.legend()).pos(Pos::new(HPos::Right, VPos::Top)),
                ))
                .map_err(de)?;
            }
        }
        Ok(())
    })
}
