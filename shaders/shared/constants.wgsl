// Constants of the shade kernel. Those that mirror a Rust constant (MAX_PARTS,
// HEADER_WORDS, SHADER_PART, MAX_SAMPLES: crate::render::gpu; PI) are compared with it by
// the test `wgsl_constants_equal_the_rust_ones` in src/render/shaders.rs.

const PI: f32 = 3.14159265358979;
const MAX_PARTS: u32 = 3u;
const HEADER_WORDS: u32 = 12u;
const SHADER_PART: u32 = 0xffffffffu;
// Visibility samples per pixel at most (the size of Params.offsets; gpu::MAX_SAMPLES).
const MAX_SAMPLES: u32 = 16u;
// ln M00 below which exp leaves f32's normal range (WGSL only).
const LN_FLOOR_F32: f32 = -87.0;
