//! The `links` commands that drive the simulated cluster: `render --nodes` (with its fault
//! injection options), `sweep nodes`, `sweep divisions`, `sweep faults`. Thin glue over
//! [`crate::cluster`]; every number is virtual time.

use crate::cluster::rccost::RcCost;
use crate::cluster::star::{NodeDeath, Noise};
use crate::cluster::sweep::{
    divisions_csv, nodes_csv, steady_state_interval, sweep_divisions, sweep_nodes,
    write_divisions_chart, write_nodes_chart, NamedPolicy,
};
use crate::cluster::{
    render_cluster, simulate_frame, ClusterRender, RunCache, SimConfig, SimReport,
};
use links_core::node::NodeConfig;
use links_core::sched::{Policy, Split};
use std::path::Path;

/// Parse a scheduling policy: `decreasing`, `static`, `fixed=N` (runs) or `fixed-rect=N`.
pub fn parse_policy(s: &str) -> Result<Policy, String> {
    let fixed = |n: &str, shape| {
        n.parse::<u32>()
            .ok()
            .filter(|&d| d > 0)
            .map(|divisions| Policy::Fixed { divisions, shape })
            .ok_or_else(|| format!("'{s}': the sub-screen count must be a positive integer"))
    };
    match s {
        "decreasing" => Ok(Policy::DECREASING),
        "static" => Ok(Policy::Static { shape: Split::Rect }),
        _ => match s.split_once('=') {
            Some(("fixed", n)) => fixed(n, Split::Span),
            Some(("fixed-rect", n)) => fixed(n, Split::Rect),
            _ => Err(format!(
                "unknown policy '{s}' (expected decreasing, static, fixed=N or fixed-rect=N)"
            )),
        },
    }
}

/// Parse `NODE@SECONDS` (a node that stops answering at that virtual time).
pub fn parse_death(s: &str) -> Result<crate::cluster::star::NodeDeath, String> {
    let bad = || format!("'{s}': expected NODE@SECONDS, e.g. 10@0.3");
    let (node, at) = s.split_once('@').ok_or_else(bad)?;
    let node = node.trim().parse().map_err(|_| bad())?;
    let at_s: f64 = at.trim().parse().map_err(|_| bad())?;
    if !(at_s.is_finite() && at_s >= 0.0) {
        return Err(bad());
    }
    Ok(crate::cluster::star::NodeDeath { node, at_s })
}

/// Parse `NODE@SECONDS` or `FIRST-LAST@SECONDS` (nodes `FIRST..=LAST` all stop answering at
/// that virtual time).
pub fn parse_deaths(s: &str) -> Result<Vec<NodeDeath>, String> {
    let bad = || format!("--kill '{s}': expected NODE@SECONDS or FIRST-LAST@SECONDS, e.g. 10@0.3");
    let (nodes, at) = s.split_once('@').ok_or_else(bad)?;
    let at_s: f64 = at.trim().parse().map_err(|_| bad())?;
    if !(at_s.is_finite() && at_s >= 0.0) {
        return Err(format!(
            "--kill '{s}': the time must be a number of seconds >= 0"
        ));
    }
    let (first, last) = match nodes.split_once('-') {
        Some((a, b)) => (a, b),
        None => (nodes, nodes),
    };
    let first: u16 = first.trim().parse().map_err(|_| bad())?;
    let last: u16 = last.trim().parse().map_err(|_| bad())?;
    if last < first {
        return Err(format!("--kill '{s}': the range {first}-{last} is empty"));
    }
    Ok((first..=last)
        .map(|node| NodeDeath { node, at_s })
        .collect())
}

