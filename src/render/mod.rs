//! The lidar renderer: Mueller/Stokes images, range maps and range-resolved pulse profiles
//! of a mesh under a batch of attitudes, on wgpu (a GPU, or Mesa's lavapipe on the CPU).
//!
//! **Where things are.** [`api`]: the request and result types and the sensor's
//! validation; [`request`]: one entry for every backend ([`request::Backend`],
//! [`request::render`]), which the Python binding calls; [`gpu`]: the host side of the wgpu
//! kernels (`shaders/*.wgsl`, [`shaders`]); [`cpu`]: the f64 CPU renderers (the kernels'
//! twins and the exact reference); [`samples`] and [`downsample`]: the pixel's sample
//! pattern and the supersampling reduction both backends share; [`geometry`]: meshes and
//! attitudes; [`pulse`]: pulse shapes and bin weights; [`tables`]: a scene's material
//! tables, cached per bistatic angle; [`thin`]: the faces thinner than a pixel and the
//! pixels they overlap; [`bvh`] and [`paths`]: ray casting and the
//! inter-reflections between parts (2 and 3 bounces, on the CPU for every backend). The
//! GPU-vs-CPU tests are in `compare_gpu_cpu.rs`.
//!
//! # Conventions (the one place they are written down)
//!
//! **Units.** Lengths in metres, times in seconds, angles in radians, cross-sections in m^2.
//!
//! **Telescope frame.** Right-handed `(X, Y, Z)`: `Z` points from the target toward the
//! receiver, `X` to the right and `Y` up in the image. The receiver direction is
//! `wo = Z`; the transmitter direction is `wi = (sin beta, 0, cos beta)` for the bistatic
//! angle `beta` (transmitter displaced toward `+X`; `beta = 0` is monostatic).
//!
//! **Attitudes.** A rotation `R` maps body-frame coordinates to the telescope frame,
//! `p_tel = R p_body`; the body origin is the range reference point. Quaternions are
//! `(w, x, y, z)` (scalar first, as `R = rotation of the body`); they are normalized, and
//! refused when their norm is off by more than `1e-6` relative or not finite.
//!
//! **Image.** The orthographic image square spans `[-ext, ext]` in `X` and `Y`, `ext` the
//! radius of the mesh's bounding sphere about the body origin (so every attitude fits).
//! Row 0 is the top (`Y = +ext`), column 0 the left (`X = -ext`); pixel `(i, j)` has its
//! centre at `X = -ext + (j + 1/2) delta`, `Y = ext - (i + 1/2) delta`, `delta = 2 ext / W`.
//! Visibility is sampled (rasterization) at `K` points of each pixel (`samples`, a power
//! of two up to 16; [`samples::sample_offsets`]: one per row and column of the `K x K` grid,
//! symmetric about the centre, `K = 1` the centre; `K >= 4` the standard 4x multisample
//! positions in `K / 4` shifted passes, [`samples::msaa_samples`]). Each
//! flat surface ([`geometry::Mesh::surfaces`]: faces joined by edges, coplanar, of one
//! material, flat-shaded; each face of a smooth-shaded mesh is its own) seen by `c` of them
//! counts for `c / K` of the pixel's area and is shaded once, on the plane of the triangle
//! its first sample sees, at the mean of its samples' points; a pixel whose samples all
//! see one surface is shaded at its centre for its whole area. The coverage output is the
//! covered fraction of the samples, the range their mean. Exception, with `K > 1`: a pixel
//! that a face thinner than a pixel in projection overlaps ([`thin`]) takes those faces'
//! visible areas by exact clipping (each shaded at its centroid) and shares the rest of
//! its area among the surfaces its other samples see ([`cpu::thin_parts`], on the CPU for
//! every backend); its coverage output is the summed area. Analytic coverage takes such
//! faces as candidates.
//!
//! **Illumination and cast shadows.** A visible point is lit when `cos(theta_i) > 0` and
//! `cos(theta_o) > 0` (shading normal) and, bistatic (`beta > 0`), it is not in the
//! transmitter's shadow. Monostatic the receiver's visibility implies illumination and no
//! shadow test runs (the kernel is compiled without it: results are unchanged bit for
//! bit). Bistatic, the mesh is also rasterized from the transmitter (rotation
//! `R_tx = R_y(-beta) R`, which maps `wi` to `+z`; the same square `[-ext, ext]`, at twice
//! the receiver's texels per side up to 4096) into a map of triangle ids, and the point
//! `p` of triangle `T` is shadowed when (0) `T`'s geometric normal, on the side the
//! receiver sees, does not face `wi` (a facet behind the terminator of a smooth-shaded
//! surface), or (1) a triangle of the map's 3x3 texels around `p`'s projection covers
//! that projection (exact point-in-triangle test on its vertices) and is closer to the
//! transmitter than `p` by more than `1e-5 ext`, or (2) `T` is none of those nine texels'
//! triangles and all nine lie, by their planes at `p`, closer than `p` by more than
//! `1e-5 ext` plus their slope mismatch with `T` over 2.5 texels (deep inside a finely
//! tessellated occluder seen obliquely). A shadowed pixel returns nothing (zero Mueller
//! matrix, no profile or total) but stays covered, and its range is still reported (the
//! receiver sees the surface). Limits: occluders thinner than about a texel (a wire, the
//! rim of a thin plate edge-on to the transmitter) can be missed, which lets light leak
//! within a texel of a shadow's edge or through a thin shadow; occluders within
//! `1e-5 ext` of `p` in depth are ignored. Details at the top of `shaders/shade.wgsl`;
//! the CPU twin ([`cpu::shadowed`]) casts the ray toward `wi` exactly.
//!
//! **Range.** The one-way range of a surface point `p` relative to the body origin is
//! `r = -p . (wi + wo) / 2` (half the extra round-trip path; `r = -Z` monostatic): positive
//! is farther from the sensor. The profile's time axis is `t = 2 r / c`.
//!
//! **Stokes bases.** The received beam propagates along `+Z`: basis `(X, Y)`. The
//! transmitted beam propagates along `k_in = -wi`: basis `x_in = normalize(k_in x Y)`
//! (`= X` monostatic), `y_in = k_in x x_in` (`= -Y` monostatic). Both are right-handed
//! about their propagation direction, as every beam in [`crate::optics`] (so `V > 0` has
//! the same meaning for both beams, and a mirror facing the sensor is
//! `R diag(1, 1, -1, -1)`: a linear state along `X` returns along `X`; `+45 deg` in the
//! transmit basis (toward `X - Y`) returns as `-45 deg` in the receive basis, the same
//! physical direction).
//!
//! **Cross-section.** A pixel's differential lidar cross-section is
//! `dsigma = 4 pi f(wi, wo) cos(theta_i) delta^2` (Mueller matrix, m^2) with `f` the BRDF
//! in the bases above and `delta^2` the pixel's area projected along `wo` (so that
//! `dA cos(theta_o) = delta^2`). Lambertian sphere check: `sigma = 8/3 pi a^2 rho`.
//!
//! **Profile.** Within a pixel the range is `r0 + gx u + gy v` (its plane; `u, v` across
//! the pixel), a trapezoid of widths `a = |gx| delta`, `b = |gy| delta` (for a triangle
//! seen by `c` of `K` samples: at their mean point, widths scaled by the extent of those
//! samples across the pixel in `u` and `v`, `max - min + 1/K`); convolved with
//! the received pulse (range FWHM `c tau / 2`) and integrated over each bin
//! ([`pulse`]). The bins cover the bounding sphere plus the pulse support (with
//! inter-reflections of up to `b` bounces, [`paths`], `b` times its radius on each side:
//! a path lands at most that far behind the origin), so the weights
//! of every pixel sum to one and the profile sums to the total cross-section. Bin edges
//! are integer multiples of the bin width, symmetric about the range origin. The pulse is
//! a Gaussian (accumulated on the device) or a sampled shape with its centroid at range 0
//! (piecewise linear, [`pulse::SampledPulse`]; accumulated on the host in f64 from the
//! kernel's per-pixel footprints `(r0, a, b)`, see [`gpu::host_profile`]).

