//! The received pulse convolved with a pixel's range footprint, as a CDF.
//!
//! Within a pixel the range is `r(u, v) = r0 + gx u + gy v` with `u, v` uniform on
//! `[-delta/2, delta/2]`, so the pixel's range density is the convolution of two box
//! densities of widths `a = |gx| delta` and `b = |gy| delta` (a trapezoid). The profile bin
//! `[e_k, e_{k+1})` of that pixel gets
//!
//! ```text
//! W_k = C(e_{k+1} - r0) - C(e_k - r0),    C = CDF of (p * box_a * box_b),
//! ```
//!
//! `p` being the received pulse in range units, so the weights telescope: their sum over all
//! bins is `C(last edge) - C(first edge)` exactly (1 when the bins cover the support).
//!
//! # Gaussian pulse: the formulas and regimes
//!
//! Everything is evaluated in sigma units, `y = x/s`, `A = a/s`, `B = b/s`, with the widths
//! sorted so that `A >= B`, and `s = max(sigma, KAPPA * max(|x|, a, b), S_MIN)` (the clamp only
//! matters when sigma is zero or negligible against the widths; it changes the result by
//! less than about `KAPPA`, and it keeps every scaled quantity below `1/KAPPA`).
//! With `Phi`, `phi` the standard normal CDF and density, define the even, decaying functions
//!
//! ```text
//! Q(t)  = Psi2(-|t|) = ((t^2 + 1) Phi(-|t|) - |t| phi(t)) / 2      (Q(0) = 1/4)
//! E1(t) = Psi1(t) - max(t, 0) = phi(t) - |t| Phi(-|t|)
//! E2(t) = Psi2(t) - max(t, 0)^2 / 2 = Q(t) if t <= 0, 1/2 - Q(t) if t > 0
//! ```
//!
//! (`Psi1 = x Phi + phi` and `Psi2 = ((x^2+1) Phi + x phi)/2` are the first and second
//! antiderivatives of `Phi`; the identities `Psi1(x) - Psi1(-x) = x` and
//! `Psi2(x) + Psi2(-x) = (x^2+1)/2` give the forms above). `Q`, `E1`, `E2` are bounded by 1/2
//! and evaluated with an absolute error of a few ulps of 1/2 (only `Phi(-|t|)` of a
//! non-positive argument is ever used, so the erfc's relative accuracy carries over).
//! Arguments of `Q`, `E1` and the Hermite terms are clamped to `|t| <= 40`, where they are 0.
//!
//! 1. **Both widths small** (`A < ALPHA`): the moment (Gram-Charlier) series of `Phi(y - W)`,
//!    `W = U + V`, which terminates only at infinity but converges fast:
//!    `C = Phi(y) - phi(y) * sum_{k=1..5} M_{2k}/(2k)! He_{2k-1}(y)`, with `He_n` the
//!    probabilists' Hermite polynomials (`He_{n+1} = y He_n - n He_{n-1}`) and
//!    `M_{2k}` the even moments of `U + V`, from the box moments `mu_{2k}(A) = (A/2)^{2k}/(2k+1)`:
//!    `M2 = mu2a + mu2b`, `M4 = mu4a + 6 mu2a mu2b + mu4b`,
//!    `M6 = mu6a + 15 (mu4a mu2b + mu2a mu4b) + mu6b`,
//!    `M8 = mu8a + 28 (mu6a mu2b + mu2a mu6b) + 70 mu4a mu4b + mu8b`,
//!    `M10 = mu10a + 45 (mu8a mu2b + mu2a mu8b) + 210 (mu6a mu4b + mu4a mu6b) + mu10b`.
//!    Exact for `A = B = 0` (`C = Phi(y)`).
//! 2. **One width small** (`A >= ALPHA`, `B < BETA`): the single-box CDF
//!    `F_A(y) = clamp((y + A/2)/A, 0, 1) + (E1(y + A/2) - E1(y - A/2))/A` (the uniform CDF plus a
//!    bounded correction, error ~ eps/A) and the moment series in `B` only:
//!    `C = F_A(y) + sum_{k=1..5} mu_{2k}(B)/(2k)! * (He_{2k-2} phi (y+A/2) - He_{2k-2} phi (y-A/2)) / A`.
//!    Exact for `B = 0`.
//! 3. **Both widths large** (`B >= BETA`): the second difference of `Psi2` split into the
//!    trapezoid CDF (second difference of `max(t,0)^2/2`, evaluated piecewise without
//!    cancellation) and the bounded rest:
//!    `C = T(y) + ((E2(y+h1) - E2(y+h2)) - (E2(y-h2) - E2(y-h1))) / (A B)`,
//!    `h1 = (A+B)/2`, `h2 = (A-B)/2`, with
//!    `T(y) = 0 | (y+h1)^2/(2AB) | (y + A/2)/A | 1 - (h1-y)^2/(2AB) | 1` on
//!    `y <= -h1 | <= -h2 | <= h2 | < h1 | else`. Error ~ eps/(A B) <= eps/BETA^2.
//!
//! The switch points are [`ALPHA_F64`], [`BETA_F64`] for the f64 reference and [`ALPHA_F32`],
//! [`BETA_F32`] for the f32 twin (the f32 twin has a larger rounding floor, so it can afford
//! the series over a wider range and must keep `1/(A B)` smaller).
//!
//! Both are one body, [`cdf_gauss_box2_generic`], over [`PulseFloat`], which holds what
//! differs between them: the erfc (`libm::erfc` in f64, [`erfc_f32`] in f32), the switches,
//! the input clamps, and the constants' rounding (the f32 ones as `shaders/shared/pulse.wgsl`
//! writes them; that file ports the f32 instance line by line).
//!
//! # Sampled pulse
//!
//! See [`SampledPulse`]: the samples are joined piecewise linearly (the pulse is the sum of
//! hat functions of half-width `dt` centred on the samples, i.e. it goes linearly to zero one
//! spacing beyond each end), and `C` is evaluated exactly (up to rounding) from tables of the
//! CDF and its two antiderivatives, with the same split into a trapezoid and bounded rests
//! for wide footprints.

