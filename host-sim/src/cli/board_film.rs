//! Films on real boards. `links upload SCENE --port P --frames A..B -o DIR/`: the PC is the
//! DM, compiling each frame ([`Film::compile_frame`], the options of `links render`) and
//! streaming it to the RC while the cluster renders the one before, and, on the same line
//! (one port has one reader), collecting the rendered frames into `DIR/frame-NNNN.png` and
//! `DIR/film.png`, as `links render --frames` writes them. `links readback --port P --frames
//! A..B -o DIR/` collects frames A..B-1 an RC is already streaming (e.g. after `links upload
//! SCENE --render N`, frames 0..N-1), one CRC-checked readback each.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use links_core::anim::Film;

use super::args::load_film_any;
use super::film::{check_range, output_dir, FrameRange, Output, Picture};
use super::readback::ReadbackArgs;
use super::upload::UploadArgs;
use super::{node, CliError};
use crate::serial::cli::{deadline, open_checked};
use crate::serial::film::{stream_film, FilmEvent, FilmOptions, FilmReport};
use crate::serial::{readback, Readback, ReadbackOptions, UploadOptions};

/// The film's frame numbers on the wire (u16): first and count.
fn wire_range(range: FrameRange) -> Result<(u16, u16), CliError> {
    let first = u16::try_from(range.start).ok();
    let count = u16::try_from(range.end - range.start).ok();
    match (first, count) {
        (Some(f), Some(c)) if range.end <= 1 << 16 => Ok((f, c)),
        _ => Err(CliError::Usage(format!(
            "--frames {}..{}: the serial protocol numbers frames below 65536",
            range.start, range.end
        ))),
    }
}

/// A frame read back, as a picture for [`Output`].
fn picture(r: Readback, port: &str) -> Picture {
    Picture {
        width: r.width,
        height: r.height,
        note: format!(
            "from {port}, CRC {:#010x} ok ({} malformed messages repaired, {} retransmit requests)",
            r.crc, r.bad_packets, r.resends
        ),
        rgb: r.rgb,
    }
}

/// Runs `links upload --frames`.
pub fn upload_film(a: &UploadArgs, range: FrameRange) -> Result<(), CliError> {
    let path = a.scene.path()?;
    let film = load_film_any(path)?;
    check_range(&film, range, path)?;
    let (first, count) = wire_range(range)?;
    let dir = output_dir(&film_output(&a.output))?;
    let mut port = open_checked(&a.port, a.baud, a.timeout_ms)?;
    // Bytes already waiting are no answers to this film.
    port.clear(serialport::ClearBuffer::Input)
        .map_err(|e| CliError::Failed(format!("serial port {}: {e}", a.port)))?;
    let opts = film_options(a);
    let compile_opts = a.scene.compile_options();
    let shown = path.display().to_string();
    let mut compile = |k: u16| -> Result<Vec<u8>, String> {
        let image = film
            .compile_frame(u32::from(k), &compile_opts)
            .map_err(|e| format!("{shown}: {e}"))?
            .bytes;
        node::check_fits(&format!("{shown} frame {k}"), image.len(), &a.node)
            .map_err(|e| e.to_string())?;
        Ok(image)
    };
    let t0 = Instant::now();
    let quiet = a.quiet;
    let events = |e: FilmEvent| match e {
        FilmEvent::Upload {
            frame,
            stored,
            total,
        } if stored == total && !quiet => {
            eprintln!("frame {frame}: scene image of {total} B stored on the RC")
        }
        FilmEvent::Started { frame } if !quiet => {
            eprintln!(
                "frame {frame}: rendering (at {:.2} s)",
                t0.elapsed().as_secs_f64()
            )
        }
        _ => {}
    };
    let mut out = Output::new(&dir, u32::from(count), rate(&film), quiet);
    let mut k = 0usize;
    let mut last = Instant::now();
    let mut got = |r: Readback| {
        let frame = u32::from(r.frame);
        let secs = last.elapsed().as_secs_f64();
        last = Instant::now();
        out.push(k, frame, &picture(r, &a.port), secs)
            .map_err(|e| crate::serial::HostSerialError::Protocol(e.to_string()))?;
        k += 1;
        Ok(())
    };
    let r = stream_film(
        &mut port,
        &a.port,
        first,
        count,
        &mut compile,
        &opts,
        &events,
        &mut got,
    )
    .map_err(|e| CliError::Failed(e.to_string()))?;
    let film_path = out.film_path.clone();
    out.finish()?;
    if !quiet {
        let secs = t0.elapsed().as_secs_f64();
        eprintln!("{}", summary(&r, range, &shown, &a.port, secs, &film_path));
    }
    Ok(())
}