/// Fault injection options of `links render --nodes N`.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct FaultArgs {
    /// A node that stops answering: NODE@SECONDS or FIRST-LAST@SECONDS of virtual time
    /// (repeatable; cluster only)
    #[arg(long = "kill", value_name = "NODE@SECONDS")]
    pub kills: Vec<String>,
    /// Bit-error rate RC -> nodes (exchanges and broadcasts, each bit independently), e.g.
    /// 1e-4 (cluster only)
    #[arg(long, value_name = "RATE", default_value_t = 0.0)]
    pub ber_down: f64,
    /// Bit-error rate nodes -> RC (cluster only)
    #[arg(long, value_name = "RATE", default_value_t = 0.0)]
    pub ber_up: f64,
    /// Probability that a node loses a broadcast whole (cluster only)
    #[arg(long, value_name = "P", default_value_t = 0.0)]
    pub drop_broadcast: f64,
    /// Seed of the bit errors and losses (a run is deterministic for a seed; cluster only)
    #[arg(long, default_value_t = 1)]
    pub fault_seed: u64,
}

/// Set the faults of `args` on `cfg` (whose node count is already set), with errors that
/// name the option.
pub fn apply_faults(cfg: &mut SimConfig, args: &FaultArgs) -> Result<(), String> {
    for (name, v) in [("--ber-down", args.ber_down), ("--ber-up", args.ber_up)] {
        if !(v.is_finite() && (0.0..=0.5).contains(&v)) {
            return Err(format!(
                "{name} {v}: a bit-error rate is a probability per bit, from 0 to 0.5"
            ));
        }
    }
    let p = args.drop_broadcast;
    if !(p.is_finite() && (0.0..1.0).contains(&p)) {
        return Err(format!(
            "--drop-broadcast {p}: a probability from 0 to below 1 (at 1 no node hears any broadcast)"
        ));
    }
    cfg.noise = Noise {
        ber_down: args.ber_down,
        ber_up: args.ber_up,
        drop_broadcast: p,
        seed: args.fault_seed,
    };
    cfg.deaths.clear();
    for k in &args.kills {
        for d in parse_deaths(k)? {
            if d.node >= cfg.nodes {
                return Err(format!(
                    "--kill '{k}': node {} does not exist ({} nodes: 0 to {})",
                    d.node,
                    cfg.nodes,
                    cfg.nodes - 1
                ));
            }
            cfg.deaths.push(d);
        }
    }
    Ok(())
}

/// What the faults did, for the render's stats line ("" without faults).
pub fn fault_summary(r: &SimReport) -> String {
    let root = &r.root;
    let corrupted: u64 = r.bus.iter().map(|b| b.corrupted()).sum();
    let dropped: u64 = r.bus.iter().map(|b| b.dropped_broadcast).sum();
    if root.timeouts == 0 && corrupted == 0 && dropped == 0 && root.repairs == 0 {
        return String::new();
    }
    format!(
        " | faults: {} declared dead ({} revived), {} sub-screens re-issued, time-out {:.3} s; {corrupted} frames corrupted, {} rejected by CRC at the RC; {dropped} broadcast copies lost, {} scene repairs",
        root.timeouts,
        root.revived,
        root.reissued,
        root.timeout_us as f64 * 1e-6,
        root.bad_frames,
        root.repairs
    )
}

/// A cluster configuration from the command line's settings.
pub fn config(nodes: u16, buses: u16, bit_rate_mhz: f64, policy: Policy) -> SimConfig {
    let mut cfg = SimConfig {
        nodes,
        buses,
        policy,
        ..SimConfig::default()
    };
    cfg.timing.bit_rate_hz = bit_rate_mhz * 1e6;
    cfg
}

/// Render one frame through the simulated cluster.
pub fn render(image: &[u8], cfg: &SimConfig) -> Result<ClusterRender, String> {
    render_cluster(image, cfg).map_err(|e| e.to_string())
}

