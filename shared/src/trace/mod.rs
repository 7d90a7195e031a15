//! The trace layer: LINKS-1's line-of-sight search with eq. 2.1 shading and eq. 2.2
//! recursion, one run of pixels at a time.
//!
//! - [`tracer`]: the entry ([`Tracer`], [`render_run`]), its limits and its error.
//! - [`clip`]: screen-space Y/X clipping of primary rays (LINKS-1 4.4).
//! - [`traversal`]: the nearest hit along a ray (boxes, clipping, the plain algorithm).
//! - [`primary`]: primary rays from the eye, triangles tested against cached edge planes.
//! - [`surface`]: completing a hit into a surface point.
//! - [`texture`]: materials with their texture maps applied.
//! - [`records`]: material and light records decoded once per tracer.
//! - [`lights`]: light sources and shadow rays.
//! - [`shading`]: eq. 2.1 and eq. 2.2.
//! - [`stats`], [`techniques`]: the operation counts and the switchable speed techniques.
//!
//! Every item is re-exported here, so `links_core::render::X` (the old path) still names it.

pub mod clip;
pub mod light_rects;
pub mod lights;
pub mod primary;
pub mod records;
pub mod shading;
pub mod stats;
pub mod surface;
pub mod techniques;
pub mod texture;
pub mod tracer;
pub mod traversal;

pub use stats::Stats;
pub use surface::Surface;
pub use techniques::Techniques;
pub use tracer::{
    render_run, to_rgb8, RenderError, Rgb8, SceneKey, Tracer, TracerState, MAX_CROSSINGS,
    SECONDARY_RAYS_PER_PIXEL,
};
