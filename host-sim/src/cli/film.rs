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
use crate::cluster::dmcost::{DmCost, DmMachine};
use crate::cluster::SimConfig;
use crate::frame::{encode_png, render_frame, Precision};
use crate::png_codec::ApngWriter;
use crate::sim::film::{compile_film, simulate_film, FilmImages, FilmRun};

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
        Some(_) if a.cluster.precision(a.precision)? == Precision::Fixed => {
            return Err(CliError::Usage(
                "a film on the cluster renders in f32 (--board f407 --precision f32); fixed-point films render without --nodes".into(),
            ))
        }
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
        node: a.cluster.node_board(),
        quiet: a.quiet,
    };
    job.render(range, &dir)
}

/// Frames `range` must lie within the film's.
pub(super) fn check_range(film: &Film, range: FrameRange, path: &Path) -> Result<(), CliError> {
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
pub(super) fn output_dir(dir: &Path) -> Result<PathBuf, CliError> {
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
pub(super) struct Picture {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) rgb: Vec<u8>,
    pub(super) note: String,
}

/// Writes the frames as they come: a PNG each, the animated PNG, a line per frame.
pub(super) struct Output<'a> {
    dir: &'a Path,
    pub(super) film_path: PathBuf,
    count: u32,
    rate: f64,
    apng: Option<ApngWriter<BufWriter<File>>>,
    quiet: bool,
}

impl<'a> Output<'a> {
    /// Frames of a `count`-frame film at `rate` frames/s into `dir`.
    pub(super) fn new(dir: &'a Path, count: u32, rate: f64, quiet: bool) -> Self {
        Output {
            dir,
            film_path: dir.join(FILM_FILE_NAME),
            count,
            rate,
            apng: None,
            quiet,
        }
    }

    /// Write frame `frame` (the `k`th of the film) as its PNG and into the animated one.
    pub(super) fn push(
        &mut self,
        k: usize,
        frame: u32,
        pic: &Picture,
        secs: f64,
    ) -> Result<(), CliError> {
        let out = self.dir.join(frame_file_name(frame));
        let png = encode_png(pic.width, pic.height, &pic.rgb).map_err(CliError::failed)?;
        write_file(&out, png)?;
        let writer = match self.apng.as_mut() {
            Some(w) => w,
            None => {
                let file =
                    File::create(&self.film_path).map_err(CliError::write(&self.film_path))?;
                let w = ApngWriter::new(
                    BufWriter::new(file),
                    pic.width,
                    pic.height,
                    self.count,
                    self.rate,
                )
                .map_err(apng_error(&self.film_path))?;
                self.apng.insert(w)
            }
        };
        writer
            .frame(&pic.rgb)
            .map_err(apng_error(&self.film_path))?;
        if !self.quiet {
            eprintln!(
                "frame {frame} ({}/{}): {} {}x{} {} | {secs:.2} s",
                k + 1,
                self.count,
                out.display(),
                pic.width,
                pic.height,
                pic.note,
            );
        }
        Ok(())
    }

    pub(super) fn finish(self) -> Result<(), CliError> {
        match self.apng {
            Some(w) => w.finish().map_err(apng_error(&self.film_path)),
            None => Ok(()),
        }
    }
}

impl Job<'_> {
    fn render(&self, range: FrameRange, dir: &Path) -> Result<(), CliError> {
        let start = Instant::now();
        let count = range.end - range.start;
        let mut out = Output::new(dir, count, self.film.timeline().rate, self.quiet);
        let summary = match &self.cluster {
            Some(cfg) => Some(self.render_on_cluster(range, cfg, &mut out)?),
            None => {
                for (k, frame) in (range.start..range.end).enumerate() {
                    let t0 = Instant::now();
                    let pic = self.host_frame(frame)?;
                    out.push(k, frame, &pic, t0.elapsed().as_secs_f64())?;
                }
                None
            }
        };
        let film_path = out.film_path.clone();
        out.finish()?;
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
            if let Some(s) = summary {
                eprintln!("{s}");
            }
        }
        Ok(())
    }

    /// Frame `frame`: compiled by the DM, rendered on the host's threads.
    fn host_frame(&self, frame: u32) -> Result<Picture, CliError> {
        let image = self
            .film
            .compile_frame(frame, &self.opts)
            .map_err(|e| CliError::Scene(format!("{}: {e}", self.path.display())))?
            .bytes;
        let f =
            render_frame(&image, self.precision, self.threads, &|| {}).map_err(CliError::failed)?;
        Ok(Picture {
            width: f.width,
            height: f.height,
            rgb: f.rgb,
            note: format!("{}, scene image {} B", self.precision.name(), image.len()),
        })
    }

    /// The whole range on the simulated cluster in ONE simulation (the DM pipeline: frame
    /// n+1's scene is broadcast into the nodes' other bank while frame n renders); returns
    /// the film's summary line.
    fn render_on_cluster(
        &self,
        range: FrameRange,
        cfg: &SimConfig,
        out: &mut Output<'_>,
    ) -> Result<String, CliError> {
        let t0 = Instant::now();
        let images = compile_film(
            self.film,
            range.start..range.end,
            &self.opts,
            &DmCost::ESTIMATE,
        )
        .map_err(|e| CliError::Scene(format!("{}: {e}", self.path.display())))?;
        for (k, image) in images.images.iter().enumerate() {
            let what = format!("{} frame {}", self.path.display(), range.start as usize + k);
            node::check_fits(&what, image.len(), &self.node)?;
        }
        let cfg = SimConfig {
            keep_frames: true,
            ..cfg.clone()
        };
        let run = simulate_film(&images, &cfg, DmMachine::PC)
            .map_err(|e| CliError::Failed(e.to_string()))?;
        let secs = t0.elapsed().as_secs_f64() / f64::from(range.end - range.start);
        let rep = &run.report;
        for (k, rgb) in rep.frames.iter().enumerate() {
            let pic = Picture {
                width: rep.width,
                height: rep.height,
                rgb: rgb.clone(),
                note: format!(
                    "on {} simulated nodes: done at {:.4} s virtual, scene image {} B, DM {:.3} ms",
                    cfg.nodes,
                    rep.frame_done_s.get(k).copied().unwrap_or(0.0),
                    images.images.get(k).map_or(0, Vec::len),
                    run.dm_s.get(k).copied().unwrap_or(0.0) * 1e3
                ),
            };
            out.push(k, range.start + k as u32, &pic, secs)?;
        }
        Ok(film_summary(&run, &images, cfg.nodes))
    }
}

/// The film's line: frames, virtual time, steady state and speed-up, DM and broadcast per
/// frame.
pub fn film_summary(run: &FilmRun, images: &FilmImages, nodes: u16) -> String {
    let rep = &run.report;
    format!(
        "film on {nodes} simulated nodes ({}): {} frames in {:.4} s virtual | steady state {:.4} s/frame, \
         1 node {:.4} s/frame, speed-up {:.2}x | DM {:.3} ms/frame ({}) | \
         broadcast {:.0} B/frame (scene image {:.0} B mean)",
        rep.profile.name,
        rep.frame_done_s.len(),
        rep.time_s,
        run.steady_s(),
        run.one_node_steady_s(),
        run.speedup(),
        run.dm_s_per_frame() * 1e3,
        if run.fixed_dm {
            "--dm-ms"
        } else {
            run.machine.name
        },
        run.broadcast_bytes_per_frame(),
        images.mean_bytes()
    )
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
