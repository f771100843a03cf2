//! `femu.Model`: a study's model (the built-in thigh, a meshed label image, a deck) with its
//! mesh as arrays; forward solves of a loading test for given parameters (nodal displacements,
//! element fields, reactions as arrays) and the exact parameter sensitivities
//! (`femu_mech::sensitivity::DirectSensitivity`, an array nodes x 2 x parameters).

use crate::convert;
use crate::errors;
use crate::running;
use crate::study::PyStudy;
use femu_mech::loading::Loading;
use femu_mech::material::Bound as LawBound;
use femu_mech::sensitivity::{all_parameters, sensitivity_map, DirectSensitivity, Parameter};
use femu_mech::{Model, Solution, SolverOptions, StaticSolver};
use femu_study::error::Context;
use femu_study::model::StudyModel;
use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// A built model, unloaded.
#[pyclass(name = "Model", module = "femu._femu", frozen)]
pub struct PyModel {
    built: StudyModel,
    /// The study's description of it (for the model folder).
    spec: femu_study::schema::ModelSpec,
}

/// `parameters` (`{name: value}`, model units) as the parameters of `model` they name, every
/// name checked against the model's parameters and every value against its law's bounds.
fn checked_parameters(
    model: &Model,
    parameters: &[(String, f64)],
) -> PyResult<Vec<(Parameter, f64)>> {
    parameters
        .iter()
        .map(|(name, value)| {
            let p = Parameter::named(model, name).ok_or_else(|| {
                let known: Vec<String> = all_parameters(model)
                    .iter()
                    .map(|p| p.name(model))
                    .collect();
                errors::input(format!(
                    "unknown parameter '{name}' (parameters: {})",
                    known.join(", ")
                ))
            })?;
            if !p.spec().admits(*value) {
                return Err(errors::input(format!(
                    "parameter {name} = {value}: outside the range of {}, {}",
                    p.spec().name,
                    interval(p.spec().lower, p.spec().upper)
                )));
            }
            Ok((p, *value))
        })
        .collect()
}

/// A law parameter's range as an interval (`(0, 10000]`).
fn interval(lower: LawBound, upper: LawBound) -> String {
    let lo = match lower {
        LawBound::Open(v) => format!("({v}"),
        LawBound::Closed(v) => format!("[{v}"),
        LawBound::Unbounded => "(-inf".into(),
    };
    let hi = match upper {
        LawBound::Open(v) => format!("{v})"),
        LawBound::Closed(v) => format!("{v}]"),
        LawBound::Unbounded => "inf)".into(),
    };
    format!("{lo}, {hi}")
}

/// `built` loaded with `load`, the `parameters` set.
fn loaded(
    built: &StudyModel,
    load: &Loading,
    parameters: &[(Parameter, f64)],
) -> femu_study::error::Result<Model> {
    let mut model = built.loaded(load)?;
    for (p, v) in parameters {
        p.set(&mut model, *v);
    }
    Ok(model)
}

/// The `{name: value}` dict of a call as pairs.
fn parameter_pairs(parameters: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, f64)>> {
    let Some(d) = parameters else {
        return Ok(Vec::new());
    };
    d.iter()
        .map(|(k, v)| {
            let name: String = k
                .extract()
                .map_err(|_| errors::input(format!("parameter names are strings, got {k}")))?;
            let value: f64 = v
                .extract()
                .map_err(|_| errors::input(format!("parameter {name}: not a number: {v}")))?;
            Ok((name, value))
        })
        .collect()
}

/// The loading test `index` of `tests` (a study whose `[[test]]` entries describe it).
fn loading(tests: &PyStudy, index: usize) -> PyResult<Loading> {
    tests
        .study
        .tests
        .get(index)
        .map(|t| t.loading.clone())
        .ok_or_else(|| {
            errors::input(format!(
                "test {index}: the study has {} tests",
                tests.study.tests.len()
            ))
        })
}

/// `model` (loaded) solved; each increment is a note.
fn solve(
    model: &Model,
    progress: &dyn femu_study::Progress,
) -> femu_study::error::Result<Solution> {
    let mut solver = StaticSolver::new(model, SolverOptions::default())?;
    let solution = solver.solve_with(model, None, &mut |rec| {
        progress.note(&format!(
            "increment {:>3}: load factor {:.4}, {} Newton iterations{}",
            rec.increment,
            rec.lambda,
            rec.iterations.len(),
            rec.failure
                .as_ref()
                .map_or(String::new(), |f| format!(", cut back: {f}"))
        ))
    })?;
    Ok(solution)
}

impl PyModel {
    /// The loading test `test` of `tests` and the checked `parameters` of a solve.
    fn request(
        &self,
        tests: &PyStudy,
        test: usize,
        parameters: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<(Loading, Vec<(Parameter, f64)>)> {
        let load = loading(tests, test)?;
        let values = checked_parameters(&self.built.model, &parameter_pairs(parameters)?)?;
        Ok((load, values))
    }
}

#[pymethods]
impl PyModel {
    /// Reference node coordinates (mm), nodes x 2.
    #[getter]
    fn nodes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let m = &self.built.model.mesh;
        let v: Vec<f64> = m.nodes.iter().flatten().copied().collect();
        convert::array(py, v, &[m.nodes.len(), 2])
    }

