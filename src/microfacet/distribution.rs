//! Isotropic normal distributions: Blinn-Phong (exponent `m`), Beckmann and GGX (`alpha`).

use crate::{Error, Result};
use std::f64::consts::PI;

/// Largest Blinn-Phong exponent accepted (alpha about 1.4e-5).
pub const M_MAX: f64 = 1e10;
/// Range of the Beckmann/GGX roughness accepted.
pub const ALPHA_MIN: f64 = 1e-5;
pub const ALPHA_MAX: f64 = 10.0;

/// A normal distribution with its roughness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distribution {
    /// `D = (m + 2)/(2 pi) cos^m(theta_h)` (seed eq. 3 with `rho = <h.n> D`).
    BlinnPhong { m: f64 },
    /// `D = exp(-tan^2/alpha^2) / (pi alpha^2 cos^4)`.
    Beckmann { alpha: f64 },
    /// `D = alpha^2 / (pi cos^4 (alpha^2 + tan^2)^2)` (Trowbridge-Reitz).
    Ggx { alpha: f64 },
}

/// Blinn-Phong exponent to Beckmann roughness, `alpha = sqrt(2/(m+2))` (Walter et al. 2007).
pub fn blinn_to_beckmann(m: f64) -> f64 {
    (2.0 / (m + 2.0)).sqrt()
}

/// Beckmann roughness to Blinn-Phong exponent, `m = 2/alpha^2 - 2`.
pub fn beckmann_to_blinn(alpha: f64) -> f64 {
    2.0 / (alpha * alpha) - 2.0
}

impl Distribution {
    /// Build and validate. `name` is "blinn_phong" (with `m`), "beckmann" or "ggx" (with `alpha`).
    pub fn new(name: &str, m: Option<f64>, alpha: Option<f64>) -> Result<Self> {
        let d = match (name, m, alpha) {
            (_, Some(_), Some(_)) => {
                return Err(Error::param(
                    "m",
                    m.unwrap(),
                    "give either m or alpha, not both",
                ))
            }
            ("blinn_phong", Some(m), None) => Distribution::BlinnPhong { m },
            ("blinn_phong", None, Some(a)) => {
                check_blinn_alpha(a)?;
                Distribution::BlinnPhong {
                    m: beckmann_to_blinn(a).clamp(0.0, M_MAX),
                }
            }
            ("beckmann", None, Some(alpha)) => Distribution::Beckmann { alpha },
            ("beckmann", Some(m), None) => {
                check_m(m)?;
                Distribution::Beckmann {
                    alpha: blinn_to_beckmann(m),
                }
            }
            ("ggx", None, Some(alpha)) => Distribution::Ggx { alpha },
            ("ggx", Some(m), None) => {
                check_m(m)?;
                Distribution::Ggx {
                    alpha: blinn_to_beckmann(m),
                }
            }
            ("blinn_phong" | "beckmann" | "ggx", None, None) => {
                return Err(Error::param(
                    "m",
                    "None",
                    "give the roughness: m (Blinn-Phong exponent) or alpha",
                ))
            }
            _ => {
                return Err(Error::param(
                    "distribution",
                    format!("{name:?}"),
                    "expected \"blinn_phong\", \"beckmann\" or \"ggx\"",
                ))
            }
        };
        d.validate()?;
        Ok(d)
    }

    pub fn validate(&self) -> Result<()> {
        match *self {
            Distribution::BlinnPhong { m } => check_m(m),
            Distribution::Beckmann { alpha } | Distribution::Ggx { alpha } => check_alpha(alpha),
        }
    }

    /// Width parameter: `alpha`, or the Beckmann-equivalent `sqrt(2/(m+2))` for Blinn-Phong.
    pub fn scale(&self) -> f64 {
        match *self {
            Distribution::BlinnPhong { m } => blinn_to_beckmann(m),
            Distribution::Beckmann { alpha } | Distribution::Ggx { alpha } => alpha,
        }
    }

