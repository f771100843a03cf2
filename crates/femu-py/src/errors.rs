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

/// `e` as the Python exception of its kind ([`femu_study::Error::kind`]), with the command
/// line's message. A computation that ends after a stop request is an interruption, also when
/// a part of it reports the stop as its own failure.
pub fn to_py(e: femu_study::Error) -> PyErr {
    use femu_study::ErrorKind;
    let message = e.chain();
    let kind = if femu_study::progress::is_interrupted(&e) {
        ErrorKind::Interrupted
    } else {
        e.kind()
    };
    match kind {
        ErrorKind::Study => StudyError::new_err(message),
        ErrorKind::Input => InputError::new_err(message),
        ErrorKind::Solve => SolveError::new_err(message),
        ErrorKind::Dic => DicError::new_err(message),
        ErrorKind::Identification => IdentificationError::new_err(message),
        ErrorKind::Interrupted => {
            PyKeyboardInterrupt::new_err(format!("{message}; what was finished is kept"))
        }
        ErrorKind::Other => FemuError::new_err(message),
    }
}

/// A bad argument of a Python call (not from a file): an [`InputError`] with `message`.
pub fn input(message: impl Into<String>) -> PyErr {
    InputError::new_err(message.into())
}

/// A femu result into a `PyResult<T>`: femu-study's errors, and the errors of the computing
/// crates (each of which femu-study's error holds as its own kind).
pub trait IntoPy<T> {
    fn py_err(self) -> PyResult<T>;
}

impl<T, E: Into<femu_study::Error>> IntoPy<T> for Result<T, E> {
    fn py_err(self) -> PyResult<T> {
        self.map_err(|e| to_py(e.into()))
    }
}
