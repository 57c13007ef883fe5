//! Thin parts: surfaces narrower than about a pixel in projection, whose coverage the
//! fixed per-pixel sample pattern aliases (a wire along the image rows is hit by the same
//! samples in every pixel along it, so its coverage error does not average out, and a wire
//! between two rows of samples is not seen at all). Per attitude the CPU finds the thin
//! faces ([`is_thin`]) turned toward the receiver and lists, per pixel, those that overlap
//! it ([`ThinPixels`], exact: each face clipped to each pixel, listed where it covers
//! more than 1e-7 of it).
//! - With `K > 1` samples such a pixel takes all its parts by exact polygon clipping,
//!   seeded by the triangles its samples see (and their neighbours) with its thin faces
//!   listed, with capacities the kernel's arrays do not limit
//!   ([`crate::render::cpu::thin_parts`]). It is shaded on the CPU in f64 for every
//!   backend: the device leaves it empty (`shaders/shade.wgsl`, binding 11) and
//!   [`crate::render::cpu::add_thin_pixels`] adds it, as the same clipping in a kernel of
//!   its own was many times slower on lavapipe.
//! - With analytic coverage the listed faces join the candidates of the kernel's exact
//!   clipping (`coverage_parts` in `shaders/shared/coverage.wgsl`, twin
//!   [`crate::render::cpu::coverage_parts`]).
//! - Where the clipping overflows its capacities, the pixel's samples (or centre) as
//!   before: rarely with `K > 1` ([`crate::render::cpu::coverage::THIN_CAPACITY`]); with
//!   analytic coverage wherever more than 32 triangles overlap a pixel (a fan's apex). The
//!   back faces of closed components ([`crate::render::geometry::Mesh::face_closed`]) are
//!   left out of the lists and the clipping, in open meshes too (a 16-sided wire in an
//!   open mesh listed its back faces and overflowed). One sample per pixel (`"fast"`) is
//!   left as it is.
//!
//! Which faces are thin is decided per face and attitude from a vector computed once per
//! mesh ([`face_thinness`]), `(a_x, a_y, a_z, s)` in the body frame (m):
//! - without vertex normals (flat shading), `a = w n`, `n` the face's unit normal and `w`
//!   the width of its flat surface ([`crate::render::geometry::Mesh::surfaces`]) in its
//!   plane (the least distance between two parallel lines that hold the surface's convex
//!   hull between them), `s = 0`: a planar region of width `w` whose normal is `R n` in the
//!   telescope frame projects to a region of width at least `w |(R n)_z|`;
//! - with vertex normals (smooth shading, each face its own surface), `a = 0` and `s` the
//!   smallest extent of the face's smooth part (the faces joined to it through edges with
//!   its material) along the principal axes of its vertices (a wire's diameter, a
//!   plate's thickness), whatever the attitude.
//!
//! A face is thin at attitude `R` when `|(R a)_z| + s < THIN_PX delta` ([`is_thin`]):
//! whatever its own size, a triangle of a wide panel seen face-on is not thin, and every
//! triangle of the panel is when it is seen nearly edge-on. Limits: the width is that of
//! the convex hull, so a narrow surface bent around a wide hull (a ring, an L) is not
//! found thin; smooth parts are judged by their principal extents.

use crate::optics::frames::V3;
use crate::render::api::Layout;
use crate::render::cpu::coverage::{clip_edge, moments};
use crate::render::geometry::{Mesh, Rot};

/// Width (pixels) under which a part is thin: its pixels take its area exactly.
pub const THIN_PX: f64 = 1.0;

/// A face that is never thin (degenerate surfaces).
const NEVER: [f64; 4] = [0.0, 0.0, 0.0, 1e30];

/// [`face_thinness`] of `mesh`, computed once per mesh and kept in it (a scene rendered
/// again does not compute it again).
pub fn mesh_thinness(mesh: &Mesh) -> &[[f64; 4]] {
    mesh.thinness_cache().get_or_init(|| face_thinness(mesh))
}

