//! Reference geometry for the augmentation tests: F_info's shape columns (scaled
//! Jacobian, corner sines, unit corner normals) straight from DESIGN §2's definitions
//! in f64, and a linear map applied in f64.

#![allow(dead_code)]

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// `m · p` in f64.
pub fn apply(m: &[[f64; 3]; 3], p: [f32; 3]) -> [f64; 3] {
    let v = [p[0] as f64, p[1] as f64, p[2] as f64];
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// Columns 12–28 of F_info for corners `p` (cyclic order): e_i = p_{i+1} − p_i,
/// c_i = e_{i−1} × e_i, sine_i = |c_i| / (|e_{i−1}||e_i|), normal_i = c_i / |c_i|,
/// Jacobian = min_i (c_i · n) / (|e_{i−1}||e_i|), n = normalize((p2 − p0) × (p3 − p1)).
pub fn shape_columns(p: [[f64; 3]; 4]) -> [f64; 17] {
    let e: Vec<[f64; 3]> = (0..4).map(|i| sub(p[(i + 1) % 4], p[i])).collect();
    let nd = cross(sub(p[2], p[0]), sub(p[3], p[1]));
    let n = nd.map(|x| x / norm(nd));
    let mut out = [0.0; 17];
    let mut jac = f64::INFINITY;
    for i in 0..4 {
        let prev = e[(i + 3) % 4];
        let c = cross(prev, e[i]);
        let ll = norm(prev) * norm(e[i]);
        out[1 + i] = norm(c) / ll;
        for a in 0..3 {
            out[5 + 3 * i + a] = c[a] / norm(c);
        }
        jac = jac.min(dot(c, n) / ll);
    }
    out[0] = jac;
    out
}
