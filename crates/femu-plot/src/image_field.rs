//! A field over an image: a grey-level picture (an ultrasound frame, a speckle image) with a
//! per-pixel value drawn over it in colour where it is defined, and a colour bar. Axes are in
//! image pixels, y pointing down as in the image.

use crate::colorbar::{draw_color_bar, draw_swatch, ColorBarPlace};
use crate::colormap::ColorMap;
use crate::text::{draw_title, font, Sizes};
use crate::{check_range, check_size, de, finite_min_max, widen, Canvas, PlotError};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

/// Options of [`image_field_png`].
#[derive(Debug, Clone)]
pub struct ImageField {
    pub title: String,
    /// Name and unit of the values, along the colour bar.
    pub value_label: String,
    /// Blue–white–red symmetric about zero instead of viridis.
    pub diverging: bool,
    /// Colour range; by default the finite values' range (symmetric for `diverging`).
    pub range: Option<(f64, f64)>,
    /// Opacity of the colours over the grey image (0–1).
    pub alpha: f64,
    /// Part of the image shown, `(x, y, w, h)` pixels; by default the whole image.
    pub crop: Option<(usize, usize, usize, usize)>,
    /// Categories instead of a continuous range: value `k` (1, 2, …) is category
    /// `categories[k - 1]`, drawn in its own colour of [`crate::colormap::SERIES`] and named in
    /// a legend that replaces the colour bar; other values show the grey image.
    pub categories: Vec<String>,
    pub width: u32,
    pub height: u32,
}

impl Default for ImageField {
    fn default() -> Self {
        ImageField {
            title: String::new(),
            value_label: String::new(),
            diverging: false,
            range: None,
            alpha: 0.75,
            crop: None,
            categories: Vec::new(),
            width: crate::DEFAULT_WIDTH,
            height: crate::DEFAULT_HEIGHT,
        }
    }
}

