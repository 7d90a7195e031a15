//! The DM ("data manipulation" module): compiles a [`SceneDesc`] into a SceneImage.
//!
//! It places every cluster (LINKS-1 4.1), transforms all shape data into view coordinates
//! (4.3: eye at the origin, X right, Y up, +Z into the screen), computes a bounding box per
//! shape and per cluster (4.2) and writes the flat node list the tracer walks. Runs on the
//! host in f64; the image stores f32, with every bounding box rounded outward so it still
//! contains its shape after rounding.
//!
//! Large meshes are split by the DM into sub-clusters down to leaves of at most
//! [`CompileOptions::leaf_size`] triangles (a binned-SAH BVH by default, see
//! [`MeshHierarchy`]), so a ray that touches a mesh's box only tests the triangles near it.
//! Each node also gets its screen rectangle (LINKS-1 4.4) for the renderer's Y/X clipping of
//! primary rays. Vertices, normals and uvs shared by triangles are written once; clusters
//! with a single child are dropped; boxes go on the image's node grid (see
//! [`crate::image::layout`]).

use crate::desc::{self, Cluster, Light, Node, SceneDesc, Shape, TransparencyMode};
use crate::image::layout::{
    ball, blob_group, boxshape, camera, corners, ellipsoid, light, material, node, normal, rect,
    texture, triangle, uv, vertex,
};
use crate::image::writer::ImageWriter;
use crate::image::{Leaf, Rect, Section, ShapeKind, MAX_DEPTH_LIMIT, NONE, NONE16};
use core::fmt;
use std::string::{String, ToString};
use std::vec::Vec;

mod bounds;
mod lights;
mod materials;
mod mesh;
mod shapes;
mod transform;
mod tree;
mod view;

use bounds::*;
use mesh::*;
use transform::*;
use view::*;

/// Largest number of triangles the DM leaves in one mesh sub-cluster.
/// Default triangles per leaf: the smallest that fits photo2 (the paper's Table 5.2 scene)
/// in 40,000 bytes; smaller leaves trade bytes for speed (`links info --leaf-size`, table in
/// docs/renderer.md).
pub const MESH_LEAF_SIZE: usize = 8;

/// Settings that are not part of the scene file.
#[derive(Clone, Debug, Default)]
pub struct CompileOptions {
    /// Output size; `None` uses the scene's.
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub max_depth: Option<u32>,
    pub transparency: Option<TransparencyMode>,
    /// How the DM organises the triangles of a mesh below its cluster.
    pub mesh_hierarchy: MeshHierarchy,
    /// Render without shadows (no shadow rays; lights always reach a lit surface), as the
    /// paper's load-balancing measurements did.
    pub no_shadows: bool,
    /// Most triangles in one leaf (1..=31; `None`: [`MESH_LEAF_SIZE`]).
    pub leaf_size: Option<usize>,
    /// Anti-aliasing: N x N primary rays per pixel (1..=[`camera::MAX_AA`]; `None`: 1).
    pub aa: Option<u32>,
}

/// The hierarchy the DM builds inside each mesh cluster.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MeshHierarchy {
    /// LINKS-1's: the mesh is one cluster of leaves, in file order.
    Flat,
    /// Median split on the longest axis down to leaves of [`CompileOptions::leaf_size`].
    Median,
    /// Binned surface-area-heuristic BVH (beyond the paper).
    #[default]
    Sah,
}

/// Why a scene could not be compiled.
#[derive(Clone, Debug, PartialEq)]
pub enum DmError {
    /// The eye, look-at and up vectors do not define a view.
    DegenerateCamera(String),
    /// A transform collapses space (zero scale) or is not finite.
    DegenerateTransform {
        cluster: String,
    },
    /// A shape becomes degenerate in view coordinates (after f32 rounding).
    DegenerateShape {
        cluster: String,
        what: String,
    },
    /// Density spheres can only be moved, rotated and scaled uniformly.
    NonUniformBlobScale {
        cluster: String,
    },
    BadIndex {
        what: String,
    },
    BadSetting(String),
    TooLarge {
        what: String,
    },
    /// A value beyond the f32 range in view coordinates (a transform carried a coordinate
    /// of the scene past it): the image would hold an infinity.
    BeyondF32 {
        section: &'static str,
        record: u32,
    },
}

