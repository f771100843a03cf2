//! The model's own error in an identification: how far the parameters identified on the
//! model's mesh are from those a converged mesh would give, from the same data.
//!
//! The seed chose its mesh once, by a convergence study under the reference parameters
//! (§2.1.2.1). An identification can still be biased by the mesh far beyond its noise: with many
//! measured points the statistical uncertainty shrinks as `1/√N` while the discretization error
//! of the field does not, so a field error well below the noise can move the parameters by many
//! standard deviations, and a small residual does not warn of it.
//!
//! At the optimum `φ̂` on the model's mesh (element size `h`), the same measured points are
//! evaluated on meshes of the same geometry refined by the ratios `ρ_i = h / h_i` (e.g. √2 and
//! 2). With `r_i` the whitened residuals on mesh `i` (the data cancel in differences), the
//! parameter shift to mesh `i` is one Gauss–Newton step with the exact Jacobian `J_i`:
//!
//! ```text
//!   δ_i = -(J_iᵀ J_i)⁻¹ J_iᵀ (r_i - r_h)
//! ```
//!
//! With a discretization error `e(h) = C h^p`, the field differences `d_i = |r_i - r_h|` obey
//! `d_2 / d_1 = (1 - ρ_2^-p) / (1 - ρ_1^-p)`, which gives the observed rate `p`; the bias of the
//! identified log-parameters (model's mesh minus converged) is then `b = -δ_f / (1 - ρ_f^-p)`
//! for the finest level `f` (Richardson). When `|b_k|` exceeds [`BIAS_FRACTION`] of the standard
//! deviation the check is flagged: the caller widens the interval ([`crate::campaign::widen`])
//! and the mesh that would make the bias negligible is `h (|b|/(f σ))^(-1/p)`.

use crate::fit::{Columns, FitError, LeastSquares};
use serde::{Deserialize, Serialize};

/// A bias above this fraction of the standard deviation is not negligible: the coverage of a
/// 95 % interval falls below 94.3 % (`Φ(1.96 - 0.25) - Φ(-1.96 - 0.25)`).
pub const BIAS_FRACTION: f64 = 0.25;

/// The rate assumed when the refined levels do not determine one (first order: the bias is
/// then twice the shift to a mesh of half the element size, the cautious side for bilinear
/// elements, whose displacements converge at rates 1–2).
pub const ASSUMED_RATE: f64 = 1.0;

/// One mesh of the check: the joint problem on it, its refinement ratio `h / h_i` (1 for the
/// model's own mesh) and its element count.
pub struct Level<'a> {
    pub ratio: f64,
    pub elements: usize,
    pub problem: &'a mut dyn LeastSquares,
}

/// A refined mesh of the check, as reported.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LevelRecord {
    pub ratio: f64,
    pub elements: usize,
    /// `|r_i - r_h|`: the change of the whitened residuals from the model's mesh (noise units).
    pub field_change: f64,
    /// Per free parameter: the Gauss–Newton shift of the log-parameter to this mesh (only for
    /// the finest level, which has a Jacobian).
    pub shift: Option<Vec<f64>>,
}

/// What the check found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiscretizationCheck {
    /// `"negligible"`, `"widened"` (the bias exceeds the fraction of the sd: intervals widened),
    /// `"reported"` (not negligible, but the data come from the model's own mesh: nothing to
    /// widen) or `"unknown"` (femu cannot refine this model).
    pub status: String,
    /// The model's mesh.
    pub elements: usize,
    pub levels: Vec<LevelRecord>,
    /// The observed convergence rate of the field at the measured points, or the assumed one.
    pub rate: f64,
    pub rate_observed: bool,
    /// Per free parameter: the estimated bias of the identified log-parameter (model's mesh
    /// minus converged), and its ratio to the parameter's relative sd.
    pub bias: Vec<f64>,
    pub bias_over_sd: Vec<f64>,
    pub threshold: f64,
    /// About how many elements would make every bias negligible (when it is not).
    pub recommended_elements: Option<usize>,
    /// What to tell the user.
    pub message: String,
}

