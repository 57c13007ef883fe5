//! Visibility on the CPU (twin of `shaders/visibility.wgsl`): the triangles at an
//! attitude ([`project`]) rasterized exactly in f64 at one point of every pixel
//! ([`rasterize`]), nearest the telescope.

use crate::optics::frames::V3;
use crate::render::geometry::{rotate, Mesh, Rot};

/// Triangle index + 1 seen at each pixel centre (0: empty), row-major `width x width`.
/// Ties (a centre on a shared edge) may resolve differently from the GPU's rasterizer.
pub fn visibility(mesh: &Mesh, rot: &Rot, width: usize, ext: f64) -> Vec<u32> {
    visibility_at(mesh, rot, width, ext, [0.5, 0.5])
}

/// Triangle index + 1 seen at the point `(u, v)` of each pixel (pixel units from its
/// top-left corner, `v` down the rows: `X = -ext + (j + u) delta`, `Y = ext - (i + v)
/// delta`), row-major `width x width` (0: empty). Twin of `shaders/visibility.wgsl` for
/// one visibility sample ([`crate::render::samples::sample_offsets`]).
pub fn visibility_at(mesh: &Mesh, rot: &Rot, width: usize, ext: f64, uv: [f64; 2]) -> Vec<u32> {
    rasterize(&project(mesh, rot), width, ext, uv)
}

/// A triangle seen from the telescope at one attitude: its rotated corners and the
/// projected signed area `den` (twice the area in `x, y`; > 0 facing the telescope on an
/// outward-wound mesh).
pub struct Projected {
    p: [V3; 3],
    den: f64,
}

/// Every triangle of `mesh` at attitude `rot`, in face order (what [`rasterize`] draws for
/// each visibility sample); `None` for triangles edge-on to the telescope and, on a closed
/// outward-wound mesh ([`Mesh::closed`]), for back faces, which the nearest hit from
/// outside never is (the kernel's raster pass culls them too).
pub fn project(mesh: &Mesh, rot: &Rot) -> Vec<Option<Projected>> {
    project_rotated(mesh, &rotate_vertices(mesh, rot))
}

/// The vertices of `mesh` at attitude `rot`.
pub fn rotate_vertices(mesh: &Mesh, rot: &Rot) -> Vec<V3> {
    mesh.vertices
        .iter()
        .map(|&v| rotate(rot, V3::from(v)))
        .collect()
}

/// [`project`] from the vertices already rotated ([`rotate_vertices`]).
pub fn project_rotated(mesh: &Mesh, vertices: &[V3]) -> Vec<Option<Projected>> {
    mesh.faces
        .iter()
        .map(|f| {
            let p = f.map(|k| vertices[k as usize]);
            let den = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
            if den == 0.0 || (mesh.closed && den < 0.0) {
                return None;
            }
            Some(Projected { p, den })
        })
        .collect()
}

/// The pixels `[i0, i1, j0, j1]` (rows `i0..=i1`, columns `j0..=j1`) whose point `(u, v)`
/// lies in the bounding box of the projected corners `p`; `None` if none does.
fn pixel_box(p: &[V3; 3], width: usize, ext: f64, uv: [f64; 2]) -> Option<[usize; 4]> {
    let pix = 2.0 * ext / width as f64;
    let [u, v] = uv;
    let (xmin, xmax) = (
        p[0][0].min(p[1][0]).min(p[2][0]),
        p[0][0].max(p[1][0]).max(p[2][0]),
    );
    let (ymin, ymax) = (
        p[0][1].min(p[1][1]).min(p[2][1]),
        p[0][1].max(p[1][1]).max(p[2][1]),
    );
    let j0 = ((xmin + ext) / pix - u).ceil().max(0.0) as usize;
    let j1 = ((xmax + ext) / pix - u).floor().min(width as f64 - 1.0) as isize;
    let i0 = ((ext - ymax) / pix - v).ceil().max(0.0) as usize;
    let i1 = ((ext - ymin) / pix - v).floor().min(width as f64 - 1.0) as isize;
    (j1 >= 0 && i1 >= 0).then_some([i0, i1 as usize, j0, j1 as usize])
}

/// Triangle index + 1 nearest the telescope at the point `(u, v)` of each pixel (as
/// [`visibility_at`]), from the projected triangles of [`project`].
pub fn rasterize(tris: &[Option<Projected>], width: usize, ext: f64, uv: [f64; 2]) -> Vec<u32> {
    let pix = 2.0 * ext / width as f64;
    let [u, v] = uv;
    let mut ids = vec![0u32; width * width];
    let mut depth = vec![f64::NEG_INFINITY; width * width];
    for (t, tri) in tris.iter().enumerate() {
        let Some(Projected { p, den }) = tri else {
            continue;
        };
        let den = *den;
        let Some([i0, i1, j0, j1]) = pixel_box(p, width, ext, uv) else {
            continue;
        };
        for i in i0..=i1 {
            let y = ext - (i as f64 + v) * pix;
            for j in j0..=j1 {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Back faces of a closed, outward-wound mesh are never the nearest hit: culling them
    /// (what `project` does when `Mesh::closed`) leaves every pixel's visible triangle as
    /// it was, and the faces it drops are about half of them.
    #[test]
    fn culling_back_faces_of_closed_meshes_changes_no_pixel() {
        let closed = crate::render::test_scenes::uv_sphere(0.5, 24, 48);
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
