//! Bindings for `crate::render`: a scene object holding the mesh, materials and their GPU
//! tables, batched rendering, device information.

use super::brdf::PyMaterial;
use crate::brdf::table::{BrdfTableOptions, PartOptions};
use crate::brdf::Material;
use crate::render::api::{Outputs, SensorSetup};
use crate::render::geometry::{
    check_rotations, rot_from_rows, rot_to_rows, rotations_from_quaternions, Mesh, Rot,
};
use crate::render::gpu::{self, DeviceChoice};
use crate::render::pulse::SampledPulse;
use crate::render::request::{self, Backend};
use crate::render::tables::SceneTables;
use numpy::ndarray::{Array1, Array2, Array3, Array4};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;

/// Mesh + materials + per-bistatic-angle table cache (Python: `pprender.Scene` wraps it).
#[pyclass(module = "pprender._core", name = "RenderScene", frozen)]
pub struct PyRenderScene {
    mesh: Arc<Mesh>,
    tables: SceneTables,
}

fn rows3(a: &PyReadonlyArray2<'_, f64>, name: &'static str) -> crate::Result<Vec<[f64; 3]>> {
    let v = a.as_array();
    if v.ncols() != 3 {
        return Err(crate::Error::Shape(format!(
            "{name} must have shape (n, 3), got {:?}",
            v.shape()
        )));
    }
    Ok(v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// What to render and on what ([`request::Request`] as a Python object): the sensor set-up,
/// the outputs, the backend and the table grid, checked once when built. `device`:
/// `"auto"`, `"cpu"`, `"gpu"`, `"twin"` (the kernel's f64 CPU twin with the same tables,
/// `cpu::render_tables`) or `"reference"` (the f64 CPU reference, exact BRDFs, no tables:
/// the table keywords are then unused). Python: `pprender.render` builds one per call.
#[pyclass(module = "pprender._core", name = "RenderRequest", frozen)]
pub struct PyRenderRequest {
    sensor: SensorSetup,
    outputs: Outputs,
    backend: Backend,
    table_options: BrdfTableOptions,
}

#[pymethods]
impl PyRenderRequest {
    #[new]
    #[pyo3(signature = (*, resolution, supersampling, samples, bistatic_angle, polarization,
        intensity_only, sigma_range, bin_width, image, range, profile, device, pulse_samples=None,
        pulse_spacing=0.0, analytic=false, n_z=None, n_psi=None, n_z_lambertian=None,
        n_psi_lambertian=None, n_z_double=None, n_psi_double=None, double_order=None,
        in_shader=false, bounces=1, path_samples=16, path_seed=0, illuminated_area=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        resolution: usize,
        supersampling: usize,
        samples: usize,
        bistatic_angle: f64,
        polarization: Option<[f64; 4]>,
        intensity_only: bool,
        sigma_range: f64,
        bin_width: f64,
        image: bool,
        range: bool,
        profile: bool,
        device: &str,
        pulse_samples: Option<Vec<f64>>,
        pulse_spacing: f64,
        analytic: bool,
        n_z: Option<usize>,
        n_psi: Option<usize>,
        n_z_lambertian: Option<usize>,
        n_psi_lambertian: Option<usize>,
        n_z_double: Option<usize>,
        n_psi_double: Option<usize>,
        double_order: Option<usize>,
        in_shader: bool,
        bounces: usize,
        path_samples: usize,
        path_seed: u32,
        illuminated_area: bool,
    ) -> PyResult<Self> {
        if pulse_samples.is_some() && !(pulse_spacing.is_finite() && pulse_spacing > 0.0) {
            return Err(crate::Error::param(
                "pulse_spacing",
                pulse_spacing,
                "finite and > 0 (m) with pulse_samples",
            )
            .into());
        }
        let sensor = SensorSetup {
            resolution,
            supersampling,
            samples,
            analytic,
            bistatic_angle,
            polarization,
            intensity_only,
            sigma_range,
            bin_width,
            pulse: pulse_samples
                .map(|v| SampledPulse::new(&v, pulse_spacing).map(Arc::new))
                .transpose()?,
            paths: crate::render::paths::PathSetup {
                bounces,
                samples: path_samples,
                seed: path_seed,
            },
            illuminated_area,
        };
        crate::render::check_sensor(&sensor)?;
        if illuminated_area && !profile {
            return Err(crate::Error::param(
                "illuminated_area",
                true,
                "only with the profile (profile=True): the area is the profile's S0 squared \
                 over the moment accumulated beside it",
            )
            .into());
        }
        Ok(PyRenderRequest {
            sensor,
            outputs: Outputs {
                image,
                range,
                profile,
            },
            backend: Backend::parse(device)?,
            table_options: table_options(
                n_z,
                n_psi,
                n_z_lambertian,
                n_psi_lambertian,
                n_z_double,
                n_psi_double,
                double_order,
                in_shader,
            ),
        })
    }

    fn __repr__(&self) -> String {
        let s = &self.sensor;
        format!(
            "RenderRequest(resolution={}, supersampling={}, samples={}, bistatic_angle={}, \
             bounces={}, path_samples={}, path_seed={}, image={}, range={}, profile={}, \
             backend={:?})",
            s.resolution,
            s.supersampling,
            s.samples,
            s.bistatic_angle,
            s.paths.bounces,
            s.paths.samples,
            s.paths.seed,
            self.outputs.image,
            self.outputs.range,
            self.outputs.profile,
            self.backend
        )
    }
}

/// `faces` (n, 3) as vertex-index triples, each index in `[0, u32::MAX]` (the upper bound
/// against the vertex count is the caller's: `Mesh::new`, or [`ray_cast`]).
fn faces3(faces: &PyReadonlyArray2<'_, i64>, n_vertices: usize) -> crate::Result<Vec<[u32; 3]>> {
    let fv = faces.as_array();
    if fv.ncols() != 3 {
        return Err(crate::Error::Shape(format!(
            "faces must have shape (n, 3), got {:?}",
            fv.shape()
        )));
    }
    let mut fs = Vec::with_capacity(fv.nrows());
    for (i, r) in fv.rows().into_iter().enumerate() {
        let mut f = [0u32; 3];
        for k in 0..3 {
            if r[k] < 0 || r[k] > u32::MAX as i64 {
                return Err(crate::Error::param(
                    "faces",
                    format!("{:?} at index {i}", r.to_vec()),
                    format!("vertex indices in [0, {n_vertices})"),
                ));
            }
            f[k] = r[k] as u32;
        }
        fs.push(f);
    }
    Ok(fs)
}

/// Table grid overrides from Python (`None`: the default of `BrdfTableOptions::resolve`).
#[allow(clippy::too_many_arguments)]
fn table_options(
    n_z: Option<usize>,
    n_psi: Option<usize>,
    n_z_lambertian: Option<usize>,
    n_psi_lambertian: Option<usize>,
    n_z_double: Option<usize>,
    n_psi_double: Option<usize>,
    double_order: Option<usize>,
    in_shader: bool,
) -> BrdfTableOptions {
    let part = |n_z, n_psi| PartOptions {
        n_z,
        n_psi,
        scale: None,
    };
    BrdfTableOptions {
        single: part(n_z, n_psi),
        depolarizing: part(n_z_lambertian, n_psi_lambertian),
        double: part(n_z_double, n_psi_double),
        double_order,
        frame: None,
        in_shader,
    }
}

#[pymethods]
impl PyRenderScene {
    #[new]
    #[pyo3(signature = (vertices, faces, face_material, materials, normals=None))]
    fn new(
        py: Python<'_>,
        vertices: PyReadonlyArray2<'_, f64>,
        faces: PyReadonlyArray2<'_, i64>,
        face_material: PyReadonlyArray1<'_, i64>,
        materials: Vec<Py<PyMaterial>>,
        normals: Option<PyReadonlyArray2<'_, f64>>,
    ) -> PyResult<Self> {
        if materials.is_empty() {
            return Err(crate::Error::param("materials", "[]", "at least one Material").into());
        }
        let verts = rows3(&vertices, "vertices")?;
        let fs = faces3(&faces, verts.len())?;
        let fm: Vec<u32> = face_material
            .as_array()
            .iter()
            .enumerate()
            .map(|(i, &m)| {
                if m < 0 || m > u32::MAX as i64 {
                    Err(crate::Error::param(
                        "face_material",
                        format!("{m} at face {i}"),
                        format!("indices in [0, {})", materials.len()),
                    ))
                } else {
                    Ok(m as u32)
                }
            })
            .collect::<crate::Result<_>>()?;
        let ns = normals.map(|n| rows3(&n, "normals")).transpose()?;
        let mats: Vec<Arc<Material>> = materials.iter().map(|m| m.get().inner.clone()).collect();
        let n_mat = mats.len();
        let mesh = py.detach(|| Mesh::new(verts, fs, ns, fm, n_mat))?;
        Ok(PyRenderScene {
            mesh: Arc::new(mesh),
            tables: SceneTables::new(mats),
        })
    }

    /// Radius of the bounding sphere about the body origin (m).
    #[getter]
    fn radius(&self) -> f64 {
        self.mesh.radius
    }

    /// The mesh's axis-aligned bounding box in the body frame, `(min, max)` (m).
    #[getter]
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for v in &self.mesh.vertices {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        (lo, hi)
    }

    #[getter]
    fn n_faces(&self) -> usize {
        self.mesh.faces.len()
    }

    /// Build (or fetch from the cache) the GPU tables for a bistatic angle and table grid
    /// (keywords as `brdf_table`); returns the build time in seconds (0 when cached).
    #[pyo3(signature = (bistatic_angle, *, n_z=None, n_psi=None, n_z_lambertian=None,
        n_psi_lambertian=None, n_z_double=None, n_psi_double=None, double_order=None, in_shader=false))]
    #[allow(clippy::too_many_arguments)]
    fn prepare(
        &self,
        py: Python<'_>,
        bistatic_angle: f64,
        n_z: Option<usize>,
        n_psi: Option<usize>,
        n_z_lambertian: Option<usize>,
        n_psi_lambertian: Option<usize>,
        n_z_double: Option<usize>,
        n_psi_double: Option<usize>,
        double_order: Option<usize>,
        in_shader: bool,
    ) -> PyResult<f64> {
        let opts = table_options(
            n_z,
            n_psi,
            n_z_lambertian,
            n_psi_lambertian,
            n_z_double,
            n_psi_double,
            double_order,
            in_shader,
        );
        let t = std::time::Instant::now();
        let (_, built) = py.detach(|| self.tables.get_with(bistatic_angle, &opts))?;
        Ok(if built {
            t.elapsed().as_secs_f64()
        } else {
            0.0
        })
    }

    /// The pixels that a face thinner than a pixel overlaps (`crate::render::thin`), which
    /// `K > 1` samples render by exact clipping, at each attitude of `rotations` (as
    /// `render`) in an image `width` pixels across: a bool array (n, width, width).
    fn thin_pixels<'py>(
        &self,
        py: Python<'py>,
        rotations: PyReadonlyArrayDyn<'py, f64>,
        width: usize,
    ) -> PyResult<Bound<'py, numpy::PyArray3<bool>>> {
        use crate::render::cpu::thin_pixel_mask;
        if width == 0 {
            return Err(crate::Error::param("width", width, "a positive number of pixels").into());
        }
        let rots = attitudes(rotations)?;
        let a = crate::render::thin::mesh_thinness(&self.mesh);
        let masks: Vec<bool> = rots
            .iter()
            .flat_map(|r| thin_pixel_mask(&self.mesh, a, r, width))
            .collect();
        Ok(Array3::from_shape_vec((rots.len(), width, width), masks)
            .expect("n x width x width values")
            .into_pyarray(py))
    }

    /// Render a batch: `rotations` (n, 3, 3) body -> telescope, or (n, 4) unit quaternions
    /// `(w, x, y, z)`, as `request` asks ([`PyRenderRequest`]). Returns a dict of arrays,
    /// `table_seconds`, the time spent building the materials' tables in this call (0 when
    /// cached), and `stage_seconds`, the wall-clock seconds of the render's stages
    /// ([`crate::render::Rendered::stage_seconds`] and the conversion to NumPy).
    /// `progress(done, total)` is called as attitudes are done; an exception it raises, or
    /// Ctrl-C (with or without a callback, on every backend), stops the render at the next
    /// report: after the GPU chunk, CPU attitude or path-traced attitude in progress.
    #[pyo3(signature = (rotations, request, *, progress=None))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        rotations: PyReadonlyArrayDyn<'py, f64>,
        request: &PyRenderRequest,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let rots = attitudes(rotations)?;
        let (sensor, outputs, backend, opts) = (
            &request.sensor,
            request.outputs,
            request.backend,
            &request.table_options,
        );
        let mesh = self.mesh.clone();
        // The callback runs with the GIL (from worker threads on the CPU backends). An
        // exception it raises, or a pending KeyboardInterrupt, stops the render and is raised.
        let raised: std::sync::Mutex<Option<PyErr>> = std::sync::Mutex::new(None);
        // Set once something is raised: the next report stops the render.
        let cancelled = std::sync::atomic::AtomicBool::new(false);
        let stop = |e: PyErr| {
            raised.lock().expect("progress error").get_or_insert(e);
            cancelled.store(true, std::sync::atomic::Ordering::Relaxed);
        };
        let report = |done: usize, total: usize| -> bool {
            if cancelled.load(std::sync::atomic::Ordering::Relaxed) {
                return false;
            }
            Python::attach(|py| {
                let r = py.check_signals().and_then(|()| match &progress {
                    Some(f) => f.call1(py, (done, total)).map(|_| ()),
                    None => Ok(()),
                });
                r.map_err(stop).is_ok()
            })
        };
        // Python runs signal handlers on its main thread only (`check_signals` does nothing
        // on others), and the CPU backends and the paths report from rayon's threads: the
        // render runs on a thread of its own while this one checks for signals (Ctrl-C)
        // every 50 ms, and the next report after one stops the render.
        let caller = std::thread::current();
        let finished = std::sync::atomic::AtomicBool::new(false);
        let out = py.detach(|| {
            std::thread::scope(|s| {
                let worker = std::thread::Builder::new()
                    .name("pprender render".into())
                    .stack_size(8 << 20)
                    .spawn_scoped(s, || {
                        let request = request::Request {
                            sensor,
                            outputs,
                            backend,
                            table_options: opts,
                        };
                        let out =
                            request::render(&mesh, &self.tables, &request, &rots, Some(&report));
                        finished.store(true, std::sync::atomic::Ordering::Release);
                        caller.unpark();
                        out
                    })
                    .map_err(|e| {
                        crate::Error::Device(format!("cannot start the render thread: {e}"))
                    })?;
                let finished = || finished.load(std::sync::atomic::Ordering::Acquire);
                // (or until the worker panics: `join` then passes the panic on)
                while !finished() && !worker.is_finished() {
                    std::thread::park_timeout(std::time::Duration::from_millis(50));
                    if !finished() && !cancelled.load(std::sync::atomic::Ordering::Relaxed) {
                        Python::attach(|py| py.check_signals()).unwrap_or_else(stop);
                    }
                }
                worker
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
        });
        if let Some(e) = raised.into_inner().expect("progress error") {
            return Err(e);
        }
        let out = out?;
        let (r, dev_name) = (out.rendered, out.device);
        let to_numpy = std::time::Instant::now();
        let mut stages = r.stage_seconds.clone();
        let d = PyDict::new(py);
        d.set_item("table_seconds", out.table_seconds)?;
        let (n, h, w, c) = (r.n, r.height, r.width, r.channels);
        let tot = Array2::from_shape_vec((n, c), r.total).expect("shape");
        d.set_item("total", tot.into_pyarray(py))?;
        if let Some(img) = r.image {
            let a = Array4::from_shape_vec((n, h, w, c), img).expect("shape");
            d.set_item("image", a.into_pyarray(py))?;
        }
        if let Some(rg) = r.range {
            let a = Array3::from_shape_vec((n, h, w), rg).expect("shape");
            d.set_item("range", a.into_pyarray(py))?;
        }
        if let Some(cv) = r.coverage {
            let a = Array3::from_shape_vec((n, h, w), cv).expect("shape");
            d.set_item("coverage", a.into_pyarray(py))?;
        }
        if let Some(p) = r.profile {
            let a = Array3::from_shape_vec((n, r.n_bins, c), p).expect("shape");
            d.set_item("profile", a.into_pyarray(py))?;
        }
        if let Some(q) = r.area_moment {
            let a = Array2::from_shape_vec((n, r.n_bins), q).expect("shape");
            d.set_item("area_moment", a.into_pyarray(py))?;
        }
        if !r.bounce_total.is_empty() {
            let k = r.bounce_total.len() / (n * c);
            let a = Array3::from_shape_vec((n, k, c), r.bounce_total).expect("shape");
            d.set_item("bounce_total", a.into_pyarray(py))?;
            if let Some(p) = r.bounce_profile {
                let a = Array4::from_shape_vec((n, k, r.n_bins, c), p).expect("shape");
                d.set_item("bounce_profile", a.into_pyarray(py))?;
            }
            if let Some(img) = r.bounce_image {
                let a =
                    numpy::ndarray::Array5::from_shape_vec((n, k, h, w, c), img).expect("shape");
                d.set_item("bounce_image", a.into_pyarray(py))?;
            }
        }
        let edges: Vec<f64> = (0..=r.n_bins)
            .map(|k| r.r_min + k as f64 * r.bin_width)
            .collect();
        d.set_item("bin_edges", Array1::from(edges).into_pyarray(py))?;
        d.set_item("pixel_size", r.pixel_size)?;
        d.set_item("extent", r.extent)?;
        d.set_item("device", dev_name)?;
        stages.push(("to NumPy", to_numpy.elapsed().as_secs_f64()));
        let st = PyDict::new(py);
        for (name, seconds) in stages {
            st.set_item(name, seconds)?;
        }
        d.set_item("stage_seconds", st)?;
        Ok(d)
    }
}

