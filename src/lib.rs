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
