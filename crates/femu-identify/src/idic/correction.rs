//! The discretization correction of the integrated-DIC model (approximation-error approach,
//! Kaipio & Somersalo 2007; Richardson extrapolation of the displacement, Roache 1998).
//!
//! The model's pixel displacement `d_h(x; θ)` differs from that of the continuum `d_0` by the
//! discretization error `e_h ≈ C(x) h^p` of its mesh. At an estimate `θ̂` the same load steps are
//! solved on further meshes of the same geometry with element sizes `h_l = h / ρ_l` (not the
//! mesh the images were made from: `ρ_l = √2, √3`, twice and three times the elements, never the
//! renderer's `render_refine²`), and per pixel the three values are fitted by
//!
//! ```text
//!   d_l = d_0 + C ρ_l^(−p)        (ρ_1 = 1: the model's own mesh)                  (1)
//! ```
//!
//! (least squares in `(d_0, C)`, the rate `p` shared by every pixel: observed from the norms
//! of the differences between levels, eq. 2). The correction `c = d_0 − d_h` is then held fixed
//! and added to the model's displacement while the parameters are identified again
//! ([`super::IdicProblem::set_correction`]); `c` depends on `θ` only through the stiffness, a
//! second-order effect over the few per cent the correction moves `θ`.
//!
//! The observed rate solves
//!
//! ```text
//!   ‖d_1 − d_2‖ / ‖d_2 − d_3‖ = (1 − ρ_2^(−p)) / (ρ_2^(−p) − ρ_3^(−p))                    (2)
//! ```
//!
//! The meshes are not nested (the mesher places its nodes anew), so `p` is uncertain: the
//! correction's uncertainty is taken as half the spread of the parameters' shifts between the
//! rates `p ∓ 1` ([`rate_range`]), an interval term that replaces the whole bias.

/// The rate used when the observed one is undefined (eq. 2 has no root in [`RATE_LIMITS`]: the
/// differences do not decrease as an asymptotic range would): the nominal rate of bilinear
/// displacements, `crate::discretization::NOMINAL_RATE`.
pub const FALLBACK_RATE: f64 = crate::discretization::NOMINAL_RATE;

/// Rates outside this range are not believed (eq. 2 on non-nested meshes can give anything
/// when the differences are dominated by the interpolation between unrelated meshes): 1 (the
/// displacement of bilinear elements across a material interface or a contact edge) to 3
/// (faster than bilinear elements converge in displacement). Below 1, the extrapolation over
/// meshes only √3 apart in size amplifies their differences five-fold and more (measured on
/// the built-in thigh: rate 0.77 observed, the correction moved C10_ISCHIO by 20 %).
pub const RATE_LIMITS: [f64; 2] = [1.0, 3.0];

/// One further mesh: `ratio = h / h_l` and the pixel displacements of every load step on it
/// (`None` where it does not cover a pixel).
pub struct Level {
    pub ratio: f64,
    pub displacement: Vec<Vec<Option<[f64; 2]>>>,
}

