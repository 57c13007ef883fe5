//! Microfacet normal distributions and masking.
//!
//! Conventions: local frame with the macro normal `n = +z`; `theta_h` is the polar angle of
//! the microfacet normal `h`. `D(h)` is normalized over projected area,
//! `int D(h) cos(theta_h) d omega = 1`; the seed's solid-angle density is
//! `rho(h) = <h.n> D(h)` with `<h.n> = 1 / int D d omega` (PHYSICS.md section 3).

pub mod distribution;
pub mod masking;
pub mod seed;

pub use distribution::Distribution;
pub use masking::{Correlation, MaskingEval, Shadowing, SmithG1};
