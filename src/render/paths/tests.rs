//! Tests of the path sampler against what it did not come from: the analytic view factor of
//! a Lambertian dihedral, the perfect-conductor dihedral's 2-bounce Mueller matrix from the
//! polarization ray-tracing matrices of [`crate::optics::path`], the dihedral's retro
//! range, and the bookkeeping (batches, seeds, convex meshes, input checks).

use super::*;
use crate::brdf::spec::Terms;
use crate::brdf::MaterialSpec;
use crate::optics::fresnel::Eta;
use crate::render::geometry::rot_from_rows;
use crate::render::test_scenes::{cuboid, lambert_sensor};
use allocate::Counts;
use std::f64::consts::FRAC_1_SQRT_2;

/// Two `side x side` square plates sharing an edge along the body `y` axis through the
/// origin, each at 45 degrees from `+z` (a 90-degree dihedral opening toward `+z`); face
/// materials: 0 on the `+x` plate, 1 on the `-x` plate.
fn dihedral(side: f64) -> Mesh {
    let (h, a) = (0.5 * side, side * FRAC_1_SQRT_2);
    let vertices = vec![
        [0.0, -h, 0.0],
        [0.0, h, 0.0],
        [a, h, a],
        [a, -h, a],
        [-a, h, a],
        [-a, -h, a],
    ];
    let faces = vec![[0, 1, 2], [0, 2, 3], [0, 4, 1], [0, 5, 4]];
    Mesh::new(vertices, faces, None, vec![0, 0, 1, 1], 2).unwrap()
}

/// The rotation taking body `(sin t, 0, cos t)` to the telescope's `+Z` (a view in the
/// dihedral's cross-section plane at `t` from its symmetry axis), then turning the image
/// by `phi` about `Z`.
fn view(t: f64, phi: f64) -> Rot {
    let (c, s) = (t.cos(), t.sin());
    let ry = rot_from_rows([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]);
    let (cp, sp) = (phi.cos(), phi.sin());
    let rz = rot_from_rows([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]]);
    rz * ry
}

/// A Lambertian BRDF `rho / pi`, depolarizing.
struct Lambert(f64);

fn perp(w: V3) -> V3 {
    let a = if w.x.abs() < 0.9 { V3::X } else { V3::Y };
    normalize(cross(w, a))
}

impl PathBrdf for Lambert {
    fn eval(&self, _: usize, _: V3, wi: V3, wo: V3) -> Framed {
        let mut m = [[0.0; 4]; 4];
        m[0][0] = self.0 / PI;
        Framed {
            m,
            x_in: perp(wi),
            x_out: perp(wo),
        }
    }
    fn lobes(&self, _: usize, _: f64, _: f64) -> Option<Lobes> {
        Some(Lobes {
            specular: None,
            p_specular: 0.0,
        })
    }
}

/// Hottel's view factor from a `w x l` rectangle to an `h x l` one sharing the edge of
/// length `l` at 90 degrees (Howell's catalogue, configuration C-14).
fn view_factor_perpendicular(w: f64, h: f64, l: f64) -> f64 {
    let (w, h) = (w / l, h / l);
    let (w2, h2) = (w * w, h * h);
    let r = (w2 + h2).sqrt();
    let a = (1.0 + w2) * (1.0 + h2) / (1.0 + w2 + h2);
    let b = (w2 * (1.0 + w2 + h2) / ((1.0 + w2) * (w2 + h2))).powf(w2);
    let c = (h2 * (1.0 + h2 + w2) / ((1.0 + h2) * (h2 + w2))).powf(h2);
    (w * (1.0 / w).atan() + h * (1.0 / h).atan() - r * (1.0 / r).atan() + 0.25 * (a * b * c).ln())
        / (PI * w)
}

fn sensor_with(res: usize, bounces: usize, samples: usize, seed: u32) -> SensorSetup {
    let mut s = lambert_sensor(res);
    s.paths = PathSetup {
        bounces,
        samples,
        seed,
    };
    s
}

/// Uniforms in `[0, 1)` from a xorshift64 stream seeded with `state` (test inputs).
pub(super) fn uniform_stream(mut state: u64) -> impl FnMut() -> f64 {
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}

const ALL: Outputs = Outputs {
    image: true,
    range: false,
    profile: true,
};

/// The view factor formula itself: two unit squares at 90 degrees see each other with
/// F = 0.20004 (the tabulated value), and reciprocity `A1 F12 = A2 F21` holds.
#[test]
fn hottel_view_factor_matches_its_tabulated_value() {
    let f = view_factor_perpendicular(1.0, 1.0, 1.0);
    assert!((f - 0.200044).abs() < 2e-6, "{f}");
    let (f12, f21) = (
        view_factor_perpendicular(2.0, 0.5, 1.0),
        view_factor_perpendicular(0.5, 2.0, 1.0),
    );
    assert!((2.0 * f12 - 0.5 * f21).abs() < 1e-12);
}

