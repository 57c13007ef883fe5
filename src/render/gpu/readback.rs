//! Reading a chunk's results back: the kernel's output buffers and their mapped copies
//! ([`ResultBuffers`]), the fixed-point sums decoded to f64, the sampled pulse's profile
//! accumulated on the host in f64 ([`host_profile`]) and the images downsampled to the
//! sensor's pixels into the batch's arrays ([`HostOutputs`]).

use super::plan::{KernelOutputs, Plan};
use super::util::{create_buffer, device_error};
use crate::error::Result;
use crate::render::api::{Layout, Outputs, Rendered, SensorSetup};
use crate::render::downsample::{downsample_range, downsample_sum};
use crate::render::pulse::SampledPulse;
use rayon::prelude::*;

/// The batch's outputs on the host, filled chunk by chunk.
pub(super) struct HostOutputs {
    n: usize,
    image: Option<Vec<f32>>,
    range: Option<Vec<f32>>,
    coverage: Option<Vec<f32>>,
    profile: Option<Vec<f64>>,
    area_moment: Option<Vec<f64>>,
    total: Vec<f64>,
}

impl HostOutputs {
    /// For `n` attitudes of `res x res` pixels, `channels` channels and `nb` bins (and the
    /// area moment with `area`): zeros
    /// (allocated zeroed, so that pages are touched only when written: every element is
    /// written by [`ResultBuffers::read_chunk`], the range NaN where nothing is seen; a
    /// NaN fill would touch every page of a large batch's range maps up front).
    pub(super) fn new(
        outputs: Outputs,
        area: bool,
        n: usize,
        res: usize,
        channels: usize,
        nb: usize,
    ) -> Self {
        HostOutputs {
            n,
            image: outputs
                .image
                .then(|| vec![0.0f32; n * res * res * channels]),
            range: outputs.range.then(|| vec![0.0f32; n * res * res]),
            coverage: outputs.range.then(|| vec![0.0f32; n * res * res]),
            profile: outputs.profile.then(|| vec![0.0f64; n * nb * channels]),
            area_moment: area.then(|| vec![0.0f64; n * nb]),
            total: vec![0.0f64; n * channels],
        }
    }

    pub(super) fn into_rendered(
        self,
        channels: usize,
        lay: &Layout,
        sensor: &SensorSetup,
    ) -> Rendered {
        let res = sensor.resolution;
        Rendered {
            n: self.n,
            height: res,
            width: res,
            channels,
            image: self.image,
            range: self.range,
            coverage: self.coverage,
            profile: self.profile,
            area_moment: self.area_moment,
            total: self.total,
            r_min: lay.r_min,
            bin_width: sensor.bin_width,
            n_bins: lay.n_bins,
            pixel_size: lay.pix * sensor.supersampling as f64,
            extent: lay.ext,
            bounce_image: None,
            bounce_profile: None,
            bounce_total: Vec::new(),
            stage_seconds: Vec::new(),
        }
    }
}

/// The kernel's output buffers for a chunk of up to `c` attitudes (16-byte placeholders
/// for those not computed), the mapped copies of those read back, and what decoding them
/// needs.
pub(super) struct ResultBuffers<'a> {
    pub(super) image: wgpu::Buffer,
    pub(super) range: wgpu::Buffer,
    pub(super) profile: wgpu::Buffer,
    pub(super) total: wgpu::Buffer,
    image_read: Option<wgpu::Buffer>,
    range_read: Option<wgpu::Buffer>,
    profile_read: Option<wgpu::Buffer>,
    total_read: wgpu::Buffer,
    kern: KernelOutputs,
    channels: usize,
    /// The fixed-point scales the kernel uses (profile, area moment).
    fix_scale: f64,
    fix_area: f64,
    lay: &'a Layout,
    sensor: &'a SensorSetup,
}

