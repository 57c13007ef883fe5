//! A pixel's parts: the triangles that share its area, each with its fraction, shading
//! point and span. From `K` visibility samples ([`sampled_parts`], twin of the K > 1 loop
//! of `shaders/shade.wgsl`) or by analytic coverage ([`analytic_parts`]: exact polygon
//! clipping in depth order, twin of `coverage_parts` there).

use crate::optics::frames::V3;
use crate::render::api::Layout;
use crate::render::geometry::Mesh;

/// One part of a pixel: a triangle, the fraction of the pixel's area it covers, the point
/// `(u, v)` of the pixel where it is shaded (pixel units from the top-left corner, `v` down
/// the rows) and the extent `(u, v)` of the pixel it spans (1, 1 for a whole pixel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Part {
    pub tri: usize,
    pub frac: f64,
    pub centre: [f64; 2],
    pub span: [f64; 2],
}

/// A pixel's parts from its K visibility samples (`ids[k]` the sample-`k` id map, `offsets`
/// the samples' points, `surfaces` [`Mesh::surfaces`]): the samples grouped by the flat
/// surface they see, in the order of their first sample; each group is shaded on the
/// triangle its first sample sees, covers `c / K` of the pixel, is shaded at the mean of
/// its points and spans their extent plus `1 / K` (twin of the K > 1 loop of `shade.wgsl`).
pub fn sampled_parts(
    ids: &[Vec<u32>],
    offsets: &[[f64; 2]],
    surfaces: &[u32],
    pixel: usize,
) -> Vec<Part> {
    let mut out = Vec::new();
    sampled_parts_into(ids, offsets, surfaces, pixel, &mut out);
    out
}

/// [`sampled_parts`] into `out` (cleared first; no allocation once it has the capacity).
pub fn sampled_parts_into(
    ids: &[Vec<u32>],
    offsets: &[[f64; 2]],
    surfaces: &[u32],
    pixel: usize,
    out: &mut Vec<Part>,
) {
    let n_s = offsets.len() as f64;
    out.clear();
    if let [uv] = offsets {
        // one sample: the whole pixel (the same as grouping one sample)
        let id = ids[0][pixel];
        if id != 0 {
            out.push(Part {
                tri: id as usize - 1,
                frac: 1.0,
                centre: *uv,
                span: [1.0, 1.0],
            });
        }
        return;
    }
    // while grouping: `frac` holds the count, `centre` the sums of the points, and
    // `extent` each group's [min u, max u, min v, max v]
    let mut extent = [[0.0f64; 4]; 16];
    for (s_ids, uv) in ids.iter().zip(offsets) {
        let id = s_ids[pixel];
        if id == 0 {
            continue;
        }
        let surf = surfaces[id as usize - 1];
        match out.iter().position(|g| surfaces[g.tri] == surf) {
            Some(g) => {
                let p = &mut out[g];
                p.frac += 1.0;
                p.centre = [p.centre[0] + uv[0], p.centre[1] + uv[1]];
                let e = &mut extent[g];
                *e = [
                    e[0].min(uv[0]),
                    e[1].max(uv[0]),
                    e[2].min(uv[1]),
                    e[3].max(uv[1]),
                ];
            }
            None => {
                extent[out.len()] = [uv[0], uv[0], uv[1], uv[1]];
                out.push(Part {
                    tri: id as usize - 1,
                    frac: 1.0,
                    centre: *uv,
                    span: [0.0; 2],
                });
            }
        }
    }
    for (p, e) in out.iter_mut().zip(&extent) {
        let c = p.frac;
        p.centre = [p.centre[0] / c, p.centre[1] / c];
        p.frac = c / n_s;
        p.span = [e[1] - e[0] + 1.0 / n_s, e[3] - e[2] + 1.0 / n_s];
    }
}

// Analytic coverage (twin of `coverage_parts` and the COVERAGE branch of `shade.wgsl`,
// with the kernel's capacities, in f64).
const CLIP_VERTS: usize = 10;
const AREA_EPS: f64 = 1e-7;

/// How much [`coverage_parts`] may examine: triangles queued, candidates overlapping the
/// pixel, convex pieces kept per visible part.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Capacity {
    pub queue: usize,
    pub cand: usize,
    pub pieces: usize,
}

/// The kernel's capacities (`shade.wgsl`'s arrays), which its twin keeps.
pub const KERNEL_CAPACITY: Capacity = Capacity {
    queue: 64,
    cand: 32,
    pieces: 8,
};

