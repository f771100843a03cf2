//! The identification step (`femu identify`, `femu synth`, and the last step of `femu run`):
//! FEMU of the study's free parameters from its measurements — one, or several fitted together
//! (a joint identification: tests seen through probe windows, grids or files) — (seed §2.1.3,
//! Eq. 2; Fig. 9), computed by `femu_identify::campaign`, with the discretization check of
//! `femu_identify::discretization`, written as
//!
//! - `parameters.csv` — identified values, Eq. 4 errors, relative sd, 95 % intervals;
//! - `measurements.csv` — each measurement's points and share of the information;
//! - `starts.csv` — every start of every repeat;
//! - `errors.png` (Fig. 9 with error bars), `cost_history.png`, `fields.png` (one
//!   `fields_NAME.png` per measurement of a list);
//! - `summary.json` — [`IdentificationSummary`].

use super::discretization;
use super::joint::{self, FitFailure, JointFit, TestModels};
use super::measure::{self, MeasureInputs, Measured, Prepared, PreparedData};
use super::parameters::IdentificationInputs;
use crate::error::{Kept, Result};
use crate::model::StudyModel;
use crate::output::{create_dir, write_json};
use crate::progress::Progress;
use crate::schema::{
    Discretization, IdentificationSpec, Measurement, MeasurementSource, Study, TestSpec, Weighting,
};
use femu_identify::campaign::{self, CampaignOptions, Estimate, Event, StartRecord};
use femu_identify::discretization::DiscretizationCheck;
use femu_identify::error_model::{self, ErrorModel};
use femu_identify::fit::{FitResult, FreeParameter, Problem};
use femu_identify::joint::{block_free, information_shares};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_identify::speckle::{ShiftScale, SpeckleShift};
use femu_identify::weighted::FieldCovariance;
use femu_mech::{Model, SolverOptions};
use femu_mesh::locate::PointLocator;
use femu_plot::{bar_chart_png, line_plot_png, BarChart, LinePlot, LineStyle, Series};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;
use std::time::Instant;

/// `summary.json` of an identification.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct IdentificationSummary {
    pub command: String,
    pub version: String,
    /// The measured test, or the tests of a joint identification joined by ` + `.
    pub test: String,
    pub optimizer: String,
    pub grouped: bool,
    pub elements: usize,
    pub measured: String,
    pub points_in_tissue: usize,
    pub points_masked: usize,
    pub noise_sigma_mm: f64,
    pub free_parameters: Vec<FreeParameterSummary>,
    pub parameters: Vec<Estimate>,
    pub correlation: Vec<Vec<f64>>,
    pub best_cost: f64,
    pub starts_per_repeat: usize,
    pub repeats: usize,
    /// The actuator term: (measured or reference travel mm, its sigma mm).
    pub travel_term: Option<(Option<f64>, f64)>,
    /// Multilevel: elements of the coarse model the starts ran on.
    pub coarse_elements: Option<usize>,
    /// Multilevel: forward solves of the refinement on the full model, per repeat.
    pub refinement_forward_solves: Vec<usize>,
    pub forward_solves_per_start: Vec<usize>,
    pub starts: Vec<StartRecord>,
    pub wall_time_s: f64,
    /// Why the values or intervals may mean nothing (a best start not converged, a parameter
    /// at a bound, an infinite sd): `femu_identify::campaign::warnings`.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// How the misfit was weighted: "one sigma" (virtual), "per point" (the file's sx, sy or
    /// w), "full covariance" (weighted FEMU).
    #[serde(default)]
    pub weighting: String,
    #[serde(default)]
    pub loss: femu_identify::weighted::Loss,
    /// Set when the user stopped the run: what was kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interrupted: Option<String>,
    /// Each measurement fitted (and each actuator term): its points and its share of the
    /// information.
    #[serde(default)]
    pub measurements: Vec<MeasurementSummary>,
    /// The discretization check (`None` when `[identification] discretization = "off"`).
    #[serde(default)]
    pub discretization: Option<DiscretizationCheck>,
    /// Weighted FEMU: the measured field's error beyond its covariance, estimated from the
    /// residuals of the first stage (`femu_identify::error_model`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_model: Option<ErrorModel>,
    /// The speckle's lateral shift under shear in the measurement model
    /// (`[measurement] speckle_*`), and its scale at the optimum.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speckle_shift: Option<SpeckleShiftSummary>,
}

/// The speckle shift of an identification (`femu_identify::speckle`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SpeckleShiftSummary {
    pub frequency_mhz: f64,
    pub resolution_mm: f64,
    pub sound_speed_m_s: f64,
    /// Whether the scale was fitted with the parameters (or held at 1, the closed form's).
    pub fitted: bool,
    /// The scale κ at the optimum (the measured field with its per-point weights).
    pub scale: f64,
    /// Its standard deviation with the free parameters free too (a fitted scale), widened by
    /// the residuals' variance factor where it exceeds 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_sd: Option<f64>,
}

/// One measurement of an identification.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeasurementSummary {
    pub name: String,
    pub label: String,
    pub source: String,
    /// Noise of a virtual measurement (mm).
    pub sigma_mm: Option<f64>,
    pub points_in_tissue: usize,
    pub points_masked: usize,
    /// Its share of the information, and what it would identify alone (per free parameter).
    pub information: femu_identify::joint::InformationShare,
}

/// A model parameter as a free parameter lists it: its material (index) and parameter name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MemberSummary {
    pub material: usize,
    pub kind: String,
}

/// A free parameter of an identification: the model parameters it moves, its bounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FreeParameterSummary {
    pub name: String,
    pub members: Vec<MemberSummary>,
    pub lower: f64,
    pub upper: f64,
    /// The unit tables show it in (C10 in kPa, D in MPa⁻¹: the seed's Table 1) and the factor
    /// from the model unit (MPa, MPa⁻¹) to it.
    #[serde(default)]
    pub unit: String,
    #[serde(default = "one")]
    pub unit_factor: f64,
}

fn one() -> f64 {
    1.0
}

impl FreeParameterSummary {
    /// `value` (model units) in the unit tables show.
    pub fn shown(&self, value: f64) -> f64 {
        value * self.unit_factor
    }
}

