//! Python bindings for `crate::microfacet::seed` (the seed's closed forms and their exact
//! references) and the exact masking functions of `crate::microfacet::masking`.
//!
//! Every function takes array-likes (scalars, lists, NumPy arrays; converted to float64),
//! broadcasts them with NumPy's rules and returns a float64 array of the broadcast shape
//! (0-d for scalar inputs; `pprender.microfacet` turns those into floats). Inputs are
//! validated first; errors name the parameter (`pprender.Error`, a `ValueError`).

use crate::microfacet::distribution::Distribution;
use crate::microfacet::masking::{self, SmithG1};
use crate::microfacet::seed;
use crate::{Error, Result};
use numpy::ndarray::{ArrayD, IxDyn, Zip};
use numpy::{AllowTypeChange, IntoPyArray, PyArrayDyn, PyArrayLikeDyn};
use pyo3::prelude::*;
use std::str::FromStr;

type In<'py> = PyArrayLikeDyn<'py, f64, AllowTypeChange>;
type Out<'py> = Bound<'py, PyArrayDyn<f64>>;

/// NumPy broadcast shape of two shapes.
fn broadcast_shape(a: &[usize], b: &[usize], names: (&str, &str)) -> Result<Vec<usize>> {
    let n = a.len().max(b.len());
    let mut out = vec![0; n];
    for i in 0..n {
        let da = if i < n - a.len() {
            1
        } else {
            a[i - (n - a.len())]
        };
        let db = if i < n - b.len() {
            1
        } else {
            b[i - (n - b.len())]
        };
        out[i] = if da == db || db == 1 {
            da
        } else if da == 1 {
            db
        } else {
            return Err(Error::Shape(format!(
                "{} with shape {:?} and {} with shape {:?} do not broadcast",
                names.0, a, names.1, b
            )));
        };
    }
    Ok(out)
}

/// Validate every element of `x` with `check`.
fn check_all(x: &In<'_>, check: impl Fn(f64) -> Result<()>) -> Result<()> {
    x.as_array().iter().try_for_each(|&v| check(v))
}

/// `f(a, b)` over the broadcast of `a` and `b` (GIL released while computing).
fn map2<'py>(
    py: Python<'py>,
    a: &In<'py>,
    b: &In<'py>,
    names: (&str, &str),
    f: impl Fn(f64, f64) -> Result<f64> + Send + Sync,
) -> PyResult<Out<'py>> {
    let (av, bv) = (a.as_array(), b.as_array());
    let shape = broadcast_shape(av.shape(), bv.shape(), names)?;
    let ab = av.broadcast(IxDyn(&shape)).expect("checked broadcast");
    let bb = bv.broadcast(IxDyn(&shape)).expect("checked broadcast");
    let out: Result<ArrayD<f64>> = py.detach(|| {
        let mut err = None;
        let out = Zip::from(&ab).and(&bb).map_collect(|&x, &y| match f(x, y) {
            Ok(v) => v,
            Err(e) => {
                err.get_or_insert(e);
                f64::NAN
            }
        });
        match err {
            Some(e) => Err(e),
            None => Ok(out),
        }
    });
    Ok(out?.into_pyarray(py))
}

/// `f(a)` elementwise.
fn map1<'py>(py: Python<'py>, a: &In<'py>, f: impl Fn(f64) -> f64 + Send + Sync) -> Out<'py> {
    let av = a.as_array();
    let out = py.detach(|| av.map(|&x| f(x)));
    out.into_pyarray(py)
}

fn check_m(m: f64) -> Result<()> {
    seed::check_m(m)
}

fn check_theta(t: f64) -> Result<()> {
    seed::check_angle("theta_k", t, 0.0)
}

fn check_alpha(a: f64) -> Result<()> {
    seed::check_angle("alpha", a, -std::f64::consts::FRAC_PI_2)
}

/// Seed function of (m, theta_k).
fn seed_mt<'py>(
    py: Python<'py>,
    m: In<'py>,
    theta_k: In<'py>,
    f: fn(f64, f64) -> f64,
) -> PyResult<Out<'py>> {
    check_all(&m, check_m)?;
    check_all(&theta_k, check_theta)?;
    map2(py, &m, &theta_k, ("m", "theta_k"), |m, t| Ok(f(m, t)))
}

/// Seed function of (m, alpha).
fn seed_ma<'py>(
    py: Python<'py>,
    m: In<'py>,
    alpha: In<'py>,
    f: fn(f64, f64) -> f64,
) -> PyResult<Out<'py>> {
    check_all(&m, check_m)?;
    check_all(&alpha, check_alpha)?;
    map2(py, &m, &alpha, ("m", "alpha"), |m, a| Ok(f(m, a)))
}

