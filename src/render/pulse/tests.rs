//! Tests of the pulse CDFs (moved out of `pulse.rs`, unchanged): the Gaussian and sampled
//! CDFs against brute-force quadrature of the convolution in every regime, continuity across
//! the regime switches, the bin weights' telescoping sums, the f32 twin's error and bits,
//! and the WGSL copy.

use super::*;
use crate::quad::integrate;

const GL: usize = 16;

#[test]
fn folded_weights_sum_to_one_and_equal_the_full_ones_inside() {
    let (sigma, bw) = (6.37e-3, 3.75e-3);
    let edges: Vec<f64> = (0..=80).map(|k| -0.15 + k as f64 * bw).collect();
    let mut full = vec![0.0; 80];
    let mut fold = vec![0.0; 80];
    for &(r0, a, b) in &[(0.0013, 1e-3, 4e-4), (-0.05, 8e-3, 2e-3), (0.031, 0.0, 0.0)] {
        let half_w = 5.0 * sigma + 0.5 * (a + b);
        bin_weights_f64(r0, a, b, sigma, &edges, &mut full);
        bin_weights_folded(r0, a, b, sigma, half_w, &edges, &mut fold);
        let s: f64 = fold.iter().sum();
        assert!((s - 1.0).abs() < 1e-15, "{s}");
        let nz: Vec<usize> = (0..80).filter(|&k| fold[k] != 0.0).collect();
        let (k0, k1) = (nz[0], *nz.last().unwrap());
        // interior bins: the same weights; end bins: plus the folded tail, which is the
        // Gaussian's mass beyond 5 sigma (2.87e-7) up to the bin's rounding
        for k in k0 + 1..k1 {
            assert!((fold[k] - full[k]).abs() < 1e-15);
        }
        let lo: f64 = full[..=k0].iter().sum();
        let hi: f64 = full[k1..].iter().sum();
        assert!((fold[k0] - lo).abs() < 1e-15 && (fold[k1] - hi).abs() < 1e-15);
        let tail: f64 = full[..k0].iter().sum();
        assert!(tail < 2.9e-7, "{tail}");
    }
}

/// Integral of `f` over [lo, hi] split at the given points (those inside), GL on each piece.
fn split_integral(lo: f64, hi: f64, splits: &[f64], f: impl Fn(f64) -> f64) -> f64 {
    let mut bp: Vec<f64> = splits
        .iter()
        .copied()
        .filter(|&s| s > lo && s < hi)
        .collect();
    bp.push(lo);
    bp.push(hi);
    bp.sort_by(|p, q| p.total_cmp(q));
    bp.windows(2).map(|w| integrate(GL, w[0], w[1], &f)).sum()
}

/// Brute force: the mean over u, v of Phi((x - u - v)/sigma), split every sigma around
/// the transitions so that each piece is smooth on the scale of the GL rule.
fn brute_gauss(x: f64, sigma: f64, a: f64, b: f64) -> f64 {
    let ks: Vec<f64> = (-12..=12).map(|k| k as f64 * sigma).collect();
    let phi = |t: f64| norm_cdf(t / sigma);
    let inner = |u: f64| -> f64 {
        if b == 0.0 {
            return phi(x - u);
        }
        let c = x - u;
        let sp: Vec<f64> = ks.iter().map(|k| c + k).collect();
        split_integral(-0.5 * b, 0.5 * b, &sp, |v| phi(c - v)) / b
    };
    if a == 0.0 {
        return inner(0.0);
    }
    let mut sp: Vec<f64> = ks.iter().map(|k| x + k).collect();
    sp.extend(ks.iter().map(|k| x + 0.5 * b + k));
    sp.extend(ks.iter().map(|k| x - 0.5 * b + k));
    split_integral(-0.5 * a, 0.5 * a, &sp, inner) / a
}

