//! Polarization along a specular path through several smooth surfaces: the 3x3 polarization
//! ray-tracing matrices of the reflections (conventions in [`crate::optics`]) composed in
//! order, and the path's Jones and Mueller matrices in chosen beam bases. For
//! inter-reflections between the parts of a mesh (issue 23): a corner of mirror-like parts
//! returns light along such a path (the image-method path of flat pairs).
//!
//! A reflection off a surface with unit normal `n` (facing the arriving beam) takes the
//! propagation `k` to `k' = k - 2 (k.n) n` and the field through
//! `P = rs s s^T + rp p' p^T + k' k^T`, with `s = normalize(k x n)`, `p = k x s`,
//! `p' = k' x s` ([`facet_sp_basis`]; at normal incidence `s` is a given vector normal to
//! `k`). The `k' k^T`
//! term keeps `P` invertible and carries no field (fields are transverse). A path's matrix
//! is the product `P_m ... P_1`, and its Jones matrix in bases `(x_in, y_in = k_in x x_in)`,
//! `(x_out, y_out = k_out x x_out)` is `J_ab = x_out_a . P x_in_b`.

use super::frames::{cross, dot, facet_sp_basis, normalize, V3};
use super::fresnel::{fresnel_amplitudes, Eta, C64};
use super::mueller::{jones_to_mueller, Jones, Mat4};

/// A complex 3x3 matrix, rows first.
pub type CMat3 = [[C64; 3]; 3];

fn outer(a: V3, b: V3, c: C64) -> CMat3 {
    let mut m = [[C64::new(0.0, 0.0); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = c * (a[i] * b[j]);
        }
    }
    m
}

fn add(a: &CMat3, b: &CMat3) -> CMat3 {
    let mut m = *a;
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] += b[i][j];
        }
    }
    m
}

fn mul(a: &CMat3, b: &CMat3) -> CMat3 {
    let mut m = [[C64::new(0.0, 0.0); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                m[i][j] += a[i][k] * b[k][j];
            }
        }
    }
    m
}

/// The reflection of the beam propagating along unit `k` off a surface with unit normal `n`
/// and index `eta`: the new propagation direction and the polarization ray-tracing matrix
/// (module docstring; `perp`, a unit vector normal to `k`, is `s` at normal incidence).
/// `None` when the beam meets the surface from behind or at grazing (`k.n >= 0`).
pub fn reflection(k: V3, n: V3, eta: Eta, perp: V3) -> Option<(V3, CMat3)> {
    let cos_i = -dot(k, n);
    if cos_i <= 0.0 || !cos_i.is_finite() {
        return None;
    }
    let k_out = k + (2.0 * cos_i) * n;
    let (s, p_in, p_out) = facet_sp_basis(k, k_out, n, perp);
    let (rs, rp) = fresnel_amplitudes(cos_i.min(1.0), eta);
    let one = C64::new(1.0, 0.0);
    let m = add(
        &add(&outer(s, s, rs), &outer(p_out, p_in, rp)),
        &outer(k_out, k, one),
    );
    Some((k_out, m))
}

/// The path of a beam propagating along unit `k_in` reflected in turn off the surfaces
/// `(normal, eta)`: the outgoing direction and the product of the reflections' matrices.
/// `perp` (normal to `k_in`) fixes `s` at normal incidence, carried along the path.
/// `None` if a surface is met from behind.
pub fn specular_path(k_in: V3, surfaces: &[(V3, Eta)], perp: V3) -> Option<(V3, CMat3)> {
    let one = C64::new(1.0, 0.0);
    let zero = C64::new(0.0, 0.0);
    let mut p = [[one, zero, zero], [zero, one, zero], [zero, zero, one]];
    let (mut k, mut perp) = (k_in, perp);
    for &(n, eta) in surfaces {
        let (k_next, m) = reflection(k, n, eta, perp)?;
        // the normal-incidence reference follows the beam: its component along k_next dropped
        perp = normalize(perp - dot(perp, k_next) * k_next);
        k = k_next;
        p = mul(&m, &p);
    }
    Some((k, p))
}