/// The `k` visibility samples of a pixel, (k, 2) `(u, v)` in pixel units from its top-left
/// corner, `v` down the rows (`crate::render::samples::sample_offsets`).
#[pyfunction]
fn sample_offsets<'py>(py: Python<'py>, k: usize) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
    crate::render::check_samples(k)?;
    let v: Vec<Vec<f64>> = crate::render::samples::sample_offsets(k)
        .into_iter()
        .map(|p| p.to_vec())
        .collect();
    Ok(numpy::PyArray2::from_vec2(py, &v).expect("rectangular"))
}

/// The attitudes of a render call: (n, 3, 3) rotation matrices or (n, 4) unit quaternions
/// `(w, x, y, z)`, checked.
fn attitudes(a: PyReadonlyArrayDyn<'_, f64>) -> PyResult<Vec<Rot>> {
    let v = a.as_array();
    let rots = match v.shape() {
        [_, 4] => {
            let qs: Vec<[f64; 4]> = v.outer_iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
            rotations_from_quaternions(&qs)?
        }
        [_, 3, 3] => v
            .outer_iter()
            .map(|m| {
                rot_from_rows([
                    [m[[0, 0]], m[[0, 1]], m[[0, 2]]],
                    [m[[1, 0]], m[[1, 1]], m[[1, 2]]],
                    [m[[2, 0]], m[[2, 1]], m[[2, 2]]],
                ])
            })
            .collect(),
        shape => {
            return Err(crate::Error::Shape(format!(
                "invalid attitudes: shape {shape:?}; expected (n, 4) quaternions (w, x, y, z) or \
                 (n, 3, 3) rotation matrices"
            ))
            .into())
        }
    };
    check_rotations(&rots)?;
    Ok(rots)
}

