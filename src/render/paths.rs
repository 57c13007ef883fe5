//! Inter-reflections between the parts of a mesh: the light that reaches a pixel's surface
//! after one or two reflections off other surfaces (paths of 2 and 3 bounces), by Monte
//! Carlo path sampling in f64 on the CPU with ray casting against the mesh ([`Bvh`]). The
//! single bounce stays with the backend's renderer; [`crate::render::request::render`]
//! adds these paths to its outputs for every backend. Conventions: [`crate::render`].
//!
//! # The estimator
//!
//! A path of `k` bounces: the receiver sees `p1` (the first surface along `-Z` through a
//! point of the pixel), light reached `p1` from `p2` along `w1` (unit, from `p1` toward
//! `p2`), ..., and `pk` is lit by the transmitter (toward `wi`, not shadowed). The pixel's
//! differential cross-section from such paths is
//!
//! `dsigma_k = 4 pi delta^2 E[ M1(w1, wo) cos1 / pdf1 ... Mk(wi, -w_{k-1}) cos_i(pk) ]`
//!
//! with `p1` uniform over the pixel's area (projected along `wo`), each `w_j` drawn with
//! density `pdf_j` at `p_j`, `M_j(in, out)` the Mueller BRDF of `p_j`'s material (1/sr)
//! and `cos_j = n_j . w_j` (shading normals). One bounce (`w` replaced by `wi` at `p1`) is
//! the renderer's `4 pi f cos(theta_i) delta^2`. The Mueller matrices are composed in
//! their own Stokes bases, rotated into each other for the beam between consecutive
//! surfaces (the beam `p_{j+1} -> p_j` is the input of `M_j` and the output of `M_{j+1}`),
//! and the path's first input and last output into the telescope's bases.
//!
//! **Sampling.** At each surface the next direction is drawn from a mixture of the
//! material's lobes: the specular lobe through the distribution of normals (`h` with
//! density `D(h) cos(theta_h)` about the shading normal, `w = reflect(w_out, h)`, pdf
//! `D cos(theta_h) / (4 |w_out . h|)`: Walter et al. 2007) and the depolarizing lobe
//! (multiple scattering + diffuse) by cosine-weighted directions, chosen with probabilities
//! in proportion to their albedos at `w_out` (at least [`MIN_LOBE_P`] each when both
//! exist); the pdf is the mixture's (the balance heuristic between the lobes). The last
//! segment, to the transmitter, is fixed (a plane wave): each surface of the path is
//! connected to `wi` with a shadow ray (next-event estimation), and the path goes on from
//! there for the next order. Directions below a surface's geometric or shading horizon
//! carry nothing.
//!
//! **Random numbers.** A pixel's `N` paths use scrambled Sobol' points ([`uniforms`]:
//! three sets, shuffled and Owen-scrambled by hashes of `(seed, pixel, set)`, Burley
//! 2020), stratified in each dimension and jointly in the pairs that draw a point or a
//! direction. They depend on the seed and the pixel only, not on the attitude
//! or its place in the batch: a batch equals single calls bit for bit, and a fit that moves
//! the attitude sees common random numbers (its objective does not jitter from step to
//! step).
//!
//! **What a surface along a path is evaluated with.** Its material's single, multiple and
//! diffuse terms ([`crate::brdf::terms::sum_terms_except`] without the double bounce: its
//! quadrature per path vertex costs more than the path); the one-bounce return, with the
//! double bounce, is the backend's.
//!
//! **Range.** A path lands at half its extra round-trip length,
//! `r = (-pk . wi + sum |p_{j+1} - p_j| - p1 . wo) / 2` (one bounce: `-p . (wi + wo) / 2`);
//! it adds to the profile as a
//! point (the pulse alone, no pixel footprint), to the image at the pixel it is seen in,
//! and not to the range map (the range of the first surface).
//!
//! **Convex meshes.** A closed mesh that is convex, or a flat one, has no inter-reflections:
//! [`has_no_interreflections`] says so and no path is traced.

pub use super::api::{check_paths, PathSetup, MAX_BOUNCES, MAX_PATH_SAMPLES};
use super::api::{Layout, Outputs, Progress, Rendered, SensorSetup};
use super::bvh::Bvh;
use super::cpu::{Brdf, Framed};
use super::geometry::{rotate, Mesh, Rot};
use super::pulse;
use crate::brdf::spec::Term;
use crate::brdf::terms::sum_terms_except;
use crate::brdf::Material;
use crate::error::{Error, Result};
use crate::microfacet::distribution::Distribution;
use crate::optics::frames::{cross, dot, normalize, Frame, V3};
use crate::optics::fresnel::fresnel_amplitudes;
use crate::optics::mueller::Mat4;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::sync::Arc;

/// The least probability of each lobe where a material has both.
pub const MIN_LOBE_P: f64 = 0.1;

/// The lobes to sample at a surface: the specular lobe's distribution of normals (if any)
/// and the probability of choosing it (the rest: the cosine-weighted depolarizing lobe).
#[derive(Debug, Clone, Copy)]
pub struct Lobes {
    pub specular: Option<Distribution>,
    pub p_specular: f64,
}

/// A BRDF the path sampler evaluates and samples.
pub trait PathBrdf: Sync {
    /// Material `mat`'s Mueller BRDF at unit shading normal `n` for unit `wi`, `wo` above
    /// it (world frame), all elements, with its bases ([`Framed`]).
    fn eval(&self, mat: usize, n: V3, wi: V3, wo: V3) -> Framed;
    /// The lobes of `mat` toward `w_out` at `cos(theta) = cos_o`, `sin(theta) = sin_o`
    /// about the normal; `None` where it reflects nothing.
    fn lobes(&self, mat: usize, cos_o: f64, sin_o: f64) -> Option<Lobes>;
}

/// The scene's materials as the path sampler sees them (module docs: single + multiple +
/// diffuse terms; the specular lobe's weight the white single-bounce albedo times the
/// normal-incidence Fresnel reflectance, the depolarizing lobe's its albedo).
pub struct Materials<'a>(pub &'a [Arc<Material>]);

impl PathBrdf for Materials<'_> {
    fn eval(&self, mat: usize, n: V3, wi: V3, wo: V3) -> Framed {
        let mats = self.0;
        let f = |m: usize, a: V3, b: V3| {
            sum_terms_except(&mats[m], a, b, Frame::Sp, Some(Term::Double))
        };
        f.eval_framed(mat, n, wi, wo, 0xffff)
    }

    fn lobes(&self, mat: usize, cos_o: f64, sin_o: f64) -> Option<Lobes> {
        let m = &self.0[mat];
        let terms = m.spec.terms;
        let w_spec = if terms.single {
            let (rs, rp) = fresnel_amplitudes(1.0, m.spec.eta);
            let r0 = 0.5 * (rs.norm_sqr() + rp.norm_sqr());
            m.white_albedo(cos_o, sin_o).unwrap_or(1.0) * r0
        } else {
            0.0
        };
        let w_dep = if terms.multiple || terms.diffuse {
            let (ms, d) = m.depolarizing_albedo(cos_o, sin_o);
            ms + d
        } else {
            0.0
        };
        lobes_from_weights(m.spec.distribution, w_spec, w_dep)
    }
}

