//! The root computer (RC): broadcast each frame's scene, hand out sub-screens, collect the
//! finished pixels, detect completion.
//!
//! The shared state is one [`RootState`] in a `RefCell`; one [`run_bus`] future per SPI bus
//! drives that bus (they run concurrently on one executor, so several buses overlap their
//! transfers). No heap: per-node bookkeeping is a fixed table of [`MAX_NODES`] entries.
//!
//! Per exchange the RC must fill its half of the swap *before* it sees the node's half, so
//! its reply carries state: the node's job list (idempotent) and the highest in-order frame
//! it has received from that node (`ack`). Animation: frame `f`'s scene goes to node bank
//! `f % 2` while frame `f - 1` renders; its jobs are handed out as soon as frame `f - 1`'s are
//! all issued, to nodes that have reported the scene ready.
//!
//! The DM stage: a [`SceneSource`] may produce scenes over time ([`SceneSource::produced`]);
//! frame `f` is broadcast only once it exists.
//!
//! Node failure: a node holding jobs that the RC has not exchanged with for
//! [`RootConfig::timeout_us`] (checked only while no ready line on its bus is up, so bus
//! congestion is never mistaken for silence) is declared dead; its jobs stay in its slot as
//! orphans, are handed (with fresh ids) to the next live nodes that ask, and every bus
//! broadcasts [`Down::Wake`] so idle nodes ask. Under a static split a node also owes the RC
//! its region of the frame being handed out: silent for two time-outs after its bus
//! broadcast that frame's scene (one for the roll call that reaches a node which missed the
//! broadcast, one for its answer), it is declared dead and its region becomes an orphan.
//! A "dead" node that speaks again is live again; if it was declared dead while holding
//! jobs, the time-out becomes at least twice the silence it was declared dead for (it was
//! too short). The time-out in force therefore never exceeds the larger of the configured
//! one and twice the longest silence of a node that was rendering, however many false alarms
//! there are (see docs/reliability.md for the recovery bound).

use super::link::{LinkError, NodeId, RootBus, Transfer};
use super::sched::{Policy, SchedError, Scheduler};
use super::wire::{self, Down, Job, SceneState, Up, JOB_QUEUE, MAX_FRAME, SCENE_CHUNK};
use crate::image::SceneView;
use core::cell::RefCell;
use core::fmt;
use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll, Waker};
use embassy_futures::select::{select4, Either4};

/// Most buses (concurrent [`run_bus`] tasks) one RC drives.
pub const MAX_BUSES: usize = 8;

/// Most nodes an RC drives (LINKS-1's design limit).
pub const MAX_NODES: usize = 256;

/// The scene image of each animation frame (the DM's output).
#[allow(async_fn_in_trait)]
pub trait SceneSource {
    fn scene(&self, frame: u16) -> Option<&[u8]>;
    /// Whether the DM has produced frame `frame`'s scene yet (it runs ahead of the RC, one
    /// frame at a time). Default: every scene exists from the start.
    fn produced(&self, _frame: u16) -> bool {
        true
    }
    /// Resolves once [`SceneSource::produced`] holds for `frame`. Implement it together
    /// with `produced`.
    async fn wait_produced(&self, _frame: u16) {}
    /// The CRC-32 of frame `frame`'s scene if the DM delivers it with the scene (the DM
    /// wrote the bytes; the RC then need not read all of them before the first chunk).
    /// Default: `None`, the RC computes it.
    fn scene_crc(&self, _frame: u16) -> Option<u32> {
        None
    }
}

/// CPU work the RC just did, reported to its clock (hardware: time passes by itself;
/// simulator: the RC's CPU is busy for the modelled time of the work).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RcWork<'a> {
    /// Composed one transfer's frame of `bytes` (choice of node, job table, postcard, CRC).
    Encode { bytes: usize },
    /// Checked, decoded and applied a node's frame (CRC, postcard, run-length expansion,
    /// job bookkeeping, the pixel sink): the frame as received.
    Decode { frame: &'a [u8] },
    /// CRC-32 of `bytes` bytes of a whole scene image (once per frame's scene).
    Checksum { bytes: usize },
}

/// The RC's time base, for node time-outs (hardware: a timer; simulator: virtual time).
#[allow(async_fn_in_trait)]
pub trait RootClock {
    /// Microseconds since the start.
    fn now_us(&self) -> u64;
    /// Resolves once `now_us() >= t`.
    async fn at_us(&self, t: u64);
    /// The RC's CPU just did `work`; resolves when that work would be finished. Default:
    /// at once (on hardware the work took its time already).
    async fn worked(&self, _work: RcWork<'_>) {}
}

/// A clock that never advances: time-outs never fire (an RC without a timer).
pub struct NoClock;

impl RootClock for NoClock {
    fn now_us(&self) -> u64 {
        0
    }
    async fn at_us(&self, _t: u64) {
        core::future::pending::<()>().await
    }
}

impl<T: AsRef<[u8]>> SceneSource for [T] {
    fn scene(&self, frame: u16) -> Option<&[u8]> {
        self.get(frame as usize).map(|s| s.as_ref())
    }
}

/// Where the RC delivers accepted pixel runs (frame memory, serial readback). With a
/// snooping frame memory on the bus the RC needs none: use `()`.
pub trait PixelSink {
    fn pixels(&mut self, frame: u16, y: u16, x: u16, rgb: &[u8]);
}

impl PixelSink for () {
    fn pixels(&mut self, _: u16, _: u16, _: u16, _: &[u8]) {}
}

/// What the RC runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RootConfig {
    pub policy: Policy,
    pub nodes: u16,
    pub frames: u16,
    /// A node holding jobs that has not been heard from for this long (µs) is declared dead
    /// and its jobs are re-issued; 0 = never. It must exceed the longest run a node renders
    /// between two exchanges ([`RootConfig::DEFAULT_TIMEOUT_US`]).
    pub timeout_us: u64,
    /// RC-side DMA double buffering: compose the next transfer and take the previous
    /// node's frame while a transfer is on the wire ([`RootBus::start`] /
    /// [`RootBus::finish`]). `false`: one transfer at a time, the bus idle while the RC
    /// composes and decodes.
    pub double_buffer: bool,
}

