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
    /// The profile's second moment per bin ([`crate::render::Rendered::area_moment`]).
    moment: Vec<f64>,
    /// The pixel's area `delta^2` (m^2).
    pix2: f64,
    tot: Vec<f64>,
    /// Scratch: one part's pulse weights per range bin, and a point's (area moment).
    weights: Vec<f64>,
    point: Vec<f64>,
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
            moment: vec![0.0; if area(sensor, outputs) { nb } else { 0 }],
            pix2: lay.pix * lay.pix,
            tot: vec![0.0; ch],
            weights: vec![0.0; nb],
            point: vec![0.0; if area(sensor, outputs) { nb } else { 0 }],
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
            if !self.moment.is_empty() && vals[0] > 0.0 {
                self.add_moment(s.range, a, b, vals[0] * vals[0] / (frac * self.pix2), edges);
            }
        }
    }

    /// Add a part's area moment: `e = I^2 / a` ([`crate::render::Rendered::area_moment`])
    /// times the mean over its footprint of the squared pointwise pulse weight of each bin
    /// (not the square of the mean, the profile's weight: that would count a part that
    /// spans bins as one uniformly lit source in each). The mean by the two-point rule that
    /// matches the footprint's mean and variance (`r0 +- d`, `d^2 = (a^2 + b^2) / 12` for
    /// the trapezoid of widths `a` and `b`), exact to third order in `d`; as the kernel
    /// does, for the Gaussian pulse on the footprint's bins with the tails folded into the
    /// end ones.
    fn add_moment(&mut self, r0: f64, a: f64, b: f64, e: f64, edges: &[f64]) {
        let d = ((a * a + b * b) / 12.0).sqrt();
        let half_w = self.support + 0.5 * (a + b);
        for off in [d, -d] {
            let point = &mut self.point;
            match &self.sensor.pulse {
                Some(p) => p.bin_weights(r0 + off, 0.0, 0.0, edges, point),
                None => {
                    point.iter_mut().for_each(|w| *w = 0.0);
                    let sigma = self.sensor.sigma_range;
                    pulse::folded_weights(
                        r0,
                        half_w,
                        edges,
                        |x| pulse::cdf_gauss_box2(x - off, sigma, 0.0, 0.0),
                        |k, w| point[k] = w,
                    );
                }
            }
            for (m, &wt) in self.moment.iter_mut().zip(point.iter()) {
                *m += 0.5 * wt * wt * e;
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
            for (x, y) in a.moment.iter_mut().zip(&b.moment) {
                *x += y;
            }
            for (x, y) in a.tot.iter_mut().zip(&b.tot) {
                *x += y;
            }
        }
        a
    }

    /// One attitude's outputs `(image, range, profile, total, coverage, area moment)`.
    #[allow(clippy::type_complexity)]
    pub(super) fn into_outputs(
        self,
    ) -> (Vec<f32>, Vec<f32>, Vec<f64>, Vec<f64>, Vec<f32>, Vec<f64>) {
        (
            self.img,
            self.rng,
            self.prof,
            self.tot,
            self.cov,
            self.moment,
        )
    }
}

/// Whether a render accumulates the area moment: asked for, with the profile.
pub(super) fn area(sensor: &SensorSetup, outputs: Outputs) -> bool {
    sensor.illuminated_area && outputs.profile
}
