//! Masking and shadowing.
//!
//! **APS masking** (seed eq. 6-7): `P(k) = <h.n> cos(theta_k) / <h.k>+` with
//! `<h.k>+ = int rho(h) max(0, h.k) d omega`. Integrating over the azimuth of `h` in closed
//! form (PHYSICS.md section 3, re-derived in `docs/masking.md`):
//!
//! `<h.k>+ = <h.n> (cos theta_k + N_D(theta_k))`,
//! `N_D = 2 int_{pi/2 - theta_k}^{pi/2} D(t) sin t  a g(b/a) dt`,
//! `a = sin t sin theta_k`, `b = cos t cos theta_k`, `g(u) = sqrt(1 - u^2) - u acos(u) >= 0`,
//!
//! so `P(k) = cos theta_k / (cos theta_k + N_D)`. `N_D` is computed without cancellation:
//! `1 - u = sin(t - t0) / (sin t sin theta_k)` exactly, `g` from `beta = acos(u)` by
//! `sin(beta) - beta cos(beta)` or its series, the endpoint `(t - t0)^{3/2}` behaviour
//! removed by `t = t0 + s^2`, and the integration range split into panels that grow
//! geometrically from `t0` on the distribution's width.
//!
//! **Smith** (Walter et al. 2007): `G1 = 1/(1 + Lambda(a))`, `a = 1/(alpha tan theta)`,
//! Beckmann `Lambda = (erf(a) - 1)/2 + exp(-a^2)/(2 a sqrt(pi))` ("exact") or Walter's
//! rational approximation (the one Mitsuba 3 uses), GGX
//! `Lambda = (sqrt(1 + 1/a^2) - 1)/2`. Blinn-Phong: the exact Smith function of its own
//! distribution, `Lambda = N_D / cos theta` (for any isotropic `D`,
//! `cos theta (1 + Lambda) = int (k.h)+ D d omega`, Heitz 2014 eq. 17, so the exact Smith
//! `G1` equals the APS `P(k)`), or with `smith_g1 = "walter"` Walter et al.'s recipe: the
//! Beckmann rational approximation with `alpha = sqrt(2/(m+2))`. That mapping is not
//! energy conserving for small `m` (the single-bounce white-furnace albedo reaches 1.34 at
//! grazing for m = 0, 1.03 at m = 10, 1 + 6e-6 at m = 20; tests/test_extremes.py); it was
//! the `"exact"` Blinn-Phong Smith as well before the extremes tests measured that.

use super::distribution::Distribution;
use crate::{Error, Result};
use std::f64::consts::{FRAC_PI_2, PI};
use std::str::FromStr;

/// The masking-shadowing model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shadowing {
    /// Ashikhmin-Premoze-Shirley `P(k)` (seed eq. 7) with a correlation `f(phi)` (eq. 6).
    Aps,
    /// Smith `G1(wi) G1(wo)`, optionally correlated by `f(phi)`.
    Smith,
    /// `P = 1` (no masking; not energy conserving near grazing).
    None,
}

/// The correlation `f(phi)` of seed eq. 6, `phi` the azimuth between `wi` and `wo`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Correlation {
    /// The seed's `f = cos(phi/2)`.
    Seed,
    /// `f = exp(-7.3 phi^2)` (as APS is often quoted).
    Aps,
    /// `f = 0`: the uncorrelated product `P(wi) P(wo)`.
    None,
}

/// Which evaluation of the APS `N_D` integral the BRDF uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskingEval {
    /// The quadrature at every call (the reference).
    Exact,
    /// A per-material table in `z`, interpolated (default; error measured in the tests).
    Table,
    /// The seed's closed-form approximation (eq. 19-23, see [`super::seed`]); Blinn-Phong only.
    Seed,
}

/// Smith G1 variant for Beckmann (and Blinn-Phong through the Beckmann mapping).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SmithG1 {
    Exact,
    /// Walter et al. 2007 eq. 27 rational approximation (< 0.35% error), as in Mitsuba 3.
    Walter,
}

