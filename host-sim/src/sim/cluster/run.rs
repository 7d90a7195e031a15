//! One simulation run, stage by stage: check the configuration, set up the RC's state, the
//! star and the DM, spawn one task per bus and per node, run the executor in virtual time
//! (recording when each frame completes), and assemble the [`SimReport`].

use super::backup::{BackupSimError, Work};
use super::backup_run::{run_line, LineCounters, LineSetup};
use super::exec::{self, Delay, ExecError, Ps, SharedClock, Task};
use super::framemem::{self, FrameMemory, ViaRoot};
use super::rccost::{LinkCpu, RcClock};
use super::relay::{RelayCode, Relays, Topology};
use super::relay_run::{self, firmware_tree, relay_tasks, RelayLink};
use super::spi_bus::{
    master_task, FirmwareBus, FirmwareLinkCounters, LinkModel, NodeOnLink, Overlapped, SharedWire,
    SpiSlave, Wire, WireTiming,
};
use super::star::{SharedStar, SimBus, SimNodeLink, Star};
use super::timeline::{LinkRow, SharedTimeline, Timeline};
use super::{dm, techniques_key, Collect, RunCache, SimConfig, SimError, SimReport, Unfinished};
use crate::cost::{CycleModel, SceneCheckCost};
use links_core::image::SceneView;
use links_core::node::{run_node, run_node_landing, Kernels, NodeReport, RunRenderer, WorkClock};
use links_core::num::{Fx, Real, Storage};
use links_core::render::{render_run, RenderError, Rgb8, Stats, Techniques, Tracer};
use links_core::root::{
    run_bus, PixelSink, RootConfig, RootError, RootReport, RootState, MAX_BUSES,
};
use links_core::spi::{
    Bank, MasterCounters, MasterShared, SlaveBanks, SlaveCounters, SlaveShared, BANK,
};
use links_core::wire;
use std::cell::{Cell, RefCell};
use std::rc::Rc;
use std::sync::Arc;

/// The tracer of the scene's storage (`f32` or Q16.16, as a node's
/// [`links_core::node::TracingByImage`]) with the configured techniques, optionally through a
/// [`RunCache`]. It carries `kernels` (the run checked them against every scene first).
struct SimRenderer {
    kernels: Kernels,
    cache: Option<Arc<RunCache>>,
    crcs: Rc<Vec<u32>>,
    techniques: Techniques,
    /// The node's number and the timeline's pixel map (frame 0), if one is recorded.
    node: u16,
    log: Option<SharedTimeline>,
}

impl SimRenderer {
    /// What a node's [`links_core::node::Tracing`] does, with `self.techniques`.
    fn trace(
        &self,
        scene: SceneView<'_>,
        y: u32,
        x: u32,
        out: &mut [Rgb8],
    ) -> Result<Stats, RenderError> {
        match scene.storage() {
            Storage::F32 => trace_run::<f32>(scene, self.techniques, (y, x), out),
            Storage::Q16_16 => trace_run::<Fx>(scene, self.techniques, (y, x), out),
        }
    }
}

