//! Tests of the polarimetric decompositions (moved out of `polarimetry.rs`, unchanged).

use super::super::mueller::{jones_to_mueller, matmul, rotator, Jones};
use super::*;
use std::f64::consts::PI;

fn c(re: f64, im: f64) -> C64 {
    C64::new(re, im)
}

fn diag(d: [f64; 4]) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    (0..4).for_each(|i| m[i][i] = d[i]);
    m
}

fn max_diff(a: &Mat4, b: &Mat4) -> f64 {
    (0..16)
        .map(|k| (a[k / 4][k % 4] - b[k / 4][k % 4]).abs())
        .fold(0.0, f64::max)
}

fn reconstruct(lc: &LuChipman) -> Mat4 {
    matmul(&lc.m_delta, &matmul(&lc.m_r, &lc.m_d))
}

/// Jones matrix of a field rotation by `t` (x toward y).
fn jrot(t: f64) -> Jones {
    let (s, co) = t.sin_cos();
    [[c(co, 0.0), c(-s, 0.0)], [c(s, 0.0), c(co, 0.0)]]
}

fn jmul(a: &Jones, b: &Jones) -> Jones {
    let mut m = [[c(0.0, 0.0); 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            m[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
        }
    }
    m
}

/// Element at fast-axis angle `theta` (field frame rotated): R(theta) J R(-theta).
fn at_angle(j: &Jones, theta: f64) -> Mat4 {
    jones_to_mueller(&jmul(&jrot(theta), &jmul(j, &jrot(-theta))))
}

fn polarizer() -> Jones {
    [[c(1.0, 0.0), c(0.0, 0.0)], [c(0.0, 0.0), c(0.0, 0.0)]]
}

/// Fast axis along x, y delayed by `delta` (exp(-i omega t) convention).
fn retarder(delta: f64) -> Jones {
    [
        [c(1.0, 0.0), c(0.0, 0.0)],
        [c(0.0, 0.0), C64::from_polar(1.0, delta)],
    ]
}

/// A small deterministic generator (SplitMix64) for the randomized tests.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
    fn jones(&mut self) -> Jones {
        let mut j = [[c(0.0, 0.0); 2]; 2];
        j.iter_mut()
            .flatten()
            .for_each(|x| *x = c(self.next(), self.next()));
        j
    }
    /// A physical Mueller matrix: a positive sum of `k` pure ones.
    fn physical(&mut self, k: usize) -> Mat4 {
        let mut m = [[0.0; 4]; 4];
        for _ in 0..k {
            let w = self.next().abs() + 0.1;
            let p = jones_to_mueller(&self.jones());
            for i in 0..4 {
                for jj in 0..4 {
                    m[i][jj] += w * p[i][jj];
                }
            }
        }
        m
    }
}

#[test]
fn stokes_degrees() {
    let s = [2.0, 0.6, 0.8, -1.0];
    assert!((dop(&s).unwrap() - (2.0f64).sqrt() / 2.0).abs() < 1e-15);
    assert!((dolp(&s).unwrap() - 0.5).abs() < 1e-15);
    assert!((docp(&s).unwrap() - 0.5).abs() < 1e-15);
    for f in [dop, dolp, docp] {
        assert_eq!(f(&[0.0; 4]).unwrap(), 0.0);
        assert!(f(&[1.0, f64::NAN, 0.0, 0.0]).is_err());
        assert!(f(&[-1.0, 0.0, 0.0, 0.0]).is_err());
    }
}

