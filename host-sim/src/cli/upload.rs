//! `links upload`: compile a scene and send its SceneImage to a real RC over a serial port
//! (refused before anything is sent when no scene bank of the node board holds it).

use links_core::board::NodeBoard;

use super::args::SceneArgs;
use super::{node, CliError};
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
    /// Give up after this many seconds in all (default: from the scene size and baud rate; 0: never)
    #[arg(long)]
    pub deadline_s: Option<u64>,
    /// Then ask the RC to render this many frames
    #[arg(long)]
    pub render: Option<u16>,
    /// No progress bar or summary line
    #[arg(short, long)]
    pub quiet: bool,
}

/// Runs `links upload`.
pub fn run(a: &UploadArgs) -> Result<(), CliError> {
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