impl DiscretizationCheck {
    /// The check of a model femu cannot refine: the error is unknown; `how` says how to check it.
    pub fn unknown(elements: usize, how: &str) -> DiscretizationCheck {
        DiscretizationCheck {
            status: "unknown".into(),
            elements,
            levels: Vec::new(),
            rate: f64::NAN,
            rate_observed: false,
            bias: Vec::new(),
            bias_over_sd: Vec::new(),
            threshold: BIAS_FRACTION,
            recommended_elements: None,
            message: format!("the discretization error of this model is unknown: {how}"),
        }
    }

    /// Whether the bias is not negligible.
    pub fn flagged(&self) -> bool {
        self.bias_over_sd.iter().any(|r| *r > self.threshold)
    }
}

/// Why the check could not be made.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    #[error("the discretization check needs the model's mesh and two refined meshes")]
    Levels,
    #[error("the meshes of the check see different data ({0} and {1} residuals): give them the same measured points")]
    Rows(usize, usize),
    #[error("the Gauss–Newton system of the finest mesh is singular")]
    Singular,
    #[error(transparent)]
    Fit(#[from] FitError),
}

/// Solves `ρ` for the rate: `(1 - r2^-p) / (1 - r1^-p) = q` (decreasing in p from
/// `ln r2 / ln r1` at 0 to 1 at infinity), by bisection on [0.25, 8]; `None` when `q` is outside.
fn rate_of(q: f64, r1: f64, r2: f64) -> Option<f64> {
    let g = |p: f64| (1.0 - r2.powf(-p)) / (1.0 - r1.powf(-p)) - q;
    let (mut lo, mut hi) = (0.25, 8.0);
    if !(g(lo) > 0.0 && g(hi) < 0.0) {
        return None;
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if g(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// `-(JᵀJ)⁻¹ Jᵀ d`.
fn gauss_newton_step(j: &Columns, d: &[f64]) -> Result<Vec<f64>, CheckError> {
    use faer::linalg::solvers::Solve;
    let n = j.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let a = faer::Mat::<f64>::from_fn(n, n, |p, q| dot(&j[p], &j[q]));
    let g = faer::Mat::<f64>::from_fn(n, 1, |p, _| -dot(&j[p], d));
    let x = a.partial_piv_lu().solve(&g);
    let step: Vec<f64> = (0..n).map(|k| x[(k, 0)]).collect();
    if step.iter().all(|v| v.is_finite()) {
        Ok(step)
    } else {
        Err(CheckError::Singular)
    }
}

/// The check at the identified parameters `theta` (model units) with relative sds `sd`, from
/// `levels`: the model's own mesh first (ratio 1), then meshes of the same geometry refined by
/// increasing ratios, all with the same measured points (see the module documentation).
/// `data_from_model`: the data were made by the model's own mesh (a virtual experiment without
/// another mesh), so the bias is reported but no interval needs widening.
pub fn check(
    theta: &[f64],
    sd: &[f64],
    levels: &mut [Level],
    data_from_model: bool,
) -> Result<DiscretizationCheck, CheckError> {
    if levels.len() < 3 || levels[0].ratio != 1.0 {
        return Err(CheckError::Levels);
    }
    let phi: Vec<f64> = theta.iter().map(|t| t.ln()).collect();
    let (r_h, _) = levels[0].problem.evaluate(&phi, false)?;
    let last = levels.len() - 1;
    let mut records = Vec::new();
    let mut shift = Vec::new();
    for (i, level) in levels.iter_mut().enumerate().skip(1) {
        let (r, j) = level.problem.evaluate(&phi, i == last)?;
        if r.len() != r_h.len() {
            return Err(CheckError::Rows(r_h.len(), r.len()));
        }
        let d: Vec<f64> = r.iter().zip(&r_h).map(|(a, b)| a - b).collect();
        if let Some(j) = j {
            shift = gauss_newton_step(&j, &d)?;
        }
        records.push(LevelRecord {
            ratio: level.ratio,
            elements: level.elements,
            field_change: norm(&d),
            shift: (i == last).then(|| shift.clone()),
        });
    }
    let (first, finest) = (&records[0], &records[records.len() - 1]);
    let observed = rate_of(
        finest.field_change / first.field_change,
        first.ratio,
        finest.ratio,
    );
    let rate = observed.unwrap_or(ASSUMED_RATE);
    let factor = 1.0 / (1.0 - finest.ratio.powf(-rate));
    let bias: Vec<f64> = shift.iter().map(|s| -s * factor).collect();
    let bias_over_sd: Vec<f64> = bias
        .iter()
        .zip(sd)
        .map(|(b, s)| if s.is_finite() { b.abs() / s } else { 0.0 })
        .collect();
    let worst = bias_over_sd.iter().copied().fold(0.0, f64::max);
    let elements = levels[0].elements;
    let recommended_elements = (worst > BIAS_FRACTION).then(|| {
        let n = elements as f64 * (worst / BIAS_FRACTION).powf(2.0 / rate);
        round_up(n)
    });
    let status = match (worst > BIAS_FRACTION, data_from_model) {
        (false, _) => "negligible",
        (true, false) => "widened",
        (true, true) => "reported",
    };
    let mut out = DiscretizationCheck {
        status: status.into(),
        elements,
        levels: records,
        rate,
        rate_observed: observed.is_some(),
        bias,
        bias_over_sd,
        threshold: BIAS_FRACTION,
        recommended_elements,
        message: String::new(),
    };
    out.message = message(&out, data_from_model);
    Ok(out)
}

/// `n` rounded up to two significant digits.
fn round_up(n: f64) -> usize {
    let scale = 10f64.powi((n.log10().floor() as i32 - 1).max(0));
    ((n / scale).ceil() * scale) as usize
}

fn message(c: &DiscretizationCheck, data_from_model: bool) -> String {
    let worst = c.bias_over_sd.iter().copied().fold(0.0, f64::max);
    let rate = if c.rate_observed {
        format!("observed rate {:.2}", c.rate)
    } else {
        format!("rate not determined by the meshes, {:.0} assumed", c.rate)
    };
    let finest = c.levels.last().map_or(0, |l| l.elements);
    if worst <= c.threshold {
        return format!(
            "discretization bias negligible: at most {worst:.2} sd (meshes of {} and {finest} elements, {rate})",
            c.levels.first().map_or(0, |l| l.elements)
        );
    }
    let need = c.recommended_elements.map_or(String::new(), |n| {
        format!("; about {n} elements would make it negligible")
    });
    if data_from_model {
        format!(
            "the mesh biases the parameters by up to {worst:.1} sd ({rate}, from {finest} elements){need}; the virtual data come from this mesh, so the intervals hold for them, not for real data"
        )
    } else {
        format!(
            "the mesh biases the parameters by up to {worst:.1} sd ({rate}, from {finest} elements): intervals widened to hold the corrected values{need}"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::FreeParameter;
    use femu_mech::material::{MaterialLaw, NeoHookean};
    use femu_mech::sensitivity::Parameter;

    /// A linear model `m(φ) = A φ + e_i` whose "discretization error" `e_i = C ρ_i^-p g`
    /// converges at rate p: the check must find p, and the bias it extrapolates must be the
    /// shift of the optimum to the converged model (`e = 0`), exactly for a linear model.
    struct Mesh {
        free: Vec<FreeParameter>,
        a: Vec<Vec<f64>>,
        error: Vec<f64>,
        data: Vec<f64>,
    }

    impl LeastSquares for Mesh {
        fn free(&self) -> &[FreeParameter] {
            &self.free
        }
        fn evaluate(
            &mut self,
            phi: &[f64],
            jacobian: bool,
        ) -> Result<(Vec<f64>, Option<Columns>), FitError> {
            let r = (0..self.data.len())
                .map(|i| {
                    (0..phi.len()).map(|k| self.a[k][i] * phi[k]).sum::<f64>() + self.error[i]
                        - self.data[i]
                })
                .collect();
            Ok((r, jacobian.then(|| self.a.clone())))
        }
        fn counts(&self) -> (usize, usize) {
            (0, 0)
        }
    }

    #[test]
    fn rate_and_bias_of_a_linear_model_are_recovered() {
        let free: Vec<FreeParameter> = (0..2)
            .map(|k| FreeParameter {
                name: format!("P{k}"),
                members: vec![Parameter::new(k, &NeoHookean::SPEC, 0).unwrap()],
                lower: 1e-3,
                upper: 1e3,
            })
            .collect();
        let a = vec![
            (0..8).map(|i| (i as f64 * 0.7).sin()).collect::<Vec<_>>(),
            (0..8).map(|i| (i as f64 * 0.3).cos()).collect(),
        ];
        let g: Vec<f64> = (0..8).map(|i| 0.01 * (i as f64 - 3.0)).collect();
        let data: Vec<f64> = (0..8).map(|i| (i as f64).sqrt()).collect();
        let p = 1.6;
        let mesh = |rho: f64| Mesh {
            free: free.clone(),
            a: a.clone(),
            error: g.iter().map(|v| v * rho.powf(-p)).collect(),
            data: data.clone(),
        };
        // The optimum of the model's own mesh, and of the converged model.
        let solve = |e: &[f64]| {
            let d: Vec<f64> = data.iter().zip(e).map(|(x, y)| y - x).collect();
            gauss_newton_step(&a, &d).unwrap()
        };
        let phi_h = solve(&mesh(1.0).error);
        let phi_inf = solve(&[0.0; 8]);
        let theta: Vec<f64> = phi_h.iter().map(|v| v.exp()).collect();
        let (mut m0, mut m1, mut m2) = (mesh(1.0), mesh(2f64.sqrt()), mesh(2.0));
        let mut levels = [
            Level {
                ratio: 1.0,
                elements: 1000,
                problem: &mut m0,
            },
            Level {
                ratio: 2f64.sqrt(),
                elements: 2000,
                problem: &mut m1,
            },
            Level {
                ratio: 2.0,
                elements: 4000,
                problem: &mut m2,
            },
        ];
        let c = check(&theta, &[1e-3, 1e-3], &mut levels, false).unwrap();
        assert!(
            c.rate_observed && (c.rate - p).abs() < 1e-9,
            "rate {}",
            c.rate
        );
        for k in 0..2 {
            let actual = phi_h[k] - phi_inf[k];
            assert!(
                (c.bias[k] - actual).abs() < 1e-9 * actual.abs().max(1e-12),
                "parameter {k}: bias {} vs {actual}",
                c.bias[k]
            );
        }
        assert_eq!(c.status, "widened");
        // The recommended mesh meets the fraction at the observed rate.
        let worst = c.bias_over_sd.iter().copied().fold(0.0, f64::max);
        let n = c.recommended_elements.unwrap() as f64;
        assert!(worst * (n / 1000.0).powf(-p / 2.0) <= BIAS_FRACTION * 1.0001);
    }

    #[test]
    fn rate_inversion_and_rounding() {
        for p in [0.5, 1.0, 2.0, 3.5] {
            let q = (1.0 - 2f64.powf(-p)) / (1.0 - 2f64.sqrt().powf(-p));
            assert!((rate_of(q, 2f64.sqrt(), 2.0).unwrap() - p).abs() < 1e-9);
        }
        assert_eq!(rate_of(2.5, 2f64.sqrt(), 2.0), None);
        assert_eq!(round_up(12_345.0), 13_000);
        assert_eq!(round_up(87.2), 88);
    }
}
