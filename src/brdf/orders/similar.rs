//! Interpolation of the banks' tables in alpha by the small-slope similarity of the
//! surface's geometry (issue 24: `orders="surface"` from alpha 0.05).
//!
//! # Why
//! Below alpha ~0.3 orders >= 2 exist only toward grazing incidence, in lobes that move
//! with alpha: order 2 of a Beckmann surface with alpha 0.1 carries 0.6% of the light at 70
//! deg and 5% at 80 deg, with alpha 0.05 none at 70 deg and 0.5% at 80 deg. Mixing two
//! nodes' tables at the same `(theta_i, theta_o, phi)` ([`OrderTable::mix`]) then mixes
//! two lobes at different places: against banks traced at the midpoints of the nodes'
//! intervals below 0.3 (`docs/bank-alpha-interpolation.md`) its order-2 M00 missed by
//! 12-29% (L1 over the exit hemisphere, aluminium) where order 2 is strong and by up to
//! 120% where it begins.
//!
//! # The similarity
//! With small slopes and grazing directions the geometry of the paths is unchanged when the
//! heights and the directions' vertical components are scaled together: a facet with
//! normal `(-grad h, 1)` reflects `d = (d_xy, d_z)` to `d_z' = -d_z + 2 d_xy . grad h`,
//! `d_xy' = d_xy + O(slope (d_z + slope))`, and scaling `h` and `d_z` by `c` scales `d_z'`
//! by `c` to first order. So a surface of roughness `alpha` at polar angle `theta` behaves
//! as one of roughness `a` at `theta'` with `cot theta' = (a / alpha) cot theta`: the
//! orders' distribution over `nu = cot(theta) / alpha` is the same. The table of node `a`
//! is read at `theta_i'`, `theta_o'` (same `phi`; bilinear between its nodes, the last
//! node beyond 87.5 deg) and the two nodes' values are mixed in `ln(M00 + eps)` with the
//! weight `w = ln(alpha / a_lo) / ln(a_hi / a_lo)`. The change of variables' Jacobian
//! (`(a / alpha)^2` at grazing) is left out: any power of `a / alpha` cancels in the mix
//! with that weight, and the rest of it (the sines and cosines away from grazing) made
//! the mix worse where order 2 is strongest.
//!
//! The polarization does not follow the similarity: each facet's local incidence is
//! close to the macroscopic one for small slopes, so the Fresnel and Jones matrices are
//! those of the actual angles, and the nodes' normalized elements `M / M00` are nearly the
//! same at the same `(theta_i, theta_o, phi)` (aluminium, order 2, 80 deg specular: `M23 /
//! M00` -0.232, -0.224, -0.229 at alpha 0.05, 0.075, 0.1, where the similarity's angles give
//! -0.85 from the lower node). The mix takes them from [`OrderTable::mix`] at the actual
//! angles (the mapped ones only where neither node has paths there).
//!
//! Against the midpoint banks (`scripts/bank_alpha_interpolation.py`,
//! `docs/bank-alpha-interpolation.md`): order 2's M00 within 2.6-8% L1 where it is strong
//! (albedo >= 1e-3) in the intervals up to 0.25 (0.25-0.3: 10%, the banks' own noise 11%),
//! up to 42% where it begins (albedo 1e-4 to 1e-3); orders 3-8 within 3.4-20% where
//! strong (the worst at 0.05-0.1, where they exist on the last three to six incidence
//! nodes only, and at 0.075-0.1 worse than the fixed-angle mix, 0.146 against 0.117); the
//! normalized elements within the banks' own noise; above 0.3 at the noise, like the
//! fixed-angle mix.
//!
//! Both nodes' values are exact on the nodes (`w = 0` gives the lower node's table, as
//! [`OrderTable::mix`]), and the mix is reciprocal: the map is the same for `theta_i` and
//! `theta_o`, so it commutes with the table's reciprocity (node `(o, i, j)` is
//! `E T(i, o, j)^T E`), and `M00` and the mixed normalized matrices each keep it.

use crate::brdf::bank::{log_mix, OrderTable, MIX_FLOOR, N_PHI, N_THETA, THETA_STEP};
use crate::optics::mueller::{scale, Mat4};

/// The polar angle whose cotangent is `r cot(theta)`.
pub fn similar_theta(theta: f64, r: f64) -> f64 {
    theta.sin().atan2(r * theta.cos())
}

/// `(k, f)`: the node below `theta` and the fraction toward the next (the last node beyond
/// the last, as the tables' own interpolation).
fn coord(theta: f64) -> (usize, f64) {
    let t = (theta / THETA_STEP).clamp(0.0, (N_THETA - 1) as f64);
    let k = (t.floor() as usize).min(N_THETA - 2);
    (k, t - k as f64)
}

