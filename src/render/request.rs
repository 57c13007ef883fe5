//! One entry for every backend: a render request (mesh, the scene's materials and table
//! cache, sensor, attitudes, outputs) run on the [`Backend`] it names, the GPU kernels
//! ([`crate::render::gpu`]) or one of the f64 CPU renderers ([`crate::render::cpu`]).
//! The Python binding only converts its arguments and calls [`render`].

use super::api::{Outputs, Progress, Rendered, SensorSetup};
use super::cpu;
use super::geometry::{Mesh, Rot};
use super::gpu::{self, DeviceChoice};
use super::paths;
use super::tables::SceneTables;
use crate::brdf::table::BrdfTableOptions;
use crate::error::Result;

/// Which renderer runs a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// The wgpu kernels (f32) on the adapter chosen, with the scene's packed tables.
    Gpu(DeviceChoice),
    /// The kernels' algorithm in f64 on the CPU with the same tables
    /// ([`cpu::render_tables`], `Lidar(arithmetic="f64")`).
    Cpu64,
    /// The exact f64 reference: every material evaluated by the core, no tables
    /// ([`cpu::render_reference`], `quality="reference"`).
    Reference,
}

impl Backend {
    /// The backend a device string names: `"twin"` ([`Backend::Cpu64`]), `"reference"`, or
    /// an adapter ([`DeviceChoice::parse`]: `"auto"`, `"cpu"`/`"lavapipe"`, `"gpu"`).
    pub fn parse(device: &str) -> Result<Self> {
        match device {
            "twin" => Ok(Backend::Cpu64),
            "reference" => Ok(Backend::Reference),
            _ => DeviceChoice::parse(device).map(Backend::Gpu),
        }
    }
}

/// Render a batch of attitudes (`rotations`) of `mesh` as `request` says, with the scene's
/// materials and their tables for the sensor's bistatic angle and `table_options` (built on
/// first use and cached in `tables`; the reference uses neither). An empty batch is
/// refused ([`gpu::check_batch`]), and the CPU backends refuse a render that would not fit
/// ([`cpu::check_cpu_render`]). Returns the result, what rendered it and the tables' build
/// time ([`RenderOutput`]). `progress` is told how many attitudes are done as the render
/// goes and may stop it ([`Progress`]).
pub fn render(
    mesh: &Mesh,
    tables: &SceneTables,
    request: &Request,
    rotations: &[Rot],
    progress: Progress,
) -> Result<RenderOutput> {
    let Request {
        sensor,
        outputs,
        backend,
        table_options,
    } = *request;
    gpu::check_batch(rotations)?;
    if sensor.illuminated_area && !outputs.profile {
        return Err(crate::Error::param(
            "illuminated_area",
            true,
            "only with the profile output: the area is the profile's S0 squared over the \
             moment accumulated beside it",
        ));
    }
    paths::check_paths_memory(mesh, sensor, rotations.len(), outputs)?;
    // the workers report as they finish, not in order: the caller sees a count that never
    // goes down and ends at the total
    let ordered = Ordered::new(progress);
    let ordered_fn = |done: usize, total: usize| ordered.report(done, total);
    let progress: Progress =
        progress.map(|_| &ordered_fn as &(dyn Fn(usize, usize) -> bool + Sync));
    let beta = sensor.bistatic_angle;
    // with inter-reflections the backend's pass is the first half of the progress
    let with_paths = sensor.paths.bounces > 1;
    let n = rotations.len();
    let halved = |done: usize, _: usize| progress.is_none_or(|p| p(done, 2 * n));
    let backend_progress: Progress = match progress {
        Some(_) if with_paths => Some(&halved),
        _ => progress,
    };
    let timed = std::time::Instant::now();
    let seconds = |built: bool| {
        if built {
            timed.elapsed().as_secs_f64()
        } else {
            0.0
        }
    };
    let (mut rendered, device, table_seconds) = match backend {
        Backend::Reference => {
            cpu::check_cpu_render(mesh, sensor, rotations.len(), outputs)?;
            let t = std::time::Instant::now();
            let mut r = cpu::render_reference(
                mesh,
                sensor,
                rotations,
                outputs,
                &tables.materials,
                backend_progress,
            )?;
            r.stage_seconds = vec![("render", t.elapsed().as_secs_f64())];
            (r, "reference (f64 CPU, exact BRDFs)".to_string(), 0.0)
        }
        Backend::Cpu64 => {
            cpu::check_cpu_render(mesh, sensor, rotations.len(), outputs)?;
            let (_, f64_tables, built) = tables.get_with_tables(beta, table_options)?;
            let t = seconds(built);
            let started = std::time::Instant::now();
            let mut r = cpu::render_tables(
                mesh,
                sensor,
                rotations,
                outputs,
                &f64_tables,
                backend_progress,
            )?;
            r.stage_seconds = vec![("tables", t), ("render", started.elapsed().as_secs_f64())];
            (r, "f64 twin (CPU, BRDF tables)".to_string(), t)
        }
        Backend::Gpu(choice) => {
            let (packed, f64_tables, built) = tables.get_with_tables(beta, table_options)?;
            let t = seconds(built);
            let started = std::time::Instant::now();
            let g = gpu::context(choice)?;
            let context = started.elapsed().as_secs_f64();
            let mut r = gpu::render_with_progress(
                &g,
                mesh,
                &packed,
                sensor,
                rotations,
                outputs,
                backend_progress,
            )?;
            r.stage_seconds
                .splice(0..0, [("tables", t), ("device context", context)]);
            // the pixels with thin faces, which the device leaves to the CPU
            let started = std::time::Instant::now();
            cpu::add_thin_pixels(
                &mut r,
                mesh,
                sensor,
                rotations,
                outputs,
                &cpu::Tables(&f64_tables),
                backend_progress,
            )?;
            r.stage_seconds
                .push(("thin pixels (CPU)", started.elapsed().as_secs_f64()));
            (r, g.info.name.clone(), t)
        }
    };
    if with_paths {
        let started = std::time::Instant::now();
        let sums = paths::render_paths(
            mesh,
            sensor,
            rotations,
            outputs,
            &paths::Materials::new(&tables.materials),
            progress,
            (n, 2 * n),
        )?;
        paths::add_paths(&mut rendered, sensor, &sums);
        rendered
            .stage_seconds
            .push(("paths", started.elapsed().as_secs_f64()));
    }
    Ok(RenderOutput {
        rendered,
        device,
        table_seconds,
    })
}

