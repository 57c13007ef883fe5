//! Bindings for `crate::brdf`: the `Material` class and batched evaluation.

use crate::brdf::spec::Autocorrelation;
use crate::brdf::{self as core_brdf, MaterialSpec, Terms};
use crate::microfacet::{Correlation, Distribution, MaskingEval, Shadowing, SmithG1};
use crate::optics::frames::{Frame, V3};
use crate::optics::fresnel::{Eta, C64};
use numpy::ndarray::{Array1, Array2, Array3, ArrayView2};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rayon::prelude::*;
use std::str::FromStr;
use std::sync::Arc;

/// Per-parameter extractors for `Material(...)` (see `args`: strings, `None` or wrong
/// types raise `pprender.Error` naming the parameter).
mod material_args {
    use crate::optics::fresnel::C64;
    use crate::python::args;
    use pyo3::prelude::*;
    macro_rules! arg {
        ($f:ident, $kind:ident, $t:ty) => {
            pub fn $f(obj: &Bound<'_, PyAny>) -> PyResult<$t> {
                args::$kind(stringify!($f), obj)
            }
        };
    }
    arg!(distribution, name, String);
    arg!(m, opt_real, Option<f64>);
    arg!(alpha, opt_real, Option<f64>);
    arg!(eta, complex, C64);
    arg!(shadowing, name, String);
    arg!(correlation, opt_name, Option<String>);
    arg!(smith_g1, name, String);
    arg!(masking, name, String);
    arg!(terms, names, Vec<String>);
    arg!(diffuse_albedo, real, f64);
    arg!(name, opt_name, Option<String>);
    arg!(double_order, count, usize);
    arg!(coherent_backscatter, flag, bool);
    arg!(double_masking, name, String);
    arg!(wavelength, real, f64);
    arg!(correlation_length, real, f64);
    arg!(orders, name, String);
    arg!(bank_rays, opt_count, Option<usize>);
    arg!(autocorrelation, name, String);
    arg!(alpha_step, opt_real, Option<f64>);
}

