//! The mesh as the paths see it: one attitude's triangles in a BVH with what a hit needs
//! ([`Posed`], [`Vertex`]), and what is known before tracing: meshes with no
//! inter-reflections, the sides of faces with nothing in front, the pixels a mesh may cover.

use super::*;

/// Whether no ray leaving the mesh's visible side can meet it again, from its faces'
/// [`open_sides`]: nothing in front of the outward side of any face of a closed component
/// (convex) nor on either side of any other face (flat).
pub fn has_no_interreflections(mesh: &Mesh) -> bool {
    no_interreflections(mesh, &open_sides(mesh))
}

/// [`has_no_interreflections`] from the mesh's [`open_sides`]: no face has anything in
/// front of a side that can be seen (the outward side of a face of a closed component,
/// [`Mesh::face_closed`]; either side of the others).
pub(super) fn no_interreflections(mesh: &Mesh, open: &[[bool; 2]]) -> bool {
    open.iter()
        .zip(&mesh.face_closed)
        .all(|(s, &closed)| !s[0] && (closed || !s[1]))
}

/// For each face, whether any vertex of the mesh lies in front of its plane (`[0]`, the side
/// its winding's normal points to) and behind it (`[1]`), beyond `1e-9` of the bounding
/// radius: a ray leaving a face on a side with nothing there cannot meet the mesh, so no
/// path is drawn from it. Computed per flat surface ([`Mesh::surfaces`]: one plane);
/// where that would take more than about `5e7` vertex tests (a large smooth mesh), every
/// side is reported open. A degenerate face (no plane) has no open side: no ray meets it,
/// so no path passes through it.
pub fn open_sides(mesh: &Mesh) -> Vec<[bool; 2]> {
    let surf = mesh.surfaces();
    let n_surf = surf
        .iter()
        .enumerate()
        .filter(|&(t, &s)| s as usize == t)
        .count();
    if n_surf.saturating_mul(mesh.vertices.len()) > 50_000_000 {
        return vec![[true, true]; mesh.faces.len()];
    }
    let tol = 1e-9 * mesh.radius;
    let vs: Vec<V3> = mesh.vertices.iter().map(|&v| V3::from(v)).collect();
    let mut by_surface: std::collections::HashMap<u32, [bool; 2]> = Default::default();
    let mut out = Vec::with_capacity(mesh.faces.len());
    for &root in surf {
        let sides = *by_surface.entry(root).or_insert_with(|| {
            let [a, b, c] = mesh.faces[root as usize].map(|k| vs[k as usize]);
            let n = cross(b - a, c - a);
            let l = dot(n, n).sqrt();
            if l <= 0.0 || l.is_nan() {
                return [false, false];
            }
            let n = n / l;
            let mut sides = [false, false];
            for &v in &vs {
                let d = dot(n, v - a);
                sides[0] |= d > tol;
                sides[1] |= d < -tol;
                if sides[0] && sides[1] {
                    break;
                }
            }
            sides
        });
        // a face of a surface shares its plane and orientation (Mesh::surfaces)
        out.push(sides);
    }
    out
}

/// The area of each flat surface ([`Mesh::surfaces`]) at the index of its first face (0
/// elsewhere).
pub(super) fn surface_areas(mesh: &Mesh) -> Vec<f64> {
    let surf = mesh.surfaces();
    let mut area = vec![0.0; mesh.faces.len()];
    for (t, f) in mesh.faces.iter().enumerate() {
        let [a, b, c] = f.map(|k| V3::from(mesh.vertices[k as usize]));
        area[surf[t] as usize] += 0.5 * cross(b - a, c - a).length();
    }
    area
}

/// A surface a path meets: the point, the geometric normal and the shading normal (both
/// on the side the ray came from), the material and the triangle.
#[derive(Debug, Clone, Copy)]
pub(super) struct Vertex {
    pub(super) p: V3,
    pub(super) ng: V3,
    pub(super) n: V3,
    pub(super) mat: usize,
    pub(super) tri: usize,
}

/// The mesh in one attitude: its rotated triangles and what a hit needs, with the mesh's
/// [`Bvh`] in its own frame (built once for every attitude: rays are turned into the mesh's
/// frame, `R^T o + t R^T d`, which leaves `t` and the barycentrics as they are).
pub(super) struct Posed<'a> {
    pub(super) mesh: &'a Mesh,
    pub(super) rot: &'a Rot,
    /// [`open_sides`] of the mesh.
    pub(super) open: &'a [[bool; 2]],
    pub(super) tris: Vec<[V3; 3]>,
    /// The tree over the mesh's unrotated triangles ([`Mesh::bvh`]).
    pub(super) bvh: &'a Bvh,
    /// `R^T`: the telescope frame to the mesh's.
    to_mesh: Rot,
    /// Ray origins leave a surface by this much along its normal (m).
    pub(super) eps: f64,
}

/// The mesh's triangles with each vertex mapped by `at` (a rotation, or none).
fn triangles(mesh: &Mesh, at: impl Fn(V3) -> V3) -> Vec<[V3; 3]> {
    let vs: Vec<V3> = mesh.vertices.iter().map(|&v| at(V3::from(v))).collect();
    mesh.faces
        .iter()
        .map(|f| f.map(|k| vs[k as usize]))
        .collect()
}

