//! The cluster layer: LINKS-1's root computer (RC) and node computers (NCs) on one bus.
//!
//! - [`board`]: the node boards as data: RAM and the two scene banks of the memory plan.
//! - [`profile`]: the board as one value: the SPI link, the node's memory, the core.
//! - [`wire`]: every message on the RC-NC bus (postcard, CRC-32, run-length pixels).
//! - [`link`]: the IMSU link as traits the node and root logic are generic over.
//! - [`landing`]: broadcast scene chunks written by the node's link straight into the scene
//!   bank the node logic is not rendering from (the IMSU's broadcast into node memory).
//! - [`sched`]: sub-screen scheduling (which region a node renders next).
//! - [`node`]: the NC's whole behaviour (scene, jobs, render, return pixel runs).
//! - [`root`]: the RC's whole behaviour (broadcast, hand out, collect, detect completion).
//! - [`backup`]: the serial backup line (RS-485 multi-drop UART): roll call, health, and
//!   the slow path for scene, work and pixels of a node whose SPI link failed.
//! - [`spi`]: the link driver's protocol over a real SPI star, generic over the MCU ports.
//! - [`relay`]: relay RCs (a node on the parent's bus, the root of their own): broadcasts
//!   stored and forwarded, node frames and replies routed in batches.

pub mod backup;
pub mod board;
pub mod landing;
pub mod link;
pub mod node;
pub mod profile;
pub mod relay;
pub mod root;
pub mod sched;
pub mod spi;
pub mod wire;