/// A polarized microfacet material.
///
/// Material(distribution="blinn_phong", *, m=None, alpha=None, eta=1.5+0j,
///          shadowing="aps", correlation=None, smith_g1="exact", masking="table",
///          terms=("single", "multiple"), diffuse_albedo=0.0, name=None,
///          double_order=160, coherent_backscatter=True, double_masking="seed",
///          wavelength=1.064e-6, correlation_length=1e-5, orders="seed",
///          bank_rays=None, autocorrelation="gaussian", alpha_step=None)
///
/// distribution: "blinn_phong" (roughness exponent ``m`` in [0, 1e10]; m = 0 is
///     Lambertian-like, m -> inf a mirror), "beckmann" or "ggx" (``alpha`` in
///     [1e-5, 10]). Giving ``m`` to Beckmann/GGX or ``alpha`` to Blinn-Phong converts
///     with alpha = sqrt(2/(m+2)) (so Blinn-Phong takes ``alpha`` in [1.414214e-5, 1]).
/// eta: complex index n + ik of the surface (n > 0, k >= 0, ``|eta| <= 1e10``);
///     ``eta=inf`` is a perfect conductor (rs = -1, rp = 1: F = 1, the white-furnace
///     material).
/// shadowing: "aps" (Ashikhmin-Premoze-Shirley P(k), seed eq. 6-7), "smith"
///     (Smith G1 product) or "none" (single term only).
/// correlation: f(phi) of seed eq. 6: "seed" (cos(phi/2)), "aps" (exp(-7.3 phi^2)) or
///     "none"; default "seed" for APS and "none" for Smith.
/// smith_g1: "exact" or "walter" (Walter et al. 2007 rational approximation, as in
///     Mitsuba 3) for the Beckmann/Blinn-Phong Smith G1. For Blinn-Phong "exact" is the
///     Smith function of the Blinn-Phong distribution itself (Lambda = N_D / cos, the
///     uncorrelated APS masking) and "walter" Walter et al.'s recipe through Beckmann
///     with alpha = sqrt(2/(m+2)), which is not energy conserving below m ~ 20
///     (white-furnace albedo 1.34 at grazing for m = 0).
/// masking: how the APS masking integral is evaluated: "table" (per-material cubic
///     table, error below 1e-8; for Beckmann and GGX it tabulates their closed form,
///     Smith's cos(theta) Lambda, equal to the integral), "exact" (quadrature at each
///     call) or "seed" (the seed's closed form, Blinn-Phong only; error in
///     docs/seed-approximation.md).
/// terms: a sequence of any of "single", "double" (two facet reflections,
///     src/brdf/double.rs), "multiple" (energy-conserving depolarizing multiple
///     scattering: what single and double do not reflect), "diffuse" (Lambertian
///     under-layer with ``diffuse_albedo`` in [0, 1]).
/// name: a label (pprender.materials sets the material's name).
/// double_order: quadrature order of the double-bounce integral (per dimension; default
///     160, within 1e-4 of the term's M00 on docs/double-bounce-benchmark.md's pairs).
/// coherent_backscatter: add the coherent-backscatter enhancement, with width set by
///     ``wavelength`` (m) and ``correlation_length`` (m). With orders="seed": to the
///     double bounce, ``correlation_length`` the rms lateral separation of the two facets
///     (a Gaussian). With orders="surface": to order 2 (2x at backscatter in every
///     element) and to the orders beyond (less than 2x in some channels), each path
///     with its reverse as the banked surface has them, ``correlation_length`` the
///     surface's height correlation length l (C(r) ~ exp(-r^2 / l^2)); the width comes
///     from the paths' 3D separations (src/brdf/bank/coherent.rs; against the explicit
///     surface: docs/coherent-backscatter.md).
/// double_masking: "seed" (the material's correlated masking in the double bounce's
///     hit/escape probabilities: seed eq. 17, made reciprocal) or "uncorrelated".
/// wavelength: the wavelength (m) ``eta`` is for; :func:`pprender.render` refuses a
///     sensor at another wavelength. pprender.materials.get sets it.
/// orders: where orders >= 2 come from: "seed" (the double term above and the
///     depolarizing multiple term; the default of Material, which builds what its caller
///     spells out; pprender.materials.get gives its Beckmann materials in [0.05, 1]
///     "surface") or "surface" (Beckmann only, alpha in [0.05, 1]: the
///     paths of Gaussian-correlated surfaces, or Matern ones (``autocorrelation``),
///     src/brdf/bank.rs; "double" is order 2,
///     "multiple" the orders beyond the enabled ones, polarized, plus a depolarizing
///     remainder that closes the energy balance). The single term's masking is then
///     calibrated to the traced surface's order 1, G s(theta_i) s(theta_o) with s(theta)
///     1.00-1.05 (its white albedo equals the surface's at every incidence node, where
///     APS/Smith masking is 0.5-5% low, most at grazing), so the remainder carries only
///     the light past 8 reflections; without it the remainder stood for that order-1
///     light and made orders 3+ too strong and depolarized. So the single term of such a
///     material differs from that of Material(terms=("single",)) by those few per cent.
///     Against the explicit surface, order 2
///     is within 0.92-1.16 where the double term is 0.27-2.75 (CHANGELOG, issue 24).
///     Between alpha nodes the tables are interpolated along the small-slope similarity
///     of the surface (cot(theta) / alpha), which follows the lobes of orders >= 2 as they
///     move toward grazing with smaller alpha (docs/bank-alpha-interpolation.md states
///     its error). Below 0.3 these orders carry light only toward grazing incidence
///     (order 2: 0.6% at 70 deg and 5% at 80 deg for alpha 0.1), where the seed's
///     multiple term instead returned 0.01-0.24 /sr toward the source. Its
///     path banks (one per alpha node 0.05, 0.075, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, ...,
///     1.0 and ``bank_rays``) are traced on first use, once per machine (about a minute
///     per node on 2 cores at the default rays, less below 0.3, with a progress line on
///     stderr unless PPRENDER_PROGRESS=0), and cached on disk (0.1-0.3 GB per node at
///     0.3-1, 147 MB at alpha 0.5, less below) in pprender.cache_dir():
///     pprender.set_cache_dir(path), else the environment variable PPRENDER_CACHE_DIR
///     (empty or "off": memory only), else $XDG_CACHE_HOME/pprender, else
///     ~/.cache/pprender. Later processes read them (a new eta needs only its tables, a
///     few seconds); a missing, corrupt or stale entry (another pprender version or other
///     parameters) is traced again, never trusted (pprender.prune_cache() removes the
///     entries an older version left). The renderer's tables carry them
///     (docs/render-table.md). GGX and Blinn-Phong materials (the GGX paints of
///     pprender.materials among them) keep "seed": the banks' surfaces are Gaussian, so
///     Beckmann, and no explicit GGX surface is in the reference to check a GGX bank
///     against. Their double term has the error measured for Beckmann (0.27-2.75x the
///     surface's order 2); in the paints it is 4% of the backscatter return at normal
///     incidence and 10% at 60 deg, the rest being the diffuse layer.
/// bank_rays: primary rays per incidence node of each path bank (orders="surface"), in
///     [1000, 2^32]; None (default): the environment variable PPRENDER_BANK_RAYS if set
///     (the test suite sets 200000: banks 20x cheaper, noisier), else 4000000
///     (docs/bank-alpha-interpolation.md states the tables' noise at that count).
/// autocorrelation: the shape of the height autocorrelation of the banks' surfaces
///     (orders="surface"; refused with orders="seed"): "gaussian"
///     (default, C(r) = exp(-r^2 / l^2)) or "matern" (Matern of smoothness 5/2,
///     (1 + x + x^2/3) exp(-x) with x = sqrt(6) r / l: the same slope statistics, so the
///     same alpha, but slopes that stay correlated over longer distances; the single
///     term's calibration follows its banks' order 1, within a few per cent of the
///     Gaussian's). The shape changes orders >= 2 at the same alpha: on explicit surfaces
///     at alpha 0.5-1 the Matern's order 2 is 0.57-1.05x the Gaussian's and its orders 3+
///     0.9-2.0x
///     (docs/surface-orders-reference.md, which scores each shape's banks against
///     surfaces of that shape). ``correlation_length`` is l for both. Each shape has its
///     own banks (traced and cached as above).
/// alpha_step: None (default) builds the material's albedo and escape tables (those that
///     normalize the multiple, diffuse and double terms) at ``alpha`` itself. A step h in
///     (0, 1] interpolates them instead, Catmull-Rom in ln(alpha), from the materials at
///     the four nodes alpha = exp(j h) about it, which are built once per process and
///     kept (the 64 most recently used). The single term is always exact. For loops and
///     fits over alpha with the double or multiple term: the first material in a new
///     range of alpha costs four builds, later ones milliseconds (docs/material-build.md
///     measures both, and the interpolation's error against the exact build). With
///     orders="surface" (and the double or multiple term) the banks' orders are mixed at
///     alpha itself as always (milliseconds once the banks' node tables are built) and the
///     nodes give the single term's calibration to the traced surface (its slow part):
///     the nodes then divide the interval between the banks' alpha nodes (above) that
///     holds alpha into steps of at most h in ln(alpha), never across a bank node. (A fit over alpha can instead interpolate its renders between node
///     materials, Fit's own alpha_step.)
///
/// Invalid values (out of range, or of the wrong type, e.g. a number as a string) raise
/// pprender.Error naming the parameter.
#[pyclass(module = "pprender", name = "Material", frozen)]
pub struct PyMaterial {
    pub inner: Arc<core_brdf::Material>,
    name: Option<String>,
    dist_name: &'static str,
}

