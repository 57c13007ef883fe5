//! The f64 CPU renderers: the backend of `Lidar(arithmetic="f64")` ([`render_tables`]:
//! the kernels' algorithm with the GPU's BRDF tables) and the exact reference of
//! `quality="reference"` ([`render_reference`]: every material evaluated by the core), both
//! through [`render_supersampled`] and [`render_cpu`].
//!
//! CPU twins of the kernels, in f64: `visibility` (of `shaders/visibility.wgsl`) by
//! rasterizing pixel centres exactly, `shade_pixel` and `render_cpu` (of
//! `shaders/shade.wgsl`) with any BRDF: the material's tables (what the GPU uses) or the
//! exact core evaluation ([`Brdf`]). With the core, the Stokes bases come from
//! [`crate::optics::frames`]'s `beam_bases` in a local frame (the kernel builds them from
//! cross products), so comparing the two checks the frame handling; with the tables
//! ([`Tables`]) the twin looks them up as the kernel does, and a test checks that against
//! [`crate::brdf::table::BrdfTable::eval_dirs`] and `change_bases`. Transmitter cast
//! shadows (bistatic) are decided here by exact ray casting in f64 ([`shadowed`]),
//! independently of the kernel's shadow-map rule. Conventions: [`crate::render`].
//!
//! The files, in the order a pixel runs through them:
//! - `raster.rs`: the triangle seen at each visibility sample ([`visibility_at`],
//!   [`rasterize`]);
//! - `coverage.rs`: a pixel's parts, from its samples ([`sampled_parts`]) or by analytic
//!   coverage ([`analytic_parts`], [`coverage_parts`]);
//! - `shade.rs`: a part shaded ([`Brdf`], [`Tables`], [`shade_point`]);
//! - `shadow.rs`: bistatic cast shadows ([`TransmitterView`], [`shadowed`]);
//! - `accumulate.rs`: the parts' sums per pixel, the profile's bins, the totals;
//! - here: the renderers and the memory checks ([`check_cpu_render`]).

mod accumulate;
pub(crate) mod coverage;
mod raster;
mod shade;
mod shadow;

pub use coverage::{
    analytic_parts, analytic_seeds, coverage_parts, sampled_parts, sampled_parts_into, thin_parts,
    Part,
};
pub use raster::{
    project, project_rotated, rasterize, rotate_vertices, visibility, visibility_at, Projected,
};
pub(crate) use shade::{double_angle, telescope_values};
pub use shade::{shade_pixel, shade_point, Brdf, Framed, PixelSample, Tables};
pub use shadow::{shadowed, TransmitterView};

use super::api::{Layout, Outputs, Progress, Rendered, SensorSetup};
use super::geometry::{Mesh, Rot};
use super::thin::{mesh_thinness, ThinPixels};
use crate::brdf::table::BrdfTable;
use crate::optics::frames::{Frame, V3};
use accumulate::{Accumulator, PixelAcc};
use rayon::prelude::*;
use shade::{shade_at, Beam};
use std::ops::Range;

/// Working memory of the CPU renderers (the twin and the reference) for attitudes
/// rendered in parallel; fewer run at a time when theirs would exceed it.
pub const CPU_MEMORY_BUDGET: usize = 4 << 30;

/// Row blocks of one attitude whose accumulators are held at once: they are rendered
/// (in parallel) in groups of this many and added in order to the attitude's sums, so a
/// profile with many bins does not cost a copy per block of the whole image.
pub const BLOCKS_AT_ONCE: usize = 32;

/// Bytes one attitude of [`render_cpu`] holds at its peak: the K sample id maps, one depth
/// map while they are drawn, the requested per-pixel outputs and profile, and the
/// profiles and pulse-weight scratch of the row blocks held at once ([`BLOCKS_AT_ONCE`]);
/// with `area` (the `"illuminated_area"` output, [`accumulate::area`]) also its second
/// moment per bin, and each block's moment and point scratch.
pub fn attitude_bytes(
    width: usize,
    samples: usize,
    channels: usize,
    n_bins: usize,
    outputs: Outputs,
    area: bool,
) -> usize {
    let px = width * width;
    let mut b = px * (4 * samples + 8) + output_bytes(width, channels, n_bins, outputs, area);
    let blocks = width.div_ceil(ROWS_PER_BLOCK).min(BLOCKS_AT_ONCE);
    let profile_channels = if outputs.profile { channels } else { 0 };
    let area_arrays = if area { 2 } else { 0 };
    b += blocks * (profile_channels + 1 + area_arrays) * n_bins * 8;
    b
}

