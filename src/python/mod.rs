//! The PyO3 binding layer (`pprender._core`): converts arrays and errors, nothing else.

use pyo3::prelude::*;

mod args;
mod bank;
pub mod brdf;
mod cache;
mod polarimetry;
mod reference;
mod render;
mod seed;

pyo3::create_exception!(
    pprender,
    Error,
    pyo3::exceptions::PyValueError,
    "Invalid input to pprender: the message names the parameter and its allowed range."
);

impl From<crate::Error> for PyErr {
    fn from(e: crate::Error) -> PyErr {
        Error::new_err(e.to_string())
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("Error", m.py().get_type::<Error>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MODEL_VERSION", crate::MODEL_VERSION)?;
    bank::register(m)?;
    brdf::register(m)?;
    cache::register(m)?;
    polarimetry::register(m)?;
    seed::register(m)?;
    reference::register(m)?;
    render::register(m)?;
    Ok(())
}
