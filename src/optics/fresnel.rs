//! Fresnel reflection amplitudes for a complex index `eta = n + i k` (seed eq. 10-11,
//! sign convention of [`crate::optics`]).

pub use num_complex::Complex64 as C64;

/// Relative index of refraction of the reflecting medium (outside medium: vacuum/air).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Eta {
    /// `n + i k`, `n > 0`, `k >= 0`.
    Complex(C64),
    /// A perfect electric conductor: `rs = -1`, `rp = +1` at every angle (`F = 1`, the
    /// white-furnace material).
    PerfectConductor,
}

impl Eta {
    /// `eta = n + i k`.
    pub fn new(n: f64, k: f64) -> Self {
        Eta::Complex(C64::new(n, k))
    }
}

/// Complex amplitudes `(rs, rp)` for reflection at incidence cosine `cos_theta_i` in [0, 1].
///
/// Stable over the whole range: the numerators are rewritten without cancellation using
/// `c^2 + sin^2 = 1`,
/// `rs = (1 - eta^2) / (c + w)^2`, `rp = (eta^2 - 1)(c^2 (eta^2 + 1) - 1) / (eta^2 c + w)^2`,
/// with `eta^2 - 1 = (eta - 1)(eta + 1)`, so `eta` near 1 keeps full relative accuracy;
/// the principal square root keeps `Im w >= 0` for `k >= 0`. `eta = 1` at exact grazing
/// (0/0) returns 0, the value at every other angle.
#[inline]
pub fn fresnel_amplitudes(cos_theta_i: f64, eta: Eta) -> (C64, C64) {
    match eta {
        Eta::PerfectConductor => (C64::new(-1.0, 0.0), C64::new(1.0, 0.0)),
        Eta::Complex(eta) => {
            let c = cos_theta_i.clamp(0.0, 1.0);
            let eta2 = eta * eta;
            let eta2m1 = (eta - 1.0) * (eta + 1.0);
            // eta^2 - sin^2 = (eta^2 - 1) + c^2
            let w = csqrt(eta2m1 + c * c);
            let ds = c + w;
            let dp = eta2 * c + w;
            if ds == C64::new(0.0, 0.0) || dp == C64::new(0.0, 0.0) {
                return (C64::new(0.0, 0.0), C64::new(0.0, 0.0));
            }
            let mut rs = -eta2m1 / (ds * ds);
            // c^2 (eta^2 + 1) - 1 = c^2 eta^2 - sin^2: no cancellation where eta is small
            // (it cancelled to 1.5e-14 above 1 in |rp|^2 under total internal reflection,
            // eta = 0.014 at 0.125 rad: tests/test_extremes.py)
            let mut rp = eta2m1 * (c * c * eta2 - (1.0 - c) * (1.0 + c)) / (dp * dp);
            if eta.im == 0.0 && w.re == 0.0 {
                // total internal reflection of a real index: |rs| = |rp| = 1 exactly
                rs /= rs.norm();
                rp /= rp.norm();
            }
            (rs, rp)
        }
    }
}

/// Principal square root without trigonometry (Kahan's algebraic form): for
/// `z = a + ib`, `t = sqrt((|z| + |a|)/2)`; `sqrt z = (t, b/(2t))` for `a >= 0`, else
/// `(|b|/(2t), sign(b) t)`. `|z|` by `hypot` only when the squares could overflow.
#[inline]
pub fn csqrt(z: C64) -> C64 {
    let (a, b) = (z.re, z.im);
    if a == 0.0 && b == 0.0 {
        return C64::new(0.0, b);
    }
    let aa = a.abs();
    let r = if aa < 1e150 && b.abs() < 1e150 {
        (a * a + b * b).sqrt()
    } else {
        a.hypot(b)
    };
    let t = (0.5 * (r + aa)).sqrt();
    if a >= 0.0 {
        C64::new(t, b / (2.0 * t))
    } else {
        C64::new(b.abs() / (2.0 * t), t.copysign(b))
    }
}

/// Unpolarized reflectance `(|rs|^2 + |rp|^2) / 2`.
#[inline]
pub fn reflectance(cos_theta_i: f64, eta: Eta) -> f64 {
    let (rs, rp) = fresnel_amplitudes(cos_theta_i, eta);
    0.5 * (rs.norm_sqr() + rp.norm_sqr())
}

