//! Stokes reference frames of the incident and reflected beams (see [`crate::optics`]).

/// A 3-vector: glam's `DVec3` (x, y, z).
///
/// The helpers below are glam's own operations (same arithmetic, in the same order, as the
/// hand-written array versions they replaced), except [`normalize`], which divides by the
/// length as before (glam's `normalize` multiplies by the reciprocal: different last bits).
pub type V3 = glam::DVec3;

#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a.dot(b)
}
#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    a.cross(b)
}
#[inline]
pub fn neg(a: V3) -> V3 {
    -a
}
#[inline]
pub fn norm(a: V3) -> f64 {
    a.length()
}
/// `a / |a|` (a division, not glam's multiplication by `1 / |a|`).
#[inline]
pub fn normalize(a: V3) -> V3 {
    a / a.length()
}

/// Mirror reflection of the direction `v` (pointing away from the surface) about the unit
/// normal `h`, given `v.h`: `2 (v.h) h - v`.
#[inline]
pub fn reflect(v: V3, h: V3, v_dot_h: f64) -> V3 {
    2.0 * v_dot_h * h - v
}

/// The s/p basis of a reflection off the facet `h` (`k_in`, `k_out` the propagation
/// directions): `s = normalize(k_in x h)`, `p_in = k_in x s`, `p_out = k_out x s`. When
/// `k_in` is along `h` (normal incidence on the facet) any `s` normal to `k_in` will do, as
/// the reflection does not depend on the choice there: `perp`, a unit vector normal to
/// `k_in` supplied by the caller, is used.
#[inline]
pub fn facet_sp_basis(k_in: V3, k_out: V3, h: V3, perp: V3) -> (V3, V3, V3) {
    let c = cross(k_in, h);
    let s = if dot(c, c) > 1e-24 {
        normalize(c)
    } else {
        perp
    };
    (s, cross(k_in, s), cross(k_out, s))
}

/// Which transverse bases the returned Mueller matrices refer to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// s/p bases of the planes (n, wi) and (n, wo); what a BRDF polarimeter measures.
    Sp,
    /// Mitsuba 3's `stokes_basis` of each propagation direction.
    Mitsuba,
}

impl std::str::FromStr for Frame {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        match s {
            "sp" => Ok(Frame::Sp),
            "mitsuba" => Ok(Frame::Mitsuba),
            _ => Err(crate::Error::param(
                "frame",
                format!("{s:?}"),
                "expected \"sp\" or \"mitsuba\"",
            )),
        }
    }
}

/// Mitsuba 3 / Duff et al. (2017) `coordinate_system(k).0`.
#[inline]
pub fn mitsuba_basis(k: V3) -> V3 {
    let sign = 1.0f64.copysign(k[2]);
    let a = -1.0 / (sign + k[2]);
    let b = k[0] * k[1] * a;
    V3::new(1.0 + sign * k[0] * k[0] * a, sign * b, -sign * k[0])
}

/// Squared horizontal length below which a direction counts as "along n" for the
/// `Sp` frame (its azimuth is then undefined to working precision).
const ALONG_N2: f64 = 1e-28;

/// Beam bases `(x_in, y_in, x_out, y_out)` for directions `wi`, `wo` (unit, z > 0).
#[inline]
pub fn beam_bases(frame: Frame, wi: V3, wo: V3) -> (V3, V3, V3, V3) {
    let k_in = neg(wi);
    let k_out = wo;
    let (x_in, x_out) = match frame {
        Frame::Mitsuba => (mitsuba_basis(k_in), mitsuba_basis(k_out)),
        Frame::Sp => {
            // Azimuth unit vectors of the two planes of incidence.
            let ri = wi[0] * wi[0] + wi[1] * wi[1];
            let ro = wo[0] * wo[0] + wo[1] * wo[1];
            let (ci, si) = if ri > ALONG_N2 {
                let l = ri.sqrt();
                (wi[0] / l, wi[1] / l)
            } else if ro > ALONG_N2 {
                let l = ro.sqrt();
                (wo[0] / l, wo[1] / l)
            } else {
                (1.0, 0.0)
            };
            let (co, so) = if ro > ALONG_N2 {
                let l = ro.sqrt();
                (wo[0] / l, wo[1] / l)
            } else {
                (ci, si)
            };
            // x_in = normalize(k_in x n) = e_phi(phi_i); x_out = normalize(k_out x n) = -e_phi(phi_o).
            (V3::new(-si, ci, 0.0), V3::new(so, -co, 0.0))
        }
    };
    (x_in, cross(k_in, x_in), x_out, cross(k_out, x_out))
}

/// Express `m`, given in the beam bases `from`, in the bases `to`.
pub fn change_bases(
    m: &crate::optics::mueller::Mat4,
    from: (V3, V3, V3, V3),
    to: (V3, V3, V3, V3),
) -> crate::optics::mueller::Mat4 {
    let (xi1, yi1, xo1, yo1) = from;
    let (xi2, yi2, xo2, yo2) = to;
    let c = |a: f64| crate::optics::fresnel::C64::new(a, 0.0);
    let jin = [
        [c(dot(xi1, xi2)), c(dot(xi1, yi2))],
        [c(dot(yi1, xi2)), c(dot(yi1, yi2))],
    ];
    let jout = [
        [c(dot(xo2, xo1)), c(dot(xo2, yo1))],
        [c(dot(yo2, xo1)), c(dot(yo2, yo1))],
    ];
    use crate::optics::mueller::{jones_to_mueller, matmul};
    let (min, mout) = (jones_to_mueller(&jin), jones_to_mueller(&jout));
    matmul(&mout, &matmul(m, &min))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bases_are_orthonormal_and_right_handed() {
        for frame in [Frame::Sp, Frame::Mitsuba] {
            for (wi, wo) in [
                (V3::new(0.3, 0.4, 0.866), V3::new(-0.5, 0.1, 0.86)),
                (V3::Z, V3::new(0.6, 0.0, 0.8)),
                (V3::Z, V3::Z),
            ] {
                let (wi, wo) = (normalize(wi), normalize(wo));
                let (xi, yi, xo, yo) = beam_bases(frame, wi, wo);
                for (x, y, k) in [(xi, yi, neg(wi)), (xo, yo, wo)] {
                    assert!((dot(x, x) - 1.0).abs() < 1e-14 && (dot(y, y) - 1.0).abs() < 1e-14);
                    assert!(
                        dot(x, k).abs() < 1e-14
                            && dot(y, k).abs() < 1e-14
                            && dot(x, y).abs() < 1e-14
                    );
                    let c = cross(x, y);
                    assert!((dot(c, k) - 1.0).abs() < 1e-14);
                }
            }
        }
    }

    #[test]
    fn sp_bases_coincide_for_specular_reflection() {
        let wi = normalize(V3::new(0.3, -0.4, 0.5));
        let wo = V3::new(-wi.x, -wi.y, wi.z);
        let (xi, _, xo, _) = beam_bases(Frame::Sp, wi, wo);
        for a in 0..3 {
            assert!((xi[a] - xo[a]).abs() < 1e-15);
        }
    }
}
