// The inter-reflection paths' random numbers for a block of pixels and paths (one
// invocation per path of a pixel): every set's three 24-bit numbers of shared/rng.wgsl, as
// render::paths::PixelRng draws them on the CPU. The device path kernel will draw its
// numbers the same way; this kernel is its twin check (compare_gpu_cpu::
// path_random_numbers_kernel_matches_twin).
//
//   params = (seed, pixels, paths, pixel_stride, pixel_offset): pixel p of the block is
//     image pixel p * pixel_stride + pixel_offset;
//   out[((p paths + i) 3 + set) 3 + d] = dimension d of set `set` for path i of pixel p.

//#include "shared/rng.wgsl"

@group(0) @binding(0) var<storage, read> params: array<u32>;
@group(0) @binding(1) var<storage, read_write> out: array<u32>;

@compute @workgroup_size(64, 1, 1)
fn cs_path_numbers(@builtin(global_invocation_id) gid: vec3<u32>) {
    let seed = params[0];
    let pixels = params[1];
    let paths = params[2];
    if (gid.x >= pixels * paths) {
        return;
    }
    let p = gid.x / paths;
    let i = gid.x % paths;
    let base = rng_pixel(seed, p * params[3] + params[4]);
    for (var which = 0u; which < 3u; which++) {
        let v = rng_set(base, i, which);
        for (var d = 0u; d < 3u; d++) {
            out[(gid.x * 3u + which) * 3u + d] = v[d];
        }
    }
}
