//! Ray casting against a triangle mesh in f64: a bounding volume hierarchy ([`Bvh`]) and
//! the ray-triangle test it uses. The foundation of inter-reflections between parts
//! (issue 23: light reaching a pixel's surface after reflections from other parts of the
//! mesh, occlusion toward the transmitter and the receiver along each path).
//!
//! Conventions: a ray is `o + t d` with `t` in `(t_min, t_max)`; `d` need not be unit
//! length (`t` is in units of `|d|`). Triangles are `[a, b, c]` in any frame; both sides
//! are hit (no culling), and a hit reports the barycentric `(u, v)` of `b` and `c`.
//!
//! The tree: nodes in one flat array (depth first, left child next to its parent), each an
//! axis-aligned box and either two children or a run of at most [`LEAF_SIZE`] triangles of
//! the permuted triangle list. Built top-down by the binned surface-area heuristic
//! (`SAH_BINS` centroid bins per axis), at the median centroid along the longest axis
//! where it cannot split or below depth `SAH_DEPTH` (so the depth stays under `SAH_DEPTH +
//! log2(n / LEAF_SIZE)`, within the fixed stack of the WGSL walk, `shaders/raycast.wgsl`;
//! the CPU's grows as needed). Walks visit the nearer child first. The flat layout is what
//! a GPU kernel can walk with a small stack.

use crate::optics::frames::{cross, dot, V3};

/// Most triangles in a leaf.
pub const LEAF_SIZE: usize = 4;

/// A node: its box, and `first`/`count` of its triangles (a leaf, `count > 0`) or the
/// index of its right child (`count == 0`; the left child is the next node).
#[derive(Debug, Clone, Copy)]
struct Node {
    lo: V3,
    hi: V3,
    first: u32,
    count: u32,
}

/// The closest hit of a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f64,
    /// Index of the triangle in the list the tree was built from.
    pub tri: usize,
    /// Barycentric weights of the triangle's second and third vertices.
    pub u: f64,
    pub v: f64,
}

/// A bounding volume hierarchy over triangles.
#[derive(Debug, Clone)]
pub struct Bvh {
    tris: Vec<[V3; 3]>,
    /// `order[k]`: the original index of the `k`-th triangle of `tris`.
    order: Vec<usize>,
    nodes: Vec<Node>,
}

