//! The single term's masking calibrated to a traced surface ([`calibrate_masking`]): the
//! `orders = Surface` materials' order 1 (issue 24), so that the depolarizing remainder
//! does not stand for order-1 light. Below [`super::material::Material`], above
//! [`Surface`] and the albedo quadrature it calls.

use super::albedo::single_albedo;
use super::recent::Recent;
use super::surface::Surface;
use super::{MaterialSpec, Terms};
use crate::microfacet::masking::{self, ZTable, TABLE_NODES};
use crate::optics::fresnel::Eta;
use std::sync::Mutex;

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

/// Fine calibration nodes per bank incidence step ([`calibrate_masking`]'s second stage),
/// up to [`FINE_GRAZING_DEG`], and beyond it (where the single albedo curves most).
pub const FINE_PER_STEP: [usize; 2] = [4, 16];
/// Where the fine nodes become denser (deg).
const FINE_GRAZING_DEG: f64 = 80.0;
/// The fine nodes end at or below this (deg); `s` is held beyond. The tables in `z` resolve
/// about 0.05 deg at grazing.
const FINE_LAST_DEG: f64 = 89.85;
/// Most updates of the fine stage.
const FINE_ITERATIONS: usize = 12;

/// What [`calibrate_masking`] reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Updates made (both stages).
    pub iterations: usize,
    /// Largest `|target / E - 1|` over the nodes of the last stage.
    pub worst: f64,
}

/// Calibrate the single term's masking to a traced surface: `G' = G s(theta_i)
/// s(theta_o)` with `s` such that the single term's white (`F = 1`) albedo is
/// `target[k]` at incidence `theta_k = k step` for every `k` (the incidence nodes of a
/// path bank, [`super::bank`]), within [`CALIBRATION_TOL`], with the `order`-point rule
/// (that of the material's albedo tables, so the two agree); and, when `fine` is given,
/// `fine(theta)` on finer nodes ([`FINE_PER_STEP`]) up to 89.85 deg as well.
///
/// Why: the APS/Smith masking of a Beckmann surface is that of uncorrelated heights
/// and slopes along the ray; on a Gaussian-correlated surface a facet that faces the
/// exit sees terrain that falls away, and the traced order-1 albedo is 0.5-5% above the
/// single term's for alpha 0.3-1 (most at grazing incidence). With the banks' orders 2
/// and up the difference would otherwise land in the depolarizing remainder, which would
/// then stand for light the surface returns in its specular lobe, polarized.
///
/// Why the fine stage: the banks' albedos are linear in `theta` between their nodes (as
/// their tables interpolate), the single term's is smooth; matched at the nodes only, the
/// two missed the energy balance between them by up to 2.2e-4 of the albedo (alpha 0.5,
/// 61 deg) and by 2e-3 beyond the last node (88 deg, where the banks are held), 5-60
/// times the light past the banks' last order that the depolarizing remainder stands for.
/// `fine` is the target as the tables interpolate it; the fine stage follows its kinks
/// (linear `ln s` between the fine nodes) and leaves about 1e-5 between them.
///
/// How: symmetric (Sinkhorn) scaling. `ln s` at the nodes (Catmull-Rom in `theta`
/// between them, held beyond the last; tabulated in `z` on [`TABLE_NODES`] nodes) is
/// moved by half of `ln(target / E)` per step (a direction's `s` enters its albedo
/// about twice: as incidence, and as exit about the mirror direction), with Anderson
/// acceleration; then the same from that curve on the fine nodes, linear between them.
/// The product form keeps reciprocity, the masking's correlation and its
/// continuity at normal incidence (`s` multiplies `G`, not the `P` inside its `min`).
/// Everything that evaluates the single term (its albedo quadratures and tables, the
/// kernel's `SingleParams`) reads `s`; the masking excess itself (the double term's
/// hit and escape probabilities) is unchanged. `s` is a few per cent above 1 (near 1.005
/// at normal incidence for alpha 0.5-1), so `G'` may exceed 1 slightly where `G` is
/// near 1: it is an empirical factor fitted to the surface, not a probability.
///
/// Cached: the result depends on the surface only through its white (`F = 1`) single
/// albedo, so not on `eta` (nor on the terms, the diffuse layer or the wavelength), and on
/// the bank only through `target` and `fine` at the fine nodes. The last
/// [`CALIBRATIONS_KEPT`] calibrations are kept per process, keyed on exactly those inputs
/// ([`CalibrationKey`]); a material of another `eta` at the same roughness and bank reuses
/// one bit for bit (`tests::cached_calibration_equals_a_fresh_one_for_another_eta`).
/// Without it each `orders = Surface` material paid about 1.7 s on 2 cores here, 9 times
/// the rest of its build.
pub fn calibrate_masking(
    surface: &mut Surface,
    step: f64,
    target: &[f64],
    fine: Option<&(dyn Fn(f64) -> f64 + Sync)>,
    order: usize,
) -> Calibration {
    if surface.calibration.is_some() {
        return calibrate_uncached(surface, step, target, fine, order);
    }
    let key = CalibrationKey::new(&surface.spec, step, target, fine, order);
    let kept = || CALIBRATIONS.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((table, result)) = kept().get(&key) {
        surface.calibration = Some(table);
        return result;
    }
    let result = calibrate_uncached(surface, step, target, fine, order);
    if let Some(table) = surface.calibration.clone() {
        kept().insert(key, (table, result));
    }
    result
}

