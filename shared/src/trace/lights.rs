//! Lights and shadows: the light arriving at a point from each light source, and the
//! transmittance of the surfaces between (transparent objects cast lighter shadows).

use super::surface::Surface;
use super::tracer::{Tracer, TracerState, MAX_CROSSINGS};
use super::traversal::Probe;
use crate::geom::{Ray, Vec3};
use crate::image::{LightKind, ShapeKind, ShapeRef};
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
    ///
    /// Out of line: inlined, its walks filled the light loop of [`Self::local_shade`] and
    /// made it keep every material constant on the stack, set up on each shading even
    /// without shadows (photo1-noshadow on the M4F: local_shade 285 instructions per pixel).
    #[inline(never)]
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
        let mut origin = surf.spawn_origin(dir);
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
                let leaving = leaving_convex(surf, dir);
                let seen = if T::ABSOLUTE_ROUNDING {
                    None
                } else {
                    self.state.borrow().light_rects.point(light, origin)
                };
                let (blocker, transparent) = self.any_opaque(&probe, t_max, leaving, seen);
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
            origin = s.spawn_origin(dir);
            k += 1;
        }
        Vec3::zero()
    }
}

/// The shape a shadow ray starts on, when that shape is convex (a box, an ellipsoid, cut or
/// not) and the ray leaves it through the outside of its surface: such a ray cannot meet
/// the shape again (the shape lies wholly behind the tangent plane the ray leaves), so
/// the any-opaque walk skips it - on photo1 that is the floor, which almost every shadow
/// ray from the floor tested. The margin keeps grazing rays, whose computed cosine might
/// have the wrong sign, on the full test.
fn leaving_convex<T: Real>(surf: &Surface<T>, dir: Vec3<T>) -> Option<ShapeRef> {
    let convex = matches!(surf.shape.kind, ShapeKind::Box | ShapeKind::Ellipsoid);
    (convex && dir.dot(surf.ng) > T::from_f32(1.0 / 1024.0)).then_some(surf.shape)
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::desc::{Camera, Cluster, CutPlane, Node, Shape, Transform};
    use crate::dm::{compile, CompileOptions};
    use crate::image::SceneView;
    use crate::trace::traversal::Probe;

    /// The skip is exact: from points all over a rotated box, an ellipsoid, a capped and an
    /// open cut ellipsoid (hit by rays from many directions), every shadow-ray direction
    /// `leaving_convex` lets skip the shape finds no crossing of that shape when tested in
    /// full; and the skip is offered for most outward directions (it is not vacuous).
    #[test]
    fn a_ray_leaving_a_convex_shape_outwards_never_meets_it_again() {
        let cut = |capped| CutPlane {
            normal: [0.3, 1.0, -0.2],
            offset: 0.4,
            capped,
        };
        let shapes = std::vec![
            Shape::Box {
                min: [-1.0, -0.5, -0.7],
                max: [1.2, 0.6, 0.9],
                material: 0,
            },
            Shape::Ellipsoid {
                center: [0.0; 3],
                radii: [1.3, 0.7, 1.0],
                rotate_deg: [10.0, 25.0, -5.0],
                cut: None,
                material: 0,
            },
            Shape::Ellipsoid {
                center: [0.0; 3],
                radii: [1.0, 1.2, 0.8],
                rotate_deg: [0.0; 3],
                cut: Some(cut(true)),
                material: 0,
            },
            Shape::Ellipsoid {
                center: [0.0; 3],
                radii: [1.0, 1.2, 0.8],
                rotate_deg: [0.0; 3],
                cut: Some(cut(false)),
                material: 0,
            },
        ];
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        for shape in shapes {
            let cluster = Node::Cluster(Cluster {
                name: "s".into(),
                transform: Transform {
                    rotate_deg: [20.0, -35.0, 10.0],
                    ..Transform::default()
                },
                children: std::vec![Node::Shape(shape.clone())],
            });
            let camera = Camera {
                eye: [0.0, 0.0, -6.0],
                look_at: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: 40.0,
            };
            let desc = crate::testkit::scene::scene_desc(camera, 8, 8, std::vec![cluster]);
            let img = compile(&desc, &CompileOptions::default()).unwrap().bytes;
            let view = SceneView::new(&img).unwrap();
            let mut tracer = crate::trace::Tracer::<f32>::new(view);
            let (mut skipped, mut tried) = (0, 0);
            for _ in 0..400 {
                // A ray from outside towards the middle, from a random direction (view
                // coordinates: the shape's centre lies 6 ahead of the eye).
                let centre = Vec3::new(0.0, 0.0, 6.0f32);
                let from = centre + Vec3::new(next(), next(), next()).normalize() * 5.0f32;
                let aim = centre + Vec3::new(next(), next(), next()) * 0.3f32;
                let ray = Ray::new(from, (aim - from).normalize());
                let Some((_, surf)) = tracer.first_surface(&ray) else {
                    continue;
                };
                for _ in 0..8 {
                    let dir = Vec3::new(next(), next(), next()).normalize();
                    tried += 1;
                    let Some(shape) = leaving_convex(&surf, dir) else {
                        continue;
                    };
                    skipped += 1;
                    assert_eq!(shape, surf.shape);
                    let origin = surf.spawn_origin(dir);
                    let probe = Probe::new(&Ray::new(origin, dir), None, false);
                    let leaf = crate::image::Leaf {
                        kind: shape.kind,
                        first: shape.index,
                        count: 1,
                        material: 0,
                    };
                    let again = tracer.intersect_shape(leaf, 0, &probe, f32::MAX);
                    assert!(
                        again.is_none(),
                        "{shape:?}: from {:?} along {dir:?}",
                        surf.p
                    );
                }
            }
            // About half the random directions point outwards.
            assert!(skipped * 4 > tried, "{skipped} of {tried} skipped");
        }
    }
}
