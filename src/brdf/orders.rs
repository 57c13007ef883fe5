//! A material's orders >= 2 from path banks ([`super::bank`]) at roughness nodes,
//! interpolated in alpha: the data behind [`super::spec::Orders::Surface`].
//!
//! For each alpha node (`ALPHA_NODES`) and autocorrelation shape
//! ([`crate::reference::microsurface::Autocorrelation`]) a bank is traced once per process
//! (64 surfaces, `MaterialSpec::bank_rays` primary rays per incidence node; thinned to
//! `PATH_CAP` paths per node and order) and each material's tables are built from it: the
//! order-2 table when "double" is on, and the table of the orders beyond the enabled ones
//! (3..=8 with "double", 2..=8 without) when "multiple" is on; plus, per incidence node,
//! their albedos with the material's Fresnel and with `F = 1` (from perfect-conductor
//! tables), which the multiple term's depolarizing remainder and the diffuse layer need.
//! A material between two nodes takes the two nodes' tables interpolated in alpha along
//! the surface's small-slope similarity ([`similar::mix`]: `M00` read at the angles with
//! the same `cot(theta) / alpha` and mixed in `ln M00`, the normalized elements mixed at
//! the actual angles; the per-incidence albedos with `F = 1` and of order 1 read the same
//! way, [`similar::mix_nodes`]), and the albedos of the mixed tables (so the energy balance
//! holds at any alpha). The nodes below 0.3 are denser: there orders >= 2 live toward
//! grazing incidence in lobes that move with alpha.
//!
//! Both caches (banks, node tables) live for the process, and banks are also kept on disk
//! ([`super::bank::cache`]) in the directory [`cache_dir`] names, so that a new process
//! reads a bank instead of tracing it; a new index `eta` at a cached node costs only its
//! tables (about a second), a new node its bank (tens of seconds to minutes on 2 cores at
//! the default rays, with a progress line on stderr: [`super::bank::progress`]) the first
//! time on a machine.
//!
//! The cache directory: [`set_cache_dir`], else the environment variable
//! `PPRENDER_CACHE_DIR` (empty or `off`: no disk cache), else `$XDG_CACHE_HOME/pprender`,
//! else `$HOME/.cache/pprender` (`%LOCALAPPDATA%\pprender\cache` on Windows). The crate's
//! own tests ignore the environment and keep banks in memory only unless a test sets a
//! directory.

use super::bank::coherent::CoherentTable;
use super::bank::progress::Reporter;
use super::bank::{
    cache, log_mix, BankSpec, OrderTable, PathBank, MAX_ORDER, MIX_FLOOR, N_THETA, THETA_STEP,
};
use crate::optics::frames::{beam_bases, change_bases, Frame, V3};
use crate::optics::fresnel::Eta;
use crate::optics::mueller::Mat4;
use crate::reference::microsurface::Autocorrelation;
use crate::{Error, Result};
use std::collections::HashMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

pub mod similar;

/// The roughness nodes of the path banks (Beckmann alpha).
pub const ALPHA_NODES: [f64; 14] = [
    0.05, 0.075, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0,
];
/// Paths kept per incidence node and order ([`PathBank::thin`]).
pub const PATH_CAP: usize = 300_000;
/// Banks kept in memory at once (each up to a few hundred MB).
const BANKS_KEPT: usize = 2;
/// Surfaces per bank.
const SURFACES: u32 = 64;

/// What the material asks of one node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct NodeKey {
    node: usize,
    rays: u64,
    shape: Autocorrelation,
    /// `(re, im)` bits, or `None` for a perfect conductor.
    eta: Option<(u64, u64)>,
    double: bool,
    multiple: bool,
}

/// One node's tables for one material.
#[derive(Debug)]
struct NodeTables {
    double: Option<OrderTable>,
    rest: Option<OrderTable>,
    /// Per incidence node: albedo of `double`, `rest` with the material's Fresnel.
    fresnel: [Vec<f64>; 2],
    /// The same with `F = 1`.
    white: [Vec<f64>; 2],
    /// Per incidence node, the bank's order-1 albedo and its fraction still on the surface
    /// after [`MAX_ORDER`] reflections (`F = 1`, counted over all primary rays).
    order1: Vec<f64>,
    truncated: Vec<f64>,
    /// The coherent backscatter of `double` and `rest`, with the material's Fresnel.
    coherent: [Option<CoherentTable>; 2],
}

/// The banks kept, by `(node, rays, shape)`, oldest first.
type Banks = Mutex<Vec<((usize, u64, Autocorrelation), Arc<PathBank>)>>;