/// One run of `scene` in number type `T` with `techniques`.
pub(super) fn trace_run<T: Real>(
    scene: SceneView<'_>,
    techniques: Techniques,
    (y, x): (u32, u32),
    out: &mut [Rgb8],
) -> Result<Stats, RenderError> {
    let mut t = Tracer::<T>::with_techniques(scene, techniques);
    render_run(&mut t, y, x, out)?;
    Ok(t.stats)
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
        if let Some(log) = self.log.as_ref().filter(|_| frame == 0) {
            log.borrow_mut().rendered(self.node, y, x, out.len());
        }
        let Some(cache) = &self.cache else {
            return self.trace(scene, y, x, out);
        };
        let key = (
            self.crcs.get(frame as usize).copied().unwrap_or(0),
            techniques_key(self.techniques),
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
        let stats = self.trace(scene, y, x, out)?;
        if let Ok(mut m) = cache.map.lock() {
            m.insert(key, (out.as_flattened().to_vec(), stats));
        }
        Ok(stats)
    }

    fn kernels(&self) -> Kernels {
        self.kernels
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
    log: Option<SharedTimeline>,
}

impl SimWork {
    /// Spend `cycles` of the node's core in virtual time.
    async fn spend(&mut self, cycles: u64) {
        let ps = (cycles as f64 * 1e12 / self.hz).ceil() as Ps;
        self.busy += ps;
        self.report.borrow_mut()[self.id] = self.busy;
        let now = self.clock.borrow().now;
        let until = now + ps;
        if let Some(log) = &self.log {
            log.borrow_mut().compute(self.id as u16, now, until);
        }
        Delay::new(&self.clock, until).await;
    }
}

impl WorkClock for SimWork {
    async fn worked(&mut self, stats: &Stats) {
        self.spend(self.model.cycles(stats)).await;
    }

    async fn checked_scene(&mut self, scene: &SceneView<'_>) {
        let instr = SceneCheckCost::CORTEX_M4F.instructions(scene);
        self.spend((instr * self.model.cycles_per_instruction).ceil() as u64)
            .await;
    }
}

pub(super) enum Sink<'a> {
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
/// DM's output; it becomes available at `(f + 1) · cfg.dm_s_per_frame`, or after the first
/// `f + 1` of `cfg.dm_frame_s`, see [`dm`]). Frame
/// `f + 1`'s scene is broadcast into the nodes' second bank while frame `f` renders. Nodes in
/// `cfg.deaths` stop answering at their time; the RC re-issues their work.
pub fn simulate<S: AsRef<[u8]>>(scenes: &[S], cfg: &SimConfig) -> Result<SimReport, SimError> {
    let (frames, storage) = check_config(scenes, cfg)?;
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
    let star = build_star(&clock, cfg, &fm);
    let wire = (cfg.link == LinkModel::Firmware).then(|| {
        let timing = WireTiming::of(&cfg.profile.link, cfg.timing.bit_rate_hz);
        Wire::new(&star, timing, &cfg.stuck)
    });
    let counters = LinkReport::new(star.borrow().bus_count(), cfg.nodes);
    let dm_ps: Vec<Ps> = if cfg.dm_frame_s.is_empty() {
        vec![(cfg.dm_s_per_frame * 1e12).round() as Ps; scenes.len()]
    } else {
        cfg.dm_frame_s
            .iter()
            .map(|s| (s * 1e12).round() as Ps)
            .collect()
    };
    let dm = dm::DmStage::with_times(scenes, &clock, &dm_ps);
    let buses = star.borrow().bus_count();
    let log: Option<SharedTimeline> = cfg.timeline.map(|limit| {
        let t = Timeline::new(cfg.nodes, buses, width, height, limit);
        Rc::new(RefCell::new(t))
    });
    if let Some(log) = &log {
        star.borrow_mut().set_timeline(log.clone());
    }
    let relay_link = firmware_tree(cfg).map(|tree| RelayLink::new(&clock, cfg, tree));
    if let (Some(link), Some(log)) = (&relay_link, &log) {
        link.links
            .star
            .borrow_mut()
            .set_link_timeline(log.clone(), LinkRow::Root);
        if let Some(mid) = &link.mid {
            mid.links
                .star
                .borrow_mut()
                .set_link_timeline(log.clone(), LinkRow::Mid);
        }
    }
    let sink = RefCell::new(match cfg.collect {
        Collect::Snoop => Sink::None,
        Collect::ViaRoot => Sink::Memory(ViaRoot(&fm)),
    });
    let busy = Rc::new(RefCell::new(vec![0 as Ps; cfg.nodes as usize]));
    let mut node_reports: Vec<NodeReport> = vec![NodeReport::default(); cfg.nodes as usize];
    // One `run_bus` per bus, or the root's one over its relays (on one or two links).
    let root_buses = if relay_link.is_some() { 1 } else { buses };
    let bus_results: RefCell<Vec<Option<Result<RootReport, RootError>>>> =
        RefCell::new(vec![None; root_buses]);
    let mut banks: Vec<[Vec<u8>; 2]> = (0..cfg.nodes)
        .map(|_| [vec![0u8; bank_len], vec![0u8; bank_len]])
        .collect();

    let line_counters = RefCell::new(LineCounters::default());
    let line_result: RefCell<Option<Result<(), BackupSimError>>> = RefCell::new(None);
    let rc_busy = Rc::new(Cell::new(0 as Ps));
    let mut tasks = match (&relay_link, &wire) {
        (Some(link), Some(wire)) => relay_tasks(
            cfg,
            &clock,
            (wire, &counters),
            link,
            (&rc_busy, &log),
            (&root, &sink, &bus_results, &dm),
        ),
        _ => bus_tasks(
            cfg,
            &clock,
            (&star, &wire, &counters),
            (&rc_busy, &log),
            (&root, &sink, &bus_results, &dm),
        ),
    };
    let line_on = cfg.backup_line || !cfg.spi_dead.is_empty();
    if line_on {
        let setup = line_setup(scenes, cfg, &clock, &root, &fm, &line_counters)?;
        let result = &line_result;
        tasks.push(Some(Box::pin(async move {
            *result.borrow_mut() = Some(run_line(setup).await);
        })));
    }
    tasks.extend(node_tasks(
        cfg,
        storage,
        (&clock, &star, &log),
        (&wire, &counters),
        (&busy, &crcs),
        &mut banks,
        &mut node_reports,
    ));

    let mut kept: Vec<Vec<u8>> = Vec::new();
    let keep = |f: u16| {
        if cfg.keep_frames {
            kept.push(fm.borrow().read(f, width, height));
        }
    };
    let taken = || star.borrow().relays().map_or(0, |r| r.taken_up_to());
    let relays_done = || relay_link.as_ref().is_none_or(RelayLink::ended);
    let res = run_frames(
        &clock,
        &mut tasks,
        (&root, &bus_results),
        (taken, relays_done),
        keep,
    );
    drop(tasks);
    let done_at = res.map_err(|cause| {
        SimError::Unfinished(Box::new(unfinished(cause, &root.borrow(), cfg, frames)))
    })?;
    for r in bus_results.borrow().iter().flatten() {
        if let Err(e) = r {
            return Err(SimError::Root(*e));
        }
    }
    if let Some(Err(e)) = line_result.borrow_mut().take() {
        return Err(SimError::Config(e.to_string()));
    }
    let node_ps = busy.borrow().clone();
    let compute_ps: Ps = node_ps.iter().sum();
    let mut stats = Stats::default();
    for r in &node_reports {
        stats.add(&r.stats);
    }
    let root_report = root.borrow().report();
    let bus = star.borrow().counters();
    let mut tree = star.borrow().relays().map(|r| r.report());
    let mut relayed = None;
    let mut link_counters = (cfg.link == LinkModel::Firmware).then(|| counters.sum());
    if let Some(l) = &relay_link {
        let frames_up = bus.iter().map(|b| b.exchanges).sum();
        tree = cfg
            .tree()
            .and_then(Result::ok)
            .map(|shape| l.report(shape, frames_up));
        relayed = Some(l.firmware_relays()?);
        // Every level's links: the leaf buses, the root's links and (two levels) the middle
        // relays' buses.
        let mids = l.mid.as_ref().map(|m| &m.links.counters);
        let master: Vec<_> = [Some(&counters), Some(&l.links.counters), mids]
            .into_iter()
            .flatten()
            .flat_map(|c| c.master.borrow().clone())
            .collect();
        let slaves: Vec<_> = [Some(&counters), Some(&l.links.counters), mids]
            .into_iter()
            .flatten()
            .flat_map(|c| c.slaves.borrow().clone())
            .collect();
        link_counters = Some(FirmwareLinkCounters::of(&master, &slaves));
    }
    let time_ps = done_at.last().copied().unwrap_or(0);
    drop(star);
    drop(wire);
    drop(relay_link);
    let timeline = log.map(|l| l.borrow().clone());
    let link = link_counters;
    Ok(SimReport {
        profile: cfg.profile,
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
        timeline,
        tree,
        backup: line_on.then(|| line_counters.take()),
        link,
        relayed,
    })
}

/// The backup line's task set-up: every frame's scene as the nodes' renderer sees it.
fn line_setup<'a, S: AsRef<[u8]>>(
    scenes: &'a [S],
    cfg: &'a SimConfig,
    clock: &SharedClock,
    root: &'a RefCell<RootState>,
    fm: &'a RefCell<FrameMemory>,
    counters: &'a RefCell<LineCounters>,
) -> Result<LineSetup<'a>, SimError> {
    let views = scenes
        .iter()
        .map(|s| SceneView::new(s.as_ref()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| SimError::Config(format!("backup line: {e}")))?;
    let width = root.borrow().size().0;
    let model = cfg.model_for(views.first().map_or(Storage::F32, |v| v.storage()));
    Ok(LineSetup {
        cfg,
        clock: clock.clone(),
        root,
        fm,
        scenes: scenes.iter().map(|s| s.as_ref()).collect(),
        work: Work {
            views,
            width,
            model,
            clock_hz: cfg.clock_hz,
            techniques: cfg.techniques,
        },
        counters,
    })
}

