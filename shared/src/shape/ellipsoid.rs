//! Ellipsoids (spheres when round), optionally cut by a plane (LINKS-1 primitive 2).
//!
//! The DM stores each ellipsoid as an affine map onto the unit sphere: `q = M (p - c)`, with
//! `L = M⁻¹` kept too so hit points can be re-projected onto the exact surface (pbrt's trick
//! for spheres, which makes the hit point's error bound tiny). The cut plane lives in the
//! same unit frame: points with `n · q <= d` are kept. A *capped* cut closes the solid with a
//! flat lid (CSG intersection of ellipsoid and half-space); an *open* cut leaves a shell.

use crate::geom::{Mat3, Ray, Vec3};
use crate::num::Real;

#[derive(Clone, Copy, Debug)]
pub struct CutPlane<T> {
    /// Unit normal in the unit-sphere frame.
    pub n: Vec3<T>,
    pub d: T,
    pub capped: bool,
}

#[derive(Clone, Copy, Debug)]
pub struct Ellipsoid<T> {
    pub center: Vec3<T>,
    /// View -> unit sphere.
    pub m: Mat3<T>,
    /// Unit sphere -> view (the inverse of `m`).
    pub l: Mat3<T>,
    pub cut: Option<CutPlane<T>>,
}

/// Which surface a hit lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EllipsoidPart {
    Shell,
    Cap,
}

#[derive(Clone, Copy, Debug)]
pub struct EllipsoidHit<T> {
    pub t: T,
    pub part: EllipsoidPart,
}

/// A surface point with its error bound, geometric normal and local (unit-frame) point.
#[derive(Clone, Copy, Debug)]
pub struct LocalSurface<T> {
    pub p: Vec3<T>,
    pub p_error: Vec3<T>,
    pub n: Vec3<T>,
    pub local: Vec3<T>,
}