macro_rules! parse_enum {
    ($t:ty, $param:literal, $($s:literal => $v:expr),+) => {
        impl FromStr for $t {
            type Err = Error;
            fn from_str(s: &str) -> Result<Self> {
                match s {
                    $($s => Ok($v),)+
                    _ => Err(Error::param($param, format!("{s:?}"),
                        concat!("expected one of:", $(" \"", $s, "\""),+))),
                }
            }
        }
    };
}
parse_enum!(Shadowing, "shadowing", "aps" => Shadowing::Aps, "smith" => Shadowing::Smith, "none" => Shadowing::None);
parse_enum!(Correlation, "correlation", "seed" => Correlation::Seed, "aps" => Correlation::Aps, "none" => Correlation::None);
parse_enum!(MaskingEval, "masking", "exact" => MaskingEval::Exact, "table" => MaskingEval::Table, "seed" => MaskingEval::Seed);
parse_enum!(SmithG1, "smith_g1", "exact" => SmithG1::Exact, "walter" => SmithG1::Walter);

impl Correlation {
    /// `f(phi)` from `cos(phi)`, `phi` in [0, pi] (no `acos` for the seed's form:
    /// `cos(phi/2) = sqrt((1 + cos phi)/2)`).
    #[inline]
    pub fn f_from_cos(&self, cos_phi: f64) -> f64 {
        match self {
            Correlation::Seed => (0.5 * (1.0 + cos_phi)).max(0.0).sqrt(),
            Correlation::Aps => self.f(cos_phi.clamp(-1.0, 1.0).acos()),
            Correlation::None => 0.0,
        }
    }

    /// `f(phi)` for `phi` in [0, pi].
    #[inline]
    pub fn f(&self, phi: f64) -> f64 {
        match self {
            Correlation::Seed => (0.5 * phi).cos().max(0.0),
            Correlation::Aps => (-7.3 * phi * phi).exp(),
            Correlation::None => 0.0,
        }
    }
}

/// `g(u) = sqrt(1 - u^2) - u acos(u)` from `1 - u` (given accurately), for u in [0, 1].
#[inline]
fn g_from_one_minus_u(one_minus_u: f64) -> f64 {
    let omu = one_minus_u.clamp(0.0, 1.0);
    // beta = acos(u) = 2 asin(sqrt((1-u)/2))
    let beta = 2.0 * (0.5 * omu).sqrt().asin();
    if beta < 0.5 {
        // sin b - b cos b = sum_n (-1)^(n+1) 2n b^(2n+1) / (2n+1)!; terms to n = 7 leave
        // a relative error below 1e-17 for b < 0.5, where the closed form would cancel.
        let b2 = beta * beta;
        let c = [
            1.0 / 3.0,
            -1.0 / 30.0,
            1.0 / 840.0,
            -1.0 / 45360.0,
            1.0 / 3991680.0,
            -1.0 / 518918400.0,
            1.0 / 93405312000.0,
        ];
        let mut acc = 0.0;
        for &cn in c.iter().rev() {
            acc = acc * b2 + cn;
        }
        beta * b2 * acc
    } else {
        let (s, c) = beta.sin_cos();
        s - beta * c
    }
}

/// `N_D` in closed form where the distribution has one: Beckmann and GGX, whose APS excess
/// is Smith's `cos theta Lambda` (module docs: `cos theta (1 + Lambda) = <h.k>+`), written
/// without the `0 * inf` of grazing incidence:
/// Beckmann `(alpha s exp(-a^2) / sqrt(pi) - c erfc(a)) / 2` with `a = c / (alpha s)`,
/// GGX `(sqrt(c^2 + alpha^2 s^2) - c) / 2`. `None` for Blinn-Phong (quadrature only).
/// Equal to [`aps_excess`]'s quadrature to 1e-15 (tested).
pub fn aps_excess_closed_form(dist: &Distribution, cos_t: f64, sin_t: f64) -> Option<f64> {
    let (c, s) = (cos_t.max(0.0), sin_t.max(0.0));
    match *dist {
        Distribution::Beckmann { alpha } => {
            let w = alpha * s;
            if w == 0.0 {
                return Some(0.0);
            }
            let a = c / w;
            Some((0.5 * (w * (-a * a).exp() / PI.sqrt() - c * libm::erfc(a))).max(0.0))
        }
        Distribution::Ggx { alpha } => {
            let w = alpha * s;
            Some((0.5 * ((c * c + w * w).sqrt() - c)).max(0.0))
        }
        Distribution::BlinnPhong { .. } => None,
    }
}