/// [`thin_parts`]'s (CPU only): a thin cylinder of 16 sides in an open mesh lists all its
/// 32 side triangles, back faces included, beside what the samples see; the kernel's
/// capacities overflowed there and the pixel fell back to its samples (3/8 of a pixel for
/// a wire covering a quarter of it).
pub const THIN_CAPACITY: Capacity = Capacity {
    queue: 1024,
    cand: 512,
    pieces: 64,
};

type Poly = Vec<[f64; 2]>;

fn unit_square() -> Poly {
    vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
}

fn side(a: [f64; 2], d: [f64; 2], s: f64, x: [f64; 2]) -> f64 {
    s * (d[0] * (x[1] - a[1]) - d[1] * (x[0] - a[0]))
}

/// The part of convex `p` where `s cross(d, x - a) >= 0`.
pub(crate) fn clip_edge(p: &Poly, a: [f64; 2], d: [f64; 2], s: f64) -> Poly {
    let mut out = Vec::with_capacity(CLIP_VERTS);
    if p.len() < 3 {
        return out;
    }
    let mut prev = p[p.len() - 1];
    let mut fp = side(a, d, s, prev);
    for &cur in p {
        let fc = side(a, d, s, cur);
        if ((fc > 0.0 && fp < 0.0) || (fc < 0.0 && fp > 0.0)) && out.len() < CLIP_VERTS {
            let t = fp / (fp - fc);
            out.push([
                prev[0] + t * (cur[0] - prev[0]),
                prev[1] + t * (cur[1] - prev[1]),
            ]);
        }
        if fc >= 0.0 && out.len() < CLIP_VERTS {
            out.push(cur);
        }
        prev = cur;
        fp = fc;
    }
    out
}

/// Whether convex `p` lies on the outer side (or on the line, within 1e-5 pixel) of one of
/// the edges of triangle `t` (orientation `s`).
fn separated(p: &Poly, t: &[[f64; 2]; 3], s: f64) -> bool {
    (0..3).any(|k| {
        let (a, b) = (t[k], t[(k + 1) % 3]);
        let d = [b[0] - a[0], b[1] - a[1]];
        let tol = 1e-5 * (d[0] * d[0] + d[1] * d[1]).sqrt();
        p.iter().all(|&v| side(a, d, s, v) <= tol)
    })
}

/// Depth at `c` of the plane through the triangle with pixel coordinates `t`, depths `z`.
fn plane_depth(t: &[[f64; 2]; 3], z: [f64; 3], c: [f64; 2]) -> f64 {
    let e1 = [t[1][0] - t[0][0], t[1][1] - t[0][1]];
    let e2 = [t[2][0] - t[0][0], t[2][1] - t[0][1]];
    let d = [c[0] - t[0][0], c[1] - t[0][1]];
    let den = e1[0] * e2[1] - e1[1] * e2[0];
    let l1 = (d[0] * e2[1] - d[1] * e2[0]) / den;
    let l2 = (e1[0] * d[1] - e1[1] * d[0]) / den;
    z[0] + l1 * (z[1] - z[0]) + l2 * (z[2] - z[0])
}

/// The part of convex `p` inside triangle `t` (orientation `s`).
fn clip_triangle(p: &Poly, t: &[[f64; 2]; 3], s: f64) -> Poly {
    let mut out = p.clone();
    for k in 0..3 {
        let (a, b) = (t[k], t[(k + 1) % 3]);
        out = clip_edge(&out, a, [b[0] - a[0], b[1] - a[1]], s);
    }
    out
}

/// (area, area-weighted u, area-weighted v) of a polygon.
pub(crate) fn moments(p: &Poly) -> [f64; 3] {
    if p.len() < 3 {
        return [0.0; 3];
    }
    let mut m = [0.0; 3];
    for k in 0..p.len() {
        let (a, b) = (p[k], p[(k + 1) % p.len()]);
        let c = a[0] * b[1] - b[0] * a[1];
        m[0] += c;
        m[1] += (a[0] + b[0]) * c;
        m[2] += (a[1] + b[1]) * c;
    }
    [0.5 * m[0], m[1] / 6.0, m[2] / 6.0]
}

