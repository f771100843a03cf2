//! The error of a measured field estimated from the fit's own residuals: a spatial covariance
//! model for weighted FEMU when the measurement's covariance does not describe its error.
//!
//! **Why.** A DIC field's covariance (`femu_dic::quality`, `C = A⁻¹ M_σ A⁻¹`) propagates the
//! grey-level residual of the correlation as if it were image noise. On B-mode frames most of a
//! field's error is not that: speckle is an interference pattern that does not move exactly with
//! the tissue (lateral resolution 5-10 times coarser than the axial one), and bright specular lines
//! (skin, fascia) fix the axial motion of an element but hardly its lateral one. Measured on frames
//! of an independent simulator, the composed field's error was 0.3-1.3 px laterally and
//! 0.1-0.3 px axially where the DIC's covariance said 0.07 px, larger near the skin, and
//! correlated over several elements. Whitening by that covariance alone trusts the wrong
//! components and the wrong places: the fits got worse than the unweighted ones.
//!
//! **Model.** Each component `c` (ux, uy) of the error at point `i` has a standard deviation
//! `σ_c(band(i))` that varies over [`BANDS`] depth bands of the field (its points in file order:
//! DIC grids are written row by row) and a correlation between points at distance `h` of
//! `ρ_c(h) = ν_c δ(h) + (1 − ν_c) exp(−h / a_c)` (a nugget `ν_c` and an exponential range `a_c`):
//!
//! `Σ_ij,c = σ_c(i) σ_c(j) ρ_c(|x_i − x_j|)`, the two components uncorrelated.
//!
//! The matrix is positive definite (the exponential is a positive definite function in the
//! plane and the nugget adds a positive diagonal; the scaling by `σ` keeps it so).
//!
//! **Estimation** (feasible generalized least squares: fit, estimate the error's covariance from
//! the residuals, fit again with it):
//! - the band variances: the mean squared residual of the band, times `n / (n − p)` for the `p`
//!   parameters the fit took from the data;
//! - the correlation: the empirical semivariogram of the standardized residuals
//!   `z = r / σ(band)` in distance classes (Matheron's estimator), fitted by weighted least squares
//!   (Cressie's weights `N(h) / γ(h)²`) with `γ(h) = ν + (1 − ν)(1 − exp(−h/a))` over a grid of
//!   ranges, `ν` in `[0, 1]` by a closed-form least squares at each range.
//!
//! The residuals of a fit underestimate the error's long-range part (the parameters absorb some
//! of it); the intervals keep their data-driven safeguards on top (Birge ratio and block jackknife,
//! [`crate::misfit_intervals`]).

use crate::fit::FitResult;
use crate::measured::MeasuredField;
use crate::weighted::FieldCovariance;
use femu_mech::Model;
use femu_mesh::locate::PointLocator;
use serde::{Deserialize, Serialize};

/// Depth bands of the variance model: 4 bands of a 40 mm window are 10 mm each, the skin and
/// fat layer in the first.
pub const BANDS: usize = 4;

/// Distance classes of the semivariogram.
const CLASSES: usize = 15;

/// The error model of one displacement component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComponentError {
    /// Standard deviation per depth band (mm), first band first.
    pub sd_mm: Vec<f64>,
    /// Fraction of the variance uncorrelated between points (`ν`).
    pub nugget: f64,
    /// Range of the exponential correlation (mm, `a`).
    pub range_mm: f64,
}

impl ComponentError {
    /// `ρ(h)` for two distinct points at distance `h` (`1` for a point with itself).
    fn correlation(&self, h: f64, same: bool) -> f64 {
        if same {
            1.0
        } else {
            (1.0 - self.nugget) * (-h / self.range_mm).exp()
        }
    }
}

/// The estimated error of a measured field (module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorModel {
    /// ux, uy.
    pub components: [ComponentError; 2],
    /// Points of the field the bands are counted over (`band(i) = i * BANDS / points`).
    pub field_points: usize,
    /// Residual points it was estimated from.
    pub used_points: usize,
}

impl ErrorModel {
    /// The band of field point `i`.
    fn band(&self, i: usize) -> usize {
        (i * BANDS / self.field_points.max(1)).min(BANDS - 1)
    }

