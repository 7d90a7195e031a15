//! LINKS-1's ray tracer, as a no_std, no-heap core shared by the node firmware, the root
//! firmware and the host simulator.
//!
//! Module map, by layer (each builds on the ones above it; one concept per module):
//! - [`math`]: [`num`] (the number formats the renderer is generic over), [`fixed`] (Q16.16),
//!   [`geom`] (vectors, rays, bounding boxes, error-bounded ray origins).
//! - [`scene`]: `desc` (feature `std`: the scene as described), `compile` (feature `std`: the
//!   DM scene compiler, also at `dm`), [`image`] (the SceneImage: byte layout, zero-copy view,
//!   validation, writer, Q16.16 rewrite).
//! - [`shape`]: the primitives (triangle, ellipsoid + cut plane, box, density spheres).
//! - [`clip`]: screen-space Y/X clipping of primary rays (LINKS-1 4.4).
//! - [`render`]: the tracer and shading (eq. 2.1, 2.2), one run of pixels at a time.
//! - [`wire`], [`link`], [`sched`], [`node`], [`root`]: the cluster (bus messages, the IMSU
//!   link traits, sub-screen scheduling, the NC and RC behaviour).
//! - [`spi`]: the link driver protocol over a real SPI star (framing, handshake, banks,
//!   retransmit requests), generic over the MCU ports.
//! - [`serial`]: the PC <-> RC serial protocol (scene upload, frame readback).
#![cfg_attr(not(any(test, feature = "std")), no_std)]
// The one exception: the FPU square root in `num` (inline asm).
#![deny(unsafe_code)]

pub mod clip;
pub mod link;
pub mod math;
pub mod node;
pub mod render;
pub mod root;
pub mod scene;
pub mod sched;
pub mod serial;
pub mod shape;
pub mod spi;
#[cfg(any(test, feature = "testkit"))]
pub mod testkit;
pub mod wire;

pub use math::{fixed, geom, num};
pub use scene::image;
#[cfg(any(test, feature = "std"))]
pub use scene::image::fixed as fixed_image;
#[cfg(feature = "std")]
pub use scene::{compile as dm, desc};
