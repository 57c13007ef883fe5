//! Bindings for `crate::brdf::bank` (order 2 from the surface's own paths). Used by
//! `scripts/` for now; the Material option that will carry it is documented in
//! `python/pprender/materials.py` once it lands.

use crate::brdf::bank::{BankSpec, OrderTable, PathBank, MAX_ORDER, N_PHI, N_THETA};
use crate::optics::frames::{Frame, V3};
use crate::optics::fresnel::{Eta, C64};
use crate::reference::microsurface::Autocorrelation;
use crate::Error;
use numpy::ndarray::{Array2, Array3, Array5};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyArray5, PyReadonlyArray2};
use pyo3::prelude::*;
use std::str::FromStr;

fn parse_eta(eta: C64) -> crate::Result<Eta> {
    if eta.re.is_nan() || eta.im.is_nan() {
        return Err(Error::param("eta", eta, "must not be NaN"));
    }
    if eta.re == f64::INFINITY {
        return Ok(Eta::PerfectConductor);
    }
    if !(eta.re > 0.0 && eta.im >= 0.0 && eta.re.is_finite() && eta.im.is_finite()) {
        return Err(Error::param(
            "eta",
            eta,
            "must be n + ik with n > 0, k >= 0 finite (or inf for a perfect conductor)",
        ));
    }
    Ok(Eta::Complex(eta))
}

/// `PathBank(alpha, rays, surfaces=64, grid=256, correlation_length=8.0, seed=1,
/// autocorrelation="gaussian")`: the order >= 2 paths of Beckmann surfaces with a Gaussian
/// or Matern height autocorrelation (`crate::brdf::bank`).
#[pyclass(module = "pprender._core", name = "PathBank", frozen)]
pub struct PyPathBank(PathBank);

#[pymethods]
impl PyPathBank {
    #[new]
    #[pyo3(signature = (alpha, rays, surfaces=64, grid=256, correlation_length=8.0, seed=1,
        autocorrelation="gaussian"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        alpha: f64,
        rays: u64,
        surfaces: u32,
        grid: usize,
        correlation_length: f64,
        seed: u64,
        autocorrelation: &str,
    ) -> PyResult<Self> {
        let spec = BankSpec {
            autocorrelation: Autocorrelation::from_name(autocorrelation)?,
            alpha,
            grid,
            correlation_length,
            rays,
            surfaces,
            seed,
        };
        let bank = py.detach(|| PathBank::trace(&spec))?;
        Ok(PyPathBank(bank))
    }

    /// `(N_THETA, MAX_ORDER + 1)`: per incidence node, the flux fractions leaving after
    /// 1, 2, ..., MAX_ORDER reflections, then the fraction still on the surface.
    #[getter]
    fn albedo<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let a = Array2::from_shape_fn((N_THETA, MAX_ORDER + 1), |(i, o)| {
            if o < MAX_ORDER {
                self.0.albedo[i][o]
            } else {
                self.0.truncated[i]
            }
        });
        a.into_pyarray(py)
    }

    /// `(N_THETA, MAX_ORDER - 1)`: the paths kept per incidence node and order 2, 3, ...
    #[getter]
    fn paths<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u64>> {
        let a = Array2::from_shape_fn((N_THETA, MAX_ORDER - 1), |(i, n)| {
            (self.0.paths[i][n].len() / (2 * (n + 2))) as u64
        });
        a.into_pyarray(py)
    }

    /// `(P, 2 n)` float32: the order-`n` paths of incidence node `i`, the slopes
    /// `(sx, sy)` of their facets in order.
    #[pyo3(signature = (i, n=2))]
    fn paths_at<'py>(
        &self,
        py: Python<'py>,
        i: usize,
        n: usize,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        if i >= N_THETA {
            return Err(Error::param("i", i, format!("must be in [0, {}]", N_THETA - 1)).into());
        }
        if !(2..=MAX_ORDER).contains(&n) {
            return Err(Error::param("n", n, format!("must be in [2, {MAX_ORDER}]")).into());
        }
        let p = &self.0.paths[i][n - 2];
        let a = Array2::from_shape_fn((p.len() / (2 * n), 2 * n), |(k, c)| p[k * 2 * n + c]);
        Ok(a.into_pyarray(py))
    }

    #[getter]
    fn rays(&self) -> u64 {
        self.0.spec.rays
    }

    #[getter]
    fn lost(&self) -> u64 {
        self.0.lost
    }

    /// The incidence (and exit) nodes in radians.
    #[getter]
    fn theta(&self) -> Vec<f64> {
        (0..N_THETA)
            .map(|k| k as f64 * crate::brdf::bank::THETA_STEP)
            .collect()
    }

    /// The table of the paths of orders `orders = (first, last)` (within `2..=8`) for index
    /// `eta` (`inf` for a perfect conductor); `reciprocal=False` skips the reciprocity mean
    /// (the kernel estimate alone, a diagnostic).
    #[pyo3(signature = (eta, orders=(2, 2), reciprocal=true))]
    fn table(
        &self,
        py: Python<'_>,
        eta: C64,
        orders: (usize, usize),
        reciprocal: bool,
    ) -> PyResult<PyOrderTable> {
        let eta = parse_eta(eta)?;
        let (a, b) = orders;
        if !(2 <= a && a <= b && b <= MAX_ORDER) {
            return Err(Error::param(
                "orders",
                format!("{orders:?}"),
                format!("must be (first, last) with 2 <= first <= last <= {MAX_ORDER}"),
            )
            .into());
        }
        Ok(PyOrderTable(py.detach(|| {
            if reciprocal {
                OrderTable::build(&self.0, eta, a..=b)
            } else {
                OrderTable::spread(&self.0, eta, a..=b)
            }
        })))
    }
}

