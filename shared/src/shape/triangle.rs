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
        if T::ABSOLUTE_ROUNDING {
            // Fixed point shears exactly in `intersect_exact_edges`: keep the direction.
            return Self {
                origin: ray.origin,
                kz,
                sx: d.x,
                sy: d.y,
                sz: d.z,
            };
        }
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
        if T::ABSOLUTE_ROUNDING {
            let d = Vec3::new(ray.sx, ray.sy, ray.sz);
            return Self::intersect_exact_edges([p0, p1, p2], d, t_max);
        }

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

    /// The sheared test in fixed point, on the vertices relative to the ray's origin and
    /// permuted (`d` the permuted direction, `|d_z|` its largest component). The shear is
    /// exact up to 2^-23 ([`Real::cross_fine`]: `x' = p_x d_z - d_x p_z`, the sheared x
    /// times `d_z`), the edge functions of the sheared vertices exact
    /// ([`Real::edge_functions`]), so every sign is exact (watertight, as the float test is
    /// by its tie-breaks: a vertex is sheared the same way in every triangle) and the
    /// barycentrics keep 22 bits whatever the triangle's size. With a shear by the rounded
    /// `d_x / d_z` and products rounded by half a step, the edges of photo2.ron's camera
    /// (triangles 300 to 2,000 steps across) moved by up to a fifth of a pixel: 37 primary
    /// rays of a 256x240 frame met another triangle than in f64.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline(always)]
    fn intersect_exact_edges(p: [Vec3<T>; 3], d: Vec3<T>, t_max: T) -> Option<TriHit<T>> {
        let x = p.map(|v| T::cross_fine(v.x, d.z, d.x, v.z));
        let y = p.map(|v| T::cross_fine(v.y, d.z, d.y, v.z));
        let (e, k) = T::edge_functions(x, y);
        // d_z < 0 mirrors the sheared plane, the same way for every triangle of the ray.
        let s0 = edge_positive(e[0], x[1], y[1], x[2], y[2]);
        let s1 = edge_positive(e[1], x[2], y[2], x[0], y[0]);
        let s2 = edge_positive(e[2], x[0], y[0], x[1], y[1]);
        if !(s0 == s1 && s1 == s2) {
            return None;
        }
        // Up to 3 * 2^22 steps: no overflow (the e have one sign or are zero).
        let det = e[0] + e[1] + e[2];
        if !(det.abs() > T::ZERO) {
            return None;
        }
        // t = Σ e_i z_i / (Σ e_i d_z): the sum exact, rounded once, then one quotient.
        let z = [p[0].z, p[1].z, p[2].z];
        let t = T::dot3(e, z) / (det * d.z);
        if !(t < t_max) {
            return None;
        }
        // Conservative t > 0. The x' and y' are off by half a step each, so each e by at
        // most a step times (max|x'| + max|y'|) in its unscaled units, which moves t by at
        // most 3 of those times the spread of z over |Σ e d_z| (b_i >= 0, so t d_z lies
        // between the z_i); t's sum and quotient round by half a step each. In e's scaled
        // units a step is 2^(-k - 16) steps; the 3 padded to 4 for the bound's roundings.
        let (mut zmin, mut zmax) = (z[0], z[0]);
        let (mut xmax, mut ymax) = (T::ZERO, T::ZERO);
        for i in 0..3 {
            zmin = zmin.min(z[i]);
            zmax = zmax.max(z[i]);
            xmax = xmax.max(x[i].abs());
            ymax = ymax.max(y[i].abs());
        }
        let spread = (xmax + ymax) / det.abs() * (zmax - zmin) / d.z.abs() + T::epsilon();
        let delta_t = spread.mul_pow2(-k - 16) * T::from_i32(4) + T::TWO * T::epsilon();
        if !(t > delta_t) {
            return None;
        }
        // Barycentrics summing to exactly one (fixed-point sums are exact).
        let b0 = e[0] / det;
        let b1 = e[1] / det;
        Some(TriHit {
            t,
            b: [b0, b1, T::ONE - b0 - b1],
        })
    }

    /// Hit point from barycentrics and its absolute error bound (pbrt: gamma(7) Σ|b_i p_i|).
    ///
    /// Fixed point: `p0 + (p1 - p0) b1 + (p2 - p0) b2`, whose differences and sums are
    /// exact (the barycentrics sum to one exactly), so only the two products' half steps
    /// take the point off the triangle's plane; Σ b_i p_i took it off by the barycentrics'
    /// own rounding times |p|, and the bound was 7 steps times Σ |b_i p_i|.
    pub fn point(&self, b: [T; 3]) -> (Vec3<T>, Vec3<T>) {
        if T::ABSOLUTE_ROUNDING {
            let p = self.p[0] + (self.p[1] - self.p[0]) * b[1] + (self.p[2] - self.p[0]) * b[2];
            return (p, Vec3::splat(T::epsilon()));
        }
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

/// The fixed-point path (`intersect_exact_edges`) against f64 on the same stored numbers.
#[cfg(test)]
mod fixed_tests {
    use super::*;
    use crate::num::Fx;
    use crate::testkit::numbers::{back, fx, lcg};

    /// Triangles 0.004 to 0.03 across (260 to 2,000 steps: photo2.ron's camera is made of
    /// such, scaled by 1/8) 20 units from the eye, rays aimed all over them: every ray more
    /// than 3e-4 of the triangle's size inside or outside an edge is classified as in f64
    /// on the same numbers; the barycentrics are within the bound of the shear's 2^-24
    /// (worst 5.3e-4, on a sliver) and t within 0.7 steps. With the shear by the rounded
    /// d_x / d_z and rounded products, 1,354 of these 19,991 rays were classified
    /// otherwise, the barycentrics were off by up to 0.26 and t by 0.24 (15,595 steps).
    #[test]
    fn small_far_triangles_classify_rays_as_f64_does() {
        let mut st = 7u64;
        let (mut tested, mut worst_b, mut worst_t) = (0, 0f64, 0f64);
        for _ in 0..200 {
            let size = 0.004 + 0.026 * lcg(&mut st);
            let c = Vec3::new(lcg(&mut st) * 8.0 - 4.0, lcg(&mut st) * 8.0 - 4.0, 20.0);
            let corner =
                |st: &mut u64| c + Vec3::new(lcg(st) - 0.5, lcg(st) - 0.5, lcg(st) - 0.5) * size;
            let tfx = Triangle {
                p: [corner(&mut st), corner(&mut st), corner(&mut st)].map(fx),
            };
            let t64 = Triangle { p: tfx.p.map(back) };
            for _ in 0..100 {
                let aim = c + Vec3::new(lcg(&mut st) - 0.5, lcg(&mut st) - 0.5, 0.0) * size;
                let rfx = Ray::new(Vec3::zero(), fx(aim).normalize());
                let r64 = Ray::new(Vec3::zero(), back(rfx.dir));
                let (h, h64) = (tfx.intersect(&rfx, Fx::MAX), t64.intersect(&r64, f64::MAX));
                // How far inside (or outside) the nearest edge the ray passes, as a share
                // of the triangle's size: the smallest barycentric in f64.
                let e = |a: Vec3<f64>, b: Vec3<f64>| a.cross(b).dot(r64.dir);
                let es = [
                    e(t64.p[1], t64.p[2]),
                    e(t64.p[2], t64.p[0]),
                    e(t64.p[0], t64.p[1]),
                ];
                let sum: f64 = es.iter().sum();
                let margin = es.iter().map(|v| (v / sum).abs()).fold(f64::MAX, f64::min);
                if margin < 3e-4 {
                    continue;
                }
                tested += 1;
                assert_eq!(h.is_some(), h64.is_some(), "{aim:?}, margin {margin}");
                if let (Some(h), Some(h64)) = (h, h64) {
                    // The sheared coordinates x' = p_x d_z - d_x p_z are rounded to 2^-24
                    // (Q23), so each e_i = x'_j y'_k - y'_j x'_k moves by at most
                    // 2^-24 2 (max|x'| + max|y'|), and b_i = e_i / Σ e by at most twice
                    // that over |Σ e|, plus the quotient's half step.
                    let d = r64.dir;
                    let xs = t64.p.map(|v| v.x * d.z - d.x * v.z);
                    let ys = t64.p.map(|v| v.y * d.z - d.y * v.z);
                    let m = xs.iter().chain(&ys).fold(0f64, |a, v| a.max(v.abs()));
                    let e = |j: usize, k: usize| xs[j] * ys[k] - ys[j] * xs[k];
                    let det = e(1, 2) + e(2, 0) + e(0, 1);
                    let bound = 2.0 * 2f64.powi(-24) * 4.0 * m / det.abs() + 1.0 / 65536.0;
                    for i in 0..3 {
                        let err = (h.b[i].to_f64() - h64.b[i]).abs();
                        assert!(err <= bound, "b{i} {err} > {bound}");
                        worst_b = worst_b.max(err);
                    }
                    worst_t = worst_t.max((h.t.to_f64() - h64.t).abs() * 65536.0);
                    let (p, err) = tfx.point(h.b);
                    // On the plane to within the bound.
                    let n = t64.face_normal().normalize();
                    let off = n.dot(back(p) - t64.p[0]).abs();
                    assert!(off <= n.abs().dot(back(err)), "{off}");
                }
            }
        }
        assert!(tested > 15_000, "{tested}");
        assert!(
            worst_b > 0.0 && worst_t < 2.0,
            "b {worst_b}, t {worst_t} steps"
        );
    }

    #[test]
    fn exact_edge_functions_keep_signs_and_ratios() {
        let f = |v: f64| Fx::from_f64(v);
        // A triangle 3 steps across: every product of two coordinates is below a step.
        let x = [Fx::from_raw(1), Fx::from_raw(-2), Fx::from_raw(1)];
        let y = [Fx::from_raw(-1), Fx::from_raw(0), Fx::from_raw(2)];
        let (e, k) = Fx::edge_functions(x, y);
        // Exactly: (x1 y2 - y1 x2, x2 y0 - y2 x0, x0 y1 - y0 x1) = (-4, -3, -2) steps².
        let want = [-4.0, -3.0, -2.0].map(|v: f64| v * 2f64.powi(-32));
        for i in 0..3 {
            assert_eq!(e[i].to_f64() * 2f64.powi(k), want[i], "{e:?} {k}");
        }
        // The plain products are all zero.
        assert_eq!(f64::from(0), (x[1] * y[2] - y[1] * x[2]).to_f64());
        // A tiny value beside a large one keeps its sign (and an exact zero stays zero).
        let (e, _) = Fx::edge_functions(
            [f(0.0), f(1000.0), Fx::from_raw(1)],
            [f(0.0), Fx::from_raw(1), f(1000.0)],
        );
        assert!(
            e[0] > Fx::ZERO && e[1].raw() == 0 && e[2].raw() == 0,
            "{e:?}"
        );
        let (e, _) = Fx::edge_functions([Fx::NAN, f(1.0), f(2.0)], [f(1.0); 3]);
        assert!(e.iter().all(|v| v.is_nan()));
        assert_eq!(f(3.0).mul_pow2(2).to_f64(), 12.0);
        assert_eq!(f(3.0).mul_pow2(-1).to_f64(), 1.5);
        assert_eq!(f(3.0).mul_pow2(20), Fx::INFINITY);
        assert_eq!(Fx::from_raw(3).mul_pow2(-1).raw(), 2);
        assert_eq!(Fx::from_raw(-3).mul_pow2(-40).raw(), 0);
    }
}

#[cfg(test)]
mod edge_plane_tests {
    use super::*;
    use crate::testkit::numbers::lcg;

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
