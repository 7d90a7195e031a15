//! The SceneImage's byte layout, defined once: the header, the section table and every
//! record's fields. The view reads through these offsets, the writer writes through them and
//! the Q16.16 rewrite converts each word by the [`Word`] kind given here.
//!
//! ## Header (version 3, all little-endian, every section 4-byte aligned)
//! ```text
//! offset size
//!  0     4    magic "LNK1"
//!  4     2    version (3)
//!  6     1    number format of stored scalars ([`Storage`]: 0 = f32, 1 = Q16.16)
//!  7     1    scale exponent k (i8; 0 for f32): stored lengths are view lengths * 2^k
//!  8     4    total length in bytes
//! 12     4    reserved (0)
//! 16   8*14   section table: (offset u32, record count u32) for each [`Section`]
//! 128   ...   sections, in table order
//! ```
//! ## Records
//! Each record has a module below (one per [`Section`]) with the byte offset of each field
//! within the record, its `SIZE` and its `WORDS` (the kind of each 4-byte word). `f` = stored
//! scalar (f32 or Q16.16), `u` = u32; `[3]` marks consecutive words (a vector). Indices that
//! may be absent hold [`NONE`].
//!
//! [`Storage`]: crate::num::Storage

pub const MAGIC: [u8; 4] = *b"LNK1";
pub const VERSION: u16 = 3;
/// "No index" marker.
pub const NONE: u32 = u32::MAX;
pub const HEADER_SIZE: usize = TABLE_AT + TABLE_ENTRY_SIZE * SECTION_COUNT;
/// Deepest recursion an image may ask for (each level is a call-stack frame on a node).
pub const MAX_DEPTH_LIMIT: u32 = 16;

/// Header field offsets (see the module doc).
pub const VERSION_AT: usize = 4;
pub const STORAGE_AT: usize = 6;
pub const SCALE_AT: usize = 7;
pub const LENGTH_AT: usize = 8;
pub const TABLE_AT: usize = 16;
/// One section-table entry: offset u32, then record count u32.
pub const TABLE_ENTRY_SIZE: usize = 8;

/// The sections of an image, in table order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Section {
    Camera = 0,
    Materials,
    Lights,
    Textures,
    Texels,
    Nodes,
    Triangles,
    Normals,
    Uvs,
    Ellipsoids,
    Boxes,
    BlobGroups,
    Balls,
    Rects,
}
pub const SECTION_COUNT: usize = 14;

impl Section {
    pub const ALL: [Section; SECTION_COUNT] = [
        Section::Camera,
        Section::Materials,
        Section::Lights,
        Section::Textures,
        Section::Texels,
        Section::Nodes,
        Section::Triangles,
        Section::Normals,
        Section::Uvs,
        Section::Ellipsoids,
        Section::Boxes,
        Section::BlobGroups,
        Section::Balls,
        Section::Rects,
    ];
    /// Bytes per record.
    pub const fn record_size(self) -> usize {
        match self {
            Section::Camera => camera::SIZE,
            Section::Materials => material::SIZE,
            Section::Lights => light::SIZE,
            Section::Textures => texture::SIZE,
            Section::Texels => 1,
            Section::Nodes => node::SIZE,
            Section::Triangles => triangle::SIZE,
            Section::Normals => normals::SIZE,
            Section::Uvs => uvs::SIZE,
            Section::Ellipsoids => ellipsoid::SIZE,
            Section::Boxes => boxshape::SIZE,
            Section::BlobGroups => blob_group::SIZE,
            Section::Balls => ball::SIZE,
            Section::Rects => rect::SIZE,
        }
    }
    /// The kind of each 4-byte word of a record (`None` for raw bytes: texels).
    pub const fn words(self) -> Option<&'static [Word]> {
        Some(match self {
            Section::Camera => &camera::WORDS,
            Section::Materials => &material::WORDS,
            Section::Lights => &light::WORDS,
            Section::Textures => &texture::WORDS,
            Section::Texels => return None,
            Section::Nodes => &node::WORDS,
            Section::Triangles => &triangle::WORDS,
            Section::Normals => &normals::WORDS,
            Section::Uvs => &uvs::WORDS,
            Section::Ellipsoids => &ellipsoid::WORDS,
            Section::Boxes => &boxshape::WORDS,
            Section::BlobGroups => &blob_group::WORDS,
            Section::Balls => &ball::WORDS,
            Section::Rects => &rect::WORDS,
        })
    }
    pub const fn name(self) -> &'static str {
        match self {
            Section::Camera => "camera",
            Section::Materials => "materials",
            Section::Lights => "lights",
            Section::Textures => "textures",
            Section::Texels => "texels",
            Section::Nodes => "nodes",
            Section::Triangles => "triangles",
            Section::Normals => "normals",
            Section::Uvs => "uvs",
            Section::Ellipsoids => "ellipsoids",
            Section::Boxes => "boxes",
            Section::BlobGroups => "blob groups",
            Section::Balls => "balls",
            Section::Rects => "screen rects",
        }
    }
}

