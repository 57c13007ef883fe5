//! Double bounce and coherent backscatter (PHYSICS.md section 5; seed eq. 12-17).
//!
//! # Model
//! Light arriving along `-wi` reflects off facet `h1` into `d = 2 (wi.h1) h1 - wi`, then off
//! a facet `h2 = normalize(wo - d)` toward `wo`. With the visible-normal density of the
//! first facet `P(wi) (wi.h1)+ D(h1) / cos_i`, the probability that the ray along `d` is
//! blocked (`1 - P(d)` if `d` points up, 1 if down), the density of the facet it hits,
//! `(u.h2)+ D(h2) / norm(u)` with `u = -d` (`norm(u) = cos_u + N(u)` if `u` points up and
//! `N(|u|)` if down, since `int (v.h)+ D = cos + N` and `int (-v.h)+ D = N`), the Jacobian
//! `d omega_o = 4 (u.h2) d omega_h2` and the escape probability `P(wo)`:
//!
//! `f2(wi, wo) = Q(wi) Q(wo) / 4  int d omega_h1  (wi.h1)+ D(h1) D(h2) T(d) M(h1, h2)`
//!
//! with `Q = P / cos` and `T(d) = 1 / (|d_z| + N(|d|))` in both cases (blocked fraction
//! over hit-density normalization: `(1 - P)/N = 1/(c + N)` going up, `1/(c + N)` going
//! down). `T(d) = T(-d)` and `(wi.h1) d omega_h1 = d omega_d / 4 = (wo.h2) d omega_h2`, so
//! the integrand is symmetric under reversing the path: **f2 is reciprocal by
//! construction**. The hit and escape probabilities are uncorrelated masking (the
//! `"uncorrelated"` P2; the seed's eq. 17 uses correlated visibilities and breaks this
//! symmetry, see docs/double-bounce.md). `M` is the Mueller matrix of the composed
//! polarization ray-tracing matrices `P2 P1` projected on the beam frames.
//!
//! At exact backscatter `h2 = normalize(wi - d)` is perpendicular to `h1` and both
//! reflections share one plane of incidence with `theta1 + theta2 = 90 deg` (seed eq. 14):
//! the Jones matrix is `diag(rs1 rs2, rp1 rp2)` in that plane's s/p basis (tested).
//!
//! # Quadrature
//! `h1` through the projected-area CDF of `D` in `w = sqrt(1 - u)` (as the albedo
//! integrator): `D(h1) d omega = 2 w dw dphi / (2 pi cos(theta_h1))`; Gauss-Legendre in
//! `w` between breakpoints (`order` points per segment) and in `phi` on panels between the
//! integrand's special azimuths (about `order` points in all, graded near grazing; see
//! [`double_marks`]).
//!
//! # Coherent backscatter
//! A double path and its reverse (through the same facets in the other order, intermediate
//! direction `-d`) add in amplitude. Near backscatter the reverse path's Jones matrix is
//! the reciprocal partner: in the sp frame at `wi = wo`, `J_rev = F J^T F`, `F = diag(-1, 1)`
//! (see `mueller::reciprocal`). The pair then contributes `M(J + e^{i Delta} J_rev)` instead
//! of `M(J) + M(J_rev)`; with `Delta = q . (r2 - r1)`, `q = (2 pi / lambda)(wo - wi)` and
//! lateral facet separations Gaussian with rms `l` (the surface correlation length) per
//! axis, `<cos Delta> = gamma = exp(-(|q_xy| l)^2 / 2)`. The enhancement added to `f2` is
//! `gamma / 2  int ... [M(J + J_rev) - M(J) - M(J_rev)]` (each pair is met twice over `d`);
//! for co-polarized light it equals the incoherent co-polarized double scatter at `beta = 0`
//! (factor 2) and vanishes for `gamma < 1e-6` (skipped). Its angular integral is of order
//! `(lambda / l)^2` and is left out of the energy bookkeeping.

use super::surface::Surface;
use crate::optics::frames::{beam_bases, dot, facet_sp_basis, neg, normalize, reflect, Frame, V3};
use crate::optics::fresnel::{fresnel_amplitudes, Eta, C64};
use crate::optics::mueller::{jones_to_mueller, Jones, Mat4};
use std::f64::consts::PI;

