//! Per-material tables for the renderer: the monostatic double-bounce Mueller BRDF (with
//! its coherent backscatter) as a function of the incidence angle only, in the
//! plane-of-incidence (sp) frame. The single term at backscatter (`D(h = wi) G / (4 cos^2)
//! R(0) diag(1, 1, -1, -1)`) and the multiple/diffuse terms (the albedo tables) are closed
//! forms the renderer evaluates directly; the double bounce is the expensive integral.
//!
//! Nodes are uniform in `z` with `cot theta = s z / (1 - z)` (`s` the distribution's width,
//! see [`ZTable`]), which puts them densest near normal incidence on the lobe's own scale.
//! The backscattered `M00` spans many decades (it falls exponentially off normal for smooth
//! surfaces), so the table holds `ln M00` and the normalized elements `M_ij / M00`, each
//! interpolated by Catmull-Rom. The double bounce is evaluated
//! with `double_order` (a lower order than the material's default trades accuracy for
//! build time; both errors are measured by [`MonostaticTable::max_error`]).

//!
//! [`BrdfTable`] (below) tabulates the **total** Mueller BRDF for the GPU renderer, for
//! monostatic and small bistatic angles; its doc comment fixes the data layout and the
//! interpolation that the WGSL port follows, and `docs/render-table.md` has its measured
//! error and build time.

use super::material::Material;
use crate::microfacet::masking::ZTable;
use crate::optics::frames::Frame;
use crate::optics::mueller::Mat4;
use rayon::prelude::*;

/// The monostatic BRDF `f(theta)` (wi = wo at polar angle theta, azimuth 0), sp frame.
#[derive(Debug, Clone)]
pub struct MonostaticTable {
    pub elements: Vec<ZTable>,
}

impl MonostaticTable {
    /// Build with `nodes` intervals, the double bounce at `double_order`.
    pub fn build(mat: &Material, nodes: usize, double_order: usize) -> Self {
        let mut m = mat.clone();
        m.spec.double_order = double_order;
        let scale = mat.spec.distribution.table_scale();
        let values: Vec<Mat4> = (0..=nodes)
            .into_par_iter()
            .map(|i| {
                let th = ZTable::theta_of_z(scale, i as f64 / nodes as f64);
                let w = [th.sin(), 0.0, th.cos()];
                double_only(&m, w)
            })
            .collect();
        let elements = (0..16)
            .map(|k| {
                let vals = values
                    .iter()
                    .map(|v| {
                        let m00 = v[0][0].max(1e-300);
                        if k == 0 {
                            m00.ln()
                        } else {
                            v[k / 4][k % 4] / m00
                        }
                    })
                    .collect();
                ZTable {
                    scale,
                    values: vals,
                }
            })
            .collect();
        MonostaticTable { elements }
    }

    /// Interpolated `f(theta)`.
    pub fn eval(&self, theta: f64) -> Mat4 {
        let (s, c) = theta.sin_cos();
        let mut out = [[0.0; 4]; 4];
        let z = self.elements[0].z_of(c, s);
        // ln M00 without overshoot (it falls to its floor where the double bounce vanishes);
        // the normalized elements are bounded by 1 in magnitude.
        let m00 = self.elements[0].eval_z_bounded(z).exp();
        out[0][0] = m00;
        for (k, t) in self.elements.iter().enumerate().skip(1) {
            out[k / 4][k % 4] = m00 * t.eval_z(z).clamp(-1.0, 1.0);
        }
        out
    }

    /// Largest error of the tabulated double term at the midpoints between nodes, against
    /// the material's own evaluation (its `double_order`), relative to the total
    /// monostatic `M00` there (single + double + multiple: what the renderer returns).
    pub fn max_error(&self, mat: &Material) -> f64 {
        let n = self.elements[0].values.len() - 1;
        let scale = self.elements[0].scale;
        (0..n)
            .into_par_iter()
            .map(|i| {
                let th = ZTable::theta_of_z(scale, (i as f64 + 0.5) / n as f64);
                let w = [th.sin(), 0.0, th.cos()];
                let want = double_only(mat, w);
                let total = super::eval(mat, w, w, Frame::Sp)[0][0];
                let got = self.eval(th);
                let mut e: f64 = 0.0;
                for a in 0..4 {
                    for b in 0..4 {
                        e = e.max((got[a][b] - want[a][b]).abs());
                    }
                }
                if total > 0.0 {
                    e / total
                } else {
                    0.0
                }
            })
            .reduce(|| 0.0, f64::max)
    }
}

/// The double-bounce term alone (with coherent backscatter as configured) at backscatter.
fn double_only(mat: &Material, w: [f64; 3]) -> Mat4 {
    super::double::eval_double_framed(mat, w, w, Frame::Sp)
}

// ---------------------------------------------------------------------------------------
// BrdfTable: the total Mueller BRDF for the GPU renderer.
// ---------------------------------------------------------------------------------------

use super::single::{masking_from_excess, single_mueller};
use crate::microfacet::masking::TABLE_NODES;
use crate::microfacet::{Correlation, Distribution, MaskingEval};
pub use crate::optics::frames::change_bases;
use crate::optics::frames::{beam_bases, cross, dot, neg, normalize, V3};
use crate::optics::fresnel::Eta;
use crate::{Error, Result};
use std::f64::consts::{FRAC_PI_2, PI};

/// `ln M00` stored where `M00 <= 0` (a direction below the horizon, or a part that
/// vanishes there) or where `ln M00` would be lower; the normalized elements are 0 there.
/// `exp(LN_FLOOR)` underflows to 0 in f32.
pub const LN_FLOOR: f64 = -200.0;

/// Sign of element `k = 4 a + b` under the mirror `y -> -y`: `d_a d_b` with
/// `D = diag(1, 1, -1, -1)`, so `M(-psi) = D M(psi) D` element by element.
pub const MIRROR_SIGN: [f64; 16] = [
    1.0, 1.0, -1.0, -1.0, //
    1.0, 1.0, -1.0, -1.0, //
    -1.0, -1.0, 1.0, 1.0, //
    -1.0, -1.0, 1.0, 1.0,
];

/// The beam frames the table's Mueller matrices refer to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableFrame {
    /// The core's `Sp` frame ([`crate::optics::frames::Frame::Sp`]): planes `(n, wi)` and
    /// `(n, wo)`. For `beta > 0` it winds around the normal: where `wi` or `wo` passes
    /// through `n` (`theta = beta/2`, `psi = pi` or `0`) the matrix is discontinuous in
    /// `(theta, psi)` and no table resolves it.
    Sp,
    /// The bisector frame: for both beams `x = normalize(e - (e.w) w)` with
    /// `e = normalize(n x b)` the azimuth vector of `b = normalize(wi + wo)` (`e = (0, 1, 0)`
    /// when `b = n`), `y = k x x` (`k_in = -wi`, `k_out = wo`). Smooth over the whole
    /// table; for `beta = 0` it is the `Sp` frame (same Mueller matrix).
    Bisector,
}

/// One term group of a [`BrdfTable`] on its own grid (layout in [`BrdfTable`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TablePart {
    /// `s` of the `z` mapping `cot(theta) = s z / (1 - z)`.
    pub scale: f64,
    /// Intervals in `z` (`n_z + 1` nodes).
    pub n_z: usize,
    /// Intervals in `psi` (`n_psi + 1` nodes); 0 when `beta == 0`.
    pub n_psi: usize,
    /// `[psi node j][z node i][16]`, row major: index `(j (n_z + 1) + i) 16 + k`.
    pub data: Vec<f64>,
    /// The nodes hold `M cos(theta)` (`theta` the table's bisector angle) instead of `M`,
    /// and the part's value is the interpolant over `cos(theta)`. Set for the single term
    /// with correlated masking, whose `M00` diverges as `1 / cos` at grazing (the `min(P_i,
    /// P_o) / (cos_i cos_o)` branch, which backscatter always takes): no polynomial in `z`
    /// follows `ln M00` to that node, and a flat face 1e-3 rad from edge-on came out
    /// 2.5e8 times too bright in the renderer (tests/test_extremes.py). `M cos` is finite
    /// there.
    pub cos_weighted: bool,
}

