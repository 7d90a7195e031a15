//! The SceneImage: one contiguous, versioned byte image of a compiled scene.
//!
//! The DM writes it once; a node receives it over the link into a bank and renders straight
//! from those bytes through [`SceneView`]: nothing is copied or allocated, each record is
//! decoded into registers when it is used. Only sections the scene uses take space.
//!
//! ## Layout (version 3, all little-endian, every section 4-byte aligned)
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
//! Record layouts are given on each `*_SIZE` constant below; `f` = stored scalar (f32),
//! `u` = u32. Indices that may be absent use [`NONE`].

use crate::geom::{Aabb, Mat3, Vec3};
use crate::num::{Real, Storage};
use crate::shape::boxshape::BoxShape;
use crate::shape::ellipsoid::{CutPlane, Ellipsoid};
use crate::shape::triangle::Triangle;
use core::fmt;

#[cfg(any(test, feature = "std"))]
pub mod fixed;

pub const MAGIC: [u8; 4] = *b"LNK1";
pub const VERSION: u16 = 3;
/// "No index" marker.
pub const NONE: u32 = u32::MAX;
pub const HEADER_SIZE: usize = 16 + 8 * SECTION_COUNT;
/// Deepest recursion an image may ask for (each level is a stack frame on a node).
pub const MAX_DEPTH_LIMIT: u32 = 16;

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
            Section::Camera => CAMERA_SIZE,
            Section::Materials => MATERIAL_SIZE,
            Section::Lights => LIGHT_SIZE,
            Section::Textures => TEXTURE_SIZE,
            Section::Texels => 1,
            Section::Nodes => NODE_SIZE,
            Section::Triangles => TRIANGLE_SIZE,
            Section::Normals => NORMALS_SIZE,
            Section::Uvs => UVS_SIZE,
            Section::Ellipsoids => ELLIPSOID_SIZE,
            Section::Boxes => BOX_SIZE,
            Section::BlobGroups => BLOB_GROUP_SIZE,
            Section::Balls => BALL_SIZE,
            Section::Rects => RECT_SIZE,
        }
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

/// width u, height u, x0 f, y0 f, dx f, dy f, background f[3], ambient f[3], max_depth u,
/// flags u (bit 0: non-refractive transparency everywhere; bit 1: no shadows), dz f (the z
/// of every primary direction: 1 in f32 images; the fixed-point DM scales x0, y0, dx, dy and
/// dz by one power of two so a pixel step keeps its precision).
pub const CAMERA_SIZE: usize = 4 * 15;
/// diffuse f[3], specular f, specular_edge f, shininess f, reflect f, reflect_edge f,
/// transmit f[3], ior f, texture u, target u, scale f[2].
pub const MATERIAL_SIZE: usize = 4 * 16;
/// kind u, color f[3], pos f[3], dir f[3], cos_inner f, cos_outer f, exponent f, falloff u.
pub const LIGHT_SIZE: usize = 4 * 14;
/// width u, height u, texel offset u (byte offset into the texel section, RGB8 rows).
pub const TEXTURE_SIZE: usize = 4 * 3;
/// aabb min f[3], max f[3], skip u (index after this node's subtree), shape u ([`NONE`] for
/// a cluster; else kind in the top 4 bits, index below).
pub const NODE_SIZE: usize = 4 * 8;
/// p0 f[3], p1 f[3], p2 f[3], material u, normals u, uvs u.
pub const TRIANGLE_SIZE: usize = 4 * 12;
/// n0 f[3], n1 f[3], n2 f[3] (unit, view coordinates).
pub const NORMALS_SIZE: usize = 4 * 9;
/// uv0 f[2], uv1 f[2], uv2 f[2].
pub const UVS_SIZE: usize = 4 * 6;
/// center f[3], m f[9], l f[9], material u, flags u (bit 0 cut, bit 1 capped), cut n f[3],
/// cut d f.
pub const ELLIPSOID_SIZE: usize = 4 * 27;
/// center f[3], m f[9], l f[9], material u.
pub const BOX_SIZE: usize = 4 * 22;
/// material u, kernel u (0 LINKS, 1 Wyvill), threshold f, first ball u, ball count u.
pub const BLOB_GROUP_SIZE: usize = 4 * 5;
/// center f[3], radius f, strength f.
pub const BALL_SIZE: usize = 4 * 5;
/// Screen rectangle of a node (LINKS-1 4.4), parallel to the node list: x_lo u16, x_hi u16,
/// y_lo u16, y_hi u16 (inclusive pixel ranges; empty when lo > hi). The primary ray of pixel
/// (x, y) can only hit shapes below a node if the node's rectangle contains (x, y).
pub const RECT_SIZE: usize = 8;

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

/// Why bytes are not a usable SceneImage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImageError {
    TooShort {
        len: u32,
    },
    BadMagic,
    UnsupportedVersion {
        found: u16,
    },
    UnsupportedFormat {
        found: u8,
    },
    LengthMismatch {
        header: u32,
        actual: u32,
    },
    SectionOutOfBounds {
        section: u8,
    },
    Misaligned {
        section: u8,
    },
    MissingCamera,
    BadReference {
        section: u8,
        record: u32,
    },
    BadValue {
        section: u8,
        record: u32,
    },
    /// The image stores scalars in another format than the number type reads.
    WrongNumberType {
        image: Storage,
        wanted: Storage,
    },
}

