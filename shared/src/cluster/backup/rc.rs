//! The RC's side of the backup line's fallback: serving nodes whose SPI link failed over the
//! line alone. Per served node, one turn at a time: the scene it lacks (chunks, then its
//! health to confirm), else its job ([`Msg::Work`], until acknowledged), else a poll for its
//! pixels ([`Msg::Poll`]), whose run-length chunks are decoded and handed to the work's
//! owner ([`BackupWork`]). Hardware-independent: the line is an [`RcLine`] (a UART
//! [`LinePort`] through [`PortLine`]; the simulator's virtual line), the work is
//! [`RootState`]'s ([`RootWork`], [`serve_root`]) or anything else that deals jobs. No heap;
//! nothing a node sends can make it panic: a reply that does not decode counts as no answer
//! (the turn is repeated), a node silent for [`MAX_MISSES`] turns is given up and its job
//! returned ([`BackupWork::lost`]).

use super::{
    decode, encode, BackupError, Health, LineError, LinePort, Msg, RollCall, RollCallStep,
    BROADCAST, MAX_ADDR, MAX_FRAME, SCENE_DATA,
};
use crate::cluster::link::NodeId;
use crate::cluster::root::{PixelSink, RootClock, RootState, SceneSource};
use crate::cluster::wire::{Job, CRC32};
use core::cell::RefCell;

/// Consecutive turns without a valid answer after which a served node is given up.
pub const MAX_MISSES: u8 = 8;

/// The RC's end of the line: one request, the addressed node's answer.
#[allow(async_fn_in_trait)]
pub trait RcLine {
    type Error: From<BackupError>;
    /// Send the frame `buf[..len]` (for `to`) and take the answer into `buf`: its length, or
    /// `None` (a broadcast, or nothing within the reply timeout).
    async fn exchange(
        &mut self,
        to: u8,
        buf: &mut [u8; MAX_FRAME],
        len: usize,
    ) -> Result<Option<usize>, Self::Error>;
}

/// An [`RcLine`] over a UART port: a reply has `timeout_us` to start. A UART error on the
/// answer counts as no answer.
pub struct PortLine<'p, P> {
    pub port: &'p mut P,
    pub timeout_us: u32,
}

impl<P: LinePort> RcLine for PortLine<'_, P> {
    type Error = LineError;
    async fn exchange(
        &mut self,
        to: u8,
        buf: &mut [u8; MAX_FRAME],
        len: usize,
    ) -> Result<Option<usize>, LineError> {
        self.port.send(&buf[..len.min(MAX_FRAME)]).await?;
        if to == BROADCAST {
            return Ok(None);
        }
        match self.port.receive(buf, Some(self.timeout_us)).await {
            Ok(0) | Err(LineError::Uart) => Ok(None),
            Ok(n) => Ok(Some(n.min(MAX_FRAME))),
            Err(e) => Err(e),
        }
    }
}

/// No line at all (an RC without one): nobody ever answers.
pub struct NoLine;

impl RcLine for NoLine {
    type Error = LineError;
    async fn exchange(
        &mut self,
        _: u8,
        _: &mut [u8; MAX_FRAME],
        _: usize,
    ) -> Result<Option<usize>, LineError> {
        Ok(None)
    }
}

/// Encode `msg` for `to`, exchange it, decode the answer if it is `to`'s (a garbled or
/// foreign answer: `None`).
async fn ask<L: RcLine>(
    line: &mut L,
    to: u8,
    msg: &Msg<'_>,
    buf: &mut [u8; MAX_FRAME],
) -> Result<Option<usize>, L::Error> {
    let n = encode(to, msg, buf)?;
    let got = line.exchange(to, buf, n).await?;
    Ok(got.filter(|&g| matches!(decode(&buf[..g]), Ok((a, _)) if a == to)))
}

/// Ask node `addr` for its health.
pub async fn ask_health<L: RcLine>(line: &mut L, addr: u8) -> Result<Option<Health>, L::Error> {
    let mut buf = [0u8; MAX_FRAME];
    let got = ask(line, addr, &Msg::RollCall, &mut buf).await?;
    Ok(match got.map(|g| decode(&buf[..g])) {
        Some(Ok((_, Msg::Health(h)))) => Some(h),
        _ => None,
    })
}