/// The upload's and readback's settings from the command line.
fn film_options(a: &UploadArgs) -> FilmOptions {
    FilmOptions {
        upload: UploadOptions {
            reply_timeout: Duration::from_millis(a.timeout_ms),
            ..UploadOptions::default()
        },
        readback: ReadbackOptions {
            timeout: Duration::from_millis(a.readback_timeout_ms),
            deadline: deadline(a.deadline_s).flatten(),
            ..ReadbackOptions::default()
        },
    }
}

/// The film's line: frames, time, bytes uploaded, repairs.
fn summary(
    r: &FilmReport,
    range: FrameRange,
    scene: &str,
    port: &str,
    secs: f64,
    film_path: &Path,
) -> String {
    format!(
        "film: {} frames ({}..{}) of {scene} over {port} in {secs:.2} s ({:.2} frames/s) | uploaded {} B ({:.0} B/frame, {} chunks, {} retransmit requests, {} time-outs) | read back with {} retransmit requests, {} malformed messages | {} (animated PNG)",
        r.frames,
        range.start,
        range.end,
        f64::from(r.frames) / secs.max(1e-9),
        r.bytes,
        r.bytes as f64 / f64::from(r.frames.max(1)),
        r.chunks_sent,
        r.naks,
        r.timeouts,
        r.resends,
        r.bad_packets,
        film_path.display()
    )
}

fn rate(film: &Film) -> f64 {
    film.timeline().rate
}

/// Runs `links readback --frames`: frames A..B-1 in order, each one readback; frames
/// numbered below A are skipped, a frame past the one due is an error naming both.
pub fn readback_film(a: &ReadbackArgs, range: FrameRange) -> Result<(), CliError> {
    let (first, count) = wire_range(range)?;
    if !(a.rate.is_finite() && a.rate > 0.0) {
        return Err(CliError::Usage(format!(
            "--rate {}: frames per second must be a positive number",
            a.rate
        )));
    }
    let dir = output_dir(&film_output(&a.output))?;
    let mut port = open_checked(&a.port, a.baud, a.timeout_ms)?;
    let opts = ReadbackOptions {
        timeout: Duration::from_millis(a.timeout_ms),
        deadline: deadline(a.deadline_s).flatten(),
        ..ReadbackOptions::default()
    };
    let mut out = Output::new(&dir, u32::from(count), a.rate, a.quiet);
    let t0 = Instant::now();
    let mut due = first;
    while due - first < count {
        let t = Instant::now();
        let r = readback(&mut port, &a.port, &opts, &|_| {})
            .map_err(|e| CliError::Failed(format!("film frame {due}: {e}")))?;
        if r.frame < due {
            continue;
        }
        if r.frame > due {
            return Err(CliError::Failed(format!(
                "film frame {due}: the RC sent frame {} instead (frame {due} was missed)",
                r.frame
            )));
        }
        let k = usize::from(due - first);
        out.push(
            k,
            u32::from(due),
            &picture(r, &a.port),
            t.elapsed().as_secs_f64(),
        )?;
        due += 1;
    }
    let film_path = out.film_path.clone();
    out.finish()?;
    if !a.quiet {
        let secs = t0.elapsed().as_secs_f64();
        eprintln!(
            "film: {count} frames ({}..{}) from {} in {secs:.2} s | {}",
            range.start,
            range.end,
            a.port,
            film_path.display()
        );
    }
    Ok(())
}

/// `-o` of a film command: a directory, `film/` when none is given.
fn film_output(o: &Option<PathBuf>) -> PathBuf {
    o.clone().unwrap_or_else(|| PathBuf::from("film"))
}
