//! A scene file loaded and compiled by the DM at a given frame size with every other option at
//! the scene's own setting: the one way tools and tests turn a bundled scene into a SceneImage.

use std::fmt;
use std::path::{Path, PathBuf};

use links_core::dm::{compile, CompileOptions, DmError};

use super::{load_scene, SceneError};

/// Why [`compile_at`] failed.
#[derive(Debug)]
pub enum CompileAtError {
    /// The scene file could not be loaded (the error names the file).
    Load(SceneError),
    /// The DM refused the scene.
    Compile { path: PathBuf, source: DmError },
}

impl fmt::Display for CompileAtError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CompileAtError::Load(e) => write!(f, "{e}"),
            CompileAtError::Compile { path, source } => {
                write!(f, "{}: {source}", path.display())
            }
        }
    }
}

impl std::error::Error for CompileAtError {}

/// The SceneImage bytes of the scene file `path` compiled at `width` x `height`.
pub fn compile_at(path: &Path, width: u32, height: u32) -> Result<Vec<u8>, CompileAtError> {
    let desc = load_scene(path).map_err(CompileAtError::Load)?;
    let opts = CompileOptions {
        width: Some(width),
        height: Some(height),
        ..CompileOptions::default()
    };
    compile(&desc, &opts)
        .map(|c| c.bytes)
        .map_err(|source| CompileAtError::Compile {
            path: path.to_path_buf(),
            source,
        })
}
