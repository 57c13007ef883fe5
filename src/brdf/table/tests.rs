//! The table's tests (one module, so their paths are `brdf::table::tests::*` as before
//! the split into submodules).

use super::build::part_reference;
use super::*;
use crate::brdf::material::Material;
use crate::microfacet::masking::ZTable;
use crate::microfacet::Distribution;
use crate::optics::frames::{normalize, V3};
use crate::optics::fresnel::{Eta, C64};
use std::f64::consts::{FRAC_PI_2, PI};

fn material(dist: Distribution, eta: C64, double: bool, order: usize) -> Material {
    let mut spec = super::super::MaterialSpec::new(dist, Eta::Complex(eta));
    spec.terms.double = double;
    spec.double_order = order;
    Material::new(spec).unwrap()
}

fn rel_diff(a: &Mat4, b: &Mat4) -> f64 {
    let mut e: f64 = 0.0;
    for r in 0..4 {
        for c in 0..4 {
            e = e.max((a[r][c] - b[r][c]).abs());
        }
    }
    e / b[0][0].abs().max(1e-300)
}

/// The single term as the kernel evaluates it (in f64: [`SingleParams::eval`]) equals
/// the core's single term for the default tabulated APS masking (the same excess
/// table), to rounding, over random pairs with grazing ones among them, and through
/// `eval_masked` (the twin's path) in the bisector frame; for the Smith closed forms
/// and the seed's, whose excess it interpolates on 512 nodes, to 1e-6 of M00 (the seed's:
/// 5e-6, measured 1.4e-6, against the closed form's own 1.5e-3 RMS, docs/tradeoff.md).
#[test]
fn single_params_equal_the_core_single_term() {
    use crate::microfacet::{MaskingEval, Shadowing};
    let mut rng = crate::reference::rng::Rng::new(11, &[]);
    let mut u = || rng.uniform();
    let cases: Vec<(Distribution, Eta, Shadowing, MaskingEval, f64)> = vec![
        (
            Distribution::Beckmann { alpha: 0.3 },
            Eta::new(0.2, 3.4),
            Shadowing::Aps,
            MaskingEval::Table,
            1e-12,
        ),
        (
            Distribution::Ggx { alpha: 1e-3 },
            Eta::new(1.0 + 1e-6, 0.0),
            Shadowing::Aps,
            MaskingEval::Table,
            1e-12,
        ),
        (
            Distribution::BlinnPhong { m: 5000.0 },
            Eta::new(1e3, 1e3),
            Shadowing::Aps,
            MaskingEval::Table,
            1e-12,
        ),
        (
            Distribution::Ggx { alpha: 10.0 },
            Eta::PerfectConductor,
            Shadowing::Aps,
            MaskingEval::Table,
            1e-12,
        ),
        (
            Distribution::Ggx { alpha: 0.5 },
            Eta::new(1.5, 0.0),
            Shadowing::Smith,
            MaskingEval::Table,
            1e-6,
        ),
        (
            Distribution::Beckmann { alpha: 0.5 },
            Eta::new(1.5, 0.0),
            Shadowing::Smith,
            MaskingEval::Table,
            1e-6,
        ),
        (
            Distribution::BlinnPhong { m: 20.0 },
            Eta::new(1.5, 0.0),
            Shadowing::Aps,
            MaskingEval::Seed,
            5e-6,
        ),
    ];
    for (dist, eta, shadowing, masking, tol) in cases {
        let mut spec = super::super::MaterialSpec::new(dist, eta);
        spec.shadowing = shadowing;
        spec.masking = masking;
        spec.terms.multiple = false;
        let mat = Material::new(spec).unwrap();
        let sp = SingleParams::new(&mat);
        let mut worst: f64 = 0.0;
        for k in 0..400 {
            // every fourth pair has a direction within 1e-7 .. 1e-2 rad of grazing
            let dir = |a: f64, b: f64, grazing: bool| {
                let th = if grazing {
                    FRAC_PI_2 - 10f64.powf(-7.0 + 5.0 * a)
                } else {
                    a * FRAC_PI_2
                };
                let ph = 2.0 * PI * b;
                V3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos())
            };
            let wi = dir(u(), u(), k % 4 == 0);
            let wo = dir(u(), u(), k % 8 == 1);
            let want = super::super::eval(&mat, wi, wo, Frame::Sp);
            let got = sp.eval(wi, wo, beam_bases(Frame::Sp, wi, wo));
            assert!(got.iter().flatten().all(|x| x.is_finite()));
            if want[0][0] > 1e-300 {
                worst = worst.max(rel_diff(&got, &want));
            }
        }
        assert!(worst < tol, "{dist:?} {shadowing:?} {masking:?}: {worst:e}");
        // through the table's lookup (bisector frame), bistatic
        let beta = 0.3;
        let opts = BrdfTableOptions {
            in_shader: true,
            ..Default::default()
        };
        let t = BrdfTable::build(&mat, beta, &opts).unwrap();
        assert!(t.parts.is_empty());
        for (theta, psi) in [(0.2f64, 0.5f64), (1.2, -2.0), (1.5, 3.0)] {
            let (wi, wo) = table_dirs(beta, theta, psi.abs());
            let mut want = part_reference(
                &mat,
                PartKind::Single,
                TableFrame::Bisector,
                beta,
                theta,
                psi.abs(),
            );
            if psi < 0.0 {
                want = mirror(&want);
            }
            let got = t.eval(theta, psi);
            assert!(
                rel_diff(&got, &want) < tol,
                "{dist:?}: ({theta}, {psi}) {wi:?} {wo:?}"
            );
        }
    }
}

