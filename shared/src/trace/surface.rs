//! Completing a hit into a surface point: position with its error bound, geometric and
//! shading normals, texture coordinates, material index.

use super::tracer::{Tracer, TracerState};
use super::traversal::{blob_group, Hit, HitDetail};
use crate::geom::{offset_along_ray, offset_ray_origin, Ray, Vec3};
use crate::image::{ShapeRef, NONE};
use crate::num::Real;
use crate::shape::ellipsoid::LocalSurface;
use core::borrow::BorrowMut;

/// A finished hit: where, how accurately, which way the surface faces, what it is made of.
#[derive(Clone, Copy, Debug)]
pub struct Surface<T> {
    pub p: Vec3<T>,
    pub p_error: Vec3<T>,
    /// Geometric normal, unit, pointing out of the object.
    pub ng: Vec3<T>,
    /// Shading normal (interpolated on smooth triangles), unit, same side as `ng`.
    pub ns: Vec3<T>,
    pub uv: [T; 2],
    pub material: u32,
    pub shape: ShapeRef,
    /// No edge within a spawned ray's offset (an ellipsoid without a cut, a blob): fixed
    /// point may then offset along the spawned ray ([`Surface::spawn_origin`]).
    pub edgeless: bool,
}

impl<T: Real> Surface<T> {
    /// The surface of a hit on a quadric-like shape (one normal for shading and geometry).
    #[inline(always)]
    fn local(
        ls: LocalSurface<T>,
        uv: [T; 2],
        material: u32,
        shape: ShapeRef,
        edgeless: bool,
    ) -> Self {
        Surface {
            p: ls.p,
            p_error: ls.p_error,
            ng: ls.n,
            ns: ls.n,
            uv,
            material,
            shape,
            edgeless,
        }
    }

    /// Where a ray leaving this surface along `dir` starts: off the surface by the hit
    /// point's error bound ([`offset_ray_origin`]); in fixed point along the ray itself
    /// where it leaves steeply enough ([`offset_along_ray`]), on an edgeless surface and
    /// for rays leaving to the outside (which can't cross another face of the solid near
    /// a convex edge; a concave corner within two offsets, a few steps, could be crossed,
    /// as by the normal offset).
    #[inline(always)]
    pub fn spawn_origin(&self, dir: Vec3<T>) -> Vec3<T> {
        if T::ABSOLUTE_ROUNDING && (self.edgeless || dir.dot(self.ng) > T::ZERO) {
            if let Some(o) = offset_along_ray(self.p, self.p_error, self.ng, dir) {
                return o;
            }
        }
        offset_ray_origin(self.p, self.p_error, self.ng, dir)
    }
}

impl<T: Real, S: BorrowMut<TracerState<T>>> Tracer<'_, T, S> {
    /// Complete a hit: position with error bound, normals, texture coordinates.
    pub(super) fn surface(&mut self, ray: &Ray<T>, hit: &Hit<T>) -> Surface<T> {
        let s = &self.scene;
        let shape = hit.shape;
        match hit.detail {
            HitDetail::Triangle { b, material } => {
                let rec = s.triangle::<T>(shape.index);
                let (p, p_error) = rec.tri.point(b);
                let mut ng = rec.tri.face_normal().normalize();
                let ns = if rec.normals != NONE {
                    let n = s.normals::<T>(rec.normals);
                    let ns = (n[0] * b[0] + n[1] * b[1] + n[2] * b[2]).normalize();
                    // Vertex normals say which side is outside; make ng agree.
                    if ns.dot(ng) < T::ZERO {
                        ng = -ng;
                    }
                    ns
                } else {
                    ng
                };
                let uv = match s.uvs::<T>(rec.uvs) {
                    Some(t) if rec.uvs != NONE => [
                        t[0][0] * b[0] + t[1][0] * b[1] + t[2][0] * b[2],
                        t[0][1] * b[0] + t[1][1] * b[1] + t[2][1] * b[2],
                    ],
                    _ => [b[1], b[2]],
                };
                Surface {
                    p,
                    p_error,
                    ng,
                    ns,
                    uv,
                    material,
                    shape,
                    edgeless: false,
                }
            }
            HitDetail::Ellipsoid(h) => {
                let rec = self.state.borrow_mut().records.ellipsoid(s, shape.index);
                let ls = rec.shape.surface(ray, &h, s.storage_epsilon());
                let q = ls.local;
                // Spherical mapping in the unit frame (v = 1 at the +Y pole, the image's top
                // row); the cap maps planar.
                let uv = if h.part == crate::shape::ellipsoid::EllipsoidPart::Cap {
                    [(q.x + T::ONE) * T::HALF, (q.z + T::ONE) * T::HALF]
                } else {
                    let two_pi = T::TWO * T::PI;
                    [
                        T::HALF + q.z.atan2(q.x) / two_pi,
                        T::ONE - q.y.max(-T::ONE).min(T::ONE).acos() / T::PI,
                    ]
                };
                let edgeless = T::ABSOLUTE_ROUNDING && rec.shape.cut.is_none();
                Surface::local(ls, uv, rec.material, shape, edgeless)
            }
            HitDetail::Box(h) => {
                let storage = self
                    .state
                    .borrow()
                    .box_bounds(shape.index)
                    .map(|b| b.storage);
                let rec = self.state.borrow_mut().records.boxshape(s, shape.index);
                let ls = rec.shape.surface_bounded(&h, s.storage_epsilon(), storage);
                let q = ls.local;
                // Planar mapping on each face from the two other local axes.
                let (a, b) = match h.face & 3 {
                    0 => (q.z, q.y),
                    1 => (q.x, q.z),
                    _ => (q.x, q.y),
                };
                let uv = [(a + T::ONE) * T::HALF, (b + T::ONE) * T::HALF];
                Surface::local(ls, uv, rec.material, shape, false)
            }
            HitDetail::Blob { t_error } => {
                let (g, group) = blob_group(*s, shape.index);
                let p = ray.at(hit.t);
                let n = (-group.gradient(p)).normalize();
                // Fixed point: the sum in `at` is exact and each product rounds by half a
                // step, so no term grows with |p| (4 steps times |p| was up to 128).
                let p_error = if T::ABSOLUTE_ROUNDING {
                    ray.dir.abs() * t_error + Vec3::splat(T::epsilon())
                } else {
                    ray.dir.abs() * t_error + p.abs() * T::err_gamma(4)
                };
                Surface {
                    p,
                    p_error,
                    ng: n,
                    ns: n,
                    uv: [T::ZERO, T::ZERO],
                    material: g.material,
                    shape,
                    edgeless: T::ABSOLUTE_ROUNDING,
                }
            }
        }
    }
}