/// A complex 3-vector (a field).
pub(crate) type CV3 = [C64; 3];

/// Apply the polarization ray-tracing matrix of a reflection off facet `h` (incident
/// propagation `k_in`, reflected `k_out`) to the field `e`:
/// `rs s (s.e) + rp p_out (p_in.e)` on the basis of [`facet_sp_basis`] (`perp`: a unit
/// vector normal to `k_in`, used at normal incidence on the facet).
#[inline]
pub(crate) fn reflect_field(e: CV3, k_in: V3, k_out: V3, h: V3, rs: C64, rp: C64, perp: V3) -> CV3 {
    let (s, p_in, p_out) = facet_sp_basis(k_in, k_out, h, perp);
    let es = s[0] * e[0] + s[1] * e[1] + s[2] * e[2];
    let ep = p_in[0] * e[0] + p_in[1] * e[1] + p_in[2] * e[2];
    let (a, b) = (rs * es, rp * ep);
    [
        s[0] * a + p_out[0] * b,
        s[1] * a + p_out[1] * b,
        s[2] * a + p_out[2] * b,
    ]
}

/// Jones matrix (beam frames of `frame`) of the double reflection `-wi -> h1 -> d -> h2 -> wo`.
/// Returns `None` when the path does not exist (`h2` below the horizon or a facet seen from
/// behind).
pub fn double_jones(
    mat: &Surface,
    wi: V3,
    wo: V3,
    h1: V3,
    frame: Frame,
) -> Option<(Jones, V3, V3)> {
    double_jones_in(mat.spec.eta, wi, wo, h1, beam_bases(frame, wi, wo))
}

/// [`double_jones`] for index `eta` in the beam bases `(x_in, y_in, x_out, y_out)` (as
/// [`beam_bases`] returns them; `x_in` and `x_out` also serve as the reference vector at
/// normal incidence on a facet).
pub fn double_jones_in(
    eta: Eta,
    wi: V3,
    wo: V3,
    h1: V3,
    bases: (V3, V3, V3, V3),
) -> Option<(Jones, V3, V3)> {
    let wi_h1 = dot(wi, h1);
    if wi_h1 <= 0.0 || h1[2] <= 0.0 {
        return None;
    }
    let d = reflect(wi, h1, wi_h1);
    let hs = wo - d;
    let l2 = dot(hs, hs);
    if l2 <= 1e-300 {
        return None;
    }
    let h2 = normalize(hs);
    if h2[2] <= 0.0 {
        return None;
    }
    let c2 = dot(wo, h2);
    if c2 <= 0.0 {
        return None;
    }
    let (rs1, rp1) = fresnel_amplitudes(wi_h1.min(1.0), eta);
    let (rs2, rp2) = fresnel_amplitudes(c2.min(1.0), eta);
    let (x_in, y_in, x_out, y_out) = bases;
    let k_in = neg(wi);
    let mut j = [[C64::new(0.0, 0.0); 2]; 2];
    for (b, e_in) in [x_in, y_in].into_iter().enumerate() {
        let e0 = [
            C64::new(e_in[0], 0.0),
            C64::new(e_in[1], 0.0),
            C64::new(e_in[2], 0.0),
        ];
        let e1 = reflect_field(e0, k_in, d, h1, rs1, rp1, x_in);
        // at normal incidence on h2 the ray goes straight back (wo = -d), so x_out is normal to d
        let e2 = reflect_field(e1, d, wo, h2, rs2, rp2, x_out);
        for (a, ax) in [x_out, y_out].into_iter().enumerate() {
            j[a][b] = e2[0] * ax[0] + e2[1] * ax[1] + e2[2] * ax[2];
        }
    }
    Some((j, d, h2))
}

/// Smallest masking excess over the cosine, `N / c`, whose table value [`blocked_over_n`]
/// divides by; below, it takes the ratio of two excesses from their closed form.
const MIN_TABLE_EXCESS: f64 = 1e-8;

