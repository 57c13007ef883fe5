//! The wgpu side of the renderer: adapter choice, pipelines, chunked batch rendering.
//!
//! Per chunk of attitudes: one render pass per attitude and visibility sample rasterizes
//! triangle indices into a layer of an R32Uint texture array (`shaders/visibility.wgsl`;
//! with `K >= 4` samples, one 4x multisampled render pass per attitude into fixed tiles,
//! gathered by `shaders/gather.wgsl` into a buffer: [`MsaaTiles`]), then one compute dispatch
//! (`shaders/shade.wgsl`, specialized by override constants to the requested outputs)
//! shades every pixel and accumulates the profile and total in 64-bit fixed point. Only the
//! requested buffers are created and read back. Bistatic (`beta > 0`) the same raster
//! pipeline first draws each attitude from the transmitter too (rotations
//! [`transmitter_rotation`]) into a second texture array, which the shade kernel (compiled
//! with `SHADOWS`) reads to test cast shadows; monostatic neither the pass nor the test
//! exists. Conventions: [`crate::render`].

use super::api::{Layout, Outputs, Rendered, SensorSetup};
use super::geometry::{gpu_rotation, transmitter_rotation, Mesh, Rot};
use super::pulse::SampledPulse;
use super::shaders;
use crate::error::{Error, Result};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};
use wgpu::util::DeviceExt;

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
}

/// One device with its pipelines.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: DeviceInfo,
    limits: wgpu::Limits,
    vis_layout: wgpu::BindGroupLayout,
    vis_pipeline: [wgpu::RenderPipeline; 2],
    /// The same at [`MSAA`] samples per texel, ids as `f32` (`fs_float`), into the tiles
    /// of `K >= 4` ([`MsaaTiles`]), and the kernel that gathers them (`gather.wgsl`).
    vis_pipeline_msaa: [wgpu::RenderPipeline; 2],
    gather_layout: wgpu::BindGroupLayout,
    gather_pipeline: wgpu::ComputePipeline,
    /// Placeholders for the shade kernel's id bindings that a request does not use: a
    /// 1 x 1 layer array (binding 0 with `K >= 4`) and a 16-byte buffer (binding 10 with
    /// `K < 4`).
    dummy_ids: wgpu::TextureView,
    dummy_buffer: wgpu::Buffer,
    shade_layout: wgpu::BindGroupLayout,
    shade_pipeline_layout: wgpu::PipelineLayout,
    shade_module: wgpu::ShaderModule,
    shade_pipelines: Mutex<HashMap<ShadeKey, Arc<wgpu::ComputePipeline>>>,
}

/// Override constants of the shade kernel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct ShadeKey {
    channels: u32,
    image: bool,
    range: bool,
    profile: bool,
    total: bool,
    footprint: bool,
    /// Transmitter cast shadows (bistatic only).
    shadows: bool,
    /// The Mueller elements looked up ([`SensorSetup::element_mask`]).
    elements: u32,
    /// Visibility samples per pixel.
    samples: u32,
    /// Analytic coverage ([`SensorSetup::analytic`]).
    analytic: bool,
    /// Some material's terms are evaluated in the kernel ([`GpuTables::in_shader`]).
    in_shader: bool,
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

fn device_error(msg: impl Into<String>) -> Error {
    Error::Device(msg.into())
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
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("pprender"),
            required_features: wgpu::Features::empty(),
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
        };

        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let storage =
            |binding: u32, read_only: bool, vis: wgpu::ShaderStages| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: vis,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            };
        let uniform = |binding: u32, vis: wgpu::ShaderStages| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: vis,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let texture = |binding: u32,
                       sample_type: wgpu::TextureSampleType,
                       view_dimension: wgpu::TextureViewDimension,
                       multisampled: bool,
                       vis: wgpu::ShaderStages| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: vis,
            ty: wgpu::BindingType::Texture {
                sample_type,
                view_dimension,
                multisampled,
            },
            count: None,
        };
        let vs = wgpu::ShaderStages::VERTEX;
        let vis_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("visibility"),
            entries: &[storage(0, true, vs), storage(1, true, vs), uniform(2, vs)],
        });
        let vis_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("visibility.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::VISIBILITY.into()),
        });
        let vis_pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("visibility"),
            bind_group_layouts: &[Some(&vis_layout)],
            immediate_size: 0,
        });
        // [no culling, back faces culled (closed, outward-wound meshes: Mesh::closed)];
        // the view maps the body's outward normals facing the viewer to counter-clockwise
        let vis_pipelines = |count: u32, fs: &str, format| {
            [None, Some(wgpu::Face::Back)].map(|cull_mode| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("visibility"),
                layout: Some(&vis_pl),
                vertex: wgpu::VertexState {
                    module: &vis_module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    cull_mode,
                    front_face: wgpu::FrontFace::Ccw,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: wgpu::TextureFormat::Depth32Float,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: wgpu::MultisampleState {
                    count,
                    ..Default::default()
                },
                fragment: Some(wgpu::FragmentState {
                    module: &vis_module,
                    entry_point: Some(fs),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
            })
        };
        let vis_pipeline = vis_pipelines(1, "fs_main", wgpu::TextureFormat::R32Uint);
        // R32Float: multisampled in core WebGPU (R32Uint needs an adapter-specific feature)
        let vis_pipeline_msaa =
            vis_pipelines(MSAA as u32, "fs_float", wgpu::TextureFormat::R32Float);
        let dummy_ids = IdTarget::new(&device, "unused ids", 1, 1).array_view;
        let dummy_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("unused"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let cs = wgpu::ShaderStages::COMPUTE;
        let gather_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gather"),
            entries: &[
                texture(
                    0,
                    wgpu::TextureSampleType::Float { filterable: false },
                    wgpu::TextureViewDimension::D2,
                    true,
                    cs,
                ),
                storage(1, false, cs),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: cs,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: true,
                        min_binding_size: wgpu::BufferSize::new(16),
                    },
                    count: None,
                },
            ],
        });
        let gather_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("gather.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::GATHER.into()),
        });
        let gather_pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("gather"),
            layout: Some(&device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("gather"),
                bind_group_layouts: &[Some(&gather_layout)],
                immediate_size: 0,
            })),
            module: &gather_module,
            entry_point: Some("cs_gather"),
            compilation_options: Default::default(),
            cache: None,
        });
        let shade_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("shade"),
            entries: &[
                texture(
                    0,
                    wgpu::TextureSampleType::Uint,
                    wgpu::TextureViewDimension::D2Array,
                    false,
                    cs,
                ),
                storage(1, true, cs),
                storage(2, true, cs),
                storage(3, true, cs),
                uniform(4, cs),
                storage(5, false, cs),
                storage(6, false, cs),
                storage(7, false, cs),
                storage(8, false, cs),
                // triangle ids seen from the transmitter (the receiver's when monostatic)
                texture(
                    9,
                    wgpu::TextureSampleType::Uint,
                    wgpu::TextureViewDimension::D2Array,
                    false,
                    cs,
                ),
                // the receiver's ids with K >= 4 samples (gather.wgsl)
                storage(10, true, cs),
            ],
        });
        let shade_pipeline_layout =
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("shade"),
                bind_group_layouts: &[Some(&shade_layout)],
                immediate_size: 0,
            });
        let shade_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shade.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::shade_module().into()),
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(device_error(format!("pipeline creation failed: {e}")));
        }
        Ok(Gpu {
            device,
            queue,
            info,
            limits,
            vis_layout,
            vis_pipeline,
            vis_pipeline_msaa,
            gather_layout,
            gather_pipeline,
            dummy_ids,
            dummy_buffer,
            shade_layout,
            shade_pipeline_layout,
            shade_module,
            shade_pipelines: Mutex::new(HashMap::new()),
        })
    }

    fn shade_pipeline(&self, key: ShadeKey) -> Result<Arc<wgpu::ComputePipeline>> {
        let mut map = self
            .shade_pipelines
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        if let Some(p) = map.get(&key) {
            return Ok(p.clone());
        }
        let b = |x: bool| if x { 1.0 } else { 0.0 };
        let constants = [
            ("CHANNELS", key.channels as f64),
            ("WRITE_IMAGE", b(key.image)),
            ("WRITE_RANGE", b(key.range)),
            ("WRITE_PROFILE", b(key.profile)),
            ("WRITE_TOTAL", b(key.total)),
            ("WRITE_FOOTPRINT", b(key.footprint)),
            ("SHADOWS", b(key.shadows)),
            ("ELEMENT_MASK", key.elements as f64),
            ("SAMPLES", key.samples as f64),
            ("COVERAGE", b(key.analytic)),
            ("IN_SHADER", b(key.in_shader)),
        ];
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let p = self
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("shade"),
                layout: Some(&self.shade_pipeline_layout),
                module: &self.shade_module,
                entry_point: Some("cs_main"),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &constants,
                    zero_initialize_workgroup_memory: true,
                },
                cache: None,
            });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(device_error(format!("shade pipeline creation failed: {e}")));
        }
        let p = Arc::new(p);
        map.insert(key, p.clone());
        Ok(p)
    }
}

