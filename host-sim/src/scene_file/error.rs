//! [`SceneError`]: everything that can go wrong loading a scene, each with a place to look.

use std::fmt;
use std::path::PathBuf;

use crate::limits::ReadError;

/// An error loading a scene. Every variant names a file; all but [`SceneError::Io`] and
/// [`SceneError::Png`] also give a 1-based line and column (columns count characters).
///
/// `Display` prints the compiler-style `file:line:col: message`, e.g.
/// `scenes/x.ron:12:7: expected a positive radius, found 0`.
#[derive(Debug)]
#[non_exhaustive]
pub enum SceneError {
    /// The scene file itself could not be read: missing, not a regular file, or over
    /// [`crate::limits::MAX_SCENE_BYTES`].
    Io {
        path: PathBuf,
        source: Box<ReadError>,
    },
    /// The text is not RON, or not the structure a scene file has (ron's own diagnosis: a
    /// missing comma, an unknown field, a string where a number belongs, ...).
    Syntax {
        file: String,
        line: usize,
        col: usize,
        message: String,
    },
    /// The structure is right but a value is not acceptable (a zero radius, an unknown material
    /// name, a degenerate triangle, ...). The position is the start of the offending value.
    Invalid {
        file: String,
        line: usize,
        col: usize,
        message: String,
    },
    /// A mesh or texture file named in the scene at `file:line:col` could not be read
    /// (missing, not a regular file, or over its limit in [`crate::limits`]).
    Asset {
        file: String,
        line: usize,
        col: usize,
        /// "mesh" or "texture".
        kind: &'static str,
        /// The path the scene gave, resolved against the scene's directory.
        path: PathBuf,
        source: Box<ReadError>,
    },
    /// A Wavefront OBJ mesh is malformed. `line` is `None` for problems with the file as a
    /// whole (no faces); `col` is `None` when the whole line is at fault.
    Obj {
        file: String,
        line: Option<usize>,
        col: Option<usize>,
        message: String,
    },
    /// A PNG texture could not be decoded or is unsuitable (too large).
    Png { file: String, message: String },
}

impl SceneError {
    /// The (file, line, column) the error points at, when it has one.
    pub fn location(&self) -> Option<(&str, usize, usize)> {
        match self {
            SceneError::Syntax {
                file, line, col, ..
            }
            | SceneError::Invalid {
                file, line, col, ..
            }
            | SceneError::Asset {
                file, line, col, ..
            } => Some((file, *line, *col)),
            SceneError::Obj {
                file,
                line: Some(line),
                col,
                ..
            } => Some((file, *line, col.unwrap_or(1))),
            _ => None,
        }
    }

    /// The message without the position prefix.
    pub fn message(&self) -> String {
        match self {
            SceneError::Io { source, .. } => {
                format!("cannot read the scene file: {}", source.reason())
            }
            SceneError::Syntax { message, .. }
            | SceneError::Invalid { message, .. }
            | SceneError::Obj { message, .. }
            | SceneError::Png { message, .. } => message.clone(),
            SceneError::Asset {
                kind, path, source, ..
            } => format!(
                "cannot read {kind} file {}: {}",
                path.display(),
                source.reason()
            ),
        }
    }
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SceneError::Io { path, .. } => write!(f, "{}: {}", path.display(), self.message()),
            SceneError::Syntax {
                file, line, col, ..
            }
            | SceneError::Invalid {
                file, line, col, ..
            }
            | SceneError::Asset {
                file, line, col, ..
            } => write!(f, "{file}:{line}:{col}: {}", self.message()),
            SceneError::Obj {
                file,
                line,
                col,
                message,
            } => match (line, col) {
                (Some(l), Some(c)) => write!(f, "{file}:{l}:{c}: {message}"),
                (Some(l), None) => write!(f, "{file}:{l}: {message}"),
                _ => write!(f, "{file}: {message}"),
            },
            SceneError::Png { file, message } => write!(f, "{file}: {message}"),
        }
    }
}

impl std::error::Error for SceneError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            SceneError::Io { source, .. } | SceneError::Asset { source, .. } => Some(&**source),
            _ => None,
        }
    }
}
