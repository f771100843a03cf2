//! Observed convergence rates: the slope of the error against the element size on a log-log
//! scale, as scikit-fem's and fenris' convergence tests fit it.

use serde::Serialize;

/// A fitted power law `e ≈ C h^p`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RateFit {
    /// The rate `p`.
    pub rate: f64,
    /// The constant `C` (mm^(1-p) for a displacement error in mm).
    pub constant: f64,
    /// Coefficient of determination of the fit in log-log space (1 for a perfect power law).
    pub r_squared: f64,
    /// Number of points fitted.
    pub points: usize,
}

/// Least-squares fit of `log e = log C + p log h` over the pairs `(h, e)` with `h, e > 0`;
/// `None` with fewer than two such pairs or a single distinct `h`.
pub fn fit_rate(h: &[f64], e: &[f64]) -> Option<RateFit> {
    let pts: Vec<(f64, f64)> = h
        .iter()
        .zip(e)
        .filter(|(h, e)| **h > 0.0 && **e > 0.0 && h.is_finite() && e.is_finite())
        .map(|(h, e)| (h.ln(), e.ln()))
        .collect();
    let n = pts.len();
    if n < 2 {
        return None;
    }
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n as f64;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let syy: f64 = pts.iter().map(|p| (p.1 - my).powi(2)).sum();
    if !(sxx > 1e-300) {
        return None;
    }
    let rate = sxy / sxx;
    let r_squared = if syy > 0.0 {
        (sxy * sxy / (sxx * syy)).min(1.0)
    } else {
        1.0
    };
    Some(RateFit {
        rate,
        constant: (my - rate * mx).exp(),
        r_squared,
        points: n,
    })
}

/// Fit of differences from the finest mesh, `e_i = |u_i - u_f|` at sizes `h_i > h_f`: if the
/// error of each mesh behaves like `C h^p` with one sign, `e_i ≈ C (h_i^p - h_f^p)`; fitting
/// `C h^p` alone would understate `p` for the meshes close to the finest (at `h_i = 1.4 h_f`
/// the difference is only half the error). The rate is found by a golden-section search on
/// the log-space residual, `C` in closed form for each trial `p`; `p` in [0.25, 8].
pub fn fit_rate_against_finest(h: &[f64], e: &[f64], h_finest: f64) -> Option<RateFit> {
    let pts: Vec<(f64, f64)> = h
        .iter()
        .zip(e)
        .filter(|(h, e)| **h > h_finest && **e > 0.0 && h.is_finite() && e.is_finite())
        .map(|(h, e)| (*h, e.ln()))
        .collect();
    let n = pts.len();
    if n < 2 || !(h_finest > 0.0) {
        return None;
    }
    // For a trial p: log C = mean(log e - log(h^p - h_f^p)), residual sum of squares.
    let fit = |p: f64| -> (f64, f64) {
        let g: Vec<f64> = pts
            .iter()
            .map(|&(h, le)| le - (h.powf(p) - h_finest.powf(p)).ln())
            .collect();
        let lc = g.iter().sum::<f64>() / n as f64;
        let ss = g.iter().map(|v| (v - lc).powi(2)).sum::<f64>();
        (lc, ss)
    };
    let (mut a, mut b) = (0.25f64, 8.0f64);
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let mut c = b - phi * (b - a);
    let mut d = a + phi * (b - a);
    for _ in 0..100 {
        if fit(c).1 < fit(d).1 {
            b = d;
        } else {
            a = c;
        }
        c = b - phi * (b - a);
        d = a + phi * (b - a);
        if b - a < 1e-10 {
            break;
        }
    }
    let rate = 0.5 * (a + b);
    let (lc, ss) = fit(rate);
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let syy: f64 = pts.iter().map(|p| (p.1 - my).powi(2)).sum();
    Some(RateFit {
        rate,
        constant: lc.exp(),
        r_squared: if syy > 0.0 {
            (1.0 - ss / syy).max(0.0)
        } else {
            1.0
        },
        points: n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_power_laws_are_recovered() {
        let h = [4.0, 2.0, 1.0, 0.5];
        let e: Vec<f64> = h.iter().map(|h: &f64| 3.0 * h.powf(1.7)).collect();
        let f = fit_rate(&h, &e).unwrap();
        assert!((f.rate - 1.7).abs() < 1e-12 && (f.constant - 3.0).abs() < 1e-10);
        let hf = 0.25;
        let d: Vec<f64> = h
            .iter()
            .map(|h: &f64| 3.0 * (h.powf(2.0) - hf * hf))
            .collect();
        let f = fit_rate_against_finest(&h, &d, hf).unwrap();
        assert!((f.rate - 2.0).abs() < 1e-6, "{f:?}");
        assert!((f.constant - 3.0).abs() < 1e-5, "{f:?}");
        assert!(fit_rate(&[1.0], &[1.0]).is_none());
    }
}