/// Rotation matrices (n, 3, 3) from (n, 4) quaternions `(w, x, y, z)`.
#[pyfunction]
fn quaternions_to_rotations<'py>(
    py: Python<'py>,
    q: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, numpy::PyArray3<f64>>> {
    let v = q.as_array();
    if v.ncols() != 4 {
        return Err(crate::Error::Shape(format!(
            "attitudes as quaternions must have shape (n, 4), got {:?}",
            v.shape()
        ))
        .into());
    }
    let qs: Vec<[f64; 4]> = v
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2], r[3]])
        .collect();
    let r = rotations_from_quaternions(&qs)?;
    let flat: Vec<f64> = r
        .iter()
        .flat_map(|m| rot_to_rows(m).into_iter().flatten())
        .collect();
    Ok(Array3::from_shape_vec((r.len(), 3, 3), flat)
        .expect("shape")
        .into_pyarray(py))
}

/// Which adapter renders for `device` (creating the device on first use).
/// `(t, tri)` per ray ([`ray_cast`]).
type Hits<'py> = (
    Bound<'py, numpy::PyArray1<f64>>,
    Bound<'py, numpy::PyArray1<i64>>,
);

/// The closest hit of each ray `origins[i] + t directions[i]`, `t > t_min`, on the mesh:
/// returns `(t, tri)`, `t = inf` and `tri = -1` for a miss. `device`: `"f64"` walks the
/// tree on the CPU in f64 (`crate::render::bvh::Bvh`, the rays shared among rayon's
/// threads); `"auto"`, `"cpu"`/`"lavapipe"` or `"gpu"` walk the same tree in the kernel
/// (`shaders/raycast.wgsl`, f32) on that adapter. For tests against other ray casters
/// (trimesh, Embree) and the ray-casting benchmark.
#[pyfunction]
#[pyo3(signature = (vertices, faces, origins, directions, t_min=0.0, device="f64"))]
fn ray_cast<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    faces: PyReadonlyArray2<'py, i64>,
    origins: PyReadonlyArray2<'py, f64>,
    directions: PyReadonlyArray2<'py, f64>,
    t_min: f64,
    device: &str,
) -> PyResult<Hits<'py>> {
    let (hits, _) = cast_rays(py, vertices, faces, origins, directions, t_min, device)?;
    Ok(hits)
}

