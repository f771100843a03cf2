//! The identification step (`femu identify`, `femu synth`, and the last step of `femu run`):
//! FEMU of the study's free parameters from the measured field (seed §2.1.3, Eq. 2; Fig. 9),
//! computed by `femu_identify::campaign`, written as
//!
//! - `parameters.csv` — identified values, Eq. 4 errors, relative sd, 95 % intervals;
//! - `starts.csv` — every start of every repeat;
//! - `errors.png` (Fig. 9 with error bars), `cost_history.png`, `fields.png`;
//! - `summary.json` — [`IdentificationSummary`].

use crate::output::{create_dir, write_json};
use crate::progress::Progress;
use crate::schema::{MeasurementSource, Study};
use anyhow::{Context, Result};
use femu_identify::campaign::{
    self, Campaign, CampaignOptions, Data, Estimate, Event, StartRecord, TravelTerm,
};
use femu_identify::fit::{FitResult, FreeParameter, Problem};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
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
    /// Set when the user stopped the run: what was kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interrupted: Option<String>,
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
}

impl From<&FreeParameter> for FreeParameterSummary {
    fn from(f: &FreeParameter) -> Self {
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
        }
    }
}

/// The measured field of an identification and where it came from.
#[derive(Debug, Clone)]
pub struct Measured {
    pub field: MeasuredField,
    pub source: String,
    /// Whether the reference parameters of the model are the truth (a simulated experiment).
    pub reference_known: bool,
}

/// The study's model loaded with its identification test, and the test's name.
pub fn measured_model(study: &Study) -> Result<(Model, String)> {
    let built = crate::model::build(&study.model)?;
    let test = study.identification_test().loading.clone();
    Ok((built.loaded(&test)?, test.name()))
}

/// The free parameters of `study` on `model` (its groups tied when `grouped`).
pub fn free_parameters(
    study: &Study,
    model: &Model,
    grouped: bool,
) -> Result<(Vec<FreeParameter>, Vec<f64>)> {
    let groups = if grouped {
        study.groups.clone()
    } else {
        Vec::new()
    };
    campaign::free_parameters(
        model,
        &groups,
        &study.identification.fixed,
        study.identification.bounds_factor,
    )
    .map_err(|e| match e {
        campaign::CampaignError::UnknownParameter { .. }
        | campaign::CampaignError::PartlyFixed(_)
        | campaign::CampaignError::NothingFree => {
            anyhow::anyhow!("[identification] fixed: {e}")
        }
        e => e.into(),
    })
}

/// The grid of the study over `model`, the points in the tissue, and the grid's size.
fn grid_in_tissue(study: &Study, model: &Model) -> (Vec<[f64; 2]>, usize) {
    let (lo, hi) = model.mesh.bounding_box();
    let grid = study.measurement.grid.points(lo, hi);
    (campaign::points_in_tissue(model, &grid), grid.len())
}

/// The virtual experiment's first noise realization of `model` (loaded with the identification
/// test), with its comments.
pub fn virtual_measurement(study: &Study, model: &Model) -> Result<MeasuredField> {
    let (free, reference) = free_parameters(study, model, study.identification.grouped())?;
    let (inside, total) = grid_in_tissue(study, model);
    let sigma = study.measurement.sigma_mm;
    let mut field = campaign::virtual_field(
        model,
        &free,
        &reference,
        &inside,
        sigma,
        study.identification.seed,
    )?;
    let [nx, ny] = study.measurement.grid.counts;
    field.comments = vec![
        "femu synth: virtual experiment (seed 2.4.1)".into(),
        format!("noise sigma {sigma} mm, seed {}", study.identification.seed),
        format!(
            "grid {nx} x {ny} over the thigh, {} of {total} points in the tissue",
            inside.len(),
        ),
    ];
    Ok(field)
}

/// Writes the virtual experiment's first noise realization to `path` (`femu synth`).
pub fn write_virtual_measurement(
    study: &Study,
    model: &Model,
    test: &str,
    path: &Path,
    progress: &dyn Progress,
) -> Result<()> {
    let field = virtual_measurement(study, model)?;
    field
        .write(path, Some(study.measurement.sigma_mm))
        .with_context(|| format!("cannot write {}", path.display()))?;
    progress.note(&format!(
        "{test}: virtual experiment, {} measured points in the tissue, noise {} mm -> {}",
        field.points.len(),
        study.measurement.sigma_mm,
        path.display()
    ));
    Ok(())
}

/// `femu synth`: the study's identification test on its model, the virtual measurement
/// written to `out/measured.csv`.
pub fn synth(study: &Study, out: &Path, progress: &dyn Progress) -> Result<()> {
    create_dir(out)?;
    let (model, test) = measured_model(study)?;
    write_virtual_measurement(study, &model, &test, &out.join("measured.csv"), progress)
}