impl From<&FreeParameter> for FreeParameterSummary {
    fn from(f: &FreeParameter) -> Self {
        let (unit, unit_factor) = f.members[0].spec().unit.report();
        FreeParameterSummary {
            name: f.name.clone(),
            members: f
                .members
                .iter()
                .map(|m| MemberSummary {
                    material: m.material,
                    kind: m.spec().name.to_string(),
                })
                .collect(),
            lower: f.lower,
            upper: f.upper,
            unit: unit.to_string(),
            unit_factor,
        }
    }
}

/// `femu synth`: the study's virtual measurements on its model (their first noise
/// realization), written to `out/measured.csv` (`out/NAME/measured.csv` for a list).
pub fn synth(study: &Study, out: &Path, progress: &dyn Progress) -> Result<()> {
    femu_mesh::folder::refuse_inputs_in(out, &study.input_files())?;
    create_dir(out)?;
    let built = crate::model::build(&study.model)?;
    let prepared = measure::prepare(&MeasureInputs::of(study), &built, out, progress)?;
    joint::write_measured(
        &IdentificationInputs::of(study),
        &built,
        &prepared,
        out,
        progress,
    )
}

/// `femu identify`: the study's identification (grouped unless `grouped = false`) from
/// `measured` (a CSV in the model frame, for a study of one measurement), the study's
/// measurements, or the virtual experiment.
pub fn identify(
    study: &Study,
    measured: Option<&Path>,
    out: &Path,
    progress: &dyn Progress,
) -> Result<IdentificationSummary> {
    let t0 = Instant::now();
    let result = identify_measured(study, measured, out, progress);
    if let Err(e) = &result {
        if crate::progress::is_interrupted(e) {
            // Stopped before a summary was written: one that says so.
            let kept: Vec<&str> = match e.kept() {
                Some(Kept::Summary) => return result,
                Some(Kept::Files(files)) => files.iter().map(String::as_str).collect(),
                None => Vec::new(),
            };
            crate::output::write_stopped(
                out,
                "identify",
                &e.chain(),
                &kept,
                t0.elapsed().as_secs_f64(),
            )?;
        }
    }
    result
}

/// [`identify`] without the account of a stop.
fn identify_measured(
    study: &Study,
    measured: Option<&Path>,
    out: &Path,
    progress: &dyn Progress,
) -> Result<IdentificationSummary> {
    let mut files = study.input_files();
    files.extend(measured);
    femu_mesh::folder::refuse_inputs_in(out, &files)?;
    if study
        .measurements
        .iter()
        .any(|m| m.source == MeasurementSource::Ultrasound)
        && measured.is_none()
    {
        crate::bail!(
            "[measurement] source = \"ultrasound\": `femu run` identifies from the images (integrated DIC, beside DIC -> FEMU); for DIC -> FEMU alone, simulate the images with `femu us-sim` and pass its measured.csv with --measured (its measured_covariance.mtx as [measurement] covariance for the weighted fit)"
        );
    }
    let built = crate::model::build(&study.model)?;
    let prepared = match measured {
        Some(p) => {
            // The file replaces the study's measured file and is read in its frame, with its
            // covariance: `--measured` and `[measurement] file` read a file alike.
            let (frame, covariance, weighting, speckle) =
                match study.measurements.first().map(|m| &m.source) {
                    Some(MeasurementSource::File {
                        frame,
                        covariance,
                        weighting,
                        speckle,
                        ..
                    }) => (*frame, covariance.as_deref(), *weighting, speckle.as_ref()),
                    _ => (
                        crate::schema::Frame::model(),
                        None,
                        Weighting::PerPoint,
                        None,
                    ),
                };
            let measured = measure::read_measured(p, &frame, covariance, weighting, speckle)?;
            measured_prepared(
                &study.measurements,
                &study.tests,
                measured,
                &format!("file {}", p.display()),
            )?
        }
        None => measure::prepare(&MeasureInputs::of(study), &built, out, progress)?,
    };
    identify_on(
        &IdentificationInputs::of(study),
        study.identification.grouped(),
        &built,
        &prepared,
        out,
        progress,
    )
}

/// The study's one measurement (of `measurements`, on `tests`) replaced by `measured` (a field
/// in the model frame, from `--measured CSV` or handed over by a script; `what` names it in the
/// label): `femu identify --measured`'s data.
pub fn measured_prepared(
    measurements: &[Measurement],
    tests: &[TestSpec],
    measured: Measured,
    what: &str,
) -> Result<Vec<Prepared>> {
    if measurements.len() > 1 {
        crate::bail!(
            "--measured replaces the one measurement of a study, and this study has {}: name the file in its [[measurement]]",
            measurements.len()
        );
    }
    let m = &measurements[0];
    Ok(vec![Prepared {
        name: m.name.clone(),
        label: format!("{}, {what}", tests[m.test].loading.name()),
        test: m.test,
        data: PreparedData::Measured(measured),
        travel: m.travel.map(|t| campaign::TravelTerm {
            measured_mm: t.measured_mm,
            sigma_mm: t.sigma_mm,
        }),
    }])
}

/// The progress of a campaign as notes and a bar per repeat.
fn show_events<'a>(progress: &'a dyn Progress, repeats: usize) -> impl Fn(Event) + Sync + 'a {
    let bar: std::sync::Mutex<Option<Box<dyn crate::progress::Task + 'a>>> =
        std::sync::Mutex::new(None);
    move |e: Event| {
        let mut b = bar.lock().unwrap_or_else(|p| p.into_inner());
        match e {
            Event::Repeat { repeat, starts } => {
                *b = Some(progress.task(
                    &format!("identification, repeat {}/{repeats}", repeat + 1),
                    Some(starts),
                ));
            }
            Event::StartFinished => {
                if let Some(t) = b.as_ref() {
                    t.inc(1);
                }
            }
            Event::Start {
                repeat,
                start,
                outcome,
            } => {
                *b = None;
                match outcome {
                    Ok(r) => progress.note(&format!(
                        "  repeat {repeat}, start {start}: cost {:.4e}, {} iterations, {} forward solves, {:.1} s",
                        r.cost, r.iterations, r.forward_solves, r.wall_time_s
                    )),
                    Err(why) => progress.note(&format!("  repeat {repeat}, start {start}: failed: {why}")),
                }
            }
            Event::Refining { repeat } => {
                *b = Some(progress.task(
                    &format!("repeat {repeat}: refining the best coarse optimum on the full model"),
                    None,
                ));
            }
            Event::Refined {
                repeat,
                elements,
                result: r,
            } => {
                *b = None;
                progress.note(&format!(
                    "  repeat {repeat}, refined on {elements} elements: cost {:.4e}, {} iterations, {} forward solves, {:.1} s",
                    r.cost, r.iterations, r.forward_solves, r.wall_time_s
                ));
            }
        }
    }
}

