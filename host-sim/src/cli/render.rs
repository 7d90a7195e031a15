//! `links render`: a scene (or a compiled SceneImage) to a PNG, on the host's threads or on a
//! simulated cluster (`--nodes`).

use std::io::IsTerminal;
use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use links_core::board::{BoardProfile, NodeBoard};
use links_core::image::SceneView;
use links_core::node::Kernels;
use links_core::num::Storage;
use links_core::render::Stats;

use super::args::{image_to_render, PrecisionArg, SceneArgs};
use super::error::write_file;
use super::film::{self, FrameRange};
use super::{node, CliError};
use crate::cli_cluster;
use crate::cluster::SimConfig;
use crate::frame::{encode_png, render_frame, Precision};
use crate::limits;
use crate::studies::timeline_chart::timeline_svg;

/// The options of `links render`.
#[derive(clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Render this compiled SceneImage file (as `info --image` writes) instead of a scene
    #[arg(long, value_name = "FILE.bin", conflicts_with_all = ["scene", "width", "height", "max_depth", "transparency", "no_shadows", "frames"])]
    pub image: Option<PathBuf>,
    /// Output PNG file; with --frames, the directory the frames are written to (created if
    /// missing)
    #[arg(short, long, default_value = "out.png")]
    pub output: PathBuf,
    /// Render frames A..B-1 of a film to numbered PNGs in the -o directory, and the film as
    /// an animated PNG, film.png (a still scene has the one frame 0..1)
    #[arg(long, value_name = "A..B", value_parser = film::parse_frames)]
    pub frames: Option<FrameRange>,
    /// Host threads (0 = all cores, at most 256; single-host render only); the image does
    /// not depend on it
    #[arg(long, default_value_t = 0, value_parser = limits::parse_threads)]
    pub threads: usize,
    /// Number type of the render (default: f32; fixed for an --image that stores Q16.16)
    #[arg(long, value_enum)]
    pub precision: Option<PrecisionArg>,
    /// No progress bar or stats line
    #[arg(short, long)]
    pub quiet: bool,
    /// Render on a simulated LINKS-1 cluster of this many node computers (1..=256)
    #[arg(long)]
    pub nodes: Option<u16>,
    #[command(flatten)]
    pub cluster: ClusterArgs,
}

