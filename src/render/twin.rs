//! CPU twins of the kernels, in f64: `visibility` (of `shaders/visibility.wgsl`) by
//! rasterizing pixel centres exactly, `shade_pixel` and `render_cpu` (of
//! `shaders/shade.wgsl`) with any BRDF: the material's tables (what the GPU uses) or the
//! exact core evaluation. The Stokes bases here come from [`crate::optics::frames`]'s
//! `beam_bases` in a local frame (the kernel builds them from cross products), so the
//! comparison also checks the frame handling. Transmitter cast shadows (bistatic) are
//! decided here by exact ray casting in f64 ([`shadowed`]), independently of the kernel's
//! shadow-map rule. Conventions: [`crate::render`].

use super::geometry::{rotate, transmitter_rotation, Mesh, Rot};
use super::gpu::{Layout, Outputs, Rendered, SensorSetup};
use super::pulse;
use crate::optics::frames::{beam_bases, change_bases, cross, dot, normalize, Frame, V3};
use crate::optics::mueller::Mat4;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Triangle index + 1 seen at each pixel centre (0: empty), row-major `width x width`.
/// Ties (a centre on a shared edge) may resolve differently from the GPU's rasterizer.
pub fn visibility(mesh: &Mesh, rot: &Rot, width: usize, ext: f64) -> Vec<u32> {
    visibility_at(mesh, rot, width, ext, [0.5, 0.5])
}

/// Triangle index + 1 seen at the point `(u, v)` of each pixel (pixel units from its
/// top-left corner, `v` down the rows: `X = -ext + (j + u) delta`, `Y = ext - (i + v)
/// delta`), row-major `width x width` (0: empty). Twin of `shaders/visibility.wgsl` for
/// one visibility sample ([`crate::render::gpu::sample_offsets`]).
pub fn visibility_at(mesh: &Mesh, rot: &Rot, width: usize, ext: f64, uv: [f64; 2]) -> Vec<u32> {
    rasterize(&project(mesh, rot), width, ext, uv)
}

/// A triangle seen from the telescope at one attitude: its rotated corners, the projected
/// signed area `den` (twice the area in `x, y`; > 0 facing the telescope on an
/// outward-wound mesh) and its bounding box `[x min, x max, y min, y max]`.
pub struct Projected {
    p: [V3; 3],
    den: f64,
    bbox: [f64; 4],
}

/// Every triangle of `mesh` at attitude `rot`, in face order (what [`rasterize`] draws for
/// each visibility sample); `None` for triangles edge-on to the telescope and, on a closed
/// outward-wound mesh ([`Mesh::closed`]), for back faces, which the nearest hit from
/// outside never is (the kernel's raster pass culls them too).
pub fn project(mesh: &Mesh, rot: &Rot) -> Vec<Option<Projected>> {
    mesh.faces
        .iter()
        .map(|f| {
            let p = f.map(|k| rotate(rot, mesh.vertices[k as usize]));
            let den = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
            if den == 0.0 || (mesh.closed && den < 0.0) {
                return None;
            }
            let xs = p.map(|v| v[0]);
            let ys = p.map(|v| v[1]);
            let bbox = [
                xs.iter().copied().fold(f64::INFINITY, f64::min),
                xs.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                ys.iter().copied().fold(f64::INFINITY, f64::min),
                ys.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            ];
            Some(Projected { p, den, bbox })
        })
        .collect()
}

