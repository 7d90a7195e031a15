//! The math layer, the bottom of the core: number formats and geometry, with no knowledge of
//! scenes, images or intersection tests.
//!
//! - [`num`]: the [`num::Real`] trait the renderer is generic over (f64, f32, Q16.16) and the
//!   storage formats of image scalars.
//! - [`fixed`]: Q16.16 fixed point ([`fixed::Fx`]).
//! - [`overflow`]: the checked build's count of fixed-point overflows (`fx-checked`).
//! - [`geom`]: vectors, matrices, rays, bounding boxes, error-bounded ray origins.
//! - [`solid`]: the primitives' parameters as plain data (triangle, ellipsoid, box, ball).

pub mod fixed;
pub mod geom;
pub mod num;
pub mod overflow;
pub mod solid;
