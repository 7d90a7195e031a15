//! The simulated LINKS-1 cluster: the shared RC and NC logic (`links_core::{root, node}`)
//! over an emulated SPI star in deterministic virtual time.
//!
//! - [`exec`]: the discrete-event executor (virtual time, fixed poll order).
//! - [`dm`]: the DM stage (each frame's scene appears after a fixed DM time per frame).
//! - [`star`]: buses, ready lines, DMA banks, timing, fault injection, the snooping collector.
//! - [`framemem`]: the 1024 x 1024 RGB8 frame memory.
//! - [`rccost`]: the RC's CPU (composing, checking, decoding frames) in virtual time.
//!
//! The sweeps over many simulations live in [`crate::studies`] ([`sweep`] and
//! [`reliability`] here are their old paths).
//!
//! Node compute time is [`CycleModel::cycles`] of each run's operation counts at the
//! configured core clock. A simulation is single-threaded and its results depend only on its
//! inputs; sweeps run independent simulations on several host threads.

pub mod dm;
pub mod exec;
pub mod framemem;
pub mod rccost;
pub mod star;

pub use crate::studies::cluster_sweep as sweep;
pub use crate::studies::faults as reliability;
pub use sweep::{
    divisions_csv, nodes_csv, steady_state_interval, sweep_divisions, sweep_nodes,
    write_divisions_chart, write_nodes_chart, DivisionPoint, NamedPolicy, NodePoint,
};

use crate::cost::{CycleModel, DEFAULT_CLOCK_HZ};
use exec::{Delay, ExecError, Ps, SharedClock, Task};
use framemem::{FrameMemory, ViaRoot};
use links_core::image::SceneView;
use links_core::node::{run_node, NodeConfig, NodeReport, RunRenderer, Tracing, WorkClock};
use links_core::render::{render_run, RenderError, Rgb8, Stats, Tracer};
use links_core::root::{
    run_bus, PixelSink, RootConfig, RootError, RootReport, RootState, MAX_BUSES,
};
use links_core::sched::Policy;
use links_core::wire::{self, Job};
use rccost::{RcClock, RcCost};
use star::{
    BroadcastDrop, BusCounters, BusTiming, Faults, NodeDeath, Noise, SimBus, SimNodeLink, Star,
};
use std::cell::RefCell;
use std::collections::HashMap;
use std::fmt;
use std::rc::Rc;
use std::sync::{Arc, Mutex};

/// How finished pixels reach the frame memory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Collect {
    /// The collector snoops every bus (IMSU snoop read): pixels never cross the RC.
    #[default]
    Snoop,
    /// The RC writes each accepted run into the frame memory.
    ViaRoot,
}

