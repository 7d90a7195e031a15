//! Vectors, rays, axis-aligned boxes and error-bounded ray origins.
//!
//! Coordinates are LINKS-1's *view coordinates* once the DM has run: the eye at the origin,
//! X to the right of the screen, Y up, +Z into the screen. With those axes the system is
//! left-handed (X × Y = +Z points away from the viewer); cross products are the ordinary
//! component formula, so a triangle wound clockwise as seen by the eye has its geometric
//! normal pointing at the eye.

use crate::num::Real;
use core::ops::{Add, Index, Mul, Neg, Sub};

/// A 3-vector of any [`Real`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vec3<T> {
    pub x: T,
    pub y: T,
    pub z: T,
}

impl<T: Real> Vec3<T> {
    #[inline]
    pub const fn new(x: T, y: T, z: T) -> Self {
        Self { x, y, z }
    }
    #[inline]
    pub fn zero() -> Self {
        Self::new(T::ZERO, T::ZERO, T::ZERO)
    }
    #[inline]
    pub fn splat(v: T) -> Self {
        Self::new(v, v, v)
    }
    #[inline]
    pub fn from_f32(a: [f32; 3]) -> Self {
        Self::new(T::from_f32(a[0]), T::from_f32(a[1]), T::from_f32(a[2]))
    }
    #[inline]
    pub fn to_f64(self) -> [f64; 3] {
        [self.x.to_f64(), self.y.to_f64(), self.z.to_f64()]
    }
    #[inline]
    pub fn dot(self, o: Self) -> T {
        T::dot3([self.x, self.y, self.z], [o.x, o.y, o.z])
    }
    #[inline]
    pub fn cross(self, o: Self) -> Self {
        Self::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    #[inline]
    pub fn length_sq(self) -> T {
        self.dot(self)
    }
    #[inline]
    pub fn length(self) -> T {
        self.length_sq().sqrt()
    }
    /// Unit vector, or `None` when the length is zero or not finite.
    #[inline]
    pub fn try_normalize(self) -> Option<Self> {
        T::normalize3([self.x, self.y, self.z]).map(|[x, y, z]| Self::new(x, y, z))
    }
    /// Unit vector; a zero vector stays zero (callers guarantee non-degenerate input).
    #[inline]
    pub fn normalize(self) -> Self {
        self.try_normalize().unwrap_or(self)
    }
    #[inline]
    pub fn abs(self) -> Self {
        Self::new(self.x.abs(), self.y.abs(), self.z.abs())
    }
    #[inline]
    pub fn mul_elem(self, o: Self) -> Self {
        Self::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
    #[inline]
    pub fn min(self, o: Self) -> Self {
        Self::new(self.x.min(o.x), self.y.min(o.y), self.z.min(o.z))
    }
    #[inline]
    pub fn max(self, o: Self) -> Self {
        Self::new(self.x.max(o.x), self.y.max(o.y), self.z.max(o.z))
    }
    #[inline]
    pub fn max_abs(self) -> T {
        self.abs().max_component()
    }
    #[inline]
    pub fn max_component(self) -> T {
        self.x.max(self.y).max(self.z)
    }
    /// Index (0, 1, 2) of the largest component.
    #[inline]
    pub fn max_dimension(self) -> usize {
        if self.x > self.y {
            if self.x > self.z {
                0
            } else {
                2
            }
        } else if self.y > self.z {
            1
        } else {
            2
        }
    }
    #[inline]
    pub fn permute(self, x: usize, y: usize, z: usize) -> Self {
        Self::new(self[x], self[y], self[z])
    }
    #[inline]
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
    /// Mirror `self` (pointing away from the surface) about normal `n`.
    #[inline]
    pub fn reflect(self, n: Self) -> Self {
        self - n * (T::TWO * self.dot(n))
    }
}

impl<T: Real> Index<usize> for Vec3<T> {
    type Output = T;
    #[inline]
    fn index(&self, i: usize) -> &T {
        match i {
            0 => &self.x,
            1 => &self.y,
            _ => &self.z,
        }
    }
}

impl<T: Real> Add for Vec3<T> {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl<T: Real> Sub for Vec3<T> {
    type Output = Self;
    // Always inlined where a checked Q16.16 subtract is a few instructions (the M3, M4, the
    // host): out of line, the M3's Q16.16 photo1 frame paid 4% for the calls (for 40 KB of
    // flash). ARMv6-M (no 32-bit atomics: see `fixed::wide::HALVES`) keeps the compiler's
    // choice: inlined, Q16.16 no longer fits the G0B1's flash.
    #[cfg_attr(all(target_arch = "arm", not(target_has_atomic = "32")), inline)]
    #[cfg_attr(
        not(all(target_arch = "arm", not(target_has_atomic = "32"))),
        inline(always)
    )]
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl<T: Real> Mul<T> for Vec3<T> {
    type Output = Self;
    #[inline]
    fn mul(self, s: T) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
}
impl<T: Real> Neg for Vec3<T> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}

/// A row-major 3x3 matrix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mat3<T> {
    pub r: [Vec3<T>; 3],
}

