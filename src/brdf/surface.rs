//! [`Surface`]: the microsurface the BRDF's terms read (the spec, the masking correlation
//! and the masking-excess table), below [`super::material::Material`], which adds the
//! terms' albedo and escape tables on top of it.

use super::spec::MaterialSpec;
use crate::microfacet::masking::{self, ZTable, TABLE_NODES};
use crate::microfacet::{seed, Correlation, Distribution, MaskingEval, Shadowing, SmithG1};

/// Gauss-Legendre order of the albedo quadratures of [`Surface::calibrate_masking`] (that of
/// the material's albedo tables, so the two agree).
pub const CALIBRATION_ORDER: usize = super::material::ALBEDO_ORDER;
/// The cheaper rule and the tolerance [`Surface::calibrate_masking`] reaches with it
/// before it goes on with [`CALIBRATION_ORDER`].
const CALIBRATION_ORDER_FIRST: usize = 48;
const CALIBRATION_TOL_FIRST: f64 = 3e-5;
/// Relative tolerance of [`Surface::calibrate_masking`] on each node's albedo.
pub const CALIBRATION_TOL: f64 = 1e-6;
/// History kept by the Anderson acceleration of [`Surface::calibrate_masking`].
const ANDERSON_DEPTH: usize = 5;
/// Most updates of [`Surface::calibrate_masking`].
pub const CALIBRATION_ITERATIONS: usize = 30;

/// What [`Surface::calibrate_masking`] reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Updates made.
    pub iterations: usize,
    /// Largest `|target / E - 1|` over the nodes.
    pub worst: f64,
}

/// The microsurface of a material: what the single and double terms and their albedo
/// integrals ([`super::single`], [`super::double`], [`super::albedo`](mod@super::albedo)) need. Built by
/// [`super::material::Material::new`] from a validated spec ([`Surface::new`]); a
/// `Material` dereferences to its `Surface` (`mat.spec`, `mat.correlation`,
/// `mat.masking_excess(..)`).
#[derive(Debug, Clone)]
pub struct Surface {
    pub spec: MaterialSpec,
    pub correlation: Correlation,
    /// APS masking excess `N_D(theta)` table (when `masking = Table` and `shadowing = Aps`).
    pub(crate) n_table: Option<ZTable>,
    /// The single term's masking calibrated to a traced surface: `G' = G s(theta_i)
    /// s(theta_o)`, `s` tabulated in `z` ([`Surface::calibrate_masking`]).
    pub calibration: Option<ZTable>,
}

impl Surface {
    /// The surface of a spec that [`super::material::Material::new`] has validated: the
    /// correlation (its default for the shadowing model) and the APS masking-excess table
    /// where the masking is tabulated (or `"exact"` with albedo tables to fill).
    pub fn new(spec: MaterialSpec) -> Self {
        let correlation = spec.correlation.unwrap_or(match spec.shadowing {
            Shadowing::Aps => Correlation::Seed,
            _ => Correlation::None,
        });
        let mut surf = Surface {
            spec,
            correlation,
            n_table: None,
            calibration: None,
        };
        let dist = surf.spec.distribution;
        let needs_albedo = surf.spec.terms.multiple || surf.spec.terms.diffuse;
        let exact = surf.spec.masking == MaskingEval::Exact;
        if (surf.spec.shadowing == Shadowing::Aps || surf.smith_is_aps())
            && (surf.spec.masking == MaskingEval::Table || (exact && needs_albedo))
        {
            // Beckmann and GGX tabulate their closed form (equal to the quadrature to
            // 1e-15, 512 evaluations in microseconds instead of 18 ms of quadratures).
            surf.n_table = Some(ZTable::build(dist.table_scale(), TABLE_NODES, |t| {
                let (s, c) = t.sin_cos();
                masking::aps_excess_closed_form(&dist, c, s)
                    .unwrap_or_else(|| masking::aps_excess(&dist, t))
            }));
        }
        surf
    }

