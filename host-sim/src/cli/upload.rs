//! `links upload`: compile a scene and send its SceneImage to a real RC over a serial port
//! (refused before anything is sent when no scene bank of the node board holds it); with
//! `--frames A..B`, stream a film and collect it ([`super::board_film`]).

use std::path::PathBuf;

use links_core::board::NodeBoard;

use super::args::SceneArgs;
use super::film::{parse_frames, FrameRange};
use super::{board_film, node, CliError};
use crate::cli_serial;

/// The options of `links upload`.
#[derive(clap::Args)]
pub struct UploadArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// The node computers' board (known: f407): a SceneImage larger than its scene bank is
    /// refused before anything is sent
    #[arg(long, default_value = nc_fw::plan::BOARD.name, value_parser = node::parse_node)]
    pub node: NodeBoard,
    /// Serial port of the RC (e.g. /dev/ttyACM0)
    #[arg(long)]
    pub port: String,
    /// Baud rate (a USB CDC port ignores it)
    #[arg(long, default_value_t = crate::serial_host::DEFAULT_BAUD)]
    pub baud: u32,
    /// How long to wait for the RC's answer to one message before sending it again, in ms
    #[arg(long, default_value_t = 1000)]
    pub timeout_ms: u64,
    /// Give up after this many seconds in all (default: from the scene size and baud rate; with
    /// --frames: none; 0: never)
    #[arg(long)]
    pub deadline_s: Option<u64>,
    /// Then ask the RC to render this many frames (of the one scene)
    #[arg(long, conflicts_with = "frames")]
    pub render: Option<u16>,
    /// Stream frames A..B-1 of a film: the PC compiles each frame (as `links render
    /// --frames`) and uploads it while the RC renders the one before, never more than one
    /// frame ahead, and collects the rendered frames on the same port into -o DIR/ as
    /// frame-NNNN.png plus the animated film.png. A still scene has the one frame 0..1
    #[arg(long, value_parser = parse_frames, value_name = "A..B")]
    pub frames: Option<FrameRange>,
    /// With --frames: the directory the frames are written to (default film/)
    #[arg(short, long, requires = "frames", value_name = "DIR")]
    pub output: Option<PathBuf>,
    /// With --frames: longest silence from the RC while reading a frame back before asking
    /// again (or giving up), in ms
    #[arg(long, default_value_t = 5000)]
    pub readback_timeout_ms: u64,
    /// No progress bar or summary line
    #[arg(short, long)]
    pub quiet: bool,
}

/// Runs `links upload`.
pub fn run(a: &UploadArgs) -> Result<(), CliError> {
    if let Some(range) = a.frames {
        return board_film::upload_film(a, range);
    }
    let image = a.scene.compile()?;
    node::check_fits(&a.scene.path()?.display().to_string(), image.len(), &a.node)?;
    let line = cli_serial::upload_command(
        &image,
        &a.port,
        a.baud,
        a.timeout_ms,
        a.deadline_s,
        a.render,
        a.quiet,
    )?;
    if !a.quiet {
        eprintln!("{line}");
    }
    Ok(())
}
