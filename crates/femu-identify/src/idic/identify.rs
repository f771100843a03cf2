//! The integrated-DIC identification, coarse to fine: the starts (the Latin-hypercube starts of
//! `identify`, plus any given, e.g. the optimum of the DIC → FEMU route) are optimized on
//! images smoothed by the widest Gaussian, where a displacement error of several pixels still
//! changes the grey levels smoothly; the best start is then continued on sharper and sharper
//! images, each (pair, band) reweighted by its residual variance, down to the images as
//! recorded. The estimate is that of the last scale, with the covariance of
//! [`super::uncertainty`].

use super::problem::{IdicError, IdicProblem};
use super::uncertainty::{block_sandwich, group_jackknife, SandwichCovariance};
use crate::campaign::StartRecord;
use crate::fit::{
    latin_hypercube, levenberg_marquardt, FitError, FitResult, FreeParameter, LeastSquares,
    LmOptions, Subset,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// How the identification runs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct IdicSettings {
    /// Gaussian smoothing of each scale (px), widest first; the last is usually 0 (the images
    /// as recorded).
    pub scales_px: Vec<f64>,
    /// Latin-hypercube starts (in the free parameters' bounds).
    pub starts: usize,
    pub seed: u64,
    /// Further starts (model units, one value per free parameter).
    pub extra_starts: Vec<Vec<f64>>,
    /// Levenberg–Marquardt on every scale but the last.
    pub coarse: LmOptions,
    /// ... and on the last.
    pub fine: LmOptions,
}

impl Default for IdicSettings {
    fn default() -> Self {
        IdicSettings {
            scales_px: vec![4.0, 2.0, 1.0, 0.0],
            starts: 5,
            seed: 1,
            extra_starts: Vec::new(),
            coarse: LmOptions {
                max_iterations: 20,
                cost_tolerance: 1e-5,
                step_tolerance: 1e-4,
                significance: Some(0.2),
                ..LmOptions::default()
            },
            fine: LmOptions {
                max_iterations: 30,
                cost_tolerance: 1e-8,
                step_tolerance: 1e-5,
                significance: Some(0.1),
                accelerate: true,
                ..LmOptions::default()
            },
        }
    }
}

/// One scale of the continuation.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ScaleRecord {
    pub scale_px: f64,
    pub result: FitResult,
    /// Residual standard deviation of each (pair, band) that weighted it (grey levels); empty
    /// on the first scale (weights from the reference's spread).
    pub band_sd: Vec<f64>,
    /// Free parameters held on this scale (indices): those the images did not see at its start
    /// (see [`seen_parameters`]).
    #[serde(default)]
    pub held: Vec<usize>,
}

/// A parameter whose relative standard deviation (block sandwich) exceeds this is not seen by
/// the images: its 95 % interval spans more than a factor 2 either way.
pub const SEEN_SD: f64 = 0.35;

/// The free parameters the images see at `phi` (sandwich sd below [`SEEN_SD`]; one at a bound
/// stays free, the optimizer's bounds handle it): the others are held while the seen ones
/// converge on a scale. Gauss–Newton crawls along the
/// directions the data hardly constrain (each step shrinks by a few per cent), and the
/// parameters the window cannot see would keep it crawling; their uncertainty still enters the
/// seen ones' through the full covariance at the end.
pub fn seen_parameters(problem: &mut IdicProblem, phi: &[f64]) -> Result<Vec<usize>, FitError> {
    let (r, j) = problem.evaluate(phi, true)?;
    let j = j.expect("asked");
    let pixels = problem.pixels();
    let n_pix = pixels.len();
    let cov = block_sandwich(&j, &r, &|k| pixels.block[k % n_pix], pixels.blocks);
    let free = problem.free();
    let seen: Vec<usize> = (0..free.len())
        .filter(|&k| {
            let at_bound =
                phi[k] <= free[k].lower.ln() + 1e-9 || phi[k] >= free[k].upper.ln() - 1e-9;
            cov.sd[k] < SEEN_SD && !at_bound
        })
        .collect();
    // Never hold everything: keep the best-seen parameter free.
    if seen.is_empty() {
        let best = (0..free.len())
            .min_by(|&a, &b| cov.sd[a].total_cmp(&cov.sd[b]))
            .unwrap_or(0);
        return Ok(vec![best]);
    }
    Ok(seen)
}

