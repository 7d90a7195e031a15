//! Triangles (LINKS-1 primitive 1) with a watertight intersection test.
//!
//! The test is Woop, Benthin and Wald's (as in pbrt): translate, permute and shear the
//! vertices into a frame where the ray is the +Z axis, then evaluate the three 2-D edge
//! functions. Neighbouring triangles compute their shared edge function from the same
//! products, so its value is exactly negated between them; an edge function that is exactly
//! zero is given the sign of a tie-break on the edge's direction (the rasteriser's top-left
//! rule), so a ray through a shared edge or vertex of a closed mesh is accepted by exactly
//! one triangle of each layer: no cracks, no double hits.

use crate::geom::{Ray, Vec3};
use crate::num::Real;

pub use crate::math::solid::Triangle;

/// Where a ray crossed a triangle: distance and barycentric weights of p0, p1, p2.
#[derive(Clone, Copy, Debug)]
pub struct TriHit<T> {
    pub t: T,
    pub b: [T; 3],
}

/// Sign of edge function `e` for the directed 2-D edge `(ax, ay) -> (bx, by)`; exact zeros
/// are broken by the edge direction, which flips for the neighbour that shares the edge.
#[inline]
fn edge_positive<T: Real>(e: T, ax: T, ay: T, bx: T, by: T) -> bool {
    if e != T::ZERO {
        return e > T::ZERO;
    }
    let dy = by - ay;
    let dx = bx - ax;
    dy > T::ZERO || (dy == T::ZERO && dx < T::ZERO)
}

/// What every triangle test of one ray shares (Woop, Benthin and Wald): the ray's origin,
/// the axis permutation that makes the largest direction component z, and the shear that
/// turns the ray into the +z axis. Made once per ray instead of once per triangle.
#[derive(Clone, Copy, Debug)]
pub struct Shear<T> {
    origin: Vec3<T>,
    kz: usize,
    sx: T,
    sy: T,
    sz: T,
}

impl<T: Real> Shear<T> {
    /// The axis of the ray's largest direction component (z after the permutation).
    #[inline(always)]
    pub fn kz(&self) -> usize {
        self.kz
    }

    /// A placeholder for rays that will test no triangle (no set-up work).
    #[inline]
    pub fn unused() -> Self {
        Self {
            origin: Vec3::zero(),
            kz: 2,
            sx: T::ZERO,
            sy: T::ZERO,
            sz: T::ONE,
        }
    }

    #[inline]
    pub fn new(ray: &Ray<T>) -> Self {
        let kz = ray.dir.abs().max_dimension();
        let kx = if kz == 2 { 0 } else { kz + 1 };
        let ky = if kx == 2 { 0 } else { kx + 1 };
        let d = ray.dir.permute(kx, ky, kz);
        let sz = d.z.recip();
        Self {
            origin: ray.origin,
            kz,
            sx: -d.x * sz,
            sy: -d.y * sz,
            sz,
        }
    }
}

impl<T: Real> Triangle<T> {
    /// Unnormalised geometric normal (p1 - p0) x (p2 - p0).
    #[inline]
    pub fn face_normal(&self) -> Vec3<T> {
        let (a, b) = (self.p[1] - self.p[0], self.p[2] - self.p[0]);
        if T::ABSOLUTE_ROUNDING {
            // Fixed point: a small triangle's edges have few significant bits and their
            // cross product fewer still; scale each edge up by a power of two (exact) first.
            (a * T::unit_scale(a.max_abs())).cross(b * T::unit_scale(b.max_abs()))
        } else {
            a.cross(b)
        }
    }

    /// Intersect for t in (0, t_max). Two-sided.
    #[inline]
    pub fn intersect(&self, ray: &Ray<T>, t_max: T) -> Option<TriHit<T>> {
        self.intersect_sheared(&Shear::new(ray), t_max)
    }

