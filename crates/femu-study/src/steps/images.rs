//! The identification from images (`[measurement] source = "ultrasound"`): integrated DIC
//! (`femu_identify::idic`) of the study's free parameters from the image sequence of the
//! measurement step — the unloaded frame and one frame per load step, correlated against the
//! finite-element state of each step — with the same starts, bounds, groups and fixed parameters
//! as `identify`; the mesh's discretization error of the displacement extrapolated from two
//! further meshes, held fixed, and the parameters identified again with it
//! (`femu_identify::idic::correction`); intervals from the grey-level residual's own
//! correlation, the correction's own uncertainty and the change from the last smoothed scale.
//! Written as
//!
//! - `parameters.csv` — identified values, errors (simulated images), standard deviations
//!   (statistical, discretization, total), 95 % intervals, whether the window sees each;
//! - `residual_before.png`, `residual_after.png` — the grey-level residual of the last load
//!   step with the tissue at rest and moved by the identified model;
//! - `displacement_ux.png`, `displacement_uy.png` — the identified model's displacement over
//!   the unloaded image;
//! - `summary.json` — [`ImageIdentificationSummary`].

use crate::bail;
use crate::error::{Context, Result};
use crate::output::{create_dir, read_json, write_json};
use crate::progress::Progress;
use crate::schema::{IdentificationSpec, Measurement, Study, TestSpec};
use crate::steps::identify::FreeParameterSummary;
use crate::steps::parameters::IdentificationInputs;
use crate::steps::ultrasound::{SimSummary, SimulatedImages};
use femu_dic::GreyImage;
use femu_identify::campaign::StartRecord;
use femu_identify::fit::FreeParameter;
use femu_identify::idic::pixels::MaskCounts;
use femu_identify::idic::pose_term::{PlacementUncertainty, PoseTerm};
use femu_identify::idic::{
    self, IdicEvent, IdicOptions, IdicProblem, IdicSettings, Pairing, PixelOptions,
};
use femu_mech::Model;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;
use std::time::Instant;

pub use super::sequence::{image_frame, ImageSequence};

/// The sequence of a `femu us-sim` folder `dir` (its `summary.json` and frames), for a script
/// that identifies from a folder written earlier (a run passes the sequence on in memory:
/// [`SimulatedImages::sequence`]).
pub fn read_sequence(dir: &Path) -> Result<ImageSequence> {
    let s: SimSummary = read_json(&dir.join("summary.json"))?;
    if s.frames.len() < 2 || s.frames.len() != s.load_fractions.len() + 1 {
        bail!(
            "{}: no image sequence ({} frames for {} load fractions); rerun the measurement",
            dir.display(),
            s.frames.len(),
            s.load_fractions.len()
        );
    }
    let frames = s
        .frames
        .iter()
        .map(|f| GreyImage::open(&dir.join(f), 0).with_context(|| format!("frame {f}")))
        .collect::<Result<Vec<_>>>()?;
    Ok(s.sequence(frames))
}

/// How the images are compared (the integrated correlation's options and its scales).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ImageRouteOptions {
    pub correlation: IdicOptions,
    /// Gaussian smoothing of each scale (px), widest first.
    pub scales_px: Vec<f64>,
    /// Whether to estimate the discretization shift on a refined mesh.
    pub discretization_check: bool,
    /// With the check: correct the model's displacement for the mesh and identify again
    /// ([`MeshCorrection`]) instead of widening the intervals by the extrapolated shift. Off by
    /// default: on the built-in thigh it did not remove the D_FAT error (which images rendered
    /// from the model's own mesh show as well: not a mesh error) and moved D_QUADRICEPS by
    /// 6 % (README, images → parameters).
    #[serde(default)]
    pub mesh_correction: bool,
    /// How well the frames' placement in the model is known: refined from the unloaded frame,
    /// its uncertainty enters the intervals as the pose term ([`PlacementKnown::Refined`]).
    #[serde(default)]
    pub placement: PlacementKnown,
}

/// How well the frames' placement in the model is known, for the intervals.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlacementKnown {
    /// The frames were made at it (simulated images): exact.
    #[default]
    Exact,
    /// Given by the study (recorded frames, `origin_mm`/`x_axis`/`y_axis` or `[probe]`): taken
    /// as exact, which a note says.
    Given,
    /// Refined from the unloaded frame, with the covariance of the refinement: the estimate's
    /// sensitivity to the placement times it is the pose term of the intervals
    /// (`femu_identify::idic::pose_term`).
    Refined(PlacementUncertainty),
}

impl Default for ImageRouteOptions {
    fn default() -> Self {
        ImageRouteOptions {
            correlation: IdicOptions {
                pairing: crate::schema::DEFAULT_IMAGE_PAIRING,
                brightness: true,
                pixels: PixelOptions::default(),
                solver: femu_mech::SolverOptions::default(),
                local_normalization_px: Some(crate::schema::DEFAULT_IMAGE_NORMALIZATION_PX),
            },
            scales_px: IdicSettings::default().scales_px,
            discretization_check: true,
            mesh_correction: false,
            placement: PlacementKnown::Exact,
        }
    }
}

impl ImageRouteOptions {
    /// The defaults with the study's own choices (`[identification] image_normalization_px`,
    /// `image_pairing`).
    pub fn for_study(study: &Study) -> ImageRouteOptions {
        ImageRouteOptions::for_identification(&study.identification)
    }

    /// The defaults with the choices of `[identification]` `spec` (`image_normalization_px`,
    /// `image_pairing`).
    pub fn for_identification(spec: &IdentificationSpec) -> ImageRouteOptions {
        let mut route = ImageRouteOptions::default();
        route.correlation.local_normalization_px = spec.image_normalization_px;
        route.correlation.pairing = spec.image_pairing;
        route
    }
}

