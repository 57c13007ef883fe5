// The visibility passes' shared part: orthographic rasterization of the mesh, one attitude
// (and visibility sample) per array layer or tile; used by visibility.wgsl (one layer per
// pass) and visibility_views.wgsl (several layers per pass by multiview).
//
// Coordinates (see src/render/mod.rs): `transforms[t]` (rotation columns, then a
// translation) maps body-frame positions to the view frame of this pass (x right, y up,
// z toward the viewer). The image square spans
// [-ext, ext] in x and y; depth maps z in [-ext_z, ext_z] to [1, 0] (nearest smallest).
// The fragment writes the triangle index + 1 (0 = empty) to an R32Uint target.
// Visibility samples (src/render/samples.rs, sample_offsets and raster_displacements): with
// K < 4, transform l K + k draws attitude l for sample k, whose offset (u, v) in the pixel
// (from its top-left corner, v down the rows) is moved onto the pixel centre, where the
// rasterizer samples: the translation is ((1/2 - u) pix, (v - 1/2) pix, 0). K = 1 samples
// the centre itself (no translation). With K >= 4, transform l K/4 + p draws raster pass p
// of attitude l into its tile of a 4x multisampled target (MsaaTiles), moved by minus the
// pass's shift of the standard sample positions (msaa_samples). Translations are built
// on the host, so the vertex stage costs one affine map per vertex for any K.
// CPU twin: `render::cpu::visibility` (ray casting through the same sample points).

struct Params {
    ext: f32,
    ext_z: f32,
    _pad0: f32,
    _pad1: f32,
}

@group(0) @binding(0) var<storage, read> geometry: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read> transforms: array<mat4x3<f32>>;
@group(0) @binding(2) var<uniform> params: Params;

struct VsOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) tri: u32,
}

// Vertex `vi` of the mesh under transform `t`: the same arithmetic whichever layer, tile or
// view it is drawn into, so an attitude rasterizes the same in any place of any batch.
fn raster_vertex(vi: u32, t: u32) -> VsOut {
    let p = transforms[t] * vec4<f32>(geometry[vi].xyz, 1.0);
    var out: VsOut;
    out.pos = vec4<f32>(p.x / params.ext, p.y / params.ext, 0.5 - 0.5 * p.z / params.ext_z, 1.0);
    out.tri = vi / 3u + 1u;
    return out;
}
