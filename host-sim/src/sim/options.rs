//! The options of `links render --nodes` that set up a simulated cluster run: the
//! scheduling policy, node deaths and link faults, and the one-line fault summary. Thin glue
//! over [`crate::sim::cluster`]; every number is virtual time.

use crate::sim::cluster::star::{NodeDeath, Noise};
use crate::sim::cluster::{render_cluster, ClusterRender, SimConfig, SimReport};
use links_core::sched::{Policy, Split};

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
pub fn parse_death(s: &str) -> Result<crate::sim::cluster::star::NodeDeath, String> {
    let bad = || format!("'{s}': expected NODE@SECONDS, e.g. 10@0.3");
    let (node, at) = s.split_once('@').ok_or_else(bad)?;
    let node = node.trim().parse().map_err(|_| bad())?;
    let at_s: f64 = at.trim().parse().map_err(|_| bad())?;
    if !(at_s.is_finite() && at_s >= 0.0) {
        return Err(bad());
    }
    Ok(crate::sim::cluster::star::NodeDeath { node, at_s })
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