/// One simulation's set-up.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// Node computers (1..=256).
    pub nodes: u16,
    /// SPI buses from the RC (1..=8); nodes are split evenly across them.
    pub buses: u16,
    pub policy: Policy,
    pub timing: BusTiming,
    /// Node core clock (Hz).
    pub clock_hz: f64,
    pub model: CycleModel,
    pub faults: Faults,
    /// Random bit errors per direction and lost broadcasts.
    pub noise: Noise,
    /// Nodes that die (stop answering) during the run.
    pub deaths: Vec<NodeDeath>,
    /// Nodes that lose some broadcasts whole (off the bus for a while, then back).
    pub drops: Vec<BroadcastDrop>,
    /// A node's scene bank (bytes): a larger scene is refused before the run. Default: the
    /// NC board's even-frame bank, [`nc_fw::plan::SCENE_EVEN`] (the simulated nodes have two
    /// banks this size).
    pub bank_bytes: usize,
    /// The RC declares a node holding jobs dead after this long without an exchange (s) and
    /// re-issues its jobs; 0 = never. Default [`RootConfig::DEFAULT_TIMEOUT_US`] (0.5 s).
    pub node_timeout_s: f64,
    /// DM time per frame (s): frame `f`'s scene exists from `(f + 1) · dm_s_per_frame` on.
    /// Default 0: every scene is compiled before the run (see docs/cluster.md).
    pub dm_s_per_frame: f64,
    pub collect: Collect,
    /// Node options (run-length coded pixel runs).
    pub node: NodeConfig,
    /// The RC's CPU cost of composing and decoding frames.
    pub rc_cost: RcCost,
    /// RC-side DMA double buffering (compose the next transfer and decode the previous
    /// one while a transfer is on the wire); `false`: one transfer at a time.
    pub rc_double_buffer: bool,
    /// Keep a copy of every finished frame in the report.
    pub keep_frames: bool,
    /// Memo of rendered runs shared between simulations of the same scenes (sweeps). The
    /// memo returns exactly what rendering returns, so it changes no result.
    pub cache: Option<Arc<RunCache>>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            nodes: 64,
            buses: 1,
            policy: Policy::DECREASING,
            timing: BusTiming::default(),
            clock_hz: DEFAULT_CLOCK_HZ,
            model: CycleModel::default(),
            faults: Faults::default(),
            noise: Noise::default(),
            deaths: Vec::new(),
            drops: Vec::new(),
            bank_bytes: nc_fw::plan::SCENE_EVEN,
            node_timeout_s: RootConfig::DEFAULT_TIMEOUT_US as f64 * 1e-6,
            dm_s_per_frame: 0.0,
            collect: Collect::Snoop,
            node: NodeConfig::default(),
            rc_cost: RcCost::default(),
            rc_double_buffer: true,
            keep_frames: false,
            cache: None,
        }
    }
}

/// What a simulation measured (all times virtual).
#[derive(Clone, Debug)]
pub struct SimReport {
    pub nodes: u16,
    pub buses: u16,
    pub policy: Policy,
    pub width: u32,
    pub height: u32,
    /// Completion time of each frame (s).
    pub frame_done_s: Vec<f64>,
    /// Time of the last frame's completion (s).
    pub time_s: f64,
    /// Compute time summed over all nodes (s): the work a single node would do alone,
    /// without any communication.
    pub compute_s: f64,
    /// Compute time of each node (s).
    pub node_compute_s: Vec<f64>,
    /// Time the RC's CPU was busy composing and decoding frames (s).
    pub rc_busy_s: f64,
    pub bus: Vec<BusCounters>,
    pub root: RootReport,
    pub node_reports: Vec<NodeReport>,
    /// The frames (RGB8 rows) if `keep_frames`.
    pub frames: Vec<Vec<u8>>,
    /// Operation counts summed over all nodes.
    pub stats: Stats,
}

impl SimReport {
    /// Busy fraction of the busiest bus over the whole run.
    pub fn bus_utilisation(&self) -> f64 {
        let t = self.time_s * 1e12;
        self.bus
            .iter()
            .map(|b| b.busy_ps as f64 / t)
            .fold(0.0, f64::max)
    }
    /// Bytes clocked on all buses.
    pub fn bytes_moved(&self) -> u64 {
        self.bus.iter().map(|b| b.clocked_bytes).sum()
    }
    /// Steady-state time per frame: mean interval between frame completions after the
    /// first (the first frame's time if there is only one).
    pub fn frame_interval_s(&self) -> f64 {
        match self.frame_done_s.as_slice() {
            [] => 0.0,
            [t] => *t,
            [first, .., last] => (last - first) / (self.frame_done_s.len() - 1) as f64,
        }
    }
    /// Node efficiency: compute time over nodes x elapsed time.
    pub fn efficiency(&self) -> f64 {
        self.compute_s / (self.nodes as f64 * self.time_s)
    }
}