impl fmt::Display for ImageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = |s: u8| Section::ALL.get(s as usize).map_or("?", |s| s.name());
        match *self {
            ImageError::TooShort { len } => write!(f, "scene image too short ({len} bytes)"),
            ImageError::BadMagic => write!(f, "not a scene image (bad magic)"),
            ImageError::UnsupportedVersion { found } => {
                write!(
                    f,
                    "scene image version {found} not supported (expected {VERSION})"
                )
            }
            ImageError::UnsupportedFormat { found } => {
                write!(f, "scene image number format {found} not supported")
            }
            ImageError::LengthMismatch { header, actual } => {
                write!(f, "scene image says {header} bytes but {actual} were given")
            }
            ImageError::SectionOutOfBounds { section } => {
                write!(f, "section '{}' lies outside the image", name(section))
            }
            ImageError::Misaligned { section } => {
                write!(f, "section '{}' is not 4-byte aligned", name(section))
            }
            ImageError::MissingCamera => write!(f, "scene image has no camera record"),
            ImageError::BadReference { section, record } => {
                write!(
                    f,
                    "{} record {record} refers to a missing record",
                    name(section)
                )
            }
            ImageError::BadValue { section, record } => {
                write!(
                    f,
                    "{} record {record} holds an invalid value",
                    name(section)
                )
            }
            ImageError::WrongNumberType { image, wanted } => write!(
                f,
                "scene image stores {} scalars but the renderer reads {} (compile the scene \
                 for the backend's format)",
                image.name(),
                wanted.name()
            ),
        }
    }
}

impl core::error::Error for ImageError {}

/// Screen and global settings.
#[derive(Clone, Copy, Debug)]
pub struct Camera<T> {
    pub width: u32,
    pub height: u32,
    /// Direction to pixel (x, y)'s centre: (x0 + (x + ½) dx, y0 - (y + ½) dy, dz).
    pub x0: T,
    pub y0: T,
    pub dx: T,
    pub dy: T,
    pub dz: T,
    pub background: Vec3<T>,
    pub ambient: Vec3<T>,
    pub max_depth: u32,
    pub non_refractive: bool,
    /// No shadow rays: every light reaches every surface facing it.
    pub no_shadows: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapTarget {
    Diffuse = 0,
    Specular = 1,
    Reflect = 2,
    Transmit = 3,
}

#[derive(Clone, Copy, Debug)]
pub struct Material<T> {
    pub diffuse: Vec3<T>,
    pub specular: T,
    pub specular_edge: T,
    pub shininess: T,
    pub reflect: T,
    pub reflect_edge: T,
    pub transmit: Vec3<T>,
    pub ior: T,
    pub texture: u32,
    pub target: MapTarget,
    pub scale: [T; 2],
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightKind {
    Directional = 0,
    Point = 1,
    Spot = 2,
}

#[derive(Clone, Copy, Debug)]
pub struct Light<T> {
    pub kind: LightKind,
    pub color: Vec3<T>,
    pub pos: Vec3<T>,
    /// Unit direction the light travels (directional, spot axis).
    pub dir: Vec3<T>,
    pub cos_inner: T,
    pub cos_outer: T,
    pub exponent: T,
    pub falloff: bool,
}

#[derive(Clone, Copy, Debug)]
pub struct TextureView<'a> {
    pub width: u32,
    pub height: u32,
    pub rgb: &'a [u8],
}

#[derive(Clone, Copy, Debug)]
pub struct Node<T> {
    pub bounds: Aabb<T>,
    pub skip: u32,
    pub shape: Option<ShapeRef>,
}

#[derive(Clone, Copy, Debug)]
pub struct TriangleRec<T> {
    pub tri: Triangle<T>,
    pub material: u32,
    pub normals: u32,
    pub uvs: u32,
}

#[derive(Clone, Copy, Debug)]
pub struct EllipsoidRec<T> {
    pub shape: Ellipsoid<T>,
    pub material: u32,
}

#[derive(Clone, Copy, Debug)]
pub struct BoxRec<T> {
    pub shape: BoxShape<T>,
    pub material: u32,
}

#[derive(Clone, Copy, Debug)]
pub struct BlobGroupRec<T> {
    pub material: u32,
    pub kernel: crate::shape::blob::Kernel,
    pub threshold: T,
    pub first: u32,
    pub count: u32,
}

/// A validated, zero-copy view of a SceneImage.
#[derive(Clone, Copy, Debug)]
pub struct SceneView<'a> {
    bytes: &'a [u8],
    table: [(u32, u32); SECTION_COUNT],
    /// Each section's records (exactly count x record size bytes), so that fetching record
    /// `i` is one compare of `i` against the count.
    sections: Sections<'a>,
    storage: Storage,
}

#[derive(Clone, Copy)]
struct Sections<'a>([&'a [u8]; SECTION_COUNT]);

impl core::fmt::Debug for Sections<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_list()
            .entries(self.0.iter().map(|s| s.len()))
            .finish()
    }
}

