//! Orders 2 and higher of a Beckmann surface (Gaussian slopes, a Gaussian or Matern height
//! autocorrelation) from the surface's own paths (issue 24).
//!
//! # Why
//! The double term ([`super::double`]) draws the second facet independently of the first.
//! On a real rough surface the second facet is the far wall of the same valley (PHYSICS.md
//! section 5b), which turns order 2 back toward the source: the double term is 0.29x the
//! explicit surface at normal-incidence backscatter for alpha 0.5, 2-4x at 50 deg
//! (`docs/microsurface-comparison.md`); and the multiple term, which stands for orders 3+,
//! is fully depolarizing where the surface's 3+ is not. The geometry of the paths depends
//! only on the surface class (alpha and the shape of the autocorrelation), not on the
//! material, so it is traced once and each material's Fresnel and Jones matrices are
//! applied per path.
//!
//! # The bank ([`PathBank`])
//! Gaussian random surfaces with the autocorrelation [`BankSpec::autocorrelation`]
//! ([`crate::reference::microsurface::height_field`]: triangulated, exactly Beckmann
//! slopes; Gaussian or Matern, with the same slope statistics), lit by a plane wave from `wi = (sin theta_i, 0, cos theta_i)` at the
//! incidence nodes `theta_i = k THETA_STEP`, `k < N_THETA` (0 to 87.5 deg). Primary rays start
//! uniformly over the tile's horizontal area (each carries `1 / R` of the flux on the tile,
//! `R` the node's primary rays) and are followed geometrically (mirror reflection off the
//! triangles, [`crate::reference::trace::trace_segment`]). A ray that leaves after `n`
//! reflections (`2 <= n <= MAX_ORDER`) is kept as its facets' slopes; the fractions leaving
//! after each number of reflections are the orders' albedos for `F = 1`. Each ray comes
//! from its own random azimuth and its path is rotated back to azimuth 0: one surface
//! realization is not isotropic (its valleys have preferred directions), and only an
//! isotropic bank is reciprocal after the table's rotations (without it the reciprocal
//! partners of the table disagreed by up to 30% on two 128 x 128 tiles). The same
//! surfaces, start points and azimuths serve every incidence node (common random numbers:
//! the table is smooth from node to node). Surfaces come from their own seed streams, so a
//! reference run ([`crate::reference::run`]) with any seed never traces the bank's surfaces.
//! The paths that leave within [`BACKSCATTER_CONE`] of the backscatter direction are also
//! kept whole (not thinned) with the displacement from their first hit point to their last
//! ([`PathBank::backscatter`]): the data of their coherent backscatter ([`coherent`]).
//!
//! # The table ([`OrderTable`])
//! `f_n(wi, wo)` (Mueller, 1/sr) summed over a range of orders `n`, on nodes
//! `(theta_i, theta_o, phi)`: `theta_i`, `theta_o` on the same `N_THETA` nodes and
//! `phi = phi_o - phi_i` on `N_PHI` nodes over `[0, pi]`, in the `Sp` beam frames
//! ([`Frame::Sp`]; at `theta = 0` the limit along the node's azimuth, so that the table is
//! smooth on the `(theta, phi)` rectangle). Each path's Mueller matrix (its Jones matrix
//! composed facet by facet, [`path_jones`], with the double term's per-facet map) is
//! spread onto the nodes by a tent kernel in `theta_o` and `phi` (mirror images folded onto
//! `phi >= 0`) and divided by the kernel's cosine-weighted solid angle: each node holds the
//! kernel-weighted mean of `f` around it, like the reference's detector cones. Exit nodes
//! within 10 deg of the pole are then averaged over neighbouring `phi` nodes (up to 37.5
//! deg at 2.5 deg, 2 deg of arc; [`smooth_near_pole`]): their kernels cover little solid
//! angle and held too few paths. At the pole
//! (`theta_o = 0`) the paths within one `theta` step are pooled over all azimuths in basis
//! vectors parallel transported from the zenith (smooth there), then expressed in each
//! azimuth's `Sp` basis.
//!
//! Symmetries, exact on the nodes and kept by the interpolation: reciprocity
//! (`M(wo, wi) = C M(wi, wo)^T C`, [`crate::optics::mueller::reciprocal`]) with a rotation
//! about `n` and the mirror `y -> -y` (`M -> D M D`, `D = diag(1, 1, -1, -1)` in `Sp`
//! frames) maps node `(o, i, phi)` to `E T(i, o, phi)^T E`, `E = diag(1, 1, 1, -1)`; the table
//! is the mean of the two, so `f` is reciprocal to rounding. Between nodes: trilinear
//! interpolation in `(theta_i, theta_o, phi)`; beyond the last node (87.5 deg) the last
//! node's value.

use super::double::reflect_field;
use super::table::{mirror, MIRROR_SIGN};
use crate::optics::frames::{
    beam_bases, change_bases, cross, dot, mitsuba_basis, neg, normalize, Frame, V3,
};
use crate::optics::fresnel::{fresnel_amplitudes, Eta, C64};
use crate::optics::mueller::{jones_to_mueller, Jones, Mat4};
use crate::reference::microsurface::{check_gaussian, height_field, Autocorrelation};
use crate::reference::rng::Rng;
use crate::reference::trace::{trace_segment, Segment};
use crate::{Error, Result};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::ops::RangeInclusive;
use std::sync::atomic::{AtomicU64, Ordering};

