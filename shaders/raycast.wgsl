// Closest hits of a batch of rays against a triangle mesh, walking the flat BVH built on
// the CPU (render::bvh::Bvh, its GPU layout Bvh::gpu_nodes / gpu_triangles): one
// invocation per ray. The groundwork of inter-reflections on the device (issue 23): wgpu
// has no portable ray queries (lavapipe has none), so the tree is walked by hand.
//
// Layout (f32, std430):
//   nodes[k] = (lo.xyz, first), (hi.xyz, count): count > 0 a leaf of triangles
//     first..first+count of `tris`; count = 0 an inner node, its left child k + 1 and its
//     right child `first`. Bounds are rounded outward from the f64 tree (they contain
//     their triangles in f32).
//   tris[3 j + c] = corner c of the j-th triangle in the tree's order, w = the bits of its
//     index in the mesh (at corner 0).
//   rays[2 i] = (o.xyz, t_min >= 0), rays[2 i + 1] = (d.xyz, t_max).
//   hits[i] = (t, bits of the mesh triangle index or 0xffffffff for a miss, u, v).
// The walk visits the nearer child first and skips boxes entered beyond the closest hit so
// far, with a stack of 96 (the tree's depth is under 40 + log2(n / 4)). The ray-triangle
// test is Moller-Trumbore, two-sided, as the f64 twin (render::bvh::intersect); ties and
// f32 rounding near edges can pick another triangle at the same t or miss a ray that
// grazes an edge (render::gpu::raycast tests count them).

struct Node {
    lo: vec3<f32>,
    first: u32,
    hi: vec3<f32>,
    count: u32,
}

@group(0) @binding(0) var<storage, read> nodes: array<Node>;
@group(0) @binding(1) var<storage, read> tris: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> rays: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> hits: array<vec4<f32>>;

const MISS: u32 = 0xffffffffu;
const STACK: u32 = 96u;

// Where the ray enters the box within (t_min, t_max), or -1 if it misses it there.
fn box_entry(o: vec3<f32>, inv_d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>, t_min: f32,
             t_max: f32) -> f32 {
    let a = (lo - o) * inv_d;
    let b = (hi - o) * inv_d;
    // an origin on a slab plane of a parallel ray gives 0 * inf = NaN: max/min with the
    // running bounds then keep them (that axis admits all)
    let near = min(a, b);
    let far = max(a, b);
    var t0 = t_min;
    var t1 = t_max;
    for (var k = 0; k < 3; k++) {
        if (near[k] > t0) {
            t0 = near[k];
        }
        if (far[k] < t1) {
            t1 = far[k];
        }
    }
    return select(-1.0, t0, t0 <= t1);
}

@compute @workgroup_size(64, 1, 1)
fn cs_raycast(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= arrayLength(&hits)) {
        return;
    }
    let od = rays[2u * i];
    let dd = rays[2u * i + 1u];
    let o = od.xyz;
    let d = dd.xyz;
    let t_min = od.w;
    var t_far = dd.w;
    let inv_d = vec3<f32>(1.0) / d;
    var best = vec4<f32>(0.0, bitcast<f32>(MISS), 0.0, 0.0);
    var stack: array<u32, 96>;
    var enter: array<f32, 96>;
    var top = 0u;
    if (arrayLength(&nodes) > 0u) {
        let t_root = box_entry(o, inv_d, nodes[0].lo, nodes[0].hi, t_min, t_far);
        if (t_root >= 0.0) {
            stack[0] = 0u;
            enter[0] = t_root;
            top = 1u;
        }
    }
    while (top > 0u) {
        top -= 1u;
        if (enter[top] > t_far) {
            continue;
        }
        let n = nodes[stack[top]];
        let idx = stack[top];
        if (n.count > 0u) {
            for (var j = n.first; j < n.first + n.count; j++) {
                let a = tris[3u * j].xyz;
                let e1 = tris[3u * j + 1u].xyz - a;
                let e2 = tris[3u * j + 2u].xyz - a;
                let p = cross(d, e2);
                let det = dot(e1, p);
                if (det == 0.0) {
                    continue;
                }
                let inv = 1.0 / det;
                let s = o - a;
                let u = dot(s, p) * inv;
                if (u < 0.0 || u > 1.0) {
                    continue;
                }
                let q = cross(s, e1);
                let v = dot(d, q) * inv;
                if (v < 0.0 || u + v > 1.0) {
                    continue;
                }
                let t = dot(e2, q) * inv;
                if (t > t_min && t < t_far) {
                    t_far = t;
                    best = vec4<f32>(t, tris[3u * j].w, u, v);
                }
            }
        } else {
            let l = idx + 1u;
            let r = n.first;
            let tl = box_entry(o, inv_d, nodes[l].lo, nodes[l].hi, t_min, t_far);
            let tr = box_entry(o, inv_d, nodes[r].lo, nodes[r].hi, t_min, t_far);
            if (top + 2u > STACK) {
                // deeper than any tree the CPU builds: give up on this ray (reported as
                // a miss with t = -1)
                best = vec4<f32>(-1.0, bitcast<f32>(MISS), 0.0, 0.0);
                break;
            }
            if (tl >= 0.0 && tr >= 0.0) {
                let l_first = tl <= tr;
                stack[top] = select(l, r, l_first);
                enter[top] = select(tl, tr, l_first);
                stack[top + 1u] = select(r, l, l_first);
                enter[top + 1u] = select(tr, tl, l_first);
                top += 2u;
            } else if (tl >= 0.0) {
                stack[top] = l;
                enter[top] = tl;
                top += 1u;
            } else if (tr >= 0.0) {
                stack[top] = r;
                enter[top] = tr;
                top += 1u;
            }
        }
    }
    hits[i] = best;
}
