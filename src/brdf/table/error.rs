//! The interpolation error of a [`BrdfTable`] against the material's own evaluation.

use super::build::{part_material, part_reference};
use super::grid::PartKind;
use super::interp::part_matrix;
use super::BrdfTable;
use crate::brdf::material::Material;
use crate::microfacet::masking::ZTable;
use rayon::prelude::*;
use std::f64::consts::PI;

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
