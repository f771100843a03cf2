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
    LeastSquares, LmOptions, Problem,
};
use crate::joint::{self, Block, JointProblem, Segments};
use crate::measured::{MeasuredField, MeasuredPoint};
use crate::speckle::SpeckleShift;
use crate::weighted::{FieldCovariance, Loss};
use femu_mech::sensitivity::all_parameters;
use femu_mech::{Model, SolverOptions, StaticSolver};
use femu_mesh::locate::PointLocator;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;
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
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut parts = virtual_segments(model, free, reference, &[(points, sigma)], &mut rng)?;
    Ok(parts.pop().unwrap_or_default())
}

/// The virtual measurement of several point sets of one model (probe windows of one test): one
/// solve at the reference parameters, each set with the noise of its own standard deviation,
/// drawn in order from `rng` (two per point); one field per set. A point outside `model`'s
/// mesh (the data's mesh may be another of the same geometry, whose polygonal outline differs
/// near the skin) has no data and is left out.
fn virtual_segments(
    model: &Model,
    free: &[FreeParameter],
    reference: &[f64],
    segments: &[(&[[f64; 2]], f64)],
    rng: &mut rand::rngs::StdRng,
) -> Result<Vec<MeasuredField>, CampaignError> {
    let truth = TruthField::solve(model, free, reference, segments, None)?;
    noisy_segments(&truth, segments, rng)
}

/// The noise-free virtual field of a block: the truth model's displacements at the reference
/// parameters at its virtual points (in the order of its segments), which of the points lie in
/// the truth model's mesh, and the solved state. Solved once per identification: each repeat's
/// realization only draws new noise ([`noisy_segments`]).
struct TruthField {
    /// Per virtual point: whether it lies in the mesh.
    inside: Vec<bool>,
    /// `[ux, uy]` of each point inside, in order (mm).
    u: Vec<f64>,
    /// The truth model's state at the reference parameters.
    state: Option<Vec<f64>>,
}

impl TruthField {
    /// One solve of `model` at `reference` (of `free`) for the points of `segments`.
    fn solve(
        model: &Model,
        free: &[FreeParameter],
        reference: &[f64],
        segments: &[(&[[f64; 2]], f64)],
        warm: Option<&[f64]>,
    ) -> Result<TruthField, CampaignError> {
        let points: Vec<[f64; 2]> = segments
            .iter()
            .flat_map(|(p, _)| p.iter().copied())
            .collect();
        if points.is_empty() {
            return Err(CampaignError::NoGridPoint);
        }
        let locator = PointLocator::new(&model.mesh);
        let inside: Vec<bool> = points
            .iter()
            .map(|x| locator.locate(*x).is_some())
            .collect();
        let all = MeasuredField {
            points: points
                .iter()
                .zip(&inside)
                .filter(|(_, i)| **i)
                .map(|(&x, _)| MeasuredPoint {
                    x,
                    u: [0.0; 2],
                    weight: [1.0; 2],
                })
                .collect(),
            comments: vec![],
        };
        let mut p = Problem::new(model.clone(), SolverOptions::default(), &all, free.to_vec())?;
        if let Some(w) = warm {
            p = p.with_warm_start(w.to_vec());
        }
        let u = p.field_at(reference)?;
        let state = p.states().pop().flatten();
        Ok(TruthField { inside, u, state })
    }
}