/// A little-endian u32 at `at`, or 0 outside `b` (never the case in a validated image).
#[inline(always)]
fn rd_u32(b: &[u8], at: usize) -> u32 {
    // `get(at..)` then the first 4 bytes: one compare each, no overflow check of `at + 4`.
    match b.get(at..).and_then(|r| r.first_chunk::<4>()) {
        Some(&w) => u32::from_le_bytes(w),
        None => 0,
    }
}

/// The texel bytes `start..end` (within the texel section) of a `w` x `h` texture at
/// offset `off`: `None` for an empty texture or when any step of `off + w * h * 3` leaves
/// u32 (so a 32-bit usize holds every bound and `w`, `h` < 2^31).
fn texel_range(w: u32, h: u32, off: u32) -> Option<(u32, u32)> {
    if w == 0 || h == 0 {
        return None;
    }
    let end = w.checked_mul(h)?.checked_mul(3)?.checked_add(off)?;
    Some((off, end))
}

/// Zeros standing in for a record outside its section (at least the largest record).
static ZERO_RECORD: [u8; 128] = [0; 128];

/// One fixed-size record, borrowed in place after a single bounds check so the field reads
/// below compile to plain loads (reading fields byte by byte with a check each cost ~240
/// instructions per node on a Cortex-M4F, measured under QEMU; a copy of the record ~40;
/// in place the loads alone).
struct Record<'b, const N: usize>(&'b [u8; N]);

impl<const N: usize> Record<'_, N> {
    #[inline(always)]
    fn u(&self, o: usize) -> u32 {
        let r = &self.0;
        u32::from_le_bytes([r[o], r[o + 1], r[o + 2], r[o + 3]])
    }
    #[inline(always)]
    fn f<T: Real>(&self, o: usize) -> T {
        T::from_stored(self.u(o))
    }
    #[inline(always)]
    fn v3<T: Real>(&self, o: usize) -> Vec3<T> {
        Vec3::new(self.f(o), self.f(o + 4), self.f(o + 8))
    }
    #[inline(always)]
    fn m3<T: Real>(&self, o: usize) -> Mat3<T> {
        Mat3 {
            r: [self.v3(o), self.v3(o + 12), self.v3(o + 24)],
        }
    }
}

impl<'a> SceneView<'a> {
    /// Check the header, every section's bounds and every cross-reference, so that the
    /// accessors below can never index out of range.
    pub fn new(bytes: &'a [u8]) -> Result<Self, ImageError> {
        if bytes.len() < HEADER_SIZE {
            return Err(ImageError::TooShort {
                len: bytes.len() as u32,
            });
        }
        if bytes[0..4] != MAGIC {
            return Err(ImageError::BadMagic);
        }
        let version = u16::from_le_bytes([bytes[4], bytes[5]]);
        if version != VERSION {
            return Err(ImageError::UnsupportedVersion { found: version });
        }
        let Some(storage) = Storage::from_u8(bytes[6]) else {
            return Err(ImageError::UnsupportedFormat { found: bytes[6] });
        };
        if storage == Storage::F32 && bytes[7] != 0 {
            return Err(ImageError::UnsupportedFormat { found: bytes[6] });
        }
        let total = rd_u32(bytes, 8);
        if usize::try_from(total).ok() != Some(bytes.len()) {
            return Err(ImageError::LengthMismatch {
                header: total,
                actual: u32::try_from(bytes.len()).unwrap_or(u32::MAX),
            });
        }
        let mut table = [(0u32, 0u32); SECTION_COUNT];
        let mut sections: [&[u8]; SECTION_COUNT] = [&[]; SECTION_COUNT];
        for (i, s) in Section::ALL.iter().enumerate() {
            let off = rd_u32(bytes, 16 + 8 * i);
            let count = rd_u32(bytes, 20 + 8 * i);
            if !off.is_multiple_of(4) {
                return Err(ImageError::Misaligned { section: i as u8 });
            }
            if count > 0 {
                // Every size in u32 (the image is at most u32::MAX bytes long), checked: the
                // section's bytes, then a slice that exists (so a 32-bit usize holds it too).
                let out = ImageError::SectionOutOfBounds { section: i as u8 };
                let end = (s.record_size() as u32)
                    .checked_mul(count)
                    .and_then(|size| off.checked_add(size))
                    .ok_or(out)?;
                if (off as usize) < HEADER_SIZE {
                    return Err(out);
                }
                sections[i] = bytes.get(off as usize..end as usize).ok_or(out)?;
            }
            table[i] = (off, count);
        }
        let view = Self {
            bytes,
            table,
            sections: Sections(sections),
            storage,
        };
        view.check_references()?;
        Ok(view)
    }

    /// Unit round-off of the stored scalars: error bounds of quantities the DM rounded
    /// separately (a matrix and its inverse) are multiples of it. For Q16.16 it is one step
    /// relative to 1 (the DM scales a scene so its coordinates are well above 1).
    pub fn storage_epsilon<T: Real>(&self) -> T {
        match self.storage {
            Storage::F32 => T::from_f32(f32::EPSILON * 0.5),
            Storage::Q16_16 => T::from_f32(1.0 / 65536.0),
        }
    }

    /// How this image stores its scalars.
    pub fn storage(&self) -> Storage {
        self.storage
    }

    /// The power of two the DM scaled the scene's lengths by (0 for f32 images): a length
    /// in the image is the view-space length times 2^scale_exponent.
    pub fn scale_exponent(&self) -> i8 {
        self.bytes[7] as i8
    }

