//! The SceneImage: one contiguous, versioned byte image of a compiled scene.
//!
//! The DM writes it once; a node receives it over the link into a bank and renders straight
//! from those bytes through [`SceneView`]: nothing is copied or allocated, each record is
//! decoded into registers when it is used. Only sections the scene uses take space.
//!
//! - [`layout`]: the header and every record's fields, defined once (read by the view,
//!   written by the writer, converted by the Q16.16 rewrite).
//! - [`view`]: [`SceneView`], the zero-copy reader, and the decoded records below.
//! - [`validate`]: the checks [`SceneView::new`] makes before anything is read.
//! - `writer` (feature `std`): [`writer::ImageWriter`], which the DM fills.
//! - `fixed` (feature `std`): the rewrite of an f32 image as Q16.16.

use crate::geom::{Aabb, Vec3};
use crate::math::solid::{BoxShape, Ellipsoid, Kernel, Triangle};
use crate::num::{Real, Storage};
use core::fmt;

#[cfg(any(test, feature = "std"))]
pub mod fixed;
pub mod layout;
pub mod validate;
pub mod view;
#[cfg(any(test, feature = "std"))]
pub mod writer;

pub use layout::*;
pub use view::{NodeRef, NodeTable, SceneView};

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
    /// Anti-aliasing grid side N (1..=[`camera::MAX_AA`]): each pixel is the mean of N x N
    /// primary rays through the centres of an N x N grid of sub-pixels.
    pub aa: u32,
}

impl<T: Real> Camera<T> {
    /// `s dx`, the x offset of the screen point `s` pixels right of x0's.
    #[inline(always)]
    pub fn across(&self, s: T) -> T {
        Self::unstep(s * self.dx)
    }
    /// `s dy`, the y offset of the screen point `s` pixels below y0's.
    #[inline(always)]
    pub fn down(&self, s: T) -> T {
        Self::unstep(s * self.dy)
    }
    /// A Q16.16 image stores dx and dy 2^[`camera::STEP_BITS`] times finer
    /// ([`crate::image::fixed`]): the product is scaled back, rounded once more.
    #[inline(always)]
    fn unstep(v: T) -> T {
        if matches!(T::STORAGE, Storage::Q16_16) {
            v * T::from_f32(1.0 / (1u32 << camera::STEP_BITS) as f32)
        } else {
            v
        }
    }
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
    /// `arc`, the ambient reflection colour, when the material has its own (else the
    /// ambient term uses the diffuse colour).
    pub ambient: Option<Vec3<T>>,
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
    /// RGB8 rows, or with a palette one index per texel.
    pub texels: &'a [u8],
    /// The palette's RGB8 colours (empty for RGB8 texels).
    pub palette: &'a [u8],
}

impl TextureView<'_> {
    /// Texel (x, y) as RGB8 (inside the texture: x < width, y < height; black outside).
    #[inline]
    pub fn texel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = (y as usize)
            .saturating_mul(self.width as usize)
            .saturating_add(x as usize);
        let at = if self.palette.is_empty() {
            Some(i.saturating_mul(3))
        } else {
            self.texels.get(i).map(|&p| p as usize * 3)
        };
        let src = if self.palette.is_empty() {
            self.texels
        } else {
            self.palette
        };
        match at
            .and_then(|a| src.get(a..))
            .and_then(|r| r.first_chunk::<3>())
        {
            Some(c) => *c,
            None => [0; 3],
        }
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Node<T> {
    pub bounds: Aabb<T>,
    pub skip: u32,
    pub leaf: Option<Leaf>,
}

#[derive(Clone, Copy, Debug)]
pub struct TriangleRec<T> {
    pub tri: Triangle<T>,
    /// Record of TriNormals, or [`NONE`] for a flat triangle.
    pub normals: u32,
    /// Record of TriUvs (the triangle's own), or [`NONE`] when the image has no uvs.
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
    pub kernel: Kernel,
    pub threshold: T,
    pub first: u32,
    pub count: u32,
}

#[cfg(test)]
mod tests;