impl<'a> Posed<'a> {
    pub(super) fn new(mesh: &'a Mesh, rot: &'a Rot, open: &'a [[bool; 2]], bvh: &'a Bvh) -> Self {
        Posed {
            mesh,
            rot,
            open,
            tris: triangles(mesh, |v| rotate(rot, v)),
            bvh,
            to_mesh: rot.transpose(),
            eps: 1e-9 * mesh.radius,
        }
    }

    /// The first surface along `o + t d` (`t > 0`), with its normals facing `-d`.
    pub(super) fn trace(&self, o: V3, d: V3) -> Option<Vertex> {
        let hit = self.bvh.closest_hit(
            rotate(&self.to_mesh, o),
            rotate(&self.to_mesh, d),
            0.0,
            f64::INFINITY,
        )?;
        let [a, b, c] = self.tris[hit.tri];
        let p = a + hit.u * (b - a) + hit.v * (c - a);
        let mut ng = normalize(cross(b - a, c - a));
        if !ng.is_finite() {
            return None;
        }
        if dot(ng, d) > 0.0 {
            ng = -ng;
        }
        let n =
            self.mesh
                .shading_normal(hit.tri, self.rot, [1.0 - hit.u - hit.v, hit.u, hit.v], ng);
        Some(Vertex {
            p,
            ng,
            n,
            mat: self.mesh.face_material[hit.tri] as usize,
            tri: hit.tri,
        })
    }

    /// Whether the ray `o + t d` (`t > 0`) meets a face of the mesh other than `skip`.
    pub(super) fn blocked(&self, o: V3, d: V3, skip: Option<usize>) -> bool {
        self.bvh.any_hit(
            rotate(&self.to_mesh, o),
            rotate(&self.to_mesh, d),
            0.0,
            f64::INFINITY,
            skip,
        )
    }

    /// Whether anything of the mesh lies on the side of `v`'s face that `v.ng` points to.
    pub(super) fn side_open(&self, v: &Vertex) -> bool {
        let [a, b, c] = self.tris[v.tri];
        let front = dot(v.ng, cross(b - a, c - a)) > 0.0;
        self.open[v.tri][if front { 0 } else { 1 }]
    }

    /// Whether `v` sees the direction `w` past the rest of the mesh, its geometric and
    /// shading normals both facing it: the transmitter (`wi`, `v` lit) or the receiver
    /// (`wo`, `v` seen).
    pub(super) fn sees(&self, v: &Vertex, w: V3) -> bool {
        dot(v.ng, w) > 0.0
            && dot(v.n, w) > 0.0
            && !self.blocked(v.p + self.eps * v.ng, w, Some(v.tri))
    }
}

/// The pixels of a `w x w` image of the square `[-ext, ext]^2` (row 0 at the top) that
/// the triangles may cover, projected on the axes `(u, v)`: those whose square, widened by
/// `1e-3` of a pixel on every side, a triangle overlaps (the separating-axis test against
/// its box and its edges' normals; conservative: no pixel with a triangle in it is left
/// out, and a long thin triangle across the image marks the pixels along it, not its
/// whole box).
pub(super) fn covered_pixels(tris: &[[V3; 3]], u: V3, v: V3, w: usize, ext: f64) -> Vec<bool> {
    let mut mask = vec![false; w * w];
    let pix = 2.0 * ext / w as f64;
    let last = (w - 1) as f64;
    // pixel units: x to the right from the image's left edge, y down from its top
    let half = 0.5 + 1e-3;
    for t in tris {
        let p = t.map(|q| ((dot(q, u) + ext) / pix, (ext - dot(q, v)) / pix));
        if p.iter().any(|&(x, y)| !(x.is_finite() && y.is_finite())) {
            continue;
        }
        let (x0, x1) = (
            p[0].0.min(p[1].0).min(p[2].0),
            p[0].0.max(p[1].0).max(p[2].0),
        );
        let (y0, y1) = (
            p[0].1.min(p[1].1).min(p[2].1),
            p[0].1.max(p[1].1).max(p[2].1),
        );
        if x1 < -1.0 || y1 < -1.0 || x0 > w as f64 + 1.0 || y0 > w as f64 + 1.0 {
            continue;
        }
        let c0 = (x0 - 1.0).floor().clamp(0.0, last) as usize;
        let c1 = (x1 + 1.0).floor().clamp(0.0, last) as usize;
        let r0 = (y0 - 1.0).floor().clamp(0.0, last) as usize;
        let r1 = (y1 + 1.0).floor().clamp(0.0, last) as usize;
        // each edge's normal (nx, ny) and the triangle's extent [lo, hi] along it
        let axes: [(f64, f64, f64, f64); 3] = std::array::from_fn(|k| {
            let (a, b, c) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            let (nx, ny) = (a.1 - b.1, b.0 - a.0);
            let (pa, pc) = (nx * a.0 + ny * a.1, nx * c.0 + ny * c.1);
            (nx, ny, pa.min(pc), pa.max(pc))
        });
        for r in r0..=r1 {
            for c in c0..=c1 {
                let (cx, cy) = (c as f64 + 0.5, r as f64 + 0.5);
                if cx + half < x0 || cx - half > x1 || cy + half < y0 || cy - half > y1 {
                    continue;
                }
                let apart = axes.iter().any(|&(nx, ny, lo, hi)| {
                    let centre = nx * cx + ny * cy;
                    let reach = half * (nx.abs() + ny.abs());
                    centre + reach < lo || centre - reach > hi
                });
                if !apart {
                    mask[r * w + c] = true;
                }
            }
        }
    }
    mask
}