/// `(P(a) - P(a, b)) / (N(b) cos_a)` for `a`, `b` above the horizon: the probability that a
/// facet seen from `a` is blocked toward `b`, over the hit-density normalization `N(b)`, in
/// the material's correlated masking (seed eq. 6) or uncorrelated when `correlated` is
/// false. Written without cancellation: with `f` the correlation of the azimuths,
/// `= (1 - f) Q(a) / (c_b + N_b) + f max(0, 1 - rho) / ((c_a + N_a)(c_b + N_b))`,
/// `rho = c_b N_a / (c_a N_b) = Lambda(a) / Lambda(b)` from the masking's closed form in
/// logarithms where it has one ([`Surface::masking_ratio`]) when `N_b < 1e-8 c_b`: near
/// the normal both excesses vanish (below the table's resolution, or f64's) while `rho`
/// stays finite. Dropping the second part there, as a ratio of table values did, made the
/// escape after the second bounce of a smooth surface jump where the table reached 0
/// (`S(v)` from 0.73 to 0.87 at 29 deg for Beckmann alpha 0.2).
#[inline]
pub(crate) fn blocked_over_n(mat: &Surface, a: V3, b: V3, correlated: bool) -> f64 {
    let (ca, cb) = (a[2], b[2]);
    if ca <= 0.0 || cb < 0.0 {
        return 0.0;
    }
    let sa = (a[0] * a[0] + a[1] * a[1]).sqrt();
    let sb = (b[0] * b[0] + b[1] * b[1]).sqrt();
    let na = mat.masking_excess(ca, sa);
    let nb = mat.masking_excess(cb, sb);
    let f = if !correlated || mat.correlation == crate::microfacet::Correlation::None {
        0.0
    } else if sa > 0.0 && sb > 0.0 {
        mat.correlation
            .f_from_cos(((a[0] * b[0] + a[1] * b[1]) / (sa * sb)).clamp(-1.0, 1.0))
    } else {
        1.0
    };
    let first = (1.0 - f) / ((ca + na) * (cb + nb));
    if f <= 0.0 {
        return first;
    }
    // the table's excess is good to 1e-3 relative down to N = 1e-8 c (7e-4 measured for
    // Beckmann alpha 0.05-1) and reaches 0 near 1e-38 c: below, the closed form
    let closed = if nb > MIN_TABLE_EXCESS * cb {
        None
    } else {
        mat.masking_ratio(ca, sa, cb, sb)
    };
    let rho = match closed {
        Some(r) => r,
        None if nb > 0.0 => cb * na / (ca * nb),
        None => return first,
    };
    first + f * (1.0 - rho).max(0.0) / ((ca + na) * (cb + nb))
}

/// The path weight over `cos_i cos_o` of the double bounce with intermediate direction
/// `d` (module docs): `d` up: `(P_i - P(wi, d)) / N(d) * P_o`; `d` down: the mirror image
/// `P_i (P_o - P(wo, -d)) / N(-d)`; both over `cos_i cos_o`. Reciprocal: reversing the
/// path swaps the two forms.
#[inline]
fn path_weight(mat: &Surface, wi: V3, wo: V3, d: V3) -> f64 {
    let correlated = mat.spec.double_correlated;
    if d[2] >= 0.0 {
        blocked_over_n(mat, wi, d, correlated) * q_of(mat, wo)
    } else {
        q_of(mat, wi) * blocked_over_n(mat, wo, neg(d), correlated)
    }
}

/// `Q(k) = P(k) / cos = 1 / (cos + N)`.
#[inline]
pub(crate) fn q_of(mat: &Surface, k: V3) -> f64 {
    let c = k[2];
    let s = (k[0] * k[0] + k[1] * k[1]).sqrt();
    1.0 / (c + mat.masking_excess(c, s))
}

/// Coherent-backscatter decorrelation `gamma = exp(-(|q_xy| l)^2 / 2)`.
#[inline]
pub fn cbe_gamma(wavelength: f64, correlation_length: f64, wi: V3, wo: V3) -> f64 {
    let k = 2.0 * PI / wavelength;
    let qx = k * (wo[0] - wi[0]);
    let qy = k * (wo[1] - wi[1]);
    let x = (qx * qx + qy * qy) * correlation_length * correlation_length;
    (-0.5 * x).exp()
}

