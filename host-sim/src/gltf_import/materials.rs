//! glTF metallic-roughness materials -> the eq. 2.1 terms (docs/scene-format.md, "glTF import").
//!
//! With base colour `c` (rgb of baseColorFactor), metallic `m`, roughness `r`, transmission `t`:
//! - `F0 = 0.04·(1 - m) + m·lum(c)`, smoothness `s = (1 - r)²`
//! - `diffuse = c·(1 - m·s)·(1 - t)`: a polished metal only mirrors, a rough one (r = 1)
//!   scatters its colour diffusely (eq. 2.1 has no rough-specular lobe to carry it)
//! - `specular = F0`, `specular_edge = F0 + (1 - F0)·s`
//! - `shininess = clamp(2/α² - 2, 1, 1000)` with `α = r²` (the Blinn-Phong exponent of GGX α)
//! - `reflect = F0·s`, `reflect_edge = specular_edge·s`
//! - `transmit = c·t·(1 - m)`, where `t` is KHR_materials_transmission's factor, raised to
//!   `1 - alpha` for alphaMode BLEND
//! - `ior` = KHR_materials_ior (glTF's default 1.5)
//! - `ambient`: none (glTF has no ambient coefficient; occlusion maps and emission are not
//!   ambient reflection), so the ambient term uses `diffuse`

use links_core::desc::{MapTarget, Material, TextureMap};

use super::warning::Warning;

/// Dielectric reflectance at normal incidence (glTF's fixed 4 %).
const DIELECTRIC_F0: f32 = 0.04;
const MAX_SHININESS: f32 = 1000.0;
const GLTF_DEFAULT_IOR: f32 = 1.5;

/// The inputs of the rule, read from a glTF material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pbr {
    pub base: [f32; 4],
    pub metallic: f32,
    pub roughness: f32,
    pub transmission: f32,
    pub blend: bool,
    pub ior: Option<f32>,
}

fn luminance(c: [f32; 3]) -> f32 {
    0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2]
}

/// The rule above.
pub fn eq21_terms(name: &str, p: &Pbr) -> Material {
    let c = [p.base[0], p.base[1], p.base[2]].map(|v| v.clamp(0.0, 1.0));
    let m = p.metallic.clamp(0.0, 1.0);
    let r = p.roughness.clamp(0.0, 1.0);
    let mut t = p.transmission.clamp(0.0, 1.0);
    if p.blend {
        t = t.max(1.0 - p.base[3].clamp(0.0, 1.0));
    }
    let f0 = DIELECTRIC_F0 * (1.0 - m) + m * luminance(c);
    let s = (1.0 - r) * (1.0 - r);
    let alpha = r * r;
    let shininess = if alpha > 0.0 {
        (2.0 / (alpha * alpha) - 2.0).clamp(1.0, MAX_SHININESS)
    } else {
        MAX_SHININESS
    };
    let specular_edge = f0 + (1.0 - f0) * s;
    Material {
        name: name.to_string(),
        diffuse: c.map(|v| v * (1.0 - m * s) * (1.0 - t)),
        specular: f0,
        specular_edge,
        shininess,
        reflect: f0 * s,
        reflect_edge: specular_edge * s,
        transmit: c.map(|v| v * t * (1.0 - m)),
        ior: p
            .ior
            .filter(|v| v.is_finite() && *v >= 1.0)
            .unwrap_or(GLTF_DEFAULT_IOR),
        // glTF has no ambient coefficient (occlusion maps and emission are other things):
        // the ambient term uses the diffuse colour.
        ambient: None,
        map: None,
    }
}

/// The rule's inputs of `mat`, and warnings for what it has beyond them.
pub fn read_pbr(mat: &gltf::Material<'_>, name: &str, warnings: &mut Vec<Warning>) -> Pbr {
    let pbr = mat.pbr_metallic_roughness();
    let mut feature = |what: &str| {
        warnings.push(Warning::MaterialFeature {
            material: name.to_string(),
            feature: what.to_string(),
        })
    };
    if pbr.metallic_roughness_texture().is_some() {
        feature("metallicRoughnessTexture (the factors are used)");
    }
    if mat.normal_texture().is_some() {
        feature("normalTexture");
    }
    if mat.occlusion_texture().is_some() {
        feature("occlusionTexture");
    }
    if mat.emissive_texture().is_some() || mat.emissive_factor().iter().any(|&v| v > 0.0) {
        feature("emission");
    }
    if matches!(mat.alpha_mode(), gltf::material::AlphaMode::Mask) {
        feature("alphaMode MASK (imported opaque)");
    }
    let transmission = mat.transmission();
    if transmission
        .as_ref()
        .is_some_and(|t| t.transmission_texture().is_some())
    {
        feature("transmissionTexture (the factor is used)");
    }
    Pbr {
        base: pbr.base_color_factor(),
        metallic: pbr.metallic_factor(),
        roughness: pbr.roughness_factor(),
        transmission: transmission.map_or(0.0, |t| t.transmission_factor()),
        blend: matches!(mat.alpha_mode(), gltf::material::AlphaMode::Blend),
        ior: mat.ior(),
    }
}

/// The texture map for a decoded base-colour texture: glTF's base colour multiplies `drc`.
pub fn diffuse_map(texture: u32) -> TextureMap {
    TextureMap {
        texture,
        target: MapTarget::Diffuse,
        scale: [1.0, 1.0],
    }
}

/// Is `bytes` a PNG by its signature (glTF's mimeType is optional for URIs)?
pub fn is_png(bytes: &[u8]) -> bool {
    bytes.starts_with(b"\x89PNG\r\n\x1a\n")
}