/// Side of the transmitter's id map for a receiver image side `w` (bistatic cast shadows):
/// twice `w` (texels of half a pixel, so that occluders down to about half a pixel wide are
/// seen), or `w` itself where that would exceed 4096 texels or the device's limit.
pub fn transmitter_map_width(w: usize, max_dim: usize) -> usize {
    if 2 * w <= max_dim.min(4096) {
        2 * w
    } else {
        w
    }
}

/// Uniform block of `shade.wgsl` (layout checked against the WGSL struct in a test).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable, Debug)]
pub struct ShadeParams {
    pub width: u32,
    pub height: u32,
    pub n_bins: u32,
    pub n_tri: u32,
    pub ext: f32,
    pub pix: f32,
    pub r_min: f32,
    pub bin_width: f32,
    pub wi: [f32; 4],
    pub wo: [f32; 4],
    pub s_tx: [f32; 4],
    pub sigma: f32,
    pub support: f32,
    pub fix_scale: f32,
    pub has_normals: u32,
    pub beta: f32,
    pub max_extent: f32,
    /// Side of the transmitter's id map (texels; bistatic only).
    pub tx_width: u32,
    /// 1 for a closed mesh ([`Mesh::closed`]: back faces culled).
    pub closed: u32,
    /// Per visibility sample `(u, v, dc, dr)`: its offset in the pixel ([`sample_offsets`])
    /// and, with `K >= 4`, the texel of its raster pass's tile that holds it, relative to
    /// the pixel's ([`msaa_samples`]; the first [`SensorSetup::samples`], which the kernel
    /// has as the constant `SAMPLES`).
    pub offsets: [[f32; 4]; MAX_SAMPLES],
}

/// Uniform block of `visibility.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable, Debug)]
struct VisParams {
    ext: f32,
    ext_z: f32,
    _pad: [f32; 2],
}

/// Most visibility samples per pixel ([`SensorSetup::samples`]).
pub const MAX_SAMPLES: usize = 16;

/// The `k` visibility samples of a pixel, `(u, v)` in pixel units from its top-left corner
/// (`u` along `+X`, `v` down the rows). Each row and each column of the `k x k` grid holds
/// one sample ("n-rooks": an axis-aligned edge is resolved to `1/k` of a pixel), and for
/// `k != 8` they form a (0, m, 2)-net: every box `[a/2^i, (a+1)/2^i) x [b/2^j, (b+1)/2^j)`
/// with `i + j = m` holds exactly one (for `k = 4, 16` one per cell of the `sqrt(k)` grid;
/// `k = 8`: two per quadrant). The set is symmetric under a half turn about the pixel
/// centre, so their mean is the centre. `k = 1` is the centre itself, `k = 2` the first
/// two points of the Sobol' sequence shifted by `1/4`; `k >= 4` are the rasterizer's
/// standard 4x multisample positions, shifted per raster pass and wrapped into the pixel
/// ([`msaa_samples`]).
pub fn sample_offsets(k: usize) -> Vec<[f64; 2]> {
    assert!(k.is_power_of_two() && k <= MAX_SAMPLES);
    match k {
        1 => vec![[0.5, 0.5]],
        2 => vec![[0.25, 0.25], [0.75, 0.75]],
        _ => msaa_samples(k).iter().map(|s| s.uv).collect(),
    }
}

/// Samples per texel of the multisampled visibility raster (`K >= 4`).
pub const MSAA: usize = 4;

/// The standard 4x multisample positions in a texel, `(u, v)` from its top-left corner
/// (WebGPU's, Vulkan's `standardSampleLocations`, Direct3D's and Metal's).
const MSAA_POSITIONS: [[i32; 2]; MSAA] = [[6, 2], [14, 6], [2, 10], [10, 14]]; // / 16

/// Per raster pass, the shift of the sample positions in units of `1 / (2k)` pixel for
/// `k = 8, 16` (`k = 4`: one pass, none), found by exhaustive search over odd shifts: the
/// `k` (wrapped) positions are symmetric under a half turn about the pixel centre (so a
/// render is invariant under a half turn about the line of sight, as the scene is) and
/// form a (0, m, 2)-net. For `k = 8` no symmetric net exists among these; of the
/// symmetric ones with one sample per row and column and two per quadrant, these shifts put
/// two samples in the fewest of the 16 `2 x 4` and `4 x 2` boxes (4), then wrap the fewest.
const MSAA_SHIFTS_8: [[i32; 2]; 2] = [[-3, -1], [3, 1]];
const MSAA_SHIFTS_16: [[i32; 2]; 4] = [[-13, -7], [-1, 5], [1, -5], [13, 7]];

/// Where visibility sample `k` of a pixel comes from with `K >= 4`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MsaaSample {
    /// Its position in the pixel, `(u, v)` from the top-left corner.
    pub uv: [f64; 2],
    /// The raster pass (tile of [`MsaaTiles`]) and the sample index in the texel.
    pub pass: usize,
    pub sample: usize,
    /// The texel that holds it, `(column, row)` relative to the pixel's: pass `p` moves
    /// the image by `-shift_p`, so its sample `s` in texel `t` sees the point
    /// `t + position_s + shift_p`, which lies in a neighbouring pixel when
    /// `position_s + shift_p` leaves `[0, 1)`.
    pub texel: [i32; 2],
}

/// The `k >= 4` visibility samples in order `k = MSAA pass + sample`.
pub fn msaa_samples(k: usize) -> Vec<MsaaSample> {
    let shifts: &[[i32; 2]] = match k {
        4 => &[[0, 0]],
        8 => &MSAA_SHIFTS_8,
        16 => &MSAA_SHIFTS_16,
        _ => panic!("msaa_samples: K = {k} (4, 8 or 16)"),
    };
    let units = 2 * k as i32; // per pixel
    let mut out = Vec::with_capacity(k);
    for (pass, sh) in shifts.iter().enumerate() {
        for (sample, pos) in MSAA_POSITIONS.iter().enumerate() {
            let a = [0, 1].map(|i| pos[i] * units / 16 + sh[i]);
            out.push(MsaaSample {
                uv: a.map(|x| x.rem_euclid(units) as f64 / units as f64),
                pass,
                sample,
                texel: a.map(|x| -x.div_euclid(units)),
            });
        }
    }
    out
}

/// The raster passes of `k` samples: per pass, the displacement `(du, dv)` (pixels, `v`
/// down) that brings its sample points where the rasterizer samples: `K < 4`, one pass per
/// sample, moved onto the texel centre; `K >= 4`, one multisampled pass per [`MSAA`]
/// samples, moved by minus its shift.
fn raster_displacements(k: usize) -> Vec<[f64; 2]> {
    if k < MSAA {
        return sample_offsets(k)
            .iter()
            .map(|o| [0.5 - o[0], 0.5 - o[1]])
            .collect();
    }
    msaa_samples(k)
        .chunks(MSAA)
        .map(|c| {
            let o = &c[0];
            let p = MSAA_POSITIONS[o.sample];
            // minus the shift: position - (uv - texel)
            [0, 1].map(|i| p[i] as f64 / 16.0 - o.uv[i] + o.texel[i] as f64)
        })
        .collect()
}

/// [`sample_offsets`] (and the tile texels, [`msaa_samples`]) as the uniform block holds them.
fn gpu_offsets(k: usize) -> [[f32; 4]; MAX_SAMPLES] {
    let mut o = [[0.0f32; 4]; MAX_SAMPLES];
    for (d, s) in o.iter_mut().zip(sample_offsets(k)) {
        *d = [s[0] as f32, s[1] as f32, 0.0, 0.0];
    }
    if k >= MSAA {
        for (d, s) in o.iter_mut().zip(msaa_samples(k)) {
            d[2] = s.texel[0] as f32;
            d[3] = s.texel[1] as f32;
        }
    }
    o
}