/// The ray-triangle intersection (Moller-Trumbore, f64): `(t, u, v)` for a hit with `t`
/// in `(t_min, t_max)`, `u, v >= 0`, `u + v <= 1`; `None` for a miss or a ray parallel to
/// the triangle's plane (determinant zero).
#[inline]
pub fn intersect(o: V3, d: V3, tri: &[V3; 3], t_min: f64, t_max: f64) -> Option<(f64, f64, f64)> {
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - tri[0];
    let u = dot(s, p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = cross(s, e1);
    let v = dot(d, q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = dot(e2, q) * inv;
    (t > t_min && t < t_max).then_some((t, u, v))
}

/// Where the ray enters the box within `(t_min, t_max)` (slabs; `inv_d` = 1 / d per axis,
/// infinite for a zero component), or `None` if it misses it there.
#[inline]
fn box_entry(o: V3, inv_d: V3, lo: V3, hi: V3, t_min: f64, t_max: f64) -> Option<f64> {
    let (mut t0, mut t1) = (t_min, t_max);
    for k in 0..3 {
        let (a, b) = ((lo[k] - o[k]) * inv_d[k], (hi[k] - o[k]) * inv_d[k]);
        // 0 * inf (an origin on a slab plane of a parallel ray) is NaN: that axis admits all
        let (near, far) = if a <= b { (a, b) } else { (b, a) };
        if near > t0 {
            t0 = near;
        }
        if far < t1 {
            t1 = far;
        }
        if t0 > t1 {
            return None;
        }
    }
    Some(t0)
}

fn bounds(tris: &[[V3; 3]]) -> (V3, V3) {
    let mut lo = V3::splat(f64::INFINITY);
    let mut hi = V3::splat(f64::NEG_INFINITY);
    for t in tris {
        for v in t {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    (lo, hi)
}

impl Bvh {
    /// The tree over `tris` (their indices are kept: [`Hit::tri`]).
    pub fn new(tris: &[[V3; 3]]) -> Self {
        let mut items: Vec<(usize, [V3; 3])> = tris.iter().copied().enumerate().collect();
        let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF_SIZE + 1);
        if !items.is_empty() {
            build(&mut items, 0, &mut nodes);
        }
        Bvh {
            order: items.iter().map(|(i, _)| *i).collect(),
            tris: items.into_iter().map(|(_, t)| t).collect(),
            nodes,
        }
    }

    /// The nodes as `shaders/raycast.wgsl` reads them: per node `[lo.x, lo.y, lo.z,
    /// bits(first), hi.x, hi.y, hi.z, bits(count)]` in f32, the bounds rounded outward so
    /// that they contain their triangles' f32 corners.
    pub fn gpu_nodes(&self) -> Vec<[f32; 8]> {
        let down = |x: f64| {
            let f = x as f32;
            if f as f64 > x {
                f.next_down()
            } else {
                f
            }
        };
        let up = |x: f64| {
            let f = x as f32;
            if (f as f64) < x {
                f.next_up()
            } else {
                f
            }
        };
        self.nodes
            .iter()
            .map(|n| {
                [
                    down(n.lo.x),
                    down(n.lo.y),
                    down(n.lo.z),
                    f32::from_bits(n.first),
                    up(n.hi.x),
                    up(n.hi.y),
                    up(n.hi.z),
                    f32::from_bits(n.count),
                ]
            })
            .collect()
    }

    /// The triangles in the tree's order as `shaders/raycast.wgsl` reads them: three
    /// corners `[x, y, z, w]` each in f32, `w` of the first the bits of the triangle's index
    /// in the list the tree was built from.
    pub fn gpu_triangles(&self) -> Vec<[f32; 4]> {
        let mut out = Vec::with_capacity(3 * self.tris.len());
        for (t, &i) in self.tris.iter().zip(&self.order) {
            for (c, v) in t.iter().enumerate() {
                let w = if c == 0 {
                    f32::from_bits(i as u32)
                } else {
                    0.0
                };
                out.push([v.x as f32, v.y as f32, v.z as f32, w]);
            }
        }
        out
    }

    /// Number of nodes (for tests and statistics).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The closest hit of the ray `o + t d` with `t` in `(t_min, t_max)`, or `None`.
    pub fn closest_hit(&self, o: V3, d: V3, t_min: f64, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_far = t_max;
        self.walk(o, d, t_min, &mut t_far, &mut |k, t, u, v| {
            best = Some(Hit {
                t,
                tri: self.order[k],
                u,
                v,
            });
            false
        });
        best
    }

    /// Whether the ray meets any triangle other than `skip` within `(t_min, t_max)`.
    pub fn any_hit(&self, o: V3, d: V3, t_min: f64, t_max: f64, skip: Option<usize>) -> bool {
        let mut found = false;
        let mut t_far = t_max;
        self.walk_filtered(o, d, t_min, &mut t_far, skip, &mut |_, _, _, _| {
            found = true;
            true
        });
        found
    }

    fn walk(
        &self,
        o: V3,
        d: V3,
        t_min: f64,
        t_far: &mut f64,
        on_hit: &mut dyn FnMut(usize, f64, f64, f64) -> bool,
    ) {
        self.walk_filtered(o, d, t_min, t_far, None, on_hit)
    }

    /// Visit the triangles whose boxes the ray meets before `t_far`; each hit closer than
    /// `t_far` is passed to `on_hit` (permuted index, t, u, v) and becomes the new `t_far`;
    /// `on_hit` returning true stops the walk.
    fn walk_filtered(
        &self,
        o: V3,
        d: V3,
        t_min: f64,
        t_far: &mut f64,
        skip: Option<usize>,
        on_hit: &mut dyn FnMut(usize, f64, f64, f64) -> bool,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let inv_d = V3::ONE / d;
        let root = &self.nodes[0];
        let Some(t_root) = box_entry(o, inv_d, root.lo, root.hi, t_min, *t_far) else {
            return;
        };
        // nodes to visit with where the ray enters their boxes: the nearer child on top
        // (the thread's stack, reused: a fresh array per ray cost its zeroing, 5% of a
        // 2-bounce render)
        STACK.with_borrow_mut(|stack| {
            stack.clear();
            stack.push((0u32, t_root));
            while let Some((idx, t_enter)) = stack.pop() {
                if t_enter > *t_far {
                    continue;
                }
                let n = self.nodes[idx as usize];
                if n.count > 0 {
                    for k in n.first as usize..(n.first + n.count) as usize {
                        if skip == Some(self.order[k]) {
                            continue;
                        }
                        if let Some((t, u, v)) = intersect(o, d, &self.tris[k], t_min, *t_far) {
                            *t_far = t;
                            if on_hit(k, t, u, v) {
                                return;
                            }
                        }
                    }
                } else {
                    let (l, r) = (idx + 1, n.first);
                    let enter = |c: u32| {
                        let b = &self.nodes[c as usize];
                        box_entry(o, inv_d, b.lo, b.hi, t_min, *t_far)
                    };
                    match (enter(l), enter(r)) {
                        (Some(tl), Some(tr)) => {
                            let (near, far) = if tl <= tr {
                                ((l, tl), (r, tr))
                            } else {
                                ((r, tr), (l, tl))
                            };
                            stack.push(far);
                            stack.push(near);
                        }
                        (Some(tl), None) => stack.push((l, tl)),
                        (None, Some(tr)) => stack.push((r, tr)),
                        (None, None) => {}
                    }
                }
            }
        })
    }
}

thread_local! {
    /// Each thread's walk stack ([`Bvh::walk_filtered`]; a walk's `on_hit` must not walk).
    static STACK: std::cell::RefCell<Vec<(u32, f64)>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Bins per axis of the surface-area heuristic ([`build`]).
const SAH_BINS: usize = 16;
/// Below this depth splits follow the surface-area heuristic; from it on, the median
/// (a bound on the depth, for the walk's fixed stack).
const SAH_DEPTH: usize = 40;

/// Surface area of a box (half of it: only ratios matter).
fn half_area(lo: V3, hi: V3) -> f64 {
    let e = (hi - lo).max(V3::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// Build the subtree of `items` (whose triangles start at `offset` of the final list) into
/// `nodes`; returns its root's index. Splits by the binned surface-area heuristic (the
/// plane between [`SAH_BINS`] centroid bins per axis that minimises `A_left N_left + A_right
/// N_right`; Wald 2007), at the median centroid along the longest axis where all centroids
/// coincide or below [`SAH_DEPTH`].
fn build(items: &mut [(usize, [V3; 3])], offset: usize, nodes: &mut Vec<Node>) -> u32 {
    build_at(items, offset, nodes, 0)
}

fn build_at(
    items: &mut [(usize, [V3; 3])],
    offset: usize,
    nodes: &mut Vec<Node>,
    depth: usize,
) -> u32 {
    let tris: Vec<[V3; 3]> = items.iter().map(|(_, t)| *t).collect();
    let (lo, hi) = bounds(&tris);
    let me = nodes.len() as u32;
    nodes.push(Node {
        lo,
        hi,
        first: offset as u32,
        count: items.len() as u32,
    });
    if items.len() <= LEAF_SIZE {
        return me;
    }
    let centroid = |t: &[V3; 3]| (t[0] + t[1] + t[2]) / 3.0;
    let (mut c_lo, mut c_hi) = (V3::splat(f64::INFINITY), V3::splat(f64::NEG_INFINITY));
    for (_, t) in items.iter() {
        let c = centroid(t);
        c_lo = c_lo.min(c);
        c_hi = c_hi.max(c);
    }
    let mid = match (depth < SAH_DEPTH)
        .then(|| sah_split(items, c_lo, c_hi))
        .flatten()
    {
        Some(m) => m,
        None => {
            let ext = hi - lo;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = items.len() / 2;
            items.select_nth_unstable_by(mid, |a, b| {
                centroid(&a.1)[axis].total_cmp(&centroid(&b.1)[axis])
            });
            mid
        }
    };
    let (left, right) = items.split_at_mut(mid);
    let l = build_at(left, offset, nodes, depth + 1);
    let r = build_at(right, offset + mid, nodes, depth + 1);
    debug_assert_eq!(l, me + 1);
    nodes[me as usize].first = r;
    nodes[me as usize].count = 0;
    me
}

/// The binned surface-area split of `items` (centroids within `[c_lo, c_hi]`): partitions
/// them in place and returns the size of the left part, or `None` where no plane separates
/// two non-empty parts (all centroids in one bin on every axis).
fn sah_split(items: &mut [(usize, [V3; 3])], c_lo: V3, c_hi: V3) -> Option<usize> {
    let centroid = |t: &[V3; 3]| (t[0] + t[1] + t[2]) / 3.0;
    let mut best: Option<(f64, usize, usize)> = None; // (cost, axis, bins on the left)
    for axis in 0..3 {
        let (a, b) = (c_lo[axis], c_hi[axis]);
        if b <= a || b.is_nan() || a.is_nan() {
            continue;
        }
        let scale = SAH_BINS as f64 / (b - a);
        let bin = |t: &[V3; 3]| (((centroid(t)[axis] - a) * scale) as usize).min(SAH_BINS - 1);
        let mut count = [0usize; SAH_BINS];
        let mut boxes = [(V3::splat(f64::INFINITY), V3::splat(f64::NEG_INFINITY)); SAH_BINS];
        for (_, t) in items.iter() {
            let k = bin(t);
            count[k] += 1;
            for v in t {
                boxes[k].0 = boxes[k].0.min(*v);
                boxes[k].1 = boxes[k].1.max(*v);
            }
        }
        // sweep from the right: the area and count of bins k.. for each k
        let mut right = [(0.0f64, 0usize); SAH_BINS];
        let (mut rl, mut rh, mut rn) = (V3::splat(f64::INFINITY), V3::splat(f64::NEG_INFINITY), 0);
        for k in (1..SAH_BINS).rev() {
            rl = rl.min(boxes[k].0);
            rh = rh.max(boxes[k].1);
            rn += count[k];
            right[k] = (half_area(rl, rh), rn);
        }
        let (mut ll, mut lh, mut ln) = (V3::splat(f64::INFINITY), V3::splat(f64::NEG_INFINITY), 0);
        for k in 1..SAH_BINS {
            ll = ll.min(boxes[k - 1].0);
            lh = lh.max(boxes[k - 1].1);
            ln += count[k - 1];
            let (ra, rn) = right[k];
            if ln == 0 || rn == 0 {
                continue;
            }
            let cost = half_area(ll, lh) * ln as f64 + ra * rn as f64;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, k));
            }
        }
    }
    let (_, axis, k) = best?;
    let (a, b) = (c_lo[axis], c_hi[axis]);
    let scale = SAH_BINS as f64 / (b - a);
    let left_of = |t: &[V3; 3]| (((centroid(t)[axis] - a) * scale) as usize).min(SAH_BINS - 1) < k;
    // partition in place, keeping the order within each side deterministic
    let mut i = 0;
    for j in 0..items.len() {
        if left_of(&items[j].1) {
            items.swap(i, j);
            i += 1;
        }
    }
    (i > 0 && i < items.len()).then_some(i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::test_scenes::sphere_and_plate;

    /// A small deterministic generator (xorshift64*), uniform in [0, 1).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn vec(&mut self, scale: f64) -> V3 {
            V3::new(self.next() - 0.5, self.next() - 0.5, self.next() - 0.5) * (2.0 * scale)
        }
    }

    /// The oracle, written apart from [`intersect`]: the ray meets the triangle's plane at
    /// `t = n.(a - o) / n.d`, and the point is inside when it is on the inner side of all
    /// three edges (edge functions against the normal).
    fn brute(
        tris: &[[V3; 3]],
        o: V3,
        d: V3,
        t_min: f64,
        t_max: f64,
        skip: Option<usize>,
    ) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        for (i, t) in tris.iter().enumerate() {
            if skip == Some(i) {
                continue;
            }
            let n = (t[1] - t[0]).cross(t[2] - t[0]);
            let den = n.dot(d);
            if den == 0.0 {
                continue;
            }
            let s = n.dot(t[0] - o) / den;
            if !(s > t_min && s < t_max) || best.is_some_and(|(_, b)| s >= b) {
                continue;
            }
            let p = o + s * d;
            let inside = (0..3).all(|k| (t[(k + 1) % 3] - t[k]).cross(p - t[k]).dot(n) >= 0.0);
            if inside {
                best = Some((i, s));
            }
        }
        best
    }

    fn soup(rng: &mut Rng, n: usize) -> Vec<[V3; 3]> {
        (0..n)
            .map(|_| {
                let c = rng.vec(1.0);
                [c + rng.vec(0.15), c + rng.vec(0.15), c + rng.vec(0.15)]
            })
            .collect()
    }

    fn mesh_tris() -> Vec<[V3; 3]> {
        let m = sphere_and_plate();
        m.faces
            .iter()
            .map(|f| f.map(|k| V3::from(m.vertices[k as usize])))
            .collect()
    }

    /// Closest hits and any-hit tests of random rays agree with the brute force: the same
    /// triangle and `t` to 1e-12 relative (the two formulas round differently; rays that
    /// graze an edge within that can pick a neighbour, which then has the same `t`).
    #[test]
    fn closest_and_any_hit_match_brute_force() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for tris in [soup(&mut rng, 700), mesh_tris()] {
            let bvh = Bvh::new(&tris);
            // leaves of up to LEAF_SIZE triangles: fewer nodes than triangles here
            assert!(bvh.node_count() < tris.len());
            let (mut hits, mut checked) = (0, 0);
            for k in 0..3000 {
                let o = rng.vec(2.0);
                // every fourth ray axis-aligned (zero direction components: infinite slabs)
                let d = if k % 4 == 0 {
                    let mut d = V3::ZERO;
                    d[k / 4 % 3] = if rng.next() < 0.5 { -1.0 } else { 1.0 };
                    d
                } else if k % 4 == 1 {
                    rng.vec(1.0)
                } else {
                    // aimed at a point near the middle: most of these hit
                    rng.vec(0.3) - o
                };
                let (t_min, t_max) = (1e-9, if k % 3 == 0 { 1.5 } else { f64::INFINITY });
                let want = brute(&tris, o, d, t_min, t_max, None);
                let got = bvh.closest_hit(o, d, t_min, t_max);
                match (want, got) {
                    (None, None) => {}
                    (Some((i, t)), Some(h)) => {
                        hits += 1;
                        assert!(
                            (h.t - t).abs() <= 1e-12 * t.abs().max(1.0),
                            "ray {k}: t {} vs {t}",
                            h.t
                        );
                        if h.tri != i {
                            // a tie on a shared edge or a coplanar neighbour: same t
                            assert!((h.t - t).abs() <= 1e-12 * t.abs().max(1.0));
                        }
                        let p = o + h.t * d;
                        let tr = &tris[h.tri];
                        let q = tr[0] + h.u * (tr[1] - tr[0]) + h.v * (tr[2] - tr[0]);
                        assert!((p - q).length() <= 1e-9, "ray {k}: barycentrics");
                    }
                    (w, g) => {
                        // only a ray grazing an edge within rounding may differ: check it is one
                        let t = w.map(|x| x.1).or(g.map(|h| h.t)).unwrap();
                        let p = o + t * d;
                        let near_edge = tris.iter().any(|tr| {
                            (0..3).any(|e| {
                                let (a, b) = (tr[e], tr[(e + 1) % 3]);
                                let ab = b - a;
                                let s = ((p - a).dot(ab) / ab.dot(ab)).clamp(0.0, 1.0);
                                (a + s * ab - p).length() < 1e-9
                            })
                        });
                        assert!(near_edge, "ray {k}: brute {w:?}, bvh {g:?}");
                    }
                }
                let skip = want.map(|(i, _)| i);
                let any_want = brute(&tris, o, d, t_min, t_max, skip).is_some();
                assert_eq!(
                    bvh.any_hit(o, d, t_min, t_max, skip),
                    any_want,
                    "ray {k}: any_hit"
                );
                checked += 1;
            }
            assert!(hits > 1000, "too few hits to test: {hits} of {checked}");
        }
    }

    /// Rays parallel to a triangle's plane, a zero direction, an empty tree and NaN input
    /// give no hit (no NaN `t`, no panic).
    /// Trees the surface-area heuristic would make deep (triangles at exponentially spaced
    /// positions, each a factor 1.5 farther out) and trees it cannot split (1000 copies of
    /// one triangle) stay within the walk's stack and find the brute force's hits.
    #[test]
    fn unbalanced_and_unsplittable_trees_are_walked() {
        fn depth(bvh: &Bvh, k: usize) -> usize {
            let n = bvh.nodes[k];
            if n.count > 0 {
                1
            } else {
                1 + depth(bvh, k + 1).max(depth(bvh, n.first as usize))
            }
        }
        let tri = |x: f64| {
            [
                V3::new(x, 0.0, 0.0),
                V3::new(x, 1.0, 0.0),
                V3::new(x, 0.0, 1.0),
            ]
        };
        let spread: Vec<[V3; 3]> = (0..1500)
            .map(|k| tri(1.5f64.powi(k % 1500 / 2) * 1e-300))
            .collect();
        let same: Vec<[V3; 3]> = (0..1000).map(|_| tri(0.5)).collect();
        for tris in [spread, same] {
            let bvh = Bvh::new(&tris);
            let d = depth(&bvh, 0);
            assert!(d < 90, "depth {d}");
            for y in [0.1, 0.3, 0.45] {
                let (o, dir) = (V3::new(-1.0, y, 0.2), V3::X);
                let want = brute(&tris, o, dir, 0.0, f64::INFINITY, None).map(|(_, t)| t);
                let got = bvh.closest_hit(o, dir, 0.0, f64::INFINITY).map(|h| h.t);
                assert_eq!(want, got);
            }
        }
    }

    #[test]
    fn degenerate_rays_and_trees_miss() {
        let tri = [
            V3::new(0.0, 0.0, 0.0),
            V3::new(1.0, 0.0, 0.0),
            V3::new(0.0, 1.0, 0.0),
        ];
        let bvh = Bvh::new(&[tri]);
        let o = V3::new(0.2, 0.2, 1.0);
        assert!(bvh
            .closest_hit(o, V3::new(1.0, 0.0, 0.0), 0.0, f64::INFINITY)
            .is_none());
        assert!(bvh.closest_hit(o, V3::ZERO, 0.0, f64::INFINITY).is_none());
        assert!(bvh
            .closest_hit(V3::splat(f64::NAN), V3::Z, 0.0, f64::INFINITY)
            .is_none());
        let h = bvh.closest_hit(o, -V3::Z, 0.0, f64::INFINITY).unwrap();
        assert_eq!((h.tri, h.t), (0, 1.0));
        assert!(
            bvh.closest_hit(o, -V3::Z, 0.0, 1.0).is_none(),
            "t_max is exclusive"
        );
        assert!(!bvh.any_hit(o, -V3::Z, 0.0, f64::INFINITY, Some(0)));
        let empty = Bvh::new(&[]);
        assert_eq!(empty.node_count(), 0);
        assert!(empty.closest_hit(o, -V3::Z, 0.0, f64::INFINITY).is_none());
        assert!(!empty.any_hit(o, -V3::Z, 0.0, f64::INFINITY, None));
    }
}