fn banks() -> &'static Banks {
    static B: OnceLock<Banks> = OnceLock::new();
    B.get_or_init(|| Mutex::new(Vec::new()))
}

fn tables() -> &'static Mutex<HashMap<NodeKey, Arc<NodeTables>>> {
    static T: OnceLock<Mutex<HashMap<NodeKey, Arc<NodeTables>>>> = OnceLock::new();
    T.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The disk cache's directory: `None` until first asked for (then resolved from the
/// environment), `Some(None)` when off.
static CACHE_DIR: Mutex<Option<Option<PathBuf>>> = Mutex::new(None);

/// The default cache directory from the environment variables `var` reads (module docs).
fn env_cache_dir(var: impl Fn(&str) -> Option<OsString>) -> Option<PathBuf> {
    let set = |k: &str| var(k).filter(|v| !v.is_empty());
    if let Some(v) = var("PPRENDER_CACHE_DIR") {
        if v.is_empty() || v.eq_ignore_ascii_case("off") {
            return None;
        }
        return Some(std::path::absolute(&v).unwrap_or_else(|_| PathBuf::from(v)));
    }
    if let Some(x) = set("XDG_CACHE_HOME").filter(|x| Path::new(x).is_absolute()) {
        return Some(PathBuf::from(x).join("pprender"));
    }
    if let Some(h) = set("HOME") {
        return Some(PathBuf::from(h).join(".cache").join("pprender"));
    }
    set("LOCALAPPDATA").map(|l| PathBuf::from(l).join("pprender").join("cache"))
}

/// Where path banks are cached on disk (module docs); `None`: in memory only.
pub fn cache_dir() -> Option<PathBuf> {
    let mut dir = CACHE_DIR.lock().unwrap_or_else(|e| e.into_inner());
    dir.get_or_insert_with(|| {
        if cfg!(test) {
            None
        } else {
            env_cache_dir(|k| std::env::var_os(k))
        }
    })
    .clone()
}

/// Set where path banks are cached on disk for the rest of the process (`None`: in memory
/// only). The directory is created when a bank is first written; a path that exists but
/// is not a directory, or an empty path, is refused, naming `cache_dir`.
pub fn set_cache_dir(dir: Option<PathBuf>) -> Result<()> {
    let dir = match dir {
        None => None,
        Some(d) => Some(check_cache_dir(&d)?),
    };
    *CACHE_DIR.lock().unwrap_or_else(|e| e.into_inner()) = Some(dir);
    Ok(())
}

/// `d` made absolute, if it can be a cache directory.
fn check_cache_dir(d: &Path) -> Result<PathBuf> {
    const RANGE: &str = "must be the path of a directory (created if missing), or None to keep \
                         path banks in memory only";
    if d.as_os_str().is_empty() {
        return Err(Error::param("cache_dir", "\"\"", RANGE));
    }
    let abs = std::path::absolute(d)
        .map_err(|e| Error::param("cache_dir", d.display(), format!("{e}")))?;
    if abs.exists() && !abs.is_dir() {
        return Err(Error::param(
            "cache_dir",
            format!("{:?}", d.display().to_string()),
            format!("exists and is not a directory: {RANGE}"),
        ));
    }
    Ok(abs)
}

/// The bank of alpha node `node` at `rays` rays per incidence node on surfaces of
/// autocorrelation `shape`.
fn bank_spec(node: usize, rays: u64, shape: Autocorrelation) -> BankSpec {
    BankSpec {
        autocorrelation: shape,
        alpha: ALPHA_NODES[node],
        grid: 256,
        correlation_length: 8.0,
        rays,
        surfaces: SURFACES.min(rays as u32),
        seed: 1,
    }
}

/// `spec`'s bank thinned to [`PATH_CAP`]: from the disk cache in `dir` when a valid entry is
/// there, else traced (with a progress line) and written there.
fn load_or_trace(dir: Option<&Path>, spec: &BankSpec) -> Result<PathBank> {
    cache::cached(dir, spec, PATH_CAP, || {
        let kept = match dir {
            Some(d) => format!("once per machine, kept in {}", d.display()),
            None => "disk cache off: once per process".to_string(),
        };
        let progress = Reporter::new(
            format!(
                "pprender: tracing the path bank for alpha {}: {N_THETA} incidence nodes x {} \
                 rays on {} surfaces ({kept})",
                spec.alpha, spec.rays, spec.surfaces
            ),
            format!("pprender: path bank alpha {}", spec.alpha),
        );
        let mut b =
            PathBank::trace_with_progress(spec, &|done, total| progress.update(done, total))?;
        progress.finish();
        b.thin(PATH_CAP);
        Ok(b)
    })
}

