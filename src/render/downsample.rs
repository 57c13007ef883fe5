//! Supersampled images to the sensor's pixels, the same for every backend: the GPU's
//! readback and the CPU renderers' `render_supersampled` reduce `ss x ss` sub-pixels with
//! these. Attitudes are reduced in parallel (rayon); each output pixel's sum runs in the
//! same order whatever the threads, so the results do not depend on them.

use rayon::prelude::*;

/// Sum `ss x ss` sub-pixels into each output pixel: `v` is (m, w, w, ch) sub-pixels, `out`
/// (at least m, w/ss, w/ss, ch) pixels.
pub(crate) fn downsample_sum(v: &[f32], m: usize, w: usize, ss: usize, ch: usize, out: &mut [f32]) {
    let res = w / ss;
    let (per_in, per_out) = (w * w * ch, res * res * ch);
    out[..m * per_out]
        .par_chunks_mut(per_out)
        .zip(v[..m * per_in].par_chunks(per_in))
        .for_each(|(out, v)| {
            if ss == 1 {
                // `0.0 + x` as the sum below does (it turns -0.0 into 0.0): bit for bit
                for (o, &x) in out.iter_mut().zip(v) {
                    *o = 0.0 + x;
                }
                return;
            }
            for i in 0..res {
                for j in 0..res {
                    let o = (i * res + j) * ch;
                    for c in 0..ch {
                        out[o + c] = 0.0;
                    }
                    for di in 0..ss {
                        for dj in 0..ss {
                            let s = ((i * ss + di) * w + j * ss + dj) * ch;
                            for c in 0..ch {
                                out[o + c] += v[s + c];
                            }
                        }
                    }
                }
            }
        });
}

/// Range: mean over the sub-pixels weighted by their covered fractions (NaN if none is
/// covered); coverage: the sub-pixels' mean covered fraction. Sub-pixel `q` has its range at
/// `v[q * stride]` and its covered fraction at `c[q * stride + offset]` (the GPU's words per
/// pixel, or separate arrays with stride 1 and offset 0).
#[allow(clippy::too_many_arguments)]
pub(crate) fn downsample_range(
    v: &[f32],
    c: &[f32],
    stride: usize,
    offset: usize,
    m: usize,
    w: usize,
    ss: usize,
    out: &mut [f32],
    cov: &mut [f32],
) {
    let res = w / ss;
    let per_in = w * w * stride;
    out[..m * res * res]
        .par_chunks_mut(res * res)
        .zip(cov[..m * res * res].par_chunks_mut(res * res))
        .zip(v[..m * per_in].par_chunks(per_in))
        .zip(c[..m * per_in].par_chunks(per_in))
        .for_each(|(((out, cov), v), c)| {
            for i in 0..res {
                for j in 0..res {
                    let (mut s, mut k) = (0.0f64, 0.0f64);
                    for di in 0..ss {
                        for dj in 0..ss {
                            let q = ((i * ss + di) * w + j * ss + dj) * stride;
                            let (r, f) = (v[q], c[q + offset]);
                            if !r.is_nan() && f > 0.0 {
                                s += f as f64 * r as f64;
                                k += f as f64;
                            }
                        }
                    }
                    let o = i * res + j;
                    out[o] = if k > 0.0 { (s / k) as f32 } else { f32::NAN };
                    cov[o] = (k / (ss * ss) as f64) as f32;
                }
            }
        });
}
