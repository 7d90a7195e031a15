//! The `links sweep nodes`, `sweep divisions` and `sweep faults` commands: run a study over
//! the simulated cluster, write its CSV, charts and document section, and return the text
//! they print. Every number is virtual time.

use crate::sim::cluster::rccost::RcCost;
use crate::sim::cluster::{simulate_frame, RunCache, SimConfig, SimError, SimReport};
use crate::sim::options::board_text;
use crate::studies::cluster_sweep::{
    divisions_csv, nodes_csv, steady_state_interval, sweep_divisions, sweep_nodes,
    write_divisions_chart, write_nodes_chart, NamedPolicy,
};
use crate::studies::report::{table_head, write_file};
use links_core::board::BoardProfile;
use links_core::node::NodeConfig;
use links_core::wire::PixelCoding;
use std::path::Path;

/// The Fig. 5.1 study: the bus table (raw vs RLE pixels, 1/2/4 buses at 64 nodes) printed,
/// and the speed-up sweep over node counts written as CSV and SVG into `out`.
pub fn nodes_study(
    image: &[u8],
    board: BoardProfile,
    out: &Path,
    progress: &dyn Fn(&str),
) -> Result<String, String> {
    let e = |e: SimError| e.to_string();
    std::fs::create_dir_all(out).map_err(|err| format!("{}: {err}", out.display()))?;
    let base = SimConfig {
        cache: Some(RunCache::new()),
        ..SimConfig::for_board(board)
    };
    let mut table = format!("{}\n\n", board_text(&base));
    table.push_str(&table_head([
        "pixels",
        "buses",
        "single frame (s)",
        "speed-up",
        "steady state (s/frame)",
        "speed-up",
        "bus busy (single)",
        "bytes (single)",
    ]));
    for coding in [PixelCoding::Raw, PixelCoding::Rle, PixelCoding::Delta] {
        let name = match coding {
            PixelCoding::Raw => "raw RGB8",
            PixelCoding::Rle => "RLE",
            PixelCoding::Delta => "RLE or delta",
        };
        for buses in [1u16, 2, 4] {
            progress(&format!("64 nodes, {buses} bus(es), {name}"));
            let cfg = SimConfig {
                buses,
                node: NodeConfig { coding },
                ..base.clone()
            };
            let (one, one_steady, r, steady) = single_and_steady(image, &cfg).map_err(e)?;
            table.push_str(&format!(
                "| {} | {buses} | {:.4} | {:.2} | {:.4} | {:.2} | {:.1}% | {} |\n",
                name,
                r.time_s,
                one / r.time_s,
                steady,
                one_steady / steady,
                100.0 * r.bus_utilisation(),
                r.bytes_moved()
            ));
        }
    }
    table.push('\n');
    table.push_str(&table_head([
        "RC",
        "nodes",
        "single frame (s)",
        "speed-up",
        "steady state (s/frame)",
        "speed-up",
        "RC busy (single)",
        "bus busy (single)",
    ]));
    let rc = RcCost::for_board(&board);
    let rcs = [
        ("double-buffered", true, rc),
        ("single-buffered", false, rc),
        ("free (no CPU time)", true, RcCost::FREE),
    ];
    for nodes in [64u16, 256] {
        for (name, double, cost) in rcs {
            progress(&format!("{nodes} nodes, RC {name}"));
            let cfg = SimConfig {
                nodes,
                rc_double_buffer: double,
                rc_cost: cost,
                ..base.clone()
            };
            let (one, one_steady, r, steady) = single_and_steady(image, &cfg).map_err(e)?;
            table.push_str(&format!(
                "| {name} | {nodes} | {:.4} | {:.2} | {:.4} | {:.2} | {:.1}% | {:.1}% |\n",
                r.time_s,
                one / r.time_s,
                steady,
                one_steady / steady,
                100.0 * r.rc_busy_s / r.time_s,
                100.0 * r.bus_utilisation(),
            ));
        }
    }
    progress("speed-up sweep over 1..256 nodes");
    let counts = [1u16, 2, 4, 8, 16, 24, 32, 48, 64, 96, 128, 192, 256];
    let pts = sweep_nodes(image, &counts, &NamedPolicy::standard(), &base, 8, 0).map_err(e)?;
    let csv = nodes_csv(&pts);
    std::fs::write(out.join("nodes.csv"), &csv).map_err(|err| err.to_string())?;
    let title = format!(
        "speed-up vs nodes (1 bus; board {}, {} MHz)",
        board.name,
        base.timing.bit_rate_hz / 1e6
    );
    write_nodes_chart(&out.join("nodes.svg"), &pts, &title).map_err(e)?;
    Ok(format!("{table}\n{csv}"))
}