/// [`Lobes`] from the two lobes' weights (probabilities kept within
/// `[MIN_LOBE_P, 1 - MIN_LOBE_P]` where both lobes exist).
pub fn lobes_from_weights(dist: Distribution, w_spec: f64, w_dep: f64) -> Option<Lobes> {
    let (s, d) = (w_spec.max(0.0), w_dep.max(0.0));
    if s + d <= 0.0 || (s + d).is_nan() {
        return None;
    }
    if d == 0.0 {
        return Some(Lobes {
            specular: Some(dist),
            p_specular: 1.0,
        });
    }
    if s == 0.0 {
        return Some(Lobes {
            specular: None,
            p_specular: 0.0,
        });
    }
    Some(Lobes {
        specular: Some(dist),
        p_specular: (s / (s + d)).clamp(MIN_LOBE_P, 1.0 - MIN_LOBE_P),
    })
}

/// Whether no ray leaving the mesh's visible side can meet it again: every face plane has
/// all vertices on or behind it (a closed convex mesh), or all vertices lie in one plane.
/// Within `1e-9` of the bounding radius.
pub fn has_no_interreflections(mesh: &Mesh) -> bool {
    let tol = 1e-9 * mesh.radius.max(f64::MIN_POSITIVE);
    let vs: Vec<V3> = mesh.vertices.iter().map(|&v| V3::from(v)).collect();
    let plane = |f: &[u32; 3]| {
        let [a, b, c] = f.map(|k| vs[k as usize]);
        let n = cross(b - a, c - a);
        let l = dot(n, n).sqrt();
        (l > 0.0).then(|| (n / l, a))
    };
    let flat = match mesh.faces.iter().find_map(plane) {
        Some((n, a)) => vs.iter().all(|&v| dot(n, v - a).abs() <= tol),
        None => true,
    };
    if flat {
        return true;
    }
    mesh.closed
        && mesh
            .faces
            .iter()
            .filter_map(plane)
            .all(|(n, a)| vs.iter().all(|&v| dot(n, v - a) <= tol))
}

/// For each face, whether any vertex of the mesh lies in front of its plane (`[0]`, the side
/// its winding's normal points to) and behind it (`[1]`), beyond `1e-9` of the bounding
/// radius: a ray leaving a face on a side with nothing there cannot meet the mesh, so no
/// path is drawn from it. Computed per flat surface ([`Mesh::surfaces`]: one plane);
/// where that would take more than about `5e7` vertex tests (a large smooth mesh), every
/// side is reported open.
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
                return [true, true];
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
fn surface_areas(mesh: &Mesh) -> Vec<f64> {
    let surf = mesh.surfaces();
    let mut area = vec![0.0; mesh.faces.len()];
    for (t, f) in mesh.faces.iter().enumerate() {
        let [a, b, c] = f.map(|k| V3::from(mesh.vertices[k as usize]));
        area[surf[t] as usize] += 0.5 * cross(b - a, c - a).length();
    }
    area
}

/// A 32-bit hash (the PCG output permutation of Jarzynski and Olano 2020).
#[inline]
pub fn hash32(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// Dimensions of a path's random numbers ([`uniforms`]): the point in the pixel (0, 1), the
/// direction at the first surface (2, 3), at the second (4, 5), and the lobes chosen there
/// (6, 7).
pub const DIMS: usize = 8;

/// Sobol' direction numbers of the first four dimensions (Joe and Kuo's primitive
/// polynomials and initial numbers: `x`, then `s = 1, 2, 3` with `a = 0, 1, 1` and
/// `m = [1], [1, 3], [1, 3, 1]`), 32 bits (the paths use the first three).
fn sobol_directions() -> &'static [[u32; 32]; 4] {
    static V: std::sync::OnceLock<[[u32; 32]; 4]> = std::sync::OnceLock::new();
    V.get_or_init(|| {
        let mut v = [[0u32; 32]; 4];
        for (k, x) in v[0].iter_mut().enumerate() {
            *x = 1u32 << (31 - k);
        }
        let polys: [(usize, u32, &[u32]); 3] = [(1, 0, &[1]), (2, 1, &[1, 3]), (3, 1, &[1, 3, 1])];
        for (d, &(deg, a, m)) in polys.iter().enumerate() {
            let vd = &mut v[d + 1];
            for k in 0..deg {
                vd[k] = m[k] << (31 - k);
            }
            for k in deg..32 {
                let mut x = vd[k - deg] ^ (vd[k - deg] >> deg);
                for j in 1..deg {
                    if (a >> (deg - 1 - j)) & 1 == 1 {
                        x ^= vd[k - j];
                    }
                }
                vd[k] = x;
            }
        }
        v
    })
}

/// Point `index` of Sobol's sequence in dimension `dim` (< 4), as 32 bits.
fn sobol(index: u32, dim: usize) -> u32 {
    let v = &sobol_directions()[dim];
    let mut x = 0u32;
    let mut i = index;
    while i != 0 {
        x ^= v[i.trailing_zeros() as usize];
        i &= i - 1;
    }
    x
}

/// Laine and Karras's hash-based Owen scrambling, on bit-reversed values (each output bit
/// depends on the bits below it only), with Burley's 2020 constants.
fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    let mut x = x.reverse_bits();
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x.reverse_bits()
}

/// The random numbers of one pixel's paths: three independent shuffled, Owen-scrambled
/// Sobol' sequences (Burley 2020), keyed by hashes of `(seed, pixel, set)`, one per pair of
/// dimensions that draws a point or a direction (its Sobol' dimensions 0 and 1, a (0,
/// 2)-sequence: the first `2^m` paths fill every one of `2^m` elementary cells of the
/// square), the lobe choice from dimension 2 of the direction's set. 24 bits each (as an
/// f32). Sets: 0 the point in the pixel, 1 and 2 the directions at the first and second
/// surface.
#[derive(Debug, Clone, Copy)]
pub struct PixelRng {
    base: u32,
}

impl PixelRng {
    pub fn new(seed: u32, pixel: u32) -> Self {
        PixelRng {
            base: hash32(hash32(seed) ^ pixel),
        }
    }

    /// Dimensions 0, 1, 2 of set `set` for path `i`.
    #[inline]
    pub fn set(&self, i: usize, set: u32) -> [f64; 3] {
        let key = hash32(self.base ^ set);
        let index = nested_uniform_scramble(i as u32, key);
        std::array::from_fn(|d| {
            let x = nested_uniform_scramble(sobol(index, d), hash32(key ^ (d as u32 + 1)));
            (x >> 8) as f64 / 16_777_216.0
        })
    }
}

/// All of path `i`'s numbers ([`PixelRng`]) in the order of [`DIMS`].
pub fn uniforms(seed: u32, pixel: u32, i: usize) -> [f64; DIMS] {
    let rng = PixelRng::new(seed, pixel);
    let [a, b, c] = [0, 1, 2].map(|set| rng.set(i, set));
    [a[0], a[1], b[0], b[1], c[0], c[1], b[2], c[2]]
}