    /// Whether number type `T` reads this image's scalars: an image is rendered by the
    /// backends of its own storage format only.
    pub fn check_storage<T: Real>(&self) -> Result<(), ImageError> {
        if T::STORAGE == self.storage {
            Ok(())
        } else {
            Err(ImageError::WrongNumberType {
                image: self.storage,
                wanted: T::STORAGE,
            })
        }
    }

    /// The raw bytes (for sending over the link).
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Number of records in a section.
    pub fn count(&self, s: Section) -> u32 {
        self.table[s as usize].1
    }

    /// Bytes a section occupies.
    pub fn section_bytes(&self, s: Section) -> usize {
        self.sections.0[s as usize].len()
    }

    fn check_references(&self) -> Result<(), ImageError> {
        let bad = |s: Section, i: u32| ImageError::BadReference {
            section: s as u8,
            record: i,
        };
        let badv = |s: Section, i: u32| ImageError::BadValue {
            section: s as u8,
            record: i,
        };
        if self.count(Section::Camera) != 1 {
            return Err(ImageError::MissingCamera);
        }
        let camera = self.camera::<f32>();
        // Pixel coordinates are u16 in screen rectangles and clipping.
        let side = 1..=u16::MAX as u32;
        if camera.max_depth > MAX_DEPTH_LIMIT
            || !side.contains(&camera.width)
            || !side.contains(&camera.height)
        {
            return Err(badv(Section::Camera, 0));
        }
        let nmat = self.count(Section::Materials);
        let ntex = self.count(Section::Textures);
        for i in 0..nmat {
            let at = self.rec(Section::Materials, i);
            let tex = self.u(at + 4 * 12);
            let target = self.u(at + 4 * 13);
            if (tex != NONE && tex >= ntex) || target > 3 {
                return Err(bad(Section::Materials, i));
            }
        }
        for i in 0..self.count(Section::Lights) {
            if self.u(self.rec(Section::Lights, i)) > 2 {
                return Err(badv(Section::Lights, i));
            }
        }
        // Each texture's texels lie inside the texel section ([`texel_range`], the same
        // checked arithmetic [`Self::texture`] uses), so sampling stays inside them.
        let ntexels = self.count(Section::Texels);
        for i in 0..ntex {
            let r = self.record::<TEXTURE_SIZE>(Section::Textures, i);
            match texel_range(r.u(0), r.u(4), r.u(8)) {
                Some((_, end)) if end <= ntexels => {}
                _ => return Err(bad(Section::Textures, i)),
            }
        }
        let nnodes = self.count(Section::Nodes);
        // One tree: node 0 is the root and its subtree is the whole list.
        if nnodes == 0 || self.node_skip(0) != nnodes {
            return Err(bad(Section::Nodes, 0));
        }
        for i in 0..nnodes {
            let at = self.rec(Section::Nodes, i);
            let skip = self.u(at + 24);
            let shape = self.u(at + 28);
            if skip <= i || skip > nnodes {
                return Err(bad(Section::Nodes, i));
            }
            if shape != NONE {
                let r = ShapeRef::decode(shape).ok_or(bad(Section::Nodes, i))?;
                let n = match r.kind {
                    ShapeKind::Triangle => self.count(Section::Triangles),
                    ShapeKind::Ellipsoid => self.count(Section::Ellipsoids),
                    ShapeKind::Box => self.count(Section::Boxes),
                    ShapeKind::Blob => self.count(Section::BlobGroups),
                };
                if r.index >= n || skip != i + 1 {
                    return Err(bad(Section::Nodes, i));
                }
            }
        }
        // Subtrees nest: every child's subtree ends within its parent's (else a walk could
        // visit nodes along exponentially many paths). O(n): each node is one child.
        for i in 0..nnodes {
            if self.node_is_leaf(i) {
                continue;
            }
            let end = self.node_skip(i);
            let mut c = i + 1;
            while c < end {
                let next = self.node_skip(c);
                if next > end {
                    return Err(bad(Section::Nodes, c));
                }
                c = next;
            }
        }
        let nrects = self.count(Section::Rects);
        if nrects != 0 && nrects != nnodes {
            return Err(bad(Section::Rects, nrects));
        }
        let (nn, nuv) = (self.count(Section::Normals), self.count(Section::Uvs));
        for i in 0..self.count(Section::Triangles) {
            let at = self.rec(Section::Triangles, i);
            let (m, n, uv) = (self.u(at + 36), self.u(at + 40), self.u(at + 44));
            if m >= nmat || (n != NONE && n >= nn) || (uv != NONE && uv >= nuv) {
                return Err(bad(Section::Triangles, i));
            }
        }
        for i in 0..self.count(Section::Ellipsoids) {
            if self.u(self.rec(Section::Ellipsoids, i) + 4 * 21) >= nmat {
                return Err(bad(Section::Ellipsoids, i));
            }
        }
        for i in 0..self.count(Section::Boxes) {
            if self.u(self.rec(Section::Boxes, i) + 4 * 21) >= nmat {
                return Err(bad(Section::Boxes, i));
            }
        }
        // A group's balls are records first..first + count, so `first + k` never wraps.
        let nballs = self.count(Section::Balls);
        for i in 0..self.count(Section::BlobGroups) {
            let at = self.rec(Section::BlobGroups, i);
            let (m, k, first, count) =
                (self.u(at), self.u(at + 4), self.u(at + 12), self.u(at + 16));
            let end = first.checked_add(count);
            if m >= nmat || k > 1 || count == 0 || end.is_none_or(|e| e > nballs) {
                return Err(bad(Section::BlobGroups, i));
            }
        }
        Ok(())
    }