/// The material tables as uploaded: per material [`HEADER_WORDS`] words of header, four
/// per part `[offset, n_z, n_psi, scale]` (offset and counts as u32 bits; `n_z = 0`: no
/// such part; `-scale` for a part whose nodes hold `M cos(theta)`,
/// [`crate::brdf::table::TablePart::cos_weighted`]), then the parts' data (layout in
/// [`crate::brdf::table::BrdfTable`]).
#[derive(Debug, Clone)]
pub struct GpuTables {
    pub data: Vec<f32>,
    /// Upper bound of `M00 cos(theta_i)` over all materials (1/sr) away from the last
    /// table cell before grazing: it sets the fixed-point scale, and the kernel clamps
    /// each pixel's accumulated value to `4 pi delta^2 max_m00`. (The single term with
    /// correlated masking, whose `M00` diverges at grazing as `1 / cos`, is tabulated as
    /// `M cos(theta)` and bounded with `cos(theta_i) / cos(theta) <= 2`; another part
    /// that grew toward grazing could still exceed the bound in the last cell, within
    /// `atan(1 / (scale n_z))` of grazing, where the clamp would touch it.)
    pub max_m00: f64,
    /// Some material's terms are evaluated in the kernel ([`InKernel`]): the kernel's
    /// `IN_SHADER`.
    pub in_shader: bool,
}

/// `n_psi` header word of a part evaluated in the kernel (`n_z` word 0, offset: its
/// words, [`crate::brdf::table::SingleParams::words`] or
/// [`crate::brdf::table::LambertianParams::words`], the first of which is its kind).
pub const SHADER_PART: u32 = u32::MAX;
/// Margin on the sampled bound of an in-kernel part's `M00 cos(theta_i)` for
/// [`GpuTables::max_m00`] (it is sampled at nodes, and the kernel clamps a pixel at the
/// bound; a factor 4 costs two of the fixed point's 40 bits).
pub const SHADER_PART_MARGIN: f64 = 4.0;

/// Table parts per material the kernel reads (single, multiple + diffuse, double).
pub const MAX_PARTS: usize = 3;
/// Header words per material.
pub const HEADER_WORDS: usize = 4 * MAX_PARTS;

/// One tabulated part: `(scale, n_z, n_psi, data [psi][z][16] with ln M00 first)`.
pub struct PartRef<'a> {
    pub scale: f64,
    pub n_z: usize,
    pub n_psi: usize,
    pub data: &'a [f64],
    /// The nodes hold `M cos(theta)` ([`crate::brdf::table::TablePart::cos_weighted`]).
    pub cos_weighted: bool,
    /// Instead of a table: a part evaluated in the kernel (`data` empty, `n_z` 0).
    pub shader: Option<InKernel<'a>>,
}

/// A part the kernel evaluates from parameters instead of a table.
#[derive(Clone, Copy)]
pub enum InKernel<'a> {
    Single(&'a crate::brdf::table::SingleParams),
    Lambertian(&'a crate::brdf::table::LambertianParams),
}

impl<'a> From<&'a crate::brdf::table::TablePart> for PartRef<'a> {
    fn from(p: &'a crate::brdf::table::TablePart) -> Self {
        PartRef {
            scale: p.scale,
            n_z: p.n_z,
            n_psi: p.n_psi,
            data: &p.data,
            cos_weighted: p.cos_weighted,
            shader: None,
        }
    }
}

impl<'a> PartRef<'a> {
    /// The parts of a material's table as the kernel reads them: with
    /// [`crate::brdf::table::BrdfTableOptions::in_shader`] the single and the multiple +
    /// diffuse terms evaluated in the kernel, then the tabulated parts (single, multiple
    /// + diffuse, double: those the table holds).
    pub fn of(t: &'a crate::brdf::table::BrdfTable) -> Vec<PartRef<'a>> {
        let in_kernel = |k: InKernel<'a>| PartRef {
            scale: 0.0,
            n_z: 0,
            n_psi: 0,
            data: &[],
            cos_weighted: false,
            shader: Some(k),
        };
        let single = t.single.iter().map(|p| in_kernel(InKernel::Single(p)));
        let lambertian = t
            .lambertian
            .iter()
            .map(|p| in_kernel(InKernel::Lambertian(p)));
        single
            .chain(lambertian)
            .chain(t.parts.iter().map(PartRef::from))
            .collect()
    }
}