/// Why a simulation could not run or finish.
#[derive(Debug)]
pub enum SimError {
    Config(String),
    /// Frame `frame`'s scene image (`bytes`) does not fit a node's scene bank (`bank`
    /// bytes, [`SimConfig::bank_bytes`]); found before the cluster starts.
    SceneTooBig {
        frame: u16,
        bytes: usize,
        bank: usize,
    },
    Root(RootError),
    /// The cluster could not finish: what it waited for when the simulation stopped.
    Unfinished(Box<Unfinished>),
    /// A frame differs from the single-node render (a broken promise, never expected).
    NotIdentical {
        what: String,
    },
    /// An error of one point of a sweep.
    Context {
        what: String,
        error: Box<SimError>,
    },
}

/// What a cluster that cannot finish lacks, when the simulation stopped (stalled, no pixel
/// accepted for a long time, or past its time limit).
#[derive(Clone, Debug)]
pub struct Unfinished {
    /// Why the simulation stopped.
    pub cause: ExecError,
    /// The first frame not complete, and how many frames there are.
    pub frame: u16,
    pub frames: u16,
    /// Sub-screens handed out and never returned: (holder, job, holder declared dead).
    pub never_returned: Vec<(u16, Job, bool)>,
    /// Sub-screens of the frame being handed out (`handing_out`) never handed out.
    pub unissued: u32,
    pub handing_out: u16,
    /// Static split: nodes whose region of that frame still waits for them to ask.
    pub reserved_for: Vec<u16>,
    /// Nodes the RC has declared dead.
    pub declared_dead: Vec<u16>,
    /// Nodes not killed that never reported the scene of the frame being handed out.
    pub no_scene: Vec<u16>,
    /// Nodes killed by fault injection: (node, when, s).
    pub killed: Vec<(u16, f64)>,
}

/// "node 3" or "nodes 0, 1, 2" (at most 12 listed).
fn node_list(nodes: &[u16]) -> String {
    let mut s = String::from(if nodes.len() == 1 { "node " } else { "nodes " });
    let shown: Vec<String> = nodes.iter().take(12).map(|n| n.to_string()).collect();
    s.push_str(&shown.join(", "));
    if nodes.len() > 12 {
        s.push_str(&format!(" and {} more", nodes.len() - 12));
    }
    s
}

fn region_text(r: &wire::Region) -> String {
    match *r {
        wire::Region::Span { start, len } => format!("pixels {start}..{}", start + len),
        wire::Region::Rect { x, y, w, h } => format!("{w}x{h} at ({x}, {y})"),
    }
}

impl fmt::Display for Unfinished {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the cluster cannot finish frame {} of {}",
            self.frame, self.frames
        )?;
        let mut parts: Vec<String> = Vec::new();
        if !self.never_returned.is_empty() {
            let items: Vec<String> = self
                .never_returned
                .iter()
                .take(8)
                .map(|(n, j, dead)| {
                    format!(
                        "frame {} {} held by node {n}{}",
                        j.frame,
                        region_text(&j.region),
                        if *dead { " (declared dead)" } else { "" }
                    )
                })
                .collect();
            let more = self.never_returned.len().saturating_sub(8);
            parts.push(format!(
                "{} sub-screen(s) never returned: {}{}",
                self.never_returned.len(),
                items.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            ));
        }
        if self.unissued > 0 {
            let mut s = format!(
                "{} sub-screen(s) of frame {} never handed out",
                self.unissued, self.handing_out
            );
            if !self.reserved_for.is_empty() {
                s.push_str(&format!(
                    " (static regions of {}, who never asked)",
                    node_list(&self.reserved_for)
                ));
            }
            parts.push(s);
        }
        if !self.declared_dead.is_empty() {
            parts.push(format!("{} declared dead", node_list(&self.declared_dead)));
        }
        if !self.no_scene.is_empty() {
            parts.push(format!(
                "{} never reported frame {}'s scene",
                node_list(&self.no_scene),
                self.handing_out
            ));
        }
        if !self.killed.is_empty() {
            let items: Vec<String> = self
                .killed
                .iter()
                .take(12)
                .map(|(n, t)| format!("node {n} killed at {t:.3} s"))
                .collect();
            let more = self.killed.len().saturating_sub(12);
            parts.push(format!(
                "{}{}",
                items.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            ));
        }
        if parts.is_empty() {
            parts.push("nothing is pending (the RC's last broadcast was lost)".into());
        }
        write!(f, ": {} (the simulation {})", parts.join("; "), self.cause)
    }
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimError::Config(s) => write!(f, "{s}"),
            SimError::SceneTooBig { frame, bytes, bank } => write!(
                f,
                "frame {frame}'s scene image is {bytes} bytes; a node's scene bank holds {bank} bytes: make the scene smaller (fewer triangles, a smaller texture)"
            ),
            SimError::Root(e) => write!(f, "root: {e}"),
            SimError::Unfinished(u) => write!(f, "{u}"),
            SimError::NotIdentical { what } => {
                write!(f, "{what}: the frame differs from the single-node render")
            }
            SimError::Context { what, error } => write!(f, "{what}: {error}"),
        }
    }
}

