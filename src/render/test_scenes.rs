//! Test scenes shared by the renderer's tests (the GPU-CPU comparisons and the CPU
//! renderers' unit tests): meshes, a Lambertian material as tables and as a BRDF, a
//! metal, the small sensor and generic attitudes.

use crate::brdf::{Material, MaterialSpec, Terms};
use crate::microfacet::Distribution;
use crate::optics::frames::V3;
use crate::optics::fresnel::{Eta, C64};
use crate::render::api::SensorSetup;
use crate::render::geometry::{Mesh, Rot};
use crate::render::gpu::{GpuTables, PartRef};

/// A UV sphere of radius `a` (outward winding).
pub fn uv_sphere(a: f64, n_lat: usize, n_lon: usize) -> Mesh {
    let mut v = vec![[0.0, 0.0, a], [0.0, 0.0, -a]];
    for i in 1..n_lat {
        let th = std::f64::consts::PI * i as f64 / n_lat as f64;
        for j in 0..n_lon {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / n_lon as f64;
            v.push([
                a * th.sin() * ph.cos(),
                a * th.sin() * ph.sin(),
                a * th.cos(),
            ]);
        }
    }
    let idx = |i: usize, j: usize| (2 + (i - 1) * n_lon + j % n_lon) as u32;
    let mut f = vec![];
    for j in 0..n_lon {
        f.push([0, idx(1, j), idx(1, j + 1)]);
        f.push([1, idx(n_lat - 1, j + 1), idx(n_lat - 1, j)]);
    }
    for i in 1..n_lat - 1 {
        for j in 0..n_lon {
            f.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
            f.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    let normals = Some(v.iter().map(|p| [p[0] / a, p[1] / a, p[2] / a]).collect());
    let nf = f.len();
    Mesh::new(v, f, normals, vec![0; nf], 1).unwrap()
}

/// A Lambertian table: `ln(rho / pi)` and zeros, `n_z` intervals.
pub fn lambert_part(rho: f64, n_z: usize) -> Vec<f64> {
    let mut d = vec![0.0; (n_z + 1) * 16];
    for k in 0..=n_z {
        d[16 * k] = (rho / std::f64::consts::PI).ln();
    }
    d
}

/// [`lambert_part`] packed as the one material's only part (bistatic angle `beta`).
pub fn lambert_tables(rho: f64, beta: f64) -> GpuTables {
    let data = lambert_part(rho, 4);
    GpuTables::pack(
        &[vec![PartRef {
            scale: 1.0,
            n_z: 4,
            n_psi: 0,
            data: &data,
            cos_weighted: false,
            shader: None,
        }]],
        beta,
    )
    .unwrap()
}

/// The Lambertian BRDF `rho / pi` (M00 alone) for the twin.
pub fn lambert_brdf(rho: f64) -> impl Fn(usize, V3, V3) -> [[f64; 4]; 4] + Sync {
    move |_m, _wi, _wo| {
        let mut m = [[0.0; 4]; 4];
        m[0][0] = rho / std::f64::consts::PI;
        m
    }
}

pub fn lambert_sensor(res: usize) -> SensorSetup {
    SensorSetup {
        resolution: res,
        supersampling: 1,
        samples: 1,
        analytic: false,
        bistatic_angle: 0.0,
        polarization: None,
        intensity_only: false,
        sigma_range: 0.01,
        bin_width: 0.02,
        pulse: None,
        paths: Default::default(),
        illuminated_area: false,
    }
}

/// The identity and a generic attitude (no face edge-on, no edge along the grid).
pub fn two_attitudes() -> Vec<Rot> {
    crate::render::geometry::rotations_from_quaternions(&[
        [1.0, 0.0, 0.0, 0.0],
        [0.9, 0.3, -0.2, 0.25].map(|x: f64| x / (0.81f64 + 0.09 + 0.04 + 0.0625).sqrt()),
    ])
    .unwrap()
}

/// A rough metal with single, double and multiple scattering (Beckmann 0.3, eta 0.2 + 3.4i).
pub fn metal() -> Material {
    let mut spec = MaterialSpec::new(
        Distribution::Beckmann { alpha: 0.3 },
        Eta::Complex(C64::new(0.2, 3.4)),
    );
    spec.terms = Terms {
        single: true,
        double: true,
        multiple: true,
        diffuse: false,
    };
    // the exact reference's double-bounce order: 96 is within 1e-4 of the double term
    // (docs/double-bounce-benchmark.md) at 40% of the default's cost
    spec.double_order = 96;
    Material::new(spec).unwrap()
}

/// A smooth-shaded UV sphere (radius 0.5, at the origin) with a thin flat-shaded square
/// plate (0.4 x 0.4 x 0.01 m) hovering in front of it toward `+X`: bistatic, the plate's
/// shadow falls on the part of the sphere the receiver sees beside the plate.
pub fn sphere_and_plate() -> Mesh {
    let s = uv_sphere(0.5, 48, 96);
    let mut v = s.vertices.clone();
    let mut f = s.faces.clone();
    let mut nrm = s.normals.clone().unwrap();
    let (c, h, t) = ([0.3, 0.1, 0.75], 0.2, 0.005);
    let corner = |k: usize| {
        let sx = if k & 1 != 0 { h } else { -h };
        let sy = if k & 2 != 0 { h } else { -h };
        let sz = if k & 4 != 0 { t } else { -t };
        [c[0] + sx, c[1] + sy, c[2] + sz]
    };
    // each face its own 4 vertices with the face normal (flat)
    for (q, n) in [
        ([0, 4, 6, 2], [-1.0, 0.0, 0.0]),
        ([1, 3, 7, 5], [1.0, 0.0, 0.0]),
        ([0, 1, 5, 4], [0.0, -1.0, 0.0]),
        ([2, 6, 7, 3], [0.0, 1.0, 0.0]),
        ([0, 2, 3, 1], [0.0, 0.0, -1.0]),
        ([4, 5, 7, 6], [0.0, 0.0, 1.0]),
    ] {
        let b = v.len() as u32;
        for k in q {
            v.push(corner(k));
            nrm.push(n);
        }
        f.push([b, b + 1, b + 2]);
        f.push([b, b + 2, b + 3]);
    }
    let nf = f.len();
    Mesh::new(v, f, Some(nrm), vec![0; nf], 1).unwrap()
}

/// A closed, flat-shaded prism of `sections` sides about body `z` (radius `r`, length
/// `len`, centred at the origin; end caps fanned from their centres): a wire.
pub fn wire(r: f64, len: f64, sections: usize) -> Mesh {
    let mut v = vec![];
    for z in [-len / 2.0, len / 2.0] {
        for j in 0..sections {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / sections as f64;
            v.push([r * ph.cos(), r * ph.sin(), z]);
        }
    }
    let n = sections as u32;
    v.push([0.0, 0.0, -len / 2.0]);
    v.push([0.0, 0.0, len / 2.0]);
    let mut f = vec![];
    for j in 0..n {
        let k = (j + 1) % n;
        f.push([j, k, n + k]);
        f.push([j, n + k, n + j]);
        f.push([2 * n, k, j]);
        f.push([2 * n + 1, n + j, n + k]);
    }
    let nf = f.len();
    Mesh::new(v, f, None, vec![0; nf], 1).unwrap()
}

/// Body `x` toward the sensor and body `z` (a [`wire`]'s axis) at `phi` to the image's `X`.
pub fn wire_view(phi: f64) -> Rot {
    let (c, s) = (phi.cos(), phi.sin());
    crate::render::geometry::rot_from_rows([[0.0, s, c], [0.0, -c, s], [1.0, 0.0, 0.0]])
}

/// The corners and outward triangles of the box `[lo, hi]`, vertex indices from `first`.
pub fn cuboid(lo: [f64; 3], hi: [f64; 3], first: u32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let v: Vec<[f64; 3]> = (0..8)
        .map(|k| [0, 1, 2].map(|d| if (k >> d) & 1 == 1 { hi[d] } else { lo[d] }))
        .collect();
    // outward windings of the six faces (corners indexed by bits x, y, z)
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let f: Vec<[u32; 3]> = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .map(|t| t.map(|i| i + first))
        .collect();
    (v, f)
}