/// What a 4-byte word of a record holds (the Q16.16 rewrite scales each kind its own way).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Word {
    /// An integer (count, index, flags, enum).
    U,
    /// A scale-free scalar (colour, coefficient, direction, unit-space value).
    P,
    /// A length.
    L,
    /// A bounding box's lower corner (a length; must round down).
    Lo,
    /// A bounding box's upper corner (a length; must round up).
    Hi,
    /// An inverse length (a view-to-unit-space matrix entry).
    I,
    /// A light colour (pre-multiplied when the light falls off with distance squared).
    C,
    /// A component of the primary directions (x0, y0, dx, dy, dz).
    D,
}

/// The camera: screen and global settings (record 0 of [`Section::Camera`]).
pub mod camera {
    use super::Word::{self, *};
    /// width u, height u (pixels).
    pub const WIDTH: usize = 0;
    pub const HEIGHT: usize = 4;
    /// x0 f, y0 f, dx f, dy f: pixel (x, y)'s direction is (x0 + (x + ½) dx, y0 - (y + ½) dy, dz).
    pub const X0: usize = 8;
    pub const Y0: usize = 12;
    pub const DX: usize = 16;
    pub const DY: usize = 20;
    /// background f[3], ambient f[3].
    pub const BACKGROUND: usize = 24;
    pub const AMBIENT: usize = 36;
    /// max_depth u.
    pub const MAX_DEPTH: usize = 48;
    /// flags u: [`NON_REFRACTIVE`] (transparency without refraction everywhere), [`NO_SHADOWS`].
    pub const FLAGS: usize = 52;
    /// dz f: the z of every primary direction (1 in f32 images; the fixed-point rewrite
    /// scales x0, y0, dx, dy and dz by one power of two so a pixel step keeps its precision).
    pub const DZ: usize = 56;
    pub const SIZE: usize = 4 * 15;
    pub const NON_REFRACTIVE: u32 = 1;
    pub const NO_SHADOWS: u32 = 2;
    pub const WORDS: [Word; SIZE / 4] = [U, U, D, D, D, D, P, P, P, P, P, P, U, U, D];
}

/// A material.
pub mod material {
    use super::Word::{self, *};
    /// diffuse f[3], specular f, specular_edge f, shininess f, reflect f, reflect_edge f.
    pub const DIFFUSE: usize = 0;
    pub const SPECULAR: usize = 12;
    pub const SPECULAR_EDGE: usize = 16;
    pub const SHININESS: usize = 20;
    pub const REFLECT: usize = 24;
    pub const REFLECT_EDGE: usize = 28;
    /// transmit f[3], ior f.
    pub const TRANSMIT: usize = 32;
    pub const IOR: usize = 44;
    /// texture u ([`super::NONE`] for none), target u (what the texture maps: 0 diffuse,
    /// 1 specular, 2 reflect, 3 transmit), scale f[2] (texture repeats per unit of uv).
    pub const TEXTURE: usize = 48;
    pub const TARGET: usize = 52;
    pub const SCALE: usize = 56;
    pub const SIZE: usize = 4 * 16;
    pub const WORDS: [Word; SIZE / 4] = [P, P, P, P, P, P, P, P, P, P, P, P, U, U, P, P];
}

/// A light.
pub mod light {
    use super::Word::{self, *};
    /// kind u (0 directional, 1 point, 2 spot), color f[3], pos f[3], dir f[3] (unit, the
    /// way the light travels), cos_inner f, cos_outer f, exponent f, falloff u (0 or 1).
    pub const KIND: usize = 0;
    pub const COLOR: usize = 4;
    pub const POS: usize = 16;
    pub const DIR: usize = 28;
    pub const COS_INNER: usize = 40;
    pub const COS_OUTER: usize = 44;
    pub const EXPONENT: usize = 48;
    pub const FALLOFF: usize = 52;
    pub const SIZE: usize = 4 * 14;
    pub const WORDS: [Word; SIZE / 4] = [U, C, C, C, L, L, L, P, P, P, P, P, P, U];
}

