// ---- terms evaluated in the kernel (IN_SHADER; twins: SingleParams::eval and
// DepolarizingParams::eval in src/brdf/table.rs, through BrdfTable::eval_masked) ----
// The material's words at `blk` (SingleParams::words): kind 0, distribution kind and m or
// alpha, perfect-conductor flag, n - 1 and k, the masking-excess table (scale, correlation
// kind, intervals, values), then the calibration table in the same z (intervals, 0 for
// none, and values; G s(theta_i) s(theta_o): Surface::calibrate_masking). All vectors are in the telescope frame.
// Uses the shade kernel's `tables` binding and ELEMENT_MASK, table.wgsl (z_of, table_1d)
// and microfacet.wgsl.

// The masking excess N at (cos, sin) from the material's 1D table.
fn excess(blk: u32, c: f32, s: f32) -> f32 {
    let z = z_of(tables[blk + 6u], c, s);
    return max(table_1d(blk + 9u, bitcast<u32>(tables[blk + 8u]), z), 0.0);
}

// What the in-kernel terms share at a shaded point, computed once (shade_at): the cosines
// of wi and wo to the normal, n x wi and n x wo (their lengths the sines: accurate near the
// normal, where 1 - cos^2 is not), and the bisector h with its cos and sin^2 to n.
struct Local {
    ci: f32,
    co: f32,
    ui: vec3<f32>,
    uo: vec3<f32>,
    si: f32,
    so: f32,
    h: vec3<f32>,
    cos_h: f32,
    sin2_h: f32,
}

// Adds the single term times cos(theta_i), M cos_i = D F (G / cos_o) / 4 (in the beam
// bases x_in, x_out; y = k x x), at the point g (Local) for wi, wo above it, to acc (the
// elements in ELEMENT_MASK). G / cos_o is formed without dividing by cos_i, so that it
// stays finite at grazing incidence: (1 - f) P_i Q_o + f min(P_i, P_o) / cos_o, Q = P / cos.
fn add_single_in_kernel(blk: u32, g: Local, wi: vec3<f32>, wo: vec3<f32>, x_in: vec3<f32>,
                        x_out: vec3<f32>, acc: ptr<function, array<f32, 16>>) {
    let d = ndf(bitcast<u32>(tables[blk + 1u]), tables[blk + 2u], g.cos_h, g.sin2_h);
    if (!(d > 0.0)) {
        return;
    }
    let h = g.h;
    let ci = g.ci;
    let co = g.co;
    let si = g.si;
    let so = g.so;
    let qi = 1.0 / (ci + excess(blk, ci, si));
    let qo = 1.0 / (co + excess(blk, co, so));
    let corr = bitcast<u32>(tables[blk + 7u]);
    var f = 0.0;
    if (corr != 0u) {
        f = 1.0;
        if (si > 0.0 && so > 0.0) {
            let cos_phi = clamp(dot(g.ui, g.uo) / (si * so), -1.0, 1.0);
            if (corr == 1u) {
                f = sqrt(max(0.5 * (1.0 + cos_phi), 0.0));
            } else {
                let phi = acos(cos_phi);
                f = exp(-7.3 * phi * phi);
            }
        }
    }
    let p_i = ci * qi;
    let p_o = co * qo;
    var g_ci = (1.0 - f) * p_i * qo + f * select(qo, p_i / co, p_i <= p_o);
    let cal = blk + 10u + bitcast<u32>(tables[blk + 8u]);
    let n_cal = bitcast<u32>(tables[cal]);
    if (n_cal > 0u) {
        let scale = tables[blk + 6u];
        g_ci *= table_1d(cal + 1u, n_cal, z_of(scale, ci, si))
            * table_1d(cal + 1u, n_cal, z_of(scale, co, so));
    }
    let r = fresnel_rs_rp(clamp(dot(wi, h), 0.0, 1.0), tables[blk + 4u], tables[blk + 5u],
                          bitcast<u32>(tables[blk + 3u]) != 0u);
    let rs = r.xy;
    let rp = r.zw;
    // the facet's s/p basis (brdf::single::facet_sp_basis): s = normalize(k_in x h)
    let k_in = -wi;
    let y_in = cross(k_in, x_in);
    let y_out = cross(wo, x_out);
    let c = cross(k_in, h);
    let sv = select(x_in, normalize(c), dot(c, c) > 1e-12);
    let p_in = cross(k_in, sv);
    let p_out = cross(wo, sv);
    let sxi = dot(sv, x_in);
    let syi = dot(sv, y_in);
    let pxi = dot(p_in, x_in);
    let pyi = dot(p_in, y_in);
    let sxo = dot(sv, x_out);
    let syo = dot(sv, y_out);
    let pxo = dot(p_out, x_out);
    let pyo = dot(p_out, y_out);
    // Jones columns c0 = (ja, jb), c1 = (jc, jd)
    let ja = rs * (sxo * sxi) + rp * (pxo * pxi);
    let jc = rs * (sxo * syi) + rp * (pxo * pyi);
    let jb = rs * (syo * sxi) + rp * (pyo * pxi);
    let jd = rs * (syo * syi) + rp * (pyo * pyi);
    // Jones to Mueller (optics::mueller::jones_to_mueller)
    let aa = dot(ja, ja);
    let bb = dot(jb, jb);
    let cc = dot(jc, jc);
    let dd = dot(jd, jd);
    let conj = vec2<f32>(1.0, -1.0);
    let ab = cmul(ja, jb * conj);
    let cd = cmul(jc, jd * conj);
    let ad = cmul(ja, jd * conj);
    let cb = cmul(jc, jb * conj);
    let ac = cmul(ja, jc * conj);
    let bd = cmul(jb, jd * conj);
    let diff = ad - cb;
    // H_j as (h00, h11, h01) for the four columns
    let h00 = vec4<f32>(aa + cc, aa - cc, 2.0 * ac.x, -2.0 * ac.y);
    let h11 = vec4<f32>(bb + dd, bb - dd, 2.0 * bd.x, -2.0 * bd.y);
    let sum = ad + cb;
    let h01_re = vec4<f32>(ab.x + cd.x, ab.x - cd.x, sum.x, -diff.y);
    let h01_im = vec4<f32>(ab.y + cd.y, ab.y - cd.y, sum.y, diff.x);
    let scale = 0.25 * d * g_ci;
    var m: array<f32, 16>;
    for (var j = 0u; j < 4u; j++) {
        m[j] = 0.5 * (h00[j] + h11[j]);
        m[4u + j] = 0.5 * (h00[j] - h11[j]);
        m[8u + j] = h01_re[j];
        m[12u + j] = h01_im[j];
    }
    for (var e = 0u; e < 16u; e++) {
        if (e == 0u || ((ELEMENT_MASK >> e) & 1u) != 0u) {
            (*acc)[e] += scale * m[e];
        }
    }
}