/// A surface a path meets: the point, the geometric normal and the shading normal (both
/// on the side the ray came from), the material and the triangle.
#[derive(Debug, Clone, Copy)]
struct Vertex {
    p: V3,
    ng: V3,
    n: V3,
    mat: usize,
    tri: usize,
}

/// The mesh in one attitude: its rotated triangles in a [`Bvh`] and what a hit needs.
struct Posed<'a> {
    mesh: &'a Mesh,
    rot: &'a Rot,
    /// [`open_sides`] of the mesh.
    open: &'a [[bool; 2]],
    tris: Vec<[V3; 3]>,
    bvh: Bvh,
    /// Ray origins leave a surface by this much along its normal (m).
    eps: f64,
}

impl<'a> Posed<'a> {
    fn new(mesh: &'a Mesh, rot: &'a Rot, open: &'a [[bool; 2]]) -> Self {
        let vs: Vec<V3> = mesh
            .vertices
            .iter()
            .map(|&v| rotate(rot, V3::from(v)))
            .collect();
        let tris: Vec<[V3; 3]> = mesh
            .faces
            .iter()
            .map(|f| f.map(|k| vs[k as usize]))
            .collect();
        let bvh = Bvh::new(&tris);
        Posed {
            mesh,
            rot,
            open,
            tris,
            bvh,
            eps: 1e-9 * mesh.radius,
        }
    }

    /// The first surface along `o + t d` (`t > 0`), with its normals facing `-d`.
    fn trace(&self, o: V3, d: V3) -> Option<Vertex> {
        let hit = self.bvh.closest_hit(o, d, 0.0, f64::INFINITY)?;
        let [a, b, c] = self.tris[hit.tri];
        let p = a + hit.u * (b - a) + hit.v * (c - a);
        let mut ng = normalize(cross(b - a, c - a));
        if !ng.is_finite() {
            return None;
        }
        if dot(ng, d) > 0.0 {
            ng = -ng;
        }
        let mut n = ng;
        if let Some(ns) = &self.mesh.normals {
            let [na, nb, nc] = self.mesh.faces[hit.tri].map(|k| V3::from(ns[k as usize]));
            let v = rotate(
                self.rot,
                (1.0 - hit.u - hit.v) * na + hit.u * nb + hit.v * nc,
            );
            let l = dot(v, v).sqrt();
            if l > 1e-15 {
                n = v / l;
                if dot(n, ng) < 0.0 {
                    n = -n;
                }
            }
        }
        Some(Vertex {
            p,
            ng,
            n,
            mat: self.mesh.face_material[hit.tri] as usize,
            tri: hit.tri,
        })
    }

    /// Whether anything of the mesh lies on the side of `v`'s face that `v.ng` points to.
    fn side_open(&self, v: &Vertex) -> bool {
        let [a, b, c] = self.tris[v.tri];
        let front = dot(v.ng, cross(b - a, c - a)) > 0.0;
        self.open[v.tri][if front { 0 } else { 1 }]
    }

    /// Whether `v` sees the transmitter (toward unit `wi`) past the rest of the mesh.
    fn lit(&self, v: &Vertex, wi: V3) -> bool {
        dot(v.ng, wi) > 0.0
            && dot(v.n, wi) > 0.0
            && !self
                .bvh
                .any_hit(v.p + self.eps * v.ng, wi, 0.0, f64::INFINITY, Some(v.tri))
    }
}

/// The pixels of a `w x w` image of the square `[-ext, ext]^2` (row 0 at the top) that
/// the triangles may cover, projected on the axes `(u, v)`: each triangle's bounding box,
/// widened by a pixel (conservative: no pixel with a triangle in it is left out).
fn covered_pixels(tris: &[[V3; 3]], u: V3, v: V3, w: usize, ext: f64) -> Vec<bool> {
    let mut mask = vec![false; w * w];
    let pix = 2.0 * ext / w as f64;
    let last = (w - 1) as f64;
    for t in tris {
        let xs = t.map(|p| dot(p, u));
        let ys = t.map(|p| dot(p, v));
        let (x0, x1) = (xs[0].min(xs[1]).min(xs[2]), xs[0].max(xs[1]).max(xs[2]));
        let (y0, y1) = (ys[0].min(ys[1]).min(ys[2]), ys[0].max(ys[1]).max(ys[2]));
        let c0 = ((x0 + ext) / pix - 1.0).floor().clamp(0.0, last) as usize;
        let c1 = ((x1 + ext) / pix + 1.0).floor().clamp(0.0, last) as usize;
        let r0 = ((ext - y1) / pix - 1.0).floor().clamp(0.0, last) as usize;
        let r1 = ((ext - y0) / pix + 1.0).floor().clamp(0.0, last) as usize;
        for r in r0..=r1 {
            mask[r * w + c0..=r * w + c1]
                .iter_mut()
                .for_each(|m| *m = true);
        }
    }
    mask
}

/// A unit vector normal to unit `n`, and a second one completing a right-handed frame.
fn tangents(n: V3) -> (V3, V3) {
    let a = if n.x.abs() < 0.9 { V3::X } else { V3::Y };
    let t1 = normalize(cross(a, n));
    (t1, cross(n, t1))
}

/// The density (1/sr) of drawing `w` at a surface with shading normal `n` toward `w_out`.
fn pdf(lobes: &Lobes, n: V3, w_out: V3, w: V3) -> f64 {
    let c = dot(n, w);
    if c <= 0.0 {
        return 0.0;
    }
    let mut p = (1.0 - lobes.p_specular) * c / PI;
    if let Some(dist) = lobes.specular {
        let h = w + w_out;
        let l = dot(h, h).sqrt();
        if l > 0.0 {
            let h = h / l;
            let ch = dot(h, n);
            let wh = dot(w_out, h);
            if ch > 0.0 && wh > 0.0 {
                let nxh = cross(n, h);
                let d = dist.d(ch, dot(nxh, nxh).min(1.0));
                p += lobes.p_specular * d * ch / (4.0 * wh);
            }
        }
    }
    p
}

/// A direction drawn at a surface with shading normal `n` toward `w_out` from the
/// uniforms `(u_lobe, u1, u2)`; `None` when the draw falls below the horizon.
fn sample(lobes: &Lobes, n: V3, w_out: V3, u: [f64; 3]) -> Option<V3> {
    let (t1, t2) = tangents(n);
    let phi = 2.0 * PI * u[2];
    let (sp, cp) = phi.sin_cos();
    let w = match lobes.specular {
        Some(dist) if u[0] < lobes.p_specular => {
            let (ch, s2h) = dist.sample_theta(u[1]);
            let sh = s2h.max(0.0).sqrt();
            let h = sh * cp * t1 + sh * sp * t2 + ch * n;
            let wh = dot(w_out, h);
            if wh <= 0.0 {
                return None;
            }
            2.0 * wh * h - w_out
        }
        _ => {
            let r = u[1].sqrt();
            let z = (1.0 - u[1]).max(0.0).sqrt();
            r * cp * t1 + r * sp * t2 + z * n
        }
    };
    (dot(w, n) > 0.0).then_some(w)
}

fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for i in 0..4 {
        for k in 0..4 {
            let aik = a[i][k];
            if aik != 0.0 {
                for j in 0..4 {
                    m[i][j] += aik * b[k][j];
                }
            }
        }
    }
    m
}

/// `m L(c, s)` for the Stokes rotation `L = [[1,0,0,0],[0,c,s,0],[0,-s,c,0],[0,0,0,1]]`.
fn mul_rotation(m: &Mat4, (c, s): (f64, f64)) -> Mat4 {
    let mut t = *m;
    for row in t.iter_mut() {
        let (a1, a2) = (row[1], row[2]);
        row[1] = a1 * c - a2 * s;
        row[2] = a1 * s + a2 * c;
    }
    t
}

/// The Stokes rotation (double angles) taking a beam's Stokes vector in the basis `x_b`
/// (`y_b = k x x_b`, `k` the propagation direction) to the basis `x_a`:
/// `S_a = L(x_a . x_b, x_a . y_b) S_b` (as `shade_at` turns the telescope's bases).
fn basis_change(x_a: V3, x_b: V3, k: V3) -> (f64, f64) {
    let y_b = cross(k, x_b);
    super::cpu::double_angle(dot(x_a, x_b), dot(x_a, y_b))
}

/// What the paths of one attitude add: per order `k = 2..=bounces` (index `k - 2`) the
/// image (pixels, channels), the profile (bins, channels) and the total (channels).
#[derive(Debug, Clone, Default)]
pub struct PathSums {
    pub image: Vec<f64>,
    pub profile: Vec<f64>,
    pub total: Vec<f64>,
}

/// What the sensor's set-up gives every path of a render.
struct Setup<'a> {
    sensor: &'a SensorSetup,
    lay: Layout,
    /// Output pixels per side and their size (m).
    width: usize,
    pix: f64,
    wi: V3,
    wo: V3,
    x_in_t: V3,
    y_in_t: V3,
    edges: Vec<f64>,
    ch: usize,
    orders: usize,
    strategies: Strategies,
    /// The transmitter's image plane: unit `tx_u`, `tx_v` normal to `wi` (`= X`, `Y`
    /// monostatic), spanning the same square as the receiver's.
    tx_u: V3,
    tx_v: V3,
}

/// Which sampling strategies draw the 2-bounce paths: from the receiver's side (a point of
/// the pixel, a direction from its surface's lobes, next-event toward the transmitter) and
/// from the transmitter's (a point of the transmitter's view, a direction from its
/// surface's lobes, a connection to the receiver), combined by the balance heuristic when
/// both are on (the default; one alone is for tests: each must be unbiased by itself).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Strategies {
    pub receiver: bool,
    pub transmitter: bool,
    /// 3-bounce paths also aimed from their middle surface at the glossy flat surfaces
    /// that mirror the transmitter ([`Mirrors`]).
    pub aim: bool,
}

impl Default for Strategies {
    fn default() -> Self {
        Strategies {
            receiver: true,
            transmitter: true,
            aim: true,
        }
    }
}

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
struct Mirrors {
    /// Per face: the index in `list` of its surface if that is a candidate, else `u32::MAX`.
    of_face: Vec<u32>,
    list: Vec<Mirror>,
    /// The cumulative probabilities of `list`.
    cdf: Vec<f64>,
}

struct Mirror {
    /// The surface's normal on its lit side.
    n: V3,
    dist: Distribution,
    /// `P(S)`.
    p: f64,
}

/// The least probability of the specular lobe for a surface to be a [`Mirror`].
const MIRROR_MIN_SPECULAR: f64 = 0.5;

impl Mirrors {
    fn none(n_faces: usize) -> Self {
        Mirrors {
            of_face: vec![u32::MAX; n_faces],
            list: Vec::new(),
            cdf: Vec::new(),
        }
    }

    /// The candidates of `posed` lit along `wi`: flat surfaces ([`Mesh::surfaces`]) whose
    /// lit side is open ([`open_sides`]) and whose material's specular lobe has at least
    /// [`MIRROR_MIN_SPECULAR`] of the probability at `wi`; `area[s]` the area of the
    /// surface whose first face is `s`.
    fn new(posed: &Posed<'_>, brdf: &(impl PathBrdf + ?Sized), wi: V3, area: &[f64]) -> Self {
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
            out.list.push(Mirror { n, dist, p: 0.0 });
        }
        let total: f64 = weights.iter().sum();
        if total <= 0.0 || total.is_nan() {
            return Mirrors::none(mesh.faces.len());
        }
        let mut acc = 0.0;
        for (m, w) in out.list.iter_mut().zip(&weights) {
            m.p = w / total;
            acc += m.p;
            out.cdf.push(acc);
        }
        for (t, &root) in surf.iter().enumerate() {
            if let Some(&j) = index_of_root.get(&root) {
                out.of_face[t] = j;
            }
        }
        out
    }

    /// The candidate drawn by the uniform `u`.
    fn pick(&self, u: f64) -> usize {
        self.cdf
            .partition_point(|&c| c <= u)
            .min(self.list.len() - 1)
    }

    /// The aiming density (per unit solid angle at the middle surface) of the direction `d`
    /// toward the surface `v` lies on, or 0 when `v` is not a candidate met on its lit
    /// side.
    fn density(&self, v: &Vertex, d: V3, wi: V3) -> f64 {
        let j = self.of_face[v.tri];
        if j == u32::MAX {
            return 0.0;
        }
        let m = &self.list[j as usize];
        if dot(v.ng, m.n) <= 0.0 {
            return 0.0;
        }
        m.p * mirror_pdf(m, wi, d)
    }
}

/// The density of the direction `d` (toward the mirror) drawn by aiming at `m`: that of
/// its reflection of `wi`, `-d`, about a normal drawn from its distribution.
fn mirror_pdf(m: &Mirror, wi: V3, d: V3) -> f64 {
    let h = wi - d;
    let l = dot(h, h).sqrt();
    if l <= 0.0 {
        return 0.0;
    }
    let h = h / l;
    let (ch, wh) = (dot(h, m.n), dot(wi, h));
    if ch <= 0.0 || wh <= 0.0 {
        return 0.0;
    }
    let nxh = cross(m.n, h);
    m.dist.d(ch, dot(nxh, nxh).min(1.0)) * ch / (4.0 * wh)
}

/// The transmitter strategy's density of drawing, at the lit surface `v`, the direction
/// `w` toward the seen one (per unit solid angle), times `|ng . wi|` (the transmitter's
/// projected area to `v`'s area): the part of its density in the balance heuristic that
/// is not shared with the receiver's.
fn transmitter_density(brdf: &(impl PathBrdf + ?Sized), v: &Vertex, wi: V3, w: V3) -> f64 {
    let c = dot(v.n, wi);
    let s = cross(v.n, wi);
    match brdf.lobes(v.mat, c, dot(s, s).sqrt()) {
        Some(lobes) => pdf(&lobes, v.n, wi, w) * dot(v.ng, wi).abs(),
        None => 0.0,
    }
}