fn parse_eta(eta: C64) -> crate::Result<Eta> {
    if eta.re.is_nan() || eta.im.is_nan() {
        return Err(crate::Error::param("eta", eta, "must not be NaN"));
    }
    if eta.re == f64::INFINITY && (eta.im == 0.0 || eta.im == f64::INFINITY) {
        return Ok(Eta::PerfectConductor);
    }
    Ok(Eta::Complex(eta))
}

#[pymethods]
impl PyMaterial {
    #[new]
    #[pyo3(signature = (distribution=String::from("blinn_phong"), *, m=None, alpha=None,
        eta=C64::new(1.5, 0.0), shadowing=String::from("aps"), correlation=None,
        smith_g1=String::from("exact"), masking=String::from("table"),
        terms=vec!["single".to_string(), "multiple".to_string()], diffuse_albedo=0.0, name=None,
        double_order=MaterialSpec::DOUBLE_ORDER, coherent_backscatter=true,
        double_masking=String::from("seed"),
        wavelength=MaterialSpec::WAVELENGTH, correlation_length=MaterialSpec::CORRELATION_LENGTH,
        orders=String::from("seed"), bank_rays=None, autocorrelation=String::from("gaussian"),
        alpha_step=None),
        text_signature = "(distribution='blinn_phong', *, m=None, alpha=None, eta=(1.5+0j), \
shadowing='aps', correlation=None, smith_g1='exact', masking='table', \
terms=('single', 'multiple'), diffuse_albedo=0.0, name=None, double_order=160, \
coherent_backscatter=True, double_masking='seed', wavelength=1.064e-06, \
correlation_length=1e-05, orders='seed', bank_rays=None, autocorrelation='gaussian', \
alpha_step=None)")]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = material_args::distribution)] distribution: String,
        #[pyo3(from_py_with = material_args::m)] m: Option<f64>,
        #[pyo3(from_py_with = material_args::alpha)] alpha: Option<f64>,
        #[pyo3(from_py_with = material_args::eta)] eta: C64,
        #[pyo3(from_py_with = material_args::shadowing)] shadowing: String,
        #[pyo3(from_py_with = material_args::correlation)] correlation: Option<String>,
        #[pyo3(from_py_with = material_args::smith_g1)] smith_g1: String,
        #[pyo3(from_py_with = material_args::masking)] masking: String,
        #[pyo3(from_py_with = material_args::terms)] terms: Vec<String>,
        #[pyo3(from_py_with = material_args::diffuse_albedo)] diffuse_albedo: f64,
        #[pyo3(from_py_with = material_args::name)] name: Option<String>,
        #[pyo3(from_py_with = material_args::double_order)] double_order: usize,
        #[pyo3(from_py_with = material_args::coherent_backscatter)] coherent_backscatter: bool,
        #[pyo3(from_py_with = material_args::double_masking)] double_masking: String,
        #[pyo3(from_py_with = material_args::wavelength)] wavelength: f64,
        #[pyo3(from_py_with = material_args::correlation_length)] correlation_length: f64,
        #[pyo3(from_py_with = material_args::orders)] orders: String,
        #[pyo3(from_py_with = material_args::bank_rays)] bank_rays: Option<usize>,
        #[pyo3(from_py_with = material_args::autocorrelation)] autocorrelation: String,
        #[pyo3(from_py_with = material_args::alpha_step)] alpha_step: Option<f64>,
    ) -> PyResult<Self> {
        let (distribution, shadowing, smith_g1, masking, double_masking) = (
            distribution.as_str(),
            shadowing.as_str(),
            smith_g1.as_str(),
            masking.as_str(),
            double_masking.as_str(),
        );
        let correlation = correlation.as_deref();
        let dist = Distribution::new(distribution, m, alpha)?;
        let spec = MaterialSpec {
            distribution: dist,
            eta: parse_eta(eta)?,
            shadowing: Shadowing::from_str(shadowing)?,
            correlation: correlation.map(Correlation::from_str).transpose()?,
            smith_g1: SmithG1::from_str(smith_g1)?,
            masking: MaskingEval::from_str(masking)?,
            terms: Terms::parse(&terms)?,
            diffuse_albedo,
            double_order,
            coherent_backscatter,
            double_correlated: match double_masking {
                "seed" => true,
                "uncorrelated" => false,
                other => return Err(crate::Error::param(
                    "double_masking",
                    format!("{other:?}"),
                    "expected \"seed\" (correlated, eq. 17 made reciprocal) or \"uncorrelated\"",
                )
                .into()),
            },
            wavelength,
            correlation_length,
            orders: crate::brdf::spec::Orders::from_name(&orders)?,
            bank_rays: match bank_rays {
                Some(n) => n as u64,
                None => default_bank_rays(|k| std::env::var_os(k))?,
            },
            autocorrelation: Autocorrelation::from_name(&autocorrelation)?,
            alpha_step,
        };
        let inner = py.detach(|| core_brdf::Material::new(spec))?;
        let dist_name = match dist {
            Distribution::BlinnPhong { .. } => "blinn_phong",
            Distribution::Beckmann { .. } => "beckmann",
            Distribution::Ggx { .. } => "ggx",
        };
        Ok(PyMaterial {
            inner: Arc::new(inner),
            name,
            dist_name,
        })
    }

    #[getter]
    fn distribution(&self) -> &'static str {
        self.dist_name
    }
    /// Blinn-Phong exponent (None for Beckmann/GGX).
    #[getter]
    fn m(&self) -> Option<f64> {
        match self.inner.spec.distribution {
            Distribution::BlinnPhong { m } => Some(m),
            _ => None,
        }
    }
    /// Beckmann/GGX roughness (None for Blinn-Phong).
    #[getter]
    fn alpha(&self) -> Option<f64> {
        match self.inner.spec.distribution {
            Distribution::Beckmann { alpha } | Distribution::Ggx { alpha } => Some(alpha),
            _ => None,
        }
    }
    #[getter]
    fn eta(&self) -> C64 {
        match self.inner.spec.eta {
            Eta::Complex(e) => e,
            Eta::PerfectConductor => C64::new(f64::INFINITY, 0.0),
        }
    }
    #[getter]
    fn shadowing(&self) -> &'static str {
        match self.inner.spec.shadowing {
            Shadowing::Aps => "aps",
            Shadowing::Smith => "smith",
            Shadowing::None => "none",
        }
    }
    #[getter]
    fn correlation(&self) -> &'static str {
        match self.inner.correlation {
            Correlation::Seed => "seed",
            Correlation::Aps => "aps",
            Correlation::None => "none",
        }
    }
    #[getter]
    fn smith_g1(&self) -> &'static str {
        match self.inner.spec.smith_g1 {
            SmithG1::Exact => "exact",
            SmithG1::Walter => "walter",
        }
    }
    #[getter]
    fn masking(&self) -> &'static str {
        match self.inner.spec.masking {
            MaskingEval::Exact => "exact",
            MaskingEval::Table => "table",
            MaskingEval::Seed => "seed",
        }
    }
    #[getter]
    fn terms(&self) -> Vec<&'static str> {
        self.inner.spec.terms.names()
    }
    #[getter]
    fn double_order(&self) -> usize {
        self.inner.spec.double_order
    }
    #[getter]
    fn coherent_backscatter(&self) -> bool {
        self.inner.spec.coherent_backscatter
    }
    #[getter]
    fn double_masking(&self) -> &'static str {
        if self.inner.spec.double_correlated {
            "seed"
        } else {
            "uncorrelated"
        }
    }
    #[getter]
    fn wavelength(&self) -> f64 {
        self.inner.spec.wavelength
    }
    #[getter]
    fn orders(&self) -> &'static str {
        self.inner.spec.orders.name()
    }

    /// The shape of the path banks' height autocorrelation ("gaussian" or "matern").
    #[getter]
    fn autocorrelation(&self) -> &'static str {
        self.inner.spec.autocorrelation.name()
    }
    #[getter]
    fn bank_rays(&self) -> u64 {
        self.inner.spec.bank_rays
    }
    /// The step of the alpha nodes the albedo and escape tables are interpolated from
    /// (None: built at ``alpha`` itself).
    #[getter]
    fn alpha_step(&self) -> Option<f64> {
        self.inner.spec.alpha_step
    }
    #[getter]
    fn correlation_length(&self) -> f64 {
        self.inner.spec.correlation_length
    }
    #[getter]
    fn diffuse_albedo(&self) -> f64 {
        self.inner.spec.diffuse_albedo
    }
    #[getter]
    fn name(&self) -> Option<String> {
        self.name.clone()
    }
    /// Hemispherical average E_avg of the white (F = 1) single-bounce albedo (None if the
    /// material has no multiple/diffuse term and so no albedo table).
    #[getter]
    fn e_avg(&self) -> Option<f64> {
        self.inner.e_white.as_ref().map(|t| t.e_avg)
    }
    /// Kulla-Conty Fresnel factor of the multiple term.
    #[getter]
    fn f_ms(&self) -> f64 {
        self.inner.f_ms
    }

    fn __repr__(&self) -> String {
        let rough = match self.inner.spec.distribution {
            Distribution::BlinnPhong { m } => format!("m={m}"),
            Distribution::Beckmann { alpha } | Distribution::Ggx { alpha } => {
                format!("alpha={alpha}")
            }
        };
        let eta = match self.inner.spec.eta {
            Eta::Complex(e) => format!("{}{:+}j", e.re, e.im),
            Eta::PerfectConductor => "inf".into(),
        };
        let name = self
            .name
            .as_ref()
            .map(|n| format!(", name={n:?}"))
            .unwrap_or_default();
        // the orders >= 2 (and their banks' rays) when not the seed's: they change the
        // numbers, so two materials that differ there must not print alike
        let spec = &self.inner.spec;
        let orders = match spec.orders {
            crate::brdf::spec::Orders::Seed => String::new(),
            o => {
                let rays = if spec.bank_rays == MaterialSpec::BANK_RAYS {
                    String::new()
                } else {
                    format!(", bank_rays={}", spec.bank_rays)
                };
                let shape = match spec.autocorrelation {
                    Autocorrelation::Gaussian => String::new(),
                    a => format!(", autocorrelation={:?}", a.name()),
                };
                format!(", orders={:?}{rays}{shape}", o.name())
            }
        };
        format!(
            "Material({:?}, {rough}, eta={eta}, shadowing={:?}, terms={:?}{orders}{})",
            self.dist_name,
            self.shadowing(),
            self.terms(),
            name
        )
    }
}