pub mod cache;
pub mod coherent;
pub mod progress;

/// Spacing of the incidence and exit nodes in `theta` (2.5 deg).
pub const THETA_STEP: f64 = PI / 72.0;
/// Nodes in `theta`: 0, 2.5, ..., 87.5 deg.
pub const N_THETA: usize = 36;
/// Nodes in `phi = phi_o - phi_i` over `[0, pi]` (7.5 deg apart).
pub const N_PHI: usize = 25;
/// Primary rays per parallel work item (fixed: results do not depend on the thread count).
const CHUNK: u64 = 4096;
/// The most reflections a banked path has (rays still on the surface after them are counted
/// as truncated: below 1e-4 of the flux for alpha <= 1).
pub const MAX_ORDER: usize = 8;
/// Seed-stream tag of the bank's surfaces and rays (the reference uses 0 and 1).
const STREAM: u64 = 0x6261_6e6b;
/// Half-angle (rad) of the cone about the backscatter direction whose paths the bank also
/// keeps with their separations ([`PathBank::backscatter`]); the reference's coherent tally
/// uses the same cone in `docs/surface-orders-reference.md`.
pub const BACKSCATTER_CONE: f64 = 0.1;

/// What to trace.
#[derive(Debug, Clone, PartialEq)]
pub struct BankSpec {
    /// Beckmann roughness of the surfaces (`alpha^2 = 2 var(slope component)`).
    pub alpha: f64,
    /// Tile size in grid cells.
    pub grid: usize,
    /// Height correlation length `l` in grid cells (`C(r) ~ exp(-r^2 / l^2)` for the
    /// Gaussian shape; the Matern's length with the same slope statistics).
    pub correlation_length: f64,
    /// The shape of the height autocorrelation.
    pub autocorrelation: Autocorrelation,
    /// Primary rays per incidence node (over all surfaces).
    pub rays: u64,
    /// Independent random surfaces (the rays are shared among them).
    pub surfaces: u32,
    pub seed: u64,
}

impl BankSpec {
    /// Check every parameter, naming the offending one.
    pub fn validate(&self) -> Result<()> {
        check_gaussian(self.alpha, self.grid, self.correlation_length)?;
        if !(1..=10_000).contains(&self.surfaces) {
            return Err(Error::param(
                "surfaces",
                self.surfaces,
                "must be in [1, 10000]",
            ));
        }
        if self.rays < self.surfaces as u64 || self.rays > 1u64 << 36 {
            return Err(Error::param(
                "rays",
                self.rays,
                format!("must be in [surfaces = {}, 2^36]", self.surfaces),
            ));
        }
        Ok(())
    }
}

/// The paths of orders 2 to [`MAX_ORDER`] of [`BankSpec`]'s surfaces at each incidence node
/// (module docs). Kept on disk by [`cache`].
#[derive(Debug, Clone, PartialEq)]
pub struct PathBank {
    pub spec: BankSpec,
    /// Primary rays traced per incidence node.
    pub rays: Vec<u64>,
    /// `paths[node][n - 2]`: the paths that left after exactly `n` reflections
    /// (`2 <= n <= MAX_ORDER`), flat: the slopes `(sx, sy)` of their `n` facets in order
    /// (`2 n` values per path; unit normal `normalize(-sx, -sy, 1)`).
    pub paths: Vec<Vec<Vec<f32>>>,
    /// `albedo[node][n - 1]`: the fraction of the flux leaving after exactly `n` reflections
    /// (`F = 1`).
    pub albedo: Vec<[f64; MAX_ORDER]>,
    /// Per node, the fraction still on the surface after `MAX_ORDER` reflections.
    pub truncated: Vec<f64>,
    /// Rays lost by the traversal (numerical failures; expected 0).
    pub lost: u64,
    /// `weights[node][n - 2]`: the flux each kept order-`n` path stands for, in units of one
    /// primary ray's (1, or more after [`PathBank::thin`]).
    pub weights: Vec<[f64; MAX_ORDER - 1]>,
    /// `backscatter[node][n - 2]`: every order-`n` path (not thinned, one primary ray each)
    /// that left within [`BACKSCATTER_CONE`] of the exact backscatter direction, flat: its
    /// `2 n` facet slopes, then `rho / l` (3 values), the displacement from its first hit
    /// point to its last in units of the height correlation length, in the frame of
    /// incidence at azimuth 0 (the coherent-backscatter data: [`coherent`]).
    pub backscatter: Vec<Vec<Vec<f32>>>,
}

