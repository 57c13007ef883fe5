//! The wgpu side of the renderer: adapter choice, pipelines, chunked batch rendering.
//!
//! Per chunk of attitudes: render passes rasterize triangle indices into one layer of an
//! R32Uint texture array per attitude and visibility sample, a pass drawing one layer
//! (`shaders/visibility.wgsl`) or, on devices with multiview, up to 31 consecutive layers
//! (`shaders/visibility_views.wgsl`, the same arithmetic per layer; `Gpu`'s
//! `raster_views`); with `K >= 4` samples, one 4x multisampled render pass per attitude into fixed tiles,
//! gathered by `shaders/gather.wgsl` into a buffer: `targets::MsaaTiles`), then one compute
//! dispatch (`shaders/shade.wgsl`, specialized by override constants to the requested
//! outputs) shades every pixel and accumulates the profile and total in 64-bit fixed point.
//! Only the requested buffers are created and read back. Bistatic (`beta > 0`) the same
//! raster pipeline first draws each attitude from the transmitter too (rotations
//! [`transmitter_rotation`](crate::render::geometry::transmitter_rotation)) into a second
//! texture array, which the shade kernel (compiled with `SHADOWS`) reads to test cast
//! shadows; monostatic neither the pass nor the test exists. Conventions: [`crate::render`].
//!
//! The files, in the order a render runs through them:
//! - `util.rs`: the device error, the error scopes around a render, buffer creation;
//! - `device.rs`: the adapter and device ([`DeviceChoice`], [`context`], [`Gpu`]);
//! - `pipelines.rs`: the pipelines a device compiles once (visibility, gather, the shade
//!   kernel per key of override constants);
//! - `plan.rs`: what the kernel computes ([`KernelOutputs`]), the device-limit checks, the
//!   chunk size and fixed-point scale;
//! - `pack.rs`: every byte layout the kernels read (geometry, [`GpuTables`],
//!   [`ShadeParams`] and the other uniform blocks);
//! - `passes.rs` and `targets.rs`: the raster targets, the bind groups and the passes
//!   encoded per chunk;
//! - `readback.rs`: the output buffers, mapping, fixed-point decoding, the sampled pulse's
//!   host profile ([`host_profile`]) and downsampling.
//!
//! The sample pattern ([`crate::render::samples`]) and the downsampling
//! ([`crate::render::downsample`]) are shared with the CPU renderers; the comparisons of
//! this backend with them are in `src/render/compare_gpu_cpu.rs`.

mod device;
mod pack;
mod passes;
mod pipelines;
mod plan;
pub mod raycast;
mod readback;
mod targets;
mod util;

pub use device::{context, DeviceChoice, DeviceInfo, Gpu};
pub use pack::{
    GpuTables, InKernel, PartRef, ShadeParams, HEADER_WORDS, MAX_PARTS, SHADER_PART,
    SHADER_PART_MARGIN,
};
pub use plan::{transmitter_map_width, KernelOutputs};
pub use readback::host_profile;

use super::api::{Layout, Outputs, Progress, Rendered, SensorSetup};
use super::geometry::{Mesh, Rot};
use super::thin;
use crate::error::Result;
use passes::{encode_chunk, shade_key, ChunkBindings, SceneBuffers};
use plan::Plan;
use readback::{HostOutputs, ResultBuffers};
use std::time::Instant;
use targets::Targets;

/// Refuse an empty batch of attitudes.
pub fn check_batch(rotations: &[Rot]) -> Result<()> {
    if rotations.is_empty() {
        return Err(crate::Error::param(
            "attitudes",
            "an empty batch (N = 0)",
            "at least one attitude",
        ));
    }
    Ok(())
}

/// Render a batch of attitudes (rotations) of `mesh` with the packed tables. With `K > 1`
/// samples (not analytic coverage) the pixels with thin faces ([`thin::ThinPixels`]) are
/// left empty: [`crate::render::cpu::add_thin_pixels`] shades them on the CPU and adds
/// them (as [`crate::render::request::render`] does).
pub fn render(
    gpu: &Gpu,
    mesh: &Mesh,
    tables: &GpuTables,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
) -> Result<Rendered> {
    render_with_progress(gpu, mesh, tables, sensor, rotations, outputs, None)
}

/// [`render`], reporting to `progress` after each chunk of attitudes (and stopping when it
/// returns `false`).
pub fn render_with_progress(
    gpu: &Gpu,
    mesh: &Mesh,
    tables: &GpuTables,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    progress: Progress,
) -> Result<Rendered> {
    // an empty batch would make an empty chunk, and stepping by it panics
    check_batch(rotations)?;
    let t0 = Instant::now();
    let lay = Layout::new(mesh, sensor);
    lay.check_bins(sensor)?;
    plan::check_image(gpu, &lay, sensor, mesh.faces.len())?;
    let geometry = pack::geometry(mesh, sensor.analytic || sensor.samples > 1);
    let plan = Plan::new(
        gpu,
        &lay,
        sensor,
        tables,
        outputs,
        &geometry,
        mesh.faces.len(),
    )?;
    let params = ShadeParams::new(
        mesh,
        &lay,
        sensor,
        plan.fix_scale,
        plan.fix_area,
        plan.tx_width,
    );
    let fix_scale = params.fix_scale as f64; // what the kernel uses
    let planned = t0.elapsed().as_secs_f64();
    let mut r = util::error_scoped(&gpu.device, || {
        render_chunks(
            gpu, mesh, &geometry, tables, &params, fix_scale, &plan, &lay, sensor, rotations,
            outputs, progress,
        )
    })?;
    r.n = rotations.len();
    r.stage_seconds.insert(0, ("plan", planned));
    Ok(r)
}

