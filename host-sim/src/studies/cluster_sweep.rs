//! The Fig. 5.1 and Fig. 5.2 analogs: speed-up against node count, and frame time against
//! the number of sub-screens, with CSV and SVG charts.
//!
//! Each point is an independent simulation; points run on a pool of host threads and are
//! returned in input order, so results never depend on the thread count. A shared
//! [`RunCache`] saves re-rendering runs two simulations have in common.

use crate::sim::cluster::{simulate, SimConfig, SimError};
use crate::studies::chart::draw_legend;
use links_core::sched::{Policy, Split};
use plotters::prelude::*;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

/// A labelled scheduling policy.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedPolicy {
    pub name: String,
    pub policy: Policy,
}

impl NamedPolicy {
    pub fn new(name: &str, policy: Policy) -> Self {
        Self {
            name: name.into(),
            policy,
        }
    }

    /// The three policies of the node sweep: static split (a grid of one rectangle per
    /// node), fixed 1024 scanline runs (LINKS-1's best count), decreasing sizes.
    pub fn standard() -> Vec<NamedPolicy> {
        vec![
            NamedPolicy::new("static", Policy::Static { shape: Split::Rect }),
            NamedPolicy::new(
                "fixed-1024",
                Policy::Fixed {
                    divisions: 1024,
                    shape: Split::Span,
                },
            ),
            NamedPolicy::new("decreasing", Policy::DECREASING),
        ]
    }
}

/// One point of the node sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct NodePoint {
    /// The board profile's name.
    pub board: &'static str,
    pub policy: String,
    pub nodes: u16,
    pub buses: u16,
    /// Single frame, from the start of the scene broadcast to the last pixel (s).
    pub single_s: f64,
    /// Steady-state time per frame of an animation (s), see [`super::SimReport::frame_interval_s`].
    pub steady_s: f64,
    /// Speed-ups against the same policy on one node.
    pub speedup_single: f64,
    pub speedup_steady: f64,
    /// Busiest bus's busy fraction (single frame).
    pub bus_utilisation: f64,
    /// Bytes clocked on all buses for the single frame.
    pub bytes: u64,
    pub exchanges: u32,
}

/// One point of the division sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct DivisionPoint {
    /// The board profile's name.
    pub board: &'static str,
    pub policy: String,
    /// Sub-screens handed out (for decreasing sizes: how many it produced).
    pub divisions: u32,
    pub nodes: u16,
    pub time_s: f64,
    pub bus_utilisation: f64,
    pub bytes: u64,
    pub exchanges: u32,
}

/// single time, steady time, bus utilisation, bytes, exchanges.
type Measured = (f64, f64, f64, u64, u32);

pub(crate) fn pool(threads: usize) -> Result<rayon::ThreadPool, SimError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| SimError::Config(format!("cannot start threads: {e}")))
}

/// Steady-state time per frame of an animation of `image` repeated: `(T(n) - T(n / 2)) /
/// (n - n / 2)`, where `T(k)` is when the last frame of a `k`-frame run completes. The start
/// (first broadcast, pipeline fill) and the end (last frame's tail) appear in both runs and
/// cancel, so what remains is the period of the pipeline. `frames` >= 2.
pub fn steady_state_interval(image: &[u8], cfg: &SimConfig, frames: u16) -> Result<f64, SimError> {
    let n = frames.max(2);
    let m = n / 2;
    let t = |k: u16| -> Result<f64, SimError> {
        let scenes = vec![image; k as usize];
        Ok(simulate(&scenes, cfg)?.time_s)
    };
    Ok((t(n)? - t(m)?) / (n - m) as f64)
}

