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

use super::star::{NodeDeath, Noise};
use super::sweep::{pool, NamedPolicy};
use super::{simulate, RunCache, SimConfig, SimError, SimReport};
use plotters::coord::Shift;
use plotters::prelude::*;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

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
    /// The sweep of docs/reliability.md on `nodes` nodes with time-out `timeout_s`.
    pub fn standard(nodes: u16, timeout_s: f64) -> Self {
        use links_core::sched::{Policy, Split};
        let div = 4 * nodes as u32;
        Self {
            base: SimConfig {
                nodes,
                node_timeout_s: timeout_s,
                cache: Some(RunCache::new()),
                ..SimConfig::default()
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
    let tau = base.node_timeout_s;
    progress("fault-free frames (every policy)");
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
    let clean_runs = run_all(image, reference, &clean_cfgs, threads)?;
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

    progress(&format!(
        "node {} killed at {} moments, {} policies",
        cfg.victim,
        cfg.kill_steps + 1,
        cfg.policies.len()
    ));
    let steps = cfg.kill_steps.max(1);
    let mut kill_cfgs = Vec::new();
    let mut kill_meta = Vec::new();
    for (p, c) in cfg.policies.iter().zip(&clean) {
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
    let kill_runs = run_all(image, reference, &kill_cfgs, threads)?;
    let kills = kill_meta
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
        .collect();

    // The noise and fraction series use the base policy (decreasing).
    let clean_base = run_all(
        image,
        reference,
        &[("fault-free".into(), base.clone())],
        threads,
    )?
    .remove(0);
    progress(&format!(
        "bit errors: {} rates x 3 directions x {} seeds",
        cfg.bers.len(),
        cfg.seeds.len()
    ));
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
    let ber_runs = run_all(image, reference, &ber_cfgs, threads)?;
    let bers = ber_meta
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
        .collect();

    progress("fractions of the nodes killed mid-frame");
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
    let frac_runs = run_all(image, reference, &frac_cfgs, threads)?;
    let fractions = frac_meta
        .into_iter()
        .zip(frac_runs)
        .map(|((killed, ber, bound_s), r)| FractionPoint {
            killed,
            ber,
            time_s: r.time_s,
            bound_s,
        })
        .collect();
    Ok(FaultSweep {
        nodes,
        width,
        height,
        timeout_s: tau,
        victim: cfg.victim,
        clean,
        kills,
        clean_s: clean_base.time_s,
        bers,
        fractions,
    })
}

/// Every point as CSV: `series,policy,x,seed,time_s,bound_s,clean_s` where `x` is the kill
/// moment (fraction of the fault-free frame), the bit-error rate, or the fraction killed.
pub fn faults_csv(s: &FaultSweep) -> String {
    let mut out = String::from("series,policy,x,seed,time_s,bound_s,clean_s\n");
    for k in &s.kills {
        let clean = s
            .clean
            .iter()
            .find(|c| c.policy == k.policy)
            .map_or(0.0, |c| c.time_s);
        let _ = writeln!(
            out,
            "kill-moment,{},{:.4},,{:.6},{:.6},{clean:.6}",
            k.policy, k.at_frac, k.time_s, k.bound_s
        );
    }
    for b in &s.bers {
        let _ = writeln!(
            out,
            "ber-{},decreasing,{:e},{},{:.6},,{:.6}",
            b.direction, b.ber, b.seed, b.time_s, s.clean_s
        );
    }
    for f in &s.fractions {
        let _ = writeln!(
            out,
            "killed-ber-{:e},decreasing,{:.4},1,{:.6},{:.6},{:.6}",
            f.ber,
            f.killed as f64 / s.nodes as f64,
            f.time_s,
            f.bound_s,
            s.clean_s
        );
    }
    out
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (n, sum) = v.fold((0u32, 0.0), |(n, s), x| (n + 1, s + x));
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// The tables of docs/reliability.md's generated section.
pub fn faults_markdown(s: &FaultSweep, command: &str) -> String {
    let mut m = String::new();
    let _ = writeln!(
        m,
        "Generated by `{command}`: {}x{} on {} nodes, 1 bus at 42 MHz, time-out τ = {} s; every frame bit-identical to the single-node render (the sweep fails otherwise). Times are virtual.\n",
        s.width, s.height, s.nodes, s.timeout_s
    );
    let _ = writeln!(
        m,
        "**Node {} killed at {} moments across the frame** (from 0 to the fault-free frame's end), per policy; the bound is `clean + 2τ + W`, W the node's compute in the fault-free frame:\n",
        s.victim,
        s.kills.len() / s.clean.len().max(1)
    );
    m.push_str("| policy | fault-free (s) | W (s) | bound (s) | worst frame (s) | killed at (s) | worst delay / allowance | mean frame (s) |\n|---|---|---|---|---|---|---|---|\n");
    for c in &s.clean {
        let pts: Vec<&KillPoint> = s.kills.iter().filter(|k| k.policy == c.policy).collect();
        let Some(worst) = pts.iter().max_by(|a, b| a.time_s.total_cmp(&b.time_s)) else {
            continue;
        };
        let allowance = worst.bound_s - c.time_s;
        let _ = writeln!(
            m,
            "| {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.0}% | {:.4} |",
            c.policy,
            c.time_s,
            c.victim_work_s,
            worst.bound_s,
            worst.time_s,
            worst.at_s,
            100.0 * (worst.time_s - c.time_s) / allowance,
            mean(pts.iter().map(|k| k.time_s)),
        );
    }
    let _ = writeln!(
        m,
        "\n**Bit errors** (decreasing; fault-free {:.4} s; mean of {} seeds, in parentheses the slowest seed):\n",
        s.clean_s,
        s.bers
            .iter()
            .map(|b| b.seed)
            .collect::<std::collections::BTreeSet<_>>()
            .len()
    );
    m.push_str("| bit-error rate | down only (s) | up only (s) | both (s) | both / fault-free | frames corrupted (both) | scene repairs (both) |\n|---|---|---|---|---|---|---|\n");
    let mut rates: Vec<f64> = s.bers.iter().map(|b| b.ber).collect();
    rates.dedup();
    for ber in rates {
        let cell = |dir: &str| {
            let pts: Vec<&BerPoint> = s
                .bers
                .iter()
                .filter(|b| b.ber == ber && b.direction == dir)
                .collect();
            let max = pts.iter().map(|b| b.time_s).fold(0.0, f64::max);
            (mean(pts.iter().map(|b| b.time_s)), max, pts)
        };
        let (down, down_max, _) = cell("down");
        let (up, up_max, _) = cell("up");
        let (both, both_max, pts) = cell("both");
        let _ = writeln!(
            m,
            "| {ber:e} | {down:.4} ({down_max:.4}) | {up:.4} ({up_max:.4}) | {both:.4} ({both_max:.4}) | {:.2}x | {:.0} | {:.0} |",
            both / s.clean_s,
            mean(pts.iter().map(|b| b.corrupted as f64)),
            mean(pts.iter().map(|b| b.repairs as f64)),
        );
    }
    let _ = writeln!(
        m,
        "\n**Nodes killed at once at {:.4} s** (half the fault-free frame; decreasing, nodes spread evenly); the bound is `clean + 2τ + ΣW` over the killed nodes:\n",
        s.clean_s / 2.0
    );
    let mut bers: Vec<f64> = s.fractions.iter().map(|f| f.ber).collect();
    bers.dedup();
    m.push_str("| killed | bound (s) |");
    for b in &bers {
        if *b == 0.0 {
            m.push_str(" frame, no bit errors (s) |");
        } else {
            let _ = write!(m, " frame, bit-error rate {b:e} both ways (s) |");
        }
    }
    m.push_str("\n|---|---|");
    for _ in &bers {
        m.push_str("---|");
    }
    m.push('\n');
    let mut ks: Vec<u16> = s.fractions.iter().map(|f| f.killed).collect();
    ks.sort_unstable();
    ks.dedup();
    for k in ks {
        let row: Vec<&FractionPoint> = s.fractions.iter().filter(|f| f.killed == k).collect();
        let _ = write!(
            m,
            "| {k} of {} ({:.0}%) | {:.4} |",
            s.nodes,
            100.0 * k as f64 / s.nodes as f64,
            row.first().map_or(0.0, |f| f.bound_s)
        );
        for b in &bers {
            match row.iter().find(|f| f.ber == *b) {
                Some(f) => {
                    let _ = write!(m, " {:.4} |", f.time_s);
                }
                None => m.push_str(" |"),
            }
        }
        m.push('\n');
    }
    m
}

const COLOURS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];

fn chart_err<E: std::fmt::Display>(e: E) -> SimError {
    SimError::Config(format!("chart: {e}"))
}

/// The legend every panel draws: top left, on a translucent white box.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.3))
        .draw()
        .map_err(chart_err)
}

/// Size of the chart (pixels).
const CHART: (u32, u32) = (820, 1500);

fn draw_all<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    s: &FaultSweep,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(chart_err)?;
    let panels = root.split_evenly((3, 1));
    draw_kills(&panels[0], s)?;
    draw_bers(&panels[1], s)?;
    draw_fractions(&panels[2], s)?;
    root.present().map_err(chart_err)
}

/// The three panels: kill moment, bit-error rate, fraction killed. An SVG file.
pub fn write_faults_chart(path: &Path, s: &FaultSweep) -> Result<(), SimError> {
    crate::chart::ensure_font().map_err(chart_err)?;
    draw_all(SVGBackend::new(path, CHART).into_drawing_area(), s)
}

/// The same chart as a PNG.
pub fn faults_png(s: &FaultSweep) -> Result<Vec<u8>, SimError> {
    crate::chart::ensure_font().map_err(chart_err)?;
    let (w, h) = CHART;
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    draw_all(
        BitMapBackend::with_buffer(&mut rgb, CHART).into_drawing_area(),
        s,
    )?;
    crate::frame::encode_png(w, h, &rgb).map_err(chart_err)
}

fn draw_kills<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    s: &FaultSweep,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    let tmax = s
        .kills
        .iter()
        .map(|k| k.time_s.max(k.bound_s))
        .fold(0.0, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "node {} of {} killed at a moment of the frame (τ = {} s)",
                s.victim, s.nodes, s.timeout_s
            ),
            ("sans-serif", 18),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..1.0, 0f64..tmax * 1.4)
        .map_err(chart_err)?;
    chart
        .configure_mesh()
        .x_desc("moment of death (fraction of the fault-free frame)")
        .y_desc("frame time, s (virtual)")
        .draw()
        .map_err(chart_err)?;
    for (i, c) in s.clean.iter().enumerate() {
        let col = COLOURS[i % COLOURS.len()];
        let pts: Vec<(f64, f64)> = s
            .kills
            .iter()
            .filter(|k| k.policy == c.policy)
            .map(|k| (k.at_frac, k.time_s))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(2)))
            .map_err(chart_err)?
            .label(c.policy.clone())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 2, col.filled())))
            .map_err(chart_err)?;
        let bound = c.time_s + 2.0 * s.timeout_s + c.victim_work_s;
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, bound), (1.0, bound)],
                6,
                4,
                col.stroke_width(1),
            ))
            .map_err(chart_err)?;
    }
    chart
        .draw_series(std::iter::once(PathElement::new(
            [(0.0, 0.0), (0.0, 0.0)],
            BLACK,
        )))
        .map_err(chart_err)?
        .label("dashed: each policy's bound, clean + 2τ + W")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.6)));
    draw_legend(&mut chart)
}