/// The batch in chunks of [`Plan::chunk`] attitudes: the scene uploaded and the chunk's
/// buffers and targets made once, then per chunk its bind groups, its passes encoded
/// between clearing the sums and copying the results out, submitted, and read back
/// (the stages timed in [`Rendered::stage_seconds`]; waiting for the device is timed
/// apart from reading the results back).
#[allow(clippy::too_many_arguments)]
fn render_chunks(
    gpu: &Gpu,
    mesh: &Mesh,
    geometry: &[[f32; 4]],
    tables: &GpuTables,
    params: &ShadeParams,
    fix_scale: f64,
    plan: &Plan,
    lay: &Layout,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
    progress: Progress,
) -> Result<Rendered> {
    let dev = &gpu.device;
    let t0 = Instant::now();
    let n = rotations.len();
    let key = shade_key(plan, sensor, tables);
    let pipeline = gpu.pipelines.shade_pipeline(dev, key)?;
    let scene = SceneBuffers::new(dev, geometry, tables, params, lay, sensor.samples);
    let c = plan.chunk.min(n);
    let fix_area = params.fix_area as f64; // what the kernel uses
    let results = ResultBuffers::new(dev, plan, lay, sensor, c, fix_scale, fix_area);
    let targets = Targets::new(
        gpu,
        lay.width,
        sensor.samples,
        scene.passes(),
        c,
        key.shadows.then_some(params.tx_width),
    );
    let transmitter = key.shadows.then_some(sensor.bistatic_angle);
    let area = outputs.profile && sensor.illuminated_area;
    let mut host = HostOutputs::new(
        outputs,
        area,
        n,
        sensor.resolution,
        plan.channels,
        lay.n_bins,
    );
    // thin parts take exact coverage with K > 1 samples and with analytic coverage
    let thinness = (sensor.samples > 1 || sensor.analytic).then(|| thin::mesh_thinness(mesh));
    let setup = t0.elapsed().as_secs_f64();
    let (mut encoding, mut waiting, mut reading) = (0.0, 0.0, 0.0);
    for start in (0..n).step_by(c) {
        let m = (n - start).min(c);
        let rots = &rotations[start..start + m];
        let t = Instant::now();
        let thin_words = thin_words(mesh, thinness, sensor.analytic, rots, lay, gpu)?;
        let bindings = ChunkBindings::new(
            gpu,
            &scene,
            &targets,
            &results,
            rots,
            transmitter,
            &thin_words,
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        results.clear(&mut enc);
        encode_chunk(
            &mut enc,
            gpu,
            &targets,
            &bindings,
            &pipeline,
            m,
            params.n_tri,
            mesh.closed,
            lay.width,
        );
        results.copy_for_readback(&mut enc, m);
        gpu.queue.submit([enc.finish()]);
        encoding += t.elapsed().as_secs_f64();
        let t = Instant::now();
        dev.poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| util::device_error(format!("device poll failed: {e}")))?;
        waiting += t.elapsed().as_secs_f64();
        let t = Instant::now();
        results.read_chunk(dev, start, m, &mut host)?;
        reading += t.elapsed().as_secs_f64();
        if let Some(report) = progress {
            if !report(start + m, n) {
                return Err(crate::Error::Cancelled);
            }
        }
    }
    let mut r = host.into_rendered(plan.channels, lay, sensor);
    r.stage_seconds = vec![
        ("pipeline and buffers", setup),
        ("encode and submit", encoding),
        ("device", waiting),
        ("readback", reading),
    ];
    Ok(r)
}

/// The shade kernel's thin-pixel words of a chunk ([`thin::gpu_words`], found on the CPU
/// for each attitude in parallel; empty without `thinness` or without thin pixels).
fn thin_words(
    mesh: &Mesh,
    thinness: Option<&[[f64; 4]]>,
    outlines: bool,
    rots: &[Rot],
    lay: &Layout,
    gpu: &Gpu,
) -> Result<Vec<u32>> {
    use rayon::prelude::*;
    let Some(a) = thinness else {
        return Ok(Vec::new());
    };
    let per: Vec<thin::ThinPixels> = rots
        .par_iter()
        .map(|r| {
            let vertices = crate::render::cpu::rotate_vertices(mesh, r);
            if outlines {
                thin::ThinPixels::with_outlines(mesh, a, r, &vertices, lay)
            } else {
                thin::ThinPixels::new(mesh, a, r, &vertices, lay)
            }
        })
        .collect();
    let words = thin::gpu_words(&per, lay.width * lay.width);
    let max = gpu.limits.max_storage_buffer_binding_size;
    if 4 * words.len() as u64 > max {
        return Err(crate::Error::param(
            "resolution",
            lay.width,
            format!(
                "an image whose thin-part lists ({} bytes for {} attitudes) fit the device's \
                 {max}-byte storage binding",
                4 * words.len(),
                rots.len()
            ),
        ));
    }
    Ok(words)
}