impl PathBank {
    /// The order-`n` paths of node `i`, each the `2 n` slopes of its facets.
    pub fn paths_of(&self, i: usize, n: usize) -> std::slice::ChunksExact<'_, f32> {
        self.paths[i][n - 2].chunks_exact(2 * n)
    }

    /// The order-`n` paths of node `i` that left near backscatter ([`Self::backscatter`]),
    /// each its `2 n` slopes then `rho / l`.
    pub fn backscatter_of(&self, i: usize, n: usize) -> std::slice::ChunksExact<'_, f32> {
        self.backscatter[i][n - 2].chunks_exact(2 * n + 3)
    }

    /// Keep at most about `cap` paths per node and order (every `k`-th, each then standing
    /// for `count / kept` rays): the memory of a bank whose noise is already below what
    /// the table's kernel resolves.
    pub fn thin(&mut self, cap: usize) {
        let cap = cap.max(1);
        for (node, w) in self.paths.iter_mut().zip(&mut self.weights) {
            for (k, p) in node.iter_mut().enumerate() {
                let len = 2 * (k + 2);
                let count = p.len() / len;
                if count <= cap {
                    continue;
                }
                let stride = count.div_ceil(cap);
                let kept: Vec<f32> = p
                    .chunks_exact(len)
                    .step_by(stride)
                    .flatten()
                    .copied()
                    .collect();
                w[k] *= count as f64 / (kept.len() / len) as f64;
                *p = kept;
            }
        }
    }
}

/// The incidence direction of node `k`.
pub fn node_direction(k: usize) -> V3 {
    let (s, c) = (k as f64 * THETA_STEP).sin_cos();
    V3::new(s, 0.0, c)
}

#[inline]
fn facet(sx: f64, sy: f64) -> V3 {
    normalize(V3::new(-sx, -sy, 1.0))
}

/// Mirror reflection of direction `d` off unit normal `h` (`d . h < 0`).
#[inline]
fn bounce(d: V3, h: V3) -> V3 {
    let c = (-dot(d, h)).clamp(0.0, 1.0);
    normalize(d + 2.0 * c * h)
}

/// What one primary ray did.
enum RayFate {
    Lost,
    /// Left after `n` reflections off the facets with these slopes (the first `2 n` values),
    /// along `k`, its last hit point `rho` (grid cells) from its first.
    Escaped {
        n: usize,
        slopes: [f32; 2 * MAX_ORDER],
        k: V3,
        rho: V3,
    },
    /// Still on the surface after `MAX_ORDER` reflections.
    Truncated,
}

fn follow(
    f: &crate::reference::microsurface::HeightField,
    wi: V3,
    start: V3,
    max_cells: usize,
) -> RayFate {
    let period = f.n as f64;
    let (mut o, mut d) = (start, neg(wi));
    let mut slopes = [0.0f32; 2 * MAX_ORDER];
    // the traversal wraps positions into the tile: the separation is the sum of the
    // segments between hits
    let mut rho = V3::ZERO;
    for order in 0..=MAX_ORDER {
        match trace_segment(f, o, d, max_cells) {
            Segment::Escaped => {
                return if order == 0 {
                    RayFate::Lost
                } else {
                    RayFate::Escaped {
                        n: order,
                        slopes,
                        k: d,
                        rho,
                    }
                }
            }
            Segment::Lost => return RayFate::Lost,
            Segment::Hit { t, plane } => {
                if order == MAX_ORDER {
                    return RayFate::Truncated;
                }
                if order > 0 {
                    rho += t * d;
                }
                o = V3::new(
                    (o[0] + t * d[0]).rem_euclid(period),
                    (o[1] + t * d[1]).rem_euclid(period),
                    o[2] + t * d[2],
                );
                slopes[2 * order] = plane.sx as f32;
                slopes[2 * order + 1] = plane.sy as f32;
                // the facet as stored (f32), so that the table sees the path it is given
                let h = facet(slopes[2 * order] as f64, slopes[2 * order + 1] as f64);
                d = bounce(d, h);
            }
        }
    }
    RayFate::Truncated
}

impl PathBank {
    /// Trace the bank (module docs). Parallel over rays; deterministic in `spec.seed`
    /// whatever the number of threads.
    pub fn trace(spec: &BankSpec) -> Result<PathBank> {
        Self::trace_with_progress(spec, &|_, _| {})
    }