/// (a, b) in sigma units covering every regime and both sides of every switch.
const REGIMES: [(f64, f64); 18] = [
    (0.0, 0.0),
    (1e-6, 0.0),
    (1e-3, 1e-4),
    (0.1, 0.05),
    (0.124, 0.124),
    (0.126, 0.01),
    (0.3, 0.0),
    (0.6, 0.39),
    (0.6, 0.41),
    (1.0, 1.0),
    (3.0, 0.2),
    (10.0, 0.5),
    (100.0, 37.0),
    (1e4, 1e4),
    (1e4, 1.0),
    (1e4, 1e-3),
    (1e4, 0.0),
    (0.0, 2.0),
];

fn x_grid(sigma: f64, a: f64, b: f64, n: usize) -> Vec<f64> {
    let h1 = 0.5 * (a + b);
    let h2 = 0.5 * (a - b).abs();
    let mut xs: Vec<f64> = (0..n)
        .map(|i| (-1.0 + 2.0 * i as f64 / (n - 1) as f64) * (h1 + 10.0 * sigma))
        .collect();
    for c in [-h1, -h2, h2, h1] {
        for d in [-3.0, -1.0, -0.3, 0.0, 0.3, 1.0, 3.0] {
            xs.push(c + d * sigma);
        }
    }
    xs
}

#[test]
fn gauss_matches_brute_force_in_every_regime() {
    let sigma = 0.7;
    let mut worst = 0.0f64;
    for (a, b) in REGIMES {
        let (a, b) = (a * sigma, b * sigma);
        let mut w = 0.0f64;
        for x in x_grid(sigma, a, b, 21) {
            let c = cdf_gauss_box2(x, sigma, a, b);
            let r = brute_gauss(x, sigma, a, b);
            w = w.max((c - r).abs());
        }
        eprintln!(
            "a/s {:e} b/s {:e}: max |C - brute| = {w:.2e}",
            a / sigma,
            b / sigma
        );
        worst = worst.max(w);
    }
    eprintln!("worst {worst:.2e}");
    assert!(worst < 3e-15, "worst {worst:e}");
}

#[test]
fn norm_cdf_matches_tabulated_values() {
    // Phi to 25 digits (Wolfram), checked relatively so that the tails count.
    let table = [
        (1.0, 0.8413447460685429485852325),
        (0.5, 0.6914624612740131036377046),
        (-1.0, 0.1586552539314570514147675),
        (-3.0, 1.349898031630094526651814e-3),
        (-5.0, 2.866515718791939116737523e-7),
        (-10.0, 7.619853024160526065973343e-24),
        (-20.0, 2.753624118606233695075e-89),
    ];
    for (x, want) in table {
        // The rounding of x/sqrt 2 alone costs ~x^2 eps relative in the tail.
        let rel = (norm_cdf(x) / want - 1.0).abs();
        assert!(rel < 2e-16 * (8.0 + x * x), "Phi({x}): rel {rel:e}");
    }
    // The reason for libm: statrs 0.19's erfc is off by ~1e-11 here.
    let statrs_phi1 = 0.5 * statrs::function::erf::erfc(-std::f64::consts::FRAC_1_SQRT_2);
    assert!((statrs_phi1 - 0.8413447460685429).abs() > 1e-12);
}

#[test]
fn gauss_monotone_with_limits_0_and_1() {
    let sigma = 1.3;
    for (a, b) in REGIMES {
        let (a, b) = (a * sigma, b * sigma);
        let h1 = 0.5 * (a + b) + 12.0 * sigma;
        let n = 4001;
        let mut prev = 0.0;
        for i in 0..n {
            let x = -h1 + 2.0 * h1 * i as f64 / (n - 1) as f64;
            let c = cdf_gauss_box2(x, sigma, a, b);
            assert!((0.0..=1.0).contains(&c), "C({x}) = {c}");
            assert!(c >= prev - 1e-15, "a {a} b {b}: C({x}) = {c} < {prev}");
            prev = c;
        }
        assert!(cdf_gauss_box2(-h1, sigma, a, b) < 1e-30);
        assert!(cdf_gauss_box2(h1, sigma, a, b) > 1.0 - 1e-15);
        for (x, want) in [
            (-1e300, 0.0),
            (1e300, 1.0),
            (f64::NEG_INFINITY, 0.0),
            (f64::INFINITY, 1.0),
        ] {
            assert_eq!(cdf_gauss_box2(x, sigma, a, b), want);
        }
    }
}

