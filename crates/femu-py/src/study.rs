//! `femu.Study`: a study file (or a dict, or the demo's study) checked by the one study schema,
//! run whole (`femu run`) or one step at a time; and the typed summaries a run folder holds,
//! read back as JSON text for the dataclasses of `python/femu/results.py`.

use crate::convert::{self, read_typed};
use crate::errors::{self, IntoPy};
use crate::running;
use femu_study::report::{ModelSummary, RunSummary};
use femu_study::schema::{self, Study};
use femu_study::steps::identify::IdentificationSummary;
use femu_study::steps::record::RunRecord;
use femu_study::steps::sensitivity::{SensitivityOptions, SensitivitySummary};
use femu_study::steps::solve::{SolveOutput, SolveSummary};
use femu_study::steps::{identify, run, sensitivity, solve};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A checked study and the TOML text it was read from.
#[pyclass(name = "Study", module = "femu._femu", frozen)]
pub struct PyStudy {
    pub study: Study,
    text: String,
    /// The study file, when read from one (`femu run` copies it and records its name).
    file: Option<PathBuf>,
    /// What `steps.json` records as the command.
    command: String,
}

impl PyStudy {
    fn parse(text: String, base: &Path, command: String) -> PyResult<PyStudy> {
        let study = schema::parse(&text, base).py_err()?;
        Ok(PyStudy {
            study,
            text,
            file: None,
            command,
        })
    }
}

/// The base folder of relative paths: `base`, or the working folder.
fn base_or_cwd(base: Option<PathBuf>) -> PathBuf {
    base.unwrap_or_else(|| PathBuf::from("."))
}

#[pymethods]
impl PyStudy {
    /// Reads and checks a study file (`femu run STUDY`'s reading).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<PyStudy> {
        let study = schema::read(&path).py_err()?;
        let text = std::fs::read_to_string(&path).py_err()?;
        Ok(PyStudy {
            study,
            text,
            command: format!("run {}", path.display()),
            file: Some(path),
        })
    }

    /// A study from TOML text; relative paths start from `base` (default: the working folder).
    #[staticmethod]
    #[pyo3(signature = (text, base = None))]
    fn from_toml(text: String, base: Option<PathBuf>) -> PyResult<PyStudy> {
        PyStudy::parse(text, &base_or_cwd(base), "python (TOML text)".into())
    }

    /// A study from a dict of tables (`{"model": {"elements": 2000}, "test": [{"kind":
    /// "compression"}]}`), written as TOML and checked by the same schema.
    #[staticmethod]
    #[pyo3(signature = (data, base = None))]
    fn from_dict(data: &Bound<'_, PyDict>, base: Option<PathBuf>) -> PyResult<PyStudy> {
        let table = convert::toml_table(data, "")?;
        let text = toml::to_string(&table)
            .map_err(|e| errors::StudyError::new_err(format!("the dict as TOML: {e}")))?;
        PyStudy::parse(text, &base_or_cwd(base), "python (dict)".into())
    }

    /// The commented example study `femu init` writes: the seed's numerical example.
    #[staticmethod]
    fn example() -> PyResult<PyStudy> {
        PyStudy::parse(
            schema::EXAMPLE_STUDY.to_string(),
            Path::new("."),
            "python (example study)".into(),
        )
    }

    /// The study `femu demo [--elements N]` runs (4 000 elements by default; from 3 000 on the
    /// identification is multilevel, its starts on a coarser thigh, as `femu demo --full`).
    #[staticmethod]
    #[pyo3(signature = (elements = None))]
    fn demo(elements: Option<usize>) -> PyResult<PyStudy> {
        let n = elements.unwrap_or(run::DEMO_ELEMENTS);
        if !schema::ELEMENTS_RANGE.contains(&n) {
            return Err(errors::StudyError::new_err(format!(
                "elements must be in [100, 500000], got {n}"
            )));
        }
        PyStudy::parse(run::demo_study(n), Path::new("."), "demo".into())
    }

    /// The study's TOML text.
    #[getter]
    fn toml(&self) -> &str {
        &self.text
    }

    /// The study file, when read from one.
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.file.clone()
    }

    /// The loading tests' names, in order.
    #[getter]
    fn tests(&self) -> Vec<String> {
        self.study.tests.iter().map(|t| t.loading.name()).collect()
    }

    /// The identification test's name.
    #[getter]
    fn identification_test(&self) -> String {
        self.study.identification_test().loading.name()
    }

    /// The whole study (`femu run`): model → forward tests → sensitivity → measurement →
    /// identification → report, written into `out`; returns `steps.json` (JSON text).
    #[pyo3(signature = (out, reporter = None))]
    fn run(
        &self,
        py: Python<'_>,
        out: PathBuf,
        reporter: Option<Bound<'_, PyAny>>,
    ) -> PyResult<String> {
        let record = running::run(py, reporter.as_ref(), |progress| {
            run::run_study(
                &self.study,
                &self.text,
                &self.command,
                &out,
                self.file.as_deref(),
                progress,
            )
        })?;
        convert::json(&record)
    }

    /// One step of the study into `out`: `model`, `forward`, `sensitivity`, `measurement` or
    /// `identification`; returns what the step's `summary.json` holds (JSON text; `forward`:
    /// one summary per test, `measurement`: the path of `measured.csv`).
    #[pyo3(signature = (name, out, reporter = None))]
    fn step(
        &self,
        py: Python<'_>,
        name: &str,
        out: PathBuf,
        reporter: Option<Bound<'_, PyAny>>,
    ) -> PyResult<String> {
        let study = &self.study;
        match name {
            "model" => running::run(py, reporter.as_ref(), |progress| {
                let t = Instant::now();
                let built = femu_study::model::build(&study.model)?;
                femu_study::steps::model::write_study_model(
                    &built,
                    &study.model.geometry,
                    study.model.element.kind(),
                    &out,
                    t.elapsed().as_secs_f64(),
                    progress,
                )?;
                read_typed::<ModelSummary>(&out.join("summary.json"))
            }),
            "forward" => running::run(py, reporter.as_ref(), |progress| {
                forward_step(study, &out, progress)
            }),
            "sensitivity" => running::run(py, reporter.as_ref(), |progress| {
                let options = SensitivityOptions {
                    out: out.clone(),
                    fd_check: false,
                    fd_step: 5e-4,
                    figures: true,
                };
                let s: SensitivitySummary = sensitivity::run(study, &options, progress)?;
                Ok(serde_json::to_string(&s)?)
            }),
            "measurement" => running::run(py, reporter.as_ref(), |progress| {
                identify::synth(study, &out, progress)?;
                Ok(serde_json::to_string(&out.join("measured.csv"))?)
            }),
            "identification" => running::run(py, reporter.as_ref(), |progress| {
                let s: IdentificationSummary = identify::identify(study, None, &out, progress)?;
                Ok(serde_json::to_string(&s)?)
            }),
            other => Err(errors::input(format!(
                "unknown step '{other}' (model, forward, sensitivity, measurement, identification)"
            ))),
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "femu.Study({}; tests {}; identification on {})",
            self.file
                .as_ref()
                .map_or("not from a file".to_string(), |p| p.display().to_string()),
            self.tests().join(", "),
            self.identification_test()
        )
    }
}

