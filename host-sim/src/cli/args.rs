//! Option groups shared by several subcommands: the scene and its overrides, the number type
//! and the transparency mode; and turning them into a SceneImage.

use std::path::{Path, PathBuf};

use clap::ValueEnum;
use links_core::desc::TransparencyMode;
use links_core::dm::{compile, CompileOptions};

use super::CliError;
use crate::cli_image;
use crate::frame::Precision;
use crate::gltf_import;
use crate::limits;
use crate::scene_file::{load_film, load_scene};
use links_core::anim::Film;
use links_core::desc::SceneDesc;

/// `--precision`: the number type of a render.
#[derive(Clone, Copy, ValueEnum)]
pub enum PrecisionArg {
    F32,
    F64,
    /// Q16.16 fixed point (the DM rescales the scene to fit)
    Fixed,
}

impl From<PrecisionArg> for Precision {
    fn from(p: PrecisionArg) -> Self {
        match p {
            PrecisionArg::F32 => Precision::F32,
            PrecisionArg::F64 => Precision::F64,
            PrecisionArg::Fixed => Precision::Fixed,
        }
    }
}

/// `--transparency`: override the scene's transparency mode.
#[derive(Clone, Copy, ValueEnum)]
pub enum TransparencyArg {
    Refractive,
    NonRefractive,
}

impl From<TransparencyArg> for TransparencyMode {
    fn from(t: TransparencyArg) -> Self {
        match t {
            TransparencyArg::Refractive => TransparencyMode::Refractive,
            TransparencyArg::NonRefractive => TransparencyMode::NonRefractive,
        }
    }
}

/// A scene file and the settings the command line may override.
#[derive(clap::Args)]
pub struct SceneArgs {
    /// Scene file (.ron), or a glTF 2.0 model (.gltf, .glb)
    #[arg(required = true)]
    pub scene: Option<PathBuf>,
    /// Image width in pixels, 1..=4096 (default: the scene's)
    #[arg(long, value_parser = limits::parse_image_side)]
    pub width: Option<u32>,
    /// Image height in pixels, 1..=4096 (default: the scene's)
    #[arg(long, value_parser = limits::parse_image_side)]
    pub height: Option<u32>,
    /// Maximum recursion depth for reflection/refraction, 0..=16 (default: the scene's)
    #[arg(long, value_parser = limits::parse_max_depth)]
    pub max_depth: Option<u32>,
    /// Override the scene's transparency mode
    #[arg(long, value_enum)]
    pub transparency: Option<TransparencyArg>,
    /// Render without shadows (no shadow rays)
    #[arg(long)]
    pub no_shadows: bool,
    /// Most triangles in one leaf of the tree, 1..=31 (default 8): larger leaves make a
    /// smaller SceneImage and test more triangles per ray
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=31))]
    pub leaf_size: Option<u8>,
    /// Anti-aliasing: N x N primary rays per pixel on a regular sub-pixel grid, averaged
    /// (traced on the nodes), 1..=8 (default 1: one ray through each pixel's centre)
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=8))]
    pub aa: Option<u8>,
}

impl SceneArgs {
    /// Scene arguments with every option at the scene's own setting.
    pub fn plain(scene: &Path) -> SceneArgs {
        SceneArgs {
            scene: Some(scene.to_path_buf()),
            width: None,
            height: None,
            max_depth: None,
            transparency: None,
            no_shadows: false,
            leaf_size: None,
            aa: None,
        }
    }

    /// The scene file (clap requires it wherever `--image` is not given).
    pub fn path(&self) -> Result<&Path, CliError> {
        self.scene
            .as_deref()
            .ok_or_else(|| CliError::Usage("a scene file is required".to_string()))
    }

    /// The DM's options these overrides give.
    pub fn compile_options(&self) -> CompileOptions {
        CompileOptions {
            width: self.width,
            height: self.height,
            max_depth: self.max_depth,
            transparency: self.transparency.map(TransparencyMode::from),
            mesh_hierarchy: Default::default(),
            no_shadows: self.no_shadows,
            leaf_size: self.leaf_size.map(usize::from),
            aa: self.aa.map(u32::from),
        }
    }

    /// The scene compiled with the overrides: its SceneImage bytes.
    pub fn compile(&self) -> Result<Vec<u8>, CliError> {
        let path = self.path()?;
        let desc = load_desc(path)?;
        let opts = self.compile_options();
        let compiled = compile(&desc, &opts)
            .map_err(|e| CliError::Scene(format!("{}: {e}", path.display())))?;
        Ok(compiled.bytes)
    }
}

/// The scene at `path`: a scene file, or a glTF model (`.gltf`/`.glb`) whose import warnings
/// are printed on stderr. For a film, its first frame.
pub fn load_desc(path: &Path) -> Result<SceneDesc, CliError> {
    if gltf_import::is_gltf_path(path) {
        let film = load_film_any(path)?;
        film.scene_at(film.timeline().start)
            .map_err(|e| CliError::Scene(format!("{}: {e}", path.display())))
    } else {
        load_scene(path).map_err(|e| CliError::Scene(e.to_string()))
    }
}

/// The film at `path`: a scene file's frames and tracks, or a glTF model's animations as
/// tracks (import warnings printed on stderr).
pub fn load_film_any(path: &Path) -> Result<Film, CliError> {
    if gltf_import::is_gltf_path(path) {
        let imported = gltf_import::import(path).map_err(|e| CliError::Scene(e.to_string()))?;
        for w in &imported.warnings {
            eprintln!("{}: warning: {w}", path.display());
        }
        imported
            .film()
            .map_err(|e| CliError::Scene(format!("{}: {e}", path.display())))
    } else {
        load_film(path).map_err(|e| CliError::Scene(e.to_string()))
    }
}

/// The SceneImage to render: the `--image` file (validated, frame within the host's limit),
/// or the scene compiled; and the number type its storage allows.
pub fn image_to_render(
    a: &SceneArgs,
    file: Option<&Path>,
    asked: Option<Precision>,
) -> Result<(Vec<u8>, Precision), CliError> {
    match file {
        Some(path) => Ok(cli_image::for_render(path, asked)?),
        None => Ok((a.compile()?, asked.unwrap_or_default())),
    }
}
