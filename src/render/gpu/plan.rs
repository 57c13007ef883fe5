//! Planning a render before anything is uploaded: what the kernel computes
//! ([`KernelOutputs`]), the checks against the device's limits, and how many attitudes go
//! in one chunk and at what fixed-point scale ([`Plan`]).

use super::device::Gpu;
use super::pack::GpuTables;
use super::targets::MsaaTiles;
use crate::error::{Error, Result};
use crate::render::api::{Layout, Outputs, SensorSetup};
use crate::render::samples::MSAA;

/// Side of the transmitter's id map for a receiver image side `w` (bistatic cast shadows):
/// twice `w` (texels of half a pixel, so that occluders down to about half a pixel wide are
/// seen), or `w` itself where that would exceed 4096 texels or the device's limit.
pub fn transmitter_map_width(w: usize, max_dim: usize) -> usize {
    if 2 * w <= max_dim.min(4096) {
        2 * w
    } else {
        w
    }
}

/// What the shade kernel computes and what is read back, from the request: a sampled
/// pulse's profile needs the image and the footprints at the internal resolution, and the
/// kernel then skips its own (Gaussian) profile.
#[derive(Debug, Clone, Copy)]
pub struct KernelOutputs {
    pub image: bool,
    pub range: bool,
    pub profile: bool,
    pub footprint: bool,
    /// The kernel accumulates the profile's second moment as one more word pair per bin
    /// after the channels ([`SensorSetup::illuminated_area`], with the profile on the
    /// device); a sampled pulse's is accumulated on the host with its profile.
    pub area: bool,
}

impl KernelOutputs {
    pub fn new(outputs: Outputs, sensor: &SensorSetup) -> Self {
        let host = outputs.profile && sensor.pulse.is_some();
        KernelOutputs {
            image: outputs.image || host,
            range: outputs.range || host,
            profile: outputs.profile && !host,
            footprint: host,
            area: outputs.profile && !host && sensor.illuminated_area,
        }
    }

    /// Fixed-point word pairs per bin of the profile buffer: the channels, and the area
    /// moment's after them.
    pub fn profile_stride(&self, channels: usize) -> usize {
        channels + self.area as usize
    }

    /// Whether the kernel sums the total: not with the profile on the device, whose sum it
    /// is (taken exactly on the host from the same fixed-point words).
    pub fn total(&self) -> bool {
        !self.profile
    }

    /// Words per pixel of the range output: `(range, covered fraction)`, or with the
    /// footprints `(r0, a, b, covered fraction)`.
    pub fn range_words(&self) -> usize {
        if self.footprint {
            4
        } else {
            2
        }
    }
}

/// Refuse an image the device cannot draw: its side (with the tiles' margins when
/// `K >= 4`) beyond the device's texture limit, or a mesh of `2^24` triangles or more with
/// `K >= 4` (ids are stored as `f32` in the multisampled tiles).
pub(super) fn check_image(
    gpu: &Gpu,
    lay: &Layout,
    sensor: &SensorSetup,
    n_tri: usize,
) -> Result<()> {
    let w = lay.width;
    // K >= 4: tiles of w + 2 texels (MsaaTiles)
    let margin = if sensor.samples >= MSAA { 2 } else { 0 };
    let max_dim = gpu.info.max_texture_dimension_2d as usize;
    if w + margin > max_dim {
        return Err(Error::param(
            "resolution",
            w,
            format!(
                "resolution x supersampling <= {} on this device",
                max_dim - margin
            ),
        ));
    }
    if sensor.samples >= MSAA && n_tri >= 1 << 24 {
        return Err(Error::param(
            "pixel_samples",
            sensor.samples,
            format!("1 or 2 for a mesh of {n_tri} triangles (4 to 16 take up to 2^24 - 1)"),
        ));
    }
    Ok(())
}

/// How a render is split and scaled.
pub(super) struct Plan {
    /// What the kernel computes and what is read back.
    pub kern: KernelOutputs,
    /// Output channels ([`SensorSetup::channels`]).
    pub channels: usize,
    /// Attitudes per chunk: every per-chunk buffer within the device's storage binding,
    /// the layers within its limits, the chunk's device memory modest and its readback
    /// within [`READBACK_BYTES`].
    pub chunk: usize,
    /// The fixed-point scale of the sums (before the uniform block rounds it to f32).
    pub fix_scale: f64,
    /// The fixed-point scale of the area moment (units per m^2, likewise).
    pub fix_area: f64,
    /// Side of the transmitter's id map ([`transmitter_map_width`]).
    pub tx_width: usize,
}

/// The most bytes of results one chunk reads back ([`Plan::chunk`]).
pub(super) const READBACK_BYTES: u64 = 64 << 20;