/// `M(J + J') - M(J) - M(J')`: the interference of two amplitudes.
#[inline]
pub(crate) fn interference(j: &Jones, jr: &Jones) -> Mat4 {
    let mut s = *j;
    for a in 0..2 {
        for b in 0..2 {
            s[a][b] += jr[a][b];
        }
    }
    let (m, m1, m2) = (
        jones_to_mueller(&s),
        jones_to_mueller(j),
        jones_to_mueller(jr),
    );
    let mut r = [[0.0; 4]; 4];
    for i in 0..4 {
        for k in 0..4 {
            r[i][k] = m[i][k] - m1[i][k] - m2[i][k];
        }
    }
    r
}

/// Breakpoints in `theta_h` (for a given azimuth of `h`) where a ray from direction `v`
/// reflected off `h` crosses the height `z` (`d_z = R cos(2 theta - delta)` with
/// `R = sqrt(s_v^2 cos^2 phi + c_v^2)`, `delta = atan2(s_v cos phi, c_v)`), and where
/// `v.h` changes sign; pushed into `out` when inside (0, pi/2).
fn push_breaks(v: V3, cos_phi: f64, sin_phi: f64, zs: &[f64], out: &mut Vec<f64>) {
    let s_v = v[0] * cos_phi + v[1] * sin_phi; // horizontal part of v along phi
    let c_v = v[2];
    let r = (s_v * s_v + c_v * c_v).sqrt();
    let delta = s_v.atan2(c_v);
    let inside = |t: f64, out: &mut Vec<f64>| {
        if t > 0.0 && t < 0.5 * PI {
            out.push(t);
        }
    };
    for &z in zs {
        if r > 0.0 && z.abs() < r {
            let a = (z / r).acos();
            for k in -2..=2 {
                let base = 2.0 * PI * k as f64;
                inside(0.5 * (delta + a + base), out);
                inside(0.5 * (delta - a + base), out);
            }
        }
    }
    // v.h = s_v sin(theta) + c_v cos(theta) = 0
    let t = (-c_v).atan2(s_v);
    for k in -1..=1 {
        inside(t + PI * k as f64, out);
    }
}

/// A special azimuth of the integrand over `h`: a panel end of the `phi` rule. `grade > 0`:
/// the integrand varies on the scale `grade` (radians) next to it, and panels of widths
/// `grade * 4^k` lead up to it from both sides; `soft`: the integrand's `theta`-integral
/// may behave like `sqrt(|phi - phi*|)` there (a cut of the integrand ending or turning
/// at this azimuth), and the panels touching it map `phi - phi* = L t^2` so that
/// Gauss-Legendre in `t` sees an analytic function.
#[derive(Debug, Clone, Copy)]
struct Mark {
    phi: f64,
    grade: f64,
    soft: bool,
}

impl Mark {
    fn plain(phi: f64) -> Self {
        Mark {
            phi,
            grade: 0.0,
            soft: false,
        }
    }
}

