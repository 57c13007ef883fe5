//! One attitude's sums on the CPU: a pixel's parts added to its image values, range,
//! coverage and the profile's bins ([`Accumulator`]), for a block of rows at a time, the
//! blocks then joined in order.

use super::coverage::Part;
use super::shade::PixelSample;
use crate::render::api::{Layout, Outputs, SensorSetup};
use crate::render::pulse;
use std::ops::Range;

/// One pixel's sums over its parts: covered fraction, fraction-weighted range, values.
#[derive(Default)]
pub(super) struct PixelAcc {
    cov: f64,
    range: f64,
    values: [f64; 16],
}

/// One attitude's outputs, only those requested (a profile-only batch holds no images).
pub(super) struct Accumulator<'a> {
    sensor: &'a SensorSetup,
    outputs: Outputs,
    /// The first pixel's index: the images hold pixels `first..`.
    first: usize,
    ch: usize,
    support: f64,
    img: Vec<f32>,
    rng: Vec<f32>,
    cov: Vec<f32>,
    prof: Vec<f64>,
    tot: Vec<f64>,
    /// Scratch: one part's pulse weights per range bin.
    weights: Vec<f64>,
}

impl<'a> Accumulator<'a> {
    /// For the pixels `pixels` (row-major indices) of one attitude.
    pub(super) fn new(
        sensor: &'a SensorSetup,
        lay: &Layout,
        outputs: Outputs,
        pixels: Range<usize>,
    ) -> Self {
        let (n, ch, nb) = (pixels.len(), sensor.channels(), lay.n_bins);
        Accumulator {
            sensor,
            outputs,
            first: pixels.start,
            ch,
            support: lay.support,
            img: vec![0.0; if outputs.image { n * ch } else { 0 }],
            rng: vec![f32::NAN; if outputs.range { n } else { 0 }],
            cov: vec![0.0; if outputs.range { n } else { 0 }],
            prof: vec![0.0; if outputs.profile { nb * ch } else { 0 }],
            tot: vec![0.0; ch],
            weights: vec![0.0; nb],
        }
    }

    /// Add the shaded part `s` of a pixel to its sums `px` and its pulse to the profile.
    pub(super) fn add(&mut self, px: &mut PixelAcc, part: &Part, s: &PixelSample, edges: &[f64]) {
        let (ch, frac) = (self.ch, part.frac);
        px.cov += frac;
        px.range += frac * s.range;
        let vals = s.values.map(|v| frac * v);
        for (p, v) in px.values.iter_mut().zip(&vals).take(ch) {
            *p += v;
        }
        if self.outputs.profile && vals[0] != 0.0 {
            // the footprint of the part of the pixel it spans (whole: 1)
            let (a, b) = (part.span[0] * s.widths.0, part.span[1] * s.widths.1);
            let weights = &mut self.weights;
            match &self.sensor.pulse {
                Some(p) => p.bin_weights(s.range, a, b, edges, weights),
                None => pulse::bin_weights_folded(
                    s.range,
                    a,
                    b,
                    self.sensor.sigma_range,
                    self.support + 0.5 * (a + b),
                    edges,
                    weights,
                ),
            }
            for (bin, &wt) in self.prof.chunks_exact_mut(ch).zip(weights.iter()) {
                if wt != 0.0 {
                    for (p, v) in bin.iter_mut().zip(&vals) {
                        *p += wt * v;
                    }
                }
            }
        }
    }

    /// Write pixel `k`'s sums to the images and the totals.
    pub(super) fn finish(&mut self, k: usize, px: &PixelAcc) {
        let (ch, k) = (self.ch, k - self.first);
        if px.cov > 0.0 && self.outputs.range {
            self.rng[k] = (px.range / px.cov) as f32;
            self.cov[k] = px.cov as f32;
        }
        for c in 0..ch {
            if self.outputs.image {
                self.img[k * ch + c] = px.values[c] as f32;
            }
            self.tot[c] += px.values[c];
        }
    }

    /// The accumulator of consecutive pixel ranges from theirs, the sums added in their
    /// order.
    pub(super) fn concat(blocks: impl IntoIterator<Item = Self>) -> Self {
        let mut it = blocks.into_iter();
        let mut a = it.next().expect("at least one block");
        for b in it {
            a.img.extend(b.img);
            a.rng.extend(b.rng);
            a.cov.extend(b.cov);
            for (x, y) in a.prof.iter_mut().zip(&b.prof) {
                *x += y;
            }
            for (x, y) in a.tot.iter_mut().zip(&b.tot) {
                *x += y;
            }
        }
        a
    }

    /// One attitude's outputs `(image, range, profile, total, coverage)`.
    #[allow(clippy::type_complexity)]
    pub(super) fn into_outputs(self) -> (Vec<f32>, Vec<f32>, Vec<f64>, Vec<f64>, Vec<f32>) {
        (self.img, self.rng, self.prof, self.tot, self.cov)
    }
}
