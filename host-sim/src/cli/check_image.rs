//! `links check-image`: validate a compiled SceneImage file and print its size by section.

use std::path::Path;

use super::CliError;
use crate::cli_image;

/// Runs `links check-image FILE`.
pub fn run(image: &Path) -> Result<(), CliError> {
    for line in cli_image::check_image(image)? {
        outln!("{line}");
    }
    Ok(())
}