/// Writes a PNG of `values` (one per pixel of an `img_w x img_h` image, NaN where there is no
/// value) blended over the grey image `grey` (0–255), with a colour bar.
pub fn image_field_png(
    path: &Path,
    grey: &[f64],
    img_w: usize,
    img_h: usize,
    values: &[f64],
    opts: &ImageField,
) -> Result<(), PlotError> {
    check_size(opts.width, opts.height)?;
    check_range("value range", opts.range)?;
    if img_w == 0 || img_h == 0 {
        return Err(PlotError::Empty("the image has no pixel".into()));
    }
    for (what, v) in [("grey levels", grey), ("values", values)] {
        if v.len() != img_w * img_h {
            return Err(PlotError::LengthMismatch {
                what: format!("{what} (one per pixel of {img_w} x {img_h})"),
                expected: img_w * img_h,
                found: v.len(),
            });
        }
    }
    if !(0.0..=1.0).contains(&opts.alpha) {
        return Err(PlotError::InvalidOption(format!(
            "alpha {} is outside 0..1",
            opts.alpha
        )));
    }
    let (cx, cy, cw, ch) = opts.crop.unwrap_or((0, 0, img_w, img_h));
    if cw == 0 || ch == 0 || cx + cw > img_w || cy + ch > img_h {
        return Err(PlotError::InvalidOption(format!(
            "crop ({cx}, {cy}, {cw}, {ch}) is not inside the {img_w} x {img_h} image"
        )));
    }
    let (lo, hi) = match opts.range {
        Some(r) => r,
        None => {
            let r = finite_min_max(values.iter().copied()).ok_or_else(|| {
                PlotError::InvalidData("every value is NaN: nothing to colour".into())
            })?;
            widen(r.0, r.1)
        }
    };
    let cmap = ColorMap::new(lo, hi, opts.diverging);
    let s = Sizes::new(opts.width, opts.height);
    // Layout: image on the left keeping its aspect ratio, colour bar on the right.
    let (yla, xla) = (s.px(90.0), s.px(70.0));
    // Right of the image: the colour bar and its labels, or the categories' legend (a swatch
    // and a name per line, the longest name setting the width).
    let longest = opts.categories.iter().map(|c| c.chars().count()).max();
    let (cb_gap, cb_w) = (s.px(30.0), s.px(30.0));
    let cb_la = longest.map_or(s.px(130.0), |n| {
        s.px(24.0 + 11.0 * (n + 3) as f64).max(s.px(130.0))
    });
    let top = s.title_band() + s.px(10.0);
    let aw = opts
        .width
        .saturating_sub(yla + s.px(16.0) + cb_gap + cb_w + cb_la + s.px(12.0))
        .max(20);
    let ah = opts.height.saturating_sub(top + xla + s.px(10.0)).max(20);
    let scale = (aw as f64 / cw as f64).min(ah as f64 / ch as f64);
    let pw = ((scale * cw as f64).floor() as u32).max(10);
    let ph = ((scale * ch as f64).floor() as u32).max(10);
    let left = yla + s.px(16.0);
    let canvas = Canvas::new(opts.width, opts.height);
    canvas.draw_and_save(path, |root| {
        draw_title(root, &opts.title, s)?;
        // Image pixels: nearest neighbour, grey blended with the colour where defined, written
        // into one RGB block and copied onto the canvas at once (a pixel at a time through the
        // drawing area cost several times the colouring itself).
        let pixels = Pixels::new(
            grey,
            values,
            img_w,
            (cx, cy, cw, ch),
            &cmap,
            opts.alpha,
            opts.categories.len(),
        );
        let block = pixels.picture(scale, pw, ph);
        let image = BitMapElement::with_owned_buffer((left as i32, top as i32), (pw, ph), block)
            .ok_or_else(|| "the image block has the wrong size".to_string())?;
        root.draw(&image).map_err(de)?;
        // Axes in image pixels (y down): the chart's y runs over −y so that it grows downwards.
        let area = root.clone().shrink((left - yla, top), (yla + pw, ph + xla));
        let mut chart = ChartBuilder::on(&area)
            .margin(0)
            .y_label_area_size(yla)
            .x_label_area_size(xla)
            .build_cartesian_2d(
                cx as f64..(cx + cw) as f64,
                -((cy + ch) as f64)..-(cy as f64),
            )
            .map_err(de)?;
        draw_image_axes(&mut chart, "x (px)", "y (px)", s)?;
        let place = ColorBarPlace {
            left: left + pw + cb_gap,
            top,
            width: cb_w,
            height: ph,
            label_width: cb_la,
        };
        if opts.categories.is_empty() {
            // NaN pixels show the grey image: no "no value" swatch.
            draw_color_bar(root, &cmap, &opts.value_label, false, place, s)
        } else {
            draw_category_legend(root, &opts.value_label, &opts.categories, place, s)
        }
    })
}

/// The category (0-based) of value `v`: `v` rounded to an integer `1..=n`.
fn category_of(v: f64, n: usize) -> Option<usize> {
    let k = v.round();
    (k >= 1.0 && k <= n as f64).then(|| k as usize - 1)
}

/// The colour of category `k` (0-based): the qualitative palette, repeated past its end.
fn category_color(k: usize) -> RGBColor {
    crate::colormap::SERIES[k % crate::colormap::SERIES.len()]
}

/// The categories' legend at `place`: under the title `label`, one line per category, a swatch
/// of its colour and `k name`.
fn draw_category_legend(
    root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    label: &str,
    categories: &[String],
    place: ColorBarPlace,
    s: Sizes,
) -> Result<(), String> {
    let x = place.left as i32;
    let line = s.px(34.0) as i32;
    let d = s.px(22.0) as i32;
    root.draw(&Text::new(
        label.to_string(),
        (x, place.top as i32),
        font(s.desc()),
    ))
    .map_err(de)?;
    for (k, name) in categories.iter().enumerate() {
        let y = place.top as i32 + line * (k as i32 + 1) + s.px(8.0) as i32;
        draw_swatch(root, (x, y), d, category_color(k))?;
        root.draw(&Text::new(
            format!("{} {name}", k + 1),
            (x + d + s.px(10.0) as i32, y),
            font(s.tick()),
        ))
        .map_err(de)?;
    }
    Ok(())
}