impl std::error::Error for SimError {}

/// (scene CRC, y, x, length) of a run.
type RunKey = (u32, u32, u32, u32);

/// Memo of rendered runs keyed by (scene CRC, y, x, length).
#[derive(Default)]
pub struct RunCache {
    map: Mutex<HashMap<RunKey, (Vec<u8>, Stats)>>,
}

impl fmt::Debug for RunCache {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.map.lock().map(|m| m.len()).unwrap_or(0);
        write!(f, "RunCache({n} runs)")
    }
}

impl RunCache {
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }
}

/// The tracer in `f32` (the nodes' format), optionally through a [`RunCache`].
struct SimRenderer {
    cache: Option<Arc<RunCache>>,
    crcs: Rc<Vec<u32>>,
}

impl RunRenderer for SimRenderer {
    fn render(
        &mut self,
        scene: SceneView<'_>,
        frame: u16,
        y: u32,
        x: u32,
        out: &mut [Rgb8],
    ) -> Result<Stats, RenderError> {
        let Some(cache) = &self.cache else {
            return Tracing::<f32>::new().render(scene, frame, y, x, out);
        };
        let key = (
            self.crcs.get(frame as usize).copied().unwrap_or(0),
            y,
            x,
            out.len() as u32,
        );
        if let Ok(m) = cache.map.lock() {
            if let Some((rgb, stats)) = m.get(&key) {
                for (o, c) in out.iter_mut().zip(rgb.chunks_exact(3)) {
                    o.copy_from_slice(c);
                }
                return Ok(*stats);
            }
        }
        let mut t = Tracer::<f32>::new(scene);
        render_run(&mut t, y, x, out)?;
        if let Ok(mut m) = cache.map.lock() {
            m.insert(key, (out.as_flattened().to_vec(), t.stats));
        }
        Ok(t.stats)
    }
}

/// Virtual time for a node's compute: the cost model at the core clock.
struct SimWork {
    clock: SharedClock,
    model: CycleModel,
    hz: f64,
    busy: Ps,
    report: Rc<RefCell<Vec<Ps>>>,
    id: usize,
}

impl WorkClock for SimWork {
    async fn worked(&mut self, stats: &Stats) {
        let cycles = self.model.cycles(stats);
        let ps = (cycles as f64 * 1e12 / self.hz).ceil() as Ps;
        self.busy += ps;
        self.report.borrow_mut()[self.id] = self.busy;
        let until = self.clock.borrow().now + ps;
        Delay::new(&self.clock, until).await;
    }
}

enum Sink<'a> {
    None,
    Memory(ViaRoot<'a>),
}

impl PixelSink for Sink<'_> {
    fn pixels(&mut self, frame: u16, y: u16, x: u16, rgb: &[u8]) {
        if let Sink::Memory(m) = self {
            m.pixels(frame, y, x, rgb);
        }
    }
}

