// Microfacet pieces of the in-kernel single term: the Fresnel amplitudes (optics::fresnel)
// and the distribution D(h) (microfacet::Distribution::d). Uses complex.wgsl, PI and
// LN_FLOOR_F32.

// (rs, rp) at incidence cosine c for eta = 1 + nm1 + i k (optics::fresnel): the
// cancellation-free numerators, eta^2 - 1 = (eta - 1)(eta + 1).
fn fresnel_rs_rp(c: f32, nm1: f32, k: f32, pec: bool) -> vec4<f32> {
    if (pec) {
        return vec4<f32>(-1.0, 0.0, 1.0, 0.0);
    }
    let e2m1 = cmul(vec2<f32>(nm1, k), vec2<f32>(nm1 + 2.0, k));
    let w = csqrt(e2m1 + vec2<f32>(c * c, 0.0));
    let ds = vec2<f32>(c, 0.0) + w;
    let dp = (e2m1 + vec2<f32>(1.0, 0.0)) * c + w;
    if (all(ds == vec2<f32>(0.0)) || all(dp == vec2<f32>(0.0))) {
        return vec4<f32>(0.0);
    }
    let rs = -cdiv(e2m1, cmul(ds, ds));
    let rp = cdiv(cmul(e2m1, (e2m1 + vec2<f32>(2.0, 0.0)) * (c * c) - vec2<f32>(1.0, 0.0)),
                  cmul(dp, dp));
    return vec4<f32>(rs, rp);
}

// D(h) from cos(theta_h) > 0 and sin^2(theta_h) (microfacet::Distribution::d).
fn ndf(kind: u32, r: f32, cos_h: f32, sin2_h: f32) -> f32 {
    if (cos_h <= 0.0) {
        return 0.0;
    }
    if (kind == 0u) { // Blinn-Phong, exponent r
        if (r == 0.0) {
            return 1.0 / PI;
        }
        // ln cos = ln(1 - sin^2) / 2 by its series where cos is near 1
        var ln_cos: f32;
        if (sin2_h < 0.01) {
            let x = sin2_h;
            ln_cos = -0.5 * x * (1.0 + x * (0.5 + x * (0.33333334 + x * 0.25)));
        } else {
            ln_cos = log(cos_h);
        }
        // below f32's normal range: zero, as Beckmann's (a floor would light pixels the f64
        // twin leaves dark)
        let e = r * ln_cos;
        if (e < LN_FLOOR_F32) {
            return 0.0;
        }
        return (r + 2.0) / (2.0 * PI) * exp(e);
    }
    let a2 = r * r;
    let c2 = cos_h * cos_h;
    if (kind == 1u) { // Beckmann
        let e = -sin2_h / (c2 * a2);
        if (e < LN_FLOOR_F32) {
            return 0.0;
        }
        return exp(e) / (PI * a2 * c2 * c2);
    }
    let t = a2 * c2 + sin2_h; // GGX
    return a2 / (PI * t * t);
}
