//! `femu run STUDY` and `femu demo`: the whole study from one file — model → forward tests →
//! sensitivity and test ranking → measurement → identification → report.
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
//! DIR/design/             tests x probe windows ranked ([run] design = true)
//! DIR/measurement/        measured.csv (the field the identification fits, model frame;
//!                         NAME/measured.csv per measurement of a [[measurement]] list)
//! DIR/identify/GROUPING/  parameters.csv, errors.png, fields.png, summary.json (Fig. 9)
//! DIR/steps.json, DIR/summary.json, DIR/report.html
//! ```

use super::frames::RecordedFrames;
use super::identify;
use super::measure::{self, MeasureInputs, Prepared, PreparedData};
use super::parameters::IdentificationInputs;
use super::record::{begin, finish, skip, RunRecord};
use super::sensitivity::{self, SensitivityInputs, SensitivityOptions};
use super::solve::{write_solved, SolveContext};
use super::ultrasound::SimulatedImages;
use crate::bail;
use crate::error::Result;
use crate::model::{build, StudyModel};
use crate::output::{create_dir, write_text};
use crate::progress::Progress;
use crate::schema::{
    self, Grouping, Measurement, MeasurementSource, Steps, Study, TestSpec, EXAMPLE_STUDY,
};
use femu_mech::{Model, SolverOptions, StaticSolver};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// Elements of the demo's built-in thigh: the whole demo runs in about 5 s on two cores.
pub const DEMO_ELEMENTS: usize = 4000;
/// `femu demo --full`: the seed's scale.
pub const FULL_ELEMENTS: usize = 25_000;

/// The demo's multilevel identification on `elements` quads: from 3 000 elements on, the starts
/// run on a coarse thigh of three eighths as many quads (at most 2 000) and the best is refined
/// on the study's mesh. On the demo's 4 101 quads the parameters and their sds are those of the
/// single-level identification to 1e-6 (relative), and the identifications take a third less
/// time.
pub fn demo_coarse_elements(elements: usize) -> Option<usize> {
    (elements >= 3000).then(|| (elements * 3 / 8 / 100 * 100).min(2000))
}

/// The demo's study: the example study on `elements` quads, multilevel as
/// [`demo_coarse_elements`] says.
pub fn demo_study(elements: usize) -> String {
    let text = EXAMPLE_STUDY.replace(
        "elements = 6000                  #",
        &format!("elements = {elements:<17}#"),
    );
    match demo_coarse_elements(elements) {
        Some(c) => text.replace(
            "# coarse_elements = 2000 ",
            &format!("coarse_elements = {c:<7}"),
        ),
        None => text,
    }
}

/// `femu demo [--full] [--elements N]`.
pub fn demo(
    out: &Path,
    full: bool,
    elements: Option<usize>,
    progress: &dyn Progress,
) -> Result<RunRecord> {
    let n = elements.unwrap_or(if full { FULL_ELEMENTS } else { DEMO_ELEMENTS });
    schema::thigh_elements(&femu_geometry::ThighParams::default(), n)
        .map_err(|m| crate::input!("--elements: {m}"))?;
    let text = demo_study(n);
    let study = schema::parse(&text, out).map_err(|e| crate::input!("the demo study: {e}"))?;
    if study.model.resolution != schema::Resolution::Elements(n)
        || study.identification.coarse_elements != demo_coarse_elements(n)
    {
        bail!("internal: the demo study did not take --elements {n}");
    }
    progress.note(&format!(
        "femu demo: the seed's numerical example on the built-in thigh ({n} elements): sensitivity of the three tests, compression measured on a 64 x 64 grid with sigma = {} mm, identification ungrouped and grouped from 5 starts -> {}",
        study.measurement.sigma_mm,
        out.display()
    ));
    run_study(&study, &text, "demo", out, None, progress)
}

/// `femu run STUDY --out DIR`.
pub fn run(study_file: &Path, out: &Path, progress: &dyn Progress) -> Result<RunRecord> {
    // Checked in full before anything is computed or written.
    let study = schema::read_for_model(study_file)?;
    let text = std::fs::read_to_string(study_file)?;
    run_study(
        &study,
        &text,
        &format!("run {}", study_file.display()),
        out,
        Some(study_file),
        progress,
    )
}

/// What a run writes at the top of its folder; [`own_folder`] clears these before a run.
const RUN_OUTPUTS: [&str; 10] = [
    "model",
    "design",
    "forward",
    "sensitivity",
    "measurement",
    "identify",
    "steps.json",
    "summary.json",
    "report.html",
    "study.toml",
];

