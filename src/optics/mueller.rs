//! Jones and Mueller matrices (conventions in [`crate::optics`]).

use super::fresnel::C64;

/// A 4x4 real Mueller matrix, row major: `M[i][j]` maps input Stokes `j` to output `i`.
pub type Mat4 = [[f64; 4]; 4];
/// A 2x2 complex Jones matrix, row major: `J[a][b]` maps input component `b` to output `a`.
pub type Jones = [[C64; 2]; 2];

/// `M_ij = 1/2 tr(sigma_i J sigma_j J^H)` in the Pauli basis of [`crate::optics`].
///
/// Written out: with columns `c0 = J[.][0]`, `c1 = J[.][1]`, the Hermitian matrices
/// `H_j = J sigma_j J^H` are `c0 c0^H +- c1 c1^H`, `c0 c1^H + c1 c0^H`, `i (c0 c1^H - c1 c0^H)`,
/// and row i of column j is `(H00 + H11)/2, (H00 - H11)/2, Re H01, Im H01`.
#[inline]
pub fn jones_to_mueller(j: &Jones) -> Mat4 {
    let (a, b) = (j[0][0], j[1][0]); // column 0
    let (c, d) = (j[0][1], j[1][1]); // column 1
    let (aa, bb, cc, dd) = (a.norm_sqr(), b.norm_sqr(), c.norm_sqr(), d.norm_sqr());
    // Entries 01 of c0 c0^H, c1 c1^H, c0 c1^H, c1 c0^H.
    let ab = a * b.conj();
    let cd = c * d.conj();
    let ad = a * d.conj();
    let cb = c * b.conj();
    // Diagonals of c0 c1^H: a c*, b d*.
    let ac = a * c.conj();
    let bd = b * d.conj();
    let i = C64::new(0.0, 1.0);
    // H_j as (h00, h11, h01)
    let h = [
        (aa + cc, bb + dd, ab + cd),
        (aa - cc, bb - dd, ab - cd),
        (2.0 * ac.re, 2.0 * bd.re, ad + cb),
        // i (c0 c1^H - c1 c0^H): diagonal i(a c* - c a*) = -2 Im(a c*), likewise for b d*.
        (-2.0 * ac.im, -2.0 * bd.im, i * (ad - cb)),
    ];
    let mut m = [[0.0; 4]; 4];
    for (jj, &(h00, h11, h01)) in h.iter().enumerate() {
        m[0][jj] = 0.5 * (h00 + h11);
        m[1][jj] = 0.5 * (h00 - h11);
        m[2][jj] = h01.re;
        m[3][jj] = h01.im;
    }
    m
}

/// Mueller matrix of a rotation of the Stokes reference basis by `theta` (radians) about
/// the propagation direction: the new `x'` is `x` turned by `theta` toward `y`.
pub fn rotator(theta: f64) -> Mat4 {
    let (s, c) = (2.0 * theta).sin_cos();
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, c, s, 0.0],
        [0.0, -s, c, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// Product `a b`.
pub fn matmul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..4 {
            m[i][j] = (0..4).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

/// Scale every element.
pub fn scale(a: &Mat4, s: f64) -> Mat4 {
    let mut m = *a;
    m.iter_mut().flatten().for_each(|x| *x *= s);
    m
}

/// The largest `|a_ij - b_ij|`.
pub fn max_abs_diff(a: &Mat4, b: &Mat4) -> f64 {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// The reciprocal partner of a Mueller matrix in the `Sp` frame.
///
/// Reciprocity of the scattering amplitude gives, for the reversed path expressed in the
/// same physical basis vectors, `J_rev = J^T`. The `Sp` frames of the reversed beams use
/// `x_rev_in = -x_out` (and `y_rev_in = y_out`), `x_rev_out = -x_in` (`y_rev_out = y_in`),
/// so `J_rev = F J^T F` with `F = diag(-1, 1)`. In Mueller form (our V sign)
/// `M(J^T) = D M^T D` with `D = diag(1, 1, 1, -1)`, and `F` contributes
/// `diag(1, 1, -1, -1)`, so `M(wo, wi) = C M(wi, wo)^T C` with `C = diag(1, 1, -1, 1)`.
pub fn reciprocal(m: &Mat4) -> Mat4 {
    let c = [1.0, 1.0, -1.0, 1.0];
    let mut r = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..4 {
            r[i][j] = c[i] * m[j][i] * c[j];
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(re: f64, im: f64) -> C64 {
        C64::new(re, im)
    }

    fn stokes(e: [C64; 2]) -> [f64; 4] {
        let (ex, ey) = (e[0], e[1]);
        let u = ex * ey.conj();
        [
            ex.norm_sqr() + ey.norm_sqr(),
            ex.norm_sqr() - ey.norm_sqr(),
            2.0 * u.re,
            2.0 * u.im,
        ]
    }

    #[test]
    fn mueller_propagates_stokes_of_pure_states() {
        // M applied to the Stokes vector of E equals the Stokes vector of J E.
        let j = [[c(0.3, -0.7), c(-0.2, 0.4)], [c(0.9, 0.1), c(0.05, -0.6)]];
        let m = jones_to_mueller(&j);
        for e in [
            [c(1.0, 0.0), c(0.0, 0.0)],
            [c(0.3, 0.2), c(-0.5, 0.9)],
            [c(1.0, 0.0), c(0.0, 1.0)],
        ] {
            let je = [
                j[0][0] * e[0] + j[0][1] * e[1],
                j[1][0] * e[0] + j[1][1] * e[1],
            ];
            let s_in = stokes(e);
            let s_out = stokes(je);
            for i in 0..4 {
                let got: f64 = (0..4).map(|k| m[i][k] * s_in[k]).sum();
                assert!(
                    (got - s_out[i]).abs() < 1e-13,
                    "i={i} got={got} want={}",
                    s_out[i]
                );
            }
        }
    }

    #[test]
    fn transpose_rule_used_by_reciprocal() {
        // M(J^T) = D M(J)^T D with D = diag(1,1,1,-1), the identity `reciprocal` relies on.
        let j = [[c(0.3, -0.7), c(-0.2, 0.4)], [c(0.9, 0.1), c(0.05, -0.6)]];
        let jt = [[j[0][0], j[1][0]], [j[0][1], j[1][1]]];
        let (m, mt) = (jones_to_mueller(&j), jones_to_mueller(&jt));
        let d = [1.0, 1.0, 1.0, -1.0];
        for i in 0..4 {
            for k in 0..4 {
                assert!((mt[i][k] - d[i] * m[k][i] * d[k]).abs() < 1e-13);
            }
        }
    }

    #[test]
    fn mirror_flips_circular() {
        let m = jones_to_mueller(&[[c(-1.0, 0.0), c(0.0, 0.0)], [c(0.0, 0.0), c(1.0, 0.0)]]);
        let want = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0, 0.0],
            [0.0, 0.0, 0.0, -1.0],
        ];
        assert_eq!(m, want);
    }
}
