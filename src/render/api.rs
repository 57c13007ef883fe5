//! The renderer's request and result types, shared by every backend (the wgpu kernels,
//! [`crate::render::gpu`], and the f64 CPU renderers, [`crate::render::cpu`]): what to
//! compute ([`Outputs`]), the validated sensor ([`SensorSetup`], [`check_sensor`]), the
//! image and profile geometry it implies for a mesh ([`Layout`]) and the arrays a render
//! returns ([`Rendered`]). Conventions: [`crate::render`].

use super::geometry::Mesh;
use super::pulse::SampledPulse;
use crate::error::{Error, Result};
use std::sync::Arc;

/// What to compute and read back.
#[derive(Debug, Clone, Copy)]
pub struct Outputs {
    pub image: bool,
    pub range: bool,
    pub profile: bool,
}

/// The most bounces a path may have.
pub const MAX_BOUNCES: usize = 3;
/// The most paths per pixel.
pub const MAX_PATH_SAMPLES: usize = 1 << 16;

/// How inter-reflections are rendered: the most bounces of a path (1 to [`MAX_BOUNCES`]; 1
/// traces no path), the paths per pixel (1 to [`MAX_PATH_SAMPLES`]) and the seed of their
/// random numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PathSetup {
    pub bounces: usize,
    pub samples: usize,
    pub seed: u32,
}

impl Default for PathSetup {
    fn default() -> Self {
        PathSetup {
            bounces: 1,
            samples: 16,
            seed: 0,
        }
    }
}

/// Refuse bounces outside `1..=MAX_BOUNCES` and path counts outside `1..=MAX_PATH_SAMPLES`.
pub fn check_paths(p: &PathSetup) -> Result<()> {
    if !(1..=MAX_BOUNCES).contains(&p.bounces) {
        return Err(Error::param(
            "bounces",
            p.bounces,
            format!("an integer in [1, {MAX_BOUNCES}]: the most reflections of a path"),
        ));
    }
    if !(1..=MAX_PATH_SAMPLES).contains(&p.samples) {
        return Err(Error::param(
            "path_samples",
            p.samples,
            format!("an integer in [1, {MAX_PATH_SAMPLES}]: paths per pixel"),
        ));
    }
    Ok(())
}

/// The sensor after validation, in the renderer's units.
#[derive(Debug, Clone)]
pub struct SensorSetup {
    /// Output image side (pixels).
    pub resolution: usize,
    /// Sub-pixels per output pixel side.
    pub supersampling: usize,
    /// Visibility samples per (sub-)pixel, a power of two in `1..=16`
    /// ([`crate::render::samples::sample_offsets`]): the pixel's area is shared among the
    /// triangles its samples see, each shaded once (see `shaders/shade.wgsl`). 1: the pixel
    /// centre alone.
    pub samples: usize,
    /// Analytic coverage (with `samples == 1`): the pixel's area is shared among the
    /// triangles seen at the centres of its 3x3 neighbourhood by exact polygon clipping in
    /// depth order, each shaded once at the centroid of its visible part
    /// (`coverage_parts` in `shaders/shade.wgsl`, twin [`crate::render::cpu::coverage_parts`]).
    pub analytic: bool,
    pub bistatic_angle: f64,
    /// Transmitted Stokes vector; `None`: full Mueller output.
    pub polarization: Option<[f64; 4]>,
    /// With a `polarization`: output the received intensity `S0` only (1 channel).
    pub intensity_only: bool,
    /// Pulse standard deviation in range units (m).
    pub sigma_range: f64,
    /// Range-bin width (m).
    pub bin_width: f64,
    /// A sampled pulse shape (range units, centroid at 0) replacing the Gaussian of
    /// `sigma_range`. Its profile is accumulated on the host in f64 from the kernel's
    /// per-pixel footprints (see [`crate::render::gpu::host_profile`]); `sigma_range` is
    /// then unused.
    pub pulse: Option<Arc<SampledPulse>>,
    /// Inter-reflections between parts ([`crate::render::paths`]): the bounces, paths per
    /// pixel and seed. The default renders one bounce (no paths).
    pub paths: PathSetup,
    /// Accumulate the profile's second moment per bin beside it ([`Rendered::area_moment`],
    /// from which the illuminated area per bin follows); with the profile only. An output
    /// option like `intensity_only`: it changes nothing else, bit for bit.
    pub illuminated_area: bool,
}

impl SensorSetup {
    /// Output channels: 16 (Mueller), 4 (Stokes `M s_tx`) or 1 (intensity `(M s_tx)_0`).
    pub fn channels(&self) -> usize {
        match (self.polarization, self.intensity_only) {
            (None, _) => 16,
            (Some(_), false) => 4,
            (Some(_), true) => 1,
        }
    }