/// The receiver strategy's counterpart of [`transmitter_density`]: the density of drawing,
/// at the seen surface `v`, the direction `w` toward the lit one, times `|ng . wo|`.
fn receiver_density(brdf: &(impl PathBrdf + ?Sized), v: &Vertex, wo: V3, w: V3) -> f64 {
    let c = dot(v.n, wo);
    let s = cross(v.n, wo);
    match brdf.lobes(v.mat, c, dot(s, s).sqrt()) {
        Some(lobes) => pdf(&lobes, v.n, wo, w) * dot(v.ng, wo).abs(),
        None => 0.0,
    }
}

impl Setup<'_> {
    /// Add `vals` (channels) at range `r` to a profile (bins x channels): the pulse's
    /// weights over the bins it reaches, its tails folded into the end ones (as
    /// [`pulse::bin_weights_folded`] for a point).
    fn deposit(&self, prof: &mut [f64], vals: &[f64], r: f64) {
        let (ch, nb) = (self.ch, self.lay.n_bins);
        let (r_min, bw, half) = (self.lay.r_min, self.sensor.bin_width, self.lay.support);
        let bin = |x: f64| (((x - r_min) / bw).floor().clamp(0.0, (nb - 1) as f64)) as usize;
        let (k0, k1) = (bin(r - half), bin(r + half));
        let mut prev = 0.0;
        for k in k0..=k1 {
            let c = if k < k1 {
                let x = self.edges[k + 1] - r;
                match &self.sensor.pulse {
                    Some(p) => p.cdf_box2(x, 0.0, 0.0),
                    None => pulse::cdf_gauss_box2(x, self.sensor.sigma_range, 0.0, 0.0),
                }
            } else {
                1.0
            };
            let wt = c - prev;
            prev = c;
            if wt != 0.0 {
                for (p, v) in prof[k * ch..(k + 1) * ch].iter_mut().zip(vals) {
                    *p += wt * v;
                }
            }
        }
    }

    /// The telescope's channels of the path matrix `m` whose input is in the basis `x_in`
    /// (normal to `wi`) and output in `x_out` (normal to `wo`), times `k`.
    fn channels(&self, m: &Mat4, x_in: V3, x_out: V3, k: f64) -> [f64; 16] {
        let ai = super::cpu::double_angle(dot(x_in, self.x_in_t), dot(x_in, self.y_in_t));
        let y_out = cross(self.wo, x_out);
        let ao = super::cpu::double_angle(x_out[0], y_out[0]);
        super::cpu::telescope_values(m, ai, ao, k, self.sensor)
    }
}

/// The paths of the pixels `rows` of one attitude: their image rows, profile and totals.
// (the loop over orders indexes the pixel's sums and also picks the random numbers and the
// strategies by order)
#[allow(clippy::needless_range_loop)]
fn render_rows(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    rows: std::ops::Range<usize>,
    outputs: Outputs,
    mask: &[bool],
    mirrors: &Mirrors,
) -> PathSums {
    let (w, ch, orders) = (setup.width, setup.ch, setup.orders);
    let nb = setup.lay.n_bins;
    let paths = setup.sensor.paths;
    let mut out = PathSums {
        image: vec![
            0.0;
            if outputs.image {
                orders * rows.len() * w * ch
            } else {
                0
            }
        ],
        profile: vec![0.0; if outputs.profile { orders * nb * ch } else { 0 }],
        total: vec![0.0; orders * ch],
    };
    let ext = setup.lay.ext;
    let n = paths.samples;
    // each path's share of the pixel: 4 pi delta^2 / N
    let weight = 4.0 * PI * setup.pix * setup.pix / n as f64;
    let (wi, wo) = (setup.wi, setup.wo);
    for row in rows.clone() {
        for col in 0..w {
            let pixel = (row * w + col) as u32;
            let mut px = vec![[0.0f64; 16]; orders];
            let rng = PixelRng::new(paths.seed, pixel);
            let n = if mask[pixel as usize] { n } else { 0 };
            for i in 0..n {
                let u = rng.set(i, 0);
                let x = -ext + (col as f64 + u[0]) * setup.pix;
                let y = ext - (row as f64 + u[1]) * setup.pix;
                let Some(v1) = posed.trace(V3::new(x, y, 2.0 * ext), -V3::Z) else {
                    continue;
                };
                if dot(v1.ng, wo) <= 0.0 || dot(v1.n, wo) <= 0.0 {
                    continue;
                }
                // the throughput from the beam arriving at the current surface (in basis
                // `x_t`) to the receiver (in `x_out1`), and the path's length so far from
                // the current surface to the receiver's plane
                let mut t = [[0.0; 4]; 4];
                for (k, row) in t.iter_mut().enumerate() {
                    row[k] = 1.0;
                }
                let mut x_t = V3::ZERO;
                let mut x_out1 = V3::ZERO;
                let mut length = -dot(v1.p, wo);
                let (mut v, mut w_out) = (v1, wo);
                for order in 0..orders {
                    if !posed.side_open(&v) {
                        break;
                    }
                    // draw the direction toward the next surface at `v`
                    let c = dot(v.n, w_out);
                    let s = cross(v.n, w_out);
                    let Some(lobes) = brdf.lobes(v.mat, c, dot(s, s).sqrt()) else {
                        break;
                    };
                    if order == 1 && !mirrors.list.is_empty() {
                        // a 3-bounce path aimed from `v` at a mirror of the transmitter
                        let aimed = aim(
                            setup,
                            posed,
                            brdf,
                            mirrors,
                            &v,
                            w_out,
                            &lobes,
                            rng.set(i, 3),
                        );
                        if let Some((m, x_in, r3)) = aimed {
                            let m = mat_mul(&mul_rotation(&t, basis_change(x_t, m.1, w_out)), &m.0);
                            let vals = setup.channels(&m, x_in, x_out1, weight);
                            if vals.iter().all(|x| x.is_finite()) {
                                for (a, b) in px[order].iter_mut().zip(&vals) {
                                    *a += b;
                                }
                                if outputs.profile {
                                    let r = 0.5 * (length + r3);
                                    let prof =
                                        &mut out.profile[order * nb * ch..(order + 1) * nb * ch];
                                    setup.deposit(prof, &vals[..ch], r);
                                }
                            }
                        }
                    }
                    let [u1, u2, u_lobe] = rng.set(i, 1 + order as u32);
                    let Some(w_next) = sample(&lobes, v.n, w_out, [u_lobe, u1, u2]) else {
                        break;
                    };
                    if dot(w_next, v.ng) <= 0.0 {
                        break;
                    }
                    let p = pdf(&lobes, v.n, w_out, w_next);
                    if p <= 0.0 || p.is_nan() {
                        break;
                    }
                    // (traced first: most paths leave the mesh here, and cost no BRDF)
                    let Some(next) = posed.trace(v.p + posed.eps * v.ng, w_next) else {
                        break;
                    };
                    let f = brdf.eval(v.mat, v.n, w_next, w_out);
                    let scale = dot(v.n, w_next) / p;
                    let fm = f.m.map(|r| r.map(|e| e * scale));
                    if order == 0 {
                        t = fm;
                        x_out1 = f.x_out;
                    } else {
                        // the beam v -> previous surface: in f's output basis, into t's input
                        t = mat_mul(&mul_rotation(&t, basis_change(x_t, f.x_out, w_out)), &fm);
                    }
                    x_t = f.x_in;
                    length += dot(next.p - v.p, next.p - v.p).sqrt();
                    // next-event: `next` lit by the transmitter, seen from `v` along -w_next
                    let back = -w_next;
                    let drawn = order > 0 || setup.strategies.receiver;
                    if drawn && dot(next.n, back) > 0.0 && posed.lit(&next, wi) {
                        let g = brdf.eval(next.mat, next.n, wi, back);
                        let ci = dot(next.n, wi);
                        // a 2-bounce path is also drawn from the transmitter's side
                        let mis = if order == 0 && setup.strategies.transmitter {
                            let a = dot(v.ng, wo).abs() * p * dot(next.ng, back).abs();
                            let b = transmitter_density(brdf, &next, wi, back)
                                * dot(v.ng, w_next).abs();
                            if a > 0.0 {
                                a / (a + b)
                            } else {
                                0.0
                            }
                        } else if order == 1 && setup.strategies.aim {
                            // a 3-bounce path is also aimed at a mirror from `v`
                            let b = mirrors.density(&next, w_next, wi);
                            p / (p + b)
                        } else {
                            1.0
                        };
                        let gm = g.m.map(|r| r.map(|e| e * ci * mis));
                        let m = mat_mul(&mul_rotation(&t, basis_change(x_t, g.x_out, back)), &gm);
                        let vals = setup.channels(&m, g.x_in, x_out1, weight);
                        if vals[0].is_finite() && vals.iter().all(|x| x.is_finite()) {
                            for (a, b) in px[order].iter_mut().zip(&vals) {
                                *a += b;
                            }
                            if outputs.profile {
                                let r = 0.5 * (length - dot(next.p, wi));
                                let prof = &mut out.profile[order * nb * ch..(order + 1) * nb * ch];
                                setup.deposit(prof, &vals[..ch], r);
                            }
                        }
                    }
                    if dot(next.n, back) <= 0.0 {
                        break;
                    }
                    v = next;
                    w_out = back;
                }
            }
            for (order, vals) in px.iter().enumerate() {
                for (c, &v) in vals.iter().enumerate().take(ch) {
                    out.total[order * ch + c] += v;
                    if outputs.image {
                        let k = ((order * rows.len() + (row - rows.start)) * w + col) * ch + c;
                        out.image[k] = v;
                    }
                }
            }
        }
    }
    out
}