/// The 2-bounce return of a Lambertian dihedral (albedo rho) seen monostatically at `t`
/// from its axis: each plate lights the other, `sigma_2 = 4 rho^2 A F (cos_a cos_b +
/// cos_b cos_a)` (`F` the view factor, `cos` of each plate's normal to the view: the
/// radiance of a plate lit at `cos_i` is `rho E cos_i / pi`). For each sampling strategy
/// alone (receiver, transmitter) and both combined, the mean of 4 seeds is within 4
/// standard errors (estimated from the seeds) of it, and that error is below 1%: each
/// unbiased, and the noise as small as the paths promise.
#[test]
fn lambertian_dihedral_second_bounce_equals_the_view_factor_formula() {
    let (side, rho) = (0.3, 0.8);
    let mesh = dihedral(side);
    let f = view_factor_perpendicular(1.0, 1.0, 1.0);
    let strategies = [(true, false), (false, true), (true, true)].map(|(r, t)| Strategies {
        receiver: r,
        transmitter: t,
        ..Strategies::default()
    });
    for (t_deg, st) in [0.0f64, 20.0]
        .into_iter()
        .flat_map(|t| strategies.map(|s| (t, s)))
    {
        let t = t_deg.to_radians();
        let (ca, cb) = ((0.25 * PI - t).sin(), (0.25 * PI + t).sin());
        let want = 8.0 * rho * rho * side * side * f * ca * cb;
        let got: Vec<f64> = (0..4)
            .map(|seed| {
                let sensor = sensor_with(48, 2, 128, seed);
                let rot = [view(t, 0.3)];
                let s =
                    render_paths_with(&mesh, &sensor, &rot, ALL, &Lambert(rho), None, (0, 1), st)
                        .unwrap();
                s[0].total[0]
            })
            .collect();
        let (mean, sd) = mean_sd(&got);
        let se = sd / 2.0;
        assert!(
            se < 0.01 * want,
            "{t_deg}, {st:?}: standard error {se} of {want}"
        );
        assert!(
            (mean - want).abs() < 4.0 * se + 1e-4 * want,
            "{t_deg} deg, {st:?}: {mean} (+- {se}) vs {want}: {got:?}"
        );
    }
}

/// A rough perfect conductor (Beckmann alpha 0.05) in a 90-degree dihedral seen along its
/// axis, its edge at `phi` in the image: the 2-bounce Mueller matrix, normalized by M00, is
/// the smooth dihedral's from the polarization ray-tracing matrices (linear states turned
/// by `4 phi`, circular handedness kept): co-polarized at 0, mixed at 22.5 deg, fully
/// cross-polarized at 45 (H -> V) within 0.03 (the roughness and the sampling noise).
#[test]
fn conductor_dihedral_second_bounce_turns_linear_states_as_the_smooth_dihedral() {
    let mesh = dihedral(0.3);
    let mut spec = MaterialSpec::new(
        Distribution::Beckmann { alpha: 0.05 },
        Eta::PerfectConductor,
    );
    spec.terms = Terms {
        single: true,
        double: false,
        multiple: false,
        diffuse: false,
    };
    let mats = vec![Arc::new(Material::new(spec).unwrap()); 2];
    for phi_deg in [0.0f64, 22.5, 45.0] {
        let phi = phi_deg.to_radians();
        let sensor = sensor_with(32, 2, 32, 0);
        let s = render_paths(
            &mesh,
            &sensor,
            &[view(0.0, phi)],
            ALL,
            &Materials::new(&mats),
            None,
            (0, 1),
        )
        .unwrap();
        let m = &s[0].total;
        // the edge (body y) lies at phi + 90 deg in the image: the smooth dihedral's matrix
        let u = V3::new(-(phi + 0.5 * PI).sin(), (phi + 0.5 * PI).cos(), 0.0);
        let pc = Eta::PerfectConductor;
        let (want, _) = crate::optics::path::path_mueller(
            -V3::Z,
            &[
                ((u + V3::Z) * FRAC_1_SQRT_2, pc),
                ((-u + V3::Z) * FRAC_1_SQRT_2, pc),
            ],
            V3::X,
            V3::X,
        )
        .unwrap();
        assert!(m[0] > 0.0);
        for i in 0..4 {
            for j in 0..4 {
                let got = m[4 * i + j] / m[0];
                assert!(
                    (got - want[i][j]).abs() < 0.03,
                    "phi {phi_deg}: M{i}{j} {got} vs {}",
                    want[i][j]
                );
            }
        }
    }
}

/// The 2-bounce light of a 90-degree dihedral seen across its edge lands at the edge's
/// range (every retro path has the length of the path to the edge and back): the order-2
/// profile's centroid is at the edge (range 0 here) within a tenth of the pulse's sigma,
/// while the one-bounce light of the plates spreads over their depth.
#[test]
fn dihedral_second_bounce_lands_at_the_edge_range() {
    let mesh = dihedral(0.3);
    let mut spec = MaterialSpec::new(
        Distribution::Beckmann { alpha: 0.05 },
        Eta::PerfectConductor,
    );
    spec.terms.multiple = false;
    let mats = vec![Arc::new(Material::new(spec).unwrap()); 2];
    for t_deg in [0.0f64, 15.0] {
        let sensor = sensor_with(32, 2, 16, 1);
        let rot = view(t_deg.to_radians(), 0.0);
        let s = render_paths(
            &mesh,
            &sensor,
            &[rot],
            ALL,
            &Materials::new(&mats),
            None,
            (0, 1),
        )
        .unwrap();
        let lay = Layout::new(&mesh, &sensor);
        let (ch, nb) = (16, lay.n_bins);
        let prof: Vec<f64> = (0..nb).map(|k| s[0].profile[k * ch]).collect();
        let sum: f64 = prof.iter().sum();
        let centroid: f64 = prof
            .iter()
            .enumerate()
            .map(|(k, p)| p * (lay.r_min + (k as f64 + 0.5) * sensor.bin_width))
            .sum::<f64>()
            / sum;
        assert!(
            (sum - s[0].total[0]).abs() < 1e-9 * sum,
            "the profile sums to the total"
        );
        assert!(
            centroid.abs() < 0.1 * sensor.sigma_range,
            "{t_deg}: centroid {centroid}"
        );
    }
}

