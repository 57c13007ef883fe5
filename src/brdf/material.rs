//! [`Material`]: a validated [`MaterialSpec`] on its [`Surface`], with the tables the
//! terms need derived from them (albedos, escape after a bounce).

use super::bank::{N_THETA, THETA_STEP};
use super::orders::{Part, SurfaceOrders, ALPHA_NODES as BANK_ALPHA_NODES};
use super::spec::{Autocorrelation, Orders};
pub use super::spec::{MaterialSpec, Term, Terms};
pub use super::surface::Surface;
use crate::microfacet::distribution::{ALPHA_MAX, ALPHA_MIN};
use crate::microfacet::masking::{catmull_rom, ZTable, TABLE_NODES};
use crate::microfacet::{Distribution, MaskingEval, Shadowing};
use crate::optics::frames::V3;
use crate::optics::fresnel::{average_reflectance, Eta};
use crate::{Error, Result};
use std::sync::Arc;

/// Albedo tables of one layer (see [`ZTable`]).
#[derive(Debug, Clone, PartialEq)]
pub struct AlbedoTable {
    /// Directional albedo `E(theta)`: at nodes uniform in the material's `z`, or with
    /// `fresnel_scale` in `zeta` ([`zeta_of`]).
    pub e: ZTable,
    /// `E_avg = 2 int E(mu) mu dmu`.
    pub e_avg: f64,
    /// `Some(s_f)`: nodes uniform in `zeta = (z_s + z_1 + z_f) / 3`, the mean of the `z`
    /// coordinates of scale `s` (the material's), 1 and `s_f` ([`fresnel_scale`]). For
    /// the albedos with the Fresnel factor: the `z` grid of scale `s` resolves the lobe
    /// near grazing but, for small `s`, leaves the middle of the range to a few intervals
    /// (for alpha = 1e-5 one interval spans 0 to 89.8 deg), where such an albedo follows
    /// the Fresnel curve; `z_1` is about uniform in `theta`, and `z_f` resolves the
    /// Fresnel curve's own feature at grazing (the rise of `R` within `sqrt|eta^2 - 1|`
    /// for eta near 1, the pseudo-Brewster dip at `cos ~ 1/|eta|` for large `|eta|`),
    /// which a smooth surface's albedo follows. Tabulated in `z` alone, the diffuse paint's
    /// albedo exceeded 1 by 0.68 at alpha = 1e-5 (1e-2 at 1e-3); in `(z_s + z_1)/2`, by
    /// 2.5e-4 for eta = 1 + 1e-6 or 1e3 + 1e3i at alpha = 1e-5.
    pub fresnel_scale: Option<f64>,
}

/// The angular scale of the unpolarized Fresnel reflectance's feature at grazing:
/// `min(1, sqrt|eta^2 - 1|, 1/|eta|)` (1 for a perfect conductor).
pub fn fresnel_scale(eta: Eta) -> f64 {
    match eta {
        Eta::PerfectConductor => 1.0,
        Eta::Complex(e) => {
            let e2m1 = ((e - 1.0) * (e + 1.0)).norm().sqrt();
            1f64.min(e2m1).min(1.0 / e.norm()).max(1e-300)
        }
    }
}

