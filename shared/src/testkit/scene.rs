//! Hand-built scenes for tests: scene descriptions for the DM ([`scene_desc`]) and
//! SceneImages of a few records ([`SceneBuilder`]) written through the image writer (so at
//! the offsets of [`crate::image::layout`]), their scalars stored as f32 or Q16.16, for
//! tests that need an image the DM would never produce or one smaller than any scene.

#[cfg(feature = "std")]
use crate::desc::{Camera, Cluster, Material, Node, SceneDesc, Transform, TransparencyMode};
use crate::image::layout::{camera, material, node, texture, triangle, vertex, STORAGE_AT};
use crate::image::writer::ImageWriter;
use crate::image::{Leaf, MapTarget, Section, ShapeKind, NONE, NONE16};
use crate::num::Storage;
use std::vec::Vec;

/// The material every [`SceneBuilder::grey_material`] writes: every scalar 0.5.
pub const GREY: [f32; 12] = [0.5; 12];
/// A material lit by ambient light only, so a pixel is its diffuse colour: diffuse 1, no
/// specular (shininess 1), no reflection or transmission, ior 1.
pub const MATTE_WHITE: [f32; 12] = [1.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// The node grid of builder images: origin 0, step 2^-8 on every axis (boxes within
/// ±128 units; exact in f32 and Q16.16).
pub const GRID_STEP: f32 = 1.0 / 256.0;

/// Builds an image record by record.
pub struct SceneBuilder {
    /// The writer, for records the builder has no method for.
    pub w: ImageWriter,
    storage: Storage,
}

impl SceneBuilder {
    /// An empty image whose scalars are stored as `storage` (Q16.16 without scaling).
    pub fn new(storage: Storage) -> Self {
        Self {
            w: ImageWriter::new(),
            storage,
        }
    }

    /// `x` as this image stores it.
    pub fn stored(&self, x: f32) -> u32 {
        match self.storage {
            Storage::F32 => x.to_bits(),
            Storage::Q16_16 => ((x * 65536.0).round() as i32) as u32,
        }
    }

    /// A camera pixel step (dx, dy) as this image stores it: a Q16.16 image holds it
    /// 2^[`camera::STEP_BITS`] times finer.
    pub fn stored_step(&self, x: f32) -> u32 {
        match self.storage {
            Storage::F32 => x.to_bits(),
            Storage::Q16_16 => {
                ((x as f64 * 65536.0 * (1u32 << camera::STEP_BITS) as f64).round() as i32) as u32
            }
        }
    }

    fn stored_all(&self, xs: &[f32]) -> Vec<u32> {
        xs.iter().map(|&x| self.stored(x)).collect()
    }

    /// The camera: `width` x `height` pixels, `window` = (x0, y0, dx, dy), a black
    /// background, grey `ambient` light, depth 2, no flags, dz 1, the [`GRID_STEP`] node
    /// grid, one-pixel rectangles.
    pub fn camera(&mut self, width: u32, height: u32, window: [f32; 4], ambient: f32) -> &mut Self {
        let v: Vec<u32> = window
            .iter()
            .chain(&[ambient; 3])
            .chain(&[1.0])
            .map(|&x| self.stored(x))
            .collect();
        let zero = self.stored(0.0);
        let steps = [self.stored_step(window[2]), self.stored_step(window[3])];
        self.w
            .push(Section::Camera)
            .1
            .u(camera::WIDTH, width)
            .u(camera::HEIGHT, height)
            .u(camera::X0, v[0])
            .u(camera::Y0, v[1])
            .u(camera::DX, steps[0])
            .u(camera::DY, steps[1])
            .u(camera::BACKGROUND, zero)
            .u(camera::BACKGROUND + 4, zero)
            .u(camera::BACKGROUND + 8, zero)
            .u(camera::AMBIENT, v[4])
            .u(camera::AMBIENT + 4, v[5])
            .u(camera::AMBIENT + 8, v[6])
            .u(camera::MAX_DEPTH, 2)
            .u(camera::FLAGS, 0)
            .u(camera::DZ, v[7]);
        let step = self.stored(GRID_STEP);
        for k in 0..3 {
            self.w
                .patch_u32(Section::Camera, 0, camera::GRID_ORIGIN + 4 * k, zero);
            self.w
                .patch_u32(Section::Camera, 0, camera::GRID_STEP + 4 * k, step);
        }
        self
    }

    /// A material: `scalars` are diffuse[3], specular, specular_edge, shininess, reflect,
    /// reflect_edge, transmit[3], ior (in layout order); `texture` maps the diffuse colour
    /// (or [`NONE`]); the texture scale is 1.
    pub fn material(&mut self, scalars: [f32; 12], texture: u32) -> &mut Self {
        let v = self.stored_all(&scalars);
        let one = self.stored(1.0);
        let mut r = self.w.push(Section::Materials).1;
        for (k, x) in v.into_iter().enumerate() {
            r = r.u(material::DIFFUSE + 4 * k, x);
        }
        r.u(material::TEXTURE, texture)
            .u(material::TARGET, MapTarget::Diffuse as u32)
            .u(material::SCALE, one)
            .u(material::SCALE + 4, one);
        self
    }

    /// A [`GREY`] untextured material.
    pub fn grey_material(&mut self) -> &mut Self {
        self.material(GREY, NONE)
    }

    /// A texture header (RGB8 texels, no palette) and its texels (appended to the texel
    /// section).
    pub fn texture(&mut self, width: u32, height: u32, offset: u32, texels: &[u8]) -> &mut Self {
        self.w
            .push(Section::Textures)
            .1
            .u(texture::WIDTH, width)
            .u(texture::HEIGHT, height)
            .u(texture::TEXELS, offset)
            .u(texture::PALETTE, 0);
        self.w.push_texels(texels);
        self
    }

    /// A triangle with vertices `p` (x, y, z each; three new vertex records), no normals
    /// or uvs (its material is its leaf's).
    pub fn triangle(&mut self, p: [f32; 9]) -> &mut Self {
        let v = self.stored_all(&p);
        let first = self.w.count(Section::Vertices) as u16;
        for c in v.chunks_exact(3) {
            self.w
                .push(Section::Vertices)
                .1
                .u(vertex::P, c[0])
                .u(vertex::P + 4, c[1])
                .u(vertex::P + 8, c[2]);
        }
        self.w
            .push(Section::Triangles)
            .1
            .hs(triangle::V, &[first, first + 1, first + 2])
            .h(triangle::NORMALS, NONE16);
        self
    }

    /// A node with box `min`..`max` (rounded outward to the [`GRID_STEP`] grid): a
    /// cluster whose subtree ends before `skip` when `shape` is [`NONE`], else a leaf of
    /// one shape, `shape` = kind << 28 | index (a triangle leaf of material 0).
    pub fn node(&mut self, min: [f32; 3], max: [f32; 3], skip: u32, shape: u32) -> &mut Self {
        let q = |v: f32, up: bool| {
            let t = v / GRID_STEP;
            (if up { t.ceil() } else { t.floor() }) as i16 as u16
        };
        let (index, info) = if shape == NONE {
            (skip as u16, 0)
        } else {
            let leaf = Leaf {
                kind: ShapeKind::from_u8((shape >> 28) as u8).unwrap_or(ShapeKind::Triangle),
                first: shape & 0x0fff_ffff,
                count: 1,
                material: 0,
            };
            (leaf.first as u16, leaf.info())
        };
        self.w
            .push(Section::Nodes)
            .1
            .hs(node::LO, &min.map(|v| q(v, false)))
            .hs(node::HI, &max.map(|v| q(v, true)))
            .h(node::INDEX, index)
            .b(node::INFO, info)
            .b(node::MATERIAL, 0);
        self
    }

    /// The image bytes, its number format set in the header.
    pub fn finish(self) -> Vec<u8> {
        let mut img = self.w.finish();
        img[STORAGE_AT] = self.storage as u8;
        img
    }
}

/// A minimal f32 image: an 8-pixel-high camera `width` wide, one grey material, one
/// triangle and the given nodes as (skip, shape word: [`NONE`] for a cluster, else a leaf,
/// see [`SceneBuilder::node`]), each with the box [-1, 1]^3.
pub fn tiny_image(width: u32, nodes: &[(u32, u32)]) -> Vec<u8> {
    let mut b = SceneBuilder::new(Storage::F32);
    b.camera(width, 8, [-1.0, 1.0, 0.1, 0.1], 0.0)
        .grey_material()
        .triangle([0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0]);
    for &(skip, shape) in nodes {
        b.node([-1.0; 3], [1.0; 3], skip, shape);
    }
    b.finish()
}

/// A 4 x 4 picture filled by one triangle whose material is texture 0 (`tex` = width,
/// height, texel offset) over `texels`, lit by ambient light only (so a pixel is its
/// texel's colour), stored as `storage`.
pub fn textured_image(storage: Storage, tex: (u32, u32, u32), texels: &[u8]) -> Vec<u8> {
    let mut b = SceneBuilder::new(storage);
    b.camera(4, 4, [-1.0, 1.0, 0.5, 0.5], 1.0)
        .material(MATTE_WHITE, 0)
        .texture(tex.0, tex.1, tex.2, texels)
        .triangle([-10.0, -10.0, 2.0, 10.0, -10.0, 2.0, 0.0, 10.0, 2.0])
        .node([-10.0, -10.0, 1.0], [10.0, 10.0, 3.0], 1, 0);
    b.finish()
}

#[cfg(feature = "std")]
/// A scene of `children` under a root cluster, seen by `camera` at `width` x `height`: one
/// default material, no textures or lights, black background, no ambient light, depth 5,
/// refractive transparency.
pub fn scene_desc(camera: Camera, width: u32, height: u32, children: Vec<Node>) -> SceneDesc {
    SceneDesc {
        camera,
        width,
        height,
        background: [0.0; 3],
        ambient: [0.0; 3],
        max_depth: 5,
        transparency: TransparencyMode::Refractive,
        materials: std::vec![Material::default()],
        textures: Vec::new(),
        lights: Vec::new(),
        root: Cluster {
            name: "root".into(),
            transform: Transform::default(),
            children,
        },
    }
}
