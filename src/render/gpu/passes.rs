//! The GPU passes: the shade kernel's key for a render ([`shade_key`]; the pipelines are in
//! [`super::pipelines`]), what a render uploads once ([`SceneBuffers`]),
//! and per chunk of attitudes the bind groups ([`ChunkBindings`]) and the encoded passes
//! ([`encode_chunk`]): the receiver's visibility raster into its targets
//! ([`super::targets`]; with `K >= 4` samples gathered from multisampled tiles), bistatic
//! the transmitter's, then the shade dispatch.

use super::device::Gpu;
use super::pack::{raster_shifts, raster_transform, GpuTables, ShadeParams, VisParams};
use super::pipelines::ShadeKey;
use super::plan::Plan;
use super::readback::ResultBuffers;
use super::targets::Targets;
use crate::render::api::{Layout, SensorSetup};
use crate::render::geometry::{gpu_rotation, transmitter_rotation, Rot};
use crate::render::samples::MSAA;
use wgpu::util::DeviceExt;

/// The kernel a render needs: its outputs ([`Plan::kern`]) and the sensor's options.
pub(super) fn shade_key(plan: &Plan, sensor: &SensorSetup, tables: &GpuTables) -> ShadeKey {
    let kern = plan.kern;
    ShadeKey {
        channels: plan.channels as u32,
        image: kern.image,
        range: kern.range,
        profile: kern.profile,
        // With the profile on the device the total is its sum, taken exactly on the host
        // from the same fixed-point words (the bins cover every pixel's footprint and pulse
        // support, see Layout): the kernel's workgroup reduction is then compiled out.
        total: kern.total(),
        footprint: kern.footprint,
        shadows: sensor.bistatic_angle > 0.0,
        elements: sensor.element_mask(),
        samples: sensor.samples as u32,
        analytic: sensor.analytic,
        in_shader: tables.in_shader,
        area: kern.area,
    }
}

/// Transforms padded to whole groups of `views` (the last repeated): a multiview pass draws
/// every layer of its group, those past the chunk's end included (never read).
fn pad_to_views(transforms: &mut Vec<[f32; 16]>, views: u32) {
    let n = transforms.len().div_ceil(views as usize) * views as usize;
    if let Some(&last) = transforms.last() {
        transforms.resize(n, last);
    }
}

/// A visibility render pass into an id target (cleared to 0) and its depth buffer (cleared
/// to the far plane, not stored), of `views` layers by multiview when that is above 1.
fn id_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    ids: &wgpu::TextureView,
    depth: &wgpu::TextureView,
    views: u32,
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
        multiview_mask: (views > 1)
            .then(|| std::num::NonZeroU32::new(u32::MAX >> (32 - views)))
            .flatten(),
    })
}

/// What a render uploads once for all its chunks: the mesh and tables, the shade kernel's
/// uniform block, the visibility passes' uniform blocks (the image square, and with
/// `K >= 4` a tile: the image with its margin) and the raster passes' displacements.
pub(super) struct SceneBuffers {
    geometry: wgpu::Buffer,
    tables: wgpu::Buffer,
    shade_params: wgpu::Buffer,
    vis_image: wgpu::Buffer,
    vis_tiles: Option<wgpu::Buffer>,
    /// Per raster pass of an attitude, its translation ([`raster_shifts`]).
    shifts: Vec<[f32; 4]>,
}