impl GpuTables {
    /// Pack up to [`MAX_PARTS`] parts per material tabulated for the bistatic angle `beta`.
    pub fn pack(materials: &[Vec<PartRef<'_>>], beta: f64) -> Result<Self> {
        let mut data = vec![0.0f32; HEADER_WORDS * materials.len()];
        let mut max_m00 = 0.0f64;
        let mut in_shader = false;
        for (m, parts) in materials.iter().enumerate() {
            if parts.len() > MAX_PARTS {
                return Err(Error::Shape(format!(
                    "material {m}: {} table parts (the renderer takes at most {MAX_PARTS})",
                    parts.len()
                )));
            }
            let mut sum_max = 0.0;
            for (p, part) in parts.iter().enumerate() {
                if let Some(k) = part.shader {
                    let h = HEADER_WORDS * m + 4 * p;
                    data[h] = f32::from_bits(data.len() as u32);
                    data[h + 1] = f32::from_bits(0);
                    data[h + 2] = f32::from_bits(SHADER_PART);
                    match k {
                        InKernel::Single(sp) => {
                            data.extend(sp.words());
                            sum_max += SHADER_PART_MARGIN * sp.max_m00_cos(beta);
                        }
                        InKernel::Lambertian(lp) => {
                            data.extend(lp.words());
                            sum_max += lp.max_m00_cos();
                        }
                    }
                    in_shader = true;
                    continue;
                }
                let rows = part.n_psi + 1;
                let want = rows * (part.n_z + 1) * 16;
                if part.data.len() != want || part.n_z == 0 {
                    return Err(Error::Shape(format!(
                        "material {m} part {p}: {} values for n_z = {}, n_psi = {}",
                        part.data.len(),
                        part.n_z,
                        part.n_psi
                    )));
                }
                let offset = data.len() as u32;
                let h = HEADER_WORDS * m + 4 * p;
                data[h] = f32::from_bits(offset);
                data[h + 1] = f32::from_bits(part.n_z as u32);
                data[h + 2] = f32::from_bits(part.n_psi as u32);
                data[h + 3] = (if part.cos_weighted {
                    -part.scale
                } else {
                    part.scale
                }) as f32;
                data.extend(part.data.iter().map(|&v| v as f32));
                // Interpolated ln M00 lies between its two bracketing z nodes (and rows),
                // so per cell max(M00) x max(cos theta_i) bounds M00 cos(theta_i) there,
                // with cos(theta_i) <= cos(max(theta_b - beta/2, 0)) for bisector angle
                // theta_b.
                let nz1 = part.n_z + 1;
                let cos_i = |i: usize| {
                    let th = crate::microfacet::masking::ZTable::theta_of_z(
                        part.scale,
                        i as f64 / part.n_z as f64,
                    );
                    (th - 0.5 * beta).max(0.0).cos()
                };
                // a cos-weighted part holds M00 cos(theta): the kernel multiplies it by
                // cos(theta_i) / cos(theta), which the lit condition (cos_o > 0) bounds by
                // 2 cos(beta/2) (and is 1 at beta = 0)
                let ratio = if beta > 0.0 {
                    2.0 * (0.5 * beta).cos()
                } else {
                    1.0
                };
                let mut mx = 0.0f64;
                for row in 0..rows {
                    for i in 1..part.n_z {
                        let a = part.data[(row * nz1 + i) * 16];
                        let b = part.data[(row * nz1 + i + 1) * 16];
                        let w = if part.cos_weighted {
                            ratio
                        } else {
                            cos_i(i).max(cos_i(i + 1))
                        };
                        mx = mx.max(a.max(b).exp() * w);
                    }
                }
                sum_max += mx;
            }
            for p in parts.len()..MAX_PARTS {
                let h = HEADER_WORDS * m + 4 * p;
                data[h + 1] = f32::from_bits(0);
            }
            max_m00 = max_m00.max(sum_max);
        }
        Ok(GpuTables {
            data,
            max_m00,
            in_shader,
        })
    }
}

/// Render a batch of attitudes (rotations) of `mesh` with the packed tables.
pub fn render(
    gpu: &Gpu,
    mesh: &Mesh,
    tables: &GpuTables,
    sensor: &SensorSetup,
    rotations: &[Rot],
    outputs: Outputs,
) -> Result<Rendered> {
    let lay = Layout::new(mesh, sensor);
    lay.check_bins(sensor)?;
    let w = lay.width;
    // K >= 4: tiles of w + 2 texels (MsaaTiles)
    let margin = if sensor.samples >= MSAA { 2 } else { 0 };
    let max_dim = gpu.info.max_texture_dimension_2d as usize;
    if w + margin > max_dim {
        return Err(Error::param(
            "resolution",
            w,
            format!(
                "resolution x supersampling <= {} on this device",
                max_dim - margin
            ),
        ));
    }
    let channels = sensor.channels();
    let n = rotations.len();
    let n_tri = mesh.faces.len();
    if sensor.samples >= MSAA && n_tri >= 1 << 24 {
        return Err(Error::param(
            "pixel_samples",
            sensor.samples,
            format!("1 or 2 for a mesh of {n_tri} triangles (4 to 16 take up to 2^24 - 1)"),
        ));
    }
    let mut geometry = mesh.gpu_geometry();
    if sensor.analytic {
        // the triangles across each edge, for the kernel's candidate search (after the
        // vertices and normals; u32::MAX across a boundary edge)
        geometry.extend(
            mesh.adjacency()
                .iter()
                .map(|a| [a[0], a[1], a[2], u32::MAX].map(f32::from_bits)),
        );
    }
    let max_binding = gpu.limits.max_storage_buffer_binding_size as u64;
    if (geometry.len() * 16) as u64 > max_binding || (tables.data.len() * 4) as u64 > max_binding {
        return Err(Error::param(
            "mesh",
            format!("{n_tri} triangles"),
            format!("geometry within the device's {max_binding}-byte storage binding"),
        ));
    }
    // chunk size: every per-chunk buffer within the binding limit, layers within limits
    let px = (w * w) as u64;
    let kern = KernelOutputs::new(outputs, sensor);
    let per_att = [
        if kern.image {
            px * channels as u64 * 4
        } else {
            0
        },
        if kern.range {
            px * 4 * if kern.footprint { 4 } else { 2 }
        } else {
            0
        },
        if kern.profile {
            (lay.n_bins * channels * 8) as u64
        } else {
            0
        },
        // triangle indices (K >= 4: gathered tiles with their margins)
        ((w + margin) * (w + margin) * 4 * sensor.samples) as u64,
    ];
    let biggest = per_att.iter().copied().max().unwrap_or(1).max(1);
    let mut chunk = (max_binding / biggest).max(1) as usize;
    if sensor.samples < MSAA {
        chunk = chunk.min(gpu.limits.max_texture_array_layers as usize / sensor.samples);
    } else if MsaaTiles::grid(w + 2, sensor.samples / MSAA, max_dim).is_none() {
        return Err(Error::param(
            "resolution",
            w,
            format!("a resolution x supersampling whose {} tiles of side + 2 texels fit a \
                     {max_dim}-texel texture", sensor.samples / MSAA),
        ));
    }
    chunk = chunk
        .min(gpu.limits.max_compute_workgroups_per_dimension as usize)
        .min(256);
    // keep the per-chunk device memory modest (tri ids + depth + outputs, plus the
    // transmitter's tri ids + depth when bistatic)
    let tx_w = transmitter_map_width(w, max_dim);
    let shadow_maps = if sensor.bistatic_angle > 0.0 {
        (tx_w * tx_w * 8) as u64
    } else {
        0
    };
    let mem_per = per_att.iter().sum::<u64>() + px * 4 * sensor.samples as u64 + shadow_maps;
    chunk = chunk.min(((512u64 << 20) / mem_per.max(1)).max(1) as usize);
    if chunk == 0 || biggest > max_binding {
        return Err(Error::param(
            "resolution",
            sensor.resolution,
            "a resolution whose per-attitude buffers fit the device's storage binding limit",
        ));
    }

    let n_pix_internal = (w * w) as f64;
    let p_max = 4.0 * std::f64::consts::PI * lay.pix * lay.pix * tables.max_m00.max(1e-300);
    // Fixed-point scale: a pixel's largest possible |value| maps to 2^40 units (a quantum of
    // 2^-40 of it, far below f32's 2^-24), and the sum of every pixel stays below 2^61. Most
    // pixels then add less than 2^32 units per bin, which the kernel does with one atomic.
    let fix_scale = (2f64.powi(40) / p_max)
        .min(2f64.powi(61) / (p_max * n_pix_internal))
        .min(f32::MAX as f64 / 4.0);
    if !(fix_scale.is_finite() && fix_scale > 0.0) {
        return Err(Error::param(
            "materials",
            format!("max tabulated M00 = {:e}", tables.max_m00),
            "finite BRDF tables",
        ));
    }

    let beta = sensor.bistatic_angle;
    let wi = [beta.sin() as f32, 0.0, beta.cos() as f32, 0.0];
    let s_tx = sensor.polarization.unwrap_or([1.0, 0.0, 0.0, 0.0]);
    let params = ShadeParams {
        width: w as u32,
        height: w as u32,
        n_bins: lay.n_bins as u32,
        n_tri: n_tri as u32,
        ext: lay.ext as f32,
        pix: lay.pix as f32,
        r_min: lay.r_min as f32,
        bin_width: sensor.bin_width as f32,
        wi,
        wo: [0.0, 0.0, 1.0, 0.0],
        s_tx: s_tx.map(|x| x as f32),
        sigma: sensor.sigma_range as f32,
        support: lay.support as f32,
        fix_scale: fix_scale as f32,
        has_normals: mesh.normals.is_some() as u32,
        beta: beta as f32,
        max_extent: lay.max_extent as f32,
        tx_width: tx_w as u32,
        closed: mesh.closed as u32,
        offsets: gpu_offsets(sensor.samples),
    };
    let fix_scale = params.fix_scale as f64; // what the kernel uses

    let dev = &gpu.device;
    let scope_v = dev.push_error_scope(wgpu::ErrorFilter::Validation);
    let scope_m = dev.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let result = render_chunks(
        gpu,
        &geometry,
        tables,
        &params,
        rotations,
        outputs,
        kern,
        channels,
        chunk,
        fix_scale,
        &lay,
        sensor,
        mesh.closed,
    );
    let oom = pollster::block_on(scope_m.pop());
    let val = pollster::block_on(scope_v.pop());
    if let Some(e) = oom {
        return Err(device_error(format!(
            "out of device memory (try a smaller resolution or batch): {e}"
        )));
    }
    if let Some(e) = val {
        return Err(device_error(format!("wgpu validation error: {e}")));
    }
    let mut r = result?;
    r.n = n;
    Ok(r)
}

#[allow(clippy::too_many_arguments)]
fn render_chunks(
    gpu: &Gpu,
    geometry: &[[f32; 4]],
    tables: &GpuTables,
    params: &ShadeParams,
    rotations: &[Rot],
    outputs: Outputs,
    kern: KernelOutputs,
    channels: usize,
    chunk: usize,
    fix_scale: f64,
    lay: &Layout,
    sensor: &SensorSetup,
    mesh_closed: bool,
) -> Result<Rendered> {
    let dev = &gpu.device;
    let w = lay.width;
    let ss = sensor.supersampling;
    let res = sensor.resolution;
    let n = rotations.len();
    let nb = lay.n_bins;
    let key = ShadeKey {
        channels: channels as u32,
        image: kern.image,
        range: kern.range,
        profile: kern.profile,
        // With the profile on the device the total is its sum, taken exactly on the host
        // from the same fixed-point words (the bins cover every pixel's footprint and pulse
        // support, see Layout): the kernel's workgroup reduction is then compiled out.
        total: !kern.profile,
        footprint: kern.footprint,
        shadows: sensor.bistatic_angle > 0.0,
        elements: sensor.element_mask(),
        samples: sensor.samples as u32,
        analytic: sensor.analytic,
        in_shader: tables.in_shader,
    };
    let rng_stride = if kern.footprint { 4 } else { 2 };
    let n_s = sensor.samples;
    let pipeline = gpu.shade_pipeline(key)?;
    let usage_in = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
    let geo_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("geometry"),
        contents: bytemuck::cast_slice(geometry),
        usage: usage_in,
    });
    let tab_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("tables"),
        contents: bytemuck::cast_slice(&tables.data),
        usage: usage_in,
    });
    let shade_uni = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("shade params"),
        contents: bytemuck::bytes_of(params),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let msaa = n_s >= MSAA;
    let vis_uni = |ext: f64| {
        dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("visibility params"),
            contents: bytemuck::bytes_of(&VisParams {
                ext: ext as f32,
                ext_z: (lay.ext * 1.001) as f32,
                _pad: [0.0; 2],
            }),
            usage: wgpu::BufferUsages::UNIFORM,
        })
    };
    let vis_uni_image = vis_uni(lay.ext);
    // a tile is the image with a one-texel margin (MsaaTiles)
    let vis_uni_tiles = msaa.then(|| vis_uni(lay.ext * (w + 2) as f64 / w as f64));
    let vis_uni_rcv = vis_uni_tiles.as_ref().unwrap_or(&vis_uni_image);
    // the receiver's raster transforms: attitude l, pass p at instance l P + p, its
    // samples moved to where the rasterizer samples (shaders/visibility.wgsl)
    let shifts: Vec<[f32; 4]> = raster_displacements(n_s)
        .iter()
        .map(|d| [(d[0] * lay.pix) as f32, (-d[1] * lay.pix) as f32, 0.0, 0.0])
        .collect();
    let n_pass = shifts.len();
    let affine = |r: &Rot, t: [f32; 4]| -> [f32; 16] {
        let mut a = [0.0f32; 16];
        a[..12].copy_from_slice(&gpu_rotation(r));
        a[12..].copy_from_slice(&t);
        a
    };
    let out_usage =
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
    let mk = |label: &str, size: u64, usage: wgpu::BufferUsages| {
        dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(16),
            usage,
            mapped_at_creation: false,
        })
    };
    let px = w * w;
    let c = chunk.min(n);
    let img_size = if kern.image {
        (c * px * channels * 4) as u64
    } else {
        16
    };
    let rng_size = if kern.range {
        (c * px * 4 * rng_stride) as u64
    } else {
        16
    };
    let prof_size = if kern.profile {
        (c * nb * channels * 8) as u64
    } else {
        16
    };
    let tot_size = (c * channels * 8) as u64;
    let img_buf = mk("image", img_size, out_usage);
    let rng_buf = mk("range", rng_size, out_usage);
    let prof_buf = mk("profile", prof_size, out_usage);
    let tot_buf = mk("total", tot_size, out_usage);
    let read_usage = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
    let img_read = kern.image.then(|| mk("image read", img_size, read_usage));
    let rng_read = kern.range.then(|| mk("range read", rng_size, read_usage));
    let prof_read = kern
        .profile
        .then(|| mk("profile read", prof_size, read_usage));
    let tot_read = mk("total read", tot_size, read_usage);
    let (rcv, tiles) = if msaa {
        let max_dim = gpu.info.max_texture_dimension_2d as usize;
        (None, Some(MsaaTiles::new(dev, w + 2, n_pass, max_dim)))
    } else {
        let t = IdTarget::new(dev, "visibility target", w as u32, (c * n_s) as u32);
        (Some(t), None)
    };
    // K >= 4: the gathered sample ids, and per attitude of a chunk its gather parameters
    // (one uniform block each, bound at a dynamic offset)
    let ids_buf = tiles.as_ref().map(|t| {
        mk(
            "sample ids",
            (c * n_pass * t.side * t.side * MSAA * 4) as u64,
            wgpu::BufferUsages::STORAGE,
        )
    });
    let stride = gpu.limits.min_uniform_buffer_offset_alignment.max(16) as usize;
    let gather_bg = tiles.as_ref().zip(ids_buf.as_ref()).map(|(t, ids)| {
        let mut words = vec![0u32; c * stride / 4];
        for l in 0..c {
            words[l * stride / 4..][..4]
                .copy_from_slice(&[l as u32, t.side as u32, t.cols as u32, n_pass as u32]);
        }
        let uni = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("gather params"),
            contents: bytemuck::cast_slice(&words),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("gather"),
            layout: &gpu.gather_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&t.view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: ids.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &uni,
                        offset: 0,
                        size: wgpu::BufferSize::new(16),
                    }),
                },
            ],
        })
    });
    // bistatic: the triangle ids seen from the transmitter (same square, tx_width texels)
    let tx = key
        .shadows
        .then(|| IdTarget::new(dev, "transmitter target", params.tx_width, c as u32));

    let mut image = outputs
        .image
        .then(|| vec![0.0f32; n * res * res * channels]);
    let mut range = outputs.range.then(|| vec![f32::NAN; n * res * res]);
    let mut coverage = outputs.range.then(|| vec![0.0f32; n * res * res]);
    let mut profile = outputs.profile.then(|| vec![0.0f64; n * nb * channels]);
    let mut total = vec![0.0f64; n * channels];

    for start in (0..n).step_by(c) {
        let m = (n - start).min(c);
        let rots: Vec<[f32; 12]> = rotations[start..start + m]
            .iter()
            .map(gpu_rotation)
            .collect();
        let rot_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("rotations"),
            contents: bytemuck::cast_slice(&rots),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let vis_group = |rot: &wgpu::Buffer, uni: &wgpu::Buffer| {
            dev.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("visibility"),
                layout: &gpu.vis_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: geo_buf.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: rot.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: uni.as_entire_binding(),
                    },
                ],
            })
        };
        let tfs: Vec<[f32; 16]> = rotations[start..start + m]
            .iter()
            .flat_map(|r| shifts.iter().map(move |&t| affine(r, t)))
            .collect();
        let tf_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("raster transforms"),
            contents: bytemuck::cast_slice(&tfs),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let vis_bg = vis_group(&tf_buf, vis_uni_rcv);
        // bistatic: R_tx = R_y(-beta) R, computed in f64 (wi -> +z)
        let tx_bg = key.shadows.then(|| {
            let rots: Vec<[f32; 16]> = rotations[start..start + m]
                .iter()
                .map(|r| affine(&transmitter_rotation(r, sensor.bistatic_angle), [0.0; 4]))
                .collect();
            let buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("transmitter rotations"),
                contents: bytemuck::cast_slice(&rots),
                usage: wgpu::BufferUsages::STORAGE,
            });
            vis_group(&buf, &vis_uni_image)
        });
        let shade_bg = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout: &gpu.shade_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(
                        rcv.as_ref().map_or(&gpu.dummy_ids, |t| &t.array_view),
                    ),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: geo_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: rot_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: tab_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: shade_uni.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: img_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: rng_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 7,
                    resource: prof_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: tot_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 9,
                    resource: wgpu::BindingResource::TextureView(
                        tx.as_ref()
                            .or(rcv.as_ref())
                            .map_or(&gpu.dummy_ids, |t| &t.array_view),
                    ),
                },
                wgpu::BindGroupEntry {
                    binding: 10,
                    resource: ids_buf
                        .as_ref()
                        .unwrap_or(&gpu.dummy_buffer)
                        .as_entire_binding(),
                },
            ],
        });
        let mut enc = dev.create_command_encoder(&Default::default());
        if kern.profile {
            enc.clear_buffer(&prof_buf, 0, None);
        }
        enc.clear_buffer(&tot_buf, 0, None);
        // the receiver's view, then (bistatic) the transmitter's
        // (layer l K + k holds attitude l's sample k, drawn as instance l K + k)
        let mut views_and_groups = vec![];
        if let Some(t) = &rcv {
            views_and_groups.push((&t.id_views, &t.depth_views, &vis_bg, n_s));
        }
        if let (Some(bg), Some(t)) = (&tx_bg, &tx) {
            views_and_groups.push((&t.id_views, &t.depth_views, bg, 1));
        }
        if let (Some(t), Some(gbg)) = (&tiles, &gather_bg) {
            // per attitude: its K / MSAA passes into the tiles, then their samples gathered
            // into its slot of the id buffer (the same tiles for every attitude, so the
            // rasterization does not depend on the attitude's place in the batch)
            let side = t.side as u32;
            for l in 0..m {
                let mut pass = id_pass(&mut enc, "visibility tiles", &t.view, &t.depth_view);
                pass.set_pipeline(&gpu.vis_pipeline_msaa[mesh_closed as usize]);
                pass.set_bind_group(0, &vis_bg, &[]);
                for p in 0..n_pass {
                    let (x, y) = t.origin(p);
                    pass.set_viewport(x as f32, y as f32, side as f32, side as f32, 0.0, 1.0);
                    pass.set_scissor_rect(x as u32, y as u32, side, side);
                    let i = (l * n_pass + p) as u32;
                    pass.draw(0..(3 * params.n_tri), i..i + 1);
                }
                drop(pass);
                let mut pass = enc.begin_compute_pass(&Default::default());
                pass.set_pipeline(&gpu.gather_pipeline);
                pass.set_bind_group(0, gbg, &[(l * stride) as u32]);
                let g = side.div_ceil(8);
                pass.dispatch_workgroups(g, g, n_pass as u32);
            }
        }
        for (views, dviews, bg, k_s) in views_and_groups {
            for l in 0..m * k_s {
                let mut pass = id_pass(&mut enc, "visibility", &views[l], &dviews[l]);
                pass.set_pipeline(&gpu.vis_pipeline[mesh_closed as usize]);
                pass.set_bind_group(0, bg, &[]);
                let l = l as u32;
                pass.draw(0..(3 * params.n_tri), l..l + 1);
            }
        }
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &shade_bg, &[]);
            let g = (w as u32).div_ceil(8);
            pass.dispatch_workgroups(g, g, m as u32);
        }
        let copy =
            |enc: &mut wgpu::CommandEncoder, src: &wgpu::Buffer, dst: &wgpu::Buffer, size| {
                enc.copy_buffer_to_buffer(src, 0, dst, 0, Some(size));
            };
        let img_bytes = (m * px * channels * 4) as u64;
        let rng_bytes = (m * px * 4 * rng_stride) as u64;
        let prof_bytes = (m * nb * channels * 8) as u64;
        let tot_bytes = (m * channels * 8) as u64;
        if let Some(b) = &img_read {
            copy(&mut enc, &img_buf, b, img_bytes);
        }
        if let Some(b) = &rng_read {
            copy(&mut enc, &rng_buf, b, rng_bytes);
        }
        if let Some(b) = &prof_read {
            copy(&mut enc, &prof_buf, b, prof_bytes);
        }
        if key.total {
            copy(&mut enc, &tot_buf, &tot_read, tot_bytes);
        }
        gpu.queue.submit([enc.finish()]);

        let read = |b: &wgpu::Buffer, bytes: u64| -> Result<Vec<u8>> {
            let slice = b.slice(0..bytes);
            slice.map_async(wgpu::MapMode::Read, |_| {});
            dev.poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| device_error(format!("device poll failed: {e}")))?;
            let v = slice
                .get_mapped_range()
                .map_err(|e| device_error(format!("cannot map a result buffer: {e}")))?
                .to_vec();
            b.unmap();
            Ok(v)
        };
        let fixed = |bytes: &[u8]| -> Vec<f64> {
            let words: &[u32] = bytemuck::cast_slice(bytes);
            words
                .chunks_exact(2)
                .map(|p| ((((p[1] as u64) << 32) | p[0] as u64) as i64) as f64 / fix_scale)
                .collect()
        };
        if key.total {
            let t = fixed(&read(&tot_read, tot_bytes)?);
            total[start * channels..(start + m) * channels].copy_from_slice(&t);
        }
        if let (Some(b), Some(out)) = (&prof_read, profile.as_mut()) {
            let bytes = read(b, prof_bytes)?;
            if !key.total {
                // exact: sums of the fixed-point integers (|sum| < 2^61 by the scale)
                let words: &[u32] = bytemuck::cast_slice(&bytes);
                for l in 0..m {
                    for ch in 0..channels {
                        let s: i64 = (0..nb)
                            .map(|k| {
                                let i = 2 * ((l * nb + k) * channels + ch);
                                (((words[i + 1] as u64) << 32) | words[i] as u64) as i64
                            })
                            .sum();
                        total[(start + l) * channels + ch] = s as f64 / fix_scale;
                    }
                }
            }
            let p = fixed(&bytes);
            out[start * nb * channels..(start + m) * nb * channels].copy_from_slice(&p);
        }
        let raw_img = img_read.as_ref().map(|b| read(b, img_bytes)).transpose()?;
        let raw_rng = rng_read.as_ref().map(|b| read(b, rng_bytes)).transpose()?;
        if let (Some(pulse), Some(out)) = (&sensor.pulse, profile.as_mut()) {
            // sampled pulse: the profile from the per-pixel footprints, in f64 on the host
            let img: &[f32] = bytemuck::cast_slice(raw_img.as_deref().expect("kernel image"));
            let foot: &[f32] = bytemuck::cast_slice(raw_rng.as_deref().expect("footprints"));
            let cap = 2f64.powi(61) / (fix_scale * px as f64);
            let prof = &mut out[start * nb * channels..(start + m) * nb * channels];
            prof.par_chunks_mut(nb * channels)
                .enumerate()
                .for_each(|(l, p)| {
                    host_profile(
                        pulse,
                        &img[l * px * channels..(l + 1) * px * channels],
                        &foot[l * px * 4..(l + 1) * px * 4],
                        channels,
                        lay.r_min,
                        sensor.bin_width,
                        cap,
                        p,
                    )
                });
        }
        if let (Some(raw), Some(out)) = (&raw_img, image.as_mut()) {
            let v: &[f32] = bytemuck::cast_slice(raw);
            downsample_sum(
                v,
                m,
                w,
                ss,
                channels,
                &mut out[start * res * res * channels..],
            );
        }
        if let (Some(raw), Some(out), Some(cov)) = (&raw_rng, range.as_mut(), coverage.as_mut()) {
            let v: &[f32] = bytemuck::cast_slice(raw);
            // (range, ..., covered fraction) per pixel
            let r0: Vec<f32> = v.iter().step_by(rng_stride).copied().collect();
            let c0: Vec<f32> = v
                .chunks_exact(rng_stride)
                .map(|p| p[rng_stride - 1])
                .collect();
            downsample_range(
                &r0,
                &c0,
                m,
                w,
                ss,
                &mut out[start * res * res..],
                &mut cov[start * res * res..],
            );
        }
    }
    Ok(Rendered {
        n,
        height: res,
        width: res,
        channels,
        image,
        range,
        coverage,
        profile,
        total,
        r_min: lay.r_min,
        bin_width: sensor.bin_width,
        n_bins: nb,
        pixel_size: lay.pix * ss as f64,
        extent: lay.ext,
    })
}