use crate::{Error, Result};
use num_traits::Float;

/// Speed of light in vacuum (m/s), for converting a temporal pulse width to range.
pub const C_LIGHT: f64 = 299_792_458.0;

/// Regime switch of the f64 reference: the double moment series is used for `A < ALPHA_F64`.
pub const ALPHA_F64: f64 = 0.125;
/// Regime switch of the f64 reference: the series in the smaller width `B` for `B < BETA_F64`.
pub const BETA_F64: f64 = 0.4;
/// Regime switch of the f32 twin, see [`ALPHA_F64`].
pub const ALPHA_F32: f32 = 0.5;
/// Regime switch of the f32 twin, see [`BETA_F64`].
pub const BETA_F32: f32 = 1.0;

/// Gaussian range standard deviation from a temporal FWHM `tau` (s): the range FWHM is
/// `c tau / 2` (two-way travel) and `sigma = FWHM / (2 sqrt(2 ln 2))`.
pub fn sigma_from_fwhm_time(tau: f64) -> f64 {
    sigma_from_range_fwhm(C_LIGHT * tau / 2.0)
}

/// Gaussian standard deviation from a FWHM in the same (range) units.
pub fn sigma_from_range_fwhm(fwhm: f64) -> f64 {
    fwhm / (2.0 * (2.0 * std::f64::consts::LN_2).sqrt())
}

// ---------------------------------------------------------------------------------------
// Gaussian pulse: one body for the f64 reference and the f32 twin (of shaders/shared/pulse.wgsl)
// ---------------------------------------------------------------------------------------

/// The float types the Gaussian pulse's CDF is evaluated in: `f64` (the reference) and
/// `f32` (the twin of `shaders/shared/pulse.wgsl`, whose constants a test compares with
/// these). What differs between the two on purpose: the erfc, the regime switches, the
/// clamps, and the constants' rounding (the f32 ones are written as in the WGSL).
pub trait PulseFloat: Float {
    /// Regime switch: the double moment series for `A < ALPHA` ([`ALPHA_F64`], [`ALPHA_F32`]).
    const ALPHA: Self;
    /// Regime switch: the series in the smaller width for `B < BETA` ([`BETA_F64`],
    /// [`BETA_F32`]).
    const BETA: Self;
    const INV_SQRT_2PI: Self;
    const FRAC_1_SQRT_2: Self;
    /// |t| beyond which phi, Q, E1 and the Hermite terms are taken as their limits (all
    /// below 1e-300 there).
    const T_CLAMP: Self;
    /// `1 / (2k)!`, `k = 0..=5`.
    const INV_FACT_EVEN: [Self; 6];
    /// Bound on `|x|` and on the widths.
    const BIG: Self;
    /// The scale is `s = max(sigma, KAPPA max(|x|, a, b), S_MIN)`.
    const KAPPA: Self;
    const S_MIN: Self;
    /// The complementary error function.
    fn erfc(x: Self) -> Self;
    /// A constant of the formulas (small integers and halves: exact in both types).
    fn lit(x: f64) -> Self;
}

impl PulseFloat for f64 {
    const ALPHA: f64 = ALPHA_F64;
    const BETA: f64 = BETA_F64;
    const INV_SQRT_2PI: f64 = 0.398_942_280_401_432_7;
    const FRAC_1_SQRT_2: f64 = std::f64::consts::FRAC_1_SQRT_2;
    const T_CLAMP: f64 = 40.0;
    const INV_FACT_EVEN: [f64; 6] = [
        1.0,
        1.0 / 2.0,
        1.0 / 24.0,
        1.0 / 720.0,
        1.0 / 40320.0,
        1.0 / 3628800.0,
    ];
    const BIG: f64 = 1e300;
    const KAPPA: f64 = 1e-16;
    const S_MIN: f64 = 1e-300;