impl SceneBuffers {
    pub(super) fn new(
        dev: &wgpu::Device,
        geometry: &[[f32; 4]],
        tables: &GpuTables,
        params: &ShadeParams,
        lay: &Layout,
        samples: usize,
    ) -> Self {
        let w = lay.width;
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
        let msaa = samples >= MSAA;
        let vis_uni = |ext: f64| {
            dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("visibility params"),
                contents: bytemuck::bytes_of(&VisParams::new(ext, lay.ext)),
                usage: wgpu::BufferUsages::UNIFORM,
            })
        };
        let vis_uni_image = vis_uni(lay.ext);
        // a tile is the image with a one-texel margin (MsaaTiles)
        let vis_uni_tiles = msaa.then(|| vis_uni(lay.ext * (w + 2) as f64 / w as f64));
        SceneBuffers {
            geometry: geo_buf,
            tables: tab_buf,
            shade_params: shade_uni,
            vis_image: vis_uni_image,
            vis_tiles: vis_uni_tiles,
            shifts: raster_shifts(samples, lay.pix),
        }
    }

    /// Raster passes per attitude of the receiver's view.
    pub(super) fn passes(&self) -> usize {
        self.shifts.len()
    }
}

/// The bind groups of one chunk of attitudes: the receiver's raster (every pass's
/// transform), bistatic the transmitter's, and the shade kernel's.
pub(super) struct ChunkBindings {
    vis: wgpu::BindGroup,
    tx: Option<wgpu::BindGroup>,
    shade: wgpu::BindGroup,
}

impl ChunkBindings {
    /// For the attitudes `rots`; `beta`: the bistatic angle when the transmitter's view
    /// is drawn (the shade kernel's cast shadows), else `None`; `thin`: the chunk's pixels
    /// with thin faces ([`crate::render::thin::gpu_words`]; empty: none).
    pub(super) fn new(
        gpu: &Gpu,
        scene: &SceneBuffers,
        targets: &Targets,
        results: &ResultBuffers<'_>,
        rots: &[Rot],
        beta: Option<f64>,
        thin: &[u32],
    ) -> Self {
        let dev = &gpu.device;
        let rot_words: Vec<[f32; 12]> = rots.iter().map(gpu_rotation).collect();
        let rot_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("rotations"),
            contents: bytemuck::cast_slice(&rot_words),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let vis_group = |rot: &wgpu::Buffer, uni: &wgpu::Buffer| {
            dev.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("visibility"),
                layout: &gpu.pipelines.vis_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: scene.geometry.as_entire_binding(),
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
        // the receiver's raster transforms: attitude l, pass p at instance l P + p, its
        // samples moved to where the rasterizer samples (shaders/visibility.wgsl)
        let mut tfs: Vec<[f32; 16]> = rots
            .iter()
            .flat_map(|r| scene.shifts.iter().map(move |&t| raster_transform(r, t)))
            .collect();
        pad_to_views(&mut tfs, gpu.pipelines.views);
        let tf_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("raster transforms"),
            contents: bytemuck::cast_slice(&tfs),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let vis_bg = vis_group(
            &tf_buf,
            scene.vis_tiles.as_ref().unwrap_or(&scene.vis_image),
        );
        // bistatic: R_tx = R_y(-beta) R, computed in f64 (wi -> +z)
        let tx_bg = beta.map(|beta| {
            let mut tx_rots: Vec<[f32; 16]> = rots
                .iter()
                .map(|r| raster_transform(&transmitter_rotation(r, beta), [0.0; 4]))
                .collect();
            pad_to_views(&mut tx_rots, gpu.pipelines.views);
            let buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("transmitter rotations"),
                contents: bytemuck::cast_slice(&tx_rots),
                usage: wgpu::BufferUsages::STORAGE,
            });
            vis_group(&buf, &scene.vis_image)
        });
        let pl = &gpu.pipelines;
        let thin_buf = (!thin.is_empty()).then(|| {
            dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("thin pixels"),
                contents: bytemuck::cast_slice(thin),
                usage: wgpu::BufferUsages::STORAGE,
            })
        });
        let shade_bg = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout: &pl.shade_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(
                        targets
                            .rcv
                            .as_ref()
                            .map_or(&pl.dummy_ids, |t| &t.array_view),
                    ),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: scene.geometry.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: rot_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: scene.tables.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: scene.shade_params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: results.image.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: results.range.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 7,
                    resource: results.profile.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: results.total.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 9,
                    resource: wgpu::BindingResource::TextureView(
                        targets
                            .tx
                            .as_ref()
                            .or(targets.rcv.as_ref())
                            .map_or(&pl.dummy_ids, |t| &t.array_view),
                    ),
                },
                wgpu::BindGroupEntry {
                    binding: 10,
                    resource: targets
                        .ids_buf
                        .as_ref()
                        .unwrap_or(&pl.dummy_buffer)
                        .as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 11,
                    resource: thin_buf
                        .as_ref()
                        .unwrap_or(&pl.dummy_buffer)
                        .as_entire_binding(),
                },
            ],
        });
        ChunkBindings {
            vis: vis_bg,
            tx: tx_bg,
            shade: shade_bg,
        }
    }
}

