//! The serial backup line simulated: the RC and nodes whose SPI link is dead (alive
//! otherwise) on the board profile's RS-485 line ([`LineProfile`]), in virtual time, running
//! the links-core protocol ([`links_core::backup`]): the node's state machine
//! ([`BackupNode`]) and the RC's roll call ([`RollCall`]) as the firmware runs them.
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
    self, BackupNode, Health, Msg, RollCall, RollCallStep, BROADCAST, MAX_FRAME, SCENE_DATA,
};
use links_core::board::{BoardProfile, LineProfile};
use links_core::image::SceneView;
use links_core::num::{Fx, Storage};
use links_core::render::{Rgb8, Stats, Techniques};
use links_core::wire::{rle_decode, Job, Region, CRC32};
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

/// The scenes (by frame), the renderer's settings, the frame being assembled (standalone
/// runs only).
pub(super) struct Work<'s> {
    pub(super) views: Vec<SceneView<'s>>,
    pub(super) width: u32,
    pub(super) model: CycleModel,
    pub(super) clock_hz: f64,
    pub(super) techniques: Techniques,
    pub(super) frame: Vec<u8>,
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

pub(super) fn send(
    line: &mut Line,
    nodes: &mut [SimNode<'_>],
    work: &Work<'_>,
    to: u8,
    msg: &Msg<'_>,
) -> Result<Option<Vec<u8>>, BackupSimError> {
    let mut buf = [0u8; MAX_FRAME];
    let n = backup::encode(to, msg, &mut buf)?;
    exchange(line, nodes, work, to, &buf[..n])
}

/// The scene's chunks for `to` from byte `from` on.
#[allow(clippy::too_many_arguments)]
pub(super) fn send_scene(
    line: &mut Line,
    nodes: &mut [SimNode<'_>],
    work: &Work<'_>,
    to: u8,
    frame: u16,
    scene: &[u8],
    from: usize,
) -> Result<(), BackupSimError> {
    let crc = CRC32.checksum(scene);
    let mut at = from;
    while at < scene.len() {
        let end = (at + SCENE_DATA).min(scene.len());
        let msg = Msg::Scene {
            frame,
            offset: at as u32,
            total: scene.len() as u32,
            crc,
            data: &scene[at..end],
        };
        send(line, nodes, work, to, &msg)?;
        at = end;
    }
    Ok(())
}

/// Roll call over every address; returns each one's health.
pub(super) fn roll_call(
    line: &mut Line,
    nodes: &mut [SimNode<'_>],
    work: &Work<'_>,
    count: u8,
) -> Result<Vec<(u8, Option<Health>)>, BackupSimError> {
    let mut rc = RollCall::new(count);
    let mut req = [0u8; MAX_FRAME];
    while let RollCallStep::Ask(a) = rc.step() {
        let n = rc.request(&mut req)?;
        let answer = exchange(line, nodes, work, a, &req[..n])?;
        // A garbled answer counts the node absent (the error is the roll call's to report).
        let _ = rc.answered(answer.as_deref());
    }
    Ok((1..=count).map(|a| (a, rc.health(a))).collect())
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
    let mut work = Work {
        views: vec![view],
        width,
        model: cfg.model,
        clock_hz: cfg.clock_hz,
        techniques: cfg.techniques,
        frame: vec![0u8; 3 * width as usize * height as usize],
    };
    let mut banks: Vec<Vec<u8>> = (0..cfg.nodes).map(|_| vec![0u8; image.len()]).collect();
    let mut nodes: Vec<SimNode<'_>> = banks
        .iter_mut()
        .enumerate()
        .map(|(i, b)| SimNode::new(i as u8 + 1, b, !cfg.dead.contains(&(i as u8 + 1))))
        .collect();
    let mut line = Line::new(cfg.line);
    let calls = roll_call(&mut line, &mut nodes, &work, cfg.nodes)?;
    let roll_call_ps = line.now;
    let present: Vec<u8> = calls
        .iter()
        .filter(|c| c.1.is_some())
        .map(|c| c.0)
        .collect();
    if present.is_empty() {
        return Err(BackupSimError::NoNodes);
    }
    deliver_scene(&mut line, &mut nodes, &work, &present, image)?;
    let scene_ps = line.now;
    let (pixel_frames, pixel_bytes) = hand_out(&mut line, &mut nodes, &mut work, &present)?;
    Ok(BackupReport {
        width,
        height,
        frame: std::mem::take(&mut work.frame),
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

/// Broadcast the scene, then ask each present node for its health and send what it lacks
/// (at most 4 rounds).
fn deliver_scene(
    line: &mut Line,
    nodes: &mut [SimNode<'_>],
    work: &Work<'_>,
    present: &[u8],
    scene: &[u8],
) -> Result<(), BackupSimError> {
    send_scene(line, nodes, work, BROADCAST, 0, scene, 0)?;
    for _ in 0..4 {
        let mut all = true;
        for &a in present {
            let h = match send(line, nodes, work, a, &Msg::RollCall)? {
                Some(r) => match backup::decode(&r)? {
                    (_, Msg::Health(h)) => h,
                    _ => continue,
                },
                None => continue,
            };
            if !h.scene_ok {
                all = false;
                send_scene(line, nodes, work, a, 0, scene, h.scene_bytes as usize)?;
            }
        }
        if all {
            return Ok(());
        }
    }
    Err(BackupSimError::Stalled)
}

/// Hand out one scanline at a time to each present node and poll for pixels until the
/// frame is complete. Returns the pixel frames accepted and their run-length bytes.
fn hand_out(
    line: &mut Line,
    nodes: &mut [SimNode<'_>],
    work: &mut Work<'_>,
    present: &[u8],
) -> Result<(u64, u64), BackupSimError> {
    let height = (work.frame.len() / 3) as u32 / work.width.max(1);
    let mut next_row = 0u32;
    // Per present node: the job it holds and the RC's ack.
    let mut holding: Vec<Option<Job>> = vec![None; present.len()];
    let mut ack: Vec<u16> = vec![0; present.len()];
    let (mut frames, mut bytes) = (0u64, 0u64);
    let mut steps = 0u64;
    while next_row < height || holding.iter().any(Option::is_some) {
        steps += 1;
        if steps > 50_000_000 {
            return Err(BackupSimError::Stalled);
        }
        for (k, &a) in present.iter().enumerate() {
            if holding[k].is_none() && next_row < height {
                let job = Job {
                    id: next_row,
                    frame: 0,
                    region: Region::Span {
                        start: next_row * work.width,
                        len: work.width,
                    },
                };
                next_row += 1;
                send(line, nodes, work, a, &Msg::Work { job })?;
                holding[k] = Some(job);
                nodes[a as usize - 1].jobs += 1;
                continue;
            }
            let Some(job) = holding[k] else { continue };
            let Some(r) = send(line, nodes, work, a, &Msg::Poll { ack: ack[k] })? else {
                continue;
            };
            if let (
                _,
                Msg::Pixels {
                    seq,
                    job: j,
                    y,
                    x,
                    len,
                    done,
                    rle,
                    ..
                },
            ) = backup::decode(&r)?
            {
                if seq != ack[k] || j != job.id {
                    continue;
                }
                let at = 3 * (y as usize * work.width as usize + x as usize);
                let dst = work
                    .frame
                    .get_mut(at..at + 3 * len as usize)
                    .ok_or(backup::BackupError::Malformed)?;
                rle_decode(rle, dst).map_err(|_| backup::BackupError::Malformed)?;
                ack[k] = ack[k].wrapping_add(1);
                frames += 1;
                bytes += rle.len() as u64;
                if done {
                    holding[k] = None;
                }
            }
        }
    }
    Ok((frames, bytes))
}
