//! Argument extraction that names the parameter: a string, `None` or a wrong type where a
//! number, a complex number, a name or a list of names is expected raises `pprender.Error`
//! (a `ValueError`) naming the parameter and what it takes, instead of PyO3's bare
//! `TypeError` ("must be real number, not str").
//!
//! Used through `#[pyo3(from_py_with = ...)]`; the functions below are one per parameter
//! because `from_py_with` passes only the object.

use crate::optics::fresnel::C64;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyString};

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

fn shown(obj: &Bound<'_, PyAny>) -> String {
    obj.repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| format!("<{}>", type_name(obj)))
}

fn invalid(name: &'static str, obj: &Bound<'_, PyAny>, expected: &str) -> PyErr {
    crate::Error::param(
        name,
        shown(obj),
        format!("{expected} (got {})", type_name(obj)),
    )
    .into()
}

/// A real number (int or float, not bool or str).
pub fn real(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<f64> {
    if obj.is_instance_of::<PyString>() || obj.is_instance_of::<PyBool>() || obj.is_none() {
        return Err(invalid(name, obj, "a real number"));
    }
    obj.extract::<f64>()
        .map_err(|_| invalid(name, obj, "a real number"))
}

/// `None` or a real number.
pub fn opt_real(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<Option<f64>> {
    if obj.is_none() {
        return Ok(None);
    }
    real(name, obj).map(Some)
}

/// A non-negative integer (not bool, float or str).
pub fn count(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<usize> {
    if obj.is_instance_of::<PyBool>() {
        return Err(invalid(name, obj, "a non-negative integer"));
    }
    obj.extract::<usize>()
        .map_err(|_| invalid(name, obj, "a non-negative integer"))
}

/// `None` or a non-negative integer (not bool, float or str).
pub fn opt_count(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<Option<usize>> {
    if obj.is_none() {
        return Ok(None);
    }
    count(name, obj).map(Some)
}

/// True or False.
pub fn flag(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<bool> {
    obj.extract::<bool>()
        .map_err(|_| invalid(name, obj, "True or False"))
}

/// A complex number (complex, float or int; not a string: `complex("1.5+2j")` parses one).
pub fn complex(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<C64> {
    let expected = "a complex number n + ik (e.g. 1.5+2j; parse a string with complex(...))";
    if obj.is_instance_of::<PyString>() || obj.is_instance_of::<PyBool>() || obj.is_none() {
        return Err(invalid(name, obj, expected));
    }
    obj.extract::<C64>()
        .map_err(|_| invalid(name, obj, expected))
}

/// A string (a name from a fixed set, checked by the caller).
pub fn name(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<String> {
    obj.extract::<String>()
        .map_err(|_| invalid(name, obj, "a string"))
}

/// `None` or a string.
pub fn opt_name(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<Option<String>> {
    if obj.is_none() {
        return Ok(None);
    }
    self::name(name, obj).map(Some)
}

/// A sequence of strings; a lone string is refused (it would be read as its characters).
pub fn names(name: &'static str, obj: &Bound<'_, PyAny>) -> PyResult<Vec<String>> {
    if obj.is_instance_of::<PyString>() {
        let s = obj.extract::<String>()?;
        return Err(crate::Error::param(
            name,
            format!("{s:?}"),
            format!("a sequence of names, e.g. ({s:?},), not a lone string"),
        )
        .into());
    }
    obj.extract::<Vec<String>>()
        .map_err(|_| invalid(name, obj, "a sequence of strings"))
}

/// `None` or a filesystem path (`str` or `os.PathLike`, not empty).
pub fn opt_path(
    name: &'static str,
    obj: &Bound<'_, PyAny>,
) -> PyResult<Option<std::path::PathBuf>> {
    if obj.is_none() {
        return Ok(None);
    }
    let p: std::path::PathBuf = obj
        .extract()
        .map_err(|_| invalid(name, obj, "a str or os.PathLike path, or None"))?;
    if p.as_os_str().is_empty() {
        return Err(invalid(
            name,
            obj,
            "a directory path (an empty string is none), or None",
        ));
    }
    Ok(Some(p))
}