#[test]
fn ideal_linear_polarizer() {
    for theta in [0.0, 0.3, PI / 4.0, 1.2, PI / 2.0] {
        let m = at_angle(&polarizer(), theta);
        assert!((diattenuation(&m).unwrap() - 1.0).abs() < 1e-14);
        assert!((polarizance(&m).unwrap() - 1.0).abs() < 1e-14);
        assert!((depolarization_index(&m).unwrap() - 1.0).abs() < 1e-14);
        let dv = diattenuation_vector(&m).unwrap();
        assert!((dv[0] - (2.0 * theta).cos()).abs() < 1e-14);
        assert!((dv[1] - (2.0 * theta).sin()).abs() < 1e-14);
        assert!(is_physical(&m, 1e-9).unwrap());
        // D = 1 limit of the decomposition: M_delta = M_R = identity.
        let lc = lu_chipman(&m).unwrap();
        assert!(max_diff(&reconstruct(&lc), &m) < 1e-14);
        assert!(max_diff(&lc.m_delta, &mat4_identity()) < 1e-14);
        assert!(max_diff(&lc.m_r, &mat4_identity()) < 1e-14);
        assert!(max_diff(&lc.m_d, &m) < 1e-14);
    }
}

#[test]
fn polarizer_then_quarter_wave_plate() {
    // x polarizer followed by a quarter-wave plate at 45 degrees: circular output.
    let j = jmul(
        &jmul(
            &jrot(PI / 4.0),
            &jmul(&retarder(PI / 2.0), &jrot(-PI / 4.0)),
        ),
        &polarizer(),
    );
    let m = jones_to_mueller(&j);
    let lc = lu_chipman(&m).unwrap();
    assert!(max_diff(&reconstruct(&lc), &m) < 1e-14);
    let r = retarder_parameters(&lc.m_r);
    assert!((r.total - PI / 2.0).abs() < 1e-12);
}

#[test]
fn linear_retarder() {
    for (delta, theta) in [
        (0.3, 0.0),
        (1.0, 0.4),
        (PI / 2.0, PI / 4.0),
        (2.5, -0.7),
        (3.0, 1.1),
    ] {
        let m = at_angle(&retarder(delta), theta);
        assert!(diattenuation(&m).unwrap() < 1e-15);
        assert!(polarizance(&m).unwrap() < 1e-15);
        assert!((depolarization_index(&m).unwrap() - 1.0).abs() < 1e-14);
        let lc = lu_chipman(&m).unwrap();
        assert!(max_diff(&lc.m_r, &m) < 1e-13);
        assert!(max_diff(&lc.m_delta, &mat4_identity()) < 1e-13);
        let r = retardance(&m).unwrap();
        assert!((r.total - delta).abs() < 1e-12, "{r:?}");
        assert!((r.linear - delta).abs() < 1e-7, "{r:?}");
        assert!(r.rotation.abs() < 1e-12);
        // Fast axis on the Poincare sphere at longitude 2 theta on the equator.
        let want = [
            delta * (2.0 * theta).cos(),
            delta * (2.0 * theta).sin(),
            0.0,
        ];
        for k in 0..3 {
            assert!((r.vector[k] - want[k]).abs() < 1e-12, "{r:?} want {want:?}");
        }
    }
}

#[test]
fn half_wave_retarder_axis() {
    let m = at_angle(&retarder(PI), 0.3);
    let r = retardance(&m).unwrap();
    assert!((r.total - PI).abs() < 1e-7);
    let want = [PI * 0.6f64.cos(), PI * 0.6f64.sin(), 0.0];
    assert!(
        r.vector.iter().zip(want).all(|(v, w)| (v - w).abs() < 1e-7),
        "{r:?}"
    );
}

#[test]
fn rotator_is_circular_retarder() {
    for psi in [0.2, -0.5, 1.0] {
        // Field rotation by psi; its Mueller matrix is the basis rotator(-psi).
        let m = jones_to_mueller(&jrot(psi));
        assert!(max_diff(&m, &rotator(-psi)) < 1e-15);
        let r = retardance(&m).unwrap();
        assert!((r.total - 2.0 * psi.abs()).abs() < 1e-12);
        assert!(r.linear.abs() < 1e-7);
        assert!((r.rotation - psi).abs() < 1e-12, "{r:?}");
        // Rotation about V.
        assert!(r.vector[0].abs() < 1e-12 && r.vector[1].abs() < 1e-12);
        assert!((r.vector[2].abs() - 2.0 * psi.abs()).abs() < 1e-12);
    }
}

