//! What an import could not carry over: returned with the scene, printed by the CLI on stderr.

use std::fmt;

#[derive(Clone, Debug, PartialEq)]
pub enum Warning {
    /// An animation channel not imported (morph-target weights, a node outside the imported
    /// scene, a second channel on the same property) or only partly (a camera or light node).
    AnimationTarget { channel: String, message: String },
    /// A CUBICSPLINE channel: imported as smooth (Catmull-Rom through the key values); the
    /// file's tangents are not used.
    CubicSpline { channel: String },
    /// A node's skin is ignored: the mesh is imported in its bind pose.
    Skin { node: String },
    /// Morph targets are ignored: the base shape is imported.
    MorphTargets { mesh: String, targets: usize },
    /// A primitive that is not TRIANGLES (points, lines, strips, fans) is skipped.
    PrimitiveMode { mesh: String, mode: String },
    /// A node matrix with shear or projection: the nearest rotation and scale are used.
    Shear { node: String },
    /// A texture that is not PNG: the material uses its factor colour only.
    ImageType { image: usize, mime: String },
    /// A material feature with no eq. 2.1 counterpart, ignored.
    MaterialFeature { material: String, feature: String },
    /// A perspective camera's own aspect ratio differs from the image; or an orthographic
    /// camera, skipped.
    Camera { camera: String, message: String },
    /// No usable camera: one framing the scene's bounding box was made.
    DefaultCamera,
    /// No KHR_lights_punctual light: one directional light was added.
    DefaultLight,
    /// A light's `range` (a cut-off distance) is ignored.
    LightRange { light: String },
    /// An extension the file uses (not required) that is ignored.
    Extension { name: String },
    /// The file has several scenes; only one is imported.
    OtherScenes { imported: usize, count: usize },
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Warning::AnimationTarget { channel, message } => write!(f, "{channel}: {message}"),
            Warning::CubicSpline { channel } => write!(
                f,
                "{channel}: CUBICSPLINE imported as smooth (Catmull-Rom through the key values); \
                 the file's tangents are approximated, not used"
            ),
            Warning::Skin { node } => {
                write!(
                    f,
                    "node '{node}': skin ignored (the mesh is imported unskinned)"
                )
            }
            Warning::MorphTargets { mesh, targets } => {
                write!(f, "mesh '{mesh}': {targets} morph targets ignored")
            }
            Warning::PrimitiveMode { mesh, mode } => {
                write!(
                    f,
                    "mesh '{mesh}': a {mode} primitive skipped (only TRIANGLES are imported)"
                )
            }
            Warning::Shear { node } => write!(
                f,
                "node '{node}': its matrix has shear or projection, which a cluster transform \
                 cannot hold; the nearest rotation and scale are used"
            ),
            Warning::ImageType { image, mime } => write!(
                f,
                "images[{image}] is {mime}, not PNG: its material uses the base colour factor only"
            ),
            Warning::MaterialFeature { material, feature } => {
                write!(f, "material '{material}': {feature} ignored")
            }
            Warning::Camera { camera, message } => write!(f, "camera '{camera}': {message}"),
            Warning::DefaultCamera => write!(
                f,
                "no perspective camera in the scene: a camera framing its bounding box was added"
            ),
            Warning::DefaultLight => write!(
                f,
                "no KHR_lights_punctual light in the scene: one directional light was added"
            ),
            Warning::LightRange { light } => {
                write!(
                    f,
                    "light '{light}': range ignored (lights reach the whole scene)"
                )
            }
            Warning::Extension { name } => write!(f, "extension {name} ignored"),
            Warning::OtherScenes { imported, count } => write!(
                f,
                "the file has {count} scenes; only scene {imported} was imported"
            ),
        }
    }
}
