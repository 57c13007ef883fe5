//! Building a [`BrdfTable`]: the options and their defaults, and the nodes from the
//! material's own evaluation of each part.

use super::coords::{bisector_bases, table_dirs};
use super::grid::{default_grid, PartGrid, PartKind, MAX_NODES, MAX_TOTAL_NODES};
use super::params::{DepolarizingParams, SingleParams};
use super::{BrdfTable, TableFrame, TablePart};
use crate::brdf::material::Material;
use crate::microfacet::masking::ZTable;
use crate::optics::frames::{beam_bases, change_bases, Frame};
use crate::optics::mueller::Mat4;
use crate::{Error, Result};
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};

/// `ln M00` stored where `M00 <= 0` (a direction below the horizon, or a part that
/// vanishes there) or where `ln M00` would be lower; the normalized elements are 0 there.
/// `exp(LN_FLOOR)` underflows to 0 in f32.
pub const LN_FLOOR: f64 = -200.0;

/// Default quadrature order of the double bounce in the table.
pub const DEFAULT_DOUBLE_ORDER: usize = 48;

/// Default intervals in `z` of the double part of a material with the path banks' orders
/// (the multiple part gets 4 times as many; the seed's terms 32 and 256): the banks' tables
/// are piecewise linear on 2.5 deg nodes, and Catmull-Rom across their kinks needs the
/// finer grid (measured in docs/render-table.md).
pub const BANKED_N_Z: usize = 128;
/// Intervals in `psi` of the parts with the path banks' orders.
pub const BANKED_N_PSI: usize = 16;

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
    pub depolarizing: PartOptions,
    /// The double bounce's grid.
    pub double: PartOptions,
    /// Quadrature order of the double bounce in the table.
    pub double_order: Option<usize>,
    pub frame: Option<TableFrame>,
    /// Evaluate the single term ([`SingleParams`]) and the multiple + diffuse terms
    /// ([`DepolarizingParams`]) per lookup from the material's parameters and 1D tables (in
    /// the kernel: `add_single_in_kernel`, `add_depolarizing_in_kernel` in
    /// `shaders/shared/in_kernel.wgsl`) instead of tabulating them; the double bounce stays
    /// tabulated.
    pub in_shader: bool,
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
                PartKind::Depolarizing,
                &self.depolarizing,
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
            // the path banks' tables are piecewise linear on 2.5 deg nodes: their kinks
            // need finer grids than the seed's smooth terms (docs/render-table.md)
            let (dz, dpsi) = match kind {
                PartKind::Double(_) if mat.surface_orders.is_some() => (BANKED_N_Z, BANKED_N_PSI),
                PartKind::Depolarizing if banked_rest(mat) => (4 * BANKED_N_Z, BANKED_N_PSI),
                _ => (dz, dpsi),
            };
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

/// The material restricted to the terms of a part.
pub(super) fn part_material(mat: &Material, kind: PartKind) -> Material {
    let mut m = mat.clone();
    let t = &mut m.spec.terms;
    match kind {
        PartKind::Single => {
            t.double = false;
            t.multiple = false;
            t.diffuse = false;
        }
        PartKind::Depolarizing => {
            t.single = false;
            t.double = false;
        }
        PartKind::Double(_) => {}
    }
    m
}

/// The material's multiple term carries the path banks' orders beyond the enabled ones
/// ([`crate::brdf::spec::Orders::Surface`]): its part is polarized.
pub(super) fn banked_rest(mat: &Material) -> bool {
    mat.spec.terms.multiple && mat.surface_orders.is_some()
}

/// A part's value in the table frame at table coordinates (`mat` from [`part_material`]).
pub(super) fn part_reference(
    mat: &Material,
    kind: PartKind,
    frame: TableFrame,
    beta: f64,
    theta: f64,
    psi: f64,
) -> Mat4 {
    let (wi, wo) = table_dirs(beta, theta, psi);
    let m = match kind {
        PartKind::Single | PartKind::Depolarizing => crate::brdf::eval(mat, wi, wo, Frame::Sp),
        // the path banks' order 2 (a table lookup, with its coherent backscatter)
        PartKind::Double(_) if mat.surface_orders.is_some() => {
            crate::brdf::terms::double_term(mat, wi, wo, Frame::Sp)
        }
        PartKind::Double(order) => crate::brdf::double::eval_double(
            mat,
            wi,
            wo,
            Frame::Sp,
            order,
            mat.spec.coherent_backscatter,
        ),
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
        let mut depolarizing = None;
        for g in grids {
            if opts.in_shader {
                match g.kind {
                    PartKind::Single => {
                        single = Some(SingleParams::new(mat));
                        continue;
                    }
                    // the path banks' orders beyond the enabled ones are polarized and not
                    // separable in (theta_i, theta_o): with them the part stays tabulated
                    PartKind::Depolarizing if !banked_rest(mat) => {
                        depolarizing = Some(DepolarizingParams::new(mat));
                        continue;
                    }
                    PartKind::Depolarizing => {}
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
            depolarizing,
        })
    }
}
