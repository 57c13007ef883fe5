//! Ray traversal of a periodic triangulated height field and polarization ray tracing.
//!
//! # Traversal
//! A 2D DDA (Amanatides and Woo 1987) walks the cells under the ray's horizontal
//! projection; cell indices wrap modulo `n` (periodic tiling) while positions stay
//! unwrapped along one segment. A cell is skipped when the ray's height over the cell's
//! parameter interval is above the cell's corner maximum (the surface in a cell never
//! exceeds it). Otherwise the interval is split where the ray crosses the cell's diagonal,
//! and in each piece (one plane) the signed height `g(t) = z_ray(t) - z_plane(t)` is linear,
//! so the first root is exact. A piece is entered only when the ray approaches its plane
//! from above (`d . n < 0`); if rounding puts the ray a hair below the plane at the start
//! of a piece, the hit is taken at the piece start, which keeps the surface watertight
//! across edges. Segments end when the ray is above the global maximum height while going
//! up (escaped), below the global minimum (lost: should not happen, counted), or after a
//! cap on the number of cells (lost).
//!
//! # Polarization
//! Each ray carries the fields `E_a = P e_a` of two orthonormal incident basis vectors
//! `e_1, e_2` (transverse to `k_in = -wi`), i.e. the two columns of the accumulated 3x3
//! polarization ray-tracing matrix `P` restricted to the incident transverse plane
//! (Chipman's `P` also maps `k_in` to `k_out`, which never enters a Jones projection). At a
//! facet with unit normal `h` (conventions of [`crate::optics`]):
//! `s = normalize(k_in x h)`, `p_in = k_in x s`, `p_out = k_out x s`,
//! `E <- rs s (s . E) + rp p_out (p_in . E)`, with `(rs, rp) = fresnel_amplitudes(-k_in . h)`.
//! At normal incidence (`k_in x h = 0`) any `s` transverse to `k_in` gives the same map
//! because `rp = -rs` there.

use super::microsurface::{HeightField, Plane};
use crate::optics::frames::{cross, dot, mitsuba_basis, V3};
use crate::optics::fresnel::{fresnel_amplitudes, Eta, C64};

/// The result of following one straight segment.
#[derive(Debug, Clone, Copy)]
pub enum Segment {
    /// Hit at parameter `t` on the plane `plane` (whose upward normal is `(-sx, -sy, 1)`).
    Hit { t: f64, plane: Plane },
    /// Above every height and going up.
    Escaped,
    /// Went below the surface or exceeded the cell budget (a numerical failure).
    Lost,
}

/// First intersection in cell `(ci, cj)` over `[t0, t1]`; `(ou, ov)` is the ray origin in
/// the cell's local coordinates.
#[inline]
#[allow(clippy::too_many_arguments)]
fn cell_hit(
    f: &HeightField,
    ci: usize,
    cj: usize,
    ou: f64,
    ov: f64,
    oz: f64,
    d: V3,
    t0: f64,
    t1: f64,
) -> Option<(f64, Plane)> {
    let planes = f.planes(ci, cj);
    let main = HeightField::main_diagonal(ci, cj);
    // Where the horizontal projection crosses the diagonal.
    let tk = if main {
        let den = d[0] - d[1];
        if den != 0.0 {
            (ov - ou) / den
        } else {
            f64::NAN
        }
    } else {
        let den = d[0] + d[1];
        if den != 0.0 {
            (1.0 - ou - ov) / den
        } else {
            f64::NAN
        }
    };
    let split = tk > t0 && tk < t1;
    let pieces = if split {
        [(t0, tk), (tk, t1)]
    } else {
        [(t0, t1), (t1, t1)]
    };
    for &(ta, tb) in &pieces[..if split { 2 } else { 1 }] {
        // Which triangle this piece lies in (at its midpoint; any point for a vertical ray).
        let tm = if tb.is_finite() {
            0.5 * (ta + tb)
        } else {
            ta + 1.0
        };
        let (um, vm) = (ou + tm * d[0], ov + tm * d[1]);
        let k = if main {
            usize::from(um < vm)
        } else {
            usize::from(um + vm > 1.0)
        };
        let p = planes[k];
        // d . (-sx, -sy, 1): the ray must approach the plane from above.
        let dn = d[2] - p.sx * d[0] - p.sy * d[1];
        if dn >= 0.0 {
            continue;
        }
        let ga = (oz + ta * d[2]) - (p.z0 + p.sx * (ou + ta * d[0]) + p.sy * (ov + ta * d[1]));
        let ts = ta - ga / dn;
        if ts <= tb {
            return Some((ts.max(ta), p));
        }
    }
    None
}

