//! Text shared by every figure: sizes, the title, and compact tick labels.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Font sizes and line widths of a picture, scaled with its size (`k = 1` at 1200 x 900 px).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sizes {
    pub k: f64,
}

impl Sizes {
    pub fn new(width: u32, height: u32) -> Self {
        Sizes {
            k: crate::scale_of(width, height),
        }
    }
    /// `v` pixels at the default size, scaled (at least 1).
    pub fn px(&self, v: f64) -> u32 {
        (v * self.k).round().max(1.0) as u32
    }
    pub fn title(&self) -> u32 {
        self.px(30.0)
    }
    pub fn tick(&self) -> u32 {
        self.px(20.0)
    }
    pub fn desc(&self) -> u32 {
        self.px(23.0)
    }
    pub fn legend(&self) -> u32 {
        self.px(20.0)
    }
    /// Height of the band that holds the title.
    pub fn title_band(&self) -> u32 {
        self.px(62.0)
    }
}

/// A text style of the embedded font.
pub(crate) fn font(size: u32) -> TextStyle<'static> {
    TextStyle::from(("sans-serif", size as f64).into_font()).color(&BLACK)
}

/// Draws `title` centred in the top band of `root`, shrinking the font until it fits.
pub(crate) fn draw_title(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    title: &str,
    s: Sizes,
) -> Result<(), String> {
    if title.trim().is_empty() {
        return Ok(());
    }
    let (w, _) = root.dim_in_pixel();
    let max_w = w.saturating_sub(2 * s.px(20.0));
    let mut size = s.title();
    while size > 10 {
        let (tw, _) = root
            .estimate_text_size(title, &font(size))
            .map_err(crate::de)?;
        if tw <= max_w {
            break;
        }
        size -= 1;
    }
    let style = font(size).pos(Pos::new(HPos::Center, VPos::Center));
    root.draw(&Text::new(
        title.to_string(),
        ((w / 2) as i32, (s.title_band() / 2 + s.px(4.0)) as i32),
        style,
    ))
    .map_err(crate::de)
}

/// The largest font size `<= size` at which every text in `texts` is at most `max_w` px wide.
pub(crate) fn fitting_size(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    texts: &[String],
    size: u32,
    max_w: u32,
) -> Result<u32, String> {
    let mut size = size;
    while size > 9 {
        let mut widest = 0;
        for t in texts {
            widest = widest.max(
                root.estimate_text_size(t, &font(size))
                    .map_err(crate::de)?
                    .0,
            );
        }
        if widest <= max_w {
            break;
        }
        size -= 1;
    }
    Ok(size)
}

const SUPERSCRIPT: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];

/// `10` followed by the exponent in superscript digits (`10⁻⁴`).
fn power_of_ten(e: i32) -> String {
    let mut s = String::from("10");
    if e < 0 {
        s.push('⁻');
    }
    for c in e.unsigned_abs().to_string().chars() {
        s.push(SUPERSCRIPT[c.to_digit(10).unwrap_or(0) as usize]);
    }
    s
}

/// Fixed-point with `decimals` decimals, trailing zeros trimmed, a typographic minus sign.
fn fixed(v: f64, decimals: usize) -> String {
    let mut s = format!("{v:.decimals$}");
    if s.contains('.') {
        while s.ends_with('0') {
            s.pop();
        }
        if s.ends_with('.') {
            s.pop();
        }
    }
    if s == "-0" {
        s = "0".into();
    }
    s.replace('-', "−")
}

/// `m×10ᵉ` with the mantissa to `decimals` decimals (`10ᵉ` alone when it is 1).
fn scientific(v: f64, e: i32, decimals: usize) -> String {
    let m = v / 10f64.powi(e);
    let ms = fixed(m, decimals);
    match ms.as_str() {
        "1" => power_of_ten(e),
        "−1" => format!("−{}", power_of_ten(e)),
        _ => format!("{ms}×{}", power_of_ten(e)),
    }
}

/// A compact tick label for `v` on a linear axis spanning `lo..hi`: fixed point with just
/// enough decimals for the span, or `m×10ᵉ` when the values are very large or very small.
pub(crate) fn tick_label(v: f64, lo: f64, hi: f64) -> String {
    let span = (hi - lo).abs().max(f64::MIN_POSITIVE);
    if v.abs() <= span * 1e-9 {
        return "0".into();
    }
    let scale = lo.abs().max(hi.abs());
    if !(1e-2..1e5).contains(&scale) {
        // Each label its own exponent; one decimal more than the tick spacing (~span/10) needs.
        let e = (v.abs().log10() + 1e-9).floor() as i32;
        let d = (e as f64 - (span / 10.0).log10().floor() + 1.0).clamp(0.0, 6.0) as usize;
        return scientific(v, e, d);
    }
    let d = (3.0 - span.log10().floor()).clamp(0.0, 10.0) as usize;
    fixed(v, d)
}

/// A tick label on a logarithmic axis: plain numbers between 0.01 and 10 000, else `m×10ᵉ`.
pub(crate) fn log_tick_label(v: f64) -> String {
    if v <= 0.0 || !v.is_finite() {
        return fixed(v, 3);
    }
    let e = (v.log10() + 1e-9).floor() as i32;
    if (-2..4).contains(&e) {
        fixed(v, (3 - e).clamp(0, 6) as usize)
    } else {
        scientific(v, e, 2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_compact() {
        assert_eq!(tick_label(0.25, 0.0, 1.0), "0.25");
        assert_eq!(tick_label(-0.5, -1.0, 1.0), "−0.5");
        assert_eq!(tick_label(1e-17, -1.0, 1.0), "0");
        assert_eq!(tick_label(40.0, 0.0, 60.0), "40");
        assert_eq!(tick_label(2.5e-4, 0.0, 1e-3), "2.5×10⁻⁴");
        assert_eq!(tick_label(1e-4, 0.0, 1e-3), "10⁻⁴");
        assert_eq!(tick_label(2e5, 0.0, 1e6), "2×10⁵");
        assert_eq!(log_tick_label(1e-4), "10⁻⁴");
        assert_eq!(log_tick_label(0.1), "0.1");
        assert_eq!(log_tick_label(100.0), "100");
        assert_eq!(log_tick_label(3e5), "3×10⁵");
    }
}
