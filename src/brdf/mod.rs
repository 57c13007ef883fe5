//! The polarized microfacet BRDF (PHYSICS.md sections 3-4).
//!
//! `f(wi, wo)` is a 4x4 Mueller matrix in 1/sr *without* the cosine factor, in the beam
//! frames of [`crate::optics::frames::Frame`]; directions as in [`crate::optics`]
//! (`wi` toward the transmitter, `wo` toward the receiver, `n = +z`).
//!
//! - [`single`]: `f1 = D(h) G(wi, wo) M_F(h) / (4 cos_i cos_o)` with the complex Fresnel
//!   Mueller matrix of the facet rotated into the beam frames (seed eq. 4, 10-11).
//! - [`multiple`]: `f_ms = F_ms (1 - E(wi)) (1 - E(wo)) / (pi (1 - E_avg)) diag(1,0,0,0)`
//!   (seed eq. 8, APS; Kulla and Conty 2017's Fresnel factor `F_ms`).
//! - the diffuse (paint) term `rho_d (1 - E_s(wi)) (1 - E_s(wo)) / (pi (1 - E_s,avg))`,
//!   `E_s` the albedo of the specular layer, which keeps the total albedo <= 1.
//!
//! [`Material`] owns the per-material tables (masking, albedo), built once.

pub mod albedo;
pub mod double;
pub mod material;
pub mod single;
pub mod table;

pub use albedo::{albedo, single_albedo};
pub use material::{Material, MaterialSpec, Terms};
pub use single::{eval, specular};
