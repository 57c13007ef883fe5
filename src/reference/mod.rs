//! An explicit-microsurface Monte Carlo reference for the polarized BRDF (PHYSICS.md
//! section 6): random Gaussian height fields, triangulated and ray traced with Fresnel
//! reflection and full polarization at every bounce, tallied per bounce order.
//!
//! It shares no model code with [`crate::brdf`] or [`crate::microfacet`]: only the optics
//! conventions ([`crate::optics::fresnel::fresnel_amplitudes`], the beam frames of
//! [`crate::optics::frames::beam_bases`] and [`crate::optics::mueller::jones_to_mueller`]).
//! Geometric optics, incoherent: no diffraction; coherent backscatter only as the optional
//! separate tally described below.
//!
//! # Estimator and its normalization
//! The tile (area `A = n^2` grid units, periodic) is lit by a plane wave of irradiance
//! `E` (power per unit area normal to the beam) from `wi`. It receives the flux
//! `E A cos(theta_i)`; the primary rays start at uniform random horizontal positions on the
//! plane `z = h_max + 0.001` (uniform over the tile's projected area) and travel along `-wi`, so
//! each of the `R` rays carries `E A cos(theta_i) / R`.
//! By the definition of the BRDF the reflected radiance is `L(wo) = f(wi, wo) E cos(theta_i)`,
//! and the power the macro area sends into a cone `C` of half-angle `gamma` around `wo` is
//! `Phi_C = A int_C L cos(theta) dw = A E cos(theta_i) int_C f cos(theta) dw`.
//! Equating with the ray estimate `Phi_C = (E A cos(theta_i) / R) sum_{rays in C} w_r`:
//!
//! `f_hat = sum_{rays in C} w_r / (R * Omega_p)`, `Omega_p = int_C cos(theta) dw = pi sin^2(gamma) cos(theta_o)`
//!
//! (`int_C w dw = pi sin^2(gamma) wo` for a spherical cap; the cap must lie above the
//! horizon). `cos(theta_i)` cancels. `f_hat` is exactly the `cos(theta)`-weighted mean of `f`
//! over the cone; the remaining bias is the curvature of `f` across the cone, O(gamma^2).
//! Using the plain solid angle `2 pi (1 - cos gamma)` instead of `Omega_p / cos(theta_o)`
//! would add a bias of `gamma^2 / 4`. With Mueller matrices `w_r` is the Mueller matrix of
//! the ray's Jones matrix (its `M00` is the ray's unpolarized throughput).
//!
//! # Frames at escape
//! The output Stokes basis is the frame's basis `(x_o, y_o)` of the cone axis `wo`
//! (`beam_bases(frame, wi, wo)`), carried to each escaping ray's own direction `k` by the
//! minimal rotation taking `wo` to `k` (parallel transport along the great circle). The
//! ray's field is transverse to `k`, so projecting onto the transported basis loses no
//! power (projecting onto `wo`'s transverse plane would lose `O(gamma^2)`), and the basis
//! varies smoothly across the cone even where the frame's own basis is singular (the `sp`
//! frame at `wo = n`, whose azimuth is undefined at the pole). As `gamma -> 0` it tends to
//! `beam_bases(frame, wi, wo)`.
//!
//! # Coherent backscatter (optional: [`Config::coherent`])
//! Each escaping path of order `N >= 2` (hit points `r_1 .. r_N`) interferes with its
//! reverse path (the same facets, `r_N` first). The tally uses the paths in the cone of the
//! first detector, which must be the exact backscatter direction `wo = wi`.
//!
//! *Phase.* Fields go as `exp(i (k . r - omega t))` (the `exp(-i omega t)` convention of
//! [`crate::optics`]), `k = 2 pi / lambda`. The incident wave travels along `-wi`, so its
//! phase at `r` is `-k wi . r`; a wave leaving `r` for a far receiver in direction `w` has
//! phase `-k w . r` relative to one leaving the origin. The inner path length is the same
//! both ways, so `phi_fwd = -k (wi . r_1 + w . r_N) + c`, `phi_rev = -k (wi . r_N + w . r_1) + c`
//! and `phi_rev - phi_fwd = Delta = q . rho`, `q = k (w - wi)`, `rho = r_N - r_1` (3D; the
//! traversal wraps positions into the tile, so the log carries the physical displacement as
//! the sum of the segments, [`trace::PathLog`]). The pair's field is
//! `e^{i phi_fwd} (J + e^{i Delta} J_rev)` and its interference term
//! `M(J + e^{i Delta} J_rev) - M(J) - M(J_rev)`. Each pair is met twice, once from each of
//! its paths (at exact backscatter the partner's term, with the roles of `J`, `J_rev` swapped
//! and `-Delta`, is the same matrix: the two sums differ by a global phase), so each path
//! tallies half of it:
//! `0.5 [M(J + e^{i Delta_b} J_rev) - M(J) - M(J_rev)]` for each bistatic direction `w = wo_b`,
//! normalized as the incoherent tally of the first detector, so that the total at order `o`
//! is `mueller + coherent` element by element.
//!
//! *Reverse path.* `J_rev` is traced, not assumed: the incident basis fields, arriving along
//! `-wi`, are reflected off the recorded facet normals in reverse order
//! ([`trace::reflect_reversed`]) and projected on the detector's bases exactly as a forward
//! ray (transported to the reversed ray's exit direction `k'`). Reciprocity is then a test:
//! one reflection's 3x3 map is `P = rs s s^T + rp p_out p_in^T`; for the reversed ray
//! (incident `-k_out`) `s' = -s`, `p'_in = p_out`, `p'_out = p_in`, so `P' = P^T`, and a
//! path's product reverses to `P^T` (tested for random facets in [`trace`]). At exact
//! backscatter (`k = wi`) the reversed path lit along `-wi` is the time reverse, so
//! `J_rev[a][b] = x_out_a . P^T x_in_b = x_in_b . P x_out_a`; the `sp` frame at backscatter
//! has `x_out = -x_in`, `y_out = y_in`, hence `J_rev = F J^T F`, `F = diag(-1, 1)` (as
//! [`crate::optics::mueller::reciprocal`] and `brdf::double`; tested on corner cubes). An
//! order-2 backscatter path is planar (`h1 . h2 = 0`, both normals in the plane of `wi`
//! and `d`), and reversing it changes neither the s/p bases nor the product
//! `diag(rs1 rs2, rp1 rp2)`: `J_rev = J`, so the order-2 coherent term equals the
//! incoherent one (PHYSICS.md 5b). Non-planar paths (orders 3+) have `J_rev != J`: less
//! than 2x, except in the channels where reciprocity makes the two amplitudes equal (linear
//! co-polarized, helicity preserving).
//!
//! *Approximations.* (1) `J_rev` is the one at exact backscatter for every bistatic
//! direction (the standard small-angle approximation: the `beta` dependence is in the phase
//! only). (2) For a ray leaving within the cone along `k != wi`, the reversed path lit along
//! `-wi` leaves along `k'` (the same angle from `wi`), not along `k`; the difference from
//! the exact partner is `O(cone)` per path and averages to `O(cone^2)` (order 2: at most
//! 0.6% of M00 at cone 0.1 in the tests). (3) The reversed path is not traced for
//! visibility (it is the time reverse of an unobstructed path up to the cone angle); when a
//! facet faces away from the reversed ray it does not exist: the path then adds nothing and
//! is counted in [`Output::coherent_unpaired`]. (4) Facets act as point scatterers at the
//! hit points (geometric optics; no diffraction by the finite facets).
//!
//! # Errors
//! Tallies are split into `batches` independent batches; each batch uses its own surface
//! realization (seed stream `[0, batch]`) and its own rays, so the standard errors (of the
//! batch estimates' mean) include the surface-to-surface variance of a finite tile.