/// Calibrations kept per process by [`calibrate_masking`] (each a few kB).
pub const CALIBRATIONS_KEPT: usize = 64;

/// Everything [`calibrate_masking`]'s result depends on: the spec with the fields that do
/// not enter the white single albedo set to fixed values, the step, the rule, and the
/// targets' bits (the fine target at the fine nodes).
#[derive(Debug, Clone, PartialEq)]
struct CalibrationKey {
    spec: MaterialSpec,
    step: u64,
    order: usize,
    target: Vec<u64>,
    fine: Option<Vec<u64>>,
}

impl CalibrationKey {
    fn new(
        spec: &MaterialSpec,
        step: f64,
        target: &[f64],
        fine: Option<&(dyn Fn(f64) -> f64 + Sync)>,
        order: usize,
    ) -> Self {
        let mut spec = spec.clone();
        spec.eta = Eta::PerfectConductor;
        spec.terms = Terms {
            single: true,
            double: false,
            multiple: false,
            diffuse: false,
        };
        spec.diffuse_albedo = 0.0;
        spec.double_order = 0;
        spec.coherent_backscatter = false;
        spec.double_correlated = true;
        spec.wavelength = 0.0;
        spec.correlation_length = 0.0;
        spec.bank_rays = 0;
        spec.alpha_step = None;
        CalibrationKey {
            spec,
            step: step.to_bits(),
            order,
            target: target.iter().map(|x| x.to_bits()).collect(),
            fine: fine.map(|f| {
                fine_thetas(step)
                    .into_iter()
                    .map(|t| f(t).to_bits())
                    .collect()
            }),
        }
    }
}

/// The calibrations kept ([`calibrate_masking`]).
static CALIBRATIONS: Mutex<Recent<CalibrationKey, (ZTable, Calibration)>> =
    Mutex::new(Recent::new(CALIBRATIONS_KEPT));

/// The fine stage's nodes (deg steps in [`FINE_PER_STEP`], up to [`FINE_LAST_DEG`]).
fn fine_thetas(step: f64) -> Vec<f64> {
    let (h, h_grazing) = (
        step / FINE_PER_STEP[0] as f64,
        step / FINE_PER_STEP[1] as f64,
    );
    let (grazing, last) = (FINE_GRAZING_DEG.to_radians(), FINE_LAST_DEG.to_radians());
    let mut thetas = vec![0.0];
    loop {
        let t = *thetas.last().unwrap();
        let next = if t < grazing - 1e-12 {
            t + h
        } else {
            t + h_grazing
        };
        if next > last + 1e-12 {
            break;
        }
        thetas.push(next);
    }
    thetas
}