/// Bytes of one attitude's requested outputs as [`render_cpu`] returns them (`area`: the
/// illuminated area's moment per bin as well).
fn output_bytes(
    width: usize,
    channels: usize,
    n_bins: usize,
    outputs: Outputs,
    area: bool,
) -> usize {
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
    if area {
        b += n_bins * 8;
    }
    b
}

/// Peak memory (bytes) of a CPU render of `n` attitudes: the attitudes rendered at once
/// ([`attitude_bytes`], [`attitudes_at_once`]) and every attitude's outputs, twice (the
/// per-attitude results and the batch arrays they are gathered into).
pub fn render_bytes(mesh: &Mesh, sensor: &SensorSetup, n: usize, outputs: Outputs) -> usize {
    let lay = Layout::new(mesh, sensor);
    let (w, ch) = (lay.width, sensor.channels());
    let area = accumulate::area(sensor, outputs);
    let one = attitude_bytes(w, sensor.samples, ch, lay.n_bins, outputs, area);
    let at_once = attitudes_at_once(one, rayon::current_num_threads()).min(n);
    at_once
        .saturating_mul(one)
        .saturating_add(n.saturating_mul(2 * output_bytes(w, ch, lay.n_bins, outputs, area)))
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

/// One attitude's rotated vertices, visibility samples' id maps, transmitter's view
/// (bistatic) and pixels with thin faces.
type Prepared = (Vec<V3>, Vec<Vec<u32>>, Option<TransmitterView>, ThinPixels);

/// The whole renderer on the CPU in f64 (twin of `gpu::render`, without supersampling
/// of the image outputs: `sensor.supersampling` must be 1).
pub fn render_cpu(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl Brdf + ?Sized),
) -> Rendered {
    render_cpu_with_progress(mesh, sensor, rotations, outputs, brdf, None)
        .expect("without a progress callback nothing cancels")
}

/// [`render_cpu`], reporting to `progress` after each attitude (from the worker threads) and
/// stopping when it returns `false`: the attitudes not yet started are skipped.
pub fn render_cpu_with_progress(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl Brdf + ?Sized),
    progress: Progress,
) -> crate::Result<Rendered> {
    render_pixels(mesh, sensor, rotations, outputs, brdf, progress, false)
}

/// The pixels with thin faces alone ([`ThinPixels`], `K > 1` samples), as [`render_cpu`]
/// renders them; every other pixel is left empty. `gpu::render` leaves exactly these
/// empty, and [`add_thin_pixels`] adds them to its result. `progress` as in
/// [`render_cpu_with_progress`].
pub fn render_thin_pixels(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl Brdf + ?Sized),
    progress: Progress,
) -> crate::Result<Rendered> {
    render_pixels(mesh, sensor, rotations, outputs, brdf, progress, true)
}

