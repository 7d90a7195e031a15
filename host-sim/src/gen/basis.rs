//! [`Basis`]: a local coordinate basis (origin, two cross-section directions and an axis) in
//! which the mesh builder's helpers place their rings.

use crate::vec3::{add, cross, dot, normalize, scale, sub};

/// A local basis for the helpers: 2-D cross-section coordinates `(c1, c2)` along `u` and
/// `w`, and a distance `t` along `axis`. `u`, `w`, `axis` are orthonormal with
/// `u x w = axis`, so counter-clockwise in `(c1, c2)` is counter-clockwise seen from `+axis`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Basis {
    pub origin: [f64; 3],
    pub u: [f64; 3],
    pub w: [f64; 3],
    pub axis: [f64; 3],
}

impl Basis {
    /// A basis at `origin` with the given axis; `u_hint` is made perpendicular to it.
    pub fn new(origin: [f64; 3], axis: [f64; 3], u_hint: [f64; 3]) -> Self {
        let axis = normalize(axis);
        let u = normalize(sub(u_hint, scale(axis, dot(u_hint, axis))));
        let w = cross(axis, u);
        Self { origin, u, w, axis }
    }

    /// Axis `+y` and `u = +x`, so `(c1, c2) = (x, -z)`; use [`Basis::xz`] to write rings in
    /// world `(x, z)`.
    pub fn y_up(origin: [f64; 3]) -> Self {
        Self::new(origin, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    }

    /// Cross-section coordinates of the world offset `(x, z)` in a [`Basis::y_up`] basis.
    pub fn xz(x: f64, z: f64) -> [f64; 2] {
        [x, -z]
    }

    /// The world point at cross-section `(c1, c2)` and height `t`.
    pub fn point(&self, c1: f64, c2: f64, t: f64) -> [f64; 3] {
        add(
            self.origin,
            add(
                scale(self.u, c1),
                add(scale(self.w, c2), scale(self.axis, t)),
            ),
        )
    }
}