#[test]
fn elliptical_retarder_parts() {
    // Linear retarder (delta, theta) after a rotator psi.
    let (delta, theta, psi) = (0.9, 0.35, 0.25);
    let m = matmul(
        &at_angle(&retarder(delta), theta),
        &jones_to_mueller(&jrot(psi)),
    );
    let r = retardance(&m).unwrap();
    assert!((r.linear - delta).abs() < 1e-10, "{r:?}");
    assert!((r.rotation - psi).abs() < 1e-12, "{r:?}");
}

#[test]
fn ideal_depolarizer() {
    let m = diag([1.0, 0.0, 0.0, 0.0]);
    assert_eq!(depolarization_index(&m).unwrap(), 0.0);
    assert_eq!(linear_depolarization_ratio(&m).unwrap(), 1.0);
    assert_eq!(circular_depolarization_ratio(&m).unwrap(), 1.0);
    let ev = cloude_eigenvalues(&m).unwrap();
    assert!(ev.iter().all(|x| (x - 0.25).abs() < 1e-15));
    let lc = lu_chipman(&m).unwrap();
    assert_eq!(lc.m_r, mat4_identity());
    assert!(max_diff(&lc.m_delta, &m) < 1e-15);
    assert!(max_diff(&lc.m_d, &mat4_identity()) < 1e-15);
    assert_eq!(retardance(&m).unwrap().total, 0.0);
}

#[test]
fn mirror() {
    let m = diag([1.0, 1.0, -1.0, -1.0]);
    assert_eq!(depolarization_index(&m).unwrap(), 1.0);
    assert_eq!(linear_depolarization_ratio(&m).unwrap(), 0.0);
    assert_eq!(circular_depolarization_ratio(&m).unwrap(), 0.0);
    let r = retardance(&m).unwrap();
    assert!((r.total - PI).abs() < 1e-15);
    assert!((r.linear - PI).abs() < 1e-15);
    assert_eq!(r.vector, [PI, 0.0, 0.0]);
    let ev = cloude_eigenvalues(&m).unwrap();
    assert!((ev[0] - 1.0).abs() < 1e-15 && ev[1..].iter().all(|x| x.abs() < 1e-15));
}

#[test]
fn depolarization_ratios_from_channels() {
    // Cross/co for H input plus V input, and for both circular handednesses.
    let mut rng = Rng(7);
    for _ in 0..20 {
        let m = rng.physical(3);
        let out = |s: [f64; 4]| -> [f64; 4] {
            let mut o = [0.0; 4];
            (0..4).for_each(|i| o[i] = (0..4).map(|k| m[i][k] * s[k]).sum());
            o
        };
        let (h, v) = (out([1.0, 1.0, 0.0, 0.0]), out([1.0, -1.0, 0.0, 0.0]));
        let co = (h[0] + h[1]) / 2.0 + (v[0] - v[1]) / 2.0;
        let cross = (h[0] - h[1]) / 2.0 + (v[0] + v[1]) / 2.0;
        assert!((linear_depolarization_ratio(&m).unwrap() - cross / co).abs() < 1e-12);
        // Co-polarized circular = what a mirror returns = opposite sign of V.
        let (r, l) = (out([1.0, 0.0, 0.0, 1.0]), out([1.0, 0.0, 0.0, -1.0]));
        let co = (r[0] - r[3]) / 2.0 + (l[0] + l[3]) / 2.0;
        let cross = (r[0] + r[3]) / 2.0 + (l[0] - l[3]) / 2.0;
        assert!((circular_depolarization_ratio(&m).unwrap() - cross / co).abs() < 1e-12);
    }
}

#[test]
fn ratios_degenerate() {
    // Half-wave plate at 45 degrees turns H into V: no co-polarized return.
    let hwp = diag([1.0, -1.0, 1.0, -1.0]);
    assert_eq!(linear_depolarization_ratio(&hwp).unwrap(), f64::INFINITY);
    let z = [[0.0; 4]; 4];
    assert_eq!(linear_depolarization_ratio(&z).unwrap(), 0.0);
    assert_eq!(circular_depolarization_ratio(&z).unwrap(), 0.0);
    assert_eq!(
        circular_depolarization_ratio(&mat4_identity()).unwrap(),
        f64::INFINITY
    );
    let big = scale_all(&diag([1.0, 0.5, 0.5, 0.5]), 1e308);
    assert!((linear_depolarization_ratio(&big).unwrap() - 1.0 / 3.0).abs() < 1e-15);
}