/// The pixels with thin faces of a `K > 1` render by `gpu::render` (which leaves them
/// empty: the same clipping in a kernel of its own was many times slower on lavapipe than
/// this f64 code), shaded on the CPU by
/// [`render_thin_pixels`] with `brdf` (the f64 originals of the device's tables,
/// [`Tables`]) and added to `r`: their images (summed into the sensor's pixels with
/// supersampling), ranges and coverage (merged with the device's covered sub-pixels by
/// coverage weights), profiles and totals. Nothing to do with one sample per pixel or
/// analytic coverage (the kernel takes them itself).
///
/// `progress`, the device pass's callback, is told `(n, n)` (`n` attitudes, all counted by
/// the device pass already) after each attitude of this pass, so that a render can still
/// be stopped during it: `false` returns [`crate::Error::Cancelled`], and `r` is then
/// incomplete.
pub fn add_thin_pixels(
    r: &mut Rendered,
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl Brdf + ?Sized),
    progress: Progress,
) -> crate::Result<()> {
    if sensor.samples <= 1 || sensor.analytic {
        return Ok(());
    }
    let n = rotations.len();
    let heartbeat = |_: usize, _: usize| progress.is_none_or(|p| p(n, n));
    let thin_progress: Progress =
        progress.map(|_| &heartbeat as &(dyn Fn(usize, usize) -> bool + Sync));
    let ss = sensor.supersampling;
    let mut inner = sensor.clone();
    inner.resolution *= ss;
    inner.supersampling = 1;
    let (res, w, ch) = (sensor.resolution, inner.resolution, r.channels);
    let n_prof = r.n_bins * ch;
    // in chunks of attitudes, so that the thin pass holds at most THIN_BYTES of outputs and
    // working memory (and at most THIN_CHUNK attitudes) beside the device's result
    let per = attitude_bytes(
        w,
        inner.samples,
        ch,
        r.n_bins,
        outputs,
        accumulate::area(&inner, outputs),
    );
    let chunk = (THIN_BYTES / per.max(1)).clamp(1, THIN_CHUNK);
    for (ci, rots) in rotations.chunks(chunk).enumerate() {
        let first = ci * chunk;
        let t = render_thin_pixels(mesh, &inner, rots, outputs, brdf, thin_progress)?;
        for (a, b) in r.total[first * ch..].iter_mut().zip(&t.total) {
            *a += b;
        }
        if let (Some(p), Some(tp)) = (r.profile.as_mut(), t.profile.as_ref()) {
            for (a, b) in p[first * n_prof..].iter_mut().zip(tp) {
                *a += b;
            }
        }
        if let (Some(q), Some(tq)) = (r.area_moment.as_mut(), t.area_moment.as_ref()) {
            for (a, b) in q[first * r.n_bins..].iter_mut().zip(tq) {
                *a += b;
            }
        }
        // output pixel of the chunk's attitude l's sub-pixel q
        let out_of =
            |l: usize, q: usize| (first + l) * res * res + (q / w / ss) * res + (q % w) / ss;
        if let (Some(im), Some(ti)) = (r.image.as_mut(), t.image.as_ref()) {
            for (k, v) in ti.chunks(ch).enumerate() {
                // (only where the thin pass has a value: the device's other pixels keep
                // their bits)
                if v.iter().any(|&x| x != 0.0) {
                    let o = out_of(k / (w * w), k % (w * w));
                    for (a, b) in im[o * ch..(o + 1) * ch].iter_mut().zip(v) {
                        *a += b;
                    }
                }
            }
        }
        if let (Some(rg), Some(cv), Some(tr), Some(tc)) = (
            r.range.as_mut(),
            r.coverage.as_mut(),
            t.range.as_ref(),
            t.coverage.as_ref(),
        ) {
            // per output pixel: the device's covered fraction and range sum, then the thin
            // sub-pixels' (both as sub-pixel areas: the device's coverage is the mean over
            // its ss^2 sub-pixels, with none from the thin ones)
            let n_sub = (ss * ss) as f64;
            let mut sums: std::collections::BTreeMap<usize, (f64, f64)> = Default::default();
            for (k, (&f, &rr)) in tc.iter().zip(tr).enumerate() {
                if f > 0.0 && !rr.is_nan() {
                    let e = sums.entry(out_of(k / (w * w), k % (w * w))).or_default();
                    e.0 += f as f64;
                    e.1 += f as f64 * rr as f64;
                }
            }
            for (o, (f, s)) in sums {
                let f_dev = cv[o] as f64 * n_sub;
                let s_dev = if f_dev > 0.0 {
                    rg[o] as f64 * f_dev
                } else {
                    0.0
                };
                rg[o] = ((s_dev + s) / (f_dev + f)) as f32;
                cv[o] = ((f_dev + f) / n_sub) as f32;
            }
        }
    }
    Ok(())
}

/// The most attitudes per pass of [`add_thin_pixels`].
const THIN_CHUNK: usize = 64;

