//! The SceneImage's byte layout, defined once: the header, the section table and every
//! record's fields. The view reads through these offsets, the writer writes through them and
//! the Q16.16 rewrite converts each word by the [`Word`] kind given here.
//!
//! ## Header (version 4, all little-endian, every section 4-byte aligned)
//! ```text
//! offset size
//!  0     4    magic "LNK1"
//!  4     2    version (4)
//!  6     1    number format of stored scalars ([`Storage`]: 0 = f32, 1 = Q16.16)
//!  7     1    scale exponent k (i8; 0 for f32): stored lengths are view lengths * 2^k
//!  8     4    total length in bytes
//! 12     4    reserved (0)
//! 16   8*17   section table: (offset u32, record count u32) for each [`Section`]
//! 152   ...   sections, in table order
//! ```
//! ## Records
//! Each record has a module below (one per [`Section`]) with the byte offset of each field
//! within the record, its `SIZE` and, for records holding stored scalars, its `WORDS` (the
//! kind of each 4-byte word). `f` = stored scalar (f32 or Q16.16), `u` = u32, `h` = u16,
//! `b` = u8; `[3]` marks consecutive fields (a vector). Indices that may be absent hold
//! [`NONE`] (u32) or [`NONE16`] (u16).
//!
//! ## What makes it compact
//! - Meshes are indexed: a vertex position or normal shared by many triangles is stored
//!   once, and a triangle is three u16 vertex indices plus one u16 index of its normal
//!   triple ([`NONE16`] for a flat triangle, which needs none). Normals are three i16.
//! - A leaf of the tree holds a range of up to [`node::MAX_LEAF`] primitives of one kind;
//!   no node has a single child.
//! - Node boxes are i16 grid coordinates on a power-of-two grid over the root box
//!   ([`camera::GRID_ORIGIN`], [`camera::GRID_STEP`]), rounded outward: `origin + q * step`
//!   is exact in f32, f64 and Q16.16 alike, so every backend decodes the same box and no
//!   hit is lost.
//! - Screen rectangles are u8 in units of 2^[`camera::RECT_SHIFT`] pixels, rounded outward.
//! - A texture of at most 256 colours stores a palette and one byte per texel.
//!
//! Indices are u16, so an image holds at most 65,535 records of a kind: a node bank
//! (at most [`crate::wire::MAX_SCENE`] bytes) could never hold that many vertices anyway.
//!
//! [`Storage`]: crate::num::Storage

pub const MAGIC: [u8; 4] = *b"LNK1";
pub const VERSION: u16 = 4;
/// "No index" marker.
pub const NONE: u32 = u32::MAX;
/// "No index" marker of a u16 index.
pub const NONE16: u16 = u16::MAX;
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
    Vertices,
    Normals,
    Triangles,
    TriNormals,
    TriUvs,
    Uvs,
    Ellipsoids,
    Boxes,
    BlobGroups,
    Balls,
    Rects,
}
pub const SECTION_COUNT: usize = 17;