/// The aimed 3-bounce path from the middle surface `v` (its throughput part `(M, x_out)`:
/// `f_v(d, w_out) cos / pdf L f_3(wi, -d) cos_i`, weighted by the balance heuristic against
/// `v`'s own `lobes`, in the bases `x_out` (normal to `w_out`) and the returned `x_in`
/// (normal to `wi`)), and the path's length from `v` on (`|p3 - v| - p3 . wi`); `None` when
/// the aimed ray misses its mirror or the mirror is shadowed ([`Mirrors`]).
#[allow(clippy::too_many_arguments)]
fn aim(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    mirrors: &Mirrors,
    v: &Vertex,
    w_out: V3,
    lobes: &Lobes,
    [u_pick, u1, u2]: [f64; 3],
) -> Option<((Mat4, V3), V3, f64)> {
    let wi = setup.wi;
    let j = mirrors.pick(u_pick);
    let m = &mirrors.list[j];
    let (t1, t2) = tangents(m.n);
    let (ch, s2h) = m.dist.sample_theta(u1);
    let sh = s2h.max(0.0).sqrt();
    let (sp, cp) = (2.0 * PI * u2).sin_cos();
    let h = sh * cp * t1 + sh * sp * t2 + ch * m.n;
    let wh = dot(wi, h);
    if wh <= 0.0 {
        return None;
    }
    let d = -(2.0 * wh * h - wi);
    if dot(d, m.n) >= 0.0 || dot(d, v.ng) <= 0.0 || dot(d, v.n) <= 0.0 {
        return None;
    }
    let p3 = posed.trace(v.p + posed.eps * v.ng, d)?;
    if mirrors.of_face[p3.tri] != j as u32
        || dot(p3.ng, m.n) <= 0.0
        || dot(p3.n, -d) <= 0.0
        || !posed.lit(&p3, wi)
    {
        return None;
    }
    let pdf_aim = m.p * mirror_pdf(m, wi, d);
    let pdf_lobe = pdf(lobes, v.n, w_out, d);
    if pdf_aim <= 0.0 || pdf_aim.is_nan() {
        return None;
    }
    let f = brdf.eval(v.mat, v.n, d, w_out);
    let g = brdf.eval(p3.mat, p3.n, wi, -d);
    let scale = dot(v.n, d) / (pdf_aim + pdf_lobe);
    let ci = dot(p3.n, wi);
    let fm = f.m.map(|r| r.map(|e| e * scale));
    let gm = g.m.map(|r| r.map(|e| e * ci));
    let m = mat_mul(&mul_rotation(&fm, basis_change(f.x_in, g.x_out, -d)), &gm);
    Some(((m, f.x_out), g.x_in, (p3.p - v.p).length() - dot(p3.p, wi)))
}

/// What the transmitter strategy adds for a block of the transmitter's rows: the pixels it
/// lands in with their values (in drawing order), the profile and the totals of the
/// 2-bounce order.
struct TxSums {
    splats: Vec<(usize, [f64; 16])>,
    profile: Vec<f64>,
    total: Vec<f64>,
}

/// The salt of the transmitter strategy's seed.
const TX_SALT: u32 = 0x5bd1_e995;