/// One identified parameter with its uncertainty.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ImageEstimate {
    pub name: String,
    /// The true value for simulated images, else `None`.
    pub reference: Option<f64>,
    pub identified: f64,
    pub relative_error: Option<f64>,
    /// `sd(ln θ)` of the noise: the larger of the block sandwich (the residual's own
    /// correlation) and the jackknife over image regions.
    pub sd_statistical: f64,
    /// The two: block sandwich and jackknife over image regions.
    pub sd_sandwich: f64,
    pub sd_jackknife: f64,
    /// `sd(ln θ)` if the pixels' residuals were independent (for comparison: too narrow).
    pub sd_independent: f64,
    /// The bias of `ln θ` the mesh implies (one Gauss–Newton step to a refined mesh,
    /// extrapolated: `femu_identify::discretization::extrapolated_bias`), if computed.
    pub discretization_bias: Option<f64>,
    /// `sd(ln θ)` of the mesh correction itself (the spread of its effect over the rates
    /// `p ∓ 1`, see [`MeshCorrection`]): what remains of the discretization error in the
    /// interval once the estimate is corrected.
    #[serde(default)]
    pub discretization_sd: Option<f64>,
    /// The estimate on the model's mesh before the correction.
    #[serde(default)]
    pub uncorrected: Option<f64>,
    /// The change of `ln θ` from the last smoothed scale to the images as recorded (see
    /// [`estimates`]).
    pub scale_change: Option<f64>,
    /// `sd(ln θ)` of the frames' placement (the pose term `S Σ Sᵀ`, see [`PoseTerm`]), when
    /// the placement was refined from the unloaded frame.
    #[serde(default)]
    pub pose_sd: Option<f64>,
    /// `√(sd_statistical² + discretization_sd² + scale_change² + pose_sd²)`: the interval's.
    pub relative_sd: f64,
    /// 95 % interval `θ exp(±1.96 sd)`, clipped to the bounds.
    pub ci95: [f64; 2],
    pub at_bound: bool,
    /// Whether the window sees the parameter (relative sd below [`SEEN_SD`], not at a bound).
    pub seen: bool,
    /// A sentence when it does not.
    pub note: Option<String>,
}

pub use femu_identify::idic::SEEN_SD;

/// One scale of the coarse-to-fine identification.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ScaleSummary {
    pub scale_px: f64,
    pub cost: f64,
    pub iterations: usize,
    pub forward_solves: usize,
    pub theta: Vec<f64>,
    /// Residual standard deviation of each (frame pair, band) that weighted it (grey levels).
    pub band_sd: Vec<f64>,
    /// Parameters held on this scale (not seen by the images at its start).
    pub held: Vec<String>,
    /// Why the optimizer stopped, and every step it tried.
    pub reason: String,
    pub history: Vec<femu_identify::fit::LmStep>,
}

/// `summary.json` of an identification from images.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ImageIdentificationSummary {
    pub command: String,
    pub version: String,
    pub method: String,
    pub test: String,
    pub grouped: bool,
    pub elements: usize,
    /// Elements of the first further mesh of the discretization correction.
    pub refined_elements: Option<usize>,
    /// The discretization correction, when made.
    #[serde(default)]
    pub mesh_correction: Option<MeshCorrection>,
    /// The placement's part of the intervals (refined placement only): the estimate's
    /// sensitivity to the pose and its covariance `S Σ Sᵀ`.
    #[serde(default)]
    pub pose_term: Option<PoseTerm>,
    pub source: String,
    pub load_fractions: Vec<f64>,
    pub image_px: (usize, usize),
    pub pixels: usize,
    pub mask: MaskCounts,
    /// Blocks of the sandwich and groups of the jackknife.
    pub sandwich_blocks: usize,
    pub jackknife_groups: usize,
    pub pairing: Pairing,
    /// The frames' local normalization window (px), if any (`IdicOptions`).
    #[serde(default)]
    pub local_normalization_px: Option<f64>,
    pub free_parameters: Vec<FreeParameterSummary>,
    pub parameters: Vec<ImageEstimate>,
    pub correlation: Vec<Vec<f64>>,
    pub scales: Vec<ScaleSummary>,
    pub starts: Vec<StartRecord>,
    /// Grey-level residual RMS of the last pair with the tissue at rest and at the optimum.
    pub residual_rms_before: f64,
    pub residual_rms_after: f64,
    pub forward_solves: usize,
    /// Identification (starts and scales), discretization check, pose term, whole step (s).
    pub identification_s: f64,
    pub discretization_s: f64,
    #[serde(default)]
    pub pose_s: f64,
    /// Of the best start's problem: time in the forward solves and sensitivities, and in the
    /// image work (s).
    pub solve_s: f64,
    pub image_s: f64,
    pub wall_time_s: f64,
    pub notes: Vec<String>,
}

/// The test `test` at each load fraction on `built` (a copy each).
fn step_models(
    test: &TestSpec,
    built: &crate::model::StudyModel,
    fractions: &[f64],
) -> Result<Vec<Model>> {
    let test = test.loading.clone();
    fractions
        .iter()
        .map(|&f| built.loaded(&test.scaled(f)))
        .collect()
}

/// A mesh of the discretization correction: the study's with `factor` times the elements
/// (element size divided by `√factor`); `None` for a deck, which femu cannot refine.
fn refined_spec(
    spec: &crate::schema::ModelSpec,
    factor: usize,
) -> Option<crate::schema::ModelSpec> {
    use crate::schema::{Geometry, Resolution, DEFAULT_ELEMENTS, DEFAULT_LABEL_SIZE_MM};
    let shrink = (factor as f64).sqrt();
    let resolution = match (&spec.geometry, spec.resolution) {
        (Geometry::Deck(_), _) => return None,
        (_, Resolution::Elements(n)) => Resolution::Elements(factor * n),
        (_, Resolution::SizeMm(h)) => Resolution::SizeMm(h / shrink),
        (Geometry::Thigh(_), Resolution::Default) => {
            Resolution::Elements(factor * DEFAULT_ELEMENTS)
        }
        (_, Resolution::Default) => Resolution::SizeMm(DEFAULT_LABEL_SIZE_MM / shrink),
    };
    Some(crate::schema::ModelSpec {
        resolution,
        ..spec.clone()
    })
}