/// Per face, `(a_x, a_y, a_z, s)` of the module's test (body frame, m).
pub fn face_thinness(mesh: &Mesh) -> Vec<[f64; 4]> {
    let n_f = mesh.faces.len();
    let corners = |t: usize| mesh.faces[t].map(|k| V3::from(mesh.vertices[k as usize]));
    let normal = |t: usize| -> Option<V3> {
        let p = corners(t);
        let c = (p[1] - p[0]).cross(p[2] - p[0]);
        let l = c.length();
        (l > 0.0 && l.is_finite()).then(|| c / l)
    };
    let mut out = vec![NEVER; n_f];
    if mesh.normals.is_none() {
        // flat surfaces: the width of each surface's hull in its plane
        let surf = mesh.surfaces();
        let mut members: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
        for (t, &s) in surf.iter().enumerate() {
            members.entry(s).or_default().push(t);
        }
        for (&root, faces) in &members {
            let Some(n) = normal(root as usize) else {
                continue;
            };
            let e1 = any_perp(n);
            let e2 = n.cross(e1);
            let pts: Vec<[f64; 2]> = faces
                .iter()
                .flat_map(|&t| corners(t))
                .map(|p| [p.dot(e1), p.dot(e2)])
                .collect();
            let w = hull_width(pts);
            for &t in faces {
                if let Some(nt) = normal(t) {
                    out[t] = [w * nt.x, w * nt.y, w * nt.z, 0.0];
                }
            }
        }
        return out;
    }
    // smooth parts: the faces joined through edges with the same material
    let adj = mesh.adjacency();
    let mut seen = vec![false; n_f];
    for root in 0..n_f {
        if seen[root] {
            continue;
        }
        seen[root] = true;
        let mut part = vec![root];
        let mut i = 0;
        while i < part.len() {
            let t = part[i];
            for &u in &adj[t] {
                let u = u as usize;
                if u < n_f && !seen[u] && mesh.face_material[u] == mesh.face_material[root] {
                    seen[u] = true;
                    part.push(u);
                }
            }
            i += 1;
        }
        let pts: Vec<V3> = part.iter().flat_map(|&t| corners(t)).collect();
        let s = principal_extent(&pts);
        for &t in &part {
            out[t] = [0.0, 0.0, 0.0, s];
        }
    }
    out
}

/// Whether a face of thinness `a` ([`face_thinness`]) is thin at attitude `rot` with
/// pixels of side `pix` (m): `|(R a)_z| + s < THIN_PX pix`.
pub fn is_thin(a: &[f64; 4], rot: &Rot, pix: f64) -> bool {
    let z = rot.row(2).dot(glam::DVec3::new(a[0], a[1], a[2]));
    z.abs() + a[3] < THIN_PX * pix
}

/// Per pixel of one attitude's image, the thin faces turned toward the receiver (all
/// faces on open meshes) whose projection overlaps the pixel.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ThinPixels {
    /// The pixels with thin faces (`row * width + col`), ascending.
    pixels: Vec<u32>,
    /// Pixel `pixels[i]`'s faces are `faces[starts[i]..starts[i + 1]]` (ascending).
    starts: Vec<u32>,
    faces: Vec<u32>,
}

impl ThinPixels {
    /// The thin faces of `mesh` at attitude `rot` (its rotated vertices `vertices`,
    /// [`crate::render::cpu::rotate_vertices`]; `thinness` from [`face_thinness`]) and the
    /// pixels of `lay`'s image each overlaps: each face clipped to each row of pixels it
    /// spans and to each column of the clipped polygon's extent, listed where it covers
    /// more than 1e-7 of the pixel (pixels it only touches are not).
    pub fn new(
        mesh: &Mesh,
        thinness: &[[f64; 4]],
        rot: &Rot,
        vertices: &[V3],
        lay: &Layout,
    ) -> Self {
        Self::build(mesh, thinness, rot, vertices, lay, false)
    }

    /// [`ThinPixels::new`] for analytic coverage: besides the thin faces, in every pixel
    /// that an outline edge crosses, every face turned toward the receiver that overlaps
    /// it ([`outline_pairs`]). The kernel's candidates are the triangles seen at the
    /// centres of a pixel's 3x3 neighbourhood and their neighbours across edges: a face
    /// seen only as a sliver between two centres beside another body's outline (a bus face
    /// in the strip beside a body-mounted panel's rim) was missing from them, and the
    /// pixel's area went to its other parts, hidden ones included (the 3U CubeSat with body
    /// panels at 48 px: the total 8% high within a 20-degree range of rolls about the line
    /// of sight, exact at others). A pixel no outline crosses is covered by one connected
    /// layer of front faces, which the centres' triangles and their neighbours reach.
    pub fn with_outlines(
        mesh: &Mesh,
        thinness: &[[f64; 4]],
        rot: &Rot,
        vertices: &[V3],
        lay: &Layout,
    ) -> Self {
        Self::build(mesh, thinness, rot, vertices, lay, true)
    }