/// The fit of `prepared` on `models`; a campaign that stops keeps what finished (`starts.csv`
/// in `out`, and the repeats finished when interrupted: returned with their number).
///
/// Weighted FEMU (the study's single measured field brings its covariance) is fitted in two
/// stages (feasible generalized least squares, `femu_identify::error_model`): with the field's
/// per-point weights first, then with its covariance plus the error its residuals show beyond
/// it (returned with the fit).
fn fit_or_keep(
    inputs: &IdentificationInputs,
    grouped: bool,
    models: &TestModels,
    prepared: &[Prepared],
    out: &Path,
    progress: &dyn Progress,
) -> Result<(JointFit, Option<usize>, Option<ErrorModel>)> {
    let spec = inputs.identification;
    let any_virtual = prepared
        .iter()
        .any(|p| matches!(p.data, PreparedData::Virtual { .. }));
    let repeats = if any_virtual { spec.repeat } else { 1 };
    let mut options = CampaignOptions {
        optimizer: spec.optimizer,
        starts: spec.starts,
        seed: spec.seed,
        repeats,
        travel: None,
        stop: progress.stop_flag(),
        covariance: None,
        speckle_shift: None,
        loss: spec.loss,
    };
    let measured = match prepared {
        [Prepared {
            data: PreparedData::Measured(m),
            ..
        }] => Some(m),
        _ => None,
    };
    let estimated = match measured {
        Some(m) if m.weighting == Weighting::Estimated => Some((
            &m.field,
            // Without a covariance: the per-point variances the file gives.
            m.covariance
                .clone()
                .unwrap_or_else(|| per_point_covariance(&m.field)),
        )),
        // Per point, or the covariance alone: one fit.
        m => {
            options.covariance = m.and_then(|m| m.covariance.clone());
            None
        }
    };
    options.speckle_shift = measured.and_then(|m| m.speckle_shift);
    let Some((field, base)) = &estimated else {
        let (fit, stopped) = fit_once(inputs, grouped, models, prepared, out, progress, &options)?;
        return Ok((fit, stopped, None));
    };
    progress.note("weighted fit, stage 1 of 2: the field's per-point weights");
    let (first, stopped) = fit_once(inputs, grouped, models, prepared, out, progress, &options)?;
    if stopped.is_some() {
        return Ok((first, stopped, None));
    }
    let residuals = error_model::raw_residuals(&models.full[0], field, &first.campaign.best[0]);
    let model = error_model::estimate(field, &residuals, first.free.len(), Some(base));
    options.covariance = Some(match &model {
        Some(e) => {
            progress.note(&format!(
                "error of the measured field beyond its covariance, from the residuals of {} points: {}",
                e.used_points,
                e.describe()
            ));
            e.covariance(field, Some(base))
        }
        None => {
            progress.note(
                "too few points to estimate the field's error from its residuals: weighted by its covariance alone",
            );
            base.clone()
        }
    });
    progress.note("weighted fit, stage 2 of 2: the covariance and the estimated error");
    let (fit, stopped) = fit_once(inputs, grouped, models, prepared, out, progress, &options)?;
    Ok((fit, stopped, model))
}

/// The diagonal covariance of the per-point weights of `field` (`1/w` per component).
fn per_point_covariance(field: &MeasuredField) -> FieldCovariance {
    let m = 2 * field.points.len();
    let mut values = vec![0.0; m * m];
    for (i, p) in field.points.iter().enumerate() {
        for c in 0..2 {
            let k = 2 * i + c;
            values[k * m + k] = if p.weight[c] > 0.0 {
                1.0 / p.weight[c]
            } else {
                0.0
            };
        }
    }
    FieldCovariance {
        points: field.points.len(),
        values,
    }
}

/// One campaign of [`fit_or_keep`] with `options`.
fn fit_once(
    inputs: &IdentificationInputs,
    grouped: bool,
    models: &TestModels,
    prepared: &[Prepared],
    out: &Path,
    progress: &dyn Progress,
    options: &CampaignOptions,
) -> Result<(JointFit, Option<usize>)> {
    let on_event = show_events(progress, options.repeats);
    match joint::fit(inputs, grouped, models, prepared, options, &on_event) {
        Ok(fit) => Ok((fit, None)),
        Err(FitFailure::Setup(e)) => Err(e),
        Err(FitFailure::Campaign(
            campaign::CampaignError::Interrupted { finished, repeats },
            free,
        )) => {
            if finished.best.is_empty() {
                write_starts_csv(&out.join("starts.csv"), &free, &finished.starts)?;
                return Err(crate::Error::stopped(
                    format!(
                        "identification: no repeat finished ({} finished starts in {})",
                        finished.starts.len(),
                        out.join("starts.csv").display()
                    ),
                    Kept::Files(vec!["starts.csv".into()]),
                ));
            }
            let (_, reference) = inputs.free_parameters(&models.full[0], grouped)?;
            Ok((
                JointFit {
                    campaign: *finished,
                    free,
                    reference,
                },
                Some(repeats),
            ))
        }
        Err(FitFailure::Campaign(
            campaign::CampaignError::AllStartsFailed {
                repeat,
                reasons,
                starts,
            },
            free,
        )) => {
            // What finished is kept: every start's outcome.
            write_starts_csv(&out.join("starts.csv"), &free, &starts)?;
            Err(
                crate::Error::from(campaign::CampaignError::AllStartsFailed {
                    repeat,
                    reasons,
                    starts,
                })
                .context(format!(
                    "identification (every start in {})",
                    out.join("starts.csv").display()
                )),
            )
        }
        Err(FitFailure::Campaign(e, _)) => Err(e.into()),
    }
}