    /// [`PathBank::trace`], calling `progress(done, total)` from the worker threads as
    /// rays are traced (`total = rays * N_THETA`; each call after a chunk of rays at one
    /// node, `done` counted atomically, so calls may arrive out of order). The callback
    /// throttles itself ([`progress::Reporter`]).
    pub fn trace_with_progress(
        spec: &BankSpec,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<PathBank> {
        spec.validate()?;
        let ns = spec.surfaces as u64;
        let total = spec.rays * N_THETA as u64;
        let done = AtomicU64::new(0);
        let mut paths = vec![vec![Vec::new(); MAX_ORDER - 1]; N_THETA];
        let mut backscatter = vec![vec![Vec::new(); MAX_ORDER - 1]; N_THETA];
        let cos_cone = BACKSCATTER_CONE.cos();
        // per node: rays leaving after 1..=MAX_ORDER reflections, then truncated
        let mut counts = vec![[0u64; MAX_ORDER + 1]; N_THETA];
        let mut lost = 0u64;
        for s in 0..ns {
            let (field, _) = height_field(
                spec.autocorrelation,
                spec.alpha,
                spec.grid,
                spec.correlation_length,
                spec.seed,
                &[STREAM, s],
            )?;
            let rays_s = spec.rays / ns + u64::from(s < spec.rays % ns);
            let n_chunks = rays_s.div_ceil(CHUNK);
            let max_cells = 64 * field.n + 4096;
            let period = field.n as f64;
            let z0 = field.h_max + 1e-3;
            for (k, ((node_paths, node_bs), node_counts)) in paths
                .iter_mut()
                .zip(&mut backscatter)
                .zip(&mut counts)
                .enumerate()
            {
                let wi = node_direction(k);
                type Chunk = (Vec<Vec<f32>>, Vec<Vec<f32>>, [u64; MAX_ORDER + 1], u64);
                let chunks: Vec<Chunk> = (0..n_chunks)
                    .into_par_iter()
                    .map(|c| {
                        // the same start points and azimuths at every node (common random numbers)
                        let mut rng = Rng::new(spec.seed, &[STREAM + 1, s, c]);
                        let mut out = vec![Vec::new(); MAX_ORDER - 1];
                        let mut bs = vec![Vec::new(); MAX_ORDER - 1];
                        let (mut cnt, mut lost) = ([0u64; MAX_ORDER + 1], 0u64);
                        let n_rays = CHUNK.min(rays_s - c * CHUNK);
                        for _ in 0..n_rays {
                            let start = V3::new(rng.uniform() * period, rng.uniform() * period, z0);
                            // a random azimuth of incidence per ray: one realization is not
                            // isotropic, the bank must be (rotations and reciprocity)
                            let (sp, cp) = (std::f64::consts::TAU * rng.uniform()).sin_cos();
                            let w = V3::new(wi[0] * cp, wi[0] * sp, wi[2]);
                            match follow(&field, w, start, max_cells) {
                                RayFate::Lost => lost += 1,
                                RayFate::Truncated => cnt[MAX_ORDER] += 1,
                                RayFate::Escaped { n, slopes, k, rho } => {
                                    cnt[n - 1] += 1;
                                    if n >= 2 {
                                        // rotated by -azimuth: incidence at azimuth 0
                                        let rot = |x: f64, y: f64| {
                                            [(cp * x + sp * y) as f32, (-sp * x + cp * y) as f32]
                                        };
                                        let start = out[n - 2].len();
                                        for q in slopes[..2 * n].chunks_exact(2) {
                                            out[n - 2].extend(rot(q[0] as f64, q[1] as f64));
                                        }
                                        if dot(k, w) >= cos_cone {
                                            let b = &mut bs[n - 2];
                                            b.extend_from_slice(&out[n - 2][start..]);
                                            let r = rho / spec.correlation_length;
                                            b.extend(rot(r[0], r[1]));
                                            b.push(r[2] as f32);
                                        }
                                    }
                                }
                            }
                        }
                        progress(done.fetch_add(n_rays, Ordering::Relaxed) + n_rays, total);
                        (out, bs, cnt, lost)
                    })
                    .collect();
                for (out, bs, cnt, l) in chunks {
                    for (a, b) in node_paths.iter_mut().zip(out) {
                        a.extend_from_slice(&b);
                    }
                    for (a, b) in node_bs.iter_mut().zip(bs) {
                        a.extend_from_slice(&b);
                    }
                    for (a, b) in node_counts.iter_mut().zip(cnt) {
                        *a += b;
                    }
                    lost += l;
                }
            }
        }
        let r = spec.rays as f64;
        let albedo = counts
            .iter()
            .map(|c| std::array::from_fn(|n| c[n] as f64 / r))
            .collect();
        let truncated = counts.iter().map(|c| c[MAX_ORDER] as f64 / r).collect();
        Ok(PathBank {
            spec: spec.clone(),
            rays: vec![spec.rays; N_THETA],
            paths,
            albedo,
            truncated,
            lost,
            weights: vec![[1.0; MAX_ORDER - 1]; N_THETA],
            backscatter,
        })
    }
}

/// The paths' light of one material on the nodes (module docs), `Sp` frames.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderTable {
    /// `data[(i * N_THETA + o) * N_PHI + j]`: node `theta_i = i THETA_STEP`,
    /// `theta_o = o THETA_STEP`, `phi = j pi / (N_PHI - 1)`.
    pub data: Vec<Mat4>,
}

/// Set the mirror-odd elements (those [`mirror`] flips) to 0: a matrix of a geometry that
/// is its own mirror image.
fn zero_mirror_odd(m: &mut Mat4) {
    for (k, s) in MIRROR_SIGN.iter().enumerate() {
        if *s < 0.0 {
            m[k / 4][k % 4] = 0.0;
        }
    }
}

/// `exp((1 - w) ln(a + eps) + w ln(b + eps)) - eps` (at least 0; 0 when `eps <= 0`): the
/// interpolation of a nonnegative quantity, geometric above `eps`, linear far below it.
pub(crate) fn log_mix(a: f64, b: f64, w: f64, eps: f64) -> f64 {
    if eps <= 0.0 {
        return 0.0;
    }
    (((1.0 - w) * (a.max(0.0) + eps).ln() + w * (b.max(0.0) + eps).ln()).exp() - eps).max(0.0)
}

