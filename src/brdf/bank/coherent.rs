//! Coherent backscatter of the path banks' orders (issue 24, item 3): the enhancement and
//! its angular width from the surface's own paths.
//!
//! # The term
//! A path of order `n >= 2` (hit points `r_1 .. r_n`) and its reverse (the same facets,
//! `r_n` first) add in amplitude; their phase difference is `Delta = q . rho`,
//! `q = (2 pi / lambda)(wo - wi)`, `rho = r_n - r_1` (3D). Each path tallies half of the
//! pair's interference, `I = 0.5 [M(J + e^{i Delta} J_rev) - M(J) - M(J_rev)]` (the
//! reference's tally, [`crate::reference`], module docs "Coherent backscatter"). With the
//! standard small-angle approximation (`J_rev` the one at exact backscatter, the bistatic
//! dependence in the phase only) the sum over the paths leaving near backscatter factors
//! into
//!
//! `C(wi, wo) = gamma(q) R(theta) M00(wi, wo)`,
//!
//! - `R(theta)` the interference at exact backscatter relative to the incoherent `M00` of
//!   the same paths (a 4x4 matrix in backscatter-aligned bases: `x_out = -x_in`,
//!   `y_out = y_in`, the `Sp` frame's at `wo = wi`). Order 2 is planar at backscatter, so
//!   `J_rev = J` and `R` is the paths' normalized Mueller matrix: the enhancement is 2x in
//!   every element. Orders 3+ are not: less than 2x in some channels.
//! - `gamma(q) = sum_p cos(q . rho_p) / P` over the `P` paths that have a reverse, the
//!   characteristic function of the separations (each path counted once, its intensity
//!   with `F = 1`: `gamma` is the surface's, the same for every material; the
//!   interference's own `M00` would be no weight, as it sums to about 0, or below, for
//!   orders 3+ at oblique incidence). It holds the separations' whole 3D
//!   distribution, where the double term's `exp(-(|q_xy| l)^2 / 2)` takes a Gaussian in the
//!   horizontal plane. Near backscatter `q` is transverse to `wi` (its component along `wi`
//!   is `O(beta^2)`, dropped), so only `rho`'s projection on that plane matters: at
//!   incidence `theta` its in-plane component `rho_a = rho . (cos theta, 0, -sin theta)` and
//!   `rho_y`, which carry the surface's heights at oblique incidence.
//!
//! # The table ([`CoherentTable`])
//! Per incidence node of the bank, from its paths within [`super::BACKSCATTER_CONE`] of
//! backscatter ([`super::PathBank::backscatter`]; the reverse path traced facet by facet with
//! the material's Fresnel, none where a facet faces away from it, as in the reference): `R`,
//! made reciprocal (`R = E R^T E`) and mirror-even, and `gamma` on a polar grid in
//! `u = l q` (`l` the height correlation length, so that the table serves any `l` and
//! `lambda`): `|u|` on [`N_U`] nodes [`DU`] apart, its angle `psi` from the in-plane axis on
//! [`N_PSI`] nodes over `[0, pi/2]` (`gamma` is even in `q`, and mirror-symmetric in
//! `u_y`, which the table imposes by averaging `rho_y` and `-rho_y`); isotropic at normal
//! incidence (averaged over `psi`). Zero beyond the last `|u|` node.
//!
//! # Evaluation ([`CoherentTable::eval`])
//! At the mean polar angle of `wi` and `wo` (linear between the incidence nodes), with `q`
//! resolved on the axes of the plane of their mean direction, and `R` in bases built from
//! that plane's normal: the term is then exactly reciprocal (`wi <-> wo` maps `q` to `-q`
//! and the bases onto the reciprocal ones), and smooth in both directions.

