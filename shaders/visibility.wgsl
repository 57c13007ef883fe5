// Visibility pass: orthographic rasterization of the mesh, one attitude per draw.
//
// Coordinates (see src/render/mod.rs): `rotations[i]` maps body-frame positions to the
// view frame of this pass (x right, y up, z toward the viewer). The image square spans
// [-ext, ext] in x and y; depth maps z in [-ext_z, ext_z] to [1, 0] (nearest smallest).
// The fragment writes the triangle index + 1 (0 = empty) to an R32Uint target.
// CPU twin: `render::twin::visibility` (ray casting through pixel centres).

struct Params {
    ext: f32,
    ext_z: f32,
    _pad0: f32,
    _pad1: f32,
}

@group(0) @binding(0) var<storage, read> geometry: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read> rotations: array<mat3x3<f32>>;
@group(0) @binding(2) var<uniform> params: Params;

struct VsOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) tri: u32,
}

@vertex
fn vs_main(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VsOut {
    let p = rotations[ii] * geometry[vi].xyz;
    var out: VsOut;
    out.pos = vec4<f32>(p.x / params.ext, p.y / params.ext, 0.5 - 0.5 * p.z / params.ext_z, 1.0);
    out.tri = vi / 3u + 1u;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) u32 {
    return in.tri;
}
