//! `links readback`: read a rendered frame from a real RC over a serial port into a PNG.

use std::path::PathBuf;

use super::CliError;
use crate::cli_serial;

/// The options of `links readback`.
#[derive(clap::Args)]
pub struct ReadbackArgs {
    /// Serial port of the RC (e.g. /dev/ttyACM0)
    #[arg(long)]
    pub port: String,
    /// Output PNG file
    #[arg(short, long, default_value = "frame.png")]
    pub output: PathBuf,
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
    let line = cli_serial::readback_command(
        &a.port,
        &a.output,
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
