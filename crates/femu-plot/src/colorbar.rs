//! The colour bar of every figure whose colours carry values ([`crate::mesh_field_png`],
//! [`crate::node_field_png`], [`crate::image_field_png`]): a vertical bar right of the plot
//! spanning the colour map's range, with ticks and the value label on its right and, if some
//! values are missing, a grey swatch "no value" below it.

use crate::colormap::{ColorMap, MISSING};
use crate::de;
use crate::text::{font, tick_label, Sizes};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Where a colour bar goes (px): the bar's left edge, top, width and height (the plot's top and
/// height, so that it stands beside the plot), and the width of the band right of the bar for its
/// tick labels and value label.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ColorBarPlace {
    pub left: u32,
    pub top: u32,
    pub width: u32,
    pub height: u32,
    pub label_width: u32,
}

/// Draws the colour bar of `cmap` at `place`, labelled `label` (name and unit of the values),
/// with the "no value" swatch below it if `missing` (some values are drawn in [`MISSING`]).
pub(crate) fn draw_color_bar(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    cmap: &ColorMap,
    label: &str,
    missing: bool,
    place: ColorBarPlace,
    s: Sizes,
) -> Result<(), String> {
    let (lo, hi) = cmap.range();
    let area = root.clone().shrink(
        (place.left, place.top),
        (place.width + place.label_width, place.height),
    );
    let mut bar = ChartBuilder::on(&area)
        .margin(0)
        .right_y_label_area_size(place.label_width)
        .build_cartesian_2d(0.0..1.0, lo..hi)
        .map_err(de)?;
    // One band per pixel row of the bar, coloured at its middle value.
    let steps = place.height.max(2) as usize;
    bar.draw_series((0..steps).map(|i| {
        let a = lo + (hi - lo) * i as f64 / steps as f64;
        let b = lo + (hi - lo) * (i + 1) as f64 / steps as f64;
        Rectangle::new([(0.0, a), (1.0, b)], cmap.color(0.5 * (a + b)).filled())
    }))
    .map_err(de)?;
    bar.draw_series(std::iter::once(Rectangle::new(
        [(0.0, lo), (1.0, hi)],
        BLACK.stroke_width(1),
    )))
    .map_err(de)?;
    bar.configure_mesh()
        .set_all_tick_mark_size(s.px(7.0))
        .disable_mesh()
        .disable_x_axis()
        .y_desc(label)
        .label_style(font(s.tick()))
        .axis_desc_style(font(s.desc()))
        .y_labels(((place.height / s.px(60.0)) as usize).clamp(3, 11))
        .y_label_formatter(&|v| tick_label(*v, lo, hi))
        .draw()
        .map_err(de)?;
    if missing {
        let (x, y) = (
            place.left as i32,
            (place.top + place.height) as i32 + s.px(18.0) as i32,
        );
        let d = s.px(18.0) as i32;
        draw_swatch(root, (x, y), d, MISSING)?;
        root.draw(&Text::new(
            "no value",
            (x + d + s.px(8.0) as i32, y + d / 2),
            font(s.tick()).pos(Pos::new(HPos::Left, VPos::Center)),
        ))
        .map_err(de)?;
    }
    Ok(())
}

/// A legend swatch: a `d x d` square of `color` with a black outline, its top-left corner at
/// `at` (the "no value" swatch of a colour bar, a category of an image map).
pub(crate) fn draw_swatch(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    at: (i32, i32),
    d: i32,
    color: RGBColor,
) -> Result<(), String> {
    let (x, y) = at;
    root.draw(&Rectangle::new([(x, y), (x + d, y + d)], color.filled()))
        .map_err(de)?;
    root.draw(&Rectangle::new(
        [(x, y), (x + d, y + d)],
        BLACK.stroke_width(1),
    ))
    .map_err(de)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bar runs from the map's low colour at the bottom to its high colour at the top, inside
    /// its place, and the grey swatch is drawn below it only when values are missing.
    #[test]
    fn bar_spans_the_map_and_the_swatch_follows_missing_values() {
        crate::ensure_font().unwrap();
        let (w, h) = (400u32, 320u32);
        let cmap = ColorMap::Viridis { lo: 0.0, hi: 1.0 };
        let place = ColorBarPlace {
            left: 60,
            top: 40,
            width: 30,
            height: 200,
            label_width: 120,
        };
        let s = Sizes::new(w, h);
        for missing in [false, true] {
            let mut buf = vec![0u8; (w * h * 3) as usize];
            {
                let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
                root.fill(&WHITE).unwrap();
                draw_color_bar(&root, &cmap, "q (-)", missing, place, s).unwrap();
                root.present().unwrap();
            }
            let pixel = |x: u32, y: u32| {
                let k = ((y * w + x) * 3) as usize;
                RGBColor(buf[k], buf[k + 1], buf[k + 2])
            };
            // One band per pixel row: two rows inside the frame, the colour is within two bands
            // of the end colour (viridis changes by at most 3 per channel per band of 200).
            let near = |a: RGBColor, b: RGBColor| {
                a.0.abs_diff(b.0) <= 8 && a.1.abs_diff(b.1) <= 8 && a.2.abs_diff(b.2) <= 8
            };
            let x = place.left + place.width / 2;
            let top = pixel(x, place.top + 2);
            let bottom = pixel(x, place.top + place.height - 3);
            assert!(near(top, cmap.color(1.0)), "top {top:?}");
            assert!(near(bottom, cmap.color(0.0)), "bottom {bottom:?}");
            // Left of the bar stays blank.
            assert_eq!(pixel(place.left - 5, place.top + 100), WHITE);
            let d = s.px(18.0);
            let swatch = pixel(
                place.left + d / 2,
                place.top + place.height + s.px(18.0) + d / 2,
            );
            assert_eq!(
                swatch,
                if missing { MISSING } else { WHITE },
                "missing {missing}"
            );
        }
    }
}