/// The Fig. 5.1 study: the bus table (raw vs RLE pixels, 1/2/4 buses at 64 nodes) printed,
/// and the speed-up sweep over node counts written as CSV and SVG into `out`.
pub fn nodes_study(image: &[u8], out: &Path, progress: &dyn Fn(&str)) -> Result<String, String> {
    let e = |e: crate::cluster::SimError| e.to_string();
    std::fs::create_dir_all(out).map_err(|err| format!("{}: {err}", out.display()))?;
    let base = SimConfig {
        cache: Some(RunCache::new()),
        ..SimConfig::default()
    };
    let mut table = String::from(
        "| pixels | buses | single frame (s) | speed-up | steady state (s/frame) | speed-up | bus busy (single) | bytes (single) |\n|---|---|---|---|---|---|---|---|\n",
    );
    for rle in [false, true] {
        for buses in [1u16, 2, 4] {
            progress(&format!(
                "64 nodes, {buses} bus(es), {}",
                if rle { "RLE" } else { "raw RGB8" }
            ));
            let cfg = SimConfig {
                buses,
                node: NodeConfig { rle },
                ..base.clone()
            };
            let one_cfg = SimConfig {
                nodes: 1,
                ..cfg.clone()
            };
            let one = simulate_frame(image, &one_cfg).map_err(e)?.time_s;
            let one_steady = steady_state_interval(image, &one_cfg, 4).map_err(e)?;
            let r = simulate_frame(image, &cfg).map_err(e)?;
            let steady = steady_state_interval(image, &cfg, 8).map_err(e)?;
            table.push_str(&format!(
                "| {} | {buses} | {:.4} | {:.2} | {:.4} | {:.2} | {:.1}% | {} |\n",
                if rle { "RLE" } else { "raw RGB8" },
                r.time_s,
                one / r.time_s,
                steady,
                one_steady / steady,
                100.0 * r.bus_utilisation(),
                r.bytes_moved()
            ));
        }
    }
    table.push_str(
        "\n| RC | nodes | single frame (s) | speed-up | steady state (s/frame) | speed-up | RC busy (single) | bus busy (single) |\n|---|---|---|---|---|---|---|---|\n",
    );
    let rcs = [
        ("double-buffered", true, RcCost::CORTEX_M4F),
        ("single-buffered", false, RcCost::CORTEX_M4F),
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
            let one_cfg = SimConfig {
                nodes: 1,
                ..cfg.clone()
            };
            let one = simulate_frame(image, &one_cfg).map_err(e)?.time_s;
            let one_steady = steady_state_interval(image, &one_cfg, 4).map_err(e)?;
            let r = simulate_frame(image, &cfg).map_err(e)?;
            let steady = steady_state_interval(image, &cfg, 8).map_err(e)?;
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
    write_nodes_chart(
        &out.join("nodes.svg"),
        &pts,
        "speed-up vs nodes (1 bus, 42 MHz)",
    )
    .map_err(e)?;
    Ok(format!("{table}\n{csv}"))
}

/// The Fig. 5.2 study: frame time against the number of sub-screens at 64 nodes, written as
/// `divisions[-noshadows].csv/svg` into `out` for each image given.
pub fn divisions_study(
    images: &[(&str, &[u8])],
    out: &Path,
    progress: &dyn Fn(&str),
) -> Result<String, String> {
    let e = |e: crate::cluster::SimError| e.to_string();
    std::fs::create_dir_all(out).map_err(|err| format!("{}: {err}", out.display()))?;
    let base = SimConfig {
        cache: Some(RunCache::new()),
        ..SimConfig::default()
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
            "64 nodes: frame time vs sub-screens{}",
            if name.contains("noshadows") {
                ", no shadows"
            } else {
                ""
            }
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
}

/// `links sweep faults`: run the reliability sweep on `scene` and write the CSV, the chart
/// and the generated section of the document. Returns the tables (markdown).
pub fn faults_study(
    scene: &Path,
    opts: &FaultSweepArgs,
    progress: &dyn Fn(&str),
) -> Result<String, String> {
    use crate::cluster::reliability::{
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
    let reference =
        crate::frame::render_frame(&image, crate::frame::Precision::F32, opts.threads, &|| {})
            .map_err(|e| e.to_string())?
            .rgb;
    let cfg = FaultSweepConfig::standard(opts.nodes, opts.timeout_ms * 1e-3);
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
        "links sweep faults {} --width {} --height {} --nodes {} --timeout-ms {}",
        scene.display(),
        opts.width,
        opts.height,
        opts.nodes,
        opts.timeout_ms
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
    std::fs::write(&csv_path, faults_csv(&sweep))
        .map_err(|e| format!("{}: {e}", csv_path.display()))?;
    write_faults_chart(&opts.chart, &sweep).map_err(|e| e.to_string())?;
    let png_path = opts.chart.with_extension("png");
    std::fs::write(&png_path, faults_png(&sweep).map_err(|e| e.to_string())?)
        .map_err(|e| format!("{}: {e}", png_path.display()))?;
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
        std::fs::write(&opts.doc, new).map_err(|e| format!("{}: {e}", opts.doc.display()))?;
        progress(&format!("wrote the tables into {}", opts.doc.display()));
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn policies_parse_and_bad_ones_say_why() {
        assert_eq!(parse_policy("decreasing"), Ok(Policy::DECREASING));
        assert_eq!(
            parse_policy("fixed=1024"),
            Ok(Policy::Fixed {
                divisions: 1024,
                shape: Split::Span
            })
        );
        assert_eq!(
            parse_policy("fixed-rect=64"),
            Ok(Policy::Fixed {
                divisions: 64,
                shape: Split::Rect
            })
        );
        assert_eq!(
            parse_policy("static"),
            Ok(Policy::Static { shape: Split::Rect })
        );
        assert!(parse_policy("fixed=0").unwrap_err().contains("positive"));
        assert!(parse_policy("round-robin")
            .unwrap_err()
            .contains("unknown policy"));
    }

    #[test]
    fn deaths_parse_single_nodes_and_ranges() {
        assert_eq!(
            parse_deaths("3@0.25"),
            Ok(vec![NodeDeath {
                node: 3,
                at_s: 0.25
            }])
        );
        let r = parse_deaths("4-6@1").unwrap();
        assert_eq!(r.iter().map(|d| d.node).collect::<Vec<_>>(), vec![4, 5, 6]);
        assert!(r.iter().all(|d| d.at_s == 1.0));
        assert!(parse_deaths("6-4@1").unwrap_err().contains("empty"));
        assert!(parse_deaths("3").unwrap_err().contains("NODE@SECONDS"));
        assert!(parse_deaths("3@-1").unwrap_err().contains(">= 0"));
        assert!(parse_deaths("x@1").unwrap_err().contains("NODE@SECONDS"));
    }

    #[test]
    fn fault_options_are_checked_and_set() {
        let mut cfg = config(8, 1, 42.0, Policy::DECREASING);
        let args = FaultArgs {
            kills: vec!["2@0.1".into(), "5-7@0.2".into()],
            ber_down: 1e-4,
            ber_up: 2e-4,
            drop_broadcast: 0.1,
            fault_seed: 9,
        };
        apply_faults(&mut cfg, &args).unwrap();
        assert_eq!(
            cfg.noise,
            Noise {
                ber_down: 1e-4,
                ber_up: 2e-4,
                drop_broadcast: 0.1,
                seed: 9
            }
        );
        assert_eq!(
            cfg.deaths.iter().map(|d| d.node).collect::<Vec<_>>(),
            vec![2, 5, 6, 7]
        );
        let bad = |f: FaultArgs| apply_faults(&mut cfg.clone(), &f).unwrap_err();
        let e = bad(FaultArgs {
            kills: vec!["8@0.1".into()],
            ..args.clone()
        });
        assert!(
            e.contains("node 8 does not exist") && e.contains("0 to 7"),
            "{e}"
        );
        let e = bad(FaultArgs {
            ber_up: 0.7,
            ..args.clone()
        });
        assert!(e.starts_with("--ber-up 0.7"), "{e}");
        let e = bad(FaultArgs {
            ber_down: f64::NAN,
            ..args.clone()
        });
        assert!(e.starts_with("--ber-down NaN"), "{e}");
        let e = bad(FaultArgs {
            drop_broadcast: 1.0,
            ..args.clone()
        });
        assert!(e.starts_with("--drop-broadcast 1"), "{e}");
    }
}