/// A raster target of triangle ids (`format`, read by a kernel) and its Depth32Float buffer,
/// `samples` per texel.
fn id_textures(
    dev: &wgpu::Device,
    label: &str,
    size: wgpu::Extent3d,
    samples: u32,
    format: wgpu::TextureFormat,
) -> (wgpu::Texture, wgpu::Texture) {
    let texture = |format, usage| {
        dev.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size,
            mip_level_count: 1,
            sample_count: samples,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let ids = texture(
        format,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
    );
    let depth = texture(
        wgpu::TextureFormat::Depth32Float,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    (ids, depth)
}

/// A visibility render pass into an id target (cleared to 0) and its depth buffer (cleared
/// to the far plane, not stored).
fn id_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    ids: &wgpu::TextureView,
    depth: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: ids,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(1.0),
                store: wgpu::StoreOp::Discard,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// A raster target of triangle ids (R32Uint, read by the shade kernel) with its depth
/// buffer, `layers` attitudes deep: per-layer views for the raster passes, an array view
/// for the kernel.
struct IdTarget {
    array_view: wgpu::TextureView,
    id_views: Vec<wgpu::TextureView>,
    depth_views: Vec<wgpu::TextureView>,
}

impl IdTarget {
    fn new(dev: &wgpu::Device, label: &str, side: u32, layers: u32) -> Self {
        let size = wgpu::Extent3d {
            width: side,
            height: side,
            depth_or_array_layers: layers,
        };
        let (ids, depth) = id_textures(dev, label, size, 1, wgpu::TextureFormat::R32Uint);
        let layer_views = |t: &wgpu::Texture| -> Vec<wgpu::TextureView> {
            (0..layers)
                .map(|l| {
                    t.create_view(&wgpu::TextureViewDescriptor {
                        dimension: Some(wgpu::TextureViewDimension::D2),
                        base_array_layer: l,
                        array_layer_count: Some(1),
                        ..Default::default()
                    })
                })
                .collect()
        };
        IdTarget {
            array_view: ids.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            }),
            id_views: layer_views(&ids),
            depth_views: layer_views(&depth),
        }
    }
}