/// The environment variable that sets `Material(bank_rays=None)`.
const BANK_RAYS_ENV: &str = "PPRENDER_BANK_RAYS";

/// `bank_rays` when not given: `PPRENDER_BANK_RAYS` (an integer in [1000, 2^32]; anything
/// else is refused, naming the variable) if set and not empty, else
/// [`MaterialSpec::BANK_RAYS`]. `var` reads the environment (a parameter, for the tests).
fn default_bank_rays(var: impl Fn(&str) -> Option<std::ffi::OsString>) -> crate::Result<u64> {
    let Some(v) = var(BANK_RAYS_ENV).filter(|v| !v.is_empty()) else {
        return Ok(MaterialSpec::BANK_RAYS);
    };
    let text = v.to_string_lossy();
    match text.trim().parse::<u64>() {
        Ok(n) if (1_000..=1u64 << 32).contains(&n) => Ok(n),
        _ => Err(crate::Error::param(
            BANK_RAYS_ENV,
            format!("{text:?}"),
            "an integer in [1000, 2^32] (the default bank_rays of Material)",
        )),
    }
}

/// Validate and normalize an (N, 3) array of directions in the upper hemisphere.
pub fn directions(a: ArrayView2<'_, f64>, name: &'static str) -> crate::Result<Vec<V3>> {
    if a.ncols() != 3 {
        return Err(crate::Error::Shape(format!(
            "{name} must have shape (..., 3), got last axis {}",
            a.ncols()
        )));
    }
    a.rows()
        .into_iter()
        .enumerate()
        .map(|(i, r)| direction([r[0], r[1], r[2]], name, i))
        .collect()
}

