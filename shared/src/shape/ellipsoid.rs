//! Ellipsoids (spheres when round), optionally cut by a plane (LINKS-1 primitive 2).
//!
//! The DM stores each ellipsoid as an affine map onto the unit sphere: `q = M (p - c)`, with
//! `L = M⁻¹` kept too so hit points can be re-projected onto the exact surface (pbrt's trick
//! for spheres, which makes the hit point's error bound tiny). The cut plane lives in the
//! same unit frame: points with `n · q <= d` are kept. A *capped* cut closes the solid with a
//! flat lid (CSG intersection of ellipsoid and half-space); an *open* cut leaves a shell.

use crate::geom::{Mat3, Ray, Vec3};
use crate::num::Real;

pub use crate::math::solid::{CutPlane, Ellipsoid};

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
    /// Fixed point, on the shell: the hit's parameter along the unit-frame unit direction
    /// from [`local_origin`]'s point, so [`Ellipsoid::surface`] rebuilds the unit-frame
    /// point from the root itself (through `t` it carried t's rounding times |M d|, four
    /// times over for glass.ron's lens). Zero otherwise (floats rebuild it from `t`).
    pub s: T,
}

/// A surface point with its error bound, geometric normal and local (unit-frame) point.
#[derive(Clone, Copy, Debug)]
pub struct LocalSurface<T> {
    pub p: Vec3<T>,
    pub p_error: Vec3<T>,
    pub n: Vec3<T>,
    pub local: Vec3<T>,
}

/// Where fixed point solves a ray against a quadric (ellipsoid or box) from: the ray's
/// point `origin + dir * tc` nearest the shape's centre in view space (for a unit `dir`;
/// a longer or shorter one takes the quotient), and the unit-frame origin `M (that point -
/// centre)`. Rounding is absolute in fixed point: from the ray's own origin the unit-frame
/// point `M (origin - centre)` is as large as the distance to the shape in radii (26 for
/// glass.ron's lens seen from the eye), and every parameter of it is then off by that
/// times the relative error of a quantity near 1 (a unit direction's length is known to
/// 2^-17, so 2e-4 of a radius along the ray, the lens's normals off by 3e-3 rad). From
/// the nearby point the unit-frame values stay near 1. `tc` is 0 for floats (which
/// round relatively and keep the ray's origin), so their results are unchanged.
#[inline]
pub(crate) fn local_origin<T: Real>(m: &Mat3<T>, center: Vec3<T>, ray: &Ray<T>) -> (T, Vec3<T>) {
    if !T::ABSOLUTE_ROUNDING {
        return (T::ZERO, m.mul_vec(ray.origin - center));
    }
    // From the eye (view space's origin: every primary ray) `center - origin` is the
    // centre itself and `origin - center` its negation, the same values without the six
    // subtractions and their special-value checks.
    let from_eye = ray.origin.x == T::ZERO && ray.origin.y == T::ZERO && ray.origin.z == T::ZERO;
    let (to_center, rel) = if from_eye {
        (center, -center)
    } else {
        (center - ray.origin, ray.origin - center)
    };
    let along = to_center.dot(ray.dir);
    let a = ray.dir.length_sq();
    let tc = if (a - T::ONE).abs() <= T::err_gamma(4) {
        along
    } else {
        along / a
    };
    // The point itself to 2^-24 (`Real::local_mat_vec`). A ray that passes too far from
    // the centre to hold the point overflows to a non-finite value, which every
    // comparison below treats as a miss.
    let (rel, dir) = ([rel.x, rel.y, rel.z], [ray.dir.x, ray.dir.y, ray.dir.z]);
    let row = |r: Vec3<T>| [r.x, r.y, r.z];
    let [x, y, z] = T::local_mat_vec([row(m.r[0]), row(m.r[1]), row(m.r[2])], rel, dir, tc);
    (tc, Vec3::new(x, y, z))
}

/// The bound on the rounding of [`local_origin`]'s unit-frame point in fixed point: the
/// view-space point is rounded to 2^-25 per coordinate, which `m` stretches by at most
/// its largest absolute row sum (counted as 2^-9 steps per unit, generously), and the
/// product rounds once, half a step (counted as one). Zero for floats, whose bounds
/// already cover `M (origin - centre)`.
#[inline]
pub(crate) fn local_origin_error<T: Real>(m: &Mat3<T>) -> T {
    if !T::ABSOLUTE_ROUNDING {
        return T::ZERO;
    }
    let one = Vec3::splat(T::ONE);
    let rows = m.r[0]
        .abs()
        .dot(one)
        .max(m.r[1].abs().dot(one))
        .max(m.r[2].abs().dot(one));
    (rows * T::from_f32(1.0 / 512.0) + T::ONE) * T::epsilon()
}

