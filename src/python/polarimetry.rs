//! Python bindings for `crate::optics::polarimetry`: batch loops over leading dimensions.
//!
//! Stokes inputs are `(..., 4)`, Mueller inputs `(..., 4, 4)` float64 arrays (any memory
//! layout); outputs are new C-contiguous arrays with the same leading shape.
use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{IntoPyArray, PyArrayDyn, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::optics::polarimetry as pol;
use crate::optics::Mat4;
use crate::Error;

type Out<'py> = Bound<'py, PyArrayDyn<f64>>;

/// The leading (batch) shape and the flat row-major data, after checking the trailing shape.
fn split(
    a: &PyReadonlyArrayDyn<'_, f64>,
    name: &str,
    trailing: &[usize],
) -> PyResult<(Vec<usize>, Vec<f64>)> {
    let view = a.as_array();
    let shape = view.shape();
    let k = trailing.len();
    if shape.len() < k || shape[shape.len() - k..] != *trailing {
        let want: Vec<String> = trailing.iter().map(|t| t.to_string()).collect();
        return Err(Error::Shape(format!(
            "{name} must have shape (..., {}), got {shape:?}",
            want.join(", ")
        ))
        .into());
    }
    Ok((
        shape[..shape.len() - k].to_vec(),
        view.iter().copied().collect(),
    ))
}

fn stokes_batch(a: &PyReadonlyArrayDyn<'_, f64>) -> PyResult<(Vec<usize>, Vec<[f64; 4]>)> {
    let (lead, flat) = split(a, "stokes", &[4])?;
    Ok((
        lead,
        flat.chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect(),
    ))
}

fn mueller_batch(a: &PyReadonlyArrayDyn<'_, f64>) -> PyResult<(Vec<usize>, Vec<Mat4>)> {
    let (lead, flat) = split(a, "mueller", &[4, 4])?;
    let mats = flat
        .chunks_exact(16)
        .map(|c| {
            let mut m = [[0.0; 4]; 4];
            m.iter_mut().flatten().zip(c).for_each(|(x, &y)| *x = y);
            m
        })
        .collect();
    Ok((lead, mats))
}

/// Map `f` over the batch without the GIL; each result is `K` numbers, appended to the
/// leading shape as `tail` (empty for scalars).
fn map_batch<T, const K: usize>(
    py: Python<'_>,
    items: Vec<T>,
    f: impl Fn(&T) -> crate::Result<[f64; K]> + Send + Sync,
) -> PyResult<Vec<f64>>
where
    T: Send + Sync,
{
    let out: crate::Result<Vec<[f64; K]>> = py.detach(|| items.par_iter().map(&f).collect());
    Ok(out?.into_iter().flatten().collect())
}

fn to_array<'py>(py: Python<'py>, lead: &[usize], tail: &[usize], data: Vec<f64>) -> Out<'py> {
    let shape: Vec<usize> = lead.iter().chain(tail).copied().collect();
    ArrayD::from_shape_vec(IxDyn(&shape), data)
        .expect("batch size matches shape")
        .into_pyarray(py)
}

fn stokes_scalar<'py>(
    py: Python<'py>,
    stokes: PyReadonlyArrayDyn<'py, f64>,
    f: fn(&[f64; 4]) -> crate::Result<f64>,
) -> PyResult<Out<'py>> {
    let (lead, items) = stokes_batch(&stokes)?;
    let data = map_batch(py, items, |s| Ok([f(s)?]))?;
    Ok(to_array(py, &lead, &[], data))
}

fn mueller_scalar<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
    f: fn(&Mat4) -> crate::Result<f64>,
) -> PyResult<Out<'py>> {
    let (lead, items) = mueller_batch(&mueller)?;
    let data = map_batch(py, items, |m| Ok([f(m)?]))?;
    Ok(to_array(py, &lead, &[], data))
}

fn mueller_vector3<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
    f: fn(&Mat4) -> crate::Result<[f64; 3]>,
) -> PyResult<Out<'py>> {
    let (lead, items) = mueller_batch(&mueller)?;
    let data = map_batch(py, items, f)?;
    Ok(to_array(py, &lead, &[3], data))
}

/// Degree of polarization of `(..., 4)` Stokes vectors.
#[pyfunction]
fn polarimetry_dop<'py>(
    py: Python<'py>,
    stokes: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    stokes_scalar(py, stokes, pol::dop)
}

/// Degree of linear polarization of `(..., 4)` Stokes vectors.
#[pyfunction]
fn polarimetry_dolp<'py>(
    py: Python<'py>,
    stokes: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    stokes_scalar(py, stokes, pol::dolp)
}

/// Degree of circular polarization `|V| / I` of `(..., 4)` Stokes vectors.
#[pyfunction]
fn polarimetry_docp<'py>(
    py: Python<'py>,
    stokes: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    stokes_scalar(py, stokes, pol::docp)
}

/// Diattenuation of `(..., 4, 4)` Mueller matrices.
#[pyfunction]
fn polarimetry_diattenuation<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    mueller_scalar(py, mueller, pol::diattenuation)
}

/// Diattenuation vectors `(..., 3)` of `(..., 4, 4)` Mueller matrices.
#[pyfunction]
fn polarimetry_diattenuation_vector<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    mueller_vector3(py, mueller, pol::diattenuation_vector)
}

