//! The scene file as written: serde structs mirroring `docs/scene-format.md`.
//!
//! Numbers, vectors and whole shapes are validated while they are read (see [`super::values`]),
//! so ron reports the position. What needs the whole file (material, texture and mesh names)
//! is resolved afterwards in [`super::resolve`]; to point at a bad name it replays the parse
//! with a [`Ref`] primed to fail (see [`Ref`]).

use std::cell::Cell;
use std::collections::HashSet;
use std::fmt;
use std::marker::PhantomData;

use links_core::desc;
use serde::de::{self, Deserializer, MapAccess, Visitor};
use serde::Deserialize;

use super::tracks::{FramesFile, TrackFile};
use super::values::{self as v, Coef, ConeAngle, Normals, Num, NumVec, Uvs};

// ---- names that are resolved after the parse ---------------------------------------------------

thread_local! {
    /// Number of [`Ref`]s read so far in the current parse.
    static NEXT_REF: Cell<u32> = const { Cell::new(0) };
    /// During a replay: the [`Ref`] id that must fail.
    static FAIL_REF: Cell<Option<u32>> = const { Cell::new(None) };
}

/// The message a replayed [`Ref`] fails with; the caller swaps in the real message.
pub(super) const REPLAY_MARK: &str = "\u{1}replayed reference\u{1}";

/// Installs the [`Ref`] numbering for one parse (restoring the previous state on drop).
pub(super) struct RefScope {
    saved: (u32, Option<u32>),
}

impl RefScope {
    /// Start a parse; with `fail = Some(id)`, the [`Ref`] numbered `id` fails with
    /// [`REPLAY_MARK`].
    pub(super) fn new(fail: Option<u32>) -> Self {
        let saved = (
            NEXT_REF.with(|c| c.replace(0)),
            FAIL_REF.with(|c| c.replace(fail)),
        );
        Self { saved }
    }
}

impl Drop for RefScope {
    fn drop(&mut self) {
        NEXT_REF.with(|c| c.set(self.saved.0));
        FAIL_REF.with(|c| c.set(self.saved.1));
    }
}

/// A name or path that is looked up after the parse: a material, a texture, a mesh file.
///
/// Each `Ref` gets a sequence number in reading order. The parse is deterministic, so when a
/// lookup fails, parsing the same text again with `FAIL_REF = id` makes exactly this `Ref` fail
/// inside ron, and ron supplies its line and column; that is how name errors get positions
/// without ron exposing spans.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Ref {
    pub text: String,
    pub id: u32,
}

/// The next sequence number of a located value (a [`Ref`] or a [`Located`]); fails with
/// [`REPLAY_MARK`] when this is the one a replay is looking for.
fn next_ref_id<E: de::Error>() -> Result<u32, E> {
    let id = NEXT_REF.with(|c| {
        let id = c.get();
        c.set(id.wrapping_add(1));
        id
    });
    if FAIL_REF.with(Cell::get) == Some(id) {
        return Err(de::Error::custom(REPLAY_MARK));
    }
    Ok(id)
}

impl<'de> Deserialize<'de> for Ref {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        let id = next_ref_id()?;
        Ok(Ref { text, id })
    }
}

/// Any value that may be found wrong after the parse (a track's target, a key's time or
/// value), numbered like a [`Ref`] so a replay can point at it.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Located<T> {
    pub value: T,
    pub id: u32,
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Located<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let value = T::deserialize(d)?;
        let id = next_ref_id()?;
        Ok(Located { value, id })
    }
}

/// `{ "name": value, ... }` kept in file order (indices follow it); duplicate names rejected.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct NamedList<T>(pub Vec<(String, T)>);

impl<T> Default for NamedList<T> {
    fn default() -> Self {
        Self(Vec::new())
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for NamedList<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Vis<T>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for Vis<T> {
            type Value = NamedList<T>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a map { \"name\": ..., }")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut seen = HashSet::new();
                let mut out = Vec::new();
                while let Some(name) = map.next_key::<String>()? {
                    if !seen.insert(name.clone()) {
                        return Err(de::Error::custom(format!(
                            "the name \"{name}\" is defined twice"
                        )));
                    }
                    let value = map.next_value::<T>()?;
                    out.push((name, value));
                }
                Ok(NamedList(out))
            }
        }
        d.deserialize_map(Vis(PhantomData))
    }
}

// ---- the scene ---------------------------------------------------------------------------------

fn default_ambient() -> [f32; 3] {
    [0.1; 3]
}

