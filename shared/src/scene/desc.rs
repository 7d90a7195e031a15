//! The scene as a person describes it, before the DM compiles it (host side, needs `std`).
//!
//! This is the semantic model the scene-file loader produces and the DM consumes: world
//! coordinates, a cluster tree with transforms, named materials already resolved to indices.
//! Every number in here has been validated by the loader (finite, non-degenerate); the DM
//! re-checks what it relies on and reports a [`crate::dm::DmError`] otherwise.

use std::string::String;
use std::vec::Vec;

/// The eye: LINKS-1 places it at the origin of view coordinates, looking along +Z.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub eye: [f64; 3],
    pub look_at: [f64; 3],
    pub up: [f64; 3],
    /// Full vertical field of view in degrees, in (0, 180).
    pub fov_y_deg: f64,
}

/// How transmitted light is computed (LINKS-1 section 4.5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TransparencyMode {
    /// Snell refraction with total internal reflection, recursive to `max_depth`; at the
    /// depth cut-off the transmitted ray continues straight (non-refractive).
    #[default]
    Refractive,
    /// Straight-through transparency everywhere, attenuated by every surface crossed.
    NonRefractive,
}

/// Which surface attribute a texture map modulates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum MapTarget {
    /// Multiplies the diffuse colour `drc` (a colour texture).
    #[default]
    Diffuse,
    /// Multiplies the specular coefficient by the map's luminance.
    Specular,
    /// Multiplies the reflection coefficient by the map's luminance.
    Reflect,
    /// Multiplies the transmittance by the map's luminance.
    Transmit,
}

#[derive(Clone, Debug, PartialEq)]
pub struct TextureMap {
    /// Index into [`SceneDesc::textures`].
    pub texture: u32,
    pub target: MapTarget,
    /// Repeats of the texture per unit of the surface parameter (u, v).
    pub scale: [f32; 2],
}

/// Surface attributes of eq. 2.1 / 2.2.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// `drc`: diffuse reflection colour (also scales the ambient term unless `ambient` is set).
    pub diffuse: [f32; 3],
    /// `src(θ)` at normal incidence.
    pub specular: f32,
    /// `src(θ)` at grazing incidence; between the two, Schlick's (1 - cos θ)^5 blend.
    pub specular_edge: f32,
    /// Phong exponent `n`.
    pub shininess: f32,
    /// `rc(θ)` at normal incidence.
    pub reflect: f32,
    /// `rc(θ)` at grazing incidence.
    pub reflect_edge: f32,
    /// `tc`: transmittance per surface crossing, per channel.
    pub transmit: [f32; 3],
    /// Index of refraction of the material (the outside is taken as air, 1.0).
    pub ior: f32,
    /// `arc`: the ambient reflection colour, used instead of `diffuse` in eq. 2.1's ambient
    /// term (a diffuse texture map scales it as it scales `diffuse`); `None`: the diffuse
    /// colour, as in the paper.
    pub ambient: Option<[f32; 3]>,
    pub map: Option<TextureMap>,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: String::from("default"),
            diffuse: [0.8, 0.8, 0.8],
            specular: 0.0,
            specular_edge: 0.0,
            shininess: 20.0,
            reflect: 0.0,
            reflect_edge: 0.0,
            transmit: [0.0, 0.0, 0.0],
            ior: 1.0,
            ambient: None,
            map: None,
        }
    }
}

/// An RGB8 image, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    /// Parallel light travelling along `dir` (from the light into the scene).
    Directional { dir: [f64; 3], color: [f32; 3] },
    /// Point light; with `falloff` the intensity is `color / d²` (d in scene units).
    Point {
        pos: [f64; 3],
        color: [f32; 3],
        falloff: bool,
    },
    /// Spot light at `pos` aimed along `dir`: full intensity inside `inner_deg` of the axis,
    /// none outside `outer_deg`, smooth in between, times cos^`exponent` of the off-axis angle.
    Spot {
        pos: [f64; 3],
        dir: [f64; 3],
        color: [f32; 3],
        inner_deg: f64,
        outer_deg: f64,
        exponent: f32,
    },
}

