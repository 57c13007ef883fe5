// Visibility pass: the mesh rasterized into one layer (or tile) per pass, instance `ii`
// drawing transform `ii` (shared/raster.wgsl says what the transforms and targets are).
// CPU twin: `render::cpu::visibility` (ray casting through the same sample points).

//#include "shared/raster.wgsl"

@vertex
fn vs_main(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VsOut {
    return raster_vertex(vi, ii);
}

@fragment
fn fs_main(in: VsOut) -> @location(0) u32 {
    return in.tri;
}

// The same for the multisampled tiles of K >= 4 samples (R32Float target, see MsaaTiles
// in src/render/gpu/targets.rs; gathered by gather.wgsl): the index + 1 as a float, exact below 2^24.
@fragment
fn fs_float(in: VsOut) -> @location(0) f32 {
    return f32(in.tri);
}