impl RootConfig {
    /// 0.5 s: a live node rendering photo1 at 512x480 at 168 MHz is silent for at most
    /// 0.15-0.2 s (its longest run), a 2.5x margin; a false alarm raises the time-out to
    /// twice the silence it missed (see docs/reliability.md).
    pub const DEFAULT_TIMEOUT_US: u64 = 500_000;
}

/// Why the RC cannot run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RootError {
    TooManyNodes {
        nodes: u16,
    },
    /// Frame `frame` has no scene, or it is not a valid SceneImage.
    BadScene {
        frame: u16,
    },
    /// Frame `frame`'s scene image is `len` bytes, more than the protocol carries (`max`,
    /// [`wire::MAX_SCENE`]).
    SceneTooLarge {
        frame: u16,
        len: u32,
        max: u32,
    },
    /// Frames of one animation differ in screen size.
    SizeChanged {
        frame: u16,
    },
    Sched(SchedError),
    Link(LinkError),
}

impl fmt::Display for RootError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RootError::TooManyNodes { nodes } => {
                write!(f, "{nodes} nodes (at most {MAX_NODES})")
            }
            RootError::BadScene { frame } => write!(f, "frame {frame} has no usable scene image"),
            RootError::SceneTooLarge { frame, len, max } => write!(
                f,
                "frame {frame}'s scene image is {len} bytes, more than the {max} bytes a scene may have"
            ),
            RootError::SizeChanged { frame } => write!(f, "frame {frame} changes the screen size"),
            RootError::Sched(e) => write!(f, "scheduling: {e}"),
            RootError::Link(e) => write!(f, "link: {e}"),
        }
    }
}

impl core::error::Error for RootError {}

impl From<LinkError> for RootError {
    fn from(e: LinkError) -> Self {
        RootError::Link(e)
    }
}

/// Counters of what the RC saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RootReport {
    pub exchanges: u32,
    pub broadcasts: u32,
    pub jobs: u32,
    pub pixels: u64,
    /// Node frames that failed CRC or decoding.
    pub bad_frames: u32,
    /// Node frames out of sequence (duplicates after a lost acknowledgement, or frames
    /// behind a lost one), dropped.
    pub out_of_order: u32,
    /// Valid frames whose contents were not plausible (unknown job, run outside the frame).
    pub rejected: u32,
    /// Scene chunks re-sent point-to-point.
    pub repairs: u32,
    pub polls: u32,
    /// Node frames accepted in sequence.
    pub accepted: u64,
    /// Nodes declared dead (silent past their deadline while holding jobs or owing their
    /// static region).
    pub timeouts: u32,
    /// Jobs of dead nodes handed to other nodes.
    pub reissued: u32,
    /// Nodes declared dead that spoke again (and were taken back).
    pub revived: u32,
    /// The time-out in force (µs): the configured one, raised by false alarms.
    pub timeout_us: u64,
}

#[derive(Clone, Copy, Debug)]
struct NodeSlot {
    expect: u16,
    jobs: [Option<Job>; JOB_QUEUE],
    /// The frame whose scene the node reported ready, per bank (`frame % 2`). Per bank,
    /// not "up to": a node may have missed frame `f`'s broadcast and still hold `f + 1`'s.
    ready: [Option<u16>; 2],
    /// Scene chunks the node lacks (frame, bitmap), minus those already re-sent.
    repair: Option<(u16, [u32; wire::MAX_CHUNKS / 32])>,
    /// The chunk re-sent in the exchange in progress.
    repairing: Option<u32>,
    /// How the node's scene is being repaired piece by piece.
    pieces: Option<Pieces>,
    /// When the RC last exchanged with the node (µs); for a node declared dead, the moment
    /// its silence was counted from.
    heard_us: u64,
    /// Declared dead: its jobs are orphans waiting to be re-issued.
    dead: bool,
    /// Declared dead while holding jobs (it was rendering): if it speaks again, the
    /// time-out was too short for its runs.
    dead_rendering: bool,
}

impl NodeSlot {
    const NEW: NodeSlot = NodeSlot {
        expect: 0,
        jobs: [None; JOB_QUEUE],
        ready: [None; 2],
        repair: None,
        repairing: None,
        pieces: None,
        heard_us: 0,
        dead: false,
        dead_rendering: false,
    };
    fn ready_for(&self, frame: u16) -> bool {
        self.ready[(frame % 2) as usize] == Some(frame)
    }
}

/// A node's scene repair on a noisy link: a chunk sent whole that the node still reports
/// missing is sent again in halves, quarters, ... down to [`wire::SCENE_PIECE`] bytes, one
/// piece per exchange and only the pieces the node lacks, so that short frames get through
/// where a whole chunk never would; two chunks in a row that get through at the first try
/// double the piece size again.
#[derive(Clone, Copy, Debug)]
struct Pieces {
    /// The frame whose scene is being repaired.
    frame: u16,
    /// Piece size in bytes (a power of two, [`wire::SCENE_PIECE`]..=[`SCENE_CHUNK`]).
    size: u16,
    /// The chunk being sent piece by piece and the offset of its next piece.
    cycle: Option<(u8, u16)>,
    /// The highest chunk sent in full so far: a chunk at or below it asked for again was
    /// lost on the way, so pieces get smaller.
    high: Option<u8>,
    /// Chunks started at the first try since the piece size last changed.
    streak: u8,
    /// The node's last report of the pieces it holds of its first missing chunk: (chunk,
    /// bitmap of pieces).
    have: Option<(u8, u16)>,
}