    fn build(
        mesh: &Mesh,
        thinness: &[[f64; 4]],
        rot: &Rot,
        vertices: &[V3],
        lay: &Layout,
        outlines: bool,
    ) -> Self {
        let w = lay.width;
        let mut pairs = if outlines {
            outline_pairs(mesh, vertices, lay)
        } else {
            Vec::new()
        };
        for (t, a) in thinness.iter().enumerate() {
            if !is_thin(a, rot, lay.pix) {
                continue;
            }
            let uv = face_uv(mesh, vertices, lay, t);
            if !is_front(mesh, t, signed_area(&uv)) {
                continue;
            }
            // (only where it covers some of the pixel: a pixel it merely touches keeps its
            // samples, as the same pixel of the same surface cut into more triangles would)
            face_pixels(&uv, w, |pixel| pairs.push((pixel as u32, t as u32)));
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut out = ThinPixels {
            starts: vec![0],
            ..Default::default()
        };
        for (k, t) in pairs {
            if out.pixels.last() != Some(&k) {
                if !out.pixels.is_empty() {
                    out.starts.push(out.faces.len() as u32);
                }
                out.pixels.push(k);
            }
            out.faces.push(t);
        }
        if !out.pixels.is_empty() {
            out.starts.push(out.faces.len() as u32);
        }
        out
    }

    /// Whether no pixel has a thin face.
    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }

    /// How many pixels have thin faces.
    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    /// The thin faces overlapping pixel `pixel` (ascending; most pixels have none).
    pub fn faces_at(&self, pixel: usize) -> &[u32] {
        match self.pixels.binary_search(&(pixel as u32)) {
            Ok(i) => &self.faces[self.starts[i] as usize..self.starts[i + 1] as usize],
            Err(_) => &[],
        }
    }

    /// The pixels with thin faces, each with its faces.
    pub fn iter(&self) -> impl Iterator<Item = (usize, &[u32])> + '_ {
        self.pixels.iter().enumerate().map(|(i, &k)| {
            (
                k as usize,
                &self.faces[self.starts[i] as usize..self.starts[i + 1] as usize],
            )
        })
    }
}

/// The shade kernel's words for a chunk of attitudes' [`ThinPixels`] (binding 11 of
/// `shaders/shade.wgsl`, `n_pix` pixels per attitude): the number of pixels with thin
/// faces, then per attitude and pixel 0 or the position `p` of its faces (`words[p]` of
/// them, then their indices), then those lists. Empty when no pixel has a thin face (the
/// kernel then reads a placeholder of zeros).
pub fn gpu_words(chunk: &[ThinPixels], n_pix: usize) -> Vec<u32> {
    if chunk.iter().all(|t| t.is_empty()) {
        return Vec::new();
    }
    let mut words = vec![0u32; 1 + chunk.len() * n_pix];
    for (l, t) in chunk.iter().enumerate() {
        words[0] += t.len() as u32;
        for (k, faces) in t.iter() {
            words[1 + l * n_pix + k] = words.len() as u32;
            words.push(faces.len() as u32);
            words.extend_from_slice(faces);
        }
    }
    words
}

/// `(pixel, face)` for every pixel that an outline edge crosses (an edge across which the
/// projection folds over: the face beyond it turned the other way or edge-on, or a
/// boundary edge) and every face turned toward the receiver (both sides of an open mesh's
/// faces, as the clipping takes them) that overlaps that pixel by more than
/// [`MIN_OVERLAP`].
fn outline_pairs(mesh: &Mesh, vertices: &[V3], lay: &Layout) -> Vec<(u32, u32)> {
    let w = lay.width;
    let uvs: Vec<[[f64; 2]; 3]> = (0..mesh.faces.len())
        .map(|t| face_uv(mesh, vertices, lay, t))
        .collect();
    let den: Vec<f64> = uvs.iter().map(signed_area).collect();
    let front = |t: usize| is_front(mesh, t, den[t]);
    let adj = mesh.adjacency();
    let mut outline = vec![false; w * w];
    let mut any = false;
    for (t, uv) in uvs.iter().enumerate() {
        if !front(t) {
            continue;
        }
        for k in 0..3 {
            let u = adj[t][k] as usize;
            // (a neighbour turned the same way has `den` of the same sign; NaN is not)
            let same_way = u < mesh.faces.len() && den[u] * den[t] > 0.0;
            if !same_way {
                segment_pixels(uv[k], uv[(k + 1) % 3], w, |pixel| {
                    outline[pixel] = true;
                    any = true;
                });
            }
        }
    }
    let mut pairs = Vec::new();
    if !any {
        return pairs;
    }
    for (t, uv) in uvs.iter().enumerate() {
        if front(t) {
            face_pixels(uv, w, |pixel| {
                if outline[pixel] {
                    pairs.push((pixel as u32, t as u32));
                }
            });
        }
    }
    pairs
}

