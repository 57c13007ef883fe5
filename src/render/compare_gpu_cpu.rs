//! The GPU kernels against their f64 CPU twins (`render_cpu` with the same tables or BRDF)
//! and against exact answers, per pixel and in total: shading and the in-kernel BRDF
//! terms, bistatic cast shadows, `K` visibility samples and analytic coverage. These
//! render on a Vulkan device (lavapipe on a machine without a GPU), so they are the
//! slowest of the crate's tests. Scenes: [`crate::render::test_scenes`].

use crate::brdf::table::{BrdfTable, BrdfTableOptions, PartKind, TableFrame};
use crate::brdf::{Material, MaterialSpec, Terms};
use crate::microfacet::Distribution;
use crate::optics::frames::{Frame, V3};
use crate::optics::fresnel::{Eta, C64};
use crate::render::api::{Layout, Outputs, Rendered};
use crate::render::cpu;
use crate::render::geometry::{rot_from_rows, Mesh, Rot};
use crate::render::gpu::{context, render, DeviceChoice, Gpu, GpuTables, PartRef};
use crate::render::test_scenes::{
    lambert_brdf, lambert_sensor, lambert_tables, metal, sphere_and_plate, two_attitudes, uv_sphere,
};

// ---- Lambertian sphere: kernel, twin and the analytic cross-section ----

#[test]
fn lambertian_sphere_on_the_device_matches_twin_and_analytic() {
    let gpu = match context(DeviceChoice::Auto) {
        Ok(g) => g,
        Err(e) => panic!("no Vulkan device (install mesa-vulkan-drivers): {e}"),
    };
    let a = 0.5;
    let rho = 0.7;
    let mesh = uv_sphere(a, 64, 128);
    let tables = lambert_tables(rho, 0.0);
    let sensor = lambert_sensor(128);
    let rot = vec![Rot::IDENTITY];
    let out = Outputs {
        image: true,
        range: true,
        profile: true,
    };
    let g = render(&gpu, &mesh, &tables, &sensor, &rot, out).unwrap();
    let brdf = lambert_brdf(rho);
    let c = cpu::render_cpu(&mesh, &sensor, &rot, out, &brdf);
    let analytic = 8.0 / 3.0 * std::f64::consts::PI * a * a * rho;
    let (tg, tc) = (g.total[0], c.total[0]);
    eprintln!("gpu {tg} cpu {tc} analytic {analytic}");
    assert!((tg - tc).abs() < 1e-5 * tc, "gpu {tg} vs twin {tc}");
    assert!(
        (tg - analytic).abs() < 2e-2 * analytic,
        "gpu {tg} vs analytic {analytic}"
    );
    let pg: f64 = g.profile.as_ref().unwrap().chunks(16).map(|c| c[0]).sum();
    assert!(
        (pg - tg).abs() < 1e-6 * tg,
        "profile sum {pg} vs total {tg}"
    );
    // per pixel
    let (ig, ic) = (g.image.unwrap(), c.image.unwrap());
    let mut worst = 0.0f64;
    for (x, y) in ig.iter().zip(&ic).step_by(16) {
        if *y > 0.0 {
            worst = worst.max(((x - y) / y).abs() as f64);
        }
    }
    eprintln!("worst pixel rel {worst}");
}

// ---- shading: the kernel and the in-kernel terms against the twin and the core BRDF ----

/// max over pixels of max_ij |a_ij - b_ij| / max(b_00, floor): relative to the pixel's
/// own M00, with an absolute floor for the faintest pixels (grazing limb pixels, where
/// f32 rounding of a tiny cos(theta_i) is relatively large but carries no signal).
fn worst(a: &[f32], b: &[f32], floor: f32) -> (f64, usize) {
    worst_over(a, b, |m00| Some(m00.max(floor)))
}

/// [`worst`] over the pixels whose `b` M00 exceeds `floor` only, relative to that M00.
fn worst_lit(a: &[f32], b: &[f32], floor: f32) -> (f64, usize) {
    worst_over(a, b, |m00| (m00 > floor).then_some(m00))
}

/// The largest `max_k |a_k - b_k| / d` over pixels and the pixel, `d = scale(b's M00)`;
/// pixels where `scale` gives `None` are left out.
fn worst_over(a: &[f32], b: &[f32], scale: impl Fn(f32) -> Option<f32>) -> (f64, usize) {
    let mut w = 0.0f64;
    let mut k = 0;
    for (p, (x, y)) in a.chunks(16).zip(b.chunks(16)).enumerate() {
        if let Some(d) = scale(y[0]) {
            let e = x
                .iter()
                .zip(y)
                .map(|(u, v)| (u - v).abs())
                .fold(0.0f32, f32::max) as f64
                / d as f64;
            if e > w {
                w = e;
                k = p;
            }
        }
    }
    (w, k)
}

/// The smooth-shaded sphere (radius 0.5) at the oblique attitude the shading tests use.
fn oblique_sphere() -> (Mesh, Vec<Rot>) {
    let rot = crate::render::geometry::rotations_from_quaternions(&[
        [0.9, 0.3, -0.2, 0.25].map(|x: f64| x / (0.81f64 + 0.09 + 0.04 + 0.0625).sqrt())
    ])
    .unwrap();
    (uv_sphere(0.5, 48, 96), rot)
}

/// One material's render by the kernel on its packed `table`, by the f64 twin on the
/// same table (as `Lidar(arithmetic="f64")` runs it) and by the twin with the exact
/// core BRDF of `mat`, on the 64-pixel sensor at `beta`.
fn kernel_twin_core(
    gpu: &Gpu,
    mesh: &Mesh,
    rot: &[Rot],
    mat: &Material,
    table: &BrdfTable,
    beta: f64,
    out: Outputs,
) -> (Rendered, Rendered, Rendered) {
    let tables = GpuTables::pack(&[PartRef::of(table)], beta).unwrap();
    assert_eq!(
        tables.in_shader,
        table.single.is_some() || table.depolarizing.is_some()
    );
    let mut sensor = lambert_sensor(64);
    sensor.bistatic_angle = beta;
    let g = render(gpu, mesh, &tables, &sensor, rot, out).unwrap();
    let by_table = cpu::Tables(std::slice::from_ref(table));
    let by_core = |_m: usize, wi: V3, wo: V3| crate::brdf::eval(mat, wi, wo, Frame::Sp);
    let t = cpu::render_cpu(mesh, &sensor, rot, out, &by_table);
    let c = cpu::render_cpu(mesh, &sensor, rot, out, &by_core);
    (g, t, c)
}

