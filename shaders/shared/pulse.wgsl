// Pulse (Gaussian) convolved with a pixel's trapezoidal range footprint: its CDF.
//
// A line-by-line port of the f32 twin `cdf_gauss_box2_f32` in src/render/pulse.rs (the f32
// instance of `cdf_gauss_box2_generic`: same constants, same branches, same order of
// operations); the formulas and the measured error are documented there. Plain functions only (no bindings, no entry point; the constants
// are checked against the Rust ones by a test in src/render/shaders.rs): shade.wgsl includes
// this file (`//#include "shared/pulse.wgsl"`) and calls
//
//   pulse_cdf_gauss_box2(x, sigma, a, b)
//
// with x = bin edge - pixel-centre range, sigma the Gaussian range standard deviation and
// a = |gx| delta, b = |gy| delta the range spreads across the pixel (all in range units).
// The weight of bin [e_k, e_{k+1}) is pulse_cdf_gauss_box2(e_{k+1} - r0, ...) -
// pulse_cdf_gauss_box2(e_k - r0, ...). Never returns NaN or inf for finite inputs
// (sigma = 0, a = b = 0 and |x| up to f32 max included).

const PULSE_ALPHA: f32 = 0.5;
const PULSE_BETA: f32 = 1.0;
const PULSE_INV_SQRT_2PI: f32 = 0.3989423;
const PULSE_FRAC_1_SQRT_2: f32 = 0.70710677;
const PULSE_T_CLAMP: f32 = 40.0;

// erfc, Numerical Recipes' erfcc: fractional error < 1.2e-7 for all x.
fn pulse_erfc(x: f32) -> f32 {
    let z = abs(x);
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -1.2655122
        + t * (1.0000237
            + t * (0.37409195
                + t * (0.09678418
                    + t * (-0.18628806
                        + t * (0.27886808
                            + t * (-1.135204
                                + t * (1.4885159
                                    + t * (-0.82215226 + t * 0.17087276))))))));
    let r = t * exp(-z * z + poly);
    return select(2.0 - r, r, x >= 0.0);
}

fn pulse_norm_cdf(x: f32) -> f32 {
    return 0.5 * pulse_erfc(-x * PULSE_FRAC_1_SQRT_2);
}

fn pulse_norm_pdf(x: f32) -> f32 {
    return PULSE_INV_SQRT_2PI * exp(-0.5 * x * x);
}

// Q(t) = Psi2(-|t|), Psi2 the second antiderivative of Phi.
fn pulse_q(t: f32) -> f32 {
    let y = min(abs(t), PULSE_T_CLAMP);
    return 0.5 * ((y * y + 1.0) * pulse_norm_cdf(-y) - y * pulse_norm_pdf(y));
}

// E1(t) = Psi1(t) - max(t, 0).
fn pulse_e1(t: f32) -> f32 {
    let y = min(abs(t), PULSE_T_CLAMP);
    return pulse_norm_pdf(y) - y * pulse_norm_cdf(-y);
}

// E2(t) = Psi2(t) - max(t, 0)^2 / 2.
fn pulse_e2(t: f32) -> f32 {
    if (t <= 0.0) {
        return pulse_q(t);
    }
    return 0.5 - pulse_q(t);
}

// CDF of the trapezoid box_a * box_b, a >= b > 0.
fn pulse_trap(y: f32, a: f32, b: f32) -> f32 {
    let h1 = 0.5 * (a + b);
    let h2 = 0.5 * (a - b);
    if (y <= -h1) {
        return 0.0;
    } else if (y <= -h2) {
        let z = y + h1;
        return z * z / (2.0 * a * b);
    } else if (y <= h2) {
        return (y + 0.5 * a) / a;
    } else if (y < h1) {
        let z = h1 - y;
        return 1.0 - z * z / (2.0 * a * b);
    }
    return 1.0;
}

// He_0..He_9 (probabilists' Hermite polynomials) at y.
fn pulse_hermite(y: f32) -> array<f32, 10> {
    var he: array<f32, 10>;
    he[0] = 1.0;
    he[1] = y;
    for (var n: i32 = 1; n < 9; n++) {
        he[n + 1] = y * he[n] - f32(n) * he[n - 1];
    }
    return he;
}

