//! Polarimetric quantities derived from Stokes vectors and Mueller matrices.
//!
//! Conventions are those of [`crate::optics`]: Stokes `(I, Q, U, V)` with
//! `V = 2 Im(Ex Ey*)`, Mueller matrices row major (`M[i][j]` maps input `j` to output `i`),
//! a flat mirror at normal incidence is `diag(1, 1, -1, -1)`.
//!
//! # Degenerate inputs
//! Every function refuses non-finite input, and (except [`cloude_eigenvalues`] and
//! [`is_physical`], which answer for any finite matrix) a negative intensity `I` or `M00`,
//! with [`Error::InvalidParameter`] naming `stokes` or `mueller`. Quantities that are
//! ratios to `I` or `M00` are `0` when `I = 0` or `M00 = 0` (nothing is transmitted, so
//! nothing is polarized). No function returns NaN: where a ratio has a zero denominator
//! and a non-zero numerator it is `inf`, as documented per function.
//!
//! # References
//! - S.-Y. Lu and R. A. Chipman, "Interpretation of Mueller matrices based on polar
//!   decomposition", J. Opt. Soc. Am. A 13, 1106 (1996).
//! - J. J. Gil and E. Bernabeu, "Depolarization and polarization indices of an optical
//!   system", Optica Acta 33, 185 (1986).
//! - S. R. Cloude, "Group theory and polarisation algebra", Optik 75, 26 (1986).
//! - G. G. Gimmestad, "Reexamination of depolarization in lidar measurements",
//!   Appl. Opt. 47, 3795 (2008); M. I. Mishchenko and J. W. Hovenier, Opt. Lett. 20,
//!   1356 (1995) (lidar depolarization ratios as Mueller-element ratios).

use nalgebra::{Matrix3, Matrix4, Vector3};

use super::fresnel::C64;
use super::mueller::Mat4;
use crate::error::{Error, Result};

/// A Stokes vector `(I, Q, U, V)` in the conventions of [`crate::optics`].
pub type Stokes = [f64; 4];

/// `1 - D` at or below which [`lu_chipman`] treats the diattenuator as ideal (`D = 1`).
///
/// Near `D = 1` the inverse of `M_D` amplifies rounding by `~1 / (1 - D)` while the
/// ideal-polarizer limit errs by `~sqrt(2 (1 - D))`; the two meet near `1e-11`.
pub const DIATTENUATION_ONE_TOL: f64 = 1e-11;

/// Singular values of the (M00-normalized) `m'` block at or below this, relative to
/// `max(1, sigma_max)`, count as zero in the polar decomposition of [`lu_chipman`].
pub const RANK_TOL: f64 = 1e-12;

// ---------------------------------------------------------------------------------------
// Input checks
// ---------------------------------------------------------------------------------------

fn check_stokes(s: &Stokes) -> Result<()> {
    if s.iter().any(|x| !x.is_finite()) || s[0] < 0.0 {
        return Err(Error::param(
            "stokes",
            format!("{s:?}"),
            "finite elements with I >= 0",
        ));
    }
    Ok(())
}

fn check_finite_mueller(m: &Mat4) -> Result<()> {
    if m.iter().flatten().any(|x| !x.is_finite()) {
        return Err(Error::param("mueller", format!("{m:?}"), "finite elements"));
    }
    Ok(())
}

fn check_mueller(m: &Mat4) -> Result<()> {
    check_finite_mueller(m)?;
    if m[0][0] < 0.0 {
        return Err(Error::param(
            "mueller",
            format!("{m:?}"),
            "finite elements with M00 >= 0",
        ));
    }
    Ok(())
}

/// `num / den` for a ratio of non-negative quantities: `0` for `0 / 0`.
fn ratio(num: f64, den: f64) -> f64 {
    if num == 0.0 && den == 0.0 {
        0.0
    } else {
        num / den
    }
}

// ---------------------------------------------------------------------------------------
// Stokes vectors
// ---------------------------------------------------------------------------------------