/// Which term set the intervals' widths on a measured field
/// (`femu_identify::misfit_intervals`), one sentence; `None` when none was applied.
fn width_note(parameters: &[Estimate]) -> Option<String> {
    let birge = parameters.iter().find_map(|p| p.birge_ratio)?;
    let names = |from: &str| -> Vec<&str> {
        parameters
            .iter()
            .filter(|p| p.width_from.as_deref() == Some(from))
            .map(|p| p.name.as_str())
            .collect()
    };
    let mut parts = Vec::new();
    for (from, what) in [
        (
            "jackknife",
            format!(
                "the jackknife over {} depth blocks of the points",
                femu_identify::misfit_intervals::JACKKNIFE_BLOCKS
            ),
        ),
        (
            "Birge ratio",
            format!("the Birge ratio √(χ²/ν) = {birge:.2}"),
        ),
        ("Fisher", "the Jacobian alone".to_string()),
    ] {
        let n = names(from);
        if !n.is_empty() {
            parts.push(format!("{what} for {}", n.join(", ")));
        }
    }
    Some(format!(
        "interval widths on the measured field: {}",
        parts.join("; ")
    ))
}

/// The estimates of `fit` with the discretization check: intervals widened when the bias is
/// not negligible and the data did not come from the model's mesh; with `"refine"`, the first
/// repeat identified again on the finest mesh of the check; without the check when `stopped`.
#[allow(clippy::too_many_arguments)]
fn estimate_with_check(
    inputs: &IdentificationInputs,
    built: &StudyModel,
    models: &TestModels,
    prepared: &[Prepared],
    fit: &mut JointFit,
    reference_known: bool,
    known_noise: bool,
    stopped: bool,
    progress: &dyn Progress,
) -> Result<(
    Vec<Estimate>,
    femu_identify::fisher::Identifiability,
    Option<DiscretizationCheck>,
)> {
    // On measured fields the intervals also answer to the misfit itself (Birge ratio, block
    // jackknife: `femu_identify::misfit_intervals`); a virtual experiment's noise is the model's.
    let measured = prepared
        .iter()
        .any(|p| matches!(p.data, PreparedData::Measured(_)));
    let estimates = |fit: &JointFit| {
        campaign::estimates(
            &fit.campaign,
            &fit.free,
            &fit.reference,
            reference_known,
            known_noise,
        )
        .map(|(mut e, id)| {
            if measured {
                femu_identify::misfit_intervals::widen_for_misfit(
                    &mut e,
                    &fit.campaign.best[0],
                    known_noise,
                );
            }
            (e, id)
        })
    };
    let (mut parameters, mut id) = estimates(fit)?;
    if inputs.identification.discretization == Discretization::Off {
        return Ok((parameters, id, None));
    }
    if stopped {
        // The user asked to stop: the repeats that finished are kept without the check's
        // solves on finer meshes (they would see the stop request and lose the repeats).
        progress.note("discretization check skipped: the identification was interrupted");
        return Ok((parameters, id, None));
    }
    let sd: Vec<f64> = parameters.iter().map(|p| p.relative_sd).collect();
    progress.note("discretization check: the fit on refined meshes");
    let mut checked =
        match discretization::check(inputs, built, models, prepared, fit, &sd, progress) {
            Ok(c) => c,
            // A stop during the check's solves: the finished fit is kept, unchecked.
            Err(e) if crate::progress::is_interrupted(&e) => {
                progress.note("discretization check interrupted: the fit is kept without it");
                let mut c = DiscretizationCheck::unknown(
                    models.elements(),
                    "the check was interrupted (run again to check the mesh)",
                );
                c.status = "interrupted".into();
                return Ok((parameters, id, Some(c)));
            }
            Err(e) => return Err(e),
        };
    let flagged = checked.check.flagged();
    if flagged
        && inputs.identification.discretization == Discretization::Refine
        && refine_on_finest(&mut checked, fit, progress)?
    {
        (parameters, id) = estimates(fit)?;
    }
    let widen = checked.check.flagged() && !discretization::data_from_model(inputs, prepared);
    if widen {
        campaign::widen(
            &mut parameters,
            &checked.check.bias,
            &fit.campaign,
            &fit.free,
            &fit.reference,
            known_noise,
        )?;
    }
    Ok((parameters, id, Some(checked.check)))
}

/// `[identification] discretization = "refine"`: the first repeat of `fit` identified again on
/// the finest mesh of the check (if it kept its problem), and the bias the check found scaled
/// to what remains beyond that mesh. Returns whether it was.
fn refine_on_finest(
    checked: &mut discretization::Checked,
    fit: &mut JointFit,
    progress: &dyn Progress,
) -> Result<bool> {
    let Some(finest) = checked.finest.as_mut() else {
        return Ok(false);
    };
    let refined = discretization::refine(
        finest,
        &fit.free,
        &fit.campaign.best[0].theta,
        &checked.check.bias,
    )?;
    let finest_elements = checked.check.levels.last().map_or(0, |l| l.elements);
    progress.note(&format!(
        "identified again on the refined mesh ({finest_elements} elements): cost {:.4e}, {} forward solves",
        refined.cost, refined.forward_solves
    ));
    fit.campaign.best[0] = refined;
    // The refined fit's Jacobian has the rows of the finest problem (the points inside every
    // level's mesh): the information shares read them through its layout.
    fit.campaign.layout = finest.segments();
    // What remains beyond the finest mesh: the bias scaled by ρ^-p.
    let check = &mut checked.check;
    let remaining = check
        .levels
        .last()
        .map_or(1.0, |l| l.ratio)
        .powf(-check.rate);
    check.bias.iter_mut().for_each(|b| *b *= remaining);
    check.bias_over_sd.iter_mut().for_each(|b| *b *= remaining);
    check.status = "refined".into();
    check.message = format!(
        "identified again on {finest_elements} elements (the mesh biased the parameters by up to {:.1} sd); the bias left is estimated at up to {:.2} sd",
        check.bias_over_sd.iter().copied().fold(0.0, f64::max) / remaining,
        check.bias_over_sd.iter().copied().fold(0.0, f64::max)
    );
    Ok(true)
}