fn default_depth() -> u32 {
    5
}

#[derive(Debug, Deserialize)]
#[serde(rename = "Scene", deny_unknown_fields)]
pub(super) struct SceneFile {
    pub camera: CameraFile,
    #[serde(default)]
    pub image: ImageFile,
    #[serde(default, deserialize_with = "v::color")]
    pub background: [f32; 3],
    #[serde(default = "default_ambient", deserialize_with = "v::color")]
    pub ambient: [f32; 3],
    #[serde(default = "default_depth", deserialize_with = "v::max_depth")]
    pub max_depth: u32,
    #[serde(default)]
    pub transparency: TransparencyFile,
    /// name -> PNG path.
    #[serde(default)]
    pub textures: NamedList<Ref>,
    #[serde(default)]
    pub materials: NamedList<MaterialFile>,
    #[serde(default)]
    pub lights: Vec<LightFile>,
    #[serde(default)]
    pub root: ClusterFile,
    /// The film's frames; a scene without them is a still (one frame, 0..1).
    #[serde(default)]
    pub frames: Option<FramesFile>,
    #[serde(default)]
    pub tracks: Vec<TrackFile>,
}

fn default_width() -> u32 {
    512
}

fn default_height() -> u32 {
    480
}

#[derive(Debug, Deserialize)]
#[serde(rename = "Image", deny_unknown_fields)]
pub(super) struct ImageFile {
    #[serde(default = "default_width", deserialize_with = "v::image_side")]
    pub width: u32,
    #[serde(default = "default_height", deserialize_with = "v::image_side")]
    pub height: u32,
}

impl Default for ImageFile {
    fn default() -> Self {
        Self {
            width: default_width(),
            height: default_height(),
        }
    }
}

#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(rename = "Transparency")]
pub(super) enum TransparencyFile {
    #[default]
    Refractive,
    NonRefractive,
}

impl From<TransparencyFile> for desc::TransparencyMode {
    fn from(t: TransparencyFile) -> Self {
        match t {
            TransparencyFile::Refractive => desc::TransparencyMode::Refractive,
            TransparencyFile::NonRefractive => desc::TransparencyMode::NonRefractive,
        }
    }
}

// ---- camera ------------------------------------------------------------------------------------

fn y_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

fn default_fov() -> f64 {
    45.0
}

#[derive(Debug, Deserialize)]
#[serde(rename = "Camera", deny_unknown_fields)]
struct RawCamera {
    #[serde(deserialize_with = "v::point")]
    eye: [f64; 3],
    #[serde(deserialize_with = "v::point")]
    look_at: [f64; 3],
    #[serde(default = "y_up", deserialize_with = "v::direction")]
    up: [f64; 3],
    #[serde(default = "default_fov", deserialize_with = "v::fov")]
    fov_y: f64,
}

/// Sine of the smallest angle allowed between `up` and the view direction (about 0.06°).
const MIN_UP_SINE: f64 = 1e-3;

#[derive(Debug, Deserialize)]
#[serde(try_from = "RawCamera")]
pub(super) struct CameraFile(pub desc::Camera);

impl TryFrom<RawCamera> for CameraFile {
    type Error = String;

    fn try_from(c: RawCamera) -> Result<Self, String> {
        let view = v::sub(c.look_at, c.eye);
        let Some(dir) = v::normalize(view) else {
            return Err(format!(
                "the camera's eye and look_at are the same point {}: there is no view direction",
                NumVec(&c.eye)
            ));
        };
        if v::length(v::cross(dir, c.up)) < MIN_UP_SINE {
            return Err(format!(
                "the camera's up {} is parallel to its view direction {}: \
                 choose an up that is not along the line from eye to look_at",
                NumVec(&c.up),
                NumVec(&dir)
            ));
        }
        Ok(CameraFile(desc::Camera {
            eye: c.eye,
            look_at: c.look_at,
            up: c.up,
            fov_y_deg: c.fov_y,
        }))
    }
}

// ---- materials ---------------------------------------------------------------------------------

fn default_diffuse() -> [f32; 3] {
    desc::Material::default().diffuse
}

fn default_shininess() -> f32 {
    desc::Material::default().shininess
}