/// Steps of the continuous colour map's lookup table in [`Pixels`]: a value's colour is the map's
/// at the nearest of 1 024 equally spaced values of its range, within a fraction of a grey level
/// of the exact one (the tables' largest step between two neighbouring entries is 0x92 − 0x43 =
/// 79 levels over a tenth of the range, 0.08 level per step of the table).
const COLOUR_STEPS: usize = 1024;

/// The image and its values as [`image_field_png`] shows them: a pixel's colour is
/// `α c + (1 − α) g`, its value's colour `c` blended over its grey level `g` (rounded to an
/// integer level), computed in integers from tables made once per picture (`α c` and
/// `(1 − α) g` in 1/256 of a level, rounded) at a fraction of the cost per pixel of the same
/// blend in floating point, and within 1.5 levels of it: the table's colour is the map's at a
/// value at most half a step away (0.04 level) rounded (0.5), the grey level is rounded (0.5),
/// and so is the sum (0.5): at most `0.54 α + 0.5 (1 − α) + 0.5` from the exact blend, 0.5 α
/// more from the blend of the map's rounded colour.
struct Pixels<'a> {
    grey: &'a [f64],
    values: &'a [f64],
    img_w: usize,
    crop: (usize, usize, usize, usize),
    /// `α c` (1/256 level) at [`COLOUR_STEPS`] equally spaced values from `lo` to `hi` of the
    /// map; empty for categories.
    scaled: Vec<[u32; 3]>,
    /// `α c` (1/256 level) of each category's colour; empty for continuous values.
    category: Vec<[u32; 3]>,
    /// `(1 − α) g` (1/256 level) for each grey level `g`.
    grey_part: [u32; 256],
    /// The map's range start and table steps per unit of value.
    lo: f64,
    steps_per_unit: f64,
}

impl<'a> Pixels<'a> {
    /// The picture's tables for `cmap` (or `categories` categories when non-zero) at opacity
    /// `alpha`.
    fn new(
        grey: &'a [f64],
        values: &'a [f64],
        img_w: usize,
        crop: (usize, usize, usize, usize),
        cmap: &ColorMap,
        alpha: f64,
        categories: usize,
    ) -> Self {
        let scaled_colour = |RGBColor(r, g, b): RGBColor| {
            [r, g, b].map(|c| (alpha * 256.0 * c as f64).round() as u32)
        };
        let (lo, hi) = cmap.range();
        let step = (hi - lo) / (COLOUR_STEPS - 1) as f64;
        let scaled = if categories > 0 {
            Vec::new()
        } else {
            (0..COLOUR_STEPS)
                .map(|i| scaled_colour(cmap.color(lo + i as f64 * step)))
                .collect()
        };
        let category = (0..categories)
            .map(|k| scaled_colour(category_color(k)))
            .collect();
        let mut grey_part = [0u32; 256];
        for (g, part) in grey_part.iter_mut().enumerate() {
            *part = ((1.0 - alpha) * 256.0 * g as f64).round() as u32;
        }
        Pixels {
            grey,
            values,
            img_w,
            crop,
            scaled,
            category,
            grey_part,
            lo,
            steps_per_unit: 1.0 / step,
        }
    }

    /// The colour of image pixel `(ix, iy)`: its grey level, blended with the value's colour
    /// where the value is defined.
    #[inline]
    fn rgb(&self, ix: usize, iy: usize) -> [u8; 3] {
        let k = iy * self.img_w + ix;
        // The nearest grey level (0.5 ≤ level + 0.5 ≤ 255.5 after the clamp; NaN gives 0).
        let g = (self.grey[k].clamp(0.0, 255.0) + 0.5) as u8;
        let v = self.values[k];
        if v.is_nan() {
            return [g; 3];
        }
        let c = if self.category.is_empty() {
            // The nearest table entry; values outside the range take the end colours.
            let t =
                ((v - self.lo) * self.steps_per_unit + 0.5).clamp(0.0, (COLOUR_STEPS - 1) as f64);
            &self.scaled[t as usize]
        } else {
            match category_of(v, self.category.len()) {
                Some(j) => &self.category[j],
                None => return [g; 3],
            }
        };
        let gp = self.grey_part[g as usize] + 128;
        c.map(|c| ((c + gp) >> 8).min(255) as u8)
    }

