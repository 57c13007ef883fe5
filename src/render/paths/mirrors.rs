//! Aiming 3-bounce paths from their middle surface at the glossy flat surfaces that mirror
//! the transmitter ([`Mirrors`], [`aim`]).

use super::*;

/// The glossy flat surfaces of one attitude a 3-bounce path may be aimed at from its middle
/// surface: each a mirror of the transmitter, blurred by its roughness. A path through a
/// glossy surface, then a diffuse one, then a glossy one (the bus showing the paint it
/// lights) is drawn poorly from either end (each end evaluates the other's narrow lobe in a
/// direction drawn without it); aimed, the middle surface draws the direction toward the
/// last one from the last one's lobe about the transmitter's mirror direction: a surface
/// `S` chosen with probability `P(S)` (its lit area, projected along `wi`, times its
/// specular lobe's probability), a normal `h` drawn from its distribution, the direction
/// toward `S` opposite the reflection of `wi` about `h`; kept when the ray meets `S` on its
/// lit side. Density `P(S) D(h) cos(theta_h) / (4 wi . h)`, combined with the middle
/// surface's own lobe sampling by the balance heuristic.
///
/// `P(S)` depends on the middle surface `v` ([`Mirrors::choose_from`]): among the surfaces
/// that may light `v` (`v` on the lit side of `S`'s plane, some of `S` above `v`'s
/// horizon and behind `v` along `S`'s mirror direction of `wi`), in proportion to their
/// lit area, projected along `wi`, times their specular lobe's probability. On the 3U
/// CubeSat nearly all third-bounce light is the bus showing the paint it lights, and one
/// aimed draw in four went to that bus face when every candidate of the mesh could be
/// drawn (the others: faces that the paint cannot see, which miss or are shadowed).
/// Leaving some directions to the lobe sampling alone keeps the estimate unbiased (the
/// balance heuristic needs only one strategy that can draw each direction, and the
/// lobes draw every direction above `v`). Measured there (6 attitudes, 16 paths, 10
/// seeds, `scripts/interreflections.py` section 3's set-up), the third bounce's share of
/// the profile noise went from 1.94% to 1.85%, within the seeds' spread, at the same cost:
/// with 4 draws per second surface the third segment is not what limits it (module docs
/// of [`super`]).
pub(super) struct Mirrors {
    /// Per face: the index in `list` of its surface if that is a candidate, else `u32::MAX`.
    pub(super) of_face: Vec<u32>,
    pub(super) list: Vec<Mirror>,
}

pub(super) struct Mirror {
    /// The surface's normal on its lit side.
    pub(super) n: V3,
    /// Its specular lobe alone (what aiming draws from).
    pub(super) lobe: Lobes,
    /// `P(S)` over every candidate (its weight in [`Mirrors::choose_from`]).
    pub(super) p: f64,
    /// A point of its plane, its corners (its vertices, or the corners of its box where it
    /// has more than [`MIRROR_MAX_CORNERS`]) and the transmitter's mirror direction
    /// `2 (wi . n) n - wi` ([`Mirrors::choose_from`]).
    pub(super) at: V3,
    pub(super) corners: Vec<V3>,
    pub(super) r: V3,
}

/// Most vertices of a [`Mirror`] kept as its corners (beyond, its box's 8 corners).
pub(super) const MIRROR_MAX_CORNERS: usize = 32;

/// The least probability of the specular lobe for a surface to be a [`Mirror`].
pub(super) const MIRROR_MIN_SPECULAR: f64 = 0.5;

impl Mirrors {
    pub(super) fn none(n_faces: usize) -> Self {
        Mirrors {
            of_face: vec![u32::MAX; n_faces],
            list: Vec::new(),
        }
    }