fn draw_bers<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    s: &FaultSweep,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    let bmin = s
        .bers
        .iter()
        .map(|b| b.ber)
        .fold(f64::MAX, f64::min)
        .min(1e-6);
    let bmax = s
        .bers
        .iter()
        .map(|b| b.ber)
        .fold(0.0, f64::max)
        .max(bmin * 10.0);
    let tmax = s.bers.iter().map(|b| b.time_s).fold(s.clean_s, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("bit errors ({} nodes, decreasing)", s.nodes),
            ("sans-serif", 18),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (bmin * 0.7..bmax * 1.4).log_scale(),
            (s.clean_s * 0.6..tmax * 1.5).log_scale(),
        )
        .map_err(chart_err)?;
    chart
        .configure_mesh()
        .x_desc("bit-error rate (log)")
        .y_desc("frame time, s (virtual, log)")
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .y_label_formatter(&|y| format!("{y:.2}"))
        .y_labels(7)
        .draw()
        .map_err(chart_err)?;
    chart
        .draw_series(LineSeries::new(
            [(bmin * 0.7, s.clean_s), (bmax * 1.4, s.clean_s)],
            BLACK.mix(0.4),
        ))
        .map_err(chart_err)?
        .label("fault-free")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.4)));
    // "both" is drawn over "down" (they nearly coincide: the down-link's errors cost), thinner.
    for (i, dir) in ["down", "up", "both"].iter().enumerate() {
        let col = COLOURS[i];
        let width = if i == 0 { 5 } else { 2 };
        let mut rates: Vec<f64> = s.bers.iter().map(|b| b.ber).collect();
        rates.dedup();
        let line: Vec<(f64, f64)> = rates
            .iter()
            .map(|&r| {
                (
                    r,
                    mean(
                        s.bers
                            .iter()
                            .filter(|b| b.ber == r && b.direction == *dir)
                            .map(|b| b.time_s),
                    ),
                )
            })
            .collect();
        chart
            .draw_series(LineSeries::new(line, col.stroke_width(width)))
            .map_err(chart_err)?
            .label(format!("{dir} (mean; dots: seeds)"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(width)));
        chart
            .draw_series(
                s.bers
                    .iter()
                    .filter(|b| b.direction == *dir)
                    .map(|b| Circle::new((b.ber, b.time_s), 2, col.filled())),
            )
            .map_err(chart_err)?;
    }
    draw_legend(&mut chart)
}

