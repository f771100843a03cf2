//! Intervals of a fit to a measured field that hold when the field's error is not what its
//! covariance says (issue 25: the DIC of B-mode images errs systematically at the skin and the
//! fascia, in spatially correlated patches, and the Jacobian's intervals covered the truth in
//! 68–70 % of the cases for a nominal 95 %).
//!
//! Two data-driven widths, the larger kept:
//!
//! - the **Birge ratio** `√(χ²/ν)` (Birge 1932): the whitened misfit's variance per degree of
//!   freedom, when above 1, scales the Fisher standard deviations (a fit whose residuals are
//!   larger than their covariance says is not as sure as the covariance says). A fit without a
//!   covariance already scales its Fisher sd by the residual variance: its ratio is 1.
//! - the **block jackknife** (delete one block, one Gauss–Newton step, `crate::idic::uncertainty::
//!   group_jackknife`) over [`JACKKNIFE_BLOCKS`] contiguous blocks of the measured points, in
//!   their file order (DIC grids are written row by row: the blocks are depth bands of the
//!   window). A systematic error that pulls the estimate one way in one band shows up as the
//!   spread of the delete-one-band estimates, which no noise model sees. Scaled by
//!   `t(0.975, B − 1) / 1.96` so that `±1.96 sd` is the jackknife's t interval.
//!
//! Which term set each width is recorded (`Estimate::width_from`).

use crate::campaign::{interval, Estimate};
use crate::fit::{normal_equations, FitError, FitResult, Problem, SpeckleColumns};
use crate::idic::uncertainty::group_jackknife;

/// Blocks of the jackknife: 16 depth bands of a 40 mm window are 2.5 mm each, two rows of a
/// 16 px (1.6 mm) DIC grid, about the thickness of the skin + fat layer's error band.
pub const JACKKNIFE_BLOCKS: usize = 16;

/// `t(0.975, 15) / 1.96`: the jackknife's 15 degrees of freedom.
pub const JACKKNIFE_T_FACTOR: f64 = 2.131 / 1.96;

/// Widens `estimates` (from the fit `best`, Fisher sd in `relative_sd`) to the larger of the
/// Birge-scaled Fisher sd (`whitened`: the residuals were whitened by the field's covariance)
/// and the block jackknife sd; sets `ci95` anew (before any discretization widening) and
/// records the terms. Leaves them as they are when the fit kept no residual or Jacobian.
pub fn widen_for_misfit(estimates: &mut [Estimate], best: &FitResult, whitened: bool) {
    let n = best.residual.len();
    if n == 0 || best.jacobian.len() != estimates.len() || n <= estimates.len() {
        return;
    }
    let dof = (n - estimates.len()) as f64;
    let birge = if whitened {
        (2.0 * best.cost / dof).sqrt().max(1.0)
    } else {
        1.0
    };
    let blocks = JACKKNIFE_BLOCKS.min(n / 2).max(2);
    let (jack, _) = group_jackknife(&best.jacobian, &best.residual, &|k| k * blocks / n, blocks);
    for (e, j) in estimates.iter_mut().zip(&jack) {
        let fisher = e.relative_sd;
        let scaled = fisher * birge;
        let jk = j * JACKKNIFE_T_FACTOR;
        let (sd, from) = if jk > scaled {
            (jk, "jackknife")
        } else if birge > 1.0 {
            (scaled, "Birge ratio")
        } else {
            (fisher, "Fisher")
        };
        e.sd_fisher = Some(fisher);
        e.birge_ratio = Some(birge);
        e.sd_jackknife = Some(jk);
        e.width_from = Some(from.to_string());
        e.relative_sd = sd;
        e.ci95 = interval(e.identified, sd, 0.0);
    }
}