/// The further meshes of the discretization term and correction: twice and three times the
/// model's elements (never the renderer's `render_refine²`).
const REFINEMENT_FACTORS: [usize; 2] = [2, 3];

/// The sequence's load steps of the identification's test on the model of `inputs` meshed
/// with `factor` times the elements.
fn refined_step_models(
    inputs: &IdentificationInputs,
    seq: &ImageSequence,
    factor: usize,
) -> Result<Vec<Model>> {
    let spec = refined_spec(inputs.model, factor).context("a deck cannot be refined")?;
    let built = crate::model::build(&spec)?;
    step_models(inputs.identification_test(), &built, &seq.load_fractions)
}

/// The estimates from the identified `theta` and their uncertainty budget, terms added in
/// quadrature:
///
/// - the noise: the larger of the block sandwich (the residual's own correlation) and the
///   jackknife over image regions (`femu_identify::idic::uncertainty`);
/// - the discretization: the bias a refined mesh implies (one Gauss–Newton step to the mesh
///   of element size / √2, extrapolated by Richardson at the first-order rate);
/// - the resolution: the change of the estimate from the last smoothed scale to the images as
///   recorded (`scale_change`). A model that described the images would give the same
///   optimum on both, each a consistent estimate; their disagreement measures what the
///   grey-level model misses (speckle that does not follow the tissue under strain: the
///   envelope decorrelates by ~20 % per load step of the built-in compression at 9 MHz even
///   with no scatterer renewed, measured), which no residual statistic sees because the
///   parameters absorb it;
/// - the placement, when it was refined from the unloaded frame: the estimate's sensitivity
///   to the pose (one Gauss–Newton step per move of the placement) times the refinement's
///   covariance (`pose`, `femu_identify::idic::pose_term`).
#[allow(clippy::too_many_arguments)]
fn estimates(
    free: &[FreeParameter],
    reference: &[f64],
    reference_known: bool,
    theta: &[f64],
    cov: &idic::SandwichCovariance,
    jackknife: &[f64],
    mesh: Option<&MeshCorrection>,
    scale_change: Option<&[f64]>,
    pose: Option<&PoseTerm>,
) -> Vec<ImageEstimate> {
    free.iter()
        .enumerate()
        .map(|(k, f)| {
            let t = theta[k];
            let sd_stat = cov.sd[k].max(jackknife[k]);
            let s = mesh.map(|m| m.bias[k]);
            let mesh_sd = mesh.map(|m| m.sd[k]);
            let c = scale_change.map(|c| c[k]);
            let pose_sd = pose.map(|p| p.sd[k]);
            let sd = sd_stat
                .hypot(mesh_sd.unwrap_or(0.0))
                .hypot(c.unwrap_or(0.0))
                .hypot(pose_sd.unwrap_or(0.0));
            let ci = [
                (t * (-1.96 * sd).exp()).max(f.lower),
                (t * (1.96 * sd).exp()).min(f.upper),
            ];
            let at_bound = at_bound(t, f);
            let seen = sd < SEEN_SD && !at_bound;
            let note = (!seen).then(|| {
                if sd.is_finite() {
                    format!(
                        "{} is not seen from this window: relative sd {:.0} %{}; its value is the optimizer's, not a measurement (fix it, or add a window or test that sees it)",
                        f.name,
                        100.0 * sd,
                        if at_bound { ", at a bound" } else { "" }
                    )
                } else {
                    format!(
                        "{} does not change the grey levels of this window at all: fix it, or add a window or test that sees it",
                        f.name
                    )
                }
            });
            ImageEstimate {
                name: f.name.clone(),
                reference: reference_known.then_some(reference[k]),
                identified: t,
                relative_error: reference_known.then(|| t / reference[k] - 1.0),
                sd_statistical: sd_stat,
                sd_sandwich: cov.sd[k],
                sd_jackknife: jackknife[k],
                sd_independent: cov.sd_independent[k],
                discretization_bias: s,
                discretization_sd: mesh_sd,
                uncorrected: mesh.filter(|m| m.corrected).map(|m| m.uncorrected[k]),
                scale_change: c,
                pose_sd,
                relative_sd: sd,
                ci95: if seen { ci } else { [f.lower, f.upper] },
                at_bound,
                seen,
                note,
            }
        })
        .collect()
}

/// Whether `theta` sits at one of `f`'s bounds (within 0.1 % in `ln θ`).
fn at_bound(theta: f64, f: &FreeParameter) -> bool {
    (theta / f.lower).ln() < 1e-3 || (f.upper / theta).ln() < 1e-3
}

/// The parameters the one-step shifts of the discretization term let move: those the noise
/// alone sees (the larger of sandwich and jackknife below [`SEEN_SD`]) and not at a bound —
/// the ones the identification itself moved. The others are held: free, the directions the
/// images hardly constrain take up the mesh's change and the seen parameters' shifts come out
/// near zero (on the built-in thigh C10_FAT's shift to the renderer's own mesh: +0.02 % with
/// every parameter free, against the +2.4 % that identifying on that mesh gives).
fn moving_parameters(free: &[FreeParameter], outcome: &idic::IdicOutcome) -> Vec<bool> {
    free.iter()
        .enumerate()
        .map(|(k, f)| {
            let sd = outcome.covariance.sd[k].max(outcome.jackknife_sd[k]);
            sd < SEEN_SD && !at_bound(outcome.theta[k], f)
        })
        .collect()
}

