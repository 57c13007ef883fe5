// Gather of multisampled visibility (K >= 4 samples per pixel): one invocation per texel
// of one raster pass of one attitude.
//
// With K >= 4 the receiver's view of an attitude is rasterized in K/4 passes at 4 samples
// per texel (visibility.wgsl, fs_float) into one multisampled R32Float texture, pass p in
// the tile at ((p % cols) side, (p / cols) side), side = width + 2 (the image with a margin
// of one texel, where samples wrapped out of a border pixel are drawn). Every attitude is
// drawn into the same texture at the same place, so its rasterization, and the result, do
// not depend on where it falls in a batch. This kernel then copies the tiles' samples,
// as u32 triangle ids + 1 (exact: ids < 2^24 as f32), into the attitude's slot of the
// `ids` buffer that the shade kernel reads (shade.wgsl, sample_id):
//   ids[((layer P + p) side^2 + y side + x) 4 + s] = sample s of texel (x, y) of tile p.
// CPU twin: the identity; render::cpu::visibility casts the samples' rays directly, and
// render::gpu tests compare the whole chain (samples_kernel_matches_twin).

struct Gather {
    layer: u32,   // the attitude's index in the chunk
    side: u32,    // tile side, width + 2
    cols: u32,    // tiles per row of the texture
    passes: u32,  // K / 4
}

@group(0) @binding(0) var tiles: texture_multisampled_2d<f32>;
@group(0) @binding(1) var<storage, read_write> ids: array<u32>;
@group(0) @binding(2) var<uniform> g: Gather;

@compute @workgroup_size(8, 8, 1)
fn cs_gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    let y = gid.y;
    let p = gid.z;
    if (x >= g.side || y >= g.side || p >= g.passes) {
        return;
    }
    let tx = (p % g.cols) * g.side + x;
    let ty = (p / g.cols) * g.side + y;
    let base = (((g.layer * g.passes + p) * g.side + y) * g.side + x) * 4u;
    for (var s = 0u; s < 4u; s++) {
        ids[base + s] = u32(textureLoad(tiles, vec2<i32>(i32(tx), i32(ty)), i32(s)).x);
    }
}
