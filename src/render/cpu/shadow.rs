//! Transmitter cast shadows on the CPU (bistatic): exact ray casting in f64 toward the
//! transmitter ([`shadowed`]), independent of the kernel's shadow-map rule.

use crate::optics::frames::{cross, V3};
use crate::render::geometry::{rotate, transmitter_rotation, Mesh, Rot};

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
            .map(|f| f.map(|k| rotate(&r, V3::from(mesh.vertices[k as usize]))))
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
    let ng = cross(t[1] - t[0], t[2] - t[0]);
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
