// Shading and accumulation: one invocation per pixel of one attitude of a chunk.
//
// For the pixel's visible triangle (from the visibility pass) it intersects the pixel-centre
// ray, takes the (optionally interpolated) normal facing the receiver, looks the material's
// Mueller BRDF up in its table (bisector frame, see src/brdf/table.rs) or, for the terms
// the material has no table of (IN_SHADER, Lidar(brdf="shader")), evaluates them here in
// the same frame, rotates it to the telescope bases and scales it to the differential
// lidar cross-section
// dsigma = 4 pi f cos(theta_i) delta^2 (m^2; delta^2 the pixel's projected area). Then,
// each behind an override constant, it writes the image channels and the range, adds the
// pixel to the range-resolved profile with its sub-pixel range extent and the pulse
// (pulse.wgsl, concatenated before this file), and adds the workgroup's sum to the total.
// Profile and total are accumulated in 64-bit fixed point (two u32 words, integer atomics):
// each addition is rounded to the nearest quantum (2^-40 of the largest value a pixel could
// take, see render() in src/render/gpu.rs), and the sums are then exact and
// order-independent, so results do not depend on scheduling.
// Conventions: src/render/mod.rs. CPU twin: render::twin::shade_pixel.
//
// Transmitter cast shadows (SHADOWS: set when the bistatic angle beta > 0; monostatic the
// receiver's visibility already implies illumination and the test is compiled out). A
// second raster pass wrote the triangle seen from the transmitter at each texel centre
// (`tx_ids`: the same orthographic square [-ext, ext]^2 at `tx_width` texels a side, twice
// the receiver's up to 4096 (src/render/gpu.rs, transmitter_map_width); rotation
// R_tx = R_y(-beta) R, so wi maps to +z). A point p (the pixel's shaded point on its
// visible triangle T, tested only when cos_i > 0 and cos_o > 0) is projected to the
// transmitter frame, q = R_y(-beta) p, and the distinct triangles U != T of the 3x3 texels
// around q are candidates. p is
//   0. SHADOWED if T's geometric normal (on the side the receiver sees) does not face the
//      transmitter: the facet itself is in the way (with smooth shading the interpolated
//      normal may still face it, just behind the terminator);
//   1. SHADOWED if a candidate covers q (closed point-in-triangle test in the transmitter
//      frame, on its own vertices) and lies closer to the transmitter than p there by more
//      than eps_z = 1e-5 ext: exact, no depth-map bias, sharp shadow edges;
//   2. else SHADOWED if T is none of the nine texels' triangles and every one of the nine
//      is a candidate whose plane, extrapolated to q, is closer than p by more than
//      eps_z + 2.5 t |g_U - g_T| (t the texel side, g the depth gradients of U and of T's
//      plane in the transmitter frame: a texel centre in U lies within 2.12 t of q, so two
//      planes of one smooth surface differ by no more at q). This catches q deep inside an
//      occluding surface whose triangle at q covers no texel centre (a fine tessellation
//      seen obliquely, every triangle a sliver);
//   3. else LIT.
// A shadowed pixel contributes nothing (zero Mueller matrix, no profile or total) but stays
// covered and keeps its range: the receiver does see the surface there.
// Limits: occluders thinner than about a texel (wires, the rims of thin plates seen edge-on)
// may cover no texel centre near q and are then missed at q (rule 1), and rule 2 needs
// all nine texels inside the occluder, so such misses are light leaking through within a
// texel of a shadow's edge or along thin shadows; occluders within eps_z of p in depth
// are ignored; shading normals do not enter (the test is geometric).
// CPU twin: render::twin::shadowed (exact f64 ray casting, independent of this rule).

override CHANNELS: u32 = 16u;      // 16: Mueller, 4: Stokes (M s_tx), 1: intensity (M s_tx)_0
override WRITE_IMAGE: bool = true;
override WRITE_RANGE: bool = true;
override WRITE_PROFILE: bool = true;
override WRITE_TOTAL: bool = true;
// Footprint mode (sampled pulses, whose profile is accumulated on the host): the range
// buffer holds (r0, a, b) per pixel, the range and the widths of its footprint.
override WRITE_FOOTPRINT: bool = false;
override SHADOWS: bool = false;    // transmitter cast shadows (beta > 0), see above
// Mueller elements to look up (bit 4 i + j: M_ij in the table frame); the others are left
// zero. Set from what the output needs (SensorSetup::element_mask in src/render/gpu.rs:
// an unpolarized transmitter's intensity needs M00 alone).
override ELEMENT_MASK: u32 = 0xffffu;
// Visibility samples per pixel K (SensorSetup::samples; a constant so that K = 1 compiles
// to the single-sample kernel).
override SAMPLES: u32 = 1u;
// Analytic coverage (SensorSetup::analytic; SAMPLES = 1): the pixel's area is shared among
// the triangles seen at the centres of its 3x3 neighbourhood by exact polygon clipping in
// depth order (see cs_main and coverage_parts).
override COVERAGE: bool = false;
// Some material's single or multiple + diffuse terms are evaluated here instead of looked
// up (BrdfTableOptions::in_shader; such a part's n_psi header word is SHADER_PART):
// compiled out when no material needs it.
override IN_SHADER: bool = false;

const PI: f32 = 3.14159265358979;
const MAX_PARTS: u32 = 3u;
const HEADER_WORDS: u32 = 12u;
const LN_FLOOR_F32: f32 = -87.0;
const SHADOW_EPS: f32 = 1e-5;      // cast shadows: eps_z = SHADOW_EPS ext
const SHADER_PART: u32 = 0xffffffffu;

struct Params {
    width: u32,
    height: u32,
    n_bins: u32,
    n_tri: u32,
    ext: f32,          // half-width of the image square (m)
    pix: f32,          // pixel side delta (m)
    r_min: f32,        // first bin edge (m)
    bin_width: f32,    // m
    wi: vec4<f32>,     // toward the transmitter (telescope frame)
    wo: vec4<f32>,     // toward the receiver (= +z)
    s_tx: vec4<f32>,   // transmitted Stokes vector (CHANNELS < 16)
    sigma: f32,        // pulse standard deviation in range units (m)
    support: f32,      // pulse half support in range units (m)
    fix_scale: f32,    // fixed-point units per m^2 (a pixel's |value| is clamped to 2^61 / (fix_scale n_pix))
    has_normals: u32,
    beta: f32,         // bistatic angle (rad)
    max_extent: f32,   // cap on the sub-pixel range widths (m)
    tx_width: u32,     // side of the transmitter's id map (texels; SHADOWS only)
    closed: u32,       // 1: closed mesh, back faces culled (Mesh::closed)
    offsets: array<vec4<f32>, 16>, // per visibility sample (u, v, dc, dr): its offset in the
                                   // pixel (from its top-left corner) and, SAMPLES >= 4, the
                                   // tile texel holding it relative to the pixel's (sample_id)
}