/// The parts of pixel `(row, col)` under exact hidden-surface clipping (twin of
/// `coverage_parts` in `shade.wgsl`): the candidates are the `seeds`, the `listed` faces
/// (the pixel's thin faces, [`crate::render::thin::ThinPixels`]; those already seeds
/// skipped) and, breadth first, the faces across the edges ([`Mesh::adjacency`]) of every
/// seed and of every other candidate that overlaps the pixel, not of the listed ones (their
/// neighbours are listed where thin, found from the seeds where not; at most `cap.queue`
/// examined; back faces of closed components skipped, [`Mesh::face_closed`]);
/// those overlapping the pixel (at most `cap.cand`) are clipped to it; a visible part is
/// the clip minus every other candidate that overlaps it and is nearer at the centroid of
/// their overlap (ties: the lower index), at most `cap.pieces` convex pieces kept. `None`
/// when more than `cap.queue` triangles were to be examined or more than `cap.cand` overlap
/// the pixel ([`KERNEL_CAPACITY`] as the kernel; [`THIN_CAPACITY`] for [`thin_parts`]).
/// `vertices`: the mesh's vertices at the attitude
/// ([`rotate_vertices`](super::rotate_vertices)).
#[allow(clippy::too_many_arguments)]
pub fn coverage_parts(
    mesh: &Mesh,
    vertices: &[V3],
    lay: &Layout,
    row: usize,
    col: usize,
    seeds: &[usize],
    listed: &[u32],
    cap: Capacity,
) -> Option<Vec<Part>> {
    let x0 = -lay.ext + col as f64 * lay.pix;
    let y0 = lay.ext - row as f64 * lay.pix;
    let adj = mesh.adjacency();
    let mut queue: Vec<usize> = seeds.to_vec();
    for &t in listed {
        if !queue.contains(&(t as usize)) {
            if queue.len() == cap.queue {
                return None;
            }
            queue.push(t as usize);
        }
    }
    let n_listed = queue.len();
    // (triangle, uv vertices, orientation, vertex depths)
    #[allow(clippy::type_complexity)]
    let mut tris: Vec<(usize, [[f64; 2]; 3], f64, [f64; 3])> = Vec::new();
    let mut qi = 0;
    while qi < queue.len() {
        let t = queue[qi];
        let p = mesh.faces[t].map(|k| vertices[k as usize]);
        let uv = p.map(|v| [(v[0] - x0) / lay.pix, (y0 - v[1]) / lay.pix]);
        let e1 = [uv[1][0] - uv[0][0], uv[1][1] - uv[0][1]];
        let e2 = [uv[2][0] - uv[0][0], uv[2][1] - uv[0][1]];
        let den = e1[0] * e2[1] - e1[1] * e2[0];
        // front faces are counter-clockwise in (x, y), so clockwise in (u, v)
        let mut overlaps = den != 0.0 && !(mesh.face_closed[t] && den > 0.0);
        if overlaps {
            overlaps = moments(&clip_triangle(&unit_square(), &uv, den.signum()))[0] > AREA_EPS;
        }
        if overlaps && tris.len() == cap.cand {
            return None;
        }
        if overlaps {
            tris.push((t, uv, den.signum(), [p[0][2], p[1][2], p[2][2]]));
        }
        if qi < seeds.len() || (overlaps && qi >= n_listed) {
            for &u in &adj[t] {
                let u = u as usize;
                if u < mesh.faces.len() && !queue.contains(&u) {
                    if queue.len() == cap.queue {
                        return None;
                    }
                    queue.push(u);
                }
            }
        }
        qi += 1;
    }
    // each visible part: the clip minus every candidate that overlaps it and is nearer at
    // the centroid of the overlap (ties: the lower index), unless one of that one's edges
    // separates them
    let mut parts = Vec::new();
    for &(t, uv, s, zt) in &tris {
        let base = clip_triangle(&unit_square(), &uv, s);
        let mut pieces = vec![base.clone()];
        for &(tj, uj, sj, zj) in &tris {
            if pieces.is_empty() {
                break;
            }
            if tj == t || separated(&base, &uj, sj) {
                continue;
            }
            let mo = moments(&clip_triangle(&base, &uj, sj));
            if mo[0] <= AREA_EPS {
                continue;
            }
            let c = [mo[1] / mo[0], mo[2] / mo[0]];
            let (di, dj) = (plane_depth(&uv, zt, c), plane_depth(&uj, zj, c));
            if dj < di || (dj == di && tj > t) {
                continue;
            }
            let mut next = Vec::new();
            for piece in &pieces {
                let mut cur = piece.clone();
                for k in 0..3 {
                    if cur.len() < 3 {
                        break;
                    }
                    let (a, b) = (uj[k], uj[(k + 1) % 3]);
                    let d = [b[0] - a[0], b[1] - a[1]];
                    let outside = clip_edge(&cur, a, d, -sj);
                    if next.len() < cap.pieces && moments(&outside)[0] > AREA_EPS {
                        next.push(outside);
                    }
                    cur = clip_edge(&cur, a, d, sj);
                }
            }
            pieces = next;
        }
        let (mut vis, mut lo, mut hi) = ([0.0f64; 3], [1.0f64; 2], [0.0f64; 2]);
        for p in &pieces {
            let m = moments(p);
            for i in 0..3 {
                vis[i] += m[i];
            }
            for v in p {
                lo = [lo[0].min(v[0]), lo[1].min(v[1])];
                hi = [hi[0].max(v[0]), hi[1].max(v[1])];
            }
        }
        if vis[0] > AREA_EPS {
            parts.push(Part {
                tri: t,
                frac: vis[0],
                centre: [vis[1] / vis[0], vis[2] / vis[0]],
                span: [
                    (hi[0] - lo[0]).clamp(0.0, 1.0),
                    (hi[1] - lo[1]).clamp(0.0, 1.0),
                ],
            });
        }
    }
    Some(parts)
}