pub mod microsurface;
pub mod rng;
pub mod trace;

use crate::optics::frames::{beam_bases, cross, dot, Frame, V3};
use crate::optics::fresnel::{Eta, C64};
use crate::optics::mueller::{jones_to_mueller, Jones, Mat4};
use crate::{Error, Result};
use microsurface::{gaussian_height_field, HeightField, SurfaceReport};
use rayon::prelude::*;
use rng::Rng;
use std::sync::Arc;
use trace::{reflect_reversed, trace_ray_logged, Fields, PathLog, RayEnd};

pub use microsurface::SlopeStats;

/// Number of order bins: 1, 2 and 3+.
pub const ORDERS: usize = 3;
/// Number of coherent order bins: 2 and 3+.
pub const COHERENT_ORDERS: usize = 2;
/// Rays per parallel work item (fixed, so results do not depend on the thread count).
const CHUNK: u64 = 2048;

/// The microsurface to trace.
#[derive(Debug, Clone)]
pub enum Surface {
    /// A Gaussian random surface per batch (see [`microsurface`]).
    Gaussian {
        /// Beckmann roughness: `alpha^2 = 2 var(slope component)`.
        alpha: f64,
        /// Grid size `n` of the periodic `n x n` tile.
        grid: usize,
        /// Height correlation length in grid units (`C(r) ~ exp(-r^2 / l^2)`).
        correlation_length: f64,
    },
    /// A user height field (`n x n`, `h[i * n + j] = h(x = i, y = j)`), the same in every batch.
    Heights(Arc<HeightField>),
}