    /// Scale of the `z` coordinate of the per-material tables (masking, albedo, escape;
    /// see [`super::masking::ZTable`]): the width [`Self::scale`], capped at 1. Beyond
    /// `alpha = 1` the tabulated functions vary on angular scales of order 1 (and steepest
    /// near grazing), while `cot theta = s z / (1 - z)` with `s = alpha` would crowd the
    /// nodes near normal incidence: at `alpha = 10` the last 0.3 rad before grazing got 8 of
    /// 256 intervals and the white furnace erred by 1.2% (tests/test_extremes.py).
    pub fn table_scale(&self) -> f64 {
        self.scale().min(1.0)
    }

    /// `D(h)` from `cos(theta_h) > 0` and `sin^2(theta_h)` (passed separately so that both
    /// stay accurate near the pole and near the horizon). Zero for `cos <= 0`.
    #[inline]
    pub fn d(&self, cos_h: f64, sin2_h: f64) -> f64 {
        if cos_h <= 0.0 {
            return 0.0;
        }
        match *self {
            Distribution::BlinnPhong { m } => {
                if m == 0.0 {
                    return 1.0 / PI;
                }
                (m + 2.0) / (2.0 * PI) * (m * ln_cos(cos_h, sin2_h)).exp()
            }
            Distribution::Beckmann { alpha } => {
                let c2 = cos_h * cos_h;
                let tan2 = sin2_h / c2;
                let a2 = alpha * alpha;
                (-tan2 / a2).exp() / (PI * a2 * c2 * c2)
            }
            Distribution::Ggx { alpha } => {
                let a2 = alpha * alpha;
                let c2 = cos_h * cos_h;
                let t = a2 * c2 + sin2_h; // = c2 (a2 + tan2)
                a2 / (PI * t * t)
            }
        }
    }

    /// Inverse of the projected-area CDF in `theta_h`: for `u` in [0, 1) returns
    /// `(cos theta_h, sin^2 theta_h)` such that `D cos d omega = du dphi / (2 pi)`.
    #[inline]
    pub fn sample_theta(&self, u: f64) -> (f64, f64) {
        match *self {
            Distribution::BlinnPhong { m } => {
                // cos^(m+2) = 1 - u  (using 1-u keeps u = 0 at the pole)
                let l = (-u).ln_1p() / (m + 2.0);
                let cos2 = (2.0 * l).exp();
                (cos2.sqrt(), -(2.0 * l).exp_m1())
            }
            Distribution::Beckmann { alpha } => {
                let tan2 = -alpha * alpha * (-u).ln_1p();
                let cos2 = 1.0 / (1.0 + tan2);
                (cos2.sqrt(), tan2 * cos2)
            }
            Distribution::Ggx { alpha } => {
                let tan2 = alpha * alpha * u / (1.0 - u);
                let cos2 = 1.0 / (1.0 + tan2);
                (cos2.sqrt(), tan2 * cos2)
            }
        }
    }

    /// The projected-area CDF `u(theta_h)`, inverse of [`Self::sample_theta`].
    pub fn cdf_theta(&self, cos_h: f64, sin2_h: f64) -> f64 {
        match *self {
            Distribution::BlinnPhong { m } => -(0.5 * (m + 2.0) * (-sin2_h).ln_1p()).exp_m1(),
            Distribution::Beckmann { alpha } => {
                let tan2 = sin2_h / (cos_h * cos_h);
                -(-tan2 / (alpha * alpha)).exp_m1()
            }
            Distribution::Ggx { alpha } => {
                let a2 = alpha * alpha;
                let tan2 = sin2_h / (cos_h * cos_h);
                tan2 / (a2 + tan2)
            }
        }
    }

