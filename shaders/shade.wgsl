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
// (shared/pulse.wgsl), and adds the workgroup's sum to the total.
// Profile and total are accumulated in 64-bit fixed point (two u32 words, integer atomics):
// each addition is rounded to the nearest quantum (2^-40 of the largest value a pixel could
// take, see the fixed-point scale in src/render/gpu/plan.rs), and the sums are then exact and
// order-independent, so results do not depend on scheduling.
// Conventions: src/render/mod.rs. CPU twin: render::cpu::shade_pixel.
//
// Transmitter cast shadows (SHADOWS: set when the bistatic angle beta > 0; monostatic the
// receiver's visibility already implies illumination and the test is compiled out). A
// second raster pass wrote the triangle seen from the transmitter at each texel centre
// (`tx_ids`: the same orthographic square [-ext, ext]^2 at `tx_width` texels a side, twice
// the receiver's up to 4096 (src/render/gpu/plan.rs, transmitter_map_width); rotation
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
// CPU twin: render::cpu::shadowed (exact f64 ray casting, independent of this rule).
//
// Assembled by src/render/shaders.rs: each `//#include "shared/NAME.wgsl"` line below is
// replaced by that file (WGSL declarations may come in any order). The shared files use
// the bindings, override constants and constants declared here.

//#include "shared/pulse.wgsl"

override CHANNELS: u32 = 16u;      // 16: Mueller, 4: Stokes (M s_tx), 1: intensity (M s_tx)_0
override WRITE_IMAGE: bool = true;
override WRITE_RANGE: bool = true;
override WRITE_PROFILE: bool = true;
// With WRITE_PROFILE: each bin's second moment sum_q (w_q I_q)^2 / a_q over the shaded
// parts q (I_q: the part's S0 cross-section where positive, a_q = frac_q pix^2, w_q its
// pulse weight in the bin), one more fixed-point word pair after the bin's channels at the
// scale fix_area (render::Rendered::area_moment; the illuminated area per bin is
// profile_S0^2 / moment). Twin: render::cpu's Accumulator::add.
override WRITE_AREA: bool = false;
override WRITE_TOTAL: bool = true;
// Footprint mode (sampled pulses, whose profile is accumulated on the host): the range
// buffer holds (r0, a, b) per pixel, the range and the widths of its footprint.
override WRITE_FOOTPRINT: bool = false;
override SHADOWS: bool = false;    // transmitter cast shadows (beta > 0), see above
// Mueller elements to look up (bit 4 i + j: M_ij in the table frame); the others are left
// zero. Set from what the output needs (SensorSetup::element_mask in src/render/api.rs:
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

//#include "shared/constants.wgsl"
const SHADOW_EPS: f32 = 1e-5;      // cast shadows: eps_z = SHADOW_EPS ext

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
    fix_area: f32,     // fixed-point units per m^2 of the area moment (WRITE_AREA)
    pad0: u32,
    pad1: u32,
    pad2: u32,
    // per visibility sample (u, v, dc, dr): its offset in the pixel (from its top-left
    // corner) and, SAMPLES >= 4, the tile texel holding it relative to the pixel's (sample_id)
    offsets: array<vec4<f32>, MAX_SAMPLES>,
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
// The pixels with thin faces (render::thin::gpu_words, per chunk): thin[0] their number
// (0: none, and this is a placeholder), thin[1 + pixel index] 0 or the position p of the
// pixel's faces (thin[p] of them, thin[p + 1 ..]). With SAMPLES > 1 such a pixel is left
// empty here and shaded on the CPU (render::cpu::add_thin_pixels); analytic coverage
// takes its faces as candidates.
@group(0) @binding(11) var<storage, read> thin: array<u32>;

// Position of the thin faces of pixel `pix_index` ((layer height + row) width + col), 0: none.
fn thin_list(pix_index: u32) -> u32 {
    if (thin[0] == 0u) {
        return 0u;
    }
    return thin[1u + pix_index];
}

var<workgroup> wg_sum: array<f32, 1024>;

//#include "shared/table.wgsl"
//#include "shared/complex.wgsl"
//#include "shared/microfacet.wgsl"
//#include "shared/in_kernel.wgsl"

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

//#include "shared/shadow.wgsl"
//#include "shared/coverage.wgsl"

// Shade the point (px, py) (telescope frame, m) of triangle `tri` in attitude `layer`: writes
// the differential cross-section of a whole pixel there (Mueller, or Stokes/intensity for
// CHANNELS < 16; zero where unlit or shadowed) to `out` and returns (r0, a, b, hit): the
// range, the pixel's footprint widths, and 1 if the triangle is not degenerate in
// projection (else 0, and nothing is written). Twin: render::cpu::shade_point.
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
                            add_depolarizing_in_kernel(blk, g, &m);
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

// Word pairs per bin of the profile buffer: the channels, then (WRITE_AREA) the moment.
fn profile_stride() -> u32 {
    return CHANNELS + select(0u, 1u, WRITE_AREA);
}

// The area moment of a part (WRITE_AREA): I^2 / a for its S0 cross-section I = g0 (0
// where not positive) and area a = frac pix^2, in fixed-point units, clamped at frac
// 2^61 / (pixels) so that a bin of every pixel stays below 2^61 units (only a pixel whose
// value exceeds the tables' bound reaches it, see render::gpu::plan).
fn area_units(g0: f32, frac: f32) -> f32 {
    if (!WRITE_AREA || g0 <= 0.0) {
        return 0.0;
    }
    let t = g0 / params.pix;
    let cap = 2.305843e18 / f32(params.width * params.height);
    return min(t * t / frac * params.fix_area, cap * frac);
}

