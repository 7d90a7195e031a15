//! The reliability sweep (`links sweep faults`, docs/reliability.md): frame time against
//!
//! - the moment one node dies, for every policy, with the recovery bound
//!   `clean + 2 · time-out + the node's work in the fault-free frame`;
//! - the bit-error rate, down (RC -> NC), up (NC -> RC) and both, over several seeds;
//! - the fraction of nodes killed at once mid-frame, without and with bit errors.
//!
//! Every frame is compared with the single-node render: a frame that differs is an error
//! ([`SimError::NotIdentical`]), not a data point. Points are independent simulations run on
//! a pool of host threads and returned in input order (results never depend on the thread
//! count); they share one [`RunCache`].

use crate::sim::cluster::star::{NodeDeath, Noise};
use crate::sim::cluster::{simulate, RunCache, SimConfig, SimError, SimReport};
use crate::studies::cluster_sweep::{pool, NamedPolicy};
use links_core::board::BoardProfile;
use rayon::prelude::*;

mod chart;
mod doc;

pub use chart::{faults_png, write_faults_chart};
pub use doc::{faults_csv, faults_markdown, replace_section, SECTION_BEGIN, SECTION_END};

/// What to sweep.
#[derive(Clone, Debug)]
pub struct FaultSweepConfig {
    /// Nodes, buses, time-out, timing: every point starts from this (policy decreasing unless
    /// the point says otherwise).
    pub base: SimConfig,
    /// The kill-moment sweep's policies.
    pub policies: Vec<NamedPolicy>,
    /// The node killed in the kill-moment sweep.
    pub victim: u16,
    /// Kill moments: `i / kill_steps` of the fault-free frame, `i = 0..=kill_steps`.
    pub kill_steps: u32,
    /// Bit-error rates (> 0) of the noise sweep, each down only, up only and both.
    pub bers: Vec<f64>,
    /// Seeds of the noise sweep (one simulation per seed and point).
    pub seeds: Vec<u64>,
    /// Fractions of the nodes killed at once, at half the fault-free frame time.
    pub kill_fractions: Vec<f64>,
    /// The bit-error rate (both directions) of the second fraction series (0: none).
    pub mixed_ber: f64,
}

/// One node killed at one moment.
#[derive(Clone, Debug, PartialEq)]
pub struct KillPoint {
    pub policy: String,
    /// When the node died (s) and as a fraction of the fault-free frame.
    pub at_s: f64,
    pub at_frac: f64,
    pub time_s: f64,
    pub bound_s: f64,
    pub timeouts: u32,
    pub reissued: u32,
}

/// A policy's fault-free frame and the victim's share of the work.
#[derive(Clone, Debug, PartialEq)]
pub struct PolicyClean {
    pub policy: String,
    pub time_s: f64,
    /// The victim's compute in the fault-free frame (s).
    pub victim_work_s: f64,
}

/// One noisy frame.
#[derive(Clone, Debug, PartialEq)]
pub struct BerPoint {
    /// "down", "up" or "both".
    pub direction: &'static str,
    pub ber: f64,
    pub seed: u64,
    pub time_s: f64,
    /// Frames hit by bit errors (all buses, both directions and broadcasts).
    pub corrupted: u64,
    /// Scene pieces and chunks re-sent point-to-point.
    pub repairs: u32,
}

/// Some nodes killed at once mid-frame, perhaps on a noisy link.
#[derive(Clone, Debug, PartialEq)]
pub struct FractionPoint {
    pub killed: u16,
    pub ber: f64,
    pub time_s: f64,
    /// `clean + 2 · time-out + the killed nodes' work in the fault-free frame`.
    pub bound_s: f64,
}

/// Everything the sweep measured.
#[derive(Clone, Debug, PartialEq)]
pub struct FaultSweep {
    /// The board profile every point ran on (its name), and the link in words.
    pub board: &'static str,
    pub board_text: String,
    pub nodes: u16,
    pub width: u32,
    pub height: u32,
    pub timeout_s: f64,
    pub victim: u16,
    pub clean: Vec<PolicyClean>,
    pub kills: Vec<KillPoint>,
    /// The fault-free frame of the noise and fraction series (decreasing).
    pub clean_s: f64,
    pub bers: Vec<BerPoint>,
    pub fractions: Vec<FractionPoint>,
}