impl<T: Real> Ellipsoid<T> {
    /// First crossing in (0, t_max).
    pub fn intersect(&self, ray: &Ray<T>, t_max: T) -> Option<EllipsoidHit<T>> {
        let o_view = self.m.mul_vec(ray.origin - self.center);
        let d_view = self.m.mul_vec(ray.dir);
        // Fixed point: solve along the unit direction from the ray's closest approach to the
        // centre, so every unit-frame quantity stays near 1: |o|² overflows Q16.16 once the
        // eye is 181 radii away, and a = |d|² of a large ellipsoid keeps too few bits for a
        // grazing ray's discriminant. t is mapped back to the ray's parameter below.
        let (o, d, a, shift, speed) = if T::ABSOLUTE_ROUNDING {
            let dn = d_view.normalize();
            let s = -o_view.dot(dn);
            (o_view + dn * s, dn, T::ONE, s, d_view.dot(dn))
        } else {
            (o_view, d_view, d_view.length_sq(), T::ZERO, T::ONE)
        };
        let b = T::TWO * o.dot(d);
        let c = o.length_sq() - T::ONE;
        // Discriminant from the ray's closest approach (pbrt-v4): 4a(1 - |v|)(1 + |v|).
        let v = o - d * (b / (T::TWO * a));
        let len = v.length();
        let disc = T::from_i32(4) * a * (T::ONE - len) * (T::ONE + len);
        if disc < T::ZERO {
            return None;
        }
        let root = disc.sqrt();
        let q = if b < T::ZERO {
            -T::HALF * (b - root)
        } else {
            -T::HALF * (b + root)
        };
        if q == T::ZERO {
            return None;
        }
        let mut t0 = q / a;
        let mut t1 = c / q;
        if t0 > t1 {
            core::mem::swap(&mut t0, &mut t1);
        }
        // Rounding bound of a root: the origin's distance to the surface is known to about
        // gamma(7)(|o|² + 1) in unit-frame units; dividing by the speed |d| gives t.
        let mut t_err = T::err_gamma(7) * (o.length_sq() + T::ONE) / a.sqrt();
        if T::ABSOLUTE_ROUNDING {
            t0 = (t0 + shift) / speed;
            t1 = (t1 + shift) / speed;
            t_err = (t_err + T::err_gamma(4) * shift.abs()) / speed;
        }
        let (o, d) = (o_view, d_view);
        let valid = |t: T| t > t_err && t < t_max;

        match self.cut {
            None => {
                if valid(t0) {
                    Some(EllipsoidHit {
                        t: t0,
                        part: EllipsoidPart::Shell,
                    })
                } else if valid(t1) {
                    Some(EllipsoidHit {
                        t: t1,
                        part: EllipsoidPart::Shell,
                    })
                } else {
                    None
                }
            }
            Some(cut) => {
                let kept = |t: T| cut.n.dot(o + d * t) <= cut.d;
                if !cut.capped {
                    if valid(t0) && kept(t0) {
                        return Some(EllipsoidHit {
                            t: t0,
                            part: EllipsoidPart::Shell,
                        });
                    }
                    if valid(t1) && kept(t1) {
                        return Some(EllipsoidHit {
                            t: t1,
                            part: EllipsoidPart::Shell,
                        });
                    }
                    return None;
                }
                // Capped: the solid is [t0, t1] ∩ {t : n·(o + t d) <= d}.
                let nd = cut.n.dot(d);
                let no = cut.n.dot(o);
                let (mut lo, mut lo_part) = (t0, EllipsoidPart::Shell);
                let (mut hi, mut hi_part) = (t1, EllipsoidPart::Shell);
                if nd == T::ZERO {
                    if no > cut.d {
                        return None;
                    }
                } else {
                    let tp = (cut.d - no) / nd;
                    if nd > T::ZERO {
                        if tp < hi {
                            hi = tp;
                            hi_part = EllipsoidPart::Cap;
                        }
                    } else if tp > lo {
                        lo = tp;
                        lo_part = EllipsoidPart::Cap;
                    }
                }
                if lo > hi {
                    return None;
                }
                // The plane root's error bound, in the same unit-frame terms.
                let tp_err =
                    T::err_gamma(5) * (no.abs() + cut.d.abs()) / nd.abs().max(T::epsilon());
                let valid_part = |t: T, part: EllipsoidPart| {
                    let e = if part == EllipsoidPart::Cap {
                        tp_err.max(t_err)
                    } else {
                        t_err
                    };
                    t > e && t < t_max
                };
                if valid_part(lo, lo_part) {
                    Some(EllipsoidHit {
                        t: lo,
                        part: lo_part,
                    })
                } else if valid_part(hi, hi_part) {
                    Some(EllipsoidHit {
                        t: hi,
                        part: hi_part,
                    })
                } else {
                    None
                }
            }
        }
    }