impl Section {
    pub const ALL: [Section; SECTION_COUNT] = [
        Section::Camera,
        Section::Materials,
        Section::Lights,
        Section::Textures,
        Section::Texels,
        Section::Nodes,
        Section::Vertices,
        Section::Normals,
        Section::Triangles,
        Section::TriNormals,
        Section::TriUvs,
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
            Section::Vertices => vertex::SIZE,
            Section::Normals => normal::SIZE,
            Section::Triangles => triangle::SIZE,
            Section::TriNormals | Section::TriUvs => corners::SIZE,
            Section::Uvs => uv::SIZE,
            Section::Ellipsoids => ellipsoid::SIZE,
            Section::Boxes => boxshape::SIZE,
            Section::BlobGroups => blob_group::SIZE,
            Section::Balls => ball::SIZE,
            Section::Rects => rect::SIZE,
        }
    }
    /// The kind of each 4-byte word of a record holding stored scalars (`None` for records
    /// of integers and raw bytes: texels, nodes, normals, triangles, corners, rectangles).
    pub const fn words(self) -> Option<&'static [Word]> {
        Some(match self {
            Section::Camera => &camera::WORDS,
            Section::Materials => &material::WORDS,
            Section::Lights => &light::WORDS,
            Section::Textures => &texture::WORDS,
            Section::Vertices => &vertex::WORDS,
            Section::Uvs => &uv::WORDS,
            Section::Ellipsoids => &ellipsoid::WORDS,
            Section::Boxes => &boxshape::WORDS,
            Section::BlobGroups => &blob_group::WORDS,
            Section::Balls => &ball::WORDS,
            Section::Texels
            | Section::Nodes
            | Section::Normals
            | Section::Triangles
            | Section::TriNormals
            | Section::TriUvs
            | Section::Rects => return None,
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
            Section::Vertices => "vertices",
            Section::Normals => "normals",
            Section::Triangles => "triangles",
            Section::TriNormals => "triangle normals",
            Section::TriUvs => "triangle uvs",
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
    /// A component of the primary directions (x0, y0, dz).
    D,
    /// A pixel step of the primary directions (dx, dy): scaled as [`Word::D`], and in a
    /// Q16.16 image by 2^[`camera::STEP_BITS`] more.
    S,
    /// The node grid's step: a power-of-two length that must stay exact.
    G,
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
    /// flags u: [`NON_REFRACTIVE`] (transparency without refraction everywhere),
    /// [`NO_SHADOWS`]; bits [`AA_SHIFT`].. hold the anti-aliasing grid side N minus one
    /// (0 = one sample per pixel, up to [`MAX_AA`] - 1: N x N sub-pixel samples).
    pub const FLAGS: usize = 52;
    /// Extra fraction bits of dx and dy in a Q16.16 image: they hold 2^STEP_BITS times the
    /// scaled step. A step of 0.1 stored as plain Q16.16 is off by up to half a step
    /// (7.6e-6), which the far column of a 256-pixel row multiplies by 256: its ray turned
    /// by up to 6e-5 rad, 2% of a pixel, enough to move tile edges seen through glass.
    /// A row is at most 64 wide after the direction scale (|x0| and |x0 + width dx| are
    /// both at most 32), so `(x + ½) dx` stays below 2^14 in the finer units.
    pub const STEP_BITS: u32 = 8;
    /// dz f: the z of every primary direction (1 in f32 images; the fixed-point rewrite
    /// scales x0, y0, dx, dy and dz by one power of two so a pixel step keeps its precision).
    pub const DZ: usize = 56;
    /// grid origin f[3], grid step f[3] (powers of two; origin a multiple of step): node
    /// box corner q (i16) lies at origin + q * step on each axis.
    pub const GRID_ORIGIN: usize = 60;
    pub const GRID_STEP: usize = 72;
    /// rect shift u: screen rectangles are stored in units of 2^shift pixels (0..=8).
    pub const RECT_SHIFT: usize = 84;
    pub const SIZE: usize = 4 * 22;
    pub const NON_REFRACTIVE: u32 = 1;
    pub const NO_SHADOWS: u32 = 2;
    pub const MAX_RECT_SHIFT: u32 = 8;
    pub const AA_SHIFT: u32 = 8;
    pub const AA_MASK: u32 = 0xff << AA_SHIFT;
    /// Largest anti-aliasing grid side (N x N samples per pixel).
    pub const MAX_AA: u32 = 8;
    /// Every flag bit a valid camera may set.
    pub const KNOWN_FLAGS: u32 = NON_REFRACTIVE | NO_SHADOWS | AA_MASK;
    #[rustfmt::skip]
    pub const WORDS: [Word; SIZE / 4] = [
        U, U, D, D, S, S, P, P, P, P, P, P, U, U, D, Lo, Lo, Lo, G, G, G, U,
    ];
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
    /// texture u ([`super::NONE`] for none), target b (what the texture maps: 0 diffuse,
    /// 1 specular, 2 reflect, 3 transmit), flags b ([`OWN_AMBIENT`]), ambient h (see
    /// below), scale f[2] (texture repeats per unit of uv).
    pub const TEXTURE: usize = 48;
    pub const TARGET: usize = 52;
    pub const FLAGS: usize = 53;
    pub const AMBIENT: usize = 54;
    pub const SCALE: usize = 56;
    pub const SIZE: usize = 4 * 16;
    /// The material has its own ambient reflection colour (`arc`, used instead of the
    /// diffuse colour in eq. 2.1's ambient term): the first three words ([`DIFFUSE`]) of
    /// Materials record `ambient`, an *ambient record* written after every material (its
    /// other fields zero, its texture [`super::NONE`]). Without the flag `ambient` is 0 and
    /// the ambient term uses the diffuse colour, so a scene that gives no material an
    /// ambient colour has exactly the bytes it had before the field existed.
    pub const OWN_AMBIENT: u8 = 1;
    /// The highest target value (3, transmit).
    pub const MAX_TARGET: u8 = 3;
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

/// A texture's header; its texels are rows in [`super::Section::Texels`]: RGB8, or (with a
/// palette) the palette's RGB8 colours followed by one palette index per texel.
pub mod texture {
    use super::Word::{self, *};
    /// width u, height u, texel offset u (byte offset into the texel section), palette u
    /// (number of palette colours, 1..=256; 0 = RGB8 texels).
    pub const WIDTH: usize = 0;
    pub const HEIGHT: usize = 4;
    pub const TEXELS: usize = 8;
    pub const PALETTE: usize = 12;
    pub const SIZE: usize = 4 * 4;
    pub const MAX_PALETTE: u32 = 256;
    pub const WORDS: [Word; SIZE / 4] = [U, U, U, U];
}

/// A node of the flat tree: a cluster (its subtree follows it) or a leaf holding a range of
/// primitives of one kind.
pub mod node {
    /// box lo h[3], hi h[3]: i16 grid coordinates (see [`super::camera::GRID_ORIGIN`]).
    pub const LO: usize = 0;
    pub const HI: usize = 6;
    /// index h: a cluster's skip (the first node after its subtree); a leaf's first
    /// primitive (a record of the section of its kind).
    pub const INDEX: usize = 12;
    /// info b: 0 for a cluster; for a leaf (1 + [`super::ShapeKind`]) << 5 | count (1..=31).
    pub const INFO: usize = 14;
    /// material b: the material of a triangle leaf's triangles (0 for other nodes).
    pub const MATERIAL: usize = 15;
    pub const SIZE: usize = 16;
    pub const MAX_LEAF: u32 = 31;
    pub const KIND_SHIFT: u32 = 5;
    pub const COUNT_MASK: u8 = 31;
}

/// A mesh vertex position (view coordinates).
pub mod vertex {
    use super::Word::{self, *};
    /// p f[3].
    pub const P: usize = 0;
    pub const SIZE: usize = 12;
    pub const WORDS: [Word; SIZE / 4] = [L, L, L];
}

/// A unit vertex normal (view coordinates), compressed: each component an i16, the unit
/// vector times [`SCALE`] rounded (an angle error below 0.003 degrees; the tracer normalises
/// the interpolated normal, so the common scale drops out).
pub mod normal {
    /// n h[3] (i16).
    pub const N: usize = 0;
    pub const SIZE: usize = 6;
    pub const SCALE: f64 = 32767.0;
}

/// A triangle: its vertices, and its normals when it is not flat (its material is its
/// leaf's).
pub mod triangle {
    /// v h[3] (records of Vertices), normals h (record of TriNormals or [`super::NONE16`]).
    pub const V: usize = 0;
    pub const NORMALS: usize = 6;
    pub const SIZE: usize = 8;
}

/// Three u16 indices, one per corner of a triangle: a TriNormals record indexes Normals; a
/// TriUvs record (parallel to Triangles, [`super::NONE16`] for a triangle without uvs)
/// indexes Uvs.
pub mod corners {
    pub const I: usize = 0;
    pub const SIZE: usize = 6;
}

/// A texture coordinate pair.
pub mod uv {
    use super::Word::{self, *};
    /// uv f[2].
    pub const UV: usize = 0;
    pub const SIZE: usize = 8;
    pub const WORDS: [Word; SIZE / 4] = [P, P];
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

/// Screen rectangle of a node (LINKS-1 4.4), parallel to the node list: inclusive ranges in
/// units of 2^shift pixels ([`super::camera::RECT_SHIFT`]), rounded outward; empty when
/// lo > hi. The primary ray of pixel (x, y) can only hit shapes below a node if the node's
/// rectangle contains (x, y).
pub mod rect {
    /// x_lo b, x_hi b, y_lo b, y_hi b.
    pub const X_LO: usize = 0;
    pub const X_HI: usize = 1;
    pub const Y_LO: usize = 2;
    pub const Y_HI: usize = 3;
    pub const SIZE: usize = 4;
}

pub const CAMERA_SIZE: usize = camera::SIZE;
pub const MATERIAL_SIZE: usize = material::SIZE;
pub const LIGHT_SIZE: usize = light::SIZE;
pub const TEXTURE_SIZE: usize = texture::SIZE;
pub const NODE_SIZE: usize = node::SIZE;
pub const VERTEX_SIZE: usize = vertex::SIZE;
pub const NORMAL_SIZE: usize = normal::SIZE;
pub const TRIANGLE_SIZE: usize = triangle::SIZE;
pub const CORNERS_SIZE: usize = corners::SIZE;
pub const UV_SIZE: usize = uv::SIZE;
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

/// Shape kinds, as a leaf stores them (see [`node::INFO`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShapeKind {
    Triangle = 0,
    Ellipsoid = 1,
    Box = 2,
    Blob = 3,
}

impl ShapeKind {
    pub const fn from_u8(k: u8) -> Option<Self> {
        Some(match k {
            0 => ShapeKind::Triangle,
            1 => ShapeKind::Ellipsoid,
            2 => ShapeKind::Box,
            3 => ShapeKind::Blob,
            _ => return None,
        })
    }
    /// The section holding this kind's records.
    pub const fn section(self) -> Section {
        match self {
            ShapeKind::Triangle => Section::Triangles,
            ShapeKind::Ellipsoid => Section::Ellipsoids,
            ShapeKind::Box => Section::Boxes,
            ShapeKind::Blob => Section::BlobGroups,
        }
    }
}

/// A reference to one shape: kind and index into that kind's section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShapeRef {
    pub kind: ShapeKind,
    pub index: u32,
}

/// A leaf's range of primitives: `count` records of `kind` from `first`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Leaf {
    pub kind: ShapeKind,
    pub first: u32,
    pub count: u32,
    /// The triangles' material (triangle leaves; 0 otherwise).
    pub material: u32,
}

impl Leaf {
    /// The info byte of [`node::INFO`].
    pub const fn info(&self) -> u8 {
        ((self.kind as u8 + 1) << node::KIND_SHIFT) | self.count as u8
    }
    /// The leaf an info byte describes (`None` for a cluster or an unknown kind).
    #[inline]
    pub const fn decode(info: u8, first: u16, material: u8) -> Option<Self> {
        let kind = info >> node::KIND_SHIFT;
        if kind == 0 {
            return None;
        }
        match ShapeKind::from_u8(kind - 1) {
            Some(kind) => Some(Leaf {
                kind,
                first: first as u32,
                count: (info & node::COUNT_MASK) as u32,
                material: material as u32,
            }),
            None => None,
        }
    }
    /// The `k`-th shape of the range.
    #[inline]
    pub const fn shape(&self, k: u32) -> ShapeRef {
        ShapeRef {
            kind: self.kind,
            index: self.first + k,
        }
    }
}