/// The kernel (f32, lavapipe or GPU) against its f64 twin with the same tables, and the
/// twin with the tables against the exact core BRDF, per pixel, monostatic and 2 deg
/// bistatic, on a smooth-shaded sphere at an oblique attitude.
#[test]
fn kernel_matches_twin_and_core_per_pixel() {
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let mat = metal();
    let (mesh, rot) = oblique_sphere();
    for beta in [0.0, 2f64.to_radians()] {
        let opts = BrdfTableOptions {
            frame: Some(TableFrame::Bisector),
            ..Default::default()
        };
        let table = BrdfTable::build(&mat, beta, &opts).unwrap();
        let out = Outputs {
            image: true,
            range: true,
            profile: true,
        };
        let (g, t, c) = kernel_twin_core(&gpu, &mesh, &rot, &mat, &table, beta, out);
        let (gi, ti, ci) = (
            g.image.as_ref().unwrap(),
            t.image.as_ref().unwrap(),
            c.image.as_ref().unwrap(),
        );
        let peak = ci.chunks(16).map(|x| x[0]).fold(0.0f32, f32::max);
        let floor = 1e-3 * peak;
        let (e_gt, k1) = worst(gi, ti, floor);
        let (e_tc, k2) = worst(ti, ci, floor);
        let (e_gc, _) = worst(gi, ci, floor);
        eprintln!(
            "beta {beta:.4}: kernel vs twin {e_gt:.2e} (pixel {k1}), twin(table) vs core \
             {e_tc:.2e} (pixel {k2}), kernel vs core {e_gc:.2e}; totals {:?} {:?} {:?}",
            &g.total[..4],
            &t.total[..4],
            &c.total[..4]
        );
        assert!(e_gt < 1e-4, "kernel vs twin {e_gt}");
        // the tables' own interpolation error (docs/render-table.md): 1e-4 monostatic;
        // bistatic, the multiple and GGX terms interpolate in psi to ~1e-4..1e-3
        let tol_table = if beta == 0.0 { 1e-4 } else { 2e-4 };
        assert!(e_tc < tol_table, "table vs core {e_tc}");
        for k in 0..16 {
            assert!((g.total[k] - t.total[k]).abs() < 1e-5 * t.total[0]);
        }
        // profile sums to the total, element by element
        let p = g.profile.as_ref().unwrap();
        for k in 0..16 {
            let s: f64 = p.chunks(16).map(|x| x[k]).sum();
            assert!((s - g.total[k]).abs() < 1e-6 * g.total[0], "element {k}");
        }
    }
}

/// The single, multiple and diffuse terms evaluated in the kernel (`in_shader`: no
/// tables for them) against their f64 twins ([`crate::brdf::table::SingleParams::eval`],
/// [`crate::brdf::table::DepolarizingParams::eval`]) and the twin
/// against the exact core BRDF, per pixel, monostatic and 2 deg bistatic, on the
/// oblique smooth sphere, for materials that span the model's switches and extremes:
/// APS with the seed's and APS correlation (the material's own masking table, so the
/// twin is the core to rounding), Smith GGX and Beckmann (their closed forms through a
/// 1D table of 512 nodes), a perfect conductor, eta near 1 and a large |eta|, alpha
/// 0.02 and 2, and single + multiple (+ diffuse, whose albedo table is in `zeta`).
#[test]
fn in_shader_matches_twin_and_core_per_pixel() {
    use crate::microfacet::{Correlation, Shadowing};
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let (mesh, rot) = oblique_sphere();
    let single_only = Terms {
        single: true,
        double: false,
        multiple: false,
        diffuse: false,
    };
    let spec = |d: Distribution, eta: Eta, f: &dyn Fn(&mut MaterialSpec)| {
        let mut s = MaterialSpec::new(d, eta);
        s.terms = single_only;
        f(&mut s);
        Material::new(s).unwrap()
    };
    let al = Eta::Complex(C64::new(1.2, 10.4));
    let beckmann = |alpha| Distribution::Beckmann { alpha };
    let ggx = |alpha| Distribution::Ggx { alpha };
    let smith = |s: &mut MaterialSpec| s.shadowing = Shadowing::Smith;
    let mats = [
        ("APS Beckmann 0.3 Al", spec(beckmann(0.3), al, &|_| {})),
        (
            "APS GGX 0.1, APS correlation, glass",
            spec(ggx(0.1), Eta::new(1.5, 0.0), &|s| {
                s.correlation = Some(Correlation::Aps)
            }),
        ),
        (
            "Blinn-Phong m 200, eta 1 + 1e-6",
            spec(
                Distribution::BlinnPhong { m: 200.0 },
                Eta::new(1.0 + 1e-6, 0.0),
                &|_| {},
            ),
        ),
        (
            "Smith GGX 2, eta 1e3 + 1e3i",
            spec(ggx(2.0), Eta::new(1e3, 1e3), &smith),
        ),
        (
            "Smith Beckmann 0.02, perfect conductor",
            spec(beckmann(0.02), Eta::PerfectConductor, &smith),
        ),
        (
            "APS Beckmann 0.3 Al, single + multiple",
            spec(beckmann(0.3), al, &|s| s.terms.multiple = true),
        ),
        (
            "APS GGX 0.5 paint: single + multiple + diffuse 0.8",
            spec(ggx(0.5), Eta::new(1.5, 0.0), &|s| {
                s.terms.multiple = true;
                s.terms.diffuse = true;
                s.diffuse_albedo = 0.8;
            }),
        ),
    ];
    for (name, mat) in &mats {
        for beta in [0.0, 2f64.to_radians()] {
            let opts = BrdfTableOptions {
                frame: Some(TableFrame::Bisector),
                in_shader: true,
                ..Default::default()
            };
            let table = BrdfTable::build(mat, beta, &opts).unwrap();
            assert!(table.single.is_some() && !table.kinds.contains(&PartKind::Single));
            assert_eq!(table.depolarizing.is_some(), mat.spec.terms.multiple);
            assert!(table.parts.is_empty());
            let out = Outputs {
                image: true,
                range: false,
                profile: true,
            };
            let (g, t, c) = kernel_twin_core(&gpu, &mesh, &rot, mat, &table, beta, out);
            let (gi, ti, ci) = (
                g.image.as_ref().unwrap(),
                t.image.as_ref().unwrap(),
                c.image.as_ref().unwrap(),
            );
            let peak = ci.chunks(16).map(|x| x[0]).fold(0.0f32, f32::max);
            assert!(peak > 0.0, "{name}: a lit sphere");
            let floor = 1e-3 * peak;
            let (e_gt, k1) = worst(gi, ti, floor);
            let (e_tc, k2) = worst(ti, ci, floor);
            eprintln!(
                "{name}, beta {beta:.4}: kernel vs twin {e_gt:.2e} (pixel {k1}), twin vs \
                 core {e_tc:.2e} (pixel {k2}); totals {:.6e} {:.6e} {:.6e}",
                g.total[0], t.total[0], c.total[0]
            );
            // f32 evaluation. Per pixel: the kernel's cosines carry an absolute error of
            // ~1e-7 (rotation and normalization of the normal in f32), a relative error
            // 1e-7 / cos_i of a value that grows with cos_i (Smith, APS: P_i ~ cos_i), so
            // the worst pixels are on the rim of a rough sphere, which stays bright
            // (measured 3.0e-4 for GGX alpha 2 at a rim pixel, 9e-5 for the glass, 4e-6
            // for Beckmann 0.3, whose rim is dark). Over the image: the relative RMS of
            // M00 is 3e-7 to 2.4e-6, and 5e-6 for Blinn-Phong m = 200, whose D =
            // exp(m ln cos) turns the f32 error of sin^2(theta_h) into m 5e-8.
            assert!(e_gt < 5e-4, "{name}: kernel vs twin {e_gt}");
            let (mut d2, mut t2) = (0.0f64, 0.0f64);
            for (x, y) in gi.iter().zip(ti.iter()).step_by(16) {
                d2 += (*x as f64 - *y as f64).powi(2);
                t2 += (*y as f64).powi(2);
            }
            let rms = (d2 / t2).sqrt();
            eprintln!("{name}, beta {beta:.4}: relative RMS of M00 {rms:.2e}");
            assert!(rms < 1e-5, "{name}: kernel vs twin RMS {rms}");
            // the twin is the core but for the masking excess's 1D table (exact for the
            // APS materials, a 512-node interpolation of the Smith forms: measured
            // 1.2e-7 for Smith GGX; the images are f32, 6e-8)
            let tol = 1e-6;
            assert!(e_tc < tol, "{name}: twin vs core {e_tc}");
            for k in 0..16 {
                assert!(
                    (g.total[k] - t.total[k]).abs() < 1e-5 * t.total[0],
                    "{name}: total element {k}"
                );
            }
        }
    }
}

