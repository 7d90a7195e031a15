//! Materials at a surface point: the texture or coefficient map applied by bilinear,
//! wrapping texture lookup.

use super::surface::Surface;
use super::tracer::{Tracer, TracerState};
use crate::geom::Vec3;
use crate::image::{MapTarget, Material, NONE};
use crate::num::Real;
use core::borrow::BorrowMut;

/// A material with its texture map already applied at a surface point.
#[derive(Clone, Copy, Debug)]
pub(super) struct Mat<T> {
    pub(super) diffuse: Vec3<T>,
    /// The ambient reflection colour: the material's own, else the diffuse colour.
    pub(super) ambient: Vec3<T>,
    pub(super) specular: T,
    pub(super) specular_edge: T,
    pub(super) shininess: T,
    pub(super) reflect: T,
    pub(super) reflect_edge: T,
    pub(super) transmit: Vec3<T>,
    pub(super) ior: T,
}

impl<T: Real, S: BorrowMut<TracerState<T>>> Tracer<'_, T, S> {
    /// Material at a surface point, with its texture or coefficient map applied (bilinear).
    pub(super) fn material_at(&mut self, surf: &Surface<T>) -> Mat<T> {
        let m: Material<T> = self
            .state
            .borrow_mut()
            .records
            .material(&self.scene, surf.material);
        let mut out = Mat {
            diffuse: m.diffuse,
            ambient: m.ambient.unwrap_or(m.diffuse),
            specular: m.specular,
            specular_edge: m.specular_edge,
            shininess: m.shininess,
            reflect: m.reflect,
            reflect_edge: m.reflect_edge,
            transmit: m.transmit,
            ior: m.ior,
        };
        if m.texture != NONE {
            let texel =
                self.texture_lookup(m.texture, surf.uv[0] * m.scale[0], surf.uv[1] * m.scale[1]);
            let lum = texel.x * T::from_f32(0.299)
                + texel.y * T::from_f32(0.587)
                + texel.z * T::from_f32(0.114);
            match m.target {
                MapTarget::Diffuse => {
                    out.diffuse = out.diffuse.mul_elem(texel);
                    out.ambient = out.ambient.mul_elem(texel);
                }
                MapTarget::Specular => {
                    out.specular *= lum;
                    out.specular_edge *= lum;
                }
                MapTarget::Reflect => {
                    out.reflect *= lum;
                    out.reflect_edge *= lum;
                }
                MapTarget::Transmit => out.transmit = out.transmit * lum,
            }
        }
        out
    }

    /// Bilinear, wrapping texture lookup; v = 0 is the bottom row of the image.
    pub(super) fn texture_lookup(&self, index: u32, u: T, v: T) -> Vec3<T> {
        let tex = self.scene.texture(index);
        // A validated image's textures are 1 .. 2^31 texels wide and high and hold exactly
        // w * h texels (`SceneView::texture`); anything else reads black, never panics.
        let (Ok(w), Ok(h)) = (i32::try_from(tex.width), i32::try_from(tex.height)) else {
            return Vec3::zero();
        };
        if w == 0 || h == 0 {
            return Vec3::zero();
        }
        let u = u - u.floor();
        let v = v - v.floor();
        let x = u * T::from_i32(w) - T::HALF;
        let y = (T::ONE - v) * T::from_i32(h) - T::HALF;
        let xf = x.floor();
        let yf = y.floor();
        let fx = x - xf;
        let fy = y - yf;
        let xi = xf.to_f32() as i32;
        let yi = yf.to_f32() as i32;
        let texel = |xx: i32, yy: i32| -> Vec3<T> {
            let rgb = tex.texel(xx.rem_euclid(w) as u32, yy.rem_euclid(h) as u32);
            let c = |k: usize| T::from_i32(rgb[k] as i32) / T::from_i32(255);
            Vec3::new(c(0), c(1), c(2))
        };
        let top = texel(xi, yi) * (T::ONE - fx) + texel(xi + 1, yi) * fx;
        let bot = texel(xi, yi + 1) * (T::ONE - fx) + texel(xi + 1, yi + 1) * fx;
        top * (T::ONE - fy) + bot * fy
    }
}
