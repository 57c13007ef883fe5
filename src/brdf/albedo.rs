//! Directional albedo `E(wi) = int f(wi, wo) cos(theta_o) d omega_o` by deterministic
//! quadrature over the half vector.
//!
//! With `h` drawn through the projected-area CDF `u(theta_h)` of `D` (so that
//! `D cos(theta_h) d omega_h = du dphi / 2 pi`) and `d omega_o = 4 (wi.h) d omega_h`:
//!
//! `E_single(wi) = 1/(2 pi) int int  F(wi.h) cos_o [G/(cos_i cos_o)] (wi.h) / cos(theta_h)  du dphi`
//!
//! integrated in `w = sqrt(1 - u)` (`du / cos = 2 w dw / cos`, smooth to the horizon), and
//! split where `theta_o = theta_i` (the branch switch of the correlated masking).
//!
//! The reflected direction leaves the upper hemisphere beyond
//! `theta_h = pi/4 + delta/2`, `delta = atan2(sin(theta_i) cos(phi_h), cos(theta_i))`
//! (from `wo.z = R cos(2 theta_h - delta)`), so for each `phi_h` node the `u` integral
//! runs over `[0, u(theta_b(phi))]` where the integrand is continuous: Gauss-Legendre of
//! order `n` in both variables converges without seeing the horizon as a jump.
//!
//! With the Fresnel factor and `0 < Re(eta^2) < 1` (an index below 1 with little
//! absorption), `F(wi.h)` has a (pseudo-)critical angle where `sin^2 = Re(eta^2)`: a kink
//! (`k = 0`) or a feature narrower than any rule. The `w` range is split there too (for
//! eta = 0.01, alpha = 0.1 the order-128 albedo erred by 4e-4 at normal incidence), and
//! the `phi` range where that curve turns (`R(phi) = cos theta_c`), with the panels' ends
//! there mapped by `phi = phi* + L t^2` (the `theta` integral varies like a root of
//! `phi - phi*` there; 6e-5 error for eta = 0.9 at order 128 without it).

use super::single::masking_over_cosines;
use super::surface::Surface;
use crate::optics::frames::{reflect, V3};
use crate::optics::fresnel::{reflectance, Eta};
use std::f64::consts::{FRAC_PI_4, PI};

/// Single-bounce albedo for incidence cosine `cos_i`, with the material's Fresnel
/// (unpolarized reflectance) or with `F = 1`, using an `n x n` rule.
pub fn single_albedo(mat: &Surface, cos_i: f64, fresnel: bool, n: usize) -> f64 {
    let ci = cos_i.clamp(0.0, 1.0);
    if ci <= 0.0 {
        return 0.0;
    }
    let si = ((1.0 - ci) * (1.0 + ci)).sqrt();
    let wi = V3::new(si, 0.0, ci);
    let dist = mat.spec.distribution;
    let rule = crate::quad::gauss_legendre(n);
    // cos of the facet incidence at the (pseudo-)critical angle, if there is one
    let crit = match mat.spec.eta {
        Eta::Complex(e) if fresnel => {
            let re = (e * e).re;
            (re > 0.0 && re < 1.0).then(|| (1.0 - re).sqrt())
        }
        _ => None,
    };
    let mut bps: Vec<f64> = Vec::with_capacity(6);
    // phi panels: [0, pi] split where R(phi) = sqrt(si^2 cos^2 phi + ci^2) = cc (soft ends)
    let mut marks: Vec<(f64, bool)> = vec![(0.0, false), (PI, false)];
    if let Some(cc) = crit {
        if si > 0.0 && cc > ci && cc < 1.0 {
            let x = ((cc * cc - ci * ci).sqrt() / si).min(1.0);
            for p in [x.acos(), (-x).acos()] {
                if p > 0.0 && p < PI {
                    marks.push((p, true));
                }
            }
        }
    }
    marks.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
    // a panel between two soft ends is split in the middle (the mapping would thin out the
    // nodes there)
    let mut i = 0;
    while i + 1 < marks.len() {
        if marks[i].1 && marks[i + 1].1 {
            marks.insert(i + 1, (0.5 * (marks[i].0 + marks[i + 1].0), false));
        }
        i += 1;
    }
    let mut phis: Vec<(f64, f64)> = Vec::with_capacity(marks.len() * n);
    for m in marks.windows(2) {
        let ((a, sa), (b, sb)) = (m[0], m[1]);
        for (&x, &w) in rule.x.iter().zip(&rule.w) {
            let (t, dt) = crate::quad::graded(x, sa, sb);
            // weights normalized to [0, pi] -> 1 (see the factor at the end)
            phis.push((a + (b - a) * t, w * dt * (b - a) / PI));
        }
    }
    let mut total = 0.0;
    for &(phi, wp) in &phis {
        let (sp, cp) = phi.sin_cos();
        let delta = (si * cp).atan2(ci);
        let theta_b = FRAC_PI_4 + 0.5 * delta;
        let (sb, cb) = theta_b.sin_cos();
        let wb = dist.w_of(cb, sb * sb);
        // The correlated masking switches branch (min(P_i, P_o)) where theta_o = theta_i,
        // i.e. R cos(2 theta_h - delta) = cos(theta_i): split the range there.
        let r = (si * si * cp * cp + ci * ci).sqrt();
        let theta_eq = (0.5 * (delta + (ci / r).clamp(-1.0, 1.0).acos())).min(theta_b);
        let (se, ce) = theta_eq.sin_cos();
        let weq = dist.w_of(ce, se * se).clamp(wb, 1.0);
        bps.clear();
        bps.extend([wb, weq, 1.0]);
        if let Some(cc) = crit {
            // wi.h = R cos(theta_h - delta) = cc
            if cc < r {
                let a = (cc / r).acos();
                for t in [delta - a, delta + a] {
                    if t > 0.0 && t < theta_b {
                        let (st, ct) = t.sin_cos();
                        bps.push(dist.w_of(ct, st * st).clamp(wb, 1.0));
                    }
                }
            }
        }
        bps.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let mut inner = 0.0;
        for seg in bps.windows(2) {
            let (lo, hi) = (seg[0], seg[1]);
            if hi <= lo {
                continue;
            }
            for (&xw, &ww) in rule.x.iter().zip(&rule.w) {
                let w = lo + (hi - lo) * xw;
                let (ch, s2h) = dist.sample_w(w);
                if ch <= 0.0 {
                    continue;
                }
                let sh = s2h.sqrt();
                let h = V3::new(sh * cp, sh * sp, ch);
                let wi_h = si * h[0] + ci * h[2];
                if wi_h <= 0.0 {
                    continue;
                }
                let wo = reflect(wi, h, wi_h);
                if wo[2] <= 0.0 {
                    continue;
                }
                let g = masking_over_cosines(mat, wi, wo);
                let f = if fresnel {
                    reflectance(wi_h, mat.spec.eta)
                } else {
                    1.0
                };
                // du / cos(theta_h) = 2 w dw / cos(theta_h)
                inner += ww * (hi - lo) * f * wo[2] * g * wi_h * 2.0 * w / ch;
            }
        }
        total += wp * inner;
    }
    // phi in [0, pi] covers half the circle (symmetry about the plane of incidence):
    // 1/(2 pi) * 2 * pi (phi Jacobian) = 1.
    total
}

