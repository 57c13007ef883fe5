//! The raster targets of triangle ids the visibility passes draw into and the shade kernel
//! reads: per attitude and sample a layer of an R32Uint array ([`IdTarget`]), or with
//! `K >= 4` visibility samples the tiles of one multisampled texture ([`MsaaTiles`])
//! gathered into a buffer; bistatic, the transmitter's layers too ([`Targets`]).

use super::device::Gpu;
use super::pack::gather_params;
use super::util::create_buffer;
use crate::render::samples::MSAA;
use wgpu::util::DeviceExt;

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

/// A raster target of triangle ids (R32Uint, read by the shade kernel) with its depth
/// buffer, `layers` attitudes (or samples) deep, rounded up to whole groups of `views`
/// layers: a view per group for the raster passes (one layer each when `views` is 1, else
/// `views`-layer arrays drawn by multiview), an array view of all layers for the kernel.
pub(super) struct IdTarget {
    pub(super) array_view: wgpu::TextureView,
    pub(super) id_views: Vec<wgpu::TextureView>,
    pub(super) depth_views: Vec<wgpu::TextureView>,
    /// Layers per pass (per view of `id_views` and `depth_views`).
    pub(super) views: u32,
}

impl IdTarget {
    pub(super) fn new(dev: &wgpu::Device, label: &str, side: u32, layers: u32, views: u32) -> Self {
        let views = views.max(1);
        let groups = layers.div_ceil(views).max(1);
        let size = wgpu::Extent3d {
            width: side,
            height: side,
            depth_or_array_layers: groups * views,
        };
        let (ids, depth) = id_textures(dev, label, size, 1, wgpu::TextureFormat::R32Uint);
        let group_views = |t: &wgpu::Texture| -> Vec<wgpu::TextureView> {
            (0..groups)
                .map(|g| {
                    t.create_view(&wgpu::TextureViewDescriptor {
                        dimension: Some(if views > 1 {
                            wgpu::TextureViewDimension::D2Array
                        } else {
                            wgpu::TextureViewDimension::D2
                        }),
                        base_array_layer: g * views,
                        array_layer_count: Some(views),
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
            id_views: group_views(&ids),
            depth_views: group_views(&depth),
            views,
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
pub(super) struct MsaaTiles {
    pub(super) view: wgpu::TextureView,
    pub(super) depth_view: wgpu::TextureView,
    pub(super) side: usize,
    cols: usize,
}

impl MsaaTiles {
    /// Columns and rows of `passes` tiles of `side` texels within `max_dim` texels.
    pub(super) fn grid(side: usize, passes: usize, max_dim: usize) -> Option<(usize, usize)> {
        let cols = (max_dim / side).min(passes);
        (cols > 0 && passes.div_ceil(cols) * side <= max_dim).then(|| (cols, passes.div_ceil(cols)))
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
    pub(super) fn origin(&self, p: usize) -> (usize, usize) {
        ((p % self.cols) * self.side, (p / self.cols) * self.side)
    }
}

/// The raster targets, made once for the largest chunk (`c` attitudes): the receiver's
/// id layers (`K < 4`) or multisampled tiles, the buffer their samples are gathered into
/// and per attitude its gather parameters (`K >= 4`), and bistatic the transmitter's id
/// layers.
pub(super) struct Targets {
    pub(super) rcv: Option<IdTarget>,
    pub(super) tiles: Option<MsaaTiles>,
    pub(super) ids_buf: Option<wgpu::Buffer>,
    pub(super) gather_bg: Option<wgpu::BindGroup>,
    /// Bytes between two attitudes' gather parameters (their dynamic offsets).
    pub(super) stride: usize,
    pub(super) tx: Option<IdTarget>,
    /// Visibility samples per pixel and raster passes per attitude.
    pub(super) samples: usize,
    pub(super) n_pass: usize,
}

impl Targets {
    pub(super) fn new(
        gpu: &Gpu,
        w: usize,
        samples: usize,
        n_pass: usize,
        c: usize,
        tx_width: Option<u32>,
    ) -> Self {
        let dev = &gpu.device;
        let (n_s, msaa) = (samples, samples >= MSAA);
        let (rcv, tiles) = if msaa {
            let max_dim = gpu.info.max_texture_dimension_2d as usize;
            (None, Some(MsaaTiles::new(dev, w + 2, n_pass, max_dim)))
        } else {
            let views = gpu.pipelines.views;
            let t = IdTarget::new(dev, "visibility target", w as u32, (c * n_s) as u32, views);
            (Some(t), None)
        };
        // K >= 4: the gathered sample ids, and per attitude of a chunk its gather parameters
        // (one uniform block each, bound at a dynamic offset)
        let ids_buf = tiles.as_ref().map(|t| {
            create_buffer(
                dev,
                "sample ids",
                (c * n_pass * t.side * t.side * MSAA * 4) as u64,
                wgpu::BufferUsages::STORAGE,
            )
        });
        let stride = gpu.limits.min_uniform_buffer_offset_alignment.max(16) as usize;
        let gather_bg = tiles.as_ref().zip(ids_buf.as_ref()).map(|(t, ids)| {
            let words = gather_params(c, stride, t.side, t.cols, n_pass);
            let uni = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("gather params"),
                contents: bytemuck::cast_slice(&words),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            dev.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("gather"),
                layout: &gpu.pipelines.gather_layout,
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
        let tx = tx_width
            .map(|tw| IdTarget::new(dev, "transmitter target", tw, c as u32, gpu.pipelines.views));
        Targets {
            rcv,
            tiles,
            ids_buf,
            gather_bg,
            stride,
            tx,
            samples,
            n_pass,
        }
    }
}