fn bank(node: usize, rays: u64, shape: Autocorrelation) -> Result<Arc<PathBank>> {
    let key = (node, rays, shape);
    // held while tracing: concurrent builders of the same bank wait for one trace
    let mut kept = banks().lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, b)) = kept.iter().find(|(k, _)| *k == key) {
        return Ok(b.clone());
    }
    let b = Arc::new(load_or_trace(
        cache_dir().as_deref(),
        &bank_spec(node, rays, shape),
    )?);
    if kept.len() >= BANKS_KEPT {
        kept.remove(0);
    }
    kept.push((key, b.clone()));
    Ok(b)
}

fn node_tables(key: NodeKey, eta: Eta) -> Result<Arc<NodeTables>> {
    if let Some(t) = tables().lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return Ok(t.clone());
    }
    let b = bank(key.node, key.rays, key.shape)?;
    let first_rest = if key.double { 3 } else { 2 };
    let build = |eta: Eta, on: bool, orders: std::ops::RangeInclusive<usize>| {
        on.then(|| OrderTable::build(&b, eta, orders))
    };
    let double = build(eta, key.double, 2..=2);
    let rest = build(eta, key.multiple, first_rest..=MAX_ORDER);
    let fresnel = [albedos(&double), albedos(&rest)];
    let coherent_of = |orders: std::ops::RangeInclusive<usize>| {
        let g = gamma(&b, key, orders.clone());
        CoherentTable::build_with(&b, eta, orders, Some(&g))
    };
    let coherent = [
        key.double.then(|| coherent_of(2..=2)),
        key.multiple.then(|| coherent_of(first_rest..=MAX_ORDER)),
    ];
    let white = if key.eta.is_none() {
        fresnel.clone()
    } else {
        let wd = build(Eta::PerfectConductor, key.double, 2..=2);
        let wr = build(Eta::PerfectConductor, key.multiple, first_rest..=MAX_ORDER);
        [albedos(&wd), albedos(&wr)]
    };
    let t = Arc::new(NodeTables {
        double,
        rest,
        fresnel,
        white,
        order1: b.albedo.iter().map(|a| a[0]).collect(),
        truncated: b.truncated.clone(),
        coherent,
    });
    tables()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(key, t.clone());
    Ok(t)
}

/// The coherent-backscatter `gamma` table of a bank's orders (the same for every material:
/// [`CoherentTable`]), computed once per process.
fn gamma(b: &PathBank, node: NodeKey, orders: std::ops::RangeInclusive<usize>) -> Arc<Vec<f64>> {
    type Gammas = Mutex<HashMap<(usize, u64, Autocorrelation, usize), Arc<Vec<f64>>>>;
    static G: OnceLock<Gammas> = OnceLock::new();
    let key = (node.node, node.rays, node.shape, *orders.start());
    let cache = G.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(g) = cache.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return g.clone();
    }
    let g = Arc::new(CoherentTable::build(b, Eta::PerfectConductor, orders).gamma);
    cache
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(key, g.clone());
    g
}

/// A table's albedo at each incidence node (zeros without the table).
fn albedos(t: &Option<OrderTable>) -> Vec<f64> {
    match t {
        Some(t) => (0..N_THETA).map(|i| t.interpolated_albedo(i)).collect(),
        None => vec![0.0; N_THETA],
    }
}

/// The orders >= 2 of one material (module docs).
#[derive(Debug, Clone)]
pub struct SurfaceOrders {
    /// Order 2 (with "double").
    pub double: Option<OrderTable>,
    /// The orders beyond the enabled ones (with "multiple").
    pub rest: Option<OrderTable>,
    fresnel: [Vec<f64>; 2],
    white: [Vec<f64>; 2],
    /// Per incidence node, the bank's order-1 albedo and truncated fraction (`F = 1`),
    /// linear in alpha between the nodes.
    order1: Vec<f64>,
    truncated: Vec<f64>,
    /// The coherent backscatter of `double` and `rest` ([`CoherentTable`]).
    coherent: [Option<CoherentTable>; 2],
}

/// Which part's albedo.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    Double = 0,
    Rest = 1,
}