/// Degree of polarization `sqrt(Q^2 + U^2 + V^2) / I`; `0` when `I = 0`.
///
/// Errors: a non-finite element or `I < 0`. A non-physical vector (`|(Q,U,V)| > I`) gives
/// a value above 1.
pub fn dop(s: &Stokes) -> Result<f64> {
    check_stokes(s)?;
    Ok(if s[0] == 0.0 {
        0.0
    } else {
        s[1].hypot(s[2]).hypot(s[3]) / s[0]
    })
}

/// Degree of linear polarization `sqrt(Q^2 + U^2) / I`; `0` when `I = 0`.
pub fn dolp(s: &Stokes) -> Result<f64> {
    check_stokes(s)?;
    Ok(if s[0] == 0.0 {
        0.0
    } else {
        s[1].hypot(s[2]) / s[0]
    })
}

/// Degree of circular polarization `|V| / I` (unsigned; the handedness is `sign(V)`);
/// `0` when `I = 0`.
pub fn docp(s: &Stokes) -> Result<f64> {
    check_stokes(s)?;
    Ok(if s[0] == 0.0 { 0.0 } else { s[3].abs() / s[0] })
}

// ---------------------------------------------------------------------------------------
// Mueller matrices: vectors and scalar indices
// ---------------------------------------------------------------------------------------

/// Diattenuation vector `D = (M01, M02, M03) / M00` (Lu & Chipman eq. 9); zero when `M00 = 0`.
pub fn diattenuation_vector(m: &Mat4) -> Result<[f64; 3]> {
    check_mueller(m)?;
    let m00 = m[0][0];
    Ok(if m00 == 0.0 {
        [0.0; 3]
    } else {
        [m[0][1] / m00, m[0][2] / m00, m[0][3] / m00]
    })
}

/// Diattenuation `|D| = sqrt(M01^2 + M02^2 + M03^2) / M00`; `0` when `M00 = 0`.
pub fn diattenuation(m: &Mat4) -> Result<f64> {
    check_mueller(m)?;
    let m00 = m[0][0];
    Ok(if m00 == 0.0 {
        0.0
    } else {
        m[0][1].hypot(m[0][2]).hypot(m[0][3]) / m00
    })
}

/// Polarizance vector `P = (M10, M20, M30) / M00` (Lu & Chipman eq. 10): the Stokes
/// vector (over `I`) of the output for unpolarized input; zero when `M00 = 0`.
pub fn polarizance_vector(m: &Mat4) -> Result<[f64; 3]> {
    check_mueller(m)?;
    let m00 = m[0][0];
    Ok(if m00 == 0.0 {
        [0.0; 3]
    } else {
        [m[1][0] / m00, m[2][0] / m00, m[3][0] / m00]
    })
}

/// Polarizance `|P| = sqrt(M10^2 + M20^2 + M30^2) / M00`; `0` when `M00 = 0`.
pub fn polarizance(m: &Mat4) -> Result<f64> {
    check_mueller(m)?;
    let m00 = m[0][0];
    Ok(if m00 == 0.0 {
        0.0
    } else {
        m[1][0].hypot(m[2][0]).hypot(m[3][0]) / m00
    })
}

/// Gil-Bernabeu depolarization index
/// `DI = sqrt(sum_ij M_ij^2 - M00^2) / (sqrt(3) M00)`:
/// 1 for every non-depolarizing (pure) Mueller matrix, 0 for the ideal depolarizer
/// `diag(1, 0, 0, 0)`, in `[0, 1]` for every physical matrix. `0` when `M00 = 0`.
pub fn depolarization_index(m: &Mat4) -> Result<f64> {
    check_mueller(m)?;
    let m00 = m[0][0];
    if m00 == 0.0 {
        return Ok(0.0);
    }
    // The sum without M00^2 directly: no cancellation.
    let s: f64 = (0..16)
        .filter(|&k| k != 0)
        .map(|k| (m[k / 4][k % 4] / m00).powi(2))
        .sum();
    Ok((s / 3.0).sqrt())
}