/// Simulate the cluster rendering one frame.
pub fn simulate_frame(image: &[u8], cfg: &SimConfig) -> Result<SimReport, SimError> {
    simulate(&[image], cfg)
}

/// Simulate the cluster rendering an animation: `scenes[f]` is frame `f`'s SceneImage (the
/// DM's output; it becomes available at `(f + 1) · cfg.dm_s_per_frame`, see [`dm`]). Frame
/// `f + 1`'s scene is broadcast into the nodes' second bank while frame `f` renders. Nodes in
/// `cfg.deaths` stop answering at their time; the RC re-issues their work.
pub fn simulate<S: AsRef<[u8]>>(scenes: &[S], cfg: &SimConfig) -> Result<SimReport, SimError> {
    if cfg.nodes == 0 || cfg.nodes as usize > links_core::root::MAX_NODES {
        return Err(SimError::Config(format!("{} nodes (1 to 256)", cfg.nodes)));
    }
    if cfg.buses == 0 || cfg.buses as usize > MAX_BUSES {
        return Err(SimError::Config(format!(
            "{} buses (1 to {MAX_BUSES})",
            cfg.buses
        )));
    }
    if !(cfg.clock_hz > 0.0 && cfg.timing.bit_rate_hz > 0.0) {
        return Err(SimError::Config(
            "clock and bit rate must be positive".into(),
        ));
    }
    let times = [cfg.node_timeout_s, cfg.dm_s_per_frame];
    if times
        .iter()
        .any(|t| !(t.is_finite() && *t >= 0.0 && *t < 1e6))
    {
        return Err(SimError::Config(
            "time-out and DM time must be finite, >= 0 and < 1e6 s".into(),
        ));
    }
    if let Some(d) = cfg
        .deaths
        .iter()
        .find(|d| d.node >= cfg.nodes || !(d.at_s.is_finite() && d.at_s >= 0.0))
    {
        return Err(SimError::Config(format!(
            "node {} cannot die at {} s",
            d.node, d.at_s
        )));
    }
    cfg.noise.check().map_err(SimError::Config)?;
    let frames =
        u16::try_from(scenes.len()).map_err(|_| SimError::Config("too many frames".into()))?;
    if let Some((frame, s)) = scenes
        .iter()
        .enumerate()
        .find(|(_, s)| s.as_ref().len() > cfg.bank_bytes)
    {
        return Err(SimError::SceneTooBig {
            frame: frame as u16,
            bytes: s.as_ref().len(),
            bank: cfg.bank_bytes,
        });
    }
    let rc = RootConfig {
        policy: cfg.policy,
        nodes: cfg.nodes,
        frames,
        timeout_us: (cfg.node_timeout_s * 1e6).round() as u64,
        double_buffer: cfg.rc_double_buffer,
    };
    let root = RefCell::new(RootState::new(rc, scenes).map_err(SimError::Root)?);
    let (width, height) = root.borrow().size();
    if width as usize > framemem::FRAME_MEMORY_SIDE || height as usize > framemem::FRAME_MEMORY_SIDE
    {
        return Err(SimError::Config(format!(
            "{width}x{height} does not fit the 1024x1024 frame memory"
        )));
    }
    let bank_len = scenes.iter().map(|s| s.as_ref().len()).max().unwrap_or(0);
    let crcs = Rc::new(
        scenes
            .iter()
            .map(|s| wire::CRC32.checksum(s.as_ref()))
            .collect::<Vec<_>>(),
    );

    let clock: SharedClock = Rc::new(RefCell::new(exec::Clock::default()));
    let fm = Rc::new(RefCell::new(FrameMemory::new()));
    let snoop = (cfg.collect == Collect::Snoop).then(|| fm.clone());
    let star = Star::new(&clock, cfg.nodes, cfg.buses, cfg.timing, cfg.faults, snoop);
    for d in &cfg.deaths {
        star.borrow_mut()
            .kill_at(d.node, (d.at_s * 1e12).round() as Ps);
    }
    for d in &cfg.drops {
        star.borrow_mut().drop_broadcasts(*d);
    }
    star.borrow_mut().set_noise(cfg.noise);
    let dm = dm::DmStage::new(scenes, &clock, (cfg.dm_s_per_frame * 1e12).round() as Ps);
    let buses = star.borrow().bus_count();
    let sink = RefCell::new(match cfg.collect {
        Collect::Snoop => Sink::None,
        Collect::ViaRoot => Sink::Memory(ViaRoot(&fm)),
    });
    let busy = Rc::new(RefCell::new(vec![0 as Ps; cfg.nodes as usize]));
    let mut node_reports: Vec<NodeReport> = vec![NodeReport::default(); cfg.nodes as usize];
    let bus_results: RefCell<Vec<Option<Result<RootReport, RootError>>>> =
        RefCell::new(vec![None; buses]);
    let mut banks: Vec<[Vec<u8>; 2]> = (0..cfg.nodes)
        .map(|_| [vec![0u8; bank_len], vec![0u8; bank_len]])
        .collect();

    let rc_cpu_free = Rc::new(std::cell::Cell::new(0 as Ps));
    let rc_busy = Rc::new(std::cell::Cell::new(0 as Ps));
    let mut tasks: Vec<Option<Task<'_>>> = Vec::new();
    {
        let (root, sink, bus_results, dm) = (&root, &sink, &bus_results, &dm);
        for b in 0..buses {
            let star = star.clone();
            let rc_clock = RcClock {
                clock: clock.clone(),
                cost: cfg.rc_cost,
                sink_pixels: cfg.collect == Collect::ViaRoot,
                cpu_free: rc_cpu_free.clone(),
                busy: rc_busy.clone(),
            };
            tasks.push(Some(Box::pin(async move {
                let mut bus = SimBus::new(&star, b);
                let r = run_bus(b, &mut bus, &rc_clock, root, dm, sink).await;
                bus_results.borrow_mut()[b] = Some(r);
            })));
        }
        for (i, ([a, b], report)) in banks.iter_mut().zip(node_reports.iter_mut()).enumerate() {
            let mut link = SimNodeLink::new(&star, i as u16);
            let mut work = SimWork {
                clock: clock.clone(),
                model: cfg.model,
                hz: cfg.clock_hz,
                busy: 0,
                report: busy.clone(),
                id: i,
            };
            let mut renderer = SimRenderer {
                cache: cfg.cache.clone(),
                crcs: crcs.clone(),
            };
            let node_cfg = cfg.node;
            tasks.push(Some(Box::pin(async move {
                // A link error ends the node; the report keeps what it did.
                let _ = run_node(
                    node_cfg,
                    &mut link,
                    &mut work,
                    &mut renderer,
                    [a.as_mut_slice(), b.as_mut_slice()],
                    report,
                )
                .await;
            })));
        }
    }

    let mut done_at: Vec<Ps> = Vec::new();
    let (mut last_accepted, mut idle_passes) = (0u64, 0u32);
    let mut kept: Vec<Vec<u8>> = Vec::new();
    let limit: Ps = 100_000 * 1_000_000_000_000; // 100 000 s of virtual time
    let res = exec::run(
        &clock,
        &mut tasks,
        limit,
        || bus_results.borrow().iter().all(|r| r.is_some()),
        |now| {
            let complete = root.borrow().frames_complete() as usize;
            while done_at.len() < complete {
                let f = done_at.len() as u16;
                done_at.push(now);
                if cfg.keep_frames {
                    kept.push(fm.borrow().read(f, width, height));
                }
            }
            let accepted = root.borrow().report().accepted;
            if accepted != last_accepted {
                last_accepted = accepted;
                idle_passes = 0;
            } else {
                idle_passes += 1;
            }
            idle_passes < 200_000
        },
    );
    drop(tasks);
    if let Err(cause) = res {
        return Err(SimError::Unfinished(Box::new(unfinished(
            cause,
            &root.borrow(),
            cfg,
            frames,
        ))));
    }
    for r in bus_results.borrow().iter().flatten() {
        if let Err(e) = r {
            return Err(SimError::Root(*e));
        }
    }
    let node_ps = busy.borrow().clone();
    let compute_ps: Ps = node_ps.iter().sum();
    let mut stats = Stats::default();
    for r in &node_reports {
        stats.add(&r.stats);
    }
    let root_report = root.borrow().report();
    let bus = star.borrow().counters();
    let time_ps = done_at.last().copied().unwrap_or(0);
    Ok(SimReport {
        nodes: cfg.nodes,
        buses: buses as u16,
        policy: cfg.policy,
        width,
        height,
        frame_done_s: done_at.iter().map(|&t| t as f64 * 1e-12).collect(),
        time_s: time_ps as f64 * 1e-12,
        compute_s: compute_ps as f64 * 1e-12,
        node_compute_s: node_ps.iter().map(|&t| t as f64 * 1e-12).collect(),
        rc_busy_s: rc_busy.get() as f64 * 1e-12,
        bus,
        root: root_report,
        node_reports,
        frames: kept,
        stats,
    })
}

