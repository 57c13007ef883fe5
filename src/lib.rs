//! pprender: polarized microfacet reflection and Pulse Polarization Ranging returns.
//!
//! The core is pure Rust (f64, no Python). Modules:
//! - [`optics`]: Fresnel amplitudes, Jones/Mueller algebra, Stokes frames, polarimetric
//!   quantities. The polarization conventions are written once at the top of [`optics`].
//! - [`microfacet`]: normal distributions (Blinn-Phong, Beckmann, GGX) and masking
//!   (APS `<h.k>+`, Smith), with exact references next to every approximation.
//! - [`brdf`]: the single-bounce, multiple-scattering and diffuse terms and [`brdf::Material`].
//! - [`quad`]: Gauss-Legendre quadrature used by every integral in the crate.
//!
//! The optional `python` feature adds the PyO3 binding layer (`pprender._core`).

pub mod brdf;
pub mod error;
pub mod microfacet;
pub mod optics;
pub mod quad;
pub mod reference;
pub mod render;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};

/// The model's version: bumped with every change that moves rendered or evaluated numbers
/// (a fix, a new default, a recalibration; not a refactor or a speed-up that keeps them
/// bit for bit). Databases (Python `pprender.build_database`) record it in their
/// fingerprint, so that a store built by another model is never resumed into.
///
/// 1 (2026-11-27): first recorded; `orders = Surface` materials calibrate the single
/// term's masking to the traced surface's order 1.
/// 2 (2026-11-27): the double bounce's correlated blocking takes the ratio of two
/// vanishing masking excesses from their closed form (the escape table of the seed's
/// double term had a jump near the normal; the albedos move below 1e-6).
/// 3 (2026-11-27): `orders = Surface` with the multiple term: the depolarizing remainder is
/// the banks' truncation, smooth in `theta`, and the single term's calibration closes the
/// energy balance between the banks' nodes and beyond the last (the remainder oscillated
/// with the nodes' 2.5 deg period at grazing angles).
pub const MODEL_VERSION: u32 = 3;