fn draw_fractions<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    s: &FaultSweep,
) -> Result<(), SimError>
where
    DB::ErrorType: 'static,
{
    let tmax = s
        .fractions
        .iter()
        .map(|f| f.time_s.max(f.bound_s))
        .fold(0.0, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "nodes killed at once mid-frame ({} nodes, decreasing)",
                s.nodes
            ),
            ("sans-serif", 18),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..1.0, 0f64..tmax * 1.1)
        .map_err(chart_err)?;
    chart
        .configure_mesh()
        .x_desc("fraction of the nodes killed")
        .y_desc("frame time, s (virtual)")
        .draw()
        .map_err(chart_err)?;
    let mut bers: Vec<f64> = s.fractions.iter().map(|f| f.ber).collect();
    bers.dedup();
    let n = s.nodes as f64;
    for (i, ber) in bers.iter().enumerate() {
        let col = COLOURS[i % COLOURS.len()];
        let pts: Vec<(f64, f64)> = s
            .fractions
            .iter()
            .filter(|f| f.ber == *ber)
            .map(|f| (f.killed as f64 / n, f.time_s))
            .collect();
        let label = if *ber == 0.0 {
            "no bit errors".to_string()
        } else {
            format!("bit-error rate {ber:e} both ways")
        };
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(2)))
            .map_err(chart_err)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, col.filled())))
            .map_err(chart_err)?;
    }
    let bound: Vec<(f64, f64)> = s
        .fractions
        .iter()
        .filter(|f| f.ber == 0.0)
        .map(|f| (f.killed as f64 / n, f.bound_s))
        .collect();
    chart
        .draw_series(DashedLineSeries::new(
            bound,
            6,
            4,
            BLACK.mix(0.6).stroke_width(1),
        ))
        .map_err(chart_err)?
        .label("bound without bit errors, clean + 2τ + ΣW")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.6)));
    draw_legend(&mut chart)
}

/// The generated section of docs/reliability.md lies between these markers.
pub const SECTION_BEGIN: &str = "<!-- faults-sweep:begin (links sweep faults) -->";
pub const SECTION_END: &str = "<!-- faults-sweep:end -->";

/// Replace the generated section of `doc` with `text`.
pub fn replace_section(doc: &str, text: &str) -> Result<String, String> {
    let (Some(b), Some(e)) = (doc.find(SECTION_BEGIN), doc.find(SECTION_END)) else {
        return Err(format!(
            "the document has no '{SECTION_BEGIN}' ... '{SECTION_END}' section"
        ));
    };
    if e < b {
        return Err("section markers out of order".into());
    }
    Ok(format!(
        "{}\n{}\n{}",
        &doc[..b + SECTION_BEGIN.len()],
        text.trim_matches('\n'),
        &doc[e..]
    ))
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
