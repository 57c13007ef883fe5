//! CPU twins of the kernels, in f64: `visibility` (of `shaders/visibility.wgsl`) by
//! rasterizing pixel centres exactly, `shade_pixel` and `render_cpu` (of
//! `shaders/shade.wgsl`) with any BRDF: the material's tables (what the GPU uses) or the
//! exact core evaluation ([`Brdf`]). With the core, the Stokes bases come from
//! [`crate::optics::frames`]'s `beam_bases` in a local frame (the kernel builds them from
//! cross products), so comparing the two checks the frame handling; with the tables
//! ([`Tables`]) the twin looks them up as the kernel does, and a test checks that against
//! [`crate::brdf::table::BrdfTable::eval_dirs`] and `change_bases`. Transmitter cast shadows (bistatic) are
//! decided here by exact ray casting in f64 ([`shadowed`]), independently of the kernel's
//! shadow-map rule. Conventions: [`crate::render`].

use super::geometry::{rotate, transmitter_rotation, Mesh, Rot};
use super::api::{Layout, Outputs, Rendered, SensorSetup};
use super::pulse;
use crate::brdf::table::{BrdfTable, TableFrame};
use crate::optics::frames::{beam_bases, cross, dot, neg, norm, normalize, Frame, V3};
use crate::optics::mueller::Mat4;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::ops::Range;

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
    mesh.vertices.iter().map(|&v| rotate(rot, v)).collect()
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

/// A pixel's shading result.
#[derive(Debug, Clone, Copy)]
pub struct PixelSample {
    /// Differential cross-section in the telescope bases (m^2), the sensor's channels
    /// ([`SensorSetup::channels`]): the Mueller matrix row-major (16), the Stokes vector
    /// `M s_tx` (4) or its intensity (1); the rest 0.
    pub values: [f64; 16],
    pub range: f64,
    /// Sub-pixel range widths `(a, b)` (m).
    pub widths: (f64, f64),
    /// The shaded point (telescope frame, m).
    pub point: V3,
}

/// A Mueller BRDF value and the beam bases it is expressed in: unit `x_in` normal to `wi`
/// and `x_out` normal to `wo` (world frame), with `y_in = -wi x x_in`, `y_out = wo x x_out`.
pub struct Framed {
    pub m: Mat4,
    pub x_in: V3,
    pub x_out: V3,
}

/// A BRDF the CPU renderers shade with.
pub trait Brdf: Sync {
    /// Material `mat` at the unit shading normal `n` for unit `wi`, `wo` above it (world
    /// frame). Only the elements in `mask` (bit `4 a + b` for `M_ab`, as
    /// [`SensorSetup::element_mask`]) need be evaluated; `M00` always is.
    fn eval_framed(&self, mat: usize, n: V3, wi: V3, wo: V3, mask: u32) -> Framed;
}

/// `brdf(material, wi_local, wo_local)`: the Mueller BRDF in the `Sp` frame of a local
/// frame with `n = z` (its tangents from a fixed helper axis: `t1 = -any_perp(n)`), all
/// elements.
impl<F: Fn(usize, V3, V3) -> Mat4 + Sync> Brdf for F {
    fn eval_framed(&self, mat: usize, n: V3, wi: V3, wo: V3, _mask: u32) -> Framed {
        let t1 = neg(any_perp(n));
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
        let m = self(mat, wil, wol);
        let (xi, _, xo, _) = beam_bases(Frame::Sp, wil, wol);
        Framed {
            m,
            x_in: to_world(xi),
            x_out: to_world(xo),
        }
    }
}

/// The renderer's BRDF tables (one per material), looked up as `shade.wgsl` does: bisector
/// coordinates and bases from cross products with the normal, only the masked elements.
/// Tables in the `Sp` frame go through [`BrdfTable::eval_dirs`] in a local frame.
pub struct Tables<'a>(pub &'a [BrdfTable]);

