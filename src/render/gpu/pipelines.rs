//! The pipelines a device compiles once ([`Pipelines`]): the visibility raster (one layer
//! per pass, multiview where the device has it, and 4x multisampled tiles with the gather
//! kernel), and the shade kernel per [`ShadeKey`] of override constants (compiled on first
//! use, then cached).

use super::util::device_error;
use crate::error::Result;
use crate::render::samples::MSAA;
use crate::render::shaders;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// The pipelines of one device.
pub(super) struct Pipelines {
    pub(super) vis_layout: wgpu::BindGroupLayout,
    pub(super) vis_pipeline: [wgpu::RenderPipeline; 2],
    /// The same drawing [`Pipelines::views`] layers per pass by multiview
    /// (`visibility_views.wgsl`), where the device has it.
    pub(super) vis_pipeline_views: Option<[wgpu::RenderPipeline; 2]>,
    /// Layers per visibility pass ([`super::device::DeviceInfo::raster_views`]).
    pub(super) views: u32,
    /// The same at [`MSAA`] samples per texel, ids as `f32` (`fs_float`), into the tiles
    /// of `K >= 4` ([`super::targets::MsaaTiles`]), and the kernel that gathers them
    /// (`gather.wgsl`).
    pub(super) vis_pipeline_msaa: [wgpu::RenderPipeline; 2],
    pub(super) gather_layout: wgpu::BindGroupLayout,
    pub(super) gather_pipeline: wgpu::ComputePipeline,
    /// Placeholders for the shade kernel's id bindings that a request does not use: a
    /// 1 x 1 layer array (binding 0 with `K >= 4`) and a 16-byte buffer (binding 10 with
    /// `K < 4`).
    pub(super) dummy_ids: wgpu::TextureView,
    pub(super) dummy_buffer: wgpu::Buffer,
    pub(super) shade_layout: wgpu::BindGroupLayout,
    pub(super) shade_pipeline_layout: wgpu::PipelineLayout,
    pub(super) shade_module: wgpu::ShaderModule,
    pub(super) shade_pipelines: Mutex<HashMap<ShadeKey, Arc<wgpu::ComputePipeline>>>,
}

/// Override constants of the shade kernel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) struct ShadeKey {
    pub(super) channels: u32,
    pub(super) image: bool,
    pub(super) range: bool,
    pub(super) profile: bool,
    pub(super) total: bool,
    pub(super) footprint: bool,
    /// Transmitter cast shadows (bistatic only).
    pub(super) shadows: bool,
    /// The Mueller elements looked up ([`SensorSetup::element_mask`]).
    pub(super) elements: u32,
    /// Visibility samples per pixel.
    pub(super) samples: u32,
    /// Analytic coverage ([`SensorSetup::analytic`]).
    pub(super) analytic: bool,
    /// Some material's terms are evaluated in the kernel ([`GpuTables::in_shader`]).
    pub(super) in_shader: bool,
    /// The profile's second moment beside it ([`KernelOutputs::area`]).
    pub(super) area: bool,
}

impl Pipelines {
    /// Compile the visibility, gather and shade pipelines on `device` (the shade kernel's
    /// specializations on demand, [`Pipelines::shade_pipeline`]).
    pub(super) fn new(device: &wgpu::Device, views: u32) -> Result<Self> {
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
            source: wgpu::ShaderSource::Wgsl(shaders::visibility_module().into()),
        });

        let vis_pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("visibility"),
            bind_group_layouts: &[Some(&vis_layout)],
            immediate_size: 0,
        });
        // [no culling, back faces culled (closed, outward-wound meshes: Mesh::closed)];
        // the view maps the body's outward normals facing the viewer to counter-clockwise
        let vis_pipelines =
            |count: u32, fs: &str, format, vertex: (&wgpu::ShaderModule, &str), mask| {
                [None, Some(wgpu::Face::Back)].map(|cull_mode| {
                    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                        label: Some("visibility"),
                        layout: Some(&vis_pl),
                        vertex: wgpu::VertexState {
                            module: vertex.0,
                            entry_point: Some(vertex.1),
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
                        multiview_mask: mask,
                        cache: None,
                    })
                })
            };
        let ids = wgpu::TextureFormat::R32Uint;
        let vis_pipeline = vis_pipelines(1, "fs_main", ids, (&vis_module, "vs_main"), None);
        // multiview (devices with the feature): a mask of the first `views` views, in an
        // error scope of its own: where the device refuses them, one layer per pass
        let vis_pipeline_views = (views > 1)
            .then(|| {
                let inner = device.push_error_scope(wgpu::ErrorFilter::Validation);
                let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("visibility_views.wgsl"),
                    source: wgpu::ShaderSource::Wgsl(shaders::visibility_views_module().into()),
                });
                let mask = std::num::NonZeroU32::new(u32::MAX >> (32 - views.min(32)));
                let p = vis_pipelines(1, "fs_main", ids, (&module, "vs_views"), mask);
                pollster::block_on(inner.pop()).is_none().then_some(p)
            })
            .flatten();
        // R32Float: multisampled in core WebGPU (R32Uint needs an adapter-specific feature)
        let vis_pipeline_msaa = vis_pipelines(
            MSAA as u32,
            "fs_float",
            wgpu::TextureFormat::R32Float,
            (&vis_module, "vs_main"),
            None,
        );
        let dummy_ids = device
            .create_texture(&wgpu::TextureDescriptor {
                label: Some("unused ids"),
                size: wgpu::Extent3d {
                    width: 1,
                    height: 1,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::R32Uint,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
            .create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            });
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
            layout: Some(
                &device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("gather"),
                    bind_group_layouts: &[Some(&gather_layout)],
                    immediate_size: 0,
                }),
            ),
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
                // the pixels with thin faces (render::thin)
                storage(11, true, cs),
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
        let views = if vis_pipeline_views.is_some() {
            views
        } else {
            1
        };
        Ok(Pipelines {
            vis_layout,
            vis_pipeline,
            vis_pipeline_views,
            views,
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

    /// The shade kernel specialized to `key` (compiled on first use, then cached).
    pub(super) fn shade_pipeline(
        &self,
        device: &wgpu::Device,
        key: ShadeKey,
    ) -> Result<Arc<wgpu::ComputePipeline>> {
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
            ("WRITE_AREA", b(key.area)),
            ("WRITE_TOTAL", b(key.total)),
            ("WRITE_FOOTPRINT", b(key.footprint)),
            ("SHADOWS", b(key.shadows)),
            ("ELEMENT_MASK", key.elements as f64),
            ("SAMPLES", key.samples as f64),
            ("COVERAGE", b(key.analytic)),
            ("IN_SHADER", b(key.in_shader)),
        ];
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let p = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
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