/// Largest jump of `f(y, lo side)` vs `f(y, hi side)` over y in [-12, 12].
fn max_jump(f: impl Fn(f64, bool) -> f64) -> f64 {
    (0..=2400)
        .map(|i| -12.0 + 0.01 * i as f64)
        .map(|y| (f(y, false) - f(y, true)).abs())
        .fold(0.0, f64::max)
}

#[test]
fn gauss_continuous_across_regime_switches() {
    // The largest float below the switch (so that the jump is not a change of the input).
    let lo = |t: f64| f64::from_bits(t.to_bits() - 1);
    let mut worst = 0.0f64;
    // A crosses ALPHA (series in both widths <-> exact box and series in B).
    for bb in [0.0, 0.01, 0.06, ALPHA_F64] {
        let j = max_jump(|y, hi| {
            let aa = if hi { ALPHA_F64 } else { lo(ALPHA_F64) };
            cdf_std::<f64>(y, aa, bb.min(aa))
        });
        eprintln!("f64 A = ALPHA, B = {bb}: jump {j:.2e}");
        worst = worst.max(j);
    }
    // B crosses BETA (series in B <-> trapezoid + second difference).
    for aa in [BETA_F64, 0.5, 1.0, 10.0, 1e4] {
        let j = max_jump(|y, hi| cdf_std::<f64>(y, aa, if hi { BETA_F64 } else { lo(BETA_F64) }));
        eprintln!("f64 B = BETA, A = {aa}: jump {j:.2e}");
        worst = worst.max(j);
    }
    assert!(worst < 2e-15, "worst jump {worst:e}");

    let lo32 = |t: f32| f32::from_bits(t.to_bits() - 1);
    let mut worst32 = 0.0f64;
    for bb in [0.0f32, 0.05, 0.3, ALPHA_F32] {
        let j = max_jump(|y, hi| {
            let aa = if hi { ALPHA_F32 } else { lo32(ALPHA_F32) };
            cdf_std::<f32>(y as f32, aa, bb.min(aa)) as f64
        });
        eprintln!("f32 A = ALPHA, B = {bb}: jump {j:.2e}");
        worst32 = worst32.max(j);
    }
    for aa in [BETA_F32, 2.0, 10.0, 1e4] {
        let j = max_jump(|y, hi| {
            cdf_std::<f32>(y as f32, aa, if hi { BETA_F32 } else { lo32(BETA_F32) }) as f64
        });
        eprintln!("f32 B = BETA, A = {aa}: jump {j:.2e}");
        worst32 = worst32.max(j);
    }
    assert!(worst32 < 4e-7, "worst f32 jump {worst32:e}");
}

#[test]
fn bin_weights_telescope() {
    let (sigma, r0) = (0.15, 10.0);
    for (a, b) in [
        (0.0, 0.0),
        (0.05, 0.01),
        (0.3, 0.0),
        (2.0, 0.7),
        (40.0, 0.2),
    ] {
        // Uneven edges covering the support, then a window cutting it.
        let mut edges = vec![r0 - 25.0];
        let mut e = r0 - 25.0;
        let mut k = 0u32;
        while e < r0 + 25.0 {
            k += 1;
            e += 0.013 + 0.02 * ((k as f64 * 0.7).sin() + 1.0);
            edges.push(e);
        }
        let mut out = vec![0.0; edges.len() - 1];
        bin_weights_f64(r0, a, b, sigma, &edges, &mut out);
        let sum: f64 = out.iter().sum();
        assert!((sum - 1.0).abs() < 1e-13, "sum {sum}");
        assert!(out.iter().all(|&w| w >= -1e-16));
        let cut = &edges[100..edges.len() - 300];
        let mut out = vec![0.0; cut.len() - 1];
        bin_weights_f64(r0, a, b, sigma, cut, &mut out);
        let want = cdf_gauss_box2(cut[cut.len() - 1] - r0, sigma, a, b)
            - cdf_gauss_box2(cut[0] - r0, sigma, a, b);
        let sum: f64 = out.iter().sum();
        assert!((sum - want).abs() < 1e-13, "sum {sum} want {want}");
    }
}