    /// The model's covariance over every point of `field` (mm², `[ux0, uy0, ux1, ...]`), plus
    /// `base` (the measurement's own covariance, e.g. the DIC's) when given.
    pub fn covariance(
        &self,
        field: &MeasuredField,
        base: Option<&FieldCovariance>,
    ) -> FieldCovariance {
        let n = field.points.len();
        let m = 2 * n;
        let mut values = match base {
            Some(b) if b.points == n => b.values.clone(),
            _ => vec![0.0; m * m],
        };
        for i in 0..n {
            let bi = self.band(i);
            for j in 0..n {
                let bj = self.band(j);
                let d = [
                    field.points[i].x[0] - field.points[j].x[0],
                    field.points[i].x[1] - field.points[j].x[1],
                ];
                let h = (d[0] * d[0] + d[1] * d[1]).sqrt();
                for (c, e) in self.components.iter().enumerate() {
                    values[(2 * i + c) * m + 2 * j + c] +=
                        e.sd_mm[bi] * e.sd_mm[bj] * e.correlation(h, i == j);
                }
            }
        }
        FieldCovariance { points: n, values }
    }

    /// One line for a log: per component the band sd (µm), nugget and range.
    pub fn describe(&self) -> String {
        let c = |name: &str, e: &ComponentError| {
            format!(
                "{name} sd {} µm by depth band, {:.0} % uncorrelated, range {:.1} mm",
                e.sd_mm
                    .iter()
                    .map(|s| format!("{:.0}", s * 1e3))
                    .collect::<Vec<_>>()
                    .join("/"),
                100.0 * e.nugget,
                e.range_mm
            )
        };
        format!(
            "{}; {}",
            c("ux", &self.components[0]),
            c("uy", &self.components[1])
        )
    }
}

/// The residual `u_model − u_measured` (mm) of each point of `field` that the fit `best` on
/// `model` used (inside the mesh, both components weighing something), with its index in the
/// field. `best.residual` holds `√w (u_model − u_measured)` per located point (a per-point
/// weighted fit, [`crate::fit::Problem`]), in field order.
pub fn raw_residuals(
    model: &Model,
    field: &MeasuredField,
    best: &FitResult,
) -> Vec<(usize, [f64; 2])> {
    let locator = PointLocator::new(&model.mesh);
    let mut out = Vec::new();
    let mut l = 0;
    for (i, p) in field.points.iter().enumerate() {
        if locator.locate(p.x).is_none() {
            continue;
        }
        if 2 * l + 1 >= best.residual.len() {
            break;
        }
        let r = [best.residual[2 * l], best.residual[2 * l + 1]];
        l += 1;
        if p.weight[0] > 0.0 && p.weight[1] > 0.0 {
            out.push((i, [r[0] / p.weight[0].sqrt(), r[1] / p.weight[1].sqrt()]));
        }
    }
    out
}

/// Estimates the error model of `field` from the residuals `residuals` (from [`raw_residuals`])
/// of a fit of `free` parameters (module doc): with the field's own covariance `base`, the
/// error beyond it (each band's variance less the band's mean variance in `base`, not below
/// zero), so that `base` plus the model is the error's whole covariance and a `base` that
/// already holds the whole error gets (nearly) nothing added. `None` with fewer than 8 points
/// per band.
pub fn estimate(
    field: &MeasuredField,
    residuals: &[(usize, [f64; 2])],
    free: usize,
    base: Option<&FieldCovariance>,
) -> Option<ErrorModel> {
    let n = residuals.len();
    if n < 8 * BANDS || n <= free {
        return None;
    }
    let mut model = ErrorModel {
        components: [0, 1].map(|_| ComponentError {
            sd_mm: vec![0.0; BANDS],
            nugget: 1.0,
            range_mm: 1.0,
        }),
        field_points: field.points.len(),
        used_points: n,
    };
    // Each component's data share of the parameters: p/2 of the 2n residuals' p.
    let leverage = n as f64 / (n as f64 - 0.5 * free as f64);
    let positions: Vec<[f64; 2]> = residuals.iter().map(|(i, _)| field.points[*i].x).collect();
    let bands: Vec<usize> = residuals.iter().map(|(i, _)| model.band(*i)).collect();
    for c in 0..2 {
        let mut sum = [0.0; BANDS];
        let mut known = [0.0; BANDS];
        let mut count = [0usize; BANDS];
        for ((i, r), &b) in residuals.iter().zip(&bands) {
            sum[b] += r[c] * r[c];
            if let Some(base) = base.filter(|b| b.points == field.points.len()) {
                let k = 2 * i + c;
                known[b] += base.values[k * 2 * base.points + k];
            }
            count[b] += 1;
        }
        let total: f64 = sum.iter().sum::<f64>() / n as f64;
        let total_known: f64 = known.iter().sum::<f64>() / n as f64;
        // A band with few points borrows the field's mean variances.
        let band_mean = |b: usize| -> (f64, f64) {
            if count[b] >= 8 {
                (sum[b] / count[b] as f64, known[b] / count[b] as f64)
            } else {
                (total, total_known)
            }
        };
        let sd_total: Vec<f64> = (0..BANDS)
            .map(|b| (band_mean(b).0 * leverage).max(1e-30).sqrt())
            .collect();
        let sd: Vec<f64> = (0..BANDS)
            .map(|b| {
                let (v, k) = band_mean(b);
                (v * leverage - k).max(0.0).sqrt()
            })
            .collect();
        // The correlation's shape from the residuals standardized by their whole sd.
        let z: Vec<f64> = residuals
            .iter()
            .zip(&bands)
            .map(|((_, r), &b)| r[c] / sd_total[b])
            .collect();
        let (nugget, range) = fit_correlation(&positions, &z);
        model.components[c] = ComponentError {
            sd_mm: sd,
            nugget,
            range_mm: range,
        };
    }
    Some(model)
}