/// The weight of the upper node at `alpha` between nodes `a_lo < a_hi` (linear in
/// `ln alpha`).
pub fn weight(a_lo: f64, a_hi: f64, alpha: f64) -> f64 {
    ((alpha / a_lo).ln() / (a_hi / a_lo).ln()).clamp(0.0, 1.0)
}

/// `t` read at the similar angles of ratio `r = a / alpha` (`a` the table's roughness):
/// node `(i, o, j)` holds `t(theta_i', theta_o', phi_j)`, bilinear in the two polar angles.
pub fn remap(t: &OrderTable, r: f64) -> OrderTable {
    let at: Vec<(usize, f64)> = (0..N_THETA)
        .map(|k| coord(similar_theta(k as f64 * THETA_STEP, r)))
        .collect();
    let mut data = Vec::with_capacity(N_THETA * N_THETA * N_PHI);
    for &(i0, fi) in &at {
        for &(o0, fo) in &at {
            for j in 0..N_PHI {
                let mut m = [[0.0; 4]; 4];
                for (i, wa) in [(i0, 1.0 - fi), (i0 + 1, fi)] {
                    for (o, wb) in [(o0, 1.0 - fo), (o0 + 1, fo)] {
                        let w = wa * wb;
                        if w != 0.0 {
                            let p = &t.data[(i * N_THETA + o) * N_PHI + j];
                            for r in 0..4 {
                                for c in 0..4 {
                                    m[r][c] += w * p[r][c];
                                }
                            }
                        }
                    }
                }
                data.push(m);
            }
        }
    }
    OrderTable { data }
}

/// The table at `alpha` between the tables `lo`, `hi` of nodes `a_lo < a_hi` (module
/// docs).
pub fn mix(lo: &OrderTable, hi: &OrderTable, a_lo: f64, a_hi: f64, alpha: f64) -> OrderTable {
    let w = weight(a_lo, a_hi, alpha);
    if w <= 0.0 {
        return lo.clone();
    }
    if w >= 1.0 {
        return hi.clone();
    }
    let (p, q) = (remap(lo, a_lo / alpha), remap(hi, a_hi / alpha));
    let polar = lo.mix(hi, w);
    let peak = |t: &OrderTable| t.data.iter().map(|m| m[0][0]).fold(0.0, f64::max);
    let eps = MIX_FLOOR * peak(lo).max(peak(hi));
    let data = (0..p.data.len())
        .map(|n| {
            let m00 = log_mix(p.data[n][0][0], q.data[n][0][0], w, eps);
            let zero: Mat4 = [[0.0; 4]; 4];
            if m00 <= 0.0 {
                return zero;
            }
            // the normalized elements at the actual angles, else at the similar ones
            let (n_lo, n_hi) = (p.data[n][0][0].max(0.0), q.data[n][0][0].max(0.0));
            let shape = if polar.data[n][0][0] > 0.0 {
                polar.data[n].map(|row| row.map(|x| x / polar.data[n][0][0]))
            } else {
                let (wa, wb) = match (n_lo > 0.0, n_hi > 0.0) {
                    (true, true) => ((1.0 - w) / n_lo, w / n_hi),
                    (true, false) => (1.0 / n_lo, 0.0),
                    (false, true) => (0.0, 1.0 / n_hi),
                    (false, false) => return zero,
                };
                let (a, b) = (&p.data[n], &q.data[n]);
                std::array::from_fn(|r| std::array::from_fn(|c| wa * a[r][c] + wb * b[r][c]))
            };
            scale(&shape, m00)
        })
        .collect();
    OrderTable { data }
}

