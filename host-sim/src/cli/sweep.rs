//! `links sweep`: the measurement sweeps (techniques ablation, cluster node count, faults,
//! sub-screen divisions).

use std::path::{Path, PathBuf};

use clap::Subcommand;
use links_core::board::BoardProfile;

use super::args::SceneArgs;
use super::error::write_file;
use super::CliError;
use crate::ablation::{run_ablation, AblationConfig};
use crate::cli_cluster;
use crate::limits;

/// The sweeps `links sweep` runs.
#[derive(Subcommand)]
pub enum SweepCmd {
    /// LINKS-1 Table 5.2 analog: modelled node time of each speed technique
    Ablation {
        /// Scene file (.ron)
        scene: PathBuf,
        #[arg(long, default_value_t = 512, value_parser = limits::parse_image_side)]
        width: u32,
        #[arg(long, default_value_t = 480, value_parser = limits::parse_image_side)]
        height: u32,
        /// Node computers the sub-screens are shared among (1..=256)
        #[arg(long, default_value_t = 16, value_parser = limits::parse_nodes)]
        nodes: u32,
        /// Sub-screen counts (multiples of the height), one table row each
        #[arg(long, value_delimiter = ',', default_value = "2400,480")]
        divisions: Vec<u32>,
        /// Markdown report to write
        #[arg(short, long, default_value = "docs/techniques.md")]
        output: PathBuf,
    },
    /// LINKS-1 Fig. 5.1 analog: cluster speed-up against node count (and the bus study)
    Nodes {
        /// Scene file (.ron)
        scene: PathBuf,
        /// Directory for nodes.csv and nodes.svg
        #[arg(short, long, default_value = "docs/cluster")]
        output: PathBuf,
        /// The board profile: f407 (the firmware's) or ideal (the idealised link)
        #[arg(long, default_value = "f407", value_parser = cli_cluster::parse_board_arg)]
        board: &'static BoardProfile,
    },
    /// Reliability: frame time against the moment a node dies (every policy, with the
    /// recovery bound), the bit-error rate and the fraction of nodes killed; writes the
    /// table into docs/reliability.md and the chart beside it
    Faults {
        /// Scene file (.ron)
        scene: PathBuf,
        #[command(flatten)]
        opts: cli_cluster::FaultSweepArgs,
    },
    /// The board profiles compared: single frame and steady state (the repeated still) on
    /// f407 and ideal, and what lifting each of the F407's limits buys
    Board {
        /// Scene file (.ron)
        scene: PathBuf,
        /// Node counts of the profiles table
        #[arg(long, value_delimiter = ',', default_value = "1,16,64,256")]
        counts: Vec<u16>,
        /// Node counts at which each F407 limit is lifted in turn
        #[arg(long, value_delimiter = ',', default_value = "64,256")]
        lift_at: Vec<u16>,
        /// The F407's link code: firmware (links_core::spi over the emulated SPI
        /// peripheral, the default) or ideal (the idealised star); the ideal board always
        /// runs the idealised one
        #[arg(long, value_parser = cli_cluster::parse_link)]
        link: Option<crate::cluster::spi_bus::LinkModel>,
    },
    /// A film's DM pipeline on f407 and ideal: one simulation of all its frames (frame n+1
    /// broadcast while frame n renders), steady-state speed-up against one node, the DM's
    /// time (cost model) and the broadcast bytes per frame; the repeated still beside it
    Film {
        /// Film: scene file (.ron) with frames, or an animated glTF
        scene: PathBuf,
        /// Frames A..B (B excluded)
        #[arg(long, default_value = "0..16", value_parser = super::film::parse_frames)]
        frames: super::film::FrameRange,
        #[arg(long, default_value_t = 512, value_parser = limits::parse_image_side)]
        width: u32,
        #[arg(long, default_value_t = 480, value_parser = limits::parse_image_side)]
        height: u32,
        /// Node computers (1..=256)
        #[arg(long, default_value_t = 64, value_parser = limits::parse_nodes)]
        nodes: u32,
    },
    /// LINKS-1 Fig. 5.2 analog: frame time against the number of sub-screens at 64 nodes
    Divisions {
        /// Scene file (.ron)
        scene: PathBuf,
        /// Directory for divisions[-noshadows].csv/svg
        #[arg(short, long, default_value = "docs/cluster")]
        output: PathBuf,
        /// The board profile: f407 (the firmware's) or ideal (the idealised link)
        #[arg(long, default_value = "f407", value_parser = cli_cluster::parse_board_arg)]
        board: &'static BoardProfile,
    },
}