impl fmt::Display for DmError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DmError::DegenerateCamera(s) => write!(f, "camera: {s}"),
            DmError::DegenerateTransform { cluster } => {
                write!(
                    f,
                    "cluster '{cluster}': transform is degenerate (zero scale or not finite)"
                )
            }
            DmError::DegenerateShape { cluster, what } => {
                write!(
                    f,
                    "cluster '{cluster}': {what} is degenerate in view coordinates"
                )
            }
            DmError::NonUniformBlobScale { cluster } => write!(
                f,
                "cluster '{cluster}': density spheres need a uniform scale (balls must stay round)"
            ),
            DmError::BadIndex { what } => write!(f, "{what}"),
            DmError::BadSetting(s) => write!(f, "{s}"),
            DmError::TooLarge { what } => write!(f, "scene too large: {what}"),
            DmError::BeyondF32 { section, record } => write!(
                f,
                "{section} record {record} holds a value beyond the f32 range (about ±3.4e38) \
                 after the cluster and view transforms"
            ),
        }
    }
}

impl std::error::Error for DmError {}

/// What the DM produced, with per-section sizes for reports.
#[derive(Clone, Debug)]
pub struct Compiled {
    pub bytes: Vec<u8>,
}

struct Dm<'a> {
    desc: &'a SceneDesc,
    w: ImageWriter,
    opts: &'a CompileOptions,
    proj: Projection,
    /// The tree as built, written by [`Dm::write_tree`] at the end.
    nodes: Vec<tree::BuildNode>,
    shared: mesh::SharedVertices,
    /// Each triangle's uv indices, written as TriUvs when any triangle has them.
    tri_uvs: Vec<Option<[u16; 3]>>,
}

/// Compile a scene for one frame.
pub fn compile(desc: &SceneDesc, opts: &CompileOptions) -> Result<Compiled, DmError> {
    let mut dm = Dm {
        desc,
        w: ImageWriter::new(),
        opts,
        proj: Projection::default(),
        nodes: Vec::new(),
        shared: mesh::SharedVertices::default(),
        tri_uvs: Vec::new(),
    };
    dm.run()?;
    let bytes = dm.w.finish();
    // Every scene-file number fits f32, but a transform can carry a coordinate past it.
    match crate::fixed_image::first_non_finite(&bytes) {
        Ok(None) => Ok(Compiled { bytes }),
        Ok(Some((section, record))) => Err(DmError::BeyondF32 {
            section: section.name(),
            record,
        }),
        Err(e) => Err(DmError::TooLarge {
            what: format!("the image the DM wrote is not valid: {e}"),
        }),
    }
}

impl Dm<'_> {
    fn run(&mut self) -> Result<(), DmError> {
        let d = self.desc;
        let width = self.opts.width.unwrap_or(d.width);
        let height = self.opts.height.unwrap_or(d.height);
        if width == 0 || height == 0 || width > 65535 || height > 65535 {
            return Err(DmError::BadSetting(format!(
                "image size {width}x{height} out of range 1..65535"
            )));
        }
        let max_depth = self.opts.max_depth.unwrap_or(d.max_depth);
        if max_depth > MAX_DEPTH_LIMIT {
            return Err(DmError::BadSetting(format!(
                "max depth {max_depth} exceeds the node limit {MAX_DEPTH_LIMIT}"
            )));
        }
        let mode = self.opts.transparency.unwrap_or(d.transparency);
        let aa = self.opts.aa.unwrap_or(1);
        if !(1..=camera::MAX_AA).contains(&aa) {
            return Err(DmError::BadSetting(format!(
                "anti-aliasing {aa} out of range 1..={}",
                camera::MAX_AA
            )));
        }

        let view = self.camera(width, height, max_depth, mode)?;
        self.check_material_count()?;

        self.textures()?;
        // The texel section must keep later sections aligned: the writer pads.
        self.materials()?;
        for l in &d.lights {
            self.light(l, &view)?;
        }
        self.cluster(&d.root, &view, d.root.name.as_str())?;
        if self.tri_uvs.iter().any(Option::is_some) {
            for c in std::mem::take(&mut self.tri_uvs) {
                let (_, r) = self.w.push(Section::TriUvs);
                r.hs(corners::I, &c.unwrap_or([NONE16; 3]));
            }
        }
        self.write_tree(width, height)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests;