impl Pieces {
    fn new(frame: u16) -> Self {
        Self {
            frame,
            size: SCENE_CHUNK as u16,
            cycle: None,
            high: None,
            streak: 0,
            have: None,
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct Progress {
    frame: u16,
    issued: u32,
    done: u32,
    all_issued: bool,
    complete: bool,
}

/// The RC's state, shared by its bus tasks.
pub struct RootState {
    cfg: RootConfig,
    width: u32,
    height: u32,
    nodes: [NodeSlot; MAX_NODES],
    sched: Scheduler,
    /// The frame whose jobs `sched` hands out.
    sched_frame: u16,
    progress: [Progress; 2],
    /// Frames complete, counted in order.
    complete: u16,
    next_job: u32,
    report: RootReport,
    /// Times jobs became orphans (a node declared dead holding jobs, a dead node's static
    /// region issued to it): each bus broadcasts `Wake` when this grows.
    orphaned: u16,
    /// The time-out in force (µs): starts at `cfg.timeout_us`; a node declared dead while
    /// rendering that speaks again raises it to twice the silence it was declared dead for.
    timeout_us: u64,
    /// Bus tasks waiting for the end (woken when the last frame completes).
    finish_wakers: [Option<Waker>; MAX_BUSES],
    /// CRC-32 of the scenes of the two frames in flight: (frame, crc) by `frame % 2`.
    scene_crc: [Option<(u16, u32)>; 2],
    /// Scene bytes checksummed since [`RootState::take_crc_work`] last ran.
    crc_work: usize,
}

/// Resolves when every frame is complete.
struct Finished<'a> {
    root: &'a RefCell<RootState>,
    slot: usize,
}

impl Future for Finished<'_> {
    type Output = ();
    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let mut r = self.root.borrow_mut();
        if r.finished() {
            return Poll::Ready(());
        }
        let slot = self.slot % MAX_BUSES;
        r.finish_wakers[slot] = Some(cx.waker().clone());
        Poll::Pending
    }
}

impl RootState {
    /// Check every frame's scene and set up the first frame's schedule.
    pub fn new<S: SceneSource + ?Sized>(cfg: RootConfig, scenes: &S) -> Result<Self, RootError> {
        if cfg.nodes as usize > MAX_NODES || cfg.nodes == 0 {
            return Err(RootError::TooManyNodes { nodes: cfg.nodes });
        }
        let mut dims = None;
        for frame in 0..cfg.frames {
            let bytes = scenes.scene(frame).ok_or(RootError::BadScene { frame })?;
            if bytes.len() > wire::MAX_SCENE {
                return Err(RootError::SceneTooLarge {
                    frame,
                    len: u32::try_from(bytes.len()).unwrap_or(u32::MAX),
                    max: wire::MAX_SCENE as u32,
                });
            }
            let v = SceneView::new(bytes).map_err(|_| RootError::BadScene { frame })?;
            let f = v.camera::<f32>();
            match dims {
                None => dims = Some((f.width, f.height)),
                Some(d) if d != (f.width, f.height) => {
                    return Err(RootError::SizeChanged { frame })
                }
                Some(_) => {}
            }
        }
        let (width, height) = dims.ok_or(RootError::BadScene { frame: 0 })?;
        let sched = Scheduler::new(cfg.policy, width, height, cfg.nodes as u32)
            .map_err(RootError::Sched)?;
        Ok(Self {
            cfg,
            width,
            height,
            nodes: [NodeSlot::NEW; MAX_NODES],
            sched,
            sched_frame: 0,
            progress: [
                Progress::default(),
                Progress {
                    frame: 1,
                    ..Progress::default()
                },
            ],
            complete: 0,
            next_job: 0,
            report: RootReport::default(),
            orphaned: 0,
            timeout_us: cfg.timeout_us,
            finish_wakers: [const { None }; MAX_BUSES],
            scene_crc: [None; 2],
            crc_work: 0,
        })
    }

    /// Screen size.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Frames finished, in order.
    pub fn frames_complete(&self) -> u16 {
        self.complete
    }

    /// Whether every frame is finished.
    pub fn finished(&self) -> bool {
        self.complete >= self.cfg.frames
    }

    pub fn report(&self) -> RootReport {
        RootReport {
            timeout_us: self.timeout_us,
            ..self.report
        }
    }

    /// Whether frame `f`'s scene may be broadcast (its node bank and frame-memory bank are
    /// free: frame `f - 2` is complete).
    pub fn may_broadcast(&self, frame: u16) -> bool {
        frame < self.cfg.frames && (frame < 2 || self.complete > frame - 2)
    }

    fn prog(&mut self, frame: u16) -> Option<&mut Progress> {
        let p = &mut self.progress[(frame % 2) as usize];
        (p.frame == frame).then_some(p)
    }

    fn update_complete(&mut self) {
        loop {
            let f = self.complete;
            if f >= self.cfg.frames {
                return;
            }
            let p = &mut self.progress[(f % 2) as usize];
            if p.frame != f || !(p.all_issued && p.done == p.issued) {
                return;
            }
            p.complete = true;
            self.complete += 1;
            if self.complete >= self.cfg.frames {
                for w in self.finish_wakers.iter_mut() {
                    if let Some(w) = w.take() {
                        w.wake();
                    }
                }
            }
            // Recycle the slot for frame f + 2.
            *p = Progress {
                frame: f + 2,
                ..Progress::default()
            };
        }
    }