impl<T: Real> Mat3<T> {
    #[inline]
    pub fn from_f32(m: [f32; 9]) -> Self {
        Self {
            r: [
                Vec3::from_f32([m[0], m[1], m[2]]),
                Vec3::from_f32([m[3], m[4], m[5]]),
                Vec3::from_f32([m[6], m[7], m[8]]),
            ],
        }
    }
    #[inline]
    pub fn mul_vec(&self, v: Vec3<T>) -> Vec3<T> {
        Vec3::new(self.r[0].dot(v), self.r[1].dot(v), self.r[2].dot(v))
    }
    /// `Mᵀ v`: how normals leave a local space whose inverse transform is `M`.
    #[inline]
    pub fn mul_transpose_vec(&self, v: Vec3<T>) -> Vec3<T> {
        self.r[0] * v.x + self.r[1] * v.y + self.r[2] * v.z
    }
}

/// A ray `origin + t * dir`, `t` in `(0, t_max)`. `dir` need not be unit length for the
/// intersection routines, but the renderer keeps it unit so `t` is a distance.
#[derive(Clone, Copy, Debug)]
pub struct Ray<T> {
    pub origin: Vec3<T>,
    pub dir: Vec3<T>,
}

impl<T: Real> Ray<T> {
    #[inline]
    pub fn new(origin: Vec3<T>, dir: Vec3<T>) -> Self {
        Self { origin, dir }
    }
    #[inline]
    pub fn at(&self, t: T) -> Vec3<T> {
        self.origin + self.dir * t
    }
}

/// Per-ray data the slab test reuses for every box: the reciprocal direction.
#[derive(Clone, Copy, Debug)]
pub struct RayInv<T> {
    pub inv_dir: Vec3<T>,
}

