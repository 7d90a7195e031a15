//! Shading: eq. 2.1 (local light at a surface point) and eq. 2.2 (plus reflected and
//! transmitted light, recursively, and straight through past the depth cap).

use super::surface::Surface;
use super::texture::Mat;
use super::tracer::{Tracer, TracerState, MAX_CROSSINGS};
use super::traversal::Hit;
use crate::geom::{Ray, Vec3};
use crate::image::MAX_DEPTH_LIMIT;
use crate::num::Real;
use core::borrow::BorrowMut;

pub(super) fn schlick<T: Real>(at_normal: T, at_edge: T, cos: T) -> T {
    let m = (T::ONE - cos.clamp01()).max(T::ZERO);
    let m2 = m * m;
    at_normal + (at_edge - at_normal) * (m2 * m2 * m)
}

impl<T: Real, S: BorrowMut<TracerState<T>>> Tracer<'_, T, S> {
    /// Eq. 2.1 at a surface point seen along `view` (unit, towards the eye).
    pub(super) fn local_shade(&mut self, surf: &Surface<T>, m: &Mat<T>, view: Vec3<T>) -> Vec3<T> {
        self.stats.shadings += 1;
        let n = if surf.ns.dot(view) < T::ZERO {
            -surf.ns
        } else {
            surf.ns
        };
        let mut c = m.ambient.mul_elem(self.camera.ambient);
        for i in 0..self.scene.light_count() {
            let Some((ldir, dist, ls)) = self.light_at(i, surf.p) else {
                continue;
            };
            let cos_t = n.dot(ldir);
            if cos_t <= T::ZERO {
                continue;
            }
            let ls = if self.camera.no_shadows {
                ls
            } else {
                let t = self.shadow(i, surf, ldir, dist);
                if t.max_component() <= T::ZERO {
                    continue;
                }
                ls.mul_elem(t)
            };
            c = c + m.diffuse.mul_elem(ls) * cos_t;
            let src = schlick(m.specular, m.specular_edge, cos_t);
            if src > T::ZERO {
                // Mirror of the light direction about n, against the view direction.
                let r = n * (T::TWO * cos_t) - ldir;
                let cos_p = r.dot(view);
                if cos_p > T::ZERO {
                    c = c + ls * (src * cos_p.pow_exponent(m.shininess));
                }
            }
        }
        c
    }

    /// Eq. 2.2 for a ray whose nearest hit is known.
    pub(super) fn shade_hit(&mut self, ray: &Ray<T>, hit: Option<Hit<T>>, depth: u32) -> Vec3<T> {
        let Some(hit) = hit else {
            return self.camera.background;
        };
        let surf = self.surface(ray, &hit);
        let m = self.material_at(&surf);
        let view = -ray.dir;
        let mut c = self.local_shade(&surf, &m, view);

        let can_recurse =
            depth < self.camera.max_depth && depth < MAX_DEPTH_LIMIT && self.secondary_left >= 2;
        if can_recurse {
            // Reserve both branches: a pixel's ray tree is at most 2^(depth+1) rays, and
            // the budget keeps a hostile image (everything mirror and glass, depth 16) from
            // taking minutes per pixel; past it, rays end as at the depth cap.
            self.secondary_left -= 2;
        }
        // A material that neither reflects nor transmits (both reflection coefficients
        // exactly zero, so the Schlick blend below is zero) needs none of what follows.
        if m.reflect == T::ZERO
            && m.reflect_edge == T::ZERO
            && m.transmit.max_component() <= T::ZERO
        {
            return c;
        }
        let entering = surf.ng.dot(ray.dir) < T::ZERO;
        let n = if entering { surf.ns } else { -surf.ns };
        let cos_v = n.dot(view).clamp01();

        let rc = schlick(m.reflect, m.reflect_edge, cos_v);
        if rc > T::ZERO && can_recurse {
            self.stats.reflect_rays += 1;
            let rdir = ray.dir.reflect(n).normalize();
            let r = Ray::new(surf.spawn_origin(rdir), rdir);
            c = c + self.trace(&r, depth + 1) * rc;
        }

        let tc = m.transmit;
        if tc.max_component() > T::ZERO {
            let it = if !can_recurse {
                self.straight_through(&surf, ray.dir)
            } else if self.camera.non_refractive {
                self.stats.straight_rays += 1;
                let r = Ray::new(surf.spawn_origin(ray.dir), ray.dir);
                self.trace(&r, depth + 1)
            } else {
                // Snell's law; the outside is air.
                let eta = if entering { m.ior.recip() } else { m.ior };
                let cos_i = cos_v;
                let k = T::ONE - eta * eta * (T::ONE - cos_i * cos_i);
                let dir = if k < T::ZERO {
                    // Total internal reflection: the transmitted share reflects.
                    self.stats.reflect_rays += 1;
                    ray.dir.reflect(n).normalize()
                } else {
                    self.stats.refract_rays += 1;
                    (ray.dir * eta + n * (eta * cos_i - k.sqrt())).normalize()
                };
                let r = Ray::new(surf.spawn_origin(dir), dir);
                self.trace(&r, depth + 1)
            };
            c = c + it.mul_elem(tc);
        }
        c
    }

    /// Non-refractive transparency without recursion: follow the ray straight on, adding
    /// each crossed surface's eq. 2.1 light weighted by the transmittance so far.
    pub(super) fn straight_through(&mut self, from: &Surface<T>, dir: Vec3<T>) -> Vec3<T> {
        let mut acc = Vec3::zero();
        let mut w = Vec3::splat(T::ONE);
        let mut origin = from.spawn_origin(dir);
        let mut k = 0;
        while k < MAX_CROSSINGS {
            self.stats.straight_rays += 1;
            let ray = Ray::new(origin, dir);
            let Some(hit) = self.closest_hit(&ray, T::MAX) else {
                return acc + w.mul_elem(self.camera.background);
            };
            let s = self.surface(&ray, &hit);
            let m = self.material_at(&s);
            acc = acc + w.mul_elem(self.local_shade(&s, &m, -dir));
            w = w.mul_elem(m.transmit);
            if w.max_component() < T::from_f32(1.0 / 1024.0) {
                return acc;
            }
            origin = s.spawn_origin(dir);
            k += 1;
        }
        acc
    }
}