/// The total Mueller BRDF `f(wi, wo)` (1/sr, no cosine) for a fixed bistatic angle `beta`,
/// tabulated for the renderer.
///
/// # Coordinates
/// For local unit `wi`, `wo` (normal `n = +z`) with `beta = angle(wi, wo)`:
/// `b = normalize(wi + wo)`, `theta` = polar angle of `b` in `[0, pi/2]`,
/// `e_phi = normalize(n x b)` (`(0, 1, 0)` when `b = n`), `e_theta = e_phi x b`,
/// `psi = atan2((wi - wo).e_phi, (wi - wo).e_theta)` in `(-pi, pi]` (0 when `beta = 0`);
/// [`table_coords`] returns `|psi|` and `mirrored = psi < 0`. Inversely (azimuth of `b`
/// = 0, [`table_dirs`]): `b = (sin t, 0, cos t)`, `e_theta = (cos t, 0, -sin t)`,
/// `tv = cos psi e_theta + sin psi (0, 1, 0)`, `wi = cos(beta/2) b + sin(beta/2) tv`,
/// `wo = cos(beta/2) b - sin(beta/2) tv` (`psi = 0`: `wi` is the more grazing one).
/// An isotropic surface's matrix does not depend on the azimuth of `b` (in either frame
/// of [`TableFrame`], both of which turn with `b`), and the mirror `y -> -y` gives
/// `M(theta, -psi) = D M(theta, psi) D`, `D = diag(1, 1, -1, -1)` (tested against the
/// material's evaluation), so `psi` in `[0, pi]` covers every pair.
///
/// # Layout
/// The BRDF is the **sum** of `parts`, in this order, each present when the material
/// enables its terms: the single bounce; the multiple + diffuse terms (depolarizing,
/// `M00` only); the double bounce with its coherent backscatter (`kinds` says which).
/// The single term is kept apart from the multiple term because `ln` of their sum has a
/// knee where the steep single lobe meets the flat multiple term (measured for Beckmann
/// 0.1, metal, 256 nodes at scale `1/sqrt(alpha)`: 2.2e-2 relative error for the two in one
/// part, 3.7e-6 for the single term alone). A part has `(n_psi + 1) x (n_z + 1)` nodes, `z_i = i / n_z`,
/// `theta_i = atan2(1 - z_i, scale z_i)` (`z = 0`: `theta = pi/2`; `z = 1`: `theta = 0`;
/// inverse `z = cos t / (scale sin t + cos t)`), `psi_j = j pi / n_psi` (a single
/// row `j = 0` when `n_psi = 0`). Node `(j, i)` holds 16 numbers at
/// `data[(j (n_z + 1) + i) 16 + k]`: `k = 0`: `ln M00` (at least [`LN_FLOOR`], which
/// also marks `M00 <= 0` and pairs below the horizon); `k = 4 a + b >= 1`: `M_ab / M00`
/// (0 where floored), in the frame `frame`.
///
/// # Interpolation (per part, then summed; see [`eval_part`])
/// `x = z n_z`, `i = min(floor(x), n_z - 1)`, `t = x - i`; Catmull-Rom
/// [`catmull_rom`] on nodes `i-1, i, i+1, i+2` with ghost nodes by quadratic
/// extrapolation (`v[-1] = 3 v[0] - 3 v[1] + v[2]`, `v[n+1] = 3 v[n] - 3 v[n-1] + v[n-2]`),
/// exactly [`ZTable::eval_z`]. Then in `psi` (when `n_psi > 0`): `y = psi n_psi / pi`,
/// `j = min(floor(y), n_psi - 1)`, `u = y - j`, Catmull-Rom over the four `z`-interpolated
/// rows `j-1 .. j+2`, where row `-1` is row `1` and row `n_psi + 1` is row `n_psi - 1`,
/// each multiplied element-wise by [`MIRROR_SIGN`] (`ln M00` is even). `ln M00` is clamped
/// after each of the two steps to the range of its two bracketing values (the nodes `i`,
/// `i+1` in `z`; the `z`-interpolated rows `j`, `j+1` in `psi`); the normalized elements
/// are clamped to `[-1, 1]` at the end. The part's matrix is `exp(ln M00) * [1, m_1 ..
/// m_15]`, divided by `cos(theta)` for a [`TablePart::cos_weighted`] part (whose nodes
/// hold `M cos(theta)`; the renderer multiplies by `cos(theta_i) / cos(theta)`, at most 2).
#[derive(Debug, Clone, PartialEq)]
pub struct BrdfTable {
    /// Bistatic angle (radians), `0 <= beta < pi/2`.
    pub beta: f64,
    pub frame: TableFrame,
    /// What each part holds (not uploaded; for [`BrdfTable::max_error`]).
    pub kinds: Vec<PartKind>,
    pub parts: Vec<TablePart>,
    /// The single term when it is evaluated per lookup instead of tabulated
    /// ([`BrdfTableOptions::in_shader`]); it is then not among `parts`.
    pub single: Option<SingleParams>,
    /// Likewise the multiple + diffuse terms.
    pub lambertian: Option<LambertianParams>,
}

/// The multiple and diffuse terms evaluated per lookup, without a 2D table: each is
/// `c (1 - E(theta_i)) (1 - E(theta_o))` (M00 only) with the material's own 1D albedo
/// table `E` (in its `z`, or `zeta` for the Fresnel-scaled ones) and `c` =
/// `F_ms / (pi (1 - E_avg))` or `rho_d / (pi (1 - E_avg))` (0 where `1 - E_avg <= 1e-14`,
/// as [`Material::multiple_z`]), so the value is the core's.
#[derive(Debug, Clone, PartialEq)]
pub struct LambertianParams {
    /// `s` of the material's `z` ([`Distribution::table_scale`]).
    pub table_scale: f64,
    /// `(E, c)` per enabled term.
    pub terms: Vec<(crate::brdf::material::AlbedoTable, f64)>,
}

impl LambertianParams {
    pub fn new(mat: &Material) -> Self {
        let coef = |t: &crate::brdf::material::AlbedoTable, x: f64| {
            let denom = PI * (1.0 - t.e_avg);
            if denom <= 1e-14 {
                0.0
            } else {
                x / denom
            }
        };
        let mut terms = vec![];
        if mat.spec.terms.multiple {
            let t = mat.e_white.as_ref().expect("multiple term enabled");
            terms.push((t.clone(), coef(t, mat.f_ms)));
        }
        if mat.spec.terms.diffuse {
            let t = mat.e_spec.as_ref().expect("diffuse term enabled");
            terms.push((t.clone(), coef(t, mat.spec.diffuse_albedo)));
        }
        LambertianParams {
            table_scale: mat.spec.distribution.table_scale(),
            terms,
        }
    }

    /// `M00` (1/sr) for local `wi`, `wo`; 0 below the horizon.
    pub fn eval(&self, wi: V3, wo: V3) -> f64 {
        let (ci, co) = (wi[2], wo[2]);
        if ci <= 0.0 || co <= 0.0 {
            return 0.0;
        }
        let si = (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
        let so = (wo[0] * wo[0] + wo[1] * wo[1]).sqrt();
        let (zi, zo) = (
            z_of(self.table_scale, ci, si),
            z_of(self.table_scale, co, so),
        );
        self.terms
            .iter()
            .map(|(t, c)| {
                let a = (1.0 - t.eval_csz(ci, si, zi)).max(0.0);
                let b = (1.0 - t.eval_csz(co, so, zo)).max(0.0);
                c * a * b
            })
            .sum()
    }

    /// Its bound on `M00 cos(theta_i)`: the sum of the coefficients.
    pub fn max_m00_cos(&self) -> f64 {
        self.terms.iter().map(|(_, c)| c).sum()
    }

    /// The words the kernel reads (`add_lambertian_in_kernel` in `shaders/shade.wgsl`):
    /// `[1 (the kind; u32 bits), table scale, terms (u32 bits)]`, then per term
    /// `[c, s_f (0: the table is in z), intervals (u32 bits), its n + 1 values]`.
    pub fn words(&self) -> Vec<f32> {
        let u = |x: u32| f32::from_bits(x);
        let mut w = vec![u(1), self.table_scale as f32, u(self.terms.len() as u32)];
        for (t, c) in &self.terms {
            w.push(*c as f32);
            w.push(t.fresnel_scale.unwrap_or(0.0) as f32);
            w.push(u((t.e.values.len() - 1) as u32));
            w.extend(t.e.values.iter().map(|&x| x as f32));
        }
        w
    }
}

/// What the kernel needs to evaluate the single term per pixel, without a table: the
/// distribution, the index, the masking correlation and the masking excess `N(theta)`
/// (`P = cos / (cos + N)`) as a 1D table in the material's `z` (for the default tabulated
/// APS masking the material's own table, so the evaluation is the core's; for the closed
/// forms and the quadrature their values at [`TABLE_NODES`] nodes, Catmull-Rom between:
/// error measured in the tests). Uploaded after the header (`GpuTables::pack`).
#[derive(Debug, Clone, PartialEq)]
pub struct SingleParams {
    pub distribution: Distribution,
    pub eta: Eta,
    pub correlation: Correlation,
    pub excess: ZTable,
}

impl SingleParams {
    pub fn new(mat: &Material) -> Self {
        let excess = match &mat.n_table {
            Some(t) if mat.spec.masking == MaskingEval::Table => t.clone(),
            _ => {
                let scale = mat.spec.distribution.table_scale();
                ZTable::build(scale, TABLE_NODES, |t| {
                    let (s, c) = t.sin_cos();
                    let c = c.max(0.0);
                    mat.masking_excess_z(c, s, mat.z_of(c, s))
                })
            }
        };
        SingleParams {
            distribution: mat.spec.distribution,
            eta: mat.spec.eta,
            correlation: mat.correlation,
            excess,
        }
    }