/// Triangle index + 1 nearest the telescope at the point `(u, v)` of each pixel (as
/// [`visibility_at`]), from the projected triangles of [`project`].
pub fn rasterize(tris: &[Option<Projected>], width: usize, ext: f64, uv: [f64; 2]) -> Vec<u32> {
    let pix = 2.0 * ext / width as f64;
    let [u, v] = uv;
    let mut ids = vec![0u32; width * width];
    let mut depth = vec![f64::NEG_INFINITY; width * width];
    for (t, tri) in tris.iter().enumerate() {
        let Some(Projected { p, den, bbox }) = tri else {
            continue;
        };
        let den = *den;
        let [xmin, xmax, ymin, ymax] = *bbox;
        let j0 = (((xmin + ext) / pix - u).ceil().max(0.0)) as usize;
        let j1 = (((xmax + ext) / pix - u).floor().min(width as f64 - 1.0)) as isize;
        let i0 = (((ext - ymax) / pix - v).ceil().max(0.0)) as usize;
        let i1 = (((ext - ymin) / pix - v).floor().min(width as f64 - 1.0)) as isize;
        if j1 < 0 || i1 < 0 {
            continue;
        }
        for i in i0..=(i1 as usize) {
            let y = ext - (i as f64 + v) * pix;
            for j in j0..=(j1 as usize) {
                let x = -ext + (j as f64 + u) * pix;
                let (dx, dy) = (x - p[0][0], y - p[0][1]);
                let l1 = (dx * (p[2][1] - p[0][1]) - dy * (p[2][0] - p[0][0])) / den;
                let l2 = ((p[1][0] - p[0][0]) * dy - (p[1][1] - p[0][1]) * dx) / den;
                let l0 = 1.0 - l1 - l2;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                let z = l0 * p[0][2] + l1 * p[1][2] + l2 * p[2][2];
                let k = i * width + j;
                if z > depth[k] {
                    depth[k] = z;
                    ids[k] = t as u32 + 1;
                }
            }
        }
    }
    ids
}

/// A pixel's shading result.
#[derive(Debug, Clone, Copy)]
pub struct PixelSample {
    /// Differential cross-section, Mueller in the telescope bases (m^2).
    pub mueller: Mat4,
    pub range: f64,
    /// Sub-pixel range widths `(a, b)` (m).
    pub widths: (f64, f64),
    /// The shaded point (telescope frame, m).
    pub point: V3,
}

/// `brdf(material, wi_local, wo_local)`: the Mueller BRDF in the `Sp` frame, local `n = z`.
pub type BrdfFn<'a> = dyn Fn(usize, V3, V3) -> Mat4 + Sync + 'a;

/// Shade pixel `(row, col)` whose centre sees triangle `tri` (f64 twin of `shade.wgsl`).
#[allow(clippy::too_many_arguments)]
pub fn shade_pixel(
    mesh: &Mesh,
    rot: &Rot,
    tri: usize,
    row: usize,
    col: usize,
    lay: &Layout,
    beta: f64,
    brdf: &BrdfFn<'_>,
) -> Option<PixelSample> {
    let x = -lay.ext + (col as f64 + 0.5) * lay.pix;
    let y = lay.ext - (row as f64 + 0.5) * lay.pix;
    shade_point(mesh, rot, tri, x, y, lay, beta, brdf)
}

