//! Where each strategy draws its paths and how many per pixel ([`Counts`]).
//!
//! A path can only start on a surface whose side toward the receiver (the receiver's
//! strategy) or the transmitter (the transmitter's) has some of the mesh in front of it
//! ([`open_sides`]); elsewhere it would leave the mesh at once. So each strategy draws only
//! in the pixels such faces may cover ([`covered_pixels`]), and the render's budget, `N`
//! paths for every pixel the mesh may cover, is shared evenly among those: `N M / M_open`
//! each (`M` pixels the mesh may cover, `M_open` of them with open faces), rounded to `N`
//! times a power of two. A satellite whose corners fill a few pixels then draws its paths
//! there, with about the work of `N` paths per pixel of the mesh.
//!
//! Pixels where an open face is thin in that view (narrower than [`THIN_PX`] pixels in
//! projection, [`crate::render::thin`]: a wire, a panel's rim seen edge-on) get
//! `2^`[`THIN_SHIFT`] times that, on top of the budget: within such a pixel the surface's
//! normal sweeps around a wire, and only a sliver of it turns the light into the rest of
//! the mesh (the CubeSat's 3 mm whip against its bus held most of the noise of the views
//! where it shows). Measured on the CubeSat at 16 paths (128 px, 3 seeds; profile noise
//! as `scripts/interreflections.py` defines it, against 16x the paths): over 25 of the 50
//! attitudes of that script, 1.22% in 23.5 ms per attitude with no extra paths, 0.90% in
//! 26.7 ms with 4x, 0.87% in 31.6 ms with 8x, 0.76% in 40.1 ms with 16x; over its 6 noise
//! attitudes, 1.36% in 30.1 ms, 0.95% in 32.9 ms with 4x and 0.76% in 37.2 ms with 8x.
//! Taking the share of the thin pixels out of the others' budget instead made some views
//! worse (the paths the others lost were those of other corners).
//!
//! The power of two keeps a pixel's count, and so its random numbers, the same while the
//! attitude moves a little (a fit's steps), except where `M / M_open` crosses a power of
//! `sqrt(2)` or a face turns thin (the Sobol' points are also best balanced at powers of
//! two). Each pixel's estimate is unbiased for any count: its `n` paths carry `1 / n` of
//! its area each, and the balance heuristic weighs a path by each strategy's count where
//! it was drawn (a strategy drawing `n` paths in a pixel has `n` times the density there).
//! Faces of closed components ([`Mesh::face_closed`]) start paths from their outward sides
//! only.

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
        let rx = counts_toward(setup, posed, setup.wo, V3::X, V3::Y, w, ext, n);
        let tx = if !transmitter {
            vec![0; w * w]
        } else if setup.monostatic() {
            // monostatic: the transmitter's view is the receiver's
            rx.clone()
        } else {
            counts_toward(setup, posed, setup.wi, setup.tx_u, setup.tx_v, w, ext, n)
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

/// A pixel with a thin open face gets `2^THIN_SHIFT` times the paths of the others (module
/// docs).
pub(super) const THIN_SHIFT: u32 = 3;

/// The counts of one strategy in the `w x w` view along `w_view` (axes `u`, `v`): in each
/// pixel that faces open toward the view may cover, `N 2^k` paths, `2^k` the power of two
/// nearest `M / M_open` (at least 1), times `2^THIN_SHIFT` where one of those faces is
/// thin (module docs); at most [`MAX_PATH_SAMPLES`].
#[allow(clippy::too_many_arguments)]
fn counts_toward(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    w_view: V3,
    u: V3,
    v: V3,
    w: usize,
    ext: f64,
    n: usize,
) -> Vec<u32> {
    let all = covered_pixels(&posed.tris, u, v, w, ext);
    let mut open_tris: Vec<[V3; 3]> = Vec::new();
    let mut thin_tris: Vec<[V3; 3]> = Vec::new();
    let faces = posed
        .tris
        .iter()
        .zip(posed.open)
        .zip(&posed.mesh.face_closed);
    for (((tri, open), &closed), a) in faces.zip(setup.thinness) {
        let [p0, p1, p2] = *tri;
        // the side facing the view (a closed component shows only its outward sides)
        let toward = dot(cross(p1 - p0, p2 - p0), w_view);
        if (toward > 0.0 && open[0]) || (toward < 0.0 && open[1] && !closed) {
            open_tris.push(*tri);
            // `crate::render::thin::is_thin` along `w_view`
            let width = dot(rotate(posed.rot, V3::new(a[0], a[1], a[2])), w_view).abs() + a[3];
            if width < THIN_PX * setup.pix {
                thin_tris.push(*tri);
            }
        }
    }
    let open = covered_pixels(&open_tris, u, v, w, ext);
    let thin = covered_pixels(&thin_tris, u, v, w, ext);
    let m = all.iter().filter(|&&x| x).count();
    let m_open = open.iter().filter(|&&x| x).count();
    if m_open == 0 {
        return vec![0; w * w];
    }
    let k = (m as f64 / m_open as f64).log2().round().max(0.0) as u32;
    (open.iter().zip(&thin))
        .map(|(&open, &thin)| match (open, thin) {
            (false, _) => 0,
            (true, false) => (n << k).min(MAX_PATH_SAMPLES) as u32,
            (true, true) => (n << (k + THIN_SHIFT)).min(MAX_PATH_SAMPLES) as u32,
        })
        .collect()
}