#[cfg(test)]
mod tests {
    use crate::brdf::{albedo, Material, MaterialSpec, Terms};
    use crate::microfacet::{Distribution, Shadowing};
    use crate::optics::frames::V3;
    use crate::optics::fresnel::Eta;

    fn furnace(distribution: Distribution, shadowing: Shadowing) -> Material {
        Material::new(MaterialSpec {
            shadowing,
            ..MaterialSpec::new(distribution, Eta::PerfectConductor)
        })
        .unwrap()
    }

    #[test]
    fn white_furnace_with_double() {
        let spec = MaterialSpec {
            terms: Terms {
                single: true,
                double: true,
                multiple: true,
                diffuse: false,
            },
            ..MaterialSpec::new(Distribution::Beckmann { alpha: 0.5 }, Eta::PerfectConductor)
        };
        let mat = Material::new(spec).unwrap();
        for deg in [0.0f64, 45.0, 80.0] {
            let a = albedo(&mat, deg.to_radians().cos(), 128);
            assert!((a - 1.0).abs() < 1e-4, "{deg}: {a}");
        }
    }

    #[test]
    fn white_furnace() {
        // F = 1: single (quadrature, order 256) + multiple (analytic, tables) = 1.
        for (d, sh) in [
            (Distribution::BlinnPhong { m: 0.0 }, Shadowing::Aps),
            (Distribution::BlinnPhong { m: 1e3 }, Shadowing::Aps),
            (Distribution::Ggx { alpha: 0.5 }, Shadowing::Smith),
        ] {
            let mat = furnace(d, sh);
            for deg in [0.0f64, 45.0, 80.0, 89.9] {
                let a = albedo(&mat, deg.to_radians().cos(), 256);
                assert!((a - 1.0).abs() < 1e-4, "{d:?} {deg}: {a}");
            }
        }
    }

    #[test]
    fn reciprocity_of_the_scalar_part() {
        let mat = furnace(Distribution::Beckmann { alpha: 0.4 }, Shadowing::Aps);
        let wi = crate::optics::frames::normalize(V3::new(0.3, -0.2, 0.7));
        let wo = crate::optics::frames::normalize(V3::new(-0.6, 0.1, 0.3));
        let f = crate::optics::frames::Frame::Sp;
        let a = crate::brdf::eval(&mat, wi, wo, f);
        let b = crate::brdf::eval(&mat, wo, wi, f);
        let r = crate::optics::mueller::reciprocal(&a);
        for i in 0..4 {
            for j in 0..4 {
                assert!((b[i][j] - r[i][j]).abs() < 1e-12 * a[0][0]);
            }
        }
    }
}
