//! Image statistics for the choice of the scanner settings (seed §2.2, criteria b and c):
//! grey-level histograms, saturation, spread, texture against depth, speckle size, and the
//! paired t-test of the random errors (§3.1.3).

use crate::error::UsError;
use statrs::distribution::{ContinuousCDF, StudentsT};

/// Grey-level statistics of an 8-bit image over its region of interest.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GreyStats {
    /// Pixels counted.
    pub pixels: usize,
    /// Counts of the grey levels 0..=255 (values rounded and clamped).
    #[serde(skip)]
    pub histogram: [u64; 256],
    pub mean: f64,
    pub std: f64,
    /// Fractions of the pixels at 0 (black saturation) and at 255 (white saturation).
    pub fraction_black: f64,
    pub fraction_white: f64,
    /// 1st and 99th percentiles and their distance.
    pub p01: f64,
    pub p99: f64,
    pub range_1_99: f64,
    /// Shannon entropy of the histogram (bits, at most 8).
    pub entropy_bits: f64,
}

impl GreyStats {
    /// Saturated fraction (black + white).
    pub fn saturation(&self) -> f64 {
        self.fraction_black + self.fraction_white
    }
}

/// Statistics of `grey` (row-major, 0–255) over the pixels where `mask` is true (all when
/// `None`). Errors when no pixel is counted.
pub fn grey_stats(grey: &[f64], mask: Option<&[bool]>) -> Result<GreyStats, UsError> {
    if let Some(m) = mask {
        if m.len() != grey.len() {
            return Err(UsError::param(
                "mask",
                format!("{} values for {} pixels", m.len(), grey.len()),
            ));
        }
    }
    let mut hist = [0u64; 256];
    let mut n = 0usize;
    let (mut s, mut s2) = (0.0, 0.0);
    for (k, &g) in grey.iter().enumerate() {
        if mask.is_some_and(|m| !m[k]) || !g.is_finite() {
            continue;
        }
        let v = g.round().clamp(0.0, 255.0);
        hist[v as usize] += 1;
        n += 1;
        s += v;
        s2 += v * v;
    }
    if n == 0 {
        return Err(UsError::param(
            "region of interest",
            "no pixel of the image is inside it",
        ));
    }
    let nf = n as f64;
    let mean = s / nf;
    let std = ((s2 / nf - mean * mean).max(0.0) * nf / (nf - 1.0).max(1.0)).sqrt();
    let percentile = |q: f64| -> f64 {
        // Smallest level whose cumulative fraction reaches q.
        let target = q * nf;
        let mut acc = 0u64;
        for (v, &c) in hist.iter().enumerate() {
            acc += c;
            if acc as f64 >= target {
                return v as f64;
            }
        }
        255.0
    };
    let entropy_bits = -hist
        .iter()
        .filter(|&&c| c > 0)
        .map(|&c| {
            let p = c as f64 / nf;
            p * p.log2()
        })
        .sum::<f64>();
    let (p01, p99) = (percentile(0.01), percentile(0.99));
    Ok(GreyStats {
        pixels: n,
        histogram: hist,
        mean,
        std,
        fraction_black: hist[0] as f64 / nf,
        fraction_white: hist[255] as f64 / nf,
        p01,
        p99,
        range_1_99: p99 - p01,
        entropy_bits,
    })
}