    /// `libm::erfc` (musl's port of the Sun/FreeBSD `s_erf.c`, error below 1 ulp). Not
    /// `statrs::function::erf::erfc`: statrs 0.19 writes the float-exact offsets of Boost's
    /// rational approximations as 10-digit f64 literals and is off by ~1e-11 for arguments
    /// >= 0.5 (e.g. Phi(1) by 1.4e-11; see the tests).
    #[inline]
    fn erfc(x: f64) -> f64 {
        libm::erfc(x)
    }

    #[inline]
    fn lit(x: f64) -> f64 {
        x
    }
}

impl PulseFloat for f32 {
    const ALPHA: f32 = ALPHA_F32;
    const BETA: f32 = BETA_F32;
    const INV_SQRT_2PI: f32 = 0.3989423;
    const FRAC_1_SQRT_2: f32 = std::f32::consts::FRAC_1_SQRT_2;
    const T_CLAMP: f32 = 40.0;
    const INV_FACT_EVEN: [f32; 6] = [
        1.0,
        0.5,
        0.041666668,
        0.0013888889,
        2.4801588e-5,
        2.755732e-7,
    ];
    const BIG: f32 = 1e30;
    const KAPPA: f32 = 1e-9;
    const S_MIN: f32 = 1e-30;

    /// [`erfc_f32`], as the WGSL's.
    #[inline]
    fn erfc(x: f32) -> f32 {
        erfc_f32(x)
    }

    #[inline]
    fn lit(x: f64) -> f32 {
        x as f32
    }
}

/// Complementary error function in f32: Numerical Recipes' `erfcc` (a Chebyshev fit with
/// fractional error below 1.2e-7 for all x in exact arithmetic), evaluated in f32. Measured in
/// the tests against libm's f64 erfc: relative error below 3.5e-7 on [0, 1] and below
/// 3.5e-7 (1 + x^2) on [0, 9] (the f32 rounding of x^2 inside the exponential), absolute
/// error below 3.5e-7 for x < 0.
pub fn erfc_f32(x: f32) -> f32 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -1.2655122
        + t * (1.0000237
            + t * (0.37409195
                + t * (0.09678418
                    + t * (-0.18628806
                        + t * (0.27886808
                            + t * (-1.135204
                                + t * (1.4885159 + t * (-0.82215226 + t * 0.17087276))))))));
    let r = t * (-z * z + poly).exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Standard normal CDF, `erfc(-x/sqrt 2)/2` with the type's erfc ([`PulseFloat::erfc`]).
#[inline]
fn norm_cdf_t<T: PulseFloat>(x: T) -> T {
    T::lit(0.5) * T::erfc(-x * T::FRAC_1_SQRT_2)
}

/// Standard normal density.
#[inline]
fn norm_pdf_t<T: PulseFloat>(x: T) -> T {
    T::INV_SQRT_2PI * (T::lit(-0.5) * x * x).exp()
}

/// Standard normal CDF in f64, `erfc(-x/sqrt 2)/2` with `libm::erfc` (see
/// [`PulseFloat::erfc`] of `f64`).
pub fn norm_cdf(x: f64) -> f64 {
    norm_cdf_t(x)
}

/// Standard normal density.
pub fn norm_pdf(x: f64) -> f64 {
    norm_pdf_t(x)
}

/// The standard normal CDF by cubic Hermite interpolation (the density as its derivative)
/// between nodes `1 / per_sigma` apart on `[-half, half]`, and [`norm_cdf`] beyond: for
/// the many evaluations of one render at points along the same Gaussian (the paths'
/// deposits). The interpolation's error is at most `h^4 max|phi''''| / 384` (`h` the node
/// spacing in standard deviations, `max|phi''''| = 3`, phi the density): 1.8e-12 at 256
/// nodes per standard deviation; measured against [`norm_cdf`], 3.3e-13 (the test asserts
/// < 2e-12).
#[derive(Debug, Clone)]
pub struct NormCdfTable {
    half: f64,
    per_sigma: f64,
    /// Per node: the CDF and the density times the spacing.
    nodes: Vec<[f64; 2]>,
}

impl NormCdfTable {
    pub fn new(half: f64, per_sigma: usize) -> Self {
        let n = (2.0 * half * per_sigma as f64).ceil() as usize;
        let h = 1.0 / per_sigma as f64;
        let nodes = (0..=n)
            .map(|j| {
                let y = -half + j as f64 * h;
                [norm_cdf(y), norm_pdf(y) * h]
            })
            .collect();
        NormCdfTable {
            half,
            per_sigma: per_sigma as f64,
            nodes,
        }
    }

    /// `Phi(y)`.
    #[inline]
    pub fn eval(&self, y: f64) -> f64 {
        let t = (y + self.half) * self.per_sigma;
        let j = t.floor();
        if !(j >= 0.0 && (j as usize) + 1 < self.nodes.len()) {
            return norm_cdf(y);
        }
        let u = t - j;
        let ([p0, d0], [p1, d1]) = (self.nodes[j as usize], self.nodes[j as usize + 1]);
        let (u2, u3) = (u * u, u * u * u);
        p0 * (2.0 * u3 - 3.0 * u2 + 1.0)
            + d0 * (u3 - 2.0 * u2 + u)
            + p1 * (3.0 * u2 - 2.0 * u3)
            + d1 * (u3 - u2)
    }
}