/// Runs `links sweep ...`.
pub fn run(cmd: SweepCmd) -> Result<(), CliError> {
    match cmd {
        SweepCmd::Ablation {
            scene,
            width,
            height,
            nodes,
            divisions,
            output,
        } => {
            let cfg = AblationConfig {
                width,
                height,
                nodes,
                divisions,
                ..AblationConfig::default()
            };
            ablation(&scene, &cfg, &output)
        }
        SweepCmd::Nodes {
            scene,
            output,
            board,
        } => {
            let image = SceneArgs::plain(&scene).compile()?;
            let text = cli_cluster::nodes_study(&image, *board, &output, &|s| {
                eprintln!("simulating {s} ...")
            })?;
            outln!("{text}");
            eprintln!("wrote {}/nodes.csv and nodes.svg", output.display());
            Ok(())
        }
        SweepCmd::Board {
            scene,
            counts,
            lift_at,
            link,
        } => {
            let image = SceneArgs::plain(&scene).compile()?;
            let text =
                crate::studies::board_study::board_study(&image, &counts, &lift_at, link, &|s| {
                    eprintln!("simulating {s} ...")
                })?;
            outln!("{text}");
            Ok(())
        }
        SweepCmd::Faults { scene, opts } => {
            let text = cli_cluster::faults_study(&scene, &opts, &|s| eprintln!("{s}"))?;
            outln!("{text}");
            Ok(())
        }
        SweepCmd::Divisions {
            scene,
            output,
            board,
        } => divisions(&scene, *board, &output),
        SweepCmd::Film {
            scene,
            frames,
            width,
            height,
            nodes,
        } => film(&scene, frames, (width, height), nodes),
    }
}

/// `links sweep ablation`: the table on stdout, the report into `output`.
fn ablation(scene: &Path, cfg: &AblationConfig, output: &Path) -> Result<(), CliError> {
    let desc = super::args::load_desc(scene)?;
    let report = run_ablation(&desc, cfg, &|step| eprintln!("rendering {step} ..."))
        .map_err(|e| CliError::Failed(format!("{}: {e}", scene.display())))?;
    let command = std::env::args().skip(1).collect::<Vec<_>>().join(" ");
    let doc = crate::ablation_doc::render(&report, &scene.display().to_string(), &command);
    outln!("{}", report.table());
    outln!(
        "refractive / non-refractive (type 1): {:.2}x",
        report.refractive_ratio()
    );
    write_file(output, doc)?;
    eprintln!("wrote {}", output.display());
    Ok(())
}

/// `links sweep divisions`: the study with and without shadows.
fn divisions(scene: &Path, board: BoardProfile, output: &Path) -> Result<(), CliError> {
    let image = SceneArgs::plain(scene).compile()?;
    let no_shadows = SceneArgs {
        no_shadows: true,
        ..SceneArgs::plain(scene)
    }
    .compile()?;
    let text = cli_cluster::divisions_study(
        &[("divisions-noshadows", &no_shadows), ("divisions", &image)],
        board,
        output,
        &|s| eprintln!("simulating {s} ..."),
    )?;
    outln!("{text}");
    eprintln!("wrote {}/divisions*.csv and .svg", output.display());
    Ok(())
}

/// `links sweep film`: the table on stdout.
fn film(
    scene: &Path,
    frames: super::film::FrameRange,
    (width, height): (u32, u32),
    nodes: u32,
) -> Result<(), CliError> {
    let film = super::args::load_film_any(scene)?;
    let opts = SceneArgs {
        width: Some(width),
        height: Some(height),
        ..SceneArgs::plain(scene)
    }
    .compile_options();
    let nodes = u16::try_from(nodes).map_err(|_| CliError::Usage(format!("{nodes} nodes")))?;
    let points = crate::studies::film_study::film_points(
        &film,
        frames.start..frames.end,
        &opts,
        nodes,
        &[BoardProfile::F407, BoardProfile::IDEAL],
        &|s| eprintln!("{s} ..."),
    )
    .map_err(|e| CliError::Failed(format!("{}: {e}", scene.display())))?;
    outln!("{}", crate::studies::film_study::film_table(&points));
    Ok(())
}