pub mod api;
pub mod bvh;
#[cfg(test)]
mod compare_gpu_cpu;
pub mod cpu;
pub mod downsample;
pub mod geometry;
pub mod gpu;
pub mod paths;
pub mod pulse;
pub mod request;
pub mod samples;
pub mod tables;
pub mod thin;
#[cfg(test)]
pub(crate) mod test_scenes;

pub use api::{
    check_samples, check_sensor, Layout, Outputs, Progress, Rendered, SensorSetup, MAX_IMAGE_SIDE,
};

/// Speed of light in vacuum (m/s).
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

pub mod shaders;

#[cfg(test)]
mod tests {
    use super::*;

    fn validate(name: &str, src: &str) -> naga::Module {
        validate_with(name, src, naga::valid::Capabilities::empty())
    }

    fn validate_with(name: &str, src: &str, caps: naga::valid::Capabilities) -> naga::Module {
        let module = naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), caps)
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        module
    }

    /// The multiview visibility stage validates with the MULTIVIEW capability alone, and
    /// not without it (it is created only on devices that have the feature).
    #[test]
    fn multiview_visibility_needs_the_multiview_capability() {
        let src = shaders::visibility_views_module();
        validate_with(
            "visibility_views",
            &src,
            naga::valid::Capabilities::MULTIVIEW,
        );
        let module = naga::front::wgsl::parse_str(&src).unwrap();
        assert!(naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty()
        )
        .validate(&module)
        .is_err());
    }

    /// Every shader parses and validates with naga (no optional capabilities needed).
    #[test]
    fn shaders_validate_with_naga() {
        validate(
            "visibility (raster + visibility)",
            &shaders::visibility_module(),
        );
        validate("pulse.wgsl", shaders::PULSE);
        validate("gather.wgsl", shaders::GATHER);
        validate("raycast.wgsl", shaders::RAYCAST);
        validate("path_numbers.wgsl", &shaders::path_numbers_module());
        let m = validate("shade (pulse + shade)", &shaders::shade_module());
        // the uniform block's size matches the Rust struct
        let params = m
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some("Params"))
            .expect("Params struct");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(m.to_ctx()).unwrap();
        assert_eq!(
            layouter[params.0].size as usize,
            std::mem::size_of::<gpu::ShadeParams>()
        );
    }
}
