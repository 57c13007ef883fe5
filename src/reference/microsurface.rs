//! Periodic triangulated height fields: Gaussian random surfaces with a Gaussian or a
//! Matern autocorrelation (spectral synthesis, [`Autocorrelation`]), and the
//! piecewise-planar geometry the ray tracer intersects.
//!
//! # Geometry
//! Heights `h[i * n + j] = h(x = i, y = j)` on a periodic `n x n` grid with unit spacing
//! (grid units; the BRDF is scale free in geometric optics). Cell `(i, j)` covers
//! `[i, i+1] x [j, j+1]` and is split into two planar triangles along a diagonal that
//! alternates in a checkerboard: the main diagonal `(0,0)-(1,1)` when `i + j` is even, the
//! anti-diagonal `(1,0)-(0,1)` when odd. Each triangle's slope `(sx, sy)` is a pair of
//! grid differences (one along x on the cell's bottom or top edge, one along y on its left
//! or right edge), so the slopes of the triangles are exactly the forward differences of
//! the grid, and each triangle has projected area 1/2: the realized facet-normal
//! distribution of the surface is the histogram of those differences.
//!
//! Why the checkerboard: with a fixed diagonal, the two slopes of a triangle are
//! correlated, `cov(sx, sy) = +/-(C(0) - 2 C(1) + C(sqrt 2))` (`C` the height
//! autocovariance; relative correlation about `1/(2 l^2)` for correlation length `l`), with
//! the sign set by the diagonal. Alternating the diagonal makes the two signs cancel over
//! the tile, so the realized slope covariance is isotropic to first order.
//!
//! # Random surfaces
//! Heights are white Gaussian noise filtered in Fourier space by
//! `H(k) = exp(-|k|^2 l^2 / 8)` (`k` in radians per grid unit), so the height power spectrum
//! is `exp(-|k|^2 l^2 / 4)` and the autocorrelation `C(r) = sigma_h^2 exp(-r^2 / l^2)`.
//! A linear filter of Gaussian noise is jointly Gaussian, so every grid difference, hence
//! every facet slope component, is exactly normal with zero mean. Beckmann's slope
//! distribution is `P(sx, sy) = exp(-(sx^2 + sy^2)/alpha^2) / (pi alpha^2)`, i.e. each slope
//! component has variance `alpha^2 / 2`:
//!
//! `alpha^2 = 2 var(sx) = 2 var(sy) = E[sx^2 + sy^2]`.
//!
//! (For the smooth continuous surface `var(sx) = -C''(0) = 2 sigma_h^2 / l^2`, so
//! `alpha = 2 sigma_h / l`; for the triangulated one `var(sx) = 2 sigma_h^2 (1 - exp(-1/l^2))`,
//! `1 - 1/(2 l^2)` times smaller.) Blinn-Phong `m` maps to `alpha = sqrt(2/(m+2))` (Walter
//! et al. 2007). After synthesis the heights are rescaled so that the realized mean of
//! `sx^2 + sy^2` over all triangles (equal projected areas) is exactly `alpha^2`; the
//! realized value before rescaling is reported relative to its ensemble expectation (its
//! spread is the finite-tile sampling error, a few percent for 256 x 256 and `l = 8`).
//!
//! **Matern** ([`Autocorrelation::Matern`], smoothness `nu = 5/2`): the filter is the
//! square root of the 2-D Matern spectrum, `H(k) = (2 nu / L^2 + |k|^2)^(-(nu + 1) / 2)`,
//! so `C(r) = sigma_h^2 (1 + x + x^2 / 3) exp(-x)`, `x = sqrt(5) r / L`. Near the origin
//! `C = sigma_h^2 (1 - 5 r^2 / (6 L^2) + ...)`, so `L = l sqrt(5 / 6)` gives the same
//! `-C''(0) / C(0) = 2 / l^2` as the Gaussian of length `l`: the same slope variance for the
//! same height variance (`alpha = 2 sigma_h / l` for both), and `2 nu / L^2 = 6 / l^2`. So
//! `l` is the same parameter for both shapes; they differ in how slopes correlate with
//! distance (at `r = 2 l` the height correlation is 0.018 for the Gaussian, 0.10 for the
//! Matern: [`Autocorrelation::correlation`]). Slopes are Gaussian for both, so both are
//! Beckmann surfaces; only orders >= 2 see the difference.