    /// The bytes of record `i` of section `s` within [`Self::bytes`] (`None` unless `i` is
    /// one of the section's records), for tools that rewrite records in place.
    pub fn record_range(&self, s: Section, i: u32) -> Option<core::ops::Range<usize>> {
        if i >= self.count(s) {
            return None;
        }
        let size = s.record_size();
        let start =
            (self.table[s as usize].0 as usize).checked_add((i as usize).checked_mul(size)?)?;
        Some(start..start.checked_add(size)?)
    }

    /// Byte offset of record `i` of section `s` (saturating: an impossible index reads
    /// nothing rather than wrapping onto other bytes).
    #[inline(always)]
    fn rec(&self, s: Section, i: u32) -> usize {
        (self.table[s as usize].0 as usize)
            .saturating_add((i as usize).saturating_mul(s.record_size()))
    }

    /// Record `i` of section `s` (N = its record size); all zeros when `i` is not a record
    /// of the section, which indices taken from a validated image never are.
    #[inline(always)]
    fn record<const N: usize>(&self, s: Section, i: u32) -> Record<'a, N> {
        debug_assert_eq!(N, s.record_size());
        let (records, _) = self.sections.0[s as usize].as_chunks::<N>();
        if let Some(r) = records.get(i as usize) {
            return Record(r);
        }
        match ZERO_RECORD.first_chunk::<N>() {
            Some(z) => Record(z),
            None => panic!("record larger than ZERO_RECORD"),
        }
    }
    #[inline(always)]
    fn u(&self, at: usize) -> u32 {
        rd_u32(self.bytes, at)
    }
    #[inline(always)]
    fn f<T: Real>(&self, at: usize) -> T {
        T::from_stored(rd_u32(self.bytes, at))
    }
    #[inline]
    fn v3<T: Real>(&self, at: usize) -> Vec3<T> {
        Vec3::new(self.f(at), self.f(at + 4), self.f(at + 8))
    }

    pub fn camera<T: Real>(&self) -> Camera<T> {
        let at = self.rec(Section::Camera, 0);
        Camera {
            width: self.u(at),
            height: self.u(at + 4),
            x0: self.f(at + 8),
            y0: self.f(at + 12),
            dx: self.f(at + 16),
            dy: self.f(at + 20),
            dz: self.f(at + 56),
            background: self.v3(at + 24),
            ambient: self.v3(at + 36),
            max_depth: self.u(at + 48),
            non_refractive: self.u(at + 52) & 1 != 0,
            no_shadows: self.u(at + 52) & 2 != 0,
        }
    }

    /// Material `i` (`i` comes from a validated record).
    pub fn material<T: Real>(&self, i: u32) -> Material<T> {
        let r = self.record::<MATERIAL_SIZE>(Section::Materials, i);
        Material {
            diffuse: r.v3(0),
            specular: r.f(12),
            specular_edge: r.f(16),
            shininess: r.f(20),
            reflect: r.f(24),
            reflect_edge: r.f(28),
            transmit: r.v3(32),
            ior: r.f(44),
            texture: r.u(48),
            target: match r.u(52) {
                1 => MapTarget::Specular,
                2 => MapTarget::Reflect,
                3 => MapTarget::Transmit,
                _ => MapTarget::Diffuse,
            },
            scale: [r.f(56), r.f(60)],
        }
    }

    pub fn light_count(&self) -> u32 {
        self.count(Section::Lights)
    }

    pub fn light<T: Real>(&self, i: u32) -> Light<T> {
        let r = self.record::<LIGHT_SIZE>(Section::Lights, i);
        Light {
            kind: match r.u(0) {
                1 => LightKind::Point,
                2 => LightKind::Spot,
                _ => LightKind::Directional,
            },
            color: r.v3(4),
            pos: r.v3(16),
            dir: r.v3(28),
            cos_inner: r.f(40),
            cos_outer: r.f(44),
            exponent: r.f(48),
            falloff: r.u(52) != 0,
        }
    }

    /// Texture `i`: its size and exactly its `width * height * 3` texel bytes. A texture
    /// a validated image does not hold (never the case for indices from its records) reads
    /// as one black texel.
    pub fn texture(&self, i: u32) -> TextureView<'a> {
        let r = self.record::<TEXTURE_SIZE>(Section::Textures, i);
        let (w, h) = (r.u(0), r.u(4));
        let texels = self.sections.0[Section::Texels as usize];
        let rgb = texel_range(w, h, r.u(8))
            .and_then(|(start, end)| texels.get(start as usize..end as usize));
        match rgb {
            Some(rgb) => TextureView {
                width: w,
                height: h,
                rgb,
            },
            None => TextureView {
                width: 1,
                height: 1,
                rgb: &ZERO_RECORD[..3],
            },
        }
    }

    pub fn node_count(&self) -> u32 {
        self.count(Section::Nodes)
    }

    #[inline]
    pub fn node<T: Real>(&self, i: u32) -> Node<T> {
        let r = self.record::<NODE_SIZE>(Section::Nodes, i);
        let shape = r.u(28);
        Node {
            bounds: Aabb {
                min: r.v3(0),
                max: r.v3(12),
            },
            skip: r.u(24),
            shape: if shape == NONE {
                None
            } else {
                ShapeRef::decode(shape)
            },
        }
    }

    /// The skip index of node `i` (first node after its subtree), without decoding its box.
    #[inline]
    pub fn node_skip(&self, i: u32) -> u32 {
        self.record::<NODE_SIZE>(Section::Nodes, i).u(24)
    }

    /// Whether node `i` is a leaf (holds a shape).
    #[inline]
    pub fn node_is_leaf(&self, i: u32) -> bool {
        self.record::<NODE_SIZE>(Section::Nodes, i).u(28) != NONE
    }

    /// Whether the DM wrote screen rectangles (needed for Y/X clipping).
    pub fn has_rects(&self) -> bool {
        self.count(Section::Rects) != 0
    }

    /// Screen rectangle of node `i` (requires [`Self::has_rects`]).
    #[inline]
    pub fn rect(&self, i: u32) -> Rect {
        let r = self.record::<RECT_SIZE>(Section::Rects, i).0;
        let h = |o: usize| u16::from_le_bytes([r[o], r[o + 1]]);
        Rect {
            x_lo: h(0),
            x_hi: h(2),
            y_lo: h(4),
            y_hi: h(6),
        }
    }

    #[inline]
    pub fn triangle<T: Real>(&self, i: u32) -> TriangleRec<T> {
        let r = self.record::<TRIANGLE_SIZE>(Section::Triangles, i);
        TriangleRec {
            tri: Triangle {
                p: [r.v3(0), r.v3(12), r.v3(24)],
            },
            material: r.u(36),
            normals: r.u(40),
            uvs: r.u(44),
        }
    }

    pub fn normals<T: Real>(&self, i: u32) -> [Vec3<T>; 3] {
        let r = self.record::<NORMALS_SIZE>(Section::Normals, i);
        [r.v3(0), r.v3(12), r.v3(24)]
    }

    pub fn uvs<T: Real>(&self, i: u32) -> [[T; 2]; 3] {
        let at = self.rec(Section::Uvs, i);
        [
            [self.f(at), self.f(at + 4)],
            [self.f(at + 8), self.f(at + 12)],
            [self.f(at + 16), self.f(at + 20)],
        ]
    }

    #[inline]
    pub fn ellipsoid<T: Real>(&self, i: u32) -> EllipsoidRec<T> {
        let r = self.record::<ELLIPSOID_SIZE>(Section::Ellipsoids, i);
        let flags = r.u(4 * 22);
        let cut = if flags & 1 != 0 {
            Some(CutPlane {
                n: r.v3(4 * 23),
                d: r.f(4 * 26),
                capped: flags & 2 != 0,
            })
        } else {
            None
        };
        EllipsoidRec {
            shape: Ellipsoid {
                center: r.v3(0),
                m: r.m3(12),
                l: r.m3(48),
                cut,
            },
            material: r.u(4 * 21),
        }
    }

    #[inline]
    pub fn boxshape<T: Real>(&self, i: u32) -> BoxRec<T> {
        let r = self.record::<BOX_SIZE>(Section::Boxes, i);
        BoxRec {
            shape: BoxShape {
                center: r.v3(0),
                m: r.m3(12),
                l: r.m3(48),
            },
            material: r.u(4 * 21),
        }
    }

    pub fn blob_group<T: Real>(&self, i: u32) -> BlobGroupRec<T> {
        let at = self.rec(Section::BlobGroups, i);
        BlobGroupRec {
            material: self.u(at),
            kernel: if self.u(at + 4) == 1 {
                crate::shape::blob::Kernel::Wyvill
            } else {
                crate::shape::blob::Kernel::Links
            },
            threshold: self.f(at + 8),
            first: self.u(at + 12),
            count: self.u(at + 16),
        }
    }

    #[inline]
    pub fn ball<T: Real>(&self, i: u32) -> crate::shape::blob::Ball<T> {
        let r = self.record::<BALL_SIZE>(Section::Balls, i);
        crate::shape::blob::Ball {
            center: r.v3(0),
            radius: r.f(12),
            strength: r.f(16),
        }
    }
}

