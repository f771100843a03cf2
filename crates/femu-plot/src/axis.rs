//! A base-10 logarithmic axis whose labels suit short ranges too.
//!
//! plotters' own log axis labels only the powers of ten, so an axis from 0.25 to 8 (a mesh
//! convergence study) gets a single label. This one labels `1, 2, 5 × 10ᵏ` (or every mantissa)
//! when the range spans few decades, and draws light lines at `1..9 × 10ᵏ`.

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use std::ops::Range;

/// A logarithmic axis over `lo..hi` (both positive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Log10Axis {
    pub lo: f64,
    pub hi: f64,
}

impl Log10Axis {
    /// The values `m × 10ᵏ` inside the range, for every mantissa `m` of `mantissas` and every
    /// `step`-th decade.
    fn points(&self, mantissas: &[f64], step: i32) -> Vec<f64> {
        let (k0, k1) = (
            self.lo.log10().floor() as i32,
            self.hi.log10().ceil() as i32,
        );
        let mut out = Vec::new();
        let mut k = k0 - k0.rem_euclid(step.max(1));
        while k <= k1 {
            for &m in mantissas {
                // Round to the printed precision so that 3×10⁻¹ is 0.3, not 0.30000000000000004.
                let v: f64 = format!("{m}e{k}").parse().unwrap_or(m * 10f64.powi(k));
                if v >= self.lo * (1.0 - 1e-12) && v <= self.hi * (1.0 + 1e-12) {
                    out.push(v);
                }
            }
            k += step.max(1);
        }
        out
    }

    /// The labelled values: the finest of `1..9`, `1, 2, 5`, `1` per decade, `1` every few
    /// decades that has at most `max` points.
    fn labelled(&self, max: usize) -> Vec<f64> {
        let max = max.max(2);
        let all: [f64; 9] = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
        for set in [&all[..], &[1.0, 2.0, 5.0][..], &[1.0][..]] {
            let p = self.points(set, 1);
            if p.len() <= max {
                return p;
            }
        }
        let decades = (self.hi / self.lo).log10().ceil() as usize;
        let step = decades.div_ceil(max - 1).max(1) as i32;
        self.points(&[1.0], step)
    }
}

impl Ranged for Log10Axis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let (a, b) = (self.lo.ln(), self.hi.ln());
        let v = if *value > 0.0 {
            value.ln()
        } else {
            a - 10.0 * (b - a)
        };
        let t = (v - a) / (b - a);
        (limit.0 as f64 + t * (limit.1 - limit.0) as f64).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        let bold = self.labelled(hint.bold_points());
        if !hint.weight().allow_light_points() {
            return bold;
        }
        // Light lines: every mantissa when the range spans at most 6 decades.
        let decades = (self.hi / self.lo).log10();
        let mut light = if decades <= 6.0 {
            self.points(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0], 1)
        } else {
            self.points(&[1.0], 1)
        };
        light.retain(|v| !bold.iter().any(|b| (b - v).abs() <= 1e-12 * v.abs()));
        light
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_suit_short_and_long_ranges() {
        let short = Log10Axis { lo: 0.23, hi: 8.8 };
        assert_eq!(short.labelled(20).len(), 15);
        assert_eq!(short.labelled(10), vec![0.5, 1.0, 2.0, 5.0]);
        let long = Log10Axis { lo: 3e-6, hi: 0.2 };
        assert_eq!(long.labelled(8), vec![1e-5, 1e-4, 1e-3, 1e-2, 1e-1]);
        let very_long = Log10Axis { lo: 1e-12, hi: 1.0 };
        assert_eq!(very_long.labelled(5), vec![1e-12, 1e-9, 1e-6, 1e-3, 1.0]);
        assert_eq!(short.map(&0.23, (0, 100)), 0);
        assert_eq!(short.map(&8.8, (0, 100)), 100);
    }
}