use super::rng::Rng;
use crate::{Error, Result};
use num_complex::Complex64;
use rayon::prelude::*;
use rustfft::FftPlanner;

/// A periodic, triangulated height field with per-cell height bounds.
#[derive(Debug, Clone)]
pub struct HeightField {
    /// Grid size (the tile is `n x n` grid units).
    pub n: usize,
    /// Heights, `h[i * n + j] = h(x = i, y = j)`.
    pub h: Vec<f64>,
    /// Per-cell `(min, max)` over the four corners (the surface in the cell lies between).
    bounds: Vec<[f64; 2]>,
    /// Global minimum and maximum height.
    pub h_min: f64,
    pub h_max: f64,
}

/// Slope statistics of the triangles (each weighted by its projected area, all equal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlopeStats {
    /// `sqrt(E[sx^2 + sy^2])`, the realized Beckmann alpha.
    pub alpha: f64,
    /// `[[E sx^2, E sx sy], [E sx sy, E sy^2]]` (the means are exactly 0 on a periodic grid).
    pub cov: [[f64; 2]; 2],
}

/// What the synthesis of one random surface did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceReport {
    /// Slope statistics after rescaling (`alpha` equals the requested one to rounding).
    pub stats: SlopeStats,
    /// Realized rms slope before rescaling divided by its ensemble expectation.
    pub alpha_unscaled_ratio: f64,
    /// Factor applied to the synthesized heights (1 for user heights).
    pub scale: f64,
}

/// One planar piece of a cell in local coordinates `(u, v)` of the cell:
/// `z = z0 + sx u + sy v`.
#[derive(Debug, Clone, Copy)]
pub struct Plane {
    pub z0: f64,
    pub sx: f64,
    pub sy: f64,
}

impl HeightField {
    /// Wrap user heights (`n * n` values, `h[i * n + j] = h(x = i, y = j)`).
    pub fn new(n: usize, h: Vec<f64>) -> Result<Self> {
        if n < 2 {
            return Err(Error::param(
                "heights",
                format!("{n} x {n}"),
                "need at least 2 x 2 samples",
            ));
        }
        if h.len() != n * n {
            return Err(Error::Shape(format!(
                "heights must have {n} x {n} = {} values, got {}",
                n * n,
                h.len()
            )));
        }
        if let Some(bad) = h.iter().find(|x| !x.is_finite()) {
            return Err(Error::param("heights", bad, "all heights must be finite"));
        }
        let mut f = HeightField {
            n,
            h,
            bounds: Vec::new(),
            h_min: 0.0,
            h_max: 0.0,
        };
        f.update_bounds();
        Ok(f)
    }

    fn update_bounds(&mut self) {
        let n = self.n;
        self.bounds = (0..n * n)
            .map(|c| {
                let (h00, h10, h01, h11) = self.corners(c / n, c % n);
                [
                    h00.min(h10).min(h01.min(h11)),
                    h00.max(h10).max(h01.max(h11)),
                ]
            })
            .collect();
        self.h_min = self.h.iter().copied().fold(f64::INFINITY, f64::min);
        self.h_max = self.h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    }

    #[inline]
    fn at(&self, i: usize, j: usize) -> f64 {
        self.h[i * self.n + j]
    }

    /// Corner heights `(h00, h10, h01, h11)` of cell `(i, j)`, `i, j < n` (periodic).
    #[inline]
    pub fn corners(&self, i: usize, j: usize) -> (f64, f64, f64, f64) {
        let n = self.n;
        let (i1, j1) = (
            if i + 1 == n { 0 } else { i + 1 },
            if j + 1 == n { 0 } else { j + 1 },
        );
        (
            self.at(i, j),
            self.at(i1, j),
            self.at(i, j1),
            self.at(i1, j1),
        )
    }

    /// Height bounds `[min, max]` of cell `(i, j)`.
    #[inline]
    pub fn cell_bounds(&self, i: usize, j: usize) -> [f64; 2] {
        self.bounds[i * self.n + j]
    }