/// What the RC still waits for when a simulation stops unfinished.
fn unfinished(cause: ExecError, root: &RootState, cfg: &SimConfig, frames: u16) -> Unfinished {
    let killed_at = |n: u16| {
        cfg.deaths
            .iter()
            .filter(|d| d.node == n)
            .map(|d| d.at_s)
            .fold(None, |a: Option<f64>, t| Some(a.map_or(t, |a| a.min(t))))
    };
    let stopped_s = cause.at_s();
    let killed_at = |n: u16| killed_at(n).filter(|&t| t <= stopped_s);
    let handing_out = root.handing_out();
    let all = 0..cfg.nodes;
    let mut killed: Vec<(u16, f64)> = all
        .clone()
        .filter_map(|n| killed_at(n).map(|t| (n, t)))
        .collect();
    killed.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    Unfinished {
        cause,
        frame: root.frames_complete(),
        frames,
        never_returned: root.pending().collect(),
        unissued: root.unissued(),
        handing_out,
        reserved_for: all
            .clone()
            .filter(|&n| root.unissued() > 0 && root.reserved(n))
            .collect(),
        declared_dead: all.clone().filter(|&n| root.is_dead(n)).collect(),
        no_scene: all
            .filter(|&n| killed_at(n).is_none() && !root.has_scene(n, handing_out))
            .collect(),
        killed,
    }
}

