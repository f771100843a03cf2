//! Box plots: one box per group (median, quartiles, whiskers to the most extreme values within
//! 1.5 interquartile ranges, points beyond drawn as outliers), Tukey's convention; optionally
//! every value drawn over its box (a population of a few dozen subjects).

use crate::colormap::SERIES;
use crate::text::{draw_title, font, tick_label, Sizes};
use crate::{check_size, de, finite_min_max, widen, Canvas, PlotError};
use plotters::prelude::*;
use std::path::Path;

/// Options of [`box_plot_png`].
#[derive(Debug, Clone, PartialEq)]
pub struct BoxPlot {
    pub title: String,
    pub y_label: String,
    /// Every value drawn as a dot over its box (spread sideways so that equal values stay
    /// apart), instead of the outliers alone.
    pub points: bool,
    pub width: u32,
    pub height: u32,
}

impl Default for BoxPlot {
    fn default() -> Self {
        BoxPlot {
            title: String::new(),
            y_label: String::new(),
            points: false,
            width: crate::DEFAULT_WIDTH,
            height: crate::DEFAULT_HEIGHT,
        }
    }
}

/// The `q`-quantile of `sorted` (ascending, not empty) by linear interpolation between order
/// statistics (type 7, R's default).
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    let h = (sorted.len() - 1) as f64 * q;
    let (i, f) = (h.floor() as usize, h - h.floor());
    if i + 1 < sorted.len() {
        sorted[i] + f * (sorted[i + 1] - sorted[i])
    } else {
        sorted[i]
    }
}

/// The sideways offset of the `i`-th dot of a group: a low-discrepancy (golden ratio) sequence
/// within ±0.2 of the box's centre, the same for every run.
fn spread(i: usize) -> f64 {
    let t = (i as f64 * 0.618_033_988_749_895).fract();
    0.4 * (t - 0.5)
}

/// Writes a box plot of `groups` (`(name, values)`; NaN values are left out).
pub fn box_plot_png(
    path: &Path,
    groups: &[(String, Vec<f64>)],
    opts: &BoxPlot,
) -> Result<(), PlotError> {
    check_size(opts.width, opts.height)?;
    if groups.is_empty() {
        return Err(PlotError::Empty("no group".into()));
    }
    let mut stats = Vec::new();
    for (name, v) in groups {
        let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        if s.is_empty() {
            return Err(PlotError::Empty(format!(
                "group '{name}' has no finite value"
            )));
        }
        s.sort_by(|a, b| a.total_cmp(b));
        let (q1, med, q3) = (quantile(&s, 0.25), quantile(&s, 0.5), quantile(&s, 0.75));
        let iqr = q3 - q1;
        let lo = *s.iter().find(|&&x| x >= q1 - 1.5 * iqr).unwrap_or(&s[0]);
        let hi = *s
            .iter()
            .rev()
            .find(|&&x| x <= q3 + 1.5 * iqr)
            .unwrap_or(&s[s.len() - 1]);
        let out: Vec<f64> = s.iter().copied().filter(|&x| x < lo || x > hi).collect();
        stats.push((name.clone(), q1, med, q3, lo, hi, out));
    }
    let all = groups.iter().flat_map(|g| g.1.iter().copied());
    let (ylo, yhi) = finite_min_max(all).ok_or_else(|| PlotError::Empty("no value".into()))?;
    let (ylo, yhi) = widen(ylo, yhi);
    let pad = 0.08 * (yhi - ylo);
    let (ylo, yhi) = (ylo - pad, yhi + pad);
    let s = Sizes::new(opts.width, opts.height);
    let n = stats.len();
    Canvas::new(opts.width, opts.height).draw_and_save(path, |root| {
        draw_title(root, &opts.title, s)?;
        let area = root
            .clone()
            .margin(s.title_band(), s.px(20.0), s.px(20.0), s.px(30.0));
        let mut chart = ChartBuilder::on(&area)
            .x_label_area_size(s.px(60.0))
            .y_label_area_size(s.px(110.0))
            .build_cartesian_2d(-0.5..(n as f64 - 0.5), ylo..yhi)
            .map_err(de)?;
        let names: Vec<String> = stats.iter().map(|t| t.0.clone()).collect();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .y_desc(opts.y_label.as_str())
            .label_style(font(s.tick()))
            .axis_desc_style(font(s.desc()))
            .x_labels(n.max(2))
            .x_label_formatter(&|v| {
                let k = v.round();
                if (v - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < names.len() {
                    names[k as usize].clone()
                } else {
                    String::new()
                }
            })
            .y_label_formatter(&|v| tick_label(*v, ylo, yhi))
            .draw()
            .map_err(de)?;
        for (k, (_, q1, med, q3, lo, hi, out)) in stats.iter().enumerate() {
            let x = k as f64;
            let c = SERIES[k % SERIES.len()];
            let w = 0.3;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x - w, *q1), (x + w, *q3)],
                    c.mix(0.35).filled(),
                )))
                .map_err(de)?;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x - w, *q1), (x + w, *q3)],
                    c.stroke_width(s.px(2.0)),
                )))
                .map_err(de)?;
            let line = |a: (f64, f64), b: (f64, f64)| {
                PathElement::new(vec![a, b], BLACK.stroke_width(s.px(2.0)))
            };
            chart
                .draw_series([
                    line((x - w, *med), (x + w, *med)),
                    line((x, *q3), (x, *hi)),
                    line((x, *q1), (x, *lo)),
                    line((x - 0.5 * w, *hi), (x + 0.5 * w, *hi)),
                    line((x - 0.5 * w, *lo), (x + 0.5 * w, *lo)),
                ])
                .map_err(de)?;
            if !opts.points {
                chart
                    .draw_series(
                        out.iter()
                            .map(|&v| Circle::new((x, v), s.px(5.0), BLACK.stroke_width(1))),
                    )
                    .map_err(de)?;
            }
        }
        if opts.points {
            for (k, (_, values)) in groups.iter().enumerate() {
                let dots = values.iter().filter(|v| v.is_finite()).enumerate();
                chart
                    .draw_series(dots.map(|(i, &v)| {
                        Circle::new(
                            (k as f64 + spread(i), v),
                            s.px(6.0),
                            BLACK.mix(0.7).filled(),
                        )
                    }))
                    .map_err(de)?;
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quartiles_and_png() {
        let s = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&s, 0.25), 2.0);
        assert_eq!(quantile(&s, 0.5), 3.0);
        let dir = std::env::temp_dir().join(format!("femu-plot-box-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let g = vec![
            ("ux".to_string(), vec![0.1, 0.2, 0.15, 0.3, 0.9]),
            ("uy".to_string(), vec![0.05, 0.1, 0.12, 0.08]),
        ];
        box_plot_png(&dir.join("b.png"), &g, &BoxPlot::default()).unwrap();
        let dots = BoxPlot {
            points: true,
            ..Default::default()
        };
        box_plot_png(&dir.join("d.png"), &g, &dots).unwrap();
        assert!((0..100).all(|i| spread(i).abs() <= 0.2));
        assert!(box_plot_png(&dir.join("c.png"), &[], &BoxPlot::default()).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