    /// [`Self::intersect`] with the ray's part of the work done once per ray.
    // The negated comparisons in the test are deliberate: they reject NaN.
    #[inline]
    pub fn intersect_sheared(&self, ray: &Shear<T>, t_max: T) -> Option<TriHit<T>> {
        // One copy per axis permutation, so the permutation is register naming, not
        // run-time component selects.
        match ray.kz {
            0 => self.intersect_permuted::<1, 2, 0>(ray, t_max),
            1 => self.intersect_permuted::<2, 0, 1>(ray, t_max),
            _ => self.intersect_permuted::<0, 1, 2>(ray, t_max),
        }
    }

    fn intersect_permuted<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        ray: &Shear<T>,
        t_max: T,
    ) -> Option<TriHit<T>> {
        self.intersect_permuted_inline::<KX, KY, KZ>(ray, t_max)
    }

    /// The test for a ray whose permutation (`ray.kz() == KZ`, `KX`, `KY` the next axes
    /// cyclically) the caller has matched once for many triangles: inlined into that loop,
    /// the vertices go from the scene image straight into registers.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline(always)]
    pub fn intersect_permuted_inline<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        ray: &Shear<T>,
        t_max: T,
    ) -> Option<TriHit<T>> {
        // Translate to the ray origin, permute so the largest direction component is z.
        let permute = |v: Vec3<T>| {
            let c = [v.x, v.y, v.z];
            Vec3::new(c[KX], c[KY], c[KZ])
        };
        let mut p0 = permute(self.p[0] - ray.origin);
        let mut p1 = permute(self.p[1] - ray.origin);
        let mut p2 = permute(self.p[2] - ray.origin);

        // Shear so the ray runs along +z.
        let (sx, sy, sz) = (ray.sx, ray.sy, ray.sz);
        p0.x += sx * p0.z;
        p0.y += sy * p0.z;
        p1.x += sx * p1.z;
        p1.y += sy * p1.z;
        p2.x += sx * p2.z;
        p2.y += sy * p2.z;

        // Edge functions at the ray (the 2-D origin). Two strictly opposite signs reject
        // before the third is computed (the tie-break only matters for exact zeros).
        let e0 = p1.x * p2.y - p1.y * p2.x;
        let e1 = p2.x * p0.y - p2.y * p0.x;
        if (e0 > T::ZERO && e1 < T::ZERO) || (e0 < T::ZERO && e1 > T::ZERO) {
            return None;
        }
        let e2 = p0.x * p1.y - p0.y * p1.x;
        let s0 = edge_positive(e0, p1.x, p1.y, p2.x, p2.y);
        let s1 = edge_positive(e1, p2.x, p2.y, p0.x, p0.y);
        let s2 = edge_positive(e2, p0.x, p0.y, p1.x, p1.y);
        if !(s0 == s1 && s1 == s2) {
            return None;
        }
        let det = e0 + e1 + e2;
        // Written to reject NaN too (non-finite vertices or direction).
        if !(det.abs() > T::ZERO) {
            return None;
        }

        // Scaled distance, compared against t_max without dividing.
        p0.z *= sz;
        p1.z *= sz;
        p2.z *= sz;
        let t_scaled = e0 * p0.z + e1 * p1.z + e2 * p2.z;
        if det < T::ZERO && (t_scaled >= T::ZERO || t_scaled < t_max * det) {
            return None;
        }
        if det > T::ZERO && (t_scaled <= T::ZERO || t_scaled > t_max * det) {
            return None;
        }
        let inv_det = det.recip();
        let t = t_scaled * inv_det;

        // Conservative t > 0: reject hits within the rounding error of t (pbrt 6.5.5).
        let max_zt = p0.z.abs().max(p1.z.abs()).max(p2.z.abs());
        let delta_z = T::err_gamma(3) * max_zt;
        let max_xt = p0.x.abs().max(p1.x.abs()).max(p2.x.abs());
        let max_yt = p0.y.abs().max(p1.y.abs()).max(p2.y.abs());
        let delta_x = T::err_gamma(5) * (max_xt + max_zt);
        let delta_y = T::err_gamma(5) * (max_yt + max_zt);
        let delta_e =
            T::TWO * (T::err_gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
        let max_e = e0.abs().max(e1.abs()).max(e2.abs());
        let delta_t = T::from_i32(3)
            * (T::err_gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e)
            * inv_det.abs();
        if !(t > delta_t) {
            return None;
        }
        Some(TriHit {
            t,
            b: [e0 * inv_det, e1 * inv_det, e2 * inv_det],
        })
    }

    /// Hit point from barycentrics and its absolute error bound (pbrt: gamma(7) Σ|b_i p_i|).
    pub fn point(&self, b: [T; 3]) -> (Vec3<T>, Vec3<T>) {
        let p = self.p[0] * b[0] + self.p[1] * b[1] + self.p[2] * b[2];
        let err = ((self.p[0] * b[0]).abs() + (self.p[1] * b[1]).abs() + (self.p[2] * b[2]).abs())
            * T::err_gamma(7);
        (p, err)
    }
}