#[test]
fn erfc_f32_relative_error() {
    // Relative error on [0, 9] measured against libm's f64 erfc; past ~2 it is dominated
    // by the f32 rounding of z^2 inside exp(-z^2 + ..), i.e. grows like z^2 * 6e-8.
    let (mut near, mut scaled, mut neg) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..=9000 {
        let x = i as f32 * 1e-3;
        let rel = (erfc_f32(x) as f64 / libm::erfc(x as f64) - 1.0).abs();
        if x <= 1.0 {
            near = near.max(rel);
        }
        scaled = scaled.max(rel / (1.0 + (x * x) as f64));
        // Negative side, 2 - erfc: absolute.
        neg = neg.max((erfc_f32(-x) as f64 - libm::erfc(-x as f64)).abs());
    }
    eprintln!("erfc_f32: rel {near:.2e} on [0, 1], rel/(1+x^2) {scaled:.2e} on [0, 9], abs {neg:.2e} on [-9, 0]");
    assert!(near < 3.5e-7 && scaled < 3.5e-7 && neg < 3.5e-7);
}

/// The grid on which the f32 twin's error is measured (and quoted in its docs): sigma in
/// {1, 0.37}, a/sigma and b/sigma each in WIDTHS (all 196 pairs), x on x_grid(.., 201)
/// (201 points over +-(h1 + 10 sigma) plus 28 points around the trapezoid's corners).
const WIDTHS: [f64; 14] = [
    0.0, 1e-4, 0.01, 0.1, 0.3, 0.49, 0.51, 0.9, 1.1, 2.0, 5.0, 30.0, 1e3, 1e4,
];

#[test]
fn f32_twin_error_grid() {
    let mut worst = 0.0f64;
    let mut at = (0.0, 0.0, 0.0, 0.0);
    for sigma in [1.0f64, 0.37] {
        for wa in WIDTHS {
            for wb in WIDTHS {
                let (a, b) = ((wa * sigma) as f32, (wb * sigma) as f32);
                for x in x_grid(sigma, a as f64, b as f64, 201) {
                    let x = x as f32;
                    let c32 = cdf_gauss_box2_f32(x, sigma as f32, a, b) as f64;
                    let c64 = cdf_gauss_box2(x as f64, sigma as f32 as f64, a as f64, b as f64);
                    let e = (c32 - c64).abs();
                    if e > worst {
                        worst = e;
                        at = (x as f64, sigma, wa, wb);
                    }
                }
            }
        }
    }
    eprintln!("f32 twin: max |C32 - C64| = {worst:.3e} at (x, sigma, a/s, b/s) = {at:?}");
    assert!(worst < MEASURED_F32_BOUND, "{worst:e} at {at:?}");
}