/// [`ray_cast`], and the seconds its stages took: `{"build": the tree, "walk": the rays
/// (for the kernel: the pipeline, the uploads, the dispatches and the read-back)}`. For
/// `benchmarks/bench_raycast.py`.
#[pyfunction]
#[pyo3(signature = (vertices, faces, origins, directions, t_min=0.0, device="f64"))]
fn ray_cast_timed<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    faces: PyReadonlyArray2<'py, i64>,
    origins: PyReadonlyArray2<'py, f64>,
    directions: PyReadonlyArray2<'py, f64>,
    t_min: f64,
    device: &str,
) -> PyResult<TimedHits<'py>> {
    let ((t, tri), (build, walk)) =
        cast_rays(py, vertices, faces, origins, directions, t_min, device)?;
    let d = PyDict::new(py);
    d.set_item("build", build)?;
    d.set_item("walk", walk)?;
    Ok((t, tri, d))
}

/// `(t, tri, seconds)` ([`ray_cast_timed`]).
type TimedHits<'py> = (
    Bound<'py, numpy::PyArray1<f64>>,
    Bound<'py, numpy::PyArray1<i64>>,
    Bound<'py, PyDict>,
);

/// [`Hits`] and the seconds of the tree's build and of the walk.
type Timed<'py> = (Hits<'py>, (f64, f64));

