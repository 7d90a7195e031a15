//! `links render SCENE --frames A..B -o DIR/`: frames A..B-1 of a film, each compiled by the
//! DM ([`Film::compile_frame`]) and rendered on the host's threads or on the simulated
//! cluster (`--nodes`), written as `DIR/frame-NNNN.png`, and the whole film as the animated
//! PNG `DIR/film.png`. A line per frame and one for the film go to stderr.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::Instant;

use links_core::anim::Film;
use links_core::dm::CompileOptions;

use super::args::load_film_any;
use super::error::write_file;
use super::render::{cluster_config, RenderArgs};
use super::{node, CliError};
use crate::cli_cluster;
use crate::cluster::SimConfig;
use crate::frame::{encode_png, render_frame, Precision};
use crate::png_codec::ApngWriter;

/// `--frames A..B`: frames `start..end`, end excluded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRange {
    pub start: u32,
    pub end: u32,
}

/// Parses `A..B` (decimal frame numbers, A < B).
pub fn parse_frames(s: &str) -> Result<FrameRange, String> {
    let usage = || format!("`{s}`: expected frames as A..B (frames A to B-1), e.g. 0..24");
    let (a, b) = s.split_once("..").ok_or_else(usage)?;
    let number = |t: &str| {
        t.parse::<u32>()
            .ok()
            .filter(|_| t.bytes().all(|c| c.is_ascii_digit()))
    };
    let (Some(start), Some(end)) = (number(a), number(b)) else {
        return Err(usage());
    };
    if start >= end {
        return Err(format!(
            "`{s}`: the range is empty; A..B renders frames A to B-1, so B must exceed A"
        ));
    }
    Ok(FrameRange { start, end })
}

/// The name of frame `f`'s PNG in the output directory.
pub fn frame_file_name(frame: u32) -> String {
    format!("frame-{frame:04}.png")
}

/// The animated PNG of the film, beside the frames.
pub const FILM_FILE_NAME: &str = "film.png";

/// Runs `links render --frames`.
pub fn run(a: &RenderArgs, range: FrameRange) -> Result<(), CliError> {
    let path = a.scene.path()?;
    let film = load_film_any(path)?;
    check_range(&film, range, path)?;
    let cluster = match a.nodes {
        Some(nodes) => Some(cluster_config(a, nodes)?),
        None => None,
    };
    let dir = output_dir(&a.output)?;
    let job = Job {
        film: &film,
        path,
        opts: a.scene.compile_options(),
        precision: a.precision.map(Precision::from).unwrap_or_default(),
        threads: a.threads,
        cluster,
        node: a.cluster.node,
        quiet: a.quiet,
    };
    job.render(range, &dir)
}

/// Frames `range` must lie within the film's.
fn check_range(film: &Film, range: FrameRange, path: &Path) -> Result<(), CliError> {
    let frames = film.timeline().frames();
    if range.start >= frames.start && range.end <= frames.end {
        return Ok(());
    }
    let what = if film.is_still() {
        "is a still scene: it has the one frame 0..1".to_string()
    } else {
        format!("has frames {}..{}", frames.start, frames.end)
    };
    Err(CliError::Usage(format!(
        "--frames {}..{}: {} {what}",
        range.start,
        range.end,
        path.display()
    )))
}

/// The output directory, created if missing; anything else at the path is refused.
fn output_dir(dir: &Path) -> Result<PathBuf, CliError> {
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => Ok(dir.to_path_buf()),
        Ok(_) => Err(CliError::Usage(format!(
            "-o {}: with --frames the output is a directory, and this is a file",
            dir.display()
        ))),
        Err(_) => {
            std::fs::create_dir_all(dir).map_err(CliError::write(dir))?;
            Ok(dir.to_path_buf())
        }
    }
}

/// One film render's settings.
struct Job<'a> {
    film: &'a Film,
    path: &'a Path,
    opts: CompileOptions,
    precision: Precision,
    threads: usize,
    /// `Some` for `--nodes`.
    cluster: Option<SimConfig>,
    node: links_core::board::NodeBoard,
    quiet: bool,
}

/// One rendered frame and a note on how it went.
struct Picture {
    width: u32,
    height: u32,
    rgb: Vec<u8>,
    note: String,
}