/// Follow the ray `o + t d` (`t > 0`, `o` anywhere; x and y wrap with period `n`) through
/// at most `max_cells` cells beyond those under its part in the height slab.
pub fn trace_segment(f: &HeightField, o: V3, d: V3, max_cells: usize) -> Segment {
    let n = f.n as i64;
    let mut ix = o[0].floor() as i64;
    let mut iy = o[1].floor() as i64;
    let axis = |oc: f64, dc: f64, ic: i64| -> (i64, f64, f64) {
        if dc > 0.0 {
            (1, ((ic + 1) as f64 - oc) / dc, 1.0 / dc)
        } else if dc < 0.0 {
            (-1, (ic as f64 - oc) / dc, -1.0 / dc)
        } else {
            (0, f64::INFINITY, f64::INFINITY)
        }
    };
    let (sx, mut tx, dtx) = axis(o[0], d[0], ix);
    let (sy, mut ty, dty) = axis(o[1], d[1], iy);
    let mut t0 = 0.0;
    // Budget: the cells under the part of the ray inside the height slab, plus
    // `max_cells` for (nearly) horizontal rays that wrap around the tile.
    let dxy = d[0].hypot(d[1]);
    let slab = if d[2] != 0.0 {
        2.0 * (f.h_max - f.h_min + 2.0) * dxy / d[2].abs() + 4.0
    } else {
        0.0
    };
    let budget = max_cells.saturating_add(slab.min(1e9) as usize);
    for _ in 0..budget {
        let t1 = tx.min(ty);
        let (ci, cj) = (ix.rem_euclid(n) as usize, iy.rem_euclid(n) as usize);
        let [_, hi] = f.cell_bounds(ci, cj);
        let za = o[2] + t0 * d[2];
        let zb = if t1.is_finite() {
            o[2] + t1 * d[2]
        } else {
            d[2] * f64::INFINITY
        };
        if za.min(zb) <= hi {
            if let Some((t, plane)) = cell_hit(
                f,
                ci,
                cj,
                o[0] - ix as f64,
                o[1] - iy as f64,
                o[2],
                d,
                t0,
                t1,
            ) {
                return Segment::Hit { t, plane };
            }
        }
        if d[2] > 0.0 && zb > f.h_max {
            return Segment::Escaped;
        }
        if d[2] <= 0.0 && zb < f.h_min {
            return Segment::Lost;
        }
        if tx < ty {
            ix += sx;
            t0 = tx;
            tx += dtx;
        } else {
            iy += sy;
            t0 = ty;
            ty += dty;
        }
    }
    Segment::Lost
}

/// Two transverse fields, the columns of the ray's polarization matrix.
pub type Fields = [[C64; 3]; 2];

/// Reflect direction `k_in` and the fields `e` off a facet with unit normal `h`
/// (`k_in . h < 0`); returns `k_out`.
#[inline]
pub fn reflect(k_in: V3, h: V3, eta: Eta, e: &mut Fields) -> V3 {
    let c = (-dot(k_in, h)).clamp(0.0, 1.0);
    let mut k_out = k_in + 2.0 * c * h;
    let l = dot(k_out, k_out).sqrt();
    k_out /= l;
    let sv = cross(k_in, h);
    let l2 = dot(sv, sv);
    let s = if l2 > 1e-30 {
        let l = l2.sqrt();
        sv / l
    } else {
        mitsuba_basis(k_in)
    };
    let p_in = cross(k_in, s);
    let p_out = cross(k_out, s);
    let (rs, rp) = fresnel_amplitudes(c, eta);
    for col in e.iter_mut() {
        let es = col[0] * s[0] + col[1] * s[1] + col[2] * s[2];
        let ep = col[0] * p_in[0] + col[1] * p_in[1] + col[2] * p_in[2];
        let (a, b) = (rs * es, rp * ep);
        for i in 0..3 {
            col[i] = a * s[i] + b * p_out[i];
        }
    }
    k_out
}

