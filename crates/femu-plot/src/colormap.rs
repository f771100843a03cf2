//! Perceptual colour maps: viridis for one-sided data, a blue–white–red diverging map for
//! signed data, grey for missing values.

use plotters::style::RGBColor;

/// The colour of a missing (NaN) value.
pub const MISSING: RGBColor = RGBColor(190, 190, 190);

/// Viridis (matplotlib's default; perceptually uniform, readable in grey and by colour-blind
/// readers), sampled at 9 equally spaced points (R `viridisLite::viridis(9)`).
const VIRIDIS: [[u8; 3]; 9] = [
    [0x44, 0x01, 0x54],
    [0x47, 0x2D, 0x7B],
    [0x3B, 0x52, 0x8B],
    [0x2C, 0x72, 0x8E],
    [0x21, 0x90, 0x8C],
    [0x27, 0xAD, 0x81],
    [0x5D, 0xC8, 0x63],
    [0xAA, 0xDC, 0x32],
    [0xFD, 0xE7, 0x25],
];

/// ColorBrewer RdBu (11 classes) reversed: dark blue for the most negative value, near-white in
/// the middle, dark red for the most positive.
const BLUE_WHITE_RED: [[u8; 3]; 11] = [
    [0x05, 0x30, 0x61],
    [0x21, 0x66, 0xAC],
    [0x43, 0x93, 0xC3],
    [0x92, 0xC5, 0xDE],
    [0xD1, 0xE5, 0xF0],
    [0xF7, 0xF7, 0xF7],
    [0xFD, 0xDB, 0xC7],
    [0xF4, 0xA5, 0x82],
    [0xD6, 0x60, 0x4D],
    [0xB2, 0x18, 0x2B],
    [0x67, 0x00, 0x1F],
];

/// A colour map over a value range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ColorMap {
    /// Viridis over `lo..hi`.
    Viridis { lo: f64, hi: f64 },
    /// Blue–white–red over `-a..a` (white at zero).
    Diverging { a: f64 },
}

impl ColorMap {
    /// The map of values in `lo..hi`: blue–white–red symmetric about zero over the larger of
    /// `|lo|` and `|hi|` if `diverging`, viridis over `lo..hi` (widened if empty) otherwise.
    pub fn new(lo: f64, hi: f64, diverging: bool) -> Self {
        if diverging {
            let a = lo.abs().max(hi.abs());
            ColorMap::Diverging {
                a: if a > 0.0 { a } else { 1.0 },
            }
        } else {
            let (lo, hi) = crate::widen(lo, hi);
            ColorMap::Viridis { lo, hi }
        }
    }

    /// The range the map spans.
    pub fn range(&self) -> (f64, f64) {
        match *self {
            ColorMap::Viridis { lo, hi } => (lo, hi),
            ColorMap::Diverging { a } => (-a, a),
        }
    }

    /// The colour of `v`; values outside the range take the end colours, NaN is [`MISSING`].
    pub fn color(&self, v: f64) -> RGBColor {
        if v.is_nan() {
            return MISSING;
        }
        let (lo, hi) = self.range();
        let t = ((v - lo) / (hi - lo)).clamp(0.0, 1.0);
        match self {
            ColorMap::Viridis { .. } => sample(&VIRIDIS, t),
            ColorMap::Diverging { .. } => sample(&BLUE_WHITE_RED, t),
        }
    }
}

/// Linear interpolation in a table of equally spaced colours, `t` in `[0, 1]`.
fn sample(table: &[[u8; 3]], t: f64) -> RGBColor {
    let x = t * (table.len() - 1) as f64;
    // x ≥ 0: truncation is the floor.
    let i = (x as usize).min(table.len() - 2);
    let f = x - i as f64;
    let c = |k: usize| {
        let a = table[i][k] as f64;
        let b = table[i + 1][k] as f64;
        round_u8(a + f * (b - a))
    };
    RGBColor(c(0), c(1), c(2))
}

/// `v.round() as u8` for `0 ≤ v` (halves away from zero, saturating at 255), without the
/// call to the C library's `round` that `f64::round` is on a baseline x86-64 target (the maps
/// round three channels of every pixel): the integer part by truncation, plus one when the
/// exact fraction `v − ⌊v⌋` is at least ½. A negative `v` gives 0, as `round` does for
/// `v > −½`, and NaN gives 0 (as `as u8` does).
#[inline]
pub fn round_u8(v: f64) -> u8 {
    let t = v.clamp(0.0, 255.0) as u32;
    let r = t + u32::from(v - t as f64 >= 0.5);
    r.min(255) as u8
}

/// Colour-blind-safe qualitative colours (Okabe & Ito) for series and bar groups.
pub const SERIES: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
    RGBColor(240, 228, 66),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_middle_and_missing() {
        let v = ColorMap::Viridis { lo: 0.0, hi: 2.0 };
        assert_eq!(v.color(0.0), RGBColor(0x44, 0x01, 0x54));
        assert_eq!(v.color(2.0), RGBColor(0xFD, 0xE7, 0x25));
        assert_eq!(v.color(5.0), RGBColor(0xFD, 0xE7, 0x25));
        assert_eq!(v.color(1.0), RGBColor(0x21, 0x90, 0x8C));
        assert_eq!(v.color(f64::NAN), MISSING);
        let d = ColorMap::Diverging { a: 3.0 };
        assert_eq!(d.color(0.0), RGBColor(0xF7, 0xF7, 0xF7));
        assert_eq!(d.color(-3.0), RGBColor(0x05, 0x30, 0x61));
        assert_eq!(d.color(3.0), RGBColor(0x67, 0x00, 0x1F));
    }

    /// [`round_u8`] equals `round() as u8` on every value of the maps' range and around it:
    /// a fine grid of [−0.5, 256] with each integer and half-integer and their neighbours
    /// one ulp away (where a rounding by `v + 0.5` would differ).
    #[test]
    fn round_u8_is_round() {
        let mut values: Vec<f64> = (0..=256 * 1024).map(|k| k as f64 / 1024.0).collect();
        values.extend([-0.4, -1e-300, -0.0, f64::NAN, 0.49999999999999994]);
        for k in 0..=256 {
            for base in [k as f64, k as f64 + 0.5] {
                values.extend([base, base.next_up(), base.next_down()]);
            }
        }
        for v in values {
            assert_eq!(round_u8(v), v.round() as u8, "{v:e}");
        }
    }
}