    /// Whether cell `(i, j)` is split along the main diagonal `u = v` (else `u + v = 1`).
    #[inline]
    pub fn main_diagonal(i: usize, j: usize) -> bool {
        (i + j).is_multiple_of(2)
    }

    /// The two planes of cell `(i, j)`: for the main diagonal `[u >= v, u < v]`, for the
    /// anti-diagonal `[u + v <= 1, u + v > 1]`.
    #[inline]
    pub fn planes(&self, i: usize, j: usize) -> [Plane; 2] {
        let (h00, h10, h01, h11) = self.corners(i, j);
        if Self::main_diagonal(i, j) {
            [
                Plane {
                    z0: h00,
                    sx: h10 - h00,
                    sy: h11 - h10,
                },
                Plane {
                    z0: h00,
                    sx: h11 - h01,
                    sy: h01 - h00,
                },
            ]
        } else {
            let (sx, sy) = (h11 - h01, h11 - h10);
            [
                Plane {
                    z0: h00,
                    sx: h10 - h00,
                    sy: h01 - h00,
                },
                Plane {
                    z0: h11 - sx - sy,
                    sx,
                    sy,
                },
            ]
        }
    }

    /// Slopes `(sx, sy)` of all `2 n^2` triangles, cell by cell (`(i * n + j) * 2 + piece`).
    pub fn facet_slopes(&self) -> Vec<[f64; 2]> {
        let n = self.n;
        let mut out = Vec::with_capacity(2 * n * n);
        for i in 0..n {
            for j in 0..n {
                for p in self.planes(i, j) {
                    out.push([p.sx, p.sy]);
                }
            }
        }
        out
    }

    /// Realized slope statistics over all triangles.
    pub fn slope_stats(&self) -> SlopeStats {
        let (mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0);
        let n = self.n;
        for i in 0..n {
            let mut r = [0.0; 3];
            for j in 0..n {
                for p in self.planes(i, j) {
                    r[0] += p.sx * p.sx;
                    r[1] += p.sy * p.sy;
                    r[2] += p.sx * p.sy;
                }
            }
            xx += r[0];
            yy += r[1];
            xy += r[2];
        }
        let m = (2 * n * n) as f64;
        let (xx, yy, xy) = (xx / m, yy / m, xy / m);
        SlopeStats {
            alpha: (xx + yy).sqrt(),
            cov: [[xx, xy], [xy, yy]],
        }
    }

    /// Multiply all heights by `s` (bounds follow).
    fn scale(&mut self, s: f64) {
        self.h.iter_mut().for_each(|x| *x *= s);
        self.update_bounds();
    }
}

/// Check the parameters of a Gaussian surface.
pub fn check_gaussian(alpha: f64, grid: usize, correlation_length: f64) -> Result<()> {
    if !(alpha.is_finite() && (1e-8..=4.0).contains(&alpha)) {
        return Err(Error::param("alpha", alpha, "must be in [1e-8, 4]"));
    }
    if !(16..=4096).contains(&grid) {
        return Err(Error::param("grid", grid, "must be in [16, 4096]"));
    }
    let lmax = grid as f64 / 4.0;
    if !(correlation_length.is_finite() && correlation_length >= 2.0 && correlation_length <= lmax)
    {
        return Err(Error::param(
            "correlation_length",
            correlation_length,
            format!(
                "must be in [2, grid/4 = {lmax}] grid units (>= 4 correlation lengths per tile)"
            ),
        ));
    }
    Ok(())
}

/// The shape of a random surface's height autocorrelation (module docs: both have the same
/// slope statistics for the same correlation length `l`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Autocorrelation {
    /// `C(r) = exp(-r^2 / l^2)` (the default, and the reference's own synthesis).
    #[default]
    Gaussian,
    /// Matern of smoothness 5/2 with the Gaussian's `-C''(0)`: `(1 + x + x^2 / 3) exp(-x)`,
    /// `x = sqrt(6) r / l`.
    Matern,
}

impl Autocorrelation {
    pub const ALL: [Autocorrelation; 2] = [Autocorrelation::Gaussian, Autocorrelation::Matern];

