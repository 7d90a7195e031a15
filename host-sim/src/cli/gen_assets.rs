//! `links gen-assets`: regenerate the procedural meshes and textures of the bundled scenes.

use std::path::Path;

use super::CliError;

/// Runs `links gen-assets --dir DIR`.
pub fn run(dir: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(dir).map_err(CliError::write(dir))?;
    let written = crate::gen::write_bundled_assets(dir)
        .map_err(|e| CliError::Failed(format!("{}: {e}", dir.display())))?;
    for p in written {
        outln!("wrote {}", p.display());
    }
    Ok(())
}
