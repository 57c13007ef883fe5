// Table lookup: port of src/brdf/table/ (interp.rs, grid.rs; layout in the docs of
// BrdfTable). Uses the shade kernel's `tables` binding and its ELEMENT_MASK, PI,
// HEADER_WORDS and LN_FLOOR_F32.

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

