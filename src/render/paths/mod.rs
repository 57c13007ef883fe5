//! Inter-reflections between the parts of a mesh: the light that reaches a pixel's surface
//! after one or two reflections off other surfaces (paths of 2 and 3 bounces), by Monte
//! Carlo path sampling in f64 on the CPU with ray casting against the mesh ([`Bvh`], built
//! once per render in the mesh's own frame, where its boxes fit the parts they hold). The
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
//! Tried and not kept: drawing the specular lobe's normals from those `w_out` sees (the
//! distribution of visible normals, Heitz and d'Eon 2014: Beckmann's by inverting its
//! slope marginal with a bracketed Halley iteration, GGX's in closed form, Blinn-Phong
//! through the Beckmann of Walter's mapping; density `D(h) / (4 (cos_out + N_D))`). Its
//! draws matched their density in histogram tests from the normal to 89.9 deg. On
//! `benchmarks/bench_render.py`'s 8 attitudes (16 paths, seeds 0-11 against 1024 paths)
//! the profile noise of `bounces=3` went from 1.65% to 1.80% (the standard error of
//! each mean 0.09%) for 12% more time; on the 0.3 m dihedral (64 px, 16 visibility
//! samples, 16 paths, 4 seeds against 2048 paths) the per-pixel error fell from 7.0% to
//! 6.4% (alpha 0.1) and from 3.8% to 3.5% (alpha 0.3) where one face is seen at 85 deg,
//! did not move at 20 deg off the axis, and the time rose by 25-40%: each Beckmann draw
//! cost about 20 times the draw from `D cos(theta_h)` (a few `erfc` per iteration), and
//! for these lobes (alpha 0.05-0.3, seen at up to 85 deg) drawing `D cos(theta_h)` loses
//! few draws below the horizon.
//!
//! **Strategies** ([`Strategies`]), combined by the balance heuristic (each path weighted
//! by its density under the strategy that drew it over the sum of the densities under
//! every strategy that could have; the densities in the product of the two surfaces' area
//! measures): the receiver's side above (`receiver.rs`); for 2 bounces also the
//! transmitter's side (`transmitter.rs`: a point of the transmitter's view of the same
//! square, a direction from its surface's lobes about `wi`, and a connection to the
//! receiver past the mesh), which draws well what the receiver's side draws poorly (a
//! diffuse surface seen, lit through a glossy one); for 3 bounces also the path aimed from
//! its middle surface at the glossy flat surfaces that mirror the transmitter
//! (`mirrors.rs`: the metal-paint-metal corner, which neither end draws well). Each strategy
//! alone is unbiased (tests); with the defaults all are on.
//!
//! **The third bounce** is drawn `d` = [`THIRD_BOUNCE_DRAWS`] times from each path's
//! second surface, sharing the first segment: the aimed path and a direction from its
//! lobes each time, each draw with `1 / d` of the path's share, from the random numbers of
//! paths `d i .. d i + d - 1` of their sets. The aimed draw chooses among the mirrors that
//! may light the second surface only (`mirrors.rs`).
//!
//! Where the noise of `bounces=3` comes from, measured on the 3U CubeSat (the set-up of
//! `scripts/interreflections.py` section 3: 6 attitudes, 128 px, 16 paths, seeds 0-2
//! against 1024 paths): the third bounce's light is nearly all the bus showing the paint it
//! lights (bus -> paint -> bus carried 99% of it and of its sum of squares at attitudes 7,
//! 11 and 19), its values within 4x (aimed) and 13x (lobes) of their mean: not fireflies.
//! The profile noise of `bounces=3` (1.98%) is the third bounce's (1.86% of the total's
//! bins, against 0.52% for the second's), and most of that is in the profile's far tail,
//! the bins past the object where only 3-bounce paths land (80-93% of those bins, at 1-20%
//! of the peak, with relative errors of 10-50% at one draw). With `d` = 1, 2, 4, 8, 16
//! draws the third bounce's share of the noise read 4.1%, 2.9%, 1.7%, 1.6%, (16 draws,
//! before the aim chose among the mirrors that may light the paint) 1.7%. Up to 4 draws
//! gain more than their number (variance 17 to 2.9 %^2 from 1 to 4): a path's draws are
//! an aligned block of its pixel's Sobol' points, stratified among themselves. Beyond,
//! what is left comes from the first two segments (which points of the paint the bus's
//! pixels reach: 90% of the third bounce's sum of squares is in 350-430 pixels), which
//! more draws from the same second surface do not sample.
//!
//! Tried and not kept: drawing those paths from the middle out (points stratified over the
//! area of the diffuse surfaces, the same points at every attitude, aimed at a mirror of
//! the receiver on one side and of the transmitter on the other, combined with the
//! receiver's strategy by the balance heuristic in the product of the three area
//! measures). On `benchmarks/bench_render.py`'s 8 attitudes (16 paths, seeds 0-2 against
//! 1024 paths) the profile noise of `bounces=3` went from 1.49% to 1.35% with about one
//! middle point per path sample per pixel area of the paint (32768 per attitude), and
//! 1.42% with a quarter of them, for 15-30% more time: no gain per unit of time. Alone
//! (the receiver's strategy leaving these paths to it) it needed 4 points per path sample
//! per pixel area, twice the time, for 2.5% on the third bounce (the receiver's: 2.0%):
//! most middle points see no mirror of the receiver, or their aimed ray misses it.
//!
//! **Where the paths go** (`allocate.rs`): each strategy draws only in the pixels that
//! faces open toward its end may cover (a surface with nothing of the mesh on the side a
//! path would leave from, [`open_sides`], starts no path), and the budget of `N` paths
//! for every pixel the mesh may cover is shared evenly among those, about `N M / M_open`
//! each;
//! whole meshes that cannot reflect onto themselves are skipped
//! ([`has_no_interreflections`]). The balance heuristic weighs each strategy by its count
//! where it drew the path.
//!
//! **Random numbers.** A pixel's `n` paths use scrambled Sobol' points ([`uniforms`]:
//! three sets, shuffled and Owen-scrambled by hashes of `(seed, pixel, set)`, Burley
//! 2020), stratified in each dimension and jointly in the pairs that draw a point or a
//! direction. They depend on the seed, the pixel and the pixel's count only, not on the
//! attitude or its place in the batch: a batch equals single calls bit for bit, and a fit
//! that moves the attitude sees common random numbers (its objective does not jitter from
//! step to step, except at the rare steps where a count changes, `allocate.rs`).
//! Tried and not kept: one sequence for the whole image, each pixel's points a block of it
//! in Morton order (so that neighbouring pixels' points form one net, after Ahmed and
//! Wonka 2020), with one scramble for the image. On `benchmarks/bench_render.py`'s 8
//! attitudes (16 paths, seeds 0-2) the profile noise of `bounces=3` went from 1.49% to
//! 1.79%: better at some attitudes (4.5% to 1.6%), much worse at others (1.0% to 5.4%),
//! and the second bounce's from 0.8% to 1.2%. The points' fine digits follow the pixel's
//! position there, which the hashed scramble does not randomize enough.
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
use super::thin::{mesh_thinness, THIN_PX};
use crate::brdf::spec::Term;
use crate::brdf::terms::sum_terms_except;
use crate::brdf::Material;
use crate::error::{Error, Result};
use crate::microfacet::distribution::Distribution;
use crate::optics::frames::{cross, dot, normalize, Frame, V3};
use crate::optics::fresnel::reflectance;
use crate::optics::mueller::{matmul, scale, Mat4};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::sync::Arc;

