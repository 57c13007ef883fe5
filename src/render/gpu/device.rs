//! The wgpu device: the adapter a [`DeviceChoice`] asks for, the device opened on it with
//! the adapter's own limits, its [`DeviceInfo`], and the shared [`context`] that caches one
//! [`Gpu`] (device, queue and pipelines, [`super::passes`]) per choice. Errors are caught by
//! error scopes ([`error_scoped`]) and reported as [`Error::Device`].

use super::pipelines::Pipelines;
use super::util::device_error;
use crate::error::{Error, Result};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// Which adapter to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DeviceChoice {
    /// A real GPU when one is present, else the CPU (lavapipe).
    Auto,
    /// The CPU implementation (Mesa lavapipe), even when a GPU is present.
    Cpu,
    /// A real GPU; an error if there is none.
    Gpu,
}

impl DeviceChoice {
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "auto" => Ok(DeviceChoice::Auto),
            "cpu" | "lavapipe" => Ok(DeviceChoice::Cpu),
            "gpu" => Ok(DeviceChoice::Gpu),
            _ => Err(Error::param(
                "device",
                format!("{s:?}"),
                "one of \"auto\", \"cpu\" (lavapipe), \"gpu\"",
            )),
        }
    }
}

/// What [`Gpu::info`] reports.
#[derive(Debug, Clone)]
pub struct DeviceInfo {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    pub driver: String,
    pub driver_info: String,
    pub max_storage_buffer_binding_size: u64,
    pub max_texture_array_layers: u32,
    pub max_texture_dimension_2d: u32,
    /// Array layers (attitudes or visibility samples) one visibility pass rasterizes: the
    /// device's multiview view count (at most 32), 1 without multiview ([`raster_views`]).
    pub raster_views: u32,
}
/// One device with its pipelines.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: DeviceInfo,
    pub(super) limits: wgpu::Limits,
    pub(super) pipelines: Pipelines,
}

static CONTEXTS: OnceLock<Mutex<HashMap<DeviceChoice, Arc<Gpu>>>> = OnceLock::new();

/// The shared device for `choice` (created on first use, then cached).
pub fn context(choice: DeviceChoice) -> Result<Arc<Gpu>> {
    let map = CONTEXTS.get_or_init(|| Mutex::new(HashMap::new()));
    let mut map = map.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(g) = map.get(&choice) {
        return Ok(g.clone());
    }
    let g = Arc::new(Gpu::new(choice)?);
    map.insert(choice, g.clone());
    Ok(g)
}

const NO_ADAPTER_HINT: &str = "install a Vulkan driver: on Debian/Ubuntu `apt install \
    mesa-vulkan-drivers libvulkan1` gives the CPU implementation (lavapipe)";
impl Gpu {
    fn new(choice: DeviceChoice) -> Result<Self> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::VULKAN;
        let instance = wgpu::Instance::new(desc);
        let request = |fallback: bool| {
            pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: fallback,
                compatible_surface: None,
                apply_limit_buckets: false,
            }))
        };
        let adapter = match choice {
            DeviceChoice::Cpu => request(true).map_err(|e| {
                device_error(format!(
                    "no CPU (lavapipe) Vulkan adapter: {e}; {NO_ADAPTER_HINT}"
                ))
            })?,
            DeviceChoice::Gpu => {
                let a = request(false).map_err(|e| {
                    device_error(format!("no GPU Vulkan adapter: {e}; use device=\"cpu\""))
                })?;
                if a.get_info().device_type == wgpu::DeviceType::Cpu {
                    return Err(device_error(format!(
                        "device=\"gpu\" but the only Vulkan adapter is the CPU implementation \
                         {:?}; use device=\"auto\" or \"cpu\"",
                        a.get_info().name
                    )));
                }
                a
            }
            DeviceChoice::Auto => match request(false) {
                Ok(a) => a,
                Err(_) => request(true).map_err(|e| {
                    device_error(format!("no Vulkan adapter: {e}; {NO_ADAPTER_HINT}"))
                })?,
            },
        };
        let ainfo = adapter.get_info();
        let limits = adapter.limits();
        let views = raster_views(&adapter);
        let features = if views > 1 {
            wgpu::Features::MULTIVIEW
        } else {
            wgpu::Features::empty()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("pprender"),
            required_features: features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| device_error(format!("cannot open the Vulkan device: {e}")))?;
        // Errors are caught by error scopes around every operation; anything that escapes
        // must not abort the Python process.
        device.on_uncaptured_error(Arc::new(|e| {
            eprintln!("pprender: uncaptured wgpu error: {e}");
        }));
        let info = DeviceInfo {
            name: ainfo.name.clone(),
            backend: format!("{:?}", ainfo.backend),
            device_type: format!("{:?}", ainfo.device_type),
            driver: ainfo.driver.clone(),
            driver_info: ainfo.driver_info.clone(),
            max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
            max_texture_array_layers: limits.max_texture_array_layers,
            max_texture_dimension_2d: limits.max_texture_dimension_2d,
            raster_views: views,
        };
        let pipelines = Pipelines::new(&device, views)?;
        // what the device accepted (one layer per pass where it refused the multiview pipelines)
        let info = DeviceInfo {
            raster_views: pipelines.views,
            ..info
        };
        Ok(Gpu {
            device,
            queue,
            info,
            limits,
            pipelines,
        })
    }
}

/// The environment variable that caps the layers per visibility pass (a diagnostic: `1`
/// draws one layer per pass, as devices without multiview do).
pub const RASTER_VIEWS_ENV: &str = "PPRENDER_RASTER_VIEWS";

/// Layers per visibility pass on `adapter`: its multiview view count, at most 31 (wgpu
/// caps the count at 32, and wgpu 30 asks for SELECTIVE_MULTIVIEW for a mask of all 32
/// views: its mask arithmetic overflows) and at most [`RASTER_VIEWS_ENV`] when that is set
/// to a positive integer; 1 without the MULTIVIEW feature. A pass per layer costs the device tens of microseconds whatever
/// the layer's size (docs/gpu-benchmark.md), which multiview shares among the views.
fn raster_views(adapter: &wgpu::Adapter) -> u32 {
    if !adapter.features().contains(wgpu::Features::MULTIVIEW) {
        return 1;
    }
    let cap = std::env::var(RASTER_VIEWS_ENV)
        .ok()
        .and_then(|v| v.trim().parse::<u32>().ok())
        .filter(|&v| v >= 1)
        .unwrap_or(32);
    adapter
        .limits()
        .max_multiview_view_count
        .min(31)
        .min(cap)
        .max(1)
}
