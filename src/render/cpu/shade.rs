//! Shading on the CPU (twin of `shade_at` in `shaders/shade.wgsl`): a BRDF ([`Brdf`]: the
//! exact core through a closure, or the renderer's tables looked up as the kernel does,
//! [`Tables`]) at a point of a triangle, turned into the telescope's Stokes bases and the
//! sensor's channels ([`shade_point`], [`shade_pixel`]).

use crate::brdf::table::{BrdfTable, TableFrame};
use crate::optics::frames::{beam_bases, cross, dot, neg, norm, normalize, Frame, V3};
use crate::optics::mueller::Mat4;
use crate::render::api::{Layout, SensorSetup};
use crate::render::geometry::{rotate, Mesh, Rot};
use std::f64::consts::PI;

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
        let to_local = |v: V3| V3::new(dot(v, t1), dot(v, t2), dot(v, n));
        let to_world = |v: V3| v.x * t1 + v.y * t2 + v.z * n;
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
        let b = normalize(wi + wo);
        let cos_t = dot(n, b).clamp(0.0, 1.0);
        let nxb = cross(n, b);
        let sin_t = norm(nxb);
        let e_phi = if sin_t > 0.0 {
            nxb / sin_t
        } else {
            any_perp(n)
        };
        let psi = if table.beta == 0.0 {
            0.0
        } else {
            let e_theta = cross(e_phi, b);
            let d = wi - wo;
            dot(d, e_phi).atan2(dot(d, e_theta))
        };
        let m = table.eval_masked(cos_t, sin_t, psi, mask);
        // the table's beam bases: x = e_phi made normal to the beam
        let across = |w: V3| {
            let c = dot(e_phi, w);
            let v = e_phi - c * w;
            let l = dot(v, v).sqrt();
            if l > 1e-15 {
                v / l
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
        cross(k, V3::X)
    } else {
        cross(k, V3::Y)
    })
}

/// `(cos 2b, sin 2b)` of the angle `b` given by `(cos b, sin b)`.
pub(crate) fn double_angle(c: f64, s: f64) -> (f64, f64) {
    (c * c - s * s, 2.0 * s * c)
}

/// The sensor's channels ([`SensorSetup::channels`]) of `k L(ao) M L(ai)`, times `s_tx`
/// for Stokes and intensity outputs, where `L(c, s)` is the Stokes rotation
/// `[[1,0,0,0],[0,c,s,0],[0,-s,c,0],[0,0,0,1]]` by the double angles `ai`, `ao`.
pub(crate) fn telescope_values(
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
    let p = mesh.faces[tri].map(|k| rotate(rot, V3::from(mesh.vertices[k as usize])));
    shade_at(mesh, rot, tri, &p, x, y, &Beam::new(sensor, lay), brdf)
}

/// What shading needs of the sensor, the same for every pixel of a render.
pub(super) struct Beam<'a> {
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
    pub(super) fn new(sensor: &'a SensorSetup, lay: &Layout) -> Self {
        let beta = sensor.bistatic_angle;
        let wi = V3::new(beta.sin(), 0.0, beta.cos());
        let wo = V3::Z;
        let k_in = neg(wi);
        let x_in_t = normalize(cross(k_in, V3::Y));
        Beam {
            sensor,
            max_extent: lay.max_extent,
            pix: lay.pix,
            wi,
            wo,
            sum: wi + wo,
            x_in_t,
            y_in_t: cross(k_in, x_in_t),
            mask: sensor.element_mask(),
        }
    }
}

/// [`shade_point`] with the triangle's rotated corners `p` (as [`project`](super::project)
/// has them).
#[allow(clippy::too_many_arguments)]
pub(super) fn shade_at(
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
    let range = -0.5 * dot(V3::new(x, y, z), s);
    let mut ng = normalize(cross(p[1] - p[0], p[2] - p[0]));
    if ng.z < 0.0 {
        ng = -ng;
    }
    let nz = ng[2].max(1e-12);
    let (dzdx, dzdy) = (-ng[0] / nz, -ng[1] / nz);
    let a = (0.5 * (s[0] + s[2] * dzdx)).abs() * beam.pix;
    let b = (0.5 * (s[1] + s[2] * dzdy)).abs() * beam.pix;
    let widths = (a.min(beam.max_extent), b.min(beam.max_extent));
    let n = mesh.shading_normal(tri, rot, [l0, l1, l2], ng);
    let (ci, co) = (dot(n, wi), dot(n, wo));
    let mut out = PixelSample {
        values: [0.0; 16],
        range,
        widths,
        point: V3::new(x, y, z),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::api::Outputs;
    use crate::render::cpu::render_cpu;

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
}
