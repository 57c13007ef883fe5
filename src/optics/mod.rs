//! Optics: Fresnel amplitudes, Jones and Mueller algebra, Stokes reference frames.
//!
//! # Conventions (the one place they are written down)
//!
//! **Directions.** Local shading frame with the macro normal `n = +z`. `wi` points from
//! the surface toward the transmitter, `wo` from the surface toward the receiver; both
//! have `z > 0`. The incident beam therefore propagates along `k_in = -wi`, the reflected
//! beam along `k_out = wo`. Half vector `h = normalize(wi + wo)`.
//!
//! **Fields.** Time dependence `exp(-i omega t)` (physics convention), so an absorbing
//! medium has `eta = n + i k` with `k >= 0`. Complex square roots take the principal branch.
//!
//! **Stokes frame of a beam.** A beam propagating along unit `k` carries a transverse
//! reference basis `(x, y)` with `y = k x x` (right-handed `(x, y, k)`). With complex
//! amplitudes `Ex, Ey` on that basis:
//! `I = |Ex|^2 + |Ey|^2`, `Q = |Ex|^2 - |Ey|^2`, `U = 2 Re(Ex Ey*)`, `V = 2 Im(Ex Ey*)`.
//! With the `exp(-i omega t)` convention `V > 0` is light whose field turns clockwise as
//! seen by an observer facing the source (right-handed in Born and Wolf's sense).
//! These choices reproduce Mitsuba 3's Mueller matrices element for element (Mitsuba
//! uses `eta = n - i k` and the opposite time convention; the two sign flips cancel),
//! which `tests/test_mitsuba.py` checks.
//!
//! **Fresnel.** `rs = (cos t - w) / (cos t + w)`, `rp = (eta^2 cos t - w) / (eta^2 cos t + w)`,
//! `w = sqrt(eta^2 - sin^2 t)`, on the s/p basis `s = normalize(k_in x h)` (the same vector
//! for both beams), `p_in = k_in x s`, `p_out = k_out x s`. At normal incidence
//! `rp = -rs`, so a mirror at normal incidence has Jones `r diag(-1, 1)` and Mueller
//! `R diag(1, 1, -1, -1)`: linear states are kept, circular handedness flips.
//!
//! **Frames offered to users** (see [`frames::Frame`]):
//! - `Sp`: the incident beam in the s/p basis of the plane containing `n` and `wi`, the
//!   reflected beam in that of the plane containing `n` and `wo`, with
//!   `x_in = normalize(k_in x n)`, `x_out = normalize(k_out x n)`. For specular reflection
//!   both are the same vector, so a flat mirror is `diag(1, 1, -1, -1) R` at every angle
//!   for a perfect conductor. If a direction is along `n` its plane of incidence is taken
//!   from the other direction (its azimuth); if both are along `n`, the x-z plane
//!   (azimuth 0). The Mueller matrix does not depend on this choice when the surface is
//!   isotropic and both directions are along `n` (normal-incidence backscatter).
//! - `Mitsuba`: Mitsuba 3's `stokes_basis`: `x_in = coordinate_system(k_in).0`,
//!   `x_out = coordinate_system(k_out).0` (Duff et al. 2017 branchless basis).
//!
//! **Polarization ray tracing.** A reflection off a facet with normal `h` maps the incident
//! field to `E_out = rs s (s . E_in) + rp p_out (p_in . E_in)`; the Jones matrix in any pair
//! of beam frames is the projection `J_ab = x_out_a . P . x_in_b`. Mueller matrices come
//! from Jones matrices by `M_ij = 1/2 tr(sigma_i J sigma_j J^H)` with the Pauli basis
//! `sigma_0 = I, sigma_1 = diag(1,-1), sigma_2 = [[0,1],[1,0]], sigma_3 = [[0,i],[-i,0]]`,
//! which is the Stokes definition above.
//!
//! **Reciprocity.** Swapping `wi` and `wo` in the `Sp` frame gives
//! `M(wo, wi) = C M(wi, wo)^T C` with `C = diag(1, 1, -1, 1)`; see
//! [`mueller::reciprocal`] for the derivation.

pub mod frames;
pub mod fresnel;
pub mod mueller;
pub mod path;
pub mod polarimetry;

pub use fresnel::{fresnel_amplitudes, Eta, C64};
pub use mueller::{jones_to_mueller, Jones, Mat4};