use super::{bounce, facet, THETA_STEP};
use super::{node_direction, path_jones, zero_mirror_odd, PathBank, E, MAX_ORDER, N_THETA};
use crate::brdf::double::interference;
use crate::optics::frames::{cross, dot, neg, normalize, V3};
use crate::optics::fresnel::Eta;
use crate::optics::mueller::{jones_to_mueller, Mat4};
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};
use std::ops::RangeInclusive;

/// Nodes in `|u| = l |q|` (0 to 24).
pub const N_U: usize = 97;
/// Spacing of the `|u|` nodes.
pub const DU: f64 = 0.25;
/// Nodes in the angle of `u` from the in-plane axis, over `[0, pi/2]`.
pub const N_PSI: usize = 13;

/// The coherent backscatter of a range of orders of one material (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct CoherentTable {
    /// Per incidence node: `R`, the interference at exact backscatter over the incoherent
    /// `M00` of the same paths (zeros where the node holds none).
    pub ratio: Vec<Mat4>,
    /// `gamma[(i * N_PSI + m) * N_U + j]`: node `i`, `psi = m pi / (2 (N_PSI - 1))`,
    /// `|u| = j DU`.
    pub gamma: Vec<f64>,
    /// Per incidence node: the paths used, and those whose reverse does not exist.
    pub paths: Vec<(u64, u64)>,
}

/// Beam bases `(x_in, y_in, x_out, y_out)`.
pub type Bases = (V3, V3, V3, V3);

/// Backscatter-aligned bases at `(wi, wo)` from the horizontal unit vector `e` normal to
/// their mean plane: `x_in` is `e` made transverse to `wi`, `x_out` is `-e` made transverse
/// to `wo` (`x_out = -x_in` at `wo = wi`, as the `Sp` frame there).
pub fn aligned_bases(e: V3, wi: V3, wo: V3) -> Bases {
    let x_in = normalize(e - dot(e, wi) * wi);
    let x_out = neg(normalize(e - dot(e, wo) * wo));
    (x_in, cross(neg(wi), x_in), x_out, cross(wo, x_out))
}

/// `(1 - w) a + w b`, element by element.
fn lerp(a: &Mat4, b: &Mat4, w: f64) -> Mat4 {
    std::array::from_fn(|r| std::array::from_fn(|c| (1.0 - w) * a[r][c] + w * b[r][c]))
}

/// Where light arriving along `-wi` leaves after the facets `hs`.
fn exit(wi: V3, hs: &[V3]) -> V3 {
    hs.iter().fold(neg(wi), |k, &h| bounce(k, h))
}

impl CoherentTable {
    /// The table of `bank`'s orders `orders` (within `2..=MAX_ORDER`) with index `eta`.
    pub fn build(bank: &PathBank, eta: Eta, orders: RangeInclusive<usize>) -> CoherentTable {
        Self::build_with(bank, eta, orders, None)
    }

    /// [`Self::build`], taking `gamma` from `gamma` when given (it depends on the bank and
    /// the orders alone, not on `eta`: [`Self::gamma`]) instead of computing it (most of
    /// the cost).
    pub fn build_with(
        bank: &PathBank,
        eta: Eta,
        orders: RangeInclusive<usize>,
        gamma: Option<&[f64]>,
    ) -> CoherentTable {
        let orders = (*orders.start()).max(2)..=(*orders.end()).min(MAX_ORDER);
        let with_gamma = gamma.is_none();
        let rows: Vec<(Mat4, Vec<f64>, (u64, u64))> = (0..N_THETA)
            .into_par_iter()
            .map(|i| node(bank, eta, orders.clone(), i, with_gamma))
            .collect();
        let mut t = CoherentTable {
            ratio: Vec::with_capacity(N_THETA),
            gamma: Vec::with_capacity(N_THETA * N_PSI * N_U),
            paths: Vec::with_capacity(N_THETA),
        };
        for (r, g, p) in rows {
            t.ratio.push(r);
            t.gamma.extend(g);
            t.paths.push(p);
        }
        if let Some(g) = gamma {
            assert_eq!(
                g.len(),
                N_THETA * N_PSI * N_U,
                "a gamma table of this layout"
            );
            t.gamma = g.to_vec();
        }
        t
    }

