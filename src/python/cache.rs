//! Bindings for the path banks' disk cache (`crate::brdf::orders::{cache_dir,
//! set_cache_dir}`, `crate::brdf::bank::cache::prune`); documented on the Python wrappers
//! in `python/pprender/__init__.py`.

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

/// prune_cache(all, path): remove the path-bank entries this build cannot read (with
/// ``all``, every entry) from ``path`` or, when None, from cache_dir(); returns
/// ``(removed, bytes, kept)``. Errors name ``all`` or ``path``; a failure to remove raises
/// OSError.
#[pyfunction]
#[pyo3(signature = (all, path))]
fn prune_cache(
    py: Python<'_>,
    all: &Bound<'_, PyAny>,
    path: &Bound<'_, PyAny>,
) -> PyResult<(usize, u64, usize)> {
    let all = args::flag("all", all)?;
    let Some(dir) = args::opt_path("path", path)?.or_else(crate::brdf::orders::cache_dir) else {
        return Ok((0, 0, 0));
    };
    if dir.exists() && !dir.is_dir() {
        return Err(crate::Error::param(
            "path",
            format!("{:?}", dir.display().to_string()),
            "must be a directory (the path-bank cache), or None for cache_dir()",
        )
        .into());
    }
    let p = py
        .detach(|| crate::brdf::bank::cache::prune(&dir, all))
        .map_err(|e| {
            pyo3::exceptions::PyOSError::new_err(format!(
                "pruning the path-bank cache {}: {e}",
                dir.display()
            ))
        })?;
    Ok((p.removed, p.bytes, p.kept))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(prune_cache, m)?)?;
    m.add_function(wrap_pyfunction!(set_cache_dir, m)?)?;
    m.add_function(wrap_pyfunction!(cache_dir, m)?)?;
    Ok(())
}
