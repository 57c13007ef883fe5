//! Supersampled images to the sensor's pixels, the same for every backend: the GPU's
//! readback and the CPU renderers' `render_supersampled` reduce `ss x ss` sub-pixels with
//! these.

/// Sum `ss x ss` sub-pixels into each output pixel.
pub(crate) fn downsample_sum(v: &[f32], m: usize, w: usize, ss: usize, ch: usize, out: &mut [f32]) {
    let res = w / ss;
    for a in 0..m {
        for i in 0..res {
            for j in 0..res {
                let o = ((a * res + i) * res + j) * ch;
                for c in 0..ch {
                    out[o + c] = 0.0;
                }
                for di in 0..ss {
                    for dj in 0..ss {
                        let s = ((a * w + i * ss + di) * w + j * ss + dj) * ch;
                        for c in 0..ch {
                            out[o + c] += v[s + c];
                        }
                    }
                }
            }
        }
    }
}

/// Range: mean over the sub-pixels weighted by their covered fractions `c` (NaN if none
/// is covered); coverage: the sub-pixels' mean covered fraction.
pub(crate) fn downsample_range(
    v: &[f32],
    c: &[f32],
    m: usize,
    w: usize,
    ss: usize,
    out: &mut [f32],
    cov: &mut [f32],
) {
    let res = w / ss;
    for a in 0..m {
        for i in 0..res {
            for j in 0..res {
                let (mut s, mut k) = (0.0f64, 0.0f64);
                for di in 0..ss {
                    for dj in 0..ss {
                        let q = (a * w + i * ss + di) * w + j * ss + dj;
                        if !v[q].is_nan() && c[q] > 0.0 {
                            s += c[q] as f64 * v[q] as f64;
                            k += c[q] as f64;
                        }
                    }
                }
                let o = (a * res + i) * res + j;
                out[o] = if k > 0.0 { (s / k) as f32 } else { f32::NAN };
                cov[o] = (k / (ss * ss) as f64) as f32;
            }
        }
    }
}
