//! The 2-bounce paths drawn from the transmitter's side and connected to the receiver
//! ([`render_tx_rows`]).

use super::*;

/// What the transmitter strategy adds for a block of the transmitter's rows: the pixels it
/// lands in with their values (in drawing order), the profile and the totals of the
/// 2-bounce order.
pub(super) struct TxSums {
    pub(super) splats: Vec<(usize, [f64; 16])>,
    pub(super) profile: Vec<f64>,
    pub(super) total: Vec<f64>,
}

/// The salt of the transmitter strategy's seed.
pub(super) const TX_SALT: u32 = 0x5bd1_e995;

/// The 2-bounce paths drawn from the transmitter's side for its rows `rows`: a point of
/// the transmitter's pixel (lit: the first surface along `-wi`), a direction from that
/// surface's lobes toward `wi`'s reflection, the surface it meets, and that surface's
/// connection to the receiver (it must see the receiver past the mesh). Weighted by the
/// balance heuristic against the receiver's strategy (module docs).
pub(super) fn render_tx_rows(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    rows: std::ops::Range<usize>,
    outputs: Outputs,
    counts: &Counts,
) -> TxSums {
    let (w, ch, nb) = (setup.width, setup.ch, setup.lay.n_bins);
    let mut out = TxSums {
        splats: Vec::new(),
        profile: vec![0.0; if outputs.profile { nb * ch } else { 0 }],
        total: vec![0.0; ch],
    };
    let ext = setup.lay.ext;
    let (wi, wo) = (setup.wi, setup.wo);
    let seed = hash32(setup.sensor.paths.seed ^ TX_SALT);
    for row in rows {
        for col in 0..w {
            let pixel = (row * w + col) as u32;
            let n = counts.tx[pixel as usize] as usize;
            if n == 0 {
                continue;
            }
            let n_tx = n as f64;
            let rng = PixelRng::new(seed, pixel);
            for i in 0..n {
                let (x, y) = setup.point_in_pixel(row, col, rng.set(i, 0));
                let o = x * setup.tx_u + y * setup.tx_v + 2.0 * ext * wi;
                let Some(v2) = posed.trace(o, -wi) else {
                    continue;
                };
                let c2 = dot(v2.n, wi);
                if c2 <= 0.0 || !posed.side_open(&v2) {
                    continue;
                }
                let Some(lobes) = lobes_toward(brdf, &v2, wi) else {
                    continue;
                };
                let [u1, u2, u_lobe] = rng.set(i, 1);
                let Some(w2) = sample(&lobes, v2.n, wi, [u_lobe, u1, u2]) else {
                    continue;
                };
                let p2 = pdf(&lobes, v2.n, wi, w2);
                if dot(w2, v2.ng) <= 0.0 || p2 <= 0.0 || p2.is_nan() {
                    continue;
                }
                let Some(v1) = posed.trace(v2.p + posed.eps * v2.ng, w2) else {
                    continue;
                };
                let w1 = -w2; // at the seen surface, toward the lit one
                if dot(v1.n, w1) <= 0.0 || !posed.sees(&v1, wo) {
                    continue;
                }
                // the image pixel it is seen in
                let (pc, pr) = (
                    ((v1.p.x + ext) / setup.pix).floor(),
                    ((ext - v1.p.y) / setup.pix).floor(),
                );
                if !(pc >= 0.0 && pr >= 0.0 && pc < w as f64 && pr < w as f64) {
                    continue;
                }
                let b = n_tx * dot(v2.ng, wi).abs() * p2 * dot(v1.ng, w1).abs();
                let mis = if setup.strategies.receiver {
                    let n_rx = counts.rx_at(pr as usize * w + pc as usize);
                    let a = n_rx * lobe_density(brdf, &v1, wo, w1) * dot(v2.ng, w2).abs();
                    b / (a + b)
                } else {
                    1.0
                };
                // f1 (w1 -> wo) L f2 (wi -> w2), the beam v2 -> v1 propagating along w2
                let f2 = brdf.eval(v2.mat, v2.n, wi, w2);
                let f1 = brdf.eval(v1.mat, v1.n, w1, wo);
                let m = chain(&f1.m, f1.x_in, &f2.m, f2.x_out, w2);
                // (n2.wi)(n1.w1) |ng2.w2| |ng1.wo| / (|ng1.w1| |ng2.wi| pdf2)
                let g = c2 * dot(v1.n, w1) * dot(v2.ng, w2).abs() * dot(v1.ng, wo).abs()
                    / (dot(v1.ng, w1).abs() * dot(v2.ng, wi).abs() * p2);
                let weight = setup.area / n_tx;
                let vals = setup.channels(&m, f2.x_in, f1.x_out, weight * g * mis);
                if !vals.iter().all(|x| x.is_finite()) {
                    continue;
                }
                for (a, v) in out.total.iter_mut().zip(&vals) {
                    *a += v;
                }
                if outputs.profile {
                    let len = -dot(v2.p, wi) + (v1.p - v2.p).length() - dot(v1.p, wo);
                    setup.deposit(&mut out.profile, &vals[..ch], 0.5 * len);
                }
                if outputs.image {
                    out.splats.push((pr as usize * w + pc as usize, vals));
                }
            }
        }
    }
    out
}