// Adds the multiple + diffuse terms times cos(theta_i) to acc[0] (M00 only; twin:
// DepolarizingParams::eval in src/brdf/table.rs): per term c (1 - E(theta_i)) (1 - E(theta_o))
// from the material's albedo table E. Words at `blk` (DepolarizingParams::words): kind 1,
// the z scale, the number of terms, then per term c, s_f (0: E in z; else in
// zeta = (z + z_1 + z_sf) / 3, material.rs zeta_of), intervals, values.
fn add_depolarizing_in_kernel(blk: u32, g: Local, acc: ptr<function, array<f32, 16>>) {
    let ci = g.ci;
    let co = g.co;
    let si = g.si;
    let so = g.so;
    let scale = tables[blk + 1u];
    let zi = z_of(scale, ci, si);
    let zo = z_of(scale, co, so);
    var o = blk + 3u;
    var v = 0.0;
    for (var k = 0u; k < bitcast<u32>(tables[blk + 2u]); k++) {
        let c = tables[o];
        let sf = tables[o + 1u];
        let nz = bitcast<u32>(tables[o + 2u]);
        var xi = zi;
        var xo = zo;
        if (sf > 0.0) {
            xi = (zi + z_of(1.0, ci, si) + z_of(sf, ci, si)) / 3.0;
            xo = (zo + z_of(1.0, co, so) + z_of(sf, co, so)) / 3.0;
        }
        let a = max(1.0 - table_1d(o + 3u, nz, xi), 0.0);
        let b = max(1.0 - table_1d(o + 3u, nz, xo), 0.0);
        v += c * a * b;
        o += 4u + nz;
    }
    (*acc)[0] += v * ci;
}