mod allocate;
mod lobes;
mod mirrors;
mod posed;
mod receiver;
mod rng;
mod transmitter;

use allocate::Counts;
pub use lobes::{lobes_from_weights, Lobes, Materials, PathBrdf, MIN_LOBE_P};
use lobes::{lobes_toward, pdf, sample};
use mirrors::{aim, Mirrors};
use posed::{covered_pixels, no_interreflections, surface_areas, Posed, Vertex};
pub use posed::{has_no_interreflections, open_sides};
use receiver::render_rows;
pub use rng::{hash32, uniforms, PixelRng, DIMS};
#[cfg(test)]
use rng::{sobol, sobol_directions};
use transmitter::{add_tx_path, render_tx_rows, TxSums, TX_SALT};

/// The Mueller matrix of `a` after `b` along a path, `a L b`: `b`'s output is the beam
/// propagating along `k` in the basis `x_b`, `a`'s input the same beam in the basis `x_a`
/// (both normal to `k`), and `L` turns one basis into the other ([`basis_change`]).
fn chain(a: &Mat4, x_a: V3, b: &Mat4, x_b: V3, k: V3) -> Mat4 {
    matmul(&mul_rotation(a, basis_change(x_a, x_b, k)), b)
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

/// Draws of the third bounce from each path's second surface (module docs).
pub const THIRD_BOUNCE_DRAWS: usize = 4;

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
    /// The Gaussian pulse's CDF (in standard deviations) for the deposits (none for a
    /// sampled pulse).
    gauss_cdf: Option<pulse::NormCdfTable>,
    /// A pixel's `4 pi delta^2`: each of its `n` paths carries `1 / n` of it.
    area: f64,
    strategies: Strategies,
    /// The transmitter's image plane: unit `tx_u`, `tx_v` normal to `wi` (`= X`, `Y`
    /// monostatic), spanning the same square as the receiver's.
    tx_u: V3,
    tx_v: V3,
    /// Each face's [`mesh_thinness`] (which faces are thin at an attitude, `allocate.rs`).
    thinness: &'a [[f64; 4]],
    /// Draws of the third bounce from each path's second surface ([`THIRD_BOUNCE_DRAWS`]).
    third_draws: usize,
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
    /// that mirror the transmitter (`mirrors::Mirrors`).
    pub aim: bool,
    /// Draws of the third bounce from each path's second surface (at least 1;
    /// [`THIRD_BOUNCE_DRAWS`] by default).
    pub third_draws: usize,
}