/// The 2-bounce paths drawn from the transmitter's side for its rows `rows`: a point of
/// the transmitter's pixel (lit: the first surface along `-wi`), a direction from that
/// surface's lobes toward `wi`'s reflection, the surface it meets, and that surface's
/// connection to the receiver (it must see the receiver past the mesh). Weighted by the
/// balance heuristic against the receiver's strategy (module docs).
fn render_tx_rows(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    rows: std::ops::Range<usize>,
    outputs: Outputs,
    mask: &[bool],
) -> TxSums {
    let (w, ch, nb) = (setup.width, setup.ch, setup.lay.n_bins);
    let paths = setup.sensor.paths;
    let mut out = TxSums {
        splats: Vec::new(),
        profile: vec![0.0; if outputs.profile { nb * ch } else { 0 }],
        total: vec![0.0; ch],
    };
    let ext = setup.lay.ext;
    let n = paths.samples;
    let weight = 4.0 * PI * setup.pix * setup.pix / n as f64;
    let (wi, wo) = (setup.wi, setup.wo);
    let seed = hash32(paths.seed ^ TX_SALT);
    for row in rows {
        for col in 0..w {
            let pixel = (row * w + col) as u32;
            if !mask[pixel as usize] {
                continue;
            }
            let rng = PixelRng::new(seed, pixel);
            for i in 0..n {
                let u = rng.set(i, 0);
                let x = -ext + (col as f64 + u[0]) * setup.pix;
                let y = ext - (row as f64 + u[1]) * setup.pix;
                let o = x * setup.tx_u + y * setup.tx_v + 2.0 * ext * wi;
                let Some(v2) = posed.trace(o, -wi) else {
                    continue;
                };
                let c2 = dot(v2.n, wi);
                if c2 <= 0.0 || !posed.side_open(&v2) {
                    continue;
                }
                let s2 = cross(v2.n, wi);
                let Some(lobes) = brdf.lobes(v2.mat, c2, dot(s2, s2).sqrt()) else {
                    continue;
                };
                let [u1, u2, u_lobe] = rng.set(i, 1);
                let Some(w2) = sample(&lobes, v2.n, wi, [u_lobe, u1, u2]) else {
                    continue;
                };
                let p2 = pdf(&lobes, v2.n, wi, w2);
                if dot(w2, v2.ng) <= 0.0 || p2 <= 0.0 || p2.is_nan() {
                    continue;
                }
                let Some(v1) = posed.trace(v2.p + posed.eps * v2.ng, w2) else {
                    continue;
                };
                let w1 = -w2; // at the seen surface, toward the lit one
                if dot(v1.n, w1) <= 0.0 || dot(v1.n, wo) <= 0.0 || dot(v1.ng, wo) <= 0.0 {
                    continue;
                }
                if posed.bvh.any_hit(
                    v1.p + posed.eps * v1.ng,
                    wo,
                    0.0,
                    f64::INFINITY,
                    Some(v1.tri),
                ) {
                    continue;
                }
                // the image pixel it is seen in
                let (pc, pr) = (
                    ((v1.p.x + ext) / setup.pix).floor(),
                    ((ext - v1.p.y) / setup.pix).floor(),
                );
                if !(pc >= 0.0 && pr >= 0.0 && pc < w as f64 && pr < w as f64) {
                    continue;
                }
                let b = dot(v2.ng, wi).abs() * p2 * dot(v1.ng, w1).abs();
                let mis = if setup.strategies.receiver {
                    let a = receiver_density(brdf, &v1, wo, w1) * dot(v2.ng, w2).abs();
                    b / (a + b)
                } else {
                    1.0
                };
                // f1 (w1 -> wo) L f2 (wi -> w2), the beam v2 -> v1 propagating along w2
                let f2 = brdf.eval(v2.mat, v2.n, wi, w2);
                let f1 = brdf.eval(v1.mat, v1.n, w1, wo);
                let m = mat_mul(
                    &mul_rotation(&f1.m, basis_change(f1.x_in, f2.x_out, w2)),
                    &f2.m,
                );
                // (n2.wi)(n1.w1) |ng2.w2| |ng1.wo| / (|ng1.w1| |ng2.wi| pdf2)
                let g = c2 * dot(v1.n, w1) * dot(v2.ng, w2).abs() * dot(v1.ng, wo).abs()
                    / (dot(v1.ng, w1).abs() * dot(v2.ng, wi).abs() * p2);
                let vals = setup.channels(&m, f2.x_in, f1.x_out, weight * g * mis);
                if !vals.iter().all(|x| x.is_finite()) {
                    continue;
                }
                for (a, v) in out.total.iter_mut().zip(&vals) {
                    *a += v;
                }
                if outputs.profile {
                    let len = -dot(v2.p, wi) + (v1.p - v2.p).length() - dot(v1.p, wo);
                    setup.deposit(&mut out.profile, &vals[..ch], 0.5 * len);
                }
                if outputs.image {
                    out.splats.push((pr as usize * w + pc as usize, vals));
                }
            }
        }
    }
    out
}

/// Rows of the image per block of work (blocks are summed in order: the same bits on any
/// number of threads).
const ROWS_PER_BLOCK: usize = 4;

/// The paths of 2 to `sensor.paths.bounces` bounces of each attitude ([`PathSums`], in the
/// order of `rotations`), at the sensor's output resolution (`resolution` pixels per side;
/// supersampling does not apply: each path draws its own point of the pixel).
/// `progress` is told after each attitude (`(done, total)` offset by `progress_offset`).
pub fn render_paths(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl PathBrdf + ?Sized),
    progress: Progress,
    progress_offset: (usize, usize),
) -> Result<Vec<PathSums>> {
    render_paths_with(
        mesh,
        sensor,
        rotations,
        outputs,
        brdf,
        progress,
        progress_offset,
        Strategies::default(),
    )
}