/// The Fig. 5.2 study: frame time against the number of sub-screens at 64 nodes, written as
/// `divisions[-noshadows].csv/svg` into `out` for each image given.
pub fn divisions_study(
    images: &[(&str, &[u8])],
    board: BoardProfile,
    out: &Path,
    progress: &dyn Fn(&str),
) -> Result<String, String> {
    let e = |e: SimError| e.to_string();
    std::fs::create_dir_all(out).map_err(|err| format!("{}: {err}", out.display()))?;
    let base = SimConfig {
        cache: Some(RunCache::new()),
        ..SimConfig::for_board(board)
    };
    let divs = [
        64u32, 128, 256, 480, 512, 1024, 2048, 2400, 4096, 7680, 15360,
    ];
    let mut text = String::new();
    for (name, image) in images {
        progress(name);
        let dp = sweep_divisions(image, 64, &divs, &base, 0).map_err(e)?;
        let csv = divisions_csv(&dp);
        std::fs::write(out.join(format!("{name}.csv")), &csv).map_err(|err| err.to_string())?;
        let title = format!(
            "64 nodes: frame time vs sub-screens{} (board {})",
            if name.contains("noshadows") {
                ", no shadows"
            } else {
                ""
            },
            board.name
        );
        write_divisions_chart(&out.join(format!("{name}.svg")), &dp, &title).map_err(e)?;
        text.push_str(&format!("{name}\n{csv}\n"));
    }
    Ok(text)
}

/// Options of `links sweep faults`.
#[derive(clap::Args, Clone, Debug)]
pub struct FaultSweepArgs {
    /// Image width of the sweep's frames
    #[arg(long, default_value_t = 128)]
    pub width: u32,
    /// Image height of the sweep's frames
    #[arg(long, default_value_t = 120)]
    pub height: u32,
    /// Node computers
    #[arg(long, default_value_t = 16)]
    pub nodes: u16,
    /// The RC's time-out before it re-issues a silent node's work, in ms
    #[arg(long, default_value_t = 100.0)]
    pub timeout_ms: f64,
    /// Document whose generated section to replace ("" = none)
    #[arg(long, default_value = "docs/reliability.md")]
    pub doc: std::path::PathBuf,
    /// The chart (SVG); a PNG and the CSV get the same name with .png and .csv
    #[arg(long, default_value = "docs/reliability/faults.svg")]
    pub chart: std::path::PathBuf,
    /// Host threads (0 = all cores); the results do not depend on it
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// The board profile: f407 (the firmware's) or ideal (the idealised link)
    #[arg(long, default_value = "f407", value_parser = crate::sim::options::parse_board_arg)]
    pub board: &'static BoardProfile,
}

