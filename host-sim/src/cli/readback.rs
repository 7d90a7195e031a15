//! `links readback`: read a rendered frame from a real RC over a serial port into a PNG;
//! with `--frames A..B`, frames A..B-1 into a directory ([`super::board_film`]).

use std::path::PathBuf;

use super::film::{parse_frames, FrameRange};
use super::{board_film, CliError};
use crate::cli_serial;

/// The options of `links readback`.
#[derive(clap::Args)]
pub struct ReadbackArgs {
    /// Serial port of the RC (e.g. /dev/ttyACM0)
    #[arg(long)]
    pub port: String,
    /// Output PNG file (default frame.png); with --frames, the directory (default film/)
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Collect frames A..B-1 (tagged with their numbers by the RC, e.g. 0..N after `links
    /// upload SCENE --render N`) as DIR/frame-NNNN.png plus the animated DIR/film.png, each
    /// CRC-checked. (A film streamed with `links upload --frames` is collected by that
    /// command itself: one port has one reader)
    #[arg(long, value_parser = parse_frames, value_name = "A..B")]
    pub frames: Option<FrameRange>,
    /// With --frames: frames per second of the animated film.png
    #[arg(long, default_value_t = 24.0)]
    pub rate: f64,
    /// Baud rate (a USB CDC port ignores it)
    #[arg(long, default_value_t = crate::serial_host::DEFAULT_BAUD)]
    pub baud: u32,
    /// Longest silence from the RC before giving up (or asking again), in ms
    #[arg(long, default_value_t = 5000)]
    pub timeout_ms: u64,
    /// Give up after this many seconds in all (default: none, the progress rules of docs/serial.md end a misbehaving RC)
    #[arg(long)]
    pub deadline_s: Option<u64>,
    /// No progress bar or summary line
    #[arg(short, long)]
    pub quiet: bool,
}

/// Runs `links readback`.
pub fn run(a: &ReadbackArgs) -> Result<(), CliError> {
    if let Some(range) = a.frames {
        return board_film::readback_film(a, range);
    }
    let output = a
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from("frame.png"));
    let line = cli_serial::readback_command(
        &a.port,
        &output,
        a.baud,
        a.timeout_ms,
        a.deadline_s,
        a.quiet,
    )?;
    if !a.quiet {
        eprintln!("{line}");
    }
    Ok(())
}