/// [`render_paths`] with the 2-bounce sampling strategies chosen ([`Strategies`]).
#[allow(clippy::too_many_arguments)]
pub fn render_paths_with(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl PathBrdf + ?Sized),
    progress: Progress,
    progress_offset: (usize, usize),
    strategies: Strategies,
) -> Result<Vec<PathSums>> {
    let lay = Layout::new(mesh, sensor);
    let orders = sensor.paths.bounces.saturating_sub(1);
    let beta = sensor.bistatic_angle;
    let wi = V3::new(beta.sin(), 0.0, beta.cos());
    let k_in = -wi;
    let x_in_t = normalize(cross(k_in, V3::Y));
    let setup = Setup {
        sensor,
        lay,
        width: sensor.resolution,
        pix: 2.0 * lay.ext / sensor.resolution as f64,
        wi,
        wo: V3::Z,
        x_in_t,
        y_in_t: cross(k_in, x_in_t),
        edges: (0..=lay.n_bins)
            .map(|k| lay.r_min + k as f64 * sensor.bin_width)
            .collect(),
        ch: sensor.channels(),
        orders,
        strategies,
        tx_u: normalize(cross(V3::Y, wi)),
        tx_v: cross(wi, normalize(cross(V3::Y, wi))),
    };
    let (w, ch, nb) = (setup.width, setup.ch, lay.n_bins);
    let skip = orders == 0 || has_no_interreflections(mesh);
    let open = if skip { Vec::new() } else { open_sides(mesh) };
    let areas = if skip {
        Vec::new()
    } else {
        surface_areas(mesh)
    };
    let blocks: Vec<std::ops::Range<usize>> = (0..w)
        .step_by(ROWS_PER_BLOCK)
        .map(|r| r..(r + ROWS_PER_BLOCK).min(w))
        .collect();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let cancelled = std::sync::atomic::AtomicBool::new(false);
    let one = |rot: &Rot| -> PathSums {
        use std::sync::atomic::Ordering::Relaxed;
        let mut sums = PathSums {
            image: vec![
                0.0;
                if outputs.image {
                    orders * w * w * ch
                } else {
                    0
                }
            ],
            profile: vec![0.0; if outputs.profile { orders * nb * ch } else { 0 }],
            total: vec![0.0; orders * ch],
        };
        if skip || cancelled.load(Relaxed) {
            return sums;
        }
        let posed = Posed::new(mesh, rot, &open);
        let seen = covered_pixels(&posed.tris, V3::X, V3::Y, w, lay.ext);
        let mirrors = if strategies.aim && orders >= 2 {
            Mirrors::new(&posed, brdf, wi, &areas)
        } else {
            Mirrors::none(mesh.faces.len())
        };
        let parts: Vec<PathSums> = blocks
            .par_iter()
            .map(|r| render_rows(&setup, &posed, brdf, r.clone(), outputs, &seen, &mirrors))
            .collect();
        for (r, part) in blocks.iter().zip(parts) {
            if outputs.image {
                let n_rows = r.len();
                for order in 0..orders {
                    let src = &part.image[order * n_rows * w * ch..(order + 1) * n_rows * w * ch];
                    let at = (order * w + r.start) * w * ch;
                    sums.image[at..at + src.len()].copy_from_slice(src);
                }
            }
            for (a, b) in sums.profile.iter_mut().zip(&part.profile) {
                *a += b;
            }
            for (a, b) in sums.total.iter_mut().zip(&part.total) {
                *a += b;
            }
        }
        if strategies.transmitter {
            let lit = covered_pixels(&posed.tris, setup.tx_u, setup.tx_v, w, lay.ext);
            let parts: Vec<TxSums> = blocks
                .par_iter()
                .map(|r| render_tx_rows(&setup, &posed, brdf, r.clone(), outputs, &lit))
                .collect();
            for part in parts {
                for (pixel, vals) in part.splats {
                    for (x, v) in sums.image[pixel * ch..(pixel + 1) * ch]
                        .iter_mut()
                        .zip(&vals)
                    {
                        *x += v;
                    }
                }
                for (a, b) in sums.profile.iter_mut().zip(&part.profile) {
                    *a += b;
                }
                for (a, b) in sums.total.iter_mut().zip(&part.total) {
                    *a += b;
                }
            }
        }
        if let Some(report) = progress {
            let (offset, total) = progress_offset;
            if !report(offset + done.fetch_add(1, Relaxed) + 1, total) {
                cancelled.store(true, Relaxed);
            }
        }
        sums
    };
    let sums: Vec<PathSums> = rotations.par_iter().map(one).collect();
    if cancelled.into_inner() {
        return Err(Error::Cancelled);
    }
    Ok(sums)
}

/// Bytes [`render_paths`] and [`add_paths`] hold at their peak for `n` attitudes: the
/// attitudes traced at once (one per thread) with their image and profile sums in f64 and
/// the row blocks' sums, and every attitude's sums and split outputs.
pub fn paths_bytes(mesh: &Mesh, sensor: &SensorSetup, n: usize, outputs: Outputs) -> usize {
    let orders = sensor.paths.bounces.saturating_sub(1);
    if orders == 0 {
        return 0;
    }
    let lay = Layout::new(mesh, sensor);
    let (w, ch) = (sensor.resolution, sensor.channels());
    let image = if outputs.image { w * w * ch } else { 0 };
    let profile = if outputs.profile { lay.n_bins * ch } else { 0 };
    // per attitude: its sums (f64) and the blocks' copies while they are joined
    let one = orders * (image + profile) * 8 * 2;
    let at_once = rayon::current_num_threads().max(1).min(n);
    // kept for every attitude: the sums (f64) and the split outputs (f32 images, f64 profiles)
    let kept = n.saturating_mul(
        orders * (image * 8 + profile * 8) + (orders + 1) * (image * 4 + profile * 8),
    );
    at_once.saturating_mul(one).saturating_add(kept)
}

/// Refuse inter-reflections that would not fit in the memory available (an allocation
/// failure aborts the process), naming the memory needed.
pub fn check_paths_memory(
    mesh: &Mesh,
    sensor: &SensorSetup,
    n: usize,
    outputs: Outputs,
) -> Result<()> {
    let need = paths_bytes(mesh, sensor, n, outputs);
    if let Some(avail) = super::cpu::available_memory() {
        if need > avail {
            const GIB: f64 = (1u64 << 30) as f64;
            return Err(Error::param(
                "bounces",
                sensor.paths.bounces,
                format!(
                    "the inter-reflections of this render ({n} attitude(s), {w} x {w} pixels) \
                     need about {:.1} GiB of memory beside the render and {:.1} GiB are \
                     available: render fewer attitudes per call, request fewer outputs (images \
                     split by bounces are the largest), or lower the resolution",
                    need as f64 / GIB,
                    avail as f64 / GIB,
                    w = sensor.resolution,
                ),
            ));
        }
    }
    Ok(())
}

/// Add the paths of each attitude (`sums`, from [`render_paths`]) to a backend's
/// one-bounce result, and split the outputs by bounces (`bounce_*` of [`Rendered`]: the
/// backend's values first, then each order's).
pub fn add_paths(r: &mut Rendered, sensor: &SensorSetup, sums: &[PathSums]) {
    let orders = sensor.paths.bounces - 1;
    let k = orders + 1;
    let (n, ch) = (r.n, r.channels);
    let mut bt = Vec::with_capacity(n * k * ch);
    for (a, s) in sums.iter().enumerate() {
        let direct = &r.total[a * ch..(a + 1) * ch];
        bt.extend_from_slice(direct);
        bt.extend_from_slice(&s.total);
        for o in 0..orders {
            for c in 0..ch {
                r.total[a * ch + c] += s.total[o * ch + c];
            }
        }
    }
    r.bounce_total = bt;
    if let Some(prof) = r.profile.as_mut() {
        let per = r.n_bins * ch;
        let mut bp = Vec::with_capacity(n * k * per);
        for (a, s) in sums.iter().enumerate() {
            bp.extend_from_slice(&prof[a * per..(a + 1) * per]);
            bp.extend_from_slice(&s.profile);
            for o in 0..orders {
                for (x, y) in prof[a * per..(a + 1) * per]
                    .iter_mut()
                    .zip(&s.profile[o * per..(o + 1) * per])
                {
                    *x += y;
                }
            }
        }
        r.bounce_profile = Some(bp);
    }
    if let Some(img) = r.image.as_mut() {
        let per = r.height * r.width * ch;
        let mut bi = Vec::with_capacity(n * k * per);
        for (a, s) in sums.iter().enumerate() {
            let direct = &mut img[a * per..(a + 1) * per];
            bi.extend_from_slice(direct);
            bi.extend(s.image.iter().map(|&v| v as f32));
            for (j, x) in direct.iter_mut().enumerate() {
                let more: f64 = (0..orders).map(|o| s.image[o * per + j]).sum();
                *x = (*x as f64 + more) as f32;
            }
        }
        r.bounce_image = Some(bi);
    }
}

#[cfg(test)]
mod tests;
