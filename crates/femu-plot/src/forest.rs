//! Forest plots: one row per estimate, its point and its interval as a horizontal bar, rows
//! labelled on the left (a population's per-subject estimates with their 95 % intervals), an
//! optional vertical reference line (the population median, a reference value).

use crate::axis::Log10Axis;
use crate::colormap::SERIES;
use crate::text::{draw_title, fitting_size, font, log_tick_label, tick_label, Sizes};
use crate::{check_size, de, finite_min_max, widen, Canvas, PlotError};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// One row of a forest plot.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ForestRow {
    pub label: String,
    /// The estimate; a non-finite one leaves the row empty (its label stays).
    pub estimate: f64,
    /// Its interval; non-finite ends draw the point alone.
    pub low: f64,
    pub high: f64,
    /// Colour (and legend entry, see [`ForestPlot::groups`]) of the row.
    pub group: usize,
}

/// Options of [`forest_plot_png`].
#[derive(Debug, Clone, PartialEq)]
pub struct ForestPlot {
    pub title: String,
    /// The value axis, with its unit.
    pub x_label: String,
    /// A logarithmic value axis (every drawn value must then be positive).
    pub log_x: bool,
    /// A vertical line at this value, named in the legend.
    pub reference: Option<(f64, String)>,
    /// Legend names of the row groups (drawn when there are two or more).
    pub groups: Vec<String>,
    pub width: u32,
    /// Picture height (px); `None`: from the number of rows.
    pub height: Option<u32>,
}

impl Default for ForestPlot {
    fn default() -> Self {
        ForestPlot {
            title: String::new(),
            x_label: String::new(),
            log_x: false,
            reference: None,
            groups: Vec::new(),
            width: crate::DEFAULT_WIDTH,
            height: None,
        }
    }
}

/// The height of a forest plot of `rows` rows: a band per row under the title and the axis.
fn auto_height(rows: usize) -> u32 {
    (190 + 44 * rows as u32).clamp(crate::MIN_SIZE.1, 16384)
}

/// Writes a forest plot of `rows` (top to bottom) to `path`.
pub fn forest_plot_png(
    path: &Path,
    rows: &[ForestRow],
    opts: &ForestPlot,
) -> Result<(), PlotError> {
    let height = opts.height.unwrap_or_else(|| auto_height(rows.len()));
    check_size(opts.width, height)?;
    if rows.is_empty() {
        return Err(PlotError::Empty("no row".into()));
    }
    let values = rows
        .iter()
        .flat_map(|r| [r.estimate, r.low, r.high])
        .chain(opts.reference.as_ref().map(|r| r.0))
        .filter(|v| v.is_finite());
    let values: Vec<f64> = values.collect();
    if opts.log_x {
        if let Some(v) = values.iter().find(|v| **v <= 0.0) {
            return Err(PlotError::InvalidData(format!(
                "value {v} is not positive on the logarithmic axis"
            )));
        }
    }
    let (lo, hi) = finite_min_max(values.iter().copied())
        .ok_or_else(|| PlotError::Empty("no finite estimate".into()))?;
    let s = Sizes::new(opts.width, opts.width * 3 / 4);
    Canvas::new(opts.width, height).draw_and_save(path, |root| {
        draw_title(root, &opts.title, s)?;
        let area = root
            .clone()
            .shrink((0, s.title_band()), (opts.width, height - s.title_band()));
        let n = rows.len() as f64;
        let ys = -0.5..(n - 0.5);
        // Room on the right for the legend (upper right), so that it hides no row.
        let legend = if opts.groups.len() >= 2 || opts.reference.is_some() {
            0.75
        } else {
            0.0
        };
        if opts.log_x {
            let (a, b) = (lo.log10(), hi.log10());
            let (a, b) = if b > a { (a, b) } else { (a - 0.3, b + 0.3) };
            let m = 0.06 * (b - a);
            let axis = Log10Axis {
                lo: 10f64.powf(a - m),
                hi: 10f64.powf(b + m + legend * (b - a)),
            };
            draw(&area, axis, ys, &|v| log_tick_label(*v), rows, opts, s)
        } else {
            let (a, b) = widen(lo, hi);
            let m = 0.06 * (b - a);
            let (a, b) = (a - m, b + m + legend * (b - a));
            draw(
                &area,
                a..b,
                ys,
                &move |v| tick_label(*v, a, b),
                rows,
                opts,
                s,
            )
        }
    })
}

