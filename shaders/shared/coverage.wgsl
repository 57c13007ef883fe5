// ---- analytic coverage (COVERAGE; twin: render::cpu::coverage_parts) ----
// Pixel-local coordinates: (u, v) in pixels from the pixel's top-left corner, v down the
// rows. Polygons are convex, counter-clockwise in (u, v) as the square (0,0) (1,0) (1,1)
// (0,1) is listed (positive shoelace area), at most CLIP_VERTS vertices (a vertex beyond
// is dropped: only pieces cut by more than six edges can need it).
// Uses the shade kernel's `params`, `geometry` and `rotations` bindings.

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

// The parts of pixel (col, row) of attitude `layer` under exact hidden-surface clipping.
// Candidates: queue[0..n_seed) (the seeds: triangles seen at the pixel's samples or its
// neighbourhood's centres), queue[n_seed..n_listed) (the pixel's thin faces, listed by
// render::thin::ThinPixels, none of them a seed) and, breadth first, the edge neighbours
// (mesh adjacency, after the normals in `geometry`) of every seed and of every other
// candidate that overlaps the pixel, not of the listed ones (at most MAX_QUEUE examined;
// so the triangles of a surface that hold no sample are found through the ones that do);
// back faces of closed components are skipped (Mesh::face_closed; on closed meshes the
// raster culls them). Each candidate
// overlapping the pixel (at most MAX_CAND) is clipped to it; its visible part is that
// clip minus every other candidate that overlaps it and is nearer at the centroid of
// their overlap (ties: the lower id is nearer), kept as at most MAX_PIECES convex pieces.
// Exact for triangles that do not intersect. Returns the number of parts written to
// `parts` (in candidate order), or OVERFLOW when more than MAX_QUEUE triangles were to be
// examined or more than MAX_CAND overlap the pixel (a vertex shared by dozens of
// triangles, a fan's apex); the caller then falls back to its samples.
fn coverage_parts(col: u32, row: u32, layer: u32, queue_in: array<u32, 64>, n_seed: u32,
                  n_listed: u32, parts: ptr<function, array<Part, 32>>) -> u32 {
    let rot = rotations[layer];
    let x0 = -params.ext + f32(col) * params.pix;
    let y0 = params.ext - f32(row) * params.pix;
    let inv = 1.0 / params.pix;
    let adj_base = 3u * params.n_tri * (1u + params.has_normals);
    var queue = queue_in;
    var n_q = n_listed;
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
        // (the back faces of closed components: Mesh::face_closed at the third corner)
        let hidden_back = bitcast<u32>(geometry[3u * t + 2u].w) != 0u && den > 0.0;
        var overlaps = den != 0.0 && !hidden_back;
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
        if (qi < n_seed || (overlaps && qi >= n_listed)) {
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