/// Lidar linear depolarization ratio `delta_L = (M00 - M11) / (M00 + M11)`.
///
/// This is the ratio of cross- to co-polarized return, summed over horizontal and vertical
/// linear input in the matrix's frame: with horizontal input `(1, 1, 0, 0)` the
/// co-polarized (horizontal) output is `(M00 + M01 + M10 + M11) / 2` and the cross-polarized
/// (vertical) one `(M00 + M01 - M10 - M11) / 2`; adding the vertical-input counterparts
/// cancels `M01` and `M10`. When `M01 = M10 = 0` (no linear diattenuation or polarizance
/// along Q, e.g. any macroscopically isotropic target) it is exactly the cross/co ratio for
/// horizontal input. Mirror `diag(1, 1, -1, -1)`: 0; ideal depolarizer `diag(1, 0, 0, 0)`: 1.
/// `0` when `M00 = M11 = 0`, `inf` when only the co-polarized sum `M00 + M11` is 0.
pub fn linear_depolarization_ratio(m: &Mat4) -> Result<f64> {
    check_mueller(m)?;
    let (a, b) = (m[0][0], m[1][1]);
    let scale = a.abs().max(b.abs());
    if scale == 0.0 {
        return Ok(0.0);
    }
    let (a, b) = (a / scale, b / scale);
    Ok(ratio(a - b, a + b))
}

/// Lidar circular depolarization ratio `delta_C = (M00 + M33) / (M00 - M33)`.
///
/// In lidar usage the co-polarized circular return is the one a mirror gives. A mirror at
/// normal incidence is `diag(1, 1, -1, -1)` in the conventions of [`crate::optics`]: it flips
/// the sign of `V`. So for input `(1, 0, 0, +-1)` the co-polarized channel is the output's
/// opposite-`V` part `(I -+ V_out) / 2` and the cross-polarized one `(I +- V_out) / 2`;
/// summed over both input handednesses they are `M00 - M33` (co) and `M00 + M33` (cross),
/// whose ratio is `delta_C` (the `M03`, `M30` terms cancel; without them it is the cross/co
/// ratio for either handedness). Mirror: 0; ideal depolarizer `diag(1, 0, 0, 0)`: 1.
/// `0` when `M00 = M33 = 0`, `inf` when only the co-polarized sum `M00 - M33` is 0.
pub fn circular_depolarization_ratio(m: &Mat4) -> Result<f64> {
    check_mueller(m)?;
    let (a, b) = (m[0][0], m[3][3]);
    let scale = a.abs().max(b.abs());
    if scale == 0.0 {
        return Ok(0.0);
    }
    let (a, b) = (a / scale, b / scale);
    Ok(ratio(a + b, a - b))
}

// ---------------------------------------------------------------------------------------
// Cloude coherency matrix
// ---------------------------------------------------------------------------------------

/// Pauli matrices of [`crate::optics`] (`sigma_3 = [[0, i], [-i, 0]]`).
fn pauli(k: usize) -> [[C64; 2]; 2] {
    let (z, o, i) = (C64::new(0.0, 0.0), C64::new(1.0, 0.0), C64::new(0.0, 1.0));
    match k {
        0 => [[o, z], [z, o]],
        1 => [[o, z], [z, -o]],
        2 => [[z, o], [o, z]],
        _ => [[z, i], [-i, z]],
    }
}

/// Cloude coherency matrix `H = 1/4 sum_ij M_ij sigma_i (x) conj(sigma_j)`, row major,
/// Kronecker index `2 a + b`.
///
/// With the Mueller map of [`crate::optics::mueller::jones_to_mueller`],
/// `M_ij = 1/2 tr(sigma_i J sigma_j J^H)`, a pure matrix gives `H = 1/2 vec(J) vec(J)^H`
/// (`vec` row major), so `H` is Hermitian, `tr H = M00`, and `M` is a non-negative sum of
/// pure Mueller matrices exactly when `H` is positive semidefinite.
pub fn coherency_matrix(m: &Mat4) -> [[C64; 4]; 4] {
    let mut h = [[C64::new(0.0, 0.0); 4]; 4];
    for (i, row) in m.iter().enumerate() {
        let si = pauli(i);
        for (j, &mij) in row.iter().enumerate() {
            if mij == 0.0 {
                continue;
            }
            let sj = pauli(j);
            for a in 0..2 {
                for b in 0..2 {
                    for c in 0..2 {
                        for d in 0..2 {
                            h[2 * a + b][2 * c + d] += 0.25 * mij * si[a][c] * sj[b][d].conj();
                        }
                    }
                }
            }
        }
    }
    h
}