    /// The `pw x ph` RGB picture of the crop at `scale` picture pixels per image pixel, nearest
    /// neighbour: picture pixel `(px, py)` shows image pixel `⌊(p + ½) / scale⌋` of the crop.
    /// Each image pixel is coloured once: a picture row that shows the same image row as the one
    /// above is a copy of it, and within a row the columns that show the same image column
    /// repeat its colour (an enlarged image shows each pixel several times).
    fn picture(&self, scale: f64, pw: u32, ph: u32) -> Vec<u8> {
        let (cx, cy, cw, ch) = self.crop;
        // The source column of each picture column once (a non-negative quotient: truncation
        // is the floor).
        let columns: Vec<usize> = (0..pw)
            .map(|px| cx + (((px as f64 + 0.5) / scale) as usize).min(cw - 1))
            .collect();
        let row_bytes = 3 * pw as usize;
        let mut block = Vec::with_capacity(row_bytes * ph as usize);
        let mut last_row = usize::MAX;
        for py in 0..ph {
            let iy = cy + (((py as f64 + 0.5) / scale) as usize).min(ch - 1);
            if iy == last_row {
                block.extend_from_within(block.len() - row_bytes..);
                continue;
            }
            last_row = iy;
            let (mut last_ix, mut rgb) = (usize::MAX, [0u8; 3]);
            for &ix in &columns {
                if ix != last_ix {
                    last_ix = ix;
                    rgb = self.rgb(ix, iy);
                }
                block.extend_from_slice(&rgb);
            }
        }
        block
    }
}

/// The label of the chart's y value `v` (−row): the row, rounded; `+ 0.0` turns the negative
/// zero of −0 into 0 (no "-0" tick at the top).
fn row_label(v: f64) -> String {
    format!("{}", (-v).round() + 0.0)
}