fn rotz(v: V3, phi: f64) -> V3 {
    let (s, c) = phi.sin_cos();
    V3::new(c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])
}

#[test]
fn nodes_equal_direct_evaluation() {
    let mat = material(
        Distribution::Beckmann { alpha: 0.3 },
        C64::new(0.2, 3.4),
        true,
        12,
    );
    for (beta, frame) in [
        (0.0, TableFrame::Bisector),
        (0.05, TableFrame::Bisector),
        (0.05, TableFrame::Sp),
    ] {
        let grid = |n_z| PartOptions {
            n_z: Some(n_z),
            n_psi: Some(4),
            scale: Some(1.5),
        };
        let opts = BrdfTableOptions {
            single: grid(8),
            depolarizing: grid(12),
            double: grid(4),
            double_order: Some(12),
            frame: Some(frame),
            in_shader: false,
        };
        let t = BrdfTable::build(&mat, beta, &opts).unwrap();
        assert_eq!(t.parts.len(), 3);
        let n_psi = if beta > 0.0 { 4 } else { 0 };
        for j in 0..=n_psi {
            for i in 1..=4 {
                // nodes common to both parts (z = i/4 of the coarse grid, same scale)
                let theta = ZTable::theta_of_z(1.5, i as f64 / 4.0);
                let psi = if n_psi == 0 {
                    0.0
                } else {
                    j as f64 * PI / n_psi as f64
                };
                let (wi, wo) = table_dirs(beta, theta, psi);
                let want = super::super::eval(&mat, wi, wo, Frame::Sp);
                // rotated about n (except at theta = 0, where psi is measured from
                // the x axis), and through the public entry point
                let phi = if i == 4 { 0.0 } else { 0.7 + i as f64 };
                let got = t.eval_dirs(rotz(wi, phi), rotz(wo, phi));
                let e = rel_diff(&got, &want);
                assert!(e < 1e-10, "beta {beta} {frame:?} node ({j}, {i}): {e}");
            }
        }
    }
}