/// A material with `orders = "surface"` (the path banks' order 2 in the double part, the
/// orders beyond it, polarized, with the depolarizing remainder in the multiple part),
/// tabulated and with the single term in the kernel: the kernel against the twin as for
/// the seed's terms, and the twin against the core's evaluation of the banks' tables
/// within the renderer grid's interpolation of them (`TOL_BANK_TABLE`, measured below).
/// Two materials: alpha 0.8 with the single term, and the default aluminium of
/// `pprender.materials` (alpha 0.1) with orders >= 2 alone, whose light lies toward the
/// sphere's limb (grazing), where the single term would put it under the pixels' floor.
#[test]
fn surface_orders_kernel_matches_twin_and_core_per_pixel() {
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let (mesh, rot) = oblique_sphere();
    for (alpha, eta, single) in [
        (0.8, C64::new(1.2, 10.4), true),
        (0.1, C64::new(1.3763, 10.2449), false),
    ] {
        let mut spec = MaterialSpec::new(Distribution::Beckmann { alpha }, Eta::Complex(eta));
        spec.terms = Terms {
            single,
            double: true,
            multiple: true,
            diffuse: false,
        };
        spec.orders = crate::brdf::spec::Orders::Surface;
        // few rays (the bank shared with brdf::orders' tests): the noise of this bank is
        // larger than a default one's, which makes the renderer grid's interpolation
        // error larger too, so the tolerance below is an upper bound for the default banks
        spec.bank_rays = 200_000;
        let mat = Material::new(spec).unwrap();
        for in_shader in [false, true] {
            for beta in [0.0, 2f64.to_radians()] {
                let opts = BrdfTableOptions {
                    frame: Some(TableFrame::Bisector),
                    in_shader,
                    ..Default::default()
                };
                let table = BrdfTable::build(&mat, beta, &opts).unwrap();
                // the banks' orders stay tabulated in the kernel's in-shader mode
                assert!(table.kinds.contains(&PartKind::Depolarizing));
                assert!(table.depolarizing.is_none());
                assert_eq!(table.single.is_some(), in_shader && single);
                let out = Outputs {
                    image: true,
                    range: false,
                    profile: true,
                };
                let (g, t, c) = kernel_twin_core(&gpu, &mesh, &rot, &mat, &table, beta, out);
                let (gi, ti, ci) = (
                    g.image.as_ref().unwrap(),
                    t.image.as_ref().unwrap(),
                    c.image.as_ref().unwrap(),
                );
                let peak = ci.chunks(16).map(|x| x[0]).fold(0.0f32, f32::max);
                let floor = 1e-3 * peak;
                let (e_gt, k1) = worst(gi, ti, floor);
                let (e_tc, k2) = worst(ti, ci, floor);
                let tot = |r: &Rendered| r.total[0];
                eprintln!(
                    "surface orders, alpha {alpha}, single {single}, in_shader {in_shader}, \
                     beta {beta:.4}: kernel vs twin {e_gt:.2e} (pixel {k1}), twin vs core \
                     {e_tc:.2e} (pixel {k2}); totals {:.6e} {:.6e} {:.6e}",
                    tot(&g),
                    tot(&t),
                    tot(&c)
                );
                assert!(tot(&c) > 0.0);
                // where the core is dark (below the floor), what the grid's interpolation
                // spreads there, relative to the peak
                let spill = ti
                    .chunks(16)
                    .zip(ci.chunks(16))
                    .filter(|(_, y)| y[0] <= floor)
                    .map(|(x, y)| (x[0] - y[0]).abs() / peak)
                    .fold(0.0f32, f32::max) as f64;
                let (e_lit, _) = worst_lit(ti, ci, floor);
                // relative to the image's peak, every pixel, every element
                let of_peak = |a: &[f32], b: &[f32]| worst_over(a, b, |_| Some(peak)).0;
                let (gt_peak, tc_peak) = (of_peak(gi, ti), of_peak(ti, ci));
                let (e_bright, _) = worst_lit(ti, ci, 0.1 * peak);
                eprintln!(
                    "  of the peak: kernel vs twin {gt_peak:.2e}, twin vs core {tc_peak:.2e}; \
                     pixels above 10% of the peak: twin vs core {e_bright:.2e}"
                );
                eprintln!(
                    "  lit pixels: twin vs core {e_lit:.2e}; dark pixels: {spill:.2e} of the peak"
                );
                // every pixel and element against the image's peak: kernel vs twin
                // measured 1.2e-5 at most; twin vs core (the grid's interpolation of the
                // tables) 8.9e-3 at alpha 0.8 and 6.6e-3 at 0.1; the pixels above 10% of the
                // peak within TOL_BANK_TABLE of their own M00 (measured 1.5e-2 at 0.8, 4.8e-4
                // at 0.1)
                assert!(gt_peak < 1e-4, "kernel vs twin {gt_peak} of the peak");
                assert!(tc_peak < 1.5e-2, "twin vs core {tc_peak} of the peak");
                assert!(e_bright < TOL_BANK_TABLE, "twin vs core {e_bright}");
                if alpha >= 0.3 {
                    // and every pixel above 1e-3 of the peak within TOL_BANK_TABLE of its
                    // own M00, the dark ones within 3e-5 of the peak (measured 2e-8)
                    assert!(e_gt < 5e-4, "kernel vs twin {e_gt}");
                    assert!(e_lit < TOL_BANK_TABLE, "twin vs core {e_lit} (pixel {k2})");
                    assert!(spill < 3e-5, "dark pixels {spill}");
                }
                // Not at alpha 0.1: its orders >= 2 lie within a few degrees of grazing, and
                // the grid spreads them over the lobe's fringe: pixels below 1% of the peak
                // off by up to 2.8x of their own value (2.4e-10 against 6.8e-10 m^2 at 2.8e-3
                // of the peak, 2 deg bistatic), dark ones by 9.7e-4 of the peak.
                // the interpolation errors average out over the image (measured 1e-4 and
                // 3e-5 at alpha 0.8, 1.3e-4 and 9.5e-4 at 0.1)
                assert!((tot(&t) - tot(&c)).abs() < 1e-3 * tot(&c));
                for k in 0..16 {
                    assert!(
                        (g.total[k] - t.total[k]).abs() < 1e-5 * t.total[0],
                        "total element {k}"
                    );
                }
            }
        }
    }
}