impl<'a> ResultBuffers<'a> {
    pub(super) fn new(
        dev: &wgpu::Device,
        plan: &Plan,
        lay: &'a Layout,
        sensor: &'a SensorSetup,
        c: usize,
        fix_scale: f64,
        fix_area: f64,
    ) -> Self {
        let (kern, channels) = (plan.kern, plan.channels);
        let (w, nb) = (lay.width, lay.n_bins);
        let rng_stride = kern.range_words();
        let mk = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            create_buffer(dev, label, size, usage)
        };
        let out_usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let px = w * w;
        let img_size = if kern.image {
            (c * px * channels * 4) as u64
        } else {
            16
        };
        let rng_size = if kern.range {
            (c * px * 4 * rng_stride) as u64
        } else {
            16
        };
        let prof_size = if kern.profile {
            (c * nb * kern.profile_stride(channels) * 8) as u64
        } else {
            16
        };
        let tot_size = (c * channels * 8) as u64;
        let img_buf = mk("image", img_size, out_usage);
        let rng_buf = mk("range", rng_size, out_usage);
        let prof_buf = mk("profile", prof_size, out_usage);
        let tot_buf = mk("total", tot_size, out_usage);
        let read_usage = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        let img_read = kern.image.then(|| mk("image read", img_size, read_usage));
        let rng_read = kern.range.then(|| mk("range read", rng_size, read_usage));
        let prof_read = kern
            .profile
            .then(|| mk("profile read", prof_size, read_usage));
        let tot_read = mk("total read", tot_size, read_usage);
        ResultBuffers {
            image: img_buf,
            range: rng_buf,
            profile: prof_buf,
            total: tot_buf,
            image_read: img_read,
            range_read: rng_read,
            profile_read: prof_read,
            total_read: tot_read,
            kern,
            channels,
            fix_scale,
            fix_area,
            lay,
            sensor,
        }
    }

    /// Bytes of `m` attitudes' image, range, profile and total.
    fn bytes(&self, m: usize) -> (u64, u64, u64, u64) {
        let (channels, nb) = (self.channels, self.lay.n_bins);
        let px = self.lay.width * self.lay.width;
        let img_bytes = (m * px * channels * 4) as u64;
        let rng_bytes = (m * px * 4 * self.kern.range_words()) as u64;
        let prof_bytes = (m * nb * self.kern.profile_stride(channels) * 8) as u64;
        let tot_bytes = (m * channels * 8) as u64;
        (img_bytes, rng_bytes, prof_bytes, tot_bytes)
    }

    /// Zero the sums the kernel accumulates atomically (before its dispatch).
    pub(super) fn clear(&self, enc: &mut wgpu::CommandEncoder) {
        if self.kern.profile {
            enc.clear_buffer(&self.profile, 0, None);
        }
        enc.clear_buffer(&self.total, 0, None);
    }

    /// Copy the results of `m` attitudes to the mapped buffers (after the kernel).
    pub(super) fn copy_for_readback(&self, enc: &mut wgpu::CommandEncoder, m: usize) {
        let copy =
            |enc: &mut wgpu::CommandEncoder, src: &wgpu::Buffer, dst: &wgpu::Buffer, size| {
                enc.copy_buffer_to_buffer(src, 0, dst, 0, Some(size));
            };
        let (img_bytes, rng_bytes, prof_bytes, tot_bytes) = self.bytes(m);
        if let Some(b) = &self.image_read {
            copy(enc, &self.image, b, img_bytes);
        }
        if let Some(b) = &self.range_read {
            copy(enc, &self.range, b, rng_bytes);
        }
        if let Some(b) = &self.profile_read {
            copy(enc, &self.profile, b, prof_bytes);
        }
        if self.kern.total() {
            copy(enc, &self.total, &self.total_read, tot_bytes);
        }
    }

    /// Read the results of the chunk of `m` attitudes from `start` (submitted) into `host`:
    /// the totals and the profile from the fixed-point sums, a sampled pulse's profile
    /// from the footprints, the images downsampled to the sensor's pixels.
    pub(super) fn read_chunk(
        &self,
        dev: &wgpu::Device,
        start: usize,
        m: usize,
        host: &mut HostOutputs,
    ) -> Result<()> {
        let (lay, sensor) = (self.lay, self.sensor);
        let (channels, nb, fix_scale) = (self.channels, lay.n_bins, self.fix_scale);
        let (w, ss, res) = (lay.width, sensor.supersampling, sensor.resolution);
        let px = w * w;
        let rng_stride = self.kern.range_words();
        let (img_bytes, rng_bytes, prof_bytes, tot_bytes) = self.bytes(m);
        let read = |b: &wgpu::Buffer, bytes: u64| map_read(dev, b, bytes);
        let fixed = |bytes: &[u8]| -> Vec<f64> {
            let words: &[u32] = bytemuck::cast_slice(bytes);
            words
                .chunks_exact(2)
                .map(|p| ((((p[1] as u64) << 32) | p[0] as u64) as i64) as f64 / fix_scale)
                .collect()
        };
        if self.kern.total() {
            let t = fixed(&read(&self.total_read, tot_bytes)?);
            host.total[start * channels..(start + m) * channels].copy_from_slice(&t);
        }
        if let (Some(b), Some(out)) = (&self.profile_read, host.profile.as_mut()) {
            let bytes = read(b, prof_bytes)?;
            let stride = self.kern.profile_stride(channels);
            if !self.kern.total() {
                // exact: sums of the fixed-point integers (|sum| < 2^61 by the scale)
                let words: &[u32] = bytemuck::cast_slice(&bytes);
                for l in 0..m {
                    for ch in 0..channels {
                        let s: i64 = (0..nb)
                            .map(|k| {
                                let i = 2 * ((l * nb + k) * stride + ch);
                                (((words[i + 1] as u64) << 32) | words[i] as u64) as i64
                            })
                            .sum();
                        host.total[(start + l) * channels + ch] = s as f64 / fix_scale;
                    }
                }
            }
            let p = fixed(&bytes);
            let dst = &mut out[start * nb * channels..(start + m) * nb * channels];
            if stride == channels {
                dst.copy_from_slice(&p);
            } else {
                // each bin's channels, then its area moment (decoded at its own scale)
                let moment = host.area_moment.as_mut().expect("area moment asked");
                let q = &mut moment[start * nb..(start + m) * nb];
                let words: &[u32] = bytemuck::cast_slice(&bytes);
                for (k, v) in p.chunks_exact(stride).enumerate() {
                    dst[k * channels..(k + 1) * channels].copy_from_slice(&v[..channels]);
                    let i = 2 * (k * stride + channels);
                    let units = (((words[i + 1] as u64) << 32) | words[i] as u64) as i64;
                    q[k] = units as f64 / self.fix_area;
                }
            }
        }
        // the image and range are decoded straight from the mapped buffers (no host copy of
        // them): both are mapped at once, as the sampled pulse needs both
        let img_slice = self.image_read.as_ref().map(|b| b.slice(0..img_bytes));
        let rng_slice = self.range_read.as_ref().map(|b| b.slice(0..rng_bytes));
        for sl in img_slice.iter().chain(rng_slice.iter()) {
            sl.map_async(wgpu::MapMode::Read, |_| {});
        }
        if img_slice.is_some() || rng_slice.is_some() {
            dev.poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| device_error(format!("device poll failed: {e}")))?;
        }
        let view = |sl: &Option<wgpu::BufferSlice>| {
            sl.as_ref()
                .map(|sl| {
                    sl.get_mapped_range()
                        .map_err(|e| device_error(format!("cannot map a result buffer: {e}")))
                })
                .transpose()
        };
        let (img_view, rng_view) = (view(&img_slice)?, view(&rng_slice)?);
        let img: Option<&[f32]> = img_view.as_deref().map(bytemuck::cast_slice);
        let rng: Option<&[f32]> = rng_view.as_deref().map(bytemuck::cast_slice);
        if let (Some(pulse), Some(out)) = (&sensor.pulse, host.profile.as_mut()) {
            // sampled pulse: the profile from the per-pixel footprints, in f64 on the host
            let img = img.expect("kernel image");
            let foot = rng.expect("footprints");
            let cap = 2f64.powi(61) / (fix_scale * px as f64);
            let prof = &mut out[start * nb * channels..(start + m) * nb * channels];
            prof.par_chunks_mut(nb * channels)
                .enumerate()
                .for_each(|(l, p)| {
                    host_profile(
                        pulse,
                        &img[l * px * channels..(l + 1) * px * channels],
                        &foot[l * px * 4..(l + 1) * px * 4],
                        channels,
                        lay.r_min,
                        sensor.bin_width,
                        cap,
                        p,
                    )
                });
            if let Some(moment) = host.area_moment.as_mut() {
                let q = &mut moment[start * nb..(start + m) * nb];
                q.par_chunks_mut(nb).enumerate().for_each(|(l, q)| {
                    host_area_moment(
                        pulse,
                        &img[l * px * channels..(l + 1) * px * channels],
                        &foot[l * px * 4..(l + 1) * px * 4],
                        channels,
                        lay.r_min,
                        sensor.bin_width,
                        lay.pix * lay.pix,
                        cap,
                        q,
                    )
                });
            }
        }
        if let (Some(v), Some(out)) = (img, host.image.as_mut()) {
            downsample_sum(
                v,
                m,
                w,
                ss,
                channels,
                &mut out[start * res * res * channels..],
            );
        }
        if let (Some(v), Some(out), Some(cov)) = (rng, host.range.as_mut(), host.coverage.as_mut())
        {
            // (range, ..., covered fraction) per pixel
            downsample_range(
                v,
                v,
                rng_stride,
                rng_stride - 1,
                m,
                w,
                ss,
                &mut out[start * res * res..],
                &mut cov[start * res * res..],
            );
        }
        drop((img_view, rng_view));
        for b in self.image_read.iter().chain(self.range_read.iter()) {
            b.unmap();
        }
        Ok(())
    }
}