impl Default for Strategies {
    fn default() -> Self {
        Strategies {
            receiver: true,
            transmitter: true,
            aim: true,
            third_draws: THIRD_BOUNCE_DRAWS,
        }
    }
}

/// The density of drawing, at the surface `v` whose path goes on toward `w_out`, the
/// direction `w` (per unit solid angle, from `v`'s lobes about `w_out`), times
/// `|ng . w_out|` (the projected area of the strategy's image plane to `v`'s area): the
/// part of a strategy's density in the balance heuristic that the other does not share.
/// The transmitter's strategy draws at the lit surface about `wi`, the receiver's at the
/// seen one about `wo`.
fn lobe_density(brdf: &(impl PathBrdf + ?Sized), v: &Vertex, w_out: V3, w: V3) -> f64 {
    match lobes_toward(brdf, v, w_out) {
        Some(lobes) => pdf(&lobes, v.n, w_out, w) * dot(v.ng, w_out).abs(),
        None => 0.0,
    }
}

impl<'a> Setup<'a> {
    fn new(mesh: &'a Mesh, sensor: &'a SensorSetup, strategies: Strategies) -> Self {
        let lay = Layout::new(mesh, sensor);
        let beta = sensor.bistatic_angle;
        let wi = V3::new(beta.sin(), 0.0, beta.cos());
        let k_in = -wi;
        let x_in_t = normalize(cross(k_in, V3::Y));
        let pix = 2.0 * lay.ext / sensor.resolution as f64;
        Setup {
            sensor,
            lay,
            width: sensor.resolution,
            pix,
            wi,
            wo: V3::Z,
            x_in_t,
            y_in_t: cross(k_in, x_in_t),
            edges: (0..=lay.n_bins)
                .map(|k| lay.r_min + k as f64 * sensor.bin_width)
                .collect(),
            ch: sensor.channels(),
            orders: sensor.paths.bounces.saturating_sub(1),
            gauss_cdf: sensor
                .pulse
                .is_none()
                .then(|| pulse::NormCdfTable::new(super::api::PULSE_SUPPORT_SIGMAS + 0.5, 256)),
            area: 4.0 * PI * pix * pix,
            strategies,
            tx_u: normalize(cross(V3::Y, wi)),
            tx_v: cross(wi, normalize(cross(V3::Y, wi))),
            thinness: mesh_thinness(mesh),
            third_draws: strategies.third_draws.max(1),
        }
    }