/// Standard normal CDF in f32 from [`erfc_f32`].
pub fn norm_cdf_f32(x: f32) -> f32 {
    norm_cdf_t(x)
}

/// Standard normal density in f32.
pub fn norm_pdf_f32(x: f32) -> f32 {
    norm_pdf_t(x)
}

fn q<T: PulseFloat>(t: T) -> T {
    let y = t.abs().min(T::T_CLAMP);
    T::lit(0.5) * ((y * y + T::one()) * norm_cdf_t(-y) - y * norm_pdf_t(y))
}

fn e1<T: PulseFloat>(t: T) -> T {
    let y = t.abs().min(T::T_CLAMP);
    norm_pdf_t(y) - y * norm_cdf_t(-y)
}

fn e2<T: PulseFloat>(t: T) -> T {
    if t <= T::zero() {
        q(t)
    } else {
        T::lit(0.5) - q(t)
    }
}

/// CDF of the trapezoid `box_a * box_b` (any consistent units), `a >= b > 0`.
fn trap<T: PulseFloat>(y: T, a: T, b: T) -> T {
    let h1 = T::lit(0.5) * (a + b);
    let h2 = T::lit(0.5) * (a - b);
    if y <= -h1 {
        T::zero()
    } else if y <= -h2 {
        let z = y + h1;
        z * z / (T::lit(2.0) * a * b)
    } else if y <= h2 {
        (y + T::lit(0.5) * a) / a
    } else if y < h1 {
        let z = h1 - y;
        T::one() - z * z / (T::lit(2.0) * a * b)
    } else {
        T::one()
    }
}

/// `He_0..=He_9` at `y` by the recurrence.
fn hermite<T: PulseFloat>(y: T) -> [T; 10] {
    let mut he = [T::zero(); 10];
    he[0] = T::one();
    he[1] = y;
    for n in 1..9 {
        he[n + 1] = y * he[n] - T::lit(n as f64) * he[n - 1];
    }
    he
}

/// `mu_{2k}(w) = (w/2)^{2k}/(2k+1)` for k = 0..=5.
fn box_moments<T: PulseFloat>(w: T) -> [T; 6] {
    let u = T::lit(0.25) * w * w;
    let mut m = [T::one(); 6];
    let mut p = T::one();
    for (k, mk) in m.iter_mut().enumerate().skip(1) {
        p = p * u;
        *mk = p / T::lit((2 * k + 1) as f64);
    }
    m
}

/// C in sigma units, `aa >= bb >= 0`.
fn cdf_std<T: PulseFloat>(y: T, aa: T, bb: T) -> T {
    let c = T::lit;
    let inv_fact = T::INV_FACT_EVEN;
    if aa == T::zero() {
        // a point (`bb <= aa`): every moment below is 0, and so is the correction
        return norm_cdf_t(y.clamp(-T::T_CLAMP, T::T_CLAMP));
    }
    if aa < T::ALPHA {
        let y = y.clamp(-T::T_CLAMP, T::T_CLAMP);
        let ma = box_moments(aa);
        let mb = box_moments(bb);
        let m2 = ma[1] + mb[1];
        let m4 = ma[2] + c(6.0) * ma[1] * mb[1] + mb[2];
        let m6 = ma[3] + c(15.0) * (ma[2] * mb[1] + ma[1] * mb[2]) + mb[3];
        let m8 =
            ma[4] + c(28.0) * (ma[3] * mb[1] + ma[1] * mb[3]) + c(70.0) * ma[2] * mb[2] + mb[4];
        let m10 = ma[5]
            + c(45.0) * (ma[4] * mb[1] + ma[1] * mb[4])
            + c(210.0) * (ma[3] * mb[2] + ma[2] * mb[3])
            + mb[5];
        let he = hermite(y);
        let s = m2 * inv_fact[1] * he[1]
            + m4 * inv_fact[2] * he[3]
            + m6 * inv_fact[3] * he[5]
            + m8 * inv_fact[4] * he[7]
            + m10 * inv_fact[5] * he[9];
        norm_cdf_t(y) - norm_pdf_t(y) * s
    } else if bb < T::BETA {
        let yp = y + c(0.5) * aa;
        let ym = y - c(0.5) * aa;
        let fa = (yp / aa).clamp(T::zero(), T::one()) + (e1(yp) - e1(ym)) / aa;
        let mb = box_moments(bb);
        let tp = yp.clamp(-T::T_CLAMP, T::T_CLAMP);
        let tm = ym.clamp(-T::T_CLAMP, T::T_CLAMP);
        let (hp, hm) = (hermite(tp), hermite(tm));
        let (pp, pm) = (norm_pdf_t(tp), norm_pdf_t(tm));
        let mut s = T::zero();
        for k in 1..=5 {
            s = s + mb[k] * inv_fact[k] * (hp[2 * k - 2] * pp - hm[2 * k - 2] * pm);
        }
        fa + s / aa
    } else {
        let h1 = c(0.5) * (aa + bb);
        let h2 = c(0.5) * (aa - bb);
        let d = (e2(y + h1) - e2(y + h2)) - (e2(y - h2) - e2(y - h1));
        trap(y, aa, bb) + d / (aa * bb)
    }
}