/// Eigenvalues of the Cloude coherency matrix ([`coherency_matrix`]), in descending order.
///
/// They sum to `M00`. `M` is physically realizable (a convex sum of non-depolarizing Mueller
/// matrices) when all are `>= 0`; a pure matrix has one non-zero eigenvalue `M00`, the ideal
/// depolarizer four equal ones `M00 / 4`. Errors: a non-finite element.
///
/// The matrix is scaled by a power of two near its largest element (exact) and elements
/// below 1e-100 of that are set to 0 first: they move the eigenvalues by at most 4e-100 of
/// the largest, but subnormal entries (a frame built from an azimuth of 1e-299 leaves
/// some) made the eigensolver return -4.4e-10 for a pure matrix (tests/test_extremes.py).
pub fn cloude_eigenvalues(m: &Mat4) -> Result<[f64; 4]> {
    check_finite_mueller(m)?;
    let big = m.iter().flatten().fold(0.0f64, |a, &x| a.max(x.abs()));
    if big == 0.0 {
        return Ok([0.0; 4]);
    }
    let scale = 2f64.powi((big.log2().round() as i32).clamp(-1000, 1000));
    let mut ms = *m;
    for x in ms.iter_mut().flatten() {
        *x = if x.abs() < 1e-100 * big {
            0.0
        } else {
            *x / scale
        };
    }
    let h = coherency_matrix(&ms);
    let hm = Matrix4::<C64>::from_fn(|r, c| h[r][c]);
    let ev = hm.symmetric_eigenvalues().map(|e| e * scale);
    let mut out = [ev[0], ev[1], ev[2], ev[3]];
    out.sort_by(|a, b| b.total_cmp(a));
    Ok(out)
}

/// Physical realizability: `M00 >= 0` and every Cloude eigenvalue `>= -tol * M00`.
///
/// Errors: a non-finite element, or `tol` negative or not finite.
pub fn is_physical(m: &Mat4, tol: f64) -> Result<bool> {
    if !tol.is_finite() || tol < 0.0 {
        return Err(Error::param("tol", tol, "finite and >= 0"));
    }
    let ev = cloude_eigenvalues(m)?;
    Ok(m[0][0] >= 0.0 && ev[3] >= -tol * m[0][0])
}

// ---------------------------------------------------------------------------------------
// Lu-Chipman polar decomposition
// ---------------------------------------------------------------------------------------

/// The three factors of the Lu-Chipman decomposition `M = m_delta m_r m_d`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LuChipman {
    /// Depolarizer `[[1, 0], [P_delta, m_delta]]` with symmetric `m_delta` (Lu & Chipman eq. 17).
    pub m_delta: Mat4,
    /// Retarder `[[1, 0], [0, m_R]]`, `m_R` a proper rotation (Lu & Chipman eq. 15).
    pub m_r: Mat4,
    /// Diattenuator `M00 [[1, D^T], [D, m_D]]`, `m_D = sqrt(1 - D^2) I + (1 - sqrt(1 - D^2)) D^ D^^T`
    /// (Lu & Chipman eqs. 12-13); it carries the transmittance `M00`.
    pub m_d: Mat4,
}

