//! `femu._femu`, the extension module of the `femu` Python package: femu's Rust libraries
//! called from Python with NumPy arrays in and out. No numerics here or in the Python side:
//! every number comes from the same library functions the `femu` command calls.
//!
//! Its modules (private: Python sees only what they register):
//!
//! - [`study`]: `Study` (a study file, TOML text, dict or the demo's study, checked by
//!   `femu_study::schema`), its run (`femu run`) and steps, the typed summaries of a run folder;
//! - [`model`]: `Model` (built-in thigh, label image from an array, deck): mesh arrays, forward
//!   solves, exact sensitivities;
//! - [`dic`]: `femu dic` on NumPy images or files, the field and its covariance;
//! - [`identify`]: the identification from a field given as arrays, and `LeastSquares`, femu's
//!   residual and exact Jacobian for SciPy;
//! - [`running`]: long calls without the GIL, with progress and Ctrl-C;
//! - [`errors`]: femu's errors as Python exceptions with the command line's messages;
//! - [`convert`]: dicts to study TOML, summaries to JSON, vectors to arrays.
//!
//! The Python side (`python/femu/`) turns the JSON summaries into dataclasses, draws progress
//! with tqdm and converts meshes for PyVista and meshio.

// The list above is for the crate's developers (`cargo doc --document-private-items`).
#![allow(rustdoc::private_intra_doc_links)]

mod convert;
mod dic;
mod errors;
mod identify;
mod model;
mod running;
mod study;

use pyo3::prelude::*;

/// The extension module.
#[pymodule]
fn _femu(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    m.add_class::<study::PyStudy>()?;
    m.add_class::<model::PyModel>()?;
    m.add_class::<identify::PyLeastSquares>()?;
    m.add_function(wrap_pyfunction!(study::read_run, m)?)?;
    m.add_function(wrap_pyfunction!(model::model_from_label_array, m)?)?;
    m.add_function(wrap_pyfunction!(model::model_of_study, m)?)?;
    m.add_function(wrap_pyfunction!(dic::dic, m)?)?;
    m.add_function(wrap_pyfunction!(dic::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(identify::identify_field, m)?)?;
    m.add_function(wrap_pyfunction!(identify::virtual_field, m)?)?;
    m.add_function(wrap_pyfunction!(identify::read_field, m)?)?;
    m.add_function(wrap_pyfunction!(identify::least_squares, m)?)?;
    Ok(())
}
