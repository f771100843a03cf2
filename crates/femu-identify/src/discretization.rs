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
//! evaluated on meshes of the same geometry with the ratios `ρ_i = h / h_i` (femu's studies: √2
//! and 2; coarser meshes serve too, one of them finer than the model's). With `r_i` the
//! whitened residuals on mesh `i`, the shift of the optimum to the finest mesh `f` (the same
//! data fitted there) is one Gauss–Newton step from `φ̂` with its exact Jacobian `J_f`:
//!
//! ```text
//!   δ_f = -(J_fᵀ J_f)⁻¹ J_fᵀ r_f
//! ```
//!
//! The whole residual of the finest mesh, not its change `r_f - r_h`: at `φ̂` the residual of
//! the model's mesh is orthogonal to that mesh's sensitivities, `J_hᵀ r_h = 0`, but not to the
//! finest mesh's when the sensitivities themselves depend on the mesh — a tissue layer a few
//! elements thick, as the seed's fat, whose C10 sensitivity changes by percents from `h` to
//! `h/2`. There `J_fᵀ r_h` is the larger part of the shift: on virtual data made by the
//! check's finest mesh of the built-in thigh (4 000 elements identified, 15 000 for the data),
//! the field change alone predicted C10_FAT's bias as +0.18 % against +1.0 % measured (its
//! intervals covered the truth in 1 of 10 repeats), and D_FAT's as +12.6 % against +0.6 %.
//!
//! With a discretization error `e(h) = C h^p`, the field differences between meshes obey
//! `|r_i - r_j| = C |ρ_i^-p - ρ_j^-p|`, which gives the observed rate `p`; the bias of the
//! identified log-parameters (model's mesh minus converged) is then `b = -δ_f / (1 - ρ_f^-p)`
//! (Richardson). When `|b_k|` exceeds [`BIAS_FRACTION`] of the standard
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

/// The nominal rate of the displacements of bilinear elements (second order); an observed
/// rate above it is used as this.
pub const NOMINAL_RATE: f64 = 2.0;

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
    /// `|r_i - r_f|`: from the finest mesh of the check.
    #[serde(default)]
    pub change_to_finest: f64,
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
    /// The convergence rate of the field at the measured points the extrapolation used: the
    /// observed one (at most [`NOMINAL_RATE`]), or [`ASSUMED_RATE`].
    pub rate: f64,
    pub rate_observed: bool,
    /// The rate the meshes' field changes fit best.
    #[serde(default)]
    pub fitted_rate: Option<f64>,
    /// RMS relative misfit of the fitted rate to the meshes' pairwise field changes (above
    /// [`RATE_MISFIT`] the meshes do not converge cleanly and the rate is assumed).
    #[serde(default)]
    pub rate_misfit: f64,
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
            fitted_rate: None,
            rate_misfit: f64::NAN,
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
    #[error("the discretization check needs the model's mesh first and two other meshes of its geometry, one of them finer")]
    Levels,
    #[error("the meshes of the check see different data ({0} and {1} residuals): give them the same measured points")]
    Rows(usize, usize),
    #[error("the Gauss–Newton system of the finest mesh is singular")]
    Singular,
    #[error(transparent)]
    Fit(#[from] FitError),
}

/// Above this RMS relative misfit the pairwise field changes do not follow `C h^p`: meshes
/// that are not nested add a change of their own (how a facet meets the plate, say), and the
/// rate is then assumed, not observed.
pub const RATE_MISFIT: f64 = 0.25;