/// The seeds of analytic coverage for pixel `(row, col)` of the centre id map `ids`
/// (`width x width`): the distinct triangles seen at the centres of its 3x3 neighbourhood,
/// in scan order, and how many of the nine centres see a surface.
pub fn analytic_seeds(ids: &[u32], width: usize, row: usize, col: usize) -> (Vec<usize>, usize) {
    let w = width as isize;
    let (mut cand, mut n_hit) = (Vec::new(), 0);
    for dr in -1isize..=1 {
        for dc in -1isize..=1 {
            let (r, c) = (row as isize + dr, col as isize + dc);
            if r < 0 || r >= w || c < 0 || c >= w {
                continue;
            }
            let id = ids[(r * w + c) as usize];
            if id == 0 {
                continue;
            }
            n_hit += 1;
            if !cand.contains(&(id as usize - 1)) {
                cand.push(id as usize - 1);
            }
        }
    }
    (cand, n_hit)
}

/// A pixel's parts under analytic coverage from the centre id map `ids` (`width x width`):
/// the seeds are the distinct triangles seen at the centres of its 3x3 neighbourhood (scan
/// order); one triangle at all nine contains their hull and so is the whole pixel, shaded
/// at its centre (unless the pixel has `thin` faces); else [`coverage_parts`] (with the
/// `thin` faces listed), or the centre sample alone where that overflows (`vertices` as
/// there).
pub fn analytic_parts(
    mesh: &Mesh,
    vertices: &[V3],
    lay: &Layout,
    ids: &[u32],
    row: usize,
    col: usize,
    thin: &[u32],
) -> Vec<Part> {
    let (cand, n_hit) = analytic_seeds(ids, lay.width, row, col);
    if cand.len() == 1 && n_hit == 9 && thin.is_empty() {
        return vec![Part {
            tri: cand[0],
            frac: 1.0,
            centre: [0.5, 0.5],
            span: [1.0, 1.0],
        }];
    }
    coverage_parts(mesh, vertices, lay, row, col, &cand, thin, KERNEL_CAPACITY).unwrap_or_else(
        || {
            // too many triangles: the centre sample, as with one sample per pixel
            match ids[row * lay.width + col] {
                0 => vec![],
                id => vec![Part {
                    tri: id as usize - 1,
                    frac: 1.0,
                    centre: [0.5, 0.5],
                    span: [1.0, 1.0],
                }],
            }
        },
    )
}

/// The parts of a pixel with thin faces (`thin`, [`crate::render::thin::ThinPixels`]) and
/// `K > 1` samples (`ids`; on the CPU for every backend, [`super::add_thin_pixels`]): all
/// of them by exact clipping ([`coverage_parts`] with [`THIN_CAPACITY`]), seeded by the
/// triangles its samples see (and their neighbours across edges) with the thin faces
/// listed. `None` (the caller falls back to the samples) if even those capacities
/// overflow.
///
/// A first version clipped the thin faces alone, against the triangles the samples see,
/// and shared the rest of the pixel among the samples: a thin face behind a surface made
/// of several triangles was counted visible wherever no sample saw the triangle that hid
/// it (the 3U CubeSat's antenna behind the finely triangulated bus: +1.4% in total at an
/// attitude lit only there, where exact clipping is within 2e-4).
pub fn thin_parts(
    mesh: &Mesh,
    vertices: &[V3],
    lay: &Layout,
    ids: &[Vec<u32>],
    pixel: usize,
    thin: &[u32],
) -> Option<Vec<Part>> {
    let (row, col) = (pixel / lay.width, pixel % lay.width);
    let mut seeds: Vec<usize> = Vec::with_capacity(ids.len());
    for s_ids in ids {
        let id = s_ids[pixel] as usize;
        if id != 0 && !seeds.contains(&(id - 1)) {
            seeds.push(id - 1);
        }
    }
    coverage_parts(mesh, vertices, lay, row, col, &seeds, thin, THIN_CAPACITY)
}
