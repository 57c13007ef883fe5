//! Per-material tables for the renderer.
//!
//! [`BrdfTable`] (below) tabulates the **total** Mueller BRDF for the GPU renderer, for
//! monostatic and small bistatic angles; its doc comment fixes the data layout and the
//! interpolation that the WGSL port follows, and `docs/render-table.md` has its measured
//! error and build time. [`MonostaticTable`] holds the double bounce alone at
//! backscatter.
//!
//! By job:
//! - [`grid`]: a part's grid (kinds, node counts, `z` scale, defaults and bounds);
//! - [`coords`]: the table coordinates of a pair of directions, the bisector frame, the
//!   mirror relation;
//! - [`interp`]: Catmull-Rom interpolation of a part;
//! - [`build`]: the build options and the nodes;
//! - [`params`]: the in-kernel parameter blocks (terms evaluated per lookup) and their
//!   GPU words;
//! - [`error`]: the interpolation error against the material;
//! - [`monostatic`]: the [`MonostaticTable`].
//!
//! Every public name is re-exported here (`crate::brdf::table::X`).

pub mod build;
pub mod coords;
pub mod error;
pub mod grid;
pub mod interp;
pub mod monostatic;
pub mod params;
#[cfg(test)]
mod tests;

pub use build::{BrdfTableOptions, PartOptions, DEFAULT_DOUBLE_ORDER, LN_FLOOR};
pub use coords::{bisector_bases, change_bases, mirror, table_coords, table_dirs, MIRROR_SIGN};
pub use error::{PartError, TableError, DYNAMIC_RANGE};
pub use grid::{cell, default_grid, z_of, PartGrid, PartKind, MAX_NODES, MAX_TOTAL_NODES};
pub use interp::{catmull_rom, catmull_rom_ends, eval_part};
pub use monostatic::MonostaticTable;
pub use params::{DepolarizingParams, SingleParams};

use crate::optics::frames::{beam_bases, Frame, V3};
use crate::optics::mueller::Mat4;
use coords::table_bases;
use interp::part_matrix;

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
/// exactly [`ZTable::eval_z`](crate::microfacet::masking::ZTable::eval_z). Then in `psi`
/// (when `n_psi > 0`): `y = psi n_psi / pi`,
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
    pub depolarizing: Option<DepolarizingParams>,
}

impl BrdfTable {
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
        if self.single.is_some() || self.depolarizing.is_some() {
            let (wi, wo) = table_dirs(self.beta, sin_t.atan2(cos_t), a);
            if let Some(single) = &self.single {
                let pm = single.eval(wi, wo, table_bases(self.frame, wi, wo));
                for k in 0..16 {
                    if k == 0 || (mask >> k) & 1 == 1 {
                        m[k / 4][k % 4] += pm[k / 4][k % 4];
                    }
                }
            }
            if let Some(l) = &self.depolarizing {
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
}
