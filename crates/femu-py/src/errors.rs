//! femu's errors as Python exceptions: one class per kind of failure, each message exactly the
//! text the command line prints after `error: ` (the file, line, key or element at fault).
//!
//! ```text
//! FemuError                 every femu failure (Exception)
//! ├── StudyError            a study file or dict: unknown key, value out of range, wrong unit (key and line)
//! ├── InputError            a deck, mesh, image, label image, measured field or argument that cannot be used
//! ├── SolveError            a forward solve that did not converge (with its diagnostics)
//! ├── DicError              a correlation that cannot run (images, region of interest, options)
//! └── IdentificationError   an identification that cannot run or whose every start failed
//! ```
//! An interrupted computation raises `KeyboardInterrupt`.

use pyo3::exceptions::{PyException, PyKeyboardInterrupt};
use pyo3::prelude::*;

pyo3::create_exception!(
    femu,
    FemuError,
    PyException,
    "A femu computation failed; the message names the file, line, key or element at fault."
);
pyo3::create_exception!(
    femu,
    StudyError,
    FemuError,
    "A study (file or dict) that cannot be used: the message names the key and its line."
);
pyo3::create_exception!(
    femu,
    InputError,
    FemuError,
    "A deck, mesh, image, label image, measured field or argument that cannot be used."
);
pyo3::create_exception!(
    femu,
    SolveError,
    FemuError,
    "A forward solve that did not converge (Newton diagnostics in the message)."
);
pyo3::create_exception!(
    femu,
    DicError,
    FemuError,
    "A digital image correlation that cannot run (images, region of interest, options)."
);
pyo3::create_exception!(
    femu,
    IdentificationError,
    FemuError,
    "An identification that cannot run (parameters, data) or whose every start failed."
);

/// Registers the exception classes in the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("FemuError", py.get_type::<FemuError>())?;
    m.add("StudyError", py.get_type::<StudyError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("SolveError", py.get_type::<SolveError>())?;
    m.add("DicError", py.get_type::<DicError>())?;
    m.add("IdentificationError", py.get_type::<IdentificationError>())?;
    Ok(())
}

/// The kind of a failure, from the first typed error of its chain (outermost first).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Study,
    Input,
    Solve,
    Dic,
    Identification,
    Interrupted,
    Other,
}

/// The kind of `e`.
pub fn kind(e: &anyhow::Error) -> Kind {
    if femu_study::progress::is_interrupted(e) {
        return Kind::Interrupted;
    }
    for cause in e.chain() {
        let is = |k: Kind| Some(k);
        let found = if cause.is::<femu_study::StudyError>() {
            is(Kind::Study)
        } else if cause.is::<femu_mech::SolveError>() {
            is(Kind::Solve)
        } else if cause.is::<femu_dic::error::DicError>() {
            is(Kind::Dic)
        } else if cause.is::<femu_identify::fit::FitError>()
            || cause.is::<femu_identify::campaign::CampaignError>()
            || cause.is::<femu_identify::fisher::FisherError>()
        {
            match cause.downcast_ref::<femu_identify::fit::FitError>() {
                Some(femu_identify::fit::FitError::Interrupted) => is(Kind::Interrupted),
                _ => is(Kind::Identification),
            }
        } else if cause.is::<femu_identify::measured::MeasuredError>()
            || cause.is::<femu_mesh::inp::InpError>()
            || cause.is::<femu_mesh::msh::MshError>()
            || cause.is::<femu_mesh::mesh::MeshError>()
            || cause.is::<femu_geometry::GeometryError>()
            || cause.is::<femu_mech::ModelError>()
            || cause.is::<femu_mech::material::MaterialError>()
            || cause.is::<femu_mech::loading::LoadingError>()
            || cause.is::<std::io::Error>()
        {
            is(Kind::Input)
        } else {
            None
        };
        if let Some(k) = found {
            return k;
        }
    }
    Kind::Other
}

/// `e` as the Python exception of its kind, with the command line's message.
pub fn to_py(e: anyhow::Error) -> PyErr {
    let message = format!("{e:#}");
    match kind(&e) {
        Kind::Study => StudyError::new_err(message),
        Kind::Input => InputError::new_err(message),
        Kind::Solve => SolveError::new_err(message),
        Kind::Dic => DicError::new_err(message),
        Kind::Identification => IdentificationError::new_err(message),
        Kind::Interrupted => {
            PyKeyboardInterrupt::new_err(format!("{message}; what was finished is kept"))
        }
        Kind::Other => FemuError::new_err(message),
    }
}

/// A bad argument of a Python call (not from a file): an [`InputError`] with `message`.
pub fn input(message: impl Into<String>) -> PyErr {
    InputError::new_err(message.into())
}

/// `Result<T, anyhow::Error>` into a `PyResult<T>`.
pub trait IntoPy<T> {
    fn py_err(self) -> PyResult<T>;
}

impl<T, E: Into<anyhow::Error>> IntoPy<T> for Result<T, E> {
    fn py_err(self) -> PyResult<T> {
        self.map_err(|e| to_py(e.into()))
    }
}