/// Floor of [`OrderTable::mix`]'s logarithmic interpolation, relative to the tables' largest
/// `M00`: below it the mix turns linear (the banks' noise and empty nodes live there).
pub const MIX_FLOOR: f64 = 1e-4;

/// `E = diag(1, 1, 1, -1)`: node `(o, i, phi)` is `E T(i, o, phi)^T E` (module docs).
const E: [f64; 4] = [1.0, 1.0, 1.0, -1.0];

/// Zenith-transported Stokes basis at `w`: the minimal rotation taking `+z` to `w` applied
/// to `(x, y)` (smooth over the hemisphere, `(x, y)` at the pole).
fn transported(w: V3) -> (V3, V3) {
    let a = 1.0 / (1.0 + w[2]);
    let x = V3::new(1.0 - w[0] * w[0] * a, -w[0] * w[1] * a, -w[0]);
    (x, cross(w, x))
}

/// The `Sp` output basis at azimuth `(cos phi, sin phi)` for direction `w`.
fn sp_out(w: V3, cp: f64, sp: f64) -> (V3, V3) {
    let x = V3::new(sp, -cp, 0.0);
    (x, cross(w, x))
}

/// The Jones matrix, in the beam bases `(x_in, y_in, x_out, y_out)`, of light arriving along
/// `-wi` and reflected off `facets` in turn (the per-facet map of
/// [`super::double::reflect_field`], the double term's); `None` when a facet is met from
/// behind.
pub fn path_jones(eta: Eta, wi: V3, facets: &[V3], bases: (V3, V3, V3, V3)) -> Option<Jones> {
    let (x_in, y_in, x_out, y_out) = bases;
    let field = |v: V3| [0, 1, 2].map(|i| C64::new(v[i], 0.0));
    let mut e = [field(x_in), field(y_in)];
    let mut k = neg(wi);
    for &h in facets {
        let c = -dot(k, h);
        if c <= 0.0 {
            return None;
        }
        let k_out = normalize(k + 2.0 * c * h);
        let (rs, rp) = fresnel_amplitudes(c.min(1.0), eta);
        // any vector transverse to k serves at normal incidence on the facet
        let perp = mitsuba_basis(k);
        for col in e.iter_mut() {
            *col = reflect_field(*col, k, k_out, h, rs, rp, perp);
        }
        k = k_out;
    }
    let proj = |a: V3, f: &[C64; 3]| f[0] * a[0] + f[1] * a[1] + f[2] * a[2];
    Some([
        [proj(x_out, &e[0]), proj(x_out, &e[1])],
        [proj(y_out, &e[0]), proj(y_out, &e[1])],
    ])
}

fn add(acc: &mut Mat4, m: &Mat4, w: f64) {
    for (a, b) in acc.iter_mut().flatten().zip(m.iter().flatten()) {
        *a += w * b;
    }
}

impl OrderTable {
    /// Apply index `eta` to every path of `bank` of an order in `orders` (within
    /// `2..=MAX_ORDER`) and tabulate (module docs).
    pub fn build(bank: &PathBank, eta: Eta, orders: RangeInclusive<usize>) -> OrderTable {
        Self::spread(bank, eta, orders).reciprocal_mean()
    }