/// The renderer grid's Catmull-Rom interpolation of the banks' tables (piecewise
/// trilinear on 2.5 deg nodes, with the noise of a 2e5-ray bank), per pixel, relative to
/// the pixel's M00: measured 1.5e-2 monostatic (M00, next to a node's kink along the
/// backscatter diagonal) and 6.2e-3 at 2 deg bistatic (4.7e-2 before the banks' tables
/// were averaged in phi near the pole and their mirror-odd elements set to 0 in the plane
/// of incidence: `bank::smooth_near_pole`).
const TOL_BANK_TABLE: f64 = 0.03;

// ---- bistatic cast shadows ----

/// Bistatic kernel (its rule on the ids of the transmitter raster, f32) against the twin
/// (exact f64 ray casting toward the transmitter): the lit masks differ only at a few
/// pixels on the shadow's edge (at most 1% of the shadowed pixels; measured 0 at 20 and
/// 40 deg, 3/487 and 2/294 at 60 deg, where the plate's 1 cm rim is under a texel wide
/// seen from the transmitter), and lit pixels agree as without shadows.
#[test]
fn bistatic_shadows_kernel_matches_twin() {
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let mesh = sphere_and_plate();
    let rho = 0.5;
    let brdf = lambert_brdf(rho);
    let rots = crate::render::geometry::rotations_from_quaternions(&[
        [1.0, 0.0, 0.0, 0.0],
        [0.15f64.cos(), 0.0, 0.0, 0.15f64.sin()], // 0.3 rad about the line of sight
    ])
    .unwrap();
    let out = Outputs {
        image: true,
        range: true,
        profile: true,
    };
    for beta_deg in [20.0f64, 40.0, 60.0] {
        let beta = beta_deg.to_radians();
        let tables = lambert_tables(rho, beta);
        let mut sensor = lambert_sensor(128);
        sensor.bistatic_angle = beta;
        let mut g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
        // (the plate's rims are thinner than a pixel: their pixels are the CPU's)
        cpu::add_thin_pixels(&mut g, &mesh, &sensor, &rots, out, &brdf, None).unwrap();
        let t = cpu::render_cpu(&mesh, &sensor, &rots, out, &brdf);
        let lay = Layout::new(&mesh, &sensor);
        let w = lay.width;
        let (gi, ti) = (g.image.as_ref().unwrap(), t.image.as_ref().unwrap());
        let (gr, tr) = (g.range.as_ref().unwrap(), t.range.as_ref().unwrap());
        for (a, rot) in rots.iter().enumerate() {
            // shadowed pixels by the twin's own functions (lit by cos, yet in shadow)
            let ids = cpu::visibility(&mesh, rot, w, lay.ext);
            let view = cpu::TransmitterView::new(&mesh, rot, beta);
            let mut n_shadow = 0;
            for (k, &id) in ids.iter().enumerate() {
                if id == 0 {
                    continue;
                }
                let s = cpu::shade_pixel(
                    &mesh,
                    rot,
                    id as usize - 1,
                    k / w,
                    k % w,
                    &lay,
                    &sensor,
                    &brdf,
                )
                .unwrap();
                if s.values[0] > 0.0 && cpu::shadowed(&view, id as usize - 1, s.point) {
                    n_shadow += 1;
                }
            }
            // Lambertian: a lit pixel is 4 rho cos_i delta^2, so its value gives cos_i
            let pix_max = 4.0 * rho * lay.pix * lay.pix;
            let (mut n_cov, mut n_mis, mut n_edge, mut n_rng, mut worst) = (0, 0, 0, 0, 0.0f64);
            let lit_t = |i: usize, j: usize| ti[16 * ((a * w + i) * w + j)] > 0.0;
            for k in a * w * w..(a + 1) * w * w {
                if tr[k].is_nan() || gr[k].is_nan() {
                    continue;
                }
                n_cov += 1;
                // shadowed pixels stay covered with their range
                if (gr[k] - tr[k]).abs() > 1e-5 {
                    n_rng += 1;
                }
                let (x, y) = (&gi[16 * k..16 * k + 16], &ti[16 * k..16 * k + 16]);
                if (x[0] > 0.0) != (y[0] > 0.0) {
                    let cos_i = x[0].max(y[0]) as f64 / pix_max;
                    eprintln!(
                        "  mismatch at pixel ({}, {}): kernel {:.3e} twin {:.3e} (cos_i {:.3})",
                        (k % (w * w)) / w,
                        k % w,
                        x[0],
                        y[0],
                        cos_i
                    );
                    n_mis += 1;
                    // on the edge: the twin has both states within the 3x3 around it
                    let (i, j) = ((k % (w * w)) / w, k % w);
                    let mut states = [false; 2];
                    for ii in i.saturating_sub(1)..(i + 2).min(w) {
                        for jj in j.saturating_sub(1)..(j + 2).min(w) {
                            if !tr[(a * w + ii) * w + jj].is_nan() {
                                states[lit_t(ii, jj) as usize] = true;
                            }
                        }
                    }
                    if states[0] && states[1] {
                        n_edge += 1;
                    }
                } else if y[0] > 0.0 {
                    // the error in cos_i
                    let e = (x[0] - y[0]).abs() as f64 / pix_max;
                    worst = worst.max(e);
                }
            }
            let (tg, tt) = (g.total[16 * a], t.total[16 * a]);
            eprintln!(
                "beta {beta_deg} attitude {a}: {n_cov} covered, {n_shadow} shadowed \
                 (twin), {n_mis} lit/shadow mismatches ({n_edge} on the shadow's edge), \
                 {n_rng} range mismatches, lit pixels worst cos_i error {worst:.1e}; \
                 totals kernel {tg:.6} twin {tt:.6}"
            );
            assert!(n_shadow > 100, "the scene should have a cast shadow");
            assert!(n_mis * 100 <= n_shadow, "{n_mis} mismatches for {n_shadow}");
            assert_eq!(n_edge, n_mis, "mismatches away from the shadow's edge");
            assert!(n_rng <= 2, "{n_rng} range mismatches");
            // lit pixels agree to the f32 rounding of cos_i (the per-pixel shading is
            // compared in detail by kernel_matches_twin_and_core_per_pixel)
            assert!(worst < 1e-5, "lit pixels: worst {worst}");
            assert!((tg - tt).abs() <= n_mis as f64 * pix_max + 1e-5 * tt);
        }
    }
}

// ---- K visibility samples ----