/// The first `bytes` of the mappable buffer `b`, once the device has finished with it.
pub(super) fn map_read(dev: &wgpu::Device, b: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>> {
    let slice = b.slice(0..bytes);
    slice.map_async(wgpu::MapMode::Read, |_| {});
    dev.poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| device_error(format!("device poll failed: {e}")))?;
    let v = slice
        .get_mapped_range()
        .map_err(|e| device_error(format!("cannot map a result buffer: {e}")))?
        .to_vec();
    b.unmap();
    Ok(v)
}

/// The profile of one attitude for a sampled pulse, on the host in f64: every covered
/// pixel (`foot` = (r0, a, b, coverage) per pixel, r0 NaN where empty; `img` its `ch` channels)
/// adds `W_k = C(e_{k+1} - r0) - C(e_k - r0)` times its channels to the bins its footprint
/// and the pulse reach, `C` = [`SampledPulse::cdf_box2`]. The channels are clamped to
/// `cap` as in the kernel's fixed-point sums, so that the profile sums to the total.
#[allow(clippy::too_many_arguments)]
pub fn host_profile(
    pulse: &SampledPulse,
    img: &[f32],
    foot: &[f32],
    ch: usize,
    r_min: f64,
    bin_width: f64,
    cap: f64,
    out: &mut [f64],
) {
    let nb = out.len() / ch;
    let (lo, hi) = pulse.support();
    let mut edges = Vec::new();
    let mut weights = Vec::new();
    for (k, f) in foot.chunks_exact(4).enumerate() {
        let r0 = f[0] as f64;
        let v = &img[k * ch..(k + 1) * ch];
        if r0.is_nan() || v[0] == 0.0 {
            continue;
        }
        let (a, b) = (f[1] as f64, f[2] as f64);
        let half = 0.5 * (a + b);
        let k0 = (((r0 - half + lo - r_min) / bin_width).floor().max(0.0) as usize).min(nb - 1);
        let k1 = (((r0 + half + hi - r_min) / bin_width).floor().max(0.0) as usize).min(nb - 1);
        edges.clear();
        edges.extend((k0..=k1 + 1).map(|j| r_min + j as f64 * bin_width));
        weights.clear();
        weights.resize(k1 + 1 - k0, 0.0);
        pulse.bin_weights(r0, a, b, &edges, &mut weights);
        for (j, &wt) in weights.iter().enumerate() {
            if wt != 0.0 {
                let o = &mut out[(k0 + j) * ch..(k0 + j + 1) * ch];
                for c in 0..ch {
                    o[c] += wt * (v[c] as f64).clamp(-cap, cap);
                }
            }
        }
    }
}