/// CDF at `x` of a centred Gaussian pulse of standard deviation `sigma` convolved with boxes
/// of widths `a` and `b` (all in range units; the widths' signs are ignored), in `T`: the
/// formulas of the [module docs](self) with `T`'s regime switches, inputs clamped
/// (`|x|` and the widths to [`PulseFloat::BIG`], `s = max(sigma, KAPPA max(|x|, a, b),
/// S_MIN)`). [`cdf_gauss_box2`] (f64) and [`cdf_gauss_box2_f32`] have the measured errors.
pub fn cdf_gauss_box2_generic<T: PulseFloat>(x: T, sigma: T, a: T, b: T) -> T {
    let x = x.clamp(-T::BIG, T::BIG);
    let a = a.abs().min(T::BIG);
    let b = b.abs().min(T::BIG);
    let m = x.abs().max(a).max(b);
    let s = sigma.max(T::KAPPA * m).max(T::S_MIN);
    let (aa, bb) = if a >= b {
        (a / s, b / s)
    } else {
        (b / s, a / s)
    };
    cdf_std(x / s, aa, bb)
}

/// CDF at `x` of a centred Gaussian pulse of standard deviation `sigma` convolved with boxes
/// of widths `a` and `b` (all in range units; the widths' signs are ignored).
///
/// f64 reference. Measured in the tests against brute-force 2-D Gauss-Legendre quadrature
/// over u, v of `Phi((x - u - v)/sigma)`: max absolute error 8.9e-16 (asserted < 3e-15) for
/// a/sigma, b/sigma from 0 to 1e4 (both small, both huge, either much larger than the other,
/// both sides of each switch), x over +-((a+b)/2 + 10 sigma) and around the trapezoid's
/// corners; jumps at the regime switches <= 1.6e-15. See the [module docs](self) for the
/// formulas. `sigma = 0` gives the trapezoid CDF; infinite `x` gives 0 or 1.
pub fn cdf_gauss_box2(x: f64, sigma: f64, a: f64, b: f64) -> f64 {
    cdf_gauss_box2_generic(x, sigma, a, b)
}

/// Bin weights of one pixel for a Gaussian pulse: `out[k] = C(edges[k+1] - r0) -
/// C(edges[k] - r0)` with `C` = [`cdf_gauss_box2`]. `edges` must be increasing and
/// `out.len() + 1 == edges.len()`.
pub fn bin_weights_f64(r0: f64, a: f64, b: f64, sigma: f64, edges: &[f64], out: &mut [f64]) {
    assert_eq!(out.len() + 1, edges.len(), "need one more edge than bins");
    let mut prev = cdf_gauss_box2(edges[0] - r0, sigma, a, b);
    for (o, &e) in out.iter_mut().zip(&edges[1..]) {
        let c = cdf_gauss_box2(e - r0, sigma, a, b);
        *o = c - prev;
        prev = c;
    }
}

/// The renderer's bin weights of one pixel (the rule of `shaders/shade.wgsl`): only the
/// bins `k0..=k1` that `[r0 - half_w, r0 + half_w]` reaches get weight (`half_w` = the
/// pulse support plus half the footprint), and the pulse's tails beyond them are folded
/// into the end bins (the first bin's weight is `C(e_{k0+1} - r0)`, the last's
/// `1 - C(e_{k1} - r0)`), so the weights sum to exactly 1: a pixel's profile sums to its
/// value whatever the support. `edges` are `r_min + k bin_width`.
pub fn bin_weights_folded(
    r0: f64,
    a: f64,
    b: f64,
    sigma: f64,
    half_w: f64,
    edges: &[f64],
    out: &mut [f64],
) {
    assert_eq!(out.len() + 1, edges.len(), "need one more edge than bins");
    out.iter_mut().for_each(|o| *o = 0.0);
    folded_weights(
        r0,
        half_w,
        edges,
        |x| cdf_gauss_box2(x, sigma, a, b),
        |k, w| out[k] = w,
    );
}

/// The weights of [`bin_weights_folded`] for any pulse, visited without touching the other
/// bins: `visit(k, w)` for each bin `k0..=k1` that `[r0 - half_w, r0 + half_w]` reaches,
/// with `w = C(e_{k+1} - r0) - C(e_k - r0)` and the tails folded into the end bins (they sum
/// to exactly 1); `cdf` is `C`, the pulse convolved with the footprint, at an offset from
/// `r0`. `edges` are `r_min + k bin_width` (at least two).
pub fn folded_weights(
    r0: f64,
    half_w: f64,
    edges: &[f64],
    cdf: impl Fn(f64) -> f64,
    mut visit: impl FnMut(usize, f64),
) {
    let nb = edges.len() - 1;
    let (r_min, bw) = (edges[0], edges[1] - edges[0]);
    let bin = |r: f64| (((r - r_min) / bw).floor().clamp(0.0, (nb - 1) as f64)) as usize;
    let (k0, k1) = (bin(r0 - half_w), bin(r0 + half_w));
    let mut prev = 0.0;
    for k in k0..=k1 {
        let c = if k < k1 { cdf(edges[k + 1] - r0) } else { 1.0 };
        visit(k, c - prev);
        prev = c;
    }
}