/// Wallis integral `A(m) = int_0^{pi/2} cos^m(t) dt` (exact reference).
#[pyfunction]
fn wallis<'py>(py: Python<'py>, m: In<'py>) -> PyResult<Out<'py>> {
    check_all(&m, check_m)?;
    Ok(map1(py, &m, seed::wallis))
}

/// Seed eq. 20 evaluated literally with f64 factorials (NaN from m = 171 on).
#[pyfunction]
fn wallis_factorial<'py>(py: Python<'py>, m: In<'py>) -> PyResult<Out<'py>> {
    check_all(&m, check_m)?;
    Ok(map1(py, &m, seed::wallis_factorial))
}

/// `A(m)` as `exp(lgamma difference)` (statrs ln_gamma); for measurements only.
#[pyfunction]
fn _wallis_lgamma<'py>(py: Python<'py>, m: In<'py>) -> PyResult<Out<'py>> {
    check_all(&m, check_m)?;
    Ok(map1(py, &m, seed::wallis_lgamma))
}

/// Seed eq. 22, `A(m) ~ (pi/2) sqrt(2 pi m + 1)/(pi m + 1)`.
#[pyfunction]
fn seed_wallis<'py>(py: Python<'py>, m: In<'py>) -> PyResult<Out<'py>> {
    check_all(&m, check_m)?;
    Ok(map1(py, &m, seed::seed_wallis))
}

/// `int_alpha^{pi/2} cos^m(t) dt`, alpha in [-pi/2, pi/2] (exact reference).
#[pyfunction]
fn incomplete_cos_pow<'py>(py: Python<'py>, m: In<'py>, alpha: In<'py>) -> PyResult<Out<'py>> {
    seed_ma(py, m, alpha, seed::incomplete_cos_pow)
}

/// The same through statrs' `beta_reg` (loses accuracy at large m); for measurements only.
#[pyfunction]
fn _incomplete_cos_pow_beta_reg<'py>(
    py: Python<'py>,
    m: In<'py>,
    alpha: In<'py>,
) -> PyResult<Out<'py>> {
    seed_ma(py, m, alpha, seed::incomplete_cos_pow_beta_reg)
}

/// Seed eq. 19 (our reading): `A(m) cos^{m+1}(alpha)` for alpha >= 0, `2A - A cos^{m+1}` below.
#[pyfunction]
#[pyo3(signature = (m, alpha, exact_wallis=false))]
fn seed_incomplete_cos_pow<'py>(
    py: Python<'py>,
    m: In<'py>,
    alpha: In<'py>,
    exact_wallis: bool,
) -> PyResult<Out<'py>> {
    if exact_wallis {
        seed_ma(py, m, alpha, |m, a| seed::eq19_with(m, a, seed::wallis(m)))
    } else {
        seed_ma(py, m, alpha, seed::seed_incomplete_cos_pow)
    }
}

/// Seed eq. 19 as printed (for showing how it fails).
#[pyfunction]
fn seed_incomplete_cos_pow_printed<'py>(
    py: Python<'py>,
    m: In<'py>,
    alpha: In<'py>,
) -> PyResult<Out<'py>> {
    seed_ma(py, m, alpha, seed::printed_eq19)
}

/// The seed's `<h.k>+` (eq. 23, our reading).
#[pyfunction]
#[pyo3(signature = (m, theta_k, exact_wallis=false))]
fn seed_hk_plus<'py>(
    py: Python<'py>,
    m: In<'py>,
    theta_k: In<'py>,
    exact_wallis: bool,
) -> PyResult<Out<'py>> {
    let f = if exact_wallis {
        seed::seed_hk_plus_exact_wallis
    } else {
        seed::seed_hk_plus
    };
    seed_mt(py, m, theta_k, f)
}

/// Seed eq. 23 as printed (for showing how it fails).
#[pyfunction]
fn seed_hk_plus_printed<'py>(py: Python<'py>, m: In<'py>, theta_k: In<'py>) -> PyResult<Out<'py>> {
    seed_mt(py, m, theta_k, seed::printed_eq23)
}

/// The seed's APS masking `P(k)`, in [0, 1].
#[pyfunction]
#[pyo3(signature = (m, theta_k, exact_wallis=false))]
fn seed_aps_p<'py>(
    py: Python<'py>,
    m: In<'py>,
    theta_k: In<'py>,
    exact_wallis: bool,
) -> PyResult<Out<'py>> {
    let f = if exact_wallis {
        seed::seed_aps_p_exact_wallis
    } else {
        seed::seed_aps_p
    };
    seed_mt(py, m, theta_k, f)
}