fn cast_rays<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    faces: PyReadonlyArray2<'py, i64>,
    origins: PyReadonlyArray2<'py, f64>,
    directions: PyReadonlyArray2<'py, f64>,
    t_min: f64,
    device: &str,
) -> PyResult<Timed<'py>> {
    use crate::optics::frames::V3;
    let v = rows3(&vertices, "vertices")?;
    let o = rows3(&origins, "origins")?;
    let d = rows3(&directions, "directions")?;
    if o.len() != d.len() {
        return Err(crate::Error::Shape(format!(
            "origins and directions must have the same length, got {} and {}",
            o.len(),
            d.len()
        ))
        .into());
    }
    let mut tris = Vec::new();
    for (i, f) in faces3(&faces, v.len())?.into_iter().enumerate() {
        if f.iter().any(|&k| k as usize >= v.len()) {
            return Err(crate::Error::param(
                "faces",
                format!("{f:?} at index {i}"),
                format!("vertex indices in [0, {})", v.len()),
            )
            .into());
        }
        tris.push(f.map(|k| V3::from(v[k as usize])));
    }
    if !(t_min >= 0.0 && t_min.is_finite()) {
        return Err(crate::Error::param("t_min", t_min, "a finite t_min >= 0").into());
    }
    let choice = match device {
        "f64" => None,
        _ => Some(DeviceChoice::parse(device).map_err(|_| {
            crate::Error::param(
                "device",
                format!("{device:?}"),
                "\"f64\", \"auto\", \"cpu\", \"lavapipe\" or \"gpu\"",
            )
        })?),
    };
    let (t, tri, seconds) = py.detach(|| -> crate::Result<_> {
        use rayon::prelude::*;
        use std::time::Instant;
        let g = choice.map(gpu::context).transpose()?;
        let start = Instant::now();
        let bvh = crate::render::bvh::Bvh::new(&tris);
        let built = Instant::now();
        let (t, tri): (Vec<f64>, Vec<i64>) = match g {
            None => o
                .par_iter()
                .zip(&d)
                .map(|(o, d)| {
                    match bvh.closest_hit(V3::from(*o), V3::from(*d), t_min, f64::INFINITY) {
                        Some(h) => (h.t, h.tri as i64),
                        None => (f64::INFINITY, -1),
                    }
                })
                .unzip(),
            Some(g) => {
                let rays: Vec<_> = o
                    .iter()
                    .zip(&d)
                    .map(|(o, d)| (V3::from(*o), V3::from(*d), t_min, f64::INFINITY))
                    .collect();
                gpu::raycast::closest_hits(&g, &bvh, &rays)?
                    .into_iter()
                    .map(|h| match h {
                        Some(h) => (h.t as f64, h.tri as i64),
                        None => (f64::INFINITY, -1),
                    })
                    .unzip()
            }
        };
        let seconds = ((built - start).as_secs_f64(), built.elapsed().as_secs_f64());
        Ok((t, tri, seconds))
    })?;
    Ok((
        (
            Array1::from(t).into_pyarray(py),
            Array1::from(tri).into_pyarray(py),
        ),
        seconds,
    ))
}

