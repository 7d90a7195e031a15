//! `links info`: compile a scene, print its SceneImage size by section, optionally write the
//! bytes (`--image`).

use std::path::Path;

use links_core::image::SceneView;

use super::args::SceneArgs;
use super::error::write_file;
use super::CliError;
use crate::cli_image;

/// Runs `links info`.
pub fn run(scene: &SceneArgs, image: Option<&Path>) -> Result<(), CliError> {
    let bytes = scene.compile()?;
    let view = SceneView::new(&bytes).map_err(CliError::failed)?;
    for line in cli_image::describe(&scene.path()?.display().to_string(), &view) {
        outln!("{line}");
    }
    if let Some(path) = image {
        write_file(path, &bytes)?;
    }
    Ok(())
}