impl FaultSweepConfig {
    /// The sweep of docs/reliability.md on `nodes` nodes of `board` with time-out
    /// `timeout_s`.
    pub fn standard(board: BoardProfile, nodes: u16, timeout_s: f64) -> Self {
        use links_core::sched::{Policy, Split};
        let div = 4 * nodes as u32;
        Self {
            base: SimConfig {
                nodes,
                node_timeout_s: timeout_s,
                cache: Some(RunCache::new()),
                ..SimConfig::for_board(board)
            },
            policies: vec![
                NamedPolicy::new("decreasing", Policy::DECREASING),
                NamedPolicy::new("static", Policy::Static { shape: Split::Rect }),
                NamedPolicy::new(
                    &format!("fixed={div}"),
                    Policy::Fixed {
                        divisions: div,
                        shape: Split::Span,
                    },
                ),
                NamedPolicy::new(
                    &format!("fixed-rect={div}"),
                    Policy::Fixed {
                        divisions: div,
                        shape: Split::Rect,
                    },
                ),
            ],
            victim: nodes / 3,
            kill_steps: 20,
            bers: vec![1e-6, 1e-5, 1e-4, 3e-4, 1e-3],
            seeds: vec![1, 2, 3],
            kill_fractions: vec![0.0, 1.0 / 16.0, 0.125, 0.25, 0.5, 0.75],
            mixed_ber: 1e-3,
        }
    }
}

/// Run `cfgs` in parallel (input order kept), each checked bit-identical to `reference`.
fn run_all(
    image: &[u8],
    reference: &[u8],
    cfgs: &[(String, SimConfig)],
    threads: usize,
) -> Result<Vec<SimReport>, SimError> {
    let results: Vec<Result<SimReport, SimError>> = pool(threads)?.install(|| {
        cfgs.par_iter()
            .map(|(what, cfg)| {
                let cfg = SimConfig {
                    keep_frames: true,
                    ..cfg.clone()
                };
                let mut r = simulate(&[image], &cfg).map_err(|e| SimError::Context {
                    what: what.clone(),
                    error: Box::new(e),
                })?;
                if r.frames.first().map(Vec::as_slice) != Some(reference) {
                    return Err(SimError::NotIdentical { what: what.clone() });
                }
                r.frames.clear();
                Ok(r)
            })
            .collect()
    });
    results.into_iter().collect()
}

/// Nodes `0..nodes` spread evenly, `k` of them (for killing a fraction).
pub fn spread(nodes: u16, k: u16) -> Vec<u16> {
    let k = k.min(nodes);
    (0..k)
        .map(|i| (i as u32 * nodes as u32 / k as u32) as u16)
        .collect()
}

/// Run the sweep. `reference` is the single-node render of `image` (RGB8 rows).
pub fn sweep_faults(
    image: &[u8],
    reference: &[u8],
    cfg: &FaultSweepConfig,
    threads: usize,
    progress: &dyn Fn(&str),
) -> Result<FaultSweep, SimError> {
    let base = SimConfig {
        cache: Some(cfg.base.cache.clone().unwrap_or_default()),
        ..cfg.base.clone()
    };
    let nodes = base.nodes;
    if cfg.victim >= nodes {
        return Err(SimError::Config(format!(
            "victim node {} of {nodes}",
            cfg.victim
        )));
    }
    let run = |cfgs: &[(String, SimConfig)]| run_all(image, reference, cfgs, threads);
    progress("fault-free frames (every policy)");
    let (clean, width, height) = clean_series(cfg, &base, &run)?;
    progress(&format!(
        "node {} killed at {} moments, {} policies",
        cfg.victim,
        cfg.kill_steps + 1,
        cfg.policies.len()
    ));
    let kills = kill_series(cfg, &base, &clean, &run)?;
    // The noise and fraction series use the base policy (decreasing).
    let clean_base = run(&[("fault-free".into(), base.clone())])?.remove(0);
    progress(&format!(
        "bit errors: {} rates x 3 directions x {} seeds",
        cfg.bers.len(),
        cfg.seeds.len()
    ));
    let bers = ber_series(cfg, &base, &run)?;
    progress("fractions of the nodes killed mid-frame");
    let fractions = fraction_series(cfg, &base, &clean_base, &run)?;
    Ok(FaultSweep {
        board: base.profile.name,
        board_text: crate::sim::options::board_text(&base),
        nodes,
        width,
        height,
        timeout_s: base.node_timeout_s,
        victim: cfg.victim,
        clean,
        kills,
        clean_s: clean_base.time_s,
        bers,
        fractions,
    })
}