    /// The masking excess `N(k)` such that `P(k) = c/(c + N)` and `P(k)/c = 1/(c + N)`
    /// for a direction with `cos theta = c`, `sin theta = s` (APS: `N_D`; Smith: `c Lambda`).
    #[inline]
    pub fn masking_excess(&self, c: f64, s: f64) -> f64 {
        self.masking_excess_z(c, s, self.z_of(c, s))
    }

    /// The table coordinate `z` of a direction (shared by all per-material tables).
    #[inline]
    pub fn z_of(&self, c: f64, s: f64) -> f64 {
        let den = self.spec.distribution.table_scale() * s + c;
        if den <= 0.0 {
            0.0
        } else {
            (c / den).clamp(0.0, 1.0)
        }
    }

    /// [`Self::masking_excess`] with the table coordinate already computed.
    #[inline]
    pub fn masking_excess_z(&self, c: f64, s: f64, z: f64) -> f64 {
        match self.spec.shadowing {
            Shadowing::None => 0.0,
            // Blinn-Phong's exact Smith function is the APS excess (masking.rs docs).
            Shadowing::Smith if !self.smith_is_aps() => {
                c * masking::smith_lambda(&self.spec.distribution, self.spec.smith_g1, c, s * s)
            }
            Shadowing::Smith | Shadowing::Aps => match self.spec.masking {
                MaskingEval::Table => self.n_table.as_ref().unwrap().eval_z(z).max(0.0),
                MaskingEval::Exact => masking::aps_excess(&self.spec.distribution, s.atan2(c)),
                MaskingEval::Seed => match self.spec.distribution {
                    Distribution::BlinnPhong { m } => seed::seed_aps_excess_cos(m, c),
                    _ => unreachable!("checked in Material::new"),
                },
            },
        }
    }

    /// Calibrate the single term's masking to a traced surface: `G' = G s(theta_i)
    /// s(theta_o)` with `s` such that the single term's white (`F = 1`) albedo is
    /// `target[k]` at incidence `theta_k = k step` for every `k` (the incidence nodes of a
    /// path bank, [`super::bank`]), within [`CALIBRATION_TOL`].
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
    pub fn calibrate_masking(&mut self, step: f64, target: &[f64]) -> Calibration {
        use rayon::prelude::*;
        let n = target.len();
        assert!(n >= 3 && step > 0.0);
        let scale = self.spec.distribution.table_scale();
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
                    super::albedo::single_albedo(surf, c, false, order)
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
        self.calibration = Some(table_of(&x));
        let mut iterations = 0;
        let mut worst = f64::INFINITY;
        // first with a cheap rule (7 times fewer evaluations), then with the tables' own
        for (order, tol) in [
            (CALIBRATION_ORDER_FIRST, CALIBRATION_TOL_FIRST),
            (CALIBRATION_ORDER, CALIBRATION_TOL),
        ] {
            let mut f;
            (f, worst) = step_of(self, order);
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
                self.calibration = Some(table_of(&next));
                let (mut f_next, mut w_next) = step_of(self, order);
                if (w_next.is_nan() || w_next >= 2.0 * worst) && !hist.is_empty() {
                    // the extrapolation went astray (noisy targets): a plain step, a new
                    // history
                    hist.clear();
                    next = plain;
                    self.calibration = Some(table_of(&next));
                    (f_next, w_next) = step_of(self, order);
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

    /// Smith masking that is evaluated as the APS excess `N_D` (the exact Smith function of
    /// a Blinn-Phong distribution, `smith_g1 = "exact"`).
    #[inline]
    pub fn smith_is_aps(&self) -> bool {
        self.spec.shadowing == Shadowing::Smith
            && self.spec.smith_g1 == SmithG1::Exact
            && matches!(self.spec.distribution, Distribution::BlinnPhong { .. })
    }
}