impl<T: Real> Ellipsoid<T> {
    /// First crossing in (0, t_max).
    pub fn intersect(&self, ray: &Ray<T>, t_max: T) -> Option<EllipsoidHit<T>> {
        let (tc, o_view) = local_origin(&self.m, self.center, ray);
        let d_view = self.m.mul_vec(ray.dir);
        // Fixed point: solve along the unit direction from the ray's closest approach to the
        // centre, so every unit-frame quantity stays near 1: |o|² overflows Q16.16 once the
        // eye is 181 radii away, and a = |d|² of a large ellipsoid keeps too few bits for a
        // grazing ray's discriminant. t is mapped back to the ray's parameter below (from
        // `local_origin`'s point, which is already near the centre, the shift is short, so
        // the unit direction's own rounding, 2^-17 of its length, moves t by little).
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
        if T::ABSOLUTE_ROUNDING {
            // The discriminant above rounds v and |v|² (about 2 steps), which near the rim
            // of a flat ellipsoid the root magnifies by |v| / (2 h), h the half chord (10
            // for h = 0.1: glass.ron's lens). One Newton step on |o + d s|² - 1 formed
            // exactly brings each root back to the rounding of o and d themselves.
            t0 = T::sphere_newton([o.x, o.y, o.z], [d.x, d.y, d.z], t0);
            t1 = T::sphere_newton([o.x, o.y, o.z], [d.x, d.y, d.z], t1);
        }
        // Rounding bound of a root: the origin's distance to the surface is known to about
        // gamma(7)(|o|² + 1) in unit-frame units; dividing by the speed |d| gives t.
        let mut t_err = T::err_gamma(7) * (o.length_sq() + T::ONE) / a.sqrt();
        let (mut s0, mut s1) = (T::ZERO, T::ZERO);
        if T::ABSOLUTE_ROUNDING {
            (s0, s1) = (t0 + shift, t1 + shift);
            t0 = tc + s0 / speed;
            t1 = tc + s1 / speed;
            t_err = (t_err + T::err_gamma(4) * shift.abs() + local_origin_error(&self.m)) / speed
                + T::epsilon();
        }
        // The cut plane below is tested at unit-frame points o + d (t - tc).
        let (o, d) = (o_view, d_view);
        let valid = |t: T| t > t_err && t < t_max;

        match self.cut {
            None => {
                if valid(t0) {
                    Some(EllipsoidHit {
                        t: t0,
                        part: EllipsoidPart::Shell,
                        s: s0,
                    })
                } else if valid(t1) {
                    Some(EllipsoidHit {
                        t: t1,
                        part: EllipsoidPart::Shell,
                        s: s1,
                    })
                } else {
                    None
                }
            }
            Some(cut) => {
                let kept = |t: T| {
                    let local = if T::ABSOLUTE_ROUNDING { t - tc } else { t };
                    cut.n.dot(o + d * local) <= cut.d
                };
                if !cut.capped {
                    if valid(t0) && kept(t0) {
                        return Some(EllipsoidHit {
                            t: t0,
                            part: EllipsoidPart::Shell,
                            s: s0,
                        });
                    }
                    if valid(t1) && kept(t1) {
                        return Some(EllipsoidHit {
                            t: t1,
                            part: EllipsoidPart::Shell,
                            s: s1,
                        });
                    }
                    return None;
                }
                // Capped: the solid is [t0, t1] ∩ {t : n·(o + t d) <= d}.
                let nd = cut.n.dot(d);
                let no = cut.n.dot(o);
                let (mut lo, mut lo_part, mut lo_s) = (t0, EllipsoidPart::Shell, s0);
                let (mut hi, mut hi_part, mut hi_s) = (t1, EllipsoidPart::Shell, s1);
                if nd == T::ZERO {
                    if no > cut.d {
                        return None;
                    }
                } else {
                    let mut tp = (cut.d - no) / nd;
                    if T::ABSOLUTE_ROUNDING {
                        tp = tc + tp;
                    }
                    if nd > T::ZERO {
                        if tp < hi {
                            (hi, hi_part, hi_s) = (tp, EllipsoidPart::Cap, T::ZERO);
                        }
                    } else if tp > lo {
                        (lo, lo_part, lo_s) = (tp, EllipsoidPart::Cap, T::ZERO);
                    }
                }
                if lo > hi {
                    return None;
                }
                // The plane root's error bound, in the same unit-frame terms.
                let tp_err = if T::ABSOLUTE_ROUNDING {
                    (T::err_gamma(5) * (no.abs() + cut.d.abs()) + local_origin_error(&self.m))
                        / nd.abs().max(T::epsilon())
                        + T::epsilon()
                } else {
                    T::err_gamma(5) * (no.abs() + cut.d.abs()) / nd.abs().max(T::epsilon())
                };
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
                        s: lo_s,
                    })
                } else if valid_part(hi, hi_part) {
                    Some(EllipsoidHit {
                        t: hi,
                        part: hi_part,
                        s: hi_s,
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
        // From the same nearby point as `intersect` (fixed point; the origin for floats).
        let (tc, o) = local_origin(&self.m, self.center, ray);
        let d = self.m.mul_vec(ray.dir);
        let t = if T::ABSOLUTE_ROUNDING {
            hit.t - tc
        } else {
            hit.t
        };
        let mut q = if T::ABSOLUTE_ROUNDING && hit.part == EllipsoidPart::Shell {
            o + d.normalize() * hit.s
        } else {
            o + d * t
        };
        let n_local = match (hit.part, self.cut) {
            (EllipsoidPart::Cap, Some(cut)) => {
                // Project onto the plane exactly: q -= n (n·q - d).
                q = q - cut.n * (cut.n.dot(q) - cut.d);
                cut.n
            }
            _ => {
                // Re-project onto the unit sphere.
                q = if T::ABSOLUTE_ROUNDING {
                    q.normalize()
                } else {
                    q * q.length().recip()
                };
                q
            }
        };
        let lq = self.l.mul_vec(q);
        let p = self.center + lq;
        let p_error = if T::ABSOLUTE_ROUNDING {
            // Fixed point: sums are exact and a product rounds by half a step whatever its
            // size, so nothing here grows with |centre| (the relative bound below is 190
            // steps for a centre 32 units away, and spawned rays were pushed off by that).
            // On the shell q is a unit vector rounded per component: its length within
            // 0.52 (|q_x| + |q_y| + |q_z|) <= 0.9 steps of 1, which moves c + L q off the
            // surface by at most |L||q| times that (a rounding along the surface moves it
            // along the surface); on the cap it is off the plane by the rounding of the
            // projection, a step and a half. L q rounds by half a step more.
            let q_err = if hit.part == EllipsoidPart::Shell {
                abs_mat_vec(&self.l, q.abs()) * T::epsilon()
            } else {
                abs_mat_vec(&self.l, q.abs() + Vec3::splat(T::ONE)) * T::err_gamma(2)
            };
            q_err + Vec3::splat(T::epsilon()) + storage_error(&self.m, &self.l, q, storage_eps)
        } else {
            (self.center.abs() + abs_mat_vec(&self.l, q.abs())) * T::err_gamma(6)
                + storage_error(&self.m, &self.l, q, storage_eps)
        };
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
///
/// Fixed point (`eps` unused): the DM's f32 matrices are such inverses with eps = 2^-24,
/// then each entry is rounded to Q16.16 by up to half a step absolutely, which is far
/// more than 2^-24 relative for entries near 1: `E` gains `ΔM L + M ΔL` with `|ΔM|` at
/// most half a step where `M` has a nonzero entry (a zero is stored exactly) and likewise
/// `ΔL`, so `|L E q|` gains `step/2 (|L| Z(M) |L||q| + |L||M| Z(L) |q|)`, `Z(X)` the
/// matrix of ones where `X` is nonzero.
pub(crate) fn storage_error<T: Real>(m: &Mat3<T>, l: &Mat3<T>, q: Vec3<T>, eps: T) -> Vec3<T> {
    if !T::ABSOLUTE_ROUNDING {
        let lq = abs_mat_vec(l, q.abs());
        return abs_mat_vec(l, abs_mat_vec(m, lq)) * (T::from_i32(3) * eps);
    }
    // One more step for the rounding of the bound itself.
    (storage_steps(m, l, q) + Vec3::splat(T::ONE)) * T::epsilon()
}

/// Fixed point: [`storage_error`] before its last step and rounding, counted in steps
/// (linear in `|q|`): 3 * 2^-24 = (3/256) steps of `|L||M||L||q|`, and the half steps of
/// the entries counted as whole ones.
pub(crate) fn storage_steps<T: Real>(m: &Mat3<T>, l: &Mat3<T>, q: Vec3<T>) -> Vec3<T> {
    let lq = abs_mat_vec(l, q.abs());
    let lml = abs_mat_vec(l, abs_mat_vec(m, lq));
    let f32_part = lml * T::from_f32(3.0 / 256.0);
    let entries = abs_mat_vec(l, nonzero_mat_vec(m, lq))
        + abs_mat_vec(l, abs_mat_vec(m, nonzero_mat_vec(l, q.abs())));
    f32_part + entries
}

/// `Z(M) v`, `Z(M)` having a one where `M` has a nonzero entry (`v >= 0`).
fn nonzero_mat_vec<T: Real>(m: &Mat3<T>, v: Vec3<T>) -> Vec3<T> {
    let row = |r: &Vec3<T>| {
        let pick = |a: T, b: T| if a == T::ZERO { T::ZERO } else { b };
        pick(r.x, v.x) + pick(r.y, v.y) + pick(r.z, v.z)
    };
    Vec3::new(row(&m.r[0]), row(&m.r[1]), row(&m.r[2]))
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

    /// glass.ron's lens as the fixed-point renderer sees it (scaled by 1/2: radii 0.7, 0.7,
    /// 0.25, 8 units from the eye), hit from the eye: the Q16.16 hit point, normal and
    /// error bound against f64 on the same stored numbers, for rays meeting it at up to
    /// 70 degrees. From the eye itself the unit-frame origin is 32 units out: before
    /// `local_origin` the worst pixels of glass.ron had the lens's hit point 36 steps off
    /// and its normal 3.6e-3 rad; the relative error bound was 6 steps times |centre| +
    /// |L q|, over 50 steps here.
    #[test]
    fn q16_16_lens_hits_are_within_steps_of_f64() {
        use crate::num::Fx;
        let fx = |v: Vec3<f64>| Vec3::new(Fx::from_f64(v.x), Fx::from_f64(v.y), Fx::from_f64(v.z));
        let back = |v: Vec3<Fx>| Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
        let mat = |m: Mat3<f64>| Mat3 { r: m.r.map(fx) };
        let e64 = Ellipsoid {
            center: Vec3::new(0.1, -1.3, 7.9),
            m: diag(1.0 / 0.7, 1.0 / 0.7, 4.0),
            l: diag(0.7, 0.7, 0.25),
            cut: None,
        };
        let efx = Ellipsoid {
            center: fx(e64.center),
            m: mat(e64.m),
            l: mat(e64.l),
            cut: None,
        };
        // f64 on exactly the numbers the Q16.16 ellipsoid holds.
        let exact = Ellipsoid {
            center: back(efx.center),
            m: Mat3 {
                r: efx.m.r.map(back),
            },
            l: Mat3 {
                r: efx.l.r.map(back),
            },
            cut: None,
        };
        let step = 1.0 / 65536.0;
        let (mut worst_p, mut worst_n, mut worst_bound, mut hits) = (0f64, 0f64, 0f64, 0);
        let mut worst_rim = 0f64;
        for i in 0..60 {
            for j in 0..60 {
                let aim = Vec3::new(
                    0.1 + (i as f64 - 29.5) * 0.024,
                    -1.3 + (j as f64 - 29.5) * 0.024,
                    7.9,
                );
                let rfx = Ray::new(Vec3::zero(), fx(aim).normalize());
                let r64 = Ray::new(Vec3::zero(), back(rfx.dir));
                let (Some(h), Some(h64)) = (
                    efx.intersect(&rfx, Fx::MAX),
                    exact.intersect(&r64, f64::MAX),
                ) else {
                    continue;
                };
                let s = efx.surface(&rfx, &h, Fx::from_raw(1));
                let s64 = exact.surface(&r64, &h64, 0.0);
                // Nearer the rim the unit-frame chord is short and its root ill-conditioned
                // (a step of |v| moves it by 1/chord steps), in every format; checked
                // apart, rays meeting the surface at up to 70 degrees first.
                let cos = s64.n.dot(r64.dir).abs();
                if cos < 0.35 {
                    if cos > 0.15 {
                        worst_rim = worst_rim.max((back(s.n) - s64.n).length());
                    }
                    continue;
                }
                hits += 1;
                let p = back(s.p);
                // Distance from the surface along the normal, and the offset that the bound
                // gives along it (offset_ray_origin).
                let off_surface = s64.n.dot(p - s64.p).abs();
                let bound = s64.n.abs().dot(back(s.p_error));
                assert!(
                    off_surface <= bound,
                    "{aim:?}: {off_surface} > bound {bound}"
                );
                worst_p = worst_p.max((p - s64.p).length() / step);
                worst_n = worst_n.max((back(s.n) - s64.n).length());
                worst_bound = worst_bound.max(bound / step);
            }
        }
        assert!(hits > 1500, "{hits}");
        // Measured: the hit point within 3.1 steps (0.5 step of the direction and of t,
        // and the root's rounding, which the unit frame's short chord near the rim
        // magnifies); the normal within 3.4e-4 rad: the lens's radius of curvature near
        // its rim is 0.09, so a step along the surface (1.5e-5) turns it by 1.7e-4. Nearer
        // the rim (the surface at 70 to 81 degrees to the ray) 7.8e-4, 9.5e-4 without the
        // Newton step (`Real::sphere_newton`). The bound along the normal: at most 5.4
        // steps (a step times |L||q|, one for L q, and the stored entries').
        assert!(worst_p < 4.0, "hit point {worst_p} steps");
        assert!(worst_n < 4e-4, "normal {worst_n}");
        assert!(worst_rim < 9e-4, "normal near the rim {worst_rim}");
        assert!(worst_bound < 6.5, "bound {worst_bound} steps");
    }

    #[test]
    fn grazing_miss_and_hit() {
        let e = ellipsoid([1.0, 1.0, 1.0], None);
        let miss = Ray::new(Vec3::new(1.0 + 1e-9, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(e.intersect(&miss, f64::MAX).is_none());
        let hit = Ray::new(Vec3::new(1.0 - 1e-9, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(e.intersect(&hit, f64::MAX).is_some());
    }

    /// `local_origin` from the eye (origin zero) takes `center` and `-center` for
    /// `center - origin` and `origin - center`: the same bits as the subtractions, for
    /// every centre (special values and the range's ends too).
    #[test]
    fn local_origin_from_the_eye_matches_the_subtractions() {
        use crate::num::Fx;
        let plain = |m: &Mat3<Fx>, center: Vec3<Fx>, ray: &Ray<Fx>| {
            let along = (center - ray.origin).dot(ray.dir);
            let a = ray.dir.length_sq();
            let tc = if (a - Fx::ONE).abs() <= Fx::err_gamma(4) {
                along
            } else {
                along / a
            };
            let rel = ray.origin - center;
            let row = |r: Vec3<Fx>| [r.x, r.y, r.z];
            let [x, y, z] = Fx::local_mat_vec(
                [row(m.r[0]), row(m.r[1]), row(m.r[2])],
                row(rel),
                row(ray.dir),
                tc,
            );
            (tc, Vec3::new(x, y, z))
        };
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 33) as i32
        };
        let edges = [
            Fx::INFINITY,
            Fx::NEG_INFINITY,
            Fx::NAN,
            Fx::MAX,
            -Fx::MAX,
            Fx::ZERO,
            Fx::from_raw(1),
        ];
        let (mut finite, mut checked) = (0, 0);
        for k in 0..20_000 {
            let mut coord = |i: usize| {
                let r = next();
                if (k + i).is_multiple_of(13) {
                    edges[(r as u32 % edges.len() as u32) as usize]
                } else {
                    Fx::from_raw(r >> (r as u32 % 12))
                }
            };
            let center = Vec3::new(coord(0), coord(1), coord(2));
            let m = Mat3 {
                r: [0; 3].map(|_| {
                    Vec3::new(
                        Fx::from_raw(next() >> 12),
                        Fx::from_raw(next() >> 12),
                        Fx::from_raw(next() >> 12),
                    )
                }),
            };
            let raw_dir = [0; 3].map(|_| Fx::from_raw(next() >> 8));
            let Some([x, y, z]) = Fx::normalize3(raw_dir) else {
                continue;
            };
            let ray = Ray::new(Vec3::zero(), Vec3::new(x, y, z));
            let (tc, q) = local_origin(&m, center, &ray);
            let (tc0, q0) = plain(&m, center, &ray);
            let bits = |v: Vec3<Fx>| [v.x.raw(), v.y.raw(), v.z.raw()];
            assert_eq!((tc.raw(), bits(q)), (tc0.raw(), bits(q0)), "{center:?}");
            checked += 1;
            if q.x.is_finite() && q.y.is_finite() && q.z.is_finite() {
                finite += 1;
            }
        }
        // Most cases reach the unit-frame point (not only the special-value paths).
        assert!(
            checked > 19_000 && finite > checked / 2,
            "{checked} {finite}"
        );
    }
}