/// A progress callback whose counts never go down: the backends' workers count attitudes
/// atomically but report them from their own threads, so a smaller count could reach the
/// caller after a larger one (a render's last report was (5, 6) after (6, 6)). A late
/// smaller count is reported as the largest so far (the callback is still asked whether to
/// go on), and reports are made one at a time.
struct Ordered<'a> {
    inner: Progress<'a>,
    last: std::sync::Mutex<usize>,
}

impl<'a> Ordered<'a> {
    fn new(inner: Progress<'a>) -> Self {
        Ordered {
            inner,
            last: std::sync::Mutex::new(0),
        }
    }

    fn report(&self, done: usize, total: usize) -> bool {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        *last = (*last).max(done);
        self.inner.is_none_or(|p| p(*last, total))
    }
}

/// What to render, and on what: the sensor set-up, the outputs, the backend and the BRDF
/// table grid (unused by the reference).
#[derive(Clone, Copy)]
pub struct Request<'a> {
    pub sensor: &'a SensorSetup,
    pub outputs: Outputs,
    pub backend: Backend,
    pub table_options: &'a BrdfTableOptions,
}

/// What [`render`] returns.
pub struct RenderOutput {
    pub rendered: Rendered,
    /// What rendered it: the adapter's name, `"f64 twin (CPU, BRDF tables)"` or
    /// `"reference (f64 CPU, exact BRDFs)"`.
    pub device: String,
    /// Seconds spent building the materials' tables in this call (0 when they were
    /// cached, and for the reference, which uses none).
    pub table_seconds: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression (a flaky `tests/test_settings.py` run: the last report was (5, 6) after
    /// (6, 6)): counts that arrive out of order reach the callback never going down and
    /// ending at the largest; a late count still asks whether to go on; none is lost.
    #[test]
    fn progress_counts_never_go_down() {
        let seen = std::sync::Mutex::new(Vec::new());
        let stop_at = 7;
        let f = |d: usize, t: usize| {
            seen.lock().unwrap().push((d, t));
            d < stop_at
        };
        let o = Ordered::new(Some(&f));
        let calls = [1, 2, 4, 6, 3, 5];
        assert!(calls.iter().all(|&d| o.report(d, 6)));
        let got: Vec<usize> = seen.lock().unwrap().iter().map(|x| x.0).collect();
        assert_eq!(got, [1, 2, 4, 6, 6, 6]);
        assert!(!o.report(7, 8) && !o.report(2, 8), "a stop is still heard");
        assert!(Ordered::new(None).report(3, 6));
    }

    /// The device strings the Python side sends name the backends; anything else is
    /// refused with the adapter choices, as before there was a `Backend`.
    #[test]
    fn device_strings_name_the_backends() {
        assert_eq!(Backend::parse("twin").unwrap(), Backend::Cpu64);
        assert_eq!(Backend::parse("reference").unwrap(), Backend::Reference);
        for (s, c) in [
            ("auto", DeviceChoice::Auto),
            ("cpu", DeviceChoice::Cpu),
            ("lavapipe", DeviceChoice::Cpu),
            ("gpu", DeviceChoice::Gpu),
        ] {
            assert_eq!(Backend::parse(s).unwrap(), Backend::Gpu(c));
        }
        let e = Backend::parse("f64").unwrap_err().to_string();
        let d = DeviceChoice::parse("f64").unwrap_err().to_string();
        assert_eq!(e, d);
    }

    /// An empty batch is an error on every backend. The GPU path panicked on it (its chunk
    /// of 0 attitudes made `step_by(0)`), inside its pushed error scopes.
    #[test]
    fn an_empty_batch_is_refused_on_every_backend() {
        use crate::render::test_scenes::{lambert_sensor, metal, uv_sphere};
        let mesh = uv_sphere(0.5, 8, 16);
        let tables = SceneTables::new(vec![std::sync::Arc::new(metal())]);
        let all = Outputs {
            image: true,
            range: true,
            profile: true,
        };
        for backend in [
            Backend::Gpu(DeviceChoice::Cpu),
            Backend::Cpu64,
            Backend::Reference,
        ] {
            let request = Request {
                sensor: &lambert_sensor(8),
                outputs: all,
                backend,
                table_options: &BrdfTableOptions::default(),
            };
            let r = render(&mesh, &tables, &request, &[], None);
            let e = r.err().expect("an empty batch is refused").to_string();
            assert!(e.contains("attitudes"), "{backend:?}: {e}");
        }
        let g = gpu::context(DeviceChoice::Cpu).unwrap();
        let packed = tables.get(0.0).unwrap().0;
        assert!(gpu::render(&g, &mesh, &packed, &lambert_sensor(8), &[], all).is_err());
    }
}