/// Lu-Chipman polar decomposition `M = M_delta M_R M_D` (diattenuator first, then
/// retarder, then depolarizer; Lu & Chipman 1996).
///
/// Regular case (`M00 > 0`, `1 - D > DIATTENUATION_ONE_TOL`): `M' = M M_D^-1 = M_delta M_R`
/// with `P_delta = (P - m D) / (1 - D^2)` and `m' = m_delta m_R` split by a polar
/// decomposition computed from the SVD `m' = U S W^T`: `m_R = U W^T` and
/// `m_delta = U S U^T = sqrt(m' m'^T)`, both negated when `det m' < 0` (Lu & Chipman's
/// sign rule, so that `m_R` stays a proper rotation). This reconstructs any finite `M` with
/// `D < 1`, physical or not.
///
/// Rank-deficient `m'` (singular values `<= RANK_TOL`, e.g. partial or total depolarizers):
/// `m_R` is not unique; we take, for rank 2, the unique proper rotation matching the two
/// non-zero singular pairs (the null singular vector's sign is flipped if needed, not the
/// whole matrix); for rank 1 the smallest rotation taking the right singular vector to the
/// left one; for rank 0 the identity. Then `m_delta = sym(m' m_R^T)`.
///
/// Limits:
/// - `M00 = 0`: `(I, I, 0)` (exact for the zero matrix, the only physical one with `M00 = 0`).
/// - `D >= 1 - DIATTENUATION_ONE_TOL` (ideal polarizer, `M_D` singular): `M_D` is its
///   `D -> 1` limit `M00 (1, D^)(1, D^)^T` with `D^ = D / |D|`; a physical such `M` is
///   `M00 (1, P)(1, D^)^T`, and we return `M_R` = the smallest rotation taking `D^` to
///   `P / |P|` (identity when `P = 0`) and `M_delta = diag(1, |P|, |P|, |P|)`. This
///   reconstructs `M` exactly when `M` is physical; otherwise it reconstructs
///   `M[.][0] (1, D^)^T`.
///
/// Errors: non-finite elements, `M00 < 0`, or `|M_ij| / M00` overflowing.
pub fn lu_chipman(m: &Mat4) -> Result<LuChipman> {
    check_mueller(m)?;
    let m00 = m[0][0];
    let ident = mat4_identity();
    if m00 == 0.0 {
        return Ok(LuChipman {
            m_delta: ident,
            m_r: ident,
            m_d: [[0.0; 4]; 4],
        });
    }
    let n = super::mueller::scale(m, 1.0 / m00);
    if n.iter().flatten().any(|x| !x.is_finite()) {
        return Err(Error::param(
            "mueller",
            format!("{m:?}"),
            "M_ij / M00 finite",
        ));
    }
    let dv = Vector3::new(n[0][1], n[0][2], n[0][3]);
    let pv = Vector3::new(n[1][0], n[2][0], n[3][0]);
    let d = dv.norm();

    let out = if 1.0 - d <= DIATTENUATION_ONE_TOL {
        // Ideal diattenuator limit.
        let dh = dv / d;
        let p = pv.norm();
        let rot = if p > 0.0 {
            smallest_rotation(&dh, &(pv / p))
        } else {
            Matrix3::identity()
        };
        let mut m_d = [[0.0; 4]; 4];
        let e = [1.0, dh[0], dh[1], dh[2]];
        for i in 0..4 {
            for j in 0..4 {
                m_d[i][j] = m00 * e[i] * e[j];
            }
        }
        let m_delta = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, p, 0.0, 0.0],
            [0.0, 0.0, p, 0.0],
            [0.0, 0.0, 0.0, p],
        ];
        LuChipman {
            m_delta,
            m_r: embed(None, &rot),
            m_d,
        }
    } else {
        // Diattenuator (eqs. 12-13), written without dividing by |D|:
        // m_D = a I + D D^T / (1 + a), a = sqrt(1 - D^2).
        let one_m_d2 = (1.0 - d) * (1.0 + d);
        let a = one_m_d2.sqrt();
        let ddt = dv * dv.transpose();
        let small_m_d = Matrix3::identity() * a + ddt / (1.0 + a);
        let mut m_d = [[0.0; 4]; 4];
        m_d[0][0] = m00;
        for i in 0..3 {
            m_d[0][i + 1] = m00 * dv[i];
            m_d[i + 1][0] = m00 * dv[i];
            for j in 0..3 {
                m_d[i + 1][j + 1] = m00 * small_m_d[(i, j)];
            }
        }
        // M' = n A^-1 with A = M_D / M00 = [[1, D^T], [D, m_D]]:
        // A^-1 = [[1, -D^T], [-D, (1 - D^2) S^-1]] / (1 - D^2), S^-1 = I / a + D D^T / (a^2 (1 + a)).
        let s_inv = Matrix3::identity() / a + ddt / (a * a * (1.0 + a));
        let mut a_inv = [[0.0; 4]; 4];
        a_inv[0][0] = 1.0 / one_m_d2;
        for i in 0..3 {
            a_inv[0][i + 1] = -dv[i] / one_m_d2;
            a_inv[i + 1][0] = -dv[i] / one_m_d2;
            for j in 0..3 {
                a_inv[i + 1][j + 1] = s_inv[(i, j)];
            }
        }
        let mp = super::mueller::matmul(&n, &a_inv);
        let p_delta = Vector3::new(mp[1][0], mp[2][0], mp[3][0]);
        let small_mp = Matrix3::from_fn(|i, j| mp[i + 1][j + 1]);
        let (m_delta_small, m_r_small) = polar(&small_mp);
        LuChipman {
            m_delta: embed(Some(&p_delta), &m_delta_small),
            m_r: embed(None, &m_r_small),
            m_d,
        }
    };
    let finite = |x: &Mat4| x.iter().flatten().all(|v| v.is_finite());
    if !(finite(&out.m_delta) && finite(&out.m_r) && finite(&out.m_d)) {
        return Err(Error::param(
            "mueller",
            format!("{m:?}"),
            "a matrix whose decomposition is finite",
        ));
    }
    Ok(out)
}