/// A per-incidence-node quantity (an albedo) at `alpha` between the nodes' values `lo`,
/// `hi`: each read at the similar angle (linear between incidence nodes) and mixed by
/// `combine(x_lo, x_hi, w)`.
pub fn mix_nodes(
    lo: &[f64],
    hi: &[f64],
    a_lo: f64,
    a_hi: f64,
    alpha: f64,
    combine: impl Fn(f64, f64, f64) -> f64,
) -> Vec<f64> {
    let w = weight(a_lo, a_hi, alpha);
    let read = |v: &[f64], r: f64, k: usize| {
        let (i, f) = coord(similar_theta(k as f64 * THETA_STEP, r));
        (1.0 - f) * v[i] + f * v[i + 1]
    };
    (0..N_THETA)
        .map(|k| {
            if w <= 0.0 {
                lo[k]
            } else if w >= 1.0 {
                hi[k]
            } else {
                combine(read(lo, a_lo / alpha, k), read(hi, a_hi / alpha, k), w)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::bank::{BankSpec, PathBank};
    use crate::optics::fresnel::{Eta, C64};

    /// The map's angles: fixed at 0 and 90 deg, `cot` scaled by `r`, its own inverse with
    /// `1 / r`; the weight is 0 and 1 on the nodes.
    #[test]
    fn similar_angles_and_weights() {
        for r in [0.5, 0.8, 1.0, 1.25, 2.0] {
            assert!(similar_theta(0.0, r).abs() < 1e-15);
            assert!(
                (similar_theta(0.5 * std::f64::consts::PI, r) - 0.5 * std::f64::consts::PI).abs()
                    < 1e-15
            );
            for deg in [10.0f64, 45.0, 80.0, 89.0] {
                let t = deg.to_radians();
                let s = similar_theta(t, r);
                assert!((1.0 / s.tan() - r / t.tan()).abs() < 1e-12 * (1.0 + r / t.tan()));
                assert!((similar_theta(s, 1.0 / r) - t).abs() < 1e-12);
            }
        }
        assert_eq!(weight(0.1, 0.2, 0.1), 0.0);
        assert_eq!(weight(0.1, 0.2, 0.2), 1.0);
        assert!((weight(0.1, 0.4, 0.2) - 0.5).abs() < 1e-15);
    }

    /// On a table that follows the similarity exactly (`f = g(cot theta_i / alpha,
    /// cot theta_o / alpha)`, Gaussian in both; no Jacobian, which the mix leaves out) the
    /// mix of two nodes is the table at alpha within the bilinear reading's error (L1 over
    /// the nodes 0.043 for these lobes, 1 in `nu` wide, about 6 deg at alpha 0.1 on 2.5 deg
    /// nodes: bound 0.05), where the fixed-angle mix misses by 0.44 (bound 0.3); the
    /// normalized elements are the nodes' (here the same); and it is reciprocal.
    #[test]
    fn mix_follows_a_similar_table_and_is_reciprocal() {
        let table = |alpha: f64| {
            let mut data = Vec::new();
            for i in 0..N_THETA {
                for o in 0..N_THETA {
                    for j in 0..N_PHI {
                        let nu = |k: usize| {
                            let t = k as f64 * THETA_STEP;
                            t.cos() / t.sin().max(1e-300) / alpha
                        };
                        // (0 where it would be subnormal: a real table's nodes are sums
                        // of paths, far above that)
                        let x = -(nu(i) - 1.5).powi(2) - (nu(o) - 1.2).powi(2);
                        let g = if x > -600.0 { x.exp() } else { 0.0 } * (1.0 + 0.1 * j as f64);
                        let mut m = [[0.0; 4]; 4];
                        m[0][0] = g;
                        m[1][1] = 0.5 * g;
                        m[2][3] = 0.2 * g;
                        m[3][2] = -0.2 * g;
                        data.push(m);
                    }
                }
            }
            OrderTable { data }
        };
        let (lo, hi, alpha) = (table(0.1), table(0.2), 0.14);
        let want = table(alpha);
        let got = mix(&lo, &hi, 0.1, 0.2, alpha);
        let fixed = lo.mix(&hi, weight(0.1, 0.2, alpha));
        let l1 = |t: &OrderTable| {
            let (mut e, mut s) = (0.0, 0.0);
            for (a, b) in t.data.iter().zip(&want.data) {
                e += (a[0][0] - b[0][0]).abs();
                s += b[0][0];
            }
            e / s
        };
        assert!(l1(&got) < 0.05, "similar {}", l1(&got));
        assert!(l1(&fixed) > 0.3, "fixed {}", l1(&fixed));
        for n in 0..got.data.len() {
            let m = &got.data[n];
            if m[0][0] > 0.0 {
                assert!((m[1][1] / m[0][0] - 0.5).abs() < 1e-12);
                assert!((m[2][3] / m[0][0] - 0.2).abs() < 1e-12);
            }
        }
        // reciprocity: node (o, i, j) = E T(i, o, j)^T E on a reciprocal table
        let (lo, hi) = (bank_table(0.3), bank_table(0.4));
        let t = mix(&lo, &hi, 0.3, 0.4, 0.35);
        let e = [1.0, 1.0, 1.0, -1.0];
        let mut worst = 0.0f64;
        for i in 0..N_THETA {
            for o in 0..N_THETA {
                for j in 0..N_PHI {
                    let a = &t.data[(i * N_THETA + o) * N_PHI + j];
                    let b = &t.data[(o * N_THETA + i) * N_PHI + j];
                    for r in 0..4 {
                        for c in 0..4 {
                            let d = (a[r][c] - e[r] * b[c][r] * e[c]).abs();
                            worst = worst.max(d / a[0][0].abs().max(1e-300));
                        }
                    }
                }
            }
        }
        assert!(worst < 1e-9, "{worst}");
    }

    fn bank_table(alpha: f64) -> OrderTable {
        let spec = BankSpec {
            alpha,
            grid: 64,
            correlation_length: 8.0,
            rays: 20_000,
            surfaces: 2,
            seed: 3,
            autocorrelation: Default::default(),
        };
        let b = PathBank::trace(&spec).unwrap();
        OrderTable::build(&b, Eta::Complex(C64::new(1.5, 0.0)), 2..=2)
    }
}