impl Brdf for Tables<'_> {
    fn eval_framed(&self, mat: usize, n: V3, wi: V3, wo: V3, mask: u32) -> Framed {
        let table = &self.0[mat];
        if table.frame != TableFrame::Bisector {
            let by_dirs = |_: usize, a: V3, b: V3| table.eval_dirs(a, b);
            return by_dirs.eval_framed(mat, n, wi, wo, mask);
        }
        // the lookup of `shade_at`: b the bisector, e_phi = n x b / |n x b|,
        // psi = atan2((wi - wo).e_phi, (wi - wo).e_theta), e_theta = e_phi x b
        let b = normalize([wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]]);
        let cos_t = dot(n, b).clamp(0.0, 1.0);
        let nxb = cross(n, b);
        let sin_t = norm(nxb);
        let e_phi = if sin_t > 0.0 {
            [nxb[0] / sin_t, nxb[1] / sin_t, nxb[2] / sin_t]
        } else {
            any_perp(n)
        };
        let psi = if table.beta == 0.0 {
            0.0
        } else {
            let e_theta = cross(e_phi, b);
            let d = [wi[0] - wo[0], wi[1] - wo[1], wi[2] - wo[2]];
            dot(d, e_phi).atan2(dot(d, e_theta))
        };
        let m = table.eval_masked(cos_t, sin_t, psi, mask);
        // the table's beam bases: x = e_phi made normal to the beam
        let across = |w: V3| {
            let c = dot(e_phi, w);
            let v = [
                e_phi[0] - c * w[0],
                e_phi[1] - c * w[1],
                e_phi[2] - c * w[2],
            ];
            let l = dot(v, v).sqrt();
            if l > 1e-15 {
                [v[0] / l, v[1] / l, v[2] / l]
            } else {
                any_perp(w)
            }
        };
        let x_in = across(wi);
        Framed {
            m,
            x_in,
            // monostatic: the same vector
            x_out: if wo == wi { x_in } else { across(wo) },
        }
    }
}

/// A unit vector normal to unit `k` (as `any_perp` in `shade.wgsl`).
fn any_perp(k: V3) -> V3 {
    normalize(if k[0].abs() < 0.9 {
        cross(k, [1.0, 0.0, 0.0])
    } else {
        cross(k, [0.0, 1.0, 0.0])
    })
}

/// `(cos 2b, sin 2b)` of the angle `b` given by `(cos b, sin b)`.
fn double_angle(c: f64, s: f64) -> (f64, f64) {
    (c * c - s * s, 2.0 * s * c)
}

/// The sensor's channels ([`SensorSetup::channels`]) of `k L(ao) M L(ai)`, times `s_tx`
/// for Stokes and intensity outputs, where `L(c, s)` is the Stokes rotation
/// `[[1,0,0,0],[0,c,s,0],[0,-s,c,0],[0,0,0,1]]` by the double angles `ai`, `ao`.
fn telescope_values(
    m: &Mat4,
    ai: (f64, f64),
    ao: (f64, f64),
    k: f64,
    sensor: &SensorSetup,
) -> [f64; 16] {
    let mut out = [0.0; 16];
    match sensor.polarization {
        None => {
            // M L(ai), then L(ao) on the left
            let mut t = *m;
            for row in t.iter_mut() {
                let (a1, a2) = (row[1], row[2]);
                row[1] = a1 * ai.0 - a2 * ai.1;
                row[2] = a1 * ai.1 + a2 * ai.0;
            }
            for j in 0..4 {
                let (b1, b2) = (t[1][j], t[2][j]);
                out[j] = k * t[0][j];
                out[4 + j] = k * (ao.0 * b1 + ao.1 * b2);
                out[8 + j] = k * (-ao.1 * b1 + ao.0 * b2);
                out[12 + j] = k * t[3][j];
            }
        }
        Some(s) => {
            // v = L(ai) s_tx, u = M v, out = L(ao) u
            let v = [
                s[0],
                ai.0 * s[1] + ai.1 * s[2],
                -ai.1 * s[1] + ai.0 * s[2],
                s[3],
            ];
            let row = |i: usize| (0..4).map(|j| m[i][j] * v[j]).sum::<f64>();
            out[0] = k * row(0);
            if !sensor.intensity_only {
                let (u1, u2) = (row(1), row(2));
                out[1] = k * (ao.0 * u1 + ao.1 * u2);
                out[2] = k * (-ao.1 * u1 + ao.0 * u2);
                out[3] = k * row(3);
            }
        }
    }
    out
}

/// Shade pixel `(row, col)` whose centre sees triangle `tri` (f64 twin of `shade.wgsl`).
#[allow(clippy::too_many_arguments)]
pub fn shade_pixel(
    mesh: &Mesh,
    rot: &Rot,
    tri: usize,
    row: usize,
    col: usize,
    lay: &Layout,
    sensor: &SensorSetup,
    brdf: &(impl Brdf + ?Sized),
) -> Option<PixelSample> {
    let x = -lay.ext + (col as f64 + 0.5) * lay.pix;
    let y = lay.ext - (row as f64 + 0.5) * lay.pix;
    shade_point(mesh, rot, tri, x, y, lay, sensor, brdf)
}