    /// The name a user gives (`"gaussian"`, `"matern"`).
    pub fn name(self) -> &'static str {
        match self {
            Autocorrelation::Gaussian => "gaussian",
            Autocorrelation::Matern => "matern",
        }
    }

    /// The shape named `name` ([`Self::name`]); anything else is refused naming
    /// `autocorrelation`.
    pub fn from_name(name: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|a| a.name() == name)
            .ok_or_else(|| {
                Error::param(
                    "autocorrelation",
                    format!("{name:?}"),
                    "expected \"gaussian\" (C(r) = exp(-r^2/l^2)) or \"matern\" (Matern of \
                 smoothness 5/2 with the same slope statistics)",
                )
            })
    }

    /// The normalized height autocorrelation `C(r) / C(0)` of the continuous surface of
    /// correlation length `l` (module docs).
    pub fn correlation(self, r: f64, l: f64) -> f64 {
        match self {
            Autocorrelation::Gaussian => (-(r * r) / (l * l)).exp(),
            Autocorrelation::Matern => {
                let x = 6f64.sqrt() * r.abs() / l;
                (1.0 + x + x * x / 3.0) * (-x).exp()
            }
        }
    }

    /// The synthesis filter's amplitude at `|k|^2 = k2` (radians per grid unit) for length
    /// `l`, up to a constant (the heights are rescaled to `alpha` afterwards).
    fn filter(self, k2: f64, l: f64) -> f64 {
        match self {
            Autocorrelation::Gaussian => (-k2 * (l * l) / 8.0).exp(),
            // (2 nu / L^2 + k^2)^(-(nu + 1) / 2), nu = 5/2, 2 nu / L^2 = 6 / l^2
            Autocorrelation::Matern => (6.0 / (l * l) + k2).powf(-1.75),
        }
    }
}

/// In-place 2D FFT of an `n x n` row-major array (rows, then columns by transposition).
fn fft2(planner: &mut FftPlanner<f64>, a: &mut [Complex64], n: usize, inverse: bool) {
    let fft = if inverse {
        planner.plan_fft_inverse(n)
    } else {
        planner.plan_fft_forward(n)
    };
    let rows = |b: &mut [Complex64]| b.par_chunks_mut(n).for_each(|r| fft.process(r));
    rows(a);
    let mut t = vec![Complex64::new(0.0, 0.0); n * n];
    let transpose = |src: &[Complex64], dst: &mut [Complex64]| {
        dst.par_chunks_mut(n).enumerate().for_each(|(j, r)| {
            r.iter_mut()
                .enumerate()
                .for_each(|(i, x)| *x = src[i * n + j])
        })
    };
    transpose(a, &mut t);
    rows(&mut t);
    transpose(&t, a);
}

/// A Gaussian random height field with Gaussian autocorrelation of length
/// `correlation_length` (grid units), rescaled so that the realized Beckmann alpha of its
/// triangles is `alpha` (module docs). Deterministic in `(seed, stream)`.
pub fn gaussian_height_field(
    alpha: f64,
    grid: usize,
    correlation_length: f64,
    seed: u64,
    stream: &[u64],
) -> Result<(HeightField, SurfaceReport)> {
    height_field(
        Autocorrelation::Gaussian,
        alpha,
        grid,
        correlation_length,
        seed,
        stream,
    )
}

