//! Material and light records decoded once per tracer instead of once per hit: a shaded
//! hit used to decode its material's 16 fields and every light's 9 from the SceneImage's
//! byte records (issue 13: ~150 instructions per pixel on the Cortex-M4F).
//!
//! The first [`CACHED_LIGHTS`] lights sit in a table indexed by light number; materials in
//! a direct-mapped table of [`CACHED_MATERIALS`] slots tagged with their index. Anything
//! else is decoded on each use, so a scene with many materials or lights is still rendered,
//! only slower. The values are the record's, so every pixel is the same as before.
//!
//! Box and ellipsoid records (a centre and two 3x3 matrices each) are kept decoded the same
//! way, in direct-mapped tables of [`CACHED_SHAPES`] slots: photo1's floor box was decoded
//! for every primary ray it was tested against and again for every hit on it.

use crate::image::{BoxRec, EllipsoidRec, Light, Material, SceneView};
use crate::num::Real;

/// Materials kept decoded (direct-mapped on the index).
pub const CACHED_MATERIALS: usize = 16;

/// Lights kept decoded (the first ones of the scene).
pub const CACHED_LIGHTS: usize = 8;

/// Boxes and ellipsoids kept decoded, each (direct-mapped on the index).
pub const CACHED_SHAPES: usize = 4;

/// Decoded material, light, box and ellipsoid records of one scene.
pub(super) struct Records<T> {
    materials: [Option<(u32, Material<T>)>; CACHED_MATERIALS],
    lights: [Option<Light<T>>; CACHED_LIGHTS],
    boxes: [Option<(u32, BoxRec<T>)>; CACHED_SHAPES],
    ellipsoids: [Option<(u32, EllipsoidRec<T>)>; CACHED_SHAPES],
}

impl<T: Real> Records<T> {
    pub(super) fn new() -> Self {
        Records {
            materials: [None; CACHED_MATERIALS],
            lights: [None; CACHED_LIGHTS],
            boxes: [None; CACHED_SHAPES],
            ellipsoids: [None; CACHED_SHAPES],
        }
    }

    /// Box `i` of `scene` (which must be the scene every earlier call named).
    #[inline]
    pub(super) fn boxshape(&mut self, scene: &SceneView<'_>, i: u32) -> &BoxRec<T> {
        let slot = &mut self.boxes[i as usize % CACHED_SHAPES];
        if slot.as_ref().is_some_and(|(tag, _)| *tag != i) {
            *slot = None;
        }
        &slot.get_or_insert_with(|| (i, scene.boxshape::<T>(i))).1
    }

    /// Ellipsoid `i` of `scene` (which must be the scene every earlier call named).
    #[inline]
    pub(super) fn ellipsoid(&mut self, scene: &SceneView<'_>, i: u32) -> &EllipsoidRec<T> {
        let slot = &mut self.ellipsoids[i as usize % CACHED_SHAPES];
        if slot.as_ref().is_some_and(|(tag, _)| *tag != i) {
            *slot = None;
        }
        &slot.get_or_insert_with(|| (i, scene.ellipsoid::<T>(i))).1
    }

    /// Material `i` of `scene` (which must be the scene every earlier call named).
    #[inline]
    pub(super) fn material(&mut self, scene: &SceneView<'_>, i: u32) -> Material<T> {
        let slot = i as usize % CACHED_MATERIALS;
        match self.materials[slot] {
            Some((tag, m)) if tag == i => m,
            _ => {
                let m = scene.material::<T>(i);
                self.materials[slot] = Some((i, m));
                m
            }
        }
    }