    /// Zero sums of `n_rows` image rows (all orders), the profile and the totals, each
    /// where `outputs` keep it.
    fn zero_sums(&self, outputs: Outputs, n_rows: usize) -> PathSums {
        let (w, ch, orders) = (self.width, self.ch, self.orders);
        let image = if outputs.image {
            orders * n_rows * w * ch
        } else {
            0
        };
        let profile = if outputs.profile {
            orders * self.lay.n_bins * ch
        } else {
            0
        };
        PathSums {
            image: vec![0.0; image],
            profile: vec![0.0; profile],
            total: vec![0.0; orders * ch],
        }
    }

    /// The point of pixel `(row, col)` of the image plane at the offsets `u[0]`, `u[1]`
    /// (pixel units from its top-left corner, rows down).
    fn point_in_pixel(&self, row: usize, col: usize, u: [f64; 3]) -> (f64, f64) {
        let ext = self.lay.ext;
        (
            -ext + (col as f64 + u[0]) * self.pix,
            ext - (row as f64 + u[1]) * self.pix,
        )
    }

    /// The profile of bounce order `order` within `profile` (orders x bins x channels), or
    /// the empty slice when no profile is kept.
    fn order_profile<'p>(&self, profile: &'p mut [f64], order: usize) -> &'p mut [f64] {
        let per = self.lay.n_bins * self.ch;
        if profile.is_empty() {
            profile
        } else {
            &mut profile[order * per..(order + 1) * per]
        }
    }

    /// Add one path of the pixel, its Mueller matrix `m` from the transmitter (basis
    /// `x_in`) to the receiver (basis `x_out`) landing at range `r`, times `weight` (the
    /// path's share of the pixel), to the pixel's sums `px` and to `profile` (when kept); a
    /// path with a value that is not finite adds nothing.
    #[allow(clippy::too_many_arguments)]
    fn add_path(
        &self,
        px: &mut [f64; 16],
        profile: &mut [f64],
        m: &Mat4,
        x_in: V3,
        x_out: V3,
        r: f64,
        weight: f64,
    ) {
        let vals = self.channels(m, x_in, x_out, weight);
        if !vals.iter().all(|x| x.is_finite()) {
            return;
        }
        for (a, b) in px.iter_mut().zip(&vals) {
            *a += b;
        }
        if !profile.is_empty() {
            self.deposit(profile, &vals[..self.ch], r);
        }
    }

    /// Add `vals` (channels) at range `r` to a profile (bins x channels): the pulse's
    /// weights over the bins it reaches, its tails folded into the end ones (as
    /// [`pulse::bin_weights_folded`] for a point; a Gaussian pulse's CDF interpolated,
    /// [`pulse::NormCdfTable`], within 2e-12 of each weight).
    fn deposit(&self, prof: &mut [f64], vals: &[f64], r: f64) {
        let ch = self.ch;
        let inv_sigma = 1.0 / self.sensor.sigma_range;
        let cdf = |x: f64| match (&self.sensor.pulse, &self.gauss_cdf) {
            (Some(p), _) => p.cdf_box2(x, 0.0, 0.0),
            (None, Some(t)) => t.eval(x * inv_sigma),
            (None, None) => pulse::norm_cdf(x * inv_sigma),
        };
        pulse::folded_weights(r, self.lay.support, &self.edges, cdf, |k, wt| {
            if wt != 0.0 {
                for (p, v) in prof[k * ch..(k + 1) * ch].iter_mut().zip(vals) {
                    *p += wt * v;
                }
            }
        });
    }

    /// Whether the transmitter's strategy starts its paths from the receiver's points
    /// (monostatic, `receiver.rs`) rather than in its own pass (`transmitter.rs`).
    fn shares_points(&self) -> bool {
        self.strategies.transmitter && self.monostatic()
    }

    /// Whether the transmitter's view is the receiver's (`wi = wo`).
    fn monostatic(&self) -> bool {
        (self.wi, self.tx_u, self.tx_v) == (self.wo, V3::X, V3::Y)
    }

    /// The transmitter's pixel (row-major index) that the point `p` is lit in, if any.
    fn tx_pixel(&self, p: V3) -> Option<usize> {
        let ext = self.lay.ext;
        let c = ((dot(p, self.tx_u) + ext) / self.pix).floor();
        let r = ((ext - dot(p, self.tx_v)) / self.pix).floor();
        let w = self.width as f64;
        (c >= 0.0 && r >= 0.0 && c < w && r < w).then(|| r as usize * self.width + c as usize)
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
    let setup = Setup::new(mesh, sensor, strategies);
    let (orders, wi) = (setup.orders, setup.wi);
    let w = setup.width;
    let open = if orders == 0 {
        Vec::new()
    } else {
        open_sides(mesh)
    };
    let skip = orders == 0 || no_interreflections(mesh, &open);
    let empty;
    let (areas, bvh) = if skip {
        empty = Bvh::new(&[]);
        (Vec::new(), &empty)
    } else {
        (surface_areas(mesh), mesh.bvh())
    };
    let done = std::sync::atomic::AtomicUsize::new(0);
    let cancelled = std::sync::atomic::AtomicBool::new(false);
    let one = |rot: &Rot| -> PathSums {
        use std::sync::atomic::Ordering::Relaxed;
        if skip || cancelled.load(Relaxed) {
            return setup.zero_sums(outputs, w);
        }
        let posed = Posed::new(mesh, rot, &open, bvh);
        let mirrors = if strategies.aim && orders >= 2 {
            Mirrors::new(&posed, brdf, wi, &areas)
        } else {
            Mirrors::none(mesh.faces.len())
        };
        let counts = Counts::new(&setup, &posed, sensor.paths.samples, strategies.transmitter);
        let sums = trace(&setup, &posed, brdf, outputs, &counts, &mirrors);
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

/// The paths of one attitude from each strategy ([`Counts`] per pixel).
fn trace(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    outputs: Outputs,
    counts: &Counts,
    mirrors: &Mirrors,
) -> PathSums {
    let (w, ch, orders) = (setup.width, setup.ch, setup.orders);
    // (monostatic, the transmitter's paths start from the receiver's points: its counts
    // are the receiver's, as `Counts::new` gives them)
    let same;
    let counts = if setup.shares_points() && counts.tx != counts.rx {
        same = Counts {
            rx: counts.rx.clone(),
            tx: counts.rx.clone(),
        };
        &same
    } else {
        counts
    };
    let mut sums = setup.zero_sums(outputs, w);
    let blocks: Vec<std::ops::Range<usize>> = (0..w)
        .step_by(ROWS_PER_BLOCK)
        .map(|r| r..(r + ROWS_PER_BLOCK).min(w))
        .collect();
    let parts: Vec<(PathSums, TxSums)> = blocks
        .par_iter()
        .map(|r| render_rows(setup, posed, brdf, r.clone(), outputs, counts, mirrors))
        .collect();
    let mut tx_parts = Vec::with_capacity(blocks.len());
    for (r, (part, tx_part)) in blocks.iter().zip(parts) {
        tx_parts.push(tx_part);
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
    if setup.strategies.transmitter {
        let parts: Vec<TxSums> = if setup.shares_points() {
            tx_parts
        } else {
            blocks
                .par_iter()
                .map(|r| render_tx_rows(setup, posed, brdf, r.clone(), outputs, counts))
                .collect()
        };
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
    sums
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
