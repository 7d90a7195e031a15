//! The serial backup line simulated: the RC and nodes whose SPI link is dead (alive
//! otherwise) on the board profile's RS-485 line ([`LineProfile`]), in virtual time, running
//! the links-core protocol ([`links_core::backup`]): the node's state machine
//! ([`BackupNode`]) and the RC's side ([`BackupRc`]: roll call, scene, jobs, pixel polls)
//! as the firmware runs them, the RC's over this module's virtual line ([`SimLine`]).
//!
//! The line is one half-duplex medium: every frame (the RC's, then the addressed node's
//! answer) occupies it for [`LineProfile::frame_ns`]; an absent node costs the reply
//! timeout. The RC's run: roll call at frame start; the scene broadcast in chunks, then each
//! present node asked for its health and sent what it lacks; then one job per node at a time
//! (one scanline each), and polls for pixels until every scanline is in. Nodes render
//! while the RC talks to others; their compute time is the cost model at the board's clock.
//! A node renders a scanline piece while the previous one waits in its outbox.

use super::exec::Ps;
use super::run::trace_run;
use crate::cost::CycleModel;
use links_core::backup::{
    self, rc, BackupNode, BackupRc, BackupWork, Health, RcLine, Turn, BROADCAST, MAX_ADDR,
    MAX_FRAME, OUTBOX_PIXELS,
};
use links_core::board::{BoardProfile, LineProfile};
use links_core::image::SceneView;
use links_core::num::{Fx, Storage};
use links_core::render::{Rgb8, Stats, Techniques};
use links_core::wire::{Job, Region};
use std::fmt;

/// One backup-line simulation's set-up.
#[derive(Clone, Debug)]
pub struct BackupConfig {
    /// The line (the board profile's).
    pub line: LineProfile,
    /// Nodes on the line, addresses 1..=nodes (at most [`backup::MAX_ADDR`]); all have a dead
    /// SPI link, so the line is their only path.
    pub nodes: u8,
    /// Addresses of nodes that are dead altogether (never answer).
    pub dead: Vec<u8>,
    /// Node core clock (Hz) and cost model.
    pub clock_hz: f64,
    pub model: CycleModel,
    pub techniques: Techniques,
}

impl BackupConfig {
    /// `nodes` nodes on `profile`'s backup line, its core's clock and weights.
    pub fn for_board(profile: &BoardProfile, nodes: u8) -> Self {
        Self {
            line: profile.backup,
            nodes,
            dead: Vec::new(),
            clock_hz: profile.core_clock_hz as f64,
            model: CycleModel::for_core(profile.core),
            techniques: Techniques::ALL,
        }
    }
}

/// What a backup-line simulation measured (times virtual).
#[derive(Clone, Debug)]
pub struct BackupReport {
    pub width: u32,
    pub height: u32,
    /// The frame (RGB8 rows).
    pub frame: Vec<u8>,
    /// When the last pixel arrived (s).
    pub time_s: f64,
    /// When the roll call and the scene delivery ended (s).
    pub roll_call_s: f64,
    pub scene_s: f64,
    /// Frames and bytes on the line (both directions), and reply timeouts waited out.
    pub line_frames: u64,
    pub line_bytes: u64,
    pub timeouts: u64,
    /// Time the line carried frames or waited for an answer (s).
    pub line_busy_s: f64,
    /// The roll call: each address's health (`None`: absent).
    pub roll_call: Vec<(u8, Option<Health>)>,
    /// Jobs (scanlines) each present node rendered, and its compute time (s).
    pub jobs: Vec<(u8, u32)>,
    pub node_compute_s: Vec<f64>,
    /// Pixel frames accepted and the run-length bytes they carried.
    pub pixel_frames: u64,
    pub pixel_bytes: u64,
}

/// Why a backup-line simulation could not run or finish.
#[derive(Debug)]
pub enum BackupSimError {
    Config(String),
    /// The scene image is not valid.
    Scene(String),
    /// A protocol error the RC cannot recover from (a node's frame that does not decode).
    Protocol(backup::BackupError),
    /// No node answered the roll call.
    NoNodes,
    /// The work did not finish in the step budget.
    Stalled,
}

impl fmt::Display for BackupSimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BackupSimError::Config(s) => write!(f, "backup line: {s}"),
            BackupSimError::Scene(s) => write!(f, "backup line: scene: {s}"),
            BackupSimError::Protocol(e) => write!(f, "backup line: {e} ({e:?})"),
            BackupSimError::NoNodes => write!(f, "backup line: no node answered the roll call"),
            BackupSimError::Stalled => write!(f, "backup line: the work did not finish"),
        }
    }
}