/// `ln Lambda` of Smith's masking function (the APS excess over the cosine,
/// [`aps_excess_closed_form`]) for a direction of cosine `cos_t` and sine `sin_t`, finite
/// wherever `Lambda > 0` even where `Lambda` underflows: Beckmann
/// `Lambda = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2`, `a = cot theta / alpha`, directly
/// below `a = 20` (the difference loses about `log10(2 a^2)` digits: 1e-13 at 20) and from
/// its asymptotic series `exp(-a^2) / (2 sqrt(pi) a) (1/(2a^2) - 3/(4a^4) + 15/(8a^6) -
/// 105/(16a^8) + ...)` beyond (truncation 2e-9 at 20); GGX
/// `Lambda = (sqrt(1 + 1/a^2) - 1) / 2` without cancellation. `-inf` along the normal
/// (`sin_t = 0`), None for Blinn-Phong (no closed form).
pub fn ln_lambda_closed_form(dist: &Distribution, cos_t: f64, sin_t: f64) -> Option<f64> {
    let (c, s) = (cos_t.max(0.0), sin_t.max(0.0));
    let alpha = match *dist {
        Distribution::Beckmann { alpha } | Distribution::Ggx { alpha } => alpha,
        Distribution::BlinnPhong { .. } => return None,
    };
    let w = alpha * s;
    if w == 0.0 {
        return Some(f64::NEG_INFINITY);
    }
    let a = c / w;
    Some(match *dist {
        Distribution::Beckmann { .. } => {
            if a < 20.0 {
                smith_lambda(dist, SmithG1::Exact, c, s * s).ln()
            } else {
                let x = 1.0 / (a * a);
                let series = x * (0.5 - x * (0.75 - x * (1.875 - x * 6.5625)));
                -a * a - (2.0 * PI.sqrt() * a).ln() + series.ln()
            }
        }
        _ => {
            let x = 1.0 / (a * a);
            (0.5 * x / ((1.0 + x).sqrt() + 1.0)).ln()
        }
    })
}

/// Exact `N_D(theta_k)` of the APS masking (module docs), `theta_k` in [0, pi/2].
pub fn aps_excess(dist: &Distribution, theta_k: f64) -> f64 {
    let theta_k = theta_k.clamp(0.0, FRAC_PI_2);
    if theta_k == 0.0 {
        return 0.0;
    }
    let t0 = FRAC_PI_2 - theta_k;
    let (sin_k, cos_k) = theta_k.sin_cos();
    let integrand = |t: f64, dt: f64| -> f64 {
        // dt = t - t0 >= 0, passed explicitly for accuracy.
        let (st, ct) = t.sin_cos();
        let a = st * sin_k;
        if a <= 0.0 {
            return 0.0;
        }
        let omu = dt.sin() / a;
        let d = dist.d(ct, st * st);
        if d == 0.0 {
            return 0.0;
        }
        let _ = cos_k;
        2.0 * d * st * a * g_from_one_minus_u(omu)
    };
    // Panels from t0: first width w0 on the distribution's scale, growing by 2.
    // The integrand's width near t0 is about min(s, s^2/t0) (Gaussian-like D of width s).
    let s = dist.scale();
    let w0 = (0.25 * s * (s / t0.max(1e-300)).min(1.0)).min(FRAC_PI_2);
    let mut total = 0.0;
    let mut lo = 0.0; // offset from t0
    let mut width = w0;
    let span = FRAC_PI_2 - t0;
    let mut first = true;
    while lo < span {
        let hi = (lo + width).min(span);
        let part = if first {
            // t = t0 + s^2 on the first panel removes the (t - t0)^{3/2} endpoint.
            let smax = hi.sqrt();
            crate::quad::integrate(QN, 0.0, smax, |s| {
                let dt = s * s;
                2.0 * s * integrand(t0 + dt, dt)
            })
        } else if hi >= span {
            // Last panel, ending at t = pi/2 where cos^m t ~ (pi/2 - t)^m is not smooth for
            // non-integer m: t = pi/2 - w y^4 turns it into y^(4m+3) dy.
            let w = span - lo;
            crate::quad::integrate(QN, 0.0, 1.0, |y| {
                let y2 = y * y;
                let v = w * y2 * y2; // pi/2 - t
                let dt = span - v;
                4.0 * w * y2 * y * integrand(t0 + dt, dt)
            })
        } else {
            crate::quad::integrate(QN, lo, hi, |dt| integrand(t0 + dt, dt))
        };
        total += part;
        if !first && part <= 1e-17 * total.max(1e-300) {
            break;
        }
        if !first && total == 0.0 && part == 0.0 {
            break;
        }
        first = false;
        lo = hi;
        width *= 2.0;
    }
    total
}

