//! Where each strategy draws its paths and how many per pixel ([`Counts`]).
//!
//! A path can only start on a surface whose side toward the receiver (the receiver's
//! strategy) or the transmitter (the transmitter's) has some of the mesh in front of it
//! ([`open_sides`]); elsewhere it would leave the mesh at once. So each strategy draws only
//! in the pixels such faces may cover ([`covered_pixels`]), and the render's budget, `N`
//! paths for every pixel the mesh may cover, is shared evenly among those: `N M / M_open`
//! each (`M` pixels the mesh may cover, `M_open` of them with open faces), rounded to `N`
//! times a power of two. A satellite whose corners fill a few pixels then draws its paths
//! there (the CubeSat's antenna against its bus), with about the work of `N` paths per
//! pixel of the mesh. The power of two keeps a pixel's count, and so its random numbers,
//! the same while the attitude moves a little (a fit's steps), except where `M / M_open`
//! crosses a power of `sqrt(2)` between them (the Sobol' points are also best balanced at
//! powers of two). Each pixel's estimate is unbiased for any count: its `n` paths carry
//! `1 / n` of its area each, and the balance heuristic weighs a path by each strategy's
//! count where it was drawn (a strategy drawing `n` paths in a pixel has `n` times the
//! density there). Faces of closed components ([`Mesh::face_closed`]) start paths from
//! their outward sides only.

use super::*;

/// The paths of one attitude per pixel of the receiver's image (`rx`) and of the
/// transmitter's (`tx`), row-major; 0 where no path can start.
pub(super) struct Counts {
    pub(super) rx: Vec<u32>,
    pub(super) tx: Vec<u32>,
}

impl Counts {
    /// The counts of `posed` seen along `wo` by the receiver (image axes `X`, `Y`) and lit
    /// along `wi` by the transmitter (axes `tx_u`, `tx_v`), `n` paths per pixel the mesh may
    /// cover on average (module docs); no transmitter paths without `transmitter`.
    pub(super) fn new(setup: &Setup<'_>, posed: &Posed<'_>, n: usize, transmitter: bool) -> Self {
        let (w, ext) = (setup.width, setup.lay.ext);
        let rx = counts_toward(posed, setup.wo, V3::X, V3::Y, w, ext, n);
        let tx = if !transmitter {
            vec![0; w * w]
        } else if (setup.wi, setup.tx_u, setup.tx_v) == (setup.wo, V3::X, V3::Y) {
            // monostatic: the transmitter's view is the receiver's
            rx.clone()
        } else {
            counts_toward(posed, setup.wi, setup.tx_u, setup.tx_v, w, ext, n)
        };
        Counts { rx, tx }
    }

    /// The receiver strategy's paths in the pixel `k`.
    #[inline]
    pub(super) fn rx_at(&self, k: usize) -> f64 {
        self.rx[k] as f64
    }

    /// The transmitter strategy's paths in the transmitter's pixel that lights `p`.
    #[inline]
    pub(super) fn tx_at(&self, setup: &Setup<'_>, p: V3) -> f64 {
        setup.tx_pixel(p).map_or(0.0, |k| self.tx[k] as f64)
    }
}

/// The counts of one strategy: `N 2^k` paths (`2^k` the power of two nearest
/// `M / M_open`, at least 1; at most [`MAX_PATH_SAMPLES`]) in each of the `M_open` pixels
/// of the `w x w` view along `w_view` (axes `u`, `v`) that the faces open toward it may
/// cover, `M` the pixels any face may cover.
fn counts_toward(
    posed: &Posed<'_>,
    w_view: V3,
    u: V3,
    v: V3,
    w: usize,
    ext: f64,
    n: usize,
) -> Vec<u32> {
    let all = covered_pixels(&posed.tris, u, v, w, ext);
    let open_tris: Vec<[V3; 3]> = (posed.tris.iter().zip(posed.open))
        .zip(&posed.mesh.face_closed)
        .filter(|(([a, b, c], open), &closed)| {
            // the side facing the view (a closed component shows only its outward sides)
            let toward = dot(cross(*b - *a, *c - *a), w_view);
            (toward > 0.0 && open[0]) || (toward < 0.0 && open[1] && !closed)
        })
        .map(|((t, _), _)| *t)
        .collect();
    let open = covered_pixels(&open_tris, u, v, w, ext);
    let m = all.iter().filter(|&&x| x).count();
    let m_open = open.iter().filter(|&&x| x).count();
    if m_open == 0 {
        return vec![0; w * w];
    }
    let each =
        (n << (m as f64 / m_open as f64).log2().round().max(0.0) as u32).min(MAX_PATH_SAMPLES);
    open.iter()
        .map(|&x| if x { each as u32 } else { 0 })
        .collect()
}