/// Runs a list of named configurations, each checked against the reference ([`run_all`]).
type Runner<'a> = dyn Fn(&[(String, SimConfig)]) -> Result<Vec<SimReport>, SimError> + 'a;

/// Every policy's fault-free frame, and the frame's size.
fn clean_series(
    cfg: &FaultSweepConfig,
    base: &SimConfig,
    run: &Runner<'_>,
) -> Result<(Vec<PolicyClean>, u32, u32), SimError> {
    let clean_cfgs: Vec<(String, SimConfig)> = cfg
        .policies
        .iter()
        .map(|p| {
            (
                format!("{}, fault-free", p.name),
                SimConfig {
                    policy: p.policy,
                    ..base.clone()
                },
            )
        })
        .collect();
    let clean_runs = run(&clean_cfgs)?;
    let (width, height) = (clean_runs[0].width, clean_runs[0].height);
    let clean: Vec<PolicyClean> = cfg
        .policies
        .iter()
        .zip(&clean_runs)
        .map(|(p, r)| PolicyClean {
            policy: p.name.clone(),
            time_s: r.time_s,
            victim_work_s: r.node_compute_s[cfg.victim as usize],
        })
        .collect();
    Ok((clean, width, height))
}

/// The victim killed at `kill_steps + 1` moments of each policy's fault-free frame.
fn kill_series(
    cfg: &FaultSweepConfig,
    base: &SimConfig,
    clean: &[PolicyClean],
    run: &Runner<'_>,
) -> Result<Vec<KillPoint>, SimError> {
    let tau = base.node_timeout_s;
    let steps = cfg.kill_steps.max(1);
    let mut kill_cfgs = Vec::new();
    let mut kill_meta = Vec::new();
    for (p, c) in cfg.policies.iter().zip(clean) {
        for i in 0..=steps {
            let frac = i as f64 / steps as f64;
            let at_s = frac * c.time_s;
            kill_cfgs.push((
                format!("{}, node {} killed at {at_s:.4} s", p.name, cfg.victim),
                SimConfig {
                    policy: p.policy,
                    deaths: vec![NodeDeath {
                        node: cfg.victim,
                        at_s,
                    }],
                    ..base.clone()
                },
            ));
            kill_meta.push((p.name.clone(), at_s, frac, c));
        }
    }
    let kill_runs = run(&kill_cfgs)?;
    Ok(kill_meta
        .into_iter()
        .zip(kill_runs)
        .map(|((policy, at_s, at_frac, c), r)| KillPoint {
            policy,
            at_s,
            at_frac,
            time_s: r.time_s,
            bound_s: c.time_s + 2.0 * tau + c.victim_work_s,
            timeouts: r.root.timeouts,
            reissued: r.root.reissued,
        })
        .collect())
}