    /// The table at fraction `w` of the way from `self` to `other` (two roughness nodes),
    /// linearly.
    pub fn mix(&self, other: &CoherentTable, w: f64) -> CoherentTable {
        let lin = |a: f64, b: f64| (1.0 - w) * a + w * b;
        CoherentTable {
            ratio: self
                .ratio
                .iter()
                .zip(&other.ratio)
                .map(|(a, b)| lerp(a, b, w))
                .collect(),
            gamma: self
                .gamma
                .iter()
                .zip(&other.gamma)
                .map(|(&a, &b)| lin(a, b))
                .collect(),
            paths: self
                .paths
                .iter()
                .zip(&other.paths)
                .map(|(a, b)| (a.0 + b.0, a.1 + b.1))
                .collect(),
        }
    }

    /// `gamma` at incidence node `i` for `u` resolved on the node's axes (bilinear in
    /// `(psi, |u|)`).
    fn gamma_at(&self, i: usize, ua: f64, uy: f64) -> f64 {
        let r = ua.hypot(uy) / DU;
        if r.is_nan() || r >= (N_U - 1) as f64 {
            return 0.0;
        }
        let psi = uy.abs().atan2(ua.abs()) / (FRAC_PI_2 / (N_PSI - 1) as f64);
        let (j, m) = ((r as usize).min(N_U - 2), (psi as usize).min(N_PSI - 2));
        let (fr, fp) = (r - j as f64, psi - m as f64);
        let g = |m: usize, j: usize| self.gamma[(i * N_PSI + m) * N_U + j];
        let row = |m: usize| (1.0 - fr) * g(m, j) + fr * g(m, j + 1);
        (1.0 - fp) * row(m) + fp * row(m + 1)
    }

    /// `gamma(q)` and `R` at `(wi, wo)` (module docs, "Evaluation") for wavelength and
    /// height correlation length `l` (same unit), with the bases `R` is given in
    /// ([`aligned_bases`]); `None` where `gamma` is 0.
    pub fn eval(&self, wi: V3, wo: V3, wavelength: f64, l: f64) -> Option<(f64, Mat4, Bases)> {
        let theta = 0.5 * (wi[2].clamp(-1.0, 1.0).acos() + wo[2].clamp(-1.0, 1.0).acos());
        let t = (theta / THETA_STEP).clamp(0.0, (N_THETA - 1) as f64);
        let i = (t as usize).min(N_THETA - 2);
        let f = t - i as f64;
        let m = wi + wo;
        let h = m[0].hypot(m[1]);
        let (c, s) = if h > 1e-12 {
            (m[0] / h, m[1] / h)
        } else {
            (1.0, 0.0)
        };
        let (st, ct) = theta.sin_cos();
        let e_a = V3::new(ct * c, ct * s, -st);
        let e_y = V3::new(-s, c, 0.0);
        let q = (2.0 * PI * l / wavelength) * (wo - wi);
        let (ua, uy) = (dot(q, e_a), dot(q, e_y));
        let g = (1.0 - f) * self.gamma_at(i, ua, uy) + f * self.gamma_at(i + 1, ua, uy);
        if g == 0.0 {
            return None;
        }
        let (a, b) = (&self.ratio[i], &self.ratio[i + 1]);
        let r = lerp(a, b, f);
        Some((g, r, aligned_bases(e_y, wi, wo)))
    }
}