/// Roll call of nodes 1..=`nodes` over `line`.
pub async fn roll_call<L: RcLine>(line: &mut L, nodes: u8) -> Result<RollCall, L::Error> {
    let mut rc = RollCall::new(nodes);
    let mut buf = [0u8; MAX_FRAME];
    while let RollCallStep::Ask(a) = rc.step() {
        let n = rc.request(&mut buf)?;
        let got = line.exchange(a, &mut buf, n).await?;
        // A garbled answer counts the node absent.
        let _ = rc.answered(got.map(|g| &buf[..g]));
    }
    Ok(rc)
}

/// Send frame `frame`'s scene to `to` (or [`BROADCAST`]) in chunks from byte `from` on.
pub async fn send_scene<L: RcLine>(
    line: &mut L,
    to: u8,
    frame: u16,
    scene: &[u8],
    from: usize,
) -> Result<(), L::Error> {
    let total = u32::try_from(scene.len()).map_err(|_| BackupError::TooLong)?;
    let crc = CRC32.checksum(scene);
    let mut buf = [0u8; MAX_FRAME];
    let mut at = from;
    while at < scene.len() {
        let end = (at + SCENE_DATA).min(scene.len());
        let msg = Msg::Scene {
            frame,
            offset: at as u32, // at < total
            total,
            crc,
            data: &scene[at..end],
        };
        let n = encode(to, &msg, &mut buf)?;
        line.exchange(to, &mut buf, n).await?;
        at = end;
    }
    Ok(())
}

/// Broadcast frame `frame`'s scene, then ask each of `nodes` for its health and send what it
/// lacks, for at most `rounds` rounds. Returns whether every node answered with the whole
/// scene.
pub async fn deliver_scene<L: RcLine>(
    line: &mut L,
    nodes: &[u8],
    frame: u16,
    scene: &[u8],
    rounds: u32,
) -> Result<bool, L::Error> {
    send_scene(line, BROADCAST, frame, scene, 0).await?;
    for _ in 0..rounds {
        let mut all = true;
        for &a in nodes {
            let Some(h) = ask_health(line, a).await? else {
                continue;
            };
            if !(h.scene_ok && h.frame == frame) {
                all = false;
                let from = if h.frame == frame { h.scene_bytes } else { 0 };
                send_scene(line, a, frame, scene, from as usize).await?;
            }
        }
        if all {
            return Ok(true);
        }
    }
    Ok(false)
}

/// What the RC serves nodes from: jobs, scenes, and where their pixels go. Nodes by line
/// address.
pub trait BackupWork {
    /// The job node `addr` holds, or a new one; `None`: nothing for it now.
    fn assign(&mut self, addr: u8) -> Option<Job>;
    /// The frame whose scene `addr` lacks for the work being handed out; `None`: it holds
    /// it.
    fn missing_scene(&self, addr: u8) -> Option<u16>;
    /// Frame `frame`'s scene image.
    fn scene(&self, frame: u16) -> Option<&[u8]>;
    /// `addr` reported frame `frame`'s scene complete.
    fn scene_ready(&mut self, addr: u8, frame: u16);
    /// A run of pixels (RGB8) of `addr`'s job `job`; `done`: the job's last. Returns whether
    /// it was taken.
    #[allow(clippy::too_many_arguments)]
    fn pixels(&mut self, addr: u8, job: u32, y: u16, x: u16, rgb: &[u8], done: bool) -> bool;
    /// `addr` stopped answering: its job goes to others.
    fn lost(&mut self, addr: u8);
}

/// What one turn did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Turn {
    /// No node in that slot, or nothing to do for it.
    Nothing,
    /// Sent the scene; `ready`: the node confirmed it.
    Scene { frame: u16, ready: bool },
    /// Sent a job; `taken`: the node acknowledged it.
    Work { job: Job, taken: bool },
    /// No valid answer (to the poll, or to the health asked after a scene).
    Silent,
    /// Polled: the node had nothing (rendering).
    Idle,
    /// Polled: `len` pixels taken (`done`: the job's last), carried in `rle` bytes.
    Pixels { len: u16, rle: u16, done: bool },
    /// Polled: a chunk that was not taken (a stale job's, dropped; or refused by the work).
    Refused,
    /// The node was silent too long and is given up.
    Lost,
}

/// What the RC's line did for the served nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RcCounters {
    /// Pixel chunks taken, their run-length bytes and pixels; jobs completed.
    pub pixel_frames: u64,
    pub pixel_bytes: u64,
    pub pixels: u64,
    pub jobs: u32,
    /// Turns without a valid answer, and nodes given up.
    pub silent: u32,
    pub lost: u32,
}