/// The options of a cluster render (`--nodes`).
#[derive(clap::Args)]
pub struct ClusterArgs {
    /// The board profile the cluster is built of (cluster only): f407 (the firmware's:
    /// 21 MHz SPI, 8-byte header + 1-byte trailer, 8 + 15 us chip-select set-up and hold,
    /// an RC whose bus task clocks the wire while it composes), f207 (the FPU-less
    /// NUCLEO-F207ZG: Cortex-M3 at 120 MHz, 15 MHz SPI, Q16.16 nodes), g0b1 (NUCLEO-G0B1RE:
    /// Cortex-M0+ at 64 MHz, 16 MHz SPI, Q16.16 nodes) or ideal (42 MHz, 4-byte header,
    /// 0.5 us per transfer, an RC that overlaps)
    #[arg(long, default_value = "f407", value_parser = cli_cluster::parse_board_arg)]
    pub board: &'static BoardProfile,
    /// The node computers' board (cluster only; known: f407, f207, g0b1; default: the
    /// --board's): a SceneImage larger than its scene bank is refused before the run
    #[arg(long, value_parser = node::parse_node)]
    pub node: Option<NodeBoard>,
    /// The kernels the nodes carry (cluster only): f32, fixed (Q16.16) or both; default: the
    /// --board's firmware's (f407: both, f207 and g0b1: fixed). A scene in a storage no kernel
    /// reads is refused before the run
    #[arg(long, value_parser = parse_kernels)]
    pub node_kernels: Option<Kernels>,
    /// How the nodes are wired (cluster only): buildable (what the board can be built as:
    /// one bus while it holds every node, otherwise a tree of relay RCs, one per bus of
    /// nodes; the ideal board's one bus holds 256), star (the RC drives --buses buses
    /// itself) or relay (a relay tree whatever the count)
    #[arg(long, default_value = "buildable", value_parser = |s: &str| s.parse::<cli_cluster::TopologyArg>())]
    pub topology: cli_cluster::TopologyArg,
    /// Which link code the buses run (cluster only): firmware (the firmware's links_core::spi
    /// master and slave state machines and frames over an emulated SPI peripheral: DMA
    /// banks, chip-selects, handshake lines, the MISO multiplexer; needs the f407 board's
    /// framing) or ideal (the idealised star: the same wire time, no protocol). Default: the
    /// board's (firmware on f407, ideal on ideal)
    #[arg(long, value_parser = cli_cluster::parse_link)]
    pub link: Option<crate::cluster::spi_bus::LinkModel>,
    /// Which code runs a relay tree's links above the leaf buses (cluster only): model (the
    /// simulator's model: node frames forwarded and batched, relays answering from the one
    /// job table as if it were local) or firmware (the firmware's relay code,
    /// links_core::relay: the root's RelayedBus and each relay's run_relay over emulated
    /// SPI links; one level of relays, or two with middle relays of 4 leaf relays
    /// (rc-fw --features relay-mid), 1 or 2 root buses, the firmware link). Default:
    /// firmware where the board's root of relays drives the tree (one level, no serial
    /// backup line), model otherwise (two levels: more than 64 nodes on the f407)
    #[arg(long, value_parser = cli_cluster::parse_relay)]
    pub relay: Option<crate::cluster::relay::RelayCode>,
    /// How the nodes may code their pixel runs (cluster only): raw, rle (raw or run-length
    /// coded, whichever is shorter) or delta (raw, run-length or delta coded: shading steps
    /// in one or two bytes a pixel)
    #[arg(long, default_value = "delta", value_parser = cli_cluster::parse_pixel_coding)]
    pub pixel_coding: links_core::wire::PixelCoding,
    /// A relay that stops answering: RELAY@SECONDS or FIRST-LAST@SECONDS of virtual time
    /// (repeatable; --relay firmware only)
    #[arg(long = "kill-relay", value_name = "RELAY@SECONDS")]
    pub kill_relays: Vec<String>,
    /// SPI buses from the root computer (cluster only): a star's node buses (default 1),
    /// or under a relay tree the root's buses to its children (default: the board's root
    /// links, 2 on the F407: SPI1 and SPI2)
    #[arg(long)]
    pub buses: Option<u16>,
    /// SPI bit rate in MHz, 0.001..=10000 (cluster only; default: the board's)
    #[arg(long, value_parser = limits::parse_bit_rate_mhz)]
    pub bit_rate_mhz: Option<f64>,
    /// Sub-screen policy (cluster only): decreasing (= decreasing=6,128), decreasing=FACTOR,MIN
    /// (each job the remaining pixels / (FACTOR x nodes), at least MIN), static, fixed=N,
    /// fixed-rect=N. Default: decreasing=6,128 on a star, decreasing=6,192 under a relay
    /// tree (as the firmware's root of relays)
    #[arg(long)]
    pub policy: Option<String>,
    /// DM time per frame in ms: frame f's scene exists at (f+1) x this (cluster only)
    #[arg(long, default_value_t = 0.0)]
    pub dm_ms: f64,
    #[command(flatten)]
    pub faults: cli_cluster::FaultArgs,
    /// How long the RC waits for a silent node holding work before re-issuing it, in ms
    /// (default: the board's, scaled to its node's speed: f407 and ideal 500, f207 4000,
    /// g0b1 15000; times N² with --aa N: a pixel is N² rays)
    #[arg(long)]
    pub timeout_ms: Option<f64>,
    /// A single-buffered RC: it composes, clocks and decodes one transfer at a time
    /// (default: as the board does; cluster only)
    #[arg(long)]
    pub rc_single_buffer: bool,
    /// Draw the frame's timeline into this SVG: one row per node (computing, waiting, its
    /// exchanges), the RC's CPU and each bus in virtual time, and the map of which node
    /// rendered which sub-screen (cluster only)
    #[arg(long, value_name = "FILE.svg")]
    pub timeline: Option<PathBuf>,
}

/// Runs `links render`.
pub fn run(a: RenderArgs) -> Result<(), CliError> {
    match (a.frames, a.nodes) {
        (Some(frames), _) => film::run(&a, frames),
        (None, Some(nodes)) => cluster(&a, nodes),
        (None, None) => host(&a),
    }
}