/// The fitted speckle-shift scale of `problem` at `phi` and its standard deviation with the
/// free parameters free too, widened as a measured field's parameters are: the larger of the
/// Gauss–Newton sd of the (p+1)-th unknown, `√(s² / (vᵀv − vᵀJ (JᵀJ)⁻¹ Jᵀv))` (`J` the
/// weighted Jacobian at that scale held, `v` the weighted shift, the scale's column; `s²` the
/// residuals' variance factor `|r|² / (n − p − 1)` where it exceeds 1), and the block
/// jackknife's over [`JACKKNIFE_BLOCKS`] depth bands of the rows. `None` unless the scale is
/// fitted ([`Problem::speckle_columns`]).
pub fn speckle_scale_sd(
    problem: &mut Problem,
    phi: &[f64],
) -> Result<Option<(f64, f64)>, FitError> {
    let Some(SpeckleColumns {
        kappa,
        residual: r,
        jacobian: j,
        shift: v,
    }) = problem.speckle_columns(phi)?
    else {
        return Ok(None);
    };
    let p = j.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    // `JᵀJ` and `Jᵀv`: the normal equations with the shift in place of the residual.
    let (jtj, jtv) = normal_equations(&j, &v);
    let inv = crate::variance_components::invert_spd(&jtj)
        .ok_or_else(|| FitError::Speckle("the parameters' normal matrix is singular".into()))?;
    let explained: f64 = (0..p)
        .map(|a| (0..p).map(|b| jtv[a] * inv[a][b] * jtv[b]).sum::<f64>())
        .sum();
    let schur = dot(&v, &v) - explained;
    let dof = r.len().saturating_sub(p + 1).max(1);
    let s2 = (dot(&r, &r) / dof as f64).max(1.0);
    let sd = if schur > 0.0 {
        (s2 / schur).sqrt()
    } else {
        f64::INFINITY
    };
    let n_rows = r.len();
    let blocks = JACKKNIFE_BLOCKS.min(n_rows / 2).max(2);
    let mut columns = j;
    columns.push(v);
    let (jack, _) = group_jackknife(&columns, &r, &|k| k * blocks / n_rows, blocks);
    let jk = jack[p] * JACKKNIFE_T_FACTOR;
    Ok(Some((kappa, if jk > sd { jk } else { sd })))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    fn estimate(sd: f64) -> Estimate {
        Estimate {
            name: "P".into(),
            reference: None,
            identified: 1.0,
            relative_error: None,
            relative_sd: sd,
            ci95: [0.0, 0.0],
            mean_relative_error: None,
            sd_relative_error: None,
            sd_identified_relative: None,
            max_relative_error: None,
            coverage95: None,
            discretization_bias: None,
            ci95_noise: None,
            sd_fisher: None,
            birge_ratio: None,
            sd_jackknife: None,
            width_from: None,
        }
    }

    fn fit(jacobian: Vec<Vec<f64>>, residual: Vec<f64>) -> FitResult {
        FitResult {
            theta: vec![1.0],
            start: vec![1.0],
            cost: 0.5 * residual.iter().map(|r| r * r).sum::<f64>(),
            iterations: 1,
            forward_solves: 1,
            jacobians: 1,
            converged: true,
            reason: String::new(),
            history: Vec::new(),
            wall_time_s: 0.0,
            data: residual.len(),
            jacobian,
            residual,
        }
    }

    /// A location fit (J = 1) to whitened data: with white noise of the stated variance the
    /// Fisher sd stands (Birge ratio ≈ 1, jackknife ≈ Fisher); with the same noise plus a
    /// constant offset per block (a correlated systematic error) the jackknife takes over and
    /// is near the spread the block offsets imply.
    #[test]
    fn block_errors_widen_white_noise_does_not() {
        let n = 1600;
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let e: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
        let mean = e.iter().sum::<f64>() / n as f64;
        let r: Vec<f64> = e.iter().map(|v| v - mean).collect();
        let fisher = 1.0 / (n as f64).sqrt();
        let mut est = vec![estimate(fisher)];
        widen_for_misfit(&mut est, &fit(vec![vec![1.0; n]], r.clone()), true);
        // χ²/ν of 1599 unit normals: within ±10 % of 1 (sd 3.5 %); jackknife of 16 blocks:
        // its sd scatters by ~18 % (15 df) around the Fisher one, times 1.087.
        assert!((est[0].birge_ratio.unwrap() - 1.0).abs() < 0.1);
        assert!(est[0].relative_sd < 1.6 * fisher, "{:?}", est[0]);
        // Block offsets of sd 1 (16 blocks of 100 rows).
        let offsets: Vec<f64> = (0..16).map(|_| StandardNormal.sample(&mut rng)).collect();
        let raw: Vec<f64> = (0..n).map(|k| e[k] + offsets[k / 100]).collect();
        let mean = raw.iter().sum::<f64>() / n as f64;
        let r: Vec<f64> = raw.iter().map(|v| v - mean).collect();
        let mut est = vec![estimate(fisher)];
        widen_for_misfit(&mut est, &fit(vec![vec![1.0; n]], r), true);
        assert_eq!(est[0].width_from.as_deref(), Some("jackknife"));
        // The mean of 16 block offsets of sd 1 has sd 1/4: the jackknife sees it (within its
        // 15-df scatter, ±50 %), where Fisher says 0.025 and Birge √2 · 0.025.
        let sd = est[0].relative_sd;
        assert!(sd > 0.125 && sd < 0.4, "sd {sd}");
    }
}