/// A triangle prepared for rays from the eye (the origin of view coordinates): the three
/// planes through the eye and each edge, and the triple product of the vertices.
///
/// A ray from the eye along `d` passes inside the triangle when `n_k . d` has the same sign
/// for all three edge planes; then `d = sum b_k p_k / t` with barycentrics
/// `b_k = e_k / sum e` and the hit at `t = det / sum e` (in units of `d`). An edge's plane is
/// computed from its endpoints in a fixed order (lower vertex index first) as `a x (b - a)`
/// and negated for the other direction, so two triangles sharing the edge get exactly
/// negated planes; writing it through `b - a` keeps the cancellation of nearly parallel
/// vertex vectors out of it. Each plane also carries a bound on the rounding error of
/// `n . d` for every ray with `|d|_1` up to a given length: a sign within it is not certain, and the triangle is then
/// decided by the sheared test instead ([`EyeTest::Uncertain`]). A ray near a shared edge
/// or vertex therefore meets every triangle around it in the same (watertight) test, and
/// every other triangle in a test whose signs are exact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgePlanes<T> {
    pub n: [Vec3<T>; 3],
    pub det: T,
    /// Per plane, the error bound of `n . d` for the rays the planes were made for.
    pub bound: [T; 3],
}

/// What the edge-plane test says about a ray from the eye.
#[derive(Clone, Copy, Debug)]
pub enum EyeTest<T> {
    Miss,
    Hit(TriHit<T>),
    /// A sign lies within its rounding error: ask [`Triangle::intersect_sheared`].
    Uncertain,
}

impl<T: Real> EyeTest<T> {
    /// The answer, asking the sheared test (with the same ray, normalised) when uncertain.
    #[inline]
    pub fn or_sheared(
        self,
        tri: impl FnOnce() -> Triangle<T>,
        ray: &Shear<T>,
        t_max: T,
    ) -> Option<TriHit<T>> {
        match self {
            EyeTest::Miss => None,
            EyeTest::Hit(h) => Some(h),
            EyeTest::Uncertain => tri().intersect_sheared(ray, t_max),
        }
    }
}

impl<T: Real> EdgePlanes<T> {
    pub const ZERO: Self = Self {
        n: [Vec3::new(T::ZERO, T::ZERO, T::ZERO); 3],
        det: T::ZERO,
        bound: [T::ZERO; 3],
    };