/// One served node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Served {
    addr: u8,
    /// The job the node acknowledged.
    sent: Option<u32>,
    /// The next pixel chunk sequence number the RC expects.
    ack: u16,
    /// Where its scene resumes, and consecutive silent turns.
    scene_from: u32,
    misses: u8,
}

/// The RC's state for up to `N` nodes served over the line.
pub struct BackupRc<const N: usize> {
    served: [Option<Served>; N],
    pub counters: RcCounters,
}

impl<const N: usize> Default for BackupRc<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> BackupRc<N> {
    pub const fn new() -> Self {
        Self {
            served: [None; N],
            counters: RcCounters {
                pixel_frames: 0,
                pixel_bytes: 0,
                pixels: 0,
                jobs: 0,
                silent: 0,
                lost: 0,
            },
        }
    }

    /// Serve node `addr` from now on (in the first free slot). Returns its slot, or `None`
    /// when all `N` are taken or the address is no node's.
    pub fn serve(&mut self, addr: u8) -> Option<usize> {
        if !(1..=MAX_ADDR).contains(&addr) {
            return None;
        }
        if let Some(k) = self.slot(addr) {
            return Some(k);
        }
        let k = self.served.iter().position(Option::is_none)?;
        self.served[k] = Some(Served {
            addr,
            sent: None,
            ack: 0,
            scene_from: 0,
            misses: 0,
        });
        Some(k)
    }

    /// The slot serving `addr`.
    pub fn slot(&self, addr: u8) -> Option<usize> {
        self.served
            .iter()
            .position(|s| s.is_some_and(|s| s.addr == addr))
    }

    /// The address served in slot `k`.
    pub fn addr_at(&self, k: usize) -> Option<u8> {
        self.served.get(k).copied().flatten().map(|s| s.addr)
    }

    /// The addresses served, slot by slot.
    pub fn addrs(&self) -> impl Iterator<Item = u8> + '_ {
        self.served.iter().flatten().map(|s| s.addr)
    }

    /// One turn for the node in slot `k`: its scene if it lacks the one being handed out
    /// (and has no job), else its job until acknowledged, else a poll for its pixels.
    pub async fn turn<L: RcLine, W: BackupWork>(
        &mut self,
        k: usize,
        line: &mut L,
        work: &mut W,
        rgb: &mut [u8],
    ) -> Result<Turn, L::Error> {
        let Some(mut sv) = self.served.get(k).copied().flatten() else {
            return Ok(Turn::Nothing);
        };
        let job = work.assign(sv.addr);
        let turn = match job {
            None => match work.missing_scene(sv.addr) {
                Some(frame) if work.scene(frame).is_some() => {
                    scene_turn(&mut sv, line, work, frame).await?
                }
                _ => return Ok(Turn::Nothing),
            },
            Some(job) if sv.sent != Some(job.id) => work_turn(&mut sv, line, job).await?,
            Some(job) => self.poll_turn(&mut sv, line, work, job, rgb).await?,
        };
        let answered = !matches!(turn, Turn::Silent | Turn::Work { taken: false, .. });
        sv.misses = if answered {
            0
        } else {
            sv.misses.saturating_add(1)
        };
        if !answered {
            self.counters.silent = self.counters.silent.saturating_add(1);
        }
        if sv.misses >= MAX_MISSES {
            self.served[k] = None;
            self.counters.lost = self.counters.lost.saturating_add(1);
            work.lost(sv.addr);
            return Ok(Turn::Lost);
        }
        self.served[k] = Some(sv);
        Ok(turn)
    }

    /// Poll the node for its job's pixels and hand a chunk to the work.
    async fn poll_turn<L: RcLine, W: BackupWork>(
        &mut self,
        sv: &mut Served,
        line: &mut L,
        work: &mut W,
        job: Job,
        rgb: &mut [u8],
    ) -> Result<Turn, L::Error> {
        let mut buf = [0u8; MAX_FRAME];
        let Some(g) = ask(line, sv.addr, &Msg::Poll { ack: sv.ack }, &mut buf).await? else {
            return Ok(Turn::Silent);
        };
        let Ok((_, msg)) = decode(&buf[..g]) else {
            return Ok(Turn::Silent);
        };
        let (seq, j, y, x, len, done, rle) = match msg {
            Msg::Pixels {
                seq,
                job,
                y,
                x,
                len,
                done,
                rle,
                ..
            } => (seq, job, y, x, len, done, rle),
            Msg::Idle => return Ok(Turn::Idle),
            _ => return Ok(Turn::Silent),
        };
        if seq != sv.ack {
            return Ok(Turn::Refused);
        }
        if j != job.id {
            // A chunk of a job the RC no longer waits for: dropped, so the node moves on.
            sv.ack = sv.ack.wrapping_add(1);
            return Ok(Turn::Refused);
        }
        if !deliver(work, sv.addr, j, (y, x, len, done), rle, rgb) {
            return Ok(Turn::Refused);
        }
        sv.ack = sv.ack.wrapping_add(1);
        let c = &mut self.counters;
        c.pixel_frames += 1;
        c.pixel_bytes += rle.len() as u64;
        c.pixels += len as u64;
        c.jobs += u32::from(done);
        Ok(Turn::Pixels {
            len,
            rle: rle.len() as u16, // <= MAX_BODY
            done,
        })
    }
}