/// The rate `p` (and its RMS relative misfit) that best fits the field changes between pairs
/// of meshes, `(ρ_i, ρ_j, |r_i - r_j|)` with `|r_i - r_j| = C |ρ_i^-p - ρ_j^-p|`, in the log
/// (C eliminated): a scan over [0.25, 8] refined by golden sections. `None` without a change.
fn fit_rate(pairs: &[(f64, f64, f64)]) -> (Option<f64>, f64) {
    if pairs.iter().any(|p| !(p.2 > 0.0 && p.2.is_finite())) || pairs.len() < 2 {
        return (None, f64::INFINITY);
    }
    let misfit = |p: f64| {
        let logs: Vec<f64> = pairs
            .iter()
            .map(|(a, b, d)| d.ln() - (a.powf(-p) - b.powf(-p)).abs().ln())
            .collect();
        let mean = logs.iter().sum::<f64>() / logs.len() as f64;
        (logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / logs.len() as f64).sqrt()
    };
    let grid: Vec<f64> = (0..=775).map(|k| 0.25 + 0.01 * k as f64).collect();
    let k = (0..grid.len())
        .min_by(|&a, &b| misfit(grid[a]).total_cmp(&misfit(grid[b])))
        .unwrap_or(0);
    let (mut lo, mut hi) = (grid[k.saturating_sub(1)], grid[(k + 1).min(grid.len() - 1)]);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..80 {
        let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if misfit(x1) < misfit(x2) {
            hi = x2;
        } else {
            lo = x1;
        }
    }
    let p = 0.5 * (lo + hi);
    // The log misfit as a relative one.
    (Some(p), misfit(p).exp() - 1.0)
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

/// The bias of the log-parameters on the model's mesh (model's minus converged) from the
/// Gauss–Newton `shift` to a mesh refined by `ratio = h / h_f`, for a discretization error
/// converging at `rate` (Richardson): `b = -δ_f / (1 - ratio^-rate)`.
pub fn extrapolated_bias(shift: &[f64], ratio: f64, rate: f64) -> Vec<f64> {
    let factor = 1.0 / (1.0 - ratio.powf(-rate));
    shift.iter().map(|s| -s * factor).collect()
}

/// One mesh of the check, evaluated at the identified parameters: its refinement ratio `h / h_i`
/// (1 for the model's own mesh), its element count and its whitened residuals.
pub struct Evaluated {
    pub ratio: f64,
    pub elements: usize,
    pub residual: Vec<f64>,
}

/// The check at the identified parameters `theta` (model units) with relative sds `sd`, from
/// `levels`: the model's own mesh first (ratio 1), then meshes of the same geometry coarser or
/// finer, all with the same measured points (see the module documentation); the finest (the
/// largest ratio, above 1) gives the Jacobian. `data_from_model`: the data were made by the
/// model's own mesh (a virtual experiment without another mesh), so the bias is reported but no
/// interval needs widening.
pub fn check(
    theta: &[f64],
    sd: &[f64],
    levels: &mut [Level],
    data_from_model: bool,
) -> Result<DiscretizationCheck, CheckError> {
    let finest = finest_level(levels.iter().map(|l| l.ratio))?;
    let phi: Vec<f64> = theta.iter().map(|t| t.ln()).collect();
    let mut evaluated = Vec::with_capacity(levels.len());
    let mut jacobian = None;
    for (i, level) in levels.iter_mut().enumerate() {
        let (residual, j) = level.problem.evaluate(&phi, i == finest)?;
        evaluated.push(Evaluated {
            ratio: level.ratio,
            elements: level.elements,
            residual,
        });
        jacobian = j.or(jacobian);
    }
    assess(
        sd,
        &evaluated,
        jacobian.as_ref().ok_or(CheckError::Levels)?,
        data_from_model,
    )
}

/// The index of the finest level of `ratios`: the model's own mesh first (ratio 1), at least
/// three meshes, the finest above 1.
pub fn finest_level(ratios: impl Iterator<Item = f64>) -> Result<usize, CheckError> {
    let ratios: Vec<f64> = ratios.collect();
    let finest = (0..ratios.len())
        .max_by(|&a, &b| ratios[a].total_cmp(&ratios[b]))
        .ok_or(CheckError::Levels)?;
    if ratios.len() < 3 || ratios[0] != 1.0 || !(ratios[finest] > 1.0) {
        return Err(CheckError::Levels);
    }
    Ok(finest)
}

/// The check from meshes already evaluated at the identified parameters (see [`check`]):
/// `evaluated[0]` the model's own mesh, `jacobian` that of the finest, with relative sds `sd`.
/// The caller may evaluate one mesh at a time (and free it before the next).
pub fn assess(
    sd: &[f64],
    evaluated: &[Evaluated],
    jacobian: &Columns,
    data_from_model: bool,
) -> Result<DiscretizationCheck, CheckError> {
    let finest = finest_level(evaluated.iter().map(|e| e.ratio))?;
    let rows = evaluated[0].residual.len();
    if let Some(e) = evaluated.iter().find(|e| e.residual.len() != rows) {
        return Err(CheckError::Rows(rows, e.residual.len()));
    }
    let residuals: Vec<&[f64]> = evaluated.iter().map(|e| e.residual.as_slice()).collect();
    let distance = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let shift = gauss_newton_step(jacobian, residuals[finest])?;
    // The refined (and coarser) meshes, the finest last.
    let mut order: Vec<usize> = (1..evaluated.len()).filter(|&i| i != finest).collect();
    order.push(finest);
    let records: Vec<LevelRecord> = order
        .iter()
        .map(|&i| LevelRecord {
            ratio: evaluated[i].ratio,
            elements: evaluated[i].elements,
            field_change: distance(residuals[i], residuals[0]),
            change_to_finest: distance(residuals[i], residuals[finest]),
            shift: (i == finest).then(|| shift.clone()),
        })
        .collect();
    // Every pair of meshes: |r_i - r_j| = C |ρ_i^-p - ρ_j^-p|.
    let mut pairs = Vec::new();
    for i in 0..evaluated.len() {
        for j in i + 1..evaluated.len() {
            pairs.push((
                evaluated[i].ratio,
                evaluated[j].ratio,
                distance(residuals[i], residuals[j]),
            ));
        }
    }
    let (fitted, misfit) = fit_rate(&pairs);
    let observed = fitted.filter(|p| *p >= 0.5 && misfit <= RATE_MISFIT);
    // A faster apparent rate is pre-asymptotic: the extrapolation uses at most the elements'
    // nominal rate.
    let rate = observed.map_or(ASSUMED_RATE, |p| p.min(NOMINAL_RATE));
    let bias = extrapolated_bias(&shift, evaluated[finest].ratio, rate);
    let bias_over_sd: Vec<f64> = bias
        .iter()
        .zip(sd)
        .map(|(b, s)| if s.is_finite() { b.abs() / s } else { 0.0 })
        .collect();
    let worst = bias_over_sd.iter().copied().fold(0.0, f64::max);
    let elements = evaluated[0].elements;
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
        fitted_rate: fitted,
        rate_misfit: misfit,
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

/// A mesh more than this many times finer than the identified one is not a practical advice.
const PRACTICAL_REFINEMENT: usize = 16;

fn message(c: &DiscretizationCheck, data_from_model: bool) -> String {
    let worst = c.bias_over_sd.iter().copied().fold(0.0, f64::max);
    let rate = match c.fitted_rate {
        Some(p) if c.rate_observed && p > c.rate => {
            format!("observed rate {p:.2}, extrapolated at {:.0}", c.rate)
        }
        _ if c.rate_observed => format!("observed rate {:.2}", c.rate),
        _ => format!(
            "the meshes do not converge cleanly (misfit {:.0} %), rate {:.0} assumed",
            100.0 * c.rate_misfit,
            c.rate
        ),
    };
    let finest = c.levels.last().map_or(0, |l| l.elements);
    if worst <= c.threshold {
        return format!(
            "discretization bias negligible: at most {worst:.2} sd (meshes of {} and {finest} elements, {rate})",
            c.levels.first().map_or(0, |l| l.elements)
        );
    }
    // With the small noise of a good measurement the sd is small, and "negligible" may need a
    // mesh no one would solve for an identification: then the widened interval is the answer,
    // and the message says so instead of sending the user to a million elements.
    let need = c.recommended_elements.map_or(String::new(), |n| {
        if n > PRACTICAL_REFINEMENT * c.elements {
            let carried = if data_from_model {
                ""
            } else {
                ": the widened intervals carry it"
            };
            format!(
                "; only some {n} elements would make it negligible (more than {PRACTICAL_REFINEMENT} times this mesh){carried}"
            )
        } else {
            format!("; about {n} elements would make it negligible")
        }
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

    /// Two free parameters (the Neo-Hookean C10 and D of one material), bounds wide open.
    fn two_free() -> Vec<FreeParameter> {
        (0..2)
            .map(|k| FreeParameter {
                name: format!("P{k}"),
                members: vec![Parameter::new(k, &NeoHookean::SPEC, 0).unwrap()],
                lower: 1e-3,
                upper: 1e3,
            })
            .collect()
    }

    /// The check's levels of `meshes` refined by `ratios` (1 000 elements at ratio 1).
    fn levels_of<'a>(meshes: &'a mut [Mesh], ratios: &[f64]) -> Vec<Level<'a>> {
        meshes
            .iter_mut()
            .zip(ratios)
            .map(|(m, &ratio)| Level {
                ratio,
                elements: (1000.0 * ratio * ratio).round() as usize,
                problem: m,
            })
            .collect()
    }

    #[test]
    fn rate_and_bias_of_a_linear_model_are_recovered() {
        let free = two_free();
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
        // Two finer meshes (the studies'), and one coarser with one finer.
        use std::f64::consts::{FRAC_1_SQRT_2, SQRT_2};
        for ratios in [[1.0, SQRT_2, 2.0], [1.0, FRAC_1_SQRT_2, SQRT_2]] {
            let mut meshes: Vec<Mesh> = ratios.iter().map(|&r| mesh(r)).collect();
            let mut levels = levels_of(&mut meshes, &ratios);
            let c = check(&theta, &[1e-3, 1e-3], &mut levels, false).unwrap();
            assert!(
                c.rate_observed && (c.rate - p).abs() < 1e-9,
                "{ratios:?}: rate {}",
                c.rate
            );
            assert_eq!(c.levels.last().unwrap().ratio, ratios[2]);
            for k in 0..2 {
                let actual = phi_h[k] - phi_inf[k];
                assert!(
                    (c.bias[k] - actual).abs() < 1e-9 * actual.abs().max(1e-12),
                    "{ratios:?}, parameter {k}: bias {} vs {actual}",
                    c.bias[k]
                );
            }
            assert_eq!(c.status, "widened");
            // The recommended mesh meets the fraction at the observed rate.
            let worst = c.bias_over_sd.iter().copied().fold(0.0, f64::max);
            let n = c.recommended_elements.unwrap() as f64;
            assert!(worst * (n / 1000.0).powf(-p / 2.0) <= BIAS_FRACTION * 1.0001);
        }
        // No mesh finer than the model's: nothing to extrapolate from.
        let mut meshes: Vec<Mesh> = [1.0, 0.5, FRAC_1_SQRT_2].iter().map(|&r| mesh(r)).collect();
        let mut levels: Vec<Level> = meshes
            .iter_mut()
            .zip([1.0, 0.5, FRAC_1_SQRT_2])
            .map(|(m, ratio)| Level {
                ratio,
                elements: 1000,
                problem: m,
            })
            .collect();
        assert!(matches!(
            check(&theta, &[1e-3, 1e-3], &mut levels, false),
            Err(CheckError::Levels)
        ));
    }

    /// A linear model whose sensitivities depend on the mesh, `m_i(φ) = (A + ρ_i^-p B) φ + e_i`
    /// (a thin layer's): one Gauss–Newton step from the model mesh's optimum with the finest
    /// mesh's whole residual lands exactly on the finest mesh's optimum (the model is linear),
    /// where the residual's change `r_f - r_h` misses the part `(J_f - J_h)ᵀ r_h` — far off here.
    #[test]
    fn the_shift_holds_when_the_sensitivities_depend_on_the_mesh() {
        let free = two_free();
        let rows = 12;
        let a: Vec<Vec<f64>> = vec![
            (0..rows).map(|i| (i as f64 * 0.7).sin()).collect(),
            (0..rows).map(|i| (i as f64 * 0.3).cos()).collect(),
        ];
        let b: Vec<Vec<f64>> = vec![
            (0..rows).map(|i| 0.4 * (i as f64 * 1.3).cos()).collect(),
            (0..rows).map(|i| 0.2 * (i as f64 * 0.9).sin()).collect(),
        ];
        let g: Vec<f64> = (0..rows).map(|i| 0.01 * (i as f64 - 5.0)).collect();
        // Data far from any mesh's model (a large residual at the optimum, as with real noise).
        let data: Vec<f64> = (0..rows)
            .map(|i| (i as f64).sqrt() + 0.3 * (i % 3) as f64)
            .collect();
        let p = 2.0;
        let mesh = |rho: f64| {
            let s = rho.powf(-p);
            Mesh {
                free: free.clone(),
                a: (0..2)
                    .map(|k| (0..rows).map(|i| a[k][i] + s * b[k][i]).collect())
                    .collect(),
                error: g.iter().map(|v| v * s).collect(),
                data: data.clone(),
            }
        };
        // A mesh's optimum (linear least squares: one step from 0).
        let optimum = |m: &mut Mesh| {
            let (r, j) = m.evaluate(&[0.0, 0.0], true).unwrap();
            gauss_newton_step(&j.unwrap(), &r).unwrap()
        };
        let ratios = [1.0, std::f64::consts::SQRT_2, 2.0];
        let mut meshes: Vec<Mesh> = ratios.iter().map(|&r| mesh(r)).collect();
        let phi_h = optimum(&mut meshes[0]);
        let phi_f = optimum(&mut meshes[2]);
        let theta: Vec<f64> = phi_h.iter().map(|v| v.exp()).collect();
        let mut levels = levels_of(&mut meshes, &ratios);
        let c = check(&theta, &[1e-3, 1e-3], &mut levels, false).unwrap();
        let shift = c.levels.last().unwrap().shift.clone().unwrap();
        for k in 0..2 {
            let exact = phi_f[k] - phi_h[k];
            assert!(
                (shift[k] - exact).abs() < 1e-9 * exact.abs(),
                "parameter {k}: shift {} against {exact}",
                shift[k]
            );
        }
        // The residual's change alone is off by more than a third of the shift here.
        let (r_h, _) = mesh(1.0).evaluate(&phi_h, false).unwrap();
        let (r_f, j_f) = mesh(2.0).evaluate(&phi_h, true).unwrap();
        let d: Vec<f64> = r_f.iter().zip(&r_h).map(|(x, y)| x - y).collect();
        let change_only = gauss_newton_step(&j_f.unwrap(), &d).unwrap();
        let off = (0..2)
            .map(|k| (change_only[k] - shift[k]).abs() / shift[k].abs())
            .fold(0.0, f64::max);
        assert!(off > 0.3, "the change alone is off by {off}");
    }

    /// A mesh 16 times finer or more is not sent to the user as advice: the message says the
    /// widened intervals carry the bias (the demo's check once advised some 300 000 elements).
    #[test]
    fn an_impractical_mesh_is_not_advised() {
        let mut c = DiscretizationCheck::unknown(4000, "");
        c.status = "widened".into();
        c.rate = 2.0;
        c.rate_observed = true;
        c.fitted_rate = Some(2.0);
        c.rate_misfit = 0.0;
        c.bias = vec![0.05];
        c.bias_over_sd = vec![3.0];
        for (n, practical) in [(40_000, true), (300_000, false)] {
            c.recommended_elements = Some(n);
            let m = message(&c, false);
            assert!(m.contains(&n.to_string()), "{m}");
            assert_eq!(m.contains(&format!("about {n} elements")), practical, "{m}");
            assert_eq!(
                m.contains("the widened intervals carry it"),
                !practical,
                "{m}"
            );
        }
    }

    #[test]
    fn rate_fit_and_rounding() {
        let r = [1.0, 2f64.sqrt(), 2.0];
        for p in [0.5, 1.0, 2.0, 3.5] {
            let pairs: Vec<(f64, f64, f64)> = [(0, 1), (0, 2), (1, 2)]
                .iter()
                .map(|&(i, j)| (r[i], r[j], 3.0 * (r[i].powf(-p) - r[j].powf(-p)).abs()))
                .collect();
            let (fitted, misfit) = fit_rate(&pairs);
            assert!((fitted.unwrap() - p).abs() < 1e-6, "{p}: {fitted:?}");
            assert!(misfit < 1e-9);
        }
        // A finer mesh as far from the model's as a coarser one: no clean rate.
        let (_, misfit) = fit_rate(&[(1.0, 1.414, 60.9), (1.0, 2.0, 55.8), (1.414, 2.0, 40.0)]);
        assert!(misfit > RATE_MISFIT, "{misfit}");
        assert_eq!(round_up(12_345.0), 13_000);
        assert_eq!(round_up(87.2), 88);
    }
}