@group(0) @binding(0) var tri_ids: texture_2d_array<u32>;
@group(0) @binding(1) var<storage, read> geometry: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> rotations: array<mat3x3<f32>>;
@group(0) @binding(3) var<storage, read> tables: array<f32>;
@group(0) @binding(4) var<uniform> params: Params;
@group(0) @binding(5) var<storage, read_write> image: array<f32>;
@group(0) @binding(6) var<storage, read_write> range_img: array<f32>;
@group(0) @binding(7) var<storage, read_write> profile: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read_write> total: array<atomic<u32>>;
// triangle id + 1 seen from the transmitter, tx_width^2 per layer (SHADOWS only;
// monostatic, tri_ids is bound here and never read)
@group(0) @binding(9) var tx_ids: texture_2d_array<u32>;
// SAMPLES >= 4: the receiver's triangle ids + 1 from 4x multisampled tiles of
// (width + 2)^2 texels, one per raster pass of each attitude (gather.wgsl); tri_ids is then
// a placeholder, as this is otherwise
@group(0) @binding(10) var<storage, read> sample_ids: array<u32>;

var<workgroup> wg_sum: array<f32, 1024>;

// ---- table lookup (port of src/brdf/table.rs) ----

fn catmull_rom(p0: f32, p1: f32, p2: f32, p3: f32, t: f32) -> f32 {
    let t2 = t * t;
    let t3 = t2 * t;
    return 0.5 * ((2.0 * p1) + (-p0 + p2) * t + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
        + (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * t3);
}

fn tval(base: u32, row: u32, node: u32, n_z: u32, e: u32) -> f32 {
    return tables[base + (row * (n_z + 1u) + node) * 16u + e];
}

// Sign of element e under the mirror relation M(-psi) = D M(psi) D, D = diag(1, 1, -1, -1).
fn mirror_sign(e: u32) -> f32 {
    let di = select(1.0, -1.0, (e / 4u) >= 2u);
    let dj = select(1.0, -1.0, (e % 4u) >= 2u);
    return di * dj;
}

// Catmull-Rom on interval i of n, nodes q0 = v[max(i, 1) - 1], p1 = v[i], p2 = v[i + 1],
// q3 = v[min(i + 2, n)], with the end ghost nodes by quadratic extrapolation (v[-1] =
// 3 v[0] - 3 v[1] + v[2], v[n + 1] = 3 v[n] - 3 v[n - 1] + v[n - 2]; table.rs
// catmull_rom_ends).
fn catmull_rom_ends(q0: f32, p1: f32, p2: f32, q3: f32, i: u32, n: u32, t: f32) -> f32 {
    let p0 = select(q0, 3.0 * p1 - 3.0 * p2 + q3, i == 0u);
    let p3 = select(q3, 3.0 * p2 - 3.0 * p1 + q0, i + 2u > n);
    return catmull_rom(p0, p1, p2, p3, t);
}

// Catmull-Rom in z along one psi row, element e.
fn interp_z(base: u32, row: u32, n_z: u32, i: u32, t: f32, e: u32) -> f32 {
    let p1 = tval(base, row, i, n_z, e);
    let p2 = tval(base, row, i + 1u, n_z, e);
    let q0 = tval(base, row, max(i, 1u) - 1u, n_z, e);
    let q3 = tval(base, row, min(i + 2u, n_z), n_z, e);
    var v = catmull_rom_ends(q0, p1, p2, q3, i, n_z, t);
    if (e == 0u) {
        v = clamp(v, min(p1, p2), max(p1, p2));
    }
    return v;
}

// psi row index with mirror ghosts: returns (row, sign flag) for virtual row k in [-1, n+1].
fn psi_row(k: i32, n_psi: u32) -> vec2<u32> {
    if (k < 0) {
        return vec2<u32>(u32(-k), 1u);
    }
    if (k > i32(n_psi)) {
        return vec2<u32>(u32(2 * i32(n_psi) - k), 1u);
    }
    return vec2<u32>(u32(k), 0u);
}

// Adds part `p` of material `m` at (z, psi) to acc (Mueller, row-major).
// Adds part `p` times `w` (cos(theta_i), or cos(theta_i) / cos(theta) for a part whose
// nodes hold M cos(theta): negative scale in the header).
fn add_part(m: u32, p: u32, z: f32, psi: f32, w: f32, acc: ptr<function, array<f32, 16>>) {
    let h = m * HEADER_WORDS + p * 4u;
    let base = bitcast<u32>(tables[h]);
    let n_z = bitcast<u32>(tables[h + 1u]);
    let n_psi = bitcast<u32>(tables[h + 2u]);
    if (n_z == 0u) {
        return;
    }
    let x = clamp(z, 0.0, 1.0) * f32(n_z);
    let i = min(u32(x), n_z - 1u);
    let t = x - f32(i);
    var vals: array<f32, 16>;
    if (n_psi == 0u) {
        for (var e = 0u; e < 16u; e++) {
            if (((ELEMENT_MASK >> e) & 1u) == 0u) {
                continue;
            }
            vals[e] = interp_z(base, 0u, n_z, i, t, e);
        }
    } else {
        let y = clamp(psi / PI, 0.0, 1.0) * f32(n_psi);
        let j = min(u32(y), n_psi - 1u);
        let s = y - f32(j);
        for (var e = 0u; e < 16u; e++) {
            if (((ELEMENT_MASK >> e) & 1u) == 0u) {
                continue;
            }
            var q: array<f32, 4>;
            for (var k = 0; k < 4; k++) {
                let rs = psi_row(i32(j) - 1 + k, n_psi);
                var v = interp_z(base, rs.x, n_z, i, t, e);
                if (rs.y == 1u && e != 0u) {
                    v = v * mirror_sign(e);
                }
                q[k] = v;
            }
            var v = catmull_rom(q[0], q[1], q[2], q[3], s);
            if (e == 0u) {
                v = clamp(v, min(q[1], q[2]), max(q[1], q[2]));
            }
            vals[e] = v;
        }
    }
    // below LN_FLOOR_F32, exp leaves f32's normal range: zero, as the table's floor and
    // the f64 twin make it (a floor value there would light covered pixels that return
    // nothing with ~1e-38, where the twin gives 0)
    let m00 = select(exp(vals[0]), 0.0, vals[0] < LN_FLOOR_F32) * w;
    (*acc)[0] += m00;
    for (var e = 1u; e < 16u; e++) {
        if (((ELEMENT_MASK >> e) & 1u) != 0u) {
            (*acc)[e] += m00 * clamp(vals[e], -1.0, 1.0);
        }
    }
}

// ---- terms evaluated in the kernel (IN_SHADER; twins: SingleParams::eval and
// LambertianParams::eval in src/brdf/table.rs, through BrdfTable::eval_masked) ----
// The material's words at `blk` (SingleParams::words): kind 0, distribution kind and m or
// alpha, perfect-conductor flag, n - 1 and k, the masking-excess table (scale, correlation
// kind, intervals, values). All vectors are in the telescope frame.

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// a / b, scaled by b's larger component so that |b|^2 neither overflows nor underflows
fn cdiv(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    let s = max(abs(b.x), abs(b.y));
    let bs = b / s;
    let an = a / s;
    return vec2<f32>(an.x * bs.x + an.y * bs.y, an.y * bs.x - an.x * bs.y) / dot(bs, bs);
}

// Principal square root, Kahan's algebraic form (as optics::fresnel::csqrt).
fn csqrt(z: vec2<f32>) -> vec2<f32> {
    if (z.x == 0.0 && z.y == 0.0) {
        return z;
    }
    let t = sqrt(0.5 * (length(z) + abs(z.x)));
    if (z.x >= 0.0) {
        return vec2<f32>(t, z.y / (2.0 * t));
    }
    return vec2<f32>(abs(z.y) / (2.0 * t), select(t, -t, z.y < 0.0));
}

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

// z of the mapping cot theta = s z / (1 - z) from (cos, sin) (ZTable::z_of)
fn z_of(scale: f32, c: f32, s: f32) -> f32 {
    return clamp(c / max(scale * s + c, 1e-30), 0.0, 1.0);
}

// A 1D table's n + 1 values at `v`, uniform in z, interpolated at z (ZTable::eval_z).
fn table_1d(v: u32, n: u32, z: f32) -> f32 {
    let x = z * f32(n);
    let i = min(u32(x), n - 1u);
    return catmull_rom_ends(tables[v + max(i, 1u) - 1u], tables[v + i], tables[v + i + 1u],
                            tables[v + min(i + 2u, n)], i, n, x - f32(i));
}

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
    let g_ci = (1.0 - f) * p_i * qo + f * select(qo, p_i / co, p_i <= p_o);
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
// LambertianParams::eval in src/brdf/table.rs): per term c (1 - E(theta_i)) (1 - E(theta_o))
// from the material's albedo table E. Words at `blk` (LambertianParams::words): kind 1,
// the z scale, the number of terms, then per term c, s_f (0: E in z; else in
// zeta = (z + z_1 + z_sf) / 3, material.rs zeta_of), intervals, values.
fn add_lambertian_in_kernel(blk: u32, g: Local, acc: ptr<function, array<f32, 16>>) {
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

// ---- geometry helpers ----

fn safe_normalize(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let l2 = dot(v, v);
    if (l2 < 1e-30) {
        return fallback;
    }
    return v * inverseSqrt(l2);
}

// Any unit vector normal to `k`.
fn any_perp(k: vec3<f32>) -> vec3<f32> {
    if (abs(k.x) < 0.9) {
        return normalize(cross(k, vec3<f32>(1.0, 0.0, 0.0)));
    }
    return normalize(cross(k, vec3<f32>(0.0, 1.0, 0.0)));
}

// Stokes rotation L with (cos b, sin b): rows of the 4x4 as applied to index pairs (1, 2).
// Returns (cos 2b, sin 2b).
fn double_angle(c: f32, s: f32) -> vec2<f32> {
    return vec2<f32>(c * c - s * s, 2.0 * s * c);
}

// Adds `v` (already in fixed-point units, |v| < 2^62) to the 64-bit two's-complement
// accumulator at `buf_index` (low word first), rounded to the nearest unit. The magnitude is
// split in f32, where both parts are exact and in range (float-to-int conversion of
// out-of-range values is not portable), and negated in integer arithmetic. The high word
// is only touched when its increment (high part + carry) is non-zero: the scale puts a
// pixel's largest possible value near 2^32 units, so most additions are a single atomic.
fn fixed_add(buf_index: u32, v: f32, is_total: bool) {
    let a = abs(v);
    let hi_f = floor(a * 2.3283064365386963e-10); // a / 2^32
    var lo_u = u32(round(a - hi_f * 4294967296.0)); // exact, in [0, 2^32 - 256]
    var hi_u = u32(hi_f);
    if (lo_u == 0u && hi_u == 0u) {
        return;
    }
    if (v < 0.0) {
        lo_u = ~lo_u + 1u;
        hi_u = ~hi_u + select(0u, 1u, lo_u == 0u);
    }
    var old: u32;
    if (is_total) {
        old = atomicAdd(&total[2u * buf_index], lo_u);
    } else {
        old = atomicAdd(&profile[2u * buf_index], lo_u);
    }
    let hi_add = hi_u + select(0u, 1u, old + lo_u < old);
    if (hi_add != 0u) {
        if (is_total) {
            atomicAdd(&total[2u * buf_index + 1u], hi_add);
        } else {
            atomicAdd(&profile[2u * buf_index + 1u], hi_add);
        }
    }
}

// ---- transmitter cast shadows (SHADOWS; rule and limits at the top of this file) ----

// Telescope frame to the transmitter frame: R_y(-beta), wi = (sin beta, 0, cos beta) -> +z.
fn to_tx(v: vec3<f32>) -> vec3<f32> {
    let c = params.wi.z;
    let s = params.wi.x;
    return vec3<f32>(c * v.x - s * v.z, v.y, s * v.x + c * v.z);
}

// What candidate `u` says about q (transmitter frame); rules at the top of this file.
const CAND_LIT: u32 = 0u;    // neither of the below
const CAND_CLOSER: u32 = 1u; // beside q, its plane at q closer by more than its margin (rule 2)
const CAND_COVERS: u32 = 2u; // covers q and closer than q by more than e_z (rule 1)

fn candidate(u: u32, rot: mat3x3<f32>, q: vec3<f32>, g_t: vec2<f32>, reach: f32, e_z: f32) -> u32 {
    let a = to_tx(rot * geometry[3u * u].xyz);
    let b = to_tx(rot * geometry[3u * u + 1u].xyz);
    let c = to_tx(rot * geometry[3u * u + 2u].xyz);
    let n = cross(b - a, c - a); // n.z: twice the projected signed area
    if (n.z == 0.0) {
        return CAND_LIT;
    }
    // edge functions (barycentric weights x n.z): all of n.z's sign inside
    let fa = (c.x - b.x) * (q.y - b.y) - (c.y - b.y) * (q.x - b.x);
    let fb = (a.x - c.x) * (q.y - c.y) - (a.y - c.y) * (q.x - c.x);
    let fc = (b.x - a.x) * (q.y - a.y) - (b.y - a.y) * (q.x - a.x);
    let lead = (fa * a.z + fb * b.z + fc * c.z) / n.z - q.z; // its plane at q, minus q
    let sg = sign(n.z);
    if (sg * fa >= 0.0 && sg * fb >= 0.0 && sg * fc >= 0.0) {
        return select(CAND_LIT, CAND_COVERS, lead > e_z);
    }
    if (reach == 0.0) {
        return CAND_LIT; // rule 2 is off
    }
    // beside q: its plane extrapolated over at most `reach`, against T's plane (gradient
    // g_t) extrapolated as far: two planes of one smooth surface differ by reach |g_u - g_t|
    let g_u = -n.xy / n.z;
    return select(CAND_LIT, CAND_CLOSER, lead > e_z + reach * length(g_u - g_t));
}

// Whether the point p (telescope frame) of visible triangle `tri` (vertices p0, p1, p2) is
// in the transmitter's shadow in layer `layer`.
fn in_shadow(tri: u32, rot: mat3x3<f32>, p: vec3<f32>, p0: vec3<f32>, p1: vec3<f32>,
             p2: vec3<f32>, layer: u32) -> bool {
    let q = to_tx(p);
    let w = i32(params.tx_width);
    let tpix = 2.0 * params.ext / f32(params.tx_width);
    let tc = i32(floor((q.x + params.ext) / tpix));
    let tr = i32(floor((params.ext - q.y) / tpix));
    let e = SHADOW_EPS * params.ext;
    // T's depth gradient in the transmitter frame; T edge-on to it: rule 1 only
    let nt = to_tx(cross(p1 - p0, p2 - p0));
    let edge_on = abs(nt.z) <= 1e-6 * length(nt);
    let g_t = select(-nt.xy / nt.z, vec2<f32>(0.0), edge_on);
    // every texel centre of the 3x3 lies within 1.5 sqrt(2) tpix of q
    let reach = select(2.5 * tpix, 0.0, edge_on);
    var ids: array<u32, 9>;
    var res: array<u32, 9>;
    var n_ids = 0u;
    var all_closer = true; // rule 2, while it can still hold
    for (var dr = -1; dr <= 1; dr++) {
        for (var dc = -1; dc <= 1; dc++) {
            let r = tr + dr;
            let c = tc + dc;
            var id = 0u;
            if (r >= 0 && r < w && c >= 0 && c < w) {
                id = textureLoad(tx_ids, vec2<i32>(c, r), i32(layer), 0).x;
            }
            if (id == 0u || id > params.n_tri || id == tri + 1u) {
                all_closer = false;
                continue;
            }
            var k = 0u;
            while (k < n_ids && ids[k] != id) {
                k++;
            }
            if (k == n_ids) {
                ids[k] = id;
                res[k] = candidate(id - 1u, rot, q, g_t, select(0.0, reach, all_closer), e);
                n_ids++;
                if (res[k] == CAND_COVERS) {
                    return true;
                }
            }
            all_closer = all_closer && res[k] == CAND_CLOSER;
        }
    }
    return all_closer;
}

// ---- analytic coverage (COVERAGE; twin: render::twin::coverage_parts) ----
// Pixel-local coordinates: (u, v) in pixels from the pixel's top-left corner, v down the
// rows. Polygons are convex, counter-clockwise in (u, v) as the square (0,0) (1,0) (1,1)
// (0,1) is listed (positive shoelace area), at most CLIP_VERTS vertices (a vertex beyond
// is dropped: only pieces cut by more than six edges can need it).

const CLIP_VERTS: u32 = 10u;
const MAX_PIECES: u32 = 8u;     // convex pieces of a candidate's visible part
const MAX_QUEUE: u32 = 64u;     // triangles examined per pixel
const MAX_CAND: u32 = 32u;      // of those, overlapping the pixel
const AREA_EPS: f32 = 1e-7;     // pieces and parts smaller than this (pixel^2) are dropped
const OVERFLOW: u32 = 0xffffffffu;

struct Poly {
    v: array<vec2<f32>, 10>,
    n: u32,
}

fn unit_square() -> Poly {
    var p: Poly;
    p.v[0] = vec2<f32>(0.0, 0.0);
    p.v[1] = vec2<f32>(1.0, 0.0);
    p.v[2] = vec2<f32>(1.0, 1.0);
    p.v[3] = vec2<f32>(0.0, 1.0);
    p.n = 4u;
    return p;
}

// s cross(d, x - a): the side of x relative to the line through a along d (evaluated
// relative to a, so vertices far from the pixel keep their precision).
fn side(a: vec2<f32>, d: vec2<f32>, s: f32, x: vec2<f32>) -> f32 {
    return s * (d.x * (x.y - a.y) - d.y * (x.x - a.x));
}

// The part of p where side(a, d, s, x) >= 0 (Sutherland-Hodgman, one edge).
fn clip_edge(p: Poly, a: vec2<f32>, d: vec2<f32>, s: f32) -> Poly {
    var out: Poly;
    out.n = 0u;
    if (p.n < 3u) {
        return out;
    }
    var prev = p.v[p.n - 1u];
    var fp = side(a, d, s, prev);
    for (var k = 0u; k < p.n; k++) {
        let cur = p.v[k];
        let fc = side(a, d, s, cur);
        // a strict crossing only: a vertex on the line is kept as it is, not doubled
        if (((fc > 0.0 && fp < 0.0) || (fc < 0.0 && fp > 0.0)) && out.n < CLIP_VERTS) {
            out.v[out.n] = prev + (fp / (fp - fc)) * (cur - prev);
            out.n++;
        }
        if (fc >= 0.0 && out.n < CLIP_VERTS) {
            out.v[out.n] = cur;
            out.n++;
        }
        prev = cur;
        fp = fc;
    }
    return out;
}

// The part of p inside the triangle with vertices t and orientation s.
fn clip_triangle(p: Poly, t: array<vec2<f32>, 3>, s: f32) -> Poly {
    var out = p;
    for (var k = 0u; k < 3u; k++) {
        out = clip_edge(out, t[k], t[select(k + 1u, 0u, k == 2u)] - t[k], s);
    }
    return out;
}

// (area, area-weighted u, area-weighted v) of p: the shoelace sums.
fn moments(p: Poly) -> vec3<f32> {
    var m = vec3<f32>(0.0);
    if (p.n < 3u) {
        return m;
    }
    for (var k = 0u; k < p.n; k++) {
        let a = p.v[k];
        let b = p.v[select(k + 1u, 0u, k + 1u == p.n)];
        let c = a.x * b.y - b.x * a.y;
        m += vec3<f32>(c, (a.x + b.x) * c, (a.y + b.y) * c);
    }
    return m * vec3<f32>(0.5, 1.0 / 6.0, 1.0 / 6.0);
}

// Whether convex polygon p lies on the outer side (or on the line, within 1e-5 pixel) of
// one of the edges of the triangle with vertices t and orientation s.
fn separated(p: Poly, t: array<vec2<f32>, 3>, s: f32) -> bool {
    for (var k = 0u; k < 3u; k++) {
        let a = t[k];
        let d = t[select(k + 1u, 0u, k == 2u)] - a;
        let tol = 1e-5 * length(d);
        var out = true;
        for (var m = 0u; m < p.n; m++) {
            out = out && side(a, d, s, p.v[m]) <= tol;
        }
        if (out) {
            return true;
        }
    }
    return false;
}

// Depth (telescope z) at the point c (pixel coordinates) of the plane through the triangle
// with vertices t (pixel coordinates) and depths z.
fn plane_depth(t: array<vec2<f32>, 3>, z: vec3<f32>, c: vec2<f32>) -> f32 {
    let e1 = t[1] - t[0];
    let e2 = t[2] - t[0];
    let d = c - t[0];
    let den = e1.x * e2.y - e1.y * e2.x;
    let l1 = (d.x * e2.y - d.y * e2.x) / den;
    let l2 = (e1.x * d.y - e1.y * d.x) / den;
    return z.x + l1 * (z.y - z.x) + l2 * (z.z - z.x);
}

// One part of a pixel: a triangle, the fraction of the pixel's area it covers, the point
// (u, v) of the pixel where it is shaded and the extent (u, v) of the pixel it spans.
struct Part {
    tri: u32,
    frac: f32,
    centre: vec2<f32>,
    span: vec2<f32>,
}

// The parts of pixel (col, row) of attitude `layer` under analytic coverage, from the
// `n_seed` distinct triangles seen at its 3x3 neighbourhood's centres (scan order).
// Candidates: the seeds and, breadth first, the edge neighbours (mesh adjacency, after the
// normals in `geometry`) of every seed and of every candidate that overlaps the pixel, at
// most MAX_QUEUE examined (so the triangles of a surface that hold no centre are found
// through the ones that do); back faces are skipped on closed meshes (the raster culls
// them). Each candidate overlapping the pixel (at most MAX_CAND) is clipped to it; its
// visible part is that clip minus every other candidate that overlaps it and is nearer
// at the centroid of their overlap (ties: the lower id is nearer), kept as at most
// MAX_PIECES convex pieces. Exact for triangles that do not intersect. Returns the
// number of parts written to `parts` (in candidate order), or OVERFLOW when more than
// MAX_QUEUE triangles were to be examined or more than MAX_CAND overlap the pixel (a
// vertex shared by dozens of triangles, a fan's apex); the caller then falls back to the
// pixel-centre sample.
fn coverage_parts(col: u32, row: u32, layer: u32, seeds: array<u32, 9>, n_seed: u32,
                  parts: ptr<function, array<Part, 32>>) -> u32 {
    let rot = rotations[layer];
    let x0 = -params.ext + f32(col) * params.pix;
    let y0 = params.ext - f32(row) * params.pix;
    let inv = 1.0 / params.pix;
    let adj_base = 3u * params.n_tri * (1u + params.has_normals);
    var queue: array<u32, 64>;
    for (var i = 0u; i < n_seed; i++) {
        queue[i] = seeds[i];
    }
    var n_q = n_seed;
    var q: array<array<vec2<f32>, 3>, 32>;
    var sg: array<f32, 32>;
    var zs: array<vec3<f32>, 32>;
    var tri: array<u32, 32>;
    var n_c = 0u;
    for (var qi = 0u; qi < n_q; qi++) {
        let t = queue[qi];
        var uv: array<vec2<f32>, 3>;
        var z: array<f32, 3>;
        for (var k = 0u; k < 3u; k++) {
            let p = rot * geometry[3u * t + k].xyz;
            uv[k] = vec2<f32>((p.x - x0) * inv, (y0 - p.y) * inv);
            z[k] = p.z;
        }
        let e1 = uv[1] - uv[0];
        let e2 = uv[2] - uv[0];
        let den = e1.x * e2.y - e1.y * e2.x;
        // front faces are counter-clockwise in (x, y), so clockwise in (u, v)
        var overlaps = den != 0.0 && !(params.closed != 0u && den > 0.0);
        if (overlaps) {
            overlaps = moments(clip_triangle(unit_square(), uv, sign(den))).x > AREA_EPS;
        }
        if (overlaps && n_c == MAX_CAND) {
            return OVERFLOW;
        }
        if (overlaps) {
            q[n_c] = uv;
            zs[n_c] = vec3<f32>(z[0], z[1], z[2]);
            sg[n_c] = sign(den);
            tri[n_c] = t;
            n_c++;
        }
        if (overlaps || qi < n_seed) {
            let nb = bitcast<vec4<u32>>(geometry[adj_base + t]);
            for (var k = 0u; k < 3u; k++) {
                let u = nb[k];
                if (u >= params.n_tri) {
                    continue;
                }
                var j = 0u;
                while (j < n_q && queue[j] != u) {
                    j++;
                }
                if (j == n_q) {
                    if (n_q == MAX_QUEUE) {
                        return OVERFLOW;
                    }
                    queue[n_q] = u;
                    n_q++;
                }
            }
        }
    }
    // each candidate's visible part: its clip minus every candidate that overlaps it and
    // is nearer there (depths compared at the centroid of the overlap; candidates that one
    // of the other's edges separates, as neighbours on one surface, are skipped at once)
    var n_parts = 0u;
    for (var i = 0u; i < n_c; i++) {
        let base = clip_triangle(unit_square(), q[i], sg[i]);
        var pieces: array<Poly, 8>;
        pieces[0] = base;
        var n_p = 1u;
        for (var j = 0u; j < n_c && n_p > 0u; j++) {
            if (j == i || separated(base, q[j], sg[j])) {
                continue;
            }
            let mo = moments(clip_triangle(base, q[j], sg[j]));
            if (mo.x <= AREA_EPS) {
                continue;
            }
            let c = mo.yz / mo.x;
            let zi = plane_depth(q[i], zs[i], c);
            let zj = plane_depth(q[j], zs[j], c);
            if (zj < zi || (zj == zi && tri[j] > tri[i])) {
                continue;
            }
            var next: array<Poly, 8>;
            var n_next = 0u;
            for (var pi = 0u; pi < n_p; pi++) {
                var cur = pieces[pi];
                for (var k = 0u; k < 3u && cur.n >= 3u; k++) {
                    let a = q[j][k];
                    let d = q[j][select(k + 1u, 0u, k == 2u)] - a;
                    let outside = clip_edge(cur, a, d, -sg[j]);
                    if (n_next < MAX_PIECES && moments(outside).x > AREA_EPS) {
                        next[n_next] = outside;
                        n_next++;
                    }
                    cur = clip_edge(cur, a, d, sg[j]);
                }
            }
            pieces = next;
            n_p = n_next;
        }
        var vis = vec3<f32>(0.0);
        var lo = vec2<f32>(1.0);
        var hi = vec2<f32>(0.0);
        for (var pi = 0u; pi < n_p; pi++) {
            vis += moments(pieces[pi]);
            for (var k = 0u; k < pieces[pi].n; k++) {
                lo = min(lo, pieces[pi].v[k]);
                hi = max(hi, pieces[pi].v[k]);
            }
        }
        if (vis.x > AREA_EPS) {
            (*parts)[n_parts] = Part(tri[i], vis.x, vis.yz / vis.x,
                                     clamp(hi - lo, vec2<f32>(0.0), vec2<f32>(1.0)));
            n_parts++;
        }
    }
    return n_parts;
}

// Shade the point (px, py) (telescope frame, m) of triangle `tri` in attitude `layer`: writes
// the differential cross-section of a whole pixel there (Mueller, or Stokes/intensity for
// CHANNELS < 16; zero where unlit or shadowed) to `out` and returns (r0, a, b, hit): the
// range, the pixel's footprint widths, and 1 if the triangle is not degenerate in
// projection (else 0, and nothing is written). Twin: render::twin::shade_point.
fn shade_at(tri: u32, layer: u32, px: f32, py: f32, out: ptr<function, array<f32, 16>>) -> vec4<f32> {
    var hit = vec4<f32>(0.0);
    let rot = rotations[layer];
    let q0 = geometry[3u * tri];
    let p0 = rot * q0.xyz;
    let p1 = rot * geometry[3u * tri + 1u].xyz;
    let p2 = rot * geometry[3u * tri + 2u].xyz;
    let mat = bitcast<u32>(q0.w);
    // barycentrics of (px, py) in the projected triangle
    let e1 = p1.xy - p0.xy;
    let e2 = p2.xy - p0.xy;
    let d = vec2<f32>(px, py) - p0.xy;
    let den = e1.x * e2.y - e1.y * e2.x;
    var ng = cross(p1 - p0, p2 - p0);
    if (abs(den) > 0.0 && dot(ng, ng) > 0.0) {
        hit.w = 1.0;
        let l1 = (d.x * e2.y - d.y * e2.x) / den;
        let l2 = (e1.x * d.y - e1.y * d.x) / den;
        let l0 = 1.0 - l1 - l2;
        let pz = p0.z + l1 * (p1.z - p0.z) + l2 * (p2.z - p0.z);
        let p = vec3<f32>(px, py, pz);
        let wi = params.wi.xyz;
        let wo = params.wo.xyz;
        let sum_dir = wi + wo;
        hit.x = -0.5 * dot(p, sum_dir);
        ng = normalize(ng);
        if (ng.z < 0.0) {
            ng = -ng;
        }
        // range gradient across the pixel (plane z = z0 - (nx x + ny y) / nz)
        let nz = max(ng.z, 1e-12);
        let dzdx = -ng.x / nz;
        let dzdy = -ng.y / nz;
        hit.y = min(abs(0.5 * (sum_dir.x + sum_dir.z * dzdx)) * params.pix, params.max_extent);
        hit.z = min(abs(0.5 * (sum_dir.y + sum_dir.z * dzdy)) * params.pix, params.max_extent);
        var n = ng;
        if (params.has_normals != 0u) {
            let base = 3u * params.n_tri + 3u * tri;
            let ns = l0 * geometry[base].xyz + l1 * geometry[base + 1u].xyz
                + l2 * geometry[base + 2u].xyz;
            n = safe_normalize(rot * ns, ng);
            if (dot(n, ng) < 0.0) {
                n = -n;
            }
        }
        let cos_i = dot(n, wi);
        let cos_o = dot(n, wo);
        var lit = cos_i > 0.0 && cos_o > 0.0;
        if (SHADOWS && lit) {
            // rule 0: a facet turned away from the transmitter shadows itself
            lit = dot(ng, wi) > 0.0 && !in_shadow(tri, rot, p, p0, p1, p2, layer);
        }
        if (lit) {
            // table coordinates (src/brdf/table.rs, bisector frame): b = bisector,
            // e_phi = normalize(n x b), e_theta = e_phi x b,
            // psi = atan2((wi - wo).e_phi, (wi - wo).e_theta), mirrored when < 0
            let b = safe_normalize(sum_dir, n);
            let cos_t = clamp(dot(n, b), 0.0, 1.0);
            let nxb = cross(n, b);
            let sin_t = length(nxb);
            var e_phi: vec3<f32>;
            if (sin_t > 1e-7) {
                e_phi = nxb / sin_t;
            } else {
                e_phi = any_perp(n);
            }
            var psi = 0.0;
            var mirrored = false;
            if (params.beta > 0.0) {
                let e_theta = cross(e_phi, b);
                let tv = wi - wo;
                psi = atan2(dot(tv, e_phi), dot(tv, e_theta));
                if (psi < 0.0) {
                    psi = -psi;
                    mirrored = true;
                }
            }
            // z of the table grid: cot theta = s z / (1 - z)  =>  z = cos / (s sin + cos)
            var m: array<f32, 16>;
            for (var part = 0u; part < MAX_PARTS; part++) {
                let sw = tables[mat * HEADER_WORDS + part * 4u + 3u];
                let scale = abs(sw);
                let z = z_of(scale, cos_t, sin_t);
                // cos_i / cos_t <= 2 cos(beta/2) while lit (1 at beta = 0)
                let w = select(cos_i, min(cos_i / max(cos_t, 1e-30), 2.0), sw < 0.0);
                add_part(mat, part, z, psi, w, &m);
            }
            if (mirrored) {
                for (var e = 1u; e < 16u; e++) {
                    m[e] *= mirror_sign(e);
                }
            }
            // the table's beam bases: x = normalize(e_phi - (e_phi.w) w), y = k x x
            let k_in = -wi;
            let x_in = safe_normalize(e_phi - dot(e_phi, wi) * wi, any_perp(wi));
            let x_out = safe_normalize(e_phi - dot(e_phi, wo) * wo, any_perp(wo));
            let y_in = cross(k_in, x_in);
            let y_out = cross(wo, x_out);
            // the parts evaluated here instead of looked up (their kind is their first word)
            if (IN_SHADER) {
                var g: Local;
                g.ci = cos_i;
                g.co = cos_o;
                g.ui = cross(n, wi);
                g.uo = cross(n, wo);
                g.si = length(g.ui);
                g.so = length(g.uo);
                g.h = b;
                g.cos_h = cos_t;
                g.sin2_h = sin_t * sin_t;
                for (var part = 0u; part < MAX_PARTS; part++) {
                    let hw = mat * HEADER_WORDS + part * 4u;
                    if (bitcast<u32>(tables[hw + 2u]) == SHADER_PART) {
                        let blk = bitcast<u32>(tables[hw]);
                        if (bitcast<u32>(tables[blk]) == 0u) {
                            add_single_in_kernel(blk, g, wi, wo, x_in, x_out, &m);
                        } else {
                            add_lambertian_in_kernel(blk, g, &m);
                        }
                    }
                }
            }
            // telescope bases: x_in_t = normalize(k_in x Y), x_out_t = X (wo = Z)
            let x_in_t = normalize(cross(k_in, vec3<f32>(0.0, 1.0, 0.0)));
            let y_in_t = cross(k_in, x_in_t);
            let x_out_t = vec3<f32>(1.0, 0.0, 0.0);
            // S_sp_in = L(b_in) S_t_in: cos b_in = x_in.x_in_t, sin b_in = x_in.y_in_t
            let ai = double_angle(dot(x_in, x_in_t), dot(x_in, y_in_t));
            // S_t_out = L(b_out) S_sp_out: cos = x_out_t.x_out, sin = x_out_t.y_out
            let ao = double_angle(dot(x_out_t, x_out), dot(x_out_t, y_out));
            // M_t = L(ao) M L(ai), L(c, s) = [[1,0,0,0],[0,c,s,0],[0,-s,c,0],[0,0,0,1]]
            var tmp: array<f32, 16>;
            for (var i = 0u; i < 4u; i++) {
                let a1 = m[i * 4u + 1u];
                let a2 = m[i * 4u + 2u];
                tmp[i * 4u] = m[i * 4u];
                tmp[i * 4u + 1u] = a1 * ai.x - a2 * ai.y;
                tmp[i * 4u + 2u] = a1 * ai.y + a2 * ai.x;
                tmp[i * 4u + 3u] = m[i * 4u + 3u];
            }
            // (cos_i is in each part's weight, add_part)
            let k = 4.0 * PI * params.pix * params.pix;
            for (var j = 0u; j < 4u; j++) {
                let b1 = tmp[4u + j];
                let b2 = tmp[8u + j];
                (*out)[j] = k * tmp[j];
                (*out)[4u + j] = k * (ao.x * b1 + ao.y * b2);
                (*out)[8u + j] = k * (-ao.y * b1 + ao.x * b2);
                (*out)[12u + j] = k * tmp[12u + j];
            }
            if (CHANNELS < 16u) {
                let s = params.s_tx;
                var st: array<f32, 16>;
                for (var i = 0u; i < 4u; i++) {
                    st[i] = (*out)[i * 4u] * s.x + (*out)[i * 4u + 1u] * s.y
                        + (*out)[i * 4u + 2u] * s.z + (*out)[i * 4u + 3u] * s.w;
                }
                *out = st;
            }
        }
    }
    return hit;
}

// Add one shaded surface's values `v` (clamped) at range r0 with footprint widths (wa, wb)
// to the profile of attitude `layer`: the pulse integrated over each bin, its tails beyond
// the support folded into the end bins (weights sum to 1; twin:
// render::pulse::bin_weights_folded).
fn add_profile(layer: u32, r0: f32, wa: f32, wb: f32, v: ptr<function, array<f32, 16>>) {
    let half_w = 0.5 * (wa + wb) + params.support;
    let lo = (r0 - half_w - params.r_min) / params.bin_width;
    let hi = (r0 + half_w - params.r_min) / params.bin_width;
    let k0 = u32(clamp(floor(lo), 0.0, f32(params.n_bins - 1u)));
    let k1 = u32(clamp(floor(hi), 0.0, f32(params.n_bins - 1u)));
    var c_prev = 0.0;
    for (var kb = k0; kb <= k1; kb++) {
        var c_next = 1.0;
        if (kb < k1) {
            c_next = pulse_cdf_gauss_box2(params.r_min + f32(kb + 1u) * params.bin_width - r0,
                                          params.sigma, wa, wb);
        }
        let w = (c_next - c_prev) * params.fix_scale;
        c_prev = c_next;
        if (w != 0.0) {
            let base = (layer * params.n_bins + kb) * CHANNELS;
            for (var c = 0u; c < CHANNELS; c++) {
                fixed_add(base + c, w * (*v)[c], false);
            }
        }
    }
}

// What a pixel's parts add up to: covered fraction, covered fraction x range, and the
// footprint widths of its largest part (`frac_big` its fraction).
struct PixelAcc {
    cov: f32,
    r_sum: f32,
    w_big: vec2<f32>,
    frac_big: f32,
}

// Shade one part of pixel (col, row) (a triangle, the fraction of the pixel it covers, the
// point in the pixel where it is shaded and the extent of the pixel it spans), add it to
// the pixel's values `out` and to the profile, and to `acc`. Twin: the loop over parts in
// render::twin::render_cpu.
fn shade_part(layer: u32, col: u32, row: u32, part: Part, cap: f32,
              out: ptr<function, array<f32, 16>>, acc: ptr<function, PixelAcc>) {
    let x = -params.ext + (f32(col) + part.centre.x) * params.pix;
    let y = params.ext - (f32(row) + part.centre.y) * params.pix;
    var g: array<f32, 16>;
    let h = shade_at(part.tri, layer, x, y, &g);
    if (h.w == 0.0) {
        return;
    }
    let wab = part.span * h.yz;
    (*acc).cov += part.frac;
    (*acc).r_sum += part.frac * h.x;
    if (part.frac > (*acc).frac_big) {
        (*acc).frac_big = part.frac;
        (*acc).w_big = wab;
    }
    for (var ch = 0u; ch < CHANNELS; ch++) {
        g[ch] *= part.frac;
        (*out)[ch] += g[ch];
        g[ch] = clamp(g[ch], -cap, cap);
    }
    if (WRITE_PROFILE && g[0] != 0.0) {
        add_profile(layer, h.x, wab.x, wab.y, &g);
    }
}

// The parts of pixel (col, row) of attitude `layer`, shaded into `out` (its values) and
// `acc`. The pixel's K visibility samples (src/render/gpu.rs, sample_offsets) are grouped
// by the flat surface they see (the faces of a flat, finely tessellated panel form one,
// Mesh::surfaces; each face of a smoothly shaded mesh is its own); each surface seen by c
// of them is shaded once, on the plane of the triangle its first sample sees, at the mean
// of its samples' points, and counts for c / K of the pixel's area, its footprint widths
// (a, b) scaled by the extent of its samples across the pixel in u and in v (max - min +
// 1/K; 1 for a whole pixel). On a flat surface the BRDF does not vary and the range is
// linear, so this is what shading each triangle's samples apart would add up to. A pixel
// whose samples all see one surface is shaded at its centre (the samples' mean) for its
// whole area: exactly the single-sample result. With COVERAGE (analytic coverage, SAMPLES = 1) the parts come from
// coverage_parts instead: exact visible areas, each shaded at its centroid.
// Twin: render::twin::render_cpu.
// Triangle id + 1 (0: none) seen by visibility sample k (SAMPLES > 1) of pixel (col, row)
// of attitude `layer`: K < 4, layer l K + k of tri_ids; K >= 4 (msaa_samples in
// src/render/gpu.rs), sample k % 4 of texel (col + 1 + dc, row + 1 + dr) of pass k / 4's
// tile, as gather.wgsl stored it.
fn sample_id(col: u32, row: u32, layer: u32, k: u32) -> u32 {
    if (SAMPLES < 4u) {
        return textureLoad(tri_ids, vec2<i32>(i32(col), i32(row)), i32(layer * SAMPLES + k), 0).x;
    }
    let side = params.width + 2u;
    let o = params.offsets[k];
    let x = u32(i32(col + 1u) + i32(o.z));
    let y = u32(i32(row + 1u) + i32(o.w));
    return sample_ids[(((layer * (SAMPLES / 4u) + k / 4u) * side + y) * side + x) * 4u + k % 4u];
}

fn pixel_parts(col: u32, row: u32, layer: u32, cap: f32,
               out: ptr<function, array<f32, 16>>, acc: ptr<function, PixelAcc>) {
    if (COVERAGE) {
        // candidates: the distinct triangles seen at the 3x3 neighbourhood's centres
        var cand: array<u32, 9>;
        var n_cand = 0u;
        var n_hit = 0u;
        for (var dr = -1; dr <= 1; dr++) {
            for (var dc = -1; dc <= 1; dc++) {
                let r = i32(row) + dr;
                let c = i32(col) + dc;
                var id = 0u;
                if (r >= 0 && r < i32(params.height) && c >= 0 && c < i32(params.width)) {
                    id = textureLoad(tri_ids, vec2<i32>(c, r), i32(layer), 0).x;
                }
                if (id == 0u || id > params.n_tri) {
                    continue;
                }
                n_hit++;
                var k = 0u;
                while (k < n_cand && cand[k] != id - 1u) {
                    k++;
                }
                if (k == n_cand) {
                    cand[k] = id - 1u;
                    n_cand++;
                }
            }
        }
        if (n_cand == 1u && n_hit == 9u) {
            // one triangle at all nine centres contains their hull, so the whole pixel
            shade_part(layer, col, row, Part(cand[0], 1.0, vec2<f32>(0.5), vec2<f32>(1.0)),
                       cap, out, acc);
            return;
        }
        if (n_cand == 0u) {
            return;
        }
        var parts: array<Part, 32>;
        var n_parts = coverage_parts(col, row, layer, cand, n_cand, &parts);
        if (n_parts == OVERFLOW) {
            // too many triangles: the centre sample, as with one sample per pixel
            let id = textureLoad(tri_ids, vec2<i32>(i32(col), i32(row)), i32(layer), 0).x;
            n_parts = 0u;
            if (id > 0u && id <= params.n_tri) {
                parts[0] = Part(id - 1u, 1.0, vec2<f32>(0.5), vec2<f32>(1.0));
                n_parts = 1u;
            }
        }
        for (var k = 0u; k < n_parts; k++) {
            shade_part(layer, col, row, parts[k], cap, out, acc);
        }
        return;
    }
    if (SAMPLES == 1u) {
        // the pixel centre alone
        let id = textureLoad(tri_ids, vec2<i32>(i32(col), i32(row)), i32(layer), 0).x;
        if (id > 0u && id <= params.n_tri) {
            let x = -params.ext + (f32(col) + 0.5) * params.pix;
            let y = params.ext - (f32(row) + 0.5) * params.pix;
            let h = shade_at(id - 1u, layer, x, y, out);
            if (h.w != 0.0) {
                *acc = PixelAcc(1.0, h.x, h.yz, 1.0);
                var g: array<f32, 16>;
                for (var ch = 0u; ch < CHANNELS; ch++) {
                    g[ch] = clamp((*out)[ch], -cap, cap);
                }
                if (WRITE_PROFILE && g[0] != 0.0) {
                    add_profile(layer, h.x, h.y, h.z, &g);
                }
            }
        }
        return;
    }
    let n_s = SAMPLES;
    // the triangle (id + 1) and the flat surface (Mesh::surfaces, + 1) each sample sees
    var ids: array<u32, 16>;
    var sids: array<u32, 16>;
    for (var k = 0u; k < n_s; k++) {
        let id = sample_id(col, row, layer, k);
        ids[k] = select(0u, id, id <= params.n_tri);
        if (ids[k] != 0u) {
            sids[k] = bitcast<u32>(geometry[3u * (id - 1u) + 1u].w) + 1u;
        }
    }
    // bit k of `done`: sample k is empty or in a group already shaded. One loop
    // iteration per group, in the order of their first samples (not one per sample:
    // lavapipe runs a branch masked for every invocation of a SIMD batch, and the loop's
    // exit test is what skips work nobody needs).
    var done = 0u;
    for (var k = 0u; k < n_s; k++) {
        done |= select(0u, 1u << k, ids[k] == 0u);
    }
    let all = (1u << n_s) - 1u;
    while (done != all) {
        let k = firstTrailingBit(~done);
        let id = ids[k];
        let sid = sids[k];
        var c = 0u;
        var su = 0.0;
        var sv = 0.0;
        var lo = vec2<f32>(1.0);
        var hi = vec2<f32>(0.0);
        for (var k2 = k; k2 < n_s; k2++) {
            if (sids[k2] == sid) {
                done |= 1u << k2;
                c += 1u;
                let o = params.offsets[k2].xy;
                su += o.x;
                sv += o.y;
                lo = min(lo, o);
                hi = max(hi, o);
            }
        }
        // the footprint of the part of the pixel its samples span (a whole pixel: 1)
        let part = Part(id - 1u, f32(c) / f32(n_s), vec2<f32>(su, sv) / f32(c),
                        hi - lo + vec2<f32>(1.0 / f32(n_s)));
        shade_part(layer, col, row, part, cap, out, acc);
    }
}

// Write a shaded pixel's image channels and its range (the covered parts' mean range, with
// the covered fraction; in footprint mode the widths are those of its largest part, an
// approximation where a pixel spans surfaces at different ranges).
fn write_pixel(pix_index: u32, out: ptr<function, array<f32, 16>>, acc: PixelAcc) {
    if (WRITE_IMAGE) {
        for (var c = 0u; c < CHANNELS; c++) {
            image[pix_index * CHANNELS + c] = (*out)[c];
        }
    }
    if (WRITE_RANGE) {
        let r_out = select(bitcast<f32>(0x7fc00000u), acc.r_sum / acc.cov, acc.cov > 0.0);
        if (WRITE_FOOTPRINT) {
            range_img[4u * pix_index] = r_out;
            range_img[4u * pix_index + 1u] = acc.w_big.x;
            range_img[4u * pix_index + 2u] = acc.w_big.y;
            range_img[4u * pix_index + 3u] = acc.cov;
        } else {
            range_img[2u * pix_index] = r_out;
            range_img[2u * pix_index + 1u] = acc.cov;
        }
    }
}

// One invocation per pixel (pixel_parts), its values added to the total by a workgroup
// reduction.
@compute @workgroup_size(8, 8, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>,
           @builtin(local_invocation_index) lidx: u32) {
    let col = gid.x;
    let row = gid.y;
    let layer = gid.z;
    let inside = col < params.width && row < params.height;
    var acc_out: array<f32, 16>; // the pixel's values, clamped for the fixed-point sums
    if (inside) {
        // bound every channel (|M_ij| <= M00) for the fixed-point sums
        let cap = 2.305843e18 / (params.fix_scale * f32(params.width * params.height));
        var out: array<f32, 16>;
        var acc = PixelAcc(0.0, 0.0, vec2<f32>(0.0), 0.0);
        pixel_parts(col, row, layer, cap, &out, &acc);
        write_pixel((layer * params.height + row) * params.width + col, &out, acc);
        for (var c = 0u; c < CHANNELS; c++) {
            acc_out[c] = clamp(out[c], -cap, cap);
        }
    }
    if (WRITE_TOTAL) {
        for (var c = 0u; c < CHANNELS; c++) {
            wg_sum[lidx * 16u + c] = acc_out[c];
        }
        workgroupBarrier();
        if (lidx < CHANNELS) {
            var s = 0.0;
            for (var t = 0u; t < 64u; t++) {
                s += wg_sum[t * 16u + lidx];
            }
            fixed_add(layer * CHANNELS + lidx, s * params.fix_scale, true);
        }
    }
}