fn default_ior() -> f32 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(rename = "Material", deny_unknown_fields)]
pub(super) struct MaterialFile {
    #[serde(default = "default_diffuse", deserialize_with = "v::rgb01")]
    pub diffuse: [f32; 3],
    #[serde(default, deserialize_with = "v::coef")]
    pub specular: f32,
    /// Defaults to `specular` (no variation with angle).
    #[serde(default)]
    pub specular_edge: Option<Coef>,
    #[serde(default = "default_shininess", deserialize_with = "v::shininess")]
    pub shininess: f32,
    #[serde(default, deserialize_with = "v::coef")]
    pub reflect: f32,
    /// Defaults to `reflect`.
    #[serde(default)]
    pub reflect_edge: Option<Coef>,
    #[serde(default, deserialize_with = "v::rgb01")]
    pub transmit: [f32; 3],
    #[serde(default = "default_ior", deserialize_with = "v::ior")]
    pub ior: f32,
    /// `arc`, the ambient reflection colour; defaults to the diffuse colour.
    #[serde(default)]
    pub ambient: Option<v::Rgb01>,
    #[serde(default)]
    pub map: Option<MapFile>,
}

fn one_one() -> [f32; 2] {
    [1.0, 1.0]
}

#[derive(Debug, Deserialize)]
#[serde(rename = "Map", deny_unknown_fields)]
pub(super) struct MapFile {
    pub texture: Ref,
    #[serde(default)]
    pub target: MapTargetFile,
    #[serde(default = "one_one", deserialize_with = "v::map_scale")]
    pub scale: [f32; 2],
}

#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(rename = "MapTarget")]
pub(super) enum MapTargetFile {
    #[default]
    Diffuse,
    Specular,
    Reflect,
    Transmit,
}

impl From<MapTargetFile> for desc::MapTarget {
    fn from(t: MapTargetFile) -> Self {
        match t {
            MapTargetFile::Diffuse => desc::MapTarget::Diffuse,
            MapTargetFile::Specular => desc::MapTarget::Specular,
            MapTargetFile::Reflect => desc::MapTarget::Reflect,
            MapTargetFile::Transmit => desc::MapTarget::Transmit,
        }
    }
}

// ---- lights ------------------------------------------------------------------------------------

fn white() -> [f32; 3] {
    [1.0; 3]
}

#[derive(Debug, Deserialize)]
#[serde(rename = "Light", deny_unknown_fields)]
enum RawLight {
    Directional {
        #[serde(deserialize_with = "v::direction")]
        dir: [f64; 3],
        #[serde(default = "white", deserialize_with = "v::color")]
        color: [f32; 3],
    },
    Point {
        #[serde(deserialize_with = "v::point")]
        pos: [f64; 3],
        #[serde(default = "white", deserialize_with = "v::color")]
        color: [f32; 3],
        #[serde(default)]
        falloff: bool,
    },
    Spot {
        #[serde(deserialize_with = "v::point")]
        pos: [f64; 3],
        #[serde(deserialize_with = "v::direction")]
        dir: [f64; 3],
        #[serde(default = "white", deserialize_with = "v::color")]
        color: [f32; 3],
        /// Defaults to `outer` (a hard-edged cone).
        #[serde(default)]
        inner: Option<ConeAngle>,
        #[serde(deserialize_with = "v::cone_angle")]
        outer: f64,
        #[serde(default, deserialize_with = "v::exponent")]
        exponent: f32,
    },
}

#[derive(Debug, Deserialize)]
#[serde(try_from = "RawLight")]
pub(super) struct LightFile(pub desc::Light);

impl TryFrom<RawLight> for LightFile {
    type Error = String;

    fn try_from(l: RawLight) -> Result<Self, String> {
        Ok(LightFile(match l {
            RawLight::Directional { dir, color } => desc::Light::Directional { dir, color },
            RawLight::Point {
                pos,
                color,
                falloff,
            } => desc::Light::Point {
                pos,
                color,
                falloff,
            },
            RawLight::Spot {
                pos,
                dir,
                color,
                inner,
                outer,
                exponent,
            } => {
                if outer <= 0.0 {
                    return Err("a spot light's outer cone angle must be positive".into());
                }
                let inner = inner.map_or(outer, |a| a.0);
                if inner > outer {
                    return Err(format!(
                        "a spot light's inner angle ({}) must not exceed its outer angle ({})",
                        Num(inner),
                        Num(outer)
                    ));
                }
                desc::Light::Spot {
                    pos,
                    dir,
                    color,
                    inner_deg: inner,
                    outer_deg: outer,
                    exponent,
                }
            }
        }))
    }
}

// ---- the cluster tree --------------------------------------------------------------------------

