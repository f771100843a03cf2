//! `femu synth STUDY --out DIR` (the virtual experiment, seed §2.4.1) and
//! `femu identify STUDY --out DIR [--measured CSV]` (FEMU, seed §2.1.3 and Fig. 9).

use crate::plan::{self, MeasurementPlan, Optimizer, Plan};
use crate::sensitivity_cmd::thigh_model;
use anyhow::{bail, Context, Result};
use femu_identify::fisher::{self, Tied};
use femu_identify::fit::{
    bfgs, latin_hypercube, levenberg_marquardt, FitResult, FreeParameter, Gradient, LmOptions,
    Problem,
};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_mech::loading::apply_loading;
use femu_mech::sensitivity::all_parameters;
use femu_mech::{Model, SolverOptions};
use femu_mesh::locate::PointLocator;
use femu_plot::{bar_chart_png, line_plot_png, BarChart, LinePlot, LineStyle, Series};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options shared by `synth` and `identify`.
#[derive(Debug, Clone)]
pub struct IdentifyArgs {
    pub study: Option<PathBuf>,
    pub out: PathBuf,
    pub measured: Option<PathBuf>,
    pub elements: Option<usize>,
    pub repeat: Option<usize>,
    pub starts: Option<usize>,
}

/// The study's model with the identification test applied, and the measured test's name.
pub fn measured_model(plan: &Plan) -> Result<(Model, String)> {
    let (mut model, skin) = thigh_model(plan)?;
    let test = plan.tests[plan.identification.test];
    apply_loading(&mut model, &skin, &test).with_context(|| format!("test {}", test.name()))?;
    Ok((model, test.name()))
}

fn read_plan(args: &IdentifyArgs) -> Result<Plan> {
    let mut plan = plan::load(args.study.as_deref(), args.elements)?;
    if let Some(r) = args.repeat {
        if r == 0 {
            bail!("--repeat must be at least 1");
        }
        plan.identification.repeat = r;
    }
    if let Some(s) = args.starts {
        if s == 0 {
            bail!("--starts must be at least 1");
        }
        plan.identification.starts = s;
    }
    Ok(plan)
}

/// The free parameters: Table 1 (or the study's) values as references, groups tied, fixed ones
/// left out; bounds a factor either side of the reference.
pub fn free_parameters(plan: &Plan, model: &Model) -> Result<(Vec<FreeParameter>, Vec<f64>)> {
    let params = all_parameters(model);
    let names: Vec<String> = params.iter().map(|p| p.name(model)).collect();
    for f in &plan.identification.fixed {
        if !names.iter().any(|n| n.eq_ignore_ascii_case(f)) {
            bail!(
                "[identification] fixed: unknown parameter '{f}' (parameters: {})",
                names.join(", ")
            );
        }
    }
    let groups = if plan.identification.grouped {
        plan.groups.clone()
    } else {
        Vec::new()
    };
    let tied = Tied::new(&names, &groups).context("[parameters] groups")?;
    let is_fixed = |k: usize| {
        plan.identification
            .fixed
            .iter()
            .any(|f| f.eq_ignore_ascii_case(&names[k]))
    };
    let mut free = Vec::new();
    let mut reference = Vec::new();
    for (name, members) in tied.names.iter().zip(&tied.members) {
        let fixed = members.iter().filter(|&&k| is_fixed(k)).count();
        if fixed > 0 && fixed < members.len() {
            bail!("[identification] fixed: part of the group {name} is fixed; fix all or none");
        }
        if fixed > 0 {
            continue;
        }
        let v = params[members[0]].value(model);
        let f = plan.identification.bounds_factor;
        free.push(FreeParameter {
            name: name.clone(),
            members: members.iter().map(|&k| params[k]).collect(),
            lower: v / f,
            upper: v * f,
        });
        reference.push(v);
    }
    if free.is_empty() {
        bail!("[identification]: every parameter is fixed, nothing to identify");
    }
    Ok((free, reference))
}