/// The Jones matrix of `p` (a path from `k_in` to `k_out`) in the bases `x_in` (normal to
/// `k_in`) and `x_out` (normal to `k_out`), `y = k x x` for each.
pub fn path_jones(p: &CMat3, k_in: V3, x_in: V3, k_out: V3, x_out: V3) -> Jones {
    let (y_in, y_out) = (cross(k_in, x_in), cross(k_out, x_out));
    let mut j = [[C64::new(0.0, 0.0); 2]; 2];
    for (b, e) in [x_in, y_in].into_iter().enumerate() {
        // P e, then its components on the output basis
        let pe: [C64; 3] =
            std::array::from_fn(|i| p[i][0] * e[0] + p[i][1] * e[1] + p[i][2] * e[2]);
        for (a, x) in [x_out, y_out].into_iter().enumerate() {
            j[a][b] = pe[0] * x[0] + pe[1] * x[1] + pe[2] * x[2];
        }
    }
    j
}

/// The Mueller matrix of the path `k_in -> surfaces` in the bases `x_in`, `x_out` (see
/// [`path_jones`]), with the outgoing direction; `None` if a surface is met from behind.
pub fn path_mueller(k_in: V3, surfaces: &[(V3, Eta)], x_in: V3, x_out: V3) -> Option<(Mat4, V3)> {
    let (k_out, p) = specular_path(k_in, surfaces, x_in)?;
    Some((
        jones_to_mueller(&path_jones(&p, k_in, x_in, k_out, x_out)),
        k_out,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::double::double_jones;
    use crate::optics::frames::{beam_bases, Frame};
    use std::f64::consts::FRAC_1_SQRT_2;

    fn close(a: &Mat4, b: &Mat4, tol: f64) -> bool {
        (0..4).all(|i| (0..4).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
    }

    /// A mirror at normal incidence: `diag(1, 1, -1, -1)` for a perfect conductor (linear
    /// states kept, circular handedness flipped), as the conventions say.
    #[test]
    fn a_mirror_at_normal_incidence_flips_handedness() {
        let (k_in, x) = (-V3::Z, V3::X);
        let (m, k_out) = path_mueller(k_in, &[(V3::Z, Eta::PerfectConductor)], x, x).unwrap();
        assert_eq!(k_out, V3::Z);
        let want = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0, 0.0],
            [0.0, 0.0, 0.0, -1.0],
        ];
        assert!(close(&m, &want, 1e-15), "{m:?}");
    }

    /// A perfect-conductor dihedral (two faces at 90 degrees, edge at angle `theta` to the
    /// x axis in the image plane, opening toward the sensor) seen straight into its
    /// opening: the beam comes back along itself after two reflections, and in the bases
    /// `x_in = x_out = x` its Jones matrix is a rotation by `2 theta`, so its Mueller
    /// matrix turns linear states by `4 theta` and keeps circular handedness:
    /// co-polarized at 0, mixed at 22.5 degrees, fully cross-polarized at 45 (H -> V).
    #[test]
    fn perfect_conductor_dihedral_rotates_linear_states_by_four_theta() {
        for deg in [0.0f64, 22.5, 45.0, 67.5, 90.0, 10.0] {
            let th = deg.to_radians();
            let (c, s) = (th.cos(), th.sin());
            // the faces' normals: edge e = (c, s, 0), across it u = (-s, c, 0)
            let u = V3::new(-s, c, 0.0);
            let n_a = (u + V3::Z) * FRAC_1_SQRT_2; // the face on the -u side, facing +u and up
            let n_b = (-u + V3::Z) * FRAC_1_SQRT_2;
            let pc = Eta::PerfectConductor;
            let (m, k_out) = path_mueller(-V3::Z, &[(n_a, pc), (n_b, pc)], V3::X, V3::X).unwrap();
            assert!((k_out - V3::Z).length() < 1e-15, "back along the beam");
            let (c4, s4) = ((4.0 * th).cos(), (4.0 * th).sin());
            let want = [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, c4, -s4, 0.0],
                [0.0, s4, c4, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ];
            assert!(close(&m, &want, 1e-14), "{deg} deg: {m:?}");
        }
        // 45 degrees: H in, V out (Q -> -Q), and circular handedness kept
        let u = V3::new(-FRAC_1_SQRT_2, FRAC_1_SQRT_2, 0.0);
        let pc = Eta::PerfectConductor;
        let (m, _) = path_mueller(
            -V3::Z,
            &[
                ((u + V3::Z) * FRAC_1_SQRT_2, pc),
                ((-u + V3::Z) * FRAC_1_SQRT_2, pc),
            ],
            V3::X,
            V3::X,
        )
        .unwrap();
        assert!((m[1][1] + 1.0).abs() < 1e-14 && (m[3][3] - 1.0).abs() < 1e-14);
    }

    /// A square trihedral (corner cube) of perfect conductor returns a beam along its axis
    /// back along itself after three reflections, with the energy kept (`M00 = 1`) and
    /// circular handedness flipped (`M33 = -1`), as an odd number of bounces does.
    #[test]
    fn corner_cube_retroreflects_and_flips_handedness() {
        let pc = Eta::PerfectConductor;
        let faces = [(V3::X, pc), (V3::Y, pc), (V3::Z, pc)];
        let k_in = -V3::new(1.0, 1.0, 1.0).normalize();
        let x_in = normalize(cross(k_in, V3::Z));
        let (m, k_out) = path_mueller(k_in, &faces, x_in, x_in).unwrap();
        assert!((k_out + k_in).length() < 1e-15, "retroreflected");
        assert!(
            (m[0][0] - 1.0).abs() < 1e-14 && (m[3][3] + 1.0).abs() < 1e-14,
            "{m:?}"
        );
    }

    /// The same two reflections composed here and by the microfacet double bounce
    /// (`brdf::double::double_jones`, which propagates the field vector step by step):
    /// equal Jones matrices for a complex index, random facet pairs, the `Sp` frame.
    #[test]
    fn two_reflections_equal_the_double_bounce_jones() {
        let mat = crate::render::test_scenes::metal(); // Beckmann 0.3, eta 0.2 + 3.4i
        let eta = mat.spec.eta;
        let mut checked = 0;
        for i in 0..40 {
            let a = 0.13 * i as f64;
            let wi = V3::new(0.5 * a.cos(), 0.4 * a.sin(), 0.8).normalize();
            let wo = V3::new(-0.3 * (1.7 * a).sin(), 0.6 * (1.3 * a).cos(), 0.7).normalize();
            let h1 = V3::new(0.6 * (2.1 * a).cos(), 0.5 * (0.7 * a).sin(), 0.6).normalize();
            let Some((jd, d, h2)) = double_jones(&mat, wi, wo, h1, Frame::Sp) else {
                continue;
            };
            let (x_in, _, x_out, _) = beam_bases(Frame::Sp, wi, wo);
            let (k_out, p) = specular_path(-wi, &[(h1, eta), (h2, eta)], x_in).unwrap();
            assert!(
                (k_out - wo).length() < 1e-12,
                "pair {i}: the path ends along wo"
            );
            let _ = d;
            let jp = path_jones(&p, -wi, x_in, k_out, x_out);
            for r in 0..2 {
                for c in 0..2 {
                    assert!(
                        (jp[r][c] - jd[r][c]).norm() < 1e-12,
                        "pair {i}: {jp:?} vs {jd:?}"
                    );
                }
            }
            checked += 1;
        }
        assert!(checked > 10, "{checked}");
    }
}