    /// Light `i` of `scene` (which must be the scene every earlier call named).
    #[inline]
    pub(super) fn light(&mut self, scene: &SceneView<'_>, i: u32) -> Light<T> {
        match self.lights.get_mut(i as usize) {
            Some(Some(l)) => *l,
            Some(slot) => *slot.insert(scene.light::<T>(i)),
            None => scene.light::<T>(i),
        }
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::desc::{Camera, Light as LightDesc, Material as MaterialDesc};
    use crate::dm::{compile, CompileOptions};
    use crate::image::Section;
    use crate::testkit::scene::scene_desc;

    #[test]
    fn cached_records_equal_the_decoded_ones_past_the_table_sizes() {
        use crate::desc::{CutPlane, Node, Shape};
        let camera = Camera {
            eye: [0.0; 3],
            look_at: [0.0, 0.0, 1.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
        };
        // Boxes and ellipsoids (every other one cut) spread in front of the eye.
        let shapes = (0..CACHED_SHAPES + 3)
            .flat_map(|k| {
                let x = k as f64 - 5.0;
                [
                    Node::Shape(Shape::Box {
                        min: [x, -1.0, 6.0 + x * 0.1],
                        max: [x + 0.5, 0.2 * k as f64, 7.0],
                        material: 0,
                    }),
                    Node::Shape(Shape::Ellipsoid {
                        center: [x, 1.5, 8.0],
                        radii: [0.3, 0.2 + 0.05 * k as f64, 0.4],
                        rotate_deg: [10.0 * k as f64, 5.0, 0.0],
                        cut: (k % 2 == 0).then_some(CutPlane {
                            normal: [0.0, 1.0, 0.2],
                            offset: 0.1,
                            capped: k % 4 == 0,
                        }),
                        material: 0,
                    }),
                ]
            })
            .collect();
        let mut desc = scene_desc(camera, 8, 8, shapes);
        desc.materials = (0..CACHED_MATERIALS + 5)
            .map(|k| MaterialDesc {
                diffuse: [k as f32 / 32.0, 0.5, 1.0 - k as f32 / 32.0],
                shininess: 2.0 + k as f32,
                ..MaterialDesc::default()
            })
            .collect();
        desc.lights = (0..CACHED_LIGHTS + 3)
            .map(|k| LightDesc::Point {
                pos: [k as f64, 2.0, -3.0],
                color: [0.1 * k as f32, 0.2, 0.3],
                falloff: k % 2 == 0,
            })
            .collect();
        let image = compile(&desc, &CompileOptions::default())
            .expect("compiles")
            .bytes;
        let scene = SceneView::new(&image).expect("valid image");
        assert!(scene.count(Section::Materials) as usize > CACHED_MATERIALS + 4);
        assert!(scene.light_count() as usize > CACHED_LIGHTS + 2);
        assert!(scene.count(Section::Boxes) as usize > CACHED_SHAPES + 2);
        assert!(scene.count(Section::Ellipsoids) as usize > CACHED_SHAPES + 2);
        let mut records = Records::<f32>::new();
        // Twice over, in an order that makes direct-mapped slots evict each other.
        for round in 0..2 {
            for i in (0..scene.count(Section::Materials)).rev() {
                let (got, want) = (records.material(&scene, i), scene.material::<f32>(i));
                assert_eq!(
                    format!("{got:?}"),
                    format!("{want:?}"),
                    "material {i} round {round}"
                );
            }
            for i in 0..scene.light_count() {
                let (got, want) = (records.light(&scene, i), scene.light::<f32>(i));
                assert_eq!(
                    format!("{got:?}"),
                    format!("{want:?}"),
                    "light {i} round {round}"
                );
            }
            for i in (0..scene.count(Section::Boxes)).rev() {
                let (got, want) = (records.boxshape(&scene, i), scene.boxshape::<f32>(i));
                assert_eq!(
                    format!("{got:?}"),
                    format!("{want:?}"),
                    "box {i} round {round}"
                );
            }
            for i in 0..scene.count(Section::Ellipsoids) {
                let (got, want) = (records.ellipsoid(&scene, i), scene.ellipsoid::<f32>(i));
                assert_eq!(
                    format!("{got:?}"),
                    format!("{want:?}"),
                    "ellipsoid {i} round {round}"
                );
            }
        }
    }
}