    /// The CRC-32 of frame `frame`'s scene `bytes` (every chunk carries it): the DM's if it
    /// delivers one, else computed once per frame; kept while the frame is in flight.
    pub fn scene_crc(&mut self, frame: u16, bytes: &[u8], from_dm: Option<u32>) -> u32 {
        let slot = &mut self.scene_crc[(frame % 2) as usize];
        match *slot {
            Some((f, c)) if f == frame => c,
            _ => {
                if let Some(c) = from_dm {
                    *slot = Some((frame, c));
                    return c;
                }
                let c = wire::CRC32.checksum(bytes);
                *slot = Some((frame, c));
                self.crc_work += bytes.len();
                c
            }
        }
    }

    /// Scene bytes checksummed since the last call (the CPU work to account for).
    pub fn take_crc_work(&mut self) -> usize {
        core::mem::take(&mut self.crc_work)
    }

    /// How many times jobs became orphans (nodes declared dead holding jobs, static regions
    /// of dead nodes): each bus calls a roll when this grows.
    pub fn orphaned(&self) -> u16 {
        self.orphaned
    }

    /// Note an exchange with `node` at `now_us`; a node declared dead is live again. If it
    /// was declared dead while rendering, the time-out was shorter than its run: the time-out
    /// becomes at least twice the silence it was declared dead for. Silences of live nodes
    /// are bounded by their longest run, so this cannot grow without bound, however many
    /// nodes are falsely declared dead at once.
    pub fn heard(&mut self, node: NodeId, now_us: u64) {
        let Some(slot) = self.nodes.get_mut(node as usize) else {
            return;
        };
        if slot.dead {
            slot.dead = false;
            self.report.revived += 1;
            if slot.dead_rendering {
                let silence = now_us.saturating_sub(slot.heard_us);
                self.timeout_us = self.timeout_us.max(silence.saturating_mul(2));
            }
            slot.dead_rendering = false;
        }
        slot.heard_us = now_us;
    }

    fn nodes_in(&self, first: NodeId, count: u16) -> core::ops::Range<usize> {
        let end = (first as usize + count as usize).min(self.cfg.nodes as usize);
        (first as usize).min(end)..end
    }

    /// Static split: whether node `n`'s region of the frame being handed out is still
    /// waiting for it.
    fn owes_region(&self, n: usize) -> bool {
        matches!(self.cfg.policy, Policy::Static { .. })
            && u16::try_from(n).is_ok_and(|n| self.sched.reserved(n))
    }

    /// When live node `n` must have spoken by, if it owes the RC an exchange, as (silence
    /// counted from, deadline): a node holding jobs a time-out after it was last heard; a
    /// node owing its static region (`scene_sent_us`: when its bus finished broadcasting the
    /// scene of the frame being handed out) two time-outs after the later of that and its
    /// last exchange.
    fn deadline(&self, n: usize, scene_sent_us: Option<u64>) -> Option<(u64, u64)> {
        let slot = self.nodes.get(n)?;
        if slot.dead || self.timeout_us == 0 {
            return None;
        }
        if slot.jobs.iter().any(|j| j.is_some()) {
            return Some((slot.heard_us, slot.heard_us.saturating_add(self.timeout_us)));
        }
        let sent = scene_sent_us?;
        if !self.owes_region(n) {
            return None;
        }
        let since = slot.heard_us.max(sent);
        Some((
            since,
            since.saturating_add(self.timeout_us.saturating_mul(2)),
        ))
    }

    /// When the first live node of `first..first + count` that owes the RC an exchange times
    /// out (µs). `scene_sent_us`: when this bus finished broadcasting the scene of the frame
    /// being handed out ([`RootState::handing_out`]), if it has.
    pub fn next_deadline(
        &self,
        first: NodeId,
        count: u16,
        scene_sent_us: Option<u64>,
    ) -> Option<u64> {
        self.nodes_in(first, count)
            .filter_map(|n| self.deadline(n, scene_sent_us))
            .map(|(_, d)| d)
            .min()
    }

    /// Declare dead every live node of `first..first + count` that owes the RC an exchange
    /// and has been silent past its deadline at `now_us` (see [`RootState::next_deadline`]),
    /// and issue the static region a dead node owes to that node as an orphan. Call only
    /// while none of them has its ready line up. Returns how many died.
    pub fn expire(
        &mut self,
        first: NodeId,
        count: u16,
        now_us: u64,
        scene_sent_us: Option<u64>,
    ) -> u16 {
        if self.timeout_us == 0 {
            return 0;
        }
        let mut died = 0u16;
        let mut orphaned = 0u16;
        for n in self.nodes_in(first, count) {
            if let Some((since, deadline)) = self.deadline(n, scene_sent_us) {
                if now_us >= deadline {
                    let slot = &mut self.nodes[n];
                    let rendering = slot.jobs.iter().any(|j| j.is_some());
                    slot.dead = true;
                    slot.dead_rendering = rendering;
                    slot.heard_us = since;
                    slot.repair = None;
                    slot.repairing = None;
                    slot.pieces = None;
                    died += 1;
                    if rendering {
                        orphaned += 1;
                    }
                }
            }
            if self.nodes[n].dead && self.orphan_region(n) {
                orphaned += 1;
            }
        }
        self.orphaned = self.orphaned.saturating_add(orphaned);
        self.report.timeouts += died as u32;
        died
    }

    /// Static split: issue dead node `n`'s region of the frame being handed out into its own
    /// slot, as an orphan for a live node to adopt. Returns whether it did.
    fn orphan_region(&mut self, n: usize) -> bool {
        if !self.owes_region(n) {
            return false;
        }
        let Some(free) = self.nodes[n].jobs.iter().position(|j| j.is_none()) else {
            return false;
        };
        let Some(region) = self.sched.next_for(n as NodeId) else {
            return false;
        };
        let frame = self.sched_frame;
        self.nodes[n].jobs[free] = Some(Job {
            id: self.next_job,
            frame,
            region,
        });
        self.next_job += 1;
        self.report.jobs += 1;
        if let Some(p) = self.prog(frame) {
            p.issued += 1;
        }
        true
    }