/// Refuse a configuration the simulator cannot run; the number of frames and the storage
/// of their scenes otherwise.
fn check_config<S: AsRef<[u8]>>(scenes: &[S], cfg: &SimConfig) -> Result<(u16, Storage), SimError> {
    if cfg.nodes == 0 || cfg.nodes as usize > links_core::root::MAX_NODES {
        return Err(SimError::Config(format!("{} nodes (1 to 256)", cfg.nodes)));
    }
    match cfg.tree() {
        None if cfg.buses == 0 || cfg.buses as usize > MAX_BUSES => {
            return Err(SimError::Config(format!(
                "{} buses (1 to {MAX_BUSES})",
                cfg.buses
            )));
        }
        Some(Err(e)) => return Err(SimError::Config(e.to_string())),
        _ => {}
    }
    if !(cfg.clock_hz > 0.0 && cfg.timing.bit_rate_hz > 0.0) {
        return Err(SimError::Config(
            "clock and bit rate must be positive".into(),
        ));
    }
    let times = [cfg.node_timeout_s, cfg.dm_s_per_frame];
    if times
        .iter()
        .chain(&cfg.dm_frame_s)
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
    let on_line = cfg.nodes.min(links_core::backup::MAX_ADDR as u16);
    if let Some(d) = cfg
        .spi_dead
        .iter()
        .find(|d| d.node >= on_line || !(d.at_s.is_finite() && d.at_s >= 0.0))
    {
        return Err(SimError::Config(format!(
            "node {}'s SPI link cannot die at {} s (the backup line reaches nodes 0..{on_line})",
            d.node, d.at_s
        )));
    }
    cfg.noise.check().map_err(SimError::Config)?;
    check_link(cfg)?;
    relay_run::check(cfg)?;
    let frames =
        u16::try_from(scenes.len()).map_err(|_| SimError::Config("too many frames".into()))?;
    if !cfg.dm_frame_s.is_empty() && cfg.dm_frame_s.len() != scenes.len() {
        return Err(SimError::Config(format!(
            "{} DM times for {} frames: give one per frame",
            cfg.dm_frame_s.len(),
            scenes.len()
        )));
    }
    if let Some((frame, s)) = scenes
        .iter()
        .enumerate()
        .find(|(_, s)| s.as_ref().len() > cfg.board.largest_bank())
    {
        return Err(SimError::SceneTooBig {
            frame: frame as u16,
            bytes: s.as_ref().len(),
            node: cfg.board.name,
            bank: cfg.board.largest_bank(),
        });
    }
    Ok((frames, check_kernels(scenes, cfg.kernels)?))
}

