//! Meshes and attitudes for the renderer (conventions in [`crate::render`]).

use crate::error::{Error, Result};
use crate::optics::frames::V3;
use glam::{DMat3, DQuat};

/// A triangle mesh in the body frame with a material index per face.
#[derive(Debug, Clone)]
pub struct Mesh {
    pub vertices: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// Optional per-vertex normals (interpolated for shading; the geometric normal decides
    /// which side faces the receiver).
    pub normals: Option<Vec<[f64; 3]>>,
    pub face_material: Vec<u32>,
    /// Radius of the bounding sphere about the body origin.
    pub radius: f64,
    /// Whether every connected component is a closed surface wound consistently with
    /// outward normals ([`is_closed_outward`]): the nearest surface along any outside ray
    /// is then a front face, and the raster passes cull back faces.
    pub closed: bool,
    /// Per face, whether its component is closed and outward-wound
    /// ([`closed_components`]): its back faces are never seen, in a closed mesh or not.
    pub face_closed: Vec<bool>,
    /// [`Mesh::adjacency`], computed on first use.
    adjacency: std::sync::OnceLock<Vec<[u32; 3]>>,
    /// [`Mesh::surfaces`], computed on first use.
    surfaces: std::sync::OnceLock<Vec<u32>>,
    /// [`Mesh::bvh`], built on first use.
    bvh: std::sync::OnceLock<super::bvh::Bvh>,
    /// The faces' thinness, computed on first use (`thin::mesh_thinness`).
    thinness: std::sync::OnceLock<Vec<[f64; 4]>>,
    // (these caches, like the two above, hold for the mesh `Mesh::new` made: a mesh whose
    // public fields are changed after it must be made anew)
}