impl std::error::Error for BackupSimError {}

impl From<backup::BackupError> for BackupSimError {
    fn from(e: backup::BackupError) -> Self {
        BackupSimError::Protocol(e)
    }
}

/// A piece rendered and waiting for the outbox: (job, y, x, pixels, last, finished at).
type Rendered = (Job, u16, u16, Vec<u8>, bool, Ps);

/// One simulated node: the protocol state, its renderer's progress in virtual time.
pub(super) struct SimNode<'b> {
    pub(super) proto: BackupNode<'b>,
    pub(super) alive: bool,
    /// The job being rendered and its next piece.
    job: Option<(Job, u32)>,
    rendered: Option<Rendered>,
    /// When its core is free again.
    free_at: Ps,
    pub(super) compute: Ps,
    pub(super) jobs: u32,
}

impl<'b> SimNode<'b> {
    pub(super) fn new(addr: u8, bank: &'b mut [u8], alive: bool) -> Self {
        Self {
            proto: BackupNode::new(addr, bank),
            alive,
            job: None,
            rendered: None,
            free_at: 0,
            compute: 0,
            jobs: 0,
        }
    }
}

/// The line, the clock and the counters.
pub(super) struct Line {
    pub(super) profile: LineProfile,
    pub(super) now: Ps,
    pub(super) frames: u64,
    pub(super) bytes: u64,
    pub(super) timeouts: u64,
    pub(super) busy: Ps,
}

impl Line {
    pub(super) fn new(profile: LineProfile) -> Self {
        Self {
            profile,
            now: 0,
            frames: 0,
            bytes: 0,
            timeouts: 0,
            busy: 0,
        }
    }

    fn carry(&mut self, bytes: usize) {
        let ps = self.profile.frame_ns(bytes) * 1000;
        self.now += ps;
        self.busy += ps;
        self.frames += 1;
        self.bytes += bytes as u64;
    }

    fn time_out(&mut self) {
        let ps = self.profile.reply_timeout_us as u64 * 1_000_000;
        self.now += ps;
        self.busy += ps;
        self.timeouts += 1;
    }
}

/// The scenes (by frame) and the renderer's settings.
pub(super) struct Work<'s> {
    pub(super) views: Vec<SceneView<'s>>,
    pub(super) width: u32,
    pub(super) model: CycleModel,
    pub(super) clock_hz: f64,
    pub(super) techniques: Techniques,
}

impl Work<'_> {
    /// Advance node `n` to time `t`: move a finished piece into its outbox, start its next
    /// piece (rendered now, charged at the core's cost), take a new job.
    pub(super) fn advance(&self, n: &mut SimNode<'_>, t: Ps) -> Result<(), BackupSimError> {
        loop {
            if let Some(r) = n.rendered.take_if(|r| r.5 <= t && n.proto.outbox_free()) {
                n.proto.push_pixels(&r.0, r.1, r.2, &r.3, r.4)?;
                continue;
            }
            if n.job.is_none() {
                n.job = n.proto.take_job().map(|j| (j, 0));
            }
            if n.rendered.is_some() {
                return Ok(());
            }
            let Some((job, i)) = n.job else {
                return Ok(());
            };
            let Some((y, x, len)) = job.region.piece(self.width, i) else {
                n.job = None;
                continue;
            };
            let last = job.region.piece(self.width, i + 1).is_none();
            n.job = Some((job, i + 1));
            let (rgb, stats) = self.render(job.frame, y, x, len)?;
            let ps = (self.model.cycles(&stats) as f64 * 1e12 / self.clock_hz).ceil() as Ps;
            let start = n.free_at.max(t);
            n.free_at = start + ps;
            n.compute += ps;
            n.rendered = Some((job, y as u16, x as u16, rgb, last, n.free_at));
        }
    }

    fn render(
        &self,
        frame: u16,
        y: u32,
        x: u32,
        len: u32,
    ) -> Result<(Vec<u8>, Stats), BackupSimError> {
        let view = *self
            .views
            .get(frame as usize)
            .ok_or_else(|| BackupSimError::Scene(format!("no frame {frame}")))?;
        let mut out = vec![Rgb8::default(); len as usize];
        // The kernel of the scene's storage, as the node's.
        let stats = match view.storage() {
            Storage::F32 => trace_run::<f32>(view, self.techniques, (y, x), &mut out),
            Storage::Q16_16 => trace_run::<Fx>(view, self.techniques, (y, x), &mut out),
        }
        .map_err(|e| BackupSimError::Scene(format!("{e:?}")))?;
        Ok((out.as_flattened().to_vec(), stats))
    }
}

