//! The BRDF as the sum of its terms: [`sum_terms`] (the Mueller BRDF, `crate::brdf::eval`)
//! and [`albedo`] (the total directional albedo), each dispatching on [`Term`] with a
//! `match` (pbrt's BxDF dispatch) over the material's enabled terms in the order of
//! [`Term::ALL`]. The top layer of the BRDF: it reads the terms ([`super::single`],
//! [`super::double`], [`super::albedo`](mod@super::albedo)) and the [`Material`] built on them.

use super::albedo::single_albedo;
use super::double::eval_double_framed;
use super::material::Material;
use super::orders::Part;
use super::single::single_term;
use super::spec::Term;
use crate::optics::frames::{Frame, V3};
use crate::optics::mueller::Mat4;

/// The BRDF Mueller matrix `f(wi, wo)` (1/sr, no cosine factor) of `mat`: the sum of its
/// enabled terms. `wi`, `wo` are unit vectors with `z >= 0`; a direction on the horizon
/// (`z == 0`) gives the zero matrix (the cross-section integrand `f cos` vanishes there).
pub fn sum_terms(mat: &Material, wi: V3, wo: V3, frame: Frame) -> Mat4 {
    sum_terms_except(mat, wi, wo, frame, None)
}

/// [`sum_terms`] without the term `skip` (if enabled): `Some(Term::Double)` is the BRDF a
/// surface met along an inter-reflection path is evaluated with ([`crate::render::paths`]:
/// the double bounce's quadrature per path vertex would cost more than the path).
pub fn sum_terms_except(mat: &Material, wi: V3, wo: V3, frame: Frame, skip: Option<Term>) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    let (ci, co) = (wi[2], wo[2]);
    if ci <= 0.0 || co <= 0.0 {
        return m;
    }
    let si = (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
    let so = (wo[0] * wo[0] + wo[1] * wo[1]).sqrt();
    let (zi, zo) = (mat.z_of(ci, si), mat.z_of(co, so));
    for term in mat.spec.terms.iter().filter(|&t| Some(t) != skip) {
        match term {
            // first in Term::ALL: it starts the sum (m is still zero; assigned, so that the
            // signs of its zeros are kept)
            Term::Single => m = single_term(mat, wi, wo, si, so, zi, zo, frame),
            Term::Double => add(&mut m, &double_term(mat, wi, wo, frame)),
            Term::Multiple => {
                if let Some(so) = &mat.surface_orders {
                    let rest = so.eval(Part::Rest, wi, wo, frame);
                    add(&mut m, &rest);
                    if mat.spec.coherent_backscatter {
                        let (wl, l) = (mat.spec.wavelength, mat.spec.correlation_length);
                        if let Some(c) = so.coherent(Part::Rest, wi, wo, frame, wl, l, rest[0][0]) {
                            add(&mut m, &c);
                        }
                    }
                }
                m[0][0] += mat.multiple_cz(ci, zi, co, zo)
            }
            Term::Diffuse => m[0][0] += mat.diffuse_z(ci, si, zi, co, so, zo),
        }
    }
    m
}

fn add(m: &mut Mat4, b: &Mat4) {
    for (row, r2) in m.iter_mut().zip(b.iter()) {
        for (x, y) in row.iter_mut().zip(r2.iter()) {
            *x += y;
        }
    }
}

/// The double term: the seed's quadrature ([`eval_double_framed`]), or with
/// `orders = Surface` the path bank's order 2 times `1 + gamma`, its coherent backscatter
/// (an order-2 backscatter path and its reverse have the same Jones matrix in
/// backscatter-aligned frames, so the pair's interference adds `gamma` times the
/// incoherent value in every element; `gamma(q)` the characteristic function of the
/// banked paths' separations, [`crate::brdf::bank::coherent`]). The orders beyond
/// (the multiple term's banked part) add `gamma R M00` there, `R` their interference
/// matrix at backscatter.
pub fn double_term(mat: &Material, wi: V3, wo: V3, frame: Frame) -> Mat4 {
    match &mat.surface_orders {
        None => eval_double_framed(mat, wi, wo, frame),
        Some(so) => {
            let mut m = so.eval(Part::Double, wi, wo, frame);
            if mat.spec.coherent_backscatter {
                let (wl, l) = (mat.spec.wavelength, mat.spec.correlation_length);
                let g = so.coherent_gamma(Part::Double, wi, wo, wl, l);
                m.iter_mut().flatten().for_each(|x| *x *= 1.0 + g);
            }
            m
        }
    }
}

/// Directional albedo of one term of `mat` for unpolarized light at incidence `(ci, si)`:
/// the single term by an `n x n` quadrature (with the real Fresnel, not the tables), the
/// double term by its quadrature over `h1` (order `min(n, 128)`) with the tabulated escape
/// `S`, the multiple and diffuse terms' hemispherical integrals, which are analytic.
fn term_albedo(mat: &Material, term: Term, ci: f64, si: f64, n: usize) -> f64 {
    match term {
        Term::Single => single_albedo(mat, ci, true, n),
        Term::Double => mat.double_albedo(V3::new(si, 0.0, ci), n.min(128)),
        Term::Multiple => {
            let rest = mat
                .surface_orders
                .as_ref()
                .map_or(0.0, |so| so.albedo(Part::Rest, true, ci));
            mat.depolarizing_albedo(ci, si).0 + rest
        }
        Term::Diffuse => mat.depolarizing_albedo(ci, si).1,
    }
}

/// Total directional albedo of `mat` for unpolarized light at incidence cosine `cos_i`:
/// the sum of its enabled terms' (`n` the quadrature order of the single and double terms).
pub fn albedo(mat: &Material, cos_i: f64, n: usize) -> f64 {
    let ci = cos_i.clamp(0.0, 1.0);
    let si = ((1.0 - ci) * (1.0 + ci)).sqrt();
    let [single, double, ms, d] = Term::ALL.map(|t| {
        if mat.spec.terms.contains(t) {
            term_albedo(mat, t, ci, si, n)
        } else {
            0.0
        }
    });
    single + double + ms + d
}
