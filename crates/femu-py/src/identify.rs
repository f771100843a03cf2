//! Identification from a measured field given as arrays (`femu identify --measured CSV` on the
//! same points), and `femu.LeastSquares`: the weighted residual `r(φ)` of the field in
//! log-parameters `φ = ln θ` and its exact Jacobian `∂r/∂φ` — `femu_identify::fit::Problem`,
//! what femu's own optimizers minimize (`½|r|²`) — for SciPy's `least_squares` or any other
//! optimizer.

use crate::convert;
use crate::errors::{self, IntoPy};
use crate::running;
use crate::study::PyStudy;
use femu_identify::fit::{
    levenberg_marquardt, Columns, FreeParameter, LeastSquares, LmOptions, Problem,
};
use femu_identify::measured::{MeasuredField, MeasuredPoint};
use femu_mech::SolverOptions;
use femu_study::schema::MeasurementSource;
use femu_study::steps::identify;
use femu_study::steps::measure;
use femu_study::steps::measure::{MeasureInputs, Measured};
use femu_study::steps::parameters::IdentificationInputs;
use pyo3::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// How the points of a field are weighted: standard deviations `sx, sy` (mm), a weight `w`,
/// or `weights` per component (points x 2, the inverse variances femu keeps).
#[derive(Default)]
struct WeightArgs<'a, 'py> {
    sx: Option<&'a Bound<'py, PyAny>>,
    sy: Option<&'a Bound<'py, PyAny>>,
    w: Option<&'a Bound<'py, PyAny>>,
    weights: Option<&'a Bound<'py, PyAny>>,
}

/// A measured field from columns (conventions.md: `x, y, ux, uy` in mm in the model frame,
/// weighted as the CSV's `sx, sy` or `w`, or by per-component `weights`).
fn measured_field(
    x: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    ux: &Bound<'_, PyAny>,
    uy: &Bound<'_, PyAny>,
    weighting: WeightArgs<'_, '_>,
) -> PyResult<MeasuredField> {
    let WeightArgs { sx, sy, w, weights } = weighting;
    let cols = [
        convert::floats(x, "x")?,
        convert::floats(y, "y")?,
        convert::floats(ux, "ux")?,
        convert::floats(uy, "uy")?,
    ];
    let n = cols[0].len();
    let same = |v: &[f64], name: &str| -> PyResult<()> {
        if v.len() != n {
            return Err(errors::input(format!(
                "{name} has {} values, x has {n}",
                v.len()
            )));
        }
        Ok(())
    };
    for (v, name) in cols.iter().zip(["x", "y", "ux", "uy"]) {
        same(v, name)?;
    }
    if n == 0 {
        return Err(errors::input("the measured field has no point"));
    }
    if weights.is_some() && (sx.is_some() || sy.is_some() || w.is_some()) {
        return Err(errors::input(
            "give weights alone, or sx, sy and w (w multiplies 1/sx², 1/sy²)",
        ));
    }
    if let Some(wts) = weights {
        let flat = convert::floats(&wts.call_method0("ravel")?, "weights")?;
        if flat.len() != 2 * n {
            return Err(errors::input(format!(
                "weights: expected {n} x 2 values (one per component), got {}",
                flat.len()
            )));
        }
        if let Some(k) = flat.iter().position(|v| !(*v >= 0.0)) {
            return Err(errors::input(format!(
                "weights: point {}: must be non-negative, got {}",
                k / 2,
                flat[k]
            )));
        }
        return Ok(field_of(&cols, |k| [flat[2 * k], flat[2 * k + 1]]));
    }
    // `w` multiplies the inverse variances (1 without sx, sy), as in a measured-field CSV:
    // `w = 0` leaves a point out.
    let w = match w {
        Some(w) => {
            let w = convert::floats(w, "w")?;
            same(&w, "w")?;
            if let Some(k) = w.iter().position(|v| !(*v >= 0.0)) {
                return Err(errors::input(format!(
                    "point {k}: w must be non-negative, got {}",
                    w[k]
                )));
            }
            Some(w)
        }
        None => None,
    };
    let wk = |k: usize| w.as_ref().map_or(1.0, |w| w[k]);
    let weights: Vec<[f64; 2]> = match (sx, sy) {
        (Some(sx), Some(sy)) => {
            let (sx, sy) = (convert::floats(sx, "sx")?, convert::floats(sy, "sy")?);
            same(&sx, "sx")?;
            same(&sy, "sy")?;
            if let Some(k) = (0..n).find(|&k| !(sx[k] > 0.0 && sy[k] > 0.0)) {
                return Err(errors::input(format!(
                    "point {k}: sx, sy must be positive, got {}, {}",
                    sx[k], sy[k]
                )));
            }
            (0..n)
                .map(|k| [wk(k) / (sx[k] * sx[k]), wk(k) / (sy[k] * sy[k])])
                .collect()
        }
        (Some(_), None) | (None, Some(_)) => return Err(errors::input("sx and sy go together")),
        (None, None) => (0..n).map(|k| [wk(k), wk(k)]).collect(),
    };
    Ok(field_of(&cols, |k| weights[k]))
}