/// `<h.k>+` (seed eq. 18) by the exact route: `<h.n> (cos theta_k + N_D)`.
pub fn hk_plus(dist: &Distribution, theta_k: f64) -> f64 {
    dist.mean_cos() * (theta_k.cos().max(0.0) + aps_excess(dist, theta_k))
}

/// APS `P(k) = cos / (cos + N_D)`.
pub fn aps_p(dist: &Distribution, theta_k: f64) -> f64 {
    let c = theta_k.cos().max(0.0);
    let n = aps_excess(dist, theta_k);
    if c + n == 0.0 {
        0.0
    } else {
        c / (c + n)
    }
}

/// Smith `Lambda` for a direction with `cos theta`, `sin^2 theta`.
pub fn smith_lambda(dist: &Distribution, variant: SmithG1, cos_t: f64, sin2_t: f64) -> f64 {
    if sin2_t <= 0.0 {
        return 0.0;
    }
    if let (Distribution::BlinnPhong { .. }, SmithG1::Exact) = (dist, variant) {
        // The exact Smith function of the Blinn-Phong distribution (module docs).
        let c = cos_t.max(0.0);
        if c == 0.0 {
            return f64::INFINITY;
        }
        return aps_excess(dist, sin2_t.sqrt().atan2(c)) / c;
    }
    let alpha = dist.scale();
    let tan_t = sin2_t.sqrt() / cos_t.max(0.0);
    if !tan_t.is_finite() {
        return f64::INFINITY;
    }
    let a = 1.0 / (alpha * tan_t);
    match (dist, variant) {
        (Distribution::Ggx { .. }, _) => 0.5 * ((1.0 + 1.0 / (a * a)).sqrt() - 1.0),
        // libm's erfc (musl, < 1 ulp), not statrs 0.19's, whose 10-digit interval constants
        // put errors of ~1e-11 into Lambda for a in [0.5, 2.25] and steps at its interval
        // ends (tests/test_extremes.py; the same defect as in render/pulse.rs's norm_cdf)
        (_, SmithG1::Exact) => 0.5 * ((-a * a).exp() / (a * PI.sqrt()) - libm::erfc(a)).max(0.0),
        (_, SmithG1::Walter) => {
            if a >= 1.6 {
                0.0
            } else {
                let g1 = (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a);
                1.0 / g1 - 1.0
            }
        }
    }
}

/// Uniform-in-`z` table of a masking function of `theta`, with `cot theta = s z / (1 - z)`
/// (`s` the distribution's width): `z = 0` is grazing, `z = 1` normal incidence.
/// Cubic (Catmull-Rom) interpolation.
#[derive(Debug, Clone, PartialEq)]
pub struct ZTable {
    pub scale: f64,
    pub values: Vec<f64>,
}

impl ZTable {
    /// Tabulate `f(theta)` at `n + 1` nodes.
    pub fn build(scale: f64, n: usize, f: impl Fn(f64) -> f64 + Sync) -> Self {
        use rayon::prelude::*;
        let values = (0..=n)
            .into_par_iter()
            .map(|i| f(Self::theta_of_z(scale, i as f64 / n as f64)))
            .collect();
        ZTable { scale, values }
    }

    #[inline]
    pub fn theta_of_z(scale: f64, z: f64) -> f64 {
        (1.0 - z).atan2(scale * z)
    }

    /// `z` from `cos theta`, `sin theta`.
    #[inline]
    pub fn z_of(&self, cos_t: f64, sin_t: f64) -> f64 {
        // cot = s z/(1-z)  =>  z = cot / (s + cot) = cos / (s sin + cos)
        let den = self.scale * sin_t + cos_t;
        if den <= 0.0 {
            0.0
        } else {
            (cos_t / den).clamp(0.0, 1.0)
        }
    }