/// Face `t`'s corners in pixel coordinates of `lay` (`u` along the columns, `v` down the
/// rows).
fn face_uv(mesh: &Mesh, vertices: &[V3], lay: &Layout, t: usize) -> [[f64; 2]; 3] {
    mesh.faces[t].map(|k| {
        let p = vertices[k as usize];
        [(p[0] + lay.ext) / lay.pix, (lay.ext - p[1]) / lay.pix]
    })
}

/// Twice the signed area of a triangle in pixel coordinates.
fn signed_area(uv: &[[f64; 2]; 3]) -> f64 {
    (uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1]) - (uv[1][1] - uv[0][1]) * (uv[2][0] - uv[0][0])
}

/// Whether face `t` (signed area `den`) is turned toward the receiver as the clipping
/// takes it: front faces are counter-clockwise in (x, y), so clockwise in (u, v); both
/// sides of an open mesh's faces.
fn is_front(mesh: &Mesh, t: usize, den: f64) -> bool {
    den.is_finite() && den != 0.0 && !(mesh.face_closed[t] && den > 0.0)
}

/// Every pixel (`row * w + col`) that the triangle `uv` (pixel coordinates) covers by more
/// than [`MIN_OVERLAP`].
fn face_pixels(uv: &[[f64; 2]; 3], w: usize, mut visit: impl FnMut(usize)) {
    let (v_lo, v_hi) = uv
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[1]), hi.max(p[1]))
        });
    let rows = (v_lo.floor().max(0.0) as usize)..(v_hi.ceil().min(w as f64) as usize);
    for row in rows {
        let strip = clip_rows(uv, row as f64);
        if strip.len() < 3 {
            continue;
        }
        let (u_lo, u_hi) = strip
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[0]), hi.max(p[0]))
            });
        let lo = u_lo.floor().max(0.0) as usize;
        let hi = (u_hi.floor() + 1.0).min(w as f64) as usize;
        for col in lo..hi {
            if overlap_area(&strip, col as f64) > MIN_OVERLAP {
                visit(row * w + col);
            }
        }
    }
}

/// Every pixel (`row * w + col`) of a `w x w` image that the segment `a`-`b` (pixel
/// coordinates, `u` along the columns, `v` down the rows) passes through or touches: per
/// row it spans, the columns of its part within that row.
fn segment_pixels(a: [f64; 2], b: [f64; 2], w: usize, mut visit: impl FnMut(usize)) {
    if !(a.iter().chain(b.iter()).all(|x| x.is_finite())) {
        return;
    }
    let wf = w as f64;
    let (v_lo, v_hi) = (a[1].min(b[1]), a[1].max(b[1]));
    if v_hi < 0.0 || v_lo > wf {
        return;
    }
    let r0 = v_lo.floor().max(0.0) as usize;
    let r1 = (v_hi.floor() as usize).min(w - 1);
    for row in r0..=r1 {
        // the segment's part with v in [row, row + 1]
        let (s0, s1) = if b[1] == a[1] {
            (0.0, 1.0)
        } else {
            let ta = (row as f64 - a[1]) / (b[1] - a[1]);
            let tb = (row as f64 + 1.0 - a[1]) / (b[1] - a[1]);
            (ta.min(tb).max(0.0), ta.max(tb).min(1.0))
        };
        if s0 > s1 {
            continue;
        }
        let (u0, u1) = (a[0] + s0 * (b[0] - a[0]), a[0] + s1 * (b[0] - a[0]));
        let (u_lo, u_hi) = (u0.min(u1), u0.max(u1));
        if u_hi < 0.0 || u_lo > wf {
            continue;
        }
        let c0 = u_lo.floor().max(0.0) as usize;
        let c1 = (u_hi.floor() as usize).min(w - 1);
        for col in c0..=c1 {
            visit(row * w + col);
        }
    }
}

/// The part of triangle `uv` (pixel coordinates) between `v = row` and `v = row + 1`.
fn clip_rows(uv: &[[f64; 2]; 3], row: f64) -> Vec<[f64; 2]> {
    let p = clip_edge(&uv.to_vec(), [0.0, row], [1.0, 0.0], 1.0);
    clip_edge(&p, [0.0, row + 1.0], [1.0, 0.0], -1.0)
}

/// The least area (pixels) of a face in a pixel for the pixel to list it: the exact
/// clipping drops parts below 1e-7 of a pixel too.
const MIN_OVERLAP: f64 = 1e-7;

/// The area (pixels) of the convex polygon `strip` (one row of pixels) within column `col`.
fn overlap_area(strip: &[[f64; 2]], col: f64) -> f64 {
    let p = clip_edge(&strip.to_vec(), [col, 0.0], [0.0, 1.0], -1.0);
    let p = clip_edge(&p, [col + 1.0, 0.0], [0.0, 1.0], 1.0);
    moments(&p)[0].abs()
}