/// Polarizance of `(..., 4, 4)` Mueller matrices.
#[pyfunction]
fn polarimetry_polarizance<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    mueller_scalar(py, mueller, pol::polarizance)
}

/// Polarizance vectors `(..., 3)` of `(..., 4, 4)` Mueller matrices.
#[pyfunction]
fn polarimetry_polarizance_vector<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    mueller_vector3(py, mueller, pol::polarizance_vector)
}

/// Gil-Bernabeu depolarization index of `(..., 4, 4)` Mueller matrices.
#[pyfunction]
fn polarimetry_depolarization_index<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    mueller_scalar(py, mueller, pol::depolarization_index)
}

/// Lidar linear depolarization ratio `(M00 - M11) / (M00 + M11)`.
#[pyfunction]
fn polarimetry_linear_depolarization_ratio<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    mueller_scalar(py, mueller, pol::linear_depolarization_ratio)
}

/// Lidar circular depolarization ratio `(M00 + M33) / (M00 - M33)`.
#[pyfunction]
fn polarimetry_circular_depolarization_ratio<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    mueller_scalar(py, mueller, pol::circular_depolarization_ratio)
}

/// Lu-Chipman decomposition: `(m_delta, m_r, m_d)`, each `(..., 4, 4)`.
#[pyfunction]
fn polarimetry_lu_chipman<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<(Out<'py>, Out<'py>, Out<'py>)> {
    let (lead, items) = mueller_batch(&mueller)?;
    let data = map_batch(py, items, |m| {
        let lc = pol::lu_chipman(m)?;
        let mut out = [0.0; 48];
        for (k, f) in [lc.m_delta, lc.m_r, lc.m_d].iter().enumerate() {
            out[16 * k..16 * (k + 1)]
                .iter_mut()
                .zip(f.iter().flatten())
                .for_each(|(o, &x)| *o = x);
        }
        Ok(out)
    })?;
    let (mut d, mut r, mut dd) = (Vec::new(), Vec::new(), Vec::new());
    for chunk in data.chunks_exact(48) {
        d.extend_from_slice(&chunk[..16]);
        r.extend_from_slice(&chunk[16..32]);
        dd.extend_from_slice(&chunk[32..]);
    }
    Ok((
        to_array(py, &lead, &[4, 4], d),
        to_array(py, &lead, &[4, 4], r),
        to_array(py, &lead, &[4, 4], dd),
    ))
}

/// Retardance of the Lu-Chipman retarder: `(total, linear, rotation, vector)`,
/// shapes `(...)`, `(...)`, `(...)`, `(..., 3)`, radians.
#[pyfunction]
fn polarimetry_retardance<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<(Out<'py>, Out<'py>, Out<'py>, Out<'py>)> {
    let (lead, items) = mueller_batch(&mueller)?;
    let data = map_batch(py, items, |m| {
        let r = pol::retardance(m)?;
        Ok([
            r.total,
            r.linear,
            r.rotation,
            r.vector[0],
            r.vector[1],
            r.vector[2],
        ])
    })?;
    let n = data.len() / 6;
    let (mut t, mut l, mut rot, mut v) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::new(),
    );
    for c in data.chunks_exact(6) {
        t.push(c[0]);
        l.push(c[1]);
        rot.push(c[2]);
        v.extend_from_slice(&c[3..]);
    }
    Ok((
        to_array(py, &lead, &[], t),
        to_array(py, &lead, &[], l),
        to_array(py, &lead, &[], rot),
        to_array(py, &lead, &[3], v),
    ))
}

/// Cloude coherency-matrix eigenvalues `(..., 4)`, descending.
#[pyfunction]
fn polarimetry_cloude_eigenvalues<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Out<'py>> {
    let (lead, items) = mueller_batch(&mueller)?;
    let data = map_batch(py, items, pol::cloude_eigenvalues)?;
    Ok(to_array(py, &lead, &[4], data))
}

/// Physical realizability `(...)` bool: Cloude eigenvalues `>= -tol * M00`.
#[pyfunction]
#[pyo3(signature = (mueller, tol = 1e-9))]
fn polarimetry_is_physical<'py>(
    py: Python<'py>,
    mueller: PyReadonlyArrayDyn<'py, f64>,
    tol: f64,
) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
    let (lead, items) = mueller_batch(&mueller)?;
    // Validate tol even for an empty batch.
    pol::is_physical(&[[0.0; 4]; 4], tol)?;
    let data = map_batch(py, items, |m| {
        Ok([if pol::is_physical(m, tol)? { 1.0 } else { 0.0 }])
    })?;
    let flags: Vec<bool> = data.into_iter().map(|x| x != 0.0).collect();
    Ok(ArrayD::from_shape_vec(IxDyn(&lead), flags)
        .expect("batch size matches shape")
        .into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(polarimetry_dop, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_dolp, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_docp, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_diattenuation, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_diattenuation_vector, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_polarizance, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_polarizance_vector, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_depolarization_index, m)?)?;
    m.add_function(wrap_pyfunction!(
        polarimetry_linear_depolarization_ratio,
        m
    )?)?;
    m.add_function(wrap_pyfunction!(
        polarimetry_circular_depolarization_ratio,
        m
    )?)?;
    m.add_function(wrap_pyfunction!(polarimetry_lu_chipman, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_retardance, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_cloude_eigenvalues, m)?)?;
    m.add_function(wrap_pyfunction!(polarimetry_is_physical, m)?)?;
    Ok(())
}