/// Reflect the fields `e` of a wave arriving along `-wi` off the facets `normals` in
/// reverse order (the last one first): the reversed path of a traced one, at exact
/// backscatter. Returns the exit direction, or `None` when a facet does not face the
/// reversed ray (`k . h >= 0`: the reversed path does not exist), leaving `e` partly
/// reflected.
pub fn reflect_reversed(wi: V3, normals: &[V3], eta: Eta, e: &mut Fields) -> Option<V3> {
    let mut d = -wi;
    for &h in normals.iter().rev() {
        if dot(d, h) >= 0.0 {
            return None;
        }
        d = reflect(d, h, eta, e);
    }
    Some(d)
}

/// How a primary ray ended.
#[derive(Debug, Clone, Copy)]
pub enum RayEnd {
    /// Left the surface after `order` reflections along `k` with fields `e`.
    Escaped { order: u32, k: V3, e: Fields },
    /// Still on the surface after `max_order` reflections (fields after the last one).
    Truncated { e: Fields },
    /// A numerical failure of the traversal.
    Lost,
}

/// Trace a primary ray from `start` along `-wi` with incident fields `e` (the incident
/// basis vectors) through at most `max_order` reflections.
pub fn trace_ray(
    f: &HeightField,
    eta: Eta,
    wi: V3,
    start: V3,
    e: Fields,
    max_order: u32,
    max_cells: usize,
) -> RayEnd {
    trace_ray_logged(f, eta, wi, start, e, max_order, max_cells, None)
}

/// The geometry of a traced path, recorded for the coherent tally: what the reversed path
/// needs.
#[derive(Debug, Clone, Default)]
pub struct PathLog {
    /// Unit facet normals in the order the ray hit them.
    pub normals: Vec<V3>,
    /// The first hit point, wrapped into the tile like the traversal's positions.
    pub first: V3,
    /// Last hit point minus first hit point, unwrapped (the physical displacement along
    /// the path, although the traversal wraps positions into the tile).
    pub rho: V3,
}