    /// The single-bounce Mueller BRDF (1/sr) for local `wi`, `wo` (normal `+z`) in the beam
    /// `bases`, as the kernel evaluates it (in f64): the zero matrix below the horizon.
    pub fn eval(&self, wi: V3, wo: V3, bases: (V3, V3, V3, V3)) -> Mat4 {
        let (ci, co) = (wi[2], wo[2]);
        if ci <= 0.0 || co <= 0.0 {
            return [[0.0; 4]; 4];
        }
        let si = (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
        let so = (wo[0] * wo[0] + wo[1] * wo[1]).sqrt();
        let n = |c: f64, s: f64| self.excess.eval(c, s).max(0.0);
        let g = masking_from_excess(self.correlation, wi, wo, si, so, n(ci, si), n(co, so));
        single_mueller(&self.distribution, self.eta, wi, wo, g, bases)
    }

    /// Largest `M00 cos(theta_i)` (1/sr) over the nodes of the default single-term grid
    /// for the bistatic angle `beta` ([`default_grid`]; the value between nodes may
    /// exceed it: the renderer takes a margin, `GpuTables::pack`).
    pub fn max_m00_cos(&self, beta: f64) -> f64 {
        let (n_z, n_psi, scale) = default_grid(PartKind::Single, self.distribution.scale(), beta);
        let n_psi = if beta > 0.0 { n_psi } else { 0 };
        (0..(n_z + 1) * (n_psi + 1))
            .into_par_iter()
            .map(|idx| {
                let (j, i) = (idx / (n_z + 1), idx % (n_z + 1));
                let theta = ZTable::theta_of_z(scale, i as f64 / n_z as f64);
                let psi = j as f64 * PI / n_psi.max(1) as f64;
                let (wi, wo) = table_dirs(beta, theta, psi);
                let m00 = self.eval(wi, wo, bisector_bases(wi, wo))[0][0];
                if m00.is_finite() {
                    m00 * wi[2].max(0.0)
                } else {
                    0.0
                }
            })
            .reduce(|| 0.0, f64::max)
    }

    /// The words the kernel reads (`add_single_in_kernel` in `shaders/shade.wgsl`):
    /// `[0 (the kind; u32 bits), distribution (0 Blinn-Phong, 1 Beckmann, 2 GGX; u32
    /// bits), m or alpha, perfect conductor (u32 bits), n - 1, k, excess table scale,
    /// correlation (0 none, 1 seed, 2 APS; u32 bits), intervals of the excess table (u32
    /// bits), its n + 1 values]`. `n - 1` is rounded from f64, so that `eta` near 1 keeps its relative
    /// accuracy in `eta^2 - 1 = (n - 1 + i k)(n + 1 + i k)`.
    pub fn words(&self) -> Vec<f32> {
        let u = |x: u32| f32::from_bits(x);
        let (kind, rough) = match self.distribution {
            Distribution::BlinnPhong { m } => (0, m),
            Distribution::Beckmann { alpha } => (1, alpha),
            Distribution::Ggx { alpha } => (2, alpha),
        };
        let (pec, nm1, k) = match self.eta {
            Eta::PerfectConductor => (1, 0.0, 0.0),
            Eta::Complex(e) => (0, e.re - 1.0, e.im),
        };
        let corr = match self.correlation {
            Correlation::None => 0,
            Correlation::Seed => 1,
            Correlation::Aps => 2,
        };
        let v = &self.excess.values;
        let mut w = vec![
            u(0),
            u(kind),
            rough as f32,
            u(pec),
            nm1 as f32,
            k as f32,
            self.excess.scale as f32,
            u(corr),
            u((v.len() - 1) as u32),
        ];
        w.extend(v.iter().map(|&x| x as f32));
        w
    }
}

/// Grid of one part; `None` takes the default of [`BrdfTableOptions::resolve`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PartOptions {
    /// Intervals in `z`.
    pub n_z: Option<usize>,
    /// Intervals in `psi` (ignored when `beta = 0`).
    pub n_psi: Option<usize>,
    /// `s` of the `z` mapping.
    pub scale: Option<f64>,
}

/// Build options (`Default`: every default).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BrdfTableOptions {
    /// The single term's grid.
    pub single: PartOptions,
    /// The grid of the multiple + diffuse terms.
    pub lambertian: PartOptions,
    /// The double bounce's grid.
    pub double: PartOptions,
    /// Quadrature order of the double bounce in the table.
    pub double_order: Option<usize>,
    pub frame: Option<TableFrame>,
    /// Evaluate the single term ([`SingleParams`]) and the multiple + diffuse terms
    /// ([`LambertianParams`]) per lookup from the material's parameters and 1D tables (in
    /// the kernel: `add_single_in_kernel`, `add_lambertian_in_kernel` in
    /// `shaders/shade.wgsl`) instead of tabulating them; the double bounce stays tabulated.
    pub in_shader: bool,
}

/// Which terms a part holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PartKind {
    /// The single bounce.
    Single,
    /// The multiple and diffuse terms (whichever are enabled; depolarizing).
    Lambertian,
    /// The double bounce (with its coherent backscatter as configured) at this order.
    Double(usize),
}

impl PartKind {
    pub fn name(&self) -> &'static str {
        match self {
            PartKind::Single => "single",
            PartKind::Lambertian => "multiple+diffuse",
            PartKind::Double(_) => "double",
        }
    }
}

/// A part's grid with the defaults filled in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartGrid {
    pub kind: PartKind,
    pub n_z: usize,
    pub n_psi: usize,
    pub scale: f64,
}

