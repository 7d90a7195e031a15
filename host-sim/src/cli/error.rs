//! `CliError`: why a `links` subcommand failed. `main` prints it as one `error: ...` line and
//! exits with status 1.

use std::fmt;
use std::path::PathBuf;

use crate::cli_image::ImageFileError;

/// Why a `links` subcommand failed.
#[derive(Debug)]
#[non_exhaustive]
pub enum CliError {
    /// Options that can't go together, or a value outside what the subcommand accepts.
    Usage(String),
    /// A scene file that could not be loaded or compiled (the message names the file).
    Scene(String),
    /// A compiled SceneImage file that can't be used.
    Image(ImageFileError),
    /// A file could not be written or a directory created.
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A SceneImage (`bytes` long, of the scene or image file `what`) larger than the scene
    /// bank (`bank` bytes) of the node board `node`: refused before anything is sent.
    DoesNotFit {
        what: String,
        bytes: usize,
        node: &'static str,
        bank: usize,
    },
    /// A failure reported as text by the module that did the work (simulator, serial link,
    /// renderer, chart and cost-model readers).
    Failed(String),
}

impl CliError {
    /// A [`CliError::Failed`] from any displayable error.
    pub fn failed(e: impl fmt::Display) -> Self {
        CliError::Failed(e.to_string())
    }

    /// A [`CliError::Write`] for `path`.
    pub fn write(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| CliError::Write { path, source }
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Usage(m) | CliError::Scene(m) | CliError::Failed(m) => f.write_str(m),
            CliError::Image(e) => write!(f, "{e}"),
            CliError::Write { path, source } => write!(f, "{}: {source}", path.display()),
            CliError::DoesNotFit {
                what,
                bytes,
                node,
                bank,
            } => write!(
                f,
                "{what}: SceneImage {} bytes does not fit the {node} node's scene bank ({} bytes)",
                super::node::grouped(*bytes),
                super::node::grouped(*bank)
            ),
        }
    }
}

impl std::error::Error for CliError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            CliError::Image(e) => Some(e),
            CliError::Write { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl From<String> for CliError {
    fn from(m: String) -> Self {
        CliError::Failed(m)
    }
}

impl From<crate::sim::options::OptionError> for CliError {
    fn from(e: crate::sim::options::OptionError) -> Self {
        CliError::Usage(e.to_string())
    }
}

impl From<ImageFileError> for CliError {
    fn from(e: ImageFileError) -> Self {
        CliError::Image(e)
    }
}

/// Writes `bytes` to `path`, naming the file on failure.
pub fn write_file(path: &std::path::Path, bytes: impl AsRef<[u8]>) -> Result<(), CliError> {
    std::fs::write(path, bytes).map_err(CliError::write(path))
}