/// The rate of eq. 2 from the model's displacement `own` (per step and pixel) and two further
/// levels of increasing ratio; `None` without a root in [`RATE_LIMITS`].
pub fn observed_rate(own: &[Vec<[f64; 2]>], levels: &[Level]) -> Option<f64> {
    let [a, b] = levels else {
        return None;
    };
    if !(b.ratio > a.ratio && a.ratio > 1.0) {
        return None;
    }
    let (mut e12, mut e23) = (0.0, 0.0);
    for (i, own) in own.iter().enumerate() {
        for (p, d1) in own.iter().enumerate() {
            if let (Some(d2), Some(d3)) = (a.displacement[i][p], b.displacement[i][p]) {
                for c in 0..2 {
                    e12 += (d1[c] - d2[c]).powi(2);
                    e23 += (d2[c] - d3[c]).powi(2);
                }
            }
        }
    }
    if !(e23 > 0.0 && e12 > 0.0) {
        return None;
    }
    let q = (e12 / e23).sqrt();
    let ratio_of = |p: f64| {
        let (r2, r3) = (a.ratio.powf(-p), b.ratio.powf(-p));
        (1.0 - r2) / (r2 - r3)
    };
    // ratio_of increases with p (from ln ρ_2 / ln(ρ_3/ρ_2) at p → 0): bisection.
    let [mut lo, mut hi] = RATE_LIMITS;
    if q < ratio_of(lo) || q > ratio_of(hi) {
        return None;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if ratio_of(mid) < q {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

/// The correction `c = d_0 − d_h` (px, per step and pixel) of eq. 1 at rate `rate`: per pixel
/// and component, the least-squares line through `(ρ_l^(−p), d_l)` over the model's level and
/// the further levels that cover the pixel, extrapolated to `ρ^(−p) = 0`; zero where no further
/// level covers it.
pub fn correction(own: &[Vec<[f64; 2]>], levels: &[Level], rate: f64) -> Vec<Vec<[f64; 2]>> {
    own.iter()
        .enumerate()
        .map(|(i, own)| {
            own.iter()
                .enumerate()
                .map(|(p, d1)| {
                    let mut pts: Vec<(f64, [f64; 2])> = vec![(1.0, *d1)];
                    pts.extend(
                        levels
                            .iter()
                            .filter_map(|l| l.displacement[i][p].map(|d| (l.ratio.powf(-rate), d))),
                    );
                    if pts.len() < 2 {
                        return [0.0, 0.0];
                    }
                    let n = pts.len() as f64;
                    let xm = pts.iter().map(|q| q.0).sum::<f64>() / n;
                    let sxx: f64 = pts.iter().map(|q| (q.0 - xm).powi(2)).sum();
                    let mut c = [0.0; 2];
                    for (k, ck) in c.iter_mut().enumerate() {
                        let ym = pts.iter().map(|q| q.1[k]).sum::<f64>() / n;
                        let sxy: f64 = pts.iter().map(|q| (q.0 - xm) * (q.1[k] - ym)).sum();
                        let slope = sxy / sxx;
                        // d_0 = ym − slope · xm.
                        *ck = ym - slope * xm - d1[k];
                    }
                    c
                })
                .collect()
        })
        .collect()
}

/// The rates whose corrections bound the correction's uncertainty: `p ∓ 1` within
/// [`RATE_LIMITS`].
pub fn rate_range(rate: f64) -> [f64; 2] {
    [
        (rate - 1.0).max(RATE_LIMITS[0]),
        (rate + 1.0).min(RATE_LIMITS[1]),
    ]
}

/// Root mean square of a correction (px) over the pixels of every step.
pub fn rms_px(c: &[Vec<[f64; 2]>]) -> f64 {
    let (s, n) = c.iter().flatten().fold((0.0, 0usize), |(s, n), d| {
        (s + d[0] * d[0] + d[1] * d[1], n + 1)
    });
    (s / n.max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Levels made exactly by eq. 1 (d_0 and C per pixel, rate 2): the observed rate and the
    /// correction come back to rounding.
    #[test]
    fn richardson_recovers_an_exact_power_law() {
        let p = 2.0;
        let d0 = [[1.0, -2.0], [0.5, 0.25], [3.0, 0.0]];
        let cc = [[0.3, 0.1], [-0.2, 0.05], [0.0, 0.4]];
        let at = |ratio: f64| -> Vec<[f64; 2]> {
            d0.iter()
                .zip(&cc)
                .map(|(d, c)| [d[0] + c[0] * ratio.powf(-p), d[1] + c[1] * ratio.powf(-p)])
                .collect()
        };
        let own = vec![at(1.0)];
        let levels: Vec<Level> = [2f64.sqrt(), 3f64.sqrt()]
            .iter()
            .map(|&r| Level {
                ratio: r,
                displacement: vec![at(r).into_iter().map(Some).collect()],
            })
            .collect();
        let rate = observed_rate(&own, &levels).expect("a root");
        // Bisection over [0.5, 4] for 60 halvings: far below 1e-9.
        assert!((rate - p).abs() < 1e-9, "rate {rate}");
        let c = correction(&own, &levels, rate);
        for (k, ck) in c[0].iter().enumerate() {
            for m in 0..2 {
                // c = −C exactly; rounding of a 3-point fit.
                assert!((ck[m] + cc[k][m]).abs() < 1e-12, "{ck:?} vs {:?}", cc[k]);
            }
        }
        // A pixel no further level covers is not corrected.
        let mut levels = levels;
        levels.iter_mut().for_each(|l| l.displacement[0][1] = None);
        assert_eq!(correction(&own, &levels, 2.0)[0][1], [0.0, 0.0]);
    }

    /// Differences that grow with refinement have no rate.
    #[test]
    fn no_rate_when_the_differences_do_not_decrease() {
        let own = vec![vec![[0.0, 0.0]]];
        let levels = vec![
            Level {
                ratio: 2f64.sqrt(),
                displacement: vec![vec![Some([0.1, 0.0])]],
            },
            Level {
                ratio: 3f64.sqrt(),
                displacement: vec![vec![Some([0.5, 0.0])]],
            },
        ];
        assert_eq!(observed_rate(&own, &levels), None);
        assert_eq!(rate_range(2.0), [1.0, 3.0]);
        assert_eq!(rate_range(1.2), [1.0, 2.2]);
    }
}