/// The discretization correction of an integrated-DIC estimate
/// (`femu_identify::idic::correction`): what it did and cost.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MeshCorrection {
    /// Whether the estimate was corrected (`ImageRouteOptions::mesh_correction`); if not,
    /// `bias` is the extrapolated shift of [`discretization_shift`] and `sd` its magnitude.
    #[serde(default)]
    pub corrected: bool,
    /// Elements of the further meshes (twice and three times the model's).
    pub elements: Vec<usize>,
    /// The rate of eq. 2 when observed, and the rate used.
    pub rate_observed: Option<f64>,
    pub rate: f64,
    /// RMS of the correction over the pixels of every step (px).
    pub correction_rms_px: f64,
    /// The estimate before (model units), `ln θ_before − ln θ_after` (the mesh's bias), and
    /// the correction's own `sd(ln θ)`.
    pub uncorrected: Vec<f64>,
    pub bias: Vec<f64>,
    pub sd: Vec<f64>,
    /// The identification with the corrected model.
    pub cost: f64,
    pub iterations: usize,
    pub reason: String,
}

/// An optimizer's error as the step's: a stop request becomes [`crate::progress::Interrupted`]
/// (what `femu run` keeps finished work for).
fn fit_error(e: femu_identify::fit::FitError) -> crate::Error {
    match e {
        femu_identify::fit::FitError::Interrupted => {
            crate::Error::from(crate::progress::Interrupted)
        }
        e => crate::Error::from(e),
    }
}

/// [`fit_error`] for an integrated-DIC run's error.
fn run_error(e: idic::IdicRunError) -> crate::Error {
    match e {
        idic::IdicRunError::Interrupted => crate::Error::from(crate::progress::Interrupted),
        e => crate::Error::from(e),
    }
}

/// The discretization term of the intervals without correction: the one-step Gauss–Newton
/// shifts of the estimate to the meshes of twice and three times the elements (element size
/// / √2 and / √3), each extrapolated by Richardson at the cautious first-order rate of the
/// general check (`femu_identify::discretization::ASSUMED_RATE`: the two meshes are not nested,
/// their shifts observe no rate), added to the sd in quadrature; only the `moving` parameters
/// shift ([`moving_parameters`]). The two extrapolations estimate the same bias but each carries
/// its own mesh's local pattern (on the built-in thigh C10_FAT's bias, about −2 %, came out
/// with its sign in 25 of 30 image realizations, 0.35–2.3 % in magnitude); `bias` is their
/// mean, `sd` the larger magnitude. Returned as a [`MeshCorrection`] that corrected nothing
/// (`corrected: false`).
fn discretization_shift(
    inputs: &IdentificationInputs,
    seq: &ImageSequence,
    problem: &IdicProblem,
    moving: &[bool],
) -> Result<MeshCorrection> {
    use femu_identify::discretization::{extrapolated_bias, ASSUMED_RATE};
    let mut elements = Vec::new();
    let mut biases: Vec<Vec<f64>> = Vec::new();
    for factor in REFINEMENT_FACTORS {
        let models = refined_step_models(inputs, seq, factor)?;
        elements.push(models[0].mesh.elements.len());
        let shift = problem
            .discretization_shift(models, moving)
            .map_err(fit_error)?;
        biases.push(extrapolated_bias(
            &shift,
            (factor as f64).sqrt(),
            ASSUMED_RATE,
        ));
    }
    let (fine, finer) = (&biases[0], &biases[1]);
    let bias: Vec<f64> = fine.iter().zip(finer).map(|(a, b)| 0.5 * (a + b)).collect();
    let sd: Vec<f64> = fine
        .iter()
        .zip(finer)
        .map(|(a, b)| a.abs().max(b.abs()))
        .collect();
    Ok(MeshCorrection {
        corrected: false,
        elements,
        rate_observed: None,
        rate: ASSUMED_RATE,
        correction_rms_px: 0.0,
        uncorrected: Vec::new(),
        sd,
        bias,
        cost: f64::NAN,
        iterations: 0,
        reason: String::new(),
    })
}