/// `links sweep faults`: run the reliability sweep on `scene` and write the CSV, the chart
/// and the generated section of the document. Returns the tables (markdown).
pub fn faults_study(
    scene: &Path,
    opts: &FaultSweepArgs,
    progress: &dyn Fn(&str),
) -> Result<String, String> {
    use crate::studies::faults::{
        faults_csv, faults_markdown, faults_png, replace_section, sweep_faults, write_faults_chart,
        FaultSweepConfig,
    };
    if !(2..=256).contains(&opts.nodes) {
        return Err(format!("--nodes {}: from 2 to 256", opts.nodes));
    }
    if !(opts.timeout_ms.is_finite() && opts.timeout_ms > 0.0) {
        return Err(format!("--timeout-ms {}: must be > 0", opts.timeout_ms));
    }
    let desc = crate::scene_file::load_scene(scene).map_err(|e| e.to_string())?;
    let copts = links_core::dm::CompileOptions {
        width: Some(opts.width),
        height: Some(opts.height),
        ..Default::default()
    };
    let image = links_core::dm::compile(&desc, &copts)
        .map_err(|e| format!("{}: {e}", scene.display()))?
        .bytes;
    progress(&format!(
        "rendering the reference ({}x{} on the host)",
        opts.width, opts.height
    ));
    let reference = crate::sim::single::render_single(
        &image,
        crate::sim::single::Precision::F32,
        opts.threads,
        &|| {},
    )
    .map_err(|e| e.to_string())?
    .rgb;
    let cfg = FaultSweepConfig::standard(*opts.board, opts.nodes, opts.timeout_ms * 1e-3);
    let start = std::time::Instant::now();
    let sweep = sweep_faults(&image, &reference, &cfg, opts.threads, &|s| {
        progress(&format!("simulating {s} ..."))
    })
    .map_err(|e| e.to_string())?;
    progress(&format!(
        "{} simulations in {:.1} s of host time",
        cfg.policies.len() * (cfg.kill_steps as usize + 2)
            + 1
            + sweep.bers.len()
            + sweep.fractions.len(),
        start.elapsed().as_secs_f64()
    ));
    let command = format!(
        "links sweep faults {} --width {} --height {} --nodes {} --timeout-ms {} --board {}",
        scene.display(),
        opts.width,
        opts.height,
        opts.nodes,
        opts.timeout_ms,
        opts.board.name
    );
    let chart_rel = opts
        .chart
        .strip_prefix(opts.doc.parent().unwrap_or(Path::new("")))
        .unwrap_or(&opts.chart);
    let mut text = faults_markdown(&sweep, &command);
    text.push_str(&format!(
        "
![frame time against the moment of death, the bit-error rate and the fraction of nodes killed]({})

Every point: [`{}`]({}).
",
        chart_rel.display(),
        chart_rel.with_extension("csv").display(),
        chart_rel.with_extension("csv").display()
    ));
    if let Some(dir) = opts.chart.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let csv_path = opts.chart.with_extension("csv");
    write_file(&csv_path, faults_csv(&sweep))?;
    write_faults_chart(&opts.chart, &sweep).map_err(|e| e.to_string())?;
    let png_path = opts.chart.with_extension("png");
    write_file(&png_path, faults_png(&sweep).map_err(|e| e.to_string())?)?;
    progress(&format!(
        "wrote {}, {} and {}",
        opts.chart.display(),
        png_path.display(),
        csv_path.display()
    ));
    if !opts.doc.as_os_str().is_empty() {
        let doc = std::fs::read_to_string(&opts.doc)
            .map_err(|e| format!("{}: {e}", opts.doc.display()))?;
        let new =
            replace_section(&doc, &text).map_err(|e| format!("{}: {e}", opts.doc.display()))?;
        write_file(&opts.doc, new)?;
        progress(&format!("wrote the tables into {}", opts.doc.display()));
    }
    Ok(text)
}

/// One configuration's single frame and steady state, and the same on one node: (one
/// node's frame time, one node's steady interval, the report, the steady interval).
pub(crate) fn single_and_steady(
    image: &[u8],
    cfg: &SimConfig,
) -> Result<(f64, f64, SimReport, f64), SimError> {
    let one_cfg = SimConfig {
        nodes: 1,
        topology: crate::sim::cluster::relay::Topology::Star,
        relay_deaths: Vec::new(),
        ..cfg.clone()
    };
    let one = simulate_frame(image, &one_cfg)?.time_s;
    let one_steady = steady_state_interval(image, &one_cfg, 4)?;
    let r = simulate_frame(image, cfg)?;
    let steady = steady_state_interval(image, cfg, 8)?;
    Ok((one, one_steady, r, steady))
}