/// With K visibility samples the kernel agrees with its twin (which casts the samples'
/// rays in f64 and groups them the same way) per pixel, in coverage, range and total,
/// on a scene full of silhouettes and occlusion edges (a plate in front of a sphere),
/// monostatic and bistatic; and a Lambertian sphere's total approaches `8/3 pi a^2 rho`
/// as K grows (the silhouette's coverage error falls).
#[test]
fn samples_kernel_matches_twin() {
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let rho = 0.5;
    let brdf = lambert_brdf(rho);
    let out = Outputs {
        image: true,
        range: true,
        profile: true,
    };
    let rots = two_attitudes();
    let mesh = sphere_and_plate();
    for (beta, k) in [(0.0, 4usize), (0.0, 16), (0.35, 8)] {
        let tables = lambert_tables(rho, beta);
        let mut sensor = lambert_sensor(64);
        sensor.samples = k;
        sensor.bistatic_angle = beta;
        let mut g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
        // (the plate's rims are thinner than a pixel: their pixels are the CPU's)
        cpu::add_thin_pixels(&mut g, &mesh, &sensor, &rots, out, &brdf, None).unwrap();
        let t = cpu::render_cpu(&mesh, &sensor, &rots, out, &brdf);
        let lay = Layout::new(&mesh, &sensor);
        let pix_max = 4.0 * rho * lay.pix * lay.pix;
        let (gi, ti) = (g.image.as_ref().unwrap(), t.image.as_ref().unwrap());
        let (gc, tc) = (g.coverage.as_ref().unwrap(), t.coverage.as_ref().unwrap());
        let (gr, tr) = (g.range.as_ref().unwrap(), t.range.as_ref().unwrap());
        // The rasterizer snaps vertices to 1/256 of a pixel (lavapipe's sub-pixel
        // precision): a sample within about 1/512 pixel of an edge may see the other
        // side than the exact f64 ray. Such a pixel differs from the twin by one sample:
        // its coverage by 1/K, or (covered both ways) its range by a fraction of the
        // depth step. Everywhere else the kernel equals the twin.
        let (mut n_partial, mut n_tie, mut n_val_diff, mut worst) = (0, 0, 0, 0.0f64);
        for p in 0..gc.len() {
            if tc[p] > 0.0 && tc[p] < 1.0 {
                n_partial += 1;
            }
            if gc[p] != tc[p] {
                assert!(
                    ((gc[p] - tc[p]).abs() - 1.0 / k as f32).abs() < 1e-6,
                    "pixel {p}: coverage {} vs twin {}",
                    gc[p],
                    tc[p]
                );
                n_tie += 1;
                continue;
            }
            if tc[p] > 0.0 && (gr[p] - tr[p]).abs() > 0.05 * lay.pix as f32 {
                n_tie += 1;
                continue;
            }
            // a sample on the edge between two triangles of one surface may see either
            // (the samples lie on lines such as X = -Y, where the UV sphere has
            // meridians): the shading point then moves by a fraction of a pixel
            let e = (gi[16 * p] - ti[16 * p]).abs() as f64 / pix_max;
            if e > 1e-2 {
                n_val_diff += 1;
            } else {
                worst = worst.max(e);
            }
        }
        let tot = (g.total[0] - t.total[0]).abs() / t.total[0];
        eprintln!(
            "beta {beta} K {k}: {n_partial} partly covered pixels, {n_tie} differ by a \
             sample, values (> 1e-2 of a pixel) at {n_val_diff} more, else worst \
             {worst:.1e}; total {} vs twin {} ({tot:.1e})",
            g.total[0], t.total[0]
        );
        assert!(n_partial > 100, "silhouette pixels expected");
        assert!(n_tie * 25 <= n_partial, "{n_tie} one-sample mismatches");
        // lit/shadow decisions differ at a few shadow-edge points (bistatic_shadows test)
        let allowed = if beta > 0.0 { 10 } else { 0 };
        assert!(n_val_diff <= allowed, "{n_val_diff} pixel mismatches");
        assert!(worst < 5e-3, "worst {worst}");
        let per_sample = pix_max / k as f64;
        assert!(
            tot < 1e-5 + (n_tie as f64 * per_sample + n_val_diff as f64 * pix_max) / t.total[0]
        );
        let p = g.profile.as_ref().unwrap();
        let s: f64 = p[..g.n_bins * 16].chunks(16).map(|x| x[0]).sum();
        assert!(
            (s - g.total[0]).abs() < 1e-9 * g.total[0],
            "profile sum {s} total {}",
            g.total[0]
        );
    }
    // The coverage error at edges falls as 1/K: a face-on Lambertian square (total
    // 4 rho A) at 47 pixels across its bounding circle: its edges cut pixels near
    // their sides, so the centre sample (K = 1) misses the four edge strips (-1.4%);
    // with K samples (one in each of the K columns of width 1/K) each edge pixel is
    // off by at most 1/(2K) of a pixel.
    let h = 0.5;
    let v = vec![[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]];
    let plate = Mesh::new(v, vec![[0, 1, 2], [0, 2, 3]], None, vec![0; 2], 1).unwrap();
    let analytic = 4.0 * rho * (2.0 * h) * (2.0 * h);
    let tables = lambert_tables(rho, 0.0);
    let rot = vec![Rot::IDENTITY];
    let mut errs = vec![];
    for k in [1usize, 4, 16] {
        let mut sensor = lambert_sensor(47);
        sensor.samples = k;
        let g = render(&gpu, &plate, &tables, &sensor, &rot, out).unwrap();
        let lay = Layout::new(&plate, &sensor);
        let side = 2.0 * h / lay.pix; // pixels
        let bound = 4.0 * side / (2.0 * k as f64) / (side * side);
        let err = (g.total[0] - analytic) / analytic;
        eprintln!("plate total error at K = {k}: {err:.2e} (bound {bound:.1e})");
        assert!(err.abs() < bound + 1e-5, "K {k}: {err} vs bound {bound}");
        errs.push(err);
    }
    assert!(
        errs[0] < -1e-2,
        "the centre sample should miss the edge strips"
    );
    assert!(errs[2].abs() < 0.1 * errs[0].abs());
}

// ---- analytic coverage ----

