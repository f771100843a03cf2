//! `femu run STUDY`, `femu demo` and `femu init`: the whole study from one file — model →
//! forward tests → sensitivity and test ranking → measurement → identification → report.
//!
//! Each step writes its own sub-folder of the output folder as soon as it finishes, and
//! `steps.json` records every step's status and time after each one, so a run that stops (an
//! error, Ctrl-C) keeps what it finished; the report is written at the end, also after a failed
//! step, and `femu report DIR` rewrites it from whatever the folder holds.
//!
//! ```text
//! DIR/study.toml          the study as run
//! DIR/model/              mesh.inp, mesh.vtu, regions.png, quality.csv, summary.json
//! DIR/forward/TEST/       displacements.csv, result.vtu, deformed_le11.png, summary.json, ...
//! DIR/sensitivity/        sensitivity maps (Fig. 8), identifiability.csv (test ranking), ...
//! DIR/measurement/        measured.csv (the field the identification fits, model frame)
//! DIR/identify/GROUPING/  parameters.csv, errors.png, fields.png, summary.json (Fig. 9)
//! DIR/steps.json, DIR/summary.json, DIR/report.html
//! ```

use crate::identify_cmd;
use crate::plan::{self, Geometry, MeasurementPlan, Plan};
use crate::run::{write_solved, SolveContext};
use crate::sensitivity_cmd::{self, SensitivityArgs};
use crate::study_model::{study_model, StudyModel};
use anyhow::{bail, Context, Result};
use femu_mech::loading::apply_loading;
use femu_mech::{Model, SolverOptions, StaticSolver};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Elements of the demo's built-in thigh: the whole demo runs in 30 s on two idle cores (90 s
/// under a load average of 6), well inside the issue's 2 minutes.
pub const DEMO_ELEMENTS: usize = 4000;
/// `femu demo --full`: the seed's scale.
pub const FULL_ELEMENTS: usize = 25_000;

/// One step of a run, as recorded in `steps.json`.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct StepRecord {
    pub name: String,
    /// `done`, `failed` or `skipped`.
    pub status: String,
    pub folder: Option<String>,
    pub seconds: f64,
    pub error: Option<String>,
}

/// The record of a run (`steps.json`).
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct RunRecord {
    pub femu_version: String,
    pub command: String,
    pub study: String,
    pub started_unix_s: u64,
    pub threads: usize,
    pub os: String,
    pub steps: Vec<StepRecord>,
    pub total_seconds: f64,
}

impl RunRecord {
    fn save(&self, out: &Path) -> Result<()> {
        let path = out.join("steps.json");
        std::fs::write(&path, serde_json::to_string_pretty(self)?)
            .with_context(|| format!("cannot write {}", path.display()))
    }
}