fn mat4_identity() -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    (0..4).for_each(|i| m[i][i] = 1.0);
    m
}

/// `[[1, 0], [col, block]]` (`col` is the first column below the corner, zero if `None`).
fn embed(col: Option<&Vector3<f64>>, block: &Matrix3<f64>) -> Mat4 {
    let mut m = mat4_identity();
    for i in 0..3 {
        if let Some(col) = col {
            m[i + 1][0] = col[i];
        }
        for j in 0..3 {
            m[i + 1][j + 1] = block[(i, j)];
        }
    }
    m
}

/// Polar decomposition `m' = m_delta m_R` with the conventions of [`lu_chipman`].
fn polar(mp: &Matrix3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    let svd = mp.svd(true, true);
    let (u, vt, s) = (svd.u.unwrap(), svd.v_t.unwrap(), svd.singular_values);
    let tol = RANK_TOL * s[0].max(1.0);
    let rank = s.iter().filter(|&&x| x > tol).count();
    let orient = u.determinant() * vt.determinant(); // +-1
    let m_r = match rank {
        3 => {
            // Lu & Chipman's sign rule: m_delta = sign(det m') sqrt(m' m'^T).
            u * vt * orient.signum()
        }
        2 => u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, orient.signum())) * vt,
        1 => smallest_rotation(&vt.row(0).transpose(), &u.column(0).into()),
        _ => Matrix3::identity(),
    };
    let x = mp * m_r.transpose();
    ((x + x.transpose()) * 0.5, m_r)
}

/// The rotation by the smallest angle taking unit `a` to unit `b` (about `a x b`); for
/// `b = -a`, the half turn about the axis perpendicular to `a` closest to the least-aligned
/// coordinate axis.
fn smallest_rotation(a: &Vector3<f64>, b: &Vector3<f64>) -> Matrix3<f64> {
    let c = a.dot(b);
    let k = a.cross(b);
    if 1.0 + c <= 1e-12 {
        let i = (0..3)
            .min_by(|&i, &j| a[i].abs().total_cmp(&a[j].abs()))
            .unwrap_or(0);
        let n = a.cross(&Vector3::ith(i, 1.0)).normalize();
        return n * n.transpose() * 2.0 - Matrix3::identity();
    }
    // Rodrigues with sin and cos folded in: R = c I + [k]x + k k^T / (1 + c).
    let kx = Matrix3::new(0.0, -k[2], k[1], k[2], 0.0, -k[0], -k[1], k[0], 0.0);
    Matrix3::identity() * c + kx + k * k.transpose() / (1.0 + c)
}