/// `--node-kernels`: f32, fixed or both.
fn parse_kernels(s: &str) -> Result<Kernels, String> {
    [Kernels::F32, Kernels::Fixed, Kernels::Both]
        .into_iter()
        .find(|k| k.name() == s)
        .ok_or_else(|| format!("unknown kernels '{s}' (expected f32, fixed or both)"))
}

impl ClusterArgs {
    /// The node board: `--node`, else the `--board`'s.
    pub fn node_board(&self) -> NodeBoard {
        self.node.unwrap_or(self.board.node)
    }

    /// The number type the cluster renders in: `--precision` (f32 or fixed), else the
    /// `--board`'s (f32 on the f407, fixed on the f207 and the g0b1). An f64 render has no
    /// node.
    pub fn precision(&self, asked: Option<PrecisionArg>) -> Result<Precision, CliError> {
        match asked {
            Some(PrecisionArg::F64) => Err(CliError::Usage(
                "the cluster's nodes compute in f32 or Q16.16: --precision f32 or fixed".into(),
            )),
            Some(p) => Ok(p.into()),
            None => Ok(match self.board.storage {
                Storage::F32 => Precision::F32,
                Storage::Q16_16 => Precision::Fixed,
            }),
        }
    }
}

/// The simulated cluster of `--nodes N` and the cluster options, checked.
pub(super) fn cluster_config(a: &RenderArgs, nodes: u16) -> Result<SimConfig, CliError> {
    let c = &a.cluster;
    c.precision(a.precision)?;
    if !(1..=256).contains(&nodes) {
        return Err(CliError::Usage(format!(
            "--nodes {nodes}: a cluster has 1 to 256 node computers"
        )));
    }
    let mut cfg = cli_cluster::config(
        *c.board,
        nodes,
        c.buses,
        c.bit_rate_mhz,
        c.policy
            .as_deref()
            .map(cli_cluster::parse_policy)
            .transpose()?,
        c.topology,
    );
    let samples = f64::from(a.scene.aa.unwrap_or(1)).powi(2);
    let timeout_ms = c.timeout_ms.unwrap_or(cfg.node_timeout_s * 1e3 * samples);
    if !(c.dm_ms.is_finite() && c.dm_ms >= 0.0 && timeout_ms.is_finite() && timeout_ms > 0.0) {
        return Err(CliError::Usage(
            "--dm-ms must be >= 0 and --timeout-ms > 0".into(),
        ));
    }
    cfg.board = c.node_board();
    cfg.kernels = c.node_kernels.unwrap_or(c.board.kernels);
    if let Some(link) = c.link {
        cfg.link = link;
    }
    if let Some(relay) = c.relay {
        cfg.relay = relay;
    }
    cfg.node.coding = c.pixel_coding;
    let relays = cfg.tree().and_then(Result::ok).map_or(0, |t| t.leaves);
    cfg.relay_deaths = cli_cluster::relay_deaths(&c.kill_relays, relays)?;
    cfg.dm_s_per_frame = c.dm_ms * 1e-3;
    cfg.node_timeout_s = timeout_ms * 1e-3;
    cfg.rc_double_buffer = cfg.rc_double_buffer && !c.rc_single_buffer;
    cli_cluster::apply_faults(&mut cfg, &c.faults)?;
    if c.timeline.is_some() {
        cfg.timeline = Some(limits::MAX_TIMELINE_INTERVALS);
    }
    // The relay code the board runs, once every option that bears on it is set.
    if c.relay.is_none() {
        cfg = cfg.with_board_relays();
    }
    Ok(cfg)
}