/// Nodes and weights `(phi, dphi)` over one turn with about `n` nodes: Gauss-Legendre on the
/// panels between the marks (graded and mapped as each mark asks). The first mark is the
/// origin of the turn.
fn phi_rule(n: usize, marks: &[Mark]) -> Vec<(f64, f64)> {
    let two_pi = 2.0 * PI;
    let origin = marks[0].phi;
    let mut ms: Vec<Mark> = marks
        .iter()
        .map(|m| Mark {
            phi: (m.phi - origin).rem_euclid(two_pi),
            ..*m
        })
        .collect();
    ms.sort_by(|a, b| a.phi.partial_cmp(&b.phi).unwrap());
    // merge marks closer than 1e-9
    let mut merged: Vec<Mark> = Vec::with_capacity(ms.len());
    for m in ms {
        let m = if two_pi - m.phi < 1e-9 {
            Mark { phi: 0.0, ..m }
        } else {
            m
        };
        if let Some(last) = merged
            .iter_mut()
            .find(|x: &&mut Mark| (x.phi - m.phi).abs() < 1e-9)
        {
            if m.grade > 0.0 && (last.grade == 0.0 || m.grade < last.grade) {
                last.grade = m.grade;
            }
            last.soft |= m.soft;
        } else {
            merged.push(m);
        }
    }
    merged.sort_by(|a, b| a.phi.partial_cmp(&b.phi).unwrap());
    // panels: (a, b, soft at a, soft at b, main)
    let mut panels: Vec<(f64, f64, bool, bool, bool)> = vec![];
    let ratio: f64 = 4.0;
    const MAX_LEVELS: i32 = 6;
    for (k, m) in merged.iter().enumerate() {
        let (next, b) = if k + 1 < merged.len() {
            (merged[k + 1], merged[k + 1].phi)
        } else {
            (merged[0], two_pi)
        };
        let a = m.phi;
        let mid = 0.5 * (a + b);
        // at most MAX_LEVELS graded panels per side (a tiny scale starts further out)
        let first = |g: f64| g.max(0.5 * (b - a) / ratio.powi(MAX_LEVELS));
        let mut left = vec![a];
        if m.grade > 0.0 {
            let mut w = first(m.grade);
            while a + w < mid {
                left.push(a + w);
                w *= ratio;
            }
        }
        let mut right = vec![b];
        if next.grade > 0.0 {
            let mut w = first(next.grade);
            while b - w > mid {
                right.push(b - w);
                w *= ratio;
            }
        }
        right.reverse();
        let main_index = left.len() - 1;
        let pts: Vec<f64> = left.into_iter().chain(right).collect();
        let np = pts.len() - 1;
        for i in 0..np {
            panels.push((
                pts[i],
                pts[i + 1],
                i == 0 && m.soft,
                i + 1 == np && next.soft,
                i == main_index,
            ));
        }
    }
    // nodes per graded panel: 12 from order 64 on (the defaults: DOUBLE_ORDER,
    // DOUBLE_TABLE_ORDER); fewer at the low orders of the renderer's and the monostatic
    // tables, whose build time they otherwise dominate (dozens of graded panels near grazing)
    let graded_n = if n >= 64 { 12 } else { (n / 8).max(4) };
    let n_graded = panels.iter().filter(|p| !p.4).count();
    let main_len: f64 = panels.iter().filter(|p| p.4).map(|p| p.1 - p.0).sum();
    let n_main = panels.len() - n_graded;
    // every main panel gets n/8 nodes (its ends may be singular), the rest by length
    let n_min = (n / 8).max(4);
    let rest = n.saturating_sub(n_graded * graded_n + n_main * n_min);
    let mut out = Vec::with_capacity(n + 8);
    for &(a, b, sa, sb, main) in &panels {
        let m = if main {
            n_min + (rest as f64 * (b - a) / main_len).round() as usize
        } else {
            graded_n
        };
        let rule = crate::quad::gauss_legendre(m);
        let l = b - a;
        for (&x, &w) in rule.x.iter().zip(&rule.w) {
            let (t, dt) = crate::quad::graded(x, sa, sb);
            out.push((origin + a + l * t, w * l * dt));
        }
    }
    out
}

/// Integrate over facet normals `h` distributed as `D(h) d omega_h`: `phi` by
/// Gauss-Legendre on the panels of [`phi_rule`] between the special azimuths `marks`, and
/// `theta_h` in `w = sqrt(1 - u)` by Gauss-Legendre on every segment between the
/// breakpoints `breaks(cos phi, sin phi)`, so that the kinks and cuts of the integrand fall
/// on segment ends. `f(h, weight)` accumulates; `weight` includes the measure
/// `D(h) d omega_h`.
fn integrate_h(
    mat: &Surface,
    order: usize,
    marks: &[Mark],
    breaks: &dyn Fn(f64, f64, &mut Vec<f64>),
    f: &mut dyn FnMut(V3, f64),
) {
    let (n_phi, n_w) = (order, order);
    let dist = mat.spec.distribution;
    let rule = crate::quad::gauss_legendre(n_w);
    let mut bps = Vec::with_capacity(16);
    let phis = phi_rule(n_phi, marks);
    for &(phi, dphi) in &phis {
        let (sp, cp) = phi.sin_cos();
        bps.clear();
        bps.push(0.0);
        bps.push(0.5 * PI);
        breaks(cp, sp, &mut bps);
        bps.sort_by(|a, b| a.partial_cmp(b).unwrap());
        for seg in bps.windows(2) {
            let (t0, t1) = (seg[0], seg[1]);
            if t1 - t0 < 1e-15 {
                continue;
            }
            let (s0, c0) = t0.sin_cos();
            let (s1, c1) = t1.sin_cos();
            // w decreases with theta
            let w_hi = dist.w_of(c0, s0 * s0);
            let w_lo = dist.w_of(c1.max(0.0), s1 * s1);
            let span = w_hi - w_lo;
            if span <= 0.0 {
                continue;
            }
            for (&xw, &ww) in rule.x.iter().zip(&rule.w) {
                let w = w_lo + span * xw;
                let (ch, s2h) = dist.sample_w(w);
                if ch <= 0.0 {
                    continue;
                }
                let sh = s2h.sqrt();
                // D d omega = 2 w dw dphi / (2 pi cos)
                let weight = ww * span * 2.0 * w / (2.0 * PI * ch) * dphi;
                f(V3::new(sh * cp, sh * sp, ch), weight);
            }
        }
    }
}