impl BrdfTableOptions {
    /// The parts `mat` gets (single; multiple + diffuse; double: those it enables), with
    /// the defaults filled in and validated, and the frame.
    pub fn resolve(&self, mat: &Material, beta: f64) -> Result<(Vec<PartGrid>, TableFrame)> {
        let alpha = mat.spec.distribution.scale();
        let bistatic = beta > 0.0;
        let order = self.double_order.unwrap_or(DEFAULT_DOUBLE_ORDER);
        if !(4..=1024).contains(&order) {
            return Err(Error::param(
                "double_order",
                order,
                "quadrature order must be in [4, 1024]",
            ));
        }
        let t = mat.spec.terms;
        let mut v = vec![];
        for (on, kind, o, names) in [
            (
                t.single,
                PartKind::Single,
                &self.single,
                ["n_z", "n_psi", "scale"],
            ),
            (
                t.multiple || t.diffuse,
                PartKind::Lambertian,
                &self.lambertian,
                ["n_z_lambertian", "n_psi_lambertian", "scale_lambertian"],
            ),
            (
                t.double,
                PartKind::Double(order),
                &self.double,
                ["n_z_double", "n_psi_double", "scale_double"],
            ),
        ] {
            if !on {
                continue;
            }
            let (dz, dpsi, dscale) = default_grid(kind, alpha, beta);
            let g = PartGrid {
                kind,
                n_z: o.n_z.unwrap_or(dz),
                n_psi: if bistatic { o.n_psi.unwrap_or(dpsi) } else { 0 },
                scale: o.scale.unwrap_or(dscale),
            };
            if !(4..=MAX_NODES).contains(&g.n_z) {
                return Err(Error::param(
                    names[0],
                    g.n_z,
                    format!("must be in [4, {MAX_NODES}]"),
                ));
            }
            if bistatic && !(2..=MAX_NODES).contains(&g.n_psi) {
                return Err(Error::param(
                    names[1],
                    g.n_psi,
                    format!("must be in [2, {MAX_NODES}] when bistatic_angle > 0"),
                ));
            }
            if (g.n_z + 1) * (g.n_psi + 1) > MAX_TOTAL_NODES {
                return Err(Error::param(
                    names[1],
                    g.n_psi,
                    format!("(n_z + 1) (n_psi + 1) must be at most {MAX_TOTAL_NODES}"),
                ));
            }
            if !(g.scale.is_finite() && g.scale > 0.0 && g.scale <= 1e6) {
                return Err(Error::param(names[2], g.scale, "must be in (0, 1e6]"));
            }
            v.push(g);
        }
        Ok((v, self.frame.unwrap_or(TableFrame::Bisector)))
    }
}

/// Upper bound on the intervals per axis and on the nodes per part.
pub const MAX_NODES: usize = 1 << 16;
pub const MAX_TOTAL_NODES: usize = 1 << 22;
/// Default quadrature order of the double bounce in the table.
pub const DEFAULT_DOUBLE_ORDER: usize = 48;

/// Default `(n_z, n_psi, scale)` of a part for a distribution of width `alpha` (chosen
/// from the measurements in `docs/render-table.md`): the single term on a fine grid with
/// `scale = 1/sqrt(alpha)`, which balances the node density near normal incidence
/// (`dtheta = dz / scale`, the lobe has width `alpha`) against that near grazing
/// (`dtheta = scale dz`); the multiple + diffuse terms on the grid of the material's own
/// albedo tables (`scale = min(alpha, 1)`, 256 intervals: the nodes coincide with theirs); the
/// double bounce, which is smooth, on a coarse grid.
pub fn default_grid(kind: PartKind, alpha: f64, _beta: f64) -> (usize, usize, f64) {
    match kind {
        PartKind::Single => (256, 32, 1.0 / alpha.sqrt()),
        // the material's table scale (`Distribution::table_scale`)
        PartKind::Lambertian => (256, 8, alpha.min(1.0)),
        PartKind::Double(_) => (32, 8, 1.0),
    }
}

pub use crate::microfacet::masking::catmull_rom;

/// Interval `i = min(floor(x), n - 1)` (x clamped to `[0, n]`) and the fraction `x - i`.
#[inline]
pub fn cell(x: f64, n: usize) -> (usize, f64) {
    let x = x.clamp(0.0, n as f64);
    let i = (x as usize).min(n - 1);
    (i, x - i as f64)
}

/// Catmull-Rom on interval `i` of `n` with the end ghost nodes by quadratic extrapolation:
/// `q0 = v[max(i, 1) - 1]`, `p1 = v[i]`, `p2 = v[i + 1]`, `q3 = v[min(i + 2, n)]`.
#[inline]
pub fn catmull_rom_ends(q0: f64, p1: f64, p2: f64, q3: f64, i: usize, n: usize, t: f64) -> f64 {
    let p0 = if i == 0 { 3.0 * p1 - 3.0 * p2 + q3 } else { q0 };
    let p3 = if i + 2 > n {
        3.0 * p2 - 3.0 * p1 + q0
    } else {
        q3
    };
    catmull_rom(p0, p1, p2, p3, t)
}

/// `z` of a polar angle given by `(cos, sin)` for the mapping scale `s`.
#[inline]
pub fn z_of(scale: f64, cos_t: f64, sin_t: f64) -> f64 {
    let den = scale * sin_t + cos_t;
    if den <= 0.0 {
        0.0
    } else {
        (cos_t / den).clamp(0.0, 1.0)
    }
}

/// The `z`-interpolated values of psi row `j` of a part at interval `i`, fraction `t`, of
/// the elements in `mask` (bit `k` for element `k`; the others are left 0; `ln M00` is
/// always interpolated, clamped to the two bracketing nodes).
#[inline]
fn interp_row(p: &TablePart, j: usize, i: usize, t: f64, mask: u32) -> [f64; 16] {
    let n = p.n_z;
    let row = j * (n + 1);
    let at = |ii: usize| &p.data[(row + ii) * 16..(row + ii) * 16 + 16];
    let (v0, v1, v2, v3) = (at(i.max(1) - 1), at(i), at(i + 1), at((i + 2).min(n)));
    let mut out = [0.0; 16];
    for k in 0..16 {
        if k == 0 || mask & (1 << k) != 0 {
            out[k] = catmull_rom_ends(v0[k], v1[k], v2[k], v3[k], i, n, t);
        }
    }
    out[0] = out[0].clamp(v1[0].min(v2[0]), v1[0].max(v2[0]));
    out
}

/// One part at `(z, psi)`, `psi` in `[0, pi]`: `(ln M00, [1, M_ab / M00 ...])` with
/// element 0 of the array being `ln M00` (the layout of a node).
pub fn eval_part(p: &TablePart, z: f64, psi: f64) -> [f64; 16] {
    eval_part_masked(p, z, psi, 0xffff)
}

/// [`eval_part`] for the elements in `mask` only (the others 0; `ln M00` always).
fn eval_part_masked(p: &TablePart, z: f64, psi: f64, mask: u32) -> [f64; 16] {
    let (i, t) = cell(z * p.n_z as f64, p.n_z);
    let mut out = if p.n_psi == 0 {
        interp_row(p, 0, i, t, mask)
    } else {
        let np = p.n_psi;
        let (j, u) = cell(psi * np as f64 / PI, np);
        let r0 = if j == 0 { 1 } else { j - 1 };
        let r3 = if j + 2 > np { np - 1 } else { j + 2 };
        let a = interp_row(p, r0, i, t, mask);
        let b = interp_row(p, j, i, t, mask);
        let c = interp_row(p, j + 1, i, t, mask);
        let d = interp_row(p, r3, i, t, mask);
        let mut o = [0.0; 16];
        for k in 0..16 {
            let s0 = if j == 0 { MIRROR_SIGN[k] } else { 1.0 };
            let s3 = if j + 2 > np { MIRROR_SIGN[k] } else { 1.0 };
            o[k] = catmull_rom(s0 * a[k], b[k], c[k], s3 * d[k], u);
        }
        o[0] = o[0].clamp(b[0].min(c[0]), b[0].max(c[0]));
        o
    };
    for v in out.iter_mut().skip(1) {
        *v = v.clamp(-1.0, 1.0);
    }
    out
}

/// The Mueller matrix of one part at `theta` given by `(cos, sin)` and `psi` (table frame,
/// `psi` in `[0, pi]`), the elements in `mask` (the others 0; `M00` always).
fn part_matrix(p: &TablePart, c: f64, s: f64, psi: f64, mask: u32) -> Mat4 {
    let v = eval_part_masked(p, z_of(p.scale, c, s), psi, mask);
    let mut m00 = v[0].exp();
    if p.cos_weighted {
        m00 = if c > 0.0 { m00 / c } else { 0.0 };
    }
    let mut m = [[0.0; 4]; 4];
    m[0][0] = m00;
    for k in 1..16 {
        m[k / 4][k % 4] = m00 * v[k];
    }
    m
}

/// The pair `(wi, wo)` of table coordinates `(theta, psi)` (azimuth of `b` = 0).
pub fn table_dirs(beta: f64, theta: f64, psi: f64) -> (V3, V3) {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    let (sb, cb) = (0.5 * beta).sin_cos();
    let b = [st, 0.0, ct];
    let t = [cp * ct, sp, -cp * st];
    let wi = [
        cb * b[0] + sb * t[0],
        cb * b[1] + sb * t[1],
        cb * b[2] + sb * t[2],
    ];
    let wo = [
        cb * b[0] - sb * t[0],
        cb * b[1] - sb * t[1],
        cb * b[2] - sb * t[2],
    ];
    (wi, wo)
}