/// Shade the point `(x, y)` (telescope frame, m) of triangle `tri`: the differential
/// cross-section of a whole pixel there in the sensor's channels, with its range and the
/// pixel's footprint widths (f64 twin of `shade_at` in `shade.wgsl`); `None` if `tri` is
/// degenerate in projection.
#[allow(clippy::too_many_arguments)]
pub fn shade_point(
    mesh: &Mesh,
    rot: &Rot,
    tri: usize,
    x: f64,
    y: f64,
    lay: &Layout,
    sensor: &SensorSetup,
    brdf: &(impl Brdf + ?Sized),
) -> Option<PixelSample> {
    let p = mesh.faces[tri].map(|k| rotate(rot, mesh.vertices[k as usize]));
    shade_at(mesh, rot, tri, &p, x, y, &Beam::new(sensor, lay), brdf)
}

/// What shading needs of the sensor, the same for every pixel of a render.
struct Beam<'a> {
    sensor: &'a SensorSetup,
    max_extent: f64,
    pix: f64,
    wi: V3,
    wo: V3,
    /// `wi + wo`
    sum: V3,
    /// The telescope's incident basis: `x_in_t = normalize(k_in x Y)`, `y_in_t = k_in x x_in_t`
    /// (`x_out_t = X`, `y_out_t = Y`).
    x_in_t: V3,
    y_in_t: V3,
    mask: u32,
}

impl<'a> Beam<'a> {
    fn new(sensor: &'a SensorSetup, lay: &Layout) -> Self {
        let beta = sensor.bistatic_angle;
        let wi = [beta.sin(), 0.0, beta.cos()];
        let wo = [0.0, 0.0, 1.0];
        let k_in = [-wi[0], -wi[1], -wi[2]];
        let x_in_t = normalize(cross(k_in, [0.0, 1.0, 0.0]));
        Beam {
            sensor,
            max_extent: lay.max_extent,
            pix: lay.pix,
            wi,
            wo,
            sum: [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]],
            x_in_t,
            y_in_t: cross(k_in, x_in_t),
            mask: sensor.element_mask(),
        }
    }
}