/// Send the node the scene (from where it left off), then ask for its health.
async fn scene_turn<L: RcLine, W: BackupWork>(
    sv: &mut Served,
    line: &mut L,
    work: &mut W,
    frame: u16,
) -> Result<Turn, L::Error> {
    if let Some(scene) = work.scene(frame) {
        let from = (sv.scene_from as usize).min(scene.len());
        send_scene(line, sv.addr, frame, scene, from).await?;
    }
    let Some(h) = ask_health(line, sv.addr).await? else {
        return Ok(Turn::Silent);
    };
    let h = Some(h);
    let ready = h.is_some_and(|h| h.scene_ok && h.frame == frame);
    sv.scene_from = match h {
        Some(h) if h.frame == frame && !ready => h.scene_bytes,
        _ => 0,
    };
    if ready {
        work.scene_ready(sv.addr, frame);
    }
    Ok(Turn::Scene { frame, ready })
}

/// Hand the node its job; it counts as sent once acknowledged.
async fn work_turn<L: RcLine>(sv: &mut Served, line: &mut L, job: Job) -> Result<Turn, L::Error> {
    let mut buf = [0u8; MAX_FRAME];
    let got = ask(line, sv.addr, &Msg::Work { job }, &mut buf).await?;
    let taken = got.is_some_and(|g| matches!(decode(&buf[..g]), Ok((_, Msg::Ack))));
    if taken {
        sv.sent = Some(job.id);
    }
    Ok(Turn::Work { job, taken })
}

/// Expand a pixel chunk (`len` pixels of scanline `y` from column `x`, run-length coded as
/// [`crate::cluster::wire::rle_encode`]) through `rgb` (whole pixels; a chunk longer than
/// it goes in parts, `done` with the last) into the work. A chunk whose runs do not add up
/// to `len` is refused whole.
fn deliver<W: BackupWork>(
    work: &mut W,
    addr: u8,
    job: u32,
    (y, x, len, done): (u16, u16, u16, bool),
    rle: &[u8],
    rgb: &mut [u8],
) -> bool {
    let room = rgb.len() / 3;
    let runs = rle.chunks_exact(4);
    let total: usize = runs.clone().map(|q| q[0] as usize + 1).sum();
    if room == 0 || !rle.len().is_multiple_of(4) || total != len as usize || len == 0 {
        return false;
    }
    let mut at = 0usize; // pixels delivered
    let mut n = 0usize; // pixels in `rgb`
    for q in runs {
        for _ in 0..=q[0] {
            rgb[3 * n..3 * n + 3].copy_from_slice(&q[1..4]);
            n += 1;
            if n == room || at + n == total {
                let last = at + n == total;
                // x + at < x + len fits the frame's u16 columns (the work checks the frame).
                let col = x.saturating_add(at as u16);
                if !work.pixels(addr, job, y, col, &rgb[..3 * n], done && last) {
                    return false;
                }
                at += n;
                n = 0;
            }
        }
    }
    true
}

/// [`RootState`]'s work for the line: its backup jobs, the scenes, the pixel sink. Borrows
/// the root only inside each call, so bus tasks sharing it run between the line's turns.
pub struct RootWork<'a, S: ?Sized, P> {
    pub root: &'a RefCell<RootState>,
    pub scenes: &'a S,
    pub sink: &'a RefCell<P>,
}