/// The `forward` step: each test of `study` solved and written into `out/TEST/` as `femu run`
/// writes `forward/`; returns `{test: SolveSummary}` as JSON text.
fn forward_step(
    study: &Study,
    out: &Path,
    progress: &dyn femu_study::Progress,
) -> femu_study::error::Result<String> {
    let t = Instant::now();
    let built = femu_study::model::build(&study.model)?;
    let read_s = t.elapsed().as_secs_f64();
    let mut summaries = Vec::new();
    for test in &study.tests {
        progress.check()?;
        let name = test.loading.name();
        let model = built.loaded(&test.loading)?;
        let dir = out.join(&name);
        let input = format!("{}, {name}", built.source);
        let summary = solve::solve_model(
            &model,
            &SolveOutput {
                input: &input,
                command: "python forward",
                out: &dir,
                read_s,
                newton_table: false,
                figures: true,
            },
            progress,
        )?;
        summaries.push(format!(
            "{}:{}",
            serde_json::to_string(&name)?,
            serde_json::to_string(&summary)?
        ));
    }
    Ok(format!("{{{}}}", summaries.join(",")))
}

/// The typed summaries of a run folder (`femu run`, `femu demo`, `Study.run`), each as JSON
/// text: `record` (steps.json), `summary` (summary.json), `model`, `forward` (per test),
/// `sensitivity`, `identification` (per grouping), `measured` (the path of measured.csv).
/// A step that did not run is absent.
#[pyfunction]
pub fn read_run<'py>(py: Python<'py>, dir: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    if !dir.join("steps.json").is_file() {
        return Err(errors::input(format!(
            "{} is not the folder of a femu run (no steps.json)",
            dir.display()
        )));
    }
    let d = PyDict::new(py);
    d.set_item(
        "record",
        read_typed::<RunRecord>(&dir.join("steps.json")).py_err()?,
    )?;
    if dir.join("summary.json").is_file() {
        d.set_item(
            "summary",
            read_typed::<RunSummary>(&dir.join("summary.json")).py_err()?,
        )?;
    }
    let model = dir.join("model").join("summary.json");
    if model.is_file() {
        d.set_item("model", read_typed::<ModelSummary>(&model).py_err()?)?;
    }
    let per_folder =
        |sub: &str, read: fn(&Path) -> femu_study::error::Result<String>| -> PyResult<_> {
            let folder = PyDict::new(py);
            let Ok(entries) = std::fs::read_dir(dir.join(sub)) else {
                return Ok(folder);
            };
            let mut names: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
            names.sort();
            for path in names {
                let summary = path.join("summary.json");
                if summary.is_file() {
                    let name = path.file_name().map(|n| n.to_string_lossy().to_string());
                    folder.set_item(name, read(&summary).py_err()?)?;
                }
            }
            Ok(folder)
        };
    d.set_item(
        "forward",
        per_folder("forward", read_typed::<SolveSummary>)?,
    )?;
    d.set_item(
        "identification",
        per_folder("identify", read_typed::<IdentificationSummary>)?,
    )?;
    let sensitivity = dir.join("sensitivity").join("summary.json");
    if sensitivity.is_file() {
        d.set_item(
            "sensitivity",
            read_typed::<SensitivitySummary>(&sensitivity).py_err()?,
        )?;
    }
    let measured = dir.join("measurement").join("measured.csv");
    if measured.is_file() {
        d.set_item("measured", measured)?;
    }
    Ok(d)
}