/// Whether a triangle mesh is a union of closed, outward-wound surfaces: every directed
/// edge `(a, b)` of a face occurs exactly once and its reverse `(b, a)` exactly once, and
/// every connected component (faces joined through shared vertices) encloses a positive
/// signed volume. Meshes with duplicated (unwelded) vertices, open parts or inconsistent
/// winding return false (and are rendered without culling).
pub fn is_closed_outward(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> bool {
    closed_components(vertices, faces).iter().all(|&c| c)
}

/// Per face, whether its connected component (faces joined through shared vertices) is a
/// closed, outward-wound surface ([`is_closed_outward`]'s test on that component alone):
/// its back faces are then hidden from any viewpoint outside it, whatever the rest of the
/// mesh is (a closed wire in an otherwise open mesh).
pub fn closed_components(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<bool> {
    use std::collections::HashMap;
    // components by union-find over vertices
    let mut parent: Vec<u32> = (0..vertices.len() as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    for f in faces {
        let r0 = find(&mut parent, f[0]);
        for &k in &f[1..] {
            let r = find(&mut parent, k);
            parent[r as usize] = r0;
        }
    }
    let root: Vec<u32> = faces.iter().map(|f| find(&mut parent, f[0])).collect();
    // per component: its signed volume and whether its edges pair up
    let mut ok: HashMap<u32, bool> = HashMap::new();
    let mut edges: HashMap<(u32, u32), u32> = HashMap::with_capacity(3 * faces.len());
    for (f, &r) in faces.iter().zip(&root) {
        ok.entry(r).or_insert(true);
        for k in 0..3 {
            let c = edges.entry((f[k], f[(k + 1) % 3])).or_insert(0);
            *c += 1;
            if *c > 1 {
                ok.insert(r, false);
            }
        }
    }
    for &(a, b) in edges.keys() {
        if !edges.contains_key(&(b, a)) {
            ok.insert(find(&mut parent, a), false);
        }
    }
    let mut volume: HashMap<u32, f64> = HashMap::new();
    for (f, &r) in faces.iter().zip(&root) {
        let [a, b, c] = f.map(|k| V3::from(vertices[k as usize]));
        *volume.entry(r).or_insert(0.0) += a.dot(b.cross(c)) / 6.0;
    }
    root.iter().map(|r| ok[r] && volume[r] > 0.0).collect()
}

/// Relative area (to the squared bounding radius) below which a triangle is degenerate.
pub const MIN_RELATIVE_AREA: f64 = 1e-14;

impl Mesh {
    /// Validate and build. `n_materials`: the number of materials the indices refer to.
    pub fn new(
        vertices: Vec<[f64; 3]>,
        faces: Vec<[u32; 3]>,
        normals: Option<Vec<[f64; 3]>>,
        face_material: Vec<u32>,
        n_materials: usize,
    ) -> Result<Self> {
        if vertices.is_empty() || faces.is_empty() {
            return Err(Error::Shape(format!(
                "mesh is empty ({} vertices, {} faces): need at least one triangle",
                vertices.len(),
                faces.len()
            )));
        }
        if let Some(i) = vertices
            .iter()
            .position(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err(Error::param(
                "vertices",
                format!("{:?} at index {i}", vertices[i]),
                "finite coordinates",
            ));
        }
        let nv = vertices.len() as u32;
        if let Some(i) = faces.iter().position(|f| f.iter().any(|&k| k >= nv)) {
            return Err(Error::param(
                "faces",
                format!("{:?} at index {i}", faces[i]),
                format!("vertex indices in [0, {})", nv),
            ));
        }
        if face_material.len() != faces.len() {
            return Err(Error::Shape(format!(
                "face_material has {} entries for {} faces",
                face_material.len(),
                faces.len()
            )));
        }
        if let Some(i) = face_material
            .iter()
            .position(|&m| m as usize >= n_materials)
        {
            return Err(Error::param(
                "face_material",
                format!("{} at face {i}", face_material[i]),
                format!("indices in [0, {n_materials}) (one per material)"),
            ));
        }
        if let Some(n) = &normals {
            if n.len() != vertices.len() {
                return Err(Error::Shape(format!(
                    "normals has {} entries for {} vertices",
                    n.len(),
                    vertices.len()
                )));
            }
            if let Some(i) = n.iter().position(|v| {
                let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                !l.is_finite() || l < 1e-12
            }) {
                return Err(Error::param(
                    "normals",
                    format!("{:?} at index {i}", n[i]),
                    "finite, non-zero vectors",
                ));
            }
        }
        let radius = vertices
            .iter()
            .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
            .fold(0.0f64, f64::max);
        if radius <= 0.0 {
            return Err(Error::param(
                "vertices",
                "all at the origin",
                "a mesh of non-zero size",
            ));
        }
        let r2 = radius * radius;
        for (i, f) in faces.iter().enumerate() {
            let [a, b, c] = f.map(|k| V3::from(vertices[k as usize]));
            let area2 = (b - a).cross(c - a).length();
            if !(area2 > 2.0 * MIN_RELATIVE_AREA * r2) {
                return Err(Error::param(
                    "faces",
                    format!("{f:?} at index {i} (area {:.3e} m^2)", 0.5 * area2),
                    format!(
                        "non-degenerate triangles (area > {MIN_RELATIVE_AREA:e} x radius^2); \
                         remove zero-area faces, e.g. trimesh's update_faces(nondegenerate_faces())"
                    ),
                ));
            }
        }
        let face_closed = closed_components(&vertices, &faces);
        let closed = face_closed.iter().all(|&c| c);
        Ok(Mesh {
            vertices,
            faces,
            normals,
            face_material,
            radius,
            closed,
            face_closed,
            adjacency: std::sync::OnceLock::new(),
            surfaces: std::sync::OnceLock::new(),
            bvh: std::sync::OnceLock::new(),
            thinness: std::sync::OnceLock::new(),
        })
    }

    /// The ray-casting tree of the triangles in the body frame (the inter-reflections'
    /// paths turn their rays into it), built on first use: a scene rendered again (a fit's
    /// steps) does not build it again.
    pub fn bvh(&self) -> &super::bvh::Bvh {
        self.bvh.get_or_init(|| {
            let tris: Vec<[V3; 3]> = (self.faces.iter())
                .map(|f| f.map(|k| V3::from(self.vertices[k as usize])))
                .collect();
            super::bvh::Bvh::new(&tris)
        })
    }

    /// The cache of the faces' thinness (`thin::mesh_thinness` fills it: this module does
    /// not name that one, which names it).
    pub(crate) fn thinness_cache(&self) -> &std::sync::OnceLock<Vec<[f64; 4]>> {
        &self.thinness
    }

    /// For each face, the face across each of its edges (edge `k` joins corners `k` and
    /// `k + 1`), `u32::MAX` across a boundary edge. Edges are matched by their end points'
    /// positions, not indices, so unwelded meshes (split vertices for flat shading) are
    /// joined too; where more than two faces share an edge, each has the next of them.
    pub fn adjacency(&self) -> &[[u32; 3]] {
        self.adjacency.get_or_init(|| {
            use std::collections::HashMap;
            let key = |k: u32| self.vertices[k as usize].map(f64::to_bits);
            // (end point, end point) as position bits -> (face, edge) sharing it
            type EdgeKey = ([u64; 3], [u64; 3]);
            let mut edges: HashMap<EdgeKey, Vec<(u32, u8)>> = HashMap::new();
            for (t, f) in self.faces.iter().enumerate() {
                for e in 0..3 {
                    let (a, b) = (key(f[e]), key(f[(e + 1) % 3]));
                    let k = if a <= b { (a, b) } else { (b, a) };
                    edges.entry(k).or_default().push((t as u32, e as u8));
                }
            }
            let mut adj = vec![[u32::MAX; 3]; self.faces.len()];
            for list in edges.values() {
                if list.len() < 2 {
                    continue;
                }
                for (i, &(t, e)) in list.iter().enumerate() {
                    adj[t as usize][e as usize] = list[(i + 1) % list.len()].0;
                }
            }
            adj
        })
    }

    /// For each face, the flat surface it belongs to: the lowest-numbered face of the set
    /// of faces joined to it through shared edges ([`Mesh::adjacency`]) that have its
    /// material and, within [`SURFACE_ANGLE`], its plane (normals parallel and pointing the
    /// same way; sharing an edge, they then share the plane), each compared with the set's
    /// first face. Every face is its own surface when the mesh has vertex normals (smooth
    /// shading varies across a face). On one flat surface, under the renderer's
    /// directional illumination and orthographic view, the Mueller BRDF is the same at
    /// every point and the range is linear, so the samples of a pixel that see different
    /// faces of one surface are shaded as one part (`shaders/shade.wgsl`,
    /// [`crate::render::cpu::sampled_parts`]): a finely tessellated panel costs what one
    /// large face does.
    pub fn surfaces(&self) -> &[u32] {
        self.surfaces.get_or_init(|| {
            let n_f = self.faces.len();
            let mut surf: Vec<u32> = (0..n_f as u32).collect();
            if self.normals.is_some() {
                return surf;
            }
            let normal = |t: usize| -> Option<V3> {
                let p = self.faces[t].map(|k| V3::from(self.vertices[k as usize]));
                let c = (p[1] - p[0]).cross(p[2] - p[0]);
                let l = c.length();
                (l > 0.0 && l.is_finite()).then(|| c / l)
            };
            let normals: Vec<Option<V3>> = (0..n_f).map(normal).collect();
            let adj = self.adjacency();
            let mut seen = vec![false; n_f];
            let mut stack = Vec::new();
            for root in 0..n_f {
                if seen[root] {
                    continue;
                }
                seen[root] = true;
                let Some(n0) = normals[root] else {
                    continue;
                };
                stack.push(root);
                while let Some(t) = stack.pop() {
                    for &u in &adj[t] {
                        let u = u as usize;
                        if u == u32::MAX as usize
                            || seen[u]
                            || self.face_material[u] != self.face_material[root]
                        {
                            continue;
                        }
                        let Some(n) = normals[u] else {
                            continue;
                        };
                        if n.dot(n0) > 0.0 && n.cross(n0).length() <= SURFACE_ANGLE {
                            seen[u] = true;
                            surf[u] = root as u32;
                            stack.push(u);
                        }
                    }
                }
            }
            surf
        })
    }

    /// The shading normal of face `tri` in the attitude `rot` at the barycentric weights
    /// `l` of its corners: the interpolated vertex normals, rotated and normalized, turned
    /// to the side of `ng` (the face's geometric normal on the side looked at); `ng` itself
    /// on a flat-shaded mesh or where the interpolated normal vanishes. The renderers'
    /// shading (`cpu::shade_at`) and the paths' surfaces use it.
    pub fn shading_normal(&self, tri: usize, rot: &Rot, l: [f64; 3], ng: V3) -> V3 {
        let Some(ns) = &self.normals else {
            return ng;
        };
        let c = self.faces[tri].map(|k| ns[k as usize]);
        let v = [0, 1, 2].map(|d| l[0] * c[0][d] + l[1] * c[1][d] + l[2] * c[2][d]);
        let v = rotate(rot, V3::from(v));
        let len = v.dot(v).sqrt();
        if len > 1e-15 {
            let n = v / len;
            if n.dot(ng) < 0.0 {
                -n
            } else {
                n
            }
        } else {
            ng
        }
    }

    /// The de-indexed GPU geometry: `3 T` corners `(x, y, z, w)`, `w` the bits of the
    /// face's material at its first corner, of its surface ([`Mesh::surfaces`]) at its
    /// second and of [`Mesh::face_closed`] (1 or 0) at its third, then, with normals, `3 T`
    /// corner normals `(nx, ny, nz, 0)`.
    pub fn gpu_geometry(&self) -> Vec<[f32; 4]> {
        let t = self.faces.len();
        let mut out = Vec::with_capacity(if self.normals.is_some() { 6 * t } else { 3 * t });
        let surf = self.surfaces();
        for (((f, &m), &s), &fc) in
            (self.faces.iter().zip(&self.face_material).zip(surf)).zip(&self.face_closed)
        {
            for (c, &k) in f.iter().enumerate() {
                let v = self.vertices[k as usize];
                let w = [m, s, fc as u32][c];
                out.push([v[0] as f32, v[1] as f32, v[2] as f32, f32::from_bits(w)]);
            }
        }
        if let Some(ns) = &self.normals {
            for f in &self.faces {
                for &k in f {
                    let n = ns[k as usize];
                    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    out.push([(n[0] / l) as f32, (n[1] / l) as f32, (n[2] / l) as f32, 0.0]);
                }
            }
        }
        out
    }
}

/// Largest angle (rad, as the sine between unit normals) between the planes of two faces
/// of one flat surface ([`Mesh::surfaces`]): far below what the shading resolves (the f32
/// kernel matches its f64 twin to 1e-4 relative), far above the rounding of a flat face's
/// normal in f64.
pub const SURFACE_ANGLE: f64 = 1e-7;

/// A rotation matrix, `p_tel = R p_body`: glam's `DMat3`, stored by columns
/// (`r.col(j)`, `r.x_axis` ..; `r.row(i)` is row `i`). Users give and get matrices by rows
/// (numpy's `(3, 3)`): [`rot_from_rows`], [`rot_to_rows`].
pub type Rot = DMat3;

/// The rotation whose row `i` is `rows[i]` (`R[i][j] = rows[i][j]`).
#[inline]
pub fn rot_from_rows(rows: [[f64; 3]; 3]) -> Rot {
    DMat3::from_cols_array_2d(&rows).transpose()
}

/// The rows of `r` (`rot_to_rows(r)[i][j] = R[i][j]`).
#[inline]
pub fn rot_to_rows(r: &Rot) -> [[f64; 3]; 3] {
    r.transpose().to_cols_array_2d()
}

/// A user quaternion `(w, x, y, z)` as glam's `DQuat` (stored `(x, y, z, w)`): the one place
/// where the two orders meet.
#[inline]
pub fn quat_from_wxyz(q: [f64; 4]) -> DQuat {
    let [w, x, y, z] = q;
    DQuat::from_xyzw(x, y, z, w)
}

/// `q` as the user's `(w, x, y, z)` (the inverse of [`quat_from_wxyz`]).
#[inline]
pub fn quat_to_wxyz(q: DQuat) -> [f64; 4] {
    [q.w, q.x, q.y, q.z]
}

/// The rotation matrix of the unit quaternion `q`. The project's formula, not glam's
/// `DMat3::from_quat` (which forms `x * (y + y)` where this forms `2 (x y)`: equal but for
/// rounding in the subnormal range).
#[inline]
pub fn rot_from_unit_quat(q: DQuat) -> Rot {
    let DQuat { x, y, z, w } = q;
    rot_from_rows([
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ])
}

/// Rotation matrices from `(w, x, y, z)` quaternions (normalized; refused when the norm is
/// off by more than `1e-6` relative or not finite).
pub fn rotations_from_quaternions(q: &[[f64; 4]]) -> Result<Vec<Rot>> {
    q.iter()
        .enumerate()
        .map(|(i, wxyz)| {
            let q = quat_from_wxyz(*wxyz);
            // the norm summed in the user's order w, x, y, z; each component divided by it
            let n = (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z).sqrt();
            if !n.is_finite() || (n - 1.0).abs() > 1e-6 {
                return Err(Error::param(
                    "attitudes",
                    format!("quaternion {i} = {wxyz:?} (norm {n})"),
                    "unit quaternions (w, x, y, z), |q| = 1 within 1e-6",
                ));
            }
            Ok(rot_from_unit_quat(q / n))
        })
        .collect()
}

/// Check rotation matrices: finite, orthonormal within `1e-6`, determinant +1.
pub fn check_rotations(r: &[Rot]) -> Result<()> {
    for (i, m) in r.iter().enumerate() {
        let m = rot_to_rows(m);
        let mut worst = 0.0f64;
        for a in 0..3 {
            for b in 0..3 {
                let d: f64 = (0..3).map(|k| m[k][a] * m[k][b]).sum();
                let want = if a == b { 1.0 } else { 0.0 };
                worst = worst.max((d - want).abs());
            }
        }
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        if !(worst <= 1e-6) || !(det > 0.0) {
            return Err(Error::param(
                "attitudes",
                format!("rotation matrix {i} (|R^T R - I| = {worst:.2e}, det = {det:.6})"),
                "proper rotation matrices (orthonormal within 1e-6, det +1)",
            ));
        }
    }
    Ok(())
}

/// `R v`: glam's `DMat3 * DVec3`, component `i` summed `(R[i][0] v.x + R[i][1] v.y) +
/// R[i][2] v.z` as the hand-written row products did.
#[inline]
pub fn rotate(r: &Rot, v: V3) -> V3 {
    *r * v
}

/// The transmitter's view of attitude `r` for the bistatic angle `beta`:
/// `R_tx = R_y(-beta) R`, which maps `wi = (sin beta, 0, cos beta)` to `+z` (rows
/// `c R_0 - s R_2`, `R_1`, `s R_0 + c R_2`). The cast-shadow raster draws with it.
pub fn transmitter_rotation(r: &Rot, beta: f64) -> Rot {
    let (s, c) = beta.sin_cos();
    // by rows, not as the product `R_y(-beta) * R` (whose `0 * R_1` terms can flip the sign
    // of a zero)
    let (r0, r1, r2) = (r.row(0), r.row(1), r.row(2));
    DMat3::from_cols(c * r0 - s * r2, r1, s * r0 + c * r2).transpose()
}

/// GPU layout of a rotation: WGSL `mat3x3<f32>` (3 columns padded to vec4).
pub fn gpu_rotation(r: &Rot) -> [f32; 12] {
    let mut out = [0.0f32; 12];
    for col in 0..3 {
        for row in 0..3 {
            out[4 * col + row] = r.col(col)[row] as f32;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_rotation_is_orthonormal_and_matches_axis_angle() {
        // 90 degrees about z: x -> y
        let h = (0.5f64).sqrt();
        let r = rotations_from_quaternions(&[[h, 0.0, 0.0, h]]).unwrap();
        let v = rotate(&r[0], V3::X);
        assert!((v[0]).abs() < 1e-15 && (v[1] - 1.0).abs() < 1e-15);
        check_rotations(&r).unwrap();
        assert!(rotations_from_quaternions(&[[1.0, 0.1, 0.0, 0.0]]).is_err());
        assert!(rotations_from_quaternions(&[[f64::NAN, 0.0, 0.0, 0.0]]).is_err());
    }

    #[test]
    fn wxyz_quaternions_convert_in_one_place_and_round_trip() {
        // 90 degrees about z, given as (w, x, y, z) = (cos 45, 0, 0, sin 45): x -> y, y -> -x
        let h = 0.5f64.sqrt();
        let q = quat_from_wxyz([h, 0.0, 0.0, h]);
        assert_eq!((q.x, q.y, q.z, q.w), (0.0, 0.0, h, h));
        let want = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
        assert!((q.dot(want) - 1.0).abs() < 1e-15);
        let r = rotations_from_quaternions(&[[h, 0.0, 0.0, h]]).unwrap()[0];
        let rows = rot_to_rows(&r);
        let expect = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        for i in 0..3 {
            for j in 0..3 {
                assert!((rows[i][j] - expect[i][j]).abs() < 1e-15, "{rows:?}");
            }
        }
        assert!((rotate(&r, V3::Y) - V3::NEG_X).length() < 1e-15);
        // a generic attitude: (w, x, y, z) round-trips exactly, the matrix agrees with
        // glam's own conversion, and glam's inverse gives the quaternion back (up to sign)
        let n = (0.81f64 + 0.09 + 0.04 + 0.0625).sqrt();
        let wxyz = [0.9, 0.3, -0.2, 0.25].map(|x: f64| x / n);
        let q = quat_from_wxyz(wxyz);
        assert_eq!(quat_to_wxyz(q), wxyz);
        assert_eq!((q.w, q.x, q.y, q.z), (wxyz[0], wxyz[1], wxyz[2], wxyz[3]));
        let r = rotations_from_quaternions(&[wxyz]).unwrap()[0];
        assert!(r.abs_diff_eq(DMat3::from_quat(q), 1e-15));
        let back = DQuat::from_mat3(&r);
        let s = back.dot(q).signum();
        let back = quat_to_wxyz(back * s);
        for k in 0..4 {
            assert!((back[k] - wxyz[k]).abs() < 1e-14, "{back:?} vs {wxyz:?}");
        }
        // rows in, rows out
        let m = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]];
        let a = rot_from_rows(m);
        assert_eq!(rot_to_rows(&a), m);
        assert_eq!(a.row(1), V3::new(4.0, 5.0, 6.0));
        assert_eq!(a.col(0), V3::new(1.0, 4.0, 7.0));
    }

    #[test]
    fn transmitter_rotation_maps_wi_to_z() {
        let n = (0.81f64 + 0.09 + 0.04 + 0.0625).sqrt();
        let r = rotations_from_quaternions(&[[0.9, 0.3, -0.2, 0.25].map(|x: f64| x / n)]).unwrap();
        let beta = 0.4f64;
        let t = transmitter_rotation(&r[0], beta);
        check_rotations(&[t]).unwrap();
        // a body vector that R maps to wi goes to +z
        let wi = [beta.sin(), 0.0, beta.cos()];
        let body = r[0].transpose() * V3::from(wi);
        let v = rotate(&t, body);
        assert!(v[0].abs() < 1e-15 && v[1].abs() < 1e-15 && (v[2] - 1.0).abs() < 1e-15);
        assert_eq!(transmitter_rotation(&r[0], 0.0), r[0]);
    }

    #[test]
    fn flat_surfaces_join_coplanar_faces_of_one_material() {
        // a cube: six surfaces of two faces each, numbered by their first face
        let (v, f) = cube([0.0; 3], 0);
        let m = Mesh::new(v.clone(), f.clone(), None, vec![0; 12], 1).unwrap();
        assert_eq!(m.surfaces(), &[0, 0, 2, 2, 4, 4, 6, 6, 8, 8, 10, 10]);
        // two materials on one face: two surfaces
        let mut fm = vec![0; 12];
        fm[1] = 1;
        let m = Mesh::new(v.clone(), f.clone(), None, fm, 2).unwrap();
        assert_eq!(&m.surfaces()[..2], &[0, 1]);
        // with vertex normals (smooth shading) every face is its own
        let m = Mesh::new(v.clone(), f.clone(), Some(v.clone()), vec![0; 12], 1).unwrap();
        assert_eq!(m.surfaces(), (0..12).collect::<Vec<u32>>());
        // a square of 2 x 8 x 8 faces on unwelded vertices, its last corner (in both faces of
        // the last cell) lifted out of the plane by 1e-9 (slopes of 1e-8, below
        // SURFACE_ANGLE: still flat) or by 1e-6 (slopes of 1e-5: those two faces are not)
        for (lift, joined) in [(0.0, 128), (1e-9, 128), (1e-6, 126)] {
            let (mut v, mut f) = (Vec::new(), Vec::new());
            for i in 0..8 {
                for j in 0..8 {
                    let c = |a: usize, b: usize| {
                        let z = if a + b == 16 { lift } else { 0.0 };
                        [a as f64 * 0.1, b as f64 * 0.1, z]
                    };
                    let q = [c(i, j), c(i + 1, j), c(i + 1, j + 1), c(i, j + 1)];
                    for t in [[0, 1, 2], [0, 2, 3]] {
                        let k = v.len() as u32;
                        v.extend(t.map(|x| q[x]));
                        f.push([k, k + 1, k + 2]);
                    }
                }
            }
            let m = Mesh::new(v, f, None, vec![0; 128], 1).unwrap();
            let s = m.surfaces();
            let n0 = s.iter().filter(|&&x| x == 0).count();
            assert_eq!(n0, joined, "lift {lift}");
        }
    }

    #[test]
    fn mesh_validation() {
        let v = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!(Mesh::new(v.clone(), vec![[0, 1, 2]], None, vec![0], 1).is_ok());
        assert!(Mesh::new(v.clone(), vec![[0, 1, 3]], None, vec![0], 1).is_err());
        assert!(Mesh::new(v.clone(), vec![[0, 1, 1]], None, vec![0], 1).is_err());
        assert!(Mesh::new(v.clone(), vec![[0, 1, 2]], None, vec![1], 1).is_err());
        assert!(Mesh::new(vec![], vec![], None, vec![], 1).is_err());
        let mut bad = v.clone();
        bad[1][0] = f64::NAN;
        assert!(Mesh::new(bad, vec![[0, 1, 2]], None, vec![0], 1).is_err());
    }

    /// A unit cube centred at `c`, outward-wound (counter-clockwise seen from outside).
    fn cube(c: [f64; 3], first: u32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        crate::render::test_scenes::cuboid(c.map(|x| x - 0.5), c.map(|x| x + 0.5), first)
    }

    #[test]
    fn closed_outward_meshes_are_recognized() {
        let (v, f) = cube([0.0; 3], 0);
        // the winding is outward: every face normal points away from the centre
        for t in &f {
            let [a, b, c] = t.map(|k| V3::from(v[k as usize]));
            assert!((b - a).cross(c - a).dot(a) > 0.0);
        }
        assert!(is_closed_outward(&v, &f));
        // two bodies, one overlapping the other: still closed
        let (v2, f2) = cube([0.7, 0.0, 0.0], 8);
        let (mut vv, mut ff) = (v.clone(), f.clone());
        vv.extend(v2);
        ff.extend(f2.clone());
        assert!(is_closed_outward(&vv, &ff));
        // one body turned inside out: its volume is negative
        let n = ff.len();
        for t in &mut ff[n - 12..] {
            t.swap(1, 2);
        }
        assert!(!is_closed_outward(&vv, &ff));
        // a missing face (open), one flipped face (inconsistent), a duplicated face
        assert!(!is_closed_outward(&v, &f[1..]));
        let mut g = f.clone();
        g[3].swap(0, 1);
        assert!(!is_closed_outward(&v, &g));
        let mut g = f.clone();
        g.push(f[0]);
        assert!(!is_closed_outward(&v, &g));
        // unwelded: the same cube with every face on its own vertices
        let vs: Vec<[f64; 3]> = f.iter().flat_map(|t| t.map(|k| v[k as usize])).collect();
        let fs: Vec<[u32; 3]> = (0..f.len() as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect();
        assert!(!is_closed_outward(&vs, &fs));
        assert!(Mesh::new(v, f, None, vec![0; 12], 1).unwrap().closed);
    }

    /// Per component: a closed cube beside an open one (a face missing) and an inside-out
    /// one; the cube's faces alone are flagged closed, and the mesh as a whole is not.
    #[test]
    fn closed_components_are_flagged_per_face() {
        let (mut v, mut f) = cube([0.0; 3], 0);
        let (v2, f2) = cube([3.0, 0.0, 0.0], 8);
        v.extend(v2);
        f.extend_from_slice(&f2[1..]);
        let (v3, mut f3) = cube([-3.0, 0.0, 0.0], 16);
        for t in &mut f3 {
            t.swap(1, 2);
        }
        v.extend(v3);
        f.extend(f3);
        let flags = closed_components(&v, &f);
        assert_eq!(flags.len(), 12 + 11 + 12);
        assert!(flags[..12].iter().all(|&c| c));
        assert!(flags[12..].iter().all(|&c| !c));
        let n = f.len();
        let mesh = Mesh::new(v, f, None, vec![0; n], 1).unwrap();
        assert!(!mesh.closed);
        assert_eq!(mesh.face_closed, flags);
    }
}