/// Corrects the estimate of `outcome` (at which `problem` was last evaluated) for the mesh's
/// discretization error: the load steps solved on meshes of 2 and 3 times the elements, the
/// displacement at the pixels extrapolated to the continuum (eq. 1 of
/// `femu_identify::idic::correction`), the correction held fixed and the parameters identified
/// again on the images as recorded (one pass: the correction depends on `θ` at second order).
/// `outcome` then holds the corrected estimate and its noise; the correction's uncertainty is
/// half the spread of the one-step Gauss–Newton shifts its rates `p ∓ 1` would give.
fn mesh_correction(
    inputs: &IdentificationInputs,
    seq: &ImageSequence,
    problem: &mut IdicProblem,
    outcome: &mut idic::IdicOutcome,
    lm: &femu_identify::fit::LmOptions,
    moving: &[bool],
) -> Result<MeshCorrection> {
    use idic::correction::{self, Level};
    let own: Vec<Vec<[f64; 2]>> = (1..=problem.steps())
        .map(|i| problem.model_displacement(i))
        .collect();
    let mut levels = Vec::new();
    let mut elements = Vec::new();
    for factor in REFINEMENT_FACTORS {
        let models = refined_step_models(inputs, seq, factor)?;
        elements.push(models[0].mesh.elements.len());
        levels.push(Level {
            ratio: (factor as f64).sqrt(),
            displacement: problem.displacements_on(models).map_err(fit_error)?,
        });
    }
    let rate_observed = correction::observed_rate(&own, &levels);
    let rate = rate_observed.unwrap_or(correction::FALLBACK_RATE);
    let c = correction::correction(&own, &levels, rate);
    // The correction's uncertainty from the rate's: the shifts of the corrections at p ∓ 1
    // relative to this one, at the uncorrected optimum (its Jacobian is the problem's).
    let sd = {
        let [lo, hi] = correction::rate_range(rate);
        let diff = |p: f64| -> Vec<Vec<[f64; 2]>> {
            correction::correction(&own, &levels, p)
                .iter()
                .zip(&c)
                .map(|(a, b)| {
                    a.iter()
                        .zip(b)
                        .map(|(a, b)| [a[0] - b[0], a[1] - b[1]])
                        .collect()
                })
                .collect()
        };
        let (s_lo, s_hi) = (
            problem.shift_for(&diff(lo), moving),
            problem.shift_for(&diff(hi), moving),
        );
        s_lo.iter()
            .zip(&s_hi)
            .map(|(a, b)| 0.5 * (a - b).abs())
            .collect::<Vec<f64>>()
    };
    let correction_rms_px = correction::rms_px(&c);
    problem.set_correction(Some(c)).map_err(fit_error)?;
    let uncorrected = outcome.theta.clone();
    let mut theta = uncorrected.clone();
    let scale = problem.scale_px();
    let rec = idic::continue_on_scale(problem, &mut theta, scale, lm).map_err(run_error)?;
    let (covariance, jackknife_sd, groups) = idic::noise_at(problem, &theta).map_err(run_error)?;
    let bias = uncorrected
        .iter()
        .zip(&theta)
        .map(|(a, b)| (a / b).ln())
        .collect();
    outcome.theta = theta;
    outcome.covariance = covariance;
    outcome.jackknife_sd = jackknife_sd;
    outcome.jackknife_groups = groups;
    Ok(MeshCorrection {
        corrected: true,
        elements,
        rate_observed,
        rate,
        correction_rms_px,
        uncorrected,
        bias,
        sd,
        cost: rec.result.cost,
        iterations: rec.result.iterations,
        reason: rec.result.reason,
    })
}

/// The integrated-DIC identification of what `inputs` reads of a study (its test, groups and
/// `[identification]`; groups tied when `grouped`) from `seq`; `extra_starts` join the
/// Latin-hypercube starts (e.g. the DIC → FEMU optimum). Writes `out`.
#[allow(clippy::too_many_arguments)]
pub fn identify_images(
    inputs: &IdentificationInputs,
    grouped: bool,
    seq: &ImageSequence,
    reference_known: bool,
    extra_starts: Vec<Vec<f64>>,
    route: &ImageRouteOptions,
    out: &Path,
    progress: &dyn Progress,
) -> Result<ImageIdentificationSummary> {
    let t0 = Instant::now();
    create_dir(out)?;
    let built = crate::model::build(inputs.model)?;
    let test = inputs.identification_test();
    let models = step_models(test, &built, &seq.load_fractions)?;
    let last = models.last().context("no load step")?;
    let (free, reference) = inputs.free_parameters(last, grouped)?;
    let options = route.correlation;
    let stop = progress.stop_flag();
    let make = || {
        IdicProblem::new(
            models.clone(),
            seq.frames.clone(),
            seq.frame,
            free.clone(),
            options,
        )
        .map(|p| p.with_stop(stop.clone()))
    };
    let settings = IdicSettings {
        starts: inputs.identification.starts,
        seed: inputs.identification.seed,
        extra_starts,
        scales_px: route.scales_px.clone(),
        ..IdicSettings::default()
    };
    progress.note(&format!(
        "identify from images (integrated DIC): {}, {} elements, {} free parameters, {}",
        test.loading.name(),
        last.mesh.elements.len(),
        free.len(),
        what_is_correlated(seq, &options, &settings)
    ));
    let (mut problem, mut outcome) = idic::identify(&make, &settings, &show_idic_events(progress))
        .map_err(|e| run_error(e).context("identification from images"))?;
    let identification_s = t0.elapsed().as_secs_f64();
    // The discretization correction on further meshes.
    let t1 = Instant::now();
    let mut notes = Vec::new();
    let mut identified = Identified {
        free: &free,
        problem: &mut problem,
        outcome: &mut outcome,
    };
    let mesh =
        identified.discretization(inputs, seq, route, &settings.fine, &mut notes, progress)?;
    let discretization_s = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let pose_term = identified.pose_term(route, &mut notes, progress);
    let pose_s = t2.elapsed().as_secs_f64();
    let parameters = identified.estimates(
        &reference,
        reference_known,
        mesh.as_ref(),
        pose_term.as_ref(),
    );
    notes.extend(parameters.iter().filter_map(|p| p.note.clone()));
    let maps = problem.residual_maps();
    let before = rest_residual(&problem);
    let summary = ImageIdentificationSummary {
        command: "identify (images)".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        method: "integrated DIC".into(),
        test: test.loading.name(),
        grouped,
        elements: last.mesh.elements.len(),
        refined_elements: mesh.as_ref().and_then(|m| m.elements.first().copied()),
        mesh_correction: mesh,
        pose_term,
        source: seq.source.clone(),
        load_fractions: seq.load_fractions.clone(),
        image_px: (seq.frames[0].width, seq.frames[0].height),
        pixels: problem.pixels().len(),
        mask: problem.pixels().counts,
        sandwich_blocks: outcome.covariance.blocks,
        jackknife_groups: outcome.jackknife_groups,
        pairing: options.pairing,
        local_normalization_px: options.local_normalization_px,
        free_parameters: free.iter().map(FreeParameterSummary::from).collect(),
        correlation: femu_identify::fisher::correlation(&outcome.covariance.covariance),
        parameters,
        scales: scale_summaries(&outcome, &free),
        starts: outcome.starts.clone(),
        residual_rms_before: finite_rms(&before),
        residual_rms_after: finite_rms(maps.last().map_or(&[][..], |m| m.as_slice())),
        forward_solves: outcome.forward_solves,
        identification_s,
        discretization_s,
        pose_s,
        solve_s: problem.timings().0,
        image_s: problem.timings().1,
        wall_time_s: t0.elapsed().as_secs_f64(),
        notes,
    };
    write_parameters_csv(&out.join("parameters.csv"), &summary.parameters)?;
    write_figures(out, &problem, &before, maps.last())?;
    write_json(&out.join("summary.json"), &summary)?;
    print_estimates(&summary, out, progress);
    Ok(summary)
}