/// The virtual measurement: the model field at the grid points in the tissue for the reference
/// parameters, plus seeded Gaussian white noise of `sigma` (seed §2.4.1).
pub fn virtual_field(
    plan: &Plan,
    model: &Model,
    free: &[FreeParameter],
    reference: &[f64],
    seed: u64,
) -> Result<MeasuredField> {
    let (lo, hi) = model.mesh.bounding_box();
    let grid = plan.grid.points(lo, hi);
    let locator = PointLocator::new(&model.mesh);
    let inside: Vec<[f64; 2]> = grid
        .iter()
        .copied()
        .filter(|x| locator.locate(*x).is_some())
        .collect();
    if inside.is_empty() {
        bail!("no grid point lies in the tissue: check [grid]");
    }
    let all = MeasuredField {
        points: inside
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
    let noise = Normal::new(0.0, plan.sigma_mm).context("noise sigma")?;
    Ok(MeasuredField {
        points: inside
            .iter()
            .enumerate()
            .map(|(k, &x)| MeasuredPoint {
                x,
                u: [
                    u[2 * k] + noise.sample(&mut rng),
                    u[2 * k + 1] + noise.sample(&mut rng),
                ],
                weight: [1.0 / (plan.sigma_mm * plan.sigma_mm); 2],
            })
            .collect(),
        comments: vec![
            "femu synth: virtual experiment (seed 2.4.1)".into(),
            format!("noise sigma {} mm, seed {seed}", plan.sigma_mm),
            format!(
                "grid {} x {} over the thigh, {} of {} points in the tissue",
                plan.grid.counts[0],
                plan.grid.counts[1],
                inside.len(),
                grid.len()
            ),
        ],
    })
}

/// `femu synth`.
pub fn synth(args: &IdentifyArgs, quiet: bool) -> Result<()> {
    let plan = read_plan(args)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder {}", args.out.display()))?;
    let (model, test) = measured_model(&plan)?;
    write_virtual_measurement(&plan, &model, &test, &args.out.join("measured.csv"), quiet)
}

/// The virtual experiment's first noise realization of `model` (loaded with the test `test`)
/// written to `path` as the measured-field CSV.
pub fn write_virtual_measurement(
    plan: &Plan,
    model: &Model,
    test: &str,
    path: &Path,
    quiet: bool,
) -> Result<()> {
    let (free, reference) = free_parameters(plan, model)?;
    let field = virtual_field(plan, model, &free, &reference, plan.identification.seed)?;
    field
        .write(path, Some(plan.sigma_mm))
        .with_context(|| format!("cannot write {}", path.display()))?;
    if !quiet {
        eprintln!(
            "{test}: virtual experiment, {} measured points in the tissue, noise {} mm -> {}",
            field.points.len(),
            plan.sigma_mm,
            path.display()
        );
    }
    Ok(())
}

#[derive(Serialize)]
struct StartSummary {
    repeat: usize,
    start: usize,
    theta_start: Vec<f64>,
    result: Option<FitResult>,
    error: Option<String>,
}

#[derive(Serialize)]
struct ParameterSummary {
    name: String,
    reference: Option<f64>,
    identified: f64,
    /// Eq. 4 (best start of the first repeat).
    relative_error: Option<f64>,
    /// Relative standard deviation from the Jacobian at the optimum.
    relative_sd: f64,
    ci95: [f64; 2],
    /// Over the repeats: mean and standard deviation of Eq. 4 and of the identified value.
    mean_relative_error: Option<f64>,
    sd_relative_error: Option<f64>,
    sd_identified_relative: Option<f64>,
}

#[derive(Serialize)]
struct Summary {
    command: &'static str,
    version: &'static str,
    test: String,
    optimizer: &'static str,
    grouped: bool,
    elements: usize,
    measured: String,
    points_in_tissue: usize,
    points_masked: usize,
    noise_sigma_mm: f64,
    free_parameters: Vec<FreeParameter>,
    parameters: Vec<ParameterSummary>,
    correlation: Vec<Vec<f64>>,
    best_cost: f64,
    starts_per_repeat: usize,
    repeats: usize,
    /// The actuator term: (measured or reference travel mm, its sigma mm).
    travel_term: Option<(Option<f64>, f64)>,
    /// Multilevel: elements of the coarse model the starts ran on.
    coarse_elements: Option<usize>,
    /// Multilevel: forward solves of the refinement on the full model, per repeat.
    refinement_forward_solves: Vec<usize>,
    forward_solves_per_start: Vec<usize>,
    starts: Vec<StartSummary>,
    wall_time_s: f64,
}

/// The measured field of the study's `[measurement]`: `None` for the virtual experiment, else
/// the file mapped to the model frame and a description of its source.
pub fn study_measurement(plan: &Plan) -> Result<Option<(MeasuredField, String)>> {
    match &plan.measurement {
        MeasurementPlan::Virtual => Ok(None),
        MeasurementPlan::Ultrasound => bail!(
            "[measurement] source = \"ultrasound\": simulate the images with `femu us-sim` and pass its measured.csv with --measured, or run the whole study with `femu run`"
        ),
        MeasurementPlan::File { path, frame } => {
            let f = MeasuredField::read(path)?;
            Ok(Some((
                f.to_model_frame(frame.scale, frame.origin, frame.x_axis, frame.y_axis),
                path.display().to_string(),
            )))
        }
    }
}

/// `femu identify`.
pub fn identify(args: &IdentifyArgs, quiet: bool) -> Result<()> {
    let plan = read_plan(args)?;
    let measured = match &args.measured {
        Some(p) => Some((MeasuredField::read(p)?, p.display().to_string())),
        None => study_measurement(&plan)?,
    };
    let (model, test) = measured_model(&plan)?;
    identify_plan(&plan, &model, &test, measured, &args.out, quiet)
}

/// One start of the study's optimizer; `coarse`: the first level of a multilevel
/// identification, where an approximate optimum is enough (20 iterations, 1e-6 relative cost).
fn fit_start(plan: &Plan, p: &mut Problem, start: &[f64], coarse: bool) -> Result<FitResult> {
    let lm = if coarse {
        LmOptions {
            max_iterations: 20,
            cost_tolerance: 1e-6,
            ..LmOptions::default()
        }
    } else {
        LmOptions::default()
    };
    Ok(match plan.identification.optimizer {
        Optimizer::LevenbergMarquardt => levenberg_marquardt(p, start, &lm)?,
        Optimizer::Bfgs => bfgs(p, start, Gradient::Exact, &lm, 200)?,
        Optimizer::BfgsFiniteDifference => {
            bfgs(p, start, Gradient::FiniteDifference(5e-4), &lm, 200)?
        }
    })
}

/// The identification of `plan` on `model` (loaded with the measured test `test`) from
/// `measured` (`None`: the virtual experiment, `[identification] repeat` noise realizations);
/// writes `out`.
pub fn identify_plan(
    plan: &Plan,
    model: &Model,
    test: &str,
    measured: Option<(MeasuredField, String)>,
    out: &Path,
    quiet: bool,
) -> Result<()> {
    let t0 = Instant::now();
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output folder {}", out.display()))?;
    let (free, reference) = free_parameters(plan, model)?;
    let virtual_experiment = measured.is_none();
    // The reference parameters are known for the virtual experiments: noise on the FE field, or
    // the DIC of simulated images (the model carries the reference parameters).
    let reference_known =
        virtual_experiment || matches!(plan.measurement, MeasurementPlan::Ultrasound);
    let repeats = if virtual_experiment {
        plan.identification.repeat
    } else {
        1
    };
    let starts_n = plan.identification.starts;
    if !quiet {
        eprintln!(
            "identify ({}): {test}, {} elements, {} free parameters, {} starts x {} noise realizations",
            plan.identification.optimizer.name(),
            model.mesh.elements.len(),
            free.len(),
            starts_n,
            repeats
        );
    }
    // Multilevel identification (`coarse_elements`): the starts on a coarse model, the best
    // refined on this one.
    let coarse: Option<(Model, usize)> = match plan.identification.coarse_elements {
        None => None,
        Some(n) => {
            let mut cp = plan.clone();
            cp.elements = Some(n);
            cp.size_mm = None;
            let (m, _) = measured_model(&cp).context("[identification] coarse_elements")?;
            if !quiet {
                eprintln!(
                    "multilevel: starts on {} elements, the best refined on {}",
                    m.mesh.elements.len(),
                    model.mesh.elements.len()
                );
            }
            Some((m, n))
        }
    };
    // The actuator term: the measured travel, or for the virtual experiment the reference
    // model's travel (the model carries the reference parameters) plus seeded noise.
    let reference_travel = match plan.travel {
        Some((None, _)) => {
            let mut solver = femu_mech::StaticSolver::new(model, SolverOptions::default())?;
            let sol = solver
                .solve(model)
                .map_err(|e| anyhow::anyhow!("the reference solve for the travel: {e}"))?;
            Some(
                sol.bodies
                    .first()
                    .context("[measurement] travel_sigma_mm: the test has no rigid body")?
                    .travel,
            )
        }
        Some((Some(t), _)) => Some(t),
        None => None,
    };
    // Counts the measured points in the tissue (the problems locate them again for themselves).
    let locator = PointLocator::new(&model.mesh);
    let mut refined: Vec<usize> = Vec::new();
    let mut all_starts = Vec::new();
    let mut best_per_repeat: Vec<FitResult> = Vec::new();
    let mut masked = 0;
    let mut inside = 0;
    let mut first_field: Option<MeasuredField> = None;
    for rep in 0..repeats {
        let field = match &measured {
            Some((f, _)) => f.clone(),
            None => virtual_field(
                plan,
                model,
                &free,
                &reference,
                plan.identification.seed + rep as u64,
            )?,
        };
        let travel: Option<(f64, f64)> = match (plan.travel, reference_travel) {
            (Some((measured_t, sigma)), Some(t)) => {
                let noise = if measured_t.is_none() {
                    let mut rng = rand::rngs::StdRng::seed_from_u64(
                        plan.identification.seed.wrapping_mul(104_729) + rep as u64,
                    );
                    Normal::new(0.0, sigma)
                        .context("travel sigma")?
                        .sample(&mut rng)
                } else {
                    0.0
                };
                Some((t + noise, sigma))
            }
            _ => None,
        };
        let actuator = |p: Problem| -> Result<Problem> {
            Ok(match travel {
                Some((t, sigma)) => p.with_travel(t, sigma)?,
                None => p,
            })
        };
        let starts = latin_hypercube(
            &free,
            starts_n,
            plan.identification.seed.wrapping_mul(7919) + rep as u64,
        );
        let bar = crate::progress::bar(
            starts.len(),
            &format!("identification, repeat {}/{repeats}", rep + 1),
            quiet,
        );
        // The starts run on the coarse model when there is one (multilevel): the same data,
        // the same free parameters, a cheaper forward model.
        let start_model = coarse.as_ref().map_or(model, |(m, _)| m);
        let outcomes: Vec<Result<FitResult>> = starts
            .par_iter()
            .map(|s| {
                let mut p = actuator(Problem::new(
                    start_model.clone(),
                    SolverOptions::default(),
                    &field,
                    free.clone(),
                )?)?;
                let r = fit_start(plan, &mut p, s, coarse.is_some());
                bar.inc(1);
                r
            })
            .collect();
        bar.finish_and_clear();
        inside = field
            .points
            .iter()
            .filter(|p| locator.locate(p.x).is_some())
            .count();
        masked = field.points.len() - inside;
        if virtual_experiment {
            // The virtual field holds only the grid points in the tissue; the rest are masked.
            masked = plan.grid.counts[0] * plan.grid.counts[1] - inside;
        }
        if first_field.is_none() {
            first_field = Some(field.clone());
        }
        let mut best: Option<FitResult> = None;
        for (k, (s, o)) in starts.iter().zip(outcomes).enumerate() {
            match o {
                Ok(r) => {
                    if !quiet {
                        eprintln!(
                            "  repeat {rep}, start {k}: cost {:.4e}, {} iterations, {} forward solves, {:.1} s",
                            r.cost, r.iterations, r.forward_solves, r.wall_time_s
                        );
                    }
                    if best.as_ref().is_none_or(|b| r.cost < b.cost) {
                        best = Some(r.clone());
                    }
                    all_starts.push(StartSummary {
                        repeat: rep,
                        start: k,
                        theta_start: s.clone(),
                        result: Some(r),
                        error: None,
                    });
                }
                Err(e) => {
                    if !quiet {
                        eprintln!("  repeat {rep}, start {k}: failed: {e:#}");
                    }
                    all_starts.push(StartSummary {
                        repeat: rep,
                        start: k,
                        theta_start: s.clone(),
                        result: None,
                        error: Some(format!("{e:#}")),
                    });
                }
            }
        }
        // Multilevel: the best coarse optimum continued on the study's model.
        let best = match (best, &coarse) {
            (Some(b), Some((_, n))) => {
                let spin = crate::progress::spinner(
                    &format!("repeat {rep}: refining the best coarse optimum on the full model"),
                    quiet,
                );
                let mut p = actuator(Problem::new(
                    model.clone(),
                    SolverOptions::default(),
                    &field,
                    free.clone(),
                )?)?;
                let r = fit_start(plan, &mut p, &b.theta, false)
                    .with_context(|| format!("repeat {rep}: refining the {n}-element optimum"))?;
                spin.finish_and_clear();
                if !quiet {
                    eprintln!(
                        "  repeat {rep}, refined on {} elements: cost {:.4e}, {} iterations, {} forward solves, {:.1} s",
                        model.mesh.elements.len(),
                        r.cost,
                        r.iterations,
                        r.forward_solves,
                        r.wall_time_s
                    );
                }
                refined.push(r.forward_solves);
                Some(r)
            }
            (b, _) => b,
        };
        match best {
            Some(b) => best_per_repeat.push(b),
            None => {
                write_starts_csv(&out.join("starts.csv"), &free, &all_starts)?;
                bail!("repeat {rep}: every start failed (see starts.csv)");
            }
        }
    }
    write_starts_csv(&out.join("starts.csv"), &free, &all_starts)?;
    let best = &best_per_repeat[0];
    // Confidence from the Jacobian at the optimum: known noise for a virtual experiment, the
    // residual variance otherwise.
    let dof = best.data.saturating_sub(free.len()).max(1);
    // The virtual field is weighted by 1/σ² (whitened, as a CSV with sx, sy is), so its
    // residuals have unit variance; the actuator term is whitened the same way.
    let s = if virtual_experiment {
        1.0
    } else {
        (2.0 * best.cost / dof as f64).sqrt()
    };
    let names: Vec<String> = free.iter().map(|f| f.name.clone()).collect();
    let info = fisher::information(&best.jacobian, s.max(1e-300), &Tied::none(&names))?;
    let id = fisher::identifiability(&info, &names);
    let parameters: Vec<ParameterSummary> = free
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let t = best.theta[k];
            let sd = id.relative_sd[k];
            let errors: Vec<f64> = best_per_repeat
                .iter()
                .map(|b| ((b.theta[k] - reference[k]) / reference[k]).abs())
                .collect();
            let logs: Vec<f64> = best_per_repeat.iter().map(|b| b.theta[k].ln()).collect();
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let sd_of = |v: &[f64]| {
                let m = mean(v);
                (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len().max(2) - 1) as f64)
                    .sqrt()
            };
            ParameterSummary {
                name: f.name.clone(),
                reference: reference_known.then_some(reference[k]),
                identified: t,
                relative_error: reference_known.then_some(errors[0]),
                relative_sd: sd,
                ci95: [t * (-1.96 * sd).exp(), t * (1.96 * sd).exp()],
                mean_relative_error: (virtual_experiment && repeats > 1).then(|| mean(&errors)),
                sd_relative_error: (virtual_experiment && repeats > 1).then(|| sd_of(&errors)),
                sd_identified_relative: (repeats > 1).then(|| sd_of(&logs)),
            }
        })
        .collect();
    write_parameters_csv(&out.join("parameters.csv"), &parameters)?;
    write_figures(out, &parameters, best, reference_known, repeats)?;
    if let Some(field) = &first_field {
        write_field_figures(out, model, &free, field, &best.theta)?;
    }
    let summary = Summary {
        command: "identify",
        version: env!("CARGO_PKG_VERSION"),
        test: test.to_string(),
        optimizer: plan.identification.optimizer.name(),
        grouped: plan.identification.grouped,
        elements: model.mesh.elements.len(),
        measured: match &measured {
            Some((_, source)) => source.clone(),
            None => "virtual experiment (femu synth)".into(),
        },
        points_in_tissue: inside,
        points_masked: masked,
        noise_sigma_mm: plan.sigma_mm,
        free_parameters: free.clone(),
        parameters,
        correlation: id.correlation,
        best_cost: best.cost,
        starts_per_repeat: starts_n,
        repeats,
        travel_term: plan.travel.map(|(_, sigma)| (reference_travel, sigma)),
        coarse_elements: coarse.as_ref().map(|(m, _)| m.mesh.elements.len()),
        refinement_forward_solves: refined,
        forward_solves_per_start: all_starts
            .iter()
            .filter_map(|s| s.result.as_ref().map(|r| r.forward_solves))
            .collect(),
        starts: all_starts,
        wall_time_s: t0.elapsed().as_secs_f64(),
    };
    let path = out.join("summary.json");
    std::fs::write(&path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    if !quiet {
        eprintln!(
            "{:<36} {:>12} {:>12} {:>10} {:>10}",
            "parameter", "reference", "identified", "error", "sd"
        );
        for p in &summary.parameters {
            eprintln!(
                "{:<36} {:>12} {:>12.5e} {:>10} {:>9.2}%",
                p.name,
                p.reference.map_or("-".into(), |v| format!("{v:.5e}")),
                p.identified,
                p.relative_error
                    .map_or("-".into(), |e| format!("{:.3}%", 100.0 * e)),
                100.0 * p.relative_sd
            );
        }
        eprintln!("wrote {} ({:.1} s)", out.display(), summary.wall_time_s);
    }
    Ok(())
}

fn write_starts_csv(path: &Path, free: &[FreeParameter], starts: &[StartSummary]) -> Result<()> {
    let mut w = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?,
    );
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
    Ok(())
}

fn write_parameters_csv(path: &Path, params: &[ParameterSummary]) -> Result<()> {
    let mut w = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?,
    );
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
    Ok(())
}

/// `errors.png` (Eq. 4 per parameter, mean ± sd over the repeats: the seed's Fig. 9) for a
/// virtual experiment, and `cost_history.png` of the best start.
fn write_figures(
    out: &Path,
    params: &[ParameterSummary],
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