#[pyfunction]
#[pyo3(signature = (device="auto"))]
fn device_info<'py>(py: Python<'py>, device: &str) -> PyResult<Bound<'py, PyDict>> {
    let choice = DeviceChoice::parse(device)?;
    let g = py.detach(|| gpu::context(choice))?;
    let i = &g.info;
    let d = PyDict::new(py);
    d.set_item("name", &i.name)?;
    d.set_item("backend", &i.backend)?;
    d.set_item("device_type", &i.device_type)?;
    d.set_item("driver", &i.driver)?;
    d.set_item("driver_info", &i.driver_info)?;
    d.set_item(
        "max_storage_buffer_binding_size",
        i.max_storage_buffer_binding_size,
    )?;
    d.set_item("max_texture_array_layers", i.max_texture_array_layers)?;
    d.set_item("max_texture_dimension_2d", i.max_texture_dimension_2d)?;
    d.set_item("raster_views", i.raster_views)?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRenderScene>()?;
    m.add_class::<PyRenderRequest>()?;
    m.add_function(wrap_pyfunction!(quaternions_to_rotations, m)?)?;
    m.add_function(wrap_pyfunction!(sample_offsets, m)?)?;
    m.add_function(wrap_pyfunction!(device_info, m)?)?;
    m.add_function(wrap_pyfunction!(ray_cast, m)?)?;
    m.add_function(wrap_pyfunction!(ray_cast_timed, m)?)?;
    Ok(())
}