    /// Element connectivity (node indices from 0), elements x 4; a triangle's fourth is -1.
    #[getter]
    fn elements<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let m = &self.built.model.mesh;
        let v: Vec<i64> = m
            .elements
            .iter()
            .flat_map(|e| (0..4).map(|k| e.nodes().get(k).map_or(-1, |&n| n as i64)))
            .collect();
        convert::int_array(py, v, &[m.elements.len(), 4])
    }

    /// The element type of each element (`CPE4`, `CPE4H`, `CPE3`).
    #[getter]
    fn element_types(&self) -> Vec<&'static str> {
        let m = &self.built.model.mesh;
        m.elements.iter().map(|e| e.kind.deck_name()).collect()
    }

    /// The region (index into `region_names`) of each element.
    #[getter]
    fn element_regions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let r = &self.built.model.element_region;
        convert::int_array(py, r.iter().map(|&k| k as i64).collect(), &[r.len()])
    }

    #[getter]
    fn region_names(&self) -> Vec<String> {
        self.built.model.region_names.clone()
    }

    /// The skin faces the loading tests act on, as (element, face) pairs (face 0 joins local
    /// nodes 1 and 2, the deck's `P1`).
    #[getter]
    fn skin<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let s = &self.built.skin;
        let v: Vec<i64> = s.iter().flat_map(|&(e, f)| [e as i64, f as i64]).collect();
        convert::int_array(py, v, &[s.len(), 2])
    }

    /// Where the model comes from (`parametric thigh`, `label image ...`, `deck ...`).
    #[getter]
    fn source(&self) -> String {
        self.built.source.clone()
    }

    /// Every material parameter: `(name, value, unit, law parameter, material)` in model
    /// units (C10 in MPa, D in MPa⁻¹), in the order of the sensitivities.
    fn parameters(&self) -> Vec<(String, f64, String, String, String)> {
        let m = &self.built.model;
        all_parameters(m)
            .iter()
            .map(|p| {
                (
                    p.name(m),
                    p.value(m),
                    format!("{:?}", p.spec().unit),
                    p.spec().name.to_string(),
                    m.materials[p.material].name.clone(),
                )
            })
            .collect()
    }

    /// Solves test `test` of `tests` (a study's `[[test]]` list) with `parameters` (`{name:
    /// value}`, model units) over the model's own; returns the arrays and reports as a dict.
    #[pyo3(signature = (tests, test = 0, parameters = None, reporter = None))]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        tests: PyRef<'_, PyStudy>,
        test: usize,
        parameters: Option<&Bound<'py, PyDict>>,
        reporter: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (load, values) = self.request(&tests, test, parameters)?;
        let built = &self.built;
        let (model, solution, fields) = running::run(py, reporter.as_ref(), |progress| {
            let model = loaded(built, &load, &values)?;
            let solution = solve(&model, progress)?;
            let fields = femu_mech::output::element_fields(&model, &solution.u);
            Ok((model, solution, fields))
        })?;
        let (n, e) = (model.node_count(), model.mesh.elements.len());
        let d = PyDict::new(py);
        d.set_item("test", load.name())?;
        d.set_item("u", convert::array(py, solution.u.clone(), &[n, 2])?)?;
        d.set_item(
            "reactions",
            convert::array(py, solution.reactions[..2 * n].to_vec(), &[n, 2])?,
        )?;
        let flat4 = |v: &[[f64; 4]]| v.iter().flatten().copied().collect::<Vec<f64>>();
        d.set_item(
            "log_strain",
            convert::array(py, flat4(&fields.log_strain), &[e, 4])?,
        )?;
        d.set_item(
            "stress",
            convert::array(py, flat4(&fields.cauchy_stress), &[e, 4])?,
        )?;
        d.set_item(
            "volume_ratio",
            convert::array(py, fields.volume_ratio.clone(), &[e])?,
        )?;
        d.set_item("bodies", convert::json(&solution.bodies)?)?;
        d.set_item("report", convert::json(&solution.report)?)?;
        Ok(d)
    }

    /// The exact sensitivities of test `test` of `tests` to every material parameter at
    /// `parameters` (direct differentiation, one back-substitution per parameter with the
    /// tangent of the solve): `du` (nodes x 2 x parameters, mm per model unit), the seed's Eq. 3
    /// maps and indices, and the solution.
    #[pyo3(signature = (tests, test = 0, parameters = None, reporter = None))]
    fn sensitivities<'py>(
        &self,
        py: Python<'py>,
        tests: PyRef<'_, PyStudy>,
        test: usize,
        parameters: Option<&Bound<'py, PyDict>>,
        reporter: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (load, values) = self.request(&tests, test, parameters)?;
        let built = &self.built;
        let (model, solution, params, dstate, report) =
            running::run(py, reporter.as_ref(), |progress| {
                let model = loaded(built, &load, &values)?;
                let mut solver = StaticSolver::new(&model, SolverOptions::default())?;
                let solution = solver
                    .solve(&model)
                    .with_context(|| format!("test {}", load.name()))?;
                progress.check()?;
                let params = all_parameters(&model);
                let mut dstate = Vec::new();
                let report = DirectSensitivity::new()
                    .compute(&mut solver, &model, &solution.state, &params, &mut dstate)
                    .with_context(|| format!("test {}", load.name()))?;
                Ok((model, solution, params, dstate, report))
            })?;
        let n = model.node_count();
        let p = params.len();
        let mut du = vec![0.0; 2 * n * p];
        let mut maps = vec![0.0; n * p];
        let mut index = Vec::with_capacity(p);
        for (k, (param, d)) in params.iter().zip(&dstate).enumerate() {
            for i in 0..2 * n {
                du[i * p + k] = d[i];
            }
            let (global, map) = sensitivity_map(&solution.u, &d[..2 * n], param.value(&model));
            for (i, s) in map.iter().enumerate() {
                maps[i * p + k] = *s;
            }
            index.push(global);
        }
        let d = PyDict::new(py);
        d.set_item("test", load.name())?;
        d.set_item(
            "names",
            params.iter().map(|q| q.name(&model)).collect::<Vec<_>>(),
        )?;
        d.set_item(
            "values",
            params.iter().map(|q| q.value(&model)).collect::<Vec<_>>(),
        )?;
        d.set_item("u", convert::array(py, solution.u.clone(), &[n, 2])?)?;
        d.set_item("du", convert::array(py, du, &[n, 2, p])?)?;
        d.set_item("maps", convert::array(py, maps, &[n, p])?)?;
        d.set_item("index", index)?;
        d.set_item("newton_iterations", solution.report.newton_iterations)?;
        d.set_item("report", convert::json(&report)?)?;
        Ok(d)
    }

    /// Writes the model folder of `femu run` (`mesh.inp`, `mesh.vtu`, `regions.png`,
    /// `quality.csv`, `summary.json`) into `out`; returns its summary (JSON text).
    fn write(&self, py: Python<'_>, out: PathBuf) -> PyResult<String> {
        let spec = &self.spec;
        let built = &self.built;
        running::run(py, None, |progress| {
            femu_study::steps::model::write_study_model(
                built,
                &spec.geometry,
                spec.element.kind(),
                &out,
                0.0,
                progress,
            )?;
            convert::read_typed::<femu_study::report::ModelSummary>(&out.join("summary.json"))
        })
    }

    fn __repr__(&self) -> String {
        let m = &self.built.model;
        format!(
            "femu.Model({}: {} nodes, {} elements, regions {})",
            self.built.source,
            m.node_count(),
            m.mesh.elements.len(),
            m.region_names.join(", ")
        )
    }
}

