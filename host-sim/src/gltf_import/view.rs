//! The camera and the lights of an import (docs/scene-format.md, "glTF import").
//!
//! - Camera: the first perspective camera met walking the scene's nodes in order; its node's
//!   world matrix places the eye at its origin looking along its -Z with +Y up; `yfov` is the
//!   vertical field of view. Without one, a camera looks at the centre of the scene's bounding
//!   box from direction [`DEFAULT_VIEW_DIR`], far enough for the box's bounding sphere to fit
//!   [`DEFAULT_FOV_DEG`].
//! - Lights (KHR_lights_punctual): colour × intensity. Directional lights shine along their
//!   node's -Z; point lights fall off as 1/d² (candela over metres² = the glTF meaning); spot
//!   lights have no distance falloff here, so their colour × intensity is divided by the square
//!   of their distance to the bounding box's centre (the centre receives what glTF gives it).

use links_core::desc::{Camera, Light};

use super::nodes::{LightKind, WorldInfo};
use super::transform::{apply_dir, apply_point};
use super::warning::Warning;
use super::{Importer, DEFAULT_HEIGHT, DEFAULT_WIDTH};
use crate::limits::MAX_IMAGE_SIDE;

pub const DEFAULT_FOV_DEG: f64 = 45.0;
/// From the box's centre towards the default eye: right, above and in front (+Z is glTF's
/// front).
pub const DEFAULT_VIEW_DIR: [f64; 3] = [0.6, 0.5, 1.0];
/// The default light's direction relative to the camera: (right, up, forward).
const DEFAULT_LIGHT_FROM_CAMERA: [f64; 3] = [0.4, -0.7, 1.0];

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add_scaled(a: [f64; 3], b: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] + b[0] * s, a[1] + b[1] * s, a[2] + b[2] * s]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (n > 0.0 && n.is_finite()).then(|| v.map(|c| c / n))
}

fn centre(world: &WorldInfo) -> ([f64; 3], f64) {
    let (lo, hi) = world.bounds.unwrap_or(([0.0; 3], [0.0; 3]));
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let r = 0.5 * sub(hi, lo).iter().map(|d| d * d).sum::<f64>().sqrt();
    (c, if r > 0.0 { r } else { 1.0 })
}

/// The image size for an aspect ratio (width / height): 512 wide, or 512x480 without one.
pub fn image_size(aspect: Option<f64>) -> (u32, u32) {
    match aspect.filter(|a| a.is_finite() && *a > 0.0) {
        Some(a) => {
            let h = (f64::from(DEFAULT_WIDTH) / a).round();
            (
                DEFAULT_WIDTH,
                h.clamp(1.0, f64::from(MAX_IMAGE_SIDE)) as u32,
            )
        }
        None => (DEFAULT_WIDTH, DEFAULT_HEIGHT),
    }
}

impl Importer<'_> {
    /// The camera and the image size.
    pub(super) fn camera(&mut self, world: &WorldInfo) -> (Camera, u32, u32) {
        if let Some(found) = &world.camera {
            let eye = apply_point(&found.world, [0.0; 3]);
            let fwd = normalize(apply_dir(&found.world, [0.0, 0.0, -1.0]));
            let up = normalize(apply_dir(&found.world, [0.0, 1.0, 0.0]));
            let fov = found.yfov.to_degrees();
            match (fwd, up) {
                (Some(fwd), Some(up)) if fov > 0.0 && fov < 180.0 => {
                    let (w, h) = image_size(found.aspect);
                    let cam = Camera {
                        eye,
                        look_at: add_scaled(eye, fwd, 1.0),
                        up,
                        fov_y_deg: fov,
                    };
                    return (cam, w, h);
                }
                _ => self.warnings.push(Warning::Camera {
                    camera: found.name.clone(),
                    message: "degenerate (zero scale or yfov outside (0, 180) degrees); skipped"
                        .into(),
                }),
            }
        }
        self.warnings.push(Warning::DefaultCamera);
        let (c, r) = centre(world);
        let dir = normalize(DEFAULT_VIEW_DIR).unwrap_or([0.0, 0.0, 1.0]);
        let dist = r / (0.5 * DEFAULT_FOV_DEG).to_radians().sin();
        let cam = Camera {
            eye: add_scaled(c, dir, dist),
            look_at: c,
            up: [0.0, 1.0, 0.0],
            fov_y_deg: DEFAULT_FOV_DEG,
        };
        (cam, DEFAULT_WIDTH, DEFAULT_HEIGHT)
    }

    /// The lights, or one directional light over the camera's shoulder (warned).
    pub(super) fn lights(&mut self, world: &WorldInfo, camera: &Camera) -> Vec<Light> {
        let (c, _) = centre(world);
        let mut out = Vec::new();
        for l in &world.lights {
            let color = l.color.map(|v| v * l.intensity);
            let pos = apply_point(&l.world, [0.0; 3]);
            let dir = normalize(apply_dir(&l.world, [0.0, 0.0, -1.0])).unwrap_or([0.0, 0.0, -1.0]);
            out.push(match l.kind {
                LightKind::Directional => Light::Directional { dir, color },
                LightKind::Point => Light::Point {
                    pos,
                    color,
                    falloff: true,
                },
                LightKind::Spot { inner, outer } => {
                    let d2 = sub(c, pos).iter().map(|d| d * d).sum::<f64>().max(1e-12);
                    Light::Spot {
                        pos,
                        dir,
                        color: color.map(|v| (f64::from(v) / d2) as f32),
                        inner_deg: inner.to_degrees(),
                        outer_deg: outer.to_degrees(),
                        exponent: 0.0,
                    }
                }
            });
        }
        if out.is_empty() {
            self.warnings.push(Warning::DefaultLight);
            out.push(default_light(camera));
        }
        out
    }
}

/// A white directional light from behind, above and right of the camera.
pub fn default_light(camera: &Camera) -> Light {
    let fwd = normalize(sub(camera.look_at, camera.eye)).unwrap_or([0.0, 0.0, -1.0]);
    let right = normalize(cross(fwd, camera.up)).unwrap_or([1.0, 0.0, 0.0]);
    let up = cross(right, fwd);
    let [a, b, f] = DEFAULT_LIGHT_FROM_CAMERA;
    let dir = [0, 1, 2].map(|k| right[k] * -a + up[k] * b + fwd[k] * f);
    Light::Directional {
        dir: normalize(dir).unwrap_or(fwd),
        color: [1.0; 3],
    }
}