    /// The kernel estimate alone, before the reciprocity mean.
    pub fn spread(bank: &PathBank, eta: Eta, orders: RangeInclusive<usize>) -> OrderTable {
        let orders = (*orders.start()).max(2)..=(*orders.end()).min(MAX_ORDER);
        let dphi = PI / (N_PHI - 1) as f64;
        let a_theta: Vec<f64> = (0..N_THETA).map(theta_weight).collect();
        let rows: Vec<Vec<Mat4>> = (0..N_THETA)
            .into_par_iter()
            .map(|i| {
                let wi = node_direction(i);
                let x_in = V3::Y;
                let y_in = cross(neg(wi), x_in);
                let mut sums = vec![[[0.0; 4]; 4]; N_THETA * N_PHI];
                let mut pole = [[0.0; 4]; 4];
                let mut hs = [V3::Z; MAX_ORDER];
                let all = orders.clone().flat_map(|n| {
                    bank.paths_of(i, n)
                        .map(move |p| (p, bank.weights[i][n - 2]))
                });
                for (p, weight) in all {
                    let n = p.len() / 2;
                    let mut wo = neg(wi);
                    for (h, q) in hs.iter_mut().zip(p.chunks_exact(2)) {
                        *h = facet(q[0] as f64, q[1] as f64);
                        wo = bounce(wo, *h);
                    }
                    if wo[1] < 0.0 {
                        // fold onto phi >= 0 by the mirror image of the path
                        hs[..n].iter_mut().for_each(|h| h[1] = -h[1]);
                        wo[1] = -wo[1];
                    }
                    if wo[2] <= 0.0 {
                        continue;
                    }
                    let rho = (wo[0] * wo[0] + wo[1] * wo[1]).sqrt();
                    let (cp, sp) = if rho > 1e-14 {
                        (wo[0] / rho, wo[1] / rho)
                    } else {
                        (1.0, 0.0)
                    };
                    let (x_out, y_out) = sp_out(wo, cp, sp);
                    let bases = (x_in, y_in, x_out, y_out);
                    let Some(j) = path_jones(eta, wi, &hs[..n], bases) else {
                        continue;
                    };
                    let mut m = jones_to_mueller(&j);
                    if weight != 1.0 {
                        m.iter_mut().flatten().for_each(|x| *x *= weight);
                    }
                    let theta = wo[2].clamp(-1.0, 1.0).acos();
                    let phi = sp.atan2(cp).clamp(0.0, PI);
                    let u = theta / THETA_STEP;
                    let k0 = (u.floor() as usize).min(N_THETA - 1);
                    let ft = u - k0 as f64;
                    let v = phi / dphi;
                    let j0 = (v.floor() as usize).min(N_PHI - 2);
                    let fp = v - j0 as f64;
                    for (k, wk) in [(k0, 1.0 - ft), (k0 + 1, ft)] {
                        if k >= N_THETA || wk <= 0.0 {
                            continue;
                        }
                        if k == 0 {
                            let (xt, yt) = transported(wo);
                            let mt = change_bases(&m, bases, (x_in, y_in, xt, yt));
                            add(&mut pole, &mt, wk);
                        } else {
                            add(&mut sums[k * N_PHI + j0], &m, wk * (1.0 - fp));
                            add(&mut sums[k * N_PHI + j0 + 1], &m, wk * fp);
                        }
                    }
                }
                let r = bank.rays[i] as f64;
                for k in 1..N_THETA {
                    for j in 0..N_PHI {
                        let b = if j == 0 || j == N_PHI - 1 {
                            dphi
                        } else {
                            2.0 * dphi
                        };
                        let m = &mut sums[k * N_PHI + j];
                        m.iter_mut()
                            .flatten()
                            .for_each(|x| *x /= r * a_theta[k] * b);
                    }
                }
                for k in 1..N_THETA {
                    let row = &mut sums[k * N_PHI..(k + 1) * N_PHI];
                    // in the plane of incidence (phi = 0, pi) the mirror y -> -y maps
                    // the geometry onto itself: the mirror-odd elements vanish there (the
                    // tent's estimate, folded from one side, is half their mean over the
                    // first cell, a jump the renderer's mirror rows turned into 2e-2
                    // errors of M12 beside the plane)
                    for j in [0, N_PHI - 1] {
                        zero_mirror_odd(&mut row[j]);
                    }
                    smooth_near_pole(row, k);
                }
                // the pole: pooled over the full circle, then in each azimuth's Sp basis
                let norm = r * a_theta[0] * 2.0 * PI;
                pole.iter_mut().flatten().for_each(|x| *x /= norm);
                let (xt, yt) = transported(V3::Z);
                // in the phi = 0 basis, with the mirror symmetry of the pole imposed (its
                // mirror-odd elements are noise: the folded paths cover one side)
                let (x0, y0) = sp_out(V3::Z, 1.0, 0.0);
                let mut p0 = change_bases(&pole, (x_in, y_in, xt, yt), (x_in, y_in, x0, y0));
                zero_mirror_odd(&mut p0);
                for (j, node) in sums.iter_mut().take(N_PHI).enumerate() {
                    let (sp, cp) = (j as f64 * dphi).sin_cos();
                    let (xo, yo) = sp_out(V3::Z, cp, sp);
                    *node = change_bases(&p0, (x_in, y_in, x0, y0), (x_in, y_in, xo, yo));
                }
                sums
            })
            .collect();
        OrderTable {
            data: rows.into_iter().flatten().collect(),
        }
    }

    /// The table at fraction `w` of the way from `self` to `other` (two roughness nodes), at
    /// fixed angles: per node, `M00` interpolated in `ln(M00 + eps)` (`eps = MIX_FLOOR`
    /// times the larger table's largest `M00`) and the normalized elements `M / M00`
    /// linearly (where one node's `M00` is 0, the other's). A material between nodes does
    /// not take this `M00`: it reads each node's `M00` at the angles of the small-slope
    /// similarity ([`crate::brdf::orders::similar::mix`], whose errors against banks traced
    /// at the intervals' midpoints `docs/bank-alpha-interpolation.md` gives), and keeps
    /// only the normalized elements of this mix. Why logarithmic: orders >= 2 grow with
    /// alpha roughly exponentially where the surface's geometry is just beginning to allow
    /// them (order 2 of aluminium at 30 deg backscatter: 1.1e-3, 3.1e-3, 9.2e-3 at alpha
    /// 0.5, 0.55, 0.6), where a linear mix of `M00` was 68% high. A mix of
    /// normalized Mueller matrices with positive weights is one (a physical matrix), and
    /// it commutes with the reciprocity and mirror maps, so the table keeps its
    /// symmetries.
    pub fn mix(&self, other: &OrderTable, w: f64) -> OrderTable {
        if w <= 0.0 {
            return self.clone();
        }
        if w >= 1.0 {
            return other.clone();
        }
        let peak = |t: &OrderTable| t.data.iter().map(|m| m[0][0]).fold(0.0, f64::max);
        let eps = MIX_FLOOR * peak(self).max(peak(other));
        let data = self
            .data
            .iter()
            .zip(&other.data)
            .map(|(p, q)| {
                let (a, b) = (p[0][0].max(0.0), q[0][0].max(0.0));
                let m00 = log_mix(a, b, w, eps);
                let (wa, wb) = match (a > 0.0, b > 0.0) {
                    (true, true) => ((1.0 - w) / a, w / b),
                    (true, false) => (1.0 / a, 0.0),
                    (false, true) => (0.0, 1.0 / b),
                    (false, false) => (0.0, 0.0),
                };
                let mut m = [[0.0; 4]; 4];
                for r in 0..4 {
                    for c in 0..4 {
                        m[r][c] = m00 * (wa * p[r][c] + wb * q[r][c]);
                    }
                }
                m
            })
            .collect();
        OrderTable { data }
    }

