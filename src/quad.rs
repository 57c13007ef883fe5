//! Gauss-Legendre quadrature on [0, 1], nodes computed once per order and cached.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// Nodes and weights of the n-point Gauss-Legendre rule mapped to [0, 1].
#[derive(Debug)]
pub struct Rule {
    pub x: Vec<f64>,
    pub w: Vec<f64>,
}

fn compute(n: usize) -> Rule {
    // Newton iteration on P_n from the Tricomi initial guess; the usual recurrence.
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    let nf = n as f64;
    for i in 0..n.div_ceil(2) {
        let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (nf + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, z);
            for k in 2..=n {
                let kf = k as f64;
                let p2 = ((2.0 * kf - 1.0) * z * p1 - (kf - 1.0) * p0) / kf;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 1 { z } else { p1 };
            let pnm1 = if n == 1 { 1.0 } else { p0 };
            dp = nf * (z * pn - pnm1) / (z * z - 1.0);
            let dz = pn / dp;
            z -= dz;
            if dz.abs() < 1e-16 {
                break;
            }
        }
        let wi = 2.0 / ((1.0 - z * z) * dp * dp);
        // Map [-1, 1] -> [0, 1].
        x[i] = 0.5 * (1.0 - z);
        x[n - 1 - i] = 0.5 * (1.0 + z);
        w[i] = 0.5 * wi;
        w[n - 1 - i] = 0.5 * wi;
    }
    Rule { x, w }
}

/// The cached n-point rule on [0, 1].
pub fn gauss_legendre(n: usize) -> Arc<Rule> {
    static CACHE: OnceLock<Mutex<HashMap<usize, Arc<Rule>>>> = OnceLock::new();
    let n = n.max(1);
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    let mut guard = cache.lock().unwrap();
    guard
        .entry(n)
        .or_insert_with(|| Arc::new(compute(n)))
        .clone()
}

/// Integrate `f` over [a, b] with the n-point rule.
pub fn integrate(n: usize, a: f64, b: f64, mut f: impl FnMut(f64) -> f64) -> f64 {
    let rule = gauss_legendre(n);
    let h = b - a;
    rule.x
        .iter()
        .zip(&rule.w)
        .map(|(&x, &w)| w * f(a + h * x))
        .sum::<f64>()
        * h
}

/// Endpoint grading of a panel: the map `x -> (t(x), dt/dx)` of `[0, 1]` onto itself that
/// clusters nodes quadratically at each end marked soft (`t ~ x^2` at 0, `1 - t ~ (1 - x)^2`
/// at 1, smoothstep when both), for integrands varying like a root of the distance to that
/// end. Identity when neither end is soft.
#[inline]
pub fn graded(x: f64, soft_a: bool, soft_b: bool) -> (f64, f64) {
    match (soft_a, soft_b) {
        (false, false) => (x, 1.0),
        (true, false) => (x * x, 2.0 * x),
        (false, true) => (1.0 - (1.0 - x) * (1.0 - x), 2.0 * (1.0 - x)),
        (true, true) => (x * x * (3.0 - 2.0 * x), 6.0 * x * (1.0 - x)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graded_maps_integrate_a_root_singularity() {
        // int_0^1 sqrt(t (1 - t)) dt = pi / 8; with both ends soft the mapped integrand is
        // smooth and 12 nodes reach 1e-6 (plain Gauss-Legendre: 1e-3)
        let rule = gauss_legendre(12);
        let f = |s: (bool, bool)| -> f64 {
            rule.x
                .iter()
                .zip(&rule.w)
                .map(|(&x, &w)| {
                    let (t, dt) = graded(x, s.0, s.1);
                    w * dt * (t * (1.0 - t)).sqrt()
                })
                .sum()
        };
        let exact = std::f64::consts::PI / 8.0;
        assert!(
            (f((true, true)) - exact).abs() < 1e-6,
            "{}",
            f((true, true)) - exact
        );
        assert!((f((false, false)) - exact).abs() > 1e-4);
        // every map sends [0, 1] onto [0, 1] with dt/dx its derivative
        for s in [(false, false), (true, false), (false, true), (true, true)] {
            assert_eq!(graded(0.0, s.0, s.1).0, 0.0);
            assert!((graded(1.0, s.0, s.1).0 - 1.0).abs() < 1e-15);
            let (x, h) = (0.37, 1e-6);
            let d = (graded(x + h, s.0, s.1).0 - graded(x - h, s.0, s.1).0) / (2.0 * h);
            assert!((d - graded(x, s.0, s.1).1).abs() < 1e-8);
        }
    }

    #[test]
    fn exact_for_polynomials_up_to_degree_2n_minus_1() {
        for n in [1usize, 2, 5, 16, 64] {
            let rule = gauss_legendre(n);
            for d in 0..(2 * n) {
                let got: f64 = rule
                    .x
                    .iter()
                    .zip(&rule.w)
                    .map(|(x, w)| w * x.powi(d as i32))
                    .sum();
                let want = 1.0 / (d as f64 + 1.0);
                assert!(
                    (got - want).abs() < 1e-13,
                    "n={n} d={d} got={got} want={want}"
                );
            }
        }
    }

    #[test]
    fn integrates_smooth_function() {
        let got = integrate(32, 0.0, std::f64::consts::PI, f64::sin);
        assert!((got - 2.0).abs() < 1e-14);
    }
}