/// FNV-1a over the bits of `f` at the inputs of [`cdf_inputs`].
fn bits_hash<T: Copy>(xs: &[[f64; 4]], f: impl Fn([f64; 4]) -> T, bits: impl Fn(T) -> u64) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &x in xs {
        for byte in bits(f(x)).to_le_bytes() {
            h = (h ^ byte as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// `(x, sigma, a, b)`: the grid of `f32_twin_error_grid`, random arguments over many
/// decades in every regime, and extremes (zero widths and sigma, huge and infinite x).
fn cdf_inputs() -> Vec<[f64; 4]> {
    let mut v = vec![];
    for sigma in [1.0f64, 0.37] {
        for wa in WIDTHS {
            for wb in WIDTHS {
                let (a, b) = (wa * sigma, wb * sigma);
                for x in x_grid(sigma, a, b, 41) {
                    v.push([x, sigma, a, b]);
                }
            }
        }
    }
    let mut rng = crate::reference::rng::Rng::new(7, &[]);
    let mut rnd = || rng.uniform();
    for i in 0..100_000 {
        let sigma = if i % 97 == 0 {
            0.0
        } else {
            10f64.powf(-3.0 + 6.0 * rnd())
        };
        let mut w = || match (rnd() * 8.0) as u32 {
            0 => 0.0,
            _ => sigma.max(1e-3) * 10f64.powf(-6.0 + 11.0 * rnd()),
        };
        let (a, b) = (w(), w());
        let x = (2.0 * rnd() - 1.0) * (0.5 * (a + b) + 12.0 * sigma);
        v.push([x, sigma, a, b]);
    }
    for x in [0.0, 1e-30, 1.0, 1e30, 3e38, 1e300, f64::MAX, f64::INFINITY] {
        for x in [x, -x] {
            for s in [0.0, 1e-40, 1e-20, 1.0, 1e20] {
                for (a, b) in [(0.0, 0.0), (1.0, 0.0), (0.3, 2.0), (1e20, 1e19)] {
                    v.push([x, s, a, b]);
                }
            }
        }
    }
    v
}

/// The f64 reference and the f32 twin (which the WGSL port follows) return the same
/// bits as before they were written once, generically (issue 22): FNV-1a hashes of
/// their results over [`cdf_inputs`], recorded from the separate f64 and f32 code.
/// A deliberate change of either formula must record new values here.
#[test]
fn cdf_bits_unchanged() {
    let xs = cdf_inputs();
    let h64 = bits_hash(&xs, |[x, s, a, b]| cdf_gauss_box2(x, s, a, b), f64::to_bits);
    let h32 = bits_hash(
        &xs,
        |[x, s, a, b]| cdf_gauss_box2_f32(x as f32, s as f32, a as f32, b as f32),
        |c| c.to_bits() as u64,
    );
    let ts: Vec<[f64; 4]> = (-4000..=4000)
        .map(|i| [i as f64 * 0.0025, 0.0, 0.0, 0.0])
        .collect();
    let hn64 = bits_hash(
        &ts,
        |[t, ..]| [norm_cdf(t), norm_pdf(t)],
        |[c, p]| c.to_bits() ^ p.to_bits().rotate_left(17),
    );
    let hn32 = bits_hash(
        &ts,
        |[t, ..]| {
            [
                norm_cdf_f32(t as f32),
                norm_pdf_f32(t as f32),
                erfc_f32(t as f32),
            ]
        },
        |[c, p, e]| {
            c.to_bits() as u64 ^ (p.to_bits() as u64) << 32 ^ (e.to_bits() as u64).rotate_left(17)
        },
    );
    eprintln!(
        "{} inputs: {h64:#018x} {h32:#018x} {hn64:#018x} {hn32:#018x}",
        xs.len()
    );
    assert_eq!(
        [h64, h32, hn64, hn32],
        [
            0x9e252257be4a7dfd,
            0xa20aa80623d9f9f6,
            0xb732c97dbcb356aa,
            0x2d75bad78568126e
        ]
    );
}

/// The bound quoted in the docs of [`cdf_gauss_box2_f32`].
const MEASURED_F32_BOUND: f64 = 2.5e-7;

#[test]
fn f32_never_nan_or_inf() {
    let xs = [
        0.0f32,
        1e-38,
        1e-20,
        1.0,
        1e20,
        1e30,
        f32::MAX,
        f32::INFINITY,
    ];
    let sig = [0.0f32, 1e-45, 1e-38, 1e-30, 1e-10, 1.0, 1e30, f32::MAX];
    let ws = [0.0f32, 1e-45, 1e-38, 1e-10, 0.7, 1.0, 3.0, 1e30, f32::MAX];
    for &x in &xs {
        for x in [x, -x] {
            for &s in &sig {
                for &a in &ws {
                    for &b in &ws {
                        let c = cdf_gauss_box2_f32(x, s, a, b);
                        assert!(
                            c.is_finite() && (-1e-6..=1.0 + 1e-6).contains(&c),
                            "f32 C({x}, {s}, {a}, {b}) = {c}"
                        );
                        let c = cdf_gauss_box2(x as f64, s as f64, a as f64, b as f64);
                        assert!(
                            c.is_finite() && (0.0..=1.0).contains(&c),
                            "f64 C({x}, {s}, {a}, {b}) = {c}"
                        );
                    }
                }
            }
        }
    }
    // sigma = 0 is the trapezoid (a box for b = 0, a step for a = b = 0).
    assert_eq!(cdf_gauss_box2(0.25, 0.0, 1.0, 0.0), 0.75);
    assert_eq!(cdf_gauss_box2(1e-3, 0.0, 0.0, 0.0), 1.0);
    assert_eq!(cdf_gauss_box2_f32(0.25, 0.0, 1.0, 0.0), 0.75);
}

#[test]
fn wgsl_parses_and_validates() {
    let src = crate::render::shaders::PULSE;
    let module = naga::front::wgsl::parse_str(src).expect("pulse.wgsl parses");
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .expect("pulse.wgsl validates");
    // It needs no optional capability either.
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .expect("pulse.wgsl validates without capabilities");
    assert!(module
        .functions
        .iter()
        .any(|(_, f)| f.name.as_deref() == Some("pulse_cdf_gauss_box2")));
}

// --- sampled pulse ---

/// Brute force for a sampled pulse: the mean over u, v of P(x - u - v), split at every
/// knot of the integrand so that GL is exact on each piece.
fn brute_sampled(sp: &SampledPulse, x: f64, a: f64, b: f64) -> f64 {
    let knots: Vec<f64> = (0..sp.p.len()).map(|j| sp.knot(j)).collect();
    let inner = |u: f64| -> f64 {
        let c = x - u;
        if b == 0.0 {
            return sp.pulse_cdf(c);
        }
        let spl: Vec<f64> = knots.iter().map(|k| c - k).collect();
        split_integral(-0.5 * b, 0.5 * b, &spl, |v| sp.pulse_cdf(c - v)) / b
    };
    if a == 0.0 {
        return inner(0.0);
    }
    let mut spl: Vec<f64> = knots.iter().map(|k| x - k).collect();
    spl.extend(knots.iter().map(|k| x - k + 0.5 * b));
    spl.extend(knots.iter().map(|k| x - k - 0.5 * b));
    split_integral(-0.5 * a, 0.5 * a, &spl, inner) / a
}

const SAMPLES: [f64; 7] = [0.3, 1.0, 2.5, 0.0, 1.7, 4.0, 0.6];

#[test]
fn sampled_exact_against_brute_force() {
    let dt = 0.37;
    let sp = SampledPulse::with_origin(&SAMPLES, dt, 3.1).unwrap();
    let k = LOCAL_KNOTS * dt;
    let widths = [
        0.0,
        1e-9 * dt,
        0.3 * dt,
        3.0 * dt,
        k * (1.0 - 1e-9),
        k * (1.0 + 1e-9),
        30.0 * dt,
        1e4 * dt,
    ];
    let mut worst = 0.0f64;
    for a in widths {
        for b in widths {
            let h1 = 0.5 * (a + b);
            for i in 0..=60 {
                let x = 3.1 - h1 - 2.0 * dt + (2.0 * h1 + 10.0 * dt) * i as f64 / 60.0;
                let c = sp.cdf_box2(x, a, b);
                let r = brute_sampled(&sp, x, a, b);
                worst = worst.max((c - r).abs());
                assert!((c - r).abs() < 1e-14, "a {a} b {b} x {x}: {c} vs {r}");
            }
        }
    }
    eprintln!("sampled vs brute force: {worst:.2e}");
}

#[test]
fn sampled_continuous_across_regime_switches() {
    let dt = 0.37;
    let sp = SampledPulse::with_origin(&SAMPLES, dt, -1.0).unwrap();
    let k = LOCAL_KNOTS * dt;
    let below = f64::from_bits(k.to_bits() - 1);
    let mut worst = 0.0f64;
    for (a_lo, a_hi, b_lo, b_hi) in [
        (below, k, 0.0, 0.0),
        (below, k, 0.5 * dt, 0.5 * dt),
        (below, k, below, below),
        (50.0 * dt, 50.0 * dt, below, k),
        (k, k, below, k),
    ] {
        for i in 0..=400 {
            let x = -1.0 - 10.0 * k + 20.0 * k * i as f64 / 400.0;
            let j = (sp.cdf_box2(x, a_lo, b_lo) - sp.cdf_box2(x, a_hi, b_hi)).abs();
            worst = worst.max(j);
        }
    }
    eprintln!("sampled: largest jump at the switches {worst:.2e}");
    assert!(worst < 3e-15, "{worst:e}");
}

#[test]
fn sampled_fine_gaussian_reproduces_gauss() {
    // Gaussian sampled every sigma/50 over +-10 sigma: the piecewise-linear interpolation
    // changes the CDF by about dt^2/12 max|p'| = 8e-6 (sigma units), the bound checked.
    let sigma = 0.8;
    let dt = sigma / 50.0;
    let samples: Vec<f64> = (-500..=500)
        .map(|i| norm_pdf(i as f64 * dt / sigma))
        .collect();
    let sp = SampledPulse::new(&samples, dt).unwrap();
    assert!(sp.centroid().abs() < 1e-13);
    assert!((sp.variance() / (sigma * sigma) - 1.0).abs() < 1e-3);
    let mut worst = 0.0f64;
    for (a, b) in REGIMES {
        let (a, b) = (a * sigma, b * sigma);
        for x in x_grid(sigma, a, b, 81) {
            let e = (sp.cdf_box2(x, a, b) - cdf_gauss_box2(x, sigma, a, b)).abs();
            worst = worst.max(e);
        }
    }
    eprintln!("fine sampled Gaussian vs closed form: {worst:.2e}");
    assert!(worst < 1e-5, "{worst:e}");
}

#[test]
fn sampled_bin_weights_sum_to_one_and_errors() {
    let sp = SampledPulse::new(&SAMPLES, 0.25).unwrap();
    let edges: Vec<f64> = (0..=400).map(|i| -50.0 + 0.25 * i as f64).collect();
    for (a, b) in [(0.0, 0.0), (0.1, 0.0), (1.0, 0.3), (10.0, 0.2), (30.0, 7.0)] {
        let mut out = vec![0.0; edges.len() - 1];
        sp.bin_weights(0.0, a, b, &edges, &mut out);
        let sum: f64 = out.iter().sum();
        assert!((sum - 1.0).abs() < 1e-13, "sum {sum}");
        assert!(out.iter().all(|&w| w > -1e-15));
    }
    assert!(SampledPulse::new(&[], 1.0).is_err());
    assert!(SampledPulse::new(&[0.0, 0.0], 1.0).is_err());
    assert!(SampledPulse::new(&[1.0, -1.0], 1.0).is_err());
    assert!(SampledPulse::new(&[1.0], 0.0).is_err());
    assert!(SampledPulse::new(&[1.0, f64::NAN], 1.0).is_err());
    // One sample: a hat of half-width dt.
    let hat = SampledPulse::new(&[2.0], 1.0).unwrap();
    assert!((hat.pulse_cdf(-0.5) - 0.125).abs() < 1e-15);
    assert!((hat.variance() - 1.0 / 6.0).abs() < 1e-15);
}

/// The interpolated normal CDF of the paths' deposits against `norm_cdf` (erfc): within
/// 2e-12 (the Hermite bound, 1.8e-12) at 256 nodes per standard deviation over 10^5 points
/// of its table and beyond, where it is `norm_cdf` itself; coarser tables err more (the
/// test can fail).
#[test]
fn interpolated_normal_cdf_matches_erfc() {
    let t = NormCdfTable::new(5.0, 256);
    let err = |t: &NormCdfTable| {
        (0..=100_000)
            .map(|k| -6.0 + 12.0 * k as f64 / 100_000.0)
            .map(|y| (t.eval(y) - norm_cdf(y)).abs())
            .fold(0.0f64, f64::max)
    };
    let e = err(&t);
    assert!(e < 2e-12, "{e}");
    assert_eq!(t.eval(7.0), norm_cdf(7.0));
    assert!(err(&NormCdfTable::new(5.0, 16)) > 1e-8);
}
