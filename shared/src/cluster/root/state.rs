//! The RC's shared state: per-node bookkeeping, per-frame progress, frame completion and
//! the queries the bus tasks make.

use super::*;
use crate::cluster::link::NodeId;
use crate::cluster::sched::Scheduler;
use crate::cluster::wire::{self, Job, JOB_QUEUE, SCENE_CHUNK};
use crate::image::SceneView;
use core::cell::RefCell;
use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll, Waker};

#[derive(Clone, Copy, Debug)]
pub(super) struct NodeSlot {
    pub(super) expect: u16,
    pub(super) jobs: [Option<Job>; JOB_QUEUE],
    /// The frame whose scene the node reported ready, per bank (`frame % 2`). Per bank,
    /// not "up to": a node may have missed frame `f`'s broadcast and still hold `f + 1`'s.
    pub(super) ready: [Option<u16>; 2],
    /// Scene chunks the node lacks (frame, bitmap), minus those already re-sent.
    pub(super) repair: Option<(u16, [u32; wire::MAX_CHUNKS / 32])>,
    /// The chunk re-sent in the exchange in progress.
    pub(super) repairing: Option<u32>,
    /// How the node's scene is being repaired piece by piece.
    pub(super) pieces: Option<Pieces>,
    /// When the RC last exchanged with the node (µs); for a node declared dead, the moment
    /// its silence was counted from.
    pub(super) heard_us: u64,
    /// Declared dead: its jobs are orphans waiting to be re-issued.
    pub(super) dead: bool,
    /// Declared dead while holding jobs (it was rendering): if it speaks again, the
    /// time-out was too short for its runs.
    pub(super) dead_rendering: bool,
}

impl NodeSlot {
    pub(super) const NEW: NodeSlot = NodeSlot {
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
    pub(super) fn ready_for(&self, frame: u16) -> bool {
        self.ready[(frame % 2) as usize] == Some(frame)
    }
}

/// A node's scene repair on a noisy link: a chunk sent whole that the node still reports
/// missing is sent again in halves, quarters, ... down to [`wire::SCENE_PIECE`] bytes, one
/// piece per exchange and only the pieces the node lacks, so that short frames get through
/// where a whole chunk never would; two chunks in a row that get through at the first try
/// double the piece size again.
#[derive(Clone, Copy, Debug)]
pub(super) struct Pieces {
    /// The frame whose scene is being repaired.
    pub(super) frame: u16,
    /// Piece size in bytes (a power of two, [`wire::SCENE_PIECE`]..=[`SCENE_CHUNK`]).
    pub(super) size: u16,
    /// The chunk being sent piece by piece and the offset of its next piece.
    pub(super) cycle: Option<(u8, u16)>,
    /// The highest chunk sent in full so far: a chunk at or below it asked for again was
    /// lost on the way, so pieces get smaller.
    pub(super) high: Option<u8>,
    /// Chunks started at the first try since the piece size last changed.
    pub(super) streak: u8,
    /// The node's last report of the pieces it holds of its first missing chunk: (chunk,
    /// bitmap of pieces).
    pub(super) have: Option<(u8, u16)>,
}

impl Pieces {
    pub(super) fn new(frame: u16) -> Self {
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
pub(super) struct Progress {
    pub(super) frame: u16,
    pub(super) issued: u32,
    pub(super) done: u32,
    pub(super) all_issued: bool,
    pub(super) complete: bool,
}

/// The RC's state, shared by its bus tasks.
pub struct RootState {
    pub(super) cfg: RootConfig,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) nodes: [NodeSlot; MAX_NODES],
    pub(super) sched: Scheduler,
    /// The frame whose jobs `sched` hands out.
    pub(super) sched_frame: u16,
    pub(super) progress: [Progress; 2],
    /// Frames complete, counted in order.
    pub(super) complete: u16,
    pub(super) next_job: u32,
    pub(super) report: RootReport,
    /// Times jobs became orphans (a node declared dead holding jobs, a dead node's static
    /// region issued to it): each bus broadcasts `Wake` when this grows.
    pub(super) orphaned: u16,
    /// The time-out in force (µs): starts at `cfg.timeout_us`; a node declared dead while
    /// rendering that speaks again raises it to twice the silence it was declared dead for.
    pub(super) timeout_us: u64,
    /// Bus tasks waiting for the end (woken when the last frame completes).
    pub(super) finish_wakers: [Option<Waker>; MAX_BUSES],
    /// CRC-32 of the scenes of the two frames in flight: (frame, crc) by `frame % 2`.
    pub(super) scene_crc: [Option<(u16, u32)>; 2],
    /// Scene bytes checksummed since [`RootState::take_crc_work`] last ran.
    pub(super) crc_work: usize,
    /// Nodes served over the backup line: (node, served now (false: back on SPI), the job
    /// it renders there), at most [`BACKUP_NODES`] at once (a table, not a field of every
    /// node's slot: the RC's RAM).
    pub(super) backup_jobs: [(NodeId, bool, Option<Job>); BACKUP_NODES],
}

/// Resolves when every frame is complete.
pub(super) struct Finished<'a> {
    pub(super) root: &'a RefCell<RootState>,
    pub(super) slot: usize,
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
            .map_err(RootError::Sched)?
            .followed_by(cfg.frames.saturating_sub(1) as u32);
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
            backup_jobs: [(NodeId::MAX, false, None); BACKUP_NODES],
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

    pub(super) fn prog(&mut self, frame: u16) -> Option<&mut Progress> {
        let p = &mut self.progress[(frame % 2) as usize];
        (p.frame == frame).then_some(p)
    }

    pub(super) fn update_complete(&mut self) {
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
}
