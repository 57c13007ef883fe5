//! Single-bounce term and the specular (flat-interface) Mueller matrix.

use super::surface::Surface;
use crate::optics::frames::{beam_bases, dot, facet_sp_basis, neg, normalize, Frame, V3};
use crate::optics::fresnel::{fresnel_amplitudes, C64};
use crate::optics::mueller::{jones_to_mueller, Jones, Mat4};

/// Jones matrix, in the beam frames `(x_in, y_in) -> (x_out, y_out)`, of a reflection off a
/// facet with normal `h` for the incident beam `k_in = -wi` (polarization ray tracing).
#[inline]
fn facet_jones(wi: V3, wo: V3, h: V3, rs: C64, rp: C64, bases: (V3, V3, V3, V3)) -> Jones {
    let (x_in, y_in, x_out, y_out) = bases;
    let (s, p_in, p_out) = facet_sp_basis(neg(wi), wo, h, x_in);
    let (sxi, syi) = (dot(s, x_in), dot(s, y_in));
    let (pxi, pyi) = (dot(p_in, x_in), dot(p_in, y_in));
    let (sxo, syo) = (dot(s, x_out), dot(s, y_out));
    let (pxo, pyo) = (dot(p_out, x_out), dot(p_out, y_out));
    [
        [
            rs * (sxo * sxi) + rp * (pxo * pxi),
            rs * (sxo * syi) + rp * (pxo * pyi),
        ],
        [
            rs * (syo * sxi) + rp * (pyo * pxi),
            rs * (syo * syi) + rp * (pyo * pyi),
        ],
    ]
}

/// Masking term `G(wi, wo) / (cos_i cos_o)` (seed eq. 6 with `P(k) = c/(c + N)`), written
/// with `Q = P/c = 1/(c + N)` so that it stays finite when one direction is grazing; times
/// `s(theta_i) s(theta_o)` when the masking is calibrated to a traced surface
/// ([`super::calibration::calibrate_masking`]).
#[inline]
pub fn masking_over_cosines(mat: &Surface, wi: V3, wo: V3) -> f64 {
    let si = (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
    let so = (wo[0] * wo[0] + wo[1] * wo[1]).sqrt();
    masking_over_cosines_z(
        mat,
        wi,
        wo,
        si,
        so,
        mat.z_of(wi[2], si),
        mat.z_of(wo[2], so),
    )
}

/// [`masking_over_cosines`] with the horizontal lengths and table coordinates given.
#[inline]
fn masking_over_cosines_z(
    mat: &Surface,
    wi: V3,
    wo: V3,
    si: f64,
    so: f64,
    zi: f64,
    zo: f64,
) -> f64 {
    let ni = mat.masking_excess_z(wi[2], si, zi);
    let no = mat.masking_excess_z(wo[2], so, zo);
    let g = masking_from_excess(mat.correlation, wi, wo, si, so, ni, no);
    match &mat.calibration {
        Some(s) => g * s.eval_z(zi) * s.eval_z(zo),
        None => g,
    }
}

/// `G(wi, wo) / (cos_i cos_o)` from the masking excesses `ni`, `no` of the two directions
/// (`P = c / (c + N)`) and the correlation `f(phi)` (seed eq. 6); `si`, `so` the
/// horizontal lengths of the local `wi`, `wo`.
#[inline]
pub(crate) fn masking_from_excess(
    correlation: crate::microfacet::Correlation,
    wi: V3,
    wo: V3,
    si: f64,
    so: f64,
    ni: f64,
    no: f64,
) -> f64 {
    let (ci, co) = (wi[2], wo[2]);
    let qi = 1.0 / (ci + ni);
    let qo = 1.0 / (co + no);
    let f = if correlation == crate::microfacet::Correlation::None {
        0.0
    } else if si > 0.0 && so > 0.0 {
        let cos_phi = ((wi[0] * wo[0] + wi[1] * wo[1]) / (si * so)).clamp(-1.0, 1.0);
        correlation.f_from_cos(cos_phi)
    } else {
        // An azimuth is undefined along n, where P = 1 and both forms agree.
        1.0
    };
    let uncorrelated = qi * qo;
    if f == 0.0 {
        return uncorrelated;
    }
    // min(P_i, P_o) / (c_i c_o)
    let (pi, po) = (ci * qi, co * qo);
    let min_term = if pi <= po { qi / co } else { qo / ci };
    (1.0 - f) * uncorrelated + f * min_term
}

/// The single-bounce Mueller BRDF `D G F / (4 cos_i cos_o)` for local `wi`, `wo` above the
/// surface, `g = G / (cos_i cos_o)` given, in the beam `bases` `(x_in, y_in, x_out, y_out)`.
#[inline]
pub(crate) fn single_mueller(
    dist: &crate::microfacet::Distribution,
    eta: crate::optics::fresnel::Eta,
    wi: V3,
    wo: V3,
    g: f64,
    bases: (V3, V3, V3, V3),
) -> Mat4 {
    let h = normalize(wi + wo);
    let d = dist.d(h[2], h[0] * h[0] + h[1] * h[1]);
    if d.is_nan() || d <= 0.0 {
        return [[0.0; 4]; 4];
    }
    let scale = 0.25 * d * g;
    let (rs, rp) = fresnel_amplitudes(dot(wi, h).clamp(0.0, 1.0), eta);
    let mut m = jones_to_mueller(&facet_jones(wi, wo, h, rs, rp, bases));
    m.iter_mut().flatten().for_each(|x| *x *= scale);
    m
}

/// The single term `D G F / (4 cos_i cos_o)` of `mat` for local `wi`, `wo` above the surface
/// (`si`, `so` their horizontal lengths, `zi`, `zo` their table coordinates), in the beam
/// frames of `frame`.
#[inline]
#[allow(clippy::too_many_arguments)]
pub(crate) fn single_term(
    mat: &Surface,
    wi: V3,
    wo: V3,
    si: f64,
    so: f64,
    zi: f64,
    zo: f64,
    frame: Frame,
) -> Mat4 {
    let g = masking_over_cosines_z(mat, wi, wo, si, so, zi, zo);
    let bases = beam_bases(frame, wi, wo);
    single_mueller(&mat.spec.distribution, mat.spec.eta, wi, wo, g, bases)
}

/// Mueller reflectance (dimensionless) of the flat interface for incidence `wi`, into the
/// mirror direction `wo = (-wi.x, -wi.y, wi.z)`: the `m -> inf` limit of the single term,
/// and what Mitsuba's smooth `conductor` returns as its sample weight.
pub fn specular(mat: &Surface, wi: V3, frame: Frame) -> Mat4 {
    let wo = V3::new(-wi[0], -wi[1], wi[2]);
    let h = V3::Z;
    let (rs, rp) = fresnel_amplitudes(wi[2].clamp(0.0, 1.0), mat.spec.eta);
    let bases = beam_bases(frame, wi, wo);
    jones_to_mueller(&facet_jones(wi, wo, h, rs, rp, bases))
}