/// The measured field of the study's `[measurement]`: `None` for the virtual experiment, else
/// the file mapped to the model frame.
pub fn study_measurement(study: &Study) -> Result<Option<Measured>> {
    match &study.measurement.source {
        MeasurementSource::Virtual => Ok(None),
        MeasurementSource::Ultrasound => anyhow::bail!(
            "[measurement] source = \"ultrasound\": simulate the images with `femu us-sim` and pass its measured.csv with --measured, or run the whole study with `femu run`"
        ),
        MeasurementSource::File { path, frame } => {
            let f = MeasuredField::read(path)?;
            Ok(Some(Measured {
                field: f.to_model_frame(frame.scale, frame.origin, frame.x_axis, frame.y_axis),
                source: path.display().to_string(),
                reference_known: false,
            }))
        }
    }
}

/// `femu identify`: the study's identification (grouped unless `grouped = false`) from
/// `measured` (a CSV in the model frame), the study's `[measurement]`, or the virtual
/// experiment.
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
            let kept: &[&str] = match e.downcast_ref::<Stopped>() {
                Some(Stopped::RepeatsKept(_)) => return result,
                Some(Stopped::BeforeARepeat(_)) => &["starts.csv"],
                None => &[],
            };
            crate::output::write_stopped(
                out,
                "identify",
                &format!("{e:#}"),
                kept,
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
    let measured = match measured {
        Some(p) => Some(Measured {
            field: MeasuredField::read(p)?,
            source: p.display().to_string(),
            reference_known: false,
        }),
        None => study_measurement(study)?,
    };
    let (model, test) = measured_model(study)?;
    let grouped = study.identification.grouped();
    identify_on(
        study,
        grouped,
        &model,
        &test,
        measured.as_ref(),
        out,
        progress,
    )
}