    /// The candidates of `posed` lit along `wi`: flat surfaces ([`Mesh::surfaces`]) whose
    /// lit side is open ([`open_sides`]) and whose material's specular lobe has at least
    /// [`MIRROR_MIN_SPECULAR`] of the probability at `wi`; `area[s]` the area of the
    /// surface whose first face is `s`.
    pub(super) fn new(
        posed: &Posed<'_>,
        brdf: &(impl PathBrdf + ?Sized),
        wi: V3,
        area: &[f64],
    ) -> Self {
        let mesh = posed.mesh;
        let surf = mesh.surfaces();
        let mut out = Mirrors::none(mesh.faces.len());
        let mut index_of_root = std::collections::HashMap::new();
        let mut weights = Vec::new();
        for (t, &root) in surf.iter().enumerate() {
            if root as usize != t || area[t] <= 0.0 {
                continue;
            }
            let [a, b, c] = posed.tris[t];
            let n = normalize(cross(b - a, c - a));
            let cw = dot(n, wi);
            if !n.is_finite() || cw == 0.0 {
                continue;
            }
            let (n, side) = if cw > 0.0 { (n, 0) } else { (-n, 1) };
            if !posed.open[t][side] {
                continue;
            }
            let ci = cw.abs();
            let si = (1.0 - ci * ci).max(0.0).sqrt();
            let mat = mesh.face_material[t] as usize;
            let Some(Lobes {
                specular: Some(dist),
                p_specular,
            }) = brdf.lobes(mat, ci, si)
            else {
                continue;
            };
            if p_specular < MIRROR_MIN_SPECULAR {
                continue;
            }
            index_of_root.insert(root, out.list.len() as u32);
            weights.push(area[t] * ci * p_specular);
            let lobe = Lobes {
                specular: Some(dist),
                p_specular: 1.0,
            };
            // (the lit side's normal `n`: `ci = wi . n`)
            let r = 2.0 * ci * n - wi;
            out.list.push(Mirror {
                n,
                lobe,
                p: 0.0,
                at: a,
                corners: Vec::new(),
                r,
            });
        }
        let total: f64 = weights.iter().sum();
        if total <= 0.0 || total.is_nan() {
            return Mirrors::none(mesh.faces.len());
        }
        for (m, w) in out.list.iter_mut().zip(&weights) {
            m.p = w / total;
        }
        // each candidate's corners: its vertices, or its box's where it has many
        let mut verts: Vec<Vec<(u32, V3)>> = vec![Vec::new(); out.list.len()];
        for (t, &root) in surf.iter().enumerate() {
            if let Some(&j) = index_of_root.get(&root) {
                out.of_face[t] = j;
                let vs = &mut verts[j as usize];
                for (&k, &q) in mesh.faces[t].iter().zip(&posed.tris[t]) {
                    if vs.len() <= MIRROR_MAX_CORNERS && !vs.iter().any(|&(i, _)| i == k) {
                        vs.push((k, q));
                    }
                }
            }
        }
        for (j, (m, vs)) in out.list.iter_mut().zip(verts).enumerate() {
            m.corners = if vs.len() <= MIRROR_MAX_CORNERS {
                vs.into_iter().map(|(_, q)| q).collect()
            } else {
                let (mut lo, mut hi) = (V3::splat(f64::INFINITY), V3::splat(f64::NEG_INFINITY));
                for (t, &f) in out.of_face.iter().enumerate() {
                    if f == j as u32 {
                        for q in posed.tris[t] {
                            lo = lo.min(q);
                            hi = hi.max(q);
                        }
                    }
                }
                (0..8)
                    .map(|k| {
                        V3::new(
                            if k & 1 == 0 { lo.x } else { hi.x },
                            if k & 2 == 0 { lo.y } else { hi.y },
                            if k & 4 == 0 { lo.z } else { hi.z },
                        )
                    })
                    .collect()
            };
        }
        out
    }

    /// The cumulative probabilities of choosing each candidate from the middle surface `v`
    /// (struct docs), into `cdf` (one per candidate, the last 1); `false`, and `cdf`
    /// empty, when none may light `v`. A candidate is kept when `v` lies on its lit side
    /// (not on it), one of its corners lies above `v`'s horizon (`v.ng`) and one behind `v`
    /// along its mirror direction `r` (where the light it reflects about `r` can come
    /// from): with its vertices as corners, whether some point of it does (a linear
    /// function's largest value over a polygon is at a vertex); its weight is its `P(S)`.
    pub(super) fn choose_from(&self, v: &Vertex, cdf: &mut Vec<f64>) -> bool {
        cdf.clear();
        let mut acc = 0.0;
        let own = self.of_face[v.tri];
        for (j, m) in self.list.iter().enumerate() {
            let lit = j as u32 != own && dot(v.p - m.at, m.n) > 0.0;
            let w = if lit
                && m.corners.iter().any(|&q| dot(q - v.p, v.ng) > 0.0)
                && m.corners.iter().any(|&q| dot(v.p - q, m.r) > 0.0)
            {
                m.p
            } else {
                0.0
            };
            acc += w;
            cdf.push(acc);
        }
        if acc <= 0.0 || acc.is_nan() {
            cdf.clear();
            return false;
        }
        for c in cdf.iter_mut() {
            *c /= acc;
        }
        true
    }