#[derive(Debug, Deserialize)]
#[serde(rename = "Transform", deny_unknown_fields)]
struct RawTransform {
    #[serde(default, deserialize_with = "v::point")]
    translate: [f64; 3],
    #[serde(default, deserialize_with = "v::angles")]
    rotate: [f64; 3],
    #[serde(default = "one3", deserialize_with = "v::scale3")]
    scale: [f64; 3],
}

fn one3() -> [f64; 3] {
    [1.0; 3]
}

#[derive(Debug, Default, Deserialize)]
#[serde(from = "RawTransform")]
pub(super) struct TransformFile(pub desc::Transform);

impl From<RawTransform> for TransformFile {
    fn from(t: RawTransform) -> Self {
        TransformFile(desc::Transform {
            translate: t.translate,
            rotate_deg: t.rotate,
            scale: t.scale,
        })
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename = "Cluster", deny_unknown_fields)]
pub(super) struct ClusterFile {
    #[serde(default)]
    pub name: String,
    #[serde(default)]
    pub transform: TransformFile,
    /// Material for the shapes below that name none.
    #[serde(default)]
    pub material: Option<Ref>,
    #[serde(default)]
    pub children: Vec<NodeFile>,
}

#[derive(Debug, Deserialize)]
#[serde(rename = "CutPlane", deny_unknown_fields)]
struct CutFile {
    #[serde(deserialize_with = "v::direction")]
    normal: [f64; 3],
    #[serde(default, deserialize_with = "v::offset")]
    offset: f64,
    #[serde(default = "yes")]
    capped: bool,
}

fn yes() -> bool {
    true
}

impl CutFile {
    fn into_desc(self) -> desc::CutPlane {
        desc::CutPlane {
            normal: self.normal,
            offset: self.offset,
            capped: self.capped,
        }
    }
}

#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(rename = "BlobKernel")]
enum KernelFile {
    #[default]
    Links,
    Wyvill,
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(rename = "Ball", deny_unknown_fields)]
struct BallFile {
    #[serde(deserialize_with = "v::point")]
    center: [f64; 3],
    #[serde(deserialize_with = "v::radius")]
    radius: f64,
    #[serde(default = "one", deserialize_with = "v::strength")]
    strength: f64,
}

/// The node variants as written.
#[derive(Debug, Deserialize)]
#[serde(rename = "Node", deny_unknown_fields)]
enum RawNode {
    Sphere {
        #[serde(deserialize_with = "v::point")]
        center: [f64; 3],
        #[serde(deserialize_with = "v::radius")]
        radius: f64,
        #[serde(default)]
        cut: Option<CutFile>,
        #[serde(default)]
        material: Option<Ref>,
    },
    Ellipsoid {
        #[serde(deserialize_with = "v::point")]
        center: [f64; 3],
        #[serde(deserialize_with = "v::radii")]
        radii: [f64; 3],
        #[serde(default, deserialize_with = "v::angles")]
        rotate: [f64; 3],
        #[serde(default)]
        cut: Option<CutFile>,
        #[serde(default)]
        material: Option<Ref>,
    },
    Box {
        #[serde(deserialize_with = "v::point")]
        min: [f64; 3],
        #[serde(deserialize_with = "v::point")]
        max: [f64; 3],
        #[serde(default)]
        material: Option<Ref>,
    },
    Triangle {
        #[serde(deserialize_with = "v::triangle")]
        v: [[f64; 3]; 3],
        #[serde(default)]
        normals: Option<Normals>,
        #[serde(default)]
        uv: Option<Uvs>,
        #[serde(default)]
        material: Option<Ref>,
    },
    Mesh {
        file: Ref,
        #[serde(default)]
        smooth: bool,
        #[serde(default)]
        material: Option<Ref>,
    },
    Blobs {
        /// For tracks that move the balls (`Ball("name", i, Center)`).
        #[serde(default)]
        name: String,
        #[serde(default)]
        kernel: KernelFile,
        #[serde(deserialize_with = "v::threshold")]
        threshold: f64,
        balls: Vec<BallFile>,
        #[serde(default)]
        material: Option<Ref>,
    },
    Cluster {
        #[serde(default)]
        name: String,
        #[serde(default)]
        transform: TransformFile,
        #[serde(default)]
        material: Option<Ref>,
        #[serde(default)]
        children: Vec<NodeFile>,
    },
}

/// A validated node; shapes carry `material: 0` until names are resolved.
#[derive(Debug, Deserialize)]
#[serde(try_from = "RawNode")]
pub(super) enum NodeFile {
    Cluster(ClusterFile),
    Shape {
        shape: desc::Shape,
        material: Option<Ref>,
        /// A Blobs shape's name ("" for the rest).
        name: String,
    },
    Mesh {
        file: Ref,
        smooth: bool,
        material: Option<Ref>,
    },
}