/// The field of columns `x, y, ux, uy` with the weights of point `k` from `weight`.
fn field_of(cols: &[Vec<f64>; 4], weight: impl Fn(usize) -> [f64; 2]) -> MeasuredField {
    MeasuredField {
        points: (0..cols[0].len())
            .map(|k| MeasuredPoint {
                x: [cols[0][k], cols[1][k]],
                u: [cols[2][k], cols[3][k]],
                weight: weight(k),
            })
            .collect(),
        comments: vec![],
    }
}

/// A field's columns: `x, y, ux, uy` and the weights (points x 2).
type FieldColumns = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<[f64; 2]>);

fn columns(field: &MeasuredField) -> FieldColumns {
    let col = |f: &dyn Fn(&MeasuredPoint) -> f64| field.points.iter().map(f).collect();
    (
        col(&|p| p.x[0]),
        col(&|p| p.x[1]),
        col(&|p| p.u[0]),
        col(&|p| p.u[1]),
        field.points.iter().map(|p| p.weight).collect(),
    )
}

/// A measured-field CSV (conventions.md) as femu reads it: columns and weights.
#[pyfunction]
pub fn read_field(path: PathBuf) -> PyResult<FieldColumns> {
    Ok(columns(&MeasuredField::read(&path).py_err()?))
}

/// The identification of `study` (its free parameters, groups, optimizer, starts) from the
/// field `x, y, ux, uy` (mm, model frame; `sx, sy` or `w` weight it) into `out`, as `femu
/// identify STUDY --measured CSV` runs it; returns `summary.json` (JSON text).
#[pyfunction]
#[pyo3(signature = (study, x, y, ux, uy, out, *, sx = None, sy = None, w = None, weights = None, grouped = None, source = None, reporter = None))]
#[allow(clippy::too_many_arguments)]
pub fn identify_field(
    py: Python<'_>,
    study: PyRef<'_, PyStudy>,
    x: &Bound<'_, PyAny>,
    y: &Bound<'_, PyAny>,
    ux: &Bound<'_, PyAny>,
    uy: &Bound<'_, PyAny>,
    out: PathBuf,
    sx: Option<&Bound<'_, PyAny>>,
    sy: Option<&Bound<'_, PyAny>>,
    w: Option<&Bound<'_, PyAny>>,
    weights: Option<&Bound<'_, PyAny>>,
    grouped: Option<bool>,
    source: Option<String>,
    reporter: Option<Bound<'_, PyAny>>,
) -> PyResult<String> {
    let weighting = WeightArgs { sx, sy, w, weights };
    let field = measured_field(x, y, ux, uy, weighting)?;
    let source = source.unwrap_or_else(|| "NumPy arrays (x, y, ux, uy)".into());
    let measured = Measured::plain(field, source.clone());
    let study = &study.study;
    let summary = running::run(py, reporter.as_ref(), |progress| {
        let built = femu_study::model::build(&study.model)?;
        let prepared =
            identify::measured_prepared(&study.measurements, &study.tests, measured, &source)?;
        let grouped = grouped.unwrap_or(study.identification.grouped());
        let inputs = IdentificationInputs::of(study);
        identify::identify_on(&inputs, grouped, &built, &prepared, &out, progress)
    })?;
    convert::json(&summary)
}

/// The study's measurements as the identification fits them in its first repeat (`femu
/// synth`: a virtual one is its test at the reference parameters on its points plus the seeded
/// noise), each as its name, columns and weights.
#[pyfunction]
pub fn virtual_field(
    py: Python<'_>,
    study: PyRef<'_, PyStudy>,
) -> PyResult<Vec<(String, FieldColumns)>> {
    let study = &study.study;
    running::run(py, None, |progress| {
        let built = femu_study::model::build(&study.model)?;
        no_ultrasound(study)?;
        // Only an ultrasound measurement writes into the folder, and there is none.
        let prepared =
            measure::prepare(&MeasureInputs::of(study), &built, Path::new("."), progress)?;
        let fields = femu_study::steps::joint::realized(
            &IdentificationInputs::of(study),
            &built,
            &prepared,
        )?;
        Ok(fields
            .into_iter()
            .map(|(p, points)| {
                let field = MeasuredField {
                    points,
                    comments: vec![],
                };
                (p.name.clone(), columns(&field))
            })
            .collect())
    })
}