/// A cluster render with its single-node reference, for `links render --nodes N`.
#[derive(Clone, Debug)]
pub struct ClusterRender {
    /// The `cfg.nodes` simulation (with the frame kept).
    pub report: SimReport,
    /// The same configuration on one node: its frame time (s).
    pub one_node_s: f64,
    /// `one_node_s / report.time_s`.
    pub speedup: f64,
}

/// Render one frame on the simulated cluster and on one node (sharing rendered runs through a
/// [`RunCache`], so the reference costs little extra host time); the frame is in
/// `report.frames[0]`.
pub fn render_cluster(image: &[u8], cfg: &SimConfig) -> Result<ClusterRender, SimError> {
    let cache = cfg.cache.clone().unwrap_or_default();
    let cfg = SimConfig {
        keep_frames: true,
        cache: Some(cache),
        ..cfg.clone()
    };
    let report = simulate_frame(image, &cfg)?;
    let one_node_s = if cfg.nodes == 1 {
        report.time_s
    } else {
        simulate_frame(
            image,
            // The reference: the same settings on one node that never fails.
            &SimConfig {
                nodes: 1,
                buses: 1,
                keep_frames: false,
                deaths: Vec::new(),
                ..cfg
            },
        )?
        .time_s
    };
    Ok(ClusterRender {
        speedup: one_node_s / report.time_s,
        one_node_s,
        report,
    })
}