/// A batch renders to the same bits as its attitudes one at a time (the random numbers
/// depend on the seed and pixel only), another seed gives other numbers, and the image
/// sums to the total.
#[test]
fn paths_are_the_same_in_a_batch_and_change_with_the_seed() {
    let mesh = dihedral(0.3);
    let rots = [view(0.1, 0.2), view(-0.3, 1.0), view(0.5, -0.4)];
    let sensor = sensor_with(16, 3, 8, 7);
    let lam = Lambert(0.7);
    let batch = render_paths(&mesh, &sensor, &rots, ALL, &lam, None, (0, 3)).unwrap();
    for (a, rot) in rots.iter().enumerate() {
        let one = render_paths(
            &mesh,
            &sensor,
            std::slice::from_ref(rot),
            ALL,
            &lam,
            None,
            (0, 1),
        )
        .unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&one[0].total), bits(&batch[a].total));
        assert_eq!(bits(&one[0].profile), bits(&batch[a].profile));
        assert_eq!(bits(&one[0].image), bits(&batch[a].image));
        // 2 orders x 16 channels; the image's sum per order and channel is the total
        for o in 0..2 {
            let img: f64 = (0..16 * 16).map(|p| one[0].image[(o * 256 + p) * 16]).sum();
            assert!((img - one[0].total[o * 16]).abs() <= 1e-12 * img.abs().max(1e-30));
            assert!(one[0].total[o * 16] > 0.0, "order {} returns light", o + 2);
        }
    }
    let other = render_paths(
        &mesh,
        &sensor_with(16, 3, 8, 8),
        &rots[..1],
        ALL,
        &lam,
        None,
        (0, 1),
    )
    .unwrap();
    assert_ne!(other[0].total[0], batch[0].total[0]);
}

/// Meshes with no inter-reflections (a closed convex one, a flat one) trace nothing; the
/// dihedral is neither.
#[test]
fn convex_and_flat_meshes_skip_the_paths() {
    let sphere = crate::render::test_scenes::uv_sphere(0.5, 8, 16);
    assert!(sphere.closed && has_no_interreflections(&sphere));
    let plate = Mesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        vec![[0, 1, 2], [0, 2, 3]],
        None,
        vec![0, 0],
        1,
    )
    .unwrap();
    assert!(has_no_interreflections(&plate));
    assert!(!has_no_interreflections(&dihedral(0.3)));
    let s = render_paths(
        &sphere,
        &sensor_with(16, 3, 4, 0),
        &[view(0.2, 0.0)],
        ALL,
        &Lambert(1.0),
        None,
        (0, 1),
    )
    .unwrap();
    assert!(s[0].total.iter().all(|&v| v == 0.0));
}

