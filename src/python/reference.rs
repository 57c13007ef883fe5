//! Bindings for `crate::reference` (the explicit-microsurface Monte Carlo reference).
//! Public documentation lives in `python/pprender/reference.py`.

use crate::optics::frames::{Frame, V3};
use crate::optics::fresnel::{Eta, C64};
use crate::reference::{self as core_ref, microsurface, Coherent, Config, Surface};
use crate::Error;
use numpy::ndarray::{Array1, Array2, Array3, Array4};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::str::FromStr;
use std::sync::Arc;

fn parse_eta(eta: C64) -> crate::Result<Eta> {
    if eta.re.is_nan() || eta.im.is_nan() {
        return Err(Error::param("eta", eta, "must not be NaN"));
    }
    if eta.re == f64::INFINITY && (eta.im == 0.0 || eta.im == f64::INFINITY) {
        return Ok(Eta::PerfectConductor);
    }
    Ok(Eta::Complex(eta))
}

fn nonneg(name: &'static str, v: i64, lo: i64, hi: i64) -> crate::Result<i64> {
    if v < lo || v > hi {
        return Err(Error::param(
            name,
            v,
            format!("must be an integer in [{lo}, {hi}]"),
        ));
    }
    Ok(v)
}

fn vec3(a: &[f64], name: &'static str) -> crate::Result<Vec<V3>> {
    if !a.len().is_multiple_of(3) {
        return Err(Error::Shape(format!("{name} must have shape (..., 3)")));
    }
    Ok(a.chunks_exact(3)
        .map(|c| V3::new(c[0], c[1], c[2]))
        .collect())
}

fn mats(v: &[[[f64; 4]; 4]]) -> Vec<f64> {
    v.iter().flat_map(|m| m.iter().flatten().copied()).collect()
}

/// `reference_microsurface(wi, wo, alpha, eta, rays, grid, correlation_length, cone,
/// max_order, frame, seed, batches, heights=None, wavelength=None, bistatic=None) -> dict`;
/// `wo` is `(K, 3)`, outputs are `(3, K, ...)`; with `wavelength`, the coherent tally for
/// the `(B, 3)` directions `bistatic` (default: `wi` alone) as `coherent` `(2, B, 4, 4)`.
#[pyfunction]
#[pyo3(signature = (wi, wo, alpha, eta, rays, grid, correlation_length, cone, max_order, frame, seed, batches, heights=None, wavelength=None, bistatic=None))]
#[allow(clippy::too_many_arguments)]
fn reference_microsurface<'py>(
    py: Python<'py>,
    wi: PyReadonlyArray1<'py, f64>,
    wo: PyReadonlyArray2<'py, f64>,
    alpha: Option<f64>,
    eta: C64,
    rays: i64,
    grid: i64,
    correlation_length: f64,
    cone: f64,
    max_order: i64,
    frame: &str,
    seed: u64,
    batches: i64,
    heights: Option<PyReadonlyArray2<'py, f64>>,
    wavelength: Option<f64>,
    bistatic: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let frame = Frame::from_str(frame)?;
    let wi = wi.as_array().to_vec();
    if wi.len() != 3 {
        return Err(Error::Shape(format!("wi must have shape (3,), got ({},)", wi.len())).into());
    }
    let wo_flat: Vec<f64> = wo.as_array().iter().copied().collect();
    let wo = vec3(&wo_flat, "wo")?;
    let surface = match (heights, alpha) {
        (Some(h), None) => {
            let h = h.as_array();
            if h.nrows() != h.ncols() {
                return Err(Error::Shape(format!(
                    "heights must be square (n, n), got {:?}",
                    h.shape()
                ))
                .into());
            }
            let n = h.nrows();
            Surface::Heights(Arc::new(microsurface::HeightField::new(
                n,
                h.iter().copied().collect(),
            )?))
        }
        (None, Some(alpha)) => Surface::Gaussian {
            alpha,
            grid: nonneg("grid", grid, 16, 4096)? as usize,
            correlation_length,
        },
        (Some(_), Some(_)) => {
            return Err(Error::param(
                "heights",
                "given with alpha",
                "give either a roughness (alpha or m) or heights, not both",
            )
            .into())
        }
        (None, None) => {
            return Err(
                Error::param("alpha", "None", "give a roughness (alpha or m) or heights").into(),
            )
        }
    };
    let wi = V3::new(wi[0], wi[1], wi[2]);
    let coherent = match (wavelength, bistatic) {
        (Some(wavelength), b) => Some(Coherent {
            wavelength,
            bistatic: match b {
                Some(b) => {
                    let flat: Vec<f64> = b.as_array().iter().copied().collect();
                    vec3(&flat, "bistatic")?
                }
                None => vec![wi],
            },
        }),
        (None, Some(_)) => {
            return Err(Error::param(
                "bistatic",
                "given without wavelength",
                "the coherent tally needs a wavelength (grid units, > 0)",
            )
            .into())
        }
        (None, None) => None,
    };
    let cfg = Config {
        wi,
        wo,
        eta: parse_eta(eta)?,
        surface,
        rays: nonneg("rays", rays, 1, 1 << 40)? as u64,
        cone,
        max_order: nonneg("max_order", max_order, 1, 1000)? as u32,
        frame,
        seed,
        batches: nonneg("batches", batches, 2, 100_000)? as u32,
        coherent,
    };
    let out = py.detach(|| core_ref::run(&cfg))?;
    let k = cfg.wo.len();
    let nb = out.surfaces.len();
    let d = PyDict::new(py);
    let m4 = |v: &[[[f64; 4]; 4]]| {
        Array4::from_shape_vec((core_ref::ORDERS, k, 4, 4), mats(v)).expect("shape")
    };
    d.set_item("mueller", m4(&out.mueller).into_pyarray(py))?;
    d.set_item("stderr", m4(&out.stderr).into_pyarray(py))?;
    let counts: Vec<i64> = out.counts.iter().map(|&c| c as i64).collect();
    d.set_item(
        "counts",
        Array2::from_shape_vec((core_ref::ORDERS, k), counts)
            .expect("shape")
            .into_pyarray(py),
    )?;
    d.set_item(
        "projected_solid_angle",
        Array1::from(out.projected_solid_angle.clone()).into_pyarray(py),
    )?;
    d.set_item("albedo", Array1::from(out.albedo.to_vec()).into_pyarray(py))?;
    d.set_item(
        "albedo_stderr",
        Array1::from(out.albedo_stderr.to_vec()).into_pyarray(py),
    )?;
    d.set_item("truncated", out.truncated)?;
    d.set_item("truncated_stderr", out.truncated_stderr)?;
    d.set_item("lost", out.lost)?;
    let alphas: Vec<f64> = out.surfaces.iter().map(|s| s.stats.alpha).collect();
    d.set_item("realized_alpha", Array1::from(alphas).into_pyarray(py))?;
    let cov: Vec<f64> = out
        .surfaces
        .iter()
        .flat_map(|s| s.stats.cov.into_iter().flatten())
        .collect();
    d.set_item(
        "slope_cov",
        Array3::from_shape_vec((nb, 2, 2), cov)
            .expect("shape")
            .into_pyarray(py),
    )?;
    let ratio: Vec<f64> = out
        .surfaces
        .iter()
        .map(|s| s.alpha_unscaled_ratio)
        .collect();
    d.set_item("alpha_unscaled_ratio", Array1::from(ratio).into_pyarray(py))?;
    let scale: Vec<f64> = out.surfaces.iter().map(|s| s.scale).collect();
    d.set_item("height_scale", Array1::from(scale).into_pyarray(py))?;
    if let Some(c) = &cfg.coherent {
        let nb = c.bistatic.len();
        let c4 = |v: &[[[f64; 4]; 4]]| {
            Array4::from_shape_vec((core_ref::COHERENT_ORDERS, nb, 4, 4), mats(v)).expect("shape")
        };
        d.set_item("coherent", c4(&out.coherent).into_pyarray(py))?;
        d.set_item("coherent_stderr", c4(&out.coherent_stderr).into_pyarray(py))?;
        let unpaired: Vec<i64> = out.coherent_unpaired.iter().map(|&c| c as i64).collect();
        d.set_item("coherent_unpaired", Array1::from(unpaired).into_pyarray(py))?;
    }
    d.set_item("elapsed_s", out.elapsed_s)?;
    Ok(d)
}