impl SurfaceOrders {
    /// The tables of a Beckmann material of roughness `alpha` and index `eta` on surfaces
    /// of autocorrelation `shape` (module docs). `alpha` must lie within the nodes.
    pub fn new(
        alpha: f64,
        eta: Eta,
        double: bool,
        multiple: bool,
        rays: u64,
        shape: Autocorrelation,
    ) -> Result<Self> {
        let (lo, hi) = (ALPHA_NODES[0], ALPHA_NODES[ALPHA_NODES.len() - 1]);
        if !(alpha >= lo && alpha <= hi) {
            return Err(Error::param(
                "alpha",
                alpha,
                format!(
                    "orders=\"surface\" has path banks for Beckmann alpha in [{lo}, {hi}] \
                     (below {lo}, orders >= 2 exist only within about 10 deg of grazing, finer \
                     than the tables' 2.5 deg incidence nodes; use orders=\"seed\")"
                ),
            ));
        }
        if !(1_000..=1u64 << 32).contains(&rays) {
            return Err(Error::param("bank_rays", rays, "must be in [1000, 2^32]"));
        }
        let k = ALPHA_NODES
            .iter()
            .position(|&a| a >= alpha)
            .unwrap_or(ALPHA_NODES.len() - 1);
        let k0 = if ALPHA_NODES[k] == alpha || k == 0 {
            k
        } else {
            k - 1
        };
        let (a_lo, a_hi) = (
            ALPHA_NODES[k0],
            ALPHA_NODES[(k0 + 1).min(ALPHA_NODES.len() - 1)],
        );
        let w = if k0 == k {
            0.0
        } else {
            similar::weight(a_lo, a_hi, alpha)
        };
        let eta_key = match eta {
            Eta::PerfectConductor => None,
            Eta::Complex(e) => Some((e.re.to_bits(), e.im.to_bits())),
        };
        let key = |node| NodeKey {
            node,
            rays,
            shape,
            eta: eta_key,
            double,
            multiple,
        };
        let a = node_tables(key(k0), eta)?;
        if w == 0.0 {
            return Ok(SurfaceOrders {
                double: a.double.clone(),
                rest: a.rest.clone(),
                fresnel: a.fresnel.clone(),
                white: a.white.clone(),
                order1: a.order1.clone(),
                truncated: a.truncated.clone(),
                coherent: a.coherent.clone(),
            });
        }
        let b = node_tables(key(k0 + 1), eta)?;
        let mix_t = |x: &Option<OrderTable>, y: &Option<OrderTable>| match (x, y) {
            (Some(x), Some(y)) => Some(similar::mix(x, y, a_lo, a_hi, alpha)),
            _ => None,
        };
        let (double, rest) = (mix_t(&a.double, &b.double), mix_t(&a.rest, &b.rest));
        // the albedos of the mixed tables themselves (so that the energy balance holds at
        // any alpha); with F = 1 from the perfect conductor's tables, which a material
        // with another index does not hold: those are mixed like the tables' M00, in
        // ln(A + eps)
        let fresnel = [albedos(&double), albedos(&rest)];
        let white = if eta_key.is_none() {
            fresnel.clone()
        } else {
            [0, 1].map(|p| {
                let peak = a.white[p]
                    .iter()
                    .chain(&b.white[p])
                    .fold(0.0f64, |m, &x| m.max(x));
                let eps = MIX_FLOOR * peak;
                similar::mix_nodes(&a.white[p], &b.white[p], a_lo, a_hi, alpha, |u, v, w| {
                    log_mix(u, v, w, eps)
                })
            })
        };
        let lin = |x: &[f64], y: &[f64]| -> Vec<f64> {
            similar::mix_nodes(x, y, a_lo, a_hi, alpha, |u, v, w| (1.0 - w) * u + w * v)
        };
        let coherent = [0, 1].map(|p| match (&a.coherent[p], &b.coherent[p]) {
            (Some(x), Some(y)) => Some(x.mix(y, w)),
            _ => None,
        });
        Ok(SurfaceOrders {
            double,
            rest,
            fresnel,
            white,
            order1: lin(&a.order1, &b.order1),
            truncated: lin(&a.truncated, &b.truncated),
            coherent,
        })
    }

    /// The white (`F = 1`) albedo the single term is calibrated to at incidence node `k`
    /// ([`crate::brdf::calibration::calibrate_masking`]): with the multiple term, what
    /// the banks' orders (with `F = 1`, as their tables hold them) and the fraction past
    /// [`MAX_ORDER`] leave of the incident light, so that the depolarizing remainder carries
    /// only that fraction; without it, the bank's counted order-1 albedo.
    pub fn order1_target(&self, k: usize) -> f64 {
        if self.rest.is_some() {
            1.0 - self.white[0][k] - self.white[1][k] - self.truncated[k]
        } else {
            self.order1[k]
        }
    }