impl Job<'_> {
    fn render(&self, range: FrameRange, dir: &Path) -> Result<(), CliError> {
        let start = Instant::now();
        let count = range.end - range.start;
        let film_path = dir.join(FILM_FILE_NAME);
        let mut apng: Option<ApngWriter<BufWriter<File>>> = None;
        for (k, frame) in (range.start..range.end).enumerate() {
            let t0 = Instant::now();
            let pic = self.frame(frame)?;
            let out = dir.join(frame_file_name(frame));
            let png = encode_png(pic.width, pic.height, &pic.rgb).map_err(CliError::failed)?;
            write_file(&out, png)?;
            let writer = match apng.as_mut() {
                Some(w) => w,
                None => apng.insert(self.apng(&film_path, &pic, count)?),
            };
            writer.frame(&pic.rgb).map_err(apng_error(&film_path))?;
            if !self.quiet {
                eprintln!(
                    "frame {frame} ({}/{count}): {} {}x{} {} | {:.2} s",
                    k + 1,
                    out.display(),
                    pic.width,
                    pic.height,
                    pic.note,
                    t0.elapsed().as_secs_f64()
                );
            }
        }
        if let Some(w) = apng {
            w.finish().map_err(apng_error(&film_path))?;
        }
        if !self.quiet {
            let secs = start.elapsed().as_secs_f64();
            eprintln!(
                "film: {count} frames ({}..{}) of {} in {secs:.2} s ({:.2} frames/s) | {} (animated PNG, {} frames/s)",
                range.start,
                range.end,
                self.path.display(),
                f64::from(count) / secs.max(1e-9),
                film_path.display(),
                self.film.timeline().rate
            );
        }
        Ok(())
    }

    /// The animated PNG, started with the first frame's size.
    fn apng(
        &self,
        path: &Path,
        first: &Picture,
        count: u32,
    ) -> Result<ApngWriter<BufWriter<File>>, CliError> {
        let file = File::create(path).map_err(CliError::write(path))?;
        let rate = self.film.timeline().rate;
        ApngWriter::new(BufWriter::new(file), first.width, first.height, count, rate)
            .map_err(apng_error(path))
    }

    /// Frame `frame`: compiled by the DM, rendered on the host or the simulated cluster.
    fn frame(&self, frame: u32) -> Result<Picture, CliError> {
        let image = self
            .film
            .compile_frame(frame, &self.opts)
            .map_err(|e| CliError::Scene(format!("{}: {e}", self.path.display())))?
            .bytes;
        match &self.cluster {
            Some(cfg) => self.cluster_frame(frame, &image, cfg),
            None => {
                let f = render_frame(&image, self.precision, self.threads, &|| {})
                    .map_err(CliError::failed)?;
                Ok(Picture {
                    width: f.width,
                    height: f.height,
                    rgb: f.rgb,
                    note: format!("{}, scene image {} B", self.precision.name(), image.len()),
                })
            }
        }
    }

    fn cluster_frame(
        &self,
        frame: u32,
        image: &[u8],
        cfg: &SimConfig,
    ) -> Result<Picture, CliError> {
        let what = format!("{} frame {frame}", self.path.display());
        node::check_fits(&what, image.len(), &self.node)?;
        let r = cli_cluster::render(image, cfg).map_err(CliError::Failed)?;
        let rep = r.report;
        let rgb = rep
            .frames
            .into_iter()
            .next()
            .ok_or_else(|| CliError::Failed("the simulation kept no frame".into()))?;
        Ok(Picture {
            width: rep.width,
            height: rep.height,
            rgb,
            note: format!(
                "on {} simulated nodes: {:.4} s virtual, speed-up {:.2}x, scene image {} B",
                cfg.nodes,
                rep.time_s,
                r.speedup,
                image.len()
            ),
        })
    }
}

fn apng_error(path: &Path) -> impl Fn(png::EncodingError) -> CliError + '_ {
    move |e| CliError::Failed(format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_ranges_parse_and_bad_ones_say_why() {
        assert_eq!(parse_frames("0..4"), Ok(FrameRange { start: 0, end: 4 }));
        assert_eq!(
            parse_frames("12..13"),
            Ok(FrameRange { start: 12, end: 13 })
        );
        assert!(parse_frames("4..4")
            .unwrap_err()
            .contains("the range is empty"));
        assert!(parse_frames("5..2")
            .unwrap_err()
            .contains("the range is empty"));
        for bad in [
            "4", "0..", "..3", "a..b", "-1..3", "+1..3", "0...3", "0..=3",
        ] {
            assert!(
                parse_frames(bad)
                    .unwrap_err()
                    .contains("expected frames as A..B"),
                "{bad}"
            );
        }
        assert_eq!(frame_file_name(7), "frame-0007.png");
        assert_eq!(frame_file_name(123_456), "frame-123456.png");
    }
}