/// Makes `out` the run's own folder: created if absent; the outputs of an earlier run in it
/// removed (so that nothing stale mixes into the new report), leaving everything else — and
/// `study_file`, when the study file itself lies there — untouched. A folder that is not an
/// earlier run's (no `steps.json`) but holds one of the run's output names is refused rather
/// than overwritten.
fn own_folder(out: &Path, study_file: Option<&Path>) -> Result<()> {
    if out.exists() && !out.is_dir() {
        bail!(
            "--out {}: a file of that name exists; give a folder",
            out.display()
        );
    }
    create_dir(out)?;
    let earlier_run = out.join("steps.json").is_file();
    let input = study_file.and_then(|p| p.canonicalize().ok());
    for name in RUN_OUTPUTS {
        let path = out.join(name);
        if !path.exists() || path.canonicalize().ok() == input {
            continue;
        }
        if !earlier_run {
            bail!(
                "--out {}: it already holds {name}, and is not the folder of an earlier femu run (no steps.json): choose an empty or new folder",
                out.display()
            );
        }
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        removed.map_err(|e| {
            crate::input!("cannot clear {} of the earlier run: {e}", path.display())
        })?;
    }
    Ok(())
}

/// Runs the steps of `study` (whose file text is `text`, copied to `out/study.toml`; read from
/// `study_file` if any) into `out`, then writes the report.
pub fn run_study(
    study: &Study,
    text: &str,
    command: &str,
    out: &Path,
    study_file: Option<&Path>,
    progress: &dyn Progress,
) -> Result<RunRecord> {
    let t0 = Instant::now();
    own_folder(out, study_file)?;
    let copy = out.join("study.toml");
    if std::fs::read_to_string(&copy).ok().as_deref() != Some(text) {
        write_text(&copy, text)?;
    }
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
    let result = steps(study, out, progress, &mut record);
    if let Err(e) = &result {
        // The failed (or interrupted) step is the last one recorded as running; name it.
        let seconds = last_step_seconds(t0, &record.steps);
        let interrupted = crate::progress::is_interrupted(e);
        match record.steps.last_mut() {
            Some(last) if last.status == "running" => {
                last.status = if interrupted { "interrupted" } else { "failed" }.into();
                last.seconds = seconds;
                last.error = Some(e.chain());
            }
            // Stopped between two steps: the record says where.
            _ if interrupted => record.steps.push(super::record::StepRecord {
                name: "(between steps)".into(),
                status: "interrupted".into(),
                folder: None,
                seconds: 0.0,
                error: Some("stopped by the user before the next step began".into()),
            }),
            _ => {}
        }
    }
    record.total_seconds = t0.elapsed().as_secs_f64();
    record.save(out)?;
    let report = crate::report::write(out);
    match (&result, &report) {
        (Ok(()), Ok(path)) => progress.note(&format!(
            "done in {:.1} s: {} (and summary.json)",
            record.total_seconds,
            path.display()
        )),
        (Err(_), Ok(path)) => progress.note(&format!(
            "stopped after {:.1} s; the finished steps are in {} and {}",
            record.total_seconds,
            out.display(),
            path.display()
        )),
        _ => {}
    }
    result?;
    report.map(|_| record)
}

/// The time of the last step of `steps` (the others are recorded) since the run began at `t0`.
fn last_step_seconds(t0: Instant, steps: &[super::record::StepRecord]) -> f64 {
    let before: f64 = steps.iter().rev().skip(1).map(|s| s.seconds).sum();
    (t0.elapsed().as_secs_f64() - before).max(0.0)
}

/// The model step: the study's model built and written to `out/model`.
fn model_step(
    study: &Study,
    out: &Path,
    progress: &dyn Progress,
    record: &mut RunRecord,
) -> Result<StudyModel> {
    let t = begin(record, out, "model", Some("model"))?;
    let spin = progress.task("meshing the model", None);
    let built = build(&study.model)?;
    drop(spin);
    super::model::write_study_model(
        &built,
        &study.model.geometry,
        study.model.element.kind(),
        &out.join("model"),
        t.elapsed().as_secs_f64(),
        progress,
    )?;
    finish(record, out, t)?;
    Ok(built)
}