/// Fig. 5.1: for every policy and node count, the single-frame time and (when
/// `anim_frames >= 2`) the steady-state frame time of an `anim_frames`-frame animation of the
/// same scene, with speed-ups against one node. `base` gives buses, timing, clock, model.
/// Node counts are sorted and 1 is always included (the reference). `threads` = 0: all cores.
pub fn sweep_nodes(
    image: &[u8],
    node_counts: &[u16],
    policies: &[NamedPolicy],
    base: &SimConfig,
    anim_frames: u16,
    threads: usize,
) -> Result<Vec<NodePoint>, SimError> {
    let mut counts: Vec<u16> = node_counts.to_vec();
    counts.push(1);
    counts.sort_unstable();
    counts.dedup();
    let cache = base.cache.clone().unwrap_or_default();
    let jobs: Vec<(usize, u16)> = (0..policies.len())
        .flat_map(|p| counts.iter().map(move |&n| (p, n)))
        .collect();
    let results: Vec<Result<Measured, SimError>> = pool(threads)?.install(|| {
        jobs.par_iter()
            .map(|&(p, n)| {
                let cfg = SimConfig {
                    nodes: n,
                    policy: policies[p].policy,
                    keep_frames: false,
                    cache: Some(cache.clone()),
                    ..base.clone()
                };
                let single = simulate(&[image], &cfg)?;
                let steady = if anim_frames >= 2 {
                    steady_state_interval(image, &cfg, anim_frames)?
                } else {
                    single.time_s
                };
                Ok((
                    single.time_s,
                    steady,
                    single.bus_utilisation(),
                    single.bytes_moved(),
                    single.root.exchanges,
                ))
            })
            .collect()
    });
    let mut out = Vec::with_capacity(jobs.len());
    let mut one = (0.0, 0.0);
    for (&(p, n), r) in jobs.iter().zip(results) {
        let (single_s, steady_s, util, bytes, exchanges) = r?;
        if n == 1 {
            one = (single_s, steady_s);
        }
        out.push(NodePoint {
            board: base.profile.name,
            policy: policies[p].name.clone(),
            nodes: n,
            buses: base.buses,
            single_s,
            steady_s,
            speedup_single: one.0 / single_s,
            speedup_steady: one.1 / steady_s,
            bus_utilisation: util,
            bytes,
            exchanges,
        });
    }
    Ok(out)
}

/// Fig. 5.2: frame time against the number of fixed sub-screens (scanline runs and
/// rectangles) on `nodes` nodes, plus the static split and decreasing sizes as references.
pub fn sweep_divisions(
    image: &[u8],
    nodes: u16,
    divisions: &[u32],
    base: &SimConfig,
    threads: usize,
) -> Result<Vec<DivisionPoint>, SimError> {
    let mut policies: Vec<(String, Policy)> = Vec::new();
    for &d in divisions {
        policies.push((
            "runs".into(),
            Policy::Fixed {
                divisions: d,
                shape: Split::Span,
            },
        ));
        policies.push((
            "rects".into(),
            Policy::Fixed {
                divisions: d,
                shape: Split::Rect,
            },
        ));
    }
    policies.push(("static".into(), Policy::Static { shape: Split::Rect }));
    policies.push(("decreasing".into(), Policy::DECREASING));
    let cache = base.cache.clone().unwrap_or_default();
    let results: Vec<Result<Option<DivisionPoint>, SimError>> = pool(threads)?.install(|| {
        policies
            .par_iter()
            .map(|(name, policy)| {
                let cfg = SimConfig {
                    nodes,
                    policy: *policy,
                    keep_frames: false,
                    cache: Some(cache.clone()),
                    ..base.clone()
                };
                match simulate(&[image], &cfg) {
                    Ok(r) => Ok(Some(DivisionPoint {
                        board: base.profile.name,
                        policy: name.clone(),
                        divisions: r.root.jobs,
                        nodes,
                        time_s: r.time_s,
                        bus_utilisation: r.bus_utilisation(),
                        bytes: r.bytes_moved(),
                        exchanges: r.root.exchanges,
                    })),
                    // A grid the screen cannot take (more cells than pixels a side): skip.
                    Err(SimError::Root(links_core::root::RootError::Sched(_))) => Ok(None),
                    Err(e) => Err(e),
                }
            })
            .collect()
    });
    let mut out = Vec::new();
    for r in results {
        if let Some(p) = r? {
            out.push(p);
        }
    }
    Ok(out)
}

/// The node sweep as CSV.
pub fn nodes_csv(points: &[NodePoint]) -> String {
    let mut s = String::from(
        "policy,nodes,buses,single_s,steady_s,speedup_single,speedup_steady,bus_utilisation,bytes,exchanges,board\n",
    );
    for p in points {
        let _ = writeln!(
            s,
            "{},{},{},{:.6},{:.6},{:.3},{:.3},{:.4},{},{},{}",
            p.policy,
            p.nodes,
            p.buses,
            p.single_s,
            p.steady_s,
            p.speedup_single,
            p.speedup_steady,
            p.bus_utilisation,
            p.bytes,
            p.exchanges,
            p.board
        );
    }
    s
}

/// The division sweep as CSV.
pub fn divisions_csv(points: &[DivisionPoint]) -> String {
    let mut s =
        String::from("policy,divisions,nodes,time_s,bus_utilisation,bytes,exchanges,board\n");
    for p in points {
        let _ = writeln!(
            s,
            "{},{},{},{:.6},{:.4},{},{},{}",
            p.policy,
            p.divisions,
            p.nodes,
            p.time_s,
            p.bus_utilisation,
            p.bytes,
            p.exchanges,
            p.board
        );
    }
    s
}

