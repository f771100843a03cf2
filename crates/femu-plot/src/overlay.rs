//! Outlines over an image: a grey frame (an ultrasound B-mode image) with sets of line
//! segments drawn on it, each set in its own colour, solid or dashed, with a legend; axes in
//! mm (lateral across, depth down, as the image is displayed). Used to check an image's pose
//! in a model at a glance: the model's skin and interfaces before and after a refinement.

use crate::image_field::draw_image_axes;
use crate::text::{draw_title, font, Sizes};
use crate::{check_size, de, Canvas, PlotError};
use plotters::prelude::*;
use std::path::Path;

/// One set of segments, in image pixel coordinates (centres at integers, y down).
#[derive(Debug, Clone)]
pub struct OutlineSet {
    /// Its name in the legend.
    pub label: String,
    pub segments_px: Vec<[[f64; 2]; 2]>,
    pub color: (u8, u8, u8),
    pub dashed: bool,
}

/// Options of [`outline_overlay_png`].
#[derive(Debug, Clone)]
pub struct OverlayOptions {
    pub title: String,
    /// Line width at the default picture size (px).
    pub line_width: f64,
    pub width: u32,
    pub height: u32,
}

impl Default for OverlayOptions {
    fn default() -> Self {
        OverlayOptions {
            title: String::new(),
            line_width: 2.0,
            width: crate::DEFAULT_WIDTH,
            height: crate::DEFAULT_HEIGHT,
        }
    }
}

/// Writes a PNG of the grey image `grey` (`img_w x img_h`, row-major, 0–255) with `sets`
/// drawn over it; the axes give mm from the image's top-left corner (`pixel_size_mm` per
/// pixel). Segments are clipped to the image.
pub fn outline_overlay_png(
    path: &Path,
    grey: &[f64],
    img_w: usize,
    img_h: usize,
    pixel_size_mm: f64,
    sets: &[OutlineSet],
    opts: &OverlayOptions,
) -> Result<(), PlotError> {
    check_size(opts.width, opts.height)?;
    if img_w == 0 || img_h == 0 {
        return Err(PlotError::Empty("the image has no pixel".into()));
    }
    if grey.len() != img_w * img_h {
        return Err(PlotError::LengthMismatch {
            what: format!("grey levels (one per pixel of {img_w} x {img_h})"),
            expected: img_w * img_h,
            found: grey.len(),
        });
    }
    if !(pixel_size_mm > 0.0 && pixel_size_mm.is_finite()) {
        return Err(PlotError::InvalidOption(format!(
            "pixel size {pixel_size_mm} mm must be positive"
        )));
    }
    if sets.is_empty() {
        return Err(PlotError::Empty("no outline set".into()));
    }
    for set in sets {
        if set
            .segments_px
            .iter()
            .flatten()
            .flatten()
            .any(|v| !v.is_finite())
        {
            return Err(PlotError::InvalidData(format!(
                "outline set {}: a non-finite coordinate",
                set.label
            )));
        }
    }
    if !(opts.line_width > 0.0 && opts.line_width <= 20.0) {
        return Err(PlotError::InvalidOption(format!(
            "line width {} is outside (0, 20]",
            opts.line_width
        )));
    }
    let s = Sizes::new(opts.width, opts.height);
    let (yla, xla) = (s.px(90.0), s.px(70.0));
    let top = s.title_band() + s.px(10.0);
    let aw = opts.width.saturating_sub(yla + s.px(40.0)).max(20);
    let ah = opts.height.saturating_sub(top + xla + s.px(10.0)).max(20);
    let scale = (aw as f64 / img_w as f64).min(ah as f64 / img_h as f64);
    let pw = ((scale * img_w as f64).floor() as u32).max(10);
    let ph = ((scale * img_h as f64).floor() as u32).max(10);
    let left = yla + s.px(16.0) + (aw.saturating_sub(pw)) / 2;
    let (wmm, hmm) = (img_w as f64 * pixel_size_mm, img_h as f64 * pixel_size_mm);
    let lw = (s.px(opts.line_width)).max(1);
    let canvas = Canvas::new(opts.width, opts.height);
    canvas.draw_and_save(path, |root| {
        draw_title(root, &opts.title, s)?;
        let columns: Vec<usize> = (0..pw)
            .map(|px| (((px as f64 + 0.5) / scale) as usize).min(img_w - 1))
            .collect();
        for py in 0..ph {
            let iy = (((py as f64 + 0.5) / scale) as usize).min(img_h - 1);
            for (px, &ix) in (0..pw).zip(&columns) {
                let g = grey[iy * img_w + ix].clamp(0.0, 255.0) as u8;
                root.draw_pixel(((left + px) as i32, (top + py) as i32), &RGBColor(g, g, g))
                    .map_err(de)?;
            }
        }
        // Chart in mm from the image's top-left corner; y drawn as −depth so it grows down.
        let area = root.clone().shrink((left - yla, top), (yla + pw, ph + xla));
        let mut chart = ChartBuilder::on(&area)
            .margin(0)
            .y_label_area_size(yla)
            .x_label_area_size(xla)
            .build_cartesian_2d(0.0..wmm, -hmm..0.0)
            .map_err(de)?;
        draw_image_axes(&mut chart, "lateral (mm)", "depth (mm)", s)?;
        // Pixel position (centre at integers) → chart point: the pixel's centre is at
        // (u + ½) mm-units from the corner.
        let to_mm = |p: [f64; 2]| ((p[0] + 0.5) * pixel_size_mm, -(p[1] + 0.5) * pixel_size_mm);
        let dash_mm = 0.6;
        for set in sets {
            let colour = RGBColor(set.color.0, set.color.1, set.color.2);
            let style = colour.stroke_width(lw);
            let mut pieces: Vec<Vec<(f64, f64)>> = Vec::new();
            for seg in &set.segments_px {
                let Some((a, b)) = clip(seg[0], seg[1], img_w as f64, img_h as f64) else {
                    continue;
                };
                let (pa, pb) = (to_mm(a), to_mm(b));
                if !set.dashed {
                    pieces.push(vec![pa, pb]);
                    continue;
                }
                // Dashes on a grid of the model's length along the segment's main axis, so
                // that consecutive short segments continue the pattern.
                let len = (pb.0 - pa.0).hypot(pb.1 - pa.1);
                let n = ((len / (0.25 * dash_mm)).ceil() as usize).max(1);
                for k in 0..n {
                    let (t0, t1) = (k as f64 / n as f64, (k + 1) as f64 / n as f64);
                    let q0 = (pa.0 + t0 * (pb.0 - pa.0), pa.1 + t0 * (pb.1 - pa.1));
                    let q1 = (pa.0 + t1 * (pb.0 - pa.0), pa.1 + t1 * (pb.1 - pa.1));
                    let mid = (0.5 * (q0.0 + q1.0), 0.5 * (q0.1 + q1.1));
                    let phase = ((mid.0 + mid.1.abs()) / dash_mm).floor() as i64;
                    if phase.rem_euclid(2) == 0 {
                        pieces.push(vec![q0, q1]);
                    }
                }
            }
            chart
                .draw_series(pieces.into_iter().map(|p| PathElement::new(p, style)))
                .map_err(de)?;
            let half = s.px(18.0) as i32;
            let anno = chart
                .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                .map_err(de)?;
            anno.label(set.label.as_str());
            // Three dashes, or one line over the same length.
            let pieces: [(i32, i32); 3] = if set.dashed {
                [
                    (0, half / 2),
                    (3 * half / 4, 5 * half / 4),
                    (3 * half / 2, 2 * half),
                ]
            } else {
                [(0, 2 * half), (0, 2 * half), (0, 2 * half)]
            };
            anno.legend(move |(x, y)| {
                let piece =
                    |k: usize| PathElement::new(vec![(pieces[k].0, 0), (pieces[k].1, 0)], style);
                EmptyElement::at((x, y)) + piece(0) + piece(1) + piece(2)
            });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .margin(s.px(14.0))
            .legend_area_size(s.px(50.0))
            .label_font(font(s.legend()))
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(120, 120, 120))
            .draw()
            .map_err(de)?;
        Ok(())
    })
}