fn draw<X, Y>(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    xr: X,
    yr: Y,
    fx: &dyn Fn(&f64) -> String,
    rows: &[ForestRow],
    opts: &ForestPlot,
    s: Sizes,
) -> Result<(), String>
where
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let n = rows.len();
    let labels: Vec<String> = rows.iter().map(|r| r.label.clone()).collect();
    let label_w = opts.width * 3 / 10;
    let size = fitting_size(area, &labels, s.tick(), label_w - s.px(20.0))?;
    let mut chart = ChartBuilder::on(area)
        .margin_left(s.px(16.0))
        .margin_right(s.px(40.0))
        .margin_top(s.px(10.0))
        .margin_bottom(s.px(10.0))
        .x_label_area_size(s.px(80.0))
        .y_label_area_size(label_w)
        .build_cartesian_2d(xr, yr)
        .map_err(de)?;
    // Row k is drawn at y = n - 1 - k (the first row on top).
    let row_y = move |k: usize| (n - 1 - k) as f64;
    let label_of = |v: &f64| {
        let k = v.round();
        if (v - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < n {
            labels[n - 1 - k as usize].clone()
        } else {
            String::new()
        }
    };
    let (pw, _) = chart.plotting_area().dim_in_pixel();
    chart
        .configure_mesh()
        .disable_y_mesh()
        .set_all_tick_mark_size(s.px(7.0))
        .x_desc(opts.x_label.as_str())
        .label_style(font(s.tick()))
        .y_label_style(font(size))
        .axis_desc_style(font(s.desc()))
        .x_labels(((pw / s.px(110.0)) as usize).clamp(3, 12))
        .y_labels(n + 1)
        .x_label_formatter(fx)
        .y_label_formatter(&label_of)
        .bold_line_style(RGBColor(215, 215, 215).stroke_width(1))
        .light_line_style(RGBColor(238, 238, 238).stroke_width(1))
        .max_light_lines(4)
        .draw()
        .map_err(de)?;
    if let Some((x, name)) = &opts.reference {
        let grey = RGBColor(110, 110, 110);
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(*x, -0.5), (*x, n as f64 - 0.5)],
                grey.stroke_width(s.px(2.0)),
            )))
            .map_err(de)?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y - 8), (x, y + 8)], grey.stroke_width(2))
            });
    }
    let r = s.px(7.0) as i32;
    let half = 0.18;
    for (k, row) in rows.iter().enumerate() {
        if !row.estimate.is_finite() {
            continue;
        }
        let c = SERIES[row.group % SERIES.len()];
        let y = row_y(k);
        if row.low.is_finite() && row.high.is_finite() {
            let bar = c.stroke_width(s.px(3.0));
            chart
                .draw_series([
                    PathElement::new(vec![(row.low, y), (row.high, y)], bar),
                    PathElement::new(vec![(row.low, y - half), (row.low, y + half)], bar),
                    PathElement::new(vec![(row.high, y - half), (row.high, y + half)], bar),
                ])
                .map_err(de)?;
        }
        chart
            .draw_series(std::iter::once(Circle::new(
                (row.estimate, y),
                r,
                c.filled(),
            )))
            .map_err(de)?;
    }
    if opts.groups.len() >= 2 {
        for (g, name) in opts.groups.iter().enumerate() {
            let c = SERIES[g % SERIES.len()];
            chart
                .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                .map_err(de)?
                .label(name.as_str())
                .legend(move |(x, y)| Circle::new((x, y), r, c.filled()));
        }
    }
    if opts.groups.len() >= 2 || opts.reference.is_some() {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .margin(s.px(14.0))
            .legend_area_size(s.px(44.0))
            .label_font(font(s.legend()))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .draw()
            .map_err(de)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_and_bad_input() {
        let dir = std::env::temp_dir().join(format!("femu-plot-forest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rows: Vec<ForestRow> = (0..5)
            .map(|k| ForestRow {
                label: format!("subject {k}"),
                estimate: 1.0 + 0.1 * k as f64,
                low: 0.9 + 0.1 * k as f64,
                high: 1.2 + 0.1 * k as f64,
                group: k % 2,
            })
            .collect();
        let opts = ForestPlot {
            title: "C10 of the fat".into(),
            x_label: "C10 (kPa)".into(),
            reference: Some((1.2, "median".into())),
            groups: vec!["left".into(), "right".into()],
            ..Default::default()
        };
        let p = dir.join("f.png");
        forest_plot_png(&p, &rows, &opts).unwrap();
        let img = image::open(&p).unwrap();
        assert_eq!(img.height(), auto_height(5));
        let log = ForestPlot {
            log_x: true,
            ..opts.clone()
        };
        forest_plot_png(&dir.join("g.png"), &rows, &log).unwrap();
        assert!(forest_plot_png(&dir.join("e.png"), &[], &opts).is_err());
        let mut bad = rows.clone();
        bad[0].low = -1.0;
        assert!(matches!(
            forest_plot_png(&dir.join("h.png"), &bad, &log),
            Err(PlotError::InvalidData(_))
        ));
        std::fs::remove_dir_all(&dir).ok();
    }
}
