//! Primary rays: what view coordinates give them.
//!
//! Every primary ray starts at the eye, the origin of view coordinates, along
//! `d = (x0 + (x + 1/2) dx, y0 - (y + 1/2) dy, dz)`. A triangle is then tested against the
//! three planes through the eye and its edges ([`EdgePlanes`]): three dot products with
//! `d`, no per-ray set-up and no divide unless the ray passes inside. The planes depend on
//! the triangle only, so the tracer keeps the ones it made in a small two-way cache
//! ([`PlaneCache`]) for the rays of the rows that follow. Every technique set tests
//! primary rays this way (the plain algorithm too), so they keep giving the same pixels.

use crate::geom::Vec3;
use crate::image::SceneView;
use crate::num::Real;

/// Triangles whose planes the cache holds at once (a power of two: the set of two slots is
/// the low bits of the triangle index). Two ways, not one slot per index: photo1-noshadow
/// at 32x30 made 643 planes direct-mapped, 487 in two ways (452 distinct triangles).
pub const PLANE_SLOTS: usize = 256;

/// A primary ray's direction before normalising, and its length.
#[derive(Clone, Copy, Debug)]
pub(super) struct EyeRay<T> {
    pub(super) d: Vec3<T>,
    pub(super) len: T,
}

/// The edge planes of recently tested triangles, by triangle index.
pub struct PlaneCache<T: Real> {
    /// Triangle index + 1 of each slot's planes (0: empty).
    tags: [u32; PLANE_SLOTS],
    planes: [T::EyePlanes; PLANE_SLOTS],
    /// The largest `|d|_1` of the frame's primary rays, which the planes' error bounds
    /// scale with.
    l1: T,
    /// Planes made (cache misses), for the operation counts.
    pub(super) made: u64,
}

impl<T: Real> PlaneCache<T> {
    /// An empty cache for primary rays whose `|d|_1` is at most `l1`.
    pub fn new(l1: T) -> Self {
        Self {
            tags: [0; PLANE_SLOTS],
            planes: [T::EYE_PLANES_EMPTY; PLANE_SLOTS],
            l1,
            made: 0,
        }
    }

    /// Empty the cache, for primary rays whose `|d|_1` is at most `l1`.
    pub fn reset(&mut self, l1: T) {
        self.tags = [0; PLANE_SLOTS];
        self.l1 = l1;
    }

    /// The largest `|d|_1` of a camera's primary rays (at the frame's corners), rounded up
    /// generously so every pixel's computed `|d|_1` stays below it.
    pub fn max_l1(camera: &crate::image::Camera<T>) -> T {
        let w = T::from_i32(camera.width.min(i32::MAX as u32) as i32);
        let h = T::from_i32(camera.height.min(i32::MAX as u32) as i32);
        let x = camera.x0.abs().max((camera.x0 + camera.across(w)).abs());
        let y = camera.y0.abs().max((camera.y0 - camera.down(h)).abs());
        (x + y + camera.dz.abs()) * T::TWO
    }

    /// The planes of triangle `i` of `scene`, made now unless the cache holds them.
    #[inline(always)]
    pub(super) fn get(&mut self, scene: &SceneView<'_>, i: u32) -> &T::EyePlanes {
        let tag = i.wrapping_add(1);
        let set = (i as usize % (PLANE_SLOTS / 2)) * 2;
        if self.tags[set] == tag {
            return &self.planes[set];
        }
        if self.tags[set + 1] == tag {
            return &self.planes[set + 1];
        }
        self.make(scene, i, set);
        &self.planes[set]
    }

    /// A miss: make triangle `i`'s planes into the first slot of its `set`, whose planes
    /// move to the second (out of line, so a hit pays no call).
    #[inline(never)]
    fn make(&mut self, scene: &SceneView<'_>, i: u32, set: usize) {
        self.tags[set + 1] = self.tags[set];
        self.planes[set + 1] = self.planes[set];
        self.planes[set] = self.made_now(scene, i);
        self.tags[set] = i.wrapping_add(1);
        self.made += 1;
    }