/// Hemispherical average `F_avg = 2 int_0^1 F(mu) mu dmu` (Kulla and Conty 2017), by
/// 64-point Gauss-Legendre on two panels (F is smooth; error below 1e-12 for the
/// materials in the tests).
pub fn average_reflectance(eta: Eta) -> f64 {
    if let Eta::PerfectConductor = eta {
        return 1.0;
    }
    let f = |mu: f64| 2.0 * reflectance(mu, eta) * mu;
    crate::quad::integrate(64, 0.0, 0.2, f) + crate::quad::integrate(64, 0.2, 1.0, f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_matches_closed_form() {
        for (n, k) in [
            (1.5, 0.0),
            (1.0 + 1e-6, 0.0),
            (0.2, 3.4),
            (1e3, 1e3),
            (2.5, 0.01),
        ] {
            let eta = C64::new(n, k);
            let r = ((eta - 1.0) / (eta + 1.0)).norm_sqr();
            let (rs, rp) = fresnel_amplitudes(1.0, Eta::Complex(eta));
            assert!((rs.norm_sqr() - r).abs() < 1e-14 * r.max(1e-300) + 1e-300);
            assert!((rp + rs).norm() < 1e-14, "rp = -rs at normal incidence");
        }
    }

    #[test]
    fn total_internal_reflection_is_lossless_and_never_above_one() {
        // hypothesis found |rp|^2 = 1 + 1.5e-14 at eta = 0.014, 0.125 rad (tests/test_extremes.py);
        // now within a few ulp of 1
        for n in [0.014061841145298952, 1e-3, 0.1, 0.5, 0.9, 0.999] {
            let crit = (1.0f64 - n * n).sqrt(); // cos of the critical angle
            for i in 0..=2000 {
                let c = i as f64 / 2000.0;
                let (rs, rp) = fresnel_amplitudes(c, Eta::new(n, 0.0));
                let (a, b) = (rs.norm_sqr(), rp.norm_sqr());
                assert!(
                    a <= 1.0 + 1e-15 && b <= 1.0 + 1e-15,
                    "n {n}, c {c}: {a} {b}"
                );
                if c < crit {
                    assert!(
                        (a - 1.0).abs() <= 1e-15 && (b - 1.0).abs() <= 1e-15,
                        "n {n}, c {c}: {a} {b}"
                    );
                }
            }
        }
    }

    #[test]
    fn matches_textbook_form_away_from_cancellation() {
        for (n, k) in [(1.5, 0.0), (0.2, 3.4), (2.5, 0.5), (1e3, 1e3)] {
            let eta = C64::new(n, k);
            for c in [1.0, 0.7, 0.3, 0.01] {
                let w = (eta * eta - (1.0 - c * c)).sqrt();
                let rs0 = (c - w) / (c + w);
                let rp0 = (eta * eta * c - w) / (eta * eta * c + w);
                let (rs, rp) = fresnel_amplitudes(c, Eta::Complex(eta));
                assert!((rs - rs0).norm() < 1e-13 && (rp - rp0).norm() < 1e-13);
            }
        }
    }

    #[test]
    fn csqrt_matches_principal_branch() {
        for (a, b) in [
            (1.0, 0.0),
            (-1.0, 0.0),
            (-1.0, 1e-300),
            (-2.39, 6.0),
            (3.0, -4.0),
            (-1e-8, 2e6),
            (1e200, 1e200),
            (0.0, 1.0),
        ] {
            let z = C64::new(a, b);
            let got = csqrt(z);
            let want = z.sqrt();
            assert!(
                (got - want).norm() <= 1e-15 * want.norm(),
                "{z}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn eta_near_one_keeps_relative_accuracy() {
        // R(0) = ((n-1)/(n+1))^2 to full precision for n = 1 + 1e-6.
        let n = 1.0 + 1e-6;
        let (rs, _) = fresnel_amplitudes(1.0, Eta::new(n, 0.0));
        let want = (n - 1.0) / (n + 1.0);
        assert!((rs.re + want).abs() < 1e-14 * want);
    }

    #[test]
    fn brewster_zero_of_rp() {
        let n: f64 = 1.5;
        let theta_b = n.atan();
        let (_, rp) = fresnel_amplitudes(theta_b.cos(), Eta::new(n, 0.0));
        assert!(rp.norm() < 1e-15);
    }

    #[test]
    fn grazing_is_total_and_finite() {
        for (n, k) in [(1.5, 0.0), (1.0 + 1e-6, 0.0), (0.2, 3.4), (1e3, 1e3)] {
            let (rs, rp) = fresnel_amplitudes(0.0, Eta::new(n, k));
            assert!((rs + 1.0).norm() < 1e-12 && (rp + 1.0).norm() < 1e-12);
            let (rs, rp) = fresnel_amplitudes(1e-7, Eta::new(n, k));
            assert!(rs.norm() <= 1.0 && rp.norm() <= 1.0);
        }
    }
}
