//! The paths drawn from the receiver's side: a point of the pixel, directions from each
//! surface's lobes, next-event estimation toward the transmitter ([`render_rows`]).
//!
//! Monostatic, the transmitter's view, pixels and counts are the receiver's, and so is the
//! first surface through a point of a pixel: the transmitter's strategy then starts its
//! paths from the receiver's points ([`Setup::shares_points`]; their surfaces and lobes
//! found once), each with its own direction (its own random numbers, as in its own pass).

use super::*;

/// The paths of the pixels `rows` of one attitude (`counts.rx` per pixel): their image
/// rows, profile and totals; monostatic, also the transmitter's strategy's paths from the
/// same points (module docs).
// (the loop over orders indexes the pixel's sums and also picks the random numbers and the
// strategies by order)
#[allow(clippy::needless_range_loop)]
pub(super) fn render_rows(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    rows: std::ops::Range<usize>,
    outputs: Outputs,
    counts: &Counts,
    mirrors: &Mirrors,
) -> (PathSums, TxSums) {
    let (w, ch, orders) = (setup.width, setup.ch, setup.orders);
    let mut out = setup.zero_sums(outputs, rows.len());
    let mut tx_out = TxSums::new(setup, outputs);
    let shared = setup.shares_points();
    let tx_seed = hash32(setup.sensor.paths.seed ^ TX_SALT);
    let ext = setup.lay.ext;
    let (wi, wo) = (setup.wi, setup.wo);
    let mut mirror_cdf: Vec<f64> = Vec::with_capacity(mirrors.list.len());
    for row in rows.clone() {
        for col in 0..w {
            let pixel = (row * w + col) as u32;
            let mut px = vec![[0.0f64; 16]; orders];
            let rng = PixelRng::new(setup.sensor.paths.seed, pixel);
            let tx_rng = PixelRng::new(tx_seed, pixel);
            let n = counts.rx[pixel as usize] as usize;
            let n_rx = n as f64;
            let weight = setup.area / n_rx;
            for i in 0..n {
                let (x, y) = setup.point_in_pixel(row, col, rng.set(i, 0));
                let Some(v1) = posed.trace(V3::new(x, y, 2.0 * ext), -V3::Z) else {
                    continue;
                };
                if dot(v1.ng, wo) <= 0.0 || dot(v1.n, wo) <= 0.0 {
                    continue;
                }
                // the throughput from the beam arriving at the current surface (in basis
                // `x_t`) to the receiver (in `x_out1`), and the path's length so far from
                // the current surface to the receiver's plane
                let mut t = [[0.0; 4]; 4];
                for (k, row) in t.iter_mut().enumerate() {
                    row[k] = 1.0;
                }
                let mut x_t = V3::ZERO;
                let mut x_out1 = V3::ZERO;
                let mut length = -dot(v1.p, wo);
                let (mut v, mut w_out) = (v1, wo);
                let (mut t_next, mut x_t_next, mut length_next) = (t, x_t, length);
                let mut v_next: Option<(Vertex, V3)> = None;
                for order in 0..orders {
                    if !posed.side_open(&v) {
                        break;
                    }
                    // draw the direction toward the next surface at `v`
                    let Some(lobes) = lobes_toward(brdf, &v, w_out) else {
                        break;
                    };
                    if order == 0 && shared {
                        // the transmitter's path from this point (lit, as it is seen)
                        let (u, n_tx) = (tx_rng.set(i, 1), counts.tx[pixel as usize] as f64);
                        add_tx_path(
                            setup,
                            posed,
                            brdf,
                            counts,
                            &v,
                            &lobes,
                            u,
                            n_tx,
                            outputs,
                            &mut tx_out,
                        );
                    }
                    // The third bounce (order 1, the last: at most 3 bounces) is drawn
                    // `third_draws` times from this second surface, each draw from a copy of
                    // the path's state and with its share of the path (module docs of
                    // `super`). After the first surface's one draw, its state is where the
                    // path goes on from (`v_next`).
                    let split = if order == 1 && order + 1 == orders {
                        setup.third_draws
                    } else {
                        1
                    };
                    let base_weight = weight;
                    // the mirrors that may light `v`, for the aimed 3-bounce paths
                    // (none: `mirror_cdf` empty, no aimed path and no aiming density)
                    let aimable = order == 1 && mirrors.choose_from(&v, &mut mirror_cdf);
                    for k in 0..split {
                        let weight = base_weight / split as f64;
                        let j = i * split + k;
                        let (mut t, mut x_t, mut length) = (t, x_t, length);
                        'draw: {
                            if aimable {
                                // a 3-bounce path aimed from `v` at a mirror of the transmitter
                                let aimed = aim(
                                    setup,
                                    posed,
                                    brdf,
                                    mirrors,
                                    &v,
                                    w_out,
                                    &lobes,
                                    &mirror_cdf,
                                    rng.set(j, 3),
                                );
                                if let Some(((m, x_m), x_in, r3)) = aimed {
                                    let m = chain(&t, x_t, &m, x_m, w_out);
                                    let prof = setup.order_profile(&mut out.profile, order);
                                    let r = 0.5 * (length + r3);
                                    setup.add_path(
                                        &mut px[order],
                                        prof,
                                        &m,
                                        x_in,
                                        x_out1,
                                        r,
                                        weight,
                                    );
                                }
                            }
                            let [u1, u2, u_lobe] = rng.set(j, 1 + order as u32);
                            let Some(w_next) = sample(&lobes, v.n, w_out, [u_lobe, u1, u2]) else {
                                break 'draw;
                            };
                            if dot(w_next, v.ng) <= 0.0 {
                                break 'draw;
                            }
                            let p = pdf(&lobes, v.n, w_out, w_next);
                            if p <= 0.0 || p.is_nan() {
                                break 'draw;
                            }
                            // (traced first: most paths leave the mesh here, and cost no BRDF)
                            let Some(next) = posed.trace(v.p + posed.eps * v.ng, w_next) else {
                                break 'draw;
                            };
                            // next-event: `next` lit by the transmitter, seen from `v` along -w_next
                            let back = -w_next;
                            let drawn = order > 0 || setup.strategies.receiver;
                            let facing = dot(next.n, back) > 0.0;
                            let lit = drawn && facing && posed.sees(&next, wi);
                            if order + 1 == orders && !lit {
                                // (the last order: nothing more from this path, nor its BRDF)
                                break 'draw;
                            }
                            let f = brdf.eval(v.mat, v.n, w_next, w_out);
                            let fm = scale(&f.m, dot(v.n, w_next) / p);
                            if order == 0 {
                                t = fm;
                                x_out1 = f.x_out;
                            } else {
                                // the beam v -> previous surface: in f's output basis, into t's input
                                t = chain(&t, x_t, &fm, f.x_out, w_out);
                            }
                            x_t = f.x_in;
                            length += dot(next.p - v.p, next.p - v.p).sqrt();
                            if lit {
                                let g = brdf.eval(next.mat, next.n, wi, back);
                                let ci = dot(next.n, wi);
                                // a 2-bounce path is also drawn from the transmitter's side
                                let mis = if order == 0 && setup.strategies.transmitter {
                                    let a =
                                        n_rx * dot(v.ng, wo).abs() * p * dot(next.ng, back).abs();
                                    let b = counts.tx_at(setup, next.p)
                                        * lobe_density(brdf, &next, wi, back)
                                        * dot(v.ng, w_next).abs();
                                    if a > 0.0 {
                                        a / (a + b)
                                    } else {
                                        0.0
                                    }
                                } else if order == 1 && setup.strategies.aim {
                                    // a 3-bounce path is also aimed at a mirror from `v`
                                    let b = mirrors.density(&mirror_cdf, &next, w_next, wi);
                                    p / (p + b)
                                } else {
                                    1.0
                                };
                                let gm = scale(&scale(&g.m, ci), mis);
                                let m = chain(&t, x_t, &gm, g.x_out, back);
                                let prof = setup.order_profile(&mut out.profile, order);
                                let r = 0.5 * (length - dot(next.p, wi));
                                setup.add_path(&mut px[order], prof, &m, g.x_in, x_out1, r, weight);
                            }
                            if !facing {
                                break 'draw;
                            }
                            if order + 1 < orders {
                                (t_next, x_t_next, length_next) = (t, x_t, length);
                                v_next = Some((next, back));
                            }
                        }
                    }
                    let Some((nv, nw)) = v_next.take() else {
                        break;
                    };
                    (t, x_t, length) = (t_next, x_t_next, length_next);
                    v = nv;
                    w_out = nw;
                }
            }
            for (order, vals) in px.iter().enumerate() {
                for (c, &v) in vals.iter().enumerate().take(ch) {
                    out.total[order * ch + c] += v;
                    if outputs.image {
                        let k = ((order * rows.len() + (row - rows.start)) * w + col) * ch + c;
                        out.image[k] = v;
                    }
                }
            }
        }
    }
    (out, tx_out)
}