#[test]
fn mirror_relation_holds_for_the_material() {
    let mat = material(
        Distribution::Beckmann { alpha: 0.3 },
        C64::new(0.2, 3.4),
        true,
        16,
    );
    let mut worst: f64 = 0.0;
    for beta in [0.01, 0.2, 1.0] {
        for theta in [0.0, 0.004, 0.3, 1.0, 1.3] {
            for psi in [0.3, 1.2, 2.0, 3.0] {
                let (wi, wo) = table_dirs(beta, theta, psi);
                let (wi2, wo2) = table_dirs(beta, theta, -psi);
                // mirror image of the pair
                assert!((wi2[1] + wi[1]).abs() < 1e-15 && (wi2[0] - wi[0]).abs() < 1e-15);
                for frame in [TableFrame::Sp, TableFrame::Bisector] {
                    let to = |wi, wo| {
                        change_bases(
                            &super::super::eval(&mat, wi, wo, Frame::Sp),
                            beam_bases(Frame::Sp, wi, wo),
                            table_bases(frame, wi, wo),
                        )
                    };
                    let (m, m2) = (to(wi, wo), to(wi2, wo2));
                    if m[0][0] > 0.0 {
                        worst = worst.max(rel_diff(&mirror(&m), &m2));
                    }
                }
            }
        }
    }
    assert!(worst < 1e-12, "{worst}");
}

#[test]
fn table_coords_round_trip() {
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..2000 {
        let beta = 1.5 * rnd();
        let theta = FRAC_PI_2 * rnd();
        let psi = PI * (2.0 * rnd() - 1.0);
        let phi = 2.0 * PI * rnd();
        let (wi, wo) = table_dirs(beta, theta, psi);
        let (wi, wo) = (rotz(wi, phi), rotz(wo, phi));
        let (t, p, mirrored) = table_coords(beta, wi, wo);
        assert!((t - theta).abs() < 1e-12, "{theta} {t}");
        let p_signed = if mirrored { -p } else { p };
        assert!(
            (p_signed - psi).abs() < 1e-9 || theta < 1e-9,
            "{beta} {theta} {psi}: {p_signed}"
        );
        let (a, b) = table_dirs(beta, t, p_signed);
        let (a, b) = (rotz(a, phi), rotz(b, phi));
        for k in 0..3 {
            assert!((a[k] - wi[k]).abs() < 1e-9 && (b[k] - wo[k]).abs() < 1e-9);
        }
    }
    // theta = 0: psi is measured from the x axis (azimuth of b taken as 0)
    let (wi, wo) = table_dirs(0.2, 0.0, 1.0);
    let (t, p, m) = table_coords(0.2, wi, wo);
    assert!(t == 0.0 && (p - 1.0).abs() < 1e-12 && !m);
    // beta = 0
    let w = normalize(V3::new(0.3, -0.2, 0.8));
    let (t, p, m) = table_coords(0.0, w, w);
    assert!((t - 0.3f64.hypot(0.2).atan2(0.8)).abs() < 1e-14 && p == 0.0 && !m);
    let n = V3::Z;
    assert_eq!(table_coords(0.0, n, n), (0.0, 0.0, false));
    assert_eq!(table_coords(0.1, n, n), (0.0, 0.0, false));
}

#[test]
fn catmull_rom_matches_ztable() {
    let zt = ZTable {
        scale: 0.7,
        values: (0..=9)
            .map(|i| (i as f64 * 0.37).sin() + 0.1 * i as f64)
            .collect(),
    };
    let part = TablePart {
        scale: 0.7,
        cos_weighted: false,
        n_z: 9,
        n_psi: 0,
        data: zt
            .values
            .iter()
            .flat_map(|&v| {
                let mut a = [0.0; 16];
                a[0] = v;
                a[5] = 0.1 * v;
                a
            })
            .collect(),
    };
    for q in 0..=100 {
        let z = q as f64 / 100.0;
        let v = eval_part(&part, z, 0.0);
        assert!((v[0] - zt.eval_z_bounded(z)).abs() < 1e-15);
        assert!((v[5] - 0.1 * zt.eval_z(z)).abs() < 1e-15);
    }
}

#[test]
fn interpolation_error_small_for_a_smooth_material() {
    let mat = material(
        Distribution::Beckmann { alpha: 0.5 },
        C64::new(1.5, 0.0),
        false,
        16,
    );
    let t = BrdfTable::build(&mat, 2f64.to_radians(), &BrdfTableOptions::default()).unwrap();
    let e = t.max_error(&mat, 85f64.to_radians(), DYNAMIC_RANGE);
    assert_eq!(e.parts.len(), 2);
    assert!(e.max < 1e-4, "{e:?}");
    let t = BrdfTable::build(&mat, 0.0, &BrdfTableOptions::default()).unwrap();
    let e = t.max_error(&mat, 85f64.to_radians(), DYNAMIC_RANGE);
    // measured 2.5e-5 (the multiple term; the single term 2.6e-7)
    assert!(e.max < 5e-5, "{e:?}");
}