/// The special azimuths of the double-bounce integrand over `h1` (see [`Mark`]), found by
/// profiling the `theta`-integral against `phi` (examples/double_conv.rs):
/// - `phi0`, the azimuth of the point singularity `d = wo`: the profile has a kink there and
///   varies on the scale `min(cot theta_i, cot theta_o)` near grazing (graded). With
///   correlated masking (`correlated`) and `wo` near `wi`, also on the scale
///   `eps_bs = (angle(wi, wo) / 2) / sin(theta_hs)` (`hs = normalize(wi + wo)`): the
///   correlated blocking of the first bounce vanishes where `d = wi` (`h1 = wi`, the
///   azimuths of `wi` and `d` agree, seed eq. 6), and that zero lies `angle(wi, wo) / 2`
///   from the singular point, so the profile has a peak of about that width at `phi0`
///   (graded for `eps_bs > 1e-3`; narrower peaks carry too little to matter, 3e-6 of the
///   term at order 96 for 0.2 deg, and at exact backscatter the two points coincide on
///   the mark);
/// - `phi_i +- 90 deg`, where the cut `wi.h1 = 0` meets the horizon and the reach of `d_z`
///   is least: the profile varies on the scale `cot theta_i` (graded near grazing);
/// - the turning points of the cut `d_z = wo_z` (`h2` on the horizon, where GGX's `D(h2)`
///   jumps): `sqrt`-like profile (soft).
fn double_marks(wi: V3, wo: V3, phi0: f64, correlated: bool) -> Vec<Mark> {
    let s_i = (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
    let s_o = (wo[0] * wo[0] + wo[1] * wo[1]).sqrt();
    let (c_i, c_o) = (wi[2], wo[2]);
    // grading only where the scale is small against the panels
    let graded = |eps: f64| if eps < 0.25 { eps } else { 0.0 };
    let mut eps0 = (c_i / s_i.max(1e-300)).min(c_o / s_o.max(1e-300));
    if correlated {
        let sep = wi - wo;
        let half_angle = (0.5 * dot(sep, sep).sqrt()).min(1.0).asin();
        let hs = normalize(wi + wo);
        let s_h = (hs[0] * hs[0] + hs[1] * hs[1]).sqrt();
        let eps_bs = half_angle / s_h.max(1e-300);
        if eps_bs > 1e-3 {
            eps0 = eps0.min(eps_bs);
        }
    }
    let mut marks = vec![
        Mark {
            phi: phi0,
            grade: graded(eps0),
            soft: true,
        },
        Mark::plain(phi0 + PI),
    ];
    if s_i > 1e-12 {
        let phi_i = wi[1].atan2(wi[0]);
        let grade = graded(c_i / s_i);
        for sgn in [-1.0, 1.0] {
            marks.push(Mark {
                phi: phi_i + sgn * 0.5 * PI,
                grade,
                soft: true,
            });
        }
        // turning points of d_z = wo_z: R = sqrt(s_v^2 + c_i^2) = wo_z (see `push_breaks`)
        if c_o > c_i {
            let x = (c_o * c_o - c_i * c_i).sqrt() / s_i;
            if x < 1.0 {
                let a = x.acos();
                for sgn in [-1.0, 1.0] {
                    marks.push(Mark {
                        phi: phi_i + sgn * a,
                        grade: 0.0,
                        soft: true,
                    });
                }
            }
        }
    }
    marks
}

/// The special azimuths of an integrand over `h` whose only cuts are `v.h = 0` and
/// `reflect(v, h)` crossing the horizon (the escape and albedo integrals): `phi_v` and
/// `phi_v + 180 deg` (panel ends), and `phi_v +- 90 deg`, where the cut `v.h = 0` meets
/// the horizon (soft, graded on `|cot theta_v|` near grazing, as in [`double_marks`]).
fn cut_marks(v: V3) -> Vec<Mark> {
    let p = v[1].atan2(v[0]);
    let s_v = (v[0] * v[0] + v[1] * v[1]).sqrt();
    let mut marks = vec![Mark::plain(p), Mark::plain(p + PI)];
    if s_v > 1e-12 {
        let eps = v[2].abs() / s_v;
        let grade = if eps < 0.25 { eps } else { 0.0 };
        for sgn in [-1.0, 1.0] {
            marks.push(Mark {
                phi: p + sgn * 0.5 * PI,
                grade,
                soft: true,
            });
        }
    }
    marks
}

/// The double-bounce Mueller BRDF (1/sr, no cosine), with the coherent-backscatter
/// enhancement when `cbe` is true, by an `order x order` quadrature over `h1` split where
/// `d` crosses the horizon, where `h2` would (d_z = wo_z) and where `wi.h1 = 0`.
pub fn eval_double(mat: &Surface, wi: V3, wo: V3, frame: Frame, order: usize, cbe: bool) -> Mat4 {
    let mut acc = [[0.0; 4]; 4];
    if wi[2] <= 0.0 || wo[2] <= 0.0 {
        return acc;
    }
    let gamma = if cbe {
        cbe_gamma(mat.spec.wavelength, mat.spec.correlation_length, wi, wo)
    } else {
        0.0
    };
    let use_cbe = gamma > 1e-6;
    let dist = mat.spec.distribution;
    let f = [-1.0, 1.0];
    // The singular point h1 = normalize(wi + wo) (d = wo): its polar angle is a breakpoint
    // for every phi (lines passing near it are resolved from both sides).
    let hs_full = normalize(wi + wo);
    let theta_s = hs_full[2].clamp(-1.0, 1.0).acos();
    let breaks = |cp: f64, sp: f64, out: &mut Vec<f64>| {
        push_breaks(wi, cp, sp, &[0.0, wo[2]], out);
        if theta_s > 0.0 && theta_s < 0.5 * PI {
            out.push(theta_s);
        }
    };
    let mut body = |h1: V3, wgt: f64| {
        let Some((j, d, h2)) = double_jones(mat, wi, wo, h1, frame) else {
            return;
        };
        let d2 = dist.d(h2[2], h2[0] * h2[0] + h2[1] * h2[1]);
        if d2 == 0.0 {
            return;
        }
        let weight = wgt * dot(wi, h1) * d2 * path_weight(mat, wi, wo, d);
        let m = jones_to_mueller(&j);
        for a in 0..4 {
            for b in 0..4 {
                acc[a][b] += weight * m[a][b];
            }
        }
        if use_cbe {
            // reverse path amplitude: J_rev = F J^T F (sp frame at backscatter)
            let jr = [
                [j[0][0] * (f[0] * f[0]), j[1][0] * (f[0] * f[1])],
                [j[0][1] * (f[1] * f[0]), j[1][1] * (f[1] * f[1])],
            ];
            let it = interference(&j, &jr);
            for a in 0..4 {
                for b in 0..4 {
                    acc[a][b] += 0.5 * gamma * weight * it[a][b];
                }
            }
        }
    };
    // The integrand has a point singularity where d = wo (h1 = normalize(wi + wo)): there
    // h2 = normalize(wo - d) has a direction-dependent limit. Its azimuth is phi0.
    let hs = [wi[0] + wo[0], wi[1] + wo[1]];
    let phi0 = if hs[0] * hs[0] + hs[1] * hs[1] > 1e-24 {
        hs[1].atan2(hs[0])
    } else {
        wi[1].atan2(wi[0])
    };
    let correlated =
        mat.spec.double_correlated && mat.correlation != crate::microfacet::Correlation::None;
    let marks = double_marks(wi, wo, phi0, correlated);
    integrate_h(mat, order, &marks, &breaks, &mut body);
    let scale = 0.25;
    for row in acc.iter_mut() {
        for x in row.iter_mut() {
            *x *= scale;
        }
    }
    acc
}

/// The escape after the second bounce, by the direction `v` the ray arrives from
/// (`d2 = reflect(v, h)`): for `v` below the horizon `S(v) = int (v.h)+ D(h) P(d2) d omega_h`;
/// for `v` above, `int (v.h)+ D(h) (P(d2) - P(d2, v)) / N(v) d omega_h` (the mirror form of
/// the path weight). With the unpolarized Fresnel reflectance when `fresnel`.
pub fn escape_after_bounce(mat: &Surface, v: V3, fresnel: bool, order: usize) -> f64 {
    let mut total = 0.0;
    let breaks = |cp: f64, sp: f64, out: &mut Vec<f64>| push_breaks(v, cp, sp, &[0.0], out);
    let mut body = |h: V3, wgt: f64| {
        let vh = dot(v, h);
        if vh <= 0.0 {
            return;
        }
        let d2 = reflect(v, h, vh);
        if d2[2] <= 0.0 {
            return;
        }
        // v down (the ray went up and was blocked): escape P(d2); v up (the ray went down):
        // the escape of a facet that was reached from above along -v, (P(d2) - P(d2, v)) / N(v).
        let p = if v[2] < 0.0 {
            d2[2] * q_of(mat, d2)
        } else {
            d2[2] * blocked_over_n(mat, d2, v, mat.spec.double_correlated)
        };
        let fr = if fresnel {
            crate::optics::fresnel::reflectance(vh.min(1.0), mat.spec.eta)
        } else {
            1.0
        };
        total += wgt * vh * p * fr;
    };
    integrate_h(mat, order, &cut_marks(v), &breaks, &mut body);
    total
}

/// Double-bounce directional albedo `E2(wi) = int (wi.h1)+ D(h1) w(d) S(-d) d omega_h1`,
/// `w = (P_i - P(wi, d)) / (N(d) cos_i)` for `d` up and `Q(wi)` for `d` down
/// (with the unpolarized Fresnel reflectance at both bounces when `fresnel`, an
/// approximation that ignores the polarization coupling of the two reflections), using
/// `s_of(-d)` for the inner integral.
pub fn double_albedo(
    mat: &Surface,
    wi: V3,
    fresnel: bool,
    order: usize,
    s_of: &dyn Fn(V3) -> f64,
) -> f64 {
    let mut total = 0.0;
    let breaks = |cp: f64, sp: f64, out: &mut Vec<f64>| push_breaks(wi, cp, sp, &[0.0], out);
    let mut body = |h1: V3, wgt: f64| {
        let wh = dot(wi, h1);
        if wh <= 0.0 {
            return;
        }
        let d = reflect(wi, h1, wh);
        let fr = if fresnel {
            crate::optics::fresnel::reflectance(wh.min(1.0), mat.spec.eta)
        } else {
            1.0
        };
        let w = if d[2] >= 0.0 {
            blocked_over_n(mat, wi, d, mat.spec.double_correlated)
        } else {
            q_of(mat, wi)
        };
        total += wgt * wh * w * s_of(neg(d)) * fr;
    };
    integrate_h(mat, order, &cut_marks(wi), &breaks, &mut body);
    total
}

/// [`eval_double`] in the sp frame (where the coherent-backscatter reverse amplitude is
/// derived), then expressed in `frame` by the Stokes rotations between the bases.
pub fn eval_double_framed(mat: &Surface, wi: V3, wo: V3, frame: Frame) -> Mat4 {
    let m = eval_double(
        mat,
        wi,
        wo,
        Frame::Sp,
        mat.spec.double_order,
        mat.spec.coherent_backscatter,
    );
    if frame == Frame::Sp {
        return m;
    }
    change_frame(&m, wi, wo, Frame::Sp, frame)
}

/// Express a Mueller matrix given in the beam frames `from` in the frames `to`.
pub fn change_frame(m: &Mat4, wi: V3, wo: V3, from: Frame, to: Frame) -> Mat4 {
    crate::optics::frames::change_bases(m, beam_bases(from, wi, wo), beam_bases(to, wi, wo))
}