    /// The Mueller elements (bit `4 i + j` for `M_ij`, sp frame) the output needs; the
    /// kernel looks up only these. The telescope output is `L(ao) M L(ai) s_tx`: rows 1
    /// and 2 mix under `L(ao)`, columns 1 and 2 under `L(ai)`. Column `j` is needed when
    /// `(L(ai) s_tx)_j` can be non-zero (column 0 when `S0 != 0`, columns 1 and 2 when
    /// `S1` or `S2 != 0`, column 3 when `S3 != 0`), row `i` when the output has it
    /// (intensity: row 0 only). `M00` is always looked up (it scales the others).
    pub fn element_mask(&self) -> u32 {
        let Some(s) = self.polarization else {
            return 0xffff;
        };
        let cols = [
            s[0] != 0.0,
            s[1] != 0.0 || s[2] != 0.0,
            s[1] != 0.0 || s[2] != 0.0,
            s[3] != 0.0,
        ];
        let rows = [
            true,
            !self.intensity_only,
            !self.intensity_only,
            !self.intensity_only,
        ];
        let mut m = 1u32;
        for i in 0..4 {
            for j in 0..4 {
                if rows[i] && cols[j] {
                    m |= 1 << (4 * i + j);
                }
            }
        }
        m
    }
}

/// The pulse support in standard deviations: a pixel adds to the bins within it of its
/// footprint, the Gaussian's tails beyond (2.9e-7 of its value on each side) folded into
/// the end bins ([`crate::render::pulse::bin_weights_folded`]), so profiles sum exactly.
pub const PULSE_SUPPORT_SIGMAS: f64 = 5.0;

