// The inter-reflection paths' random numbers (twin: render::paths::rng, bit for bit):
// three shuffled, Owen-scrambled Sobol' sequences per pixel (Burley 2020), keyed by
// hashes of (seed, pixel, set). Set 0 draws the point in the pixel, sets 1 and 2 the
// directions at the first and second surface (dimensions 0, 1) and the lobe (dimension 2).
// Each number is 24 bits, returned as the integer x in [0, 2^24): u = x / 2^24 exactly in
// f32 (and in the twin's f64).

// The PCG output permutation of Jarzynski and Olano 2020 (render::paths::hash32).
fn rng_hash32(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Sobol' direction numbers of dimensions 1 and 2 (Joe and Kuo: x + 1, m = 1; x^2 + x + 1,
// m = 1, 3), 32 bits; dimension 0 is the bit reversal of the index.
const RNG_SOBOL1 = array<u32, 32>(
    0x80000000u, 0xc0000000u, 0xa0000000u, 0xf0000000u, 0x88000000u, 0xcc000000u,
    0xaa000000u, 0xff000000u, 0x80800000u, 0xc0c00000u, 0xa0a00000u, 0xf0f00000u,
    0x88880000u, 0xcccc0000u, 0xaaaa0000u, 0xffff0000u, 0x80008000u, 0xc000c000u,
    0xa000a000u, 0xf000f000u, 0x88008800u, 0xcc00cc00u, 0xaa00aa00u, 0xff00ff00u,
    0x80808080u, 0xc0c0c0c0u, 0xa0a0a0a0u, 0xf0f0f0f0u, 0x88888888u, 0xccccccccu,
    0xaaaaaaaau, 0xffffffffu);
const RNG_SOBOL2 = array<u32, 32>(
    0x80000000u, 0xc0000000u, 0x60000000u, 0x90000000u, 0xe8000000u, 0x5c000000u,
    0x8e000000u, 0xc5000000u, 0x68800000u, 0x9cc00000u, 0xee600000u, 0x55900000u,
    0x80680000u, 0xc09c0000u, 0x60ee0000u, 0x90550000u, 0xe8808000u, 0x5cc0c000u,
    0x8e606000u, 0xc5909000u, 0x6868e800u, 0x9c9c5c00u, 0xeeee8e00u, 0x5555c500u,
    0x8000e880u, 0xc0005cc0u, 0x60008e60u, 0x9000c590u, 0xe8006868u, 0x5c009c9cu,
    0x8e00eeeeu, 0xc5005555u);

// Point `index` of Sobol's sequence in dimension `dim` (0, 1 or 2).
fn rng_sobol(index: u32, dim: u32) -> u32 {
    if (dim == 0u) {
        return reverseBits(index);
    }
    var x = 0u;
    var i = index;
    while (i != 0u) {
        let k = firstTrailingBit(i);
        x ^= select(RNG_SOBOL2[k], RNG_SOBOL1[k], dim == 1u);
        i &= i - 1u;
    }
    return x;
}

// Laine and Karras's hash-based Owen scrambling, Burley's constants.
fn rng_scramble(x: u32, seed: u32) -> u32 {
    var v = reverseBits(x);
    v += seed;
    v ^= v * 0x6c50b47cu;
    v ^= v * 0xb82f1e52u;
    v ^= v * 0xc7afe638u;
    v ^= v * 0x8d22f6e6u;
    return reverseBits(v);
}

// The key of a pixel's numbers (render::paths::PixelRng::new).
fn rng_pixel(seed: u32, pixel: u32) -> u32 {
    return rng_hash32(rng_hash32(seed) ^ pixel);
}

// Dimensions 0, 1, 2 of set `which` for path `i` of the pixel keyed `base`, as 24-bit
// integers (render::paths::PixelRng::set).
fn rng_set(base: u32, i: u32, which: u32) -> vec3<u32> {
    let key = rng_hash32(base ^ which);
    let index = rng_scramble(i, key);
    var out: vec3<u32>;
    for (var d = 0u; d < 3u; d++) {
        out[d] = rng_scramble(rng_sobol(index, d), rng_hash32(key ^ (d + 1u))) >> 8u;
    }
    return out;
}