    #[inline]
    pub fn eval_z(&self, z: f64) -> f64 {
        let v = &self.values;
        let n = v.len() - 1;
        let x = z * n as f64;
        let i = (x as usize).min(n - 1); // x >= 0: truncation is floor
        let t = x - i as f64;
        let p1 = v[i];
        let p2 = v[i + 1];
        // Ghost nodes by quadratic extrapolation keep third order in the end intervals.
        let p0 = if i > 0 {
            v[i - 1]
        } else {
            3.0 * p1 - 3.0 * p2 + v[(i + 2).min(n)]
        };
        let p3 = if i + 2 <= n {
            v[i + 2]
        } else {
            3.0 * p2 - 3.0 * p1 + v[i.saturating_sub(1)]
        };
        catmull_rom(p0, p1, p2, p3, t)
    }

    #[inline]
    pub fn eval(&self, cos_t: f64, sin_t: f64) -> f64 {
        self.eval_z(self.z_of(cos_t, sin_t))
    }

    /// [`Self::eval_z`] clamped to the range of the two bracketing nodes (no overshoot:
    /// for data with jumps, such as a logarithm that falls to its floor).
    #[inline]
    pub fn eval_z_bounded(&self, z: f64) -> f64 {
        let n = self.values.len() - 1;
        let i = ((z * n as f64) as usize).min(n - 1);
        let (a, b) = (self.values[i], self.values[i + 1]);
        self.eval_z(z).clamp(a.min(b), a.max(b))
    }
}