/// The identification of what `inputs` reads of a study (groups tied when `grouped`) on the
/// model `built` from its `prepared` measurements (virtual ones drawn for `[identification]
/// repeat` noise realizations); writes `out`.
pub fn identify_on(
    inputs: &IdentificationInputs,
    grouped: bool,
    built: &StudyModel,
    prepared: &[Prepared],
    out: &Path,
    progress: &dyn Progress,
) -> Result<IdentificationSummary> {
    let t0 = Instant::now();
    create_dir(out)?;
    let spec = inputs.identification;
    let models = TestModels::new(inputs, built, prepared)?;
    let data = DataKind::of(prepared);
    let tests: Vec<String> = models
        .tests
        .iter()
        .map(|&t| inputs.tests[t].loading.name())
        .collect();
    note_identification(spec, &models, prepared, &tests, progress);
    let (mut fit, interrupted, error_model) =
        fit_or_keep(inputs, grouped, &models, prepared, out, progress)?;
    write_starts_csv(&out.join("starts.csv"), &fit.free, &fit.campaign.starts)?;
    let (parameters, id, check) = estimate_with_check(
        inputs,
        built,
        &models,
        prepared,
        &mut fit,
        data.reference_known,
        data.known_noise(),
        interrupted.is_some(),
        progress,
    )?;
    if let Some(note) = width_note(&parameters) {
        progress.note(&note);
    }
    let warnings = campaign::warnings(&fit.campaign, &fit.free, &parameters);
    let measurements = measurement_summaries(prepared, &fit);
    write_parameters_csv(&out.join("parameters.csv"), &parameters)?;
    write_measurements_csv(&out.join("measurements.csv"), &fit.free, &measurements)?;
    let speckle_shift = femu_mesh::stop::shielded(|| speckle_at_optimum(&models, &fit, prepared))?;
    if let Some(s) = &speckle_shift {
        progress.note(&format!(
            "speckle shift under shear: scale {:.3}{} of the closed form at {} MHz, lateral resolution {} mm ({})",
            s.scale,
            s.scale_sd.map_or(String::new(), |sd| format!(" (sd {sd:.3})")),
            s.frequency_mhz,
            s.resolution_mm,
            if s.fitted { "fitted" } else { "fixed" }
        ));
    }
    let c = &fit.campaign;
    let best = &c.best[0];
    // What finished is written even after a stop (the field figures need one more solve).
    femu_mesh::stop::shielded(|| {
        write_result_figures(
            inputs.measurement_list,
            &models,
            &fit,
            &parameters,
            data.reference_known,
            speckle_shift.and_then(|s| Some((measure::measured_speckle(prepared)?.1, s.scale))),
            out,
        )
    })?;
    let summary = IdentificationSummary {
        command: "identify".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        test: tests.join(" + "),
        optimizer: spec.optimizer.name().into(),
        grouped,
        elements: models.elements(),
        measured: measured_sources(prepared),
        points_in_tissue: c.points_in_tissue,
        points_masked: measurements.iter().map(|m| m.points_masked).sum(),
        noise_sigma_mm: data.sigma.unwrap_or(inputs.sigma_mm),
        free_parameters: fit.free.iter().map(FreeParameterSummary::from).collect(),
        parameters,
        correlation: id.correlation,
        best_cost: best.cost,
        starts_per_repeat: spec.starts,
        repeats: c.best.len(),
        travel_term: prepared
            .iter()
            .find_map(|p| p.travel)
            .map(|t| (c.reference_travel, t.sigma_mm)),
        coarse_elements: models.coarse.first().map(|m| m.mesh.elements.len()),
        refinement_forward_solves: c.refinement_forward_solves.clone(),
        forward_solves_per_start: c
            .starts
            .iter()
            .filter_map(|s| s.result.as_ref().map(|r| r.forward_solves))
            .collect(),
        starts: c.starts.clone(),
        wall_time_s: t0.elapsed().as_secs_f64(),
        warnings,
        weighting: data.weighting(error_model.is_some()).into(),
        loss: spec.loss,
        interrupted: interrupted_note(interrupted, c.best.len(), check.as_ref()),
        measurements,
        discretization: check,
        error_model,
        speckle_shift,
    };
    write_summary(summary, out, progress)
}

/// The speckle shift of the study's single measured field (`[measurement] speckle_*`) with its
/// scale at the optimum: a held scale as given; a fitted one profiled again there, with the
/// field's per-point weights (the scale a weighted fit profiled can differ a little), and its sd.
fn speckle_at_optimum(
    models: &TestModels,
    fit: &JointFit,
    prepared: &[Prepared],
) -> Result<Option<SpeckleShiftSummary>> {
    let Some((field, shift)) = measure::measured_speckle(prepared) else {
        return Ok(None);
    };
    let Some(best) = fit.campaign.best.first() else {
        return Ok(None);
    };
    let model = &models.full[0];
    let (bfree, map) = block_free(&fit.free, model, model);
    let phi: Vec<f64> = map.iter().map(|&k| best.theta[k].ln()).collect();
    let mut p = Problem::new(model.clone(), SolverOptions::default(), field, bfree)?
        .with_speckle_shift(shift)?;
    // A held scale is its value; a fitted one is profiled at the optimum with its sd.
    let (scale, scale_sd) = match femu_identify::misfit_intervals::speckle_scale_sd(&mut p, &phi)? {
        Some((kappa, sd)) => (kappa, Some(sd)),
        None => (p.speckle_scale().unwrap_or(0.0), None),
    };
    Ok(Some(SpeckleShiftSummary {
        frequency_mhz: shift.frequency_mhz,
        resolution_mm: shift.resolution_mm,
        sound_speed_m_s: shift.sound_speed_m_s,
        fitted: matches!(shift.scale, ShiftScale::Fitted),
        scale,
        scale_sd,
    }))
}