    /// The frame whose jobs are being handed out.
    pub fn handing_out(&self) -> u16 {
        self.sched_frame
    }

    /// Sub-screens handed out and not yet returned, as (holder, job, holder declared dead):
    /// what a run that cannot finish waits for (diagnostics).
    pub fn pending(&self) -> impl Iterator<Item = (NodeId, Job, bool)> + '_ {
        self.nodes[..self.cfg.nodes as usize]
            .iter()
            .enumerate()
            .flat_map(|(n, s)| {
                s.jobs
                    .iter()
                    .flatten()
                    .map(move |j| (n as NodeId, *j, s.dead))
            })
    }

    /// Sub-screens of the frame being handed out that no node has been given yet (about, for
    /// the decreasing policy; see [`Scheduler::remaining`]).
    pub fn unissued(&self) -> u32 {
        if self.sched.exhausted() {
            0
        } else {
            self.sched.remaining()
        }
    }

    /// Static split: whether `node`'s region of the frame being handed out still waits for
    /// it to ask.
    pub fn reserved(&self, node: NodeId) -> bool {
        self.sched.reserved(node)
    }

    /// Whether `node` is declared dead now.
    pub fn is_dead(&self, node: NodeId) -> bool {
        self.nodes.get(node as usize).is_some_and(|s| s.dead)
    }

    /// Whether `node` has reported frame `frame`'s scene ready.
    pub fn has_scene(&self, node: NodeId, frame: u16) -> bool {
        self.nodes
            .get(node as usize)
            .is_some_and(|s| s.ready_for(frame))
    }

    /// The frame to call a roll ([`Down::Wake`]) for on nodes `first..first + count`, if
    /// work waits that no node there can otherwise be asked for: jobs of a dead node (any
    /// bus), or a live node holding no jobs that has not reported the scene of the frame
    /// being handed out although this bus has broadcast it (`broadcast_upto`: frames below it
    /// are fully broadcast here) and no repair is under way. `None` with time-outs off.
    pub fn roll_call(&self, first: NodeId, count: u16, broadcast_upto: u16) -> Option<u16> {
        if self.finished() || self.timeout_us == 0 {
            return None;
        }
        if let Some((d, k)) = self.orphan() {
            return self.nodes[d].jobs[k].map(|j| j.frame);
        }
        let f = self.sched_frame;
        if f >= broadcast_upto || self.sched.exhausted() {
            return None;
        }
        self.nodes[self.nodes_in(first, count)]
            .iter()
            .any(|s| {
                !s.dead
                    && !s.ready_for(f)
                    && s.jobs.iter().all(|j| j.is_none())
                    && s.repair.is_none()
            })
            .then_some(f)
    }

    /// The time-out in force (µs; false alarms raise it, see [`RootState::heard`]).
    pub fn timeout_us(&self) -> u64 {
        self.timeout_us
    }

    /// A job held by a dead node, as (node, queue index), oldest frame first.
    fn orphan(&self) -> Option<(usize, usize)> {
        let mut best: Option<(usize, usize, u16)> = None;
        for (n, slot) in self.nodes[..self.cfg.nodes as usize].iter().enumerate() {
            if !slot.dead {
                continue;
            }
            for (k, j) in slot.jobs.iter().enumerate() {
                if let Some(j) = j {
                    if best.is_none_or(|(_, _, f)| j.frame < f) {
                        best = Some((n, k, j.frame));
                    }
                }
            }
        }
        best.map(|(n, k, _)| (n, k))
    }

    /// Hand one orphaned job to `node` (a fresh id, so the node takes it). Returns whether
    /// it did.
    fn adopt(&mut self, node: NodeId) -> bool {
        let Some((d, k)) = self.orphan() else {
            return false;
        };
        let slot = &self.nodes[node as usize];
        let Some(job) = self.nodes[d].jobs[k] else {
            return false;
        };
        let Some(free) = slot.jobs.iter().position(|j| j.is_none()) else {
            return false;
        };
        if slot.dead || !slot.ready_for(job.frame) {
            return false;
        }
        self.nodes[d].jobs[k] = None;
        if self.nodes[d].jobs[0].is_none() {
            self.nodes[d].jobs.swap(0, 1);
        }
        self.nodes[node as usize].jobs[free] = Some(Job {
            id: self.next_job,
            ..job
        });
        self.next_job += 1;
        self.report.reissued += 1;
        true
    }

    /// Move the schedule on to the next frame if the current one is all issued and the
    /// next one's progress slot is free.
    fn advance_schedule(&mut self) {
        if !self.sched.exhausted() {
            return;
        }
        let cur = self.sched_frame;
        if let Some(p) = self.prog(cur) {
            p.all_issued = true;
        }
        self.update_complete();
        let next = cur + 1;
        if next >= self.cfg.frames || self.progress[(next % 2) as usize].frame != next {
            return;
        }
        if let Ok(s) = Scheduler::new(
            self.cfg.policy,
            self.width,
            self.height,
            self.cfg.nodes as u32,
        ) {
            self.sched = s;
            self.sched_frame = next;
        }
    }

    /// Top up a node's job list (called when composing its exchange reply).
    fn assign(&mut self, node: NodeId) {
        loop {
            self.advance_schedule();
            let slot = &self.nodes[node as usize];
            let held = slot.jobs.iter().filter(|j| j.is_some()).count();
            if held >= JOB_QUEUE || (held > 0 && !self.sched.may_prefetch()) {
                return;
            }
            if self.orphaned > 0 && self.adopt(node) {
                continue;
            }
            let slot = &self.nodes[node as usize];
            let frame = self.sched_frame;
            if !slot.ready_for(frame) || self.sched.exhausted() {
                return;
            }
            let Some(region) = self.sched.next_for(node) else {
                return;
            };
            let job = Job {
                id: self.next_job,
                frame,
                region,
            };
            self.next_job += 1;
            self.report.jobs += 1;
            if let Some(p) = self.prog(frame) {
                p.issued += 1;
            }
            if let Some(free) = self.nodes[node as usize]
                .jobs
                .iter_mut()
                .find(|j| j.is_none())
            {
                *free = Some(job);
            }
        }
    }

    /// Compose the RC's half of an exchange with `node` into `tx`; returns its length.
    fn reply<S: SceneSource + ?Sized>(&mut self, node: NodeId, scenes: &S, tx: &mut [u8]) -> usize {
        if node >= self.cfg.nodes {
            return 0;
        }
        let ack = self.nodes[node as usize].expect.wrapping_sub(1);
        let seq = self.report.exchanges as u16;
        let slot = &mut self.nodes[node as usize];
        slot.repairing = None;
        let pieces = slot.pieces;
        let next = slot.repair.and_then(|(frame, map)| {
            // Only chunks the scene has (a node that heard nothing of it asks for all).
            let chunks = scenes
                .scene(frame)
                .map_or(0, |s| s.len().div_ceil(SCENE_CHUNK)) as u32;
            // A chunk part-sent in pieces is finished first.
            if let Some((c, _)) = pieces.filter(|p| p.frame == frame).and_then(|p| p.cycle) {
                if (c as u32) < chunks {
                    return Some((frame, c as u32));
                }
            }
            let c = (0..chunks.min(wire::MAX_CHUNKS as u32))
                .find(|&c| map[(c / 32) as usize] & (1 << (c % 32)) != 0)?;
            Some((frame, c))
        });
        if next.is_none() {
            slot.repair = None;
        }
        if let Some((frame, c)) = next {
            slot.repairing = Some(c);
            if let Some(scene) = scenes.scene(frame) {
                let mut p = match slot.pieces {
                    Some(p) if p.frame == frame => p,
                    _ => Pieces::new(frame),
                };
                let c8 = c as u8;
                let at = match p.cycle {
                    Some((cc, at)) if cc == c8 => at as usize,
                    _ => {
                        if p.high.is_some_and(|h| c8 <= h) {
                            // Sent in full and asked for again: lost on the way.
                            p.size = (p.size / 2).max(wire::SCENE_PIECE as u16);
                            p.streak = 0;
                        } else {
                            p.streak = p.streak.saturating_add(1);
                            if p.streak > 2 {
                                p.size = (p.size * 2).min(SCENE_CHUNK as u16);
                                p.streak = 0;
                            }
                        }
                        0
                    }
                };
                let chunk_start = (c as usize * SCENE_CHUNK).min(scene.len());
                let chunk_end = (chunk_start + SCENE_CHUNK).min(scene.len());
                // Skip the pieces the node says it holds.
                let held = p.have.filter(|h| h.0 == c8).map_or(0, |h| h.1);
                let piece = wire::SCENE_PIECE;
                let mut at = at;
                while at < chunk_end - chunk_start && held & (1u16 << ((at / piece) % 16)) != 0 {
                    at += piece;
                }
                if at >= chunk_end - chunk_start {
                    // It holds them all by its last word: send the rest of the cycle anyway.
                    at = p.cycle.filter(|c| c.0 == c8).map_or(0, |c| c.1 as usize);
                }
                let start = (chunk_start + at).min(chunk_end);
                let end = (start + p.size as usize).min(chunk_end);
                if end >= chunk_end {
                    if let Some((_, map)) = &mut slot.repair {
                        map[(c / 32) as usize] &= !(1 << (c % 32));
                    }
                    p.cycle = None;
                    p.high = Some(p.high.map_or(c8, |h| h.max(c8)));
                } else {
                    p.cycle = Some((c8, (at + p.size as usize) as u16));
                }
                slot.pieces = Some(p);
                let crc = self.scene_crc(frame, scene, scenes.scene_crc(frame));
                let msg = Down::Scene {
                    frame,
                    offset: start as u32,
                    total: scene.len() as u32,
                    crc,
                    data: &scene[start..end],
                };
                self.report.repairs += 1;
                return wire::encode(seq, ack, &msg, tx).unwrap_or(0);
            }
        }
        if self.finished() {
            // A node that missed the Stop broadcast learns it here.
            return wire::encode(seq, ack, &Down::Stop, tx).unwrap_or(0);
        }
        self.assign(node);
        let jobs = self.nodes[node as usize].jobs;
        wire::encode(seq, ack, &Down::Work { jobs }, tx).unwrap_or(0)
    }

    /// Take a node's half of an exchange.
    fn take<P: PixelSink>(&mut self, node: NodeId, bytes: &[u8], sink: &mut P) {
        if node >= self.cfg.nodes {
            self.report.rejected += 1;
            return;
        }
        let env = match wire::decode::<Up>(bytes) {
            Ok(e) => e,
            Err(_) => {
                self.report.bad_frames += 1;
                return;
            }
        };
        let slot = &mut self.nodes[node as usize];
        if env.msg == Up::Poll {
            self.report.polls += 1;
            return;
        }
        if env.seq != slot.expect {
            self.report.out_of_order += 1;
            return;
        }
        slot.expect = slot.expect.wrapping_add(1);
        self.report.accepted += 1;
        match env.msg {
            Up::Poll => {}
            Up::Status { scene } => match scene {
                SceneState::Ready { frame } => {
                    slot.ready[(frame % 2) as usize] = Some(frame);
                    if slot.repair.is_some_and(|(f, _)| f == frame) {
                        slot.repair = None;
                    }
                    if slot.pieces.is_some_and(|p| p.frame == frame) {
                        slot.pieces = None;
                    }
                }
                SceneState::Missing {
                    frame,
                    mut chunks,
                    pieces,
                } => {
                    // What it holds of its first missing chunk.
                    let first = (0..wire::MAX_CHUNKS as u32)
                        .find(|&c| chunks[(c / 32) as usize] & (1 << (c % 32)) != 0);
                    if let (Some(p), Some(c)) = (&mut slot.pieces, first) {
                        if p.frame == frame {
                            p.have = Some((c as u8, pieces));
                        }
                    }
                    // A chunk being sent in pieces that the node now has is done.
                    if let Some(p) = &mut slot.pieces {
                        if let Some((c, _)) = p.cycle {
                            if p.frame == frame && chunks[(c / 32) as usize] & (1 << (c % 32)) == 0
                            {
                                p.cycle = None;
                            }
                        }
                    }
                    // The node wrote this before our reply in this exchange reached it.
                    if let Some(c) = slot.repairing {
                        chunks[(c / 32) as usize] &= !(1 << (c % 32));
                    }
                    slot.repair = Some((frame, chunks));
                }
                SceneState::None => {}
            },
            Up::Pixels { .. } | Up::PixelsRle { .. } => {
                let mut buf = [0u8; 3 * wire::MAX_RUN];
                let (job, frame, y, x, rgb, done) = match env.msg {
                    Up::Pixels {
                        job,
                        frame,
                        y,
                        x,
                        rgb,
                        done,
                    } => (job, frame, y, x, rgb, done),
                    Up::PixelsRle {
                        job,
                        frame,
                        y,
                        x,
                        len,
                        data,
                        done,
                    } => {
                        let Some(out) = buf.get_mut(..3 * len as usize) else {
                            self.report.rejected += 1;
                            return;
                        };
                        if wire::rle_decode(data, out).is_err() {
                            self.report.rejected += 1;
                            return;
                        }
                        (job, frame, y, x, &*out, done)
                    }
                    _ => return,
                };
                let Some(k) = slot
                    .jobs
                    .iter()
                    .position(|j| j.is_some_and(|j| j.id == job && j.frame == frame))
                else {
                    self.report.rejected += 1;
                    return;
                };
                let n = rgb.len() / 3;
                if rgb.len() % 3 != 0 || y as u32 >= self.height || x as u32 + n as u32 > self.width
                {
                    self.report.rejected += 1;
                    return;
                }
                sink.pixels(frame, y, x, rgb);
                self.report.pixels += n as u64;
                if done {
                    slot.jobs[k] = None;
                    if slot.jobs[0].is_none() {
                        slot.jobs.swap(0, 1);
                    }
                    if let Some(p) = self.prog(frame) {
                        p.done += 1;
                    }
                    self.advance_schedule();
                    self.update_complete();
                }
            }
        }
    }
}

