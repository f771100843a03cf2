//! A whole identification as the seed runs it (§2.1.3, §2.4): the free parameters (groups
//! tied, some fixed, bounds around the references), the data (a measured field, or the
//! virtual experiment: the model field at the reference parameters on a grid plus seeded
//! Gaussian noise, §2.4.1), several Latin-hypercube starts in parallel keeping the lowest cost,
//! optionally on a coarse model first (multilevel), repeated over noise realizations (Monte
//! Carlo), and the estimates: identified values, Eq. 4 errors, relative standard deviations
//! and 95 % intervals from the Jacobian at the optimum, correlations.

use crate::fisher::{self, FisherError, Identifiability, Tied};
use crate::fit::{
    bfgs, latin_hypercube, levenberg_marquardt, FitError, FitResult, FreeParameter, Gradient,
    LmOptions, Problem,
};
use crate::measured::{MeasuredField, MeasuredPoint};
use femu_mech::sensitivity::all_parameters;
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::locate::PointLocator;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The optimizer of an identification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Optimizer {
    /// Levenberg–Marquardt with the exact Jacobian (default).
    LevenbergMarquardt,
    /// BFGS with the exact gradient `Jᵀr`.
    Bfgs,
    /// BFGS with central finite-difference gradients (the seed's method, §2.1.3).
    BfgsFiniteDifference,
}

impl Optimizer {
    /// The study-file name.
    pub fn name(self) -> &'static str {
        match self {
            Optimizer::LevenbergMarquardt => "lm",
            Optimizer::Bfgs => "bfgs",
            Optimizer::BfgsFiniteDifference => "bfgs-fd",
        }
    }
}