/// f32 twin of [`cdf_gauss_box2`], the exact formulas of `pulse_cdf_gauss_box2` in
/// `shaders/shared/pulse.wgsl` (no f64 inside). Regimes as in the [module docs](self) with
/// [`ALPHA_F32`], [`BETA_F32`]; inputs are clamped (`|x| <= 1e30`, widths `<= 1e30`,
/// `s = max(sigma, 1e-9 max(|x|, a, b), 1e-30)`) so that no NaN or infinity can arise,
/// also for `sigma = 0`, `a = b = 0` or `x = +-f32::MAX`.
///
/// Measured maximum absolute error against the f64 reference evaluated at the same f32
/// inputs: 1.96e-7 (the test asserts < 2.5e-7), over the grid of `f32_twin_error_grid`:
/// sigma in {1, 0.37}; a/sigma and b/sigma each in {0, 1e-4, 0.01, 0.1, 0.3, 0.49, 0.51, 0.9,
/// 1.1, 2, 5, 30, 1e3, 1e4} (all 196 pairs, both sides of both switches); x at 201 points
/// evenly over +-((a+b)/2 + 10 sigma) plus 28 points at -3..3 sigma around each trapezoid
/// corner +-(a+b)/2, +-(a-b)/2. The jumps at the regime switches are below 2.4e-7.
/// Not counted: the rounding of `x` itself to f32 (the renderer's `e_k - r0`), which costs
/// up to `ulp(x) * max density <= ulp(x) / max(a, sigma sqrt(2 pi))`.
pub fn cdf_gauss_box2_f32(x: f32, sigma: f32, a: f32, b: f32) -> f32 {
    cdf_gauss_box2_generic(x, sigma, a, b)
}

// ---------------------------------------------------------------------------------------
// Sampled pulse
// ---------------------------------------------------------------------------------------

/// Footprints narrower than this many sample spacings are integrated knot by knot.
const LOCAL_KNOTS: f64 = 8.0;

/// A user-sampled pulse shape and the tables to evaluate `C = CDF of p * box_a * box_b`.
///
/// Interpolation: the samples `s_i >= 0` at `r_i = r_first + i dt` are joined piecewise
/// linearly and the shape goes linearly to zero over one spacing beyond each end, i.e.
/// `p(r) = sum_i s_i hat((r - r_i)/dt) / (dt sum_i s_i)` with the unit hat `hat(u) =
/// max(1 - |u|, 0)`; the normalisation makes its area exactly 1. `P` (its CDF) is then
/// piecewise quadratic with knots at `r_first + (j-1) dt`, `j = 0..=N+1`.
///
/// Tables at the knots: `p`, its slope on each interval, `P`, and the bounded first and
/// second antiderivatives `E1(t) = int (P - H(. - mu))`, `E2(t) = int E1` taken relative to a
/// unit step at the centroid `mu` (so `E1 -> 0`, `E2 -> Var/2` on the right). Between knots
/// they are the exact polynomials.
///
/// Evaluation of `C(x)` (widths sorted `a >= b`, `h1 = (a+b)/2`, `h2 = (a-b)/2`):
/// - `a <= 8 dt`: `C = int P(x - w) t(w) dw` with `t` the trapezoid density, integrated
///   exactly piece by piece between the knots of `P` and of `t` (2-point Gauss-Legendre on
///   cubic pieces); `a = 0` gives `P(x)`.
/// - `b <= 8 dt < a`: `C = (1/b) int_{x-b/2}^{x+b/2} F_a(y) dy` (the mean of `F_a` over that
///   window) with the single-box CDF
///   `F_a(y) = clamp((y - mu + a/2)/a, 0, 1) + (E1(y + a/2) - E1(y - a/2))/a`, again exactly
///   between its knots; `b = 0` gives `F_a(x)`.
/// - `b > 8 dt`: `C = T(x - mu) + ((E2(x+h1) - E2(x+h2)) - (E2(x-h2) - E2(x-h1)))/(a b)` with
///   `T` the trapezoid CDF, as for the Gaussian.
#[derive(Debug, Clone)]
pub struct SampledPulse {
    /// Position of knot 0 (the zero pad before the first sample).
    r0: f64,
    dt: f64,
    mu: f64,
    var: f64,
    p: Vec<f64>,
    slope: Vec<f64>,
    cdf: Vec<f64>,
    e1: Vec<f64>,
    e2: Vec<f64>,
}

enum Loc {
    Left,
    Right,
    In(usize, f64),
}