/// [`shade_point`] with the triangle's rotated corners `p` (as [`project`] has them).
#[allow(clippy::too_many_arguments)]
fn shade_at(
    mesh: &Mesh,
    rot: &Rot,
    tri: usize,
    p: &[V3; 3],
    x: f64,
    y: f64,
    beam: &Beam<'_>,
    brdf: &(impl Brdf + ?Sized),
) -> Option<PixelSample> {
    let den = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
    if den == 0.0 {
        return None;
    }
    let (dx, dy) = (x - p[0][0], y - p[0][1]);
    let l1 = (dx * (p[2][1] - p[0][1]) - dy * (p[2][0] - p[0][0])) / den;
    let l2 = ((p[1][0] - p[0][0]) * dy - (p[1][1] - p[0][1]) * dx) / den;
    let l0 = 1.0 - l1 - l2;
    let z = l0 * p[0][2] + l1 * p[1][2] + l2 * p[2][2];
    let (wi, wo, s) = (beam.wi, beam.wo, beam.sum);
    let range = -0.5 * dot([x, y, z], s);
    let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
    let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
    let mut ng = normalize(cross(e1, e2));
    if ng[2] < 0.0 {
        ng = [-ng[0], -ng[1], -ng[2]];
    }
    let nz = ng[2].max(1e-12);
    let (dzdx, dzdy) = (-ng[0] / nz, -ng[1] / nz);
    let a = (0.5 * (s[0] + s[2] * dzdx)).abs() * beam.pix;
    let b = (0.5 * (s[1] + s[2] * dzdy)).abs() * beam.pix;
    let widths = (a.min(beam.max_extent), b.min(beam.max_extent));
    let mut n = ng;
    if let Some(ns) = &mesh.normals {
        let c = mesh.faces[tri].map(|k| ns[k as usize]);
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
    let mut out = PixelSample {
        values: [0.0; 16],
        range,
        widths,
        point: [x, y, z],
    };
    if ci <= 0.0 || co <= 0.0 {
        return Some(out);
    }
    let mat = mesh.face_material[tri] as usize;
    let fr = brdf.eval_framed(mat, n, wi, wo, beam.mask);
    // S_in (BRDF bases) = L(ai) S_in (telescope): cos = x_in.x_in_t, sin = x_in.y_in_t;
    // S_out (telescope) = L(ao) S_out (BRDF bases): cos = X.x_out, sin = X.y_out
    let ai = double_angle(dot(fr.x_in, beam.x_in_t), dot(fr.x_in, beam.y_in_t));
    let y_out = cross(wo, fr.x_out);
    let ao = double_angle(fr.x_out[0], y_out[0]);
    let k = 4.0 * PI * ci * beam.pix * beam.pix;
    out.values = telescope_values(&fr.m, ai, ao, k, beam.sensor);
    Some(out)
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
/// triangles were to be examined or more than `MAX_CAND` overlap the pixel. `vertices`: the
/// mesh's vertices at the attitude ([`rotate_vertices`]).
pub fn coverage_parts(
    mesh: &Mesh,
    vertices: &[V3],
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
        let p = mesh.faces[t].map(|k| vertices[k as usize]);
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
/// at its centre; else [`coverage_parts`], or the centre sample alone where that overflows
/// (`vertices` as there).
pub fn analytic_parts(
    mesh: &Mesh,
    vertices: &[V3],
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
    coverage_parts(mesh, vertices, lay, row, col, &cand).unwrap_or_else(|| {
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

/// Row blocks of one attitude whose accumulators are held at once: they are rendered
/// (in parallel) in groups of this many and added in order to the attitude's sums, so a
/// profile with many bins does not cost a copy per block of the whole image.
pub const BLOCKS_AT_ONCE: usize = 32;

/// Bytes one attitude of [`render_cpu`] holds at its peak: the K sample id maps, one depth
/// map while they are drawn, the requested per-pixel outputs and profile, and the
/// profiles and pulse-weight scratch of the row blocks held at once ([`BLOCKS_AT_ONCE`]).
pub fn attitude_bytes(
    width: usize,
    samples: usize,
    channels: usize,
    n_bins: usize,
    outputs: Outputs,
) -> usize {
    let px = width * width;
    let mut b = px * (4 * samples + 8) + output_bytes(width, channels, n_bins, outputs);
    let blocks = width.div_ceil(ROWS_PER_BLOCK).min(BLOCKS_AT_ONCE);
    let profile_channels = if outputs.profile { channels } else { 0 };
    b += blocks * (profile_channels + 1) * n_bins * 8;
    b
}

/// Bytes of one attitude's requested outputs as [`render_cpu`] returns them.
fn output_bytes(width: usize, channels: usize, n_bins: usize, outputs: Outputs) -> usize {
    let px = width * width;
    let mut b = channels * 8;
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

/// Peak memory (bytes) of a CPU render of `n` attitudes: the attitudes rendered at once
/// ([`attitude_bytes`], [`attitudes_at_once`]) and every attitude's outputs, twice (the
/// per-attitude results and the batch arrays they are gathered into).
pub fn render_bytes(mesh: &Mesh, sensor: &SensorSetup, n: usize, outputs: Outputs) -> usize {
    let lay = Layout::new(mesh, sensor);
    let (w, ch) = (lay.width, sensor.channels());
    let one = attitude_bytes(w, sensor.samples, ch, lay.n_bins, outputs);
    let at_once = attitudes_at_once(one, rayon::current_num_threads()).min(n);
    at_once
        .saturating_mul(one)
        .saturating_add(n.saturating_mul(2 * output_bytes(w, ch, lay.n_bins, outputs)))
}

/// Memory the system can give without swapping (`MemAvailable` of `/proc/meminfo`), in
/// bytes; None where it cannot be read (not Linux).
pub fn available_memory() -> Option<usize> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib.saturating_mul(1024))
}

/// Refuse a CPU render (the twin or the reference) that would not fit: more profile bins
/// than the device path accepts ([`Layout::check_bins`]), or more memory than is available
/// ([`render_bytes`] against [`available_memory`]): an allocation failure would abort
/// the process, so the render is refused up front with the memory it would need.
pub fn check_cpu_render(
    mesh: &Mesh,
    sensor: &SensorSetup,
    n: usize,
    outputs: Outputs,
) -> crate::Result<()> {
    let lay = Layout::new(mesh, sensor);
    lay.check_bins(sensor)?;
    let need = render_bytes(mesh, sensor, n, outputs);
    if let Some(avail) = available_memory() {
        if need > avail {
            const GIB: f64 = (1u64 << 30) as f64;
            return Err(crate::Error::param(
                "resolution",
                sensor.resolution,
                format!(
                    "this CPU render ({n} attitude(s), {w} x {w} pixels, {k} samples, {b} \
                     bins) needs about {:.1} GiB of memory and {:.1} GiB are available: \
                     lower resolution, supersampling or pixel_samples, request fewer outputs, \
                     or render fewer attitudes per call",
                    need as f64 / GIB,
                    avail as f64 / GIB,
                    w = lay.width,
                    k = sensor.samples,
                    b = lay.n_bins,
                ),
            ));
        }
    }
    Ok(())
}

/// How many attitudes of `bytes` each to render at once on `threads` threads within
/// [`CPU_MEMORY_BUDGET`] (at least one).
pub fn attitudes_at_once(bytes: usize, threads: usize) -> usize {
    (CPU_MEMORY_BUDGET / bytes.max(1)).clamp(1, threads.max(1))
}

/// Rows of an attitude's image per block of [`render_cpu`]'s work.
const ROWS_PER_BLOCK: usize = 8;

/// One pixel's sums over its parts: covered fraction, fraction-weighted range, values.
#[derive(Default)]
struct PixelAcc {
    cov: f64,
    range: f64,
    values: [f64; 16],
}

/// One attitude's outputs, only those requested (a profile-only batch holds no images).
struct Accumulator<'a> {
    sensor: &'a SensorSetup,
    outputs: Outputs,
    /// The first pixel's index: the images hold pixels `first..`.
    first: usize,
    ch: usize,
    support: f64,
    img: Vec<f32>,
    rng: Vec<f32>,
    cov: Vec<f32>,
    prof: Vec<f64>,
    tot: Vec<f64>,
    /// Scratch: one part's pulse weights per range bin.
    weights: Vec<f64>,
}

impl<'a> Accumulator<'a> {
    /// For the pixels `pixels` (row-major indices) of one attitude.
    fn new(sensor: &'a SensorSetup, lay: &Layout, outputs: Outputs, pixels: Range<usize>) -> Self {
        let (n, ch, nb) = (pixels.len(), sensor.channels(), lay.n_bins);
        Accumulator {
            sensor,
            outputs,
            first: pixels.start,
            ch,
            support: lay.support,
            img: vec![0.0; if outputs.image { n * ch } else { 0 }],
            rng: vec![f32::NAN; if outputs.range { n } else { 0 }],
            cov: vec![0.0; if outputs.range { n } else { 0 }],
            prof: vec![0.0; if outputs.profile { nb * ch } else { 0 }],
            tot: vec![0.0; ch],
            weights: vec![0.0; nb],
        }
    }

    /// Add the shaded part `s` of a pixel to its sums `px` and its pulse to the profile.
    fn add(&mut self, px: &mut PixelAcc, part: &Part, s: &PixelSample, edges: &[f64]) {
        let (ch, frac) = (self.ch, part.frac);
        px.cov += frac;
        px.range += frac * s.range;
        let vals = s.values.map(|v| frac * v);
        for (p, v) in px.values.iter_mut().zip(&vals).take(ch) {
            *p += v;
        }
        if self.outputs.profile && vals[0] != 0.0 {
            // the footprint of the part of the pixel it spans (whole: 1)
            let (a, b) = (part.span[0] * s.widths.0, part.span[1] * s.widths.1);
            let weights = &mut self.weights;
            match &self.sensor.pulse {
                Some(p) => p.bin_weights(s.range, a, b, edges, weights),
                None => pulse::bin_weights_folded(
                    s.range,
                    a,
                    b,
                    self.sensor.sigma_range,
                    self.support + 0.5 * (a + b),
                    edges,
                    weights,
                ),
            }
            for (bin, &wt) in self.prof.chunks_exact_mut(ch).zip(weights.iter()) {
                if wt != 0.0 {
                    for (p, v) in bin.iter_mut().zip(&vals) {
                        *p += wt * v;
                    }
                }
            }
        }
    }

    /// Write pixel `k`'s sums to the images and the totals.
    fn finish(&mut self, k: usize, px: &PixelAcc) {
        let (ch, k) = (self.ch, k - self.first);
        if px.cov > 0.0 && self.outputs.range {
            self.rng[k] = (px.range / px.cov) as f32;
            self.cov[k] = px.cov as f32;
        }
        for c in 0..ch {
            if self.outputs.image {
                self.img[k * ch + c] = px.values[c] as f32;
            }
            self.tot[c] += px.values[c];
        }
    }

    /// The accumulator of consecutive pixel ranges from theirs, the sums added in their
    /// order.
    fn concat(blocks: impl IntoIterator<Item = Self>) -> Self {
        let mut it = blocks.into_iter();
        let mut a = it.next().expect("at least one block");
        for b in it {
            a.img.extend(b.img);
            a.rng.extend(b.rng);
            a.cov.extend(b.cov);
            for (x, y) in a.prof.iter_mut().zip(&b.prof) {
                *x += y;
            }
            for (x, y) in a.tot.iter_mut().zip(&b.tot) {
                *x += y;
            }
        }
        a
    }

    /// One attitude's outputs `(image, range, profile, total, coverage)`.
    #[allow(clippy::type_complexity)]
    fn into_outputs(self) -> (Vec<f32>, Vec<f32>, Vec<f64>, Vec<f64>, Vec<f32>) {
        (self.img, self.rng, self.prof, self.tot, self.cov)
    }
}

/// The whole renderer on the CPU in f64 (twin of `gpu::render`, without supersampling
/// of the image outputs: `sensor.supersampling` must be 1).
pub fn render_cpu(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl Brdf + ?Sized),
) -> Rendered {
    let lay = Layout::new(mesh, sensor);
    let w = lay.width;
    let ch = sensor.channels();
    let nb = lay.n_bins;
    let edges: Vec<f64> = (0..=nb)
        .map(|k| lay.r_min + k as f64 * sensor.bin_width)
        .collect();
    let offsets = super::samples::sample_offsets(sensor.samples);
    let beta = sensor.bistatic_angle;
    let beam = Beam::new(sensor, &lay);
    // per attitude: the rotated vertices, the visibility samples' id maps (in parallel
    // when the attitudes are not) and the transmitter's view (bistatic)
    let prepare = |rot: &Rot, in_parallel: bool| {
        let vertices = rotate_vertices(mesh, rot);
        let tris = project_rotated(mesh, &vertices);
        let ids: Vec<Vec<u32>> = if in_parallel {
            offsets
                .par_iter()
                .map(|&uv| rasterize(&tris, w, lay.ext, uv))
                .collect()
        } else {
            offsets
                .iter()
                .map(|&uv| rasterize(&tris, w, lay.ext, uv))
                .collect()
        };
        let tx = (beta > 0.0).then(|| TransmitterView::new(mesh, rot, beta));
        (vertices, ids, tx)
    };
    // shade the pixels of rows `rows` of an attitude
    let shade_rows = |rot: &Rot,
                      (vertices, ids, tx): &(Vec<V3>, Vec<Vec<u32>>, Option<TransmitterView>),
                      rows: &Range<usize>| {
        let mut acc = Accumulator::new(sensor, &lay, outputs, rows.start * w..rows.end * w);
        let mut parts: Vec<Part> = Vec::with_capacity(sensor.samples);
        for k in rows.start * w..rows.end * w {
            // a pixel none of whose samples sees the mesh adds nothing (analytic coverage
            // also looks at the neighbours' centres)
            if !sensor.analytic && ids.iter().all(|s_ids| s_ids[k] == 0) {
                continue;
            }
            let (row, col) = (k / w, k % w);
            if sensor.analytic {
                parts = analytic_parts(mesh, vertices, &lay, &ids[0], row, col);
            } else {
                sampled_parts_into(ids, &offsets, mesh.surfaces(), k, &mut parts);
            }
            let mut px = PixelAcc::default();
            for part in &parts {
                let tri = part.tri;
                let x = -lay.ext + (col as f64 + part.centre[0]) * lay.pix;
                let y = lay.ext - (row as f64 + part.centre[1]) * lay.pix;
                // from the rotated vertices, not from `project`'s triangles: in pixel order
                // they are the smaller working set (and `project` drops back faces)
                let corners = mesh.faces[tri].map(|k| vertices[k as usize]);
                let Some(mut s) = shade_at(mesh, rot, tri, &corners, x, y, &beam, brdf) else {
                    continue;
                };
                // cast shadow: the point stays covered (range reported) but returns nothing
                if let Some(tx) = tx {
                    let lit = s.values.iter().any(|&v| v != 0.0);
                    if lit && shadowed(tx, tri, s.point) {
                        s.values = [0.0; 16];
                    }
                }
                acc.add(&mut px, part, &s, &edges);
            }
            acc.finish(k, &px);
        }
        acc
    };
    // an attitude's rows in fixed blocks (not one per thread), summed in their order: the
    // same sums in any batch, on any number of threads
    let blocks: Vec<Range<usize>> = (0..w)
        .step_by(ROWS_PER_BLOCK)
        .map(|r| r..(r + ROWS_PER_BLOCK).min(w))
        .collect();
    // (in groups of BLOCKS_AT_ONCE, each group added in order to the sums so far: the
    // same additions in the same order as all blocks at once, without holding every
    // block's profile)
    let render_one = |rot: &Rot, in_parallel: bool| {
        let prep = prepare(rot, in_parallel);
        let mut sums: Option<Accumulator> = None;
        for group in blocks.chunks(BLOCKS_AT_ONCE) {
            let accs: Vec<Accumulator> = if in_parallel {
                group
                    .par_iter()
                    .map(|r| shade_rows(rot, &prep, r))
                    .collect()
            } else {
                group.iter().map(|r| shade_rows(rot, &prep, r)).collect()
            };
            sums = Some(Accumulator::concat(sums.into_iter().chain(accs)));
        }
        sums.expect("at least one row block").into_outputs()
    };
    // attitudes in parallel when there are enough of them and that many fit the memory
    // budget; otherwise at most as many at a time as fit, each one's visibility samples
    // and row blocks in parallel
    let threads = rayon::current_num_threads();
    let at_once = attitudes_at_once(attitude_bytes(w, sensor.samples, ch, nb, outputs), threads);
    #[allow(clippy::type_complexity)]
    let per: Vec<(Vec<f32>, Vec<f32>, Vec<f64>, Vec<f64>, Vec<f32>)> =
        if at_once >= threads && rotations.len() >= threads {
            rotations.par_iter().map(|r| render_one(r, false)).collect()
        } else {
            rotations
                .chunks(at_once)
                .flat_map(|c| {
                    c.par_iter()
                        .map(|r| render_one(r, true))
                        .collect::<Vec<_>>()
                })
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
/// originals, looked up as the kernel does: [`Tables`]): what `Lidar(arithmetic="f64")`
/// runs. Against `gpu::render` with the same tables only the arithmetic differs (and, when
/// bistatic, the cast-shadow test: exact rays here, the kernel's shadow map there).
pub fn render_tables(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    tables: &[BrdfTable],
) -> Rendered {
    render_supersampled(mesh, sensor, rotations, outputs, &Tables(tables))
}

/// [`render_cpu`] at `sensor.supersampling` sub-pixels per pixel side, the images summed
/// and the range averaged over covered sub-pixels to the sensor's pixels (as `gpu::render`).
pub fn render_supersampled(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl Brdf + ?Sized),
) -> Rendered {
    let mut r = render_cpu(mesh, sensor, rotations, outputs, brdf);
    let ss = sensor.supersampling;
    if ss > 1 {
        let (w, res, n, ch) = (r.width, sensor.resolution, r.n, r.channels);
        if let Some(img) = r.image.as_mut() {
            let mut out = vec![0.0f32; n * res * res * ch];
            super::downsample::downsample_sum(img, n, w, ss, ch, &mut out);
            *img = out;
        }
        if let Some(rng) = r.range.as_mut() {
            let mut out = vec![0.0f32; n * res * res];
            let mut cov = vec![0.0f32; n * res * res];
            let c0 = r.coverage.take().expect("coverage with the range");
            super::downsample::downsample_range(rng, &c0, n, w, ss, &mut out, &mut cov);
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
        // bytes per pixel, the profile and the total, and 16 row blocks' profiles and
        // weights
        let b = attitude_bytes(128, 8, 16, 100, all);
        let blocks = 16 * (100 * 16 * 8 + 100 * 8);
        assert_eq!(
            b,
            128 * 128 * (4 * 8 + 8 + 16 * 4 + 8) + 100 * 16 * 8 + 16 * 8 + blocks
        );
        assert_eq!(attitudes_at_once(b, 16), 16); // small: one per thread
        let profile_only = Outputs {
            image: false,
            range: false,
            profile: true,
        };
        assert_eq!(
            attitude_bytes(128, 8, 16, 100, profile_only),
            128 * 128 * 40 + 100 * 16 * 8 + 16 * 8 + blocks
        );
        // many bins at the largest side: the blocks held at once are BLOCKS_AT_ONCE, not
        // all 1024 of them
        assert_eq!(
            attitude_bytes(8192, 1, 1, 65536, profile_only),
            8192 * 8192 * 12 + 65536 * 8 + 8 + BLOCKS_AT_ONCE * 65536 * 16
        );
        // the largest image side at 16 samples (8192^2 x 144 bytes, 9.7 GB): one at a time
        let big = attitude_bytes(8192, 16, 16, 1000, all);
        assert!(big > CPU_MEMORY_BUDGET);
        assert_eq!(attitudes_at_once(big, 16), 1);
        // in between: as many as fit
        assert_eq!(attitudes_at_once(CPU_MEMORY_BUDGET / 3 + 1, 16), 2);
        assert_eq!(attitudes_at_once(1, 0), 1);
    }

    /// The twin's table lookup ([`Tables`]: the kernel's bisector coordinates and bases
    /// from cross products, only the elements the output needs, double-angle Stokes
    /// rotations) against the table's own evaluation in a local frame
    /// ([`BrdfTable::eval_dirs`], all 16 elements, `change_bases` through Jones matrices):
    /// the same numbers to rounding, for Mueller, Stokes and intensity outputs, monostatic
    /// and bistatic, on a smooth sphere (every orientation of the normal).
    #[test]
    fn table_lookup_as_the_kernel_equals_the_tables_own_evaluation() {
        use crate::brdf::table::BrdfTableOptions;
        let mat = crate::render::test_scenes::metal();
        let mesh = crate::render::test_scenes::uv_sphere(0.5, 16, 32);
        let rots = crate::render::test_scenes::two_attitudes();
        let all = Outputs {
            image: true,
            range: false,
            profile: true,
        };
        let opts = BrdfTableOptions {
            frame: Some(TableFrame::Bisector),
            ..Default::default()
        };
        for beta in [0.0, 2f64.to_radians(), 0.3] {
            let table = BrdfTable::build(&mat, beta, &opts).unwrap();
            let by_dirs = |_: usize, wi: V3, wo: V3| table.eval_dirs(wi, wo);
            let tables = [table.clone()];
            for (pol, intensity_only) in [
                (None, false),
                (Some([1.0, 0.0, 0.0, 0.0]), false),
                (Some([1.0, 0.3, -0.5, 0.4]), false),
                (Some([1.0, 0.0, 0.0, 0.0]), true),
                (Some([1.0, 0.6, 0.2, -0.7]), true),
            ] {
                let mut sensor = crate::render::test_scenes::lambert_sensor(40);
                sensor.bistatic_angle = beta;
                sensor.polarization = pol;
                sensor.intensity_only = intensity_only;
                let a = render_cpu(&mesh, &sensor, &rots, all, &Tables(&tables));
                let b = render_cpu(&mesh, &sensor, &rots, all, &by_dirs);
                let (ia, ib) = (a.image.unwrap(), b.image.unwrap());
                let peak = ib.iter().fold(0.0f32, |m, &v| m.max(v.abs()));
                assert!(peak > 0.0 && ib.iter().filter(|&&v| v != 0.0).count() > 500);
                // images in f32: within two roundings of the larger value
                for (x, y) in ia.iter().zip(&ib) {
                    let tol = 2.5e-7 * x.abs().max(y.abs()) + 1e-12 * peak;
                    assert!((x - y).abs() <= tol, "beta {beta} {pol:?}: {x} vs {y}");
                }
                let scale = b.total[0].abs();
                for (x, y) in a.total.iter().zip(&b.total).chain(
                    a.profile
                        .as_ref()
                        .unwrap()
                        .iter()
                        .zip(b.profile.as_ref().unwrap()),
                ) {
                    assert!(
                        (x - y).abs() <= 1e-10 * scale,
                        "beta {beta} {pol:?}: {x} vs {y}"
                    );
                }
            }
        }
    }

    /// An attitude renders to the same bits alone (its row blocks in parallel) and in a
    /// batch (attitudes in parallel, each one's blocks in turn): the blocks are fixed and
    /// summed in their order.
    #[test]
    fn an_attitude_renders_the_same_alone_and_in_a_batch() {
        let mesh = crate::render::test_scenes::uv_sphere(0.5, 16, 32);
        let q = |a: f64| {
            [
                (0.5 * a).cos(),
                0.6 * (0.5 * a).sin(),
                0.8 * (0.5 * a).sin(),
                0.0,
            ]
        };
        let quats: Vec<[f64; 4]> = (0..8).map(|k| q(0.4 * k as f64)).collect();
        let rots = crate::render::geometry::rotations_from_quaternions(&quats).unwrap();
        let brdf = |_: usize, wi: V3, wo: V3| {
            let mut m = [[0.0; 4]; 4];
            m[0][0] = 0.2 / PI * (1.0 + wi[0] * wo[0]);
            m[1][1] = 0.1 * wo[2];
            m
        };
        let all = Outputs {
            image: true,
            range: true,
            profile: true,
        };
        let mut sensor = crate::render::test_scenes::lambert_sensor(40);
        sensor.samples = 4;
        sensor.bistatic_angle = 0.2;
        let batch = render_cpu(&mesh, &sensor, &rots, all, &brdf);
        let (n_img, n_px, n_prof) = (40 * 40 * 16, 40 * 40, batch.n_bins * 16);
        for (a, rot) in rots.iter().enumerate() {
            let one = render_cpu(&mesh, &sensor, std::slice::from_ref(rot), all, &brdf);
            let bits32 = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let bits64 = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let (bi, oi) = (batch.image.as_ref().unwrap(), one.image.unwrap());
            assert!(
                bits32(&bi[a * n_img..(a + 1) * n_img]) == bits32(&oi),
                "image {a}"
            );
            let (br, or) = (batch.range.as_ref().unwrap(), one.range.unwrap());
            assert!(
                bits32(&br[a * n_px..(a + 1) * n_px]) == bits32(&or),
                "range {a}"
            );
            let (bp, op) = (batch.profile.as_ref().unwrap(), one.profile.unwrap());
            assert!(
                bits64(&bp[a * n_prof..(a + 1) * n_prof]) == bits64(&op),
                "profile {a}"
            );
            let bt = &batch.total[a * 16..(a + 1) * 16];
            assert!(bits64(bt) == bits64(&one.total), "total {a}");
            assert!(one.total[0] > 0.0);
        }
    }

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