/// Writes `summary.json` and prints the table; an identification a stop cut short is then the
/// error that says what was kept.
fn write_summary(
    summary: IdentificationSummary,
    out: &Path,
    progress: &dyn Progress,
) -> Result<IdentificationSummary> {
    write_json(&out.join("summary.json"), &summary)?;
    print_table(&summary, progress);
    progress.note(&format!(
        "wrote {} ({:.1} s)",
        out.display(),
        summary.wall_time_s
    ));
    if let Some(note) = &summary.interrupted {
        return Err(crate::Error::stopped(
            format!("identification: {note} in {}", out.display()),
            Kept::Summary,
        ));
    }
    Ok(summary)
}

/// What kind of data an identification fits.
struct DataKind {
    /// Every measurement is virtual (the model's field with noise of known sigma).
    virtual_experiment: bool,
    /// The reference parameters are the truth (a simulated experiment).
    reference_known: bool,
    /// A measurement is weighted by a covariance (whitened residuals).
    weighted: bool,
    /// The noise sigma of the first virtual measurement.
    sigma: Option<f64>,
}

impl DataKind {
    fn of(prepared: &[Prepared]) -> DataKind {
        DataKind {
            virtual_experiment: prepared
                .iter()
                .all(|p| matches!(p.data, PreparedData::Virtual { .. })),
            reference_known: prepared.iter().all(|p| match &p.data {
                PreparedData::Virtual { .. } => true,
                PreparedData::Measured(m) => m.reference_known,
            }),
            weighted: prepared.iter().any(|p| {
                matches!(&p.data, PreparedData::Measured(m) if m.weighting != Weighting::PerPoint)
            }),
            sigma: prepared.iter().find_map(|p| match p.data {
                PreparedData::Virtual { sigma, .. } => Some(sigma),
                PreparedData::Measured(_) => None,
            }),
        }
    }

    /// Whether the noise's size is known: a virtual experiment's sigma, or whitened residuals
    /// (unit variance); the intervals then need no residual scaling.
    fn known_noise(&self) -> bool {
        self.virtual_experiment || self.weighted
    }

    /// How the misfit is weighted, as the summary says it (`estimated_error`: an error model
    /// was estimated beside the covariance).
    fn weighting(&self, estimated_error: bool) -> &'static str {
        if self.weighted && estimated_error {
            "covariance and estimated error"
        } else if self.weighted {
            "full covariance"
        } else if self.virtual_experiment {
            "one sigma"
        } else {
            "per point"
        }
    }
}

/// What an identification is about to fit, for the user.
fn note_identification(
    spec: &IdentificationSpec,
    models: &TestModels,
    prepared: &[Prepared],
    tests: &[String],
    progress: &dyn Progress,
) {
    let any_virtual = prepared
        .iter()
        .any(|p| matches!(p.data, PreparedData::Virtual { .. }));
    progress.note(&format!(
        "identify ({}): {} ({} measurement{}), {} elements, {} starts x {} noise realizations",
        spec.optimizer.name(),
        tests.join(" + "),
        prepared.len(),
        if prepared.len() == 1 { "" } else { "s" },
        models.elements(),
        spec.starts,
        if any_virtual { spec.repeat } else { 1 }
    ));
    if let Some(c) = models.coarse.first() {
        progress.note(&format!(
            "multilevel: starts on {} elements, the best refined on {}",
            c.mesh.elements.len(),
            models.elements()
        ));
    }
}

/// Where the measurements come from, each source once.
fn measured_sources(prepared: &[Prepared]) -> String {
    let mut sources: Vec<String> = Vec::new();
    for p in prepared {
        if !sources.contains(&p.source()) {
            sources.push(p.source());
        }
    }
    sources.join("; ")
}

/// What the summary says of a stop: the repeats kept of `interrupted` asked (`finished` of
/// them), or a discretization check cut short.
fn interrupted_note(
    interrupted: Option<usize>,
    finished: usize,
    check: Option<&DiscretizationCheck>,
) -> Option<String> {
    match interrupted {
        Some(n) => Some(format!(
            "interrupted: {finished} of {n} repeats finished and kept"
        )),
        None if check.is_some_and(|k| k.status == "interrupted") => Some(
            "interrupted during the discretization check: the fit is kept, its intervals not checked for the mesh".into(),
        ),
        None => None,
    }
}

/// `errors.png`, `cost_history.png` and the field figure of each measurement (`fields.png`,
/// or `fields_NAME.png` for a `measurement_list`) of the best start of the first repeat.
fn write_result_figures(
    measurement_list: bool,
    models: &TestModels,
    fit: &JointFit,
    parameters: &[Estimate],
    reference_known: bool,
    speckle: Option<(SpeckleShift, f64)>,
    out: &Path,
) -> Result<()> {
    let c = &fit.campaign;
    let best = &c.best[0];
    write_figures(out, parameters, best, reference_known, c.best.len())?;
    for (b, block) in c.blocks.iter().enumerate() {
        for seg in &block.segments {
            let name = if measurement_list {
                format!("fields_{}.png", seg.name)
            } else {
                "fields.png".to_string()
            };
            let field = MeasuredField {
                points: block.first_field.points[seg.points.clone()].to_vec(),
                comments: Vec::new(),
            };
            let (bfree, map) = block_free(&fit.free, &models.full[0], &models.full[b]);
            let btheta: Vec<f64> = map.iter().map(|&k| best.theta[k]).collect();
            // The measured field's speckle shift (the single measurement's block) at its scale.
            let shift = speckle.filter(|_| b == 0).map(|(s, kappa)| SpeckleShift {
                scale: ShiftScale::Fixed(kappa),
                ..s
            });
            write_field_figures(out, &name, &models.full[b], bfree, &btheta, &field, shift)?;
        }
    }
    Ok(())
}