/// An order-2 Mueller table (`crate::brdf::bank::OrderTable`).
#[pyclass(module = "pprender._core", name = "OrderTable", frozen)]
pub struct PyOrderTable(OrderTable);

#[pymethods]
impl PyOrderTable {
    /// `eval(wi, wo, frame="sp") -> (N, 4, 4)`: `f2` (1/sr) for direction pairs `(N, 3)`.
    #[pyo3(signature = (wi, wo, frame="sp"))]
    fn eval<'py>(
        &self,
        py: Python<'py>,
        wi: PyReadonlyArray2<'py, f64>,
        wo: PyReadonlyArray2<'py, f64>,
        frame: &str,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let frame = Frame::from_str(frame)?;
        let (wi, wo) = (wi.as_array(), wo.as_array());
        if wi.ncols() != 3 || wo.ncols() != 3 || wi.nrows() != wo.nrows() {
            return Err(Error::Shape(format!(
                "wi and wo must both have shape (N, 3), got {:?} and {:?}",
                wi.shape(),
                wo.shape()
            ))
            .into());
        }
        let n = wi.nrows();
        let mut out = Array3::<f64>::zeros((n, 4, 4));
        for k in 0..n {
            let a = V3::new(wi[[k, 0]], wi[[k, 1]], wi[[k, 2]]);
            let b = V3::new(wo[[k, 0]], wo[[k, 1]], wo[[k, 2]]);
            if !(a.is_finite() && b.is_finite()) {
                return Err(Error::param("wi, wo", k, "directions must be finite").into());
            }
            let m = self.0.eval(a.normalize(), b.normalize(), frame);
            for r in 0..4 {
                for c in 0..4 {
                    out[[k, r, c]] = m[r][c];
                }
            }
        }
        Ok(out.into_pyarray(py))
    }

    /// The table at fraction `w` in `[0, 1]` of the way to `other` (two roughness nodes),
    /// mixed node by node at the same angles (`crate::brdf::bank::OrderTable::mix`; what
    /// `orders="surface"` did before `mix_alpha`, kept for comparison).
    fn mix(&self, other: &PyOrderTable, w: f64) -> PyResult<PyOrderTable> {
        if !(0.0..=1.0).contains(&w) {
            return Err(Error::param("w", w, "must be in [0, 1]").into());
        }
        Ok(PyOrderTable(self.0.mix(&other.0, w)))
    }

    /// The table at roughness ``alpha`` between this table, of roughness node ``a_lo``, and
    /// ``other``, of node ``a_hi > a_lo``, as ``orders="surface"`` interpolates in alpha: M00
    /// at the similar angles (``cot theta`` scaled by ``a / alpha``), the normalized
    /// elements at the actual ones (``crate::brdf::orders::similar``).
    fn mix_alpha(
        &self,
        other: &PyOrderTable,
        a_lo: f64,
        a_hi: f64,
        alpha: f64,
    ) -> PyResult<PyOrderTable> {
        if !(a_lo > 0.0 && a_lo.is_finite()) {
            return Err(Error::param("a_lo", a_lo, "must be positive and finite").into());
        }
        if !(a_hi > a_lo && a_hi.is_finite()) {
            return Err(Error::param(
                "a_hi",
                a_hi,
                format!("must be finite and above a_lo = {a_lo}"),
            )
            .into());
        }
        if !(alpha >= a_lo && alpha <= a_hi) {
            return Err(Error::param(
                "alpha",
                alpha,
                format!("must be in [a_lo, a_hi] = [{a_lo}, {a_hi}]"),
            )
            .into());
        }
        Ok(PyOrderTable(crate::brdf::orders::similar::mix(
            &self.0, &other.0, a_lo, a_hi, alpha,
        )))
    }

    /// `(N_THETA, N_THETA, N_PHI, 4, 4)`: the nodes (`Sp` frames).
    #[getter]
    fn data<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray5<f64>> {
        let a = Array5::from_shape_fn((N_THETA, N_THETA, N_PHI, 4, 4), |(i, o, j, r, c)| {
            self.0.data[(i * N_THETA + o) * N_PHI + j][r][c]
        });
        a.into_pyarray(py)
    }

    /// The table's albedo at incidence node `i` (unpolarized).
    fn node_albedo(&self, i: usize) -> PyResult<f64> {
        if i >= N_THETA {
            return Err(Error::param("i", i, format!("must be in [0, {}]", N_THETA - 1)).into());
        }
        Ok(self.0.node_albedo(i))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPathBank>()?;
    m.add_class::<PyOrderTable>()?;
    Ok(())
}
