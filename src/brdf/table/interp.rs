//! Catmull-Rom interpolation of a table part: the rule in the docs of
//! [`BrdfTable`](super::BrdfTable), which the WGSL port `shaders/shared/table.wgsl` follows.

use super::coords::MIRROR_SIGN;
use super::grid::{cell, z_of};
use super::TablePart;
use crate::optics::mueller::Mat4;
use std::f64::consts::PI;

pub use crate::microfacet::masking::catmull_rom;

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
pub(super) fn eval_part_masked(p: &TablePart, z: f64, psi: f64, mask: u32) -> [f64; 16] {
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
pub(super) fn part_matrix(p: &TablePart, c: f64, s: f64, psi: f64, mask: u32) -> Mat4 {
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