/// Analytic coverage: the kernel agrees with its f64 twin per pixel (value, coverage,
/// range) and in total, monostatic and bistatic, on a scene of silhouettes and
/// occlusion edges (a plate in front of a sphere, two attitudes).
#[test]
fn analytic_kernel_matches_twin() {
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let rho = 0.5;
    let brdf = lambert_brdf(rho);
    let out = Outputs {
        image: true,
        range: true,
        profile: true,
    };
    let rots = two_attitudes();
    let mesh = sphere_and_plate();
    for beta in [0.0, 0.35] {
        let tables = lambert_tables(rho, beta);
        let mut sensor = lambert_sensor(64);
        sensor.analytic = true;
        sensor.bistatic_angle = beta;
        let mut g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
        // (the plate's rims are thinner than a pixel: their pixels are the CPU's)
        cpu::add_thin_pixels(&mut g, &mesh, &sensor, &rots, out, &brdf, None).unwrap();
        let t = cpu::render_cpu(&mesh, &sensor, &rots, out, &brdf);
        let lay = Layout::new(&mesh, &sensor);
        let pix_max = 4.0 * rho * lay.pix * lay.pix;
        let (gi, ti) = (g.image.as_ref().unwrap(), t.image.as_ref().unwrap());
        let (gc, tc) = (g.coverage.as_ref().unwrap(), t.coverage.as_ref().unwrap());
        let (gr, tr) = (g.range.as_ref().unwrap(), t.range.as_ref().unwrap());
        // A centre within about 1/512 pixel of an edge may see the other triangle on
        // the GPU (lavapipe snaps vertices to 1/256 pixel) than in the twin: the
        // candidates of up to nine pixels around then differ, which changes the value
        // only where the candidates were incomplete (renormalized pixels). Elsewhere
        // kernel and twin agree to f32 rounding.
        let (mut n_partial, mut n_diff, mut n_fallback) = (0, 0, 0);
        let (mut worst_v, mut worst_c, mut worst_r) = (0.0f64, 0.0f64, 0.0f64);
        for p in 0..gc.len() {
            if tc[p] > 0.0 && tc[p] < 0.999 {
                n_partial += 1;
            }
            let ev = (gi[16 * p] - ti[16 * p]).abs() as f64 / pix_max;
            let ec = (gc[p] - tc[p]).abs() as f64;
            // the range: a covered-area-weighted mean, so a part's area error moves it by
            // that error times the depth step between the parts
            let er = if tc[p] > 0.0 {
                (gr[p] - tr[p]).abs() as f64 / lay.pix
            } else {
                0.0
            };
            if ev > 1e-3 || ec > 1e-3 || er > 1e-2 {
                n_diff += 1;
                continue;
            }
            worst_v = worst_v.max(ev);
            worst_c = worst_c.max(ec);
            worst_r = worst_r.max(er);
        }
        // pixels where the candidate search overflows (the centre-sample fallback)
        let ids = cpu::visibility(&mesh, &rots[0], lay.width, lay.ext);
        let vertices = cpu::rotate_vertices(&mesh, &rots[0]);
        for p in 0..lay.width * lay.width {
            let (row, col) = (p / lay.width, p % lay.width);
            let w = lay.width;
            let (seeds, _) = cpu::analytic_seeds(&ids, w, row, col);
            if !seeds.is_empty()
                && cpu::coverage_parts(
                    &mesh,
                    &vertices,
                    &lay,
                    row,
                    col,
                    &seeds,
                    &[],
                    cpu::coverage::KERNEL_CAPACITY,
                )
                .is_none()
            {
                n_fallback += 1;
            }
        }
        let tot = (g.total[0] - t.total[0]).abs() / t.total[0];
        eprintln!(
            "analytic beta {beta}: {n_fallback} pixels of attitude 0 fall back, {n_partial} partly covered pixels, {n_diff} differ by \
             > 1e-3 of a pixel, else worst value {worst_v:.1e} coverage {worst_c:.1e} \
             range {worst_r:.1e} pixel; \
             total {} vs twin {} ({tot:.1e})",
            g.total[0], t.total[0]
        );
        // the UV sphere (9,216 triangles) is dense at its pole and, seen edge-on, at its
        // rim: there a pixel can overlap more than MAX_CAND triangles (fallback)
        assert!(n_partial > 50, "silhouette pixels expected");
        assert!(n_fallback < 200, "{n_fallback} fallbacks");
        // lit/shadow decisions differ at a few shadow-edge points (bistatic_shadows
        // test), and a fallback decided differently in f32 and f64 changes a pixel
        let allowed = if beta > 0.0 { 10 } else { 3 };
        assert!(n_diff <= allowed, "{n_diff} pixel mismatches");
        // values: a sliver part's centroid (moments over a tiny area) moves in f32, and
        // the smooth normal shaded there with it
        assert!(
            worst_v < 5e-4 && worst_c < 1e-5,
            "worst {worst_v} {worst_c}"
        );
        assert!(
            tot < 1e-5 + (n_diff as f64 * pix_max) / t.total[0],
            "total {tot}"
        );
        let p = g.profile.as_ref().unwrap();
        let s: f64 = p[..g.n_bins * 16].chunks(16).map(|x| x[0]).sum();
        assert!((s - g.total[0]).abs() < 1e-9 * g.total[0]);
    }
}

/// Against exact areas, independent of the clipping code: a face-on Lambertian square
/// (total `4 rho A`) whose edges cut pixels anywhere, at several resolutions, and a
/// flat-shaded UV sphere, whose total is the sum over its faces turned toward the sensor
/// of `4 rho A n_z^2` (projected area `A n_z`, `cos_i = n_z`): analytic coverage gives
/// them to f32 rounding where one centre sample per pixel is off to first order in the
/// pixel size.
#[test]
fn analytic_coverage_totals_are_exact() {
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let rho = 0.5;
    let out = Outputs {
        image: false,
        range: false,
        profile: true,
    };
    let tables = lambert_tables(rho, 0.0);
    let h = 0.5;
    let v = vec![[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]];
    let plate = Mesh::new(v, vec![[0, 1, 2], [0, 2, 3]], None, vec![0; 2], 1).unwrap();
    let rot = vec![Rot::IDENTITY];
    let c = 0.3f64;
    let s = (1.0 - c * c).sqrt();
    // a turn about the view axis, so that no edge lies along the pixel grid
    let turned = vec![rot_from_rows([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])];
    let analytic = 4.0 * rho * (2.0 * h) * (2.0 * h);
    for res in [47usize, 64, 101] {
        for (r, name) in [(&rot, "aligned"), (&turned, "turned")] {
            let mut sensor = lambert_sensor(res);
            let g1 = render(&gpu, &plate, &tables, &sensor, r, out).unwrap();
            sensor.analytic = true;
            let ga = render(&gpu, &plate, &tables, &sensor, r, out).unwrap();
            let (e1, ea) = (
                (g1.total[0] - analytic) / analytic,
                (ga.total[0] - analytic) / analytic,
            );
            eprintln!("plate {name} at {res}: centre sample {e1:.2e}, analytic {ea:.2e}");
            assert!(ea.abs() < 2e-6, "plate {name} {res}: {ea}");
        }
    }
    // flat-shaded UV sphere: its exact total from the faces
    let sph = uv_sphere(0.5, 12, 24);
    let flat = Mesh::new(
        sph.vertices.clone(),
        sph.faces.clone(),
        None,
        vec![0; sph.faces.len()],
        1,
    )
    .unwrap();
    let rots = two_attitudes();
    for (a, rot) in rots.iter().enumerate() {
        let mut exact = 0.0;
        for f in &flat.faces {
            let p = f
                .map(|k| crate::render::geometry::rotate(rot, V3::from(flat.vertices[k as usize])));
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            let len = n.length();
            if n[2] > 0.0 {
                // 4 rho A n_z^2, A = len / 2, n_z = n[2] / len
                exact += 4.0 * rho * 0.5 * len * (n[2] / len).powi(2);
            }
        }
        let r1 = vec![*rot];
        for res in [32usize, 64] {
            let mut sensor = lambert_sensor(res);
            let g1 = render(&gpu, &flat, &tables, &sensor, &r1, out).unwrap();
            sensor.analytic = true;
            let ga = render(&gpu, &flat, &tables, &sensor, &r1, out).unwrap();
            let (e1, ea) = ((g1.total[0] - exact) / exact, (ga.total[0] - exact) / exact);
            eprintln!(
                "flat UV sphere, attitude {a}, {res} px: centre sample {e1:.2e}, analytic {ea:.2e}"
            );
            assert!(ea.abs() < 1e-5, "sphere {a} {res}: {ea}");
        }
    }
}