/// The storage every scene shares, if the nodes' `kernels` read it.
fn check_kernels<S: AsRef<[u8]>>(scenes: &[S], kernels: Kernels) -> Result<Storage, SimError> {
    let mut first = None;
    for (frame, s) in scenes.iter().enumerate() {
        let image = SceneView::new(s.as_ref())
            .map_err(|e| SimError::Config(format!("frame {frame}'s scene: {e}")))?
            .storage();
        let mixed = first.is_some_and(|f| f != image);
        if mixed || !kernels.run(image) {
            return Err(SimError::NoKernel {
                frame: frame as u16,
                image,
                kernels,
                mixed,
            });
        }
        first = Some(image);
    }
    Ok(first.unwrap_or(Storage::F32))
}

/// Refuse a link the board cannot run: the firmware's code needs the firmware's framing,
/// and only it has handshake lines to stick.
fn check_link(cfg: &SimConfig) -> Result<(), SimError> {
    let link = &cfg.profile.link;
    if cfg.link == LinkModel::Firmware && !LinkModel::firmware_framing(link) {
        return Err(SimError::Config(format!(
            "the firmware link frames transfers with an {}-byte header and a {}-byte trailer; the {} board's are {} and {}: use the ideal link",
            links_core::spi::HEADER,
            links_core::spi::TRAILER,
            cfg.profile.name,
            link.header_bytes,
            link.trailer_bytes
        )));
    }
    if cfg.link == LinkModel::Ideal && !cfg.stuck.is_empty() {
        return Err(SimError::Config(
            "a stuck handshake line needs the firmware link (the idealised star has none)".into(),
        ));
    }
    if let Some(st) = cfg
        .stuck
        .iter()
        .find(|s| s.node >= cfg.nodes || !(s.at_s.is_finite() && s.at_s >= 0.0))
    {
        return Err(SimError::Config(format!(
            "node {}'s handshake line cannot stick at {} s",
            st.node, st.at_s
        )));
    }
    Ok(())
}