/// Why an identification could not run.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    #[error("unknown parameter '{name}' (parameters: {known})")]
    UnknownParameter { name: String, known: String },
    #[error("part of the group {0} is fixed; fix all or none")]
    PartlyFixed(String),
    #[error("every parameter is fixed, nothing to identify")]
    NothingFree,
    #[error("[parameters] groups: {0}")]
    Groups(#[from] FisherError),
    #[error("no grid point lies in the tissue: check the grid")]
    NoGridPoint,
    #[error("noise standard deviation {0}: must be positive and finite")]
    BadNoise(f64),
    #[error("the reference solve for the travel: {0}")]
    ReferenceTravel(String),
    #[error("the actuator term needs a test with a rigid body")]
    NoRigidBody,
    /// Every start of a repeat failed; the reasons, most frequent first, and every start so
    /// far (to keep what finished).
    #[error("repeat {repeat}: every start failed: {}", summarize(reasons))]
    AllStartsFailed {
        repeat: usize,
        reasons: Vec<(String, usize)>,
        starts: Vec<StartRecord>,
    },
    #[error("refining the coarse optimum on the full model: {0}")]
    Refinement(FitError),
    /// The user asked to stop; the repeats finished before are kept.
    #[error("interrupted after {} of {repeats} repeats", finished.best.len())]
    Interrupted {
        finished: Box<Campaign>,
        repeats: usize,
    },
    #[error(transparent)]
    Fit(#[from] FitError),
}

fn summarize(reasons: &[(String, usize)]) -> String {
    reasons
        .iter()
        .map(|(r, n)| format!("{r} ({n} start{})", if *n == 1 { "" } else { "s" }))
        .collect::<Vec<_>>()
        .join("; ")
}

/// The free parameters of `model`: every material parameter, those of each group in `groups`
/// tied into one, those in `fixed` left out; references from the model, bounds a factor
/// `bounds_factor` either side. Returns them with their reference values.
pub fn free_parameters(
    model: &Model,
    groups: &[Vec<String>],
    fixed: &[String],
    bounds_factor: f64,
) -> Result<(Vec<FreeParameter>, Vec<f64>), CampaignError> {
    let params = all_parameters(model);
    let names: Vec<String> = params.iter().map(|p| p.name(model)).collect();
    for f in fixed {
        if !names.iter().any(|n| n.eq_ignore_ascii_case(f)) {
            return Err(CampaignError::UnknownParameter {
                name: f.clone(),
                known: names.join(", "),
            });
        }
    }
    let tied = Tied::new(&names, groups)?;
    let is_fixed = |k: usize| fixed.iter().any(|f| f.eq_ignore_ascii_case(&names[k]));
    let mut free = Vec::new();
    let mut reference = Vec::new();
    for (name, members) in tied.names.iter().zip(&tied.members) {
        let n_fixed = members.iter().filter(|&&k| is_fixed(k)).count();
        if n_fixed > 0 && n_fixed < members.len() {
            return Err(CampaignError::PartlyFixed(name.clone()));
        }
        if n_fixed > 0 {
            continue;
        }
        let v = params[members[0]].value(model);
        free.push(FreeParameter {
            name: name.clone(),
            members: members.iter().map(|&k| params[k]).collect(),
            lower: v / bounds_factor,
            upper: v * bounds_factor,
        });
        reference.push(v);
    }
    if free.is_empty() {
        return Err(CampaignError::NothingFree);
    }
    Ok((free, reference))
}

/// The grid points that lie in the tissue of `model`.
pub fn points_in_tissue(model: &Model, grid: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let locator = PointLocator::new(&model.mesh);
    grid.iter()
        .copied()
        .filter(|x| locator.locate(*x).is_some())
        .collect()
}

/// The virtual measurement (seed §2.4.1): the model field at `points` (in the tissue) for the
/// reference parameters, plus seeded Gaussian white noise of `sigma` (mm), weighted by `1/σ²`.
pub fn virtual_field(
    model: &Model,
    free: &[FreeParameter],
    reference: &[f64],
    points: &[[f64; 2]],
    sigma: f64,
    seed: u64,
) -> Result<MeasuredField, CampaignError> {
    if points.is_empty() {
        return Err(CampaignError::NoGridPoint);
    }
    let noise = Normal::new(0.0, sigma).map_err(|_| CampaignError::BadNoise(sigma))?;
    let all = MeasuredField {
        points: points
            .iter()
            .map(|&x| MeasuredPoint {
                x,
                u: [0.0; 2],
                weight: [1.0; 2],
            })
            .collect(),
        comments: vec![],
    };
    let mut p = Problem::new(model.clone(), SolverOptions::default(), &all, free.to_vec())?;
    let u = p.field_at(reference)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    Ok(MeasuredField {
        points: points
            .iter()
            .enumerate()
            .map(|(k, &x)| MeasuredPoint {
                x,
                u: [
                    u[2 * k] + noise.sample(&mut rng),
                    u[2 * k + 1] + noise.sample(&mut rng),
                ],
                weight: [1.0 / (sigma * sigma); 2],
            })
            .collect(),
        comments: vec![],
    })
}

/// The data an identification fits.
#[derive(Debug, Clone, Copy)]
pub enum Data<'a> {
    /// A measured field in the model frame.
    Measured(&'a MeasuredField),
    /// The virtual experiment: the model field at the reference parameters at these points (in
    /// the tissue) plus noise of this standard deviation (mm), one realization per repeat.
    Virtual { points: &'a [[f64; 2]], sigma: f64 },
}

/// The actuator term: the measured travel of the force-controlled body (`None`: synthesized
/// from the reference model plus noise, for a virtual experiment) and its standard deviation
/// (mm).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TravelTerm {
    pub measured_mm: Option<f64>,
    pub sigma_mm: f64,
}

/// How an identification runs.
#[derive(Debug, Clone)]
pub struct CampaignOptions {
    pub optimizer: Optimizer,
    /// Latin-hypercube starts per repeat.
    pub starts: usize,
    /// Seeds the noise, the starts and the travel noise.
    pub seed: u64,
    /// Noise realizations of a virtual experiment (a measured field is fitted once).
    pub repeats: usize,
    pub travel: Option<TravelTerm>,
    /// Set by the user to stop: the starts stop at their next forward solve and the campaign
    /// returns the repeats it finished ([`CampaignError::Interrupted`]).
    pub stop: Option<Arc<AtomicBool>>,
}

/// What happens during an identification, for the caller to show.
#[derive(Debug)]
pub enum Event<'a> {
    /// A repeat's starts begin.
    Repeat { repeat: usize, starts: usize },
    /// One start finished (in any order: they run in parallel).
    StartFinished,
    /// A start's outcome, in start order once the repeat's starts are done.
    Start {
        repeat: usize,
        start: usize,
        outcome: Result<&'a FitResult, &'a str>,
    },
    /// The best coarse optimum of a repeat is refined on the full model.
    Refining { repeat: usize },
    /// ... and the refined optimum.
    Refined {
        repeat: usize,
        elements: usize,
        result: &'a FitResult,
    },
}