/// The coherent-backscatter tally (module docs, "Coherent backscatter").
#[derive(Debug, Clone)]
pub struct Coherent {
    /// Wavelength in grid units (the units of the tile and of `correlation_length`), > 0.
    pub wavelength: f64,
    /// Bistatic receiver directions `wo_b` (unit, within pi/4 of `wi`); the interference
    /// term is tallied for each. `wo_b = wi` is exact backscatter (bistatic angle 0).
    pub bistatic: Vec<V3>,
}

/// Parameters of one reference run.
#[derive(Debug, Clone)]
pub struct Config {
    /// Direction toward the transmitter (unit, `z > 0`).
    pub wi: V3,
    /// Detector cone axes (unit, above the horizon by more than `cone`).
    pub wo: Vec<V3>,
    pub eta: Eta,
    pub surface: Surface,
    /// Total number of primary rays (over all batches).
    pub rays: u64,
    /// Detector cone half-angle in radians.
    pub cone: f64,
    /// Maximum number of reflections followed.
    pub max_order: u32,
    pub frame: Frame,
    pub seed: u64,
    pub batches: u32,
    /// The coherent-backscatter tally, if wanted; then `wo[0]` must equal `wi`.
    pub coherent: Option<Coherent>,
}

/// Results of a run. Order bins `o = 0, 1, 2` are 1, 2 and 3+ reflections.
#[derive(Debug, Clone)]
pub struct Output {
    /// Mueller BRDF (1/sr) per order and detector, `mueller[o * K + k]`.
    pub mueller: Vec<Mat4>,
    /// Standard errors of `mueller` (batch means).
    pub stderr: Vec<Mat4>,
    /// Number of rays tallied per order and detector, `counts[o * K + k]`.
    pub counts: Vec<u64>,
    /// `Omega_p = pi sin^2(cone) cos(theta_o)` per detector (sr).
    pub projected_solid_angle: Vec<f64>,
    /// Directional albedo (escaped unpolarized power fraction) per order.
    pub albedo: [f64; ORDERS],
    pub albedo_stderr: [f64; ORDERS],
    /// Unpolarized power fraction still on the surface after `max_order` reflections.
    pub truncated: f64,
    pub truncated_stderr: f64,
    /// Fraction of rays lost by the traversal (numerical failures; expected 0).
    pub lost: f64,
    /// Coherent-backscatter interference term (1/sr, normalized as `mueller`) of the paths
    /// in the first detector's cone, per coherent order bin `c` (0: order 2, 1: orders 3+)
    /// and bistatic direction `b`: `coherent[c * B + b]`. Empty without
    /// [`Config::coherent`]. At `wo_b = wi` the total (coherent plus incoherent) is
    /// `mueller[o * K] + coherent[(o - 1) * B + b]`.
    pub coherent: Vec<Mat4>,
    /// Standard errors of `coherent` (batch means).
    pub coherent_stderr: Vec<Mat4>,
    /// Per coherent order bin: tallied paths whose reversed facet sequence does not exist
    /// (a facet faces away from the reversed ray); their coherent term is 0.
    pub coherent_unpaired: [u64; COHERENT_ORDERS],
    /// One report per batch surface.
    pub surfaces: Vec<SurfaceReport>,
    /// Wall time of the run in seconds.
    pub elapsed_s: f64,
}

/// Per-chunk (and per-batch) sums.
#[derive(Debug, Clone)]
struct Tally {
    m: Vec<Mat4>,
    counts: Vec<u64>,
    albedo: [f64; ORDERS],
    truncated: f64,
    lost: u64,
    /// Coherent terms, `coh[c * B + b]` (empty without the coherent tally).
    coh: Vec<Mat4>,
    unpaired: [u64; COHERENT_ORDERS],
}

/// `a += b` element by element.
#[inline]
fn add_mat(a: &mut Mat4, b: &Mat4) {
    a.iter_mut()
        .flatten()
        .zip(b.iter().flatten())
        .for_each(|(x, y)| *x += y);
}

impl Tally {
    fn new(k: usize, nb: usize) -> Self {
        Tally {
            m: vec![[[0.0; 4]; 4]; ORDERS * k],
            counts: vec![0; ORDERS * k],
            albedo: [0.0; ORDERS],
            truncated: 0.0,
            lost: 0,
            coh: vec![[[0.0; 4]; 4]; COHERENT_ORDERS * nb],
            unpaired: [0; COHERENT_ORDERS],
        }
    }
    fn add(&mut self, o: &Tally) {
        for (a, b) in self.m.iter_mut().zip(&o.m) {
            add_mat(a, b);
        }
        for (a, b) in self.coh.iter_mut().zip(&o.coh) {
            add_mat(a, b);
        }
        self.unpaired
            .iter_mut()
            .zip(&o.unpaired)
            .for_each(|(a, b)| *a += b);
        self.counts
            .iter_mut()
            .zip(&o.counts)
            .for_each(|(a, b)| *a += b);
        self.albedo
            .iter_mut()
            .zip(&o.albedo)
            .for_each(|(a, b)| *a += b);
        self.truncated += o.truncated;
        self.lost += o.lost;
    }
}

