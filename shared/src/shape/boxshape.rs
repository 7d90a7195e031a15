//! Boxes (LINKS-1 primitive 4): the cube [-1, 1]³ under an affine map, so axis-aligned and
//! rotated/scaled boxes share one test. `q = M (p - c)`, `L = M⁻¹`.

use super::ellipsoid::{
    abs_mat_vec, local_origin, local_origin_error, storage_error, storage_steps, LocalSurface,
};
use crate::geom::{Mat3, Ray, Vec3};
use crate::num::Real;

pub use crate::math::solid::BoxShape;

#[derive(Clone, Copy, Debug)]
pub struct BoxHit<T> {
    pub t: T,
    /// Face: axis 0..2 in the low bits, bit 2 set for the +1 side.
    pub face: u8,
    /// The unit-frame point `o + d (t - tc)` from `intersect`'s own local origin (`t` for
    /// floats, whose `tc` is 0), before it is snapped onto the face: `surface` takes it
    /// from here instead of forming the local origin again (in fixed point that was a
    /// second `local_origin` and `M d`, some 700 instructions per pixel of photo1 on
    /// the Cortex-M3).
    pub q: Vec3<T>,
}

/// The parts of a box's fixed-point error bounds that depend on its matrices alone
/// ([`BoxShape::bounds`]): the tracer forms them once per scene for its first boxes
/// instead of per test and per hit (on photo1's table, some 700 instructions per pixel on
/// the Cortex-M3). Zero for floats, whose bounds are formed per hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxBounds<T> {
    /// [`local_origin_error`] of `m`.
    pub origin: T,
    /// `K`, [`storage_error`] as a matrix: that bound is `(K |q| + 1)` steps, `K` summing
    /// three products of `|L|`, `|M|` and their nonzero patterns; its columns are
    /// [`storage_steps`] at each unit vector.
    pub storage: Mat3<T>,
}

impl<T: Real> BoxShape<T> {
    /// The box's [`BoxBounds`].
    pub fn bounds(&self) -> BoxBounds<T> {
        if !T::ABSOLUTE_ROUNDING {
            return BoxBounds {
                origin: T::ZERO,
                storage: Mat3 {
                    r: [Vec3::zero(); 3],
                },
            };
        }
        let col = |e: Vec3<T>| storage_steps(&self.m, &self.l, e);
        let (x, y, z) = (
            col(Vec3::new(T::ONE, T::ZERO, T::ZERO)),
            col(Vec3::new(T::ZERO, T::ONE, T::ZERO)),
            col(Vec3::new(T::ZERO, T::ZERO, T::ONE)),
        );
        BoxBounds {
            origin: local_origin_error(&self.m),
            storage: Mat3 {
                r: [
                    Vec3::new(x.x, y.x, z.x),
                    Vec3::new(x.y, y.y, z.y),
                    Vec3::new(x.z, y.z, z.z),
                ],
            },
        }
    }

    /// First crossing in (0, t_max).
    pub fn intersect(&self, ray: &Ray<T>, t_max: T) -> Option<BoxHit<T>> {
        self.intersect_bounded(ray, t_max, None)
    }