/// `reference_height_field(alpha, grid, correlation_length, seed, batch) -> dict`: the
/// surface that batch `batch` of `reference_microsurface` with the same seed traces.
#[pyfunction]
fn reference_height_field<'py>(
    py: Python<'py>,
    alpha: f64,
    grid: i64,
    correlation_length: f64,
    seed: u64,
    batch: i64,
) -> PyResult<Bound<'py, PyDict>> {
    let grid = nonneg("grid", grid, 16, 4096)? as usize;
    let batch = nonneg("batch", batch, 0, u32::MAX as i64)? as u32;
    let surface = Surface::Gaussian {
        alpha,
        grid,
        correlation_length,
    };
    let (f, rep) = py.detach(|| core_ref::batch_surface(&surface, seed, batch))?;
    let n = f.n;
    let d = PyDict::new(py);
    d.set_item(
        "heights",
        Array2::from_shape_vec((n, n), f.h.clone())
            .expect("shape")
            .into_pyarray(py),
    )?;
    let slopes: Vec<f64> = f.facet_slopes().into_iter().flatten().collect();
    d.set_item(
        "slopes",
        Array2::from_shape_vec((2 * n * n, 2), slopes)
            .expect("shape")
            .into_pyarray(py),
    )?;
    d.set_item("realized_alpha", rep.stats.alpha)?;
    let cov: Vec<f64> = rep.stats.cov.into_iter().flatten().collect();
    d.set_item(
        "slope_cov",
        Array2::from_shape_vec((2, 2), cov)
            .expect("shape")
            .into_pyarray(py),
    )?;
    d.set_item("alpha_unscaled_ratio", rep.alpha_unscaled_ratio)?;
    d.set_item("height_scale", rep.scale)?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(reference_microsurface, m)?)?;
    m.add_function(wrap_pyfunction!(reference_height_field, m)?)?;
    Ok(())
}