fn to_array3(n: usize, data: Vec<[[f64; 4]; 4]>) -> Array3<f64> {
    let flat: Vec<f64> = data
        .into_iter()
        .flat_map(|m| m.into_iter().flatten())
        .collect();
    Array3::from_shape_vec((n, 4, 4), flat).expect("shape")
}

/// Batches below this run on one thread (rayon's overhead dominates).
const PAR_MIN: usize = 2048;

/// Validate and normalize one direction (row `i` of the parameter `name`).
#[inline]
fn direction(v: [f64; 3], name: &'static str, i: usize) -> crate::Result<V3> {
    if !v.iter().all(|x| x.is_finite()) {
        return Err(crate::Error::InvalidDirection {
            name,
            reason: format!("element {i} = {v:?} is not finite"),
        });
    }
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if (l - 1.0).abs() > 1e-6 {
        return Err(crate::Error::InvalidDirection {
            name,
            reason: format!("element {i} = {v:?} has length {l}; directions must be unit vectors (|w| - 1 within 1e-6)"),
        });
    }
    if v[2] < 0.0 {
        return Err(crate::Error::InvalidDirection {
            name,
            reason: format!("element {i} = {v:?} is below the horizon (z < 0); directions point away from the surface, z >= 0"),
        });
    }
    Ok(V3::from_array(v) / l)
}