/// A detector: cone axis and the precomputed bases.
#[derive(Debug, Clone, Copy)]
struct Detector {
    wo: V3,
    /// Coefficients of `x_in`, `y_in` on the incident basis `(e1, e2)` the rays carry.
    a: [f64; 2],
    b: [f64; 2],
    x_out: V3,
    cos_cone: f64,
}

impl Detector {
    /// The detector of axis `wo` and half-angle `cone` for rays carrying the fields of the
    /// incident basis `e = (e1, e2)`.
    fn new(frame: Frame, wi: V3, wo: V3, e: (V3, V3), cone: f64) -> Self {
        let (x_in, y_in, x_out, _) = beam_bases(frame, wi, wo);
        Detector {
            wo,
            a: [dot(x_in, e.0), dot(x_in, e.1)],
            b: [dot(y_in, e.0), dot(y_in, e.1)],
            x_out,
            cos_cone: cone.cos(),
        }
    }

    /// Jones matrix of an escaped ray (direction `k`, fields `e` of `e1, e2`).
    #[inline]
    fn jones(&self, k: V3, e: &Fields) -> Jones {
        let px: [C64; 3] = std::array::from_fn(|i| e[0][i] * self.a[0] + e[1][i] * self.a[1]);
        let py: [C64; 3] = std::array::from_fn(|i| e[0][i] * self.b[0] + e[1][i] * self.b[1]);
        // Parallel transport of x_out from wo to k: R = I + [w]x + [w]x^2 / (1 + c).
        let w = cross(self.wo, k);
        let c = dot(self.wo, k);
        let wx = cross(w, self.x_out);
        let wwx = cross(w, wx);
        let mut x = self.x_out + wx + wwx / (1.0 + c);
        let xk = dot(x, k);
        x -= xk * k;
        let l = dot(x, x).sqrt();
        x /= l;
        let y = cross(k, x);
        let proj = |u: V3, f: &[C64; 3]| f[0] * u[0] + f[1] * u[1] + f[2] * u[2];
        [[proj(x, &px), proj(x, &py)], [proj(y, &px), proj(y, &py)]]
    }
}

/// Add one escaped path's coherent terms to `out[b]`:
/// `0.5 [M(J + e^{i Delta_b} J_rev) - M(J) - M(J_rev)]`, `Delta_b = q[b] . rho`, with `J`
/// the path's Jones matrix in the backscatter detector's bases and `J_rev` that of the
/// reversed facet sequence lit along `-wi` (module docs). Returns `false`, adding nothing,
/// when the reversed path does not exist.
#[allow(clippy::too_many_arguments)]
fn coherent_terms(
    det: &Detector,
    eta: Eta,
    wi: V3,
    e0: &Fields,
    j: &Jones,
    log: &PathLog,
    q: &[V3],
    out: &mut [Mat4],
) -> bool {
    let mut er = *e0;
    let Some(kr) = reflect_reversed(wi, &log.normals, eta, &mut er) else {
        return false;
    };
    let jr = det.jones(kr, &er);
    let (m, mr) = (jones_to_mueller(j), jones_to_mueller(&jr));
    for (acc, &qb) in out.iter_mut().zip(q) {
        let z = C64::from_polar(1.0, dot(qb, log.rho));
        let sum: Jones = std::array::from_fn(|a| std::array::from_fn(|b| j[a][b] + z * jr[a][b]));
        let ms = jones_to_mueller(&sum);
        for r in 0..4 {
            for c in 0..4 {
                acc[r][c] += 0.5 * (ms[r][c] - m[r][c] - mr[r][c]);
            }
        }
    }
    true
}

/// Validate a direction (unit within 1e-6, finite).
fn unit(v: V3, name: &'static str) -> Result<V3> {
    if !v.is_finite() {
        return Err(Error::InvalidDirection {
            name,
            reason: format!("{:?} is not finite", v.to_array()),
        });
    }
    let l = dot(v, v).sqrt();
    if (l - 1.0).abs() > 1e-6 {
        return Err(Error::InvalidDirection {
            name,
            reason: format!("{:?} has length {l}; must be a unit vector", v.to_array()),
        });
    }
    Ok(v / l)
}