/// Results of one batch, row-major arrays.
#[derive(Debug, Clone)]
pub struct Rendered {
    pub n: usize,
    pub height: usize,
    pub width: usize,
    /// 16 (Mueller, row-major) or 4 (Stokes).
    pub channels: usize,
    /// (n, h, w, channels) m^2 per pixel.
    pub image: Option<Vec<f32>>,
    /// (n, h, w) m; NaN where nothing is seen.
    pub range: Option<Vec<f32>>,
    /// (n, h, w) fraction of the pixel's sub-pixels covered.
    pub coverage: Option<Vec<f32>>,
    /// (n, bins, channels) m^2.
    pub profile: Option<Vec<f64>>,
    /// With [`SensorSetup::illuminated_area`]: (n, bins) m^2, per bin `j` the sum over the
    /// shaded parts `q` of the directly lit surface (a pixel's, or its part's, shared among
    /// surfaces) of `(w_jq I_q)^2 / a_q`: `I_q` the part's `S0` cross-section (channel 0,
    /// where positive), `a_q` its projected area (its fraction of the pixel times
    /// `delta^2`) and `w_jq` its pulse weight in the bin, the same as its profile's. The
    /// illuminated area of bin `j` is `A_j = P_j^2 / Q_j` with `P_j` the single-bounce
    /// `S0` profile (Goodman's `(int I)^2 / int I^2` of the bin's source). Inter-reflection
    /// paths add nothing to it (they are Monte Carlo points, not areas).
    pub area_moment: Option<Vec<f64>>,
    /// (n, channels) m^2.
    pub total: Vec<f64>,
    /// Bin edges: `r_min + k bin_width`, k = 0..=n_bins.
    pub r_min: f64,
    pub bin_width: f64,
    pub n_bins: usize,
    pub pixel_size: f64,
    pub extent: f64,
    /// With `bounces > 1` ([`PathSetup`]): the outputs split by the number of bounces `k`
    /// (index `k - 1`, `k` up to `bounces`; they sum to `image`, `profile`, `total`):
    /// (n, bounces, h, w, channels) with the image, (n, bounces, bins, channels) with the
    /// profile, (n, bounces, channels). None (empty) with one bounce.
    pub bounce_image: Option<Vec<f32>>,
    pub bounce_profile: Option<Vec<f64>>,
    pub bounce_total: Vec<f64>,
    /// Wall-clock seconds of this render's stages, in order (a diagnostic: on the GPU
    /// `plan`, `pipeline and buffers`, `encode and submit`, `device`, `readback`; one
    /// `render` stage on the CPU backends).
    pub stage_seconds: Vec<(&'static str, f64)>,
}

/// Geometry of the image and profile for a mesh and sensor.
#[derive(Debug, Clone, Copy)]
pub struct Layout {
    pub ext: f64,
    pub width: usize,
    pub pix: f64,
    pub r_min: f64,
    pub n_bins: usize,
    pub max_extent: f64,
    pub support: f64,
}

impl Layout {
    pub fn new(mesh: &Mesh, s: &SensorSetup) -> Self {
        let ext = mesh.radius;
        let width = s.resolution * s.supersampling;
        let pix = 2.0 * ext / width as f64;
        let max_extent = 0.25 * ext;
        let support = match &s.pulse {
            Some(p) => {
                let (lo, hi) = p.support();
                lo.abs().max(hi.abs())
            }
            None => PULSE_SUPPORT_SIGMAS * s.sigma_range,
        };
        // a path of `b` bounces lands at most `b ext` behind the origin (its extra length:
        // at most `2 ext` per segment between surfaces)
        let half = s.paths.bounces.max(1) as f64 * ext + max_extent + support;
        // bin edges at integer multiples of the bin width (the same grid for every scene
        // and pulse with this bin width), symmetric about the range origin
        let k = (half / s.bin_width).ceil().max(1.0);
        let n_bins = 2 * k as usize;
        let r_min = -k * s.bin_width;
        Layout {
            ext,
            width,
            pix,
            r_min,
            n_bins,
            max_extent,
            support,
        }
    }
}

/// Largest number of profile bins accepted (a sanity bound on `bin_width`).
pub const MAX_BINS: usize = 1 << 16;

impl Layout {
    /// Refuse more than [`MAX_BINS`] profile bins (the bins span the bounding sphere about
    /// the body origin: a mesh far from it needs many).
    pub fn check_bins(&self, sensor: &SensorSetup) -> Result<()> {
        if self.n_bins > MAX_BINS {
            return Err(Error::param(
                "bin_width",
                sensor.bin_width,
                format!(
                    "a bin width giving at most {MAX_BINS} bins over the object's range extent \
                     ({:.4} m, the bounding sphere about the body origin; {} bins asked): \
                     a wider bin_width, or a mesh centred on the body origin",
                    2.0 * self.ext,
                    self.n_bins
                ),
            ));
        }
        Ok(())
    }
}

/// Largest image side (resolution x supersampling) accepted.
pub const MAX_IMAGE_SIDE: usize = 8192;

/// Validate a number of visibility samples per pixel ([`super::samples::sample_offsets`]).
pub fn check_samples(k: usize) -> Result<()> {
    if k.is_power_of_two() && k <= super::samples::MAX_SAMPLES {
        Ok(())
    } else {
        Err(Error::param(
            "pixel_samples",
            k,
            format!(
                "visibility samples per pixel: 1, 2, 4, 8 or {}",
                super::samples::MAX_SAMPLES
            ),
        ))
    }
}

/// Validate a sensor set-up (every parameter named with its allowed range).
pub fn check_sensor(s: &SensorSetup) -> Result<()> {
    if s.intensity_only && s.polarization.is_none() {
        return Err(Error::param(
            "intensity_only",
            true,
            "only with a transmitted polarization (a Stokes vector); without one the output is the Mueller matrix",
        ));
    }
    if s.resolution < 1 || s.resolution > MAX_IMAGE_SIDE {
        return Err(Error::param(
            "resolution",
            s.resolution,
            format!("an integer in [1, {MAX_IMAGE_SIDE}]"),
        ));
    }
    if s.supersampling < 1 || s.resolution * s.supersampling > MAX_IMAGE_SIDE {
        return Err(Error::param(
            "supersampling",
            s.supersampling,
            format!("an integer >= 1 with resolution x supersampling <= {MAX_IMAGE_SIDE}"),
        ));
    }
    check_samples(s.samples)?;
    check_paths(&s.paths)?;
    if s.analytic && s.samples != 1 {
        return Err(Error::param(
            "pixel_samples",
            s.samples,
            "1 with analytic coverage (coverage=\"analytic\" finds the pixel's triangles \
             at the pixel centres)",
        ));
    }
    if !(s.bistatic_angle >= 0.0 && s.bistatic_angle < 0.5 * std::f64::consts::PI) {
        return Err(Error::param(
            "bistatic_angle",
            s.bistatic_angle,
            "radians in [0, pi/2)",
        ));
    }
    if let Some(p) = s.polarization {
        if !p.iter().all(|x| x.is_finite()) || p[0] <= 0.0 {
            return Err(Error::param(
                "polarization",
                format!("{p:?}"),
                "a finite Stokes vector with S0 > 0",
            ));
        }
        let dop = (p[1] * p[1] + p[2] * p[2] + p[3] * p[3]).sqrt();
        if dop > p[0] * (1.0 + 1e-9) {
            return Err(Error::param(
                "polarization",
                format!("{p:?}"),
                "a physical Stokes vector (sqrt(S1^2 + S2^2 + S3^2) <= S0)",
            ));
        }
    }
    if !(s.sigma_range > 0.0 && s.sigma_range.is_finite()) {
        return Err(Error::param(
            "pulse_fwhm",
            s.sigma_range,
            "a positive, finite pulse width",
        ));
    }
    if !(s.bin_width > 0.0 && s.bin_width.is_finite()) {
        return Err(Error::param(
            "bin_width",
            s.bin_width,
            "a positive, finite length (m)",
        ));
    }
    Ok(())
}

/// A progress callback: called with `(attitudes done, attitudes in the batch)` as a render
/// goes (after each GPU chunk, after each attitude on the CPU; from worker threads there);
/// returning `false` stops the render, which then returns [`crate::Error::Cancelled`].
pub type Progress<'a> = Option<&'a (dyn Fn(usize, usize) -> bool + Sync)>;
