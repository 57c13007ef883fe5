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

impl TxSums {
    /// Nothing yet, for a profile of `setup`'s bins when `outputs` keep one.
    pub(super) fn new(setup: &Setup<'_>, outputs: Outputs) -> Self {
        TxSums {
            splats: Vec::new(),
            profile: vec![
                0.0;
                if outputs.profile {
                    setup.lay.n_bins * setup.ch
                } else {
                    0
                }
            ],
            total: vec![0.0; setup.ch],
        }
    }
}

/// The 2-bounce paths drawn from the transmitter's side for its rows `rows`: a point of
/// the transmitter's pixel (lit: the first surface along `-wi`), then [`add_tx_path`].
/// Monostatic, the receiver's pass draws them from its own points instead
/// ([`Setup::shares_points`]).
pub(super) fn render_tx_rows(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    rows: std::ops::Range<usize>,
    outputs: Outputs,
    counts: &Counts,
) -> TxSums {
    let w = setup.width;
    let mut out = TxSums::new(setup, outputs);
    let ext = setup.lay.ext;
    let wi = setup.wi;
    let seed = hash32(setup.sensor.paths.seed ^ TX_SALT);
    for row in rows {
        for col in 0..w {
            let pixel = (row * w + col) as u32;
            let n = counts.tx[pixel as usize] as usize;
            if n == 0 {
                continue;
            }
            let rng = PixelRng::new(seed, pixel);
            for i in 0..n {
                let (x, y) = setup.point_in_pixel(row, col, rng.set(i, 0));
                let o = x * setup.tx_u + y * setup.tx_v + 2.0 * ext * wi;
                let Some(v2) = posed.trace(o, -wi) else {
                    continue;
                };
                if dot(v2.n, wi) <= 0.0 || !posed.side_open(&v2) {
                    continue;
                }
                let Some(lobes) = lobes_toward(brdf, &v2, wi) else {
                    continue;
                };
                let u = rng.set(i, 1);
                add_tx_path(
                    setup, posed, brdf, counts, &v2, &lobes, u, n as f64, outputs, &mut out,
                );
            }
        }
    }
    out
}

/// One path of the transmitter's strategy from the lit surface `v2` (its shading normal
/// toward `wi`, its side open, `lobes` its lobes about `wi`), drawn as one of `n_tx` in its
/// pixel: a direction from the lobes (uniforms `u`: `[u1, u2, u_lobe]`), the surface it
/// meets, and that surface's connection to the receiver (it must see the receiver past the
/// mesh). Weighted by the balance heuristic against the receiver's strategy (module docs
/// of [`super`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn add_tx_path(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    counts: &Counts,
    v2: &Vertex,
    lobes: &Lobes,
    u: [f64; 3],
    n_tx: f64,
    outputs: Outputs,
    out: &mut TxSums,
) {
    let (w, ch) = (setup.width, setup.ch);
    let ext = setup.lay.ext;
    let (wi, wo) = (setup.wi, setup.wo);
    let c2 = dot(v2.n, wi);
    let [u1, u2, u_lobe] = u;
    let Some(w2) = sample(lobes, v2.n, wi, [u_lobe, u1, u2]) else {
        return;
    };
    let p2 = pdf(lobes, v2.n, wi, w2);
    if dot(w2, v2.ng) <= 0.0 || p2 <= 0.0 || p2.is_nan() {
        return;
    }
    let Some(v1) = posed.trace(v2.p + posed.eps * v2.ng, w2) else {
        return;
    };
    let w1 = -w2; // at the seen surface, toward the lit one
    if dot(v1.n, w1) <= 0.0 || !posed.sees(&v1, wo) {
        return;
    }
    // the image pixel it is seen in
    let (pc, pr) = (
        ((v1.p.x + ext) / setup.pix).floor(),
        ((ext - v1.p.y) / setup.pix).floor(),
    );
    if !(pc >= 0.0 && pr >= 0.0 && pc < w as f64 && pr < w as f64) {
        return;
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
        return;
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