/// Any unit vector normal to the unit vector `n`.
fn any_perp(n: V3) -> V3 {
    let t = if n.x.abs() < 0.9 {
        V3::new(1.0, 0.0, 0.0)
    } else {
        V3::new(0.0, 1.0, 0.0)
    };
    let p = n.cross(t);
    p / p.length()
}

/// The width of the convex hull of `pts`: over the hull's edges, the least of the largest
/// distances of a hull vertex from the edge's line (0 for fewer than three points or
/// collinear ones).
fn hull_width(mut pts: Vec<[f64; 2]>) -> f64 {
    pts.sort_by(|a, b| a.partial_cmp(b).expect("finite vertices"));
    pts.dedup();
    if pts.len() < 3 {
        return 0.0;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    // Andrew's monotone chain
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = hull.len();
        let it: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in it {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    if hull.len() < 3 {
        return 0.0;
    }
    let mut w = f64::INFINITY;
    for k in 0..hull.len() {
        let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
        let l = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        if l == 0.0 {
            continue;
        }
        let far = hull
            .iter()
            .map(|&p| cross(a, b, p).abs() / l)
            .fold(0.0, f64::max);
        w = w.min(far);
    }
    w
}

/// The smallest extent of `pts` along the principal axes of their covariance.
fn principal_extent(pts: &[V3]) -> f64 {
    let n = pts.len() as f64;
    let mean = pts.iter().fold(V3::ZERO, |s, &p| s + p) / n;
    let mut c = nalgebra::Matrix3::<f64>::zeros();
    for p in pts {
        let d = *p - mean;
        let d = nalgebra::Vector3::new(d.x, d.y, d.z);
        c += d * d.transpose();
    }
    let eig = nalgebra::SymmetricEigen::new(c);
    (0..3)
        .map(|i| {
            let u = eig.eigenvectors.column(i);
            let u = V3::new(u[0], u[1], u[2]);
            let (lo, hi) = pts
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    let x = p.dot(u);
                    (lo.min(x), hi.max(x))
                });
            hi - lo
        })
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hull width of a rectangle is its short side, at any rotation in the plane.
    #[test]
    fn hull_width_of_a_rectangle() {
        for t in [0.0f64, 0.3, 1.0] {
            let (c, s) = (t.cos(), t.sin());
            let r = |x: f64, y: f64| [c * x - s * y, s * x + c * y];
            let pts = vec![
                r(0.0, 0.0),
                r(3.0, 0.0),
                r(3.0, 0.5),
                r(0.0, 0.5),
                r(1.0, 0.2),
            ];
            assert!((hull_width(pts) - 0.5).abs() < 1e-12);
        }
        assert_eq!(hull_width(vec![[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]), 0.0);
    }

    /// A thin plate (flat shaded): its rims are thin at any attitude, its faces only
    /// nearly edge-on; the same plate with vertex normals is one smooth part as thin as
    /// its thickness.
    #[test]
    fn plate_rims_and_faces() {
        let (h, t) = (0.5, 0.002);
        let mut v = vec![];
        for z in [-t / 2.0, t / 2.0] {
            v.extend([[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]]);
        }
        let f: Vec<[u32; 3]> = vec![
            [4, 5, 6],
            [4, 6, 7],
            [0, 2, 1],
            [0, 3, 2],
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7],
        ];
        let mesh = Mesh::new(v.clone(), f.clone(), None, vec![0; 12], 1).unwrap();
        let a = face_thinness(&mesh);
        assert!((a[0][2].abs() - 2.0 * h).abs() < 1e-12 && a[0][3] == 0.0);
        assert!((a[4][1].abs() - t).abs() < 1e-12);
        let pix = 0.004;
        let face_on = Rot::IDENTITY;
        assert!(!is_thin(&a[0], &face_on, pix) && is_thin(&a[4], &face_on, pix));
        let edge_on = Rot::from_rotation_x(std::f64::consts::FRAC_PI_2 - 1e-3);
        assert!(is_thin(&a[0], &edge_on, pix) && is_thin(&a[4], &edge_on, pix));
        let normals: Vec<[f64; 3]> = v.iter().map(|p| [0.0, 0.0, p[2].signum()]).collect();
        let smooth = Mesh::new(v, f, Some(normals), vec![0; 12], 1).unwrap();
        let s = face_thinness(&smooth);
        assert!(s.iter().all(|x| (x[3] - t).abs() < 1e-12 && x[2] == 0.0));
    }
}