/// One incidence node's `R`, `gamma` and path counts.
fn node(
    bank: &PathBank,
    eta: Eta,
    orders: RangeInclusive<usize>,
    i: usize,
    with_gamma: bool,
) -> (Mat4, Vec<f64>, (u64, u64)) {
    let wi = node_direction(i);
    let e = V3::Y;
    let mut inter = [[0.0; 4]; 4];
    let mut m00 = 0.0;
    let mut gsum = vec![0.0; if with_gamma { N_PSI * N_U } else { 0 }];
    let mut wsum = 0.0;
    let (mut used, mut unpaired) = (0u64, 0u64);
    let mut hs = [V3::Z; MAX_ORDER];
    let mut hr = [V3::Z; MAX_ORDER];
    let (st, ct) = (i as f64 * THETA_STEP).sin_cos();
    let psi: Vec<(f64, f64)> = (0..N_PSI)
        .map(|m| (m as f64 * FRAC_PI_2 / (N_PSI - 1) as f64).sin_cos())
        .collect();
    for n in orders {
        for p in bank.backscatter_of(i, n) {
            for (h, s) in hs.iter_mut().zip(p[..2 * n].chunks_exact(2)) {
                *h = facet(s[0] as f64, s[1] as f64);
            }
            let wo = exit(wi, &hs[..n]);
            let Some(j) = path_jones(eta, wi, &hs[..n], aligned_bases(e, wi, wo)) else {
                continue;
            };
            used += 1;
            let m = jones_to_mueller(&j);
            m00 += m[0][0];
            for (a, b) in hr[..n].iter_mut().zip(hs[..n].iter().rev()) {
                *a = *b;
            }
            let kr = exit(wi, &hr[..n]);
            let Some(jr) = path_jones(eta, wi, &hr[..n], aligned_bases(e, wi, kr)) else {
                unpaired += 1;
                continue;
            };
            let x = interference(&j, &jr);
            for (a, b) in inter.iter_mut().flatten().zip(x.iter().flatten()) {
                *a += 0.5 * b;
            }
            if !with_gamma {
                continue;
            }
            // the characteristic function of rho's transverse part, by the Chebyshev
            // recurrence cos((j + 1) x) = 2 cos(x) cos(j x) - cos((j - 1) x); each path
            // once (its intensity with F = 1)
            let w = 1.0;
            let rho = &p[2 * n..];
            let ra = ct * rho[0] as f64 - st * rho[2] as f64;
            let ry = rho[1] as f64;
            wsum += w;
            for (k, &(sp, cp)) in psi.iter().enumerate() {
                let row = &mut gsum[k * N_U..(k + 1) * N_U];
                for x in [cp * ra + sp * ry, cp * ra - sp * ry] {
                    let c1 = (DU * x).cos();
                    let (mut prev, mut cur) = (c1, 1.0);
                    for g in row.iter_mut() {
                        *g += 0.5 * w * cur;
                        let next = 2.0 * c1 * cur - prev;
                        prev = cur;
                        cur = next;
                    }
                }
            }
        }
    }
    let mut ratio = [[0.0; 4]; 4];
    if m00 > 0.0 {
        for r in 0..4 {
            for c in 0..4 {
                // reciprocity with the mirror of the plane of incidence (the tables' node
                // symmetry, bank module docs): R = E R^T E at backscatter
                ratio[r][c] = 0.5 * (inter[r][c] + E[r] * E[c] * inter[c][r]) / m00;
            }
        }
        zero_mirror_odd(&mut ratio);
    }
    let mut gamma = vec![0.0; if with_gamma { N_PSI * N_U } else { 0 }];
    if wsum > 0.0 {
        for (g, s) in gamma.iter_mut().zip(&gsum) {
            *g = s / wsum;
        }
        if i == 0 {
            // isotropic at normal incidence
            for j in 0..N_U {
                let mean = (0..N_PSI).map(|m| gamma[m * N_U + j]).sum::<f64>() / N_PSI as f64;
                for m in 0..N_PSI {
                    gamma[m * N_U + j] = mean;
                }
            }
        }
    }
    (ratio, gamma, (used, unpaired))
}

#[cfg(test)]
mod tests;
