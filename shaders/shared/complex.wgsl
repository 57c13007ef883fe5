// Complex arithmetic on vec2<f32> (re, im), for the Fresnel amplitudes of the in-kernel
// single term.

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