/// The area moment ([`crate::render::Rendered::area_moment`]) of one attitude for a
/// sampled pulse, on the host in f64 beside [`host_profile`]: every covered pixel with a
/// positive `S0` (channel 0 of `img`, clamped to `cap`) adds `S0^2 / (coverage pix2)`
/// (`pix2` the pixel's area, m^2) times the mean squared pointwise pulse weight of bin `k`
/// over its footprint (the two-point rule of the CPU renderers). A pixel that
/// spans several surfaces counts as one part here, at its mean range and its largest
/// part's footprint (the kernel's footprint mode).
#[allow(clippy::too_many_arguments)]
pub fn host_area_moment(
    pulse: &SampledPulse,
    img: &[f32],
    foot: &[f32],
    ch: usize,
    r_min: f64,
    bin_width: f64,
    pix2: f64,
    cap: f64,
    out: &mut [f64],
) {
    let nb = out.len();
    let (lo, hi) = pulse.support();
    let mut edges = Vec::new();
    let mut weights = Vec::new();
    for (k, f) in foot.chunks_exact(4).enumerate() {
        let (r0, cov) = (f[0] as f64, f[3] as f64);
        let s0 = (img[k * ch] as f64).min(cap);
        if r0.is_nan() || s0.is_nan() || s0 <= 0.0 || cov.is_nan() || cov <= 0.0 {
            continue;
        }
        let e = s0 * s0 / (cov * pix2);
        let (a, b) = (f[1] as f64, f[2] as f64);
        // the mean squared pointwise weight over the footprint by the two-point rule of
        // the CPU renderers (render::cpu's Accumulator::add_moment)
        let d = ((a * a + b * b) / 12.0).sqrt();
        for off in [d, -d] {
            let r = r0 + off;
            let k0 = (((r + lo - r_min) / bin_width).floor().max(0.0) as usize).min(nb - 1);
            let k1 = (((r + hi - r_min) / bin_width).floor().max(0.0) as usize).min(nb - 1);
            edges.clear();
            edges.extend((k0..=k1 + 1).map(|j| r_min + j as f64 * bin_width));
            weights.clear();
            weights.resize(k1 + 1 - k0, 0.0);
            pulse.bin_weights(r, 0.0, 0.0, &edges, &mut weights);
            for (j, &wt) in weights.iter().enumerate() {
                out[k0 + j] += 0.5 * wt * wt * e;
            }
        }
    }
}