/// `(e_theta, e_phi)` of the unit bisector `b` (`e_phi = (0, 1, 0)` when `b = n`).
#[inline]
fn bisector_axes(b: V3) -> (V3, V3) {
    let r = (b[0] * b[0] + b[1] * b[1]).sqrt();
    let (c, s) = if r > 0.0 {
        (b[0] / r, b[1] / r)
    } else {
        (1.0, 0.0)
    };
    ([b[2] * c, b[2] * s, -r], [-s, c, 0.0])
}

/// Table coordinates of local unit directions `wi`, `wo` (`z >= 0`): `(theta, psi,
/// mirrored)` with `psi` in `[0, pi]`; when `mirrored` the table value must be taken as
/// `D M D` (`D = diag(1, 1, -1, -1)`). `beta` is the table's bistatic angle: for
/// `beta = 0`, `psi = 0` (the matrix does not depend on it). At `theta = 0` the azimuth
/// of `b` is taken as 0.
pub fn table_coords(beta: f64, wi: V3, wo: V3) -> (f64, f64, bool) {
    let b = normalize([wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]]);
    let r = (b[0] * b[0] + b[1] * b[1]).sqrt();
    let theta = r.atan2(b[2]);
    if beta == 0.0 {
        return (theta, 0.0, false);
    }
    let (et, ep) = bisector_axes(b);
    let d = [wi[0] - wo[0], wi[1] - wo[1], wi[2] - wo[2]];
    let psi = dot(d, ep).atan2(dot(d, et));
    (theta, psi.abs(), psi < 0.0)
}

/// Beam bases `(x_in, y_in, x_out, y_out)` of [`TableFrame::Bisector`].
pub fn bisector_bases(wi: V3, wo: V3) -> (V3, V3, V3, V3) {
    let b = normalize([wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]]);
    let (_, e) = bisector_axes(b);
    let proj = |w: V3| {
        let c = dot(e, w);
        normalize([e[0] - c * w[0], e[1] - c * w[1], e[2] - c * w[2]])
    };
    let (x_in, x_out) = (proj(wi), proj(wo));
    (x_in, cross(neg(wi), x_in), x_out, cross(wo, x_out))
}

/// Bases of `frame` for the pair.
fn table_bases(frame: TableFrame, wi: V3, wo: V3) -> (V3, V3, V3, V3) {
    match frame {
        TableFrame::Sp => beam_bases(Frame::Sp, wi, wo),
        TableFrame::Bisector => bisector_bases(wi, wo),
    }
}

/// `D m D` with `D = diag(1, 1, -1, -1)`.
pub fn mirror(m: &Mat4) -> Mat4 {
    let mut o = *m;
    for (k, s) in MIRROR_SIGN.iter().enumerate() {
        o[k / 4][k % 4] *= s;
    }
    o
}

/// The material restricted to the terms of a part.
fn part_material(mat: &Material, kind: PartKind) -> Material {
    let mut m = mat.clone();
    let t = &mut m.spec.terms;
    match kind {
        PartKind::Single => {
            t.double = false;
            t.multiple = false;
            t.diffuse = false;
        }
        PartKind::Lambertian => {
            t.single = false;
            t.double = false;
        }
        PartKind::Double(_) => {}
    }
    m
}

/// A part's value in the table frame at table coordinates (`mat` from [`part_material`]).
fn part_reference(
    mat: &Material,
    kind: PartKind,
    frame: TableFrame,
    beta: f64,
    theta: f64,
    psi: f64,
) -> Mat4 {
    let (wi, wo) = table_dirs(beta, theta, psi);
    let m = match kind {
        PartKind::Single | PartKind::Lambertian => super::eval(mat, wi, wo, Frame::Sp),
        PartKind::Double(order) => {
            super::double::eval_double(mat, wi, wo, Frame::Sp, order, mat.spec.coherent_backscatter)
        }
    };
    if frame == TableFrame::Sp || m[0][0] <= 0.0 {
        m
    } else {
        change_bases(&m, beam_bases(Frame::Sp, wi, wo), bisector_bases(wi, wo))
    }
}

/// Nodes where the pair `(wi, wo)` lies strictly below the horizon (a prefix of every psi
/// row, large theta, when `beta > 0`) hold no BRDF; they are only ever read as the
/// neighbours of cells at the cut, which the renderer does evaluate (pixels next to the
/// terminator). Storing the floor there pulled those cells' `ln M00` down by up to ~200
/// (a Lambertian sphere at beta = 60 deg lost 0.5% of its cross-section); they now repeat
/// the row's first node above the cut (constant extrapolation, so the interpolation across
/// the cut stays within the valid values' range).
fn extend_below_horizon(
    mut nodes: Vec<[f64; 16]>,
    beta: f64,
    n_z: usize,
    n_psi: usize,
    scale: f64,
) -> Vec<[f64; 16]> {
    if beta <= 0.0 {
        return nodes;
    }
    let nz1 = n_z + 1;
    for j in 0..=n_psi {
        let psi = if n_psi == 0 {
            0.0
        } else {
            j as f64 * PI / n_psi as f64
        };
        let below = |i: usize| {
            let theta = ZTable::theta_of_z(scale, i as f64 / n_z as f64);
            let (wi, wo) = table_dirs(beta, theta, psi);
            wi[2] < 0.0 || wo[2] < 0.0
        };
        // z = 0 is theta = 90 deg: the below-horizon nodes are i = 0 .. cut
        let Some(cut) = (0..nz1).find(|&i| !below(i)) else {
            continue;
        };
        let row = j * nz1;
        let fill = nodes[row + cut];
        for node in &mut nodes[row..row + cut] {
            *node = fill;
        }
    }
    nodes
}

/// The 16 stored numbers of a node.
fn encode(m: &Mat4) -> [f64; 16] {
    let mut out = [0.0; 16];
    out[0] = LN_FLOOR;
    let m00 = m[0][0];
    if m00 > 0.0 && m00.is_finite() && m00.ln() > LN_FLOOR {
        out[0] = m00.ln();
        for k in 1..16 {
            out[k] = m[k / 4][k % 4] / m00;
        }
    }
    out
}

/// Where a part's interpolation error is largest (see [`BrdfTable::max_error`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartError {
    /// The part's terms.
    pub kind: &'static str,
    /// `max_ab |M_ab(table) - M_ab(material)| / M00_total` over the cell centres.
    pub max: f64,
    pub theta: f64,
    pub psi: f64,
    /// Element `4 a + b` where the largest error occurs.
    pub element: usize,
    /// Cell centres checked.
    pub points: usize,
}

/// Interpolation error of a [`BrdfTable`] against the material's own evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct TableError {
    /// Sum of the parts' maxima: a bound on the total's error at any cell centre.
    pub max: f64,
    pub parts: Vec<PartError>,
}

/// Default dynamic range of [`BrdfTable::max_error`]: errors are relative to
/// `max(M00_total, DYNAMIC_RANGE * M00_peak)`. Where the BRDF is more than 10 decades
/// below its peak the material's own evaluation is at its noise level (for smooth
/// surfaces `1 - E(theta)` of the multiple term is then 1e-10 to 1e-13, the albedo
/// table's rounding), and f32 sums cannot resolve it next to the peak anyway.
pub const DYNAMIC_RANGE: f64 = 1e-10;