/// Shade the point `(x, y)` (telescope frame, m) of triangle `tri`: the differential
/// cross-section of a whole pixel there, with its range and the pixel's footprint widths
/// (f64 twin of `shade_at` in `shade.wgsl`); `None` if `tri` is degenerate in projection.
#[allow(clippy::too_many_arguments)]
pub fn shade_point(
    mesh: &Mesh,
    rot: &Rot,
    tri: usize,
    x: f64,
    y: f64,
    lay: &Layout,
    beta: f64,
    brdf: &BrdfFn<'_>,
) -> Option<PixelSample> {
    let f = mesh.faces[tri];
    let p = f.map(|k| rotate(rot, mesh.vertices[k as usize]));
    let den = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
    if den == 0.0 {
        return None;
    }
    let (dx, dy) = (x - p[0][0], y - p[0][1]);
    let l1 = (dx * (p[2][1] - p[0][1]) - dy * (p[2][0] - p[0][0])) / den;
    let l2 = ((p[1][0] - p[0][0]) * dy - (p[1][1] - p[0][1]) * dx) / den;
    let l0 = 1.0 - l1 - l2;
    let z = l0 * p[0][2] + l1 * p[1][2] + l2 * p[2][2];
    let wi = [beta.sin(), 0.0, beta.cos()];
    let wo = [0.0, 0.0, 1.0];
    let s = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
    let range = -0.5 * dot([x, y, z], s);
    let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
    let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
    let mut ng = normalize(cross(e1, e2));
    if ng[2] < 0.0 {
        ng = [-ng[0], -ng[1], -ng[2]];
    }
    let nz = ng[2].max(1e-12);
    let (dzdx, dzdy) = (-ng[0] / nz, -ng[1] / nz);
    let a = (0.5 * (s[0] + s[2] * dzdx)).abs() * lay.pix;
    let b = (0.5 * (s[1] + s[2] * dzdy)).abs() * lay.pix;
    let widths = (a.min(lay.max_extent), b.min(lay.max_extent));
    let mut n = ng;
    if let Some(ns) = &mesh.normals {
        let c = f.map(|k| ns[k as usize]);
        let v = [0, 1, 2].map(|d| l0 * c[0][d] + l1 * c[1][d] + l2 * c[2][d]);
        let v = rotate(rot, v);
        let l = dot(v, v).sqrt();
        if l > 1e-15 {
            n = [v[0] / l, v[1] / l, v[2] / l];
            if dot(n, ng) < 0.0 {
                n = [-n[0], -n[1], -n[2]];
            }
        }
    }
    let (ci, co) = (dot(n, wi), dot(n, wo));
    let zero = PixelSample {
        mueller: [[0.0; 4]; 4],
        range,
        widths,
        point: [x, y, z],
    };
    if ci <= 0.0 || co <= 0.0 {
        return Some(zero);
    }
    // local frame (t1, t2, n)
    let helper = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let t1 = normalize(cross(helper, n));
    let t2 = cross(n, t1);
    let to_local = |v: V3| [dot(v, t1), dot(v, t2), dot(v, n)];
    let to_world = |v: V3| {
        [
            v[0] * t1[0] + v[1] * t2[0] + v[2] * n[0],
            v[0] * t1[1] + v[1] * t2[1] + v[2] * n[1],
            v[0] * t1[2] + v[1] * t2[2] + v[2] * n[2],
        ]
    };
    let (wil, wol) = (to_local(wi), to_local(wo));
    let mat = mesh.face_material[tri] as usize;
    let m_sp = brdf(mat, wil, wol);
    let (xi, yi, xo, yo) = beam_bases(Frame::Sp, wil, wol);
    let (xi, yi, xo, yo) = (to_world(xi), to_world(yi), to_world(xo), to_world(yo));
    // telescope bases
    let k_in = [-wi[0], -wi[1], -wi[2]];
    let xit = normalize(cross(k_in, [0.0, 1.0, 0.0]));
    let yit = cross(k_in, xit);
    let (xot, yot) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
    let mt = change_bases(&m_sp, (xi, yi, xo, yo), (xit, yit, xot, yot));
    let k = 4.0 * PI * ci * lay.pix * lay.pix;
    let mut out = [[0.0; 4]; 4];
    for r in 0..4 {
        for c in 0..4 {
            out[r][c] = k * mt[r][c];
        }
    }
    Some(PixelSample {
        mueller: out,
        range,
        widths,
        point: [x, y, z],
    })
}

/// The mesh seen from the transmitter (frame `R_tx = R_y(-beta) R`, `wi` along `+z`):
/// every triangle's vertices and its projected bounding box, for [`shadowed`].
pub struct TransmitterView {
    beta: f64,
    tris: Vec<[V3; 3]>,
    /// `[xmin, xmax, ymin, ymax]` per triangle.
    boxes: Vec<[f64; 4]>,
    /// Hits closer than this along `wi` (m) are ignored (`1e-9 ext`).
    offset: f64,
}

impl TransmitterView {
    pub fn new(mesh: &Mesh, rot: &Rot, beta: f64) -> Self {
        let r = transmitter_rotation(rot, beta);
        let tris: Vec<[V3; 3]> = mesh
            .faces
            .iter()
            .map(|f| f.map(|k| rotate(&r, mesh.vertices[k as usize])))
            .collect();
        let boxes = tris
            .iter()
            .map(|t| {
                let (x, y) = (t.map(|v| v[0]), t.map(|v| v[1]));
                [
                    x[0].min(x[1]).min(x[2]),
                    x[0].max(x[1]).max(x[2]),
                    y[0].min(y[1]).min(y[2]),
                    y[0].max(y[1]).max(y[2]),
                ]
            })
            .collect();
        TransmitterView {
            beta,
            tris,
            boxes,
            offset: 1e-9 * mesh.radius,
        }
    }
}

