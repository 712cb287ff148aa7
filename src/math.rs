//! Small fixed-size vector helpers on `[f64; 3]` / `[f32; 3]` used by the geometry
//! code. (nalgebra serves the matrix work; these keep hot geometric loops plain.)

/// a − b
#[inline]
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
/// a + b
#[inline]
pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
/// s·a
#[inline]
pub fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}
/// a · b
#[inline]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
/// a × b
#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
/// |a|
#[inline]
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}
/// |a − b|²
#[inline]
pub fn dist_sq(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}
/// a / |a|, or `None` when |a| is zero or not finite.
#[inline]
pub fn normalize(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = norm(a);
    if n > 0.0 && n.is_finite() {
        Some(scale(a, 1.0 / n))
    } else {
        None
    }
}
/// Row-major 3×3 matrix times vector.
#[inline]
pub fn mat_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}
/// Widens an f32 point.
#[inline]
pub fn to_f64(p: [f32; 3]) -> [f64; 3] {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}
/// Narrows an f64 point.
#[inline]
pub fn to_f32(p: [f64; 3]) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn cross_is_orthogonal_and_right_handed() {
        let c = cross([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        assert_eq!(c, [0.0, 0.0, 1.0]);
        let a = [0.3, -1.2, 2.0];
        let b = [1.5, 0.1, -0.7];
        let c = cross(a, b);
        assert!(dot(a, c).abs() < 1e-12 && dot(b, c).abs() < 1e-12);
        assert!(normalize([0.0; 3]).is_none());
        assert!((norm(normalize(a).unwrap()) - 1.0).abs() < 1e-12);
    }
}