/// Take the frame of the transfer that just left the wire (an exchange: account for the
/// decoding, then apply the node's frame; a broadcast: count it).
async fn complete<C: RootClock, P: PixelSink>(
    sent: Sent,
    rx: &[u8],
    clock: &C,
    root: &RefCell<RootState>,
    sink: &RefCell<P>,
) {
    match sent {
        Sent::Exchange(node) => {
            clock.worked(RcWork::Decode { frame: rx }).await;
            let mut r = root.borrow_mut();
            r.report.exchanges += 1;
            r.heard(node, clock.now_us());
            r.take(node, rx, &mut *sink.borrow_mut());
        }
        Sent::Broadcast => root.borrow_mut().report.broadcasts += 1,
    }
}

/// What a bus transfer carried, for [`complete`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sent {
    Exchange(NodeId),
    Broadcast,
}

/// Drive one bus until every frame is complete, then broadcast `Stop`. `index` numbers the
/// bus tasks (0..[`MAX_BUSES`]) sharing `root`.
///
/// With [`RootConfig::double_buffer`] the RC works while the bus does: it composes transfer
/// `k + 1` in the idle TX bank while transfer `k` is on the wire, starts it the moment `k`
/// ends, and decodes and applies `k`'s node frame while `k + 1` is on the wire. The bus
/// waits for the RC only when composing `k + 1` takes longer than transfer `k`. Without it,
/// each transfer is composed, clocked and taken in turn.
pub async fn run_bus<B: RootBus, C: RootClock, S: SceneSource + ?Sized, P: PixelSink>(
    index: usize,
    bus: &mut B,
    clock: &C,
    root: &RefCell<RootState>,
    scenes: &S,
    sink: &RefCell<P>,
) -> Result<RootReport, RootError> {
    let mut rx = [0u8; MAX_FRAME];
    let double = root.borrow().cfg.double_buffer;
    // Broadcast position: frame, byte offset (None = SceneEnd next).
    let mut bframe: u16 = 0;
    let mut boffset: Option<u32> = Some(0);
    // When this bus finished broadcasting each of the two latest frames' scenes (µs), by
    // `frame % 2`: a node owing its static region is timed from then.
    let mut scene_sent: [Option<(u16, u64)>; 2] = [None; 2];
    // Orphaning events this bus has broadcast `Wake` for.
    let mut woken: u16 = 0;
    // Roll calls: when the next may go out while work waits (None: nothing waits), and the
    // interval after it (doubles while the wait lasts, up to two time-outs: a lost `Wake` is
    // repeated within a bounded delay, a node that never answers costs one small broadcast
    // per two time-outs).
    let mut call_at: Option<u64> = None;
    let mut call_every: u64 = 0;
    // The transfer on the wire (double buffering only).
    let mut inflight: Option<Sent> = None;
    let (first, count) = bus.nodes();
    loop {
        if root.borrow().finished() {
            if let Some(sent) = inflight.take() {
                let got = bus.finish(&mut rx).await?;
                complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
            }
            let n = wire::encode(0, 0, &Down::Stop, bus.tx_bank()).unwrap_or(0);
            clock.worked(RcWork::Encode { bytes: n }).await;
            bus.start(Transfer::Broadcast, n)?;
            bus.finish(&mut rx).await?;
            return Ok(root.borrow().report());
        }
        // 1. Choose the next transfer and compose it into the idle TX bank.
        let mut ready = bus.ready();
        let mut wake: Option<u16> = None;
        if ready.is_none() {
            let now = clock.now_us();
            let f = root.borrow().handing_out();
            let sent = scene_sent[(f % 2) as usize]
                .filter(|&(g, _)| g == f)
                .map(|(_, t)| t);
            root.borrow_mut().expire(first, count, now, sent);
            let waiting = root.borrow().roll_call(first, count, bframe);
            let every = root.borrow().timeout_us();
            match waiting {
                None => call_at = None,
                Some(frame) => {
                    // Jobs became orphans (on any bus): idle nodes must be told to ask for
                    // them at once. Otherwise call once the wait has lasted a time-out.
                    if root.borrow().orphaned() > woken {
                        woken = root.borrow().orphaned();
                        call_at = Some(now);
                        call_every = every;
                    }
                    let at = *call_at.get_or_insert_with(|| {
                        call_every = every;
                        now.saturating_add(every)
                    });
                    if now >= at {
                        wake = Some(frame);
                        call_at = Some(now.saturating_add(call_every));
                        call_every = call_every.saturating_mul(2).min(every.saturating_mul(2));
                    }
                }
            }
            let can_send = root.borrow().may_broadcast(bframe);
            if wake.is_none() && !(can_send && scenes.produced(bframe)) {
                // Nothing to send now. The frame on the wire may change that: take it first.
                if let Some(sent) = inflight.take() {
                    let got = bus.finish(&mut rx).await?;
                    complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
                    continue;
                }
                let deadline = match (root.borrow().next_deadline(first, count, sent), call_at) {
                    (Some(a), Some(b)) => Some(a.min(b)),
                    (a, b) => a.or(b),
                };
                let timer = async {
                    match deadline {
                        Some(t) => clock.at_us(t).await,
                        None => core::future::pending::<()>().await,
                    }
                };
                let dm = async {
                    if can_send {
                        scenes.wait_produced(bframe).await
                    } else {
                        core::future::pending::<()>().await
                    }
                };
                let end = Finished { root, slot: index };
                match select4(bus.wait_ready(), end, timer, dm).await {
                    Either4::First(n) => ready = Some(n),
                    _ => continue,
                }
            }
        }
        // A node whose exchange is still on the wire (or not yet taken) that is ready again
        // already has our reply: take its last frame before composing the next reply.
        if let (Some(node), Some(Sent::Exchange(busy))) = (ready, inflight) {
            if node == busy {
                inflight = None;
                let got = bus.finish(&mut rx).await?;
                complete(
                    Sent::Exchange(node),
                    &rx[..got.min(rx.len())],
                    clock,
                    root,
                    sink,
                )
                .await;
                continue;
            }
        }
        let (next, n) = match ready {
            Some(node) => {
                // Its ready line is up: the node is alive.
                let mut r = root.borrow_mut();
                r.heard(node, clock.now_us());
                (Sent::Exchange(node), r.reply(node, scenes, bus.tx_bank()))
            }
            None if wake.is_some() => (
                Sent::Broadcast,
                wire::encode(
                    0,
                    0,
                    &Down::Wake {
                        frame: wake.unwrap_or(0),
                    },
                    bus.tx_bank(),
                )
                .unwrap_or(0),
            ),
            None => {
                let scene = scenes
                    .scene(bframe)
                    .ok_or(RootError::BadScene { frame: bframe })?;
                let crc = root
                    .borrow_mut()
                    .scene_crc(bframe, scene, scenes.scene_crc(bframe));
                let tx = bus.tx_bank();
                let n = match boffset {
                    Some(off) => {
                        let start = off as usize;
                        let end = (start + SCENE_CHUNK).min(scene.len());
                        let msg = Down::Scene {
                            frame: bframe,
                            offset: off,
                            total: scene.len() as u32,
                            crc,
                            data: &scene[start..end],
                        };
                        boffset = (end < scene.len()).then_some(end as u32);
                        wire::encode(0, 0, &msg, tx).unwrap_or(0)
                    }
                    None => {
                        let msg = Down::SceneEnd {
                            frame: bframe,
                            len: scene.len() as u32,
                            crc,
                        };
                        scene_sent[(bframe % 2) as usize] = Some((bframe, clock.now_us()));
                        bframe += 1;
                        boffset = Some(0);
                        wire::encode(0, 0, &msg, tx).unwrap_or(0)
                    }
                };
                (Sent::Broadcast, n)
            }
        };
        let crc_bytes = root.borrow_mut().take_crc_work();
        if crc_bytes > 0 {
            clock.worked(RcWork::Checksum { bytes: crc_bytes }).await;
        }
        clock.worked(RcWork::Encode { bytes: n }).await;
        // 2. The transfer on the wire must end before this one starts; then take its frame
        // while this one is on the wire.
        let prev = match inflight.take() {
            Some(sent) => Some((sent, bus.finish(&mut rx).await?)),
            None => None,
        };
        let transfer = match next {
            Sent::Exchange(node) => Transfer::Exchange(node),
            Sent::Broadcast => Transfer::Broadcast,
        };
        bus.start(transfer, n)?;
        if let Some((sent, got)) = prev {
            complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
        }
        if double {
            inflight = Some(next);
        } else {
            let got = bus.finish(&mut rx).await?;
            complete(next, &rx[..got.min(rx.len())], clock, root, sink).await;
        }
    }
}