/// The part of the segment `a–b` inside the image `[−½, w − ½] x [−½, h − ½]` (pixel
/// edges), by Liang–Barsky clipping; `None` if it is outside.
fn clip(a: [f64; 2], b: [f64; 2], w: f64, h: f64) -> Option<([f64; 2], [f64; 2])> {
    let d = [b[0] - a[0], b[1] - a[1]];
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-d[0], a[0] + 0.5),
        (d[0], w - 0.5 - a[0]),
        (-d[1], a[1] + 0.5),
        (d[1], h - 0.5 - a[1]),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then(|| {
        (
            [a[0] + t0 * d[0], a[1] + t0 * d[1]],
            [a[0] + t1 * d[0], a[1] + t1 * d[1]],
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_png_clips_and_rejects_bad_input() {
        let (w, h) = (80, 60);
        let grey: Vec<f64> = (0..w * h).map(|k| ((k * 37) % 255) as f64).collect();
        let sets = vec![
            OutlineSet {
                label: "before".into(),
                segments_px: vec![[[-10.0, 5.0], [90.0, 20.0]], [[10.0, 10.0], [20.0, 50.0]]],
                color: (230, 60, 40),
                dashed: true,
            },
            OutlineSet {
                label: "after".into(),
                segments_px: vec![[[0.0, 30.0], [79.0, 30.0]]],
                color: (40, 200, 255),
                dashed: false,
            },
        ];
        let dir = std::env::temp_dir().join(format!("femu-plot-overlay-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("o.png");
        let opts = OverlayOptions {
            title: "outlines".into(),
            width: 600,
            height: 500,
            ..Default::default()
        };
        outline_overlay_png(&p, &grey, w, h, 0.1, &sets, &opts).unwrap();
        let img = image::open(&p).unwrap().to_rgb8();
        assert_eq!((img.width(), img.height()), (600, 500));
        // The solid set's colour is in the picture (a grey image has no such pixel).
        assert!(img.pixels().any(|px| px.0 == [40, 200, 255]));
        assert!(outline_overlay_png(&p, &grey[1..], w, h, 0.1, &sets, &opts).is_err());
        assert!(outline_overlay_png(&p, &grey, w, h, 0.0, &sets, &opts).is_err());
        assert!(outline_overlay_png(&p, &grey, w, h, 0.1, &[], &opts).is_err());
        std::fs::remove_dir_all(&dir).ok();
        // Clipping: a segment crossing the image keeps its inside part, one outside is dropped.
        let (a, b) = clip([-10.0, 5.0], [90.0, 5.0], 80.0, 60.0).unwrap();
        assert!((a[0] + 0.5).abs() < 1e-12 && (b[0] - 79.5).abs() < 1e-12);
        assert!(clip([-10.0, -5.0], [-2.0, -3.0], 80.0, 60.0).is_none());
    }
}