/// Check every parameter, naming the offending one.
fn validate(cfg: &Config) -> Result<()> {
    let wi = unit(cfg.wi, "wi")?;
    if wi[2] <= 1e-6 {
        return Err(Error::InvalidDirection {
            name: "wi",
            reason: format!(
                "{:?} must be above the horizon (z > 1e-6)",
                cfg.wi.to_array()
            ),
        });
    }
    if !(cfg.cone.is_finite() && cfg.cone > 0.0 && cfg.cone <= std::f64::consts::FRAC_PI_4) {
        return Err(Error::param(
            "cone",
            cfg.cone,
            "half-angle must be in (0, pi/4] radians",
        ));
    }
    if cfg.wo.is_empty() {
        return Err(Error::Shape("wo must hold at least one direction".into()));
    }
    for (i, &w) in cfg.wo.iter().enumerate() {
        let w = unit(w, "wo")?;
        if w[2] <= cfg.cone.sin() {
            return Err(Error::InvalidDirection {
                name: "wo",
                reason: format!(
                    "element {i} = {:?}: the detector cone of half-angle {} reaches the horizon (need z > sin(cone) = {})",
                    w.to_array(),
                    cfg.cone,
                    cfg.cone.sin()
                ),
            });
        }
    }
    if let Eta::Complex(e) = cfg.eta {
        if !(e.re.is_finite() && e.im.is_finite() && e.re > 0.0 && e.im >= 0.0) {
            return Err(Error::param(
                "eta",
                e,
                "must be n + ik with n > 0, k >= 0 finite (or inf for a perfect conductor)",
            ));
        }
    }
    if !(1..=1000).contains(&cfg.max_order) {
        return Err(Error::param(
            "max_order",
            cfg.max_order,
            "must be in [1, 1000]",
        ));
    }
    if !(2..=100_000).contains(&cfg.batches) {
        return Err(Error::param(
            "batches",
            cfg.batches,
            "must be in [2, 100000] (standard errors need 2)",
        ));
    }
    if cfg.rays < cfg.batches as u64 || cfg.rays > 1u64 << 40 {
        return Err(Error::param(
            "rays",
            cfg.rays,
            format!("must be in [batches = {}, 2^40]", cfg.batches),
        ));
    }
    if let Surface::Gaussian {
        alpha,
        grid,
        correlation_length,
    } = cfg.surface
    {
        microsurface::check_gaussian(alpha, grid, correlation_length)?;
    }
    if let Some(c) = &cfg.coherent {
        if !(c.wavelength.is_finite() && c.wavelength > 0.0) {
            return Err(Error::param(
                "wavelength",
                c.wavelength,
                "must be finite and > 0 (grid units)",
            ));
        }
        let wo0 = unit(cfg.wo[0], "wo")?;
        // Exact backscatter: the tally uses J_rev at wo = wi (module docs).
        if (wo0 - wi).length() > 1e-9 {
            return Err(Error::param(
                "wo",
                format!("{:?}", cfg.wo[0].to_array()),
                format!(
                    "with the coherent tally the first detector direction must equal wi = {:?} (exact backscatter)",
                    cfg.wi.to_array()
                ),
            ));
        }
        if c.bistatic.is_empty() {
            return Err(Error::param(
                "bistatic",
                "[]",
                "give at least one bistatic direction (wi itself for exact backscatter)",
            ));
        }
        for (i, &w) in c.bistatic.iter().enumerate() {
            let w = unit(w, "bistatic")?;
            let beta = dot(w, wi).clamp(-1.0, 1.0).acos();
            if beta > std::f64::consts::FRAC_PI_4 || w[2] <= 0.0 {
                return Err(Error::param(
                    "bistatic",
                    format!("element {i} = {:?}", w.to_array()),
                    format!(
                        "must be above the horizon and within pi/4 of wi (bistatic angle {beta} rad)"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Mean and standard error of the mean of batch estimates.
fn mean_se(x: &[f64]) -> (f64, f64) {
    let b = x.len() as f64;
    let m = x.iter().sum::<f64>() / b;
    let v = x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (b - 1.0);
    (m, (v / b).sqrt())
}

/// The surface of batch `batch` (Gaussian: seed stream `[0, batch]`).
pub fn batch_surface(
    surface: &Surface,
    seed: u64,
    batch: u32,
) -> Result<(Arc<HeightField>, SurfaceReport)> {
    match surface {
        Surface::Gaussian {
            alpha,
            grid,
            correlation_length,
        } => {
            let (f, rep) = gaussian_height_field(
                *alpha,
                *grid,
                *correlation_length,
                seed,
                &[0, batch as u64],
            )?;
            Ok((Arc::new(f), rep))
        }
        Surface::Heights(f) => Ok((
            f.clone(),
            SurfaceReport {
                stats: f.slope_stats(),
                alpha_unscaled_ratio: f64::NAN,
                scale: 1.0,
            },
        )),
    }
}

/// Run the reference (module docs). Parallel over rays (rayon); deterministic in `seed`
/// whatever the number of threads.
pub fn run(cfg: &Config) -> Result<Output> {
    validate(cfg)?;
    let start = std::time::Instant::now();
    let wi = unit(cfg.wi, "wi")?;
    let wo: Vec<V3> = cfg
        .wo
        .iter()
        .map(|&w| unit(w, "wo"))
        .collect::<Result<_>>()?;
    let nk = wo.len();
    // Incident basis carried by the rays: that of the first detector's frame.
    let (e1, e2, _, _) = beam_bases(cfg.frame, wi, wo[0]);
    let detectors: Vec<Detector> = wo
        .iter()
        .map(|&w| Detector::new(cfg.frame, wi, w, (e1, e2), cfg.cone))
        .collect();
    let omega_p: Vec<f64> = wo
        .iter()
        .map(|w| std::f64::consts::PI * cfg.cone.sin().powi(2) * w[2])
        .collect();
    let e0: Fields = [e1, e2].map(|v| v.to_array().map(|x| C64::new(x, 0.0)));
    // Coherent tally: q_b = (2 pi / lambda)(wo_b - wi) per bistatic direction.
    let q: Vec<V3> = match &cfg.coherent {
        Some(c) => c
            .bistatic
            .iter()
            .map(|&w| Ok((std::f64::consts::TAU / c.wavelength) * (unit(w, "bistatic")? - wi)))
            .collect::<Result<_>>()?,
        None => Vec::new(),
    };
    let nq = q.len();

    let nb = cfg.batches as u64;
    let mut batch_tallies = Vec::with_capacity(cfg.batches as usize);
    let mut batch_rays = Vec::with_capacity(cfg.batches as usize);
    let mut surfaces = Vec::with_capacity(cfg.batches as usize);
    for b in 0..cfg.batches {
        let (field, rep) = batch_surface(&cfg.surface, cfg.seed, b)?;
        surfaces.push(rep);
        let rays_b = cfg.rays / nb + u64::from((b as u64) < cfg.rays % nb);
        let n_chunks = rays_b.div_ceil(CHUNK);
        let max_cells = 64 * field.n + 4096;
        let period = field.n as f64;
        // Any start plane above the surface gives the same hits; a close one keeps
        // grazing rays short.
        let z0 = field.h_max + 1e-3;
        let chunks: Vec<Tally> = (0..n_chunks)
            .into_par_iter()
            .map(|c| {
                let mut rng = Rng::new(cfg.seed, &[1, b as u64, c]);
                let mut t = Tally::new(nk, nq);
                let mut log = PathLog::default();
                let count = CHUNK.min(rays_b - c * CHUNK);
                for _ in 0..count {
                    let start = V3::new(rng.uniform() * period, rng.uniform() * period, z0);
                    let log_opt = if nq > 0 { Some(&mut log) } else { None };
                    match trace_ray_logged(
                        &field,
                        cfg.eta,
                        wi,
                        start,
                        e0,
                        cfg.max_order,
                        max_cells,
                        log_opt,
                    ) {
                        RayEnd::Escaped { order, k, e } => {
                            let bin = (order.min(3) - 1) as usize;
                            let p: f64 = e.iter().flatten().map(|z| z.norm_sqr()).sum();
                            t.albedo[bin] += 0.5 * p;
                            for (kk, det) in detectors.iter().enumerate() {
                                if dot(k, det.wo) >= det.cos_cone {
                                    let j = det.jones(k, &e);
                                    let m = jones_to_mueller(&j);
                                    add_mat(&mut t.m[bin * nk + kk], &m);
                                    t.counts[bin * nk + kk] += 1;
                                    // The coherent tally: detector 0 (at wo = wi), orders >= 2.
                                    if kk == 0 && nq > 0 && bin > 0 {
                                        let cb = bin - 1;
                                        let out = &mut t.coh[cb * nq..(cb + 1) * nq];
                                        if !coherent_terms(det, cfg.eta, wi, &e0, &j, &log, &q, out)
                                        {
                                            t.unpaired[cb] += 1;
                                        }
                                    }
                                }
                            }
                        }
                        RayEnd::Truncated { e } => {
                            t.truncated +=
                                0.5 * e.iter().flatten().map(|z| z.norm_sqr()).sum::<f64>();
                        }
                        RayEnd::Lost => t.lost += 1,
                    }
                }
                t
            })
            .collect();
        let mut tb = Tally::new(nk, nq);
        chunks.iter().for_each(|c| tb.add(c));
        batch_tallies.push(tb);
        batch_rays.push(rays_b as f64);
    }

    // Pooled means; standard errors from the spread of the batch estimates.
    let total = cfg.rays as f64;
    let mut mueller = vec![[[0.0; 4]; 4]; ORDERS * nk];
    let mut stderr = vec![[[0.0; 4]; 4]; ORDERS * nk];
    let mut counts = vec![0u64; ORDERS * nk];
    for idx in 0..ORDERS * nk {
        let k = idx % nk;
        counts[idx] = batch_tallies.iter().map(|t| t.counts[idx]).sum();
        for i in 0..4 {
            for j in 0..4 {
                let est: Vec<f64> = batch_tallies
                    .iter()
                    .zip(&batch_rays)
                    .map(|(t, r)| t.m[idx][i][j] / (r * omega_p[k]))
                    .collect();
                let pooled: f64 = batch_tallies.iter().map(|t| t.m[idx][i][j]).sum::<f64>()
                    / (total * omega_p[k]);
                mueller[idx][i][j] = pooled;
                stderr[idx][i][j] = mean_se(&est).1;
            }
        }
    }
    // The coherent terms, normalized as the first detector's.
    let mut coherent = vec![[[0.0; 4]; 4]; COHERENT_ORDERS * nq];
    let mut coherent_stderr = vec![[[0.0; 4]; 4]; COHERENT_ORDERS * nq];
    for idx in 0..COHERENT_ORDERS * nq {
        for i in 0..4 {
            for j in 0..4 {
                let est: Vec<f64> = batch_tallies
                    .iter()
                    .zip(&batch_rays)
                    .map(|(t, r)| t.coh[idx][i][j] / (r * omega_p[0]))
                    .collect();
                coherent[idx][i][j] = batch_tallies.iter().map(|t| t.coh[idx][i][j]).sum::<f64>()
                    / (total * omega_p[0]);
                coherent_stderr[idx][i][j] = mean_se(&est).1;
            }
        }
    }
    let mut coherent_unpaired = [0u64; COHERENT_ORDERS];
    for t in &batch_tallies {
        coherent_unpaired
            .iter_mut()
            .zip(&t.unpaired)
            .for_each(|(a, b)| *a += b);
    }
    let mut albedo = [0.0; ORDERS];
    let mut albedo_stderr = [0.0; ORDERS];
    for o in 0..ORDERS {
        let est: Vec<f64> = batch_tallies
            .iter()
            .zip(&batch_rays)
            .map(|(t, r)| t.albedo[o] / r)
            .collect();
        albedo[o] = batch_tallies.iter().map(|t| t.albedo[o]).sum::<f64>() / total;
        albedo_stderr[o] = mean_se(&est).1;
    }
    let est: Vec<f64> = batch_tallies
        .iter()
        .zip(&batch_rays)
        .map(|(t, r)| t.truncated / r)
        .collect();
    let truncated = batch_tallies.iter().map(|t| t.truncated).sum::<f64>() / total;
    let lost = batch_tallies.iter().map(|t| t.lost).sum::<u64>() as f64 / total;
    Ok(Output {
        mueller,
        stderr,
        counts,
        projected_solid_angle: omega_p,
        albedo,
        albedo_stderr,
        truncated,
        truncated_stderr: mean_se(&est).1,
        lost,
        coherent,
        coherent_stderr,
        coherent_unpaired,
        surfaces,
        elapsed_s: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests_coherent;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::frames::normalize;
    use crate::optics::fresnel::fresnel_amplitudes;

    fn dir(theta_deg: f64, phi_deg: f64) -> V3 {
        let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
        V3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
    }

    fn gaussian(alpha: f64) -> Surface {
        Surface::Gaussian {
            alpha,
            grid: 128,
            correlation_length: 8.0,
        }
    }

    fn cfg(wi: V3, wo: Vec<V3>, eta: Eta, surface: Surface, rays: u64) -> Config {
        Config {
            wi,
            wo,
            eta,
            surface,
            rays,
            cone: 0.05,
            max_order: 10,
            frame: Frame::Sp,
            seed: 1,
            batches: 4,
            coherent: None,
        }
    }

    #[test]
    fn nearly_flat_surface_is_the_fresnel_mirror() {
        let wi = dir(40.0, 30.0);
        let wo = V3::new(-wi[0], -wi[1], wi[2]);
        let eta = Eta::new(1.5, 0.3);
        let out = run(&cfg(
            wi,
            vec![wo, dir(10.0, 0.0)],
            eta,
            gaussian(1e-8),
            4000,
        ))
        .unwrap();
        let (rs, rp) = fresnel_amplitudes(wi[2], eta);
        // Sp frame, specular: Jones diag(rs, rp) up to the sign convention of the frames.
        let want = jones_to_mueller(&[[rs, C64::new(0.0, 0.0)], [C64::new(0.0, 0.0), rp]]);
        let got = crate::optics::mueller::scale(&out.mueller[0], out.projected_solid_angle[0]);
        for i in 0..4 {
            for j in 0..4 {
                assert!(
                    (got[i][j] - want[i][j]).abs() < 1e-9,
                    "{i}{j}: {got:?} vs {want:?}"
                );
            }
        }
        assert_eq!(out.counts[0], 4000);
        assert_eq!(out.counts[1], 0);
        assert!(out.albedo[1] == 0.0 && out.albedo[2] == 0.0 && out.lost == 0.0);
    }

    #[test]
    fn perfect_conductor_conserves_energy() {
        let out = run(&cfg(
            dir(60.0, 0.0),
            vec![dir(0.0, 0.0)],
            Eta::PerfectConductor,
            gaussian(0.8),
            20_000,
        ))
        .unwrap();
        let total: f64 = out.albedo.iter().sum::<f64>() + out.truncated;
        assert_eq!(out.lost, 0.0);
        assert!((total - 1.0).abs() < 1e-12, "{out:?}");
        assert!(
            out.albedo[1] > 0.05,
            "rough surface has double bounces: {:?}",
            out.albedo
        );
    }

    #[test]
    fn v_groove_is_a_dihedral() {
        // 90-degree grooves along y (period 2 cells, slopes +-1). At normal incidence every
        // ray reflects twice and returns along wi; tilted in the x-z plane, the rays that
        // hit high on a face leave over the opposite (finite) wall after one reflection,
        // and the others still reflect twice and return along wi.
        let n = 16;
        let h: Vec<f64> = (0..n * n).map(|k| ((k / n) % 2) as f64).collect();
        let f = Arc::new(HeightField::new(n, h).unwrap());
        let eta = Eta::new(0.8, 2.5);
        for tilt in [0.0f64, 20.0] {
            let wi = dir(tilt, 0.0);
            let out = run(&cfg(wi, vec![wi], eta, Surface::Heights(f.clone()), 2000)).unwrap();
            if tilt == 0.0 {
                assert_eq!(out.counts[1], 2000, "{out:?}");
            }
            assert_eq!(out.counts[0] + out.counts[2], 0);
            let (t1, t2) = ((45.0 - tilt).to_radians(), (45.0 + tilt).to_radians());
            let (rs1, rp1) = fresnel_amplitudes(t1.cos(), eta);
            let (rs2, rp2) = fresnel_amplitudes(t2.cos(), eta);
            let z = C64::new(0.0, 0.0);
            let want = jones_to_mueller(&[[rs1 * rs2, z], [z, rp1 * rp2]]);
            // Mean Mueller matrix of a backscattered ray.
            let per_ray = out.projected_solid_angle[0] * 2000.0 / out.counts[1] as f64;
            let got = crate::optics::mueller::scale(&out.mueller[1], per_ray);
            for i in 0..4 {
                for j in 0..4 {
                    assert!(
                        (got[i][j] - want[i][j]).abs() < 1e-12,
                        "tilt {tilt} {i}{j}: {got:?} vs {want:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn results_do_not_depend_on_thread_count() {
        let c = cfg(
            dir(30.0, 0.0),
            vec![dir(30.0, 0.0), normalize(V3::new(0.2, 0.1, 0.9))],
            Eta::new(1.2, 1.0),
            gaussian(0.4),
            5000,
        );
        let a = run(&c).unwrap();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let b = pool.install(|| run(&c).unwrap());
        assert_eq!(a.mueller, b.mueller);
        assert_eq!(a.albedo, b.albedo);
    }

    #[test]
    fn errors_name_the_parameter() {
        let base = cfg(
            dir(30.0, 0.0),
            vec![dir(30.0, 0.0)],
            Eta::new(1.5, 0.0),
            gaussian(0.3),
            100,
        );
        let mut c = base.clone();
        c.cone = 0.0;
        assert!(run(&c).unwrap_err().to_string().contains("cone"));
        let mut c = base.clone();
        c.wo = vec![dir(89.0, 0.0)];
        assert!(run(&c).unwrap_err().to_string().contains("wo"));
        let mut c = base.clone();
        c.batches = 1;
        assert!(run(&c).unwrap_err().to_string().contains("batches"));
        let mut c = base.clone();
        c.max_order = 0;
        assert!(run(&c).unwrap_err().to_string().contains("max_order"));
        let mut c = base;
        c.wi = V3::new(0.0, 0.0, 2.0);
        assert!(run(&c).unwrap_err().to_string().contains("wi"));
    }
}