/// Catmull-Rom cubic through `p1` (t = 0) and `p2` (t = 1) with neighbours `p0`, `p3`
/// (the interpolation of every table in the crate and of `shaders/shared/table.wgsl`).
#[inline]
pub fn catmull_rom(p0: f64, p1: f64, p2: f64, p3: f64, t: f64) -> f64 {
    let t2 = t * t;
    let t3 = t2 * t;
    0.5 * ((2.0 * p1)
        + (-p0 + p2) * t
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
        + (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * t3)
}

/// Catmull-Rom through the node values `v` at `u` in node units (`v[k]` at `u = k`), the
/// ends held (the neighbour beyond an end is the end), `u` clamped to the nodes.
#[inline]
pub fn catmull_rom_nodes(v: &[f64], u: f64) -> f64 {
    let n = v.len();
    let u = u.clamp(0.0, (n - 1) as f64);
    let i = (u as usize).min(n - 2) as isize;
    let p = |j: isize| v[j.clamp(0, n as isize - 1) as usize];
    catmull_rom(p(i - 1), p(i), p(i + 1), p(i + 2), u - i as f64)
}

/// Default node count of the per-material masking tables.
pub const TABLE_NODES: usize = 512;
/// Gauss-Legendre points per panel of the `N_D` quadrature. Measured: 64 gives relative
/// errors below 1e-11 at grazing for non-integer m down to 0.1 (24 gave 1e-7 at m = 0.5).
const QN: usize = 64;

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute-force `<h.k>+` by a 2D quadrature over (theta_h, phi_h), for checking the
    /// 1D reduction (no shared code with `aps_excess` beyond `D`).
    fn hk_plus_2d(dist: &Distribution, theta_k: f64) -> f64 {
        let k = [theta_k.sin(), 0.0, theta_k.cos()];
        let s = dist.scale();
        let mut total = 0.0;
        let mut a = 0.0;
        let mut w = s / 8.0;
        while a < FRAC_PI_2 {
            let b = (a + w).min(FRAC_PI_2);
            total += crate::quad::integrate(48, a, b, |t| {
                let (st, ct) = t.sin_cos();
                let d = dist.d(ct, st * st);
                // phi integral, split where h.k changes sign
                let inner = crate::quad::integrate(256, 0.0, PI, |p| {
                    let hk = st * p.cos() * k[0] + ct * k[2];
                    hk.max(0.0)
                });
                2.0 * d * st * inner
            });
            a = b;
            w *= 1.5;
        }
        total * dist.mean_cos()
    }

    #[test]
    fn one_d_reduction_matches_two_d_quadrature() {
        for dist in [
            Distribution::BlinnPhong { m: 0.0 },
            Distribution::BlinnPhong { m: 20.0 },
            Distribution::Beckmann { alpha: 0.3 },
            Distribution::Ggx { alpha: 0.5 },
        ] {
            for theta in [0.3, 1.0, 1.4, 1.55] {
                let exact = hk_plus(&dist, theta);
                let brute = hk_plus_2d(&dist, theta);
                // the 2D rule has a kink in phi: 2e-5 relative is its own accuracy
                assert!(
                    (exact - brute).abs() < 2e-5 * exact,
                    "{dist:?} {theta}: {exact} vs {brute}"
                );
            }
        }
    }

    #[test]
    fn grazing_value_for_non_integer_small_m() {
        // At theta_k = pi/2: <h.k>+ = (m+1)/pi int cos^m t sin^2 t ... closed form
        // <h.k>+(pi/2) = A(m+2)/pi ... checked against the Wallis integral:
        // int rho max(0, h.x) d omega = (m+1)/(2 pi) int cos^m sin^2 dt * 2 = A(m+2)(m+1)/pi / (m+1)
        for m in [0.1f64, 0.3, 0.5, 0.9, 1.5, 2.5] {
            let d = Distribution::BlinnPhong { m };
            let got = hk_plus(&d, FRAC_PI_2);
            let want = super::super::seed::wallis(m + 2.0) / PI;
            assert!((got / want - 1.0).abs() < 1e-11, "m={m}: {got} vs {want}");
        }
    }

    #[test]
    fn g_series_and_closed_form_agree() {
        for omu in [1e-7f64, 1e-6, 1e-5, 2e-6] {
            let beta = 2.0 * (0.5 * omu).sqrt().asin();
            let (s, c) = beta.sin_cos();
            let direct = s - beta * c;
            let series = g_from_one_minus_u(omu);
            assert!((direct - series).abs() <= 1e-6 * series, "{omu}");
        }
        // continuity at the switch
        let b: f64 = 0.5;
        let omu = 1.0 - b.cos();
        // Both branches at the switch point agree (the closed form is accurate there).
        let series = g_from_one_minus_u(omu * (1.0 - 1e-15));
        let (s, c) = b.sin_cos();
        let direct = s - b * c;
        assert!(
            (series - direct).abs() < 1e-14 * direct,
            "{}",
            series / direct - 1.0
        );
    }

    #[test]
    fn correlation_from_cos_matches_angle_form() {
        for c in [Correlation::Seed, Correlation::Aps, Correlation::None] {
            for phi in [0.0, 0.3, 1.0, 2.0, 3.0, PI] {
                assert!(
                    (c.f_from_cos(f64::cos(phi)) - c.f(phi)).abs() < 1e-7,
                    "{c:?} {phi}"
                );
            }
        }
    }

    #[test]
    fn aps_excess_closed_form_is_the_quadrature() {
        for dist in [
            Distribution::Beckmann { alpha: 0.01 },
            Distribution::Beckmann { alpha: 0.3 },
            Distribution::Beckmann { alpha: 1.0 },
            Distribution::Ggx { alpha: 0.05 },
            Distribution::Ggx { alpha: 2.0 },
        ] {
            let mut worst: f64 = 0.0;
            for i in 0..=400 {
                let th = FRAC_PI_2 * i as f64 / 400.0;
                let (s, c) = th.sin_cos();
                let closed = aps_excess_closed_form(&dist, c, s).unwrap();
                let quad = aps_excess(&dist, th);
                // relative to the masking denominator c + N, which is what P uses
                worst = worst.max((closed - quad).abs() / (c + quad));
            }
            // measured 2e-15 or less
            assert!(worst < 1e-12, "{dist:?}: {worst}");
            // grazing: finite, Beckmann alpha / (2 sqrt(pi)), GGX alpha / 2
            let g = aps_excess_closed_form(&dist, 0.0, 1.0).unwrap();
            let want = match dist {
                Distribution::Beckmann { alpha } => alpha / (2.0 * PI.sqrt()),
                Distribution::Ggx { alpha } => alpha / 2.0,
                _ => unreachable!(),
            };
            assert!(
                (g - want).abs() < 1e-15 * want.max(1.0),
                "{dist:?}: {g} vs {want}"
            );
        }
        assert!(aps_excess_closed_form(&Distribution::BlinnPhong { m: 10.0 }, 0.5, 0.8).is_none());
    }

    #[test]
    fn aps_p_limits() {
        let d = Distribution::BlinnPhong { m: 10.0 };
        assert_eq!(aps_p(&d, 0.0), 1.0);
        assert!(aps_p(&d, FRAC_PI_2) < 1e-15);
        let mut last = 1.0;
        for i in 0..=100 {
            let p = aps_p(&d, FRAC_PI_2 * i as f64 / 100.0);
            assert!(p <= last + 1e-15);
            last = p;
        }
    }

    #[test]
    fn table_matches_exact() {
        for dist in [
            Distribution::BlinnPhong { m: 0.0 },
            Distribution::BlinnPhong { m: 1e6 },
            Distribution::Beckmann { alpha: 0.1 },
            Distribution::Ggx { alpha: 0.5 },
        ] {
            // The BRDF tabulates N_D and forms P = c / (c + N_D).
            let table = ZTable::build(dist.scale(), TABLE_NODES, |t| aps_excess(&dist, t));
            let mut worst: f64 = 0.0;
            for i in 0..4999 {
                let z = (i as f64 + 0.37) / 4999.0;
                let th = ZTable::theta_of_z(dist.scale(), z);
                let c = th.cos();
                let p_tab = c / (c + table.eval(c, th.sin()).max(0.0));
                worst = worst.max((p_tab - aps_p(&dist, th)).abs());
            }
            // measured with 512 nodes: 2.4e-7 (m = 0) and below 1e-7 for the others
            assert!(worst < 5e-7, "{dist:?}: table error {worst}");
        }
    }

    #[test]
    fn smith_walter_close_to_exact() {
        let d = Distribution::Beckmann { alpha: 0.3 };
        for theta in [0.2, 0.8, 1.2, 1.5] {
            let (s, c) = f64::sin_cos(theta);
            let g_e = 1.0 / (1.0 + smith_lambda(&d, SmithG1::Exact, c, s * s));
            let g_w = 1.0 / (1.0 + smith_lambda(&d, SmithG1::Walter, c, s * s));
            assert!((g_e - g_w).abs() < 4e-3, "{theta}: {g_e} {g_w}");
        }
    }

    /// `ln Lambda` in closed form: the direct formula against the asymptotic series where
    /// both hold (Beckmann, `a` from 20 to 26, where `exp(-a^2)` is still representable and
    /// the direct difference loses only 3 digits), the branch at 20 continuous, GGX against
    /// its direct form, and `-inf` along the normal.
    #[test]
    fn ln_lambda_closed_form_is_right_beyond_underflow() {
        let beckmann = Distribution::Beckmann { alpha: 0.2 };
        for k in 0..=60 {
            let a = 20.0 + 0.1 * k as f64;
            let theta = (a * 0.2).recip().atan(); // cot(theta) / alpha = a
            let (s, c) = theta.sin_cos();
            let direct = smith_lambda(&beckmann, SmithG1::Exact, c, s * s).ln();
            let got = ln_lambda_closed_form(&beckmann, c, s).unwrap();
            // relative to |ln Lambda| ~ 400-680; the series' truncation is 2e-9 at a = 20
            assert!((got - direct).abs() < 1e-8, "a {a}: {got} vs {direct}");
        }
        let ggx = Distribution::Ggx { alpha: 0.3 };
        for theta in [1e-6, 0.1, 0.7, 1.5] {
            let (s, c) = f64::sin_cos(theta);
            let a = c / (0.3 * s);
            let want = (0.5 * ((1.0 + 1.0 / (a * a)).sqrt() - 1.0)).ln();
            let got = ln_lambda_closed_form(&ggx, c, s).unwrap();
            // the direct form cancels for small theta (a = 3e5: 1/a^2 = 1e-11 of 1)
            let tol = if theta < 1e-3 { 1e-2 } else { 1e-12 };
            assert!((got - want).abs() < tol, "theta {theta}: {got} vs {want}");
            // and it is the closed-form excess over the cosine
            let n = aps_excess_closed_form(&ggx, c, s).unwrap();
            if theta > 1e-3 {
                assert!((got.exp() * c / n - 1.0).abs() < 1e-10);
            }
        }
        assert_eq!(
            ln_lambda_closed_form(&beckmann, 1.0, 0.0),
            Some(f64::NEG_INFINITY)
        );
        assert_eq!(
            ln_lambda_closed_form(&Distribution::BlinnPhong { m: 10.0 }, 0.5, 0.8),
            None
        );
    }
}