/// One start: where it began and how it ended.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StartRecord {
    pub repeat: usize,
    pub start: usize,
    pub theta_start: Vec<f64>,
    pub result: Option<FitResult>,
    pub error: Option<String>,
}

/// The outcome of [`run`].
#[derive(Debug, Clone)]
pub struct Campaign {
    /// The best optimum of each repeat (refined on the full model when multilevel).
    pub best: Vec<FitResult>,
    /// Every start of every repeat.
    pub starts: Vec<StartRecord>,
    /// Forward solves of each repeat's refinement (multilevel).
    pub refinement_forward_solves: Vec<usize>,
    /// The field of the first repeat (the measured one, or the first noise realization).
    pub first_field: MeasuredField,
    pub points_in_tissue: usize,
    /// Points of the field outside the tissue (for a virtual experiment: of the grid).
    pub points_masked: usize,
    /// The reference (or measured) travel of the actuator term (mm).
    pub reference_travel: Option<f64>,
}

/// One start of the optimizer; `coarse`: the first level of a multilevel identification,
/// where an approximate optimum is enough (20 iterations, 1e-6 relative cost).
fn fit_start(
    optimizer: Optimizer,
    p: &mut Problem,
    start: &[f64],
    coarse: bool,
) -> Result<FitResult, FitError> {
    let lm = if coarse {
        LmOptions {
            max_iterations: 20,
            cost_tolerance: 1e-6,
            ..LmOptions::default()
        }
    } else {
        LmOptions::default()
    };
    match optimizer {
        Optimizer::LevenbergMarquardt => levenberg_marquardt(p, start, &lm),
        Optimizer::Bfgs => bfgs(p, start, Gradient::Exact, &lm, 200),
        Optimizer::BfgsFiniteDifference => {
            bfgs(p, start, Gradient::FiniteDifference(5e-4), &lm, 200)
        }
    }
}

/// The travel of the reference model's first rigid body (the model carries the reference
/// parameters).
fn reference_travel(model: &Model) -> Result<f64, CampaignError> {
    let mut solver = StaticSolver::new(model, SolverOptions::default())
        .map_err(|e| CampaignError::ReferenceTravel(e.to_string()))?;
    let sol = solver
        .solve(model)
        .map_err(|e| CampaignError::ReferenceTravel(e.to_string()))?;
    Ok(sol.bodies.first().ok_or(CampaignError::NoRigidBody)?.travel)
}

