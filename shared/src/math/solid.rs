//! The solids a scene is built from, as plain data in view coordinates: what a SceneImage
//! record decodes to and what the intersection code (`crate::shape`) tests rays against.
//! Only the parameters live here, so the image layer does not depend on the intersection
//! code; each shape's tests are implemented on these types in its `shape` module.
//!
//! Ellipsoids and boxes are stored as an affine map onto the unit sphere or the cube
//! [-1, 1]³: `q = M (p - c)`, with `L = M⁻¹` kept too.

use crate::geom::{Mat3, Vec3};

/// A triangle as the renderer sees it (view coordinates).
#[derive(Clone, Copy, Debug)]
pub struct Triangle<T> {
    pub p: [Vec3<T>; 3],
}

#[derive(Clone, Copy, Debug)]
pub struct CutPlane<T> {
    /// Unit normal in the unit-sphere space.
    pub n: Vec3<T>,
    pub d: T,
    pub capped: bool,
}

#[derive(Clone, Copy, Debug)]
pub struct Ellipsoid<T> {
    pub center: Vec3<T>,
    /// View -> unit sphere.
    pub m: Mat3<T>,
    /// Unit sphere -> view (the inverse of `m`).
    pub l: Mat3<T>,
    pub cut: Option<CutPlane<T>>,
}

#[derive(Clone, Copy, Debug)]
pub struct BoxShape<T> {
    pub center: Vec3<T>,
    pub m: Mat3<T>,
    pub l: Mat3<T>,
}

/// The radial density function of every ball of a group.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// `b(1 - 3r²/d²)` for `r <= d/3`, `(3b/2)(1 - r/d)²` for `d/3 < r <= d`.
    Links,
    /// `b(1 - r²/d²)²` for `r <= d`.
    Wyvill,
}

/// One density sphere.
#[derive(Clone, Copy, Debug)]
pub struct Ball<T> {
    pub center: Vec3<T>,
    /// Radius of influence `d` (> 0; balls with `d <= 0` are ignored).
    pub radius: T,
    /// Strength `b`; negative balls carve dents.
    pub strength: T,
}