/// The SPI star with the configuration's faults: deaths, dropped broadcasts, bit errors.
fn build_star(clock: &SharedClock, cfg: &SimConfig, fm: &Rc<RefCell<FrameMemory>>) -> SharedStar {
    let snoop = (cfg.collect == Collect::Snoop).then(|| fm.clone());
    let buses = cfg.node_buses();
    let star = Star::new(clock, cfg.nodes, buses, cfg.timing, cfg.faults, snoop);
    if let (Some(Ok(shape)), Topology::RelayTree { batch, .. }) = (cfg.tree(), cfg.topology) {
        if cfg.relay == RelayCode::Model {
            let relays = Relays::new(shape, batch, cfg.timing, cfg.rc_cost);
            star.borrow_mut().set_relays(relays);
        }
    }
    for d in cfg.deaths.iter().chain(&cfg.spi_dead) {
        star.borrow_mut()
            .kill_at(d.node, (d.at_s * 1e12).round() as Ps);
    }
    for d in &cfg.drops {
        star.borrow_mut().drop_broadcasts(*d);
    }
    star.borrow_mut().set_noise(cfg.noise);
    star
}

/// What the RC's bus tasks share: its state, the pixel sink, each bus's result, the DM.
pub(super) type RootShared<'a, S> = (
    &'a RefCell<RootState>,
    &'a RefCell<Sink<'a>>,
    &'a RefCell<Vec<Option<Result<RootReport, RootError>>>>,
    &'a dm::DmStage<'a, S>,
);

/// The RC: one task per bus, sharing one CPU ([`RcClock`]); under a relay tree each bus is
/// a leaf relay's, with a CPU of its own.
fn bus_tasks<'a, S: AsRef<[u8]>>(
    cfg: &SimConfig,
    clock: &SharedClock,
    (star, wire, counters): (&SharedStar, &Option<SharedWire>, &LinkReport),
    (rc_busy, log): (&Rc<Cell<Ps>>, &Option<SharedTimeline>),
    (root, sink, bus_results, dm): RootShared<'a, S>,
) -> Vec<Option<Task<'a>>> {
    let rc_cpu_free = Rc::new(Cell::new(0 as Ps));
    let buses = star.borrow().bus_count();
    let mut tasks: Vec<Option<Task<'a>>> = Vec::new();
    let relays = cfg.topology != Topology::Star;
    for b in 0..buses {
        let star = star.clone();
        let rc_clock = RcClock {
            clock: clock.clone(),
            cost: cfg.rc_cost,
            sink_pixels: cfg.collect == Collect::ViaRoot,
            cpu_free: if relays {
                Rc::new(Cell::new(0))
            } else {
                rc_cpu_free.clone()
            },
            busy: rc_busy.clone(),
            timeline: log.clone(),
        };
        let task: Task<'a> = match wire {
            None => Box::pin(async move {
                let mut bus = SimBus::new(&star, b);
                let r = run_bus(b, &mut bus, &rc_clock, root, dm, sink).await;
                bus_results.borrow_mut()[b] = Some(r);
            }),
            Some(wire) => {
                let (wire, report) = (wire.clone(), counters.master.clone());
                let split = cfg.rc_double_buffer;
                Box::pin(async move {
                    let end = MasterEnd {
                        split,
                        report,
                        cpu: None,
                    };
                    let rc_clock = &rc_clock;
                    on_master_bus(&wire, b, end, async move |mut bus| {
                        let r = run_bus(b, &mut bus, rc_clock, root, dm, sink).await;
                        bus_results.borrow_mut()[b] = Some(r);
                    })
                    .await
                })
            }
        };
        tasks.push(Some(task));
    }
    tasks
}