/// Encode the passes of a chunk of `m` attitudes (`width` the internal image side): the
/// receiver's visibility raster (`K >= 4`: per attitude its multisampled passes into the
/// tiles, then their samples gathered), bistatic the transmitter's, then the shade kernel.
#[allow(clippy::too_many_arguments)]
pub(super) fn encode_chunk(
    enc: &mut wgpu::CommandEncoder,
    gpu: &Gpu,
    targets: &Targets,
    bindings: &ChunkBindings,
    pipeline: &wgpu::ComputePipeline,
    m: usize,
    n_tri: u32,
    closed: bool,
    width: usize,
) {
    let pl = &gpu.pipelines;
    let (n_s, n_pass) = (targets.samples, targets.n_pass);
    // the receiver's view, then (bistatic) the transmitter's
    // (layer l K + k holds attitude l's sample k, drawn with transform l K + k)
    let mut views_and_groups = vec![];
    if let Some(t) = &targets.rcv {
        views_and_groups.push((t, &bindings.vis, n_s));
    }
    if let (Some(bg), Some(t)) = (&bindings.tx, &targets.tx) {
        views_and_groups.push((t, bg, 1));
    }
    if let (Some(t), Some(gbg)) = (&targets.tiles, &targets.gather_bg) {
        // per attitude: its K / MSAA passes into the tiles, then their samples gathered
        // into its slot of the id buffer (the same tiles for every attitude, so the
        // rasterization does not depend on the attitude's place in the batch)
        let side = t.side as u32;
        for l in 0..m {
            let mut pass = id_pass(enc, "visibility tiles", &t.view, &t.depth_view, 1);
            pass.set_pipeline(&pl.vis_pipeline_msaa[closed as usize]);
            pass.set_bind_group(0, &bindings.vis, &[]);
            for p in 0..n_pass {
                let (x, y) = t.origin(p);
                pass.set_viewport(x as f32, y as f32, side as f32, side as f32, 0.0, 1.0);
                pass.set_scissor_rect(x as u32, y as u32, side, side);
                let i = (l * n_pass + p) as u32;
                pass.draw(0..(3 * n_tri), i..i + 1);
            }
            drop(pass);
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pl.gather_pipeline);
            pass.set_bind_group(0, gbg, &[(l * targets.stride) as u32]);
            let g = side.div_ceil(8);
            pass.dispatch_workgroups(g, g, n_pass as u32);
        }
    }
    // a pass per group of V layers: instance g V draws them, view v the layer g V + v
    // (multiview), or V = 1 and a pass per layer
    for (t, bg, k_s) in views_and_groups {
        let v = t.views as usize;
        let pipeline = match (&pl.vis_pipeline_views, v > 1) {
            (Some(p), true) => &p[closed as usize],
            _ => &pl.vis_pipeline[closed as usize],
        };
        for g in 0..(m * k_s).div_ceil(v) {
            let mut pass = id_pass(
                enc,
                "visibility",
                &t.id_views[g],
                &t.depth_views[g],
                t.views,
            );
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bg, &[]);
            let first = (g * v) as u32;
            pass.draw(0..(3 * n_tri), first..first + 1);
        }
    }
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &bindings.shade, &[]);
        let g = (width as u32).div_ceil(8);
        pass.dispatch_workgroups(g, g, m as u32);
    }
}