impl SampledPulse {
    /// Pulse from samples spaced `dt_range` apart (range units), placed so that its centroid
    /// is at range 0 (as the centred Gaussian of [`cdf_gauss_box2`]).
    pub fn new(samples: &[f64], dt_range: f64) -> Result<Self> {
        let mu = Self::build(samples, dt_range, 0.0)?.mu;
        Self::build(samples, dt_range, -mu)
    }

    /// Pulse whose first sample sits at range `r_first` (range units), the others at
    /// `r_first + i dt_range`.
    pub fn with_origin(samples: &[f64], dt_range: f64, r_first: f64) -> Result<Self> {
        Self::build(samples, dt_range, r_first)
    }

    fn build(samples: &[f64], dt: f64, r_first: f64) -> Result<Self> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(Error::param("dt_range", dt, "finite and > 0"));
        }
        if !r_first.is_finite() {
            return Err(Error::param("r_first", r_first, "finite"));
        }
        if samples.is_empty() {
            return Err(Error::Shape("pulse samples: need at least one".into()));
        }
        if let Some(s) = samples.iter().find(|s| !(s.is_finite() && **s >= 0.0)) {
            return Err(Error::param("pulse sample", s, "finite and >= 0"));
        }
        let total: f64 = samples.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return Err(Error::param(
                "sum of pulse samples",
                total,
                "> 0 and finite",
            ));
        }
        let n = samples.len() + 2;
        let r0 = r_first - dt;
        let mut p = vec![0.0; n];
        for (pj, s) in p[1..n - 1].iter_mut().zip(samples) {
            *pj = s / (total * dt);
        }
        let knot = |j: usize| r0 + j as f64 * dt;
        // Centroid and variance of the hat sum (each hat adds dt^2/6).
        let mu = (1..n - 1).map(|j| p[j] * dt * knot(j)).sum::<f64>();
        let var = (1..n - 1)
            .map(|j| p[j] * dt * (knot(j) - mu).powi(2))
            .sum::<f64>()
            + dt * dt / 6.0;
        let mut slope = vec![0.0; n - 1];
        let mut cdf = vec![0.0; n];
        let mut e1 = vec![0.0; n];
        let mut e2 = vec![0.0; n];
        for j in 0..n - 1 {
            let d = (p[j + 1] - p[j]) / dt;
            slope[j] = d;
            cdf[j + 1] = cdf[j] + dt * (p[j] + d * dt / 2.0);
            let rj = knot(j);
            let (h1, h2) = if rj >= mu {
                (dt, dt * dt / 2.0)
            } else {
                let z = (knot(j + 1) - mu).max(0.0);
                (z, z * z / 2.0)
            };
            e1[j + 1] = e1[j] + dt * (cdf[j] + dt * (p[j] / 2.0 + dt * d / 6.0)) - h1;
            e2[j + 1] =
                e2[j] + dt * (e1[j] + dt * (cdf[j] / 2.0 + dt * (p[j] / 6.0 + dt * d / 24.0))) - h2;
        }
        Ok(Self {
            r0,
            dt,
            mu,
            var,
            p,
            slope,
            cdf,
            e1,
            e2,
        })
    }

    /// Centroid of the interpolated pulse (range units).
    pub fn centroid(&self) -> f64 {
        self.mu
    }

    /// Variance of the interpolated pulse (range units squared).
    pub fn variance(&self) -> f64 {
        self.var
    }

    /// Where the interpolated pulse is non-zero: `(first knot, last knot)` (range units).
    pub fn support(&self) -> (f64, f64) {
        (self.r0, self.r_end())
    }

    fn knot(&self, j: usize) -> f64 {
        self.r0 + j as f64 * self.dt
    }

    fn r_end(&self) -> f64 {
        self.knot(self.p.len() - 1)
    }

    fn locate(&self, t: f64) -> Loc {
        let u = (t - self.r0) / self.dt;
        let last = (self.p.len() - 1) as f64;
        if u.is_nan() || u <= 0.0 {
            Loc::Left
        } else if u >= last {
            Loc::Right
        } else {
            let j = (u.floor() as usize).min(self.p.len() - 2);
            Loc::In(j, t - self.knot(j))
        }
    }

    /// The CDF `P(t)` of the interpolated pulse.
    pub fn pulse_cdf(&self, t: f64) -> f64 {
        match self.locate(t) {
            Loc::Left => 0.0,
            Loc::Right => 1.0,
            Loc::In(j, s) => self.cdf[j] + s * (self.p[j] + s * self.slope[j] / 2.0),
        }
    }

    fn e1_at(&self, t: f64) -> f64 {
        match self.locate(t) {
            Loc::Left => 0.0,
            Loc::Right => self.e1[self.e1.len() - 1],
            Loc::In(j, s) => {
                let h = if self.knot(j) >= self.mu {
                    s
                } else {
                    (t - self.mu).max(0.0)
                };
                self.e1[j] + s * (self.cdf[j] + s * (self.p[j] / 2.0 + s * self.slope[j] / 6.0)) - h
            }
        }
    }

    fn e2_at(&self, t: f64) -> f64 {
        match self.locate(t) {
            Loc::Left => 0.0,
            Loc::Right => self.e2[self.e2.len() - 1],
            Loc::In(j, s) => {
                let h = if self.knot(j) >= self.mu {
                    s * s / 2.0
                } else {
                    let z = (t - self.mu).max(0.0);
                    z * z / 2.0
                };
                self.e2[j]
                    + s * (self.e1[j]
                        + s * (self.cdf[j] / 2.0
                            + s * (self.p[j] / 6.0 + s * self.slope[j] / 24.0)))
                    - h
            }
        }
    }

    /// Knot positions `r_j + shift` strictly inside `(lo, hi)`, pushed onto `out`.
    fn push_knots(&self, lo: f64, hi: f64, shift: f64, out: &mut Vec<f64>) {
        let n = self.p.len();
        let jlo = ((lo - shift - self.r0) / self.dt).floor().max(0.0);
        let jhi = ((hi - shift - self.r0) / self.dt)
            .ceil()
            .min((n - 1) as f64);
        if !(jlo <= jhi) {
            return;
        }
        for j in jlo as usize..=jhi as usize {
            let k = self.knot(j) + shift;
            if k > lo && k < hi {
                out.push(k);
            }
        }
    }

    /// CDF at `x` of this pulse convolved with boxes of widths `a` and `b` (range units; the
    /// widths' signs are ignored). f64; see the type docs for the regimes.
    pub fn cdf_box2(&self, x: f64, a: f64, b: f64) -> f64 {
        let (a, b) = if a.abs() >= b.abs() {
            (a.abs(), b.abs())
        } else {
            (b.abs(), a.abs())
        };
        let h1 = 0.5 * (a + b);
        let h2 = 0.5 * (a - b);
        if x - h1 >= self.r_end() {
            return 1.0;
        }
        if x + h1 <= self.r0 {
            return 0.0;
        }
        let kdt = LOCAL_KNOTS * self.dt;
        if b > kdt {
            let d = (self.e2_at(x + h1) - self.e2_at(x + h2))
                - (self.e2_at(x - h2) - self.e2_at(x - h1));
            trap(x - self.mu, a, b) + d / (a * b)
        } else if a > kdt {
            let fa = |y: f64| {
                ((y - self.mu + 0.5 * a) / a).clamp(0.0, 1.0)
                    + (self.e1_at(y + 0.5 * a) - self.e1_at(y - 0.5 * a)) / a
            };
            let (lo, hi) = (x - 0.5 * b, x + 0.5 * b);
            // The mean over the window as represented: divide by hi - lo, not b (they differ
            // by ulp(x), which matters when b is tiny).
            if !(hi > lo) {
                return fa(x);
            }
            let mut bp = vec![lo, hi];
            for k in [self.mu - 0.5 * a, self.mu + 0.5 * a] {
                if k > lo && k < hi {
                    bp.push(k);
                }
            }
            self.push_knots(lo, hi, -0.5 * a, &mut bp);
            self.push_knots(lo, hi, 0.5 * a, &mut bp);
            integrate_pieces(&mut bp, fa) / (hi - lo)
        } else {
            if a == 0.0 {
                return self.pulse_cdf(x);
            }
            let dens = |w: f64| {
                let aw = w.abs();
                if aw <= h2 {
                    1.0 / a
                } else {
                    ((h1 - aw) / (a * b)).max(0.0)
                }
            };
            let mut bp = vec![-h1, h1];
            if b > 0.0 {
                bp.push(-h2);
                bp.push(h2);
            }
            // Knots of P(x - w) in w: w = x - r_j.
            let mut ks = Vec::new();
            self.push_knots(x - h1, x + h1, 0.0, &mut ks);
            bp.extend(ks.iter().map(|k| x - k));
            integrate_pieces(&mut bp, |w| self.pulse_cdf(x - w) * dens(w))
        }
    }

    /// Bin weights of one pixel for this pulse, as [`bin_weights_f64`].
    pub fn bin_weights(&self, r0: f64, a: f64, b: f64, edges: &[f64], out: &mut [f64]) {
        assert_eq!(out.len() + 1, edges.len(), "need one more edge than bins");
        let mut prev = self.cdf_box2(edges[0] - r0, a, b);
        for (o, &e) in out.iter_mut().zip(&edges[1..]) {
            let c = self.cdf_box2(e - r0, a, b);
            *o = c - prev;
            prev = c;
        }
    }
}

/// Sum over consecutive breakpoints of the 2-point Gauss-Legendre rule (exact for cubics).
fn integrate_pieces(bp: &mut [f64], f: impl Fn(f64) -> f64) -> f64 {
    bp.sort_by(|p, q| p.total_cmp(q));
    let g = 0.5 / 3f64.sqrt();
    let mut sum = 0.0;
    for w in bp.windows(2) {
        let (lo, hi) = (w[0], w[1]);
        let h = hi - lo;
        if h <= 0.0 {
            continue;
        }
        let mid = 0.5 * (lo + hi);
        sum += 0.5 * h * (f(mid - g * h) + f(mid + g * h));
    }
    sum
}

#[cfg(test)]
mod tests;