    /// The mean of each node and its reciprocal partner: node `(o, i, j)` is
    /// `E T(i, o, j)^T E` (module docs).
    fn reciprocal_mean(&self) -> OrderTable {
        let at = |i: usize, o: usize, j: usize| &self.data[(i * N_THETA + o) * N_PHI + j];
        let mut data = Vec::with_capacity(N_THETA * N_THETA * N_PHI);
        for i in 0..N_THETA {
            for o in 0..N_THETA {
                for j in 0..N_PHI {
                    let (t, r) = (at(i, o, j), at(o, i, j));
                    let mut m = [[0.0; 4]; 4];
                    for a in 0..4 {
                        for b in 0..4 {
                            m[a][b] = 0.5 * (t[a][b] + E[a] * r[b][a] * E[b]);
                        }
                    }
                    data.push(m);
                }
            }
        }
        OrderTable { data }
    }

    /// `f(wi, wo)` (1/sr) in the beam frames of `frame`; zero when either direction is on
    /// or below the horizon.
    pub fn eval(&self, wi: V3, wo: V3, frame: Frame) -> Mat4 {
        let mut m = [[0.0; 4]; 4];
        if wi[2] <= 0.0 || wo[2] <= 0.0 {
            return m;
        }
        // the azimuths as the Sp frame of `beam_bases` takes them
        let (x_in, _, x_out, _) = beam_bases(Frame::Sp, wi, wo);
        // x_in = e_phi(phi_i) = (-sin, cos), x_out = -e_phi(phi_o) = (sin, -cos)
        let (ci, si) = (x_in[1], -x_in[0]);
        let (co, so) = (-x_out[1], x_out[0]);
        let phi = (ci * so - si * co).atan2(ci * co + si * so);
        let mirrored = phi < 0.0;
        let coord = |t: f64, n: usize| {
            let t = t.clamp(0.0, (n - 1) as f64);
            let k = (t.floor() as usize).min(n - 2);
            (k, t - k as f64)
        };
        let (i0, fi) = coord(wi[2].clamp(-1.0, 1.0).acos() / THETA_STEP, N_THETA);
        let (o0, fo) = coord(wo[2].clamp(-1.0, 1.0).acos() / THETA_STEP, N_THETA);
        let (j0, fj) = coord(phi.abs() / (PI / (N_PHI - 1) as f64), N_PHI);
        for (i, wa) in [(i0, 1.0 - fi), (i0 + 1, fi)] {
            for (o, wb) in [(o0, 1.0 - fo), (o0 + 1, fo)] {
                for (j, wc) in [(j0, 1.0 - fj), (j0 + 1, fj)] {
                    let w = wa * wb * wc;
                    if w != 0.0 {
                        add(&mut m, &self.data[(i * N_THETA + o) * N_PHI + j], w);
                    }
                }
            }
        }
        if mirrored {
            m = mirror(&m);
        }
        if frame != Frame::Sp {
            m = change_bases(&m, beam_bases(Frame::Sp, wi, wo), beam_bases(frame, wi, wo));
        }
        m
    }