const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// A chart that could not be drawn, as the sweeps' error.
pub(crate) fn chart_err<E: std::fmt::Display>(e: E) -> SimError {
    SimError::Config(format!("chart: {e}"))
}

/// Speed-up against node count (single frame solid, steady state dashed-by-marker), one
/// line per policy, with the ideal line; an SVG file.
pub fn write_nodes_chart(path: &Path, points: &[NodePoint], title: &str) -> Result<(), SimError> {
    crate::studies::chart::ensure_font().map_err(chart_err)?;
    let root = SVGBackend::new(path, (800, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(chart_err)?;
    let max_n = points.iter().map(|p| p.nodes).max().unwrap_or(1) as f64;
    let max_s = points
        .iter()
        .map(|p| p.speedup_single.max(p.speedup_steady))
        .fold(1.0, f64::max)
        .max(max_n.min(64.0));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0f64..max_n * 1.02, 0f64..max_s * 1.1)
        .map_err(chart_err)?;
    chart
        .configure_mesh()
        .x_desc("nodes")
        .y_desc("speed-up vs 1 node")
        .draw()
        .map_err(chart_err)?;
    chart
        .draw_series(LineSeries::new(
            [(0.0, 0.0), (max_n, max_n)],
            BLACK.mix(0.3),
        ))
        .map_err(chart_err)?
        .label("ideal")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.3)));
    let mut names: Vec<&str> = Vec::new();
    for p in points {
        if !names.contains(&p.policy.as_str()) {
            names.push(&p.policy);
        }
    }
    for (i, name) in names.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        let pts: Vec<&NodePoint> = points.iter().filter(|p| p.policy == *name).collect();
        chart
            .draw_series(LineSeries::new(
                pts.iter().map(|p| (p.nodes as f64, p.speedup_single)),
                c.stroke_width(2),
            ))
            .map_err(chart_err)?
            .label(format!("{name}, single frame"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(LineSeries::new(
                pts.iter().map(|p| (p.nodes as f64, p.speedup_steady)),
                c.mix(0.5).stroke_width(1),
            ))
            .map_err(chart_err)?;
        chart
            .draw_series(
                pts.iter()
                    .map(|p| Circle::new((p.nodes as f64, p.speedup_steady), 3, c.filled())),
            )
            .map_err(chart_err)?
            .label(format!("{name}, steady state (dots)"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft).map_err(chart_err)?;
    root.present().map_err(chart_err)
}

/// Frame time against the number of sub-screens (log scale), runs and rectangles, with the
/// static split and decreasing sizes as horizontal references; an SVG file.
pub fn write_divisions_chart(
    path: &Path,
    points: &[DivisionPoint],
    title: &str,
) -> Result<(), SimError> {
    crate::studies::chart::ensure_font().map_err(chart_err)?;
    let root = SVGBackend::new(path, (800, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(chart_err)?;
    let fixed: Vec<&DivisionPoint> = points
        .iter()
        .filter(|p| p.policy == "runs" || p.policy == "rects")
        .collect();
    let dmin = fixed.iter().map(|p| p.divisions).min().unwrap_or(1).max(1) as f64;
    let dmax = fixed.iter().map(|p| p.divisions).max().unwrap_or(2).max(2) as f64;
    let tmax = points.iter().map(|p| p.time_s).fold(0.0, f64::max);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d((dmin * 0.9..dmax * 1.1).log_scale(), 0f64..tmax * 1.1)
        .map_err(chart_err)?;
    chart
        .configure_mesh()
        .x_desc("sub-screens (log)")
        .y_desc("frame time, s (virtual)")
        .draw()
        .map_err(chart_err)?;
    for (i, name) in ["runs", "rects"].iter().enumerate() {
        let c = COLOURS[i];
        let pts: Vec<(f64, f64)> = fixed
            .iter()
            .filter(|p| p.policy == *name)
            .map(|p| (p.divisions as f64, p.time_s))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
            .map_err(chart_err)?
            .label(format!("fixed, {name}"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))
            .map_err(chart_err)?;
    }
    for (i, name) in ["static", "decreasing"].iter().enumerate() {
        let c = COLOURS[2 + i];
        if let Some(p) = points.iter().find(|p| p.policy == *name) {
            chart
                .draw_series(LineSeries::new(
                    [(dmin * 0.9, p.time_s), (dmax * 1.1, p.time_s)],
                    c.stroke_width(1),
                ))
                .map_err(chart_err)?
                .label(format!("{name} ({} sub-screens)", p.divisions))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c));
        }
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperMiddle).map_err(chart_err)?;
    root.present().map_err(chart_err)
}