/// Checks that a cut plane leaves something of an axis-aligned ellipsoid with these radii.
fn check_cut(cut: &desc::CutPlane, radii: [f64; 3]) -> Result<(), String> {
    // The ellipsoid's support distance along the (unit) normal: max n·p over the ellipsoid.
    let h = (0..3)
        .map(|i| (radii[i] * cut.normal[i]).powi(2))
        .sum::<f64>()
        .sqrt();
    if cut.offset <= -h {
        return Err(format!(
            "the cut plane removes the whole ellipsoid: with this normal the offset must be \
             greater than {} (the kept side is normal · p <= offset), found {}",
            Num(-h),
            Num(cut.offset)
        ));
    }
    Ok(())
}

/// An ellipsoid shape, its cut plane (if any) checked against its radii.
fn ellipsoid(
    center: [f64; 3],
    radii: [f64; 3],
    rotate_deg: [f64; 3],
    cut: Option<CutFile>,
) -> Result<desc::Shape, String> {
    let cut = cut.map(CutFile::into_desc);
    if let Some(c) = &cut {
        check_cut(c, radii)?;
    }
    Ok(desc::Shape::Ellipsoid {
        center,
        radii,
        rotate_deg,
        cut,
        material: 0,
    })
}

/// A box shape; `min < max` on every axis.
fn box_shape(min: [f64; 3], max: [f64; 3]) -> Result<desc::Shape, String> {
    if let Some(axis) = (0..3).find(|&i| min[i] >= max[i]) {
        return Err(format!(
            "a box needs min < max on every axis, but on {} min = {} and max = {}",
            ["x", "y", "z"][axis],
            Num(min[axis]),
            Num(max[axis])
        ));
    }
    Ok(desc::Shape::Box {
        min,
        max,
        material: 0,
    })
}

/// A blob shape; at least one ball, one of them of positive strength.
fn blobs(kernel: KernelFile, threshold: f64, balls: Vec<BallFile>) -> Result<desc::Shape, String> {
    if balls.is_empty() {
        return Err("a Blobs shape needs at least one ball".into());
    }
    if !balls.iter().any(|b| b.strength > 0.0) {
        return Err(
            "a Blobs shape needs at least one ball of positive strength \
                    (negative balls only subtract)"
                .into(),
        );
    }
    Ok(desc::Shape::Blobs {
        balls: balls
            .into_iter()
            .map(|b| desc::Ball {
                center: b.center,
                radius: b.radius,
                strength: b.strength,
            })
            .collect(),
        threshold,
        kernel: match kernel {
            KernelFile::Links => desc::BlobKernel::Links,
            KernelFile::Wyvill => desc::BlobKernel::Wyvill,
        },
        material: 0,
    })
}

impl TryFrom<RawNode> for NodeFile {
    type Error = String;

    fn try_from(n: RawNode) -> Result<Self, String> {
        let shape = |shape, material| {
            Ok(NodeFile::Shape {
                shape,
                material,
                name: String::new(),
            })
        };
        match n {
            RawNode::Sphere {
                center,
                radius,
                cut,
                material,
            } => shape(ellipsoid(center, [radius; 3], [0.0; 3], cut)?, material),
            RawNode::Ellipsoid {
                center,
                radii,
                rotate,
                cut,
                material,
            } => shape(ellipsoid(center, radii, rotate, cut)?, material),
            RawNode::Box { min, max, material } => shape(box_shape(min, max)?, material),
            RawNode::Triangle {
                v,
                normals,
                uv,
                material,
            } => shape(
                desc::Shape::Triangle {
                    v,
                    normals: normals.map(|n| n.0),
                    uv: uv.map(|u| u.0),
                    material: 0,
                },
                material,
            ),
            RawNode::Mesh {
                file,
                smooth,
                material,
            } => Ok(NodeFile::Mesh {
                file,
                smooth,
                material,
            }),
            RawNode::Blobs {
                name,
                kernel,
                threshold,
                balls,
                material,
            } => Ok(NodeFile::Shape {
                shape: blobs(kernel, threshold, balls)?,
                material,
                name,
            }),
            RawNode::Cluster {
                name,
                transform,
                material,
                children,
            } => Ok(NodeFile::Cluster(ClusterFile {
                name,
                transform,
                material,
                children,
            })),
        }
    }
}
