//! A small, seedable, splittable random number generator for the reference (no external
//! crate): xoshiro256++ (Blackman and Vigna 2019) seeded through SplitMix64, with
//! independent streams derived by hashing `(seed, stream ids)`.

/// SplitMix64 step (Steele, Lea and Flood 2014): a bijective 64-bit mixer.
#[inline]
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// xoshiro256++.
#[derive(Debug, Clone)]
pub struct Rng {
    s: [u64; 4],
}

impl Rng {
    /// A generator for stream `ids` of `seed`: different `(seed, ids)` give streams that
    /// are independent for every practical purpose (distinct SplitMix64 seeds).
    pub fn new(seed: u64, ids: &[u64]) -> Self {
        let mut h = seed ^ 0x6A09_E667_F3BC_C909;
        let mut key = splitmix64(&mut h);
        for &id in ids {
            let mut t = key ^ id.wrapping_mul(0xD1B5_4A32_D192_ED03);
            key = splitmix64(&mut t) ^ splitmix64(&mut t).rotate_left(17);
        }
        let mut st = key;
        let s = [
            splitmix64(&mut st),
            splitmix64(&mut st),
            splitmix64(&mut st),
            splitmix64(&mut st),
        ];
        Rng { s }
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.s;
        let result = (s[0].wrapping_add(s[3])).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// A pair of independent standard normal deviates (Box-Muller; `1 - u` keeps the
    /// logarithm finite).
    #[inline]
    pub fn normal_pair(&mut self) -> (f64, f64) {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        (r * c, r * s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<u64> = (0..4).map(|_| Rng::new(7, &[1, 2]).next_u64()).collect();
        assert!(a.iter().all(|&x| x == a[0]));
        let b = Rng::new(7, &[2, 1]).next_u64();
        let c = Rng::new(8, &[1, 2]).next_u64();
        assert!(a[0] != b && a[0] != c && b != c);
    }

    #[test]
    fn moments_of_uniform_and_normal() {
        let mut r = Rng::new(1, &[]);
        let n = 200_000;
        let (mut su, mut sn, mut sn2, mut sn4) = (0.0, 0.0, 0.0, 0.0);
        for _ in 0..n {
            su += r.uniform();
            let (a, b) = r.normal_pair();
            for x in [a, b] {
                sn += x;
                sn2 += x * x;
                sn4 += x * x * x * x;
            }
        }
        let nf = n as f64;
        assert!((su / nf - 0.5).abs() < 0.003);
        assert!((sn / (2.0 * nf)).abs() < 0.01);
        assert!((sn2 / (2.0 * nf) - 1.0).abs() < 0.01);
        assert!((sn4 / (2.0 * nf) - 3.0).abs() < 0.06);
    }
}