/// The multilevel identification's coarse model: the built-in thigh with
/// `[identification] coarse_elements`, loaded with the identification test.
fn coarse_model(study: &Study) -> Result<Option<Model>> {
    let Some(n) = study.identification.coarse_elements else {
        return Ok(None);
    };
    let mut cs = study.clone();
    cs.model.resolution = crate::schema::Resolution::Elements(n);
    let (m, _) = measured_model(&cs).context("[identification] coarse_elements")?;
    Ok(Some(m))
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

/// The identification of `study` (groups tied when `grouped`) on `model` (loaded with the
/// measured test `test`) from `measured` (`None`: the virtual experiment, `[identification]
/// repeat` noise realizations); writes `out`.
pub fn identify_on(
    study: &Study,
    grouped: bool,
    model: &Model,
    test: &str,
    measured: Option<&Measured>,
    out: &Path,
    progress: &dyn Progress,
) -> Result<IdentificationSummary> {
    let t0 = Instant::now();
    create_dir(out)?;
    let spec = &study.identification;
    let (free, reference) = free_parameters(study, model, grouped)?;
    let virtual_experiment = measured.is_none();
    let reference_known = measured.is_none_or(|m| m.reference_known);
    let repeats = if virtual_experiment { spec.repeat } else { 1 };
    progress.note(&format!(
        "identify ({}): {test}, {} elements, {} free parameters, {} starts x {} noise realizations",
        spec.optimizer.name(),
        model.mesh.elements.len(),
        free.len(),
        spec.starts,
        repeats
    ));
    let coarse = coarse_model(study)?;
    if let Some(c) = &coarse {
        progress.note(&format!(
            "multilevel: starts on {} elements, the best refined on {}",
            c.mesh.elements.len(),
            model.mesh.elements.len()
        ));
    }
    let (inside, grid_total) = grid_in_tissue(study, model);
    let data = match measured {
        Some(m) => Data::Measured(&m.field),
        None => Data::Virtual {
            points: &inside,
            sigma: study.measurement.sigma_mm,
        },
    };
    let options = CampaignOptions {
        optimizer: spec.optimizer,
        starts: spec.starts,
        seed: spec.seed,
        repeats,
        travel: study.measurement.travel.map(|t| TravelTerm {
            measured_mm: t.measured_mm,
            sigma_mm: t.sigma_mm,
        }),
        stop: progress.stop_flag(),
    };
    let on_event = show_events(progress, repeats);
    let result = campaign::run(
        model,
        coarse.as_ref(),
        &free,
        &reference,
        data,
        &options,
        &on_event,
    );
    let (c, interrupted): (Campaign, Option<usize>) = match result {
        Ok(c) => (c, None),
        Err(campaign::CampaignError::Interrupted { finished, repeats }) => {
            if finished.best.is_empty() {
                write_starts_csv(&out.join("starts.csv"), &free, &finished.starts)?;
                return Err(anyhow::Error::new(crate::progress::Interrupted).context(
                    Stopped::BeforeARepeat(format!(
                        "identification: no repeat finished ({} finished starts in {})",
                        finished.starts.len(),
                        out.join("starts.csv").display()
                    )),
                ));
            }
            (*finished, Some(repeats))
        }
        Err(campaign::CampaignError::AllStartsFailed {
            repeat,
            reasons,
            starts,
        }) => {
            // What finished is kept: every start's outcome.
            write_starts_csv(&out.join("starts.csv"), &free, &starts)?;
            return Err(
                anyhow::Error::new(campaign::CampaignError::AllStartsFailed {
                    repeat,
                    reasons,
                    starts,
                })
                .context(format!(
                    "identification (every start in {})",
                    out.join("starts.csv").display()
                )),
            );
        }
        Err(e) => return Err(e.into()),
    };
    write_starts_csv(&out.join("starts.csv"), &free, &c.starts)?;
    let (parameters, id) =
        campaign::estimates(&c, &free, &reference, reference_known, virtual_experiment)?;
    let repeats = c.best.len();
    let best = &c.best[0];
    write_parameters_csv(&out.join("parameters.csv"), &parameters)?;
    // What finished is written even after a stop (the field figure needs one more solve).
    femu_mesh::stop::shielded(|| {
        write_figures(out, &parameters, best, reference_known, repeats)?;
        write_field_figures(out, model, &free, &c.first_field, &best.theta)
    })?;
    let points_masked = if virtual_experiment {
        // The virtual field holds only the grid points in the tissue; the rest are masked.
        grid_total - c.points_in_tissue
    } else {
        c.points_masked
    };
    let summary = IdentificationSummary {
        command: "identify".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        test: test.to_string(),
        optimizer: spec.optimizer.name().into(),
        grouped,
        elements: model.mesh.elements.len(),
        measured: match measured {
            Some(m) => m.source.clone(),
            None => "virtual experiment (femu synth)".into(),
        },
        points_in_tissue: c.points_in_tissue,
        points_masked,
        noise_sigma_mm: study.measurement.sigma_mm,
        free_parameters: free.iter().map(FreeParameterSummary::from).collect(),
        parameters,
        correlation: id.correlation,
        best_cost: best.cost,
        starts_per_repeat: spec.starts,
        repeats,
        travel_term: study
            .measurement
            .travel
            .map(|t| (c.reference_travel, t.sigma_mm)),
        coarse_elements: coarse.as_ref().map(|m| m.mesh.elements.len()),
        refinement_forward_solves: c.refinement_forward_solves.clone(),
        forward_solves_per_start: c
            .starts
            .iter()
            .filter_map(|s| s.result.as_ref().map(|r| r.forward_solves))
            .collect(),
        starts: c.starts.clone(),
        wall_time_s: t0.elapsed().as_secs_f64(),
        interrupted: interrupted
            .map(|n| format!("interrupted: {repeats} of {n} repeats finished and kept")),
    };
    write_json(&out.join("summary.json"), &summary)?;
    progress.note(&format!(
        "{:<36} {:>12} {:>12} {:>10} {:>10}",
        "parameter", "reference", "identified", "error", "sd"
    ));
    for p in &summary.parameters {
        progress.note(&format!(
            "{:<36} {:>12} {:>12.5e} {:>10} {:>9.2}%",
            p.name,
            p.reference.map_or("-".into(), |v| format!("{v:.5e}")),
            p.identified,
            p.relative_error
                .map_or("-".into(), |e| format!("{:.3}%", 100.0 * e)),
            100.0 * p.relative_sd
        ));
    }
    progress.note(&format!(
        "wrote {} ({:.1} s)",
        out.display(),
        summary.wall_time_s
    ));
    if let Some(note) = &summary.interrupted {
        return Err(anyhow::Error::new(crate::progress::Interrupted).context(
            Stopped::RepeatsKept(format!("identification: {note} in {}", out.display())),
        ));
    }
    Ok(summary)
}

/// How an identification stopped by the user ended (the context of its error).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
enum Stopped {
    /// Before a repeat finished: `starts.csv` holds the starts that finished.
    #[error("{0}")]
    BeforeARepeat(String),
    /// After some repeats: their results are written (summary.json says so).
    #[error("{0}")]
    RepeatsKept(String),
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
    model: &Model,
    free: &[FreeParameter],
    field: &MeasuredField,
    theta: &[f64],
) -> Result<()> {
    let locator = PointLocator::new(&model.mesh);
    let inside: Vec<&MeasuredPoint> = field
        .points
        .iter()
        .filter(|p| locator.locate(p.x).is_some())
        .collect();
    let mut p = Problem::new(
        model.clone(),
        SolverOptions::default(),
        field,
        free.to_vec(),
    )?;
    let u = p.field_at(theta)?;
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
    let spacing = xs[1] - xs[0];
    let grey = vec![255.0; nx * ny];
    let panels_dir = out.join("panels");
    std::fs::create_dir_all(&panels_dir)?;
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
        for (k, what) in ["measured", "model (identified)", "model - measured"]
            .iter()
            .enumerate()
        {
            let path = panels_dir.join(format!("field_{comp}_{k}.png"));
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
    femu_plot::tile_png(&out.join("fields.png"), &refs, 3)?;
    Ok(())
}
