// ---- transmitter cast shadows (SHADOWS; rule and limits at the top of shade.wgsl) ----
// Uses the shade kernel's `params`, `geometry` and `tx_ids` bindings and SHADOW_EPS.

// Telescope frame to the transmitter frame: R_y(-beta), wi = (sin beta, 0, cos beta) -> +z.
fn to_tx(v: vec3<f32>) -> vec3<f32> {
    let c = params.wi.z;
    let s = params.wi.x;
    return vec3<f32>(c * v.x - s * v.z, v.y, s * v.x + c * v.z);
}

// What candidate `u` says about q (transmitter frame); rules at the top of shade.wgsl.
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