    /// The planes of `tri`, whose vertices have indices `index` (shared vertices share an
    /// index, which fixes each edge's orientation), for rays whose `|d|_1` is at most `l1`.
    pub fn new(tri: &Triangle<T>, index: [u32; 3], l1: T) -> Self {
        // |fl(n . d) - n . d| <= gamma(3) |n| |d|_1 + |fl(n) - n| |d|_1 (max norm for n);
        // each component of n = a x c (c = fl(b - a)) is at most 2 |a| |c| and lies within
        // 2 gamma(3) |a| |c| of the exact one, c within eps |c| of b - a. So 12 gamma(3)
        // |a| |c| |d|_1 bounds it, with room to spare.
        let k = T::from_i32(12) * T::err_gamma(3) * l1;
        let edge = |i: usize, j: usize| {
            let (a, b) = if index[i] < index[j] {
                (tri.p[i], tri.p[j])
            } else {
                (tri.p[j], tri.p[i])
            };
            let c = b - a;
            let n = a.cross(c);
            // The 1-norms (>= the max norms) cost fewer instructions than maxima.
            let norm1 = |v: Vec3<T>| v.x.abs() + v.y.abs() + v.z.abs();
            let bound = k * norm1(a) * norm1(c);
            (if index[i] < index[j] { n } else { -n }, bound)
        };
        let (n0, b0) = edge(1, 2);
        let (n1, b1) = edge(2, 0);
        let (n2, b2) = edge(0, 1);
        Self {
            n: [n0, n1, n2],
            det: n0.dot(tri.p[0]),
            bound: [b0, b1, b2],
        }
    }

