//! Boxes (LINKS-1 primitive 4): the cube [-1, 1]³ under an affine map, so axis-aligned and
//! rotated/scaled boxes share one test. `q = M (p - c)`, `L = M⁻¹`.

use super::ellipsoid::{abs_mat_vec, storage_error, LocalSurface};
use crate::geom::{Ray, Vec3};
use crate::num::Real;

pub use crate::math::solid::BoxShape;

#[derive(Clone, Copy, Debug)]
pub struct BoxHit<T> {
    pub t: T,
    /// Face: axis 0..2 in the low bits, bit 2 set for the +1 side.
    pub face: u8,
}

impl<T: Real> BoxShape<T> {
    /// First crossing in (0, t_max).
    pub fn intersect(&self, ray: &Ray<T>, t_max: T) -> Option<BoxHit<T>> {
        let o = self.m.mul_vec(ray.origin - self.center);
        let d = self.m.mul_vec(ray.dir);
        let mut t0 = -T::MAX;
        let mut t1 = T::MAX;
        let mut f0 = 0u8;
        let mut f1 = 0u8;
        // Rounding bound of the entry and exit roots, from the slab each one came from.
        let mut e0 = T::ZERO;
        let mut e1 = T::ZERO;
        let mut axis = 0;
        while axis < 3 {
            let (oi, di) = (o[axis], d[axis]);
            if di == T::ZERO {
                if oi < -T::ONE || oi > T::ONE {
                    return None;
                }
            } else {
                let inv = di.recip();
                let mut tn = (-T::ONE - oi) * inv;
                let mut tf = (T::ONE - oi) * inv;
                let (mut fnear, mut ffar) = (axis as u8, axis as u8 | 4);
                if tn > tf {
                    core::mem::swap(&mut tn, &mut tf);
                    core::mem::swap(&mut fnear, &mut ffar);
                }
                let err = T::err_gamma(4) * (oi.abs() + T::ONE) * inv.abs();
                if tn > t0 {
                    t0 = tn;
                    f0 = fnear;
                    e0 = err;
                }
                if tf < t1 {
                    t1 = tf;
                    f1 = ffar;
                    e1 = err;
                }
            }
            axis += 1;
        }
        if t0 > t1 {
            return None;
        }
        if t0 > e0 && t0 < t_max {
            Some(BoxHit { t: t0, face: f0 })
        } else if t1 > e1 && t1 < t_max {
            Some(BoxHit { t: t1, face: f1 })
        } else {
            None
        }
    }

    /// Hit point snapped onto its face, error bound, outward normal, local point.
    /// `storage_eps`: see [`super::ellipsoid::Ellipsoid::surface`].
    pub fn surface(&self, ray: &Ray<T>, hit: &BoxHit<T>, storage_eps: T) -> LocalSurface<T> {
        let o = self.m.mul_vec(ray.origin - self.center);
        let d = self.m.mul_vec(ray.dir);
        let mut q = o + d * hit.t;
        let axis = (hit.face & 3) as usize;
        let side = if hit.face & 4 != 0 { T::ONE } else { -T::ONE };
        let clamp = |v: T| v.max(-T::ONE).min(T::ONE);
        q = Vec3::new(clamp(q.x), clamp(q.y), clamp(q.z));
        let mut n_local = Vec3::zero();
        match axis {
            0 => {
                q.x = side;
                n_local.x = side;
            }
            1 => {
                q.y = side;
                n_local.y = side;
            }
            _ => {
                q.z = side;
                n_local.z = side;
            }
        }
        let p = self.center + self.l.mul_vec(q);
        let p_error = (self.center.abs() + abs_mat_vec(&self.l, q.abs())) * T::err_gamma(6)
            + storage_error(&self.m, &self.l, q, storage_eps);
        let n = self.m.mul_transpose_vec(n_local).normalize();
        LocalSurface {
            p,
            p_error,
            n,
            local: q,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Mat3;

    fn unit_box_at(z: f64, half: f64) -> BoxShape<f64> {
        let s = |v: f64| Mat3 {
            r: [
                Vec3::new(v, 0.0, 0.0),
                Vec3::new(0.0, v, 0.0),
                Vec3::new(0.0, 0.0, v),
            ],
        };
        BoxShape {
            center: Vec3::new(0.0, 0.0, z),
            m: s(1.0 / half),
            l: s(half),
        }
    }

    #[test]
    fn front_face_hit_and_normal() {
        let b = unit_box_at(10.0, 2.0);
        let r = Ray::new(Vec3::new(0.5, 0.5, 0.0), Vec3::new(0.0, 0.0, 1.0));
        let h = b.intersect(&r, f64::MAX).unwrap();
        assert!((h.t - 8.0).abs() < 1e-12);
        let s = b.surface(&r, &h, 0.0);
        assert_eq!(s.n, Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(s.p.z, 8.0);
    }

    #[test]
    fn ray_parallel_to_a_slab() {
        let b = unit_box_at(10.0, 2.0);
        let r = Ray::new(Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(
            b.intersect(&r, f64::MAX).is_some(),
            "on the face plane: touching counts"
        );
        let r = Ray::new(Vec3::new(2.0 + 1e-9, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(b.intersect(&r, f64::MAX).is_none());
    }

    #[test]
    fn near_parallel_axis_does_not_inflate_the_error_bound() {
        // Regression: the slab of an axis the ray almost parallels has a huge root error;
        // it must not reject an entry through another face (a mirror's reflection missed).
        let b = unit_box_at(10.0, 2.0);
        let r = Ray::new(
            Vec3::new(-8.0, 0.0, 9.0),
            Vec3::new(1.0, 0.0, 6e-8).normalize(),
        );
        let h = b
            .intersect(&r, f64::MAX)
            .expect("enters through the x = -2 face");
        assert!((h.t - 6.0).abs() < 1e-9);
        let bf = BoxShape::<f32> {
            center: Vec3::new(0.0, 0.0, 10.0),
            m: Mat3 {
                r: [
                    Vec3::new(0.5, 0.0, 0.0),
                    Vec3::new(0.0, 0.5, 0.0),
                    Vec3::new(0.0, 0.0, 0.5),
                ],
            },
            l: Mat3 {
                r: [
                    Vec3::new(2.0, 0.0, 0.0),
                    Vec3::new(0.0, 2.0, 0.0),
                    Vec3::new(0.0, 0.0, 2.0),
                ],
            },
        };
        let r = Ray::new(Vec3::new(-8.0f32, 0.0, 9.0), Vec3::new(1.0f32, 0.0, 6e-8));
        assert!(bf.intersect(&r, f32::MAX).is_some());
    }

    #[test]
    fn from_inside_exits_through_the_far_face() {
        let b = unit_box_at(10.0, 2.0);
        let r = Ray::new(Vec3::new(0.0, 0.0, 10.0), Vec3::new(0.0, 1.0, 0.0));
        let h = b.intersect(&r, f64::MAX).unwrap();
        assert!((h.t - 2.0).abs() < 1e-12);
        assert_eq!(b.surface(&r, &h, 0.0).n, Vec3::new(0.0, 1.0, 0.0));
    }
}