/// [`calibrate_masking`] without the cache.
pub(crate) fn calibrate_uncached(
    surface: &mut Surface,
    step: f64,
    target: &[f64],
    fine: Option<&(dyn Fn(f64) -> f64 + Sync)>,
    order: usize,
) -> Calibration {
    let n = target.len();
    assert!(n >= 3 && step > 0.0);
    let scale = surface.spec.distribution.table_scale();
    // the coarse stage: ln s = x at the bank's nodes, Catmull-Rom between
    let coarse = move |x: &[f64], theta: f64| masking::catmull_rom_nodes(x, theta / step);
    let thetas: Vec<f64> = (0..n).map(|k| k as f64 * step).collect();
    let table_of = |x: &[f64]| ZTable::build(scale, TABLE_NODES, |t| coarse(x, t).exp());
    let stages = [
        (CALIBRATION_ORDER_FIRST, CALIBRATION_TOL_FIRST),
        (order, CALIBRATION_TOL),
    ];
    let (x, mut iterations, mut worst) = sinkhorn(
        surface,
        &thetas,
        target,
        &table_of,
        vec![0.0; n],
        &stages,
        CALIBRATION_ITERATIONS,
    );
    if let Some(fine) = fine {
        let thetas = fine_thetas(step);
        let m = thetas.len();
        let target: Vec<f64> = thetas.iter().map(|&t| fine(t)).collect();
        let nodes = thetas.clone();
        let linear = move |x: &[f64], theta: f64| -> f64 {
            let i = nodes.partition_point(|&t| t <= theta).clamp(1, m - 1) - 1;
            let f = ((theta - nodes[i]) / (nodes[i + 1] - nodes[i])).clamp(0.0, 1.0);
            (1.0 - f) * x[i] + f * x[i + 1]
        };
        let table_of = |x: &[f64]| ZTable::build(scale, TABLE_NODES, |t| linear(x, t).exp());
        let x0 = thetas.iter().map(|&t| coarse(&x, t)).collect();
        let (_, it, w) = sinkhorn(
            surface,
            &thetas,
            &target,
            &table_of,
            x0,
            &[(order, CALIBRATION_TOL)],
            FINE_ITERATIONS,
        );
        iterations += it;
        worst = w;
    }
    Calibration { iterations, worst }
}

/// The symmetric scaling of [`calibrate_masking`] on one set of nodes: from `x` (`ln s` at
/// `thetas`, tabulated by `table_of`), stage by stage (each an albedo rule and the
/// tolerance it is run to), at most `max_iter` updates in all. Leaves `surface` calibrated
/// with the last `x` tried and returns it, the updates made and the last worst ratio.
fn sinkhorn(
    surface: &mut Surface,
    thetas: &[f64],
    target: &[f64],
    table_of: &dyn Fn(&[f64]) -> ZTable,
    mut x: Vec<f64>,
    stages: &[(usize, f64)],
    max_iter: usize,
) -> (Vec<f64>, usize, f64) {
    use rayon::prelude::*;
    // the fixed-point map's step: half the log of target / E at each node
    let step_of = |surf: &Surface, order: usize| -> (Vec<f64>, f64) {
        let e: Vec<f64> = thetas
            .par_iter()
            .map(|t| single_albedo(surf, t.cos(), false, order))
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
    surface.calibration = Some(table_of(&x));
    let mut iterations = 0;
    let mut worst = f64::INFINITY;
    for &(order, tol) in stages {
        let mut f;
        (f, worst) = step_of(surface, order);
        let mut hist: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
        while worst > tol && iterations < max_iter {
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
    (x, iterations, worst)
}
