//! The trace layer: primary-ray clipping, traversal, shading and the per-run entry.

pub mod clip;