/// Texture against depth (seed Fig. 4): the mean magnitude of the grey-level gradient
/// (central differences, grey levels per pixel) in horizontal bands of `band` rows, over the
/// pixels whose 4 neighbours are inside the mask. One value per band (NaN for a band without
/// such pixel), band `b` covering rows `b·band .. (b+1)·band`.
pub fn texture_by_depth(
    grey: &[f64],
    width: usize,
    height: usize,
    mask: Option<&[bool]>,
    band: usize,
) -> Result<Vec<f64>, UsError> {
    if band == 0 {
        return Err(UsError::param("depth band", "must be at least 1 row"));
    }
    if grey.len() != width * height {
        return Err(UsError::param(
            "image",
            format!("{} values for {width} x {height}", grey.len()),
        ));
    }
    let inside = |x: usize, y: usize| mask.is_none_or(|m| m[y * width + x]);
    let nb = height.div_ceil(band);
    let mut sum = vec![0.0; nb];
    let mut cnt = vec![0usize; nb];
    for y in 1..height.saturating_sub(1) {
        for x in 1..width.saturating_sub(1) {
            if !(inside(x, y)
                && inside(x - 1, y)
                && inside(x + 1, y)
                && inside(x, y - 1)
                && inside(x, y + 1))
            {
                continue;
            }
            let gx = 0.5 * (grey[y * width + x + 1] - grey[y * width + x - 1]);
            let gy = 0.5 * (grey[(y + 1) * width + x] - grey[(y - 1) * width + x]);
            sum[y / band] += gx.hypot(gy);
            cnt[y / band] += 1;
        }
    }
    Ok(sum
        .iter()
        .zip(&cnt)
        .map(|(s, &c)| if c > 0 { s / c as f64 } else { f64::NAN })
        .collect())
}

/// Speckle size: the lag (pixels, linearly interpolated) where the normalized autocovariance
/// of `values` along x (`axis = 0`, lateral) or y (`axis = 1`, axial) over the rectangle
/// `[x0, x1) x [y0, y1)` (each row normalized first) first drops below 1/2 — half the full width at half maximum of the
/// autocorrelation peak. Errors if it never drops within a quarter of the rectangle.
pub fn correlation_length(
    values: &[f64],
    width: usize,
    rect: [usize; 4],
    axis: usize,
) -> Result<f64, UsError> {
    let [x0, y0, x1, y1] = rect;
    if x1 <= x0 + 4 || y1 <= y0 + 4 || values.len() < y1 * width || x1 > width {
        return Err(UsError::param(
            "rectangle",
            format!("{rect:?} is too small or outside the image"),
        ));
    }
    // Each row normalized to zero mean and unit variance: a depth trend (attenuation, TGC)
    // is not speckle and must not count as correlation.
    let mut z = vec![0.0; width * y1];
    for y in y0..y1 {
        let row = &values[y * width + x0..y * width + x1];
        let (m, s) = mean_sd(row);
        for x in x0..x1 {
            z[y * width + x] = if s > 0.0 {
                (values[y * width + x] - m) / s
            } else {
                0.0
            };
        }
    }
    let values = &z;
    let mean = 0.0;
    let cov = |lag: usize| -> f64 {
        let (mut s, mut c) = (0.0, 0usize);
        for y in y0..y1 - if axis == 1 { lag } else { 0 } {
            for x in x0..x1 - if axis == 0 { lag } else { 0 } {
                let (xx, yy) = if axis == 0 {
                    (x + lag, y)
                } else {
                    (x, y + lag)
                };
                s += (values[y * width + x] - mean) * (values[yy * width + xx] - mean);
                c += 1;
            }
        }
        s / c as f64
    };
    let c0 = cov(0);
    if !(c0 > 0.0) {
        return Err(UsError::param("image", "no variation over the rectangle"));
    }
    let max_lag = if axis == 0 {
        (x1 - x0) / 4
    } else {
        (y1 - y0) / 4
    };
    let mut prev = 1.0;
    for lag in 1..=max_lag {
        let r = cov(lag) / c0;
        if r < 0.5 {
            return Ok(lag as f64 - 1.0 + (prev - 0.5) / (prev - r));
        }
        prev = r;
    }
    Err(UsError::param(
        "image",
        format!("the autocorrelation stays above 1/2 up to a lag of {max_lag} px"),
    ))
}

/// Result of a paired t-test.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PairedTTest {
    /// Number of pairs.
    pub n: usize,
    /// Mean of the differences `a − b`.
    pub mean_difference: f64,
    /// `t = mean(d) / (sd(d) / √n)`.
    pub t: f64,
    pub degrees_of_freedom: f64,
    /// Two-sided p-value `2 (1 − T_{n−1}(|t|))`.
    pub p_value: f64,
}