/// The frames, starts and scales of an integrated-DIC identification, in words.
fn what_is_correlated(
    seq: &ImageSequence,
    options: &IdicOptions,
    settings: &IdicSettings,
) -> String {
    format!(
        "{} frames (pairs: {:?}), {} starts + {} given, scales {:?} px, {}",
        seq.frames.len(),
        options.pairing,
        settings.starts,
        settings.extra_starts.len(),
        settings.scales_px,
        match options.local_normalization_px {
            Some(w) => format!("frames locally normalized over {w} px"),
            None => "grey levels as recorded".into(),
        }
    )
}

/// The progress of an integrated-DIC identification as notes: each start, each scale.
fn show_idic_events(progress: &dyn Progress) -> impl Fn(IdicEvent) + '_ {
    move |e: IdicEvent| match e {
        IdicEvent::Start { index, outcome } => match outcome {
            Ok(r) => progress.note(&format!(
                "  start {index}: cost {:.4e}, {} iterations, {} forward solves, {:.1} s ({})",
                r.cost, r.iterations, r.forward_solves, r.wall_time_s, r.reason
            )),
            Err(why) => progress.note(&format!("  start {index}: failed: {why}")),
        },
        IdicEvent::Scale(r) => progress.note(&format!(
            "  scale {} px: cost {:.4e}, {} iterations, {} forward solves, {:.1} s ({}); θ = {:?}",
            r.scale_px,
            r.result.cost,
            r.result.iterations,
            r.result.forward_solves,
            r.result.wall_time_s,
            r.result.reason,
            r.result.theta
        )),
    }
}

/// An integrated-DIC estimate and the problem it was last evaluated on.
struct Identified<'a> {
    free: &'a [FreeParameter],
    problem: &'a mut IdicProblem,
    outcome: &'a mut idic::IdicOutcome,
}

impl Identified<'_> {
    /// The estimates with their uncertainty budget ([`estimates`]).
    fn estimates(
        &self,
        reference: &[f64],
        reference_known: bool,
        mesh: Option<&MeshCorrection>,
        pose: Option<&PoseTerm>,
    ) -> Vec<ImageEstimate> {
        let outcome = &*self.outcome;
        estimates(
            self.free,
            reference,
            reference_known,
            &outcome.theta,
            &outcome.covariance,
            &outcome.jackknife_sd,
            mesh,
            scale_change(outcome).as_deref(),
            pose,
        )
    }

    /// The pose term of the intervals (`femu_identify::idic::pose_term`) when the placement
    /// was refined (`route.placement`), at the estimate the problem was last evaluated at; a
    /// given placement is taken as exact (a note). A pose term that fails is a note.
    fn pose_term(
        &self,
        route: &ImageRouteOptions,
        notes: &mut Vec<String>,
        progress: &dyn Progress,
    ) -> Option<PoseTerm> {
        let u = match route.placement {
            PlacementKnown::Exact => return None,
            PlacementKnown::Given => {
                notes.push(
                    "the frames' placement is the one given, taken as exact: the intervals leave its uncertainty out ([measurement] pose = \"refined\" estimates it from the unloaded frame and widens them by it)".into(),
                );
                return None;
            }
            PlacementKnown::Refined(u) => u,
        };
        let moving = moving_parameters(self.free, self.outcome);
        match femu_identify::idic::pose_term::pose_term(self.problem, &u, &moving) {
            Ok(t) => {
                progress.note(&format!(
                    "  pose term: the placement moved by one sd along each of its {} principal directions, {} of {} pixels left the mesh at most",
                    t.steps.len(),
                    t.pixels_outside,
                    t.pixels
                ));
                Some(t)
            }
            Err(e) => {
                notes.push(format!(
                    "the pose term failed ({e}): the intervals leave the placement's uncertainty out"
                ));
                None
            }
        }
    }

    /// The discretization term of the intervals as `route` asks: none (with a note saying
    /// why), the extrapolated shift ([`discretization_shift`]) or the estimate corrected for the
    /// mesh ([`mesh_correction`], which identifies again). A check that fails is a note; a
    /// stop request ends the step.
    fn discretization(
        &mut self,
        inputs: &IdentificationInputs,
        seq: &ImageSequence,
        route: &ImageRouteOptions,
        lm: &femu_identify::fit::LmOptions,
        notes: &mut Vec<String>,
        progress: &dyn Progress,
    ) -> Result<Option<MeshCorrection>> {
        if !route.discretization_check {
            notes.push(
                "the discretization check was not asked for: the intervals leave the mesh's error out"
                    .into(),
            );
            return Ok(None);
        }
        if refined_spec(inputs.model, 2).is_none() {
            notes.push(
                "the discretization error of a deck's mesh is unknown: femu cannot refine it; solve a finer deck of the same geometry and compare".into(),
            );
            return Ok(None);
        }
        let moving = moving_parameters(self.free, self.outcome);
        let (result, what, without) = if route.mesh_correction {
            let r = mesh_correction(inputs, seq, self.problem, self.outcome, lm, &moving);
            if let Ok(m) = &r {
                progress.note(&format!(
                    "  mesh correction: meshes of {:?} elements, rate {:.2} ({}), correction RMS {:.3} px; identified again: cost {:.4e}, {} iterations ({})",
                    m.elements,
                    m.rate,
                    if m.rate_observed.is_some() { "observed" } else { "not observed: nominal" },
                    m.correction_rms_px,
                    m.cost,
                    m.iterations,
                    m.reason
                ));
            }
            (
                r,
                "correction",
                "the estimate is the mesh's own and the intervals leave the mesh's error out",
            )
        } else {
            (
                discretization_shift(inputs, seq, self.problem, &moving),
                "check",
                "the intervals leave the mesh's error out",
            )
        };
        match result {
            Ok(m) => Ok(Some(m)),
            Err(e) if e.is_interrupted() => Err(e),
            Err(e) => {
                notes.push(format!(
                    "the discretization {what} failed ({}): {without}",
                    e.chain()
                ));
                Ok(None)
            }
        }
    }
}