    /// Triangle `i`'s planes made now and not kept (the same values [`Self::get`] gives):
    /// the plain algorithm tests every triangle of the scene for each ray, more than the
    /// cache holds, so keeping them would only evict (+7% on the M4F's photo1-noshadow
    /// plain algorithm with two ways, `docs/cortex-m-bench.md`).
    #[inline(never)]
    pub(super) fn made_now(&self, scene: &SceneView<'_>, i: u32) -> T::EyePlanes {
        let (index, tri) = scene.triangle_corners::<T>(i);
        T::eye_planes(&tri, index, self.l1)
    }
}

#[cfg(test)]
mod tests {
    // The cache itself is exercised by the test that needs the DM (`std`).
    #[cfg(feature = "std")]
    use super::*;
    use crate::math::solid::Triangle;
    use crate::shape::triangle::EdgePlanes;

    /// More triangles than slots, asked for in an order that makes them evict each other:
    /// every answer is the triangle's own planes.
    #[cfg(feature = "std")]
    #[test]
    fn the_cache_answers_each_triangle_with_its_own_planes() {
        use crate::desc::{Camera, Node, Shape};
        use crate::dm::{compile, CompileOptions};
        let n = PLANE_SLOTS + 300;
        let tris = (0..n)
            .map(|i| {
                let x = i as f64 * 0.01 - 3.0;
                Node::Shape(Shape::Triangle {
                    v: [[x, 0.0, 10.0], [x + 0.01, 0.0, 10.0], [x, 0.5, 10.5]],
                    normals: None,
                    uv: None,
                    material: 0,
                })
            })
            .collect();
        let camera = Camera {
            eye: [0.0; 3],
            look_at: [0.0, 0.0, 1.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
        };
        let desc = crate::testkit::scene::scene_desc(camera, 32, 24, tris);
        let img = compile(&desc, &CompileOptions::default()).unwrap().bytes;
        let view = SceneView::new(&img).unwrap();
        let count = view.count(crate::image::Section::Triangles);
        assert_eq!(count as usize, n);
        let mut cache = PlaneCache::<f32>::new(4.0);
        let order = (0..count).flat_map(|i| [i, (i + PLANE_SLOTS as u32) % count, i]);
        let mut asked = 0u64;
        for i in order {
            let (index, tri) = view.triangle_corners::<f32>(i);
            assert_eq!(
                *cache.get(&view, i),
                EdgePlanes::new(&tri, index, 4.0),
                "triangle {i}"
            );
            asked += 1;
        }
        // The repeat of each triangle right after it is a hit; the others evicted it.
        assert!(cache.made < asked && cache.made >= count as u64);

        // Two triangles of one set are both kept; a third evicts the older of them.
        let set = (PLANE_SLOTS / 2) as u32;
        let mut cache = PlaneCache::<f32>::new(4.0);
        for i in [0, set, 0, set, set, 0] {
            cache.get(&view, i);
        }
        assert_eq!(cache.made, 2);
        for i in [2 * set, set, 0] {
            let (index, tri) = view.triangle_corners::<f32>(i);
            assert_eq!(*cache.get(&view, i), EdgePlanes::new(&tri, index, 4.0));
        }
        // 2 * set evicted 0 (the older), so 0 was made again, evicting set.
        assert_eq!(cache.made, 4);
        cache.get(&view, set);
        assert_eq!(cache.made, 5);
        // Planes made on the spot (the plain algorithm's) are the cached ones, and not kept.
        for i in [0, set, 2 * set] {
            let now = cache.made_now(&view, i);
            assert_eq!(now, *cache.get(&view, i));
        }
        assert_eq!(cache.made, 6, "only 2 * set was not held");
    }

    #[test]
    fn planes_from_the_cache_equal_fresh_ones() {
        let tri = Triangle {
            p: [
                crate::geom::Vec3::new(-1.0f32, -1.0, 5.0),
                crate::geom::Vec3::new(1.0, -1.0, 5.0),
                crate::geom::Vec3::new(0.0, 1.0, 6.0),
            ],
        };
        let a = EdgePlanes::new(&tri, [3, 1, 2], 2.0);
        let b = EdgePlanes::new(&tri, [3, 1, 2], 2.0);
        assert_eq!(a, b);
        // The triple product is the volume term: p0 . (p1 x p2).
        let want = tri.p[0].dot(tri.p[1].cross(tri.p[2]));
        assert!((a.det - want).abs() <= 1e-5 * want.abs());
    }
}
