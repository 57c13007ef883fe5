// Visibility pass by multiview (devices with wgpu's MULTIVIEW feature): one pass draws V
// consecutive layers of the id target, view `v` of instance `ii` drawing transform ii + v
// into layer ii + v of the pass's V-layer view. One draw then rasterizes V attitudes (or
// samples) instead of one pass per layer; each layer's arithmetic is that of
// visibility.wgsl's vs_main (raster_vertex), and the fragment stage is visibility.wgsl's.
// CPU twin: `render::cpu::visibility`, as for visibility.wgsl.

//#include "shared/raster.wgsl"

@vertex
fn vs_views(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32,
            @builtin(view_index) view: u32) -> VsOut {
    return raster_vertex(vi, ii + view);
}