impl BrdfTable {
    /// Tabulate `mat` for the bistatic angle `beta` (radians, `0 <= beta < pi/2`).
    pub fn build(mat: &Material, beta: f64, opts: &BrdfTableOptions) -> Result<Self> {
        if !(beta.is_finite() && (0.0..FRAC_PI_2).contains(&beta)) {
            return Err(Error::param(
                "bistatic_angle",
                beta,
                "must be in [0, pi/2) radians",
            ));
        }
        let (grids, frame) = opts.resolve(mat, beta)?;
        let mut parts = vec![];
        let mut kinds = vec![];
        let mut single = None;
        let mut lambertian = None;
        for g in grids {
            if opts.in_shader {
                match g.kind {
                    PartKind::Single => {
                        single = Some(SingleParams::new(mat));
                        continue;
                    }
                    PartKind::Lambertian => {
                        lambertian = Some(LambertianParams::new(mat));
                        continue;
                    }
                    PartKind::Double(_) => {}
                }
            }
            let m = part_material(mat, g.kind);
            let (n_z, n_psi, scale) = (g.n_z, g.n_psi, g.scale);
            let cos_weighted = g.kind == PartKind::Single
                && mat.spec.shadowing != crate::microfacet::Shadowing::None
                && mat.correlation != crate::microfacet::Correlation::None;
            let nz1 = n_z + 1;
            let nodes: Vec<[f64; 16]> = (0..(n_psi + 1) * nz1)
                .into_par_iter()
                .map(|idx| {
                    let (j, i) = (idx / nz1, idx % nz1);
                    let theta = ZTable::theta_of_z(scale, i as f64 / n_z as f64);
                    let psi = if n_psi == 0 {
                        0.0
                    } else {
                        j as f64 * PI / n_psi as f64
                    };
                    let mut v = part_reference(&m, g.kind, frame, beta, theta, psi);
                    if cos_weighted {
                        // cos(theta) > 0 even at the z = 0 node (cos(FRAC_PI_2) = 6e-17)
                        let c = theta.cos();
                        v.iter_mut().flatten().for_each(|x| *x *= c);
                    }
                    encode(&v)
                })
                .collect();
            let nodes = extend_below_horizon(nodes, beta, n_z, n_psi, scale);
            parts.push(TablePart {
                scale,
                n_z,
                n_psi,
                data: nodes.into_iter().flatten().collect(),
                cos_weighted,
            });
            kinds.push(g.kind);
        }
        Ok(BrdfTable {
            beta,
            frame,
            kinds,
            parts,
            single,
            lambertian,
        })
    }

    /// The interpolated BRDF at table coordinates (`psi` in `[-pi, pi]`; negative `psi`
    /// through the mirror relation), in the table's frame.
    pub fn eval(&self, theta: f64, psi: f64) -> Mat4 {
        let (s, c) = theta.sin_cos();
        self.eval_masked(c, s, psi, 0xffff)
    }

    /// [`BrdfTable::eval`] at `theta` given by `(cos, sin)`, for the elements in `mask` only
    /// (bit `4 a + b` for `M_ab`; the others are 0, `M00` is always evaluated): the CPU
    /// twin of the kernel's `ELEMENT_MASK` lookup.
    pub fn eval_masked(&self, cos_t: f64, sin_t: f64, psi: f64, mask: u32) -> Mat4 {
        let (a, mirrored) = (psi.abs(), psi < 0.0);
        let mut m = [[0.0; 4]; 4];
        for p in &self.parts {
            let pm = part_matrix(p, cos_t, sin_t, a, mask);
            for r in 0..4 {
                for c in 0..4 {
                    m[r][c] += pm[r][c];
                }
            }
        }
        if self.single.is_some() || self.lambertian.is_some() {
            let (wi, wo) = table_dirs(self.beta, sin_t.atan2(cos_t), a);
            if let Some(single) = &self.single {
                let pm = single.eval(wi, wo, table_bases(self.frame, wi, wo));
                for k in 0..16 {
                    if k == 0 || (mask >> k) & 1 == 1 {
                        m[k / 4][k % 4] += pm[k / 4][k % 4];
                    }
                }
            }
            if let Some(l) = &self.lambertian {
                m[0][0] += l.eval(wi, wo);
            }
        }
        if mirrored {
            mirror(&m)
        } else {
            m
        }
    }

    /// The interpolated BRDF for local unit directions, in the core's `Sp` frame (the
    /// table-frame value rotated to `Sp` for the actual pair). The pair's own angle is
    /// used for `(theta, psi)`; it should be close to `beta`.
    pub fn eval_dirs(&self, wi: V3, wo: V3) -> Mat4 {
        let (theta, psi, mirrored) = table_coords(self.beta, wi, wo);
        let m = self.eval(theta, if mirrored { -psi } else { psi });
        if self.frame == TableFrame::Sp {
            return m;
        }
        change_bases(
            &m,
            table_bases(self.frame, wi, wo),
            beam_bases(Frame::Sp, wi, wo),
        )
    }

    /// The data of all parts in f32, concatenated, with per part
    /// `(scale, n_z, n_psi, offset)` (`offset` in floats; `-scale` for a
    /// [`TablePart::cos_weighted`] part, as the renderer's header stores it).
    #[allow(clippy::type_complexity)]
    pub fn to_f32(&self) -> (Vec<(f32, u32, u32, u32)>, Vec<f32>) {
        let mut headers = vec![];
        let mut data = vec![];
        for p in &self.parts {
            headers.push((
                (if p.cos_weighted { -p.scale } else { p.scale }) as f32,
                p.n_z as u32,
                p.n_psi as u32,
                data.len() as u32,
            ));
            data.extend(p.data.iter().map(|&x| x as f32));
        }
        (headers, data)
    }