/// The paths' random numbers in WGSL (`shaders/shared/rng.wgsl`, run by
/// `shaders/path_numbers.wgsl`) against their twin
/// (`render::paths::PixelRng`): every number of 3 sets x 3 dimensions for 64 paths of 50
/// pixels under two seeds is the same 24-bit value, bit for bit (the groundwork of a device
/// path kernel: the same paths on the device as on the CPU).
#[test]
fn path_random_numbers_kernel_matches_twin() {
    use crate::render::paths::PixelRng;
    use wgpu::util::DeviceExt;
    let g = context(DeviceChoice::Cpu).unwrap();
    let dev = &g.device;
    let src = crate::render::shaders::path_numbers_module();
    let (pixels, paths) = (50u32, 64u32);
    let n_out = (pixels * paths * 9) as usize;
    for seed in [0u32, 0xdead_beef] {
        let params = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("rng params"),
            contents: bytemuck::cast_slice(&[seed, pixels, paths, 7919u32, 3u32, 0, 0, 0]),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let out = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("rng out"),
            size: (n_out * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("rng read"),
            size: (n_out * 4) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let module = dev.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("rng twin"),
            source: wgpu::ShaderSource::Wgsl(src.clone().into()),
        });
        let pipeline = dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("rng twin"),
            layout: None,
            module: &module,
            entry_point: Some("cs_path_numbers"),
            compilation_options: Default::default(),
            cache: None,
        });
        let bind = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("rng twin"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: out.as_entire_binding(),
                },
            ],
        });
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups((pixels * paths).div_ceil(64), 1, 1);
        }
        enc.copy_buffer_to_buffer(&out, 0, &read, 0, (n_out * 4) as u64);
        g.queue.submit([enc.finish()]);
        let slice = read.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        dev.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        let got: Vec<u32> = bytemuck::cast_slice(&slice.get_mapped_range().unwrap()).to_vec();
        read.unmap();
        for p in 0..pixels {
            let rng = PixelRng::new(seed, p * 7919 + 3);
            for i in 0..paths {
                for set in 0..3u32 {
                    let want = rng.set(i as usize, set);
                    for d in 0..3 {
                        let k = (((p * paths + i) * 3 + set) * 3) as usize + d;
                        let u = got[k] as f64 / 16_777_216.0;
                        assert_eq!(
                            u, want[d],
                            "seed {seed} pixel {p} path {i} set {set} dim {d}"
                        );
                    }
                }
            }
        }
    }
}

// ---- thin parts ----

/// A Lambertian wire a sixth of a pixel across (16 flat sides, closed), its axis at 0 to 90
/// deg to the image rows: the pixels it overlaps take its facets' areas exactly
/// (render::thin), with K = 8 samples on the CPU (the device leaves them empty:
/// `cpu::add_thin_pixels`) and with analytic coverage in the kernel, so both give the sum
/// over the facets turned to the sensor, `4 rho A n_z^2`: the twin to 1e-9 (f64 clipping,
/// seen 3e-14), the kernel to 5e-5 (f32 clipping of slivers 0.02 pixel wide, seen 7e-6),
/// where the samples alone are off by up to tens of percent (docs/thin-parts.md); per
/// pixel the device's result equals the twin's within 2e-3 of the larger of its value and
/// a hundredth of a full pixel's (seen 1e-4).
#[test]
fn thin_wire_kernel_and_twin_match_the_facet_sum() {
    use crate::render::test_scenes::{wire, wire_view};
    use crate::render::thin::{face_thinness, ThinPixels};
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let rho = 0.5;
    let brdf = lambert_brdf(rho);
    let tables = lambert_tables(rho, 0.0);
    let out = Outputs {
        image: true,
        range: false,
        profile: true,
    };
    let mesh = wire(0.0015, 0.6, 16);
    let rots: Vec<Rot> = [0.0f64, 5.0, 30.0, 45.0, 90.0]
        .iter()
        .map(|d| wire_view(d.to_radians()))
        .collect();
    for (k, analytic) in [(8usize, false), (1, true)] {
        let mut sensor = lambert_sensor(64);
        sensor.samples = k;
        sensor.analytic = analytic;
        let lay = Layout::new(&mesh, &sensor);
        let mut g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
        if !analytic {
            // the device leaves the wire's pixels, every one of them thin, to the CPU
            assert!(g.total.iter().all(|&x| x == 0.0), "{:?}", &g.total[..1]);
            cpu::add_thin_pixels(&mut g, &mesh, &sensor, &rots, out, &brdf, None).unwrap();
        }
        let t = cpu::render_cpu(&mesh, &sensor, &rots, out, &brdf);
        let a = face_thinness(&mesh);
        for (i, rot) in rots.iter().enumerate() {
            let vertices = cpu::rotate_vertices(&mesh, rot);
            let thin = ThinPixels::new(&mesh, &a, rot, &vertices, &lay);
            assert!(
                thin.len() > 60,
                "the wire's pixels are thin ({})",
                thin.len()
            );
            let mut exact = 0.0;
            for f in &mesh.faces {
                let p = f.map(|k| {
                    crate::render::geometry::rotate(rot, V3::from(mesh.vertices[k as usize]))
                });
                let n = (p[1] - p[0]).cross(p[2] - p[0]);
                let len = n.length();
                if n[2] > 0.0 {
                    exact += 4.0 * rho * 0.5 * len * (n[2] / len).powi(2);
                }
            }
            let (eg, et) = (
                (g.total[16 * i] - exact) / exact,
                (t.total[16 * i] - exact) / exact,
            );
            eprintln!(
                "wire K {k} analytic {analytic} attitude {i}: kernel {eg:.1e}, twin {et:.1e}"
            );
            assert!(
                eg.abs() < 5e-5 && et.abs() < 1e-9,
                "attitude {i}: {eg} {et}"
            );
        }
        let (gi, ti) = (g.image.as_ref().unwrap(), t.image.as_ref().unwrap());
        let pix_max = 4.0 * rho * lay.pix * lay.pix;
        // per pixel, relative to a hundredth of a full pixel's value
        let (e, p) = worst(gi, ti, (0.01 * pix_max) as f32);
        eprintln!("wire K {k} analytic {analytic}: worst pixel {e:.1e} at {p}");
        assert!(e < 2e-3, "pixel {p}: {e}");
    }
    // with supersampling and more attitudes than add_thin_pixels takes at once: the
    // device's result with the CPU's thin pixels merged equals the twin's supersampled
    // render (totals and profiles to 1e-6 of the largest, every pixel's coverage to 1e-6
    // and range to 1e-6 of the extent where covered)
    let rots: Vec<Rot> = (0..70)
        .map(|d| wire_view((d as f64 * 1.3).to_radians()))
        .collect();
    let mut sensor = lambert_sensor(24);
    sensor.samples = 4;
    sensor.supersampling = 2;
    let out = Outputs {
        image: true,
        range: true,
        profile: true,
    };
    let mut g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
    cpu::add_thin_pixels(&mut g, &mesh, &sensor, &rots, out, &brdf, None).unwrap();
    let t = cpu::render_supersampled(&mesh, &sensor, &rots, out, &brdf);
    let big = t.total.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (a, b) in g.total.iter().zip(&t.total) {
        assert!((a - b).abs() < 1e-6 * big, "total {a} vs twin {b}");
    }
    let (gp, tp) = (g.profile.as_ref().unwrap(), t.profile.as_ref().unwrap());
    let big = tp.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(gp.iter().zip(tp).all(|(a, b)| (a - b).abs() < 1e-6 * big));
    let (gc, tc) = (g.coverage.as_ref().unwrap(), t.coverage.as_ref().unwrap());
    let (gr, tr) = (g.range.as_ref().unwrap(), t.range.as_ref().unwrap());
    let ext = Layout::new(&mesh, &sensor).ext as f32;
    for p in 0..gc.len() {
        assert!(
            (gc[p] - tc[p]).abs() < 1e-6,
            "pixel {p}: {} vs {}",
            gc[p],
            tc[p]
        );
        if tc[p] > 0.0 {
            assert!(
                (gr[p] - tr[p]).abs() < 1e-6 * ext,
                "pixel {p}: {} vs {}",
                gr[p],
                tr[p]
            );
        }
    }
}