#[test]
fn bad_options_are_rejected() {
    let mat = material(
        Distribution::Beckmann { alpha: 0.5 },
        C64::new(1.5, 0.0),
        false,
        16,
    );
    let b = |beta: f64, o: BrdfTableOptions| BrdfTable::build(&mat, beta, &o).unwrap_err();
    assert!(b(-0.1, Default::default())
        .to_string()
        .contains("bistatic_angle"));
    assert!(b(FRAC_PI_2, Default::default())
        .to_string()
        .contains("bistatic_angle"));
    assert!(b(f64::NAN, Default::default())
        .to_string()
        .contains("bistatic_angle"));
    let o = BrdfTableOptions {
        single: PartOptions {
            n_z: Some(3),
            ..Default::default()
        },
        ..Default::default()
    };
    assert!(b(0.0, o).to_string().contains("n_z"));
    let o = BrdfTableOptions {
        single: PartOptions {
            n_psi: Some(1),
            ..Default::default()
        },
        ..Default::default()
    };
    assert!(b(0.1, o).to_string().contains("n_psi"));
    let o = BrdfTableOptions {
        depolarizing: PartOptions {
            scale: Some(0.0),
            ..Default::default()
        },
        ..Default::default()
    };
    assert!(b(0.1, o).to_string().contains("scale_lambertian"));
    let o = BrdfTableOptions {
        double_order: Some(2),
        ..Default::default()
    };
    assert!(b(0.1, o).to_string().contains("double_order"));
}

/// Exploration: `TABLE_EXPLORE="dist alpha eta_re eta_im double beta_deg
/// [n_z n_psi scale]x3 (single, depolarizing, double; 0 = default) order frame; ..."`
/// (frame: sp|bis).
#[test]
#[ignore]
fn explore() {
    let spec = std::env::var("TABLE_EXPLORE").unwrap_or_default();
    for line in spec.split(';').filter(|l| !l.trim().is_empty()) {
        let f: Vec<&str> = line.split_whitespace().collect();
        let num = |i: usize| f[i].parse::<f64>().unwrap();
        let dist = match f[0] {
            "beckmann" => Distribution::Beckmann { alpha: num(1) },
            "ggx" => Distribution::Ggx { alpha: num(1) },
            _ => Distribution::BlinnPhong { m: num(1) },
        };
        let t0 = std::time::Instant::now();
        let mat = material(dist, C64::new(num(2), num(3)), f[4] == "1", 96);
        let tm = t0.elapsed().as_secs_f64();
        let opt = |x: f64| if x > 0.0 { Some(x) } else { None };
        let grid = |a: usize| PartOptions {
            n_z: opt(num(a)).map(|x| x as usize),
            n_psi: opt(num(a + 1)).map(|x| x as usize),
            scale: opt(num(a + 2)),
        };
        let opts = BrdfTableOptions {
            single: grid(6),
            depolarizing: grid(9),
            double: grid(12),
            double_order: opt(num(15)).map(|x| x as usize),
            frame: Some(if f[16] == "sp" {
                TableFrame::Sp
            } else {
                TableFrame::Bisector
            }),
            in_shader: false,
        };
        let t0 = std::time::Instant::now();
        let t = BrdfTable::build(&mat, num(5).to_radians(), &opts).unwrap();
        let tb = t0.elapsed().as_secs_f64();
        let e = t.max_error(&mat, 85f64.to_radians(), DYNAMIC_RANGE);
        let parts: Vec<String> = e
            .parts
            .iter()
            .map(|p| {
                format!(
                    "{} {:.2e}@(th {:.3}, psi {:.1}, k {})",
                    &p.kind[..3],
                    p.max,
                    p.theta.to_degrees(),
                    p.psi.to_degrees(),
                    p.element
                )
            })
            .collect();
        println!(
            "{line} | mat {tm:.2}s build {tb:.3}s | {}",
            parts.join(" + ")
        );
    }
}