/// What the identification found.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct IdicOutcome {
    /// Every start on the widest scale.
    pub starts: Vec<StartRecord>,
    /// The best start continued on each scale.
    pub scales: Vec<ScaleRecord>,
    /// Identified free parameters (model units).
    pub theta: Vec<f64>,
    /// The covariance of `ln θ` from the residual of the last scale.
    pub covariance: SandwichCovariance,
    /// `sd(ln θ)` of the delete-one-group jackknife over regions of the image, and the groups.
    pub jackknife_sd: Vec<f64>,
    pub jackknife_groups: usize,
    /// Forward solves of all steps, summed over starts and scales.
    pub forward_solves: usize,
    pub wall_time_s: f64,
}

/// What happens during an identification, for the caller to show.
#[derive(Debug)]
pub enum IdicEvent<'a> {
    Start {
        index: usize,
        outcome: Result<&'a FitResult, &'a str>,
    },
    Scale(&'a ScaleRecord),
}

/// Why an identification stopped.
#[derive(Debug, thiserror::Error)]
pub enum IdicRunError {
    #[error(transparent)]
    Setup(#[from] IdicError),
    #[error("every start failed on the widest scale: {0}")]
    AllStartsFailed(String),
    #[error("scale {scale_px} px: {error}")]
    Scale { scale_px: f64, error: FitError },
    #[error("interrupted")]
    Interrupted,
}

/// Continues the identification from `theta` (model units, updated) on images smoothed by
/// `scale_px`: each (pair, band) reweighted by its residual variance, the parameters the images
/// do not see held ([`seen_parameters`]), the others optimized by `lm`. One scale of
/// [`identify`]; also the re-identification with a corrected model (see
/// [`IdicProblem::set_correction`]).
pub fn continue_on_scale(
    problem: &mut IdicProblem,
    theta: &mut Vec<f64>,
    scale_px: f64,
    lm: &LmOptions,
) -> Result<ScaleRecord, IdicRunError> {
    let err = |error: FitError| match error {
        FitError::Interrupted => IdicRunError::Interrupted,
        error => IdicRunError::Scale { scale_px, error },
    };
    let free = problem.free().to_vec();
    problem.set_scale(scale_px);
    // exp(ln θ) of a parameter at its bound may land an ulp outside it.
    for (t, f) in theta.iter_mut().zip(&free) {
        *t = t.clamp(f.lower, f.upper);
    }
    let phi: Vec<f64> = theta.iter().map(|t| t.ln()).collect();
    let band_sd = problem.reweight(&phi).map_err(err)?;
    let seen = seen_parameters(problem, &phi).map_err(err)?;
    let start: Vec<f64> = seen.iter().map(|&k| theta[k]).collect();
    let mut sub = Subset::new(problem, seen.clone(), phi);
    let mut result = levenberg_marquardt(&mut sub, &start, lm).map_err(err)?;
    let full: Vec<f64> = sub
        .full(&result.theta.iter().map(|t| t.ln()).collect::<Vec<_>>())
        .iter()
        .map(|p| p.exp())
        .collect();
    result.theta = full.clone();
    *theta = full;
    Ok(ScaleRecord {
        scale_px,
        result,
        band_sd,
        held: (0..free.len()).filter(|k| !seen.contains(k)).collect(),
    })
}

/// The noise part of the uncertainty at `theta` (the problem is left there): the block
/// sandwich covariance of `ln θ` and the delete-one-group jackknife sd over image regions, with
/// the number of groups.
pub fn noise_at(
    problem: &mut IdicProblem,
    theta: &[f64],
) -> Result<(SandwichCovariance, Vec<f64>, usize), IdicRunError> {
    let phi: Vec<f64> = theta.iter().map(|t| t.ln()).collect();
    let (r, j) = problem
        .evaluate(&phi, true)
        .map_err(|error| IdicRunError::Scale {
            scale_px: problem.scale_px(),
            error,
        })?;
    let j = j.expect("asked");
    let pixels = problem.pixels();
    let n_pix = pixels.len();
    let covariance = block_sandwich(&j, &r, &|k| pixels.block[k % n_pix], pixels.blocks);
    let (jackknife_sd, groups) =
        group_jackknife(&j, &r, &|k| pixels.group[k % n_pix], pixels.groups);
    Ok((covariance, jackknife_sd, groups))
}

/// The given starts (estimates of other routes, e.g. FEMU on the DIC's field), clamped into the
/// bounds (read back from files, exp(ln θ) of a bound may land an ulp outside). A value on a
/// bound (within 1e-3 in `ln θ`) is not an estimate: the route that made it did not hold the
/// parameter inside its bounds. It is replaced by the geometric mean of the other given starts'
/// values of that parameter that are inside, or by the centre of the bounds (in `ln θ`) when
/// none is. On the widest scale the images hardly see some parameters (the compressibilities),
/// so a start left on a bound stays there: on one simulated sequence a DIC → FEMU start with
/// D_QUADRICEPS on its lower bound had the lower cost after the widest scale, was kept, and the
/// estimate ended on the bound with C10_QUADRICEPS outside its interval.
pub fn given_starts(free: &[FreeParameter], given: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let on_bound = |v: f64, f: &FreeParameter| {
        (v / f.lower).ln() < BOUND_LN_TOLERANCE || (f.upper / v).ln() < BOUND_LN_TOLERANCE
    };
    let clamped: Vec<Vec<f64>> = given
        .iter()
        .map(|s| {
            s.iter()
                .zip(free)
                .map(|(v, f)| v.clamp(f.lower, f.upper))
                .collect()
        })
        .collect();
    clamped
        .iter()
        .map(|s| {
            s.iter()
                .zip(free)
                .enumerate()
                .map(|(k, (&v, f))| {
                    if !on_bound(v, f) {
                        return v;
                    }
                    let inside: Vec<f64> = clamped
                        .iter()
                        .map(|o| o[k])
                        .filter(|&o| !on_bound(o, f))
                        .collect();
                    if inside.is_empty() {
                        (0.5 * (f.lower.ln() + f.upper.ln())).exp()
                    } else {
                        (inside.iter().map(|o| o.ln()).sum::<f64>() / inside.len() as f64).exp()
                    }
                })
                .collect()
        })
        .collect()
}

/// A value within this of a bound in `ln θ` is on it ([`given_starts`]).
const BOUND_LN_TOLERANCE: f64 = 1e-3;

/// Identifies the free parameters of the problems `make` builds (one per start; they must be
/// identical) from its images (module documentation). Returns the problem of the best start,
/// evaluated at the optimum (its residual maps and displacements are those of the estimate),
/// and the outcome.
pub fn identify(
    make: &(dyn Fn() -> Result<IdicProblem, IdicError> + Sync),
    settings: &IdicSettings,
    on_event: &(dyn Fn(IdicEvent) + Sync),
) -> Result<(IdicProblem, IdicOutcome), IdicRunError> {
    let t0 = Instant::now();
    let first = make()?;
    let free = first.free().to_vec();
    let mut starts = latin_hypercube(&free, settings.starts, settings.seed.wrapping_mul(7919));
    starts.extend(given_starts(&free, &settings.extra_starts));
    if starts.is_empty() {
        return Err(IdicRunError::AllStartsFailed(
            "no start: settings.starts is 0 and no start was given".into(),
        ));
    }
    let widest = settings.scales_px.first().copied().unwrap_or(0.0);
    let mut problems: Vec<Option<IdicProblem>> = (0..starts.len()).map(|_| None).collect();
    problems[0] = Some(first);
    let outcomes: Vec<(Result<FitResult, FitError>, Option<IdicProblem>)> = starts
        .par_iter()
        .zip(problems.par_iter_mut())
        .map(|(s, slot)| {
            let mut p = match slot.take() {
                Some(p) => p,
                None => match make() {
                    Ok(p) => p,
                    Err(e) => return (Err(FitError::Solve(e.to_string())), None),
                },
            };
            p.set_scale(widest);
            let phi: Vec<f64> = s.iter().map(|t| t.ln()).collect();
            let r = p
                .freeze_mask(&phi)
                .and_then(|_| levenberg_marquardt(&mut p, s, &settings.coarse));
            (r, Some(p))
        })
        .collect();
    let mut records = Vec::new();
    let mut best: Option<(f64, Vec<f64>, IdicProblem)> = None;
    let mut reasons = Vec::new();
    let mut solves = 0;
    for (k, ((r, p), s)) in outcomes.into_iter().zip(&starts).enumerate() {
        if let Some(p) = &p {
            solves += p.counts().0;
        }
        match r {
            Ok(fit) => {
                on_event(IdicEvent::Start {
                    index: k,
                    outcome: Ok(&fit),
                });
                if best.as_ref().is_none_or(|b| fit.cost < b.0) {
                    best = Some((
                        fit.cost,
                        fit.theta.clone(),
                        p.expect("a fitted start has its problem"),
                    ));
                }
                records.push(StartRecord {
                    repeat: 0,
                    start: k,
                    theta_start: s.clone(),
                    result: Some(fit),
                    error: None,
                });
            }
            Err(FitError::Interrupted) => return Err(IdicRunError::Interrupted),
            Err(e) => {
                let why = e.to_string();
                on_event(IdicEvent::Start {
                    index: k,
                    outcome: Err(&why),
                });
                reasons.push(why.clone());
                records.push(StartRecord {
                    repeat: 0,
                    start: k,
                    theta_start: s.clone(),
                    result: None,
                    error: Some(why),
                });
            }
        }
    }
    let Some((_, mut theta, mut problem)) = best else {
        return Err(IdicRunError::AllStartsFailed(reasons.join("; ")));
    };
    let mut scales = Vec::new();
    let n_scales = settings.scales_px.len();
    for (i, &scale_px) in settings.scales_px.iter().enumerate().skip(1) {
        let lm = if i + 1 == n_scales {
            &settings.fine
        } else {
            &settings.coarse
        };
        let solves0 = problem.counts().0;
        let rec = continue_on_scale(&mut problem, &mut theta, scale_px, lm)?;
        solves += problem.counts().0 - solves0;
        on_event(IdicEvent::Scale(&rec));
        scales.push(rec);
    }
    let noise = noise_at(&mut problem, &theta)?;
    solves += problem.steps();
    let (covariance, jackknife_sd, jackknife_groups) = noise;
    Ok((
        problem,
        IdicOutcome {
            starts: records,
            scales,
            theta,
            covariance,
            jackknife_sd,
            jackknife_groups,
            forward_solves: solves,
            wall_time_s: t0.elapsed().as_secs_f64(),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn free(lower: f64, upper: f64) -> FreeParameter {
        FreeParameter {
            name: "P".into(),
            members: Vec::new(),
            lower,
            upper,
        }
    }

    /// A given start's value on a bound takes the other given starts' values inside the bounds
    /// (their geometric mean), or the centre of the bounds when none is inside; values inside
    /// are kept, values an ulp outside are clamped first.
    #[test]
    fn a_given_start_on_a_bound_starts_inside() {
        let f = [free(0.1, 10.0), free(1.0, 100.0)];
        let given = vec![
            vec![0.1, 100.0 * (1.0 + 1e-15)],
            vec![2.0, 100.0],
            vec![8.0, 50.0],
        ];
        let s = given_starts(&f, &given);
        assert!((s[0][0] - 4.0).abs() < 1e-12, "{:?}", s[0]);
        assert!((s[0][1] - 50.0).abs() < 1e-12, "{:?}", s[0]);
        assert!(
            s[1][0] == 2.0 && (s[1][1] - 50.0).abs() < 1e-12,
            "{:?}",
            s[1]
        );
        assert_eq!(s[2], vec![8.0, 50.0]);
        let lone = given_starts(&f, &[vec![10.0, 1.0]]);
        assert!((lone[0][0] - 1.0).abs() < 1e-12 && (lone[0][1] - 10.0).abs() < 1e-12);
    }
}