/// The steps of a run, each recorded in `record` (and `out/steps.json`) as it begins and ends.
fn steps(study: &Study, out: &Path, progress: &dyn Progress, record: &mut RunRecord) -> Result<()> {
    // 1. The model.
    let built = model_step(study, out, progress, record)?;

    // 2–3. The forward tests and their sensitivities (one solve per test serves both); a test
    // that fails is left out, and only the steps that need it are skipped.
    progress.check()?;
    let failed = forward_and_sensitivity(
        &study.steps,
        SensitivityInputs::of(study),
        &built,
        out,
        progress,
        record,
    )?;

    // The design of the experiment (tests x probe windows), when asked.
    if study.steps.design {
        progress.check()?;
        let t = begin(record, out, "design", Some("design"))?;
        let inputs = super::design::DesignInputs::of(study, &built)?;
        super::design::run_on(&inputs, &built, &out.join("design"), progress)?;
        finish(record, out, t)?;
    }

    // 4–5. The measurement and the identification.
    if !study.steps.identification {
        skip(record, out, "measurement", "[run] identification = false")?;
        skip(
            record,
            out,
            "identification",
            "[run] identification = false",
        )?;
        return Ok(());
    }
    refuse_unsolved_tests(&study.measurements, &study.tests, &failed, out, record)?;
    progress.check()?;
    let t = begin(record, out, "measurement", Some("measurement"))?;
    let identification = IdentificationInputs::of(study);
    let measured = measure_step(
        &MeasureInputs::of(study),
        &identification,
        &built,
        &out.join("measurement"),
        progress,
    )?;
    finish(record, out, t)?;

    for (grouped, name) in groupings(study.identification.grouping) {
        progress.check()?;
        let folder = format!("identify/{name}");
        let t = begin(
            record,
            out,
            &format!("identification ({name})"),
            Some(&folder),
        )?;
        let into = out.join(&folder);
        match &measured {
            Measurements::Frames(recorded) => {
                super::frames::identify_frames(
                    &identification,
                    &study.measurements[0],
                    grouped,
                    &built,
                    recorded,
                    &into,
                    progress,
                )?;
            }
            Measurements::Images(simulated) => {
                super::images::identify_image_measurement(
                    &identification,
                    &study.measurements[0],
                    grouped,
                    simulated,
                    &into,
                    progress,
                )?;
            }
            Measurements::Fields(prepared) => {
                identify::identify_on(&identification, grouped, &built, prepared, &into, progress)?;
            }
        }
        finish(record, out, t)?;
    }
    Ok(())
}

/// The measurement and identification steps skipped, and an error, when the test of one of
/// `measurements` (of `tests`) could not be solved.
fn refuse_unsolved_tests(
    measurements: &[Measurement],
    tests: &[TestSpec],
    failed: &[(String, String)],
    out: &Path,
    record: &mut RunRecord,
) -> Result<()> {
    for m in measurements {
        let test = &tests[m.test].loading;
        if let Some((_, why)) = failed.iter().find(|(name, _)| *name == test.name()) {
            let reason = format!("its test {} could not be solved: {why}", test.name());
            skip(record, out, "measurement", &reason)?;
            skip(record, out, "identification", &reason)?;
            bail!(
                "the identification needs the test {}, which could not be solved: {why}",
                test.name()
            );
        }
    }
    Ok(())
}

/// What the measurement step made, for the identifications.
enum Measurements {
    /// Recorded frames: identified by integrated DIC (`super::frames`).
    Frames(Box<RecordedFrames>),
    /// Simulated images: integrated DIC, beside DIC -> FEMU plain and weighted.
    Images(Arc<SimulatedImages>),
    /// Fields to fit (virtual, files, simulated images in a list of measurements).
    Fields(Vec<Prepared>),
}

/// The measurement step of `inputs` into `dir`: recorded frames read, placed and correlated;
/// any other measurement prepared once for the identifications, its fields written as the
/// identification of `identification` fits them.
fn measure_step(
    inputs: &MeasureInputs,
    identification: &IdentificationInputs,
    built: &StudyModel,
    dir: &Path,
    progress: &dyn Progress,
) -> Result<Measurements> {
    create_dir(dir)?;
    if let [m] = inputs.measurements {
        if let MeasurementSource::Frames(spec) = &m.source {
            let test = &inputs.tests[m.test];
            let recorded = super::frames::measure(test, inputs.probe, built, spec, dir, progress)?;
            return Ok(Measurements::Frames(Box::new(recorded)));
        }
    }
    let prepared = measure::prepare(inputs, built, dir, progress)?;
    super::joint::write_measured(identification, built, &prepared, dir, progress)?;
    let simulated = match prepared.as_slice() {
        [p] => match &p.data {
            PreparedData::Measured(m) => m.simulated.clone(),
            PreparedData::Virtual { .. } => None,
        },
        _ => None,
    };
    Ok(match simulated {
        Some(simulated) => Measurements::Images(simulated),
        None => Measurements::Fields(prepared),
    })
}

