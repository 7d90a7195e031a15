//! The `links` commands that drive the simulated cluster: `render --nodes`, `sweep nodes`,
//! `sweep divisions`. Thin glue over [`crate::cluster`]; every number is virtual time.

use crate::cluster::rccost::RcCost;
use crate::cluster::sweep::{
    divisions_csv, nodes_csv, steady_state_interval, sweep_divisions, sweep_nodes,
    write_divisions_chart, write_nodes_chart, NamedPolicy,
};
use crate::cluster::{render_cluster, simulate_frame, ClusterRender, RunCache, SimConfig};
use links_core::node::NodeConfig;
use links_core::sched::{Policy, Shape};
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
        "static" => Ok(Policy::Static { shape: Shape::Rect }),
        _ => match s.split_once('=') {
            Some(("fixed", n)) => fixed(n, Shape::Span),
            Some(("fixed-rect", n)) => fixed(n, Shape::Rect),
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
                shape: Shape::Span
            })
        );
        assert_eq!(
            parse_policy("fixed-rect=64"),
            Ok(Policy::Fixed {
                divisions: 64,
                shape: Shape::Rect
            })
        );
        assert_eq!(
            parse_policy("static"),
            Ok(Policy::Static { shape: Shape::Rect })
        );
        assert!(parse_policy("fixed=0").unwrap_err().contains("positive"));
        assert!(parse_policy("round-robin")
            .unwrap_err()
            .contains("unknown policy"));
    }
}