/// Each measurement (and actuator term) with its points and its share of the information.
fn measurement_summaries(prepared: &[Prepared], fit: &JointFit) -> Vec<MeasurementSummary> {
    let names: Vec<String> = fit.free.iter().map(|f| f.name.clone()).collect();
    let shares = information_shares(&fit.campaign.best[0].jacobian, &fit.campaign.layout, &names);
    let segments: Vec<&campaign::SegmentRecord> = fit
        .campaign
        .blocks
        .iter()
        .flat_map(|b| b.segments.iter())
        .collect();
    shares
        .into_iter()
        .map(|information| {
            let p = prepared.iter().find(|p| p.name == information.measurement);
            let seg = segments.iter().find(|s| s.name == information.measurement);
            MeasurementSummary {
                name: information.measurement.clone(),
                label: p.map_or_else(
                    || format!("{} (actuator term)", information.measurement),
                    |p| p.label.clone(),
                ),
                source: p.map_or("the rigid body's measured travel".into(), |p| p.source()),
                sigma_mm: p.and_then(|p| match p.data {
                    PreparedData::Virtual { sigma, .. } => Some(sigma),
                    PreparedData::Measured(_) => None,
                }),
                points_in_tissue: seg.map_or(0, |s| s.points_in_tissue),
                points_masked: match p.map(|p| &p.data) {
                    Some(PreparedData::Virtual { points, total, .. }) => total - points.len(),
                    _ => seg.map_or(0, |s| s.points_masked),
                },
                information,
            }
        })
        .collect()
}

/// The identified parameters in the console, in the units of the seed's Table 1 (C10 kPa, D
/// MPa⁻¹), their coverage over repeats, then the warnings.
fn print_table(summary: &IdentificationSummary, progress: &dyn Progress) {
    progress.note(&format!(
        "{:<36} {:>7} {:>12} {:>12} {:>10} {:>10}",
        "parameter", "unit", "reference", "identified", "error", "sd"
    ));
    for (p, f) in summary.parameters.iter().zip(&summary.free_parameters) {
        progress.note(&format!(
            "{:<36} {:>7} {:>12} {:>12.5} {:>10} {:>9.2}%",
            p.name,
            f.unit,
            p.reference
                .map_or("-".into(), |v| format!("{:.5}", f.shown(v))),
            f.shown(p.identified),
            p.relative_error
                .map_or("-".into(), |e| format!("{:.3}%", 100.0 * e)),
            100.0 * p.relative_sd
        ));
    }
    if summary.repeats > 1 {
        for p in &summary.parameters {
            if let (Some(worst), Some(cov)) = (p.max_relative_error, p.coverage95) {
                progress.note(&format!(
                    "  {:<34} over {} repeats: worst error {:.2} %, 95 % interval coverage {:.0} %",
                    p.name,
                    summary.repeats,
                    100.0 * worst,
                    100.0 * cov
                ));
            }
        }
    }
    for w in &summary.warnings {
        progress.warn(&format!("identification: {w}"));
    }
}

/// `measurements.csv`: per measurement, its points and, per free parameter, its share of the
/// information and the relative sd it would give alone.
fn write_measurements_csv(
    path: &Path,
    free: &[FreeParameter],
    measurements: &[MeasurementSummary],
) -> Result<()> {
    let mut w = crate::output::create_file(path)?;
    write!(w, "name,label,points_in_tissue,points_masked,sigma_mm")?;
    for f in free {
        write!(w, ",share_{}", f.name)?;
    }
    for f in free {
        write!(w, ",alone_sd_{}", f.name)?;
    }
    writeln!(w)?;
    for m in measurements {
        write!(
            w,
            "{},\"{}\",{},{},{}",
            m.name,
            m.label.replace('"', "'"),
            m.points_in_tissue,
            m.points_masked,
            m.sigma_mm.map_or(String::new(), |s| format!("{s:e}"))
        )?;
        for v in m
            .information
            .share
            .iter()
            .chain(&m.information.alone_relative_sd)
        {
            write!(w, ",{v:.6e}")?;
        }
        writeln!(w)?;
    }
    crate::output::commit(w)
}

fn write_starts_csv(path: &Path, free: &[FreeParameter], starts: &[StartRecord]) -> Result<()> {
    let mut w = crate::output::create_file(path)?;
    write!(
        w,
        "repeat,start,cost,iterations,forward_solves,converged,error"
    )?;
    for f in free {
        write!(w, ",{}", f.name)?;
    }
    writeln!(w)?;
    for s in starts {
        match &s.result {
            Some(r) => {
                write!(
                    w,
                    "{},{},{:.9e},{},{},{},",
                    s.repeat, s.start, r.cost, r.iterations, r.forward_solves, r.converged
                )?;
                for t in &r.theta {
                    write!(w, ",{t:.9e}")?;
                }
            }
            None => {
                write!(
                    w,
                    "{},{},,,,false,\"{}\"",
                    s.repeat,
                    s.start,
                    s.error.clone().unwrap_or_default().replace('"', "'")
                )?;
                for _ in free {
                    write!(w, ",")?;
                }
            }
        }
        writeln!(w)?;
    }
    crate::output::commit(w)
}

fn write_parameters_csv(path: &Path, params: &[Estimate]) -> Result<()> {
    let mut w = crate::output::create_file(path)?;
    writeln!(
        w,
        "name,reference,identified,relative_error,relative_sd,ci95_low,ci95_high,mean_relative_error,sd_relative_error"
    )?;
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.6e}"));
    for p in params {
        writeln!(
            w,
            "{},{},{:.9e},{},{:.6e},{:.9e},{:.9e},{},{}",
            p.name,
            opt(p.reference),
            p.identified,
            opt(p.relative_error),
            p.relative_sd,
            p.ci95[0],
            p.ci95[1],
            opt(p.mean_relative_error),
            opt(p.sd_relative_error)
        )?;
    }
    crate::output::commit(w)
}

