//! The single term's masking calibrated to a traced surface ([`calibrate_masking`]): the
//! `orders = Surface` materials' order 1 (issue 24), so that the depolarizing remainder
//! does not stand for order-1 light. Below [`super::material::Material`], above
//! [`Surface`] and the albedo quadrature it calls.

use super::albedo::single_albedo;
use super::surface::Surface;
use crate::microfacet::masking::{self, ZTable, TABLE_NODES};

/// The cheaper rule and the tolerance [`calibrate_masking`] reaches with it
/// before it goes on with the given rule.
const CALIBRATION_ORDER_FIRST: usize = 48;
const CALIBRATION_TOL_FIRST: f64 = 3e-5;
/// Relative tolerance of [`calibrate_masking`] on each node's albedo.
pub const CALIBRATION_TOL: f64 = 1e-6;
/// History kept by the Anderson acceleration of [`calibrate_masking`].
const ANDERSON_DEPTH: usize = 5;
/// Most updates of [`calibrate_masking`].
pub const CALIBRATION_ITERATIONS: usize = 30;

/// What [`calibrate_masking`] reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Updates made.
    pub iterations: usize,
    /// Largest `|target / E - 1|` over the nodes.
    pub worst: f64,
}

/// Calibrate the single term's masking to a traced surface: `G' = G s(theta_i)
/// s(theta_o)` with `s` such that the single term's white (`F = 1`) albedo is
/// `target[k]` at incidence `theta_k = k step` for every `k` (the incidence nodes of a
/// path bank, [`super::bank`]), within [`CALIBRATION_TOL`], with the `order`-point rule
/// (that of the material's albedo tables, so the two agree).
///
/// Why: the APS/Smith masking of a Beckmann surface is that of uncorrelated heights
/// and slopes along the ray; on a Gaussian-correlated surface a facet that faces the
/// exit sees terrain that falls away, and the traced order-1 albedo is 0.5-5% above the
/// single term's for alpha 0.3-1 (most at grazing incidence). With the banks' orders 2
/// and up the difference would otherwise land in the depolarizing remainder, which would
/// then stand for light the surface returns in its specular lobe, polarized.
///
/// How: symmetric (Sinkhorn) scaling. `ln s` at the nodes (Catmull-Rom in `theta`
/// between them, held beyond the last; tabulated in `z` on [`TABLE_NODES`] nodes) is
/// moved by half of `ln(target / E)` per step (a direction's `s` enters its albedo
/// about twice: as incidence, and as exit about the mirror direction), with Anderson
/// acceleration. The product form keeps reciprocity, the masking's correlation and its
/// continuity at normal incidence (`s` multiplies `G`, not the `P` inside its `min`).
/// Everything that evaluates the single term (its albedo quadratures and tables, the
/// kernel's `SingleParams`) reads `s`; the masking excess itself (the double term's
/// hit and escape probabilities) is unchanged. `s` is a few per cent above 1 (near 1.005
/// at normal incidence for alpha 0.5-1), so `G'` may exceed 1 slightly where `G` is
/// near 1: it is an empirical factor fitted to the surface, not a probability.
pub fn calibrate_masking(
    surface: &mut Surface,
    step: f64,
    target: &[f64],
    order: usize,
) -> Calibration {
    use rayon::prelude::*;
    let n = target.len();
    assert!(n >= 3 && step > 0.0);
    let scale = surface.spec.distribution.table_scale();
    // the table of s with ln s = x at the nodes
    let table_of = |x: &[f64]| -> ZTable {
        let at = |theta: f64| -> f64 {
            let u = (theta / step).clamp(0.0, (n - 1) as f64);
            let i = (u as usize).min(n - 2);
            let p = |j: isize| x[j.clamp(0, n as isize - 1) as usize];
            let i = i as isize;
            masking::catmull_rom(p(i - 1), p(i), p(i + 1), p(i + 2), u - i as f64)
        };
        ZTable::build(scale, TABLE_NODES, |theta| at(theta).exp())
    };
    // the fixed-point map's step: half the log of target / E at each node
    let step_of = |surf: &Surface, order: usize| -> (Vec<f64>, f64) {
        let e: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|k| {
                let c = (k as f64 * step).cos();
                single_albedo(surf, c, false, order)
            })
            .collect();
        let worst = target
            .iter()
            .zip(&e)
            .fold(0.0f64, |w, (t, e)| w.max((t / e - 1.0).abs()));
        let f = target
            .iter()
            .zip(&e)
            .map(|(t, e)| 0.5 * (t / e).ln())
            .collect();
        (f, worst)
    };
    // Anderson acceleration (Walker & Ni 2011, depth ANDERSON_DEPTH) of x <- x + f(x):
    // the plain iteration converges linearly at about 0.85 per step (the tilts that
    // move light between small and large angles barely change the albedos)
    let mut x = vec![0.0; n];
    surface.calibration = Some(table_of(&x));
    let mut iterations = 0;
    let mut worst = f64::INFINITY;
    // first with a cheap rule (7 times fewer evaluations), then with the tables' own
    for (order, tol) in [
        (CALIBRATION_ORDER_FIRST, CALIBRATION_TOL_FIRST),
        (order, CALIBRATION_TOL),
    ] {
        let mut f;
        (f, worst) = step_of(surface, order);
        let mut hist: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
        while worst > tol && iterations < CALIBRATION_ITERATIONS {
            iterations += 1;
            let plain: Vec<f64> = x.iter().zip(&f).map(|(a, b)| a + b).collect();
            let mut next = plain.clone();
            if !hist.is_empty() {
                // gamma = argmin |f - dF gamma| (normal equations, slightly regularized)
                let k = hist.len();
                let mut a = nalgebra::DMatrix::<f64>::zeros(k, k);
                let mut r = nalgebra::DVector::<f64>::zeros(k);
                for i in 0..k {
                    for j in 0..k {
                        a[(i, j)] = hist[i].1.iter().zip(&hist[j].1).map(|(p, q)| p * q).sum();
                    }
                    r[i] = hist[i].1.iter().zip(&f).map(|(p, q)| p * q).sum();
                }
                let tr = (0..k).map(|i| a[(i, i)]).sum::<f64>() / k as f64;
                for i in 0..k {
                    a[(i, i)] += 1e-10 * tr;
                }
                if let Some(g) = a.cholesky().map(|ch| ch.solve(&r)) {
                    for (i, (dx, df)) in hist.iter().enumerate() {
                        for (v, (p, q)) in next.iter_mut().zip(dx.iter().zip(df)) {
                            *v -= g[i] * (p + q);
                        }
                    }
                }
            }
            surface.calibration = Some(table_of(&next));
            let (mut f_next, mut w_next) = step_of(surface, order);
            if (w_next.is_nan() || w_next >= 2.0 * worst) && !hist.is_empty() {
                // the extrapolation went astray (noisy targets): a plain step, a new
                // history
                hist.clear();
                next = plain;
                surface.calibration = Some(table_of(&next));
                (f_next, w_next) = step_of(surface, order);
            }
            let dx: Vec<f64> = next.iter().zip(&x).map(|(a, b)| a - b).collect();
            let df: Vec<f64> = f_next.iter().zip(&f).map(|(a, b)| a - b).collect();
            if hist.len() == ANDERSON_DEPTH {
                hist.remove(0);
            }
            hist.push((dx, df));
            (x, f, worst) = (next, f_next, w_next);
        }
    }
    Calibration { iterations, worst }
}