/// Translate, rotate (degrees about X, then Y, then Z), scale; applied as
/// `p' = T · Rz · Ry · Rx · S · p`.
#[derive(Clone, Debug, PartialEq)]
pub struct Transform {
    pub translate: [f64; 3],
    pub rotate_deg: [f64; 3],
    pub scale: [f64; 3],
}

impl Default for Transform {
    fn default() -> Self {
        Self {
            translate: [0.0; 3],
            rotate_deg: [0.0; 3],
            scale: [1.0; 3],
        }
    }
}

/// One vertex of a mesh face: indices into the mesh's arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FaceVertex {
    pub position: u32,
    pub normal: Option<u32>,
    pub uv: Option<u32>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Where it came from, for error messages ("camera.obj").
    pub source: String,
    pub positions: Vec<[f64; 3]>,
    pub normals: Vec<[f64; 3]>,
    pub uvs: Vec<[f64; 2]>,
    pub faces: Vec<[FaceVertex; 3]>,
    /// The modeller's parts (OBJ `g`/`o`), in face order; empty for an ungrouped mesh.
    pub groups: Vec<MeshGroup>,
}

/// A named run of consecutive faces of a mesh, from `first_face` to the next group's start.
/// The DM makes each group a sub-cluster of its mesh (LINKS-1 4.1: the cluster hierarchy
/// follows the object's structure).
#[derive(Clone, Debug, PartialEq)]
pub struct MeshGroup {
    pub name: String,
    pub first_face: u32,
}

/// `kernel` of a density-sphere group (LINKS-1 2, primitive 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BlobKernel {
    /// Nishimura et al.: b(1-3r²/d²) for r <= d/3, (3b/2)(1-r/d)² for r <= d, 0 beyond.
    #[default]
    Links,
    /// b(1-r²/d²)² for r <= d, 0 beyond (smooth, "soft objects").
    Wyvill,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball {
    pub center: [f64; 3],
    /// Radius of influence `d`.
    pub radius: f64,
    /// Peak density `b` (negative subtracts).
    pub strength: f64,
}

/// A plane cutting an ellipsoid, in the ellipsoid's own coordinates (origin at its centre, before
/// its rotation): points with `normal · p <= offset` are kept.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutPlane {
    pub normal: [f64; 3],
    pub offset: f64,
    /// Close the cut with a flat cap (a solid), or leave it open (a shell you can see into).
    pub capped: bool,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// One triangle; `normals` per vertex give smooth shading (else the face normal).
    Triangle {
        v: [[f64; 3]; 3],
        normals: Option<[[f64; 3]; 3]>,
        uv: Option<[[f64; 2]; 3]>,
        material: u32,
    },
    /// A triangle mesh (from OBJ); per-vertex normals interpolate, `smooth` computes them
    /// from the faces when the mesh has none.
    Mesh {
        mesh: Mesh,
        material: u32,
        smooth: bool,
    },
    /// An ellipsoid (sphere when the radii are equal), rotated, optionally cut by a plane.
    Ellipsoid {
        center: [f64; 3],
        radii: [f64; 3],
        rotate_deg: [f64; 3],
        cut: Option<CutPlane>,
        material: u32,
    },
    /// A box `[min, max]` in its cluster's coordinates (transformed with the cluster).
    Box {
        min: [f64; 3],
        max: [f64; 3],
        material: u32,
    },
    /// A group of density spheres whose summed field forms one iso-surface.
    Blobs {
        balls: Vec<Ball>,
        threshold: f64,
        kernel: BlobKernel,
        material: u32,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub enum Node {
    Cluster(Cluster),
    Shape(Shape),
}

/// A node of the cluster hierarchy (LINKS-1 4.1): moving a cluster moves all below it.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Cluster {
    pub name: String,
    pub transform: Transform,
    pub children: Vec<Node>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct SceneDesc {
    pub camera: Camera,
    /// Default output size (the CLI can override it).
    pub width: u32,
    pub height: u32,
    pub background: [f32; 3],
    /// `Ia`: global ambient light.
    pub ambient: [f32; 3],
    pub max_depth: u32,
    pub transparency: TransparencyMode,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub lights: Vec<Light>,
    pub root: Cluster,
}