/// A texture's header; its texels are RGB8 rows in [`super::Section::Texels`].
pub mod texture {
    use super::Word::{self, *};
    /// width u, height u, texel offset u (byte offset into the texel section).
    pub const WIDTH: usize = 0;
    pub const HEIGHT: usize = 4;
    pub const TEXELS: usize = 8;
    pub const SIZE: usize = 4 * 3;
    pub const WORDS: [Word; SIZE / 4] = [U, U, U];
}

/// A node of the flat tree: a cluster (its subtree follows it) or a leaf holding one shape.
pub mod node {
    use super::Word::{self, *};
    /// aabb min f[3], max f[3].
    pub const MIN: usize = 0;
    pub const MAX: usize = 12;
    /// skip u: the index of the first node after this node's subtree.
    pub const SKIP: usize = 24;
    /// shape u: [`super::NONE`] for a cluster, else a [`super::ShapeRef`] (kind in the top
    /// 4 bits, index below).
    pub const SHAPE: usize = 28;
    pub const SIZE: usize = 4 * 8;
    pub const WORDS: [Word; SIZE / 4] = [Lo, Lo, Lo, Hi, Hi, Hi, U, U];
}

/// A triangle.
pub mod triangle {
    use super::Word::{self, *};
    /// p0 f[3], p1 f[3], p2 f[3] (the vertices, [`VERTEX_STRIDE`] apart).
    pub const P: usize = 0;
    pub const VERTEX_STRIDE: usize = 12;
    /// material u, normals u (record in Normals or NONE), uvs u (record in Uvs or NONE).
    pub const MATERIAL: usize = 36;
    pub const NORMALS: usize = 40;
    pub const UVS: usize = 44;
    pub const SIZE: usize = 4 * 12;
    pub const WORDS: [Word; SIZE / 4] = [L, L, L, L, L, L, L, L, L, U, U, U];
}

/// A triangle's vertex normals.
pub mod normals {
    use super::Word::{self, *};
    /// n0 f[3], n1 f[3], n2 f[3] (unit, view coordinates), [`STRIDE`] apart.
    pub const N: usize = 0;
    pub const STRIDE: usize = 12;
    pub const SIZE: usize = 4 * 9;
    pub const WORDS: [Word; SIZE / 4] = [P; SIZE / 4];
}

/// A triangle's vertex texture coordinates.
pub mod uvs {
    use super::Word::{self, *};
    /// uv0 f[2], uv1 f[2], uv2 f[2], [`STRIDE`] apart.
    pub const UV: usize = 0;
    pub const STRIDE: usize = 8;
    pub const SIZE: usize = 4 * 6;
    pub const WORDS: [Word; SIZE / 4] = [P; SIZE / 4];
}

/// An ellipsoid: the unit sphere under an affine map, optionally cut by a plane.
pub mod ellipsoid {
    use super::Word::{self, *};
    /// center f[3], m f[9] (view -> unit space, rows), l f[9] (unit -> view space, rows).
    pub const CENTER: usize = 0;
    pub const TO_UNIT: usize = 12;
    pub const TO_VIEW: usize = 48;
    /// material u, flags u ([`CUT`], [`CAPPED`]), cut n f[3], cut d f (unit space).
    pub const MATERIAL: usize = 84;
    pub const FLAGS: usize = 88;
    pub const CUT_N: usize = 92;
    pub const CUT_D: usize = 104;
    pub const SIZE: usize = 4 * 27;
    pub const CUT: u32 = 1;
    pub const CAPPED: u32 = 2;
    #[rustfmt::skip]
    pub const WORDS: [Word; SIZE / 4] = [
        L, L, L, I, I, I, I, I, I, I, I, I, L, L, L, L, L, L, L, L, L, U, U, P, P, P, P,
    ];
}

/// A box: the cube [-1, 1]^3 under an affine map; its fields are an ellipsoid's first ones,
/// at the same offsets (center, the two maps, material).
pub mod boxshape {
    pub use super::ellipsoid::{CENTER, MATERIAL, TO_UNIT, TO_VIEW};
    use super::Word;
    pub const SIZE: usize = MATERIAL + 4;
    pub const WORDS: [Word; SIZE / 4] = {
        let mut w = [Word::U; SIZE / 4];
        let mut k = 0;
        while k < w.len() {
            w[k] = super::ellipsoid::WORDS[k];
            k += 1;
        }
        w
    };
}

