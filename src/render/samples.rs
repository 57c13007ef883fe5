//! The visibility samples of a pixel, shared by every backend: where the `K` samples lie
//! ([`sample_offsets`]) and, with `K >= 4`, which pass and sample of the GPU's 4x
//! multisampled raster draws each ([`msaa_samples`], `raster_displacements`). The CPU
//! renderers cast rays through the same points. Conventions: [`crate::render`].

/// Most visibility samples per pixel ([`crate::render::SensorSetup::samples`]).
pub const MAX_SAMPLES: usize = 16;

/// The `k` visibility samples of a pixel, `(u, v)` in pixel units from its top-left corner
/// (`u` along `+X`, `v` down the rows). Each row and each column of the `k x k` grid holds
/// one sample ("n-rooks": an axis-aligned edge is resolved to `1/k` of a pixel), and for
/// `k != 8` they form a (0, m, 2)-net: every box `[a/2^i, (a+1)/2^i) x [b/2^j, (b+1)/2^j)`
/// with `i + j = m` holds exactly one (for `k = 4, 16` one per cell of the `sqrt(k)` grid;
/// `k = 8`: two per quadrant). The set is symmetric under a half turn about the pixel
/// centre, so their mean is the centre. `k = 1` is the centre itself, `k = 2` the first
/// two points of the Sobol' sequence shifted by `1/4`; `k >= 4` are the rasterizer's
/// standard 4x multisample positions, shifted per raster pass and wrapped into the pixel
/// ([`msaa_samples`]).
pub fn sample_offsets(k: usize) -> Vec<[f64; 2]> {
    assert!(k.is_power_of_two() && k <= MAX_SAMPLES);
    match k {
        1 => vec![[0.5, 0.5]],
        2 => vec![[0.25, 0.25], [0.75, 0.75]],
        _ => msaa_samples(k).iter().map(|s| s.uv).collect(),
    }
}

/// Samples per texel of the multisampled visibility raster (`K >= 4`).
pub const MSAA: usize = 4;

/// The standard 4x multisample positions in a texel, `(u, v)` from its top-left corner
/// (WebGPU's, Vulkan's `standardSampleLocations`, Direct3D's and Metal's).
const MSAA_POSITIONS: [[i32; 2]; MSAA] = [[6, 2], [14, 6], [2, 10], [10, 14]]; // / 16

/// Per raster pass, the shift of the sample positions in units of `1 / (2k)` pixel for
/// `k = 8, 16` (`k = 4`: one pass, none), found by exhaustive search over odd shifts: the
/// `k` (wrapped) positions are symmetric under a half turn about the pixel centre (so a
/// render is invariant under a half turn about the line of sight, as the scene is) and
/// form a (0, m, 2)-net. For `k = 8` no symmetric net exists among these; of the
/// symmetric ones with one sample per row and column and two per quadrant, these shifts put
/// two samples in the fewest of the 16 `2 x 4` and `4 x 2` boxes (4), then wrap the fewest.
const MSAA_SHIFTS_8: [[i32; 2]; 2] = [[-3, -1], [3, 1]];
const MSAA_SHIFTS_16: [[i32; 2]; 4] = [[-13, -7], [-1, 5], [1, -5], [13, 7]];

/// Where visibility sample `k` of a pixel comes from with `K >= 4`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MsaaSample {
    /// Its position in the pixel, `(u, v)` from the top-left corner.
    pub uv: [f64; 2],
    /// The raster pass (tile of the GPU's multisampled target, `gpu::passes::MsaaTiles`)
    /// and the sample index in the texel.
    pub pass: usize,
    pub sample: usize,
    /// The texel that holds it, `(column, row)` relative to the pixel's: pass `p` moves
    /// the image by `-shift_p`, so its sample `s` in texel `t` sees the point
    /// `t + position_s + shift_p`, which lies in a neighbouring pixel when
    /// `position_s + shift_p` leaves `[0, 1)`.
    pub texel: [i32; 2],
}