impl<T: Real> RayInv<T> {
    /// Reciprocals of a direction. A zero component gives ±inf for floats, which the slab
    /// test handles (a ray parallel to a slab is inside it or misses it for every t).
    #[inline]
    pub fn new(dir: Vec3<T>) -> Self {
        Self {
            inv_dir: Vec3::new(
                dir.x.recip_beyond(),
                dir.y.recip_beyond(),
                dir.z.recip_beyond(),
            ),
        }
    }
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb<T> {
    pub min: Vec3<T>,
    pub max: Vec3<T>,
}

impl<T: Real> Aabb<T> {
    /// The empty box (grows by union).
    pub fn empty() -> Self {
        Self {
            min: Vec3::splat(T::MAX),
            max: Vec3::splat(-T::MAX),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }
    pub fn union_point(self, p: Vec3<T>) -> Self {
        Self {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }
    pub fn union(self, o: Self) -> Self {
        Self {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }
    pub fn contains(&self, p: Vec3<T>) -> bool {
        p.x >= self.min.x
            && p.x <= self.max.x
            && p.y >= self.min.y
            && p.y <= self.max.y
            && p.z >= self.min.z
            && p.z <= self.max.z
    }
    /// Slab test (LINKS-1 4.2): does the ray hit the box for some t in `[0, t_max]`?
    ///
    /// NaN-safe: `0 * inf` (a ray in a slab's plane) gives NaN, and the comparisons are
    /// written so that a NaN bound never shrinks the interval. The far bound is widened by
    /// 1 + 2·gamma(3) (pbrt) so rounding can't make a ray graze past a box it touches.
    #[inline]
    pub fn hit(&self, ray: &Ray<T>, inv: &RayInv<T>, t_max: T) -> bool {
        self.entry(ray, inv, t_max).is_some()
    }

    /// The slab test returning where the ray enters the box (0 when it starts inside), or
    /// `None` when it misses within `[0, t_max]`.
    #[inline]
    pub fn entry(&self, ray: &Ray<T>, inv: &RayInv<T>, t_max: T) -> Option<T> {
        let mut span = SlabSpan::new(t_max);
        let mut axis = 0;
        while axis < 3 {
            let (lo, hi) = (self.min[axis], self.max[axis]);
            if !span.clip(lo, hi, ray.origin[axis], inv.inv_dir[axis]) {
                return None;
            }
            axis += 1;
        }
        Some(span.t0)
    }
}

/// The interval of `t` a slab test has narrowed so far. The slabs may be clipped in any
/// order with the same result: each only raises `t0` and lowers `t1`.
#[derive(Clone, Copy, Debug)]
pub struct SlabSpan<T> {
    pub t0: T,
    pub t1: T,
}

impl<T: Real> SlabSpan<T> {
    /// `[0, t_max]`.
    #[inline(always)]
    pub fn new(t_max: T) -> Self {
        SlabSpan {
            t0: T::ZERO,
            t1: t_max,
        }
    }

    /// Narrow to where a ray from `o` (one coordinate) with reciprocal direction `id` lies
    /// between `lo` and `hi`; false when the interval empties.
    ///
    /// NaN-safe: `0 * inf` (a ray in a slab's plane) gives NaN, and the comparisons are
    /// written so that a NaN bound never shrinks the interval. The far bound is widened by
    /// 1 + 2·gamma(3) (pbrt) so rounding can't make a ray graze past a box it touches.
    #[inline(always)]
    pub fn clip(&mut self, lo: T, hi: T, o: T, id: T) -> bool {
        let widen = T::ONE + T::TWO * T::err_gamma(3);
        // Beyond the range (a ray nearly parallel to the slab) is an infinity, as intended.
        let mut tn = (lo - o).mul_beyond(id);
        let mut tf = (hi - o).mul_beyond(id);
        if tn > tf {
            core::mem::swap(&mut tn, &mut tf);
        }
        tf *= widen;
        // `x > t0` is false for NaN, so NaN leaves the interval unchanged.
        if tn > self.t0 {
            self.t0 = tn;
        }
        if tf < self.t1 {
            self.t1 = tf;
        }
        if self.t0 > self.t1 {
            return false;
        }
        true
    }

    /// [`Self::clip`] for a ray known to enter the slab at `near` and leave it at `far`
    /// (`near` = the lower bound when the direction is positive along the axis, the upper
    /// when negative, as the reciprocal's sign bit says, `-0` included). For a finite reciprocal and `lo <= hi` it gives
    /// bit for bit what `clip` gives (rounding is monotone, so `clip`'s swap picks the same
    /// products), without the compare-and-swap. A ray lying in the slab's plane (an
    /// infinite reciprocal) exactly on one of its bounds is kept, from either side (`clip`
    /// kept it only for `+inf`): boxes may only over-approximate.
    #[inline(always)]
    pub fn clip_entering(&mut self, near: T, far: T, o: T, id: T) -> bool {
        let widen = T::ONE + T::TWO * T::err_gamma(3);
        let tn = (near - o).mul_beyond(id);
        let tf = (far - o).mul_beyond(id) * widen;
        if tn > self.t0 {
            self.t0 = tn;
        }
        if tf < self.t1 {
            self.t1 = tf;
        }
        // Negated so a NaN bound (never stored) cannot empty the interval.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let kept = !(self.t0 > self.t1);
        kept
    }
}

/// Fixed point's offset for a surface without edges nearby (an ellipsoid without a cut, a
/// blob): move the origin along the spawned ray itself, by the `t` that clears the error
/// bound along the normal (and two steps for the move's own rounding), when the ray leaves
/// at 60 degrees or less from the normal (then by at most twice the normal offset);
/// `None` otherwise. The normal offset moves the ray sideways: in fixed point that is 5 to
/// 10 steps, and a curved surface turns it into another hit point and normal further on
/// (glass.ron's lens: the second surface's normals 4e-4 rad off). Along the ray the start
/// moves but the line does not. A ray going into a solid near one of its edges could leave
/// it through the other face that way (glass.ron's box, 33 steps above the floor), so
/// rays into boxes, triangles and cut ellipsoids keep the normal offset
/// ([`crate::render::Surface::spawn_origin`]).
// The negated comparison is deliberate: it declines NaN too.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
#[inline]
pub fn offset_along_ray<T: Real>(
    p: Vec3<T>,
    p_error: Vec3<T>,
    n: Vec3<T>,
    dir: Vec3<T>,
) -> Option<Vec3<T>> {
    let cos = dir.dot(n).abs();
    if !(cos >= T::HALF) {
        return None;
    }
    let d = n.abs().dot(p_error) + T::TWO * T::epsilon();
    Some(p + dir * (d / cos))
}

/// Offset a spawned ray's origin off the surface by the hit point's error bound (pbrt's
/// OffsetRayOrigin): move along the geometric normal far enough that the rounding error of
/// the hit point can't put the origin on the wrong side, to the side `dir` leaves through.
#[inline]
pub fn offset_ray_origin<T: Real>(
    p: Vec3<T>,
    p_error: Vec3<T>,
    n: Vec3<T>,
    dir: Vec3<T>,
) -> Vec3<T> {
    let d = n.abs().dot(p_error);
    let mut offset = n * d;
    if dir.dot(n) < T::ZERO {
        offset = -offset;
    }
    let mut po = p + offset;
    // Round away from p so the offset itself can't be lost to rounding.
    let mut i = 0;
    while i < 3 {
        let c = match i {
            0 => &mut po.x,
            1 => &mut po.y,
            _ => &mut po.z,
        };
        if offset[i] > T::ZERO {
            *c = c.next_up();
        } else if offset[i] < T::ZERO {
            *c = c.next_down();
        }
        i += 1;
    }
    po
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box() -> Aabb<f64> {
        Aabb {
            min: Vec3::new(-1.0, -1.0, -1.0),
            max: Vec3::new(1.0, 1.0, 1.0),
        }
    }

    /// The sign-specialised slab step gives bit for bit what the compare-and-swap step
    /// gives for finite reciprocals and ordered bounds (random values over many
    /// magnitudes, both signs, and the interval carried across three steps); with the ray in
    /// a slab's plane exactly on a bound it keeps the ray from either side.
    #[test]
    fn clip_entering_equals_clip_with_the_entry_bound_chosen_by_sign() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = |scale: f32| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let u = (x >> 40) as f32 / (1u64 << 24) as f32; // [0, 1)
            (u * 2.0 - 1.0) * scale
        };
        for n in 0..20_000 {
            let scale = [1e-3, 1.0, 37.0, 1e4][n % 4];
            let mut a = SlabSpan::new(next(1e3).abs() + 1.0);
            let mut b = a;
            for _ in 0..3 {
                let (p, q) = (next(scale), next(scale));
                let (lo, hi) = (p.min(q), p.max(q));
                let (o, d) = (next(scale), next(2.0));
                if d == 0.0 {
                    continue;
                }
                let id = d.recip();
                let (near, far) = if id.is_sign_negative() {
                    (hi, lo)
                } else {
                    (lo, hi)
                };
                let kept_a = a.clip(lo, hi, o, id);
                let kept_b = b.clip_entering(near, far, o, id);
                assert_eq!(kept_a, kept_b, "lo {lo} hi {hi} o {o} id {id}");
                assert_eq!(
                    (a.t0.to_bits(), a.t1.to_bits()),
                    (b.t0.to_bits(), b.t1.to_bits())
                );
                if !kept_a {
                    break;
                }
            }
        }
        // In the plane y = 1 of the slab [-1, 1], moving along it: kept for +0 and -0.
        for d in [0.0f32, -0.0] {
            let id = d.recip();
            let (near, far) = if id.is_sign_negative() {
                (1.0, -1.0)
            } else {
                (-1.0, 1.0)
            };
            let mut s = SlabSpan::new(10.0f32);
            assert!(s.clip_entering(near, far, 1.0, id), "direction {d}");
            let mut s = SlabSpan::new(10.0f32);
            assert!(
                !s.clip_entering(near, far, 1.5, id),
                "outside the slab, direction {d}"
            );
        }
    }

    #[test]
    fn slab_hits_and_misses() {
        let b = unit_box();
        let r = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(b.hit(&r, &RayInv::new(r.dir), f64::MAX));
        assert!(!b.hit(&r, &RayInv::new(r.dir), 3.0), "box starts at t=4");
        let r = Ray::new(Vec3::new(0.0, 2.0, -5.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(!b.hit(&r, &RayInv::new(r.dir), f64::MAX));
        let r = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(
            !b.hit(&r, &RayInv::new(r.dir), f64::MAX),
            "box is behind the ray"
        );
    }

    #[test]
    fn slab_ray_in_a_face_plane_is_nan_safe() {
        // Origin exactly on the y = 1 slab plane, direction parallel to it: 0 * inf = NaN.
        let b = unit_box();
        let r = Ray::new(Vec3::new(0.0, 1.0, -5.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(b.hit(&r, &RayInv::new(r.dir), f64::MAX));
        let r = Ray::new(Vec3::new(0.0, 1.0 + 1e-9, -5.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(!b.hit(&r, &RayInv::new(r.dir), f64::MAX));
    }

    #[test]
    fn offset_origin_lands_on_the_leaving_side() {
        let p = Vec3::new(0.0f32, 0.0, 1.0);
        let n = Vec3::new(0.0f32, 0.0, -1.0);
        let err = Vec3::splat(1e-6f32);
        let out = offset_ray_origin(p, err, n, Vec3::new(0.0, 0.0, -1.0));
        assert!(out.z < 1.0);
        let inside = offset_ray_origin(p, err, n, Vec3::new(0.0, 0.0, 1.0));
        assert!(inside.z > 1.0);
    }

    /// The offset along the ray clears the surface by at least the normal offset's distance
    /// (in Q16.16, including the move's own rounding), on the side the ray leaves through,
    /// and stays on the ray's line; it declines rays leaving at more than 60 degrees.
    #[test]
    fn offset_along_the_ray_clears_the_surface_on_the_ray() {
        use crate::num::Fx;
        let f =
            |x: f64, y: f64, z: f64| Vec3::new(Fx::from_f64(x), Fx::from_f64(y), Fx::from_f64(z));
        let p = f(1.25, -0.5, 7.0);
        let n = f(0.6, 0.0, -0.8);
        let err = f(3e-5, 5e-5, 2e-5);
        let need = n.abs().dot(err).to_f64();
        for (dx, dz) in [
            (0.6, -0.8),
            (0.8, -0.6),
            (-0.6, 0.8),
            (0.0, -1.0),
            (0.3, 0.954),
        ] {
            let dir = f(dx, 0.0, dz).normalize();
            let o = offset_along_ray(p, err, n, dir).expect("within 60 degrees");
            let moved = Vec3::new(
                o.x.to_f64() - p.x.to_f64(),
                o.y.to_f64() - p.y.to_f64(),
                o.z.to_f64() - p.z.to_f64(),
            );
            let along_n = moved.x * n.x.to_f64() + moved.z * n.z.to_f64();
            let side = (dir.dot(n).to_f64()).signum();
            assert!(along_n * side >= need, "{dx} {dz}: {along_n} < {need}");
            // On the ray's line to the rounding of the move (half a step per coordinate).
            let d = [dir.x.to_f64(), dir.y.to_f64(), dir.z.to_f64()];
            let t = moved.x * d[0] + moved.y * d[1] + moved.z * d[2];
            let off_line = ((moved.x - t * d[0]).powi(2) + (moved.z - t * d[2]).powi(2)).sqrt();
            assert!(off_line <= 1.0 / 65536.0, "{off_line}");
        }
        assert!(offset_along_ray(p, err, n, f(0.8, 0.0, 0.6)).is_none());
    }

    #[test]
    fn reflect_mirrors_about_the_normal() {
        let d = Vec3::new(1.0f64, -1.0, 0.0);
        let r = d.reflect(Vec3::new(0.0, 1.0, 0.0));
        assert_eq!(r, Vec3::new(1.0, 1.0, 0.0));
    }
}