/// The root mean square of the finite values of `m` (a residual map, NaN outside the mask).
fn finite_rms(m: &[f64]) -> f64 {
    let v: Vec<f64> = m.iter().copied().filter(|x| x.is_finite()).collect();
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Each scale of the coarse-to-fine identification, for the summary.
fn scale_summaries(outcome: &idic::IdicOutcome, free: &[FreeParameter]) -> Vec<ScaleSummary> {
    outcome
        .scales
        .iter()
        .map(|s| ScaleSummary {
            scale_px: s.scale_px,
            cost: s.result.cost,
            iterations: s.result.iterations,
            forward_solves: s.result.forward_solves,
            theta: s.result.theta.clone(),
            band_sd: s.band_sd.clone(),
            held: s.held.iter().map(|&k| free[k].name.clone()).collect(),
            reason: s.result.reason.clone(),
            history: s.result.history.clone(),
        })
        .collect()
}

/// The estimates of `summary` as a table for the user, and where they were written.
fn print_estimates(summary: &ImageIdentificationSummary, out: &Path, progress: &dyn Progress) {
    progress.note(&format!(
        "{:<36} {:>12} {:>12} {:>10} {:>9} {:>9} {:>9}",
        "parameter", "reference", "identified", "error", "sd", "mesh bias", "pose sd"
    ));
    for p in &summary.parameters {
        progress.note(&format!(
            "{:<36} {:>12} {:>12.5e} {:>10} {:>8.2}% {:>9} {:>9}{}",
            p.name,
            p.reference.map_or("-".into(), |v| format!("{v:.5e}")),
            p.identified,
            p.relative_error
                .map_or("-".into(), |e| format!("{:.3}%", 100.0 * e)),
            100.0 * p.relative_sd,
            p.discretization_bias
                .map_or("-".into(), |s| format!("{:.2}%", 100.0 * s)),
            p.pose_sd
                .map_or("-".into(), |s| format!("{:.2}%", 100.0 * s)),
            if p.seen { "" } else { "  (not seen)" }
        ));
    }
    progress.note(&format!(
        "wrote {} ({:.1} s: identification {:.1} s, discretization check {:.1} s{})",
        out.display(),
        summary.wall_time_s,
        summary.identification_s,
        summary.discretization_s,
        if summary.pose_term.is_some() {
            format!(", pose term {:.1} s", summary.pose_s)
        } else {
            String::new()
        }
    ));
}

/// `ln θ` of the last scale minus that of the one before (None with a single scale).
fn scale_change(outcome: &idic::IdicOutcome) -> Option<Vec<f64>> {
    let n = outcome.scales.len();
    if n < 2 {
        return None;
    }
    let (a, b) = (
        &outcome.scales[n - 2].result.theta,
        &outcome.scales[n - 1].result.theta,
    );
    Some(a.iter().zip(b).map(|(x, y)| (y / x).ln()).collect())
}

/// The residual of the last pair with the tissue at rest (no displacement), the same
/// brightness correction per band: how much the images differ before any correlation.
fn rest_residual(problem: &IdicProblem) -> Vec<f64> {
    let px = problem.pixels();
    let (w, h) = (px.width, px.height);
    let f = &problem.images()[0];
    let g = problem.images().last().expect("frames");
    let mut sums = vec![femu_identify::idic::brightness::BandSums::default(); px.bands];
    for (k, p) in px.px.iter().enumerate() {
        sums[px.band[k]].add(f.at(p[0], p[1]), g.at(p[0], p[1]));
    }
    let fits: Vec<_> = sums.iter().map(|s| s.fit(true)).collect();
    let mut m = vec![f64::NAN; w * h];
    for (k, p) in px.px.iter().enumerate() {
        m[p[1] * w + p[0]] = fits[px.band[k]].residual(f.at(p[0], p[1]), g.at(p[0], p[1]));
    }
    m
}

fn write_parameters_csv(path: &Path, params: &[ImageEstimate]) -> Result<()> {
    let mut w = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?,
    );
    writeln!(
        w,
        "name,reference,identified,relative_error,sd_statistical,sd_independent,discretization_bias,scale_change,pose_sd,relative_sd,ci95_low,ci95_high,seen"
    )?;
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.6e}"));
    for p in params {
        writeln!(
            w,
            "{},{},{:.9e},{},{:.6e},{:.6e},{},{},{},{:.6e},{:.9e},{:.9e},{}",
            p.name,
            opt(p.reference),
            p.identified,
            opt(p.relative_error),
            p.sd_statistical,
            p.sd_independent,
            opt(p.discretization_bias),
            opt(p.scale_change),
            opt(p.pose_sd),
            p.relative_sd,
            p.ci95[0],
            p.ci95[1],
            p.seen
        )?;
    }
    Ok(())
}