#[pyfunction]
#[pyo3(name = "brdf")]
fn brdf_eval<'py>(
    py: Python<'py>,
    material: &PyMaterial,
    wi: PyReadonlyArray2<'py, f64>,
    wo: PyReadonlyArray2<'py, f64>,
    frame: &str,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let frame = Frame::from_str(frame)?;
    let (wi, wo) = (wi.as_array(), wo.as_array());
    for (a, name) in [(&wi, "wi"), (&wo, "wo")] {
        if a.ncols() != 3 {
            return Err(crate::Error::Shape(format!(
                "{name} must have shape (..., 3), got last axis {}",
                a.ncols()
            ))
            .into());
        }
    }
    if wi.nrows() != wo.nrows() {
        return Err(crate::Error::Shape(format!(
            "wi and wo have {} and {} directions",
            wi.nrows(),
            wo.nrows()
        ))
        .into());
    }
    let n = wi.nrows();
    // Contiguous row-major input (the Python wrapper guarantees it) read in place.
    let (Some(a), Some(b)) = (wi.as_slice(), wo.as_slice()) else {
        return Err(crate::Error::Shape("wi and wo must be C-contiguous".into()).into());
    };
    let mat = material.inner.clone();
    // Uninitialized output, filled in parallel: no zeroing pass, no intermediate copies.
    let out = unsafe { PyArray3::<f64>::new(py, [n, 4, 4], false) };
    let buf = unsafe { out.as_slice_mut() }.expect("fresh contiguous array");
    let result: crate::Result<()> = py.detach(|| {
        let f = |(i, dst): (usize, &mut [f64])| -> crate::Result<()> {
            let x = direction([a[3 * i], a[3 * i + 1], a[3 * i + 2]], "wi", i)?;
            let y = direction([b[3 * i], b[3 * i + 1], b[3 * i + 2]], "wo", i)?;
            let m = core_brdf::eval(&mat, x, y, frame);
            for (d, s) in dst.iter_mut().zip(m.iter().flatten()) {
                *d = *s;
            }
            Ok(())
        };
        // A double-bounce evaluation costs milliseconds: parallel from two pairs then.
        let par_min = if mat.spec.terms.double { 2 } else { PAR_MIN };
        if n >= par_min {
            buf.par_chunks_mut(16).enumerate().try_for_each(f)
        } else {
            buf.chunks_mut(16).enumerate().try_for_each(f)
        }
    });
    result?;
    Ok(out)
}

#[pyfunction]
fn specular<'py>(
    py: Python<'py>,
    material: &PyMaterial,
    wi: PyReadonlyArray2<'py, f64>,
    frame: &str,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let frame = Frame::from_str(frame)?;
    let wi = directions(wi.as_array(), "wi")?;
    let mat = material.inner.clone();
    let n = wi.len();
    let v: Vec<_> = wi
        .iter()
        .map(|w| core_brdf::specular(&mat, *w, frame))
        .collect();
    Ok(to_array3(n, v).into_pyarray(py))
}

#[pyfunction]
fn albedo<'py>(
    py: Python<'py>,
    material: &PyMaterial,
    cos_theta_i: PyReadonlyArray1<'py, f64>,
    order: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    if !(8..=4096).contains(&order) {
        return Err(
            crate::Error::param("order", order, "quadrature order must be in [8, 4096]").into(),
        );
    }
    let c: Vec<f64> = cos_theta_i.as_array().to_vec();
    if let Some(bad) = c
        .iter()
        .find(|x| !(x.is_finite() && (0.0..=1.0).contains(*x)))
    {
        return Err(crate::Error::param("wi", bad, "cos(theta_i) = wi.z must be in [0, 1]").into());
    }
    let mat = material.inner.clone();
    let out = py.detach(move || {
        c.par_iter()
            .map(|&x| core_brdf::albedo(&mat, x, order))
            .collect::<Vec<f64>>()
    });
    Ok(Array1::from(out).into_pyarray(py))
}

/// Jones matrix of one double-reflection path `-wi -> h1 -> d -> h2 -> wo` (beam frames of
/// `frame`), with `d` and `h2`; `None` when the path does not exist.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn double_jones(
    material: &PyMaterial,
    wi: [f64; 3],
    wo: [f64; 3],
    h1: [f64; 3],
    frame: &str,
) -> PyResult<Option<([[C64; 2]; 2], [f64; 3], [f64; 3])>> {
    let frame = Frame::from_str(frame)?;
    let wi = direction(wi, "wi", 0)?;
    let wo = direction(wo, "wo", 0)?;
    let h1 = direction(h1, "h1", 0)?;
    Ok(
        crate::brdf::double::double_jones(&material.inner, wi, wo, h1, frame)
            .map(|(j, d, h2)| (j, d.to_array(), h2.to_array())),
    )
}