/// The axes of an image drawn with its rows going down (the chart's y runs over −row, labelled
/// positive): no grid, six labels a side.
pub(crate) fn draw_image_axes<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    x_desc: &str,
    y_desc: &str,
    s: Sizes,
) -> Result<(), String> {
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(font(s.tick()))
        .axis_desc_style(font(s.desc()))
        .x_labels(6)
        .y_labels(6)
        .y_label_formatter(&|v| row_label(*v))
        .x_label_formatter(&|v| format!("{}", v.round()))
        .draw()
        .map_err(de)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The picture colours each shown image pixel once and repeats it: every picture pixel is
    /// the colour of the image pixel it shows, enlarged (non-integer and integer scales) and
    /// reduced, crop included.
    #[test]
    fn the_picture_shows_each_pixel_of_the_crop() {
        let (w, h) = (37, 23);
        let grey: Vec<f64> = (0..w * h).map(|k| ((k * 53) % 256) as f64).collect();
        let values: Vec<f64> = (0..w * h)
            .map(|k| {
                if k % 7 == 0 {
                    f64::NAN
                } else {
                    (k as f64 * 0.37).sin()
                }
            })
            .collect();
        let cmap = ColorMap::new(-1.0, 1.0, true);
        let crop = (3, 2, 30, 19);
        let pixels = Pixels::new(&grey, &values, w, crop, &cmap, 0.75, 0);
        for scale in [0.61, 1.0, 1.58, 3.0] {
            let (pw, ph) = ((scale * 30.0) as u32, (scale * 19.0) as u32);
            let block = pixels.picture(scale, pw, ph);
            assert_eq!(block.len(), (3 * pw * ph) as usize);
            for py in 0..ph as usize {
                for px in 0..pw as usize {
                    let ix = crop.0 + (((px as f64 + 0.5) / scale) as usize).min(crop.2 - 1);
                    let iy = crop.1 + (((py as f64 + 0.5) / scale) as usize).min(crop.3 - 1);
                    let at = 3 * (py * pw as usize + px);
                    assert_eq!(
                        block[at..at + 3],
                        pixels.rgb(ix, iy),
                        "scale {scale} ({px}, {py})"
                    );
                }
            }
        }
    }

    /// Category values take their own colour (blended over the grey as continuous ones are),
    /// values that are no category show the grey image, and the top row's tick reads 0.
    #[test]
    fn categories_have_their_own_colours() {
        let grey = vec![100.0; 4];
        let values = vec![1.0, 4.0, 7.0, f64::NAN];
        let cmap = ColorMap::new(1.0, 5.0, false);
        let pixels = Pixels::new(&grey, &values, 4, (0, 0, 4, 1), &cmap, 0.75, 5);
        // 0.75 c + 25 in the tables' integers (1/256 level; see the test below for the bound
        // against the blend in floating point).
        let blend = |c: RGBColor| {
            let m = |x: u8| ((192 * x as u32 + 6400 + 128) >> 8) as u8;
            [m(c.0), m(c.1), m(c.2)]
        };
        assert_eq!(pixels.rgb(0, 0), blend(crate::colormap::SERIES[0]));
        assert_eq!(pixels.rgb(1, 0), blend(crate::colormap::SERIES[3]));
        assert_eq!(pixels.rgb(2, 0), [100; 3], "7 is no category of 5");
        assert_eq!(pixels.rgb(3, 0), [100; 3]);
        assert_eq!(row_label(-0.0), "0");
        assert_eq!(row_label(0.0), "0");
        assert_eq!(row_label(-100.0), "100");
    }

    /// The integer blend of the tables is within 1.5 levels of `α c + (1 − α) g` in floating
    /// point with `c` the map's (rounded) colour, for every grey level (and grey values between
    /// levels), values across and beyond the range, both maps and several opacities.
    #[test]
    fn the_tables_blend_within_a_level_and_a_half() {
        let n = 4001;
        let values: Vec<f64> = (0..n)
            .map(|k| -1.3 + 2.6 * k as f64 / (n - 1) as f64)
            .collect();
        for (cmap, alpha) in [
            (ColorMap::new(-1.0, 1.0, true), 0.75),
            (ColorMap::new(-0.4, 0.9, false), 0.75),
            (ColorMap::new(0.0, 1.0, false), 0.3),
            (ColorMap::new(-2.0, 0.5, true), 1.0),
        ] {
            for g in 0..=255u8 {
                let grey = vec![g as f64 + 0.4 * (g % 2) as f64; n];
                let pixels = Pixels::new(&grey, &values, n, (0, 0, n, 1), &cmap, alpha, 0);
                for (ix, &v) in values.iter().enumerate() {
                    let RGBColor(r, gg, b) = cmap.color(v);
                    let got = pixels.rgb(ix, 0);
                    for (c, got) in [r, gg, b].into_iter().zip(got) {
                        let gv = g as f64 + 0.4 * (g % 2) as f64;
                        let exact = alpha * c as f64 + (1.0 - alpha) * gv;
                        assert!(
                            (got as f64 - exact).abs() <= 1.5,
                            "{cmap:?} alpha {alpha} grey {g} value {v}: {got} against {exact}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn writes_a_png_and_rejects_bad_input() {
        let (w, h) = (60, 40);
        let grey: Vec<f64> = (0..w * h).map(|k| ((k * 37) % 255) as f64).collect();
        let vals: Vec<f64> = (0..w * h)
            .map(|k| {
                if (k % w) > 10 && (k / w) > 5 {
                    (k % w) as f64 * 0.01 - 0.3
                } else {
                    f64::NAN
                }
            })
            .collect();
        let dir = std::env::temp_dir().join(format!("femu-plot-img-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("f.png");
        let opts = ImageField {
            title: "ux".into(),
            value_label: "ux (px)".into(),
            diverging: true,
            width: 600,
            height: 400,
            ..Default::default()
        };
        image_field_png(&p, &grey, w, h, &vals, &opts).unwrap();
        let img = image::open(&p).unwrap();
        assert_eq!((img.width(), img.height()), (600, 400));
        assert!(image_field_png(&p, &grey[1..], w, h, &vals, &opts).is_err());
        let bad = ImageField {
            crop: Some((50, 0, 20, 10)),
            ..opts.clone()
        };
        assert!(image_field_png(&p, &grey, w, h, &vals, &bad).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
