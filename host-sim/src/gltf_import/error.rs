//! The errors of a glTF import: each names the file and, where it can, the JSON path or index.

use std::fmt;

use crate::limits::ReadError;

#[derive(Debug)]
pub enum GltfError {
    /// The file, or a buffer or image file it names, cannot be read (missing, too large, ...).
    Read(ReadError),
    /// Not glTF: bad JSON, a bad GLB header or chunk.
    Parse { file: String, message: String },
    /// The JSON is glTF but breaks the specification (an index out of range, a missing field);
    /// `path` is the JSON path, e.g. `meshes[0].primitives[0].attributes["POSITION"]`.
    Invalid {
        file: String,
        path: String,
        message: String,
    },
    /// `extensionsRequired` names an extension this importer does not implement.
    RequiredExtension { file: String, name: String },
    /// A buffer's data is missing, malformed (bad `data:` URI) or shorter than declared.
    Buffer {
        file: String,
        buffer: usize,
        message: String,
    },
    /// An accessor or buffer view reaches past the data it reads.
    Accessor {
        file: String,
        path: String,
        message: String,
    },
    /// A triangle refers to a vertex the primitive does not have.
    VertexIndex {
        file: String,
        mesh: usize,
        primitive: usize,
        index: u32,
        vertices: usize,
    },
    /// A base-colour image that claims to be PNG does not decode.
    Image {
        file: String,
        image: usize,
        message: String,
    },
    /// The document has no scene to import, or its scene has no triangles.
    Empty { file: String, message: String },
    /// An animation channel is malformed (`path` e.g. `animations[0].channels[1]`): times not
    /// increasing, outputs of the wrong type or count.
    Animation {
        file: String,
        path: String,
        message: String,
    },
    /// The node graph is deeper than the cluster tree allows, or expands to too many nodes.
    TooLarge { file: String, message: String },
}

impl fmt::Display for GltfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GltfError::Read(e) => write!(f, "{e}"),
            GltfError::Parse { file, message } => {
                write!(f, "{file}: not a glTF 2.0 file: {message}")
            }
            GltfError::Invalid {
                file,
                path,
                message,
            } => write!(f, "{file}: {path}: {message}"),
            GltfError::RequiredExtension { file, name } => write!(
                f,
                "{file}: extensionsRequired names `{name}`, which this importer does not support"
            ),
            GltfError::Buffer {
                file,
                buffer,
                message,
            } => write!(f, "{file}: buffers[{buffer}]: {message}"),
            GltfError::Accessor {
                file,
                path,
                message,
            } => write!(f, "{file}: {path}: {message}"),
            GltfError::Animation {
                file,
                path,
                message,
            } => write!(f, "{file}: {path}: malformed animation channel: {message}"),
            GltfError::VertexIndex {
                file,
                mesh,
                primitive,
                index,
                vertices,
            } => write!(
                f,
                "{file}: meshes[{mesh}].primitives[{primitive}]: vertex index {index} out of range \
                 (the primitive has {vertices} vertices)"
            ),
            GltfError::Image {
                file,
                image,
                message,
            } => write!(f, "{file}: images[{image}]: {message}"),
            GltfError::Empty { file, message } | GltfError::TooLarge { file, message } => {
                write!(f, "{file}: {message}")
            }
        }
    }
}

impl std::error::Error for GltfError {}