    /// The candidate drawn by the uniform `u` from the cumulative probabilities `cdf`
    /// ([`Mirrors::choose_from`]).
    pub(super) fn pick(cdf: &[f64], u: f64) -> usize {
        // (past a run of zero-probability candidates, as `u < 1` always is)
        cdf.partition_point(|&c| c <= u).min(cdf.len() - 1)
    }

    /// Candidate `j`'s probability in `cdf` ([`Mirrors::choose_from`]).
    fn probability(cdf: &[f64], j: usize) -> f64 {
        cdf[j] - if j > 0 { cdf[j - 1] } else { 0.0 }
    }

    /// The aiming density (per unit solid angle at the middle surface whose choice is
    /// `cdf`, [`Mirrors::choose_from`]; none when empty) of the direction `d` toward the
    /// surface `v` lies on, or 0 when `v` is not a candidate met on its lit side.
    pub(super) fn density(&self, cdf: &[f64], v: &Vertex, d: V3, wi: V3) -> f64 {
        let j = self.of_face[v.tri];
        if j == u32::MAX || cdf.is_empty() {
            return 0.0;
        }
        let m = &self.list[j as usize];
        if dot(v.ng, m.n) <= 0.0 {
            return 0.0;
        }
        let p = Mirrors::probability(cdf, j as usize);
        if p <= 0.0 {
            return 0.0;
        }
        p * mirror_pdf(m, wi, d)
    }
}

/// The density of the direction `d` (toward the mirror) drawn by aiming at `m`: that of
/// its reflection of `wi`, `-d`, about a normal drawn from its distribution.
pub(super) fn mirror_pdf(m: &Mirror, wi: V3, d: V3) -> f64 {
    pdf(&m.lobe, m.n, wi, -d)
}

/// The aimed 3-bounce path from the middle surface `v` whose choice of mirrors is `cdf`
/// ([`Mirrors::choose_from`], not empty) (its throughput part `(M, x_out)`:
/// `f_v(d, w_out) cos / pdf L f_3(wi, -d) cos_i`, weighted by the balance heuristic against
/// `v`'s own `lobes`, in the bases `x_out` (normal to `w_out`) and the returned `x_in`
/// (normal to `wi`)), and the path's length from `v` on (`|p3 - v| - p3 . wi`); `None` when
/// the aimed ray misses its mirror or the mirror is shadowed (`Mirrors`).
#[allow(clippy::too_many_arguments)]
pub(super) fn aim(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    mirrors: &Mirrors,
    v: &Vertex,
    w_out: V3,
    lobes: &Lobes,
    cdf: &[f64],
    [u_pick, u1, u2]: [f64; 3],
) -> Option<((Mat4, V3), V3, f64)> {
    let wi = setup.wi;
    let j = Mirrors::pick(cdf, u_pick);
    let m = &mirrors.list[j];
    // the light leaving the mirror about its specular direction, and the way to it
    let d = -sample(&m.lobe, m.n, wi, [0.0, u1, u2])?;
    if dot(d, v.ng) <= 0.0 || dot(d, v.n) <= 0.0 {
        return None;
    }
    let p3 = posed.trace(v.p + posed.eps * v.ng, d)?;
    if mirrors.of_face[p3.tri] != j as u32
        || dot(p3.ng, m.n) <= 0.0
        || dot(p3.n, -d) <= 0.0
        || !posed.sees(&p3, wi)
    {
        return None;
    }
    let pdf_aim = Mirrors::probability(cdf, j) * mirror_pdf(m, wi, d);
    let pdf_lobe = pdf(lobes, v.n, w_out, d);
    if pdf_aim <= 0.0 || pdf_aim.is_nan() {
        return None;
    }
    let f = brdf.eval(v.mat, v.n, d, w_out);
    let g = brdf.eval(p3.mat, p3.n, wi, -d);
    let fm = scale(&f.m, dot(v.n, d) / (pdf_aim + pdf_lobe));
    let gm = scale(&g.m, dot(p3.n, wi));
    let m = chain(&fm, f.x_in, &gm, g.x_out, -d);
    Some(((m, f.x_out), g.x_in, (p3.p - v.p).length() - dot(p3.p, wi)))
}