/// `femu init PATH`.
pub fn init(path: &Path, force: bool, quiet: bool) -> Result<()> {
    if path.exists() && !force {
        bail!(
            "{} exists: choose another name or pass --force to overwrite it",
            path.display()
        );
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(path, plan::EXAMPLE_STUDY)
        .with_context(|| format!("cannot write {}", path.display()))?;
    if !quiet {
        eprintln!(
            "wrote {} (the seed's numerical example, every key with its default); run it with: femu run {} --out out/study",
            path.display(),
            path.display()
        );
    }
    Ok(())
}

/// The demo's study: the example study on `elements` quads; above 6 000 the identification is
/// multilevel (starts on 2 000 elements, the best refined on the study's mesh).
pub fn demo_study(elements: usize) -> String {
    let text = plan::EXAMPLE_STUDY.replace(
        "elements = 6000                  #",
        &format!("elements = {elements:<17}#"),
    );
    if elements > 6000 {
        text.replace("# coarse_elements = 2000 ", "coarse_elements = 2000   ")
    } else {
        text
    }
}

/// `femu demo [--full] [--elements N]`.
pub fn demo(out: &Path, full: bool, elements: Option<usize>, quiet: bool) -> Result<()> {
    let n = elements.unwrap_or(if full { FULL_ELEMENTS } else { DEMO_ELEMENTS });
    let text = demo_study(n);
    let plan = plan::parse(&text, out).context("the demo study")?;
    if plan.elements != Some(n) || (n > 6000) != plan.identification.coarse_elements.is_some() {
        bail!("internal: the demo study did not take --elements {n}");
    }
    if !quiet {
        eprintln!(
            "femu demo: the seed's numerical example on the built-in thigh ({n} elements): sensitivity of the three tests, compression measured on a 64 x 64 grid with sigma = {} mm, identification ungrouped and grouped from 5 starts -> {}",
            plan.sigma_mm,
            out.display()
        );
    }
    run_plan(&plan, None, &text, "demo", out, quiet)
}

/// `femu run STUDY --out DIR`.
pub fn run(study: &Path, out: &Path, quiet: bool) -> Result<()> {
    let text = std::fs::read_to_string(study)
        .with_context(|| format!("cannot read study file {}", study.display()))?;
    // Checked in full before anything is computed or written.
    let plan = plan::load(Some(study), None)?;
    run_plan(
        &plan,
        Some(study),
        &text,
        &format!("run {}", study.display()),
        out,
        quiet,
    )
}

/// Runs the steps of `plan` (read from `study`, or from its copy in `out` for the demo) into
/// `out`, then writes the report.
fn run_plan(
    plan: &Plan,
    study: Option<&Path>,
    text: &str,
    command: &str,
    out: &Path,
    quiet: bool,
) -> Result<()> {
    let t0 = Instant::now();
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output folder {}", out.display()))?;
    let copy = out.join("study.toml");
    if study.is_none_or(|s| s != copy) {
        std::fs::write(&copy, text).with_context(|| format!("cannot write {}", copy.display()))?;
    }
    let study = study.unwrap_or(&copy);
    let mut record = RunRecord {
        femu_version: env!("CARGO_PKG_VERSION").into(),
        command: command.into(),
        study: "study.toml".into(),
        started_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
        threads: rayon::current_num_threads(),
        os: format!("{} {}", std::env::consts::OS, std::env::consts::ARCH),
        steps: Vec::new(),
        total_seconds: 0.0,
    };
    let result = steps(plan, study, out, quiet, &mut record);
    if let Err(e) = &result {
        // The failed step is the last one recorded as running; name it.
        if let Some(last) = record.steps.last_mut() {
            if last.status == "running" {
                last.status = "failed".into();
                last.error = Some(format!("{e:#}"));
            }
        }
    }
    record.total_seconds = t0.elapsed().as_secs_f64();
    record.save(out)?;
    let report = crate::report::write(out);
    match (&result, &report) {
        (Ok(()), Ok(path)) if !quiet => eprintln!(
            "done in {:.1} s: {} (and summary.json)",
            record.total_seconds,
            path.display()
        ),
        (Err(_), Ok(path)) if !quiet => eprintln!(
            "stopped after {:.1} s; the finished steps are in {} and {}",
            record.total_seconds,
            out.display(),
            path.display()
        ),
        _ => {}
    }
    result?;
    report.map(|_| ())
}

/// Starts a step: records it as running.
fn begin(record: &mut RunRecord, out: &Path, name: &str, folder: Option<&str>) -> Result<Instant> {
    record.steps.push(StepRecord {
        name: name.into(),
        status: "running".into(),
        folder: folder.map(Into::into),
        seconds: 0.0,
        error: None,
    });
    record.save(out)?;
    Ok(Instant::now())
}

fn finish(record: &mut RunRecord, out: &Path, t: Instant) -> Result<()> {
    let last = record.steps.last_mut().expect("a step was begun");
    last.status = "done".into();
    last.seconds = t.elapsed().as_secs_f64();
    record.save(out)
}

fn skip(record: &mut RunRecord, out: &Path, name: &str, why: &str) -> Result<()> {
    record.steps.push(StepRecord {
        name: name.into(),
        status: "skipped".into(),
        folder: None,
        seconds: 0.0,
        error: Some(why.into()),
    });
    record.save(out)
}

fn steps(plan: &Plan, study: &Path, out: &Path, quiet: bool, record: &mut RunRecord) -> Result<()> {
    // 1. The model.
    let t = begin(record, out, "model", Some("model"))?;
    let spin = crate::progress::spinner("meshing the model", quiet);
    let built = study_model(plan)?;
    spin.finish_and_clear();
    write_model(
        plan,
        &built,
        &out.join("model"),
        t.elapsed().as_secs_f64(),
        quiet,
    )?;
    finish(record, out, t)?;

    // 2–3. The forward tests and their sensitivities (one solve per test serves both).
    let forward_dir = out.join("forward");
    let mut on_solved = |name: &str, model: &Model, solution: &femu_mech::Solution, solve_s| {
        write_solved(
            model,
            solution,
            None,
            &SolveContext {
                input: &format!("{}, {name}", built.source),
                command: "run",
                out: &forward_dir.join(name),
                figures: true,
                quiet: true,
                options: SolverOptions::default(),
                read_s: 0.0,
                setup_s: 0.0,
                solve_s,
            },
        )
    };
    if plan.steps.sensitivity {
        let t = begin(record, out, "forward and sensitivity", Some("sensitivity"))?;
        let args = SensitivityArgs {
            study: None,
            out: out.join("sensitivity"),
            elements: None,
            fd_check: false,
            fd_step: 5e-4,
            no_figures: false,
        };
        sensitivity_cmd::run_plan(
            plan,
            &built.model,
            &built.skin,
            &args,
            quiet,
            &mut on_solved,
        )?;
        finish(record, out, t)?;
    } else if plan.steps.forward {
        let t = begin(record, out, "forward", Some("forward"))?;
        let bar = crate::progress::bar(plan.tests.len(), "forward tests", quiet);
        for loading in &plan.tests {
            let mut model = built.model.clone();
            apply_loading(&mut model, &built.skin, loading)
                .with_context(|| format!("test {}", loading.name()))?;
            let mut solver = StaticSolver::new(&model, SolverOptions::default())?;
            let ts = Instant::now();
            let solution = solver
                .solve(&model)
                .map_err(|e| anyhow::anyhow!("test {}: {e}", loading.name()))?;
            on_solved(
                &loading.name(),
                &model,
                &solution,
                ts.elapsed().as_secs_f64(),
            )?;
            bar.inc(1);
        }
        bar.finish_and_clear();
        finish(record, out, t)?;
    } else {
        skip(record, out, "forward", "[run] forward = false")?;
    }
    if !plan.steps.sensitivity {
        skip(record, out, "sensitivity", "[run] sensitivity = false")?;
    }

    // 4–5. The measurement and the identification.
    if !plan.steps.identification {
        skip(record, out, "measurement", "[run] identification = false")?;
        skip(
            record,
            out,
            "identification",
            "[run] identification = false",
        )?;
        return Ok(());
    }
    let test = plan.tests[plan.identification.test];
    let mut measured_model = built.model.clone();
    apply_loading(&mut measured_model, &built.skin, &test)
        .with_context(|| format!("test {}", test.name()))?;
    let t = begin(record, out, "measurement", Some("measurement"))?;
    let measured = write_measurement(
        plan,
        study,
        &measured_model,
        &out.join("measurement"),
        quiet,
    )?;
    finish(record, out, t)?;

    let groupings: Vec<(bool, &str)> = if plan.identification.both_groupings {
        vec![(false, "ungrouped"), (true, "grouped")]
    } else if plan.identification.grouped {
        vec![(true, "grouped")]
    } else {
        vec![(false, "ungrouped")]
    };
    for (grouped, name) in groupings {
        let folder = format!("identify/{name}");
        let t = begin(
            record,
            out,
            &format!("identification ({name})"),
            Some(&folder),
        )?;
        let mut p = plan.clone();
        p.identification.grouped = grouped;
        identify_cmd::identify_plan(
            &p,
            &measured_model,
            &test.name(),
            measured.clone(),
            &out.join(&folder),
            quiet,
        )?;
        finish(record, out, t)?;
    }
    Ok(())
}

/// The model folder: for a meshed thigh the `femu mesh` folder; for a deck its mesh with the
/// regions (VTU) and the element quality.
fn write_model(
    plan: &Plan,
    built: &StudyModel,
    dir: &Path,
    mesh_s: f64,
    quiet: bool,
) -> Result<()> {
    let kind = plan.element.kind();
    match (&built.thigh, &plan.geometry) {
        (Some(thigh), geometry) => {
            let materials: Vec<femu_mesh::MaterialDef> =
                built.model.materials.iter().map(|m| m.to_def()).collect();
            let (input, command) = match geometry {
                Geometry::Labels(l) => (
                    serde_json::json!({"model": "label image", "image": l.image, "map": l.map}),
                    "mesh labels",
                ),
                _ => (
                    serde_json::json!({"model": "parametric thigh"}),
                    "mesh thigh",
                ),
            };
            crate::mesh_cmd::write_model_folder(
                thigh, &materials, input, kind, command, dir, mesh_s, quiet,
            )
        }
        (None, _) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            let mesh = &built.model.mesh;
            let names: Vec<String> = built
                .model
                .materials
                .iter()
                .map(|m| m.name.clone())
                .collect();
            let quality = femu_geometry::quality_report(mesh, &names)
                .or_else(|_| femu_geometry::quality_report(mesh, &[]))?;
            std::fs::write(dir.join("quality.csv"), quality.to_csv())?;
            let region: Vec<f64> = built
                .model
                .element_material
                .iter()
                .map(|&m| m as f64)
                .collect();
            femu_mesh::vtu::write_vtu(
                &dir.join("mesh.vtu"),
                mesh,
                None,
                &[],
                &[femu_mesh::vtu::VtuField {
                    name: "material",
                    components: 1,
                    data: &region,
                }],
            )?;
            let summary = serde_json::json!({
                "femu_version": env!("CARGO_PKG_VERSION"),
                "command": "run (deck)",
                "input": built.source,
                "nodes": mesh.nodes.len(),
                "elements": mesh.elements.len(),
                "skin_faces": built.skin.len(),
                "quality": quality,
            });
            std::fs::write(
                dir.join("summary.json"),
                serde_json::to_string_pretty(&summary)?,
            )?;
            Ok(())
        }
    }
}

