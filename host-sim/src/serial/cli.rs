//! The `links upload` and `links readback` commands: progress bars and messages around
//! [`crate::serial_host`].

use crate::serial::host::{
    open_port, readback, upload, upload_deadline, ReadbackEvent, ReadbackOptions, UploadOptions,
};
use crate::sim::single::encode_png;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::Path;
use std::time::Duration;

pub fn bar(quiet: bool, len: u64, template: &str) -> ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template(template) {
        b.set_style(style);
    }
    b
}

/// `--deadline-s`: `None` when absent, `Some(None)` for 0 (no overall deadline).
pub fn deadline(deadline_s: Option<u64>) -> Option<Option<Duration>> {
    deadline_s.map(|s| (s > 0).then(|| Duration::from_secs(s)))
}

/// Open `port` for a command whose reply time-out is `timeout_ms` (which must be > 0).
pub fn open_checked(
    port: &str,
    baud: u32,
    timeout_ms: u64,
) -> Result<Box<dyn serialport::SerialPort>, String> {
    if timeout_ms == 0 {
        return Err("--timeout-ms must be > 0".into());
    }
    open_port(port, baud).map_err(|e| e.to_string())
}

/// `links upload`: send a compiled SceneImage; returns the summary line. Without
/// `deadline_s` the overall deadline is [`upload_deadline`]; 0 means none.
pub fn upload_command(
    image: &[u8],
    port: &str,
    baud: u32,
    timeout_ms: u64,
    deadline_s: Option<u64>,
    render: Option<u16>,
    quiet: bool,
) -> Result<String, String> {
    let mut p = open_checked(port, baud, timeout_ms)?;
    // Bytes already waiting are no answers to this upload.
    p.clear(serialport::ClearBuffer::Input)
        .map_err(|e| format!("serial port {port}: {e}"))?;
    let b = bar(
        quiet,
        image.len() as u64,
        "{spinner} upload {bar:40} {bytes}/{total_bytes} ({bytes_per_sec}, eta {eta})",
    );
    let mut opts = UploadOptions {
        reply_timeout: Duration::from_millis(timeout_ms),
        start_render: render,
        ..UploadOptions::default()
    };
    opts.deadline =
        deadline(deadline_s).unwrap_or_else(|| Some(upload_deadline(image.len(), baud, &opts)));
    let r = upload(&mut p, port, image, &opts, &|n| b.set_position(n));
    b.finish_and_clear();
    let r = r.map_err(|e| e.to_string())?;
    Ok(format!(
        "{port}: uploaded {} bytes in {} chunks ({} retransmit requests from the RC, {} time-outs){}",
        r.bytes,
        r.chunks_sent,
        r.naks,
        r.timeouts,
        if render.is_some() {
            ", render started"
        } else {
            ""
        }
    ))
}

/// `links readback`: read one frame and write it as a PNG; returns the summary line. No
/// overall deadline unless `deadline_s` (> 0) gives one: rendering takes what it takes, and
/// the progress rules of [`readback`] end a misbehaving RC.
pub fn readback_command(
    port: &str,
    output: &Path,
    baud: u32,
    timeout_ms: u64,
    deadline_s: Option<u64>,
    quiet: bool,
) -> Result<String, String> {
    let mut p = open_checked(port, baud, timeout_ms)?;
    let b = bar(
        quiet,
        1,
        "{spinner} {msg} {bar:40} {pos}/{len} pixels ({per_sec}, eta {eta})",
    );
    b.set_message("waiting for a frame");
    let opts = ReadbackOptions {
        timeout: Duration::from_millis(timeout_ms),
        deadline: deadline(deadline_s).flatten(),
        ..ReadbackOptions::default()
    };
    let r = readback(&mut p, port, &opts, &|ev| match ev {
        ReadbackEvent::Rendering { done, total } => {
            b.set_message("rendering");
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
        ReadbackEvent::Header {
            frame,
            width,
            height,
        } => {
            b.set_message(format!("frame {frame} {width}x{height}"));
            b.set_length(width as u64 * height as u64);
            b.set_position(0);
        }
        ReadbackEvent::Pixels { have, total } => {
            b.set_length(total);
            b.set_position(have);
        }
        ReadbackEvent::Resend { pixels } => {
            b.set_message(format!("asking again for {pixels} pixels"));
        }
    });
    b.finish_and_clear();
    let r = r.map_err(|e| e.to_string())?;
    let png = encode_png(r.width, r.height, &r.rgb).map_err(|e| e.to_string())?;
    std::fs::write(output, png).map_err(|e| format!("{}: {e}", output.display()))?;
    Ok(format!(
        "{}: frame {} {}x{} from {port}, CRC {:#010x} ok ({} malformed messages repaired by {} retransmit requests)",
        output.display(),
        r.frame,
        r.width,
        r.height,
        r.crc,
        r.bad_packets,
        r.resends
    ))
}