/// A group of density spheres (a blob) rendered as one surface.
pub mod blob_group {
    use super::Word::{self, *};
    /// material u, kernel u (0 LINKS, 1 Wyvill), threshold f, first ball u, ball count u.
    pub const MATERIAL: usize = 0;
    pub const KERNEL: usize = 4;
    pub const THRESHOLD: usize = 8;
    pub const FIRST: usize = 12;
    pub const COUNT: usize = 16;
    pub const SIZE: usize = 4 * 5;
    pub const WORDS: [Word; SIZE / 4] = [U, U, P, U, U];
}

/// One density sphere of a blob group.
pub mod ball {
    use super::Word::{self, *};
    /// center f[3], radius f, strength f.
    pub const CENTER: usize = 0;
    pub const RADIUS: usize = 12;
    pub const STRENGTH: usize = 16;
    pub const SIZE: usize = 4 * 5;
    pub const WORDS: [Word; SIZE / 4] = [L, L, L, L, P];
}

/// Screen rectangle of a node (LINKS-1 4.4), parallel to the node list: inclusive pixel
/// ranges, empty when lo > hi. The primary ray of pixel (x, y) can only hit shapes below a
/// node if the node's rectangle contains (x, y).
pub mod rect {
    use super::Word::{self, *};
    /// x_lo u16, x_hi u16, y_lo u16, y_hi u16.
    pub const X_LO: usize = 0;
    pub const X_HI: usize = 2;
    pub const Y_LO: usize = 4;
    pub const Y_HI: usize = 6;
    pub const SIZE: usize = 8;
    pub const WORDS: [Word; SIZE / 4] = [U, U];
}

pub const CAMERA_SIZE: usize = camera::SIZE;
pub const MATERIAL_SIZE: usize = material::SIZE;
pub const LIGHT_SIZE: usize = light::SIZE;
pub const TEXTURE_SIZE: usize = texture::SIZE;
pub const NODE_SIZE: usize = node::SIZE;
pub const TRIANGLE_SIZE: usize = triangle::SIZE;
pub const NORMALS_SIZE: usize = normals::SIZE;
pub const UVS_SIZE: usize = uvs::SIZE;
pub const ELLIPSOID_SIZE: usize = ellipsoid::SIZE;
pub const BOX_SIZE: usize = boxshape::SIZE;
pub const BLOB_GROUP_SIZE: usize = blob_group::SIZE;
pub const BALL_SIZE: usize = ball::SIZE;
pub const RECT_SIZE: usize = rect::SIZE;

/// A node's screen rectangle, inclusive pixel ranges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Rect {
    pub x_lo: u16,
    pub x_hi: u16,
    pub y_lo: u16,
    pub y_hi: u16,
}

impl Rect {
    pub const EMPTY: Rect = Rect {
        x_lo: 1,
        x_hi: 0,
        y_lo: 1,
        y_hi: 0,
    };
    #[inline]
    pub fn contains_row(&self, y: u16) -> bool {
        self.y_lo <= y && y <= self.y_hi
    }
    #[inline]
    pub fn contains_column(&self, x: u16) -> bool {
        self.x_lo <= x && x <= self.x_hi
    }
    pub fn is_empty(&self) -> bool {
        self.x_lo > self.x_hi || self.y_lo > self.y_hi
    }
    pub fn union(self, o: Rect) -> Rect {
        if self.is_empty() {
            return o;
        }
        if o.is_empty() {
            return self;
        }
        Rect {
            x_lo: self.x_lo.min(o.x_lo),
            x_hi: self.x_hi.max(o.x_hi),
            y_lo: self.y_lo.min(o.y_lo),
            y_hi: self.y_hi.max(o.y_hi),
        }
    }
}

/// Shape kinds as stored in a node's shape word.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShapeKind {
    Triangle = 0,
    Ellipsoid = 1,
    Box = 2,
    Blob = 3,
}

/// A reference to one shape: kind and index into that kind's section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShapeRef {
    pub kind: ShapeKind,
    pub index: u32,
}

impl ShapeRef {
    pub const INDEX_BITS: u32 = 28;
    pub fn encode(self) -> u32 {
        ((self.kind as u32) << Self::INDEX_BITS) | self.index
    }
    pub fn decode(w: u32) -> Option<Self> {
        let kind = match w >> Self::INDEX_BITS {
            0 => ShapeKind::Triangle,
            1 => ShapeKind::Ellipsoid,
            2 => ShapeKind::Box,
            3 => ShapeKind::Blob,
            _ => return None,
        };
        Some(Self {
            kind,
            index: w & ((1 << Self::INDEX_BITS) - 1),
        })
    }
}