/// Identifies the free parameters of `model` (loaded with the measured test, carrying the
/// reference parameters) from `data` (see the module documentation); with `coarse`, the starts
/// run on that model and the best is refined on `model`. `on_event` sees the progress.
pub fn run(
    model: &Model,
    coarse: Option<&Model>,
    free: &[FreeParameter],
    reference: &[f64],
    data: Data,
    options: &CampaignOptions,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Campaign, CampaignError> {
    let repeats = match data {
        Data::Virtual { .. } => options.repeats.max(1),
        Data::Measured(_) => 1,
    };
    let reference_travel = match options.travel {
        Some(TravelTerm {
            measured_mm: None, ..
        }) => Some(reference_travel(model)?),
        Some(TravelTerm {
            measured_mm: Some(t),
            ..
        }) => Some(t),
        None => None,
    };
    let locator = PointLocator::new(&model.mesh);
    let mut out = Campaign {
        best: Vec::new(),
        starts: Vec::new(),
        refinement_forward_solves: Vec::new(),
        first_field: MeasuredField::default(),
        points_in_tissue: 0,
        points_masked: 0,
        reference_travel,
    };
    for rep in 0..repeats {
        let field = match data {
            Data::Measured(f) => f.clone(),
            Data::Virtual { points, sigma } => virtual_field(
                model,
                free,
                reference,
                points,
                sigma,
                options.seed + rep as u64,
            )?,
        };
        // The actuator term of this repeat: the measured travel, or the reference travel plus
        // seeded noise.
        let travel = match (options.travel, reference_travel) {
            (Some(term), Some(t)) => {
                let noise = if term.measured_mm.is_none() {
                    let mut rng = rand::rngs::StdRng::seed_from_u64(
                        options.seed.wrapping_mul(104_729) + rep as u64,
                    );
                    Normal::new(0.0, term.sigma_mm)
                        .map_err(|_| CampaignError::BadNoise(term.sigma_mm))?
                        .sample(&mut rng)
                } else {
                    0.0
                };
                Some((t + noise, term.sigma_mm))
            }
            _ => None,
        };
        let problem = |m: &Model| -> Result<Problem, FitError> {
            let p = Problem::new(m.clone(), SolverOptions::default(), &field, free.to_vec())?
                .with_stop(options.stop.clone());
            match travel {
                Some((t, sigma)) => p.with_travel(t, sigma),
                None => Ok(p),
            }
        };
        let starts = latin_hypercube(
            free,
            options.starts,
            options.seed.wrapping_mul(7919) + rep as u64,
        );
        on_event(Event::Repeat {
            repeat: rep,
            starts: starts.len(),
        });
        // The starts run on the coarse model when there is one (multilevel): the same data,
        // the same free parameters, a cheaper forward model.
        let start_model = coarse.unwrap_or(model);
        let outcomes: Vec<Result<FitResult, FitError>> = starts
            .par_iter()
            .map(|s| {
                let r = problem(start_model)
                    .and_then(|mut p| fit_start(options.optimizer, &mut p, s, coarse.is_some()));
                on_event(Event::StartFinished);
                r
            })
            .collect();
        let stopped = femu_mesh::stop::requested()
            || options
                .stop
                .as_ref()
                .is_some_and(|f| f.load(Ordering::Relaxed));
        if stopped {
            // The starts that finished before the stop are kept; the stopped ones are not
            // results.
            for (k, (s, o)) in starts.iter().zip(outcomes).enumerate() {
                if let Ok(r) = o {
                    out.starts.push(StartRecord {
                        repeat: rep,
                        start: k,
                        theta_start: s.clone(),
                        result: Some(r),
                        error: None,
                    });
                }
            }
            return Err(CampaignError::Interrupted {
                finished: Box::new(out),
                repeats,
            });
        }
        out.points_in_tissue = field
            .points
            .iter()
            .filter(|p| locator.locate(p.x).is_some())
            .count();
        out.points_masked = field.points.len() - out.points_in_tissue;
        if rep == 0 {
            out.first_field = field.clone();
        }
        let mut best: Option<FitResult> = None;
        let mut reasons: Vec<(String, usize)> = Vec::new();
        for (k, (s, o)) in starts.iter().zip(outcomes).enumerate() {
            let (result, error) = match o {
                Ok(r) => {
                    on_event(Event::Start {
                        repeat: rep,
                        start: k,
                        outcome: Ok(&r),
                    });
                    if best.as_ref().is_none_or(|b| r.cost < b.cost) {
                        best = Some(r.clone());
                    }
                    (Some(r), None)
                }
                Err(e) => {
                    let why = e.to_string();
                    on_event(Event::Start {
                        repeat: rep,
                        start: k,
                        outcome: Err(&why),
                    });
                    match reasons.iter_mut().find(|(r, _)| *r == why) {
                        Some(entry) => entry.1 += 1,
                        None => reasons.push((why.clone(), 1)),
                    }
                    (None, Some(why))
                }
            };
            out.starts.push(StartRecord {
                repeat: rep,
                start: k,
                theta_start: s.clone(),
                result,
                error,
            });
        }
        let Some(mut best) = best else {
            reasons.sort_by_key(|r| std::cmp::Reverse(r.1));
            return Err(CampaignError::AllStartsFailed {
                repeat: rep,
                reasons,
                starts: out.starts,
            });
        };
        // Multilevel: the best coarse optimum continued on the study's model.
        if coarse.is_some() {
            on_event(Event::Refining { repeat: rep });
            let refined = problem(model)
                .and_then(|mut p| fit_start(options.optimizer, &mut p, &best.theta, false));
            best = match refined {
                Ok(r) => r,
                Err(FitError::Interrupted) => {
                    return Err(CampaignError::Interrupted {
                        finished: Box::new(out),
                        repeats,
                    })
                }
                Err(e) => return Err(CampaignError::Refinement(e)),
            };
            on_event(Event::Refined {
                repeat: rep,
                elements: model.mesh.elements.len(),
                result: &best,
            });
            out.refinement_forward_solves.push(best.forward_solves);
        }
        out.best.push(best);
    }
    Ok(out)
}

/// An identified parameter with its uncertainty.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Estimate {
    pub name: String,
    pub reference: Option<f64>,
    pub identified: f64,
    /// Eq. 4 (best start of the first repeat).
    pub relative_error: Option<f64>,
    /// Relative standard deviation from the Jacobian at the optimum.
    pub relative_sd: f64,
    pub ci95: [f64; 2],
    /// Over the repeats: mean and standard deviation of Eq. 4 and of the identified value.
    pub mean_relative_error: Option<f64>,
    pub sd_relative_error: Option<f64>,
    pub sd_identified_relative: Option<f64>,
}