    /// Sampling in `w = sqrt(1 - u)` (`u` the projected-area CDF), which stays accurate
    /// where `u` rounds to 1 and makes `du / cos(theta_h) = 2 w dw / cos(theta_h)` smooth up
    /// to the horizon for every distribution. Returns `(cos theta_h, sin^2 theta_h)`.
    #[inline]
    pub fn sample_w(&self, w: f64) -> (f64, f64) {
        let w = w.clamp(0.0, 1.0);
        if w == 0.0 {
            return (0.0, 1.0);
        }
        match *self {
            Distribution::BlinnPhong { m } => {
                // cos^(m+2) = w^2
                let l = 2.0 * w.ln() / (m + 2.0); // ln cos
                ((l).exp(), -(2.0 * l).exp_m1())
            }
            Distribution::Beckmann { alpha } => {
                let tan2 = -2.0 * alpha * alpha * w.ln();
                let cos2 = 1.0 / (1.0 + tan2);
                (cos2.sqrt(), tan2 * cos2)
            }
            Distribution::Ggx { alpha } => {
                // w^2 = alpha^2 / (alpha^2 + tan^2)
                let a2 = alpha * alpha;
                let w2 = w * w;
                let tan2 = a2 * (1.0 - w2) / w2;
                let cos2 = w2 / (w2 + a2 * (1.0 - w2));
                let _ = tan2;
                (cos2.sqrt(), a2 * (1.0 - w2) / (w2 + a2 * (1.0 - w2)))
            }
        }
    }

    /// `w(theta_h) = sqrt(1 - u(theta_h))`, inverse of [`Self::sample_w`].
    #[inline]
    pub fn w_of(&self, cos_h: f64, sin2_h: f64) -> f64 {
        if cos_h <= 0.0 {
            return 0.0;
        }
        match *self {
            Distribution::BlinnPhong { m } => (0.5 * (m + 2.0) * ln_cos(cos_h, sin2_h)).exp(),
            Distribution::Beckmann { alpha } => {
                (-0.5 * sin2_h / (cos_h * cos_h * alpha * alpha)).exp()
            }
            Distribution::Ggx { alpha } => {
                let a2 = alpha * alpha;
                (a2 * cos_h * cos_h / (a2 * cos_h * cos_h + sin2_h)).sqrt()
            }
        }
    }

    /// `<h.n> = int rho cos d omega = 1 / int D d omega` (PHYSICS.md section 3).
    /// Exact for Blinn-Phong, `(m+1)/(m+2)`; otherwise `int_0^1 du / cos(theta_h(u))` by
    /// 96-point Gauss-Legendre after `u = 1 - s^2` (removes the GGX endpoint singularity).
    pub fn mean_cos(&self) -> f64 {
        if let Distribution::BlinnPhong { m } = *self {
            return (m + 1.0) / (m + 2.0);
        }
        let inv = crate::quad::integrate(96, 0.0, 1.0, |s| {
            let (c, _) = self.sample_theta(1.0 - s * s);
            2.0 * s / c
        });
        1.0 / inv
    }
}

/// `ln cos(theta)` from whichever of `cos`, `sin^2` carries the precision.
#[inline]
fn ln_cos(cos_t: f64, sin2_t: f64) -> f64 {
    if sin2_t < 0.5 {
        0.5 * (-sin2_t).ln_1p()
    } else {
        cos_t.ln()
    }
}

fn check_m(m: f64) -> Result<()> {
    if !(m.is_finite() && (0.0..=M_MAX).contains(&m)) {
        return Err(Error::param(
            "m",
            m,
            format!("Blinn-Phong exponent must be finite and in [0, {M_MAX:e}]"),
        ));
    }
    Ok(())
}

/// `alpha` given for Blinn-Phong: `m = 2/alpha^2 - 2` must be in [0, M_MAX], i.e. `alpha`
/// in [sqrt(2/(M_MAX + 2)), 1] (a Blinn-Phong lobe is never wider than `m = 0`).
fn check_blinn_alpha(alpha: f64) -> Result<()> {
    let lo = blinn_to_beckmann(M_MAX);
    // alpha = 1 (m = 0) exactly and the smallest alpha map inside [0, M_MAX] up to rounding,
    // which the clamp in `new` absorbs.
    if !(alpha.is_finite() && (lo * (1.0 - 1e-15)..=1.0).contains(&alpha)) {
        return Err(Error::param(
            "alpha",
            alpha,
            format!(
                "for distribution \"blinn_phong\" alpha = sqrt(2/(m+2)) must be finite and in [{lo:.6e}, 1] (m in [0, {M_MAX:e}])"
            ),
        ));
    }
    Ok(())
}

