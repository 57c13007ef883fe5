//! The monostatic double-bounce table: the double-bounce Mueller BRDF (with its coherent
//! backscatter) at backscatter as a function of the incidence angle only, in the
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

use crate::brdf::material::Material;
use crate::microfacet::masking::ZTable;
use crate::optics::frames::{Frame, V3};
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
                let w = V3::new(th.sin(), 0.0, th.cos());
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
                let w = V3::new(th.sin(), 0.0, th.cos());
                let want = double_only(mat, w);
                let total = crate::brdf::eval(mat, w, w, Frame::Sp)[0][0];
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

/// The double-bounce term alone (with coherent backscatter as configured) at backscatter:
/// the seed's quadrature or the path banks' order 2 ([`crate::brdf::terms::double_term`]).
fn double_only(mat: &Material, w: V3) -> Mat4 {
    crate::brdf::terms::double_term(mat, w, w, Frame::Sp)
}