    /// The directional albedo of the interpolated table at incidence node `i` for
    /// unpolarized light, `int M00 cos(theta_o) d omega_o` over the hemisphere, the
    /// table bilinear in `(theta_o, phi)` within each cell (constant beyond the last node):
    /// Gauss-Legendre, 4 x 4 points per cell. Between incidence nodes the table's albedo
    /// is the linear interpolation of these (the interpolation weights in `theta_i` do not
    /// depend on `wo`).
    pub fn interpolated_albedo(&self, i: usize) -> f64 {
        let dphi = PI / (N_PHI - 1) as f64;
        let g = [
            (-0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
            (-0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
            (0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
            (0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
        ];
        let m00 = |o: usize, j: usize| self.data[(i * N_THETA + o) * N_PHI + j][0][0];
        let mut s = 0.0;
        for o in 0..N_THETA {
            let (t0, t1) = (
                o as f64 * THETA_STEP,
                ((o + 1) as f64 * THETA_STEP).min(0.5 * PI),
            );
            for j in 0..N_PHI - 1 {
                for (xt, wt) in g {
                    let u = 0.5 * (xt + 1.0);
                    let t = t0 + u * (t1 - t0);
                    let jac_t = 0.5 * (t1 - t0) * t.sin() * t.cos();
                    for (xp, wp) in g {
                        let v = 0.5 * (xp + 1.0);
                        let (lo, hi) = if o + 1 < N_THETA {
                            (
                                (1.0 - v) * m00(o, j) + v * m00(o, j + 1),
                                (1.0 - v) * m00(o + 1, j) + v * m00(o + 1, j + 1),
                            )
                        } else {
                            let c = (1.0 - v) * m00(o, j) + v * m00(o, j + 1);
                            (c, c)
                        };
                        let f = (1.0 - u) * lo + u * hi;
                        s += wt * wp * f * jac_t * 0.5 * dphi;
                    }
                }
            }
        }
        // both halves of the circle
        2.0 * s
    }

    /// The directional albedo of the table at incidence node `i` for unpolarized light,
    /// `int M00 cos(theta_o) d omega_o` in the kernel's own quadrature (each node's value
    /// times its kernel's cosine-weighted solid angle): before the reciprocity mean this is
    /// exactly the paths' flux (the tents are a partition of unity), less the paths beyond
    /// the last node's tent.
    pub fn node_albedo(&self, i: usize) -> f64 {
        let dphi = PI / (N_PHI - 1) as f64;
        let mut s = 0.0;
        for o in 0..N_THETA {
            for j in 0..N_PHI {
                let b = if o == 0 {
                    // the pole's value is one pooled value, in every azimuth's basis
                    2.0 * PI / N_PHI as f64
                } else if j == 0 || j == N_PHI - 1 {
                    dphi
                } else {
                    2.0 * dphi
                };
                s += self.data[(i * N_THETA + o) * N_PHI + j][0][0] * theta_weight(o) * b;
            }
        }
        s
    }
}

/// Exit nodes nearer the pole than this hold as few paths per `phi` node as one at
/// `POOL_THETA` once averaged over `phi` ([`smooth_near_pole`]).
const POOL_THETA: f64 = 15.0 * PI / 180.0;

/// Half-width in `phi` nodes of the box average of exit node `k` ([`smooth_near_pole`]):
/// `round(sin(POOL_THETA) / sin(theta_k)) - 1`, 5 at 2.5 deg, 2 at 5 deg, 1 at 7.5 and
/// 10 deg, 0 from 12.5 deg.
fn pole_half_width(k: usize) -> usize {
    let s = (k as f64 * THETA_STEP).sin();
    if s <= 0.0 {
        return 0;
    }
    ((POOL_THETA.sin() / s).round() as usize).saturating_sub(1)
}

/// Average the `phi` row of exit node `k` (nodes `0..N_PHI` over `[0, pi]`) over
/// `2 w + 1` neighbours, `w = pole_half_width(k)`, on the full circle (the values at
/// `-phi` and `2 pi - phi` are the mirror images `D M D`). Near the pole a `phi` node's
/// kernel covers a solid angle `sin(theta)` times smaller than at the equator, so it holds
/// few paths: the 2.5 deg row of a 4e6-ray bank carried 4% noise into bistatic pairs
/// near normal incidence, which the relative azimuth crosses quickly. The average spans at
/// most 2 deg of arc there (where the surface's orders >= 2 vary on the scale of alpha),
/// and it keeps the row's trapezoid sum (the albedo) exactly: it is a circular
/// convolution with a normalized kernel.
fn smooth_near_pole(row: &mut [Mat4], k: usize) {
    let w = pole_half_width(k);
    if w == 0 {
        return;
    }
    let n = N_PHI - 1; // the circle has 2 n nodes
    let at = |idx: isize| -> Mat4 {
        let idx = idx.rem_euclid(2 * n as isize) as usize;
        if idx <= n {
            row[idx]
        } else {
            mirror(&row[2 * n - idx])
        }
    };
    let scale = 1.0 / (2 * w + 1) as f64;
    let out: Vec<Mat4> = (0..N_PHI as isize)
        .map(|j| {
            let mut m = [[0.0; 4]; 4];
            for d in -(w as isize)..=(w as isize) {
                add(&mut m, &at(j + d), scale);
            }
            m
        })
        .collect();
    row.copy_from_slice(&out);
}

/// `int K_k(theta) cos(theta) sin(theta) d theta` of node `k`'s tent over `[0, pi/2]`.
fn theta_weight(k: usize) -> f64 {
    let (c, h) = (k as f64 * THETA_STEP, THETA_STEP);
    let n = 512;
    let mut s = 0.0;
    // midpoint rule on each side of the node (the kernel's kink is at the node)
    for side in [-1.0, 1.0] {
        for m in 0..n {
            let u = (m as f64 + 0.5) / n as f64;
            let t = c + side * u * h;
            if (0.0..=0.5 * PI).contains(&t) {
                s += (1.0 - u) * t.sin() * t.cos() * h / n as f64;
            }
        }
    }
    s
}

#[cfg(test)]
mod tests;
