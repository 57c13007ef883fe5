//! Every byte layout the kernels read: the mesh's geometry ([`geometry`]), the material
//! tables ([`GpuTables`], header of [`HEADER_WORDS`] words per material for up to
//! [`MAX_PARTS`] parts), the uniform blocks mirroring the WGSL structs ([`ShadeParams`]
//! for `shade.wgsl`, `VisParams` for `visibility.wgsl`, the gather parameters of
//! `gather.wgsl`) and the raster passes' transforms. The WGSL side of each is named where
//! it is declared here; change both together.

use crate::error::{Error, Result};
use crate::render::api::{Layout, SensorSetup};
use crate::render::geometry::{gpu_rotation, Mesh, Rot};
use crate::render::samples::{
    msaa_samples, raster_displacements, sample_offsets, MAX_SAMPLES, MSAA,
};

/// The mesh as the kernels read it ([`Mesh::gpu_geometry`]: vertices, then normals), with
/// `adjacency` (analytic coverage, or K > 1 samples for the thin-part pixels) followed by
/// the triangles across each edge, for the kernel's candidate search (`u32::MAX` across a
/// boundary edge).
pub fn geometry(mesh: &Mesh, adjacency: bool) -> Vec<[f32; 4]> {
    let mut geometry = mesh.gpu_geometry();
    if adjacency {
        // the triangles across each edge, for the kernel's candidate search (after the
        // vertices and normals; u32::MAX across a boundary edge)
        geometry.extend(
            mesh.adjacency()
                .iter()
                .map(|a| [a[0], a[1], a[2], u32::MAX].map(f32::from_bits)),
        );
    }
    geometry
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
    /// Fixed-point units per m^2 of the area moment (`WRITE_AREA`).
    pub fix_area: f32,
    pub _pad: [u32; 3],
    /// Per visibility sample `(u, v, dc, dr)`: its offset in the pixel ([`sample_offsets`])
    /// and, with `K >= 4`, the texel of its raster pass's tile that holds it, relative to
    /// the pixel's ([`msaa_samples`]; the first [`SensorSetup::samples`], which the kernel
    /// has as the constant `SAMPLES`).
    pub offsets: [[f32; 4]; MAX_SAMPLES],
}

/// Uniform block of `visibility.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable, Debug)]
pub(super) struct VisParams {
    ext: f32,
    ext_z: f32,
    _pad: [f32; 2],
}

impl ShadeParams {
    /// The uniform block of a render: `fix_scale` and `fix_area` the fixed-point scales of
    /// the profile and the area moment (rounded to f32 here; the kernel's are what the host
    /// divides by), `tx_width` the transmitter's map.
    pub fn new(
        mesh: &Mesh,
        lay: &Layout,
        sensor: &SensorSetup,
        fix_scale: f64,
        fix_area: f64,
        tx_w: usize,
    ) -> Self {
        let w = lay.width;
        let beta = sensor.bistatic_angle;
        let wi = [beta.sin() as f32, 0.0, beta.cos() as f32, 0.0];
        let s_tx = sensor.polarization.unwrap_or([1.0, 0.0, 0.0, 0.0]);
        ShadeParams {
            width: w as u32,
            height: w as u32,
            n_bins: lay.n_bins as u32,
            n_tri: mesh.faces.len() as u32,
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
            fix_area: fix_area as f32,
            _pad: [0; 3],
            offsets: gpu_offsets(sensor.samples),
        }
    }
}

impl VisParams {
    /// The square `[-ext, ext]` drawn, depths scaled by the mesh's extent `mesh_ext`.
    pub(super) fn new(ext: f64, mesh_ext: f64) -> Self {
        VisParams {
            ext: ext as f32,
            ext_z: (mesh_ext * 1.001) as f32,
            _pad: [0.0; 2],
        }
    }
}

/// Per raster pass of `k` samples, the translation (m, the image's `(X, Y)`) that moves its
/// sample points where the rasterizer samples ([`raster_displacements`], pixels of side
/// `pix`, `v` down).
pub(super) fn raster_shifts(k: usize, pix: f64) -> Vec<[f32; 4]> {
    raster_displacements(k)
        .iter()
        .map(|d| [(d[0] * pix) as f32, (-d[1] * pix) as f32, 0.0, 0.0])
        .collect()
}

/// A raster pass's transform as `visibility.wgsl` reads it: the rotation's 12 words
/// ([`gpu_rotation`]) and the translation `t`.
pub(super) fn raster_transform(r: &Rot, t: [f32; 4]) -> [f32; 16] {
    let mut a = [0.0f32; 16];
    a[..12].copy_from_slice(&gpu_rotation(r));
    a[12..].copy_from_slice(&t);
    a
}

/// The uniform blocks of `gather.wgsl` for the `c` attitudes of a chunk, `stride` bytes
/// apart (bound at dynamic offsets): `[attitude, tile side, tiles per row, passes]`.
pub(super) fn gather_params(
    c: usize,
    stride: usize,
    side: usize,
    cols: usize,
    n_pass: usize,
) -> Vec<u32> {
    let mut words = vec![0u32; c * stride / 4];
    for l in 0..c {
        words[l * stride / 4..][..4].copy_from_slice(&[
            l as u32,
            side as u32,
            cols as u32,
            n_pass as u32,
        ]);
    }
    words
}

/// [`sample_offsets`] (and the tile texels, [`msaa_samples`]) as the uniform block holds them.
pub(super) fn gpu_offsets(k: usize) -> [[f32; 4]; MAX_SAMPLES] {
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
/// [`crate::brdf::table::DepolarizingParams::words`], the first of which is its kind).
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
    Depolarizing(&'a crate::brdf::table::DepolarizingParams),
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
        let depolarizing = t
            .depolarizing
            .iter()
            .map(|p| in_kernel(InKernel::Depolarizing(p)));
        single
            .chain(depolarizing)
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
                        InKernel::Depolarizing(lp) => {
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