fn check_alpha(alpha: f64) -> Result<()> {
    if !(alpha.is_finite() && (ALPHA_MIN..=ALPHA_MAX).contains(&alpha)) {
        return Err(Error::param(
            "alpha",
            alpha,
            format!("roughness must be finite and in [{ALPHA_MIN:e}, {ALPHA_MAX}]"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dists() -> Vec<Distribution> {
        vec![
            Distribution::BlinnPhong { m: 0.0 },
            Distribution::BlinnPhong { m: 7.0 },
            Distribution::BlinnPhong { m: 1e4 },
            Distribution::Beckmann { alpha: 0.05 },
            Distribution::Beckmann { alpha: 0.8 },
            Distribution::Ggx { alpha: 0.05 },
            Distribution::Ggx { alpha: 0.6 },
        ]
    }

    #[test]
    fn projected_area_normalization() {
        // int D cos d omega = 1 by direct quadrature in theta (split near the peak).
        for d in dists() {
            let s = d.scale();
            let f = |t: f64| {
                let (st, ct) = t.sin_cos();
                2.0 * PI * d.d(ct, st * st) * ct * st
            };
            let mut total = 0.0;
            let mut a = 0.0;
            let mut w = s / 4.0;
            while a < PI / 2.0 {
                let b = (a + w).min(PI / 2.0);
                total += crate::quad::integrate(32, a, b, f);
                a = b;
                w *= 1.5;
            }
            assert!((total - 1.0).abs() < 1e-9, "{d:?}: {total}");
        }
    }

    #[test]
    fn cdf_inverts_sampling() {
        for d in dists() {
            for u in [1e-9, 0.01, 0.3, 0.9, 0.999] {
                let (c, s2) = d.sample_theta(u);
                assert!((c * c + s2 - 1.0).abs() < 1e-12);
                let back = d.cdf_theta(c, s2);
                assert!(
                    (back - u).abs() < 1e-9 * u.max(1e-3),
                    "{d:?} u={u} back={back}"
                );
            }
        }
    }

    #[test]
    fn w_sampling_inverts_and_matches_u() {
        for d in dists() {
            for w in [1e-12, 1e-3, 0.2, 0.7, 0.999999, 1.0] {
                let (c, s2) = d.sample_w(w);
                assert!((c * c + s2 - 1.0).abs() < 1e-12);
                assert!((d.w_of(c, s2) - w).abs() < 1e-9 * w, "{d:?} w={w}");
                if w > 1e-3 && w < 0.99 {
                    let (cu, _) = d.sample_theta(1.0 - w * w);
                    assert!((cu - c).abs() < 1e-9, "{d:?} w={w}");
                }
            }
        }
    }

    #[test]
    fn mean_cos_matches_direct_integral() {
        for d in dists() {
            let got = d.mean_cos();
            // 1 / int D d omega by the direct theta quadrature
            let f = |t: f64| {
                let (st, ct) = t.sin_cos();
                2.0 * PI * d.d(ct, st * st) * st
            };
            let mut inv = 0.0;
            let mut a = 0.0;
            let mut w = d.scale() / 4.0;
            while a < PI / 2.0 {
                let b = (a + w).min(PI / 2.0);
                inv += crate::quad::integrate(32, a, b, f);
                a = b;
                w *= 1.5;
            }
            assert!(
                (got * inv - 1.0).abs() < 1e-7,
                "{d:?}: {got} vs {}",
                1.0 / inv
            );
        }
    }
}
