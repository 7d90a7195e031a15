//! The `links` command line: the clap definition of every subcommand, a file per subcommand
//! with its options and its run function, and [`main`], which dispatches and turns a
//! [`CliError`] into one `error: ...` line and exit status 1.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// `println!` that ends the program quietly when stdout is closed (`links ... | head`).
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write;
        if let Err(e) = writeln!(std::io::stdout().lock(), $($arg)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
            eprintln!("error: cannot write to stdout: {e}");
            std::process::exit(1);
        }
    }};
}

pub mod args;
pub use crate::studies::backend;
pub mod board_film;
pub mod calibrate;
pub mod chart;
pub mod check_image;
pub mod compare;
pub mod error;
pub mod film;
pub mod gen_assets;
pub mod image_file;
pub mod info;
pub mod node;
pub mod readback;
pub mod render;
pub mod sweep;
pub mod upload;

pub use backend::Backend;
pub use error::CliError;

use args::SceneArgs;
use links_core::board::NodeBoard;

/// The `links` command line.
#[derive(Parser)]
#[command(
    name = "links",
    version,
    about = "LINKS-1 ray tracer: render scenes, inspect scene images"
)]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Cmd,
}

/// The subcommands of `links`.
#[derive(Subcommand)]
pub enum Cmd {
    /// Render a scene (or a compiled SceneImage, --image) to a PNG file
    #[command(mut_arg("scene", |a| a.required(false).required_unless_present("image")))]
    Render(Box<render::RenderArgs>),
    /// Check a compiled SceneImage file and print its size by section
    CheckImage {
        /// SceneImage file (as `info --image` writes)
        image: PathBuf,
    },
    /// Compile a scene and print its SceneImage size by section
    Info {
        #[command(flatten)]
        scene: SceneArgs,
        /// Also write the SceneImage bytes to this file
        #[arg(long)]
        image: Option<PathBuf>,
        /// Also give each section's share and the fit against this node board's two scene
        /// banks (known: f407)
        #[arg(long, value_parser = node::parse_node)]
        node: Option<NodeBoard>,
    },
    /// Render a scene in a number format and in f64 and report how far apart they are
    Compare {
        #[command(flatten)]
        scene: SceneArgs,
        /// The number format to measure: f32, f32-fast (micromath's approximations) or fixed
        /// (Q16.16)
        #[arg(long, default_value = "f32")]
        backend: String,
        /// Host threads (0 = all cores, at most 256)
        #[arg(long, default_value_t = 0, value_parser = crate::limits::parse_threads)]
        threads: usize,
    },
    /// Compile a scene and send its SceneImage to a real RC over a serial port
    Upload(upload::UploadArgs),
    /// Read a rendered frame from a real RC over a serial port and write it as a PNG
    Readback(readback::ReadbackArgs),
    /// Measurement sweeps
    #[command(subcommand)]
    Sweep(sweep::SweepCmd),
    /// Charts of measured results
    #[command(subcommand)]
    Chart(chart::ChartCmd),
    /// Fit the cycle model's weights to QEMU-measured frames (scripts/qemu-bench's CSV)
    Calibrate {
        /// CSV written by scripts/qemu-bench
        #[arg(long, default_value = "docs/cortex-m-bench.csv")]
        csv: PathBuf,
        /// Which target's samples to fit
        #[arg(long, default_value = "thumbv7em-none-eabihf")]
        target: String,
        /// Which number backend's samples to fit (f32, q16.16)
        #[arg(long, default_value = "f32")]
        backend: String,
    },
    /// Regenerate the procedural meshes and textures of the bundled scenes
    GenAssets {
        /// Output directory
        #[arg(long, default_value = "scenes/assets")]
        dir: PathBuf,
    },
}

/// Parses `args` (the program name first, as `std::env::args_os` gives them) and runs the
/// command: the `links` binary as a library call, for tests.
pub fn run_from<I, T>(args: I) -> Result<(), CliError>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = Cli::try_parse_from(args).map_err(|e| CliError::Usage(e.to_string()))?;
    run(cli)
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> Result<(), CliError> {
    match cli.cmd {
        Cmd::Render(a) => render::run(*a),
        Cmd::CheckImage { image } => check_image::run(&image),
        Cmd::Info { scene, image, node } => info::run(&scene, image.as_deref(), node.as_ref()),
        Cmd::Compare {
            scene,
            backend,
            threads,
        } => compare::run(&scene, &backend, threads),
        Cmd::Upload(a) => upload::run(&a),
        Cmd::Readback(a) => readback::run(&a),
        Cmd::Sweep(cmd) => sweep::run(cmd),
        Cmd::Chart(cmd) => chart::run(cmd),
        Cmd::Calibrate {
            csv,
            target,
            backend,
        } => calibrate::run(&csv, &target, &backend),
        Cmd::GenAssets { dir } => gen_assets::run(&dir),
    }
}

/// The `links` program: parse the command line, run it, report a failure on stderr.
pub fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