/// Writes an image section by section (host side, used by the DM).
#[cfg(feature = "std")]
pub mod writer {
    use super::*;
    use std::vec::Vec;

    /// Accumulates the records of each section, then lays them out.
    #[derive(Default)]
    pub struct ImageWriter {
        sections: [Vec<u8>; SECTION_COUNT],
        counts: [u32; SECTION_COUNT],
    }

    /// Appends one record's fields.
    pub struct Rec<'w>(&'w mut Vec<u8>);
    impl Rec<'_> {
        pub fn f(self, v: f32) -> Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        pub fn fs(mut self, v: &[f32]) -> Self {
            for x in v {
                self = self.f(*x);
            }
            self
        }
        pub fn u(self, v: u32) -> Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        pub fn bytes(self, b: &[u8]) -> Self {
            self.0.extend_from_slice(b);
            self
        }
    }

    impl ImageWriter {
        pub fn new() -> Self {
            Self::default()
        }
        /// Start a record in section `s`; returns its index.
        pub fn push(&mut self, s: Section) -> (u32, Rec<'_>) {
            let i = self.counts[s as usize];
            self.counts[s as usize] += if s == Section::Texels { 0 } else { 1 };
            (i, Rec(&mut self.sections[s as usize]))
        }
        /// Append texel bytes, returning their offset within the texel section.
        pub fn push_texels(&mut self, rgb: &[u8]) -> u32 {
            let v = &mut self.sections[Section::Texels as usize];
            let off = v.len() as u32;
            v.extend_from_slice(rgb);
            self.counts[Section::Texels as usize] = v.len() as u32;
            off
        }
        pub fn count(&self, s: Section) -> u32 {
            self.counts[s as usize]
        }
        /// Overwrite a u32 field of an already written record (patching `skip`).
        pub fn patch_u32(&mut self, s: Section, record: u32, field_offset: usize, v: u32) {
            let at = record as usize * s.record_size() + field_offset;
            self.sections[s as usize][at..at + 4].copy_from_slice(&v.to_le_bytes());
        }
        pub fn finish(self) -> Vec<u8> {
            let mut out = Vec::new();
            out.extend_from_slice(&MAGIC);
            out.extend_from_slice(&VERSION.to_le_bytes());
            out.push(0);
            out.push(0);
            out.extend_from_slice(&[0; 8]);
            out.resize(HEADER_SIZE, 0);
            for (i, data) in self.sections.iter().enumerate() {
                debug_assert_eq!(
                    data.len(),
                    self.counts[i] as usize * Section::ALL[i].record_size()
                );
                let off = if data.is_empty() { 0 } else { out.len() as u32 };
                out[16 + 8 * i..20 + 8 * i].copy_from_slice(&off.to_le_bytes());
                out[20 + 8 * i..24 + 8 * i].copy_from_slice(&self.counts[i].to_le_bytes());
                out.extend_from_slice(data);
                while out.len() % 4 != 0 {
                    out.push(0);
                }
            }
            let len = out.len() as u32;
            out[8..12].copy_from_slice(&len.to_le_bytes());
            out
        }
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::writer::ImageWriter;
    use super::*;

    /// A minimal image: a camera, one material, and the given nodes as (skip, shape word).
    fn image(width: u32, nodes: &[(u32, u32)]) -> std::vec::Vec<u8> {
        let mut w = ImageWriter::new();
        w.push(Section::Camera)
            .1
            .u(width)
            .u(8)
            .fs(&[-1.0, 1.0, 0.1, 0.1])
            .fs(&[0.0; 6])
            .u(2)
            .u(0)
            .fs(&[1.0]);
        w.push(Section::Materials)
            .1
            .fs(&[0.5; 12])
            .u(NONE)
            .u(0)
            .fs(&[1.0, 1.0]);
        w.push(Section::Triangles)
            .1
            .fs(&[0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0])
            .u(0)
            .u(NONE)
            .u(NONE);
        for &(skip, shape) in nodes {
            w.push(Section::Nodes)
                .1
                .fs(&[-1.0, -1.0, -1.0, 1.0, 1.0, 1.0])
                .u(skip)
                .u(shape);
        }
        w.finish()
    }

    /// A 4 x 4 picture filled by one triangle whose material is texture 0 (`tex` = width,
    /// height, texel offset) over `texels`, lit by ambient light only (so a pixel is its
    /// texel's colour), stored as f32 or Q16.16.
    fn textured(storage: Storage, tex: (u32, u32, u32), texels: &[u8]) -> std::vec::Vec<u8> {
        let s = |x: f32| match storage {
            Storage::F32 => x.to_bits(),
            Storage::Q16_16 => ((x * 65536.0).round() as i32) as u32,
        };
        let mut w = ImageWriter::new();
        let mut r = w.push(Section::Camera).1.u(4).u(4);
        for x in [-1.0, 1.0, 0.5, 0.5, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0] {
            r = r.u(s(x));
        }
        r.u(2).u(0).u(s(1.0));
        let mut r = w.push(Section::Materials).1;
        // diffuse 1, no specular (shininess 1), no reflection or transmission, ior 1.
        for x in [1.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0] {
            r = r.u(s(x));
        }
        r.u(0).u(MapTarget::Diffuse as u32).u(s(1.0)).u(s(1.0));
        w.push(Section::Textures).1.u(tex.0).u(tex.1).u(tex.2);
        w.push_texels(texels);
        let mut r = w.push(Section::Triangles).1;
        for x in [-10.0, -10.0, 2.0, 10.0, -10.0, 2.0, 0.0, 10.0, 2.0] {
            r = r.u(s(x));
        }
        r.u(0).u(NONE).u(NONE);
        let mut r = w.push(Section::Nodes).1;
        for x in [-10.0, -10.0, 1.0, 10.0, 10.0, 3.0] {
            r = r.u(s(x));
        }
        r.u(1).u(0);
        let mut img = w.finish();
        img[6] = storage as u8;
        img
    }

    /// Every pixel of an image with number type `T`.
    fn render_every_pixel<T: Real>(view: SceneView<'_>) -> std::vec::Vec<crate::render::Rgb8> {
        let f = view.camera::<f32>();
        let mut tracer = crate::render::Tracer::<T>::new(view);
        let mut row = std::vec![[0u8; 3]; f.width as usize];
        let mut out = std::vec::Vec::new();
        for y in 0..f.height {
            crate::render::render_run(&mut tracer, y, 0, &mut row).unwrap();
            out.extend_from_slice(&row);
        }
        out
    }

    #[test]
    fn a_texture_that_fits_its_texels_is_sampled_in_every_number_format() {
        let texels = [200, 100, 50].repeat(4);
        for storage in [Storage::F32, Storage::Q16_16] {
            let img = textured(storage, (2, 2, 0), &texels);
            let view = SceneView::new(&img).unwrap();
            let px: std::vec::Vec<_> = match storage {
                Storage::F32 => {
                    let a = render_every_pixel::<f32>(view);
                    assert_eq!(a, render_every_pixel::<f64>(view));
                    a
                }
                Storage::Q16_16 => render_every_pixel::<crate::num::Fx>(view),
            };
            assert_eq!(px.len(), 16);
            for p in px {
                for (got, want) in p.iter().zip([200u8, 100, 50]) {
                    assert!(got.abs_diff(want) <= 1, "{storage:?}: {p:?}");
                }
            }
        }
    }

    #[test]
    fn texture_sizes_whose_arithmetic_overflows_are_rejected() {
        let texels = [7u8; 36];
        let textures = |section: u8| ImageError::BadReference { section, record: 0 };
        let t = Section::Textures as u8;
        // 1684887088 x 3649452082 x 3 = 2^64 + 32: a u64 product wraps to 32 bytes, which
        // the 36 texels "hold"; sampling then indexes gigabytes past them.
        let wraps_u64 = (1_684_887_088, 3_649_452_082, 0);
        // w * h * 3 = 3 * 2^32: wraps a u32 (a 32-bit usize) to 0.
        let wraps_u32 = (65_536, 65_536, 0);
        // The offset plus the texture's bytes pass u32::MAX.
        let offset_wraps = (1, 1, u32::MAX - 1);
        // One byte more than the texels: the exact bound.
        let one_past = (3, 4, 1);
        for storage in [Storage::F32, Storage::Q16_16] {
            for tex in [wraps_u64, wraps_u32, offset_wraps, one_past] {
                let img = textured(storage, tex, &texels);
                assert_eq!(
                    SceneView::new(&img).err(),
                    Some(textures(t)),
                    "{storage:?} texture {tex:?}"
                );
            }
            // The largest texture the texels hold is accepted and rendered.
            let img = textured(storage, (3, 4, 0), &texels);
            let view = SceneView::new(&img).unwrap();
            let px = match storage {
                Storage::F32 => render_every_pixel::<f32>(view),
                Storage::Q16_16 => render_every_pixel::<crate::num::Fx>(view),
            };
            assert!(px.iter().flatten().all(|&c| c.abs_diff(7) <= 1), "{px:?}");
        }
    }

    #[test]
    fn a_well_formed_tree_is_accepted() {
        let img = image(8, &[(3, NONE), (3, NONE), (3, 0)]);
        assert!(SceneView::new(&img).is_ok());
    }

    #[test]
    fn trees_that_could_mislead_a_walk_are_rejected() {
        let nodes_error = |r: Result<SceneView<'_>, ImageError>| matches!(r, Err(ImageError::BadReference { section, .. }) if section == Section::Nodes as u8);
        // No nodes at all: node 0 would be read from the header.
        assert!(nodes_error(SceneView::new(&image(8, &[]))));
        // Two top-level trees: closest-hit walks only node 0's.
        assert!(nodes_error(SceneView::new(&image(8, &[(1, NONE), (2, 0)]))));
        // A child's subtree ending beyond its parent's (exponential walks).
        assert!(nodes_error(SceneView::new(&image(
            8,
            &[(5, NONE), (3, NONE), (4, NONE), (4, 0), (5, 0)]
        ))));
    }

    #[test]
    fn cameras_wider_than_the_u16_pixel_range_are_rejected() {
        assert!(SceneView::new(&image(65535, &[(1, NONE)])).is_ok());
        assert!(matches!(
            SceneView::new(&image(65536, &[(1, NONE)])),
            Err(ImageError::BadValue { .. })
        ));
    }

    #[test]
    fn records_out_of_range_read_as_zeros_not_other_bytes() {
        let img = image(8, &[(1, NONE)]);
        let v = SceneView::new(&img).unwrap();
        // There are no ellipsoids: the section offset is 0 (the header) but nothing is read.
        let e = v.ellipsoid::<f32>(0);
        assert_eq!(e.material, 0);
        assert_eq!(e.shape.center, Vec3::zero());
        assert_eq!(v.triangle::<f32>(u32::MAX).material, 0);
        // No textures: one black texel, not an empty one (sampling divides by its size).
        let t = v.texture(0);
        assert_eq!((t.width, t.height, t.rgb), (1, 1, &[0u8, 0, 0][..]));
        assert_eq!(v.record_range(Section::Ellipsoids, 0), None);
        assert_eq!(
            v.record_range(Section::Camera, 0),
            Some(128..128 + CAMERA_SIZE)
        );
    }
}