/// Paired (dependent-samples) two-sided t-test of `a` against `b` (Student 1908; as
/// `scipy.stats.ttest_rel`), with the t distribution of `statrs`. Needs at least two pairs;
/// identical samples (all differences equal) give `t = ±∞, p = 0` unless the differences are
/// all zero (`t = 0`, `p = 1`).
pub fn paired_t_test(a: &[f64], b: &[f64]) -> Result<PairedTTest, UsError> {
    if a.len() != b.len() {
        return Err(UsError::param(
            "paired t-test",
            format!(
                "{} and {} values: the samples must pair up",
                a.len(),
                b.len()
            ),
        ));
    }
    let n = a.len();
    if n < 2 {
        return Err(UsError::param(
            "paired t-test",
            format!("{n} pair(s): at least 2 are needed"),
        ));
    }
    if a.iter().chain(b).any(|v| !v.is_finite()) {
        return Err(UsError::param("paired t-test", "a value is not finite"));
    }
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let nf = n as f64;
    let mean = d.iter().sum::<f64>() / nf;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (nf - 1.0);
    let df = nf - 1.0;
    let (t, p) = if var > 0.0 {
        let t = mean / (var / nf).sqrt();
        let dist = StudentsT::new(0.0, 1.0, df)
            .map_err(|e| UsError::param("paired t-test", e.to_string()))?;
        (t, (2.0 * (1.0 - dist.cdf(t.abs()))).clamp(0.0, 1.0))
    } else if mean == 0.0 {
        (0.0, 1.0)
    } else {
        (mean.signum() * f64::INFINITY, 0.0)
    };
    Ok(PairedTTest {
        n,
        mean_difference: mean,
        t,
        degrees_of_freedom: df,
        p_value: p,
    })
}

/// Mean and sample standard deviation.
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = v.iter().sum::<f64>() / n;
    let s = if v.len() > 1 {
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    (m, s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_of_a_known_image() {
        let g: Vec<f64> = (0..100)
            .map(|k| {
                if k < 10 {
                    0.0
                } else if k < 15 {
                    255.0
                } else {
                    100.0
                }
            })
            .collect();
        let s = grey_stats(&g, None).unwrap();
        assert_eq!(s.pixels, 100);
        assert!((s.fraction_black - 0.1).abs() < 1e-12 && (s.fraction_white - 0.05).abs() < 1e-12);
        assert_eq!((s.p01, s.p99), (0.0, 255.0));
        let h = -(0.1f64 * 0.1f64.log2() + 0.05 * 0.05f64.log2() + 0.85 * 0.85f64.log2());
        assert!((s.entropy_bits - h).abs() < 1e-12);
        let mask: Vec<bool> = (0..100).map(|k| k >= 15).collect();
        let s = grey_stats(&g, Some(&mask)).unwrap();
        assert_eq!((s.mean, s.std, s.saturation()), (100.0, 0.0, 0.0));
        assert!(grey_stats(&g, Some(&[false; 100])).is_err());
    }

    #[test]
    fn texture_of_a_ramp() {
        // grey = 3 x: gradient magnitude 3 everywhere inside.
        let (w, h) = (20, 12);
        let g: Vec<f64> = (0..w * h).map(|k| 3.0 * (k % w) as f64).collect();
        let t = texture_by_depth(&g, w, h, None, 4).unwrap();
        assert_eq!(t.len(), 3);
        assert!(t.iter().all(|v| (v - 3.0).abs() < 1e-12));
    }

    #[test]
    fn t_test_edge_cases() {
        assert!(paired_t_test(&[1.0], &[2.0]).is_err());
        assert!(paired_t_test(&[1.0, 2.0], &[2.0]).is_err());
        let same = paired_t_test(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]).unwrap();
        assert_eq!((same.t, same.p_value), (0.0, 1.0));
    }
}
