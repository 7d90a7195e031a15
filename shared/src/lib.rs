//! LINKS-1's ray tracer, as a no_std, no-heap core shared by the node firmware, the root
//! firmware and the host simulator.
//!
//! Module map (one concept each):
//! - [`num`]: the number formats the renderer is generic over.
//! - [`geom`]: vectors, rays, bounding boxes, error-bounded ray origins.
//! - [`shape`]: the primitives (triangle, ellipsoid + cut plane, box, density spheres).
//! - [`image`]: the SceneImage byte layout and its zero-copy view.
//! - [`clip`]: screen-space Y/X clipping of primary rays (LINKS-1 4.4).
//! - [`render`]: the tracer and shading (eq. 2.1, 2.2), one run of pixels at a time.
//! - `desc` and `dm` (feature `std`): the scene description and the DM scene compiler.
//! - [`wire`], [`link`], [`sched`], [`node`], [`root`]: the cluster (bus messages, the IMSU
//!   link traits, sub-screen scheduling, the NC and RC behaviour).
//! - [`spi`]: the link driver protocol over a real SPI star (framing, handshake, banks,
//!   retransmit requests), generic over the MCU ports.
//! - [`serial`]: the PC <-> RC serial protocol (scene upload, frame readback).
#![cfg_attr(not(any(test, feature = "std")), no_std)]
// The one exception: the FPU square root in `num` (inline asm).
#![deny(unsafe_code)]

pub mod clip;
#[cfg(feature = "std")]
pub mod desc;
#[cfg(feature = "std")]
pub mod dm;
pub mod fixed;
#[cfg(any(test, feature = "std"))]
pub mod fixed_image;
pub mod geom;
pub mod image;
pub mod link;
pub mod node;
pub mod num;
pub mod render;
pub mod root;
pub mod sched;
pub mod serial;
pub mod shape;
pub mod spi;
#[cfg(any(test, feature = "testkit"))]
pub mod testkit;
pub mod wire;
