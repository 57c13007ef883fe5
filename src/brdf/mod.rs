//! The polarized microfacet BRDF (PHYSICS.md sections 3-4).
//!
//! `f(wi, wo)` is a 4x4 Mueller matrix in 1/sr *without* the cosine factor, in the beam
//! frames of [`crate::optics::frames::Frame`]; directions as in [`crate::optics`]
//! (`wi` toward the transmitter, `wo` toward the receiver, `n = +z`).
//!
//! The terms ([`Term`]), summed by [`terms::sum_terms`] ([`eval`]):
//! - [`single`]: `f1 = D(h) G(wi, wo) M_F(h) / (4 cos_i cos_o)` with the complex Fresnel
//!   Mueller matrix of the facet rotated into the beam frames (seed eq. 4, 10-11).
//! - [`double`]: the double bounce with its coherent backscatter (seed eq. 12-17).
//! - multiple: `f_ms = F_ms (1 - E(wi)) (1 - E(wo)) / (pi (1 - E_avg)) diag(1,0,0,0)`
//!   (seed eq. 8, APS; Kulla and Conty 2017's Fresnel factor `F_ms`).
//! - the diffuse (paint) term `rho_d (1 - E_s(wi)) (1 - E_s(wo)) / (pi (1 - E_s,avg))`,
//!   `E_s` the albedo of the specular layer, which keeps the total albedo <= 1.
//!
//! Layers (each module reads only those below it): [`spec`] (what the user gives) <-
//! [`surface`] (the microsurface: masking) <- [`single`], [`double`], [`albedo`](mod@albedo) (the terms'
//! physics) <- [`material`] ([`Material`]: the per-material tables, built once from the
//! terms) <- [`terms`] (their sum) <- [`table`] (the renderer's tables).

pub mod albedo;
pub mod bank;
pub mod calibration;
pub mod double;
pub mod material;
pub mod orders;
mod recent;
pub mod single;
pub mod spec;
pub mod surface;
pub mod table;
pub mod terms;

pub use albedo::single_albedo;
pub use material::{Material, MaterialSpec, Terms};
pub use single::specular;
pub use spec::Term;
pub use surface::Surface;
pub use terms::albedo;
/// The BRDF Mueller matrix of a material: the sum of its enabled terms
/// ([`terms::sum_terms`]).
pub use terms::sum_terms as eval;