    /// Surface point, its error bound and the outward geometric normal for a hit.
    /// `storage_eps` is the unit round-off of the numbers `m` and `l` were stored in: they
    /// are each rounded from exact inverses, so `m · l` is the identity only to a few of
    /// those units, and the error bound must include it (see [`storage_error`]).
    pub fn surface(&self, ray: &Ray<T>, hit: &EllipsoidHit<T>, storage_eps: T) -> LocalSurface<T> {
        let o = self.m.mul_vec(ray.origin - self.center);
        let d = self.m.mul_vec(ray.dir);
        let mut q = o + d * hit.t;
        let n_local = match (hit.part, self.cut) {
            (EllipsoidPart::Cap, Some(cut)) => {
                // Project onto the plane exactly: q -= n (n·q - d).
                q = q - cut.n * (cut.n.dot(q) - cut.d);
                cut.n
            }
            _ => {
                // Re-project onto the unit sphere.
                q = q * q.length().recip();
                q
            }
        };
        let lq = self.l.mul_vec(q);
        let p = self.center + lq;
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

/// Bound on how far `c + l q` can lie off the surface that `m` defines, when `m` and `l` are
/// separately rounded inverses: `m l = I + E` with `|E| <= 2 eps |m||l|`, so the point is
/// off by `l E q` in view units, bounded by `2 eps |l||m||l||q|` (first order, padded to 3).
pub(crate) fn storage_error<T: Real>(m: &Mat3<T>, l: &Mat3<T>, q: Vec3<T>, eps: T) -> Vec3<T> {
    let lq = abs_mat_vec(l, q.abs());
    abs_mat_vec(l, abs_mat_vec(m, lq)) * (T::from_i32(3) * eps)
}

/// `|L| v` with `|L|` the element-wise absolute matrix: bounds `L v`'s rounding error.
pub(crate) fn abs_mat_vec<T: Real>(l: &Mat3<T>, v: Vec3<T>) -> Vec3<T> {
    Vec3::new(
        l.r[0].abs().dot(v),
        l.r[1].abs().dot(v),
        l.r[2].abs().dot(v),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn diag(x: f64, y: f64, z: f64) -> Mat3<f64> {
        Mat3 {
            r: [
                Vec3::new(x, 0.0, 0.0),
                Vec3::new(0.0, y, 0.0),
                Vec3::new(0.0, 0.0, z),
            ],
        }
    }

    fn ellipsoid(r: [f64; 3], cut: Option<CutPlane<f64>>) -> Ellipsoid<f64> {
        Ellipsoid {
            center: Vec3::new(0.0, 0.0, 10.0),
            m: diag(1.0 / r[0], 1.0 / r[1], 1.0 / r[2]),
            l: diag(r[0], r[1], r[2]),
            cut,
        }
    }

    #[test]
    fn sphere_hit_distance_and_normal() {
        let e = ellipsoid([2.0, 2.0, 2.0], None);
        let r = Ray::new(Vec3::zero(), Vec3::new(0.0, 0.0, 1.0));
        let h = e.intersect(&r, f64::MAX).expect("hit");
        assert!((h.t - 8.0).abs() < 1e-12);
        let s = e.surface(&r, &h, 0.0);
        assert!((s.n.z + 1.0).abs() < 1e-12, "normal faces the eye");
    }

    #[test]
    fn ellipsoid_radii_along_each_axis() {
        let e = ellipsoid([1.0, 3.0, 0.5], None);
        let r = Ray::new(Vec3::new(0.0, -10.0, 10.0), Vec3::new(0.0, 1.0, 0.0));
        let h = e.intersect(&r, f64::MAX).unwrap();
        assert!((h.t - 7.0).abs() < 1e-12);
        let r = Ray::new(Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        let h = e.intersect(&r, f64::MAX).unwrap();
        assert!((h.t - 9.5).abs() < 1e-12);
    }

    #[test]
    fn ray_from_inside_finds_the_far_side() {
        let e = ellipsoid([2.0, 2.0, 2.0], None);
        let r = Ray::new(Vec3::new(0.0, 0.0, 10.0), Vec3::new(1.0, 0.0, 0.0));
        let h = e.intersect(&r, f64::MAX).unwrap();
        assert!((h.t - 2.0).abs() < 1e-12);
    }

    #[test]
    fn capped_cut_is_a_solid_with_a_flat_lid() {
        // Keep y <= 0.5 (unit frame, sphere radius 1): a ray from above hits the lid.
        let cut = CutPlane {
            n: Vec3::new(0.0, 1.0, 0.0),
            d: 0.5,
            capped: true,
        };
        let e = ellipsoid([1.0, 1.0, 1.0], Some(cut));
        let r = Ray::new(Vec3::new(0.0, 5.0, 10.0), Vec3::new(0.0, -1.0, 0.0));
        let h = e.intersect(&r, f64::MAX).unwrap();
        assert_eq!(h.part, EllipsoidPart::Cap);
        assert!((h.t - 4.5).abs() < 1e-12);
        let s = e.surface(&r, &h, 0.0);
        assert!((s.n.y - 1.0).abs() < 1e-12);
        // Open cut: the same ray passes the missing lid and hits the inside of the bowl.
        let open = ellipsoid(
            [1.0, 1.0, 1.0],
            Some(CutPlane {
                capped: false,
                ..cut
            }),
        );
        let h = open.intersect(&r, f64::MAX).unwrap();
        assert_eq!(h.part, EllipsoidPart::Shell);
        assert!((h.t - 6.0).abs() < 1e-12);
    }

    #[test]
    fn grazing_miss_and_hit() {
        let e = ellipsoid([1.0, 1.0, 1.0], None);
        let miss = Ray::new(Vec3::new(1.0 + 1e-9, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(e.intersect(&miss, f64::MAX).is_none());
        let hit = Ray::new(Vec3::new(1.0 - 1e-9, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(e.intersect(&hit, f64::MAX).is_some());
    }
}