/// Monostatic table: (theta nodes, Mueller values (n+1, 4, 4), build seconds, max
/// interpolation error relative to M00 against the material's own evaluation).
#[pyfunction]
#[pyo3(signature = (material, nodes=64, double_order=48, measure=true))]
#[allow(clippy::type_complexity)]
fn monostatic_table<'py>(
    py: Python<'py>,
    material: &PyMaterial,
    nodes: usize,
    double_order: usize,
    measure: bool,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray3<f64>>,
    f64,
    Option<f64>,
)> {
    if !(4..=100_000).contains(&nodes) {
        return Err(crate::Error::param("nodes", nodes, "must be in [4, 100000]").into());
    }
    if !(4..=1024).contains(&double_order) {
        return Err(
            crate::Error::param("double_order", double_order, "must be in [4, 1024]").into(),
        );
    }
    let mat = material.inner.clone();
    let (table, secs, err) = py.detach(move || {
        let t0 = std::time::Instant::now();
        let table = crate::brdf::table::MonostaticTable::build(&mat, nodes, double_order);
        let secs = t0.elapsed().as_secs_f64();
        let err = if measure {
            Some(table.max_error(&mat))
        } else {
            None
        };
        (table, secs, err)
    });
    let scale = table.elements[0].scale;
    let n = nodes + 1;
    let theta: Vec<f64> = (0..n)
        .map(|i| crate::microfacet::masking::ZTable::theta_of_z(scale, i as f64 / nodes as f64))
        .collect();
    let mut vals = Array3::<f64>::zeros((n, 4, 4));
    for i in 0..n {
        let m00 = table.elements[0].values[i].exp();
        vals[[i, 0, 0]] = m00;
        for (k, t) in table.elements.iter().enumerate().skip(1) {
            vals[[i, k / 4, k % 4]] = m00 * t.values[i];
        }
    }
    Ok((
        Array1::from(theta).into_pyarray(py),
        vals.into_pyarray(py),
        secs,
        err,
    ))
}

/// The total Mueller BRDF tabulated for the renderer (`crate::brdf::table::BrdfTable`).
#[pyclass(module = "pprender", name = "BrdfTable", frozen)]
pub struct PyBrdfTable {
    table: crate::brdf::table::BrdfTable,
    material: Arc<core_brdf::Material>,
    build_seconds: f64,
}

fn mat4_to_array<'py>(py: Python<'py>, m: [[f64; 4]; 4]) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_vec((4, 4), m.into_iter().flatten().collect())
        .expect("shape")
        .into_pyarray(py)
}

#[pymethods]
impl PyBrdfTable {
    /// Interpolated BRDF (4, 4) at table coordinates, in the table's frame.
    fn eval<'py>(
        &self,
        py: Python<'py>,
        theta: f64,
        psi: f64,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        if !(theta.is_finite() && (0.0..=std::f64::consts::FRAC_PI_2).contains(&theta)) {
            return Err(crate::Error::param("theta", theta, "must be in [0, pi/2] radians").into());
        }
        if !(psi.is_finite() && psi.abs() <= std::f64::consts::PI) {
            return Err(crate::Error::param("psi", psi, "must be in [-pi, pi] radians").into());
        }
        Ok(mat4_to_array(py, self.table.eval(theta, psi)))
    }

    /// Interpolated BRDF (4, 4) for local unit directions, in the core's "sp" frame.
    fn eval_dirs<'py>(
        &self,
        py: Python<'py>,
        wi: [f64; 3],
        wo: [f64; 3],
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let wi = direction(wi, "wi", 0)?;
        let wo = direction(wo, "wo", 0)?;
        Ok(mat4_to_array(py, self.table.eval_dirs(wi, wo)))
    }

    /// Largest interpolation error at the cell centres with theta <= theta_max, per part.
    #[pyo3(signature = (theta_max=85f64.to_radians(), dynamic_range=crate::brdf::table::DYNAMIC_RANGE))]
    fn max_error<'py>(
        &self,
        py: Python<'py>,
        theta_max: f64,
        dynamic_range: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(theta_max.is_finite() && theta_max >= 0.0) {
            return Err(crate::Error::param("theta_max", theta_max, "must be >= 0 radians").into());
        }
        if !(dynamic_range.is_finite() && dynamic_range >= 0.0) {
            return Err(crate::Error::param(
                "dynamic_range",
                dynamic_range,
                "must be finite and >= 0",
            )
            .into());
        }
        let (table, mat) = (&self.table, self.material.clone());
        let e = py.detach(|| table.max_error(&mat, theta_max, dynamic_range));
        let d = PyDict::new(py);
        d.set_item("max", e.max)?;
        let parts = PyList::empty(py);
        for p in e.parts {
            let pd = PyDict::new(py);
            pd.set_item("kind", p.kind)?;
            pd.set_item("max", p.max)?;
            pd.set_item("theta", p.theta)?;
            pd.set_item("psi", p.psi)?;
            pd.set_item("element", (p.element / 4, p.element % 4))?;
            pd.set_item("points", p.points)?;
            parts.append(pd)?;
        }
        d.set_item("parts", parts)?;
        Ok(d)
    }

    /// Seconds the build took.
    #[getter]
    fn build_seconds(&self) -> f64 {
        self.build_seconds
    }
    #[getter]
    fn bistatic_angle(&self) -> f64 {
        self.table.beta
    }
    #[getter]
    fn frame(&self) -> &'static str {
        match self.table.frame {
            crate::brdf::table::TableFrame::Sp => "sp",
            crate::brdf::table::TableFrame::Bisector => "bisector",
        }
    }
    /// What each part holds: "single", "multiple+diffuse", "double".
    #[getter]
    fn kinds(&self) -> Vec<&'static str> {
        self.table.kinds.iter().map(|k| k.name()).collect()
    }

    /// Per part: whether its nodes hold `M cos(theta)` instead of `M` (the single term
    /// with correlated masking, which diverges as `1 / cos` at grazing; `TablePart::cos_weighted`).
    #[getter]
    fn cos_weighted(&self) -> Vec<bool> {
        self.table.parts.iter().map(|p| p.cos_weighted).collect()
    }

    /// Per part: (scale, n_z, n_psi, data) with data of shape (n_psi + 1, n_z + 1, 16)
    /// (node `k = 0`: `ln M00`, of `M00 cos(theta)` for a `cos_weighted` part).
    #[allow(clippy::type_complexity)]
    fn arrays<'py>(&self, py: Python<'py>) -> Vec<(f64, usize, usize, Bound<'py, PyArray3<f64>>)> {
        self.table
            .parts
            .iter()
            .map(|p| {
                let a = Array3::from_shape_vec((p.n_psi + 1, p.n_z + 1, 16), p.data.clone())
                    .expect("shape");
                (p.scale, p.n_z, p.n_psi, a.into_pyarray(py))
            })
            .collect()
    }

    fn __repr__(&self) -> String {
        let parts: Vec<String> = self
            .table
            .kinds
            .iter()
            .zip(&self.table.parts)
            .map(|(k, p)| format!("{}: {}x{}", k.name(), p.n_z, p.n_psi))
            .collect();
        format!(
            "BrdfTable(bistatic_angle={}, frame={:?}, parts=[{}])",
            self.table.beta,
            self.frame(),
            parts.join(", ")
        )
    }
}