/// The receiver's raster target with `K >= 4` visibility samples: one multisampled
/// ([`MSAA`]) R32Float texture of `passes` square tiles, `side` texels a side, `cols` to a
/// row, pass `p` in tile `p`. A tile is the image with a margin of one texel on every side
/// (pixel `(c, r)` is its texel `(c + 1, r + 1)`), where samples wrapped out of a border
/// pixel are drawn. Ids are stored as `f32` (exact below `2^24` triangles; R32Float is
/// multisampled in core WebGPU, R32Uint is not) and gathered per attitude into a u32 buffer
/// by `shaders/gather.wgsl`.
struct MsaaTiles {
    view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    side: usize,
    cols: usize,
}

impl MsaaTiles {
    /// Columns and rows of `passes` tiles of `side` texels within `max_dim` texels.
    fn grid(side: usize, passes: usize, max_dim: usize) -> Option<(usize, usize)> {
        let cols = (max_dim / side).min(passes);
        (cols > 0 && passes.div_ceil(cols) * side <= max_dim)
            .then(|| (cols, passes.div_ceil(cols)))
    }

    fn new(dev: &wgpu::Device, side: usize, passes: usize, max_dim: usize) -> Self {
        let (cols, rows) = Self::grid(side, passes, max_dim).expect("checked by render()");
        let size = wgpu::Extent3d {
            width: (cols * side) as u32,
            height: (rows * side) as u32,
            depth_or_array_layers: 1,
        };
        let (ids, depth) = id_textures(
            dev,
            "visibility tiles",
            size,
            MSAA as u32,
            wgpu::TextureFormat::R32Float,
        );
        MsaaTiles {
            view: ids.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            side,
            cols,
        }
    }