/// The measurement folder: `measured.csv` in the model frame — the virtual experiment's first
/// noise realization, or the study's file mapped to the model frame. Returns the field the
/// identification fits (`None`: the virtual experiment, drawn per noise realization).
fn write_measurement(
    plan: &Plan,
    study: &Path,
    model: &Model,
    dir: &Path,
    quiet: bool,
) -> Result<Option<(femu_identify::measured::MeasuredField, String)>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let path: PathBuf = dir.join("measured.csv");
    match &plan.measurement {
        MeasurementPlan::Virtual => {
            let test = plan.tests[plan.identification.test].name();
            identify_cmd::write_virtual_measurement(plan, model, &test, &path, quiet)?;
            Ok(None)
        }
        MeasurementPlan::Ultrasound => {
            let args = crate::us_cmd::UsSimArgs {
                study: Some(study.to_path_buf()),
                out: dir.to_path_buf(),
                elements: None,
                element: 16,
                regularization: None,
                grid_step: 16.0,
                levels: 3,
                steps: 4,
            };
            crate::us_cmd::sim(&args, quiet)?;
            let field = femu_identify::measured::MeasuredField::read(&path)?;
            Ok(Some((
                field,
                "DIC of simulated B-mode images (femu us-sim)".to_string(),
            )))
        }
        MeasurementPlan::File { .. } => {
            let (field, source) =
                identify_cmd::study_measurement(plan)?.expect("a file measurement");
            field
                .write(&path, None)
                .with_context(|| format!("cannot write {}", path.display()))?;
            if !quiet {
                eprintln!(
                    "measurement: {} points from {source}, mapped to the model frame -> {}",
                    field.points.len(),
                    path.display()
                );
            }
            Ok(Some((field, source)))
        }
    }
}
