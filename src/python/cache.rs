//! Bindings for the path banks' disk cache (`crate::brdf::orders::{cache_dir,
//! set_cache_dir}`); documented on the Python wrappers in `python/pprender/__init__.py`.

use crate::python::args;
use pyo3::prelude::*;
use std::path::PathBuf;

/// set_cache_dir(path): where path banks are cached on disk; None keeps them in memory
/// only. Errors name ``cache_dir``.
#[pyfunction]
#[pyo3(signature = (path))]
fn set_cache_dir(path: &Bound<'_, PyAny>) -> PyResult<()> {
    let dir = args::opt_path("cache_dir", path)?;
    crate::brdf::orders::set_cache_dir(dir)?;
    Ok(())
}

/// cache_dir(): the directory path banks are cached in (pathlib.Path), or None.
#[pyfunction]
fn cache_dir() -> Option<PathBuf> {
    crate::brdf::orders::cache_dir()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(set_cache_dir, m)?)?;
    m.add_function(wrap_pyfunction!(cache_dir, m)?)?;
    Ok(())
}
