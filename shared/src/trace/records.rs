//! Material and light records decoded once per tracer instead of once per hit: a shaded
//! hit used to decode its material's 16 fields and every light's 9 from the SceneImage's
//! byte records (issue 13: ~150 instructions per pixel on the Cortex-M4F).
//!
//! The first [`CACHED_LIGHTS`] lights sit in a table indexed by light number; materials in
//! a direct-mapped table of [`CACHED_MATERIALS`] slots tagged with their index. Anything
//! else is decoded on each use, so a scene with many materials or lights is still rendered,
//! only slower. The values are the record's, so every pixel is the same as before.

use crate::image::{Light, Material, SceneView};
use crate::num::Real;

/// Materials kept decoded (direct-mapped on the index).
pub const CACHED_MATERIALS: usize = 16;

/// Lights kept decoded (the first ones of the scene).
pub const CACHED_LIGHTS: usize = 8;

/// Decoded material and light records of one scene.
pub(super) struct Records<T> {
    materials: [Option<(u32, Material<T>)>; CACHED_MATERIALS],
    lights: [Option<Light<T>>; CACHED_LIGHTS],
}

impl<T: Real> Records<T> {
    pub(super) fn new() -> Self {
        Records {
            materials: [None; CACHED_MATERIALS],
            lights: [None; CACHED_LIGHTS],
        }
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
        let camera = Camera {
            eye: [0.0; 3],
            look_at: [0.0, 0.0, 1.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
        };
        let mut desc = scene_desc(camera, 8, 8, std::vec::Vec::new());
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
        }
    }
}
