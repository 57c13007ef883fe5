//! The in-kernel parameter blocks: what the kernel needs to evaluate the single and the
//! multiple + diffuse terms per lookup instead of reading a table
//! ([`super::BrdfTableOptions::in_shader`]), their f64 twins and the words uploaded for
//! `add_single_in_kernel` and `add_depolarizing_in_kernel` (`shaders/shared/in_kernel.wgsl`).

use super::coords::{bisector_bases, table_dirs};
use super::grid::{default_grid, z_of, PartKind};
use crate::brdf::material::Material;
use crate::brdf::single::{masking_from_excess, single_mueller};
use crate::microfacet::masking::{ZTable, TABLE_NODES};
use crate::microfacet::{Correlation, Distribution, MaskingEval};
use crate::optics::frames::V3;
use crate::optics::fresnel::Eta;
use crate::optics::mueller::Mat4;
use rayon::prelude::*;
use std::f64::consts::PI;

/// The multiple and diffuse terms evaluated per lookup, without a 2D table: each is
/// `c (1 - E(theta_i)) (1 - E(theta_o))` (M00 only) with the material's own 1D albedo
/// table `E` (in its `z`, or `zeta` for the Fresnel-scaled ones) and `c` =
/// `F_ms / (pi (1 - E_avg))` or `rho_d / (pi (1 - E_avg))` (0 where `1 - E_avg <= 1e-14`,
/// as [`Material::multiple_z`]), so the value is the core's.
#[derive(Debug, Clone, PartialEq)]
pub struct DepolarizingParams {
    /// `s` of the material's `z` ([`Distribution::table_scale`]).
    pub table_scale: f64,
    /// `(E, c)` per enabled term.
    pub terms: Vec<(crate::brdf::material::AlbedoTable, f64)>,
}

impl DepolarizingParams {
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
        DepolarizingParams {
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

    /// The words the kernel reads (`add_depolarizing_in_kernel`, `shaders/shared/in_kernel.wgsl`):
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
    /// The masking's calibration `s` to a traced surface (`G s(theta_i) s(theta_o)`,
    /// [`crate::brdf::calibration::calibrate_masking`]), if any.
    pub calibration: Option<ZTable>,
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
            calibration: mat.calibration.clone(),
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
        let mut g = masking_from_excess(self.correlation, wi, wo, si, so, n(ci, si), n(co, so));
        if let Some(t) = &self.calibration {
            g *= t.eval(ci, si) * t.eval(co, so);
        }
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

    /// The words the kernel reads (`add_single_in_kernel`, `shaders/shared/in_kernel.wgsl`):
    /// `[0 (the kind; u32 bits), distribution (0 Blinn-Phong, 1 Beckmann, 2 GGX; u32
    /// bits), m or alpha, perfect conductor (u32 bits), n - 1, k, excess table scale,
    /// correlation (0 none, 1 seed, 2 APS; u32 bits), intervals of the excess table (u32
    /// bits), its n + 1 values, intervals of the calibration table (u32 bits; 0: none),
    /// its values (in the same `z`)]`. `n - 1` is rounded from f64, so that `eta` near 1 keeps its relative
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
        match &self.calibration {
            Some(t) => {
                debug_assert_eq!(t.scale, self.excess.scale);
                w.push(u((t.values.len() - 1) as u32));
                w.extend(t.values.iter().map(|&x| x as f32));
            }
            None => w.push(u(0)),
        }
        w
    }
}
