//! Lights and shadows: the light arriving at a point from each light source, and the
//! transmittance of the surfaces between (transparent objects cast lighter shadows).

use super::surface::Surface;
use super::tracer::{Tracer, TracerState, MAX_CROSSINGS};
use super::traversal::Probe;
use crate::geom::{offset_ray_origin, Ray, Vec3};
use crate::image::LightKind;
use crate::num::Real;
use core::borrow::BorrowMut;

impl<T: Real, S: BorrowMut<TracerState<T>>> Tracer<'_, T, S> {
    /// Direction to light `i` from `p`, its distance (MAX for parallel light) and the
    /// light's intensity arriving at `p` before shadowing.
    pub(super) fn light_at(&mut self, i: u32, p: Vec3<T>) -> Option<(Vec3<T>, T, Vec3<T>)> {
        let l = self.state.borrow_mut().records.light(&self.scene, i);
        match l.kind {
            LightKind::Directional => Some((-l.dir, T::MAX, l.color)),
            LightKind::Point | LightKind::Spot => {
                let to = l.pos - p;
                let d2 = to.length_sq();
                let d = d2.sqrt();
                if d == T::ZERO {
                    return None;
                }
                let dir = to * d.recip();
                let mut c = l.color;
                if l.kind == LightKind::Point {
                    if l.falloff {
                        c = c * d2.recip();
                    }
                } else {
                    let cos_axis = -dir.dot(l.dir);
                    if cos_axis <= l.cos_outer {
                        return None;
                    }
                    let edge = if cos_axis >= l.cos_inner || l.cos_inner <= l.cos_outer {
                        T::ONE
                    } else {
                        let s = (cos_axis - l.cos_outer) / (l.cos_inner - l.cos_outer);
                        s * s * (T::from_i32(3) - T::TWO * s)
                    };
                    let shape = if l.exponent > T::ZERO {
                        cos_axis.max(T::ZERO).pow_exponent(l.exponent)
                    } else {
                        T::ONE
                    };
                    c = c * (edge * shape);
                }
                Some((dir, d, c))
            }
        }
    }

    /// Light transmitted from `surf` towards a light `dist` away along `dir`: the product of
    /// the transmittances of every surface crossed (LINKS-1: transparent objects cast
    /// lighter shadows).
    pub(super) fn shadow(
        &mut self,
        light: u32,
        surf: &Surface<T>,
        dir: Vec3<T>,
        dist: T,
    ) -> Vec3<T> {
        let mut atten = Vec3::splat(T::ONE);
        if self.camera.no_shadows {
            return atten;
        }
        self.stats.shadow_rays += 1;
        let mut origin = offset_ray_origin(surf.p, surf.p_error, surf.ng, dir);
        let far = dist < T::MAX;
        let light_pos = surf.p + dir * dist;
        if self.techniques.shadow_early_exit {
            // Any opaque blocker makes the answer exactly zero, as the stepping below would
            // find; nothing at all in the way makes it exactly one.
            let t_max = if far {
                (light_pos - origin).dot(dir)
            } else {
                T::MAX
            };
            if t_max > T::ZERO {
                let probe = Probe::new(&Ray::new(origin, dir), None, self.has_triangles);
                // The shape that blocked this light's last shadow ray is tried first: the
                // rays of neighbouring pixels are likely blocked by it too.
                let slot = self
                    .state
                    .borrow_mut()
                    .blockers
                    .get_mut(light as usize)
                    .and_then(|b| b.take());
                if let Some(b) = slot {
                    if self.blocks(b, &probe, t_max) {
                        self.state.borrow_mut().blockers[light as usize] = Some(b);
                        self.stats.shadow_early_exits += 1;
                        return Vec3::zero();
                    }
                }
                let (blocker, transparent) = self.any_opaque(&probe, t_max);
                if let Some(b) = blocker {
                    if let Some(slot) = self.state.borrow_mut().blockers.get_mut(light as usize) {
                        *slot = Some(b);
                    }
                }
                if blocker.is_some() || !transparent {
                    self.stats.shadow_early_exits += 1;
                    return if blocker.is_some() {
                        Vec3::zero()
                    } else {
                        atten
                    };
                }
            }
        }
        let mut k = 0;
        while k < MAX_CROSSINGS {
            let t_max = if far {
                (light_pos - origin).dot(dir)
            } else {
                T::MAX
            };
            if t_max <= T::ZERO {
                return atten;
            }
            let ray = Ray::new(origin, dir);
            let Some(hit) = self.closest_hit(&ray, t_max) else {
                return atten;
            };
            let s = self.surface(&ray, &hit);
            let m = self.material_at(&s);
            atten = atten.mul_elem(m.transmit);
            if atten.max_component() < T::from_f32(1.0 / 1024.0) {
                return Vec3::zero();
            }
            origin = offset_ray_origin(s.p, s.p_error, s.ng, dir);
            k += 1;
        }
        Vec3::zero()
    }
}
