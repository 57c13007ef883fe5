//! Table coordinates `(theta, psi)` of a pair of directions (the bisector `b`, the azimuth
//! `psi` of `wi - wo` about it; see [`BrdfTable`](super::BrdfTable)), their inverse, the
//! beam bases of the bisector frame, and the mirror relation
//! `M(theta, -psi) = D M(theta, psi) D`.

use super::TableFrame;
pub use crate::optics::frames::change_bases;
use crate::optics::frames::{beam_bases, cross, dot, neg, normalize, Frame, V3};
use crate::optics::mueller::Mat4;

/// Sign of element `k = 4 a + b` under the mirror `y -> -y`: `d_a d_b` with
/// `D = diag(1, 1, -1, -1)`, so `M(-psi) = D M(psi) D` element by element.
pub const MIRROR_SIGN: [f64; 16] = [
    1.0, 1.0, -1.0, -1.0, //
    1.0, 1.0, -1.0, -1.0, //
    -1.0, -1.0, 1.0, 1.0, //
    -1.0, -1.0, 1.0, 1.0,
];

/// The pair `(wi, wo)` of table coordinates `(theta, psi)` (azimuth of `b` = 0).
pub fn table_dirs(beta: f64, theta: f64, psi: f64) -> (V3, V3) {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    let (sb, cb) = (0.5 * beta).sin_cos();
    let b = V3::new(st, 0.0, ct);
    let t = V3::new(cp * ct, sp, -cp * st);
    let wi = cb * b + sb * t;
    let wo = cb * b - sb * t;
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
    (V3::new(b[2] * c, b[2] * s, -r), V3::new(-s, c, 0.0))
}

/// Table coordinates of local unit directions `wi`, `wo` (`z >= 0`): `(theta, psi,
/// mirrored)` with `psi` in `[0, pi]`; when `mirrored` the table value must be taken as
/// `D M D` (`D = diag(1, 1, -1, -1)`). `beta` is the table's bistatic angle: for
/// `beta = 0`, `psi = 0` (the matrix does not depend on it). At `theta = 0` the azimuth
/// of `b` is taken as 0.
pub fn table_coords(beta: f64, wi: V3, wo: V3) -> (f64, f64, bool) {
    let b = normalize(wi + wo);
    let r = (b[0] * b[0] + b[1] * b[1]).sqrt();
    let theta = r.atan2(b[2]);
    if beta == 0.0 {
        return (theta, 0.0, false);
    }
    let (et, ep) = bisector_axes(b);
    let d = wi - wo;
    let psi = dot(d, ep).atan2(dot(d, et));
    (theta, psi.abs(), psi < 0.0)
}

/// Beam bases `(x_in, y_in, x_out, y_out)` of [`TableFrame::Bisector`].
pub fn bisector_bases(wi: V3, wo: V3) -> (V3, V3, V3, V3) {
    let b = normalize(wi + wo);
    let (_, e) = bisector_axes(b);
    let proj = |w: V3| {
        let c = dot(e, w);
        normalize(e - c * w)
    };
    let (x_in, x_out) = (proj(wi), proj(wo));
    (x_in, cross(neg(wi), x_in), x_out, cross(wo, x_out))
}

/// Bases of `frame` for the pair.
pub(super) fn table_bases(frame: TableFrame, wi: V3, wo: V3) -> (V3, V3, V3, V3) {
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
