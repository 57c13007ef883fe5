//! The paths' random numbers: shuffled, Owen-scrambled Sobol' points keyed by the seed and
//! the pixel ([`PixelRng`]; module docs of [`super`]).

/// A 32-bit hash (the PCG output permutation of Jarzynski and Olano 2020).
#[inline]
pub fn hash32(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// Dimensions of a path's random numbers ([`uniforms`]): the point in the pixel (0, 1), the
/// direction at the first surface (2, 3), at the second (4, 5), and the lobes chosen there
/// (6, 7).
pub const DIMS: usize = 8;

/// Sobol' direction numbers of the first four dimensions (Joe and Kuo's primitive
/// polynomials and initial numbers: `x`, then `s = 1, 2, 3` with `a = 0, 1, 1` and
/// `m = [1], [1, 3], [1, 3, 1]`), 32 bits (the paths use the first three).
pub(super) fn sobol_directions() -> &'static [[u32; 32]; 4] {
    static V: std::sync::OnceLock<[[u32; 32]; 4]> = std::sync::OnceLock::new();
    V.get_or_init(|| {
        let mut v = [[0u32; 32]; 4];
        for (k, x) in v[0].iter_mut().enumerate() {
            *x = 1u32 << (31 - k);
        }
        let polys: [(usize, u32, &[u32]); 3] = [(1, 0, &[1]), (2, 1, &[1, 3]), (3, 1, &[1, 3, 1])];
        for (d, &(deg, a, m)) in polys.iter().enumerate() {
            let vd = &mut v[d + 1];
            for k in 0..deg {
                vd[k] = m[k] << (31 - k);
            }
            for k in deg..32 {
                let mut x = vd[k - deg] ^ (vd[k - deg] >> deg);
                for j in 1..deg {
                    if (a >> (deg - 1 - j)) & 1 == 1 {
                        x ^= vd[k - j];
                    }
                }
                vd[k] = x;
            }
        }
        v
    })
}

/// Point `index` of Sobol's sequence in dimension `dim` (< 4), as 32 bits: the XOR of the
/// direction numbers of `index`'s set bits, read a byte of `index` at a time from tables
/// of those XORs ([`sobol_bytes`]; the paths draw 3 dimensions per set for every path, and
/// a loop over the bits took a tenth of a 3-bounce render). Dimension 0 is the van der
/// Corput sequence, `index` with its bits reversed.
#[inline]
pub(super) fn sobol(index: u32, dim: usize) -> u32 {
    if dim == 0 {
        return index.reverse_bits();
    }
    let t = &sobol_bytes()[dim];
    let b = index.to_le_bytes();
    t[0][b[0] as usize] ^ t[1][b[1] as usize] ^ t[2][b[2] as usize] ^ t[3][b[3] as usize]
}

/// Per dimension and byte `k` of the index, the XOR of the direction numbers of each byte
/// value's set bits (bits `8 k .. 8 k + 7` of the index).
fn sobol_bytes() -> &'static [[[u32; 256]; 4]; 4] {
    static T: std::sync::OnceLock<Box<[[[u32; 256]; 4]; 4]>> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        let v = sobol_directions();
        let mut t = Box::new([[[0u32; 256]; 4]; 4]);
        for (d, td) in t.iter_mut().enumerate() {
            for (k, tk) in td.iter_mut().enumerate() {
                for (byte, x) in tk.iter_mut().enumerate() {
                    *x = (0..8)
                        .filter(|b| byte >> b & 1 == 1)
                        .fold(0, |acc, b| acc ^ v[d][8 * k + b]);
                }
            }
        }
        t
    })
}

/// Laine and Karras's hash-based Owen scrambling, on bit-reversed values (each output bit
/// depends on the bits below it only), with Burley's 2020 constants.
pub(super) fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    let mut x = x.reverse_bits();
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x.reverse_bits()
}

/// The random numbers of one pixel's paths: three independent shuffled, Owen-scrambled
/// Sobol' sequences (Burley 2020), keyed by hashes of `(seed, pixel, set)`, one per pair of
/// dimensions that draws a point or a direction (its Sobol' dimensions 0 and 1, a (0,
/// 2)-sequence: the first `2^m` paths fill every one of `2^m` elementary cells of the
/// square), the lobe choice from dimension 2 of the direction's set. 24 bits each (as an
/// f32). Sets: 0 the point in the pixel, 1 and 2 the directions at the first and second
/// surface.
#[derive(Debug, Clone, Copy)]
pub struct PixelRng {
    pub(super) base: u32,
    /// The scrambling keys of sets `0..CACHED_SETS` ([`set_keys`]), hashed once per pixel.
    keys: [[u32; 4]; CACHED_SETS],
}

/// Sets whose keys a [`PixelRng`] holds (the paths use sets 0 to 3).
const CACHED_SETS: usize = 4;

/// The keys of set `set` of the pixel whose base is `base`: the index's scramble, then each
/// dimension's.
#[inline]
fn set_keys(base: u32, set: u32) -> [u32; 4] {
    let key = hash32(base ^ set);
    [key, hash32(key ^ 1), hash32(key ^ 2), hash32(key ^ 3)]
}

impl PixelRng {
    pub fn new(seed: u32, pixel: u32) -> Self {
        let base = hash32(hash32(seed) ^ pixel);
        PixelRng {
            base,
            keys: std::array::from_fn(|s| set_keys(base, s as u32)),
        }
    }

    /// Dimensions 0, 1, 2 of set `set` for path `i`.
    #[inline]
    pub fn set(&self, i: usize, set: u32) -> [f64; 3] {
        let keys = match self.keys.get(set as usize) {
            Some(k) => *k,
            None => set_keys(self.base, set),
        };
        let index = nested_uniform_scramble(i as u32, keys[0]);
        std::array::from_fn(|d| {
            let x = nested_uniform_scramble(sobol(index, d), keys[d + 1]);
            (x >> 8) as f64 / 16_777_216.0
        })
    }
}

/// All of path `i`'s numbers ([`PixelRng`]) in the order of [`DIMS`].
pub fn uniforms(seed: u32, pixel: u32, i: usize) -> [f64; DIMS] {
    let rng = PixelRng::new(seed, pixel);
    let [a, b, c] = [0, 1, 2].map(|set| rng.set(i, set));
    [a[0], a[1], b[0], b[1], c[0], c[1], b[2], c[2]]
}