/// Refuses a study whose measurements simulate ultrasound images (a whole run's work).
fn no_ultrasound(study: &femu_study::schema::Study) -> femu_study::error::Result<()> {
    if study
        .measurements
        .iter()
        .any(|m| m.source == MeasurementSource::Ultrasound)
    {
        femu_study::bail!(
            "[measurement] source = \"ultrasound\": the images are simulated by Study.run or `femu us-sim`; give its measured.csv as a Field"
        );
    }
    Ok(())
}

/// The last evaluation, kept for the Jacobian SciPy asks for at the point it just evaluated.
struct Cached {
    phi: Vec<f64>,
    r: Vec<f64>,
    j: Columns,
}

struct State {
    problem: Problem,
    cached: Option<Cached>,
}

/// femu's weighted least-squares problem on a measured field: residuals `√w (u_model(θ) −
/// u_measured)` at the measured points in the tissue, parameters `φ = ln θ` (see the module
/// documentation).
#[pyclass(name = "LeastSquares", module = "femu._femu", frozen)]
pub struct PyLeastSquares {
    state: Mutex<State>,
    free: Vec<FreeParameter>,
    reference: Vec<f64>,
}

/// The problem of `study` on the field `x, y, ux, uy` (weighted by `sx, sy` or `w`), or on
/// the study's virtual measurement when no field is given; `grouped`: tie the study's groups
/// (default: as the study's identification).
#[pyfunction]
#[pyo3(signature = (study, x = None, y = None, ux = None, uy = None, *, sx = None, sy = None, w = None, weights = None, grouped = None))]
#[allow(clippy::too_many_arguments)]
pub fn least_squares(
    py: Python<'_>,
    study: PyRef<'_, PyStudy>,
    x: Option<&Bound<'_, PyAny>>,
    y: Option<&Bound<'_, PyAny>>,
    ux: Option<&Bound<'_, PyAny>>,
    uy: Option<&Bound<'_, PyAny>>,
    sx: Option<&Bound<'_, PyAny>>,
    sy: Option<&Bound<'_, PyAny>>,
    w: Option<&Bound<'_, PyAny>>,
    weights: Option<&Bound<'_, PyAny>>,
    grouped: Option<bool>,
) -> PyResult<PyLeastSquares> {
    let weighting = WeightArgs { sx, sy, w, weights };
    let field = match (x, y, ux, uy) {
        (Some(x), Some(y), Some(ux), Some(uy)) => Some(measured_field(x, y, ux, uy, weighting)?),
        (None, None, None, None) => None,
        _ => {
            return Err(errors::input(
                "give all of x, y, ux, uy, or none (the virtual measurement)",
            ))
        }
    };
    let study = &study.study;
    let (problem, free, reference) = running::run(py, None, |progress| {
        let built = femu_study::model::build(&study.model)?;
        let prepared = match field {
            Some(f) => {
                let measured = Measured::plain(f, "NumPy arrays (x, y, ux, uy)".into());
                identify::measured_prepared(
                    &study.measurements,
                    &study.tests,
                    measured,
                    "NumPy arrays",
                )?
            }
            None => {
                no_ultrasound(study)?;
                if study.measurements.len() > 1 {
                    femu_study::bail!(
                        "the study has {} measurements: LeastSquares fits one field (give it as arrays)",
                        study.measurements.len()
                    );
                }
                measure::prepare(&MeasureInputs::of(study), &built, Path::new("."), progress)?
            }
        };
        let inputs = IdentificationInputs::of(study);
        let (p, points) = femu_study::steps::joint::realized(&inputs, &built, &prepared)?
            .pop()
            .expect("one measurement");
        let model = built.loaded(&study.tests[p.test].loading)?;
        let grouped = grouped.unwrap_or(study.identification.grouped());
        let (free, reference) = inputs.free_parameters(&model, grouped)?;
        let field = MeasuredField {
            points,
            comments: vec![],
        };
        let mut problem = Problem::new(model, SolverOptions::default(), &field, free.clone())?;
        if let Some(t) = p.travel {
            let Some(measured) = t.measured_mm else {
                femu_study::bail!(
                    "[measurement] travel_sigma_mm without travel_mm: the virtual experiment's travel is drawn per repeat inside femu's identification; give travel_mm to use the actuator term here"
                );
            };
            problem = problem.with_travel(measured, t.sigma_mm)?;
        }
        Ok((problem, free, reference))
    })?;
    Ok(PyLeastSquares {
        state: Mutex::new(State {
            problem,
            cached: None,
        }),
        free,
        reference,
    })
}