    /// Top-left texel of tile `p`.
    fn origin(&self, p: usize) -> (usize, usize) {
        ((p % self.cols) * self.side, (p / self.cols) * self.side)
    }
}

/// What the shade kernel computes and what is read back, from the request: a sampled
/// pulse's profile needs the image and the footprints at the internal resolution, and the
/// kernel then skips its own (Gaussian) profile.
#[derive(Debug, Clone, Copy)]
pub struct KernelOutputs {
    pub image: bool,
    pub range: bool,
    pub profile: bool,
    pub footprint: bool,
}

impl KernelOutputs {
    pub fn new(outputs: Outputs, sensor: &SensorSetup) -> Self {
        let host = outputs.profile && sensor.pulse.is_some();
        KernelOutputs {
            image: outputs.image || host,
            range: outputs.range || host,
            profile: outputs.profile && !host,
            footprint: host,
        }
    }
}

/// The profile of one attitude for a sampled pulse, on the host in f64: every covered
/// pixel (`foot` = (r0, a, b, coverage) per pixel, r0 NaN where empty; `img` its `ch` channels)
/// adds `W_k = C(e_{k+1} - r0) - C(e_k - r0)` times its channels to the bins its footprint
/// and the pulse reach, `C` = [`SampledPulse::cdf_box2`]. The channels are clamped to
/// `cap` as in the kernel's fixed-point sums, so that the profile sums to the total.
#[allow(clippy::too_many_arguments)]
pub fn host_profile(
    pulse: &SampledPulse,
    img: &[f32],
    foot: &[f32],
    ch: usize,
    r_min: f64,
    bin_width: f64,
    cap: f64,
    out: &mut [f64],
) {
    let nb = out.len() / ch;
    let (lo, hi) = pulse.support();
    let mut edges = Vec::new();
    let mut weights = Vec::new();
    for (k, f) in foot.chunks_exact(4).enumerate() {
        let r0 = f[0] as f64;
        let v = &img[k * ch..(k + 1) * ch];
        if r0.is_nan() || v[0] == 0.0 {
            continue;
        }
        let (a, b) = (f[1] as f64, f[2] as f64);
        let half = 0.5 * (a + b);
        let k0 = (((r0 - half + lo - r_min) / bin_width).floor().max(0.0) as usize).min(nb - 1);
        let k1 = (((r0 + half + hi - r_min) / bin_width).floor().max(0.0) as usize).min(nb - 1);
        edges.clear();
        edges.extend((k0..=k1 + 1).map(|j| r_min + j as f64 * bin_width));
        weights.clear();
        weights.resize(k1 + 1 - k0, 0.0);
        pulse.bin_weights(r0, a, b, &edges, &mut weights);
        for (j, &wt) in weights.iter().enumerate() {
            if wt != 0.0 {
                let o = &mut out[(k0 + j) * ch..(k0 + j + 1) * ch];
                for c in 0..ch {
                    o[c] += wt * (v[c] as f64).clamp(-cap, cap);
                }
            }
        }
    }
}

/// Sum `ss x ss` sub-pixels into each output pixel.
pub(crate) fn downsample_sum(v: &[f32], m: usize, w: usize, ss: usize, ch: usize, out: &mut [f32]) {
    let res = w / ss;
    for a in 0..m {
        for i in 0..res {
            for j in 0..res {
                let o = ((a * res + i) * res + j) * ch;
                for c in 0..ch {
                    out[o + c] = 0.0;
                }
                for di in 0..ss {
                    for dj in 0..ss {
                        let s = ((a * w + i * ss + di) * w + j * ss + dj) * ch;
                        for c in 0..ch {
                            out[o + c] += v[s + c];
                        }
                    }
                }
            }
        }
    }
}