    /// Largest interpolation error at the cell centres (`z` and `psi` midpoints) with
    /// `theta <= theta_max`, per part, against the material's own evaluation of that part
    /// (the double bounce at the material's `double_order`, so a table built at a lower
    /// order includes that error), as `max_ab |dM_ab| / M00_total`, where `M00_total` is
    /// the part's reference plus the other parts' interpolated `M00` there, but at least
    /// `dynamic_range` times `M00_peak` (the largest interpolated total `M00` at the first
    /// part's nodes with `theta <= theta_max`; see [`DYNAMIC_RANGE`]).
    pub fn max_error(&self, mat: &Material, theta_max: f64, dynamic_range: f64) -> TableError {
        let peak = match self.parts.first() {
            None => 0.0,
            Some(p) => (0..=p.n_z)
                .map(|i| ZTable::theta_of_z(p.scale, i as f64 / p.n_z as f64))
                .filter(|&t| t <= theta_max)
                .flat_map(|t| {
                    (0..=p.n_psi).map(move |j| (t, j as f64 * PI / p.n_psi.max(1) as f64))
                })
                .map(|(t, psi)| self.eval(t, psi)[0][0])
                .fold(0.0, f64::max),
        };
        let floor = dynamic_range * peak;
        let mut parts = vec![];
        for (pi_, (p, &kind)) in self.parts.iter().zip(&self.kinds).enumerate() {
            let kind = match kind {
                PartKind::Double(_) => PartKind::Double(mat.spec.double_order),
                k => k,
            };
            let m = part_material(mat, kind);
            let n_psi_cells = p.n_psi.max(1);
            let pts: Vec<(f64, f64)> = (0..n_psi_cells * p.n_z)
                .map(|idx| {
                    let (j, i) = (idx / p.n_z, idx % p.n_z);
                    let theta = ZTable::theta_of_z(p.scale, (i as f64 + 0.5) / p.n_z as f64);
                    let psi = if p.n_psi == 0 {
                        0.0
                    } else {
                        (j as f64 + 0.5) * PI / p.n_psi as f64
                    };
                    (theta, psi)
                })
                .filter(|&(theta, _)| theta <= theta_max)
                .collect();
            let none = PartError {
                kind: kind.name(),
                max: 0.0,
                theta: 0.0,
                psi: 0.0,
                element: 0,
                points: 0,
            };
            let worst = pts
                .par_iter()
                .map(|&(theta, psi)| {
                    let want = part_reference(&m, kind, self.frame, self.beta, theta, psi);
                    let (st, ct) = theta.sin_cos();
                    let got = part_matrix(p, ct, st, psi, 0xffff);
                    let others: f64 = self
                        .parts
                        .iter()
                        .enumerate()
                        .filter(|(q, _)| *q != pi_)
                        .map(|(_, q)| part_matrix(q, ct, st, psi, 1)[0][0])
                        .sum();
                    let total = (want[0][0] + others).max(floor);
                    if !(total > 0.0) {
                        return none;
                    }
                    let mut e = (0.0, 0);
                    for k in 0..16 {
                        let d = (got[k / 4][k % 4] - want[k / 4][k % 4]).abs();
                        if d > e.0 {
                            e = (d, k);
                        }
                    }
                    PartError {
                        max: e.0 / total,
                        theta,
                        psi,
                        element: e.1,
                        points: 1,
                        ..none
                    }
                })
                .reduce(
                    || none,
                    |a, b| {
                        let mut w = if b.max > a.max { b } else { a };
                        w.points = a.points + b.points;
                        w
                    },
                );
            parts.push(worst);
        }
        TableError {
            max: parts.iter().map(|p| p.max).sum(),
            parts,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::microfacet::Distribution;
    use crate::optics::fresnel::{Eta, C64};

    fn material(dist: Distribution, eta: C64, double: bool, order: usize) -> Material {
        let mut spec = super::super::MaterialSpec::new(dist, Eta::Complex(eta));
        spec.terms.double = double;
        spec.double_order = order;
        Material::new(spec).unwrap()
    }

    fn rel_diff(a: &Mat4, b: &Mat4) -> f64 {
        let mut e: f64 = 0.0;
        for r in 0..4 {
            for c in 0..4 {
                e = e.max((a[r][c] - b[r][c]).abs());
            }
        }
        e / b[0][0].abs().max(1e-300)
    }

    /// The single term as the kernel evaluates it (in f64: [`SingleParams::eval`]) equals
    /// the core's single term for the default tabulated APS masking (the same excess
    /// table), to rounding, over random pairs with grazing ones among them, and through
    /// `eval_masked` (the twin's path) in the bisector frame; for the Smith closed forms
    /// and the seed's, whose excess it interpolates on 512 nodes, to 1e-6 of M00 (the seed's:
    /// 5e-6, measured 1.4e-6, against the closed form's own 1.5e-3 RMS, docs/tradeoff.md).
    #[test]
    fn single_params_equal_the_core_single_term() {
        use crate::microfacet::{MaskingEval, Shadowing};
        let mut rng = crate::reference::rng::Rng::new(11, &[]);
        let mut u = || rng.uniform();
        let cases: Vec<(Distribution, Eta, Shadowing, MaskingEval, f64)> = vec![
            (
                Distribution::Beckmann { alpha: 0.3 },
                Eta::new(0.2, 3.4),
                Shadowing::Aps,
                MaskingEval::Table,
                1e-12,
            ),
            (
                Distribution::Ggx { alpha: 1e-3 },
                Eta::new(1.0 + 1e-6, 0.0),
                Shadowing::Aps,
                MaskingEval::Table,
                1e-12,
            ),
            (
                Distribution::BlinnPhong { m: 5000.0 },
                Eta::new(1e3, 1e3),
                Shadowing::Aps,
                MaskingEval::Table,
                1e-12,
            ),
            (
                Distribution::Ggx { alpha: 10.0 },
                Eta::PerfectConductor,
                Shadowing::Aps,
                MaskingEval::Table,
                1e-12,
            ),
            (
                Distribution::Ggx { alpha: 0.5 },
                Eta::new(1.5, 0.0),
                Shadowing::Smith,
                MaskingEval::Table,
                1e-6,
            ),
            (
                Distribution::Beckmann { alpha: 0.5 },
                Eta::new(1.5, 0.0),
                Shadowing::Smith,
                MaskingEval::Table,
                1e-6,
            ),
            (
                Distribution::BlinnPhong { m: 20.0 },
                Eta::new(1.5, 0.0),
                Shadowing::Aps,
                MaskingEval::Seed,
                5e-6,
            ),
        ];
        for (dist, eta, shadowing, masking, tol) in cases {
            let mut spec = super::super::MaterialSpec::new(dist, eta);
            spec.shadowing = shadowing;
            spec.masking = masking;
            spec.terms.multiple = false;
            let mat = Material::new(spec).unwrap();
            let sp = SingleParams::new(&mat);
            let mut worst: f64 = 0.0;
            for k in 0..400 {
                // every fourth pair has a direction within 1e-7 .. 1e-2 rad of grazing
                let dir = |a: f64, b: f64, grazing: bool| {
                    let th = if grazing {
                        FRAC_PI_2 - 10f64.powf(-7.0 + 5.0 * a)
                    } else {
                        a * FRAC_PI_2
                    };
                    let ph = 2.0 * PI * b;
                    [th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]
                };
                let wi = dir(u(), u(), k % 4 == 0);
                let wo = dir(u(), u(), k % 8 == 1);
                let want = super::super::eval(&mat, wi, wo, Frame::Sp);
                let got = sp.eval(wi, wo, beam_bases(Frame::Sp, wi, wo));
                assert!(got.iter().flatten().all(|x| x.is_finite()));
                if want[0][0] > 1e-300 {
                    worst = worst.max(rel_diff(&got, &want));
                }
            }
            assert!(worst < tol, "{dist:?} {shadowing:?} {masking:?}: {worst:e}");
            // through the table's lookup (bisector frame), bistatic
            let beta = 0.3;
            let opts = BrdfTableOptions {
                in_shader: true,
                ..Default::default()
            };
            let t = BrdfTable::build(&mat, beta, &opts).unwrap();
            assert!(t.parts.is_empty());
            for (theta, psi) in [(0.2f64, 0.5f64), (1.2, -2.0), (1.5, 3.0)] {
                let (wi, wo) = table_dirs(beta, theta, psi.abs());
                let mut want = part_reference(
                    &mat,
                    PartKind::Single,
                    TableFrame::Bisector,
                    beta,
                    theta,
                    psi.abs(),
                );
                if psi < 0.0 {
                    want = mirror(&want);
                }
                let got = t.eval(theta, psi);
                assert!(
                    rel_diff(&got, &want) < tol,
                    "{dist:?}: ({theta}, {psi}) {wi:?} {wo:?}"
                );
            }
        }
    }

    fn rotz(v: V3, phi: f64) -> V3 {
        let (s, c) = phi.sin_cos();
        [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]
    }

    #[test]
    fn nodes_equal_direct_evaluation() {
        let mat = material(
            Distribution::Beckmann { alpha: 0.3 },
            C64::new(0.2, 3.4),
            true,
            12,
        );
        for (beta, frame) in [
            (0.0, TableFrame::Bisector),
            (0.05, TableFrame::Bisector),
            (0.05, TableFrame::Sp),
        ] {
            let grid = |n_z| PartOptions {
                n_z: Some(n_z),
                n_psi: Some(4),
                scale: Some(1.5),
            };
            let opts = BrdfTableOptions {
                single: grid(8),
                lambertian: grid(12),
                double: grid(4),
                double_order: Some(12),
                frame: Some(frame),
                in_shader: false,
            };
            let t = BrdfTable::build(&mat, beta, &opts).unwrap();
            assert_eq!(t.parts.len(), 3);
            let n_psi = if beta > 0.0 { 4 } else { 0 };
            for j in 0..=n_psi {
                for i in 1..=4 {
                    // nodes common to both parts (z = i/4 of the coarse grid, same scale)
                    let theta = ZTable::theta_of_z(1.5, i as f64 / 4.0);
                    let psi = if n_psi == 0 {
                        0.0
                    } else {
                        j as f64 * PI / n_psi as f64
                    };
                    let (wi, wo) = table_dirs(beta, theta, psi);
                    let want = super::super::eval(&mat, wi, wo, Frame::Sp);
                    // rotated about n (except at theta = 0, where psi is measured from
                    // the x axis), and through the public entry point
                    let phi = if i == 4 { 0.0 } else { 0.7 + i as f64 };
                    let got = t.eval_dirs(rotz(wi, phi), rotz(wo, phi));
                    let e = rel_diff(&got, &want);
                    assert!(e < 1e-10, "beta {beta} {frame:?} node ({j}, {i}): {e}");
                }
            }
        }
    }

    #[test]
    fn mirror_relation_holds_for_the_material() {
        let mat = material(
            Distribution::Beckmann { alpha: 0.3 },
            C64::new(0.2, 3.4),
            true,
            16,
        );
        let mut worst: f64 = 0.0;
        for beta in [0.01, 0.2, 1.0] {
            for theta in [0.0, 0.004, 0.3, 1.0, 1.3] {
                for psi in [0.3, 1.2, 2.0, 3.0] {
                    let (wi, wo) = table_dirs(beta, theta, psi);
                    let (wi2, wo2) = table_dirs(beta, theta, -psi);
                    // mirror image of the pair
                    assert!((wi2[1] + wi[1]).abs() < 1e-15 && (wi2[0] - wi[0]).abs() < 1e-15);
                    for frame in [TableFrame::Sp, TableFrame::Bisector] {
                        let to = |wi, wo| {
                            change_bases(
                                &super::super::eval(&mat, wi, wo, Frame::Sp),
                                beam_bases(Frame::Sp, wi, wo),
                                table_bases(frame, wi, wo),
                            )
                        };
                        let (m, m2) = (to(wi, wo), to(wi2, wo2));
                        if m[0][0] > 0.0 {
                            worst = worst.max(rel_diff(&mirror(&m), &m2));
                        }
                    }
                }
            }
        }
        assert!(worst < 1e-12, "{worst}");
    }

    #[test]
    fn table_coords_round_trip() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..2000 {
            let beta = 1.5 * rnd();
            let theta = FRAC_PI_2 * rnd();
            let psi = PI * (2.0 * rnd() - 1.0);
            let phi = 2.0 * PI * rnd();
            let (wi, wo) = table_dirs(beta, theta, psi);
            let (wi, wo) = (rotz(wi, phi), rotz(wo, phi));
            let (t, p, mirrored) = table_coords(beta, wi, wo);
            assert!((t - theta).abs() < 1e-12, "{theta} {t}");
            let p_signed = if mirrored { -p } else { p };
            assert!(
                (p_signed - psi).abs() < 1e-9 || theta < 1e-9,
                "{beta} {theta} {psi}: {p_signed}"
            );
            let (a, b) = table_dirs(beta, t, p_signed);
            let (a, b) = (rotz(a, phi), rotz(b, phi));
            for k in 0..3 {
                assert!((a[k] - wi[k]).abs() < 1e-9 && (b[k] - wo[k]).abs() < 1e-9);
            }
        }
        // theta = 0: psi is measured from the x axis (azimuth of b taken as 0)
        let (wi, wo) = table_dirs(0.2, 0.0, 1.0);
        let (t, p, m) = table_coords(0.2, wi, wo);
        assert!(t == 0.0 && (p - 1.0).abs() < 1e-12 && !m);
        // beta = 0
        let w = normalize([0.3, -0.2, 0.8]);
        let (t, p, m) = table_coords(0.0, w, w);
        assert!((t - 0.3f64.hypot(0.2).atan2(0.8)).abs() < 1e-14 && p == 0.0 && !m);
        let n = [0.0, 0.0, 1.0];
        assert_eq!(table_coords(0.0, n, n), (0.0, 0.0, false));
        assert_eq!(table_coords(0.1, n, n), (0.0, 0.0, false));
    }

    #[test]
    fn catmull_rom_matches_ztable() {
        let zt = ZTable {
            scale: 0.7,
            values: (0..=9)
                .map(|i| (i as f64 * 0.37).sin() + 0.1 * i as f64)
                .collect(),
        };
        let part = TablePart {
            scale: 0.7,
            cos_weighted: false,
            n_z: 9,
            n_psi: 0,
            data: zt
                .values
                .iter()
                .flat_map(|&v| {
                    let mut a = [0.0; 16];
                    a[0] = v;
                    a[5] = 0.1 * v;
                    a
                })
                .collect(),
        };
        for q in 0..=100 {
            let z = q as f64 / 100.0;
            let v = eval_part(&part, z, 0.0);
            assert!((v[0] - zt.eval_z_bounded(z)).abs() < 1e-15);
            assert!((v[5] - 0.1 * zt.eval_z(z)).abs() < 1e-15);
        }
    }

    #[test]
    fn interpolation_error_small_for_a_smooth_material() {
        let mat = material(
            Distribution::Beckmann { alpha: 0.5 },
            C64::new(1.5, 0.0),
            false,
            16,
        );
        let t = BrdfTable::build(&mat, 2f64.to_radians(), &BrdfTableOptions::default()).unwrap();
        let e = t.max_error(&mat, 85f64.to_radians(), DYNAMIC_RANGE);
        assert_eq!(e.parts.len(), 2);
        assert!(e.max < 1e-4, "{e:?}");
        let t = BrdfTable::build(&mat, 0.0, &BrdfTableOptions::default()).unwrap();
        let e = t.max_error(&mat, 85f64.to_radians(), DYNAMIC_RANGE);
        // measured 2.5e-5 (the multiple term; the single term 2.6e-7)
        assert!(e.max < 5e-5, "{e:?}");
    }

    #[test]
    fn bad_options_are_rejected() {
        let mat = material(
            Distribution::Beckmann { alpha: 0.5 },
            C64::new(1.5, 0.0),
            false,
            16,
        );
        let b = |beta: f64, o: BrdfTableOptions| BrdfTable::build(&mat, beta, &o).unwrap_err();
        assert!(b(-0.1, Default::default())
            .to_string()
            .contains("bistatic_angle"));
        assert!(b(FRAC_PI_2, Default::default())
            .to_string()
            .contains("bistatic_angle"));
        assert!(b(f64::NAN, Default::default())
            .to_string()
            .contains("bistatic_angle"));
        let o = BrdfTableOptions {
            single: PartOptions {
                n_z: Some(3),
                ..Default::default()
            },
            ..Default::default()
        };
        assert!(b(0.0, o).to_string().contains("n_z"));
        let o = BrdfTableOptions {
            single: PartOptions {
                n_psi: Some(1),
                ..Default::default()
            },
            ..Default::default()
        };
        assert!(b(0.1, o).to_string().contains("n_psi"));
        let o = BrdfTableOptions {
            lambertian: PartOptions {
                scale: Some(0.0),
                ..Default::default()
            },
            ..Default::default()
        };
        assert!(b(0.1, o).to_string().contains("scale_lambertian"));
        let o = BrdfTableOptions {
            double_order: Some(2),
            ..Default::default()
        };
        assert!(b(0.1, o).to_string().contains("double_order"));
    }

    /// Exploration: `TABLE_EXPLORE="dist alpha eta_re eta_im double beta_deg
    /// [n_z n_psi scale]x3 (single, lambertian, double; 0 = default) order frame; ..."`
    /// (frame: sp|bis).
    #[test]
    #[ignore]
    fn explore() {
        let spec = std::env::var("TABLE_EXPLORE").unwrap_or_default();
        for line in spec.split(';').filter(|l| !l.trim().is_empty()) {
            let f: Vec<&str> = line.split_whitespace().collect();
            let num = |i: usize| f[i].parse::<f64>().unwrap();
            let dist = match f[0] {
                "beckmann" => Distribution::Beckmann { alpha: num(1) },
                "ggx" => Distribution::Ggx { alpha: num(1) },
                _ => Distribution::BlinnPhong { m: num(1) },
            };
            let t0 = std::time::Instant::now();
            let mat = material(dist, C64::new(num(2), num(3)), f[4] == "1", 96);
            let tm = t0.elapsed().as_secs_f64();
            let opt = |x: f64| if x > 0.0 { Some(x) } else { None };
            let grid = |a: usize| PartOptions {
                n_z: opt(num(a)).map(|x| x as usize),
                n_psi: opt(num(a + 1)).map(|x| x as usize),
                scale: opt(num(a + 2)),
            };
            let opts = BrdfTableOptions {
                single: grid(6),
                lambertian: grid(9),
                double: grid(12),
                double_order: opt(num(15)).map(|x| x as usize),
                frame: Some(if f[16] == "sp" {
                    TableFrame::Sp
                } else {
                    TableFrame::Bisector
                }),
                in_shader: false,
            };
            let t0 = std::time::Instant::now();
            let t = BrdfTable::build(&mat, num(5).to_radians(), &opts).unwrap();
            let tb = t0.elapsed().as_secs_f64();
            let e = t.max_error(&mat, 85f64.to_radians(), DYNAMIC_RANGE);
            let parts: Vec<String> = e
                .parts
                .iter()
                .map(|p| {
                    format!(
                        "{} {:.2e}@(th {:.3}, psi {:.1}, k {})",
                        &p.kind[..3],
                        p.max,
                        p.theta.to_degrees(),
                        p.psi.to_degrees(),
                        p.element
                    )
                })
                .collect();
            println!(
                "{line} | mat {tm:.2}s build {tb:.3}s | {}",
                parts.join(" + ")
            );
        }
    }
}