/// The model of `study` (a `[labels]` geometry) meshed from `labels`, a label image as an
/// integer array (row 0 at the top, as an image is stored).
#[pyfunction]
pub fn model_from_label_array(
    py: Python<'_>,
    study: PyRef<'_, PyStudy>,
    labels: &Bound<'_, PyAny>,
) -> PyResult<PyModel> {
    let np = py.import("numpy")?;
    let a = np.call_method1("ascontiguousarray", (labels,))?;
    let kind: String = a.getattr("dtype")?.getattr("kind")?.extract()?;
    if kind != "u" && kind != "i" {
        return Err(errors::input(format!(
            "labels: expected an integer array (one label per pixel), got dtype {}",
            a.getattr("dtype")?
        )));
    }
    let a = np.call_method1("ascontiguousarray", (a, "int64"))?;
    let arr: PyReadonlyArray2<'_, i64> = a
        .extract()
        .map_err(|_| errors::input("labels: expected a two-dimensional array (rows x columns)"))?;
    let [h, w] = [arr.shape()[0], arr.shape()[1]];
    let values = arr.as_slice()?;
    if let Some(k) = values.iter().position(|&v| v < 0 || v > u32::MAX as i64) {
        return Err(errors::input(format!(
            "labels: pixel (row {}, column {}) holds {}, not a label (0 to 4294967295)",
            k / w.max(1),
            k % w.max(1),
            values[k]
        )));
    }
    let rows: Vec<u32> = values.iter().map(|&v| v as u32).collect();
    if w == 0 || h == 0 {
        return Err(errors::input("labels: the image is empty"));
    }
    let img = femu_geometry::LabelImage::from_rows_top_down(w, h, &rows);
    let spec = study.study.model.clone();
    let built = running::run(py, None, |_| {
        femu_study::model::build_from_label_image(&spec, &img)
    })?;
    Ok(PyModel { built, spec })
}

/// The model `study` describes (mesh and materials, no load), built as `femu run` builds it.
#[pyfunction]
#[pyo3(signature = (study, reporter = None))]
pub fn model_of_study(
    py: Python<'_>,
    study: PyRef<'_, PyStudy>,
    reporter: Option<Bound<'_, PyAny>>,
) -> PyResult<PyModel> {
    let spec = study.study.model.clone();
    let built = running::run(py, reporter.as_ref(), |_| femu_study::model::build(&spec))?;
    Ok(PyModel { built, spec })
}