/// How the RC's end of a firmware-link bus is run ([`on_master_bus`]).
pub(super) struct MasterEnd {
    /// The board's split link (`MasterFront` + `MasterTask`, where the RC overlaps), else
    /// the inline `MasterLink`.
    pub(super) split: bool,
    /// Where the link's counters are kept (one slot per bus of the wire).
    pub(super) report: Rc<RefCell<Vec<MasterCounters>>>,
    /// The relay code's CPU work around each transfer, if charged.
    pub(super) cpu: Option<LinkCpu>,
}

/// `logic` as the master of bus `b` of `wire` (the RC's link code over the emulated SPI
/// master, on two TX banks and one RX bank): with the split link, `logic` and the
/// link's `MasterTask` polled as one simulated task ([`Overlapped`]), as the RC and a
/// relay run their buses.
pub(super) async fn on_master_bus<R>(
    wire: &SharedWire,
    b: usize,
    end: MasterEnd,
    logic: impl for<'s, 'k> AsyncFnOnce(FirmwareBus<'s, 'k>) -> R,
) -> R {
    let mut banks = Box::new([[0u8; BANK]; 3]);
    if !end.split {
        let bus = FirmwareBus::new(wire, b, &mut banks, None, end.report).with_cpu(end.cpu);
        return logic(bus).await;
    }
    let shared = MasterShared::new();
    let task = Box::pin(master_task(wire.clone(), b, &shared));
    let bus = FirmwareBus::new(wire, b, &mut banks, Some(&shared), end.report).with_cpu(end.cpu);
    Overlapped {
        shared: &shared,
        logic: Box::pin(logic(bus)),
        task,
    }
    .await
}

/// `logic` as the slave `i` of `wire` (a node's link, or a relay's towards the root):
/// `SlaveTask::run` over the emulated SPI slave on `banks` (two TX, two RX, scratch)
/// beside `logic`, polled as one simulated task ([`NodeOnLink`]); the link's counters go to
/// `slots[i]` when it ends.
pub(super) async fn on_slave_link<'b, R>(
    wire: &SharedWire,
    i: u16,
    slots: Rc<RefCell<Vec<SlaveCounters>>>,
    banks: &'b mut [Bank; 5],
    logic: impl for<'s> AsyncFnOnce(&'s SlaveShared<'b>) -> R,
) -> R {
    let mut port = SpiSlave::new(wire, i);
    let [t0, t1, r0, r1, scratch] = banks;
    let (shared, task) = SlaveShared::new(SlaveBanks {
        tx: [t0, t1],
        rx: [r0, r1],
        scratch,
    });
    let _out = SlaveCountersOut {
        shared: &shared,
        slots,
        node: i as usize,
    };
    NodeOnLink {
        link: Box::pin(task.run(&mut port, &shared)),
        logic: Box::pin(logic(&shared)),
    }
    .await
}

/// What the firmware link's ends counted, kept outside the tasks (a node's link task and
/// the RC's link live inside theirs).
pub(super) struct LinkReport {
    pub(super) master: Rc<RefCell<Vec<MasterCounters>>>,
    pub(super) slaves: Rc<RefCell<Vec<SlaveCounters>>>,
}

impl LinkReport {
    pub(super) fn new(buses: usize, nodes: u16) -> Self {
        Self {
            master: Rc::new(RefCell::new(vec![MasterCounters::default(); buses])),
            slaves: Rc::new(RefCell::new(vec![SlaveCounters::default(); nodes as usize])),
        }
    }

    fn sum(&self) -> FirmwareLinkCounters {
        FirmwareLinkCounters::of(&self.master.borrow(), &self.slaves.borrow())
    }
}

/// Copies a node's link counters into the report when its task ends or is dropped.
struct SlaveCountersOut<'s, 'b> {
    shared: &'s SlaveShared<'b>,
    slots: Rc<RefCell<Vec<SlaveCounters>>>,
    node: usize,
}

impl Drop for SlaveCountersOut<'_, '_> {
    fn drop(&mut self) {
        if let Some(slot) = self.slots.borrow_mut().get_mut(self.node) {
            *slot = self.shared.counters();
        }
    }
}