/// The `k >= 4` visibility samples in order `k = MSAA pass + sample`.
pub fn msaa_samples(k: usize) -> Vec<MsaaSample> {
    let shifts: &[[i32; 2]] = match k {
        4 => &[[0, 0]],
        8 => &MSAA_SHIFTS_8,
        16 => &MSAA_SHIFTS_16,
        _ => panic!("msaa_samples: K = {k} (4, 8 or 16)"),
    };
    let units = 2 * k as i32; // per pixel
    let mut out = Vec::with_capacity(k);
    for (pass, sh) in shifts.iter().enumerate() {
        for (sample, pos) in MSAA_POSITIONS.iter().enumerate() {
            let a = [0, 1].map(|i| pos[i] * units / 16 + sh[i]);
            out.push(MsaaSample {
                uv: a.map(|x| x.rem_euclid(units) as f64 / units as f64),
                pass,
                sample,
                texel: a.map(|x| -x.div_euclid(units)),
            });
        }
    }
    out
}

/// The raster passes of `k` samples: per pass, the displacement `(du, dv)` (pixels, `v`
/// down) that brings its sample points where the rasterizer samples: `K < 4`, one pass per
/// sample, moved onto the texel centre; `K >= 4`, one multisampled pass per [`MSAA`]
/// samples, moved by minus its shift.
pub(crate) fn raster_displacements(k: usize) -> Vec<[f64; 2]> {
    if k < MSAA {
        return sample_offsets(k)
            .iter()
            .map(|o| [0.5 - o[0], 0.5 - o[1]])
            .collect();
    }
    msaa_samples(k)
        .chunks(MSAA)
        .map(|c| {
            let o = &c[0];
            let p = MSAA_POSITIONS[o.sample];
            // minus the shift: position - (uv - texel)
            [0, 1].map(|i| p[i] as f64 / 16.0 - o.uv[i] + o.texel[i] as f64)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The samples form a (0, m, 2)-net (K = 8: n-rooks and two per quadrant): every
    /// elementary box of area 1/K holds exactly one (so each row and column of the K x K
    /// grid holds one); the set is symmetric under a half turn about the centre; and with
    /// K >= 4 sample `k` is where the multisampled raster puts it: the standard position
    /// of its sample index, moved by its pass's shift, in the texel it is read from.
    #[test]
    fn sample_offsets_form_a_net() {
        assert_eq!(sample_offsets(1), vec![[0.5, 0.5]]);
        for k in [2usize, 4, 8, 16] {
            let s = sample_offsets(k);
            let m = k.trailing_zeros();
            let count = |nx: usize, ny: usize| {
                let mut count = vec![0; nx * ny];
                for p in &s {
                    assert!((0.0..1.0).contains(&p[0]) && (0.0..1.0).contains(&p[1]));
                    let (a, b) = ((p[0] * nx as f64) as usize, (p[1] * ny as f64) as usize);
                    count[a * ny + b] += 1;
                }
                count
            };
            for i in 0..=m {
                let (nx, ny) = (1usize << i, 1usize << (m - i));
                if k == 8 && i != 0 && i != m {
                    continue;
                }
                let c = count(nx, ny);
                assert!(c.iter().all(|&c| c == 1), "k {k}: {nx} x {ny} boxes {c:?}");
            }
            if k == 8 {
                assert_eq!(count(2, 2), vec![2; 4]);
                let doubled: usize = [(2, 4), (4, 2)]
                    .iter()
                    .map(|&(nx, ny)| count(nx, ny).iter().filter(|&&c| c == 2).count())
                    .sum();
                assert_eq!(doubled, 4);
            }
            for p in &s {
                let q = [1.0 - p[0], 1.0 - p[1]];
                assert!(s.contains(&q), "k {k}: {p:?} without its mirror image");
            }
        }
        for k in [4usize, 8, 16] {
            let d = raster_displacements(k);
            assert_eq!(d.len(), k / MSAA);
            for (i, o) in msaa_samples(k).iter().enumerate() {
                assert_eq!((o.pass, o.sample), (i / MSAA, i % MSAA));
                // the raster sample s of texel t sees t + position_s - displacement_p,
                // which must be the pixel's point for t = the pixel's + texel
                let pos = MSAA_POSITIONS[o.sample];
                for a in 0..2 {
                    let seen = o.texel[a] as f64 + pos[a] as f64 / 16.0 - d[o.pass][a];
                    assert!(
                        (seen - o.uv[a]).abs() < 1e-12,
                        "k {k} sample {i}: {seen} {o:?}"
                    );
                }
                assert!(o.texel.iter().all(|t| t.abs() <= 1));
            }
        }
    }
}
