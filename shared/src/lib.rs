//! LINKS-1's ray tracer, as a no_std, no-heap core shared by the node firmware, the root
//! firmware and the host simulator.
//!
//! Module map, by layer (math -> scene -> trace -> cluster, with serial beside the cluster),
//! one concept each; every module is also re-exported at its old root path:
//! - [`num`]: the number formats the renderer is generic over.
//! - [`geom`]: vectors, rays, bounding boxes, error-bounded ray origins.
//! - [`shape`]: the primitives (triangle, ellipsoid + cut plane, box, density spheres).
//! - [`image`]: the SceneImage byte layout and its zero-copy view.
//! - [`trace`] (also at the old path `render`): the tracer, one run of pixels at a time:
//!   traversal returning hits, surfaces, textures, lights, shading (eq. 2.1, 2.2) apart, the
//!   operation counts and speed techniques, and [`clip`] (screen-space Y/X clipping of
//!   primary rays, LINKS-1 4.4).
//! - `desc` and `dm` (feature `std`): the scene description and the DM scene compiler.
//! - [`cluster`]: [`wire`], [`link`], [`sched`], [`node`], [`root`] (bus messages, the IMSU
//!   link traits, sub-screen scheduling, the NC and RC behaviour) and [`spi`] (the link driver
//!   protocol over a real SPI star: framing, master, slave), generic over the MCU ports.
//! - [`serial`]: the PC <-> RC serial protocol (scene upload, frame readback).
#![cfg_attr(not(any(test, feature = "std")), no_std)]
// The one exception: the FPU square root in `num` (inline asm).
#![deny(unsafe_code)]

pub mod cluster;
#[cfg(feature = "std")]
pub mod desc;
#[cfg(feature = "std")]
pub mod dm;
pub mod fixed;
#[cfg(any(test, feature = "std"))]
pub mod fixed_image;
pub mod geom;
pub mod image;
pub mod num;
pub mod serial;
pub mod shape;
pub mod trace;

pub use cluster::{link, node, root, sched, spi, wire};
pub use trace as render;
pub use trace::clip;