fn scale_all(m: &Mat4, s: f64) -> Mat4 {
    super::super::mueller::scale(m, s)
}

#[test]
fn zero_matrix() {
    let z = [[0.0; 4]; 4];
    assert_eq!(diattenuation(&z).unwrap(), 0.0);
    assert_eq!(polarizance(&z).unwrap(), 0.0);
    assert_eq!(depolarization_index(&z).unwrap(), 0.0);
    assert_eq!(diattenuation_vector(&z).unwrap(), [0.0; 3]);
    let lc = lu_chipman(&z).unwrap();
    assert_eq!(reconstruct(&lc), z);
    assert!(is_physical(&z, 1e-9).unwrap());
    assert_eq!(cloude_eigenvalues(&z).unwrap(), [0.0; 4]);
}

#[test]
fn errors() {
    let mut m = mat4_identity();
    m[2][3] = f64::INFINITY;
    assert!(lu_chipman(&m).is_err());
    assert!(cloude_eigenvalues(&m).is_err());
    assert!(diattenuation(&m).is_err());
    let neg = diag([-1.0, 0.0, 0.0, 0.0]);
    assert!(depolarization_index(&neg).is_err());
    assert!(!is_physical(&neg, 1e-9).unwrap());
    assert!(is_physical(&mat4_identity(), -1.0).is_err());
    assert!(is_physical(&mat4_identity(), f64::NAN).is_err());
    let e = lu_chipman(&m).unwrap_err().to_string();
    assert!(e.contains("mueller"), "{e}");
}

#[test]
fn random_physical_decomposition() {
    let mut rng = Rng(12345);
    for k in [1, 2, 3, 4, 6] {
        for _ in 0..200 {
            let m = rng.physical(k);
            let lc = lu_chipman(&m).unwrap();
            let err = max_diff(&reconstruct(&lc), &m) / m[0][0];
            assert!(err < 1e-12, "k={k} err={err}");
            // Factors have their documented structure.
            let (md, mr) = (lc.m_delta, lc.m_r);
            assert_eq!(md[0], [1.0, 0.0, 0.0, 0.0]);
            let sym = Matrix3::from_fn(|i, j| md[i + 1][j + 1]);
            assert!((sym - sym.transpose()).abs().max() < 1e-13);
            let rt = Matrix3::from_fn(|i, j| mr[i + 1][j + 1]);
            assert!((rt * rt.transpose() - Matrix3::identity()).abs().max() < 1e-12);
            assert!((rt.determinant() - 1.0).abs() < 1e-12);
            assert!(is_physical(&m, 1e-9).unwrap());
            let di = depolarization_index(&m).unwrap();
            assert!((0.0..=1.0 + 1e-12).contains(&di));
            if k == 1 {
                assert!((di - 1.0).abs() < 1e-12);
                let ev = cloude_eigenvalues(&m).unwrap();
                assert!((ev[0] - m[0][0]).abs() < 1e-12 * m[0][0]);
                assert!(ev[1..].iter().all(|x| x.abs() < 1e-12 * m[0][0]));
            }
        }
    }
}

#[test]
fn coherency_of_pure_matrix_is_vec_j() {
    let mut rng = Rng(99);
    let j = rng.jones();
    let h = coherency_matrix(&jones_to_mueller(&j));
    let v = [j[0][0], j[0][1], j[1][0], j[1][1]];
    for r in 0..4 {
        for cc in 0..4 {
            let want = 0.5 * v[r] * v[cc].conj();
            assert!((h[r][cc] - want).norm() < 1e-14, "{r} {cc}");
        }
    }
}

