//! `links info`: compile a scene, print its SceneImage size by section, optionally write the
//! bytes (`--image`); with `--node`, each section's share and the fit against that node
//! board's scene banks.

use std::path::Path;

use links_core::board::NodeBoard;
use links_core::image::SceneView;

use super::args::SceneArgs;
use super::error::write_file;
use super::{node, CliError};
use crate::cli_image;

/// Runs `links info`.
pub fn run(
    scene: &SceneArgs,
    image: Option<&Path>,
    board: Option<&NodeBoard>,
) -> Result<(), CliError> {
    let bytes = scene.compile()?;
    let view = SceneView::new(&bytes).map_err(CliError::failed)?;
    let name = scene.path()?.display().to_string();
    for line in cli_image::describe(&name, &view, board.is_some()) {
        outln!("{line}");
    }
    for line in board
        .map(|b| node::fit_lines(bytes.len(), b))
        .unwrap_or_default()
    {
        outln!("{line}");
    }
    if let Some(path) = image {
        write_file(path, &bytes)?;
    }
    Ok(())
}