/// [`trace_ray`], also recording the path in `log` when given (cleared first). The ray's
/// own arithmetic is the same with or without a log.
#[allow(clippy::too_many_arguments)]
pub fn trace_ray_logged(
    f: &HeightField,
    eta: Eta,
    wi: V3,
    start: V3,
    mut e: Fields,
    max_order: u32,
    max_cells: usize,
    mut log: Option<&mut PathLog>,
) -> RayEnd {
    if let Some(l) = log.as_deref_mut() {
        l.normals.clear();
        l.first = V3::ZERO;
        l.rho = V3::ZERO;
    }
    let mut o = start;
    let mut d = -wi;
    let mut order = 0;
    let period = f.n as f64;
    loop {
        match trace_segment(f, o, d, max_cells) {
            Segment::Escaped => {
                if order == 0 {
                    return RayEnd::Lost;
                }
                return RayEnd::Escaped { order, k: d, e };
            }
            Segment::Lost => return RayEnd::Lost,
            Segment::Hit { t, plane } => {
                if order == max_order {
                    return RayEnd::Truncated { e };
                }
                // New origin, wrapped into the tile.
                o = V3::new(
                    (o[0] + t * d[0]).rem_euclid(period),
                    (o[1] + t * d[1]).rem_euclid(period),
                    o[2] + t * d[2],
                );
                let l = (plane.sx * plane.sx + plane.sy * plane.sy + 1.0).sqrt();
                let h = V3::new(-plane.sx / l, -plane.sy / l, 1.0 / l);
                if let Some(log) = log.as_deref_mut() {
                    // `o` is the hit point (wrapped); `t d` the segment from the previous hit.
                    if order > 0 {
                        log.rho += t * d;
                    } else {
                        log.first = o;
                    }
                    log.normals.push(h);
                }
                d = reflect(d, h, eta, &mut e);
                order += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::frames::normalize;

    fn real(v: V3) -> [C64; 3] {
        [
            C64::new(v[0], 0.0),
            C64::new(v[1], 0.0),
            C64::new(v[2], 0.0),
        ]
    }

    #[test]
    fn reflection_matches_the_convention_in_the_facet_frame() {
        let eta = Eta::new(1.3, 2.1);
        let k_in = normalize(V3::new(0.3, -0.2, -0.9));
        let h = normalize(V3::new(0.1, 0.25, 1.0));
        let s = normalize(cross(k_in, h));
        let p_in = cross(k_in, s);
        let mut e = [real(s), real(p_in)];
        let k_out = reflect(k_in, h, eta, &mut e);
        let (rs, rp) = fresnel_amplitudes(-dot(k_in, h), eta);
        let p_out = cross(k_out, s);
        for i in 0..3 {
            assert!((e[0][i] - rs * s[i]).norm() < 1e-14);
            assert!((e[1][i] - rp * p_out[i]).norm() < 1e-14);
        }
        // Mirror law.
        let d = dot(k_out, h) + dot(k_in, h);
        assert!(d.abs() < 1e-14);
    }

    #[test]
    fn perfect_conductor_preserves_field_norm() {
        let k_in = normalize(V3::new(0.0, 0.0, -1.0));
        for h in [V3::Z, normalize(V3::new(0.5, -0.3, 1.0))] {
            let mut e = [real(V3::X), real(V3::Y)];
            let k = reflect(k_in, h, Eta::PerfectConductor, &mut e);
            for col in &e {
                let p: f64 = col.iter().map(|c| c.norm_sqr()).sum();
                assert!((p - 1.0).abs() < 1e-14);
                let along: C64 = col[0] * k[0] + col[1] * k[1] + col[2] * k[2];
                assert!(along.norm() < 1e-14, "field stays transverse");
            }
        }
    }

    #[test]
    fn segments_hit_flat_and_tilted_surfaces_where_expected() {
        // Plane z = 0.5 x (periodicity ignored over the short path): a ray straight down
        // from (2.3, 1.7, 10) hits at z = 0.5 * 0.3 + h(2) ... use a linear ramp in x.
        let n = 8;
        let h: Vec<f64> = (0..n * n).map(|k| 0.25 * (k / n) as f64).collect();
        let f = HeightField::new(n, h).unwrap();
        let o = V3::new(2.3, 1.7, 10.0);
        match trace_segment(&f, o, V3::NEG_Z, 1000) {
            Segment::Hit { t, plane } => {
                assert!((10.0 - t - (0.5 + 0.25 * 0.3)).abs() < 1e-12);
                assert!((plane.sx - 0.25).abs() < 1e-15 && plane.sy.abs() < 1e-15);
            }
            s => panic!("{s:?}"),
        }
        match trace_segment(
            &f,
            V3::new(2.3, 1.7, 10.0),
            normalize(V3::new(0.1, 0.2, 1.0)),
            1000,
        ) {
            Segment::Escaped => {}
            s => panic!("{s:?}"),
        }
    }

    /// Height and upward unit normal of the triangulated surface at `(x, y)` (wrapped).
    fn surface_at(f: &HeightField, x: f64, y: f64) -> (f64, V3) {
        let n = f.n as f64;
        let (x, y) = (x.rem_euclid(n), y.rem_euclid(n));
        let (ci, cj) = (x.floor() as usize % f.n, y.floor() as usize % f.n);
        let (u, v) = (x - ci as f64, y - cj as f64);
        let k = if HeightField::main_diagonal(ci, cj) {
            usize::from(u < v)
        } else {
            usize::from(u + v > 1.0)
        };
        let p = f.planes(ci, cj)[k];
        let h = normalize(V3::new(-p.sx, -p.sy, 1.0));
        (p.z0 + p.sx * u + p.sy * v, h)
    }

    #[test]
    fn path_log_records_the_hit_points_and_normals() {
        // The first hit point and the last one (first + rho, wrapped) lie on the surface,
        // on facets with the recorded normals, and the log leaves the ray unchanged. A
        // wrong (wrapped or partial) displacement would put the last point off the surface.
        let (f, _) =
            crate::reference::microsurface::gaussian_height_field(0.9, 16, 2.0, 4, &[]).unwrap();
        let mut rng = crate::reference::rng::Rng::new(8, &[]);
        let wi = normalize(V3::new(0.3, 0.2, 1.0));
        let e = [real(V3::X), real(V3::Y)];
        let mut log = PathLog::default();
        let (mut multi, mut wrapped) = (0, 0);
        for _ in 0..3000 {
            let start = V3::new(rng.uniform() * 16.0, rng.uniform() * 16.0, f.h_max + 1e-3);
            let plain = trace_ray(&f, Eta::PerfectConductor, wi, start, e, 20, 10_000);
            let logged = trace_ray_logged(
                &f,
                Eta::PerfectConductor,
                wi,
                start,
                e,
                20,
                10_000,
                Some(&mut log),
            );
            let RayEnd::Escaped { order, k, e: ef } = logged else {
                continue;
            };
            let RayEnd::Escaped { k: k0, e: e0, .. } = plain else {
                panic!("{plain:?} vs {logged:?}");
            };
            assert!(k == k0 && ef == e0);
            assert_eq!(log.normals.len(), order as usize);
            let last = log.first + log.rho;
            for (p, h) in [
                (log.first, log.normals[0]),
                (last, log.normals[order as usize - 1]),
            ] {
                let (z, hs) = surface_at(&f, p[0], p[1]);
                assert!((p[2] - z).abs() < 1e-9, "{p:?} vs surface {z}");
                assert!(dot(h, hs) > 1.0 - 1e-9, "{h:?} vs {hs:?}");
            }
            if order >= 2 {
                multi += 1;
                if !(0.0..16.0).contains(&last[0]) || !(0.0..16.0).contains(&last[1]) {
                    wrapped += 1;
                }
            }
        }
        // Enough multiple paths, some of them crossing the tile's edge.
        assert!(multi > 300 && wrapped > 20, "{multi} {wrapped}");
    }

    #[test]
    fn reversed_path_is_the_transpose() {
        // Reciprocity of the polarization ray tracing: facets h1..hN lit along -wi send the
        // field P e out along k; the same facets in reverse order lit along -k send P_rev f
        // out along wi, with f . (P e) = e . (P_rev f) for all transverse e, f (bilinear,
        // no conjugation: P_rev = P^T). Random facets, an absorbing metal, 1 to 5 facets.
        let eta = Eta::new(0.7, 3.1);
        let mut rng = crate::reference::rng::Rng::new(3, &[]);
        let wi = normalize(V3::new(-0.4, 0.3, 1.0));
        for trial in 0..200 {
            let n = 1 + trial % 5;
            let mut normals = Vec::new();
            let mut d = -wi;
            while normals.len() < n {
                // Any orientation (a facet of a closed object): a facing one always exists.
                let h = normalize(V3::new(
                    rng.uniform() - 0.5,
                    rng.uniform() - 0.5,
                    rng.uniform() - 0.5,
                ));
                if dot(d, h) < -0.05 {
                    d = d - 2.0 * dot(d, h) * h;
                    normals.push(h);
                }
            }
            let ein = [mitsuba_basis(-wi), cross(-wi, mitsuba_basis(-wi))];
            let mut pe = [real(ein[0]), real(ein[1])];
            let mut k = -wi;
            for &h in &normals {
                k = reflect(k, h, eta, &mut pe);
            }
            let fin = [mitsuba_basis(-k), cross(-k, mitsuba_basis(-k))];
            let mut pf = [real(fin[0]), real(fin[1])];
            let out = reflect_reversed(k, &normals, eta, &mut pf).expect("the reverse exists");
            assert!((out - wi).length() < 1e-12, "{out:?} vs {wi:?}");
            let bil = |u: V3, f: &[C64; 3]| f[0] * u[0] + f[1] * u[1] + f[2] * u[2];
            for a in 0..2 {
                for b in 0..2 {
                    let fwd = bil(fin[a], &pe[b]);
                    let rev = bil(ein[b], &pf[a]);
                    assert!(
                        (fwd - rev).norm() < 1e-12,
                        "{n} facets {a}{b}: {fwd} vs {rev}"
                    );
                }
            }
        }
    }

    /// Brute force: the first hit of `o + t d` over every triangle of the 3 x 3 tiles
    /// around the origin tile (Moller-Trumbore), returning `(t, unit normal)`.
    fn brute_force(f: &HeightField, o: V3, d: V3) -> Option<(f64, V3)> {
        let n = f.n;
        let mut best: Option<(f64, V3)> = None;
        for ox in [-1i64, 0, 1] {
            for oy in [-1i64, 0, 1] {
                for i in 0..n {
                    for j in 0..n {
                        let (h00, h10, h01, h11) = f.corners(i, j);
                        let (x, y) = (
                            (i as i64 + ox * n as i64) as f64,
                            (j as i64 + oy * n as i64) as f64,
                        );
                        let p00 = V3::new(x, y, h00);
                        let p10 = V3::new(x + 1.0, y, h10);
                        let p01 = V3::new(x, y + 1.0, h01);
                        let p11 = V3::new(x + 1.0, y + 1.0, h11);
                        let tris = if HeightField::main_diagonal(i, j) {
                            [[p00, p10, p11], [p00, p11, p01]]
                        } else {
                            [[p00, p10, p01], [p10, p11, p01]]
                        };
                        for [a, b, c] in tris {
                            let e1 = b - a;
                            let e2 = c - a;
                            let pv = cross(d, e2);
                            let det = dot(e1, pv);
                            if det.abs() < 1e-14 {
                                continue;
                            }
                            let tv = o - a;
                            let u = dot(tv, pv) / det;
                            let qv = cross(tv, e1);
                            let v = dot(d, qv) / det;
                            let t = dot(e2, qv) / det;
                            if u < 0.0 || v < 0.0 || u + v > 1.0 || t <= 1e-12 {
                                continue;
                            }
                            let mut nrm = normalize(cross(e1, e2));
                            if nrm[2] < 0.0 {
                                nrm = -nrm;
                            }
                            if best.is_none_or(|(tb, _)| t < tb) {
                                best = Some((t, nrm));
                            }
                        }
                    }
                }
            }
        }
        best
    }

    #[test]
    fn traversal_agrees_with_brute_force_intersection() {
        let (f, _) =
            crate::reference::microsurface::gaussian_height_field(0.8, 16, 2.0, 9, &[]).unwrap();
        let mut rng = crate::reference::rng::Rng::new(5, &[]);
        let mut hits = 0;
        for _ in 0..3000 {
            // Downward rays from above the surface, and rays starting on it going up-ish.
            let theta = rng.uniform() * 1.2;
            let phi = rng.uniform() * std::f64::consts::TAU;
            let mut d = V3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                -theta.cos(),
            );
            let mut o = V3::new(rng.uniform() * 16.0, rng.uniform() * 16.0, f.h_max + 0.5);
            if rng.uniform() < 0.5 {
                // Start at a brute-force surface point and shoot along a reflected direction.
                let Some((t, h)) = brute_force(&f, o, d) else {
                    continue;
                };
                o += t * d;
                let c = -dot(d, h);
                d = normalize(d + 2.0 * c * h);
            }
            let want = brute_force(&f, o, d);
            let got = trace_segment(&f, o, d, 100_000);
            match (got, want) {
                (Segment::Hit { t, plane }, Some((tw, nw))) => {
                    let l = (plane.sx * plane.sx + plane.sy * plane.sy + 1.0).sqrt();
                    let ng = V3::new(-plane.sx / l, -plane.sy / l, 1.0 / l);
                    assert!((t - tw).abs() < 1e-9 * (1.0 + tw), "t {t} vs {tw}");
                    assert!(
                        dot(ng, nw) > 1.0 - 1e-9 || (t - tw).abs() < 1e-9,
                        "normal {ng:?} vs {nw:?}"
                    );
                    hits += 1;
                }
                (Segment::Escaped, None) => {}
                (Segment::Escaped, Some((tw, _))) => {
                    // Brute force sees only the 3 x 3 tiles; an escaping ray must not hit there.
                    panic!("escaped but brute force hits at {tw}: o {o:?} d {d:?}");
                }
                (Segment::Hit { t, .. }, None) => {
                    // Only acceptable beyond the brute-force tiles.
                    let x = o[0] + t * d[0];
                    let y = o[1] + t * d[1];
                    assert!(
                        !(-16.0..32.0).contains(&x) || !(-16.0..32.0).contains(&y),
                        "hit at {t} missed by brute force"
                    );
                }
                (g, w) => panic!("{g:?} vs {w:?}"),
            }
        }
        assert!(hits > 1500, "{hits}");
    }
}