#[test]
fn non_physical_detected() {
    // diag(1, 1, 1, -1) is the transpose-like "V flip" with no Jones realization.
    assert!(!is_physical(&diag([1.0, 1.0, 1.0, -1.0]), 1e-9).unwrap());
    assert!(!is_physical(&diag([1.0, 1.0, 0.5, 0.4]), 1e-9).unwrap());
    // diag(1, 1, 0, 0), the mean of the identity and the mirror, is physical.
    assert!(is_physical(&diag([1.0, 1.0, 0.0, 0.0]), 1e-9).unwrap());
    let mut m = mat4_identity();
    m[0][1] = 1.5; // D > 1
    assert!(!is_physical(&m, 1e-9).unwrap());
    assert!(is_physical(&diag([1.0, 0.5, 0.5, 0.5]), 1e-9).unwrap());
}

#[test]
fn rank_deficient_and_near_polarizer() {
    // Partial depolarizers of rank 2 and 1 in m', with a mirror-like sign.
    for d in [
        [1.0, 0.6, -0.4, 0.0],
        [1.0, 0.5, 0.0, 0.0],
        [1.0, 0.0, 0.0, -0.3],
    ] {
        let m = matmul(&diag(d), &at_angle(&retarder(0.7), 0.2));
        let lc = lu_chipman(&m).unwrap();
        assert!(max_diff(&reconstruct(&lc), &m) < 1e-13, "{d:?}");
        let rt = Matrix3::from_fn(|i, j| lc.m_r[i + 1][j + 1]);
        assert!((rt.determinant() - 1.0).abs() < 1e-12);
    }
    // Partial polarizer approaching D = 1 on both sides of the switch.
    // Jones diag(1, q) has 1 - D = 2 q^2 / (1 + q^2).
    for eps in [1e-6, 1e-9, 1e-10, 1e-12, 0.0] {
        let q = (eps / 2.0f64).sqrt();
        let j = [[c(1.0, 0.0), c(0.0, 0.0)], [c(0.0, 0.0), c(q, 0.0)]];
        let m = jones_to_mueller(&jmul(&retarder(0.4), &j));
        let lc = lu_chipman(&m).unwrap();
        let err = max_diff(&reconstruct(&lc), &m);
        assert!(err < 1e-5, "eps={eps} err={err}");
    }
}

#[test]
fn cloude_eigenvalues_ignore_subnormal_noise() {
    // The single-term BRDF of m = 0, eta = 0.1 at wi theta 1, azimuth 7.47e-300, wo = n
    // (tests/test_extremes.py, found by hypothesis): a pure matrix whose frame left
    // subnormal off-diagonal elements. The eigensolver returned -4.4e-10 M00 for it.
    let mut m = [[0.0; 4]; 4];
    m[0][0] = 0.10332708211196062;
    m[1][1] = 0.10332708211196062;
    m[2][2] = -0.054181134688168535;
    m[3][3] = -0.054181134688168535;
    m[2][3] = -0.08798233084929265;
    m[3][2] = 0.08798233084929265;
    m[0][1] = 5.73580528e-17;
    m[1][0] = 5.73580528e-17;
    m[1][2] = 2.50620886e-316;
    m[1][3] = -2.33372669e-316;
    m[2][0] = 8.79662144e-318;
    m[2][1] = -6.72984010e-317;
    m[3][0] = -1.42844408e-317;
    m[3][1] = -3.35774562e-316;
    m[0][2] = -1.67757520e-317;
    let ev = cloude_eigenvalues(&m).unwrap();
    assert!(ev[3] >= -1e-15 * m[0][0], "{ev:?}");
    assert!((ev.iter().sum::<f64>() - m[0][0]).abs() < 1e-15);
    // the same at any scale (the power-of-two scaling is exact)
    for s in [1e-300, 1e300] {
        let ms = m.map(|r| r.map(|x| x * s));
        let es = cloude_eigenvalues(&ms).unwrap();
        assert!(es[3] >= -1e-15 * ms[0][0], "{s}: {es:?}");
    }
}