    /// [`Self::intersect`] given `origin_error`, this box's [`BoxBounds::origin`] (formed
    /// here, for a box the ray meets, when it is `None`).
    pub fn intersect_bounded(
        &self,
        ray: &Ray<T>,
        t_max: T,
        origin_error: Option<T>,
    ) -> Option<BoxHit<T>> {
        // Fixed point starts from the ray's point nearest the centre (see `local_origin`):
        // from the eye the unit-frame origin is some 20 half-sizes away, and a slab root
        // (±1 - o) / d then carried the reciprocal's rounding 20-fold.
        let (tc, o) = local_origin(&self.m, self.center, ray);
        let d = self.m.mul_vec(ray.dir);
        let mut t0 = -T::MAX;
        let mut t1 = T::MAX;
        let mut f0 = 0u8;
        let mut f1 = 0u8;
        // Rounding bound of the entry and exit roots, from the slab each one came from
        // (fixed point: that slab's |±1 - o| + 1 and |1/d|, the bound formed only for a box
        // the ray meets).
        let mut e0 = T::ZERO;
        let mut e1 = T::ZERO;
        let (mut g0, mut g1) = ((T::ZERO, T::ZERO), (T::ZERO, T::ZERO));
        let mut axis = 0;
        while axis < 3 {
            let (oi, di) = (o[axis], d[axis]);
            if di == T::ZERO {
                if oi < -T::ONE || oi > T::ONE {
                    return None;
                }
            } else {
                // The slab test in the unit frame: beyond the range is an infinity, as
                // intended (`Real::mul_beyond`).
                let inv = di.recip_beyond();
                let mut tn = (-T::ONE - oi).mul_beyond(inv);
                let mut tf = (T::ONE - oi).mul_beyond(inv);
                if T::ABSOLUTE_ROUNDING {
                    tn = tc + tn;
                    tf = tc + tf;
                }
                let (mut fnear, mut ffar) = (axis as u8, axis as u8 | 4);
                if tn > tf {
                    core::mem::swap(&mut tn, &mut tf);
                    core::mem::swap(&mut fnear, &mut ffar);
                }
                let err = if T::ABSOLUTE_ROUNDING {
                    T::ZERO
                } else {
                    T::err_gamma(4) * (oi.abs() + T::ONE) * inv.abs()
                };
                let g = (oi.abs() + T::ONE, inv.abs());
                if tn > t0 {
                    t0 = tn;
                    f0 = fnear;
                    e0 = err;
                    g0 = g;
                }
                if tf < t1 {
                    t1 = tf;
                    f1 = ffar;
                    e1 = err;
                    g1 = g;
                }
            }
            axis += 1;
        }
        if t0 > t1 {
            return None;
        }
        if T::ABSOLUTE_ROUNDING {
            // Absolute rounding: the origin's error (o_err) and the reciprocal's (half a
            // step, and d's own half step grown by inv^2) times |±1 - o| <= |o| + 1, the
            // product's half step; the sum with tc is exact.
            let o_err = origin_error.unwrap_or_else(|| local_origin_error(&self.m));
            let bound = |(span, inv): (T, T)| {
                (o_err + span * inv * T::epsilon()) * inv + (span + T::ONE) * T::epsilon()
            };
            e0 = bound(g0);
            e1 = bound(g1);
        }
        let hit = |t: T, face: u8| {
            let local = if T::ABSOLUTE_ROUNDING { t - tc } else { t };
            Some(BoxHit {
                t,
                face,
                q: o + d * local,
            })
        };
        if t0 > e0 && t0 < t_max {
            hit(t0, f0)
        } else if t1 > e1 && t1 < t_max {
            hit(t1, f1)
        } else {
            None
        }
    }

    /// Hit point snapped onto its face, error bound, outward normal, local point, for a
    /// hit of `intersect` (whose unit-frame point it carries; `_ray` is the ray it came
    /// from, taken for symmetry with [`super::ellipsoid::Ellipsoid::surface`]).
    /// `storage_eps`: see there.
    pub fn surface(&self, _ray: &Ray<T>, hit: &BoxHit<T>, storage_eps: T) -> LocalSurface<T> {
        self.surface_bounded(hit, storage_eps, None)
    }