impl Plan {
    /// Check the uploads (`geometry`, the tables) against the device's storage binding and
    /// choose the chunk size and the fixed-point scale.
    pub(super) fn new(
        gpu: &Gpu,
        lay: &Layout,
        sensor: &SensorSetup,
        tables: &GpuTables,
        outputs: Outputs,
        geometry: &[[f32; 4]],
        n_tri: usize,
    ) -> Result<Self> {
        let w = lay.width;
        let margin = if sensor.samples >= MSAA { 2 } else { 0 };
        let max_dim = gpu.info.max_texture_dimension_2d as usize;
        let channels = sensor.channels();
        let max_binding = gpu.limits.max_storage_buffer_binding_size as u64;
        if (geometry.len() * 16) as u64 > max_binding
            || (tables.data.len() * 4) as u64 > max_binding
        {
            return Err(Error::param(
                "mesh",
                format!("{n_tri} triangles"),
                format!("geometry within the device's {max_binding}-byte storage binding"),
            ));
        }
        // chunk size: every per-chunk buffer within the binding limit, layers within limits
        let px = (w * w) as u64;
        let kern = KernelOutputs::new(outputs, sensor);
        let per_att = [
            if kern.image {
                px * channels as u64 * 4
            } else {
                0
            },
            if kern.range {
                px * 4 * if kern.footprint { 4 } else { 2 }
            } else {
                0
            },
            if kern.profile {
                (lay.n_bins * kern.profile_stride(channels) * 8) as u64
            } else {
                0
            },
            // triangle indices (K >= 4: gathered tiles with their margins); these also
            // bound the thin-pixel index (4 bytes a pixel; its lists are checked when made)
            ((w + margin) * (w + margin) * 4 * sensor.samples) as u64,
        ];
        let biggest = per_att.iter().copied().max().unwrap_or(1).max(1);
        let mut chunk = (max_binding / biggest).max(1) as usize;
        if sensor.samples < MSAA {
            chunk = chunk.min(gpu.limits.max_texture_array_layers as usize / sensor.samples);
        } else if MsaaTiles::grid(w + 2, sensor.samples / MSAA, max_dim).is_none() {
            return Err(Error::param(
                "resolution",
                w,
                format!(
                    "a resolution x supersampling whose {} tiles of side + 2 texels fit a \
                         {max_dim}-texel texture",
                    sensor.samples / MSAA
                ),
            ));
        }
        chunk = chunk
            .min(gpu.limits.max_compute_workgroups_per_dimension as usize)
            .min(256);
        // keep the per-chunk device memory modest (tri ids + depth + outputs, plus the
        // transmitter's tri ids + depth when bistatic)
        let tx_w = transmitter_map_width(w, max_dim);
        let shadow_maps = if sensor.bistatic_angle > 0.0 {
            (tx_w * tx_w * 8) as u64
        } else {
            0
        };
        let mem_per = per_att.iter().sum::<u64>() + px * 4 * sensor.samples as u64 + shadow_maps;
        chunk = chunk.min(((512u64 << 20) / mem_per.max(1)).max(1) as usize);
        // and its readback (images, range maps, profiles) within READBACK_BYTES: on an H200
        // a call of 128 or more full-model attitudes (1.1 MiB each at 128 x 128) as one
        // chunk spent tens of milliseconds creating its buffers and ran at under half the
        // rate of calls of 64 (issue 22's closing note); the chunks of a call share them
        let readback_per = per_att[0] + per_att[1] + per_att[2];
        chunk = chunk.min((READBACK_BYTES / readback_per.max(1)).max(1) as usize);
        if chunk == 0 || biggest > max_binding {
            return Err(Error::param(
                "resolution",
                sensor.resolution,
                "a resolution whose per-attitude buffers fit the device's storage binding limit",
            ));
        }

        let n_pix_internal = (w * w) as f64;
        let p_max = 4.0 * std::f64::consts::PI * lay.pix * lay.pix * tables.max_m00.max(1e-300);
        // Fixed-point scale: a pixel's largest possible |value| maps to 2^40 units (a quantum of
        // 2^-40 of it, far below f32's 2^-24), and the sum of every pixel stays below 2^61. Most
        // pixels then add less than 2^32 units per bin, which the kernel does with one atomic.
        let fix_scale = (2f64.powi(40) / p_max)
            .min(2f64.powi(61) / (p_max * n_pix_internal))
            .min(f32::MAX as f64 / 4.0);
        // The area moment's: a pixel adds at most q_max = p_max^2 / delta^2 over all bins
        // (a part's I^2 / a is at most f q_max, its S0 at most p_max times its fraction f
        // of the pixel over f delta^2, and its squared weights sum to at most 1), so every
        // pixel's sum stays below 2^61 units. Not capped at 2^40 per pixel as the profile
        // is (there for one atomic per addition): the moment is quadratic in the weights,
        // and a bin at 1e-4 of the peak of a face-on plate at 2^40 was 1.5e-4 off by the
        // rounding of its additions. The kernel clamps a part's at f 2^61 / (pixels),
        // which only a pixel beyond the tables' bound p_max reaches (where the profile's
        // own clamp is the guard).
        let q_max = p_max / (lay.pix * lay.pix) * p_max;
        let fix_area = (2f64.powi(61) / (q_max * n_pix_internal)).min(f32::MAX as f64 / 4.0);
        if !(fix_scale.is_finite() && fix_scale > 0.0 && fix_area.is_finite() && fix_area > 0.0) {
            return Err(Error::param(
                "materials",
                format!("max tabulated M00 = {:e}", tables.max_m00),
                "finite BRDF tables",
            ));
        }

        Ok(Plan {
            kern,
            channels,
            chunk,
            fix_scale,
            fix_area,
            tx_width: tx_w,
        })
    }
}