/// The virtual measurement of `segments` from their noise-free field `truth`: each set with
/// seeded Gaussian noise of its own standard deviation, drawn in order from `rng` (two per
/// point), weighted by `1/σ²`; one field per set.
fn noisy_segments(
    truth: &TruthField,
    segments: &[(&[[f64; 2]], f64)],
    rng: &mut rand::rngs::StdRng,
) -> Result<Vec<MeasuredField>, CampaignError> {
    let (inside, u) = (&truth.inside, &truth.u);
    let mut out = Vec::with_capacity(segments.len());
    let (mut k, mut row) = (0, 0);
    for &(pts, sigma) in segments {
        if !(sigma > 0.0) {
            return Err(CampaignError::BadNoise(sigma));
        }
        let noise = Normal::new(0.0, sigma).map_err(|_| CampaignError::BadNoise(sigma))?;
        let mut field = MeasuredField::default();
        for &x in pts {
            if inside[k] {
                field.points.push(MeasuredPoint {
                    x,
                    u: [
                        u[2 * row] + noise.sample(rng),
                        u[2 * row + 1] + noise.sample(rng),
                    ],
                    weight: [1.0 / (sigma * sigma); 2],
                });
                row += 1;
            }
            k += 1;
        }
        out.push(field);
    }
    Ok(out)
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

/// A measured block of a joint identification ([`run_joint`]): one loading test's model and the
/// parts of its field that are measured (probe windows, grids, files), fitted by FEMU. The
/// parts share one forward solve per evaluation.
#[derive(Debug, Clone)]
pub struct FieldBlock<'a> {
    /// The block's name (its test).
    pub name: String,
    /// The model loaded with the block's test.
    pub model: &'a Model,
    /// Multilevel: the same test on a coarse model, where the starts run.
    pub coarse: Option<&'a Model>,
    /// The model whose field at the reference parameters is the virtual data (e.g. a finer mesh
    /// of the same geometry, so that the identification does not fit data its own mesh made);
    /// `model` when `None`.
    pub truth: Option<&'a Model>,
    /// The measured parts, named, in the order of the block's residuals.
    pub segments: Vec<(String, Data<'a>)>,
    pub travel: Option<TravelTerm>,
    /// A solution of `model` at the reference parameters (another step solved it), from which
    /// the virtual data's solve starts Newton when `truth` is `None`.
    pub warm: Option<&'a [f64]>,
}

/// Builds a block that is not a measured field (grey levels, say) for the coarse model of a
/// multilevel identification (`true`) or the full one (`false`); its data must not change over
/// the repeats.
pub type BuildBlock<'a> = dyn Fn(bool) -> Result<Block, FitError> + Sync + 'a;

/// A block of a joint identification.
pub enum BlockSpec<'a> {
    Field(FieldBlock<'a>),
    /// Any other least-squares block with an exact Jacobian.
    Custom {
        name: String,
        build: &'a BuildBlock<'a>,
    },
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
    /// The actuator term of [`run`]'s single measurement ([`run_joint`] takes one per block).
    pub travel: Option<TravelTerm>,
    /// The measured field's full covariance (model frame, mm²; weighted FEMU, module
    /// [`crate::weighted`]), used instead of its per-point weights; measured data only.
    pub covariance: Option<FieldCovariance>,
    /// The speckle's lateral shift under shear in the measurement model of the measured field
    /// (module [`crate::speckle`]); measured data only, like `covariance`.
    pub speckle_shift: Option<SpeckleShift>,
    /// The loss on the (whitened) residuals.
    pub loss: Loss,
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

/// A measured part of a field block, as fitted in the first repeat.
#[derive(Debug, Clone)]
pub struct SegmentRecord {
    pub name: String,
    /// Its points in the block's field.
    pub points: Range<usize>,
    pub points_in_tissue: usize,
    pub points_masked: usize,
}

/// A field block as fitted in the first repeat.
#[derive(Debug, Clone)]
pub struct BlockRecord {
    pub name: String,
    /// The block's field (its segments one after the other).
    pub first_field: MeasuredField,
    pub segments: Vec<SegmentRecord>,
    /// The reference (or measured) travel of its actuator term (mm).
    pub reference_travel: Option<f64>,
}

/// The outcome of [`run`] and [`run_joint`].
#[derive(Debug, Clone)]
pub struct Campaign {
    /// The best optimum of each repeat (refined on the full model when multilevel).
    pub best: Vec<FitResult>,
    /// Every start of every repeat.
    pub starts: Vec<StartRecord>,
    /// Forward solves of each repeat's refinement (multilevel).
    pub refinement_forward_solves: Vec<usize>,
    /// The field of the first block in the first repeat (the measured one, or the first noise
    /// realization).
    pub first_field: MeasuredField,
    /// Points in the tissue and masked, over every field block.
    pub points_in_tissue: usize,
    /// Points of the fields outside the tissue (for a virtual experiment: of its points).
    pub points_masked: usize,
    /// The reference (or measured) travel of the first block's actuator term (mm).
    pub reference_travel: Option<f64>,
    /// The field blocks (custom blocks have no record).
    pub blocks: Vec<BlockRecord>,
    /// The named parts of the stacked residual of the full model (see
    /// [`JointProblem::segments`]), for each measurement's share of the information.
    pub layout: Segments,
    /// The full models' forward states at the end of the first repeat's refinement (one per
    /// forward model, as [`LeastSquares::states`]; empty without a multilevel refinement): a
    /// later problem on the same meshes near the optimum starts Newton from them.
    pub refined_states: Vec<Option<Vec<f64>>>,
}

/// One start of the optimizer; `coarse`: the first level of a multilevel identification,
/// where an approximate optimum is enough (20 iterations, 1e-6 relative cost).
fn fit_start<P: LeastSquares + ?Sized>(
    optimizer: Optimizer,
    p: &mut P,
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
/// run on that model and the best is refined on `model`. `on_event` sees the progress. A joint
/// identification of one measurement ([`run_joint`]).
pub fn run(
    model: &Model,
    coarse: Option<&Model>,
    free: &[FreeParameter],
    reference: &[f64],
    data: Data,
    options: &CampaignOptions,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Campaign, CampaignError> {
    let block = FieldBlock {
        name: "measurement".into(),
        model,
        coarse,
        truth: None,
        segments: vec![("measurement".into(), data)],
        travel: options.travel,
        warm: None,
    };
    run_joint(
        model,
        free,
        reference,
        &[BlockSpec::Field(block)],
        options,
        on_event,
    )
}

/// A field block's data in one repeat: the field (its segments one after the other), each
/// segment's points, and the actuator term `(travel, σ)`.
struct Realized {
    field: MeasuredField,
    segments: Vec<Range<usize>>,
    travel: Option<(f64, f64)>,
}

/// The noise stream of block `b` in repeat `rep`: the first block's is the single-measurement
/// identification's (`seed + rep`), so that a joint study of one reproduces it.
fn block_seed(seed: u64, b: usize, rep: usize) -> u64 {
    (seed + rep as u64).wrapping_add((b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// Realizes a field block's data for repeat `rep`: measured segments as given, virtual ones
/// made by the block's truth model at the reference plus seeded noise; the travel measured, or
/// the reference travel plus seeded noise.
fn realize(
    block: &FieldBlock,
    truth: Option<&TruthField>,
    b: usize,
    rep: usize,
    seed: u64,
    reference_travel: Option<f64>,
) -> Result<Realized, CampaignError> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(block_seed(seed, b, rep));
    let virtual_parts = virtual_parts(block);
    let mut virtual_fields = match truth {
        Some(t) if !virtual_parts.is_empty() => noisy_segments(t, &virtual_parts, &mut rng)?,
        _ => Vec::new(),
    }
    .into_iter();
    let mut field = MeasuredField::default();
    let mut segments = Vec::new();
    for (_, d) in &block.segments {
        let start = field.points.len();
        match d {
            Data::Measured(f) => field.points.extend_from_slice(&f.points),
            Data::Virtual { .. } => field
                .points
                .extend(virtual_fields.next().unwrap_or_default().points),
        }
        segments.push(start..field.points.len());
    }
    let travel = match (block.travel, reference_travel) {
        (Some(term), Some(t)) => {
            let noise = if term.measured_mm.is_none() {
                let mut rng = rand::rngs::StdRng::seed_from_u64(
                    seed.wrapping_mul(104_729) + rep as u64 + (b as u64).wrapping_mul(7_654_321),
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
    Ok(Realized {
        field,
        segments,
        travel,
    })
}

/// The virtual segments of `block`: points and noise of each.
fn virtual_parts<'a>(block: &FieldBlock<'a>) -> Vec<(&'a [[f64; 2]], f64)> {
    block
        .segments
        .iter()
        .filter_map(|(_, d)| match d {
            Data::Virtual { points, sigma } => Some((*points, *sigma)),
            Data::Measured(_) => None,
        })
        .collect()
}

/// The noise-free field of `block`'s virtual segments: its truth model (or its model) solved
/// at the reference parameters; `None` for a block without virtual segments.
fn truth_field(
    block: &FieldBlock,
    free: &[FreeParameter],
    free_model: &Model,
    reference: &[f64],
) -> Result<Option<TruthField>, CampaignError> {
    let parts = virtual_parts(block);
    if parts.is_empty() {
        return Ok(None);
    }
    let (truth, warm) = match block.truth {
        Some(t) => (t, None),
        None => (block.model, block.warm),
    };
    let (tfree, map) = joint::block_free(free, free_model, truth);
    let tref: Vec<f64> = map.iter().map(|&k| reference[k]).collect();
    TruthField::solve(truth, &tfree, &tref, &parts, warm).map(Some)
}

/// A field block's data: its field and each segment's points in it.
pub type RealizedField = (MeasuredField, Vec<Range<usize>>);

/// The data of every field block of `blocks` in repeat `rep` as [`run_joint`] fits them: per
/// block, its field (virtual segments realized with their noise) and each segment's points in
/// it — what `femu synth` writes.
pub fn realized_fields(
    free_model: &Model,
    free: &[FreeParameter],
    reference: &[f64],
    blocks: &[BlockSpec],
    seed: u64,
    rep: usize,
) -> Result<Vec<RealizedField>, CampaignError> {
    blocks
        .iter()
        .filter_map(|b| match b {
            BlockSpec::Field(f) => Some(f),
            BlockSpec::Custom { .. } => None,
        })
        .enumerate()
        .map(|(b, f)| {
            let mut f = f.clone();
            f.travel = None;
            let truth = truth_field(&f, free, free_model, reference)?;
            realize(&f, truth.as_ref(), b, rep, seed, None).map(|r| (r.field, r.segments))
        })
        .collect()
}

/// The FEMU block of `block` on `model` (the block's model or its coarse one) with the data of
/// one repeat, under the campaign's loss. The `first` field block, when it is one measured
/// segment (the study's single measured field), takes the options' covariance (weighted FEMU)
/// and speckle shift. `warm`: a state of `model` its first solve starts from.
#[allow(clippy::too_many_arguments)]
fn field_problem(
    block: &FieldBlock,
    data: &Realized,
    model: &Model,
    free: &[FreeParameter],
    free_model: &Model,
    options: &CampaignOptions,
    first: bool,
    warm: Option<&[f64]>,
) -> Result<Block, FitError> {
    let (bfree, map) = joint::block_free(free, free_model, model);
    let mut p = Problem::new(model.clone(), SolverOptions::default(), &data.field, bfree)?
        .with_stop(options.stop.clone())
        .with_loss(options.loss);
    if let Some(state) = warm {
        p = p.with_warm_start(state.to_vec());
    }
    if let (true, [(_, Data::Measured(_))]) = (first, block.segments.as_slice()) {
        if let Some(c) = &options.covariance {
            p = p.with_covariance(c)?;
        }
        if let Some(s) = options.speckle_shift {
            p = p.with_speckle_shift(s)?;
        }
    }
    if let Some((t, sigma)) = data.travel {
        p = p.with_travel(t, sigma)?;
    }
    let mut segments: Vec<(String, Range<usize>)> = block
        .segments
        .iter()
        .zip(&data.segments)
        .map(|((name, _), pts)| (name.clone(), p.rows_of(pts.clone())))
        .collect();
    if let Some(row) = p.travel_row() {
        segments.push((format!("{} travel", block.name), row..row + 1));
    }
    Ok(Block {
        name: block.name.clone(),
        problem: Box::new(p),
        map,
        segments,
    })
}

/// Identifies the free parameters (`free`, defined on `free_model`, with their reference
/// values) from several measured blocks at once ([`crate::joint`]): the same starts, bounds,
/// multilevel refinement and repeats as [`run`], over the stacked residuals of every block.
/// Each field block's model carries the reference parameters; its virtual data get their own
/// noise stream (the first block's is [`run`]'s).
pub fn run_joint(
    free_model: &Model,
    free: &[FreeParameter],
    reference: &[f64],
    blocks: &[BlockSpec],
    options: &CampaignOptions,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Campaign, CampaignError> {
    let fields = || {
        blocks.iter().filter_map(|b| match b {
            BlockSpec::Field(f) => Some(f),
            BlockSpec::Custom { .. } => None,
        })
    };
    let any_virtual = fields().any(|f| {
        f.segments
            .iter()
            .any(|(_, d)| matches!(d, Data::Virtual { .. }))
    });
    let repeats = if any_virtual {
        options.repeats.max(1)
    } else {
        1
    };
    let multilevel = fields().any(|f| f.coarse.is_some());
    let travels: Vec<Option<f64>> = fields()
        .map(|f| match f.travel {
            Some(TravelTerm {
                measured_mm: None, ..
            }) => reference_travel(f.truth.unwrap_or(f.model)).map(Some),
            Some(TravelTerm {
                measured_mm: Some(t),
                ..
            }) => Ok(Some(t)),
            None => Ok(None),
        })
        .collect::<Result<_, _>>()?;
    let mut out = Campaign {
        best: Vec::new(),
        starts: Vec::new(),
        refinement_forward_solves: Vec::new(),
        first_field: MeasuredField::default(),
        points_in_tissue: 0,
        points_masked: 0,
        reference_travel: travels.first().copied().flatten(),
        blocks: Vec::new(),
        layout: Vec::new(),
        refined_states: Vec::new(),
    };
    // The noise-free virtual fields, one per field block, solved once (empty until then): the
    // repeats draw their noise on them.
    let mut truths: Vec<Option<TruthField>> = Vec::new();
    for rep in 0..repeats {
        // A stop between repeats, or one that ends this repeat's virtual experiment (its
        // forward solve sees the request), keeps the repeats that finished.
        let realized: Result<Vec<Realized>, CampaignError> = (|| {
            if stop_requested(options) {
                return Err(CampaignError::Fit(FitError::Interrupted));
            }
            if truths.is_empty() {
                truths = fields()
                    .map(|f| truth_field(f, free, free_model, reference))
                    .collect::<Result<_, _>>()?;
            }
            fields()
                .enumerate()
                .map(|(b, f)| realize(f, truths[b].as_ref(), b, rep, options.seed, travels[b]))
                .collect()
        })();
        let realized = match realized {
            Ok(r) => r,
            Err(_) if stop_requested(options) => {
                return Err(CampaignError::Interrupted {
                    finished: Box::new(out),
                    repeats,
                })
            }
            Err(e) => return Err(e),
        };
        // The joint problem of this repeat's data on the coarse or the full models.
        let problem = |coarse: bool| -> Result<JointProblem, FitError> {
            let mut stacked = Vec::with_capacity(blocks.len());
            let mut data = realized.iter().zip(&truths);
            // The measured field's covariance and speckle shift belong to the first field block
            // (the study's single [measurement]).
            let mut first = true;
            for spec in blocks {
                stacked.push(match spec {
                    BlockSpec::Field(f) => {
                        let model = if coarse {
                            f.coarse.unwrap_or(f.model)
                        } else {
                            f.model
                        };
                        let (d, truth) = data.next().expect("one realization per field block");
                        // The refinement starts near the reference: Newton from the virtual
                        // data's solution when they were made on this mesh.
                        let warm = truth
                            .as_ref()
                            .and_then(|t| t.state.as_deref())
                            .filter(|_| multilevel && !coarse && f.truth.is_none());
                        let p = field_problem(f, d, model, free, free_model, options, first, warm)?;
                        first = false;
                        p
                    }
                    BlockSpec::Custom { build, .. } => build(coarse)?,
                });
            }
            JointProblem::new(free.to_vec(), stacked).map_err(|e| FitError::Joint(e.to_string()))
        };
        let best = run_repeat(&problem, free, multilevel, rep, options, on_event, &mut out)?;
        if rep == 0 {
            record_blocks(&mut out, fields(), &realized, &travels)?;
        }
        if multilevel {
            on_event(Event::Refining { repeat: rep });
            let refined = problem(false).and_then(|mut p| {
                let r = fit_start(options.optimizer, &mut p, &best.theta, false)?;
                if rep == 0 {
                    out.refined_states = p.states();
                }
                Ok((r, p.segments()))
            });
            let (best, layout) = match refined {
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
                elements: fields().map(|f| f.model.mesh.elements.len()).sum(),
                result: &best,
            });
            out.refinement_forward_solves.push(best.forward_solves);
            out.layout = layout;
            out.best.push(best);
        } else {
            out.best.push(best);
        }
    }
    Ok(out)
}

/// Whether the user asked to stop (Ctrl-C / SIGTERM, or the caller's flag).
fn stop_requested(options: &CampaignOptions) -> bool {
    femu_mesh::stop::requested()
        || options
            .stop
            .as_ref()
            .is_some_and(|f| f.load(Ordering::Relaxed))
}

/// The starts of one repeat in parallel (on the coarse models when `multilevel`); every start
/// recorded in `out`; returns the best (its layout kept in `out` on one level).
fn run_repeat(
    problem: &(dyn Fn(bool) -> Result<JointProblem, FitError> + Sync),
    free: &[FreeParameter],
    multilevel: bool,
    rep: usize,
    options: &CampaignOptions,
    on_event: &(dyn Fn(Event) + Sync),
    out: &mut Campaign,
) -> Result<FitResult, CampaignError> {
    let starts = latin_hypercube(
        free,
        options.starts,
        options.seed.wrapping_mul(7919) + rep as u64,
    );
    on_event(Event::Repeat {
        repeat: rep,
        starts: starts.len(),
    });
    type Outcome = Result<(FitResult, Segments), FitError>;
    let outcomes: Vec<Outcome> = starts
        .par_iter()
        .map(|s| {
            let r = problem(multilevel).and_then(|mut p| {
                let r = fit_start(options.optimizer, &mut p, s, multilevel)?;
                Ok((r, p.segments()))
            });
            on_event(Event::StartFinished);
            r
        })
        .collect();
    if stop_requested(options) {
        // The starts that finished before the stop are kept; the stopped ones are not
        // results.
        for (k, (s, o)) in starts.iter().zip(outcomes).enumerate() {
            if let Ok((mut r, _)) = o {
                r.jacobian = Vec::new();
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
            finished: Box::new(out.clone()),
            repeats: options.repeats.max(1),
        });
    }
    let mut best: Option<(FitResult, Segments)> = None;
    let mut reasons: Vec<(String, usize)> = Vec::new();
    for (k, (s, o)) in starts.iter().zip(outcomes).enumerate() {
        let (result, error) = match o {
            Ok((r, layout)) => {
                on_event(Event::Start {
                    repeat: rep,
                    start: k,
                    outcome: Ok(&r),
                });
                if best.as_ref().is_none_or(|b| r.cost < b.0.cost) {
                    best = Some((r.clone(), layout));
                }
                // The record keeps no Jacobian (only the best needs it, for the intervals):
                // 20 repeats of 2 starts on 10^5 residuals would hold 300 MB of them.
                let mut r = r;
                r.jacobian = Vec::new();
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
    let Some((best, layout)) = best else {
        reasons.sort_by_key(|r| std::cmp::Reverse(r.1));
        return Err(CampaignError::AllStartsFailed {
            repeat: rep,
            reasons,
            starts: out.starts.clone(),
        });
    };
    if !multilevel {
        out.layout = layout;
    }
    Ok(best)
}

/// Records the field blocks of the first repeat in `out`: fields, points in the tissue of the
/// full models, travels.
fn record_blocks<'a>(
    out: &mut Campaign,
    fields: impl Iterator<Item = &'a FieldBlock<'a>>,
    realized: &[Realized],
    travels: &[Option<f64>],
) -> Result<(), CampaignError> {
    for ((f, r), travel) in fields.zip(realized).zip(travels) {
        let locator = PointLocator::new(&f.model.mesh);
        let mut segments = Vec::new();
        for ((name, _), pts) in f.segments.iter().zip(&r.segments) {
            let inside = r.field.points[pts.clone()]
                .iter()
                .filter(|p| locator.locate(p.x).is_some())
                .count();
            out.points_in_tissue += inside;
            out.points_masked += pts.len() - inside;
            segments.push(SegmentRecord {
                name: name.clone(),
                points: pts.clone(),
                points_in_tissue: inside,
                points_masked: pts.len() - inside,
            });
        }
        out.blocks.push(BlockRecord {
            name: f.name.clone(),
            first_field: r.field.clone(),
            segments,
            reference_travel: *travel,
        });
    }
    if let Some(b) = out.blocks.first() {
        out.first_field = b.first_field.clone();
    }
    Ok(())
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
    /// The 95 % interval: from the Jacobian at the optimum, widened by the estimated
    /// discretization bias when that is not negligible ([`widen`]).
    pub ci95: [f64; 2],
    /// Over the repeats: mean and standard deviation of Eq. 4 and of the identified value.
    pub mean_relative_error: Option<f64>,
    pub sd_relative_error: Option<f64>,
    pub sd_identified_relative: Option<f64>,
    /// Over the repeats: the largest Eq. 4 error.
    #[serde(default)]
    pub max_relative_error: Option<f64>,
    /// Over the repeats: the fraction whose 95 % interval (each from its own Jacobian, widened
    /// like `ci95`) holds the reference.
    #[serde(default)]
    pub coverage95: Option<f64>,
    /// The estimated discretization bias of the log-parameter (identified on the model's mesh
    /// minus on a converged mesh; see `crate::discretization`), when it widened the interval.
    #[serde(default)]
    pub discretization_bias: Option<f64>,
    /// The interval of the noise alone, when `ci95` was widened.
    #[serde(default)]
    pub ci95_noise: Option<[f64; 2]>,
    /// On a measured field (`crate::misfit_intervals`): the Fisher sd, the Birge ratio, the
    /// block jackknife sd, and which of the three set `relative_sd`.
    #[serde(default)]
    pub sd_fisher: Option<f64>,
    #[serde(default)]
    pub birge_ratio: Option<f64>,
    #[serde(default)]
    pub sd_jackknife: Option<f64>,
    #[serde(default)]
    pub width_from: Option<String>,
}

/// The 95 % interval of `theta` with relative (log) standard deviation `sd` and an estimated
/// bias `bias` of its logarithm: the hull of the intervals around `theta` and around the
/// corrected `theta·e^(-bias)`.
pub(crate) fn interval(theta: f64, sd: f64, bias: f64) -> [f64; 2] {
    let corrected = theta * (-bias).exp();
    [
        theta.min(corrected) * (-1.96 * sd).exp(),
        theta.max(corrected) * (1.96 * sd).exp(),
    ]
}

/// The relative standard deviations of every repeat's optimum (whitened residuals when
/// `known_noise`, else scaled by each repeat's residual variance).
fn repeat_sds(
    campaign: &Campaign,
    free: &[FreeParameter],
    known_noise: bool,
) -> Result<Vec<Vec<f64>>, CampaignError> {
    let names: Vec<String> = free.iter().map(|f| f.name.clone()).collect();
    campaign
        .best
        .iter()
        .map(|b| {
            let dof = b.data.saturating_sub(free.len()).max(1);
            let s = if known_noise {
                1.0
            } else {
                (2.0 * b.cost / dof as f64).sqrt()
            };
            let info = fisher::information(&b.jacobian, s.max(1e-300), &Tied::none(&names))?;
            Ok(fisher::identifiability(&info, &names).relative_sd)
        })
        .collect()
}

/// Per parameter, the fraction of repeats whose interval (with `bias`) holds the reference.
fn coverage(campaign: &Campaign, sds: &[Vec<f64>], reference: &[f64], bias: &[f64]) -> Vec<f64> {
    (0..reference.len())
        .map(|k| {
            let hits = campaign
                .best
                .iter()
                .zip(sds)
                .filter(|(b, sd)| {
                    let [lo, hi] = interval(b.theta[k], sd[k], bias[k]);
                    lo <= reference[k] && reference[k] <= hi
                })
                .count();
            hits as f64 / campaign.best.len().max(1) as f64
        })
        .collect()
}

/// The estimates of a campaign: identified values (first repeat), their relative standard
/// deviations and 95 % intervals from the Jacobian at the optimum (the residuals have unit
/// variance when the data are whitened, `known_noise`; otherwise the residual variance scales
/// them), Eq. 4 errors when the references are the truth (`reference_known`), and the spread,
/// the worst error and the interval coverage over the repeats.
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
    let several = repeats > 1;
    let statistics = reference_known && known_noise && several;
    let covered = if statistics {
        let sds = repeat_sds(campaign, free, known_noise)?;
        Some(coverage(campaign, &sds, reference, &vec![0.0; free.len()]))
    } else {
        None
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
            Estimate {
                name: f.name.clone(),
                reference: reference_known.then_some(reference[k]),
                identified: t,
                relative_error: reference_known.then_some(errors[0]),
                relative_sd: sd,
                ci95: interval(t, sd, 0.0),
                mean_relative_error: statistics.then(|| mean(&errors)),
                sd_relative_error: statistics.then(|| sd_of(&errors)),
                sd_identified_relative: several.then(|| sd_of(&logs)),
                max_relative_error: statistics.then(|| errors.iter().copied().fold(0.0, f64::max)),
                coverage95: covered.as_ref().map(|c| c[k]),
                discretization_bias: None,
                ci95_noise: None,
                sd_fisher: None,
                birge_ratio: None,
                sd_jackknife: None,
                width_from: None,
            }
        })
        .collect();
    Ok((out, id))
}

/// What makes an identification's values or intervals meaningless, one sentence each, for
/// the console, the summary and the report (issue 32.6: such fits used to end with exit 0,
/// `inf %` standard deviations and no word): a best start that did not converge, a parameter
/// at one of its bounds (the data do not hold it inside), an infinite or undefined standard
/// deviation (the field does not determine it).
pub fn warnings(
    campaign: &Campaign,
    free: &[FreeParameter],
    estimates: &[Estimate],
) -> Vec<String> {
    let mut out = Vec::new();
    let unconverged: Vec<&FitResult> = campaign.best.iter().filter(|b| !b.converged).collect();
    if let Some(b) = unconverged.first() {
        let of = if campaign.best.len() > 1 {
            format!(
                " in {} of {} repeats",
                unconverged.len(),
                campaign.best.len()
            )
        } else {
            String::new()
        };
        out.push(format!(
            "the best start did not converge{of} ({} after {} iterations): its values are not an optimum; see starts.csv",
            b.reason, b.iterations
        ));
    }
    let best = &campaign.best[0];
    let mut at_bounds = Vec::new();
    for (f, &t) in free.iter().zip(&best.theta) {
        // The optimizers clamp ln θ to the log-bounds: at a bound to rounding.
        let side = if (t / f.lower).ln().abs() < 1e-9 {
            Some(("lower", f.lower))
        } else if (t / f.upper).ln().abs() < 1e-9 {
            Some(("upper", f.upper))
        } else {
            None
        };
        if let Some((side, b)) = side {
            let (unit, factor) = f.members[0].spec().unit.report();
            at_bounds.push(format!("{} ({side}, {} {unit})", f.name, b * factor));
        }
    }
    if !at_bounds.is_empty() {
        out.push(format!(
            "{} of {} parameters stopped at a bound: {}; the data do not hold them inside the bounds, so their values and intervals mean nothing (fix or tie them, widen [identification] bounds_factor, or measure a test that moves them)",
            at_bounds.len(),
            free.len(),
            at_bounds.join(", ")
        ));
    }
    let undetermined: Vec<&str> = estimates
        .iter()
        .filter(|e| !e.relative_sd.is_finite())
        .map(|e| e.name.as_str())
        .collect();
    if !undetermined.is_empty() {
        out.push(format!(
            "no finite standard deviation for {}: the measured field does not determine them (their Jacobian columns are zero or combinations of the others); fix or tie them",
            undetermined.join(", ")
        ));
    }
    out
}

/// Widens the intervals of `estimates` by the estimated discretization bias of each
/// log-parameter (`bias[k]`: identified on the model's mesh minus converged; see
/// `crate::discretization`): each interval becomes the hull of the intervals around the
/// identified and around the bias-corrected value, the noise-only interval kept in
/// `ci95_noise`; the coverage over the repeats is recounted with the widened intervals.
pub fn widen(
    estimates: &mut [Estimate],
    bias: &[f64],
    campaign: &Campaign,
    free: &[FreeParameter],
    reference: &[f64],
    known_noise: bool,
) -> Result<(), CampaignError> {
    let covered = if estimates.iter().any(|e| e.coverage95.is_some()) {
        let sds = repeat_sds(campaign, free, known_noise)?;
        Some(coverage(campaign, &sds, reference, bias))
    } else {
        None
    };
    for (k, e) in estimates.iter_mut().enumerate() {
        e.ci95_noise = Some(e.ci95);
        e.ci95 = interval(e.identified, e.relative_sd, bias[k]);
        e.discretization_bias = Some(bias[k]);
        if let Some(c) = &covered {
            e.coverage95 = Some(c[k]);
        }
    }
    Ok(())
}