// ---- the illuminated area's moment beside the profile ----

/// The area moment ([`Rendered::area_moment`]) of the kernel against the twin's, per bin,
/// for one sample per pixel, `K` samples with bistatic shadows, analytic coverage, a
/// Stokes output and a sampled pulse (on the host); and asking for it leaves every other
/// output bit for bit as it was, on the device and on the twin. Measured at 48 x 48
/// (lavapipe): 1e-6 of the peak bin at the identity attitude, up to 4.2e-3 where the
/// rasterizer's snapped edges and the twin's exact ones see different triangles at a few
/// pixels, which moves the profile's S0 by as much (4.0e-3).
#[test]
fn area_moment_kernel_matches_twin_and_leaves_the_rest_unchanged() {
    let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
    let rho = 0.5;
    let brdf = lambert_brdf(rho);
    let out = Outputs {
        image: true,
        range: true,
        profile: true,
    };
    let rots = two_attitudes();
    let mesh = sphere_and_plate();
    let pulse = crate::render::pulse::SampledPulse::new(&[0.0, 1.0, 3.0, 2.0, 0.5, 0.0], 0.006)
        .map(std::sync::Arc::new)
        .unwrap();
    // (beta, samples, analytic, polarization, sampled pulse); the unchanged bits are
    // checked where it costs no extra kernel compilation on lavapipe (a Stokes output: the
    // kernel's profile indexing is the same code in every mode) and with the host's pulse
    let cases: [(f64, usize, bool, Option<[f64; 4]>, bool); 4] = [
        (0.0, 1, false, Some([1.0, 0.6, 0.0, 0.0]), false),
        (0.35, 4, false, None, false),
        (0.0, 1, true, None, false),
        (0.0, 1, false, None, true),
    ];
    for (ci, (beta, k, analytic, pol, sampled)) in cases.into_iter().enumerate() {
        let check_bits = ci == 0 || sampled;
        let tables = lambert_tables(rho, beta);
        let mut sensor = lambert_sensor(48);
        sensor.samples = k;
        sensor.analytic = analytic;
        sensor.bistatic_angle = beta;
        sensor.polarization = pol;
        if sampled {
            sensor.pulse = Some(pulse.clone());
        }
        sensor.illuminated_area = true;
        let mut g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
        let t = cpu::render_cpu(&mesh, &sensor, &rots, out, &brdf);
        let bits32 = |v: &Option<Vec<f32>>| {
            v.as_ref()
                .map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
        };
        let bits64 = |v: &Option<Vec<f64>>| {
            v.as_ref()
                .map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
        };
        let case = format!("beta {beta} K {k} analytic {analytic} {pol:?} sampled {sampled}");
        if check_bits {
            sensor.illuminated_area = false;
            let plain = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
            assert!(plain.area_moment.is_none());
            assert!(bits32(&plain.image) == bits32(&g.image), "{case}: image");
            assert!(bits32(&plain.range) == bits32(&g.range), "{case}: range");
            assert!(
                bits64(&plain.profile) == bits64(&g.profile),
                "{case}: profile"
            );
            assert!(
                bits64(&Some(plain.total)) == bits64(&Some(g.total.clone())),
                "{case}: total"
            );
            let t_plain = cpu::render_cpu(&mesh, &sensor, &rots, out, &brdf);
            assert!(t_plain.area_moment.is_none());
            assert!(
                bits64(&t_plain.profile) == bits64(&t.profile),
                "{case}: twin profile"
            );
            assert!(
                bits32(&t_plain.image) == bits32(&t.image),
                "{case}: twin image"
            );
            sensor.illuminated_area = true;
        }
        cpu::add_thin_pixels(&mut g, &mesh, &sensor, &rots, out, &brdf, None).unwrap();
        let (qg, qt) = (g.area_moment.unwrap(), t.area_moment.unwrap());
        let nb = g.n_bins;
        for a in 0..rots.len() {
            let (qg, qt) = (&qg[a * nb..(a + 1) * nb], &qt[a * nb..(a + 1) * nb]);
            let peak = qt.iter().fold(0.0f64, |m, &v| m.max(v));
            assert!(peak > 0.0, "{case}");
            let (mut worst, mut worst_rel) = (0.0f64, 0.0f64);
            for (x, y) in qg.iter().zip(qt) {
                worst = worst.max((x - y).abs() / peak);
                if *y > 1e-2 * peak {
                    worst_rel = worst_rel.max((x - y).abs() / y);
                }
            }
            // the profile's S0 for scale: where the rasterizer and the f64 twin see
            // different triangles at a pixel edge (attitude 1) both differ alike
            let (pg, pt) = (g.profile.as_ref().unwrap(), t.profile.as_ref().unwrap());
            let ch = g.channels;
            let s0 = |p: &[f64], j: usize| p[(a * nb + j) * ch];
            let p_peak = (0..nb).fold(0.0f64, |m, j| m.max(s0(pt, j)));
            let p_worst =
                (0..nb).fold(0.0f64, |m, j| m.max((s0(pg, j) - s0(pt, j)).abs() / p_peak));
            eprintln!(
                "{case} attitude {a}: area moment worst {worst:.2e} of the peak \
                 ({worst_rel:.2e} relative where > 1% of it); profile S0 {p_worst:.2e}"
            );
            // f32 shading: 1e-6 of the peak at the identity; where the rasterizer's
            // snapped edges (or, bistatic, the shadow map) and the twin's exact ones see
            // different triangles at a few pixels, their whole shares move the profile and
            // the moment alike (the moment by up to twice the relative amount: it is
            // quadratic in a pixel's value); measured up to 4.2e-3 of the peak with the
            // profile's S0 off by 4.0e-3 (bistatic, K = 4, attitude 1)
            assert!(
                worst <= 1e-5 + 3.0 * p_worst && worst < 1e-2,
                "{case}: {worst} (profile {p_worst})"
            );
        }
    }
}