/// The nodes: one task each, rendering into its two scene banks and reporting into its slot;
/// on the firmware link each node's task also runs its link task ([`NodeOnLink`]).
fn node_tasks<'a>(
    cfg: &SimConfig,
    storage: Storage,
    (clock, star, log): (&SharedClock, &SharedStar, &Option<SharedTimeline>),
    (wire, counters): (&Option<SharedWire>, &LinkReport),
    (busy, crcs): (&Rc<RefCell<Vec<Ps>>>, &Rc<Vec<u32>>),
    banks: &'a mut [[Vec<u8>; 2]],
    node_reports: &'a mut [NodeReport],
) -> Vec<Option<Task<'a>>> {
    let mut tasks: Vec<Option<Task<'a>>> = Vec::new();
    for (i, ([a, b], report)) in banks.iter_mut().zip(node_reports.iter_mut()).enumerate() {
        let mut work = SimWork {
            clock: clock.clone(),
            model: cfg.model_for(storage),
            hz: cfg.clock_hz,
            busy: 0,
            report: busy.clone(),
            id: i,
            log: log.clone(),
        };
        let mut renderer = SimRenderer {
            kernels: cfg.kernels,
            cache: cfg.cache.clone(),
            crcs: crcs.clone(),
            techniques: cfg.techniques,
            node: i as u16,
            log: log.clone(),
        };
        let node_cfg = cfg.node;
        let scene = [a.as_mut_slice(), b.as_mut_slice()];
        let task: Task<'a> = match wire {
            None => {
                let mut link = SimNodeLink::new(star, i as u16);
                Box::pin(async move {
                    // A link error ends the node; the report keeps what it did.
                    let _ = run_node(node_cfg, &mut link, &mut work, &mut renderer, scene, report)
                        .await;
                })
            }
            Some(wire) => {
                let (wire, slots) = (wire.clone(), counters.slaves.clone());
                Box::pin(async move {
                    let mut banks: Box<[Bank; 5]> = Box::new([[0u8; BANK]; 5]);
                    on_slave_link(&wire, i as u16, slots, &mut banks, async move |shared| {
                        let mut handle = shared.handle();
                        // The node's link writes broadcast scene chunks straight into the
                        // bank it is not rendering from, as nc-fw's does.
                        let mut scene = scene;
                        let parts = (&mut handle, shared, &mut work, &mut renderer);
                        // A link error ends the node; the report keeps what it did.
                        let _ = run_node_landing(node_cfg, parts, &mut scene, report).await;
                    })
                    .await
                })
            }
        };
        tasks.push(Some(task));
    }
    tasks
}

/// What the RC's state and its bus tasks' results, as [`run_frames`] watches them.
type Watched<'a> = (
    &'a RefCell<RootState>,
    &'a RefCell<Vec<Option<Result<RootReport, RootError>>>>,
);

/// Run the tasks in virtual time until every bus has finished (and, under the firmware's
/// relay code, every relay has passed the root's `Stop` on, `relays_done`): the time each
/// frame completed (`keep` is called with the frame as it does), or, under the modelled
/// relay tree, the later time the root had taken every node frame forwarded until then
/// (`taken`). Stops after 100 000 s of virtual time, or when no new result arrives over
/// 200 000 executor passes; a stall once every bus has finished is the end (a relay that
/// never heard the `Stop`).
fn run_frames(
    clock: &SharedClock,
    tasks: &mut [Option<Task<'_>>],
    (root, bus_results): Watched<'_>,
    (taken, relays_done): (impl Fn() -> Ps, impl Fn() -> bool),
    mut keep: impl FnMut(u16),
) -> Result<Vec<Ps>, ExecError> {
    let mut done_at: Vec<Ps> = Vec::new();
    let (mut last_accepted, mut idle_passes) = (0u64, 0u32);
    let limit: Ps = 100_000 * 1_000_000_000_000; // 100 000 s of virtual time
    let buses_done = || bus_results.borrow().iter().all(|r| r.is_some());
    let res = exec::run(
        clock,
        tasks,
        limit,
        || buses_done() && relays_done(),
        |now| {
            let complete = root.borrow().frames_complete() as usize;
            while done_at.len() < complete {
                let f = done_at.len() as u16;
                done_at.push(now.max(taken()));
                keep(f);
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
    match res {
        Err(ExecError::Deadlock { .. }) if buses_done() => Ok(done_at),
        r => r.map(|_| done_at),
    }
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
                topology: Topology::Star,
                keep_frames: false,
                deaths: Vec::new(),
                relay_deaths: Vec::new(),
                spi_dead: Vec::new(),
                stuck: Vec::new(),
                backup_line: false,
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