impl PyLeastSquares {
    /// The residual and Jacobian at `phi`: the cached ones if `phi` was the last point, else a
    /// forward solve and its sensitivities (without the GIL; Ctrl-C is checked before and after).
    fn at<T: Send>(
        &self,
        py: Python<'_>,
        phi: Vec<f64>,
        take: impl FnOnce(&Cached) -> T + Send,
    ) -> PyResult<T> {
        if phi.len() != self.free.len() {
            return Err(errors::input(format!(
                "phi has {} values for {} free parameters ({})",
                phi.len(),
                self.free.len(),
                self.names().join(", ")
            )));
        }
        if let Some(k) = phi.iter().position(|v| !v.is_finite()) {
            return Err(errors::input(format!("phi[{k}] is not finite")));
        }
        py.check_signals()?;
        let out = py.detach(|| -> femu_study::error::Result<T> {
            let mut state = self.state.lock().unwrap_or_else(|p| p.into_inner());
            let hit = state.cached.as_ref().is_some_and(|c| c.phi == phi);
            if !hit {
                state.cached = None;
                let (r, j) = state.problem.evaluate(&phi, true)?;
                state.cached = Some(Cached {
                    phi,
                    r,
                    j: j.expect("asked for the Jacobian"),
                });
            }
            Ok(take(state.cached.as_ref().expect("evaluated")))
        });
        py.check_signals()?;
        out.py_err()
    }

    fn names(&self) -> Vec<String> {
        self.free.iter().map(|f| f.name.clone()).collect()
    }
}

#[pymethods]
impl PyLeastSquares {
    /// The free parameters' names (`C10_FAT`, `D_ISCHIO+D_SARTORIUS+D_GRACILIS`, ...).
    #[getter(names)]
    fn py_names(&self) -> Vec<String> {
        self.names()
    }

    /// Lower bounds (model units: C10 in MPa, D in MPa⁻¹).
    #[getter]
    fn lower(&self) -> Vec<f64> {
        self.free.iter().map(|f| f.lower).collect()
    }

    /// Upper bounds (model units).
    #[getter]
    fn upper(&self) -> Vec<f64> {
        self.free.iter().map(|f| f.upper).collect()
    }

    /// The study's (reference) values of the free parameters (model units).
    #[getter]
    fn reference(&self) -> Vec<f64> {
        self.reference.clone()
    }

    /// Measured points inside the tissue, and masked ones.
    #[getter]
    fn points(&self) -> (usize, usize) {
        let state = self.state.lock().unwrap_or_else(|p| p.into_inner());
        state.problem.points()
    }

    /// Forward solves and Jacobian evaluations so far.
    #[getter]
    fn counts(&self) -> (usize, usize) {
        let state = self.state.lock().unwrap_or_else(|p| p.into_inner());
        state.problem.counts()
    }

    /// The weighted residuals at `phi` (log-parameters), a NumPy array that owns a copy of
    /// the kept ones (moved into NumPy, not converted number by number).
    fn residual<'py>(&self, py: Python<'py>, phi: Vec<f64>) -> PyResult<Bound<'py, PyAny>> {
        let r = self.at(py, phi, |c| c.r.clone())?;
        let m = r.len();
        convert::array(py, r, &[m])
    }

    /// The Jacobian `∂r/∂φ` at `phi`, a NumPy array residuals x parameters.
    fn jacobian<'py>(&self, py: Python<'py>, phi: Vec<f64>) -> PyResult<Bound<'py, PyAny>> {
        let (flat, m, n) = self.at(py, phi, |c| {
            let (m, n) = (c.r.len(), c.j.len());
            let mut flat = vec![0.0; m * n];
            for (k, col) in c.j.iter().enumerate() {
                for (i, v) in col.iter().enumerate() {
                    flat[i * n + k] = *v;
                }
            }
            (flat, m, n)
        })?;
        convert::array(py, flat, &[m, n])
    }

    /// femu's Levenberg–Marquardt from `start` (model units; default the reference), as each
    /// start of an identification runs it; returns its `FitResult` (JSON text).
    #[pyo3(signature = (start = None))]
    fn levenberg_marquardt(&self, py: Python<'_>, start: Option<Vec<f64>>) -> PyResult<String> {
        let start = start.unwrap_or_else(|| self.reference.clone());
        let result = running::run(py, None, |_| {
            let mut state = self.state.lock().unwrap_or_else(|p| p.into_inner());
            state.cached = None;
            Ok(levenberg_marquardt(
                &mut state.problem,
                &start,
                &LmOptions::default(),
            )?)
        })?;
        convert::json(&result)
    }
}