/// The most memory one pass of [`add_thin_pixels`] holds ([`attitude_bytes`] per attitude;
/// one attitude at least).
const THIN_BYTES: usize = 256 << 20;

/// Whether each pixel of an image `width` pixels across (the renderer's framing, `[-ext,
/// ext]` with `ext` the mesh's radius) has a thin face at attitude `rot` ([`ThinPixels`];
/// `thinness` from [`mesh_thinness`]), row-major.
pub fn thin_pixel_mask(mesh: &Mesh, thinness: &[[f64; 4]], rot: &Rot, width: usize) -> Vec<bool> {
    let ext = mesh.radius;
    let lay = Layout {
        ext,
        width,
        pix: 2.0 * ext / width as f64,
        r_min: 0.0,
        n_bins: 0,
        max_extent: 0.0,
        support: 0.0,
    };
    let thin = ThinPixels::new(mesh, thinness, rot, &rotate_vertices(mesh, rot), &lay);
    let mut mask = vec![false; width * width];
    for (k, _) in thin.iter() {
        mask[k] = true;
    }
    mask
}

#[allow(clippy::too_many_arguments)]
fn render_pixels(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl Brdf + ?Sized),
    progress: Progress,
    thin_only: bool,
) -> crate::Result<Rendered> {
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
    // thin parts take exact coverage with K > 1 samples and with analytic coverage
    let thinness = (sensor.samples > 1 || sensor.analytic).then(|| mesh_thinness(mesh));
    // per attitude: the rotated vertices, the visibility samples' id maps (in parallel
    // when the attitudes are not), the transmitter's view (bistatic) and the pixels with
    // thin faces
    let prepare = |rot: &Rot, in_parallel: bool| {
        let vertices = rotate_vertices(mesh, rot);
        let thin = thinness
            .map(|a| {
                if sensor.analytic {
                    ThinPixels::with_outlines(mesh, a, rot, &vertices, &lay)
                } else {
                    ThinPixels::new(mesh, a, rot, &vertices, &lay)
                }
            })
            .unwrap_or_default();
        if thin_only && thin.is_empty() {
            // nothing to shade: no raster
            return (vertices, vec![], None, thin);
        }
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
        (vertices, ids, tx, thin)
    };
    // shade the pixels of rows `rows` of an attitude
    let shade_rows = |rot: &Rot, (vertices, ids, tx, thin): &Prepared, rows: &Range<usize>| {
        let mut acc = Accumulator::new(sensor, &lay, outputs, rows.start * w..rows.end * w);
        let mut parts: Vec<Part> = Vec::with_capacity(sensor.samples);
        for k in rows.start * w..rows.end * w {
            // a pixel none of whose samples sees the mesh adds nothing (analytic coverage
            // also looks at the neighbours' centres), unless a thin face overlaps it
            let thin_faces = thin.faces_at(k);
            if thin_only && thin_faces.is_empty() {
                continue;
            }
            if !sensor.analytic && thin_faces.is_empty() && ids.iter().all(|s_ids| s_ids[k] == 0) {
                continue;
            }
            let (row, col) = (k / w, k % w);
            if sensor.analytic {
                parts = analytic_parts(mesh, vertices, &lay, &ids[0], row, col, thin_faces);
            } else if let Some(p) = (!thin_faces.is_empty())
                .then(|| thin_parts(mesh, vertices, &lay, ids, k, thin_faces))
                .flatten()
            {
                parts = p;
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
    let render_one_attitude = |rot: &Rot, in_parallel: bool| {
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
    let n_done = std::sync::atomic::AtomicUsize::new(0);
    let cancelled = std::sync::atomic::AtomicBool::new(false);
    let render_one = |rot: &Rot, in_parallel: bool| {
        use std::sync::atomic::Ordering::Relaxed;
        if cancelled.load(Relaxed) {
            return Default::default();
        }
        let out = render_one_attitude(rot, in_parallel);
        if let Some(report) = progress {
            if !report(n_done.fetch_add(1, Relaxed) + 1, rotations.len()) {
                cancelled.store(true, Relaxed);
            }
        }
        out
    };
    // attitudes in parallel when there are enough of them and that many fit the memory
    // budget; otherwise at most as many at a time as fit, each one's visibility samples
    // and row blocks in parallel
    let threads = rayon::current_num_threads();
    let one = attitude_bytes(
        w,
        sensor.samples,
        ch,
        nb,
        outputs,
        accumulate::area(sensor, outputs),
    );
    let at_once = attitudes_at_once(one, threads);
    #[allow(clippy::type_complexity)]
    let per: Vec<(Vec<f32>, Vec<f32>, Vec<f64>, Vec<f64>, Vec<f32>, Vec<f64>)> =
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
    if cancelled.into_inner() {
        return Err(crate::Error::Cancelled);
    }
    let n = rotations.len();
    let cov: Vec<f32> = per.iter().flat_map(|p| p.4.iter().copied()).collect();
    Ok(Rendered {
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
        area_moment: accumulate::area(sensor, outputs)
            .then(|| per.iter().flat_map(|p| p.5.iter().copied()).collect()),
        r_min: lay.r_min,
        bin_width: sensor.bin_width,
        n_bins: nb,
        pixel_size: lay.pix,
        extent: lay.ext,
        bounce_image: None,
        bounce_profile: None,
        bounce_total: Vec::new(),
        stage_seconds: Vec::new(),
    })
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
    progress: Progress,
) -> crate::Result<Rendered> {
    let brdf = |m: usize, wi: V3, wo: V3| crate::brdf::eval(&materials[m], wi, wo, Frame::Sp);
    render_supersampled_with_progress(mesh, sensor, rotations, outputs, &brdf, progress)
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
    progress: Progress,
) -> crate::Result<Rendered> {
    render_supersampled_with_progress(mesh, sensor, rotations, outputs, &Tables(tables), progress)
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
    render_supersampled_with_progress(mesh, sensor, rotations, outputs, brdf, None)
        .expect("without a progress callback nothing cancels")
}

/// [`render_supersampled`] with a progress callback ([`render_cpu_with_progress`]).
pub fn render_supersampled_with_progress(
    mesh: &Mesh,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    brdf: &(impl Brdf + ?Sized),
    progress: Progress,
) -> crate::Result<Rendered> {
    let mut r = render_cpu_with_progress(mesh, sensor, rotations, outputs, brdf, progress)?;
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
            super::downsample::downsample_range(rng, &c0, 1, 0, n, w, ss, &mut out, &mut cov);
            *rng = out;
            r.coverage = Some(cov);
        }
        r.height = res;
        r.width = res;
        r.pixel_size *= ss as f64;
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

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
        let b = attitude_bytes(128, 8, 16, 100, all, false);
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
            attitude_bytes(128, 8, 16, 100, profile_only, false),
            128 * 128 * 40 + 100 * 16 * 8 + 16 * 8 + blocks
        );
        // many bins at the largest side: the blocks held at once are BLOCKS_AT_ONCE, not
        // all 1024 of them
        assert_eq!(
            attitude_bytes(8192, 1, 1, 65536, profile_only, false),
            8192 * 8192 * 12 + 65536 * 8 + 8 + BLOCKS_AT_ONCE * 65536 * 16
        );
        // the illuminated area: its moment per bin in the output, and each block's moment
        // and point scratch
        assert_eq!(
            attitude_bytes(128, 8, 16, 100, profile_only, true),
            128 * 128 * 40 + 100 * 16 * 8 + 16 * 8 + 100 * 8 + blocks + 16 * 2 * 100 * 8
        );
        // the largest image side at 16 samples (8192^2 x 144 bytes, 9.7 GB): one at a time
        let big = attitude_bytes(8192, 16, 16, 1000, all, false);
        assert!(big > CPU_MEMORY_BUDGET);
        assert_eq!(attitudes_at_once(big, 16), 1);
        // in between: as many as fit
        assert_eq!(attitudes_at_once(CPU_MEMORY_BUDGET / 3 + 1, 16), 2);
        assert_eq!(attitudes_at_once(1, 0), 1);
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
}