/// The groupings the identification runs (`[identification] grouped`), with their folders.
fn groupings(grouping: Grouping) -> Vec<(bool, &'static str)> {
    match grouping {
        Grouping::Both => vec![(false, "ungrouped"), (true, "grouped")],
        Grouping::Grouped => vec![(true, "grouped")],
        Grouping::Ungrouped => vec![(false, "ungrouped")],
    }
}

/// Steps 2–3: each test of `inputs` solved on `built` (its forward folder written) and, unless
/// `[run] sensitivity = false` (`steps`), differentiated. Returns the tests that could not be
/// solved, with the reason (the step records them as a note).
fn forward_and_sensitivity(
    steps: &Steps,
    inputs: SensitivityInputs,
    built: &StudyModel,
    out: &Path,
    progress: &dyn Progress,
    record: &mut RunRecord,
) -> Result<Vec<(String, String)>> {
    let mut failed = Vec::new();
    let forward_dir = out.join("forward");
    let mut on_solved = |name: &str, model: &Model, solution: &femu_mech::Solution, solve_s| {
        // Kept for the measurement and the identifications (a name that two tests share is
        // ambiguous: not kept).
        let mut named = inputs.tests.iter().filter(|t| t.loading.name() == name);
        if let (Some(test), None) = (named.next(), named.next()) {
            built.keep_reference_state(&test.loading, solution.state.clone());
        }
        write_solved(
            model,
            solution,
            None,
            &SolveContext {
                input: &format!("{}, {name}", built.source),
                command: "run",
                out: &forward_dir.join(name),
                figures: true,
                options: SolverOptions::default(),
                read_s: 0.0,
                setup_s: 0.0,
                solve_s,
            },
            &crate::progress::Quiet,
        )
        .map(|_| ())
    };
    if steps.sensitivity {
        let t = begin(record, out, "forward and sensitivity", Some("sensitivity"))?;
        let options = SensitivityOptions {
            out: out.join("sensitivity"),
            fd_check: false,
            fd_step: 5e-4,
            figures: true,
        };
        let summary = sensitivity::run_on(
            inputs,
            &built.model,
            &built.skin,
            &options,
            progress,
            &mut on_solved,
        )?;
        failed = summary.failed_tests;
        finish(record, out, t)?;
    } else if steps.forward {
        let t = begin(record, out, "forward", Some("forward"))?;
        let bar = progress.task("forward tests", Some(inputs.tests.len()));
        for test in inputs.tests {
            progress.check()?;
            let loading = &test.loading;
            let model = built.loaded(loading)?;
            let mut solver = StaticSolver::new(&model, SolverOptions::default())?;
            let ts = Instant::now();
            match solver.solve(&model) {
                Ok(solution) => on_solved(
                    &loading.name(),
                    &model,
                    &solution,
                    ts.elapsed().as_secs_f64(),
                )?,
                Err(femu_mech::SolveError::Interrupted(stop)) => {
                    return Err(crate::Error::from(stop).context("forward tests"))
                }
                Err(e) => {
                    let why = format!(
                        "{e} (refine the mesh, [model] elements, or lower the test's load)"
                    );
                    progress.warn(&format!("test {} left out: {why}", loading.name()));
                    failed.push((loading.name(), why));
                }
            }
            bar.inc(1);
        }
        drop(bar);
        finish(record, out, t)?;
    } else {
        skip(record, out, "forward", "[run] forward = false")?;
    }
    if !steps.sensitivity {
        skip(record, out, "sensitivity", "[run] sensitivity = false")?;
    }
    if !failed.is_empty() {
        // The step is done for the other tests; its note says which were left out.
        if let Some(step) = record.steps.iter_mut().rev().find(|s| s.status == "done") {
            step.error = Some(
                failed
                    .iter()
                    .map(|(t, why)| format!("test {t} left out: {why}"))
                    .collect::<Vec<_>>()
                    .join("; "),
            );
            record.save(out)?;
        }
    }
    Ok(failed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The demo's study parses with the multilevel's coarse mesh its rule gives: none below
    /// 3 000 elements, three eighths of the mesh on the demo's default, 2 000 at paper scale.
    #[test]
    fn the_demo_study_takes_its_coarse_mesh() {
        for (n, coarse) in [
            (2000, None),
            (DEMO_ELEMENTS, Some(1500)),
            (FULL_ELEMENTS, Some(2000)),
        ] {
            assert_eq!(demo_coarse_elements(n), coarse, "{n}");
            let study = schema::parse(&demo_study(n), Path::new(".")).unwrap();
            assert_eq!(study.identification.coarse_elements, coarse, "{n}");
            assert_eq!(study.model.resolution, schema::Resolution::Elements(n));
        }
    }
}