/// Bounces outside 1..=3 and path counts outside 1..=65536 are refused, naming the
/// parameter and the range.
#[test]
fn bounces_and_path_samples_out_of_range_are_refused() {
    for b in [0, 4, 100] {
        let e = check_paths(&PathSetup {
            bounces: b,
            samples: 4,
            seed: 0,
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("bounces") && e.contains("[1, 3]"), "{e}");
    }
    for n in [0, MAX_PATH_SAMPLES + 1] {
        let e = check_paths(&PathSetup {
            bounces: 2,
            samples: n,
            seed: 0,
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("path_samples"), "{e}");
    }
    let mut s = lambert_sensor(8);
    s.paths.bounces = 0;
    assert!(crate::render::check_sensor(&s).is_err());
}

/// The path numbers lie in [0, 1), depend on the seed and pixel, and are stratified over a
/// pixel's paths: 256 paths put exactly one in each of 256 intervals of every dimension,
/// and 16 in each of 16 x 16 cells of the pairs that draw a point or a direction
/// (independent numbers would stray by +- 8 at two standard deviations). The Sobol'
/// direction numbers are Joe and Kuo's.
#[test]
fn path_uniforms_are_an_even_lattice_per_pixel() {
    let us: Vec<[f64; DIMS]> = (0..256).map(|i| uniforms(3, 17, i)).collect();
    for d in 0..DIMS {
        let mut counts = [0usize; 256];
        for u in &us {
            assert!((0.0..1.0).contains(&u[d]));
            counts[(u[d] * 256.0) as usize] += 1;
        }
        assert!(counts.iter().all(|&c| c == 1), "dim {d}: {counts:?}");
    }
    for (a, b) in [(0, 1), (2, 3), (4, 5)] {
        let mut counts = [0usize; 256];
        for u in &us {
            counts[(u[a] * 16.0) as usize * 16 + (u[b] * 16.0) as usize] += 1;
        }
        assert!(counts.iter().all(|&c| c == 1), "dims {a}, {b}: {counts:?}");
    }
    // direction numbers m_k / 2^k (Joe and Kuo): m = 1, 3, 5, 15 (x + 1), 1, 3, 3, 9
    // (x^2 + x + 1), 1, 3, 1, 5 (x^3 + x + 1)
    let v = sobol_directions();
    let scaled = |d: usize| {
        (0..4)
            .map(|k| v[d][k] as f64 / 4_294_967_296.0)
            .collect::<Vec<_>>()
    };
    assert_eq!(scaled(1), [0.5, 0.75, 0.625, 0.9375]);
    assert_eq!(scaled(2), [0.5, 0.75, 0.375, 0.5625]);
    assert_eq!(scaled(3), [0.5, 0.75, 0.125, 0.3125]);
    assert_eq!(sobol(3, 2), v[2][0] ^ v[2][1]);
    // the byte tables give each index's XOR of its bits' direction numbers
    let mut rand = uniform_stream(0x2545_f491_4f6c_dd1d);
    for k in 0..4000u32 {
        let index = match k {
            0..=1023 => k,
            _ => (rand() * 4_294_967_296.0) as u32,
        };
        for (d, vd) in v.iter().enumerate() {
            let by_bits = (0..32)
                .filter(|b| index >> b & 1 == 1)
                .fold(0, |x, b| x ^ vd[b]);
            assert_eq!(sobol(index, d), by_bits, "index {index}, dim {d}");
        }
    }
    assert_ne!(uniforms(3, 17, 0), uniforms(4, 17, 0));
    assert_ne!(uniforms(3, 17, 0), uniforms(3, 18, 0));
}

/// [`open_sides`] is exact where it matters: from random points of a face, random rays
/// into a side it reports closed meet nothing (so skipping them loses no path), and the
/// dihedral's inner sides are open, its outer ones and a sphere's outside closed.
#[test]
fn closed_sides_let_no_ray_meet_the_mesh() {
    let dih = dihedral(0.3);
    let open = open_sides(&dih);
    assert!(
        open.iter().all(|s| s.iter().filter(|&&o| o).count() == 1),
        "{open:?}"
    );
    let sphere = crate::render::test_scenes::uv_sphere(0.5, 8, 16);
    assert!(open_sides(&sphere).iter().all(|s| !s[0] && s[1]));
    let mut rand = uniform_stream(0x2545_f491_4f6c_dd1d);
    for mesh in [dih, crate::render::test_scenes::sphere_and_plate()] {
        let open = open_sides(&mesh);
        let rot = Rot::IDENTITY;
        let bvh = mesh.bvh();
        let posed = Posed::new(&mesh, &rot, &open, &bvh);
        let mut closed_checked = 0;
        for (t, tri) in posed.tris.iter().enumerate() {
            let wn = normalize(cross(tri[1] - tri[0], tri[2] - tri[0]));
            for (side, sign) in [(0, 1.0), (1, -1.0)] {
                if open[t][side] {
                    continue;
                }
                for _ in 0..20 {
                    let (mut a, mut b) = (rand(), rand());
                    if a + b > 1.0 {
                        (a, b) = (1.0 - a, 1.0 - b);
                    }
                    let p = tri[0] + a * (tri[1] - tri[0]) + b * (tri[2] - tri[0]);
                    let d = normalize(V3::new(rand() - 0.5, rand() - 0.5, rand() - 0.5));
                    let d = if dot(d, wn) * sign > 0.0 { d } else { -d };
                    let hit = posed.blocked(p + 1e-9 * sign * wn, d, Some(t));
                    assert!(!hit, "face {t} side {side}: a ray met the mesh");
                    closed_checked += 1;
                }
            }
        }
        assert!(closed_checked >= 80, "{closed_checked}");
    }
}

/// The bus-and-paint corner of the tests below: the dihedral with a glossy conductor plate
/// (Beckmann alpha 0.1) and a Lambertian one (albedo 0.8), seen 15 degrees off its axis; the
/// third bounce's S0 (channel 0 of order 3) for each of `seeds`.
fn bus_and_paint_third_bounce(st: Strategies, seeds: std::ops::Range<u32>) -> Vec<f64> {
    third_bounce_s0(&dihedral(0.3), st, seeds)
}

/// [`bus_and_paint_third_bounce`] for a mesh whose material 0 is the glossy conductor and
/// 1 the Lambertian paint.
fn third_bounce_s0(mesh: &Mesh, st: Strategies, seeds: std::ops::Range<u32>) -> Vec<f64> {
    let mats = bus_and_paint_materials();
    let rot = [view(15f64.to_radians(), 0.4)];
    seeds
        .map(|seed| {
            let sensor = sensor_with(32, 3, 16, seed);
            let brdf = Materials::new(&mats);
            let s = render_paths_with(mesh, &sensor, &rot, ALL, &brdf, None, (0, 1), st).unwrap();
            s[0].total[16]
        })
        .collect()
}

/// The bus-and-paint materials: 0 a glossy conductor (Beckmann alpha 0.1, single term),
/// 1 a Lambertian paint (albedo 0.8).
fn bus_and_paint_materials() -> Vec<Arc<Material>> {
    let mut metal = MaterialSpec::new(Distribution::Beckmann { alpha: 0.1 }, Eta::PerfectConductor);
    metal.terms = Terms {
        single: true,
        double: false,
        multiple: false,
        diffuse: false,
    };
    let mut paint = MaterialSpec::new(
        Distribution::Beckmann { alpha: 0.3 },
        Eta::Complex(crate::optics::fresnel::C64::new(1.0, 0.0)),
    );
    paint.terms = Terms {
        single: false,
        double: false,
        multiple: false,
        diffuse: true,
    };
    paint.diffuse_albedo = 0.8;
    vec![
        Arc::new(Material::new(metal).unwrap()),
        Arc::new(Material::new(paint).unwrap()),
    ]
}

/// The bus-and-paint dihedral with a third plate, glossy metal too, lit and flat (`z = 0`,
/// `x` in `[-1, -0.7]`), behind the paint's plane: the paint cannot see it.
fn dihedral_and_plate_behind_the_paint() -> Mesh {
    let d = dihedral(0.3);
    let mut vertices = d.vertices.clone();
    let k = vertices.len() as u32;
    vertices.extend([
        [-1.0, -0.15, 0.0],
        [-0.7, -0.15, 0.0],
        [-0.7, 0.15, 0.0],
        [-1.0, 0.15, 0.0],
    ]);
    let mut faces = d.faces.clone();
    faces.extend([[k, k + 1, k + 2], [k, k + 2, k + 3]]);
    Mesh::new(vertices, faces, None, vec![0, 0, 1, 1, 0, 0], 2).unwrap()
}

/// The mirrors aimed at from a middle surface are those that may light it
/// ([`Mirrors::choose_from`]): with a third metal plate behind the paint's plane (lit, open,
/// a candidate over the whole mesh), the paint's points choose the dihedral's metal plate
/// alone, and a point of the metal plate chooses none (the paint is no mirror; the third
/// plate's light goes up, away from it).
#[test]
fn mirrors_are_chosen_among_those_that_may_light_the_middle_surface() {
    let mesh = dihedral_and_plate_behind_the_paint();
    let mats = bus_and_paint_materials();
    let brdf = Materials::new(&mats);
    let open = open_sides(&mesh);
    let bvh = mesh.bvh();
    let rot = view(15f64.to_radians(), 0.4);
    let posed = Posed::new(&mesh, &rot, &open, &bvh);
    let mirrors = Mirrors::new(&posed, &brdf, V3::Z, &surface_areas(&mesh));
    // the two metal surfaces: the dihedral's plate (faces 0, 1) and the third (4, 5)
    assert_eq!(mirrors.list.len(), 2, "{:?}", mirrors.of_face);
    let (plate, third) = (mirrors.of_face[0] as usize, mirrors.of_face[4] as usize);
    assert!(mirrors.list[third].p > 0.2, "{}", mirrors.list[third].p);
    let mut cdf = Vec::new();
    let mut rand = uniform_stream(7);
    let (mut on_paint, mut on_metal) = (0, 0);
    for _ in 0..400 {
        let (x, y) = (0.4 * rand() - 0.2, 0.4 * rand() - 0.2);
        let Some(v) = posed.trace(V3::new(x, y, 2.0), -V3::Z) else {
            continue;
        };
        let found = mirrors.choose_from(&v, &mut cdf);
        match v.mat {
            1 => {
                on_paint += 1;
                assert!(found);
                let p = |j: usize| cdf[j] - if j > 0 { cdf[j - 1] } else { 0.0 };
                assert_eq!((p(plate), p(third)), (1.0, 0.0), "{cdf:?}");
                assert_eq!(Mirrors::pick(&cdf, rand()), plate);
            }
            _ if v.tri < 2 => {
                on_metal += 1;
                assert!(!found && cdf.is_empty(), "{cdf:?}");
            }
            _ => {}
        }
    }
    assert!(on_paint > 50 && on_metal > 50, "{on_paint} {on_metal}");
}

/// Aiming only at the mirrors that may light the middle surface keeps the third bounce
/// unbiased where other candidates exist: with the third plate behind the paint, the mean
/// with aiming is the mean without (within 4 standard errors over 6 seeds each), and the
/// standard deviation is less than half.
#[test]
fn aiming_among_several_mirrors_keeps_the_third_bounce() {
    let mesh = dihedral_and_plate_behind_the_paint();
    let st = |aim: bool| Strategies {
        aim,
        third_draws: 1,
        ..Strategies::default()
    };
    let with = third_bounce_s0(&mesh, st(true), 0..6);
    let without = third_bounce_s0(&mesh, st(false), 0..6);
    let ((m1, s1), (m0, s0)) = (mean_sd(&with), mean_sd(&without));
    assert!(m1 > 0.0 && m0 > 0.0);
    let se = (s1 * s1 / 6.0 + s0 * s0 / 6.0).sqrt();
    assert!((m1 - m0).abs() < 4.0 * se, "{with:?} vs {without:?}");
    assert!(s1 < 0.5 * s0, "std {s1} with aiming, {s0} without");
}

/// Mean and standard deviation of a sample.
fn mean_sd(v: &[f64]) -> (f64, f64) {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
    (m, var.sqrt())
}

/// The bus-and-paint corner's 3-bounce light is mostly glossy -> diffuse -> glossy (the
/// metal shows the paint it lights), which either end draws poorly; aiming from the middle
/// surface at the transmitter's mirror ([`Mirrors`]) gives the same mean (within 4 standard
/// errors over 6 seeds each) with less than half the standard deviation (measured: 0.1019
/// +- 0.0007 aimed, 0.108 +- 0.016 not, with one draw from each second surface).
#[test]
fn aiming_at_mirrors_keeps_the_third_bounce_and_cuts_its_noise() {
    let st = |aim: bool| Strategies {
        aim,
        third_draws: 1,
        ..Strategies::default()
    };
    let with = bus_and_paint_third_bounce(st(true), 0..6);
    let without = bus_and_paint_third_bounce(st(false), 0..6);
    let ((m1, s1), (m0, s0)) = (mean_sd(&with), mean_sd(&without));
    assert!(m1 > 0.0 && m0 > 0.0);
    let se = (s1 * s1 / 6.0 + s0 * s0 / 6.0).sqrt();
    assert!((m1 - m0).abs() < 4.0 * se, "{with:?} vs {without:?}");
    assert!(s1 < 0.5 * s0, "std {s1} with aiming, {s0} without");
}

/// [`THIRD_BOUNCE_DRAWS`] draws from each second surface, each with its share of the path,
/// keep the third bounce's mean (within 4 standard errors over 32 seeds each) and cut its
/// standard deviation below 0.8 of one draw's (measured: 0.10152 +- 0.00093 with one,
/// 0.10135 +- 0.00062 with 4; over 64 seeds 0.10136 +- 0.00100 and 0.10141 +- 0.00059).
/// Aimed, this corner's third draw is rarely what varies most: the CubeSat, where it is,
/// gains more (`docs/interreflections.md`).
#[test]
fn more_third_bounce_draws_keep_its_mean_and_cut_its_noise() {
    let st = |draws: usize| Strategies {
        third_draws: draws,
        ..Strategies::default()
    };
    let one = bus_and_paint_third_bounce(st(1), 0..32);
    let more = bus_and_paint_third_bounce(st(THIRD_BOUNCE_DRAWS), 0..32);
    let ((m1, s1), (m4, s4)) = (mean_sd(&one), mean_sd(&more));
    let se = (s1 * s1 / 32.0 + s4 * s4 / 32.0).sqrt();
    assert!((m1 - m4).abs() < 4.0 * se, "{one:?} vs {more:?}");
    assert!(
        s4 < 0.8 * s1,
        "std {s4} with {THIRD_BOUNCE_DRAWS} draws, {s1} with one"
    );
}

/// The memory estimate grows with what is kept (images split by bounces dominate) and is
/// zero with one bounce; a render that would need more than the machine has is refused
/// with the parameter named.
#[test]
fn paths_memory_is_estimated_and_checked() {
    let mesh = dihedral(0.3);
    let mut s = sensor_with(64, 3, 4, 0);
    let prof = Outputs {
        image: false,
        range: false,
        profile: true,
    };
    let small = paths_bytes(&mesh, &s, 10, prof);
    let big = paths_bytes(&mesh, &s, 10, ALL);
    // the images: 2 orders x 64^2 pixels x 16 channels, f64 sums and f32 outputs
    assert!(big - small >= 10 * (2 * 64 * 64 * 16 * 8 + 3 * 64 * 64 * 16 * 4));
    assert!(check_paths_memory(&mesh, &s, 10, ALL).is_ok());
    s.resolution = 8192;
    let e = check_paths_memory(&mesh, &s, 100_000, ALL)
        .unwrap_err()
        .to_string();
    assert!(e.contains("bounces") && e.contains("GiB"), "{e}");
    s.paths.bounces = 1;
    assert_eq!(paths_bytes(&mesh, &s, 100_000, ALL), 0);
}

/// `covered_pixels` marks the pixel of every point of every triangle (random triangles and
/// points, some crossing the image's edges), and a long thin triangle across the image
/// only the pixels along it (not its bounding box).
#[test]
fn covered_pixels_hold_their_triangles_and_follow_thin_ones() {
    let mut rand = uniform_stream(0x9e37_79b9_7f4a_7c15);
    let (w, ext) = (32, 1.0);
    let pix = 2.0 * ext / w as f64;
    for _ in 0..200 {
        let c = V3::new(2.4 * rand() - 1.2, 2.4 * rand() - 1.2, rand());
        let s = 0.5 * rand() * rand();
        let tri = [0, 1, 2].map(|_| c + s * V3::new(rand() - 0.5, rand() - 0.5, rand() - 0.5));
        let mask = covered_pixels(&[tri], V3::X, V3::Y, w, ext);
        for _ in 0..200 {
            let (mut a, mut b) = (rand(), rand());
            if a + b > 1.0 {
                (a, b) = (1.0 - a, 1.0 - b);
            }
            let p = tri[0] + a * (tri[1] - tri[0]) + b * (tri[2] - tri[0]);
            let (col, row) = (((p.x + ext) / pix).floor(), ((ext - p.y) / pix).floor());
            if col < 0.0 || row < 0.0 || col >= w as f64 || row >= w as f64 {
                continue;
            }
            assert!(
                mask[row as usize * w + col as usize],
                "{tri:?}: {p:?} not covered"
            );
        }
    }
    // a wire 0.01 pixel wide across 28.8 x 23.5 pixels: it crosses about 53 of them, and
    // its box holds 29 x 24
    let d = 0.01 * pix;
    let tri = [
        V3::new(-0.9, -0.87, 0.0),
        V3::new(0.9, 0.6, 0.0),
        V3::new(0.9 - d, 0.6 + d, 0.0),
    ];
    let n = covered_pixels(&[tri], V3::X, V3::Y, w, ext)
        .iter()
        .filter(|&&m| m)
        .count();
    assert!(
        (52..=70).contains(&n),
        "{n} pixels for a wire across about 53"
    );
}

/// The balance heuristic with each strategy's own count per pixel: paths shared unevenly
/// (the receiver's 2x in a third of its pixels and 1/4 elsewhere, the transmitter's 2x in
/// even rows and 1/2 in odd ones) still give the Lambertian dihedral's 2-bounce return
/// (the view-factor formula of the test above, each plate seen and the other lit) within
/// 4 standard errors of 12 seeds, monostatic (where the transmitter's paths start from
/// the receiver's points, with its counts) and 0.1 rad bistatic (its own pixels and
/// counts). (4 seeds were too few to estimate the error: their mean
/// read +0.2% at 1.6 of their standard errors' 4, where 48 seeds read -0.08 +- 0.08%.)
#[test]
fn uneven_path_counts_keep_the_estimate_unbiased() {
    let (side, rho, t) = (0.3, 0.8, 20f64.to_radians());
    let mesh = dihedral(side);
    let f = view_factor_perpendicular(1.0, 1.0, 1.0);
    let open = open_sides(&mesh);
    let bvh = mesh.bvh();
    let rot = view(t, 0.3);
    let posed = Posed::new(&mesh, &rot, &open, &bvh);
    let mirrors = Mirrors::none(mesh.faces.len());
    // the plates' inner normals (+x plate, -x plate) in the telescope frame
    let n_a = rotate(&rot, V3::new(-FRAC_1_SQRT_2, 0.0, FRAC_1_SQRT_2));
    let n_b = rotate(&rot, V3::new(FRAC_1_SQRT_2, 0.0, FRAC_1_SQRT_2));
    for beta in [0.0, 0.1] {
        let got: Vec<f64> = (0..12)
            .map(|seed| {
                let mut sensor = sensor_with(48, 2, 128, seed);
                sensor.bistatic_angle = beta;
                let setup = Setup::new(&mesh, &sensor, Strategies::default());
                let base = Counts::new(&setup, &posed, 128, true);
                let counts = Counts {
                    rx: (base.rx.iter().enumerate())
                        .map(|(k, &c)| if k % 3 == 0 { 2 * c } else { c / 4 })
                        .collect(),
                    tx: (base.tx.iter().enumerate())
                        .map(|(k, &c)| if (k / 48) % 2 == 0 { 2 * c } else { c / 2 })
                        .collect(),
                };
                assert!(counts.rx.iter().any(|&c| c == 256));
                assert!(counts.tx.iter().any(|&c| c == 64));
                trace(&setup, &posed, &Lambert(rho), ALL, &counts, &mirrors).total[0]
            })
            .collect();
        // 4 pi (rho / pi)^2 cos_o cos_i pi A F for each plate seen and the other lit
        let (wi, wo) = (V3::new(beta.sin(), 0.0, beta.cos()), V3::Z);
        let cos = |n: V3, w: V3| dot(n, w);
        let want = 4.0
            * rho
            * rho
            * side
            * side
            * f
            * (cos(n_a, wo) * cos(n_b, wi) + cos(n_b, wo) * cos(n_a, wi));
        let (mean, sd) = mean_sd(&got);
        let se = sd / 12f64.sqrt();
        assert!(
            se < 0.01 * want,
            "beta {beta}: standard error {se} of {want}"
        );
        assert!(
            (mean - want).abs() < 4.0 * se + 1e-4 * want,
            "beta {beta}: {mean} (+- {se}) vs {want}: {got:?}"
        );
    }
}

/// A thin square post (0.02 m wide, thinner than a pixel) standing on a box: the pixels
/// of its faces get `2^`[`allocate::THIN_SHIFT`] times the others' paths, in both views,
/// and the others all the same count.
#[test]
fn thin_parts_get_more_paths() {
    let (mut v, mut f) = cuboid([-1.0, -1.0, -1.0], [1.0, 1.0, 0.0], 0);
    let (v2, f2) = cuboid([-0.01, -0.01, 0.0], [0.01, 0.01, 0.8], 8);
    v.extend(v2);
    f.extend(f2);
    let n_f = f.len();
    let mesh = Mesh::new(v, f, None, vec![0; n_f], 1).unwrap();
    let open = open_sides(&mesh);
    let bvh = mesh.bvh();
    let rot = view(0.6, 0.4);
    let posed = Posed::new(&mesh, &rot, &open, &bvh);
    let mut sensor = sensor_with(64, 2, 4, 0);
    sensor.bistatic_angle = 0.1;
    let setup = Setup::new(&mesh, &sensor, Strategies::default());
    assert!(setup.pix > 0.02, "the post must be thinner than a pixel");
    let counts = Counts::new(&setup, &posed, 4, true);
    for (counts, w_view, u, v) in [
        (&counts.rx, setup.wo, V3::X, V3::Y),
        (&counts.tx, setup.wi, setup.tx_u, setup.tx_v),
    ] {
        // the post's open faces in this view: its sides (the last 8 faces; its top sees
        // nothing of the mesh) toward the view
        let post: Vec<[V3; 3]> = (posed.tris[16..].iter())
            .filter(|[a, b, c]| dot(cross(*b - *a, *c - *a), w_view) > 0.0)
            .copied()
            .collect();
        let on_post = covered_pixels(&post, u, v, 64, setup.lay.ext);
        let base = (counts.iter().zip(&on_post))
            .filter(|(&c, &p)| c > 0 && !p)
            .map(|(&c, _)| c)
            .min()
            .unwrap();
        let more = base << allocate::THIN_SHIFT;
        let thin: Vec<u32> = (counts.iter().zip(&on_post))
            .filter(|(_, &p)| p)
            .map(|(&c, _)| c)
            .collect();
        assert!(thin.len() > 10, "{} pixels of the post", thin.len());
        assert!(thin.iter().all(|&c| c == more), "{base}: {thin:?}");
        // the others: all the same count (or none)
        let others = (counts.iter().zip(&on_post)).filter(|(_, &p)| !p);
        assert!(others.clone().all(|(&c, _)| c == 0 || c == base));
        assert!(others.filter(|(&c, _)| c == base).count() > 100);
    }
}

/// A closed mesh with a corner in a few pixels (a small box on a big one): the paths go to
/// the pixels of faces with some of the mesh in front (the big box's top, the small box's
/// sides), `N M / M_open` each (to the nearest power of two), and none to the pixels of
/// the others alone.
#[test]
fn paths_go_to_the_pixels_of_open_faces() {
    let (mut v, mut f) = cuboid([-1.0, -1.0, -1.0], [1.0, 1.0, 0.0], 0);
    let (v2, f2) = cuboid([-0.2, -0.2, 0.0], [0.2, 0.2, 0.4], 8);
    v.extend(v2);
    f.extend(f2);
    let n_f = f.len();
    let mesh = Mesh::new(v, f, None, vec![0; n_f], 1).unwrap();
    assert!(mesh.closed);
    let open = open_sides(&mesh);
    let bvh = mesh.bvh();
    // mostly the big box's closed side x = 1, and the small box's closed top
    let rot = view(1.2, 0.3);
    let posed = Posed::new(&mesh, &rot, &open, &bvh);
    let sensor = sensor_with(64, 2, 16, 0);
    let setup = Setup::new(&mesh, &sensor, Strategies::default());
    let counts = Counts::new(&setup, &posed, 16, true);
    let all = covered_pixels(&posed.tris, V3::X, V3::Y, 64, setup.lay.ext);
    let m = all.iter().filter(|&&x| x).count();
    let m_open = counts.rx.iter().filter(|&&c| c > 0).count();
    assert!(m_open > 0 && 2 * m_open < m, "{m_open} of {m} pixels");
    let each = 16 << (m as f64 / m_open as f64).log2().round() as u32;
    assert!(counts.rx.iter().all(|&c| c == 0 || c == each), "{each}");
    assert!(counts.rx.iter().zip(&all).all(|(&c, &a)| a || c == 0));
    // monostatic: the transmitter's view is the receiver's
    assert_eq!(counts.rx, counts.tx);
}

/// A surface met along a path is evaluated with its material's terms but the seed's double
/// bounce (a quadrature per vertex); with `orders = "surface"` the banks' order 2 is a
/// table lookup and stays in: the path BRDF is then the whole core BRDF.
#[test]
fn later_surfaces_keep_the_banks_order_2() {
    use crate::brdf::spec::Orders;
    let mut spec = MaterialSpec::new(
        crate::microfacet::Distribution::Beckmann { alpha: 0.8 },
        Eta::new(1.5, 0.0),
    );
    spec.terms = Terms {
        single: true,
        double: true,
        multiple: true,
        diffuse: false,
    };
    let seed = Arc::new(Material::new(spec.clone()).unwrap());
    spec.orders = Orders::Surface;
    spec.bank_rays = 20_000;
    let surface = Arc::new(Material::new(spec).unwrap());
    let mats = [seed.clone(), surface.clone()];
    let brdf = Materials::new(&mats);
    let n = V3::new(0.0, 0.0, 1.0);
    let (wi, wo) = (
        V3::new(0.3, 0.1, 0.95).normalize(),
        V3::new(-0.2, 0.4, 0.89).normalize(),
    );
    let core = |m: &Material| crate::brdf::eval(m, wi, wo, Frame::Sp)[0][0];
    let double = |m: &Material| crate::brdf::terms::double_term(m, wi, wo, Frame::Sp)[0][0];
    let (a, b) = (
        brdf.eval(0, n, wi, wo).m[0][0],
        brdf.eval(1, n, wi, wo).m[0][0],
    );
    assert!(double(&seed) > 1e-3 * core(&seed) && double(&surface) > 1e-3 * core(&surface));
    assert!((a - (core(&seed) - double(&seed))).abs() < 1e-12 * a, "{a}");
    assert!((b - core(&surface)).abs() < 1e-12 * b, "{b}");
}