/// The residual maps before and after, and the identified displacement over the unloaded
/// image.
fn write_figures(
    out: &Path,
    problem: &IdicProblem,
    before: &[f64],
    after: Option<&Vec<f64>>,
) -> Result<()> {
    let px = problem.pixels();
    let (w, h) = (px.width, px.height);
    let grey = &problem.images()[0].data;
    let limit = before
        .iter()
        .filter(|v| v.is_finite())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    // With local normalization the residual is that of the normalized frames (a textured
    // region's local spread is 50 there).
    let (unit, what) = match problem.options().local_normalization_px {
        Some(w) => (
            format!("locally normalized grey levels ({w} px)"),
            "Residual of the locally normalized frames",
        ),
        None => ("grey levels".to_string(), "Grey-level residual"),
    };
    let residual = |name: &str, map: &[f64], title: &str| -> Result<()> {
        let p = out.join(name);
        femu_plot::image_field_png(
            &p,
            grey,
            w,
            h,
            map,
            &femu_plot::ImageField {
                title: format!("{what} {title}"),
                value_label: unit.clone(),
                diverging: true,
                range: (limit > 0.0).then_some((-limit, limit)),
                ..Default::default()
            },
        )
        .with_context(|| format!("cannot write {}", p.display()))
    };
    residual(
        "residual_before.png",
        before,
        "of the last load step, tissue at rest",
    )?;
    if let Some(a) = after {
        residual(
            "residual_after.png",
            a,
            "of the last load step, tissue moved by the identified model",
        )?;
    }
    let last = problem.steps();
    let d = problem.displacement(last);
    for (c, name, title) in [
        (0, "displacement_ux.png", "ux (along the probe)"),
        (1, "displacement_uy.png", "uy (depth, down)"),
    ] {
        let mut map = vec![f64::NAN; w * h];
        for (k, p) in px.px.iter().enumerate() {
            map[p[1] * w + p[0]] = d[k][c];
        }
        let p = out.join(name);
        femu_plot::image_field_png(
            &p,
            grey,
            w,
            h,
            &map,
            &femu_plot::ImageField {
                title: format!("Identified model displacement {title}, last load step"),
                value_label: "displacement (px)".into(),
                diverging: true,
                ..Default::default()
            },
        )
        .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

/// The three routes from the same images of the measurement `m`, side by side (`femu run` with
/// `[measurement] source = "ultrasound"`), each in its folder under `out`:
///
/// - `dic/` — DIC → FEMU, plain: the composed incremental DIC field (`measured.csv` of
///   `simulated`) with one weight per point, as `identify --measured` fits it;
/// - `dic-weighted/` — DIC → FEMU weighted by the field's full covariance
///   (`measured_covariance.mtx`) with Huber's loss;
/// - `.` (the folder itself) — integrated DIC from the frames, started from the two optima
///   above (the incremental DIC brings the capture range the grey levels alone lack: from the
///   Latin-hypercube starts themselves, 25–75 % off, the widest smoothing does not capture the
///   motion and the optimizer stops where it began).
///
/// Returns the three summaries.
pub fn identify_image_measurement(
    inputs: &IdentificationInputs,
    m: &Measurement,
    grouped: bool,
    simulated: &SimulatedImages,
    out: &Path,
    progress: &dyn Progress,
) -> Result<(
    crate::steps::identify::IdentificationSummary,
    crate::steps::identify::IdentificationSummary,
    ImageIdentificationSummary,
)> {
    use crate::steps::identify::identify_on;
    use crate::steps::measure::Measured;
    use crate::steps::measure::{Prepared, PreparedData};
    use femu_identify::weighted::{Loss, HUBER_K};
    let field = &simulated.measured;
    let covariance = simulated.covariance.clone();
    // Its own model, as `femu identify` builds it (the discretization check's meshes start
    // afresh for each grouping).
    let built = crate::model::build(inputs.model)?;
    let source = "DIC of the simulated B-mode images (incremental, composed)".to_string();
    let prepared = |covariance: Option<femu_identify::weighted::FieldCovariance>| Prepared {
        name: m.name.clone(),
        label: m.label(inputs.tests),
        test: m.test,
        data: PreparedData::Measured(Measured {
            field: field.clone(),
            source: if covariance.is_some() {
                format!("{source}, weighted by its covariance")
            } else {
                source.clone()
            },
            reference_known: true,
            speckle_shift: None,
            weighting: if covariance.is_some() {
                crate::schema::Weighting::Estimated
            } else {
                crate::schema::Weighting::PerPoint
            },
            covariance,
            simulated: None,
        }),
        travel: None,
    };
    let mut squared = inputs.identification.clone();
    squared.loss = Loss::Squared;
    progress.note("DIC -> FEMU, one weight per point:");
    let a = identify_on(
        &inputs.with(&squared),
        grouped,
        &built,
        &[prepared(None)],
        &out.join("dic"),
        progress,
    )?;
    let mut huber = inputs.identification.clone();
    huber.loss = Loss::Huber { k: HUBER_K };
    progress.note("DIC -> FEMU, weighted by the DIC's covariance, Huber's loss:");
    let b = identify_on(
        &inputs.with(&huber),
        grouped,
        &built,
        &[prepared(Some(covariance))],
        &out.join("dic-weighted"),
        progress,
    )?;
    let seq = simulated.sequence();
    let starts = vec![
        a.parameters.iter().map(|p| p.identified).collect(),
        b.parameters.iter().map(|p| p.identified).collect(),
    ];
    let route = ImageRouteOptions::for_identification(inputs.identification);
    let mut idic_spec = inputs.identification.clone();
    // The integrated DIC's starts are the two optima (see above).
    idic_spec.starts = 0;
    let c = identify_images(
        &inputs.with(&idic_spec),
        grouped,
        &seq,
        true,
        starts,
        &route,
        out,
        progress,
    )?;
    Ok((a, b, c))
}