/// The root's node of line address `addr`.
fn node_of(addr: u8) -> NodeId {
    NodeId::from(addr).saturating_sub(1)
}

impl<S: SceneSource + ?Sized, P: PixelSink> BackupWork for RootWork<'_, S, P> {
    fn assign(&mut self, addr: u8) -> Option<Job> {
        self.root.borrow_mut().backup_assign(node_of(addr))
    }

    fn missing_scene(&self, addr: u8) -> Option<u16> {
        let root = self.root.borrow();
        let frame = root.handing_out();
        (!root.has_scene(node_of(addr), frame)).then_some(frame)
    }

    fn scene(&self, frame: u16) -> Option<&[u8]> {
        self.scenes.scene(frame)
    }

    fn scene_ready(&mut self, addr: u8, frame: u16) {
        self.root
            .borrow_mut()
            .backup_scene_ready(node_of(addr), frame)
    }

    fn pixels(&mut self, addr: u8, job: u32, y: u16, x: u16, rgb: &[u8], done: bool) -> bool {
        let mut sink = self.sink.borrow_mut();
        self.root
            .borrow_mut()
            .backup_pixels(node_of(addr), job, y, x, rgb, done, &mut *sink)
    }

    fn lost(&mut self, addr: u8) {
        self.root.borrow_mut().backup_lost(node_of(addr));
    }
}

/// How the RC looks for and serves nodes over the line next to its SPI buses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ServeConfig {
    /// Nodes 0..`nodes` of the root (line addresses 1..=min(nodes, MAX_ADDR)).
    pub nodes: u16,
    /// Least time between two calls of a candidate ([`RootState::backup_candidate`]).
    pub call_gap_us: u64,
    /// How long the line rests when no served node has anything to do.
    pub idle_us: u64,
}

/// Serve the root's nodes that failed on SPI over the line until every frame is complete:
/// call the roll of each candidate in turn (one every `call_gap_us`); a node that answers
/// is served ([`RootState::serve_by_backup`]) by `rc`, one turn each, round-robin.
/// `rgb` is the pixel buffer of [`BackupRc::turn`].
pub async fn serve_root<L, C, S, P, const N: usize>(
    rc: &mut BackupRc<N>,
    line: &mut L,
    clock: &C,
    work: &mut RootWork<'_, S, P>,
    cfg: ServeConfig,
    rgb: &mut [u8],
) -> Result<(), L::Error>
where
    L: RcLine,
    C: RootClock,
    S: SceneSource + ?Sized,
    P: PixelSink,
{
    let on_line = cfg.nodes.min(MAX_ADDR as u16);
    let mut cursor: u16 = 0;
    let mut next_call = 0u64;
    while !work.root.borrow().finished() {
        let now = clock.now_us();
        if now >= next_call && on_line > 0 {
            next_call = now.saturating_add(cfg.call_gap_us);
            let found = (0..on_line).map(|i| (cursor + i) % on_line).find(|&n| {
                rc.slot(n as u8 + 1).is_none() && work.root.borrow().backup_candidate(n, now)
            });
            if let Some(n) = found {
                cursor = (n + 1) % on_line;
                call_candidate(rc, line, clock, work.root, n).await?;
            }
        }
        let mut busy = false;
        for k in 0..N {
            busy |= !matches!(rc.turn(k, line, work, rgb).await?, Turn::Nothing);
        }
        if !busy {
            let wake = clock.now_us().saturating_add(cfg.idle_us);
            clock.at_us(wake.min(next_call.max(now + 1))).await;
        }
    }
    Ok(())
}

/// Ask candidate `n` for its health; serve it if it answers and the root agrees.
async fn call_candidate<L: RcLine, C: RootClock, const N: usize>(
    rc: &mut BackupRc<N>,
    line: &mut L,
    clock: &C,
    root: &RefCell<RootState>,
    n: NodeId,
) -> Result<(), L::Error> {
    let addr = n as u8 + 1; // n < MAX_ADDR
    if ask_health(line, addr).await?.is_none() || rc.slot(addr).is_some() {
        return Ok(());
    }
    let free = rc.served.iter().any(Option::is_none);
    if free && root.borrow_mut().serve_by_backup(n, clock.now_us()) {
        rc.serve(addr);
    }
    Ok(())
}
