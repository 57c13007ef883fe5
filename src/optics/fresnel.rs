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
/// Stable over the whole range: `sin^2` is computed as `(1 - c)(1 + c)`, the principal
/// square root keeps `Im w >= 0` for `k >= 0`, and `|rs|, |rp| <= 1` for passive media.
#[inline]
pub fn fresnel_amplitudes(cos_theta_i: f64, eta: Eta) -> (C64, C64) {
    match eta {
        Eta::PerfectConductor => (C64::new(-1.0, 0.0), C64::new(1.0, 0.0)),
        Eta::Complex(eta) => {
            let c = cos_theta_i.clamp(0.0, 1.0);
            let sin2 = (1.0 - c) * (1.0 + c);
            let eta2 = eta * eta;
            let w = (eta2 - sin2).sqrt();
            let rs = (c - w) / (c + w);
            let eta2c = eta2 * c;
            let rp = (eta2c - w) / (eta2c + w);
            (rs, rp)
        }
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