/// Whether the point `p` (telescope frame) of triangle `tri` is in the transmitter's
/// shadow: the side of `tri` the receiver sees faces away from `wi` (geometric normal), or
/// the ray from `p` toward `wi` hits another triangle farther than the offset (`1e-9 ext`)
/// along it. Exact ray casting in f64 against every triangle (the geometric truth the
/// kernel's shadow-map rule approximates, see `shaders/shade.wgsl`).
pub fn shadowed(view: &TransmitterView, tri: usize, p: V3) -> bool {
    let (s, c) = view.beta.sin_cos();
    // transmitter frame: wi = +z, wo = (-sin beta, 0, cos beta)
    let t = &view.tris[tri];
    let e1 = [0, 1, 2].map(|d| t[1][d] - t[0][d]);
    let e2 = [0, 1, 2].map(|d| t[2][d] - t[0][d]);
    let ng = cross(e1, e2);
    let toward_rx = -s * ng[0] + c * ng[2];
    if ng[2] * toward_rx.signum() <= 0.0 {
        return true;
    }
    let q = [c * p[0] - s * p[2], p[1], s * p[0] + c * p[2]];
    for (u, (t, b)) in view.tris.iter().zip(&view.boxes).enumerate() {
        if u == tri || q[0] < b[0] || q[0] > b[1] || q[1] < b[2] || q[1] > b[3] {
            continue;
        }
        let den =
            (t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[1][1] - t[0][1]) * (t[2][0] - t[0][0]);
        if den == 0.0 {
            continue;
        }
        let (dx, dy) = (q[0] - t[0][0], q[1] - t[0][1]);
        let l1 = (dx * (t[2][1] - t[0][1]) - dy * (t[2][0] - t[0][0])) / den;
        let l2 = ((t[1][0] - t[0][0]) * dy - (t[1][1] - t[0][1]) * dx) / den;
        let l0 = 1.0 - l1 - l2;
        if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
            continue;
        }
        let z = l0 * t[0][2] + l1 * t[1][2] + l2 * t[2][2];
        if z > q[2] + view.offset {
            return true;
        }
    }
    false
}

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
    let n_s = offsets.len() as f64;
    // (id, count, sum u, sum v, [min u, max u, min v, max v])
    #[allow(clippy::type_complexity)]
    let mut groups: Vec<(u32, usize, f64, f64, [f64; 4])> = Vec::new();
    for (s_ids, uv) in ids.iter().zip(offsets) {
        let id = s_ids[pixel];
        if id == 0 {
            continue;
        }
        let surf = surfaces[id as usize - 1];
        match groups
            .iter_mut()
            .find(|g| surfaces[g.0 as usize - 1] == surf)
        {
            Some(g) => {
                g.1 += 1;
                g.2 += uv[0];
                g.3 += uv[1];
                g.4 = [
                    g.4[0].min(uv[0]),
                    g.4[1].max(uv[0]),
                    g.4[2].min(uv[1]),
                    g.4[3].max(uv[1]),
                ];
            }
            None => groups.push((id, 1, uv[0], uv[1], [uv[0], uv[0], uv[1], uv[1]])),
        }
    }
    groups
        .iter()
        .map(|&(id, c, su, sv, e)| Part {
            tri: id as usize - 1,
            frac: c as f64 / n_s,
            centre: [su / c as f64, sv / c as f64],
            span: [e[1] - e[0] + 1.0 / n_s, e[3] - e[2] + 1.0 / n_s],
        })
        .collect()
}

// Analytic coverage (twin of `coverage_parts` and the COVERAGE branch of `shade.wgsl`,
// with the kernel's capacities, in f64).
const CLIP_VERTS: usize = 10;
const MAX_PIECES: usize = 8;
const MAX_QUEUE: usize = 64;
const MAX_CAND: usize = 32;
const AREA_EPS: f64 = 1e-7;

