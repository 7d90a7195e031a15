//! LINKS-1's ray tracer, as a no_std, no-heap core shared by the node firmware, the root
//! firmware and the host simulator.
//!
//! Module map, by layer (each builds on the ones above it; one concept per module):
//! - [`math`]: [`num`] (the number formats the renderer is generic over), [`fixed`] (Q16.16),
//!   [`geom`] (vectors, rays, bounding boxes, error-bounded ray origins), `solid` (the
//!   primitives' parameters as plain data).
//! - [`scene`]: `desc` (feature `std`: the scene as described), `compile` (feature `std`: the
//!   DM scene compiler, also at `dm`), [`image`] (the SceneImage: byte layout, zero-copy view,
//!   validation, writer, Q16.16 rewrite).
//! - [`trace`] (also at `render`): the tracer, one run of pixels at a time: traversal of the
//!   cluster hierarchy returning hits, surfaces, textures, lights, shading (eq. 2.1, 2.2), the
//!   operation counts ([`render::Stats`]), and [`clip`] (screen-space Y/X clipping, LINKS-1 4.4);
//!   [`shape`]: the primitives' intersection tests (triangle, ellipsoid + cut plane, box,
//!   density spheres).
//! - [`cluster`]: [`wire`] (bus messages), [`link`] (the IMSU link traits), [`sched`]
//!   (sub-screen scheduling), [`node`] and [`root`] (the NC and RC behaviour), [`spi`] (the
//!   link driver protocol over a real SPI star: framing, handshake, banks, retransmit
//!   requests, generic over the MCU ports).
//! - [`serial`]: the PC <-> RC serial protocol (scene upload, frame readback) and the RC's
//!   side of it.
//! - `testkit` (tests, feature `testkit`): test doubles shared by every test.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
// The one exception: the FPU square root in `num` (inline asm).
#![deny(unsafe_code)]

pub mod cluster;
pub mod math;
pub mod scene;
pub mod serial;
pub mod shape;
#[cfg(any(test, feature = "testkit"))]
pub mod testkit;
pub mod trace;

// The short paths: every module at the crate root, as before the layers.
pub use cluster::{backup, board, landing, link, node, relay, root, sched, spi, wire};
pub use math::{fixed, geom, num};
pub use scene::image;
#[cfg(any(test, feature = "std"))]
pub use scene::image::fixed as fixed_image;
#[cfg(feature = "std")]
pub use scene::{anim, compile as dm, desc};
pub use trace as render;
pub use trace::clip;