/// Exact Blinn-Phong `<h.k>+` from the exact reduction of seed eq. 18.
#[pyfunction]
fn hk_plus_eq18<'py>(py: Python<'py>, m: In<'py>, theta_k: In<'py>) -> PyResult<Out<'py>> {
    seed_mt(py, m, theta_k, seed::hk_plus_eq18)
}

/// Evaluate `f(dist, theta)` over theta_k broadcast with the roughness (m or alpha).
fn over_distribution<'py>(
    py: Python<'py>,
    theta_k: In<'py>,
    distribution: &str,
    m: Option<In<'py>>,
    alpha: Option<In<'py>>,
    f: impl Fn(&Distribution, f64) -> f64 + Send + Sync,
) -> PyResult<Out<'py>> {
    check_all(&theta_k, check_theta)?;
    let name = distribution.to_owned();
    match (m, alpha) {
        (Some(m), None) => map2(py, &theta_k, &m, ("theta_k", "m"), |t, m| {
            Ok(f(&Distribution::new(&name, Some(m), None)?, t))
        }),
        (None, Some(a)) => map2(py, &theta_k, &a, ("theta_k", "alpha"), |t, a| {
            Ok(f(&Distribution::new(&name, None, Some(a))?, t))
        }),
        (Some(_), Some(_)) => {
            Err(Error::param("m", "given with alpha", "give either m or alpha, not both").into())
        }
        (None, None) => {
            Distribution::new(&name, None, None)?;
            unreachable!("Distribution::new rejects a missing roughness")
        }
    }
}

/// Exact `<h.k>+ = int rho(h) max(0, h.k) d omega` (masking::hk_plus).
#[pyfunction]
#[pyo3(signature = (theta_k, distribution="blinn_phong", m=None, alpha=None))]
fn hk_plus<'py>(
    py: Python<'py>,
    theta_k: In<'py>,
    distribution: &str,
    m: Option<In<'py>>,
    alpha: Option<In<'py>>,
) -> PyResult<Out<'py>> {
    over_distribution(py, theta_k, distribution, m, alpha, masking::hk_plus)
}

/// Exact APS masking `P(k) = <h.n> cos / <h.k>+` (masking::aps_p).
#[pyfunction]
#[pyo3(signature = (theta_k, distribution="blinn_phong", m=None, alpha=None))]
fn aps_masking<'py>(
    py: Python<'py>,
    theta_k: In<'py>,
    distribution: &str,
    m: Option<In<'py>>,
    alpha: Option<In<'py>>,
) -> PyResult<Out<'py>> {
    over_distribution(py, theta_k, distribution, m, alpha, masking::aps_p)
}

/// Smith `G1 = 1/(1 + Lambda)` (masking::smith_lambda).
#[pyfunction]
#[pyo3(signature = (theta_k, distribution, m=None, alpha=None, variant="exact"))]
fn smith_g1<'py>(
    py: Python<'py>,
    theta_k: In<'py>,
    distribution: &str,
    m: Option<In<'py>>,
    alpha: Option<In<'py>>,
    variant: &str,
) -> PyResult<Out<'py>> {
    let v = SmithG1::from_str(variant).map_err(|_| {
        Error::param(
            "variant",
            format!("{variant:?}"),
            "expected \"exact\" or \"walter\"",
        )
    })?;
    over_distribution(py, theta_k, distribution, m, alpha, move |d, t| {
        let (s, c) = t.sin_cos();
        1.0 / (1.0 + masking::smith_lambda(d, v, c, s * s))
    })
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(wallis, m)?)?;
    m.add_function(wrap_pyfunction!(wallis_factorial, m)?)?;
    m.add_function(wrap_pyfunction!(_wallis_lgamma, m)?)?;
    m.add_function(wrap_pyfunction!(seed_wallis, m)?)?;
    m.add_function(wrap_pyfunction!(incomplete_cos_pow, m)?)?;
    m.add_function(wrap_pyfunction!(_incomplete_cos_pow_beta_reg, m)?)?;
    m.add_function(wrap_pyfunction!(seed_incomplete_cos_pow, m)?)?;
    m.add_function(wrap_pyfunction!(seed_incomplete_cos_pow_printed, m)?)?;
    m.add_function(wrap_pyfunction!(seed_hk_plus, m)?)?;
    m.add_function(wrap_pyfunction!(seed_hk_plus_printed, m)?)?;
    m.add_function(wrap_pyfunction!(seed_aps_p, m)?)?;
    m.add_function(wrap_pyfunction!(hk_plus_eq18, m)?)?;
    m.add_function(wrap_pyfunction!(hk_plus, m)?)?;
    m.add_function(wrap_pyfunction!(aps_masking, m)?)?;
    m.add_function(wrap_pyfunction!(smith_g1, m)?)?;
    Ok(())
}