/// `z` of scale `scale` from `cos`, `sin`.
#[inline]
fn z_scaled(scale: f64, c: f64, s: f64) -> f64 {
    let den = scale * s + c;
    if den > 0.0 {
        (c / den).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// `zeta` of [`AlbedoTable::fresnel_scale`] from `cos`, `sin`, `z_s` and `s_f`.
#[inline]
pub fn zeta_of(c: f64, s: f64, z: f64, s_f: f64) -> f64 {
    (z + z_scaled(1.0, c, s) + z_scaled(s_f, c, s)) / 3.0
}

/// `theta` of a `zeta` in [0, 1] (bisection: `zeta` falls from 1 at `theta = 0` to 0 at
/// `pi/2`).
fn theta_of_zeta(scale: f64, s_f: f64, zeta: f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, std::f64::consts::FRAC_PI_2);
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        let (s, c) = mid.sin_cos();
        if zeta_of(c, s, z_scaled(scale, c, s), s_f) > zeta {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

impl AlbedoTable {
    /// `E` at a direction with `cos theta = c`, `sin theta = s` and material coordinate `z`.
    #[inline]
    pub fn eval_csz(&self, c: f64, s: f64, z: f64) -> f64 {
        match self.fresnel_scale {
            Some(s_f) => self.e.eval_z(zeta_of(c, s, z, s_f)),
            None => self.e.eval_z(z),
        }
    }
}

/// The angle of node `i` of `n` of an albedo table (scale, [`AlbedoTable::fresnel_scale`]).
fn node_theta(scale: f64, s_f: Option<f64>, i: usize, n: usize) -> f64 {
    match s_f {
        Some(s_f) => theta_of_zeta(scale, s_f, i as f64 / n as f64),
        None => ZTable::theta_of_z(scale, i as f64 / n as f64),
    }
}

/// A validated material with its caches.
#[derive(Debug, Clone)]
pub struct Material {
    /// The spec, the masking correlation and its table (the material dereferences to it).
    pub surface: Surface,
    /// Single-scattering albedo with `F = 1`, for the multiple term.
    pub(crate) e_white: Option<AlbedoTable>,
    /// Kulla-Conty factor `F_ms = F_avg^2 E_avg / (1 - F_avg (1 - E_avg))`.
    pub f_ms: f64,
    /// Albedo of the specular layer (single + multiple, real Fresnel), for the diffuse term.
    pub(crate) e_spec: Option<AlbedoTable>,
    /// Escape after a bounce, `S(v)` (F = 1), when "double" is on: (v up, v down) tables
    /// in `z` of `|v_z|` (the integrand changes form at the horizon, so two tables).
    pub(crate) s_white: Option<(ZTable, ZTable)>,
    /// The same with the unpolarized Fresnel reflectance.
    pub(crate) s_fresnel: Option<(ZTable, ZTable)>,
    /// With `orders = Surface` and "double" or "multiple" on: the path banks' orders
    /// ([`super::orders`]).
    pub surface_orders: Option<std::sync::Arc<SurfaceOrders>>,
}

impl std::ops::Deref for Material {
    type Target = Surface;

    #[inline]
    fn deref(&self) -> &Surface {
        &self.surface
    }
}

impl std::ops::DerefMut for Material {
    #[inline]
    fn deref_mut(&mut self) -> &mut Surface {
        &mut self.surface
    }
}

/// Largest `|eta|` accepted. The Fresnel amplitudes form `eta^4`-sized intermediates (and
/// complex division squares its denominator), which overflowed to NaN from about
/// `|eta| = 1e38`; up to 1e10 they stay far from overflow, and `1 - R` is already below
/// `4/|eta| = 4e-10` at normal incidence there (eta=inf gives the exact F = 1).
pub const ETA_MAX: f64 = 1e10;

/// Nodes of the albedo tables, and the quadrature order used to fill them.
pub const ALBEDO_NODES: usize = 256;
pub const ALBEDO_ORDER: usize = 128;
/// Nodes of the double-bounce escape table S(theta_v), theta_v in [0, pi], and the
/// quadrature order of the double-bounce albedo integrals (their phi panels end at
/// `phi_v +- 90 deg`, graded near grazing: `double::cut_marks`). Order 80 costs what order
/// 96 did with plain panels; white furnace (single + double + multiple, 13 materials,
/// order-128 albedo) within 1e-5 to 80 deg and 7e-5 at 89-89.9 deg, against 2.2e-5 and
/// 1.7e-4 with plain panels at order 96.
pub const S_NODES: usize = 256;
pub const DOUBLE_TABLE_ORDER: usize = 80;

impl Material {
    /// Validate `spec` and build the tables its terms need.
    ///
    /// With [`MaterialSpec::alpha_step`] `Some(h)` the albedo and escape tables (those that
    /// normalize the multiple, diffuse and double terms; the single term needs none) are
    /// interpolated from the materials at the four alpha nodes about `alpha`
    /// ([`alpha_nodes`]), index by index on this material's `z` scale (the tables follow
    /// their lobe there) and in `ln(1 - value)`, with the averages and `F_ms` recomputed
    /// from the result; the node materials are kept for the process ([`NODE_CACHE_LEN`]),
    /// so the first material of a new range of alpha costs four builds and later ones
    /// milliseconds. The numbers depend on the nodes only, not on what the process built
    /// before. With path banks ([`MaterialSpec::uses_banks`]) the banks' orders are still
    /// mixed at `alpha` itself (cheap once their node tables are built) and the nodes, then
    /// within the banks' alpha interval ([`bank_alpha_nodes`]), also give the single
    /// term's calibration ([`interpolate_calibration`]), the slow part of such a build.
    /// `benchmarks/bench_material_build.py` measures the cost and the error against the
    /// exact build (docs/material-build.md).
    pub fn new(spec: MaterialSpec) -> Result<Self> {
        spec.distribution.validate()?;
        match spec.eta {
            Eta::PerfectConductor => {}
            Eta::Complex(e) => {
                if !(e.re.is_finite() && e.im.is_finite()) {
                    return Err(Error::param(
                        "eta",
                        e,
                        "must be finite (use eta=inf for a perfect conductor)",
                    ));
                }
                if e.norm() > ETA_MAX {
                    return Err(Error::param(
                        "eta",
                        e,
                        format!("|eta| must be at most {ETA_MAX:e} (use eta=inf for a perfect conductor)"),
                    ));
                }
                if e.im < 0.0 {
                    return Err(Error::param(
                        "eta",
                        e,
                        "imaginary part k must be >= 0 (eta = n + ik, absorbing k > 0)",
                    ));
                }
                if e.re < 0.0 || (e.re == 0.0 && e.im == 0.0) {
                    return Err(Error::param(
                        "eta",
                        e,
                        "real part n must be > 0 (or n >= 0 with k > 0)",
                    ));
                }
            }
        }
        if !(spec.wavelength.is_finite() && spec.wavelength > 0.0) {
            return Err(Error::param(
                "wavelength",
                spec.wavelength,
                "must be finite and > 0 (metres)",
            ));
        }
        if !(spec.correlation_length.is_finite() && spec.correlation_length >= 0.0) {
            return Err(Error::param(
                "correlation_length",
                spec.correlation_length,
                "must be finite and >= 0 (metres)",
            ));
        }
        if !(4..=1024).contains(&spec.double_order) {
            return Err(Error::param(
                "double_order",
                spec.double_order,
                "quadrature order must be in [4, 1024]",
            ));
        }
        if spec.shadowing == Shadowing::None && spec.terms.double {
            return Err(Error::param(
                "shadowing",
                "\"none\"",
                "term \"double\" needs a masking model: \"aps\" or \"smith\"",
            ));
        }
        if !(spec.diffuse_albedo.is_finite() && (0.0..=1.0).contains(&spec.diffuse_albedo)) {
            return Err(Error::param(
                "diffuse_albedo",
                spec.diffuse_albedo,
                "must be in [0, 1]",
            ));
        }
        if spec.terms.diffuse != (spec.diffuse_albedo > 0.0) && spec.terms.diffuse {
            return Err(Error::param(
                "diffuse_albedo",
                spec.diffuse_albedo,
                "term \"diffuse\" needs diffuse_albedo > 0",
            ));
        }
        if spec.shadowing == Shadowing::None && (spec.terms.multiple || spec.terms.diffuse) {
            return Err(Error::param(
                "shadowing",
                "\"none\"",
                "terms \"multiple\" and \"diffuse\" need an energy-conserving masking: \"aps\" or \"smith\"",
            ));
        }
        if spec.masking == MaskingEval::Seed
            && !(spec.shadowing == Shadowing::Aps
                && matches!(spec.distribution, Distribution::BlinnPhong { .. }))
        {
            return Err(Error::param("masking", "\"seed\"", "the seed's closed form exists for shadowing=\"aps\" with distribution=\"blinn_phong\" only"));
        }
        if let Some(step) = spec.alpha_step {
            if !(step.is_finite() && step > 0.0 && step <= 1.0) {
                return Err(Error::param(
                    "alpha_step",
                    step,
                    "must be in (0, 1] (the step of the alpha nodes in ln alpha), or None",
                ));
            }
            if matches!(spec.distribution, Distribution::BlinnPhong { .. }) {
                return Err(Error::param(
                    "alpha_step",
                    step,
                    "alpha nodes need distribution=\"beckmann\" or \"ggx\" (or alpha_step=None)",
                ));
            }
        }
        // (like `orders` itself, the shape has nothing to do with the single term alone)
        if spec.autocorrelation != Autocorrelation::Gaussian && spec.orders != Orders::Surface {
            return Err(Error::param(
                "autocorrelation",
                format!("{:?}", spec.autocorrelation.name()),
                "the autocorrelation shape is that of the path banks' surfaces: it needs \
                 orders=\"surface\" (the seed's terms have no shape); else leave it \
                 \"gaussian\"",
            ));
        }
        let surface_orders = if spec.uses_banks() {
            let Distribution::Beckmann { alpha } = spec.distribution else {
                return Err(Error::param(
                    "orders",
                    "\"surface\"",
                    "the path banks are of Gaussian random (so Beckmann) surfaces: use \
                     distribution=\"beckmann\" (or orders=\"seed\")",
                ));
            };
            Some(std::sync::Arc::new(SurfaceOrders::new(
                alpha,
                spec.eta,
                spec.terms.double,
                spec.terms.multiple,
                spec.bank_rays,
                spec.autocorrelation,
            )?))
        } else {
            None
        };
        let mut mat = Material {
            surface: Surface::new(spec),
            e_white: None,
            f_ms: 1.0,
            e_spec: None,
            s_white: None,
            s_fresnel: None,
            surface_orders,
        };
        let nodes = match mat.spec.alpha_step {
            Some(step) => alpha_nodes(&mat.spec, step)?,
            None => None,
        };
        // the surface's order 1 (`calibration::calibrate_masking`), before any table reads the
        // masking; from alpha nodes, their calibrations interpolated
        if let Some(so) = mat.surface_orders.clone() {
            if let (Some(nodes), true) = (&nodes, mat.spec.shadowing != Shadowing::None) {
                mat.surface.calibration = interpolate_calibration(
                    nodes,
                    mat.surface.spec.distribution.table_scale(),
                    &|theta| so.calibration_target(theta),
                );
            } else if mat.spec.shadowing != Shadowing::None {
                let target: Vec<f64> = (0..N_THETA).map(|k| so.order1_target(k)).collect();
                // with the remainder, the energy balance at every angle (the banks' albedos
                // linear between their nodes, held beyond the last, as their tables are)
                let closure = |theta: f64| so.calibration_target(theta);
                let fine: Option<&(dyn Fn(f64) -> f64 + Sync)> =
                    so.rest.is_some().then_some(&closure);
                super::calibration::calibrate_masking(
                    &mut mat.surface,
                    THETA_STEP,
                    &target,
                    fine,
                    ALBEDO_ORDER,
                );
            }
        }
        if let Some(nodes) = nodes {
            mat.interpolate_tables(&nodes);
            return Ok(mat);
        }
        let needs_albedo = mat.spec.terms.multiple || mat.spec.terms.diffuse;
        let exact = mat.spec.masking == MaskingEval::Exact;
        // The escape and albedo tables normalize the double, multiple and diffuse terms
        // (to 1e-5); with masking="exact" they are filled with the tabulated masking (error
        // below 1e-8 in P) instead of a quadrature inside every node, which would take
        // minutes. The single term itself keeps the exact masking.
        let mut builder = mat.clone();
        if exact {
            builder.spec.masking = MaskingEval::Table;
        }
        if mat.spec.terms.double && mat.surface_orders.is_none() {
            builder.s_white = Some(builder.escape_table(false));
            builder.s_fresnel = Some(builder.escape_table(true));
        }
        if needs_albedo {
            let white = builder.albedo_table(false, None);
            let f_avg = average_reflectance(mat.spec.eta);
            let e_avg = white.e_avg;
            builder.f_ms = f_avg * f_avg * e_avg / (1.0 - f_avg * (1.0 - e_avg));
            builder.e_white = Some(white);
            if mat.spec.terms.diffuse {
                let with_ms = if mat.spec.terms.multiple {
                    builder.e_white.clone()
                } else {
                    None
                };
                builder.e_spec = Some(builder.albedo_table(true, with_ms.as_ref()));
            }
        }
        mat.s_white = builder.s_white;
        mat.s_fresnel = builder.s_fresnel;
        mat.f_ms = builder.f_ms;
        mat.e_white = builder.e_white;
        mat.e_spec = builder.e_spec;
        Ok(mat)
    }

    /// Tabulate the single-bounce albedo (with Fresnel or with `F = 1`), plus the multiple
    /// term's share `(1 - E_white) F_ms` when `ms` is given, on the grid of
    /// [`AlbedoTable::fresnel_scale`] (`2 ALBEDO_NODES` intervals) when `fresnel`.
    fn albedo_table(&self, fresnel: bool, ms: Option<&AlbedoTable>) -> AlbedoTable {
        let f_ms = self.f_ms;
        // With the double bounce on, E includes its albedo, through the escape tables
        // built before this (see `new`).
        let s_table = if fresnel {
            self.s_fresnel.as_ref()
        } else {
            self.s_white.as_ref()
        };
        let scale = self.spec.distribution.table_scale();
        let s_f = fresnel.then(|| fresnel_scale(self.spec.eta));
        let n = if fresnel {
            2 * ALBEDO_NODES
        } else {
            ALBEDO_NODES
        };
        let node = |i: usize| node_theta(scale, s_f, i, n);
        let f = |theta: f64| {
            let c = theta.cos();
            let mut v = super::albedo::single_albedo(self, c, fresnel, ALBEDO_ORDER);
            if let Some(st) = s_table {
                let wi = V3::new(theta.sin(), 0.0, c);
                v += super::double::double_albedo(self, wi, fresnel, DOUBLE_TABLE_ORDER, &|u| {
                    eval_escape(st, u)
                });
            }
            if fresnel {
                // the banks' orders with the material's Fresnel (the white table leaves them
                // out: [`Material::e_white_total`] adds them exactly, piecewise linear in
                // theta as the tables are, which a cubic in z would round at the kinks)
                v += self.bank_albedo(c, true);
            }
            if let Some(w) = ms {
                v += self.remainder_deficit(w, c, theta.sin(), None) * f_ms;
            }
            v
        };
        use rayon::prelude::*;
        let values = (0..=n).into_par_iter().map(|i| f(node(i))).collect();
        self.with_average(
            AlbedoTable {
                e: ZTable { scale, values },
                e_avg: 0.0,
                fresnel_scale: s_f,
            },
            fresnel,
        )
    }

    /// `table` with its `e_avg` (of the white `E` with the banks' orders unless `fresnel`).
    fn with_average(&self, table: AlbedoTable, fresnel: bool) -> AlbedoTable {
        let (scale, s_f, n) = (table.e.scale, table.fresnel_scale, table.e.values.len() - 1);
        let node = |i: usize| node_theta(scale, s_f, i, n);
        // 1 - E_avg directly (it is ~alpha^2 for smooth surfaces: forming E_avg first
        // would leave only its rounding); the white E with the banks' orders
        let deficit = average_over_cosine(n, node, |c, s| {
            if !fresnel && self.surface_orders.is_some() {
                self.remainder_deficit(&table, c, s, None)
            } else {
                1.0 - table.eval_csz(c, s, z_scaled(scale, c, s))
            }
        });
        AlbedoTable {
            e_avg: 1.0 - deficit,
            ..table
        }
    }

    /// The albedo and escape tables as the sums of the `nodes`' tables (weight, material)
    /// at the same node indices, on this material's `z` scale ([`alpha_nodes`]); the
    /// averages and `F_ms` from the sums.
    fn interpolate_tables(&mut self, nodes: &[Node]) {
        let scale = self.spec.distribution.table_scale();
        let blend = |get: &dyn Fn(&Material) -> Option<&ZTable>| -> Option<ZTable> {
            let first = get(&nodes[0].1)?;
            let tables: Vec<&[f64]> = nodes
                .iter()
                .map(|(_, m)| &get(m).expect("nodes share their terms").values[..])
                .collect();
            let values = (0..first.values.len())
                .map(|i| {
                    // in ln(1 - x): the deficits of the albedos and the hit probabilities
                    // go as powers of alpha for smooth surfaces (~alpha^2), which a
                    // polynomial in ln alpha follows there and a polynomial in x does not
                    // (in x, the multiple term of alpha 0.0123 was off by 6e-4 of itself
                    // at the median pair; in ln(1 - x), by 7e-8)
                    let deficits: Option<Vec<f64>> = tables
                        .iter()
                        .map(|t| (1.0 - t[i] > 1e-200).then(|| (1.0 - t[i]).ln()))
                        .collect();
                    match deficits {
                        Some(d) => {
                            1.0 - nodes
                                .iter()
                                .zip(&d)
                                .map(|((w, _), l)| w * l)
                                .sum::<f64>()
                                .exp()
                        }
                        None => nodes.iter().zip(&tables).map(|((w, _), t)| w * t[i]).sum(),
                    }
                })
                .collect();
            Some(ZTable { scale, values })
        };
        let pair = |get: &dyn Fn(&Material) -> Option<&UpDown>| -> Option<UpDown> {
            Some((
                blend(&|m| get(m).map(|t| &t.0))?,
                blend(&|m| get(m).map(|t| &t.1))?,
            ))
        };
        self.s_white = pair(&|m| m.s_white.as_ref());
        self.s_fresnel = pair(&|m| m.s_fresnel.as_ref());
        if let Some(e) = blend(&|m| m.e_white.as_ref().map(|t| &t.e)) {
            let white = self.with_average(
                AlbedoTable {
                    e,
                    e_avg: 0.0,
                    fresnel_scale: None,
                },
                false,
            );
            let f_avg = average_reflectance(self.spec.eta);
            self.f_ms = f_avg * f_avg * white.e_avg / (1.0 - f_avg * (1.0 - white.e_avg));
            self.e_white = Some(white);
        }
        if let Some(e) = blend(&|m| m.e_spec.as_ref().map(|t| &t.e)) {
            let fresnel_scale = nodes[0].1.e_spec.as_ref().and_then(|t| t.fresnel_scale);
            self.e_spec = Some(self.with_average(
                AlbedoTable {
                    e,
                    e_avg: 0.0,
                    fresnel_scale,
                },
                true,
            ));
        }
    }

    /// Tabulate `S(v)` for `v` above and below the horizon, each in `z` of `|v_z|`.
    fn escape_table(&self, fresnel: bool) -> (ZTable, ZTable) {
        let scale = self.spec.distribution.table_scale();
        let up = ZTable::build(scale, S_NODES, |th| {
            super::double::escape_after_bounce(
                self,
                V3::new(th.sin(), 0.0, th.cos()),
                fresnel,
                DOUBLE_TABLE_ORDER,
            )
        });
        let down = ZTable::build(scale, S_NODES, |th| {
            super::double::escape_after_bounce(
                self,
                V3::new(th.sin(), 0.0, -th.cos()),
                fresnel,
                DOUBLE_TABLE_ORDER,
            )
        });
        (up, down)
    }

    /// Double-bounce albedo for unpolarized light at `wi`, with the unpolarized Fresnel
    /// product (see [`super::double::double_albedo`]), by an `n x n` quadrature over `h1`.
    pub fn double_albedo(&self, wi: V3, n: usize) -> f64 {
        if let Some(so) = &self.surface_orders {
            return so.albedo(Part::Double, true, wi[2]);
        }
        match &self.s_fresnel {
            Some(st) => super::double::double_albedo(self, wi, true, n, &|u| eval_escape(st, u)),
            None => 0.0,
        }
    }

    /// The albedo of the path banks' orders at incidence cosine `c` (0 without them), with
    /// the material's Fresnel or with `F = 1`.
    #[inline]
    pub fn bank_albedo(&self, c: f64, fresnel: bool) -> f64 {
        self.surface_orders
            .as_ref()
            .map_or(0.0, |so| so.orders_albedo(fresnel, c))
    }

    /// The white (`F = 1`) albedo `E` the multiple term completes to 1: the table `t`
    /// (single, and the seed's double) plus the banks' orders; `z` the material coordinate
    /// when known.
    #[inline]
    fn e_white_total(&self, t: &AlbedoTable, c: f64, s: f64, z: Option<f64>) -> f64 {
        let e = match z {
            Some(z) => t.e.eval_z(z),
            None => t.e.eval(c, s),
        };
        e + self.bank_albedo(c, false)
    }

    /// `1 - E` of the multiple term's depolarizing part at incidence cosine `c`: what the
    /// white albedo `E` ([`Self::e_white_total`]) leaves; for a material whose single term
    /// is calibrated to its path banks with the remainder on, the banks' truncation
    /// ([`SurfaceOrders::remainder`], smooth), which the calibration makes the same to
    /// about 1e-5 of the albedo.
    #[inline]
    fn remainder_deficit(&self, t: &AlbedoTable, c: f64, s: f64, z: Option<f64>) -> f64 {
        if let Some(so) = &self.surface_orders {
            if so.rest.is_some() && self.calibration.is_some() {
                return so.remainder(c);
            }
        }
        (1.0 - self.e_white_total(t, c, s, z)).max(0.0)
    }

    /// `E(theta)` of the white (F = 1) single-bounce term, if tabulated.
    pub fn white_albedo(&self, c: f64, s: f64) -> Option<f64> {
        self.e_white.as_ref().map(|t| t.e.eval(c, s))
    }

    /// Multiple-scattering value `f_ms(wi, wo)` (1/sr) from cosines/sines of both directions.
    #[inline]
    pub fn multiple(&self, ci: f64, si: f64, co: f64, so: f64) -> f64 {
        self.multiple_cz(ci, self.z_of(ci, si), co, self.z_of(co, so))
    }

    /// [`Self::multiple`] from the cosines and table coordinates of both directions (the
    /// banks' albedos are in `theta`).
    #[inline]
    pub fn multiple_cz(&self, ci: f64, zi: f64, co: f64, zo: f64) -> f64 {
        if self.surface_orders.is_none() {
            return self.multiple_z(zi, zo);
        }
        let t = self.e_white.as_ref().expect("multiple term enabled");
        let denom = std::f64::consts::PI * (1.0 - t.e_avg);
        if denom <= 1e-14 {
            return 0.0;
        }
        let a = self.remainder_deficit(t, ci, 0.0, Some(zi));
        let b = self.remainder_deficit(t, co, 0.0, Some(zo));
        self.f_ms * a * b / denom
    }

    /// [`Self::multiple`] from the table coordinates of both directions.
    #[inline]
    pub fn multiple_z(&self, zi: f64, zo: f64) -> f64 {
        let t = self.e_white.as_ref().expect("multiple term enabled");
        let denom = std::f64::consts::PI * (1.0 - t.e_avg);
        if denom <= 1e-14 {
            return 0.0;
        }
        let a = (1.0 - t.e.eval_z(zi)).max(0.0);
        let b = (1.0 - t.e.eval_z(zo)).max(0.0);
        self.f_ms * a * b / denom
    }

    /// Diffuse (paint) value (1/sr).
    #[inline]
    pub fn diffuse(&self, ci: f64, si: f64, co: f64, so: f64) -> f64 {
        self.diffuse_z(ci, si, self.z_of(ci, si), co, so, self.z_of(co, so))
    }

    /// [`Self::diffuse`] with the table coordinates of both directions given.
    #[inline]
    pub fn diffuse_z(&self, ci: f64, si: f64, zi: f64, co: f64, so: f64, zo: f64) -> f64 {
        let t = self.e_spec.as_ref().expect("diffuse term enabled");
        let denom = std::f64::consts::PI * (1.0 - t.e_avg);
        if denom <= 1e-14 {
            return 0.0;
        }
        let a = (1.0 - t.eval_csz(ci, si, zi)).max(0.0);
        let b = (1.0 - t.eval_csz(co, so, zo)).max(0.0);
        self.spec.diffuse_albedo * a * b / denom
    }

    /// Analytic hemispherical integrals of the multiple and diffuse terms for incidence
    /// `(c, s)`: `int f cos(theta_o) d omega_o` = `(1 - E(wi)) F_ms` and `rho_d (1 - E_s(wi))`.
    pub fn depolarizing_albedo(&self, c: f64, s: f64) -> (f64, f64) {
        let ms = if self.spec.terms.multiple {
            let t = self.e_white.as_ref().unwrap();
            if t.e_avg < 1.0 - 1e-14 {
                self.remainder_deficit(t, c, s, None) * self.f_ms
            } else {
                0.0
            }
        } else {
            0.0
        };
        let d = if self.spec.terms.diffuse {
            let t = self.e_spec.as_ref().unwrap();
            if t.e_avg < 1.0 - 1e-14 {
                self.spec.diffuse_albedo * (1.0 - t.eval_csz(c, s, self.z_of(c, s))).max(0.0)
            } else {
                0.0
            }
        } else {
            0.0
        };
        (ms, d)
    }
}

/// A node material and its weight ([`alpha_nodes`]).
type Node = (f64, Arc<Material>);

/// Tables for directions above and below the horizon (the escape tables).
type UpDown = (ZTable, ZTable);

/// `S(v)` from its (up, down) tables.
#[inline]
fn eval_escape(t: &(ZTable, ZTable), v: V3) -> f64 {
    let s = (v[0] * v[0] + v[1] * v[1]).sqrt();
    let table = if v[2] >= 0.0 { &t.0 } else { &t.1 };
    table.eval(v[2].abs(), s).max(0.0)
}

/// `2 int_0^1 g mu dmu = 2 int_0^{pi/2} g cos sin dtheta` for `g(cos theta, sin theta)`
/// interpolated on a table of `n` intervals with node angles `node(i)` (decreasing in `i`):
/// Gauss-Legendre (order 8) on every interval between the nodes' angles, where the
/// interpolant is smooth, intervals wider than 1/64 rad split evenly. (The former rule,
/// 16 panels in `z`, missed the Jacobian's peak of width `scale` at `z = 1`: `E_avg` came
/// out 1.37 for alpha = 1e-4 and 0.07 for 1e-5, which switched the multiple term off or
/// mis-normalized it.)
fn average_over_cosine(n: usize, node: impl Fn(usize) -> f64, g: impl Fn(f64, f64) -> f64) -> f64 {
    let rule = crate::quad::gauss_legendre(8);
    let mut total = 0.0;
    for i in 0..n {
        let hi = node(i);
        let lo = node(i + 1);
        let k = ((hi - lo) * 64.0).ceil().max(1.0) as usize;
        let w = (hi - lo) / k as f64;
        for j in 0..k {
            let a = lo + j as f64 * w;
            for (&x, &wx) in rule.x.iter().zip(&rule.w) {
                let th = a + w * x;
                let (s, c) = th.sin_cos();
                total += wx * w * 2.0 * g(c, s) * c * s;
            }
        }
    }
    total
}

/// Catmull-Rom weights of the nodes `j - 1 .. j + 2` at `t` in [0, 1) past node `j`
/// (C1 in `t`, exact for quadratics): the crate's [`catmull_rom`] of each unit vector
/// (exactly `[0, 1, 0, 0]` at `t = 0`).
fn catmull_rom_weights(t: f64) -> [f64; 4] {
    let unit = |m: usize| [0, 1, 2, 3].map(|k| if k == m { 1.0 } else { 0.0 });
    [0, 1, 2, 3].map(|m| {
        let [p0, p1, p2, p3] = unit(m);
        catmull_rom(p0, p1, p2, p3, t)
    })
}

/// The alpha nodes of a material whose orders come from the path banks: the interval
/// `[a_k, a_{k+1}]` of the banks' nodes ([`BANK_ALPHA_NODES`]) that holds `alpha` divided
/// into `m = ceil(ln(a_{k+1} / a_k) / step)` equal steps in `ln alpha`, and the
/// Catmull-Rom weights of the four nodes about `alpha` among them (in the end steps a
/// ghost node extrapolated quadratically from the three nearest, as [`ZTable::eval_z`]
/// does; linear when `m = 1`). The nodes stay within one interval because the banks'
/// orders are mixed linearly between their nodes: a material's tables have kinks in
/// alpha at the banks' nodes, and a stencil across one (nodes `exp(j h)` as for other
/// materials) missed the white furnace by 5.3e-4 at alpha 0.7013, step 0.02, where one
/// inside the interval (alpha 0.745) stayed within 1e-5 (default banks).
/// `None` outside the banks' nodes (the exact build then says why).
fn bank_alpha_nodes(spec: &MaterialSpec, step: f64) -> Result<Option<Vec<Node>>> {
    let Some(weights) = bank_node_weights(spec.distribution.scale(), step) else {
        return Ok(None);
    };
    weights
        .into_iter()
        .map(|(a, w)| Ok((w, node_material(spec, a)?)))
        .collect::<Result<Vec<_>>>()
        .map(Some)
}

/// The `(alpha node, weight)` pairs of [`bank_alpha_nodes`] (weights not zero), or `None`
/// for `alpha` outside the banks' nodes.
fn bank_node_weights(alpha: f64, step: f64) -> Option<Vec<(f64, f64)>> {
    let a = &BANK_ALPHA_NODES;
    if !(alpha >= a[0] && alpha <= a[a.len() - 1]) {
        return None;
    }
    let k = a.partition_point(|&x| x <= alpha).clamp(1, a.len() - 1) - 1;
    let (lo, hi) = (a[k].ln(), a[k + 1].ln());
    let m = ((hi - lo) / step - 1e-9).ceil().max(1.0) as usize;
    let node = |i: usize| match i {
        0 => a[k],
        _ if i == m => a[k + 1],
        _ => (lo + (hi - lo) * i as f64 / m as f64).exp(),
    };
    let mut t = (alpha.ln() - lo) / (hi - lo) * m as f64;
    if (t - t.round()).abs() < 1e-9 {
        t = t.round();
    }
    let t = t.clamp(0.0, m as f64);
    let i = (t.floor() as usize).min(m - 1);
    let f = t - i as f64;
    // weights per node index 0..=m
    let mut w = vec![0.0; m + 1];
    if f == 0.0 {
        w[i] = 1.0;
    } else if f == 1.0 {
        w[i + 1] = 1.0;
    } else if m == 1 {
        w[0] = 1.0 - f;
        w[1] = f;
    } else {
        let cr = catmull_rom_weights(f);
        w[i] += cr[1];
        w[i + 1] += cr[2];
        if i >= 1 {
            w[i - 1] += cr[0];
        } else {
            // p(-1) = 3 p(0) - 3 p(1) + p(2)
            w[0] += 3.0 * cr[0];
            w[1] -= 3.0 * cr[0];
            w[2] += cr[0];
        }
        if i + 2 <= m {
            w[i + 2] += cr[3];
        } else {
            // p(m + 1) = 3 p(m) - 3 p(m - 1) + p(m - 2)
            w[m] += 3.0 * cr[3];
            w[m - 1] -= 3.0 * cr[3];
            w[m - 2] += cr[3];
        }
    }
    Some(
        w.iter()
            .enumerate()
            .filter(|(_, &wj)| wj != 0.0)
            .map(|(j, &wj)| (node(j), wj))
            .collect(),
    )
}

/// The single term's calibration ([`super::calibration::calibrate_masking`]) of a material
/// between alpha nodes, tabulated on its `z` scale (`scale`): `ln s(theta)` as the nodes'
/// weighted sum of `ln s_m - ln(T_m) / 2`, plus `ln(T) / 2`, where `T_m` and `T` are the
/// white single albedos the calibrations aim at (the nodes' and this material's,
/// [`SurfaceOrders::calibration_target`], exact and cheap at any alpha). `s` enters the
/// single albedo about twice (incidence and exit), so the target's own curvature in alpha
/// is followed exactly and only the rest is interpolated. `None` where the nodes have no
/// calibration.
fn interpolate_calibration(
    nodes: &[Node],
    scale: f64,
    target: &(dyn Fn(f64) -> f64 + Sync),
) -> Option<ZTable> {
    let tables: Vec<(f64, &ZTable, &SurfaceOrders)> = nodes
        .iter()
        .map(|(w, m)| Some((*w, m.calibration.as_ref()?, m.surface_orders.as_deref()?)))
        .collect::<Option<_>>()?;
    let half_ln = |t: f64| {
        if t > 0.0 && t.is_finite() {
            0.5 * t.ln()
        } else {
            0.0
        }
    };
    Some(ZTable::build(scale, TABLE_NODES, |theta| {
        let (s, c) = theta.sin_cos();
        let shape: f64 = tables
            .iter()
            .map(|(w, t, so)| w * (t.eval(c, s).ln() - half_ln(so.calibration_target(theta))))
            .sum();
        (shape + half_ln(target(theta))).exp()
    }))
}

/// Materials at alpha nodes, kept for the process: the [`NODE_CACHE_LEN`] most recently
/// used, keyed by their whole spec.
static NODE_CACHE: std::sync::Mutex<super::recent::Recent<String, Arc<Material>>> =
    std::sync::Mutex::new(super::recent::Recent::new(NODE_CACHE_LEN));
/// Node materials kept (4 per region of alpha in use; each holds a few tables of 257 to
/// 513 values, and the banks' mixed orders when `orders = Surface`).
pub const NODE_CACHE_LEN: usize = 64;

/// The material of `spec` at node roughness `alpha` (exact tables), from the cache or
/// built and kept. Two threads asking for the same node at once may both build it (the
/// same tables): the cache holds one.
fn node_material(spec: &MaterialSpec, alpha: f64) -> Result<Arc<Material>> {
    let mut node = spec.clone();
    node.alpha_step = None;
    node.distribution = match spec.distribution {
        Distribution::Beckmann { .. } => Distribution::Beckmann { alpha },
        Distribution::Ggx { .. } => Distribution::Ggx { alpha },
        Distribution::BlinnPhong { .. } => unreachable!("alpha_step is refused for Blinn-Phong"),
    };
    let key = format!("{node:?}");
    let cache = || NODE_CACHE.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(m) = cache().get(&key) {
        return Ok(m);
    }
    let m = Arc::new(Material::new(node)?);
    cache().insert(key, m.clone());
    Ok(m)
}

/// The nodes of [`MaterialSpec::alpha_step`] `h` about the spec's `alpha`: `u = ln(alpha) / h`
/// (snapped to an integer within 1e-9), `j = floor(u)`, the materials at
/// `alpha = exp((j + m - 1) h)`, `m = 0..3`, with their Catmull-Rom weights at `u - j`
/// (those of weight 0 left out: on a node, that node alone). `None` when a node falls
/// outside the valid roughness range (the material is then built at its own `alpha`).
/// A material whose orders come from the path banks takes [`bank_alpha_nodes`] instead.
fn alpha_nodes(spec: &MaterialSpec, step: f64) -> Result<Option<Vec<Node>>> {
    if spec.uses_banks() {
        return bank_alpha_nodes(spec, step);
    }
    let alpha = spec.distribution.scale();
    let mut u = alpha.ln() / step;
    if (u - u.round()).abs() < 1e-9 {
        u = u.round();
    }
    let j = u.floor();
    let weights = catmull_rom_weights(u - j);
    let mut out = Vec::with_capacity(4);
    for (m, &w) in weights.iter().enumerate() {
        if w == 0.0 {
            continue;
        }
        let a = ((j + m as f64 - 1.0) * step).exp();
        if !(ALPHA_MIN..=ALPHA_MAX).contains(&a) {
            return Ok(None);
        }
        out.push((w, node_material(spec, a)?));
    }
    Ok(Some(out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::Terms;

    fn spec(alpha: f64, step: Option<f64>) -> MaterialSpec {
        spec_with(alpha, step, true)
    }

    fn spec_with(alpha: f64, step: Option<f64>, double: bool) -> MaterialSpec {
        MaterialSpec {
            terms: Terms {
                single: true,
                double,
                multiple: true,
                diffuse: false,
            },
            alpha_step: step,
            ..MaterialSpec::new(
                Distribution::Beckmann { alpha },
                Eta::Complex(crate::optics::fresnel::C64::new(1.38, 10.2)),
            )
        }
    }

    fn tables(m: &Material) -> Vec<f64> {
        let mut v = m.e_white.as_ref().unwrap().e.values.clone();
        v.push(m.e_white.as_ref().unwrap().e_avg);
        v.push(m.f_ms);
        for t in [m.s_white.as_ref(), m.s_fresnel.as_ref()]
            .into_iter()
            .flatten()
        {
            v.extend(&t.0.values);
            v.extend(&t.1.values);
        }
        v
    }

    #[test]
    fn alpha_step_out_of_range_or_for_blinn_phong_is_refused() {
        for step in [0.0, -0.1, 1.5, f64::NAN, f64::INFINITY] {
            let e = Material::new(spec(0.3, Some(step)))
                .unwrap_err()
                .to_string();
            assert!(e.contains("alpha_step") && e.contains("(0, 1]"), "{e}");
        }
        let bp = MaterialSpec {
            alpha_step: Some(0.05),
            ..MaterialSpec::new(Distribution::BlinnPhong { m: 20.0 }, Eta::PerfectConductor)
        };
        let e = Material::new(bp).unwrap_err().to_string();
        assert!(e.contains("alpha_step") && e.contains("beckmann"), "{e}");
    }

    /// The path-bank materials' alpha nodes: within the banks' interval that holds alpha
    /// (never across a bank node, where the tables have kinks in alpha), weights that sum
    /// to 1 and reproduce a quadratic in `ln alpha` exactly (Catmull-Rom, with quadratic
    /// ghosts in the end steps; a linear function where a step spans the whole interval),
    /// one node alone on a node, none outside the banks' range.
    #[test]
    fn bank_alpha_nodes_stay_in_one_interval_and_are_exact_for_quadratics() {
        for step in [0.02, 0.05, 0.1, 0.3, 1.0] {
            // steps 0.3 and 1: one or two steps per interval (a linear function)
            let c2 = if step < 0.2 { 2.9 } else { 0.0 };
            let q = |a: f64| {
                let x = a.ln();
                0.3 - 1.7 * x + c2 * x * x
            };
            let (first, last) = (
                BANK_ALPHA_NODES[0],
                BANK_ALPHA_NODES[BANK_ALPHA_NODES.len() - 1],
            );
            for j in 0..=1000 {
                let alpha = (first * (last / first).powf(j as f64 / 1000.0)).min(last);
                let w = bank_node_weights(alpha, step).unwrap();
                let k = BANK_ALPHA_NODES
                    .iter()
                    .position(|&a| a > alpha)
                    .unwrap_or(BANK_ALPHA_NODES.len() - 1)
                    - 1;
                let (lo, hi) = (BANK_ALPHA_NODES[k], BANK_ALPHA_NODES[k + 1]);
                assert!(w.len() <= 4);
                for &(a, _) in &w {
                    assert!(
                        a >= lo * (1.0 - 1e-12) && a <= hi * (1.0 + 1e-12),
                        "{alpha} {step} {a}"
                    );
                }
                let sum: f64 = w.iter().map(|p| p.1).sum();
                assert!((sum - 1.0).abs() < 1e-12, "{alpha} {step} {sum}");
                let v: f64 = w.iter().map(|&(a, wj)| wj * q(a)).sum();
                assert!(
                    (v - q(alpha)).abs() < 1e-9,
                    "{alpha} {step}: {v} vs {}",
                    q(alpha)
                );
            }
        }
        for &a in &BANK_ALPHA_NODES {
            assert_eq!(bank_node_weights(a, 0.05).unwrap(), vec![(a, 1.0)]);
        }
        assert!(bank_node_weights(0.0499, 0.05).is_none());
        assert!(bank_node_weights(1.0001, 0.05).is_none());
    }

    /// On a node the tables are that node's (the one weight is 1; ln(1 - x) and back
    /// costs a few ulps of 1 - x), and a node beyond alpha's range builds exactly.
    #[test]
    fn on_a_node_the_tables_are_the_exact_ones_and_outside_the_range_they_are_built() {
        let alpha = (7.0f64 * 0.1).exp() / 10.0; // not a node of 0.1 ...
        let node = (-23.0f64 * 0.1).exp(); // ... this one is: exp(-2.3)
        let exact = tables(&Material::new(spec(node, None)).unwrap());
        let nodes = tables(&Material::new(spec(node, Some(0.1))).unwrap());
        for (a, b) in exact.iter().zip(&nodes) {
            assert!((a - b).abs() <= 1e-14 * a.abs().max(1.0), "{a} vs {b}");
        }
        // alpha 9.9: the node above, exp(23 * 0.1) = 9.97, and the one after, 11.0 > 10
        // (without the double term from here: 0.4 s a build instead of 2.5 s)
        let near_max = tables(&Material::new(spec_with(9.9, Some(0.1), false)).unwrap());
        assert_eq!(
            near_max,
            tables(&Material::new(spec_with(9.9, None, false)).unwrap())
        );
        // between nodes: the white albedo, its average and F_ms close to the exact build's,
        // not equal to them (the escape tables are left out: the exact ones are not smooth
        // in theta at alpha 0.2, up to 0.37 between neighbouring nodes near 15 deg, noted
        // in the closing note of this change)
        let (e, n) = (
            tables(&Material::new(spec_with(alpha, None, false)).unwrap()),
            tables(&Material::new(spec_with(alpha, Some(0.1), false)).unwrap()),
        );
        let worst = e[..ALBEDO_NODES + 3]
            .iter()
            .zip(&n)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst > 0.0 && worst < 1e-5, "{worst}");
    }

    /// The escape after the second bounce, `S(v)` for `v` above the horizon, is continuous
    /// in `theta` for a smooth metal. Regression: the correlated part of the blocking was
    /// dropped wherever the masking table reached 0 (`cot theta / alpha` above about 9),
    /// so `S` jumped from 0.73 to 0.87 between 29.0 and 29.5 deg at alpha 0.2 (the
    /// quadrature agreed at orders 80, 160 and 400: the integrand jumped). Now the largest
    /// step between samples 0.25 deg apart over 2-45 deg is 0.009, the smooth rise near
    /// the normal (0.45 at 5 deg to 0.86 at 30) plus the order-80 quadrature's 1e-3;
    /// the jump was 0.135 in one step.
    #[test]
    fn escape_after_the_second_bounce_is_continuous_near_the_normal() {
        let m = Material::new(spec(0.2, None)).unwrap();
        let s = |deg: f64| {
            let t = deg.to_radians();
            super::super::double::escape_after_bounce(&m, V3::new(t.sin(), 0.0, t.cos()), true, 80)
        };
        let vals: Vec<f64> = (8..=180).map(|k| s(0.25 * k as f64)).collect();
        let worst = vals
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.02, "largest step {worst}");
    }
}