/// `errors.png` (Eq. 4 per parameter, mean ± sd over the repeats: the seed's Fig. 9) for a
/// virtual experiment, and `cost_history.png` of the best start.
fn write_figures(
    out: &Path,
    params: &[Estimate],
    best: &FitResult,
    virtual_experiment: bool,
    repeats: usize,
) -> Result<()> {
    if virtual_experiment {
        let names: Vec<String> = params.iter().map(|p| p.name.clone()).collect();
        let values: Vec<f64> = params
            .iter()
            .map(|p| {
                100.0
                    * p.mean_relative_error
                        .or(p.relative_error)
                        .unwrap_or(f64::NAN)
            })
            .collect();
        let bars: Option<Vec<Vec<f64>>> = (repeats > 1).then(|| {
            vec![params
                .iter()
                .map(|p| 100.0 * p.sd_relative_error.unwrap_or(0.0))
                .collect()]
        });
        bar_chart_png(
            &out.join("errors.png"),
            &names,
            &[(
                if repeats > 1 {
                    format!("mean over {repeats} noise realizations (± sd)")
                } else {
                    "identified vs reference".into()
                },
                values,
            )],
            bars.as_deref(),
            &BarChart {
                title: "Identification error (seed Eq. 4, Fig. 9)".into(),
                x_label: "parameter".into(),
                y_label: "relative error (%)".into(),
                ..Default::default()
            },
        )?;
    }
    let accepted: Vec<(f64, f64)> = best
        .history
        .iter()
        .filter(|h| h.accepted && h.cost > 0.0)
        .map(|h| (h.iteration as f64, h.cost))
        .collect();
    if accepted.len() >= 2 {
        line_plot_png(
            &out.join("cost_history.png"),
            &[Series::new(
                "best start",
                accepted,
                LineStyle::LineAndMarkers,
            )],
            &LinePlot {
                title: "Levenberg–Marquardt: cost of the accepted steps".into(),
                x_label: "iteration".into(),
                y_label: "cost ½|r|² (mm²)".into(),
                log_y: true,
                ..Default::default()
            },
        )?;
    }
    Ok(())
}

/// `fields.png`: measured and model ux, uy at the measured points and their difference (one
/// panel each), when the points lie on a regular grid (as written by `synth` and `dic`).
fn write_field_figures(
    out: &Path,
    name: &str,
    model: &Model,
    bfree: Vec<FreeParameter>,
    btheta: &[f64],
    field: &MeasuredField,
    speckle: Option<SpeckleShift>,
) -> Result<()> {
    let locator = PointLocator::new(&model.mesh);
    let inside: Vec<&MeasuredPoint> = field
        .points
        .iter()
        .filter(|p| locator.locate(p.x).is_some())
        .collect();
    if inside.is_empty() {
        return Ok(());
    }
    let mut p = Problem::new(model.clone(), SolverOptions::default(), field, bfree)?;
    if let Some(s) = speckle {
        p = p.with_speckle_shift(s)?;
    }
    let u = p.field_at(btheta)?;
    // The grid: distinct x and y values.
    let distinct = |k: usize| {
        let mut v: Vec<f64> = inside.iter().map(|p| p.x[k]).collect();
        v.sort_by(f64::total_cmp);
        v.dedup_by(|a, b| (*a - *b).abs() < 1e-9 * (1.0 + b.abs()));
        v
    };
    let (xs, ys) = (distinct(0), distinct(1));
    let (nx, ny) = (xs.len(), ys.len());
    if nx < 2 || ny < 2 || nx * ny > 1_000_000 || nx * ny < inside.len() {
        return Ok(()); // not a grid: no picture
    }
    let index = |v: f64, axis: &[f64]| {
        axis.binary_search_by(|a| a.total_cmp(&v))
            .or_else(|i| {
                let near =
                    |j: usize| j < axis.len() && (axis[j] - v).abs() < 1e-9 * (1.0 + v.abs());
                if near(i) {
                    Ok(i)
                } else if i > 0 && near(i - 1) {
                    Ok(i - 1)
                } else {
                    Err(())
                }
            })
            .ok()
    };
    let mut images = vec![vec![f64::NAN; nx * ny]; 6];
    for (k, pt) in inside.iter().enumerate() {
        let (Some(i), Some(j)) = (index(pt.x[0], &xs), index(pt.x[1], &ys)) else {
            return Ok(());
        };
        let pix = (ny - 1 - j) * nx + i; // image rows go down, y goes up
        let m = [u[2 * k], u[2 * k + 1]];
        for c in 0..2 {
            images[3 * c][pix] = pt.u[c];
            images[3 * c + 1][pix] = m[c];
            images[3 * c + 2][pix] = m[c] - pt.u[c];
        }
    }
    let model_label = if speckle.is_some() {
        "model (identified, with the speckle shift)"
    } else {
        "model (identified)"
    };
    write_field_panels(out, name, (nx, ny), xs[1] - xs[0], &images, model_label)
}

/// The six panels of a field figure (measured, model as `model_label` says, difference; ux
/// then uy) on an `nx x ny` grid `spacing` mm apart, written into `out/panels/` and tiled into
/// `out/name`.
fn write_field_panels(
    out: &Path,
    name: &str,
    (nx, ny): (usize, usize),
    spacing: f64,
    images: &[Vec<f64>],
    model_label: &str,
) -> Result<()> {
    let grey = vec![255.0; nx * ny];
    let panels_dir = out.join("panels");
    femu_mesh::atomic::create_dir_all(&panels_dir)?;
    let mut paths = Vec::new();
    for c in 0..2 {
        let comp = ["ux", "uy"][c];
        let lo_hi = images[3 * c]
            .iter()
            .chain(&images[3 * c + 1])
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        for (k, what) in ["measured", model_label, "model - measured"]
            .iter()
            .enumerate()
        {
            let path = panels_dir.join(format!("{}_{comp}_{k}.png", name.trim_end_matches(".png")));
            femu_plot::image_field_png(
                &path,
                &grey,
                nx,
                ny,
                &images[3 * c + k],
                &femu_plot::ImageField {
                    title: format!(
                        "{what} {comp} ({nx} x {ny} grid, {spacing:.3} mm apart; anterior up)"
                    ),
                    value_label: format!("{comp} (mm)"),
                    diverging: k == 2,
                    range: (k < 2 && lo_hi.0 < lo_hi.1).then_some(lo_hi),
                    alpha: 1.0,
                    width: 700,
                    height: 560,
                    ..Default::default()
                },
            )?;
            paths.push(path);
        }
    }
    let refs: Vec<&Path> = paths.iter().map(|p| p.as_path()).collect();
    femu_plot::tile_png(&out.join(name), &refs, 3)?;
    Ok(())
}