/// Every bit-error rate down, up and both, over every seed.
fn ber_series(
    cfg: &FaultSweepConfig,
    base: &SimConfig,
    run: &Runner<'_>,
) -> Result<Vec<BerPoint>, SimError> {
    let mut ber_cfgs = Vec::new();
    let mut ber_meta = Vec::new();
    for &ber in &cfg.bers {
        for direction in ["down", "up", "both"] {
            for &seed in &cfg.seeds {
                let noise = Noise {
                    ber_down: if direction == "up" { 0.0 } else { ber },
                    ber_up: if direction == "down" { 0.0 } else { ber },
                    drop_broadcast: 0.0,
                    seed,
                };
                ber_cfgs.push((
                    format!("bit-error rate {ber:e} {direction}, seed {seed}"),
                    SimConfig {
                        noise,
                        ..base.clone()
                    },
                ));
                ber_meta.push((direction, ber, seed));
            }
        }
    }
    let ber_runs = run(&ber_cfgs)?;
    Ok(ber_meta
        .into_iter()
        .zip(ber_runs)
        .map(|((direction, ber, seed), r)| BerPoint {
            direction,
            ber,
            seed,
            time_s: r.time_s,
            corrupted: r.bus.iter().map(|b| b.corrupted()).sum(),
            repairs: r.root.repairs,
        })
        .collect())
}

/// Fractions of the nodes killed at once at half the fault-free frame, without bit errors
/// and (if `cfg.mixed_ber` > 0) with them.
fn fraction_series(
    cfg: &FaultSweepConfig,
    base: &SimConfig,
    clean_base: &SimReport,
    run: &Runner<'_>,
) -> Result<Vec<FractionPoint>, SimError> {
    let (nodes, tau) = (base.nodes, base.node_timeout_s);
    let mid = clean_base.time_s / 2.0;
    let mut frac_cfgs = Vec::new();
    let mut frac_meta = Vec::new();
    let series = if cfg.mixed_ber > 0.0 {
        vec![0.0, cfg.mixed_ber]
    } else {
        vec![0.0]
    };
    for ber in series {
        for &f in &cfg.kill_fractions {
            let k = ((f * nodes as f64).round() as u16).min(nodes.saturating_sub(1));
            let victims = spread(nodes, k);
            let work: f64 = victims
                .iter()
                .map(|&v| clean_base.node_compute_s[v as usize])
                .sum();
            frac_cfgs.push((
                format!("{k} of {nodes} nodes killed at {mid:.4} s, bit-error rate {ber:e}"),
                SimConfig {
                    deaths: victims
                        .iter()
                        .map(|&node| NodeDeath { node, at_s: mid })
                        .collect(),
                    noise: Noise {
                        ber_down: ber,
                        ber_up: ber,
                        drop_broadcast: 0.0,
                        seed: 1,
                    },
                    ..base.clone()
                },
            ));
            frac_meta.push((k, ber, clean_base.time_s + 2.0 * tau + work));
        }
    }
    let frac_runs = run(&frac_cfgs)?;
    Ok(frac_meta
        .into_iter()
        .zip(frac_runs)
        .map(|((killed, ber, bound_s), r)| FractionPoint {
            killed,
            ber,
            time_s: r.time_s,
            bound_s,
        })
        .collect())
}

/// The mean of `v` (0 when empty).
pub(super) fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (n, sum) = v.fold((0u32, 0.0), |(n, s), x| (n + 1, s + x));
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_picks_distinct_nodes_evenly() {
        assert_eq!(spread(16, 4), vec![0, 4, 8, 12]);
        assert_eq!(spread(16, 0), Vec::<u16>::new());
        assert_eq!(spread(5, 2), vec![0, 2]);
        assert_eq!(spread(3, 9), vec![0, 1, 2]);
    }

    #[test]
    fn the_section_is_replaced_and_missing_markers_are_an_error() {
        let doc = format!("# R\nintro\n{SECTION_BEGIN}\nold\n{SECTION_END}\nafter\n");
        assert_eq!(
            replace_section(&doc, "\nnew table\n").unwrap(),
            format!("# R\nintro\n{SECTION_BEGIN}\nnew table\n{SECTION_END}\nafter\n")
        );
        assert!(replace_section("# R\n", "x").unwrap_err().contains("no '"));
    }
}