    /// Intersect the ray from the eye along `d` (`len` = |d|; `|d|_1` at most the planes'
    /// `l1`) for distances (along the unit direction) in (0, t_max). Two-sided.
    // The negated comparisons below are deliberate: they reject NaN.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline(always)]
    pub fn intersect_from_eye(&self, d: Vec3<T>, len: T, t_max: T) -> EyeTest<T> {
        let [b0, b1, b2] = self.bound;
        let e0 = self.n[0].dot(d);
        let e1 = self.n[1].dot(d);
        // Most rays miss: two planes certainly on opposite sides decide it.
        if (e0 > b0 && e1 < -b1) || (e0 < -b0 && e1 > b1) {
            return EyeTest::Miss;
        }
        let e2 = self.n[2].dot(d);
        if (e2 > b2 && (e0 < -b0 || e1 < -b1)) || (e2 < -b2 && (e0 > b0 || e1 > b1)) {
            return EyeTest::Miss;
        }
        if !(e0.abs() > b0 && e1.abs() > b1 && e2.abs() > b2) {
            // Near an edge or vertex (or NaN): the whole triangle goes to the sheared test,
            // as does every triangle sharing that edge.
            return EyeTest::Uncertain;
        }
        // All three certain and none opposite: all of one sign.
        let s0 = e0 > T::ZERO;
        let sum = e0 + e1 + e2;
        // In front of the eye: det and the sum agree in sign (and neither is zero or NaN).
        let front = if s0 {
            sum > T::ZERO && self.det > T::ZERO
        } else {
            sum < T::ZERO && self.det < T::ZERO
        };
        if !front {
            return EyeTest::Miss;
        }
        let inv = sum.recip();
        let t = self.det * inv * len;
        if !(t < t_max) {
            return EyeTest::Miss;
        }
        EyeTest::Hit(TriHit {
            t,
            b: [e0 * inv, e1 * inv, e2 * inv],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> Triangle<f64> {
        Triangle {
            p: [
                Vec3::new(-1.0, -1.0, 5.0),
                Vec3::new(1.0, -1.0, 5.0),
                Vec3::new(0.0, 1.0, 5.0),
            ],
        }
    }

    #[test]
    fn hits_centre_with_right_distance_and_barycentrics() {
        let r = Ray::new(Vec3::zero(), Vec3::new(0.0, 0.0, 1.0));
        let h = tri().intersect(&r, f64::MAX).expect("hit");
        assert!((h.t - 5.0).abs() < 1e-12);
        let (p, _) = tri().point(h.b);
        assert!((p.x).abs() < 1e-12 && (p.y).abs() < 1e-12);
        assert!((h.b[0] + h.b[1] + h.b[2] - 1.0).abs() < 1e-12);
        assert!(
            (h.b[2] - 0.5).abs() < 1e-12,
            "centre (0,0) is halfway up to p2"
        );
    }

    #[test]
    fn misses_outside_behind_and_beyond_t_max() {
        let r = Ray::new(Vec3::zero(), Vec3::new(0.0, 0.0, 1.0));
        assert!(tri().intersect(&r, 4.9).is_none());
        let r = Ray::new(Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(tri().intersect(&r, f64::MAX).is_none());
        let r = Ray::new(Vec3::zero(), Vec3::new(0.0, 0.0, -1.0));
        assert!(tri().intersect(&r, f64::MAX).is_none());
    }

    #[test]
    fn shared_edge_hit_by_exactly_one_of_two_triangles() {
        // Two triangles sharing the edge x = 0; rays exactly on it.
        let a = Triangle {
            p: [
                Vec3::new(0.0f32, -1.0, 3.0),
                Vec3::new(0.0, 1.0, 3.0),
                Vec3::new(-1.0, 0.0, 3.0),
            ],
        };
        let b = Triangle {
            p: [
                Vec3::new(0.0f32, 1.0, 3.0),
                Vec3::new(0.0, -1.0, 3.0),
                Vec3::new(1.0, 0.0, 3.0),
            ],
        };
        for i in 0..21 {
            let y = -0.9 + 0.09 * i as f32;
            let r = Ray::new(Vec3::new(0.0, y, 0.0), Vec3::new(0.0, 0.0, 1.0));
            let n = a.intersect(&r, f32::MAX).is_some() as u32
                + b.intersect(&r, f32::MAX).is_some() as u32;
            assert_eq!(n, 1, "y = {y}");
        }
    }
}

#[cfg(test)]
mod edge_plane_tests {
    use super::*;

    /// A small deterministic generator (tests need no crate for it).
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn hits_centre_with_the_sheared_tests_distance_and_barycentrics() {
        let tri = Triangle {
            p: [
                Vec3::new(-1.0f64, -1.0, 5.0),
                Vec3::new(1.0, -1.0, 5.0),
                Vec3::new(0.0, 1.0, 5.0),
            ],
        };
        let planes = EdgePlanes::new(&tri, [0, 1, 2], 4.0);
        // Any length of d: the distance is along the unit direction.
        let d = Vec3::new(0.0, 0.0, 2.0);
        let eye = |d: Vec3<f64>, t_max: f64| {
            let len = d.length();
            let ray = Shear::new(&Ray::new(Vec3::zero(), d * (1.0 / len)));
            planes
                .intersect_from_eye(d, len, t_max)
                .or_sheared(|| tri, &ray, t_max)
        };
        assert!(matches!(
            planes.intersect_from_eye(d, 2.0, f64::MAX),
            EyeTest::Hit(_)
        ));
        let h = eye(d, f64::MAX).expect("hit");
        assert!((h.t - 5.0).abs() < 1e-12);
        assert!((h.b[2] - 0.5).abs() < 1e-12 && (h.b[0] - 0.25).abs() < 1e-12);
        assert!(eye(d, 4.9).is_none(), "beyond t_max");
        let back = Vec3::new(0.0, 0.0, -1.0);
        assert!(eye(back, f64::MAX).is_none(), "behind the eye");
    }

    #[test]
    fn agrees_with_the_sheared_test_on_random_rays() {
        let mut st = 12345u64;
        let mut hits = 0;
        for _ in 0..4000 {
            let mut r = || lcg(&mut st) * 2.0 - 1.0;
            let p = [
                Vec3::new(r(), r(), 4.0 + r()),
                Vec3::new(r(), r(), 4.0 + r()),
                Vec3::new(r(), r(), 4.0 + r()),
            ];
            let tri = Triangle { p };
            let d = Vec3::new(r() * 0.3, r() * 0.3, 1.0);
            let len = d.length();
            let ray = Ray::new(Vec3::zero(), d * (1.0 / len));
            let a = tri.intersect(&ray, f64::MAX);
            let b = EdgePlanes::new(&tri, [0, 1, 2], 2.0)
                .intersect_from_eye(d, len, f64::MAX)
                .or_sheared(|| tri, &Shear::new(&ray), f64::MAX);
            match (a, b) {
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert!((a.t - b.t).abs() <= 1e-9 * a.t, "{} vs {}", a.t, b.t);
                    for k in 0..3 {
                        assert!((a.b[k] - b.b[k]).abs() < 1e-9);
                    }
                }
                (None, None) => {}
                (a, b) => panic!("sheared {a:?} vs planes {b:?} for {tri:?} along {d:?}"),
            }
        }
        assert!(
            hits > 200,
            "the sample must hit often enough to mean something: {hits}"
        );
    }

    #[test]
    fn a_shared_edge_is_hit_by_exactly_one_triangle_whatever_the_winding() {
        // A fan of four triangles around vertex 0 (a pyramid seen from the eye), with
        // vertex indices as the DM shares them; rays on and near every edge, in f32.
        let v = [
            Vec3::new(0.0f32, 0.0, 5.0),
            Vec3::new(1.0, 0.0, 6.0),
            Vec3::new(0.0, 1.0, 6.0),
            Vec3::new(-1.0, 0.0, 6.0),
            Vec3::new(0.0, -1.0, 6.0),
        ];
        // Mixed windings: watertightness must not depend on them.
        let fan = [[0u32, 1, 2], [0, 3, 2], [3, 0, 4], [0, 4, 1]];
        let tris: Vec<Triangle<f32>> = fan
            .iter()
            .map(|i| Triangle {
                p: i.map(|k| v[k as usize]),
            })
            .collect();
        let planes: Vec<EdgePlanes<f32>> = tris
            .iter()
            .zip(&fan)
            .map(|(t, i)| EdgePlanes::new(t, *i, 16.0))
            .collect();
        let mut st = 99u64;
        for k in 0..2000 {
            // Points on the four spokes (shared edges) and random points inside the fan.
            let s = lcg(&mut st) as f32;
            let p = if k % 2 == 0 {
                let spoke = v[1 + (k / 2) % 4];
                v[0] + (spoke - v[0]) * s
            } else {
                let a = v[1 + (k / 2) % 4];
                let b = v[1 + (k / 2 + 1) % 4];
                let t = lcg(&mut st) as f32;
                v[0] + (a - v[0]) * (s * (1.0 - t)) + (b - v[0]) * (s * t)
            };
            if p == v[0] {
                continue;
            }
            let len = p.length();
            let shear = Shear::new(&Ray::new(Vec3::zero(), p * (1.0 / len)));
            let n = planes
                .iter()
                .zip(&tris)
                .filter(|(pl, tri)| {
                    pl.intersect_from_eye(p, len, f32::MAX)
                        .or_sheared(|| **tri, &shear, f32::MAX)
                        .is_some()
                })
                .count();
            assert_eq!(n, 1, "ray through {p:?} hit {n} triangles of the fan");
        }
    }
}

#[cfg(test)]
mod nan_tests {
    use super::*;

    #[test]
    fn non_finite_input_never_reports_a_hit() {
        let t = Triangle {
            p: [
                Vec3::new(f32::NAN, -1.0, 3.0),
                Vec3::new(1.0, -1.0, 3.0),
                Vec3::new(0.0, 1.0, 3.0),
            ],
        };
        let r = Ray::new(Vec3::zero(), Vec3::new(0.0f32, 0.0, 1.0));
        assert!(t.intersect(&r, f32::MAX).is_none());
        let ok = Triangle {
            p: [
                Vec3::new(-1.0f32, -1.0, 3.0),
                Vec3::new(1.0, -1.0, 3.0),
                Vec3::new(0.0, 1.0, 3.0),
            ],
        };
        // A zero direction and huge coordinates whose products overflow.
        assert!(ok
            .intersect(&Ray::new(Vec3::zero(), Vec3::zero()), f32::MAX)
            .is_none());
        let huge = Triangle {
            p: ok.p.map(|p| p * 1e25),
        };
        let h = huge.intersect(&Ray::new(Vec3::zero(), Vec3::new(0.0, 0.0, 1.0)), f32::MAX);
        assert!(h.is_none_or(|h| h.t.is_finite()));
    }
}