/// `links render --nodes N`: the frame of a simulated cluster.
fn cluster(a: &RenderArgs, nodes: u16) -> Result<(), CliError> {
    let c = &a.cluster;
    let cfg = cluster_config(a, nodes)?;
    let (image, _) = image_to_render(&a.scene, a.image.as_deref(), a.precision.map(Into::into))?;
    // `--precision`, else the image's own storage if it is Q16.16, else the board's.
    let stored = SceneView::new(&image).map_err(CliError::failed)?.storage();
    let precision = match (a.precision, stored) {
        (None, Storage::Q16_16) => Precision::Fixed,
        (asked, _) => c.precision(asked)?,
    };
    // What the DM sends nodes computing in fixed point: the Q16.16 rewrite.
    let image = match precision {
        Precision::Fixed => crate::frame::fixed_image(&image).map_err(CliError::failed)?,
        _ => image,
    };
    let what = match &a.image {
        Some(path) => path.display().to_string(),
        None => a.scene.path()?.display().to_string(),
    };
    node::check_fits(&what, image.len(), &c.node_board())?;
    let start = std::time::Instant::now();
    let r = cli_cluster::render(&image, &cfg)?;
    let rep = &r.report;
    let frame = rep
        .frames
        .first()
        .ok_or_else(|| CliError::Failed("the simulation kept no frame".into()))?;
    let png = encode_png(rep.width, rep.height, frame).map_err(CliError::failed)?;
    write_file(&a.output, png)?;
    if let (Some(path), Some(log)) = (&c.timeline, &rep.timeline) {
        let title = format!("{what}: {}", cli_cluster::board_text(&cfg));
        write_file(path, timeline_svg(log, rep, &title))?;
    }
    if !a.quiet {
        eprintln!(
            "{}: {}x{} on {nodes} simulated nodes ({}, {}; {}): {:.4} s virtual, speed-up {:.2}x vs 1 node ({:.3} s) | bus busy {:.1}%, RC busy {:.1}% ({}-buffered){}, {} bytes moved{}{} | host {:.2} s",
            a.output.display(),
            rep.width,
            rep.height,
            cli_cluster::topology_text(&cfg),
            cli_cluster::board_text(&cfg),
            cli_cluster::policy_text(cfg.policy),
            rep.time_s,
            r.speedup,
            r.one_node_s,
            100.0 * rep.bus_utilisation(),
            100.0 * rep.rc_utilisation(),
            if cfg.rc_double_buffer { "double" } else { "single" },
            cli_cluster::tree_summary(rep),
            rep.bytes_moved(),
            cli_cluster::fault_summary(rep),
            cli_cluster::topology_note(&cfg),
            start.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// The progress bar of a host render of `rows` rows (hidden when quiet or not on a terminal).
pub(super) fn progress_bar(quiet: bool, rows: u32) -> Result<ProgressBar, CliError> {
    if quiet || !std::io::stderr().is_terminal() {
        return Ok(ProgressBar::hidden());
    }
    let b = ProgressBar::with_draw_target(Some(rows as u64), ProgressDrawTarget::stderr());
    b.set_style(
        ProgressStyle::with_template("{spinner} {bar:40} {pos}/{len} rows, {elapsed} (eta {eta})")
            .map_err(CliError::failed)?,
    );
    Ok(b)
}

/// `links render` on the host's threads.
fn host(a: &RenderArgs) -> Result<(), CliError> {
    let asked = a.precision.map(Precision::from);
    let (image, precision) = image_to_render(&a.scene, a.image.as_deref(), asked)?;
    let view = SceneView::new(&image).map_err(CliError::failed)?;
    let bar = progress_bar(a.quiet, view.camera::<f32>().height)?;
    links_core::math::overflow::reset();
    let frame =
        render_frame(&image, precision, a.threads, &|| bar.inc(1)).map_err(CliError::failed)?;
    bar.finish_and_clear();
    let png = encode_png(frame.width, frame.height, &frame.rgb).map_err(CliError::failed)?;
    write_file(&a.output, png)?;
    if !a.quiet {
        let s = &frame.stats;
        let secs = frame.elapsed.as_secs_f64();
        // Every counter, by its name in `Stats` (the one list of them).
        let counts: Vec<String> = Stats::NAMES
            .iter()
            .zip(s.values())
            .map(|(name, v)| format!("{name} {v}"))
            .collect();
        eprintln!(
            "{}: {}x{} {} in {:.3} s, {:.3} Mrays/s | {} | scene image {} B",
            a.output.display(),
            frame.width,
            frame.height,
            precision.name(),
            secs,
            s.rays() as f64 / secs.max(1e-9) / 1e6,
            counts.join(", "),
            image.len()
        );
    }
    if precision == Precision::Fixed {
        super::compare::report_overflows();
    }
    Ok(())
}
