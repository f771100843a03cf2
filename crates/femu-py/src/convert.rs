//! Values between Python and femu: dicts into study TOML (so that a dict goes through the one
//! study schema, `femu_study::schema`), femu's typed summaries out as JSON text (read into the
//! mirror dataclasses of `python/femu/results.py`), and flat vectors out as NumPy arrays.

use crate::errors;
use femu_study::error::Context;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use std::path::Path;

/// A Python value as a TOML value; `at` names it in errors (`model.elements`).
pub fn toml_value(obj: &Bound<'_, PyAny>, at: &str) -> PyResult<toml::Value> {
    if obj.is_none() {
        return Err(errors::StudyError::new_err(format!(
            "{at}: None is not a value (leave the key out for its default)"
        )));
    }
    if obj.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(obj.extract()?));
    }
    if obj.is_instance_of::<PyInt>() {
        return Ok(toml::Value::Integer(obj.extract().map_err(|_| {
            errors::StudyError::new_err(format!("{at}: integer out of range"))
        })?));
    }
    if obj.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(obj.extract()?));
    }
    if obj.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(obj.extract()?));
    }
    if let Ok(d) = obj.cast::<PyDict>() {
        return Ok(toml::Value::Table(toml_table(d, at)?));
    }
    if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        let items: PyResult<Vec<toml::Value>> = obj
            .try_iter()?
            .enumerate()
            .map(|(k, item)| toml_value(&item?, &format!("{at}[{k}]")))
            .collect();
        return Ok(toml::Value::Array(items?));
    }
    // Paths (os.PathLike), NumPy scalars and arrays.
    if obj.hasattr("__fspath__")? {
        let path = obj.call_method0("__fspath__")?;
        return Ok(toml::Value::String(path.str()?.to_string()));
    }
    if obj.hasattr("tolist")? {
        return toml_value(&obj.call_method0("tolist")?, at);
    }
    if obj.hasattr("__index__")? {
        return Ok(toml::Value::Integer(
            obj.call_method0("__index__")?.extract()?,
        ));
    }
    if obj.hasattr("__float__")? {
        return Ok(toml::Value::Float(
            obj.call_method0("__float__")?.extract()?,
        ));
    }
    Err(errors::StudyError::new_err(format!(
        "{at}: a {} cannot be written in a study (use numbers, strings, booleans, lists and dicts)",
        obj.get_type().name()?
    )))
}

/// A Python dict as a TOML table.
pub fn toml_table(d: &Bound<'_, PyDict>, at: &str) -> PyResult<toml::Table> {
    let mut table = toml::Table::new();
    for (k, v) in d.iter() {
        let key: String = k.extract().map_err(|_| {
            errors::StudyError::new_err(format!("{at}: keys must be strings, got {k}"))
        })?;
        let here = if at.is_empty() {
            key.clone()
        } else {
            format!("{at}.{key}")
        };
        table.insert(key, toml_value(&v, &here)?);
    }
    Ok(table)
}

/// `value` as JSON text (non-finite numbers as `null`, as the summaries are written).
pub fn json<T: serde::Serialize + ?Sized>(value: &T) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| errors::FemuError::new_err(e.to_string()))
}

/// A flat vector as a NumPy array of `shape` (row-major).
pub fn array<'py>(
    py: Python<'py>,
    values: Vec<f64>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    let a = PyArray1::from_vec(py, values);
    Ok(a.reshape(shape.to_vec())?.into_any())
}

/// A flat vector of integers as a NumPy array of `shape` (row-major).
pub fn int_array<'py>(
    py: Python<'py>,
    values: Vec<i64>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    let a = PyArray1::from_vec(py, values);
    Ok(a.reshape(shape.to_vec())?.into_any())
}

/// A one-dimensional float array argument (any sequence NumPy can convert), checked finite.
pub fn floats(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    let np = obj.py().import("numpy")?;
    let a = np
        .call_method1("ascontiguousarray", (obj, "float64"))
        .map_err(|e| errors::input(format!("{name}: not an array of numbers ({e})")))?;
    let a = a.cast_into::<PyArray1<f64>>().map_err(|_| {
        errors::input(format!(
            "{name}: expected a one-dimensional array, got shape {}",
            obj.getattr("shape").map_or("?".into(), |s| s.to_string())
        ))
    })?;
    let v = a.readonly().as_slice()?.to_vec();
    if let Some(k) = v.iter().position(|x| !x.is_finite()) {
        return Err(errors::input(format!("{name}[{k}] is not finite")));
    }
    Ok(v)
}

/// A summary file checked against its typed struct (it must read back into the struct that
/// wrote it), as its JSON text: the numbers exactly as written (shortest round-trip decimals,
/// which Python's `json` reads back to the same doubles).
pub fn read_typed<T: serde::de::DeserializeOwned>(
    path: &Path,
) -> femu_study::error::Result<String> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    femu_study::json::from_str::<T>(&text)
        .with_context(|| format!("{} is not a femu result", path.display()))?;
    Ok(text)
}