/// Range: mean over the sub-pixels weighted by their covered fractions `c` (NaN if none
/// is covered); coverage: the sub-pixels' mean covered fraction.
pub(crate) fn downsample_range(
    v: &[f32],
    c: &[f32],
    m: usize,
    w: usize,
    ss: usize,
    out: &mut [f32],
    cov: &mut [f32],
) {
    let res = w / ss;
    for a in 0..m {
        for i in 0..res {
            for j in 0..res {
                let (mut s, mut k) = (0.0f64, 0.0f64);
                for di in 0..ss {
                    for dj in 0..ss {
                        let q = (a * w + i * ss + di) * w + j * ss + dj;
                        if !v[q].is_nan() && c[q] > 0.0 {
                            s += c[q] as f64 * v[q] as f64;
                            k += c[q] as f64;
                        }
                    }
                }
                let o = (a * res + i) * res + j;
                out[o] = if k > 0.0 { (s / k) as f32 } else { f32::NAN };
                cov[o] = (k / (ss * ss) as f64) as f32;
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::render::twin;

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
    pub fn lambert_brdf(rho: f64) -> impl Fn(usize, [f64; 3], [f64; 3]) -> [[f64; 4]; 4] + Sync {
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
        let rot = vec![[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]];
        let out = Outputs {
            image: true,
            range: true,
            profile: true,
        };
        let g = render(&gpu, &mesh, &tables, &sensor, &rot, out).unwrap();
        let brdf = lambert_brdf(rho);
        let c = twin::render_cpu(&mesh, &sensor, &rot, out, &brdf);
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
}

#[cfg(test)]
pub(crate) mod twin_tests {
    use super::tests::uv_sphere;
    use super::*;
    use crate::brdf::table::{BrdfTable, BrdfTableOptions, PartKind, TableFrame};
    use crate::brdf::{Material, MaterialSpec, Terms};
    use crate::microfacet::Distribution;
    use crate::optics::frames::Frame;
    use crate::optics::fresnel::{Eta, C64};
    use crate::render::twin;

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

    /// max over pixels of max_ij |a_ij - b_ij| / max(b_00, floor): relative to the pixel's
    /// own M00, with an absolute floor for the faintest pixels (grazing limb pixels, where
    /// f32 rounding of a tiny cos(theta_i) is relatively large but carries no signal).
    fn worst(a: &[f32], b: &[f32], floor: f32) -> (f64, usize) {
        let mut w = 0.0f64;
        let mut k = 0;
        for (p, (x, y)) in a.chunks(16).zip(b.chunks(16)).enumerate() {
            {
                let e = x
                    .iter()
                    .zip(y)
                    .map(|(u, v)| (u - v).abs())
                    .fold(0.0f32, f32::max) as f64
                    / y[0].max(floor) as f64;
                if e > w {
                    w = e;
                    k = p;
                }
            }
        }
        (w, k)
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
        assert_eq!(tables.in_shader, table.single.is_some() || table.lambertian.is_some());
        let mut sensor = super::tests::lambert_sensor(64);
        sensor.bistatic_angle = beta;
        let g = render(gpu, mesh, &tables, &sensor, rot, out).unwrap();
        let by_table = twin::Tables(std::slice::from_ref(table));
        let by_core =
            |_m: usize, wi: [f64; 3], wo: [f64; 3]| crate::brdf::eval(mat, wi, wo, Frame::Sp);
        let t = twin::render_cpu(mesh, &sensor, rot, out, &by_table);
        let c = twin::render_cpu(mesh, &sensor, rot, out, &by_core);
        (g, t, c)
    }

    /// The kernel (f32, lavapipe or GPU) against its f64 twin with the same tables, and the
    /// twin with the tables against the exact core BRDF, per pixel, monostatic and 2 deg
    /// bistatic, on a smooth-shaded sphere at an oblique attitude.
    #[test]
    fn kernel_matches_twin_and_core_per_pixel() {
        let gpu = context(DeviceChoice::Auto).expect("a Vulkan device (lavapipe)");
        let mat = metal();
        let mesh = uv_sphere(0.5, 48, 96);
        let rot = crate::render::geometry::rotations_from_quaternions(&[
            [0.9, 0.3, -0.2, 0.25].map(|x: f64| x / (0.81f64 + 0.09 + 0.04 + 0.0625).sqrt())
        ])
        .unwrap();
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
    /// [`crate::brdf::table::LambertianParams::eval`]) and the twin
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
        let mesh = uv_sphere(0.5, 48, 96);
        let rot = crate::render::geometry::rotations_from_quaternions(&[
            [0.9, 0.3, -0.2, 0.25].map(|x: f64| x / (0.81f64 + 0.09 + 0.04 + 0.0625).sqrt())
        ])
        .unwrap();
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
                assert_eq!(table.lambertian.is_some(), mat.spec.terms.multiple);
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
}

#[cfg(test)]
mod shadow_tests {
    use super::tests::{lambert_brdf, lambert_sensor, lambert_tables, uv_sphere};
    use super::*;
    use crate::render::twin;

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
            let g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
            let t = twin::render_cpu(&mesh, &sensor, &rots, out, &brdf);
            let lay = Layout::new(&mesh, &sensor);
            let w = lay.width;
            let (gi, ti) = (g.image.as_ref().unwrap(), t.image.as_ref().unwrap());
            let (gr, tr) = (g.range.as_ref().unwrap(), t.range.as_ref().unwrap());
            for (a, rot) in rots.iter().enumerate() {
                // shadowed pixels by the twin's own functions (lit by cos, yet in shadow)
                let ids = twin::visibility(&mesh, rot, w, lay.ext);
                let view = twin::TransmitterView::new(&mesh, rot, beta);
                let mut n_shadow = 0;
                for (k, &id) in ids.iter().enumerate() {
                    if id == 0 {
                        continue;
                    }
                    let s = twin::shade_pixel(
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
                    if s.values[0] > 0.0 && twin::shadowed(&view, id as usize - 1, s.point) {
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
}

#[cfg(test)]
mod sample_tests {
    use super::shadow_tests::sphere_and_plate;
    use super::tests::{lambert_brdf, lambert_sensor, lambert_tables, two_attitudes};
    use super::*;
    use crate::render::twin;

    /// The samples form a (0, m, 2)-net (K = 8: n-rooks and two per quadrant): every
    /// elementary box of area 1/K holds exactly one (so each row and column of the K x K
    /// grid holds one); the set is symmetric under a half turn about the centre; and with
    /// K >= 4 sample `k` is where the multisampled raster puts it: the standard position
    /// of its sample index, moved by its pass's shift, in the texel it is read from.
    #[test]
    fn sample_offsets_form_a_net() {
        assert_eq!(sample_offsets(1), vec![[0.5, 0.5]]);
        for k in [2usize, 4, 8, 16] {
            let s = sample_offsets(k);
            let m = k.trailing_zeros();
            let count = |nx: usize, ny: usize| {
                let mut count = vec![0; nx * ny];
                for p in &s {
                    assert!((0.0..1.0).contains(&p[0]) && (0.0..1.0).contains(&p[1]));
                    let (a, b) = ((p[0] * nx as f64) as usize, (p[1] * ny as f64) as usize);
                    count[a * ny + b] += 1;
                }
                count
            };
            for i in 0..=m {
                let (nx, ny) = (1usize << i, 1usize << (m - i));
                if k == 8 && i != 0 && i != m {
                    continue;
                }
                let c = count(nx, ny);
                assert!(c.iter().all(|&c| c == 1), "k {k}: {nx} x {ny} boxes {c:?}");
            }
            if k == 8 {
                assert_eq!(count(2, 2), vec![2; 4]);
                let doubled: usize = [(2, 4), (4, 2)]
                    .iter()
                    .map(|&(nx, ny)| count(nx, ny).iter().filter(|&&c| c == 2).count())
                    .sum();
                assert_eq!(doubled, 4);
            }
            for p in &s {
                let q = [1.0 - p[0], 1.0 - p[1]];
                assert!(s.contains(&q), "k {k}: {p:?} without its mirror image");
            }
        }
        for k in [4usize, 8, 16] {
            let d = raster_displacements(k);
            assert_eq!(d.len(), k / MSAA);
            for (i, o) in msaa_samples(k).iter().enumerate() {
                assert_eq!((o.pass, o.sample), (i / MSAA, i % MSAA));
                // the raster sample s of texel t sees t + position_s - displacement_p,
                // which must be the pixel's point for t = the pixel's + texel
                let pos = MSAA_POSITIONS[o.sample];
                for a in 0..2 {
                    let seen = o.texel[a] as f64 + pos[a] as f64 / 16.0 - d[o.pass][a];
                    assert!((seen - o.uv[a]).abs() < 1e-12, "k {k} sample {i}: {seen} {o:?}");
                }
                assert!(o.texel.iter().all(|t| t.abs() <= 1));
            }
        }
    }

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
            let g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
            let t = twin::render_cpu(&mesh, &sensor, &rots, out, &brdf);
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
                    assert!(((gc[p] - tc[p]).abs() - 1.0 / k as f32).abs() < 1e-6);
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
        let rot = vec![[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]];
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
}

#[cfg(test)]
mod coverage_tests {
    use super::shadow_tests::sphere_and_plate;
    use super::tests::{lambert_brdf, lambert_sensor, lambert_tables, two_attitudes, uv_sphere};
    use super::*;
    use crate::render::twin;

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
            let g = render(&gpu, &mesh, &tables, &sensor, &rots, out).unwrap();
            let t = twin::render_cpu(&mesh, &sensor, &rots, out, &brdf);
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
                let er = if tc[p] > 0.0 { (gr[p] - tr[p]).abs() as f64 / lay.pix } else { 0.0 };
                if ev > 1e-3 || ec > 1e-3 || er > 1e-2 {
                    n_diff += 1;
                    continue;
                }
                worst_v = worst_v.max(ev);
                worst_c = worst_c.max(ec);
                worst_r = worst_r.max(er);
            }
            // pixels where the candidate search overflows (the centre-sample fallback)
            let ids = twin::visibility(&mesh, &rots[0], lay.width, lay.ext);
            let vertices = twin::rotate_vertices(&mesh, &rots[0]);
            for p in 0..lay.width * lay.width {
                let (row, col) = (p / lay.width, p % lay.width);
                let w = lay.width;
                let (seeds, _) = twin::analytic_seeds(&ids, w, row, col);
                if !seeds.is_empty()
                    && twin::coverage_parts(&mesh, &vertices, &lay, row, col, &seeds).is_none()
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
            assert!(worst_v < 5e-4 && worst_c < 1e-5, "worst {worst_v} {worst_c}");
            assert!(tot < 1e-5 + (n_diff as f64 * pix_max) / t.total[0], "total {tot}");
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
        let rot = vec![[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]];
        let c = 0.3f64;
        let s = (1.0 - c * c).sqrt();
        // a turn about the view axis, so that no edge lies along the pixel grid
        let turned = vec![[[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]];
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
                let p = f.map(|k| crate::render::geometry::rotate(rot, flat.vertices[k as usize]));
                let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
                let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
                let n = [
                    e1[1] * e2[2] - e1[2] * e2[1],
                    e1[2] * e2[0] - e1[0] * e2[2],
                    e1[0] * e2[1] - e1[1] * e2[0],
                ];
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
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
                eprintln!("flat UV sphere, attitude {a}, {res} px: centre sample {e1:.2e}, analytic {ea:.2e}");
                assert!(ea.abs() < 1e-5, "sphere {a} {res}: {ea}");
            }
        }
    }
}