// Add one shaded surface's values `v` (clamped) at range r0 with footprint widths (wa, wb)
// to the profile of attitude `layer`: the pulse integrated over each bin, its tails beyond
// the support folded into the end bins (weights sum to 1; twin:
// render::pulse::bin_weights_folded); with WRITE_AREA, `e` (area_units) times the mean
// over the footprint of the squared pointwise pulse weight to the bin's area moment, by the
// two-point rule r0 +- d, d^2 = (wa^2 + wb^2) / 12 (the trapezoid's variance; twin:
// render::cpu's Accumulator::add_moment).
fn add_profile(layer: u32, r0: f32, wa: f32, wb: f32, v: ptr<function, array<f32, 16>>,
               e: f32) {
    let half_w = 0.5 * (wa + wb) + params.support;
    let d = sqrt((wa * wa + wb * wb) / 12.0);
    var p_prev = 0.0;
    var m_prev = 0.0;
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
        let base = (layer * params.n_bins + kb) * profile_stride();
        if (w != 0.0) {
            for (var c = 0u; c < CHANNELS; c++) {
                fixed_add(base + c, w * (*v)[c], false);
            }
        }
        if (WRITE_AREA && e > 0.0) {
            var p_next = 1.0;
            var m_next = 1.0;
            if (kb < k1) {
                let x = params.r_min + f32(kb + 1u) * params.bin_width - r0;
                p_next = pulse_cdf_gauss_box2(x - d, params.sigma, 0.0, 0.0);
                m_next = pulse_cdf_gauss_box2(x + d, params.sigma, 0.0, 0.0);
            }
            let wp = p_next - p_prev;
            let wm = m_next - m_prev;
            p_prev = p_next;
            m_prev = m_next;
            fixed_add(base + CHANNELS, 0.5 * (wp * wp + wm * wm) * e, false);
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
// render::cpu::render_cpu.
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
        add_profile(layer, h.x, wab.x, wab.y, &g, area_units(g[0], part.frac));
    }
}

// The parts of pixel (col, row) of attitude `layer`, shaded into `out` (its values) and
// `acc`. The pixel's K visibility samples (src/render/samples.rs, sample_offsets) are grouped
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
// Twin: render::cpu::render_cpu.
// Triangle id + 1 (0: none) seen by visibility sample k (SAMPLES > 1) of pixel (col, row)
// of attitude `layer`: K < 4, layer l K + k of tri_ids; K >= 4 (msaa_samples in
// src/render/samples.rs), sample k % 4 of texel (col + 1 + dc, row + 1 + dr) of pass k / 4's
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

// Append pixel (col, row)'s thin faces (binding 11) to queue[0..n) (those not already
// there): the new count, or OVERFLOW when they do not fit in MAX_QUEUE.
fn add_thin(col: u32, row: u32, layer: u32, queue: ptr<function, array<u32, 64>>,
            n: u32) -> u32 {
    let p = thin_list((layer * params.height + row) * params.width + col);
    if (p == 0u) {
        return n;
    }
    var m = n;
    let count = thin[p];
    for (var i = 0u; i < count; i++) {
        let t = thin[p + 1u + i];
        var j = 0u;
        while (j < n && (*queue)[j] != t) {
            j++;
        }
        if (j == n) {
            if (m == MAX_QUEUE) {
                return OVERFLOW;
            }
            (*queue)[m] = t;
            m++;
        }
    }
    return m;
}

fn pixel_parts(col: u32, row: u32, layer: u32, cap: f32,
               out: ptr<function, array<f32, 16>>, acc: ptr<function, PixelAcc>) {
    if (COVERAGE) {
        // candidates: the distinct triangles seen at the 3x3 neighbourhood's centres, then
        // the pixel's thin faces
        var cand: array<u32, 64>;
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
        let n_listed = add_thin(col, row, layer, &cand, n_cand);
        if (n_cand == 1u && n_hit == 9u && n_listed == n_cand) {
            // one triangle at all nine centres contains their hull, so the whole pixel
            shade_part(layer, col, row, Part(cand[0], 1.0, vec2<f32>(0.5), vec2<f32>(1.0)),
                       cap, out, acc);
            return;
        }
        if (n_listed == 0u) {
            return;
        }
        var parts: array<Part, 32>;
        var n_parts = OVERFLOW;
        if (n_listed != OVERFLOW) {
            n_parts = coverage_parts(col, row, layer, cand, n_cand, n_listed, &parts);
        }
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
                    add_profile(layer, h.x, h.y, h.z, &g, area_units(g[0], 1.0));
                }
            }
        }
        return;
    }
    // a pixel with thin faces is the CPU's (render::cpu::add_thin_pixels)
    if (thin_list((layer * params.height + row) * params.width + col) != 0u) {
        return;
    }
    sampled_groups(col, row, layer, cap, out, acc);
}

// The parts of pixel (col, row) from its SAMPLES > 1 visibility samples (pixel_parts).
fn sampled_groups(col: u32, row: u32, layer: u32, cap: f32,
                  out: ptr<function, array<f32, 16>>, acc: ptr<function, PixelAcc>) {
    let n_s = SAMPLES;
    // the triangle (id + 1) and the flat surface (Mesh::surfaces, + 1) each sample sees
    var ids: array<u32, MAX_SAMPLES>;
    var sids: array<u32, MAX_SAMPLES>;
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