/// Send the RC's frame `req` (for `to`; every alive node hears it) and return the answer,
/// charging the line; an addressed node that does not answer costs the reply timeout.
pub(super) fn exchange(
    line: &mut Line,
    nodes: &mut [SimNode<'_>],
    work: &Work<'_>,
    to: u8,
    req: &[u8],
) -> Result<Option<Vec<u8>>, BackupSimError> {
    line.carry(req.len());
    let mut answer = None;
    let mut reply = [0u8; MAX_FRAME];
    for n in nodes.iter_mut().filter(|n| n.alive) {
        work.advance(n, line.now)?;
        // A frame a node cannot take is counted in its health, as on the board.
        if let Ok(Some(r)) = n.proto.handle(req, &mut reply) {
            answer = Some(reply[..r].to_vec());
        }
    }
    match &answer {
        Some(a) => line.carry(a.len()),
        None if to != BROADCAST => line.time_out(),
        None => {}
    }
    Ok(answer)
}

/// The RC's end of the simulated line ([`RcLine`]): every exchange charged in virtual time.
pub(super) struct SimLine<'l, 'n, 'b, 'w, 's> {
    pub(super) line: &'l mut Line,
    pub(super) nodes: &'n mut [SimNode<'b>],
    pub(super) work: &'w Work<'s>,
}

impl RcLine for SimLine<'_, '_, '_, '_, '_> {
    type Error = BackupSimError;
    async fn exchange(
        &mut self,
        to: u8,
        buf: &mut [u8; MAX_FRAME],
        len: usize,
    ) -> Result<Option<usize>, BackupSimError> {
        let answer = exchange(self.line, self.nodes, self.work, to, &buf[..len])?;
        Ok(answer.map(|a| {
            let n = a.len().min(MAX_FRAME);
            buf[..n].copy_from_slice(&a[..n]);
            n
        }))
    }
}

/// The pixel buffer of the RC's turns: a whole outbox chunk at once.
pub(super) const RC_RGB: usize = 3 * OUTBOX_PIXELS;

/// The standalone run's work: one scanline per job, rows in order, into the frame.
struct Dealer<'f> {
    frame: &'f mut [u8],
    width: u32,
    height: u32,
    next_row: u32,
    /// Per address: the job it holds; jobs of nodes given up, to hand out again.
    holding: Vec<Option<Job>>,
    again: Vec<Job>,
}

impl Dealer<'_> {
    fn finished(&self) -> bool {
        self.next_row >= self.height
            && self.again.is_empty()
            && self.holding.iter().all(Option::is_none)
    }
}

impl BackupWork for Dealer<'_> {
    fn assign(&mut self, addr: u8) -> Option<Job> {
        let held = self.holding.get_mut(addr as usize - 1)?;
        if held.is_none() {
            *held = match self.again.pop() {
                Some(j) => Some(j),
                None if self.next_row < self.height => {
                    let row = self.next_row;
                    self.next_row += 1;
                    Some(Job {
                        id: row,
                        frame: 0,
                        region: Region::Span {
                            start: row * self.width,
                            len: self.width,
                        },
                    })
                }
                None => None,
            };
        }
        *held
    }

    fn missing_scene(&self, _: u8) -> Option<u16> {
        None
    }

    fn scene(&self, _: u16) -> Option<&[u8]> {
        None
    }

    fn scene_ready(&mut self, _: u8, _: u16) {}

    fn pixels(&mut self, addr: u8, job: u32, y: u16, x: u16, rgb: &[u8], done: bool) -> bool {
        let Some(held) = self.holding.get_mut(addr as usize - 1) else {
            return false;
        };
        if held.is_none_or(|j| j.id != job) || x as u32 + (rgb.len() / 3) as u32 > self.width {
            return false;
        }
        let at = 3 * (y as usize * self.width as usize + x as usize);
        let Some(dst) = self.frame.get_mut(at..at + rgb.len()) else {
            return false;
        };
        dst.copy_from_slice(rgb);
        if done {
            *held = None;
        }
        true
    }

    fn lost(&mut self, addr: u8) {
        if let Some(j) = self
            .holding
            .get_mut(addr as usize - 1)
            .and_then(Option::take)
        {
            self.again.push(j);
        }
    }
}