    /// [`Self::surface`] given `storage`, this box's [`BoxBounds::storage`] (formed here
    /// when it is `None`; floats form their bound from the hit).
    pub fn surface_bounded(
        &self,
        hit: &BoxHit<T>,
        storage_eps: T,
        storage: Option<Mat3<T>>,
    ) -> LocalSurface<T> {
        let mut q = hit.q;
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
        let p_error = if T::ABSOLUTE_ROUNDING {
            // Fixed point: q lies exactly on the face, L q rounds by half a step, the sum
            // with the centre is exact (a relative bound grows with |centre|: glass.ron's
            // box, 33 steps above the floor, sent rays through it); and the stored
            // entries' bound, linear in |q| (`BoxBounds::storage`).
            let k = storage.unwrap_or_else(|| self.bounds().storage);
            Vec3::splat(T::epsilon())
                + (abs_mat_vec(&k, q.abs()) + Vec3::splat(T::ONE)) * T::epsilon()
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

    /// glass.ron's glass box as the fixed-point renderer sees it (scaled by 1/2: half-size
    /// 1, turned 30 degrees about y, 10 units from the eye), hit from the eye: the Q16.16
    /// hit point and error bound against f64 on the same stored numbers. The bound was
    /// 6 steps times |centre| + |L q| and more: the box stands 33 steps above glass.ron's
    /// floor, and rays leaving its bottom were pushed through the floor.
    #[test]
    fn q16_16_box_hits_are_within_steps_of_f64() {
        use crate::num::Fx;
        let fx = |v: Vec3<f64>| Vec3::new(Fx::from_f64(v.x), Fx::from_f64(v.y), Fx::from_f64(v.z));
        let back = |v: Vec3<Fx>| Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64());
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let rot = Mat3 {
            r: [
                Vec3::new(c, 0.0, s),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(-s, 0.0, c),
            ],
        };
        let half = [1.0, 0.9995, 1.0];
        // m = diag(1/half) R^T (view -> unit), l = R diag(half).
        let m = Mat3 {
            r: [0, 1, 2]
                .map(|i| Vec3::new(rot.r[0][i], rot.r[1][i], rot.r[2][i]) * (1.0 / half[i])),
        };
        let l = Mat3 {
            r: rot
                .r
                .map(|row| Vec3::new(row.x * half[0], row.y * half[1], row.z * half[2])),
        };
        let bfx = BoxShape {
            center: fx(Vec3::new(1.75, 1.0005, 10.5)),
            m: Mat3 { r: m.r.map(fx) },
            l: Mat3 { r: l.r.map(fx) },
        };
        let exact = BoxShape {
            center: back(bfx.center),
            m: Mat3 {
                r: bfx.m.r.map(back),
            },
            l: Mat3 {
                r: bfx.l.r.map(back),
            },
        };
        let step = 1.0 / 65536.0;
        let (mut worst_p, mut worst_bound, mut hits) = (0f64, 0f64, 0);
        let (mut least_old, mut worst_vs_nested) = (f64::MAX, 0);
        for i in 0..60 {
            for j in 0..60 {
                let aim = Vec3::new(
                    1.75 + (i as f64 - 29.5) * 0.05,
                    1.0 + (j as f64 - 29.5) * 0.05,
                    10.5,
                );
                let rfx = Ray::new(Vec3::zero(), fx(aim).normalize());
                let r64 = Ray::new(Vec3::zero(), back(rfx.dir));
                let (Some(h), Some(h64)) = (
                    bfx.intersect(&rfx, Fx::MAX),
                    exact.intersect(&r64, f64::MAX),
                ) else {
                    continue;
                };
                if h.face != h64.face {
                    continue; // an edge, within rounding
                }
                hits += 1;
                let sfx = bfx.surface(&rfx, &h, Fx::from_raw(1));
                // The tracer's kept bounds give the same hit and surface.
                let kept = bfx.bounds();
                let hk = bfx
                    .intersect_bounded(&rfx, Fx::MAX, Some(kept.origin))
                    .unwrap();
                assert_eq!((hk.t, hk.face, hk.q), (h.t, h.face, h.q));
                let sk = bfx.surface_bounded(&hk, Fx::from_raw(1), Some(kept.storage));
                assert_eq!((sk.p, sk.p_error, sk.n), (sfx.p, sfx.p_error, sfx.n));
                // K |q| against the nested products at this q: within the roundings.
                let nested = Vec3::splat(Fx::STEP)
                    + storage_error(&bfx.m, &bfx.l, sfx.local, Fx::from_raw(1));
                let off = sfx.p_error - nested;
                for v in [off.x, off.y, off.z] {
                    worst_vs_nested = worst_vs_nested.max(v.raw().abs());
                }
                let s64 = exact.surface(&r64, &h64, 0.0);
                let p = back(sfx.p);
                let off_face = s64.n.dot(p - s64.p).abs();
                let bound = s64.n.abs().dot(back(sfx.p_error));
                assert!(off_face <= bound, "{aim:?}: {off_face} > bound {bound}");
                worst_p = worst_p.max((p - s64.p).length() / step);
                worst_bound = worst_bound.max(bound / step);
                // The relative bound it replaces (what floats use, with eps = 2^-16).
                let q = s64.local.abs();
                let lq = abs_mat_vec(&exact.l, q);
                let old = (exact.center.abs() + lq) * (6.0 * step)
                    + abs_mat_vec(&exact.l, abs_mat_vec(&exact.m, lq)) * (3.0 * step);
                least_old = least_old.min(s64.n.abs().dot(old) / step);
            }
        }
        assert!(hits > 2000, "{hits}");
        // Measured: the hit point within 4.3 steps (t to a step or two from the nearby
        // point, q's rounding, times |L| ~ 1); the bound at most 12.3 steps along the
        // normal (a step for L q, and the stored entries' half steps, summed as if they
        // all added up), where the relative bound was at least 52. K |q| rounds
        // differently from the nested products it replaces, by far less than a step:
        // every hit here has the same bound from both.
        assert!(worst_p < 6.0, "hit point {worst_p} steps");
        assert_eq!(worst_vs_nested, 0, "steps from the nested bound");
        assert!(worst_bound < 14.0, "bound {worst_bound} steps");
        assert!(least_old > 40.0, "old bound {least_old} steps");
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