/// Build a `BrdfTable` (see `crate::brdf::table`).
#[pyfunction]
#[pyo3(signature = (material, bistatic_angle=0.0, n_z=None, n_psi=None, double_order=None, *,
    n_z_lambertian=None, n_psi_lambertian=None, n_z_double=None, n_psi_double=None,
    scale=None, scale_lambertian=None, scale_double=None, frame="bisector"))]
#[allow(clippy::too_many_arguments)]
fn brdf_table(
    py: Python<'_>,
    material: &PyMaterial,
    bistatic_angle: f64,
    n_z: Option<usize>,
    n_psi: Option<usize>,
    double_order: Option<usize>,
    n_z_lambertian: Option<usize>,
    n_psi_lambertian: Option<usize>,
    n_z_double: Option<usize>,
    n_psi_double: Option<usize>,
    scale: Option<f64>,
    scale_lambertian: Option<f64>,
    scale_double: Option<f64>,
    frame: &str,
) -> PyResult<PyBrdfTable> {
    use crate::brdf::table::{BrdfTable, BrdfTableOptions, PartOptions, TableFrame};
    let frame = match frame {
        "bisector" => TableFrame::Bisector,
        "sp" => TableFrame::Sp,
        other => {
            return Err(crate::Error::param(
                "frame",
                format!("{other:?}"),
                "expected \"bisector\" or \"sp\"",
            )
            .into())
        }
    };
    let opts = BrdfTableOptions {
        single: PartOptions { n_z, n_psi, scale },
        depolarizing: PartOptions {
            n_z: n_z_lambertian,
            n_psi: n_psi_lambertian,
            scale: scale_lambertian,
        },
        double: PartOptions {
            n_z: n_z_double,
            n_psi: n_psi_double,
            scale: scale_double,
        },
        double_order,
        frame: Some(frame),
        in_shader: false,
    };
    let mat = material.inner.clone();
    let (table, secs) = py.detach(|| {
        let t0 = std::time::Instant::now();
        let t = BrdfTable::build(&mat, bistatic_angle, &opts);
        (t, t0.elapsed().as_secs_f64())
    });
    Ok(PyBrdfTable {
        table: table?,
        material: mat,
        build_seconds: secs,
    })
}

/// Coherent-backscatter decorrelation factor gamma for a material and directions.
#[pyfunction]
fn cbe_gamma(material: &PyMaterial, wi: [f64; 3], wo: [f64; 3]) -> f64 {
    let s = &material.inner.spec;
    crate::brdf::double::cbe_gamma(
        s.wavelength,
        s.correlation_length,
        V3::from_array(wi),
        V3::from_array(wo),
    )
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(double_jones, m)?)?;
    m.add_function(wrap_pyfunction!(cbe_gamma, m)?)?;
    m.add_function(wrap_pyfunction!(monostatic_table, m)?)?;
    m.add_function(wrap_pyfunction!(brdf_table, m)?)?;
    m.add_class::<PyBrdfTable>()?;
    m.add_class::<PyMaterial>()?;
    m.add_function(wrap_pyfunction!(brdf_eval, m)?)?;
    m.add_function(wrap_pyfunction!(specular, m)?)?;
    m.add_function(wrap_pyfunction!(albedo, m)?)?;
    Ok(())
}