/// Simulate rendering one frame over the backup line only.
pub fn simulate_backup(image: &[u8], cfg: &BackupConfig) -> Result<BackupReport, BackupSimError> {
    if cfg.nodes == 0 || cfg.nodes > backup::MAX_ADDR {
        return Err(BackupSimError::Config(format!(
            "{} nodes (1 to {})",
            cfg.nodes,
            backup::MAX_ADDR
        )));
    }
    if cfg.clock_hz.is_nan() || cfg.clock_hz <= 0.0 || cfg.line.bit_rate_hz == 0 {
        return Err(BackupSimError::Config(
            "clock and bit rate must be positive".into(),
        ));
    }
    let view = SceneView::new(image).map_err(|e| BackupSimError::Scene(e.to_string()))?;
    let cam = view.camera::<f32>();
    let (width, height) = (cam.width, cam.height);
    let work = Work {
        views: vec![view],
        width,
        model: cfg.model,
        clock_hz: cfg.clock_hz,
        techniques: cfg.techniques,
    };
    let mut banks: Vec<Vec<u8>> = (0..cfg.nodes).map(|_| vec![0u8; image.len()]).collect();
    let mut nodes: Vec<SimNode<'_>> = banks
        .iter_mut()
        .enumerate()
        .map(|(i, b)| SimNode::new(i as u8 + 1, b, !cfg.dead.contains(&(i as u8 + 1))))
        .collect();
    let mut line = Line::new(cfg.line);
    let mut sim = SimLine {
        line: &mut line,
        nodes: &mut nodes,
        work: &work,
    };
    let roll = embassy_futures::block_on(rc::roll_call(&mut sim, cfg.nodes))?;
    let calls: Vec<(u8, Option<Health>)> = (1..=cfg.nodes).map(|a| (a, roll.health(a))).collect();
    let roll_call_ps = sim.line.now;
    let present: Vec<u8> = calls
        .iter()
        .filter(|c| c.1.is_some())
        .map(|c| c.0)
        .collect();
    if present.is_empty() {
        return Err(BackupSimError::NoNodes);
    }
    // Broadcast, then each node's health and what it lacks (at most 4 rounds).
    if !embassy_futures::block_on(rc::deliver_scene(&mut sim, &present, 0, image, 4))? {
        return Err(BackupSimError::Stalled);
    }
    let scene_ps = sim.line.now;
    let mut frame = vec![0u8; 3 * width as usize * height as usize];
    let (pixel_frames, pixel_bytes) = hand_out(&mut line, &mut nodes, &work, &present, &mut frame)?;
    Ok(BackupReport {
        width,
        height,
        frame,
        time_s: line.now as f64 * 1e-12,
        roll_call_s: roll_call_ps as f64 * 1e-12,
        scene_s: scene_ps as f64 * 1e-12,
        line_frames: line.frames,
        line_bytes: line.bytes,
        timeouts: line.timeouts,
        line_busy_s: line.busy as f64 * 1e-12,
        roll_call: calls,
        jobs: present
            .iter()
            .map(|&a| (a, nodes[a as usize - 1].jobs))
            .collect(),
        node_compute_s: nodes.iter().map(|n| n.compute as f64 * 1e-12).collect(),
        pixel_frames,
        pixel_bytes,
    })
}

/// Hand out one scanline at a time to each present node and poll for pixels until the
/// frame is complete ([`BackupRc`] over the simulated line). Returns the pixel frames
/// accepted and their run-length bytes.
fn hand_out(
    line: &mut Line,
    nodes: &mut [SimNode<'_>],
    work: &Work<'_>,
    present: &[u8],
    frame: &mut [u8],
) -> Result<(u64, u64), BackupSimError> {
    let mut dealer = Dealer {
        height: (frame.len() / 3) as u32 / work.width.max(1),
        frame,
        width: work.width,
        next_row: 0,
        holding: vec![None; MAX_ADDR as usize],
        again: Vec::new(),
    };
    let mut rc = BackupRc::<{ MAX_ADDR as usize }>::new();
    for &a in present {
        rc.serve(a);
    }
    let mut rgb = [0u8; RC_RGB];
    let mut steps = 0u64;
    while !dealer.finished() {
        steps += 1;
        if steps > 50_000_000 || rc.addrs().next().is_none() {
            return Err(BackupSimError::Stalled);
        }
        for k in 0..present.len() {
            let mut sim = SimLine {
                line: &mut *line,
                nodes: &mut *nodes,
                work,
            };
            let addr = rc.addr_at(k);
            let turn = embassy_futures::block_on(rc.turn(k, &mut sim, &mut dealer, &mut rgb))?;
            if let (Turn::Work { .. }, Some(a)) = (turn, addr) {
                nodes[a as usize - 1].jobs += 1;
            }
        }
    }
    Ok((rc.counters.pixel_frames, rc.counters.pixel_bytes))
}