/// `(ν, a)` of the correlation `ν δ + (1 − ν) exp(−h/a)` fitted to the semivariogram of the
/// standardized values `z` at `x` (module doc).
fn fit_correlation(x: &[[f64; 2]], z: &[f64]) -> (f64, f64) {
    let n = x.len();
    let mut hmax: f64 = 0.0;
    let mut hmin = f64::INFINITY;
    for i in 0..n {
        for j in 0..i {
            let h = dist(x[i], x[j]);
            hmax = hmax.max(h);
            if h > 0.0 {
                hmin = hmin.min(h);
            }
        }
    }
    if !(hmin.is_finite() && hmax > hmin) {
        return (1.0, 1.0);
    }
    // Distance classes up to half the largest distance (the usual limit of a variogram's
    // reliable part).
    let top = 0.5 * hmax;
    let width = top / CLASSES as f64;
    let mut g = [0.0; CLASSES];
    let mut cnt = [0usize; CLASSES];
    let mut hsum = [0.0; CLASSES];
    for i in 0..n {
        for j in 0..i {
            let h = dist(x[i], x[j]);
            if h >= top || h <= 0.0 {
                continue;
            }
            let k = ((h / width) as usize).min(CLASSES - 1);
            let d = z[i] - z[j];
            g[k] += 0.5 * d * d;
            cnt[k] += 1;
            hsum[k] += h;
        }
    }
    let classes: Vec<(f64, f64, f64)> = (0..CLASSES)
        .filter(|&k| cnt[k] >= 10)
        .map(|k| (hsum[k] / cnt[k] as f64, g[k] / cnt[k] as f64, cnt[k] as f64))
        .collect();
    if classes.len() < 3 {
        return (1.0, hmin);
    }
    let mut best = (f64::INFINITY, 1.0, hmin);
    let ranges = 60;
    for s in 0..ranges {
        // Ranges from a tenth of the smallest spacing to twice the largest distance.
        let a = 0.1 * hmin * (20.0 * hmax / hmin).powf(s as f64 / (ranges - 1) as f64);
        // γ(h) = ν + (1 − ν) e(h) with e = 1 − exp(−h/a): γ − e = ν (1 − e), least squares in ν
        // with Cressie's weights from the data's own γ (one pass).
        let (mut num, mut den) = (0.0, 0.0);
        for &(h, gh, c) in &classes {
            let e = 1.0 - (-h / a).exp();
            let w = c / gh.max(1e-6).powi(2);
            num += w * (gh - e) * (1.0 - e);
            den += w * (1.0 - e) * (1.0 - e);
        }
        let nu = if den > 0.0 {
            (num / den).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let sse: f64 = classes
            .iter()
            .map(|&(h, gh, c)| {
                let model = nu + (1.0 - nu) * (1.0 - (-h / a).exp());
                c / model.max(1e-6).powi(2) * (gh - model).powi(2)
            })
            .sum();
        if sse < best.0 {
            best = (sse, nu, a);
        }
    }
    (best.1, best.2)
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measured::MeasuredPoint;
    use crate::weighted::Whitening;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// A `side x side` grid of points 0.8 mm apart, row by row.
    fn grid_field(side: usize) -> MeasuredField {
        MeasuredField {
            points: (0..side * side)
                .map(|k| MeasuredPoint {
                    x: [0.8 * (k % side) as f64, 0.8 * (k / side) as f64],
                    u: [0.0; 2],
                    weight: [1.0; 2],
                })
                .collect(),
            comments: Vec::new(),
        }
    }

    /// `count` error fields drawn from `cov` (seeded; `L w`, `cov = L Lᵀ`), as residuals per point.
    fn draws(cov: &FieldCovariance, seed: u64, count: usize) -> Vec<Vec<(usize, [f64; 2])>> {
        let m = 2 * cov.points;
        let a = faer::Mat::<f64>::from_fn(m, m, |i, j| cov.values[i * m + j]);
        let l = a.llt(faer::Side::Lower).unwrap().L().to_owned();
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..count)
            .map(|_| {
                let w: Vec<f64> = (0..m).map(|_| StandardNormal.sample(&mut rng)).collect();
                let e: Vec<f64> = (0..m)
                    .map(|i| (0..=i).map(|j| l[(i, j)] * w[j]).sum())
                    .collect();
                (0..cov.points)
                    .map(|i| (i, [e[2 * i], e[2 * i + 1]]))
                    .collect()
            })
            .collect()
    }

    /// A 24 x 24 grid (0.8 mm) with errors drawn from a known model: the estimate finds its band
    /// sd within 15 % and its range within a factor 1.6 (576 points, an exponential field of
    /// range 2 mm over a 19 mm square: about 20 independent patches per band).
    #[test]
    fn recovers_a_known_error_model() {
        let field = grid_field(24);
        let truth = ErrorModel {
            components: [
                ComponentError {
                    sd_mm: vec![0.12, 0.05, 0.04, 0.05],
                    nugget: 0.3,
                    range_mm: 2.0,
                },
                ComponentError {
                    sd_mm: vec![0.02, 0.01, 0.01, 0.015],
                    nugget: 0.6,
                    range_mm: 1.0,
                },
            ],
            field_points: field.points.len(),
            used_points: field.points.len(),
        };
        let cov = truth.covariance(&field, None);
        let estimates: Vec<ErrorModel> = draws(&cov, 11, 6)
            .iter()
            .map(|r| estimate(&field, r, 0, None).unwrap())
            .collect();
        for c in 0..2 {
            for b in 0..BANDS {
                let mean = estimates
                    .iter()
                    .map(|e| e.components[c].sd_mm[b])
                    .sum::<f64>()
                    / estimates.len() as f64;
                let t = truth.components[c].sd_mm[b];
                assert!(
                    (mean / t - 1.0).abs() < 0.15,
                    "component {c} band {b}: sd {mean} for {t}"
                );
            }
            let range = estimates
                .iter()
                .map(|e| e.components[c].range_mm.ln())
                .sum::<f64>()
                / estimates.len() as f64;
            let t = truth.components[c].range_mm;
            assert!(
                (range.exp() / t).ln().abs() < 1.6f64.ln(),
                "component {c}: range {} for {t}",
                range.exp()
            );
        }
        // The estimate's covariance whitens: positive definite.
        Whitening::new(&estimates[0].covariance(&field, None)).unwrap();
    }

    /// A field whose own covariance already holds its whole error gets little added: the excess
    /// variance is the sampling scatter of the band means (576 points, ~20 patches a band: a
    /// few tens of % of the variance at most), where an underestimated covariance (a tenth of
    /// the error's variance) gets most of it back.
    #[test]
    fn adds_only_the_error_beyond_the_given_covariance() {
        let field = grid_field(24);
        let truth = ErrorModel {
            components: [0, 1].map(|_| ComponentError {
                sd_mm: vec![0.05; BANDS],
                nugget: 0.5,
                range_mm: 1.5,
            }),
            field_points: field.points.len(),
            used_points: field.points.len(),
        };
        let cov = truth.covariance(&field, None);
        let residuals = draws(&cov, 5, 1).remove(0);
        let whole = estimate(&field, &residuals, 0, Some(&cov)).unwrap();
        let small = FieldCovariance {
            points: cov.points,
            values: cov.values.iter().map(|v| 0.1 * v).collect(),
        };
        let under = estimate(&field, &residuals, 0, Some(&small)).unwrap();
        for c in 0..2 {
            for b in 0..BANDS {
                let added = whole.components[c].sd_mm[b].powi(2) / 0.05f64.powi(2);
                assert!(
                    added < 0.4,
                    "component {c} band {b}: {added} of the variance added"
                );
                let back = under.components[c].sd_mm[b].powi(2) / 0.05f64.powi(2);
                assert!(
                    (0.5..1.5).contains(&back),
                    "component {c} band {b}: {back} of the variance added to a tenth"
                );
            }
        }
    }

    #[test]
    fn too_few_points_give_no_model() {
        let field = MeasuredField {
            points: (0..10)
                .map(|k| MeasuredPoint {
                    x: [k as f64, 0.0],
                    u: [0.0; 2],
                    weight: [1.0; 2],
                })
                .collect(),
            comments: Vec::new(),
        };
        let r: Vec<(usize, [f64; 2])> = (0..10).map(|i| (i, [0.1, 0.1])).collect();
        assert!(estimate(&field, &r, 2, None).is_none());
    }
}