/// A Gaussian random height field with the autocorrelation `shape` of length
/// `correlation_length` (grid units), rescaled so that the realized Beckmann alpha of its
/// triangles is `alpha` (module docs). Deterministic in `(shape, seed, stream)`; the
/// Gaussian shape is [`gaussian_height_field`].
pub fn height_field(
    shape: Autocorrelation,
    alpha: f64,
    grid: usize,
    correlation_length: f64,
    seed: u64,
    stream: &[u64],
) -> Result<(HeightField, SurfaceReport)> {
    check_gaussian(alpha, grid, correlation_length)?;
    let n = grid;
    let mut rng = Rng::new(seed, stream);
    // White Gaussian noise.
    let mut a: Vec<Complex64> = Vec::with_capacity(n * n);
    while a.len() < n * n {
        let (x, y) = rng.normal_pair();
        a.push(Complex64::new(x, 0.0));
        if a.len() < n * n {
            a.push(Complex64::new(y, 0.0));
        }
    }
    // Filter H(k) (Gaussian: exp(-|k|^2 l^2 / 8)), k = 2 pi m / n with m wrapped to
    // [-n/2, n/2).
    let l = correlation_length;
    let kk: Vec<f64> = (0..n)
        .map(|m| {
            let mm = if 2 * m >= n {
                m as f64 - n as f64
            } else {
                m as f64
            };
            let k = std::f64::consts::TAU * mm / n as f64;
            k * k
        })
        .collect();
    let mut planner = FftPlanner::new();
    fft2(&mut planner, &mut a, n, false);
    // Expected E[sx^2 + sy^2] of the unit-noise field: (1/n^2) sum H^2 2 (2 - cos kx - cos ky)
    // (the forward differences have |exp(i k) - 1|^2 = 2 (1 - cos k)).
    let mut expected = 0.0;
    for i in 0..n {
        let cx = (std::f64::consts::TAU * i as f64 / n as f64).cos();
        for j in 0..n {
            let cy = (std::f64::consts::TAU * j as f64 / n as f64).cos();
            let hk = shape.filter(kk[i] + kk[j], l);
            a[i * n + j] *= hk;
            expected += hk * hk * 2.0 * (2.0 - cx - cy);
        }
    }
    expected /= (n * n) as f64;
    fft2(&mut planner, &mut a, n, true);
    // rustfft is unnormalized: forward + inverse multiplies by n^2.
    let norm = 1.0 / (n * n) as f64;
    let mut h: Vec<f64> = a.iter().map(|z| z.re * norm).collect();
    let mean = h.iter().sum::<f64>() / (n * n) as f64;
    h.iter_mut().for_each(|x| *x -= mean);
    let mut field = HeightField::new(n, h)?;
    let raw = field.slope_stats().alpha;
    if raw.is_nan() || raw <= 0.0 {
        return Err(Error::param(
            "alpha",
            alpha,
            "the synthesized surface is flat (should not happen)",
        ));
    }
    let scale = alpha / raw;
    field.scale(scale);
    let stats = field.slope_stats();
    Ok((
        field,
        SurfaceReport {
            stats,
            alpha_unscaled_ratio: raw / expected.sqrt(),
            scale,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planes_interpolate_corners_and_meet_on_the_diagonal() {
        let h: Vec<f64> = (0..16)
            .map(|k| ((k * 7919) % 13) as f64 * 0.37 - 2.0)
            .collect();
        let f = HeightField::new(4, h).unwrap();
        for i in 0..4 {
            for j in 0..4 {
                let (h00, h10, h01, h11) = f.corners(i, j);
                let [a, b] = f.planes(i, j);
                let z = |p: Plane, u: f64, v: f64| p.z0 + p.sx * u + p.sy * v;
                let eps = 1e-12;
                if HeightField::main_diagonal(i, j) {
                    assert!(
                        (z(a, 0.0, 0.0) - h00).abs() < eps && (z(a, 1.0, 0.0) - h10).abs() < eps
                    );
                    assert!(
                        (z(a, 1.0, 1.0) - h11).abs() < eps && (z(b, 0.0, 1.0) - h01).abs() < eps
                    );
                    assert!(
                        (z(b, 0.0, 0.0) - h00).abs() < eps && (z(b, 1.0, 1.0) - h11).abs() < eps
                    );
                    assert!((z(a, 0.3, 0.3) - z(b, 0.3, 0.3)).abs() < eps);
                } else {
                    assert!(
                        (z(a, 0.0, 0.0) - h00).abs() < eps && (z(a, 1.0, 0.0) - h10).abs() < eps
                    );
                    assert!(
                        (z(a, 0.0, 1.0) - h01).abs() < eps && (z(b, 1.0, 1.0) - h11).abs() < eps
                    );
                    assert!(
                        (z(b, 1.0, 0.0) - h10).abs() < eps && (z(b, 0.0, 1.0) - h01).abs() < eps
                    );
                    assert!((z(a, 0.3, 0.7) - z(b, 0.3, 0.7)).abs() < eps);
                }
            }
        }
    }

    /// The realized height autocorrelation of each shape, along x and y at 0.5, 1 and 2
    /// correlation lengths, averaged over 8 tiles of 256 x 256 (l = 8), against the
    /// continuous surface's `C(r) / C(0)` written from the shapes' definitions
    /// ([`Autocorrelation::correlation`]). Tolerance 0.03, 3 standard deviations of the
    /// 8-tile mean at 2 lengths: over 16 other seeds its deviation from `C` had standard
    /// deviation 0.002-0.010 (growing with the lag) and mean within 0.002 for both shapes,
    /// at most 0.026. The two shapes differ by 0.02, 0.10 and 0.085 at these lags, and
    /// each estimate must also lie closer to its own shape at 1 and 2 lengths. Both keep
    /// the requested alpha.
    #[test]
    fn each_shape_has_its_autocorrelation_and_the_requested_alpha() {
        let (n, l) = (256usize, 8.0);
        for shape in Autocorrelation::ALL {
            let other = Autocorrelation::ALL
                .into_iter()
                .find(|&a| a != shape)
                .unwrap();
            let mut c = [0.0; 3];
            let tiles = 8;
            for t in 0..tiles {
                let (f, rep) = height_field(shape, 0.5, n, l, 11, &[t]).unwrap();
                assert!((rep.stats.alpha - 0.5).abs() < 1e-12);
                assert!(
                    (rep.alpha_unscaled_ratio - 1.0).abs() < 0.1,
                    "{shape:?} {rep:?}"
                );
                let h = &f.h;
                let var = h.iter().map(|x| x * x).sum::<f64>() / (n * n) as f64;
                for (k, lag) in [4usize, 8, 16].into_iter().enumerate() {
                    let mut s = 0.0;
                    for i in 0..n {
                        for j in 0..n {
                            let x = h[i * n + j];
                            s += x * (h[((i + lag) % n) * n + j] + h[i * n + (j + lag) % n]);
                        }
                    }
                    c[k] += s / (2.0 * (n * n) as f64 * var) / tiles as f64;
                }
            }
            for (k, r) in [4.0, 8.0, 16.0].into_iter().enumerate() {
                let (own, alt) = (shape.correlation(r, l), other.correlation(r, l));
                assert!(
                    (c[k] - own).abs() < 0.03,
                    "{shape:?} r = {r}: {} against {own}",
                    c[k]
                );
                if k > 0 {
                    assert!((c[k] - own).abs() < (c[k] - alt).abs(), "{shape:?} r = {r}");
                }
            }
        }
        assert_eq!(
            Autocorrelation::from_name("matern").unwrap(),
            Autocorrelation::Matern
        );
        let e = Autocorrelation::from_name("exponential")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("autocorrelation") && e.contains("\"matern\""),
            "{e}"
        );
    }

    #[test]
    fn gaussian_surface_has_requested_alpha_and_isotropic_gaussian_slopes() {
        let (f, rep) = gaussian_height_field(0.4, 256, 8.0, 3, &[0]).unwrap();
        assert!((rep.stats.alpha - 0.4).abs() < 1e-12);
        assert!((rep.alpha_unscaled_ratio - 1.0).abs() < 0.06, "{rep:?}");
        let c = rep.stats.cov;
        let v = 0.4 * 0.4 / 2.0;
        assert!(
            (c[0][0] - v).abs() < 0.06 * v && (c[1][1] - v).abs() < 0.06 * v,
            "{c:?}"
        );
        assert!(c[0][1].abs() < 0.04 * v, "{c:?}");
        // tan^2(theta_h) / alpha^2 is Exp(1) under Beckmann: check P(t > 1) = 1/e.
        let s = f.facet_slopes();
        let frac = s
            .iter()
            .filter(|p| p[0] * p[0] + p[1] * p[1] > 0.16)
            .count() as f64
            / s.len() as f64;
        assert!((frac - (-1.0f64).exp()).abs() < 0.02, "{frac}");
    }

    #[test]
    fn bad_parameters_are_named() {
        let e = gaussian_height_field(0.0, 256, 8.0, 0, &[]).unwrap_err();
        assert!(e.to_string().contains("alpha"));
        let e = gaussian_height_field(0.3, 8, 2.0, 0, &[]).unwrap_err();
        assert!(e.to_string().contains("grid"));
        let e = gaussian_height_field(0.3, 64, 32.0, 0, &[]).unwrap_err();
        assert!(e.to_string().contains("correlation_length"));
    }
}