// mu_{2k}(w) = (w/2)^{2k} / (2k+1), k = 0..5 (even moments of a box of width w).
fn pulse_box_moments(w: f32) -> array<f32, 6> {
    let u = 0.25 * w * w;
    var m: array<f32, 6>;
    m[0] = 1.0;
    var p: f32 = 1.0;
    for (var k: i32 = 1; k < 6; k++) {
        p *= u;
        m[k] = p / f32(2 * k + 1);
    }
    return m;
}

// 1/(2k)!, k = 0..5. (hp, hm are `var` so that runtime indexing works on every backend.)
const PULSE_INV_FACT_EVEN = array<f32, 6>(1.0, 0.5, 0.041666668, 0.0013888889, 2.4801588e-5, 2.755732e-7);

// C in sigma units, aa >= bb >= 0.
fn pulse_cdf_std(y_in: f32, aa: f32, bb: f32) -> f32 {
    if (aa < PULSE_ALPHA) {
        // Both widths small: moment series around Phi.
        let y = clamp(y_in, -PULSE_T_CLAMP, PULSE_T_CLAMP);
        let ma = pulse_box_moments(aa);
        let mb = pulse_box_moments(bb);
        let m2 = ma[1] + mb[1];
        let m4 = ma[2] + 6.0 * ma[1] * mb[1] + mb[2];
        let m6 = ma[3] + 15.0 * (ma[2] * mb[1] + ma[1] * mb[2]) + mb[3];
        let m8 = ma[4] + 28.0 * (ma[3] * mb[1] + ma[1] * mb[3]) + 70.0 * ma[2] * mb[2] + mb[4];
        let m10 = ma[5]
            + 45.0 * (ma[4] * mb[1] + ma[1] * mb[4])
            + 210.0 * (ma[3] * mb[2] + ma[2] * mb[3])
            + mb[5];
        let he = pulse_hermite(y);
        let s = m2 * PULSE_INV_FACT_EVEN[1] * he[1]
            + m4 * PULSE_INV_FACT_EVEN[2] * he[3]
            + m6 * PULSE_INV_FACT_EVEN[3] * he[5]
            + m8 * PULSE_INV_FACT_EVEN[4] * he[7]
            + m10 * PULSE_INV_FACT_EVEN[5] * he[9];
        return pulse_norm_cdf(y) - pulse_norm_pdf(y) * s;
    } else if (bb < PULSE_BETA) {
        // One box exactly, moment series in the small width bb.
        let yp = y_in + 0.5 * aa;
        let ym = y_in - 0.5 * aa;
        let fa = clamp(yp / aa, 0.0, 1.0) + (pulse_e1(yp) - pulse_e1(ym)) / aa;
        let mb = pulse_box_moments(bb);
        let tp = clamp(yp, -PULSE_T_CLAMP, PULSE_T_CLAMP);
        let tm = clamp(ym, -PULSE_T_CLAMP, PULSE_T_CLAMP);
        var hp = pulse_hermite(tp);
        var hm = pulse_hermite(tm);
        let pp = pulse_norm_pdf(tp);
        let pm = pulse_norm_pdf(tm);
        var s: f32 = 0.0;
        for (var k: i32 = 1; k <= 5; k++) {
            s += mb[k] * PULSE_INV_FACT_EVEN[k] * (hp[2 * k - 2] * pp - hm[2 * k - 2] * pm);
        }
        return fa + s / aa;
    }
    // Both widths large: trapezoid CDF + bounded second difference.
    let h1 = 0.5 * (aa + bb);
    let h2 = 0.5 * (aa - bb);
    let d = (pulse_e2(y_in + h1) - pulse_e2(y_in + h2)) - (pulse_e2(y_in - h2) - pulse_e2(y_in - h1));
    return pulse_trap(y_in, aa, bb) + d / (aa * bb);
}

// CDF at x of a centred Gaussian pulse (standard deviation sigma) convolved with boxes of
// widths a and b; all in range units, signs of a and b ignored.
fn pulse_cdf_gauss_box2(x_in: f32, sigma: f32, a_in: f32, b_in: f32) -> f32 {
    let x = clamp(x_in, -1e30, 1e30);
    let a = min(abs(a_in), 1e30);
    let b = min(abs(b_in), 1e30);
    let m = max(max(abs(x), a), b);
    let s = max(max(sigma, 1e-9 * m), 1e-30);
    if (a >= b) {
        return pulse_cdf_std(x / s, a / s, b / s);
    }
    return pulse_cdf_std(x / s, b / s, a / s);
}