type Poly = Vec<[f64; 2]>;

fn unit_square() -> Poly {
    vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
}

fn side(a: [f64; 2], d: [f64; 2], s: f64, x: [f64; 2]) -> f64 {
    s * (d[0] * (x[1] - a[1]) - d[1] * (x[0] - a[0]))
}

/// The part of convex `p` where `s cross(d, x - a) >= 0`.
fn clip_edge(p: &Poly, a: [f64; 2], d: [f64; 2], s: f64) -> Poly {
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
fn moments(p: &Poly) -> [f64; 3] {
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
/// `coverage_parts` in `shade.wgsl`): the candidates are the `seeds` and, breadth first, the
/// faces across the edges ([`Mesh::adjacency`]) of every seed and of every candidate that
/// overlaps the pixel (at most `MAX_QUEUE` examined; back faces skipped on closed meshes);
/// those overlapping the pixel (at most `MAX_CAND`) are clipped to it; a visible part is
/// the clip minus every other candidate that overlaps it and is nearer at the centroid of
/// their overlap (ties: the lower index), at most `MAX_PIECES` convex pieces kept. `None` when more than `MAX_QUEUE`
/// triangles were to be examined or more than `MAX_CAND` overlap the pixel.
pub fn coverage_parts(
    mesh: &Mesh,
    rot: &Rot,
    lay: &Layout,
    row: usize,
    col: usize,
    seeds: &[usize],
) -> Option<Vec<Part>> {
    let x0 = -lay.ext + col as f64 * lay.pix;
    let y0 = lay.ext - row as f64 * lay.pix;
    let adj = mesh.adjacency();
    let mut queue: Vec<usize> = seeds.to_vec();
    // (triangle, uv vertices, orientation, vertex depths)
    #[allow(clippy::type_complexity)]
    let mut tris: Vec<(usize, [[f64; 2]; 3], f64, [f64; 3])> = Vec::new();
    let mut qi = 0;
    while qi < queue.len() {
        let t = queue[qi];
        let p = mesh.faces[t].map(|k| rotate(rot, mesh.vertices[k as usize]));
        let uv = p.map(|v| [(v[0] - x0) / lay.pix, (y0 - v[1]) / lay.pix]);
        let e1 = [uv[1][0] - uv[0][0], uv[1][1] - uv[0][1]];
        let e2 = [uv[2][0] - uv[0][0], uv[2][1] - uv[0][1]];
        let den = e1[0] * e2[1] - e1[1] * e2[0];
        // front faces are counter-clockwise in (x, y), so clockwise in (u, v)
        let mut overlaps = den != 0.0 && !(mesh.closed && den > 0.0);
        if overlaps {
            overlaps = moments(&clip_triangle(&unit_square(), &uv, den.signum()))[0] > AREA_EPS;
        }
        if overlaps && tris.len() == MAX_CAND {
            return None;
        }
        if overlaps {
            tris.push((t, uv, den.signum(), [p[0][2], p[1][2], p[2][2]]));
        }
        if overlaps || qi < seeds.len() {
            for &u in &adj[t] {
                let u = u as usize;
                if u < mesh.faces.len() && !queue.contains(&u) {
                    if queue.len() == MAX_QUEUE {
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
                    if next.len() < MAX_PIECES && moments(&outside)[0] > AREA_EPS {
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
/// at its centre; else [`coverage_parts`], or the centre sample alone where that overflows.
pub fn analytic_parts(
    mesh: &Mesh,
    rot: &Rot,
    lay: &Layout,
    ids: &[u32],
    row: usize,
    col: usize,
) -> Vec<Part> {
    let (cand, n_hit) = analytic_seeds(ids, lay.width, row, col);
    if cand.len() == 1 && n_hit == 9 {
        return vec![Part {
            tri: cand[0],
            frac: 1.0,
            centre: [0.5, 0.5],
            span: [1.0, 1.0],
        }];
    }
    coverage_parts(mesh, rot, lay, row, col, &cand).unwrap_or_else(|| {
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
    })
}

/// Working memory of the CPU renderers (the twin and the reference) for attitudes
/// rendered in parallel; fewer run at a time when theirs would exceed it.
pub const CPU_MEMORY_BUDGET: usize = 4 << 30;

/// Bytes one attitude of [`render_cpu`] holds at its peak: the K sample id maps, one depth
/// map while they are drawn, and the requested per-pixel outputs and profile.
pub fn attitude_bytes(
    width: usize,
    samples: usize,
    channels: usize,
    n_bins: usize,
    outputs: Outputs,
) -> usize {
    let px = width * width;
    let mut b = px * (4 * samples + 8);
    if outputs.image {
        b += px * channels * 4;
    }
    if outputs.range {
        b += px * 8;
    }
    if outputs.profile {
        b += n_bins * channels * 8;
    }
    b
}

/// How many attitudes of `bytes` each to render at once on `threads` threads within
/// [`CPU_MEMORY_BUDGET`] (at least one).
pub fn attitudes_at_once(bytes: usize, threads: usize) -> usize {
    (CPU_MEMORY_BUDGET / bytes.max(1)).clamp(1, threads.max(1))
}

/// The whole renderer on the CPU in f64 (twin of `gpu::render`, without supersampling
/// of the image outputs: `sensor.supersampling` must be 1).
pub fn render_cpu(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &BrdfFn<'_>,
) -> Rendered {
    let lay = Layout::new(mesh, sensor);
    let w = lay.width;
    let ch = sensor.channels();
    let nb = lay.n_bins;
    let edges: Vec<f64> = (0..=nb)
        .map(|k| lay.r_min + k as f64 * sensor.bin_width)
        .collect();
    let render_one = |rot: &Rot| {
        let offsets = super::gpu::sample_offsets(sensor.samples);
        let tris = project(mesh, rot);
        let ids: Vec<Vec<u32>> = offsets
            .iter()
            .map(|&uv| rasterize(&tris, w, lay.ext, uv))
            .collect();
        let beta = sensor.bistatic_angle;
        let tx = (beta > 0.0).then(|| TransmitterView::new(mesh, rot, beta));
        // only what is requested is kept (a profile-only batch holds no images)
        let mut img = vec![0.0f32; if outputs.image { w * w * ch } else { 0 }];
        let mut rng = vec![f32::NAN; if outputs.range { w * w } else { 0 }];
        let mut cov = vec![0.0f32; if outputs.range { w * w } else { 0 }];
        let mut prof = vec![0.0f64; if outputs.profile { nb * ch } else { 0 }];
        let mut tot = vec![0.0f64; ch];
        let mut weights = vec![0.0f64; nb];
        for k in 0..w * w {
            // a pixel none of whose samples sees the mesh adds nothing (analytic coverage
            // also looks at the neighbours' centres)
            if !sensor.analytic && ids.iter().all(|s_ids| s_ids[k] == 0) {
                continue;
            }
            let (row, col) = (k / w, k % w);
            let parts = if sensor.analytic {
                analytic_parts(mesh, rot, &lay, &ids[0], row, col)
            } else {
                sampled_parts(&ids, &offsets, mesh.surfaces(), k)
            };
            let (mut cov_sum, mut r_sum) = (0.0f64, 0.0f64);
            let mut pixel = [0.0f64; 16];
            for part in &parts {
                let tri = part.tri;
                let x = -lay.ext + (col as f64 + part.centre[0]) * lay.pix;
                let y = lay.ext - (row as f64 + part.centre[1]) * lay.pix;
                let Some(mut s) = shade_point(mesh, rot, tri, x, y, &lay, beta, brdf) else {
                    continue;
                };
                // cast shadow: the point stays covered (range reported) but returns nothing
                if let Some(tx) = &tx {
                    let lit = s.mueller.iter().flatten().any(|&v| v != 0.0);
                    if lit && shadowed(tx, tri, s.point) {
                        s.mueller = [[0.0; 4]; 4];
                    }
                }
                let frac = part.frac;
                cov_sum += frac;
                r_sum += frac * s.range;
                let mut vals = [0.0f64; 16];
                for (c, v) in vals.iter_mut().enumerate().take(ch) {
                    *v = match sensor.polarization {
                        None => frac * s.mueller[c / 4][c % 4],
                        Some(st) => frac * (0..4).map(|j| s.mueller[c][j] * st[j]).sum::<f64>(),
                    };
                }
                for c in 0..ch {
                    pixel[c] += vals[c];
                }
                if outputs.profile && vals[0] != 0.0 {
                    // the footprint of the part of the pixel it spans (whole: 1)
                    let (a, b) = (part.span[0] * s.widths.0, part.span[1] * s.widths.1);
                    match &sensor.pulse {
                        Some(p) => p.bin_weights(s.range, a, b, &edges, &mut weights),
                        None => pulse::bin_weights_folded(
                            s.range,
                            a,
                            b,
                            sensor.sigma_range,
                            lay.support + 0.5 * (a + b),
                            &edges,
                            &mut weights,
                        ),
                    }
                    for (b, &wt) in weights.iter().enumerate() {
                        if wt != 0.0 {
                            for c in 0..ch {
                                prof[b * ch + c] += wt * vals[c];
                            }
                        }
                    }
                }
            }
            if cov_sum > 0.0 && outputs.range {
                rng[k] = (r_sum / cov_sum) as f32;
                cov[k] = cov_sum as f32;
            }
            for c in 0..ch {
                if outputs.image {
                    img[k * ch + c] = pixel[c] as f32;
                }
                tot[c] += pixel[c];
            }
        }
        (img, rng, prof, tot, cov)
    };
    // attitudes in parallel (at most one per thread at a time), fewer at a time when that
    // many would exceed the memory budget
    let threads = rayon::current_num_threads();
    let at_once = attitudes_at_once(attitude_bytes(w, sensor.samples, ch, nb, outputs), threads);
    #[allow(clippy::type_complexity)]
    let per: Vec<(Vec<f32>, Vec<f32>, Vec<f64>, Vec<f64>, Vec<f32>)> = if at_once >= threads {
        rotations.par_iter().map(render_one).collect()
    } else {
        rotations
            .chunks(at_once)
            .flat_map(|c| c.par_iter().map(render_one).collect::<Vec<_>>())
            .collect()
    };
    let n = rotations.len();
    let cov: Vec<f32> = per.iter().flat_map(|p| p.4.iter().copied()).collect();
    Rendered {
        n,
        height: w,
        width: w,
        channels: ch,
        image: outputs
            .image
            .then(|| per.iter().flat_map(|p| p.0.iter().copied()).collect()),
        range: outputs
            .range
            .then(|| per.iter().flat_map(|p| p.1.iter().copied()).collect()),
        coverage: outputs.range.then_some(cov),
        profile: outputs
            .profile
            .then(|| per.iter().flat_map(|p| p.2.iter().copied()).collect()),
        total: per.iter().flat_map(|p| p.3.iter().copied()).collect(),
        r_min: lay.r_min,
        bin_width: sensor.bin_width,
        n_bins: nb,
        pixel_size: lay.pix,
        extent: lay.ext,
    }
}

/// The exact f64 reference renderer: [`render_cpu`] with every material evaluated by the
/// core ([`crate::brdf::eval`], no tables), at `sensor.supersampling` sub-pixels per pixel
/// side (images summed, range averaged over covered sub-pixels, as `gpu::render` does).
/// Slow (the full model per pixel, double bounce quadrature included): the accuracy
/// reference beside the GPU path.
pub fn render_reference(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    materials: &[std::sync::Arc<crate::brdf::Material>],
) -> Rendered {
    let brdf = |m: usize, wi: V3, wo: V3| crate::brdf::eval(&materials[m], wi, wo, Frame::Sp);
    render_supersampled(mesh, sensor, rotations, outputs, &brdf)
}

/// The kernel's algorithm in f64 on the CPU with the GPU's BRDF tables (their f64
/// originals, [`crate::brdf::table::BrdfTable::eval_dirs`]): what `Lidar(arithmetic="f64")`
/// runs. Against `gpu::render` with the same tables only the arithmetic differs (and, when
/// bistatic, the cast-shadow test: exact rays here, the kernel's shadow map there).
pub fn render_tables(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    tables: &[crate::brdf::table::BrdfTable],
) -> Rendered {
    let brdf = |m: usize, wi: V3, wo: V3| tables[m].eval_dirs(wi, wo);
    render_supersampled(mesh, sensor, rotations, outputs, &brdf)
}

/// [`render_cpu`] at `sensor.supersampling` sub-pixels per pixel side, the images summed
/// and the range averaged over covered sub-pixels to the sensor's pixels (as `gpu::render`).
pub fn render_supersampled(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &BrdfFn<'_>,
) -> Rendered {
    let mut r = render_cpu(mesh, sensor, rotations, outputs, brdf);
    let ss = sensor.supersampling;
    if ss > 1 {
        let (w, res, n, ch) = (r.width, sensor.resolution, r.n, r.channels);
        if let Some(img) = r.image.as_mut() {
            let mut out = vec![0.0f32; n * res * res * ch];
            super::gpu::downsample_sum(img, n, w, ss, ch, &mut out);
            *img = out;
        }
        if let Some(rng) = r.range.as_mut() {
            let mut out = vec![0.0f32; n * res * res];
            let mut cov = vec![0.0f32; n * res * res];
            let c0 = r.coverage.take().expect("coverage with the range");
            super::gpu::downsample_range(rng, &c0, n, w, ss, &mut out, &mut cov);
            *rng = out;
            r.coverage = Some(cov);
        }
        r.height = res;
        r.width = res;
        r.pixel_size *= ss as f64;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_renderers_stay_within_the_memory_budget() {
        let all = Outputs {
            image: true,
            range: true,
            profile: true,
        };
        // 128 x 128, 8 samples, Mueller: ids 32, depth 8, image 64, range + coverage 8
        // bytes per pixel, and the profile
        let b = attitude_bytes(128, 8, 16, 100, all);
        assert_eq!(b, 128 * 128 * (4 * 8 + 8 + 16 * 4 + 8) + 100 * 16 * 8);
        assert_eq!(attitudes_at_once(b, 16), 16); // small: one per thread
        let profile_only = Outputs {
            image: false,
            range: false,
            profile: true,
        };
        assert_eq!(
            attitude_bytes(128, 8, 16, 100, profile_only),
            128 * 128 * 40 + 100 * 16 * 8
        );
        // the largest image side at 16 samples (8192^2 x 144 bytes, 9.7 GB): one at a time
        let big = attitude_bytes(8192, 16, 16, 1000, all);
        assert!(big > CPU_MEMORY_BUDGET);
        assert_eq!(attitudes_at_once(big, 16), 1);
        // in between: as many as fit
        assert_eq!(attitudes_at_once(CPU_MEMORY_BUDGET / 3 + 1, 16), 2);
        assert_eq!(attitudes_at_once(1, 0), 1);
    }

    /// Back faces of a closed, outward-wound mesh are never the nearest hit: culling them
    /// (what `project` does when `Mesh::closed`) leaves every pixel's visible triangle as
    /// it was, and the faces it drops are about half of them.
    #[test]
    fn culling_back_faces_of_closed_meshes_changes_no_pixel() {
        let closed = crate::render::gpu::tests::uv_sphere(0.5, 24, 48);
        assert!(closed.closed);
        let mut open = closed.clone();
        open.closed = false;
        let rot = crate::render::geometry::rotations_from_quaternions(&[
            [0.9, 0.3, -0.2, 0.25].map(|x: f64| x / (0.81f64 + 0.09 + 0.04 + 0.0625).sqrt())
        ])
        .unwrap()[0];
        let (tc, to) = (project(&closed, &rot), project(&open, &rot));
        let kept = tc.iter().filter(|t| t.is_some()).count();
        assert!(kept < to.iter().filter(|t| t.is_some()).count() * 6 / 10 && kept > 0);
        for uv in [[0.5, 0.5], [0.1875, 0.8125]] {
            let (a, b) = (rasterize(&tc, 96, 0.5, uv), rasterize(&to, 96, 0.5, uv));
            assert!(a.iter().filter(|&&id| id != 0).count() > 5000);
            assert_eq!(a, b);
        }
    }
}