// ---------------------------------------------------------------------------------------
// Retardance
// ---------------------------------------------------------------------------------------

/// Retardance parameters of a retarder `M_R` (Lu & Chipman eqs. 19-20 and 25-27).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Retardance {
    /// Total retardance `R = acos(tr(M_R) / 2 - 1)` in `[0, pi]` (radians).
    pub total: f64,
    /// Linear retardance `delta = acos(sqrt((M_R11 + M_R22)^2 + (M_R21 - M_R12)^2) - 1)`
    /// in `[0, pi]` (radians).
    pub linear: f64,
    /// Optical rotation `psi = atan2(M_R21 - M_R12, M_R11 + M_R22) / 2` in `(-pi/2, pi/2]`
    /// (radians): `M_R = M_LR(delta) M_rot(psi)`, the rotator acting first, where
    /// `M_rot(psi)` turns the polarization ellipse by `psi` from `x` toward `y`
    /// (`Q` toward `U`), i.e. `mueller::rotator(-psi)`. `0` when `delta = pi`
    /// (undefined there).
    pub rotation: f64,
    /// Retardance vector `R a`: `a` is the fast axis on the Poincare sphere, `(1, 0, 0)`
    /// for a linear retarder with its fast axis along `x`. At `R = pi` the axis sign is
    /// ambiguous; we make its first non-zero component positive. Zero when `R = 0`.
    pub vector: [f64; 3],
}

/// Retardance parameters of the rotation block of a retarder Mueller matrix (`m_r` from
/// [`lu_chipman`]; its first row and column are ignored).
pub fn retarder_parameters(m_r: &Mat4) -> Retardance {
    let r = |i: usize, j: usize| m_r[i][j];
    let cos_r = ((r(1, 1) + r(2, 2) + r(3, 3) - 1.0) * 0.5).clamp(-1.0, 1.0);
    let total = cos_r.acos();
    let lin_arg = (r(1, 1) + r(2, 2)).hypot(r(2, 1) - r(1, 2)) - 1.0;
    let linear = lin_arg.clamp(-1.0, 1.0).acos();
    let rotation = 0.5 * (r(2, 1) - r(1, 2)).atan2(r(1, 1) + r(2, 2));
    // w = 2 sin(R) a (fast-axis sign checked against a retarder diag(1, e^{i delta}) in tests).
    let w = Vector3::new(r(2, 3) - r(3, 2), r(3, 1) - r(1, 3), r(1, 2) - r(2, 1));
    let axis = if total <= std::f64::consts::FRAC_PI_2 {
        let sin_r = total.sin();
        if sin_r > 0.0 {
            w / (2.0 * sin_r)
        } else {
            Vector3::zeros()
        }
    } else {
        // a a^T = (sym(m_R) - cos R I) / (1 - cos R): stable near R = pi.
        let sym = Matrix3::from_fn(|i, j| 0.5 * (r(i + 1, j + 1) + r(j + 1, i + 1)));
        let aat = (sym - Matrix3::identity() * cos_r) / (1.0 - cos_r);
        let k = (0..3)
            .max_by(|&i, &j| aat[(i, i)].total_cmp(&aat[(j, j)]))
            .unwrap_or(0);
        let mut a = aat.column(k).into_owned();
        let norm = a.norm();
        a /= if norm > 0.0 { norm } else { 1.0 };
        let dot = a.dot(&w);
        let first = a.iter().copied().find(|x| x.abs() > 1e-12).unwrap_or(1.0);
        if dot < -1e-12 || (dot.abs() <= 1e-12 && first < 0.0) {
            a = -a;
        }
        a
    };
    let v = axis * total;
    Retardance {
        total,
        linear,
        rotation,
        vector: [v[0], v[1], v[2]],
    }
}

/// Retardance of `M`: [`retarder_parameters`] of the `m_r` factor of [`lu_chipman`].
pub fn retardance(m: &Mat4) -> Result<Retardance> {
    Ok(retarder_parameters(&lu_chipman(m)?.m_r))
}

#[cfg(test)]
mod tests;