/// The estimates of a campaign: identified values (first repeat), their relative standard
/// deviations and 95 % intervals from the Jacobian at the optimum (the residuals have unit
/// variance when the data are whitened, `known_noise`; otherwise the residual variance scales
/// them), Eq. 4 errors when the references are the truth (`reference_known`), and the spread
/// over the repeats.
pub fn estimates(
    campaign: &Campaign,
    free: &[FreeParameter],
    reference: &[f64],
    reference_known: bool,
    known_noise: bool,
) -> Result<(Vec<Estimate>, Identifiability), CampaignError> {
    let best = &campaign.best[0];
    let repeats = campaign.best.len();
    let dof = best.data.saturating_sub(free.len()).max(1);
    let s = if known_noise {
        1.0
    } else {
        (2.0 * best.cost / dof as f64).sqrt()
    };
    let names: Vec<String> = free.iter().map(|f| f.name.clone()).collect();
    let info = fisher::information(&best.jacobian, s.max(1e-300), &Tied::none(&names))?;
    let id = fisher::identifiability(&info, &names);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let sd_of = |v: &[f64]| {
        let m = mean(v);
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len().max(2) - 1) as f64).sqrt()
    };
    let out = free
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let t = best.theta[k];
            let sd = id.relative_sd[k];
            let errors: Vec<f64> = campaign
                .best
                .iter()
                .map(|b| ((b.theta[k] - reference[k]) / reference[k]).abs())
                .collect();
            let logs: Vec<f64> = campaign.best.iter().map(|b| b.theta[k].ln()).collect();
            let several = repeats > 1;
            Estimate {
                name: f.name.clone(),
                reference: reference_known.then_some(reference[k]),
                identified: t,
                relative_error: reference_known.then_some(errors[0]),
                relative_sd: sd,
                ci95: [t * (-1.96 * sd).exp(), t * (1.96 * sd).exp()],
                mean_relative_error: (reference_known && known_noise && several)
                    .then(|| mean(&errors)),
                sd_relative_error: (reference_known && known_noise && several)
                    .then(|| sd_of(&errors)),
                sd_identified_relative: several.then(|| sd_of(&logs)),
            }
        })
        .collect();
    Ok((out, id))
}