    /// What the depolarizing remainder carries once the single term is calibrated
    /// ([`Self::order1_target`]): the fraction of the light past [`MAX_ORDER`] at incidence
    /// cosine `c` (`F = 1`), Catmull-Rom in `theta` between the incidence nodes (held beyond
    /// the last), at least 0. Smooth: the energy balance between the nodes is the single
    /// term's to close ([`crate::brdf::calibration::calibrate_masking`]'s fine stage), not
    /// this, which would carry the banks' interpolation error between their nodes
    /// (periodic in `theta`, up to 5-60 times the truncation itself).
    pub fn remainder(&self, c: f64) -> f64 {
        let u = c.clamp(-1.0, 1.0).acos() / THETA_STEP;
        crate::microfacet::masking::catmull_rom_nodes(&self.truncated, u).max(0.0)
    }

    /// The white single albedo that the calibration of the single term aims at, at
    /// incidence `theta` (rad): with the remainder, what the banks' orders and the light
    /// past [`MAX_ORDER`] leave, as their tables interpolate them (the calibration's fine
    /// stage); without it, the bank's counted order 1, Catmull-Rom in `theta` between the
    /// incidence nodes (as its coarse stage interpolates `ln s`).
    pub fn calibration_target(&self, theta: f64) -> f64 {
        if self.rest.is_some() {
            let c = theta.cos();
            1.0 - self.orders_albedo(false, c) - self.remainder(c)
        } else {
            crate::microfacet::masking::catmull_rom_nodes(&self.order1, theta / THETA_STEP)
        }
    }

    /// The albedo of the banks' orders (both parts, as the tables interpolate them) at
    /// incidence cosine `c`, with the material's Fresnel or with `F = 1`.
    pub fn orders_albedo(&self, fresnel: bool, c: f64) -> f64 {
        self.albedo(Part::Double, fresnel, c) + self.albedo(Part::Rest, fresnel, c)
    }

    /// The bank's counted order-1 albedo (`F = 1`) at incidence node `k`.
    pub fn order1_counted(&self, k: usize) -> f64 {
        self.order1[k]
    }

    /// The albedo of `part` at incidence cosine `c` (unpolarized), with the material's
    /// Fresnel or with `F = 1`: linear in `theta` between the incidence nodes, as the
    /// tables are (constant beyond the last node).
    pub fn albedo(&self, part: Part, fresnel: bool, c: f64) -> f64 {
        let a = if fresnel { &self.fresnel } else { &self.white };
        let v = &a[match part {
            Part::Double => 0,
            Part::Rest => 1,
        }];
        let t = c.clamp(-1.0, 1.0).acos() / THETA_STEP;
        let t = t.clamp(0.0, (N_THETA - 1) as f64);
        let k = (t.floor() as usize).min(N_THETA - 2);
        let f = t - k as f64;
        (1.0 - f) * v[k] + f * v[k + 1]
    }

    /// `part`'s coherent-backscatter decorrelation `gamma(q)` at `(wi, wo)`
    /// ([`CoherentTable`]; `wavelength` and the height correlation length `l` in one unit):
    /// 1 at exact backscatter, 0 far from it or when the part is not enabled.
    pub fn coherent_gamma(&self, part: Part, wi: V3, wo: V3, wavelength: f64, l: f64) -> f64 {
        self.coherent[part as usize]
            .as_ref()
            .and_then(|t| t.eval(wi, wo, wavelength, l))
            .map_or(0.0, |(g, _, _)| g)
    }

    /// `part`'s coherent-backscatter term (1/sr) at `(wi, wo)` in `frame`,
    /// `gamma(q) R M00` with `m00` the part's incoherent `M00` there ([`CoherentTable`]);
    /// `None` where it is 0.
    #[allow(clippy::too_many_arguments)]
    pub fn coherent(
        &self,
        part: Part,
        wi: V3,
        wo: V3,
        frame: Frame,
        wavelength: f64,
        l: f64,
        m00: f64,
    ) -> Option<Mat4> {
        let (g, r, bases) = self.coherent[part as usize]
            .as_ref()?
            .eval(wi, wo, wavelength, l)?;
        let s = g * m00;
        let m: Mat4 = r.map(|row| row.map(|x| s * x));
        Some(change_bases(&m, bases, beam_bases(frame, wi, wo)))
    }

    /// `part`'s Mueller BRDF (1/sr) in `frame`; zero when the part is not enabled.
    pub fn eval(&self, part: Part, wi: V3, wo: V3, frame: Frame) -> Mat4 {
        let t = match part {
            Part::Double => &self.double,
            Part::Rest => &self.rest,
        };
        match t {
            Some(t) => t.eval(wi, wo, frame),
            None => [[0.0; 4]; 4],
        }
    }
}

#[cfg(test)]
mod tests;
