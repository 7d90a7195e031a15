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
    // The negated comparisons below are deliberate: they reject NaN.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn intersect(&self, ray: &Ray<T>, t_max: T) -> Option<TriHit<T>> {
        // Translate to the ray origin, permute so the largest direction component is z.
        let mut p0 = self.p[0] - ray.origin;
        let mut p1 = self.p[1] - ray.origin;
        let mut p2 = self.p[2] - ray.origin;
        let kz = ray.dir.abs().max_dimension();
        let kx = if kz == 2 { 0 } else { kz + 1 };
        let ky = if kx == 2 { 0 } else { kx + 1 };
        let d = ray.dir.permute(kx, ky, kz);
        p0 = p0.permute(kx, ky, kz);
        p1 = p1.permute(kx, ky, kz);
        p2 = p2.permute(kx, ky, kz);

        // Shear so the ray runs along +z.
        let sz = d.z.recip();
        let sx = -d.x * sz;
        let sy = -d.y * sz;
        p0.x += sx * p0.z;
        p0.y += sy * p0.z;
        p1.x += sx * p1.z;
        p1.y += sy * p1.z;
        p2.x += sx * p2.z;
        p2.y += sy * p2.z;

        // Edge functions at the ray (the 2-D origin).
        let e0 = p1.x * p2.y - p1.y * p2.x;
        let e1 = p2.x * p0.y - p2.y * p0.x;
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
