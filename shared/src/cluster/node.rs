//! The node computer (NC): receive the scene, take jobs, render, return pixel runs.
//!
//! [`run_node`] is the whole behaviour of an NC, generic over the link ([`NodeLink`]), a
//! [`WorkClock`] (on hardware time passes by itself; in the simulator it advances virtual
//! time by the cost model) and a [`RunRenderer`] (the tracer; the simulator may substitute a
//! memo of identical results). No heap: the scene banks are borrowed from the caller, every
//! other buffer is a fixed array inside the future.
//!
//! Loop: post a frame (a pixel run, a scene status, or a poll for acknowledgements), render
//! the next run while that frame waits for and crosses the bus (DMA double buffer), then take
//! what arrives (broadcast scene chunks, the RC's reply to the exchange) until the exchange
//! is done. Frames stay in one of two banks until the RC acknowledges them; a gap in the
//! RC's acknowledgements makes the node send them again (go-back-N). Nothing read from the
//! bus can make it panic: bad frames are counted and otherwise ignored.

use super::landing::{scene_range, Landed, LentBank, NoLanding, SceneKey, SceneLanding};
use super::link::{Incoming, LinkError, NodeLink};
use super::wire::{
    self, Down, Job, PixelCoding, SceneState, Up, JOB_QUEUE, MAX_CHUNKS, MAX_MESSAGE, MAX_RUN,
    MAX_SCENE, PIECES_PER_CHUNK, SCENE_CHUNK, SCENE_PIECE,
};
use crate::image::SceneView;
use crate::num::Storage;
use crate::render::{RenderError, Rgb8, Stats};
use core::fmt;

mod bank;
mod kernel;
use bank::Bank;
pub use kernel::{KernelNumber, Kernels, Tracing, TracingByImage};

/// Where compute time goes.
#[allow(async_fn_in_trait)]
pub trait WorkClock {
    /// The node just did the work counted in `stats` (a delta).
    async fn worked(&mut self, stats: &Stats);

    /// The node just checked a complete scene: its CRC-32 and the full validation
    /// ([`SceneView::new`]), once per bank that becomes ready. `scene` is that scene.
    async fn checked_scene(&mut self, _scene: &SceneView<'_>) {}
}

/// Renders one scanline run of the scene held in a bank.
pub trait RunRenderer {
    /// Render `out.len()` pixels of scanline `y` from column `x` of frame `frame`'s scene;
    /// returns the operations counted.
    fn render(
        &mut self,
        scene: SceneView<'_>,
        frame: u16,
        y: u32,
        x: u32,
        out: &mut [Rgb8],
    ) -> Result<Stats, RenderError>;

    /// The kernels this renderer carries: `run_node` renders a scene only if one of them
    /// reads its storage ([`SceneView::storage`]).
    fn kernels(&self) -> Kernels;

    /// The bytes of a scene it rendered may have changed under the same bank and frame (the
    /// backup line reuses a bank): drop anything kept from run to run. Default: nothing kept.
    fn forget(&mut self) {}
}

/// A clock for hardware: time passes by itself.
#[derive(Clone, Copy, Debug, Default)]
pub struct RealTime;

impl WorkClock for RealTime {
    async fn worked(&mut self, _stats: &Stats) {}
}

/// Node options.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NodeConfig {
    /// How pixel runs may be coded: each run goes as the shortest of raw and these
    /// ([`Up::PixelsRle`], [`Up::PixelsDelta`]).
    pub coding: PixelCoding,
}

impl Default for NodeConfig {
    /// Delta coding (which also tries RLE): the fewest bytes up the tree, where the root's
    /// link is the bound of a 256-node frame (docs/cluster.md, "Delta-coded pixel runs").
    fn default() -> Self {
        Self {
            coding: PixelCoding::Delta,
        }
    }
}

/// Why a node stopped other than by the RC's `Stop`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NodeError {
    Link(LinkError),
    /// A scene bank is smaller than a frame needs or the banks differ in size.
    BankTooSmall {
        len: u32,
    },
    /// A scene arrived stored as `image`, which none of the node's kernels reads (a node
    /// built with one kernel, sent an image of the other storage).
    NoKernel {
        image: Storage,
        kernels: Kernels,
    },
    /// The scene bank lent to the link did not come back (a link that breaks
    /// [`SceneLanding`]'s contract).
    BankLost,
}

impl fmt::Display for NodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NodeError::Link(e) => write!(f, "link: {e}"),
            NodeError::BankTooSmall { len } => write!(f, "scene bank of {len} bytes is too small"),
            NodeError::NoKernel { image, kernels } => write!(
                f,
                "a {} scene arrived but this node carries {kernels} only",
                image.name()
            ),
            NodeError::BankLost => write!(f, "the scene bank lent to the link did not come back"),
        }
    }
}

impl core::error::Error for NodeError {}

impl From<LinkError> for NodeError {
    fn from(e: LinkError) -> Self {
        NodeError::Link(e)
    }
}

/// What a node did (for diagnostics and tests).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NodeReport {
    pub jobs: u32,
    pub pixels: u64,
    /// Frames posted, of which re-sent after a missing acknowledgement, and polls.
    pub messages_posted: u32,
    pub messages_resent: u32,
    pub polls: u32,
    /// Frames from the RC that failed their CRC or were malformed.
    pub bad_messages: u32,
    /// Jobs dropped because their region or scene was unusable.
    pub bad_jobs: u32,
    /// Scene chunks written.
    pub chunks: u32,
    /// Full scene validations ([`SceneView::new`], one per bank completed) and cheap
    /// re-opens of a validated bank ([`SceneView::open_validated`], per run and `Work` reply).
    pub validations: u32,
    pub opens: u32,
    pub stats: Stats,
}

#[cfg(feature = "defmt")]
impl defmt::Format for NodeReport {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "jobs={} pixels={} posted={} resent={} polls={} bad={} bad_jobs={} chunks={} validations={} opens={}",
            self.jobs,
            self.pixels,
            self.messages_posted,
            self.messages_resent,
            self.polls,
            self.bad_messages,
            self.bad_jobs,
            self.chunks,
            self.validations,
            self.opens
        )
    }
}

/// The shortest pixel run a node sends when its frames keep getting lost (see
/// `Nc::run_cap`).
pub const MIN_RUN: usize = 16;

/// A frame kept until acknowledged.
struct Slot {
    seq: u16,
    len: usize,
    /// Exchange number it was last sent in.
    sent_in: u32,
    buf: [u8; MAX_MESSAGE],
}

/// The run rendered and waiting for a free bank.
#[derive(Clone, Copy)]
struct Built {
    job: u32,
    frame: u16,
    y: u16,
    x: u16,
    len: usize,
    done: bool,
}

/// Where the node is in its current job.
#[derive(Clone, Copy)]
struct Cursor {
    job: Job,
    piece: u32,
    offset: u32,
}

fn seq_le(a: u16, b: u16) -> bool {
    (b.wrapping_sub(a) as i16) >= 0
}

/// The node's state apart from the banks.
struct Nc {
    banks: [Bank; 2],
    queue: [Option<Job>; JOB_QUEUE],
    last_taken: Option<u32>,
    cursor: Option<Cursor>,
    built: Option<Built>,
    slots: [Option<Slot>; 2],
    /// Index of the next slot to (re)send; 2 = none.
    resend: usize,
    next_seq: u16,
    exchanges: u32,
    last_rc_seq: u16,
    /// Scene state to report (sequenced).
    status: Option<SceneState>,
    /// A bank whose state the RC must hear once `status` is free (what landed in a lent bank
    /// changed it while the other bank's state still waited to be sent).
    deferred: Option<usize>,
    /// The bank just checked (`check_scene`), whose time the clock has yet to hear of.
    checked: Option<usize>,
    /// The RC broadcast [`Down::Wake`] for this frame: answer if idle.
    wake: Option<u16>,
    /// The RC's half of the last exchange was unreadable: ask again (a `Poll`) even with
    /// nothing to send, or a lost job list would leave an idle node silent until the RC
    /// times it out.
    reask: bool,
    /// Longest pixel run to render next (pixels): halves (to [`MIN_RUN`]) whenever a frame
    /// has to be sent again, grows by an eighth with every frame acknowledged at the first
    /// try (to [`MAX_RUN`]), so on a noisy link frames shrink until most get through.
    run_cap: usize,
    stopped: bool,
    report: NodeReport,
}

impl Nc {
    /// A node that has received nothing yet, continuing `report`.
    fn new(report: NodeReport) -> Self {
        Nc {
            banks: [Bank::EMPTY, Bank::EMPTY],
            queue: [None; JOB_QUEUE],
            last_taken: None,
            cursor: None,
            built: None,
            slots: [None, None],
            resend: 2,
            next_seq: 0,
            exchanges: 0,
            last_rc_seq: 0,
            status: None,
            deferred: None,
            checked: None,
            wake: None,
            reask: false,
            run_cap: MAX_RUN,
            stopped: false,
            report,
        }
    }

    fn unacked(&self) -> usize {
        self.slots.iter().filter(|s| s.is_some()).count()
    }

    /// Encode a new sequenced frame into a free slot; returns the slot index.
    fn push_slot(
        &mut self,
        f: impl FnOnce(u16, &mut [u8]) -> Result<usize, wire::WireError>,
    ) -> Option<usize> {
        self.order_slots();
        let i = self.slots.iter().position(|s| s.is_none())?;
        let seq = self.next_seq;
        let mut slot = Slot {
            seq,
            len: 0,
            sent_in: self.exchanges,
            buf: [0; MAX_MESSAGE],
        };
        slot.len = f(seq, &mut slot.buf).ok()?;
        self.next_seq = self.next_seq.wrapping_add(1);
        self.slots[i] = Some(slot);
        Some(i)
    }

    fn order_slots(&mut self) {
        if let (Some(a), Some(b)) = (&self.slots[0], &self.slots[1]) {
            if !seq_le(a.seq, b.seq) {
                self.slots.swap(0, 1);
            }
        } else if self.slots[0].is_none() && self.slots[1].is_some() {
            self.slots.swap(0, 1);
        }
    }

    /// Apply the RC's acknowledgement after exchange `ex` (`ack` = None when its frame was
    /// unreadable): drop what it covers, go back to the first frame it should have covered.
    fn acknowledge(&mut self, ack: Option<u16>, ex: u32) {
        let mut acked = false;
        if let Some(a) = ack {
            for s in self.slots.iter_mut() {
                if s.as_ref().is_some_and(|s| seq_le(s.seq, a)) {
                    *s = None;
                    acked = true;
                }
            }
        }
        self.order_slots();
        // A frame sent before this exchange and still unacknowledged was lost (or its
        // acknowledgement was): send it and everything after it again, and render shorter
        // runs (a noisy link loses long frames first).
        if self.slots[0].as_ref().is_some_and(|s| s.sent_in < ex) {
            self.resend = 0;
            self.run_cap = (self.run_cap / 2).max(MIN_RUN);
        } else if acked {
            self.run_cap = (self.run_cap + self.run_cap / 8 + 1).min(MAX_RUN);
        }
    }

    fn take_jobs(&mut self, jobs: &[Option<Job>; JOB_QUEUE], dims: [Option<(u16, u32, u32)>; 2]) {
        let bank_dims = |frame: u16| match dims[(frame % 2) as usize] {
            Some((f, w, h)) if f == frame => Some((w, h)),
            _ => None,
        };
        for job in jobs.iter().flatten() {
            if self.last_taken.is_some_and(|l| job.id <= l) {
                continue;
            }
            let Some(free) = self.queue.iter().position(|q| q.is_none()) else {
                return;
            };
            let Some((w, h)) = bank_dims(job.frame) else {
                // Scene not ready for that frame: the RC will list the job again.
                return;
            };
            self.last_taken = Some(job.id);
            if !job.region.fits(w, h) {
                self.report.bad_jobs += 1;
                continue;
            }
            self.queue[free] = Some(*job);
        }
    }

    fn bank_state(&self, b: usize) -> SceneState {
        let bank = &self.banks[b];
        match bank.frame {
            None => SceneState::None,
            Some(frame) if bank.ready => SceneState::Ready { frame },
            Some(frame) => {
                let mut chunks = [0u32; MAX_CHUNKS / 32];
                for c in 0..bank.chunks() {
                    let (w, bit) = ((c / 32) as usize, 1u32 << (c % 32));
                    if bank.got[w] & bit == 0 {
                        chunks[w] |= bit;
                    }
                }
                let pieces = bank.first_missing().map_or(0, |c| bank.pieces_of(c));
                SceneState::Missing {
                    frame,
                    chunks,
                    pieces,
                }
            }
        }
    }
}

/// Write a scene chunk into its bank; update readiness. Returns whether the state changed in
/// a way the RC must hear (scene now ready, or still incomplete after the broadcast ended).
#[allow(clippy::too_many_arguments)]
fn scene_chunk(
    nc: &mut Nc,
    banks: &mut [&mut [u8]; 2],
    frame: u16,
    offset: u32,
    total: u32,
    crc: u32,
    data: &[u8],
    direct: bool,
) -> bool {
    let b = (frame % 2) as usize;
    let piece = SCENE_PIECE as u32;
    let Some(end) = scene_range(offset, data.len(), total, banks[b].len(), direct) else {
        nc.report.bad_messages += 1;
        return false;
    };
    nc.banks[b].expect(frame, total, crc);
    if nc.banks[b].ready {
        return false;
    }
    if !nc.banks[b].write(banks[b], offset as usize, data) {
        nc.report.bad_messages += 1;
        return false;
    }
    nc.banks[b].got_pieces(offset / piece, end.div_ceil(piece));
    nc.report.chunks += 1;
    // Broadcasts go in order: the last chunk ends it even if its SceneEnd is lost. A chunk
    // sent point-to-point (a repair) means the broadcast is over, whether or not we heard it.
    if end == total || direct {
        nc.banks[b].ended = true;
    }
    check_scene(nc, banks, b);
    nc.banks[b].ready || nc.banks[b].ended
}

/// A complete bank whose CRC-32 and full validation pass becomes ready and validated (and
/// `nc.checked` names it, so the loop charges the check's time); a complete bank that fails
/// is taken again.
fn check_scene(nc: &mut Nc, banks: &[&mut [u8]; 2], b: usize) {
    let bank = &mut nc.banks[b];
    if bank.first_missing().is_some() {
        return;
    }
    let Some(bytes) = banks[b].get(..bank.total as usize) else {
        return;
    };
    let ok = bank.crc == wire::CRC32.checksum(bytes) && {
        nc.report.validations += 1;
        SceneView::new(bytes).is_ok()
    };
    if ok {
        bank.ready = true;
        bank.validated = true;
        nc.checked = Some(b);
    } else {
        // Complete but wrong: take it all again.
        bank.got = [0; MAX_CHUNKS / 32];
        bank.pieces = [0; MAX_SCENE / SCENE_PIECE / 32];
    }
}

/// Run a node until the RC sends `Stop`. `banks` are the two scene banks (each at least as
/// large as any scene the RC sends; frame `f` lands in bank `f % 2`). `report` is kept up to
/// date as the node works (readable once the future is dropped, even if it never ends).
pub async fn run_node<L: NodeLink, C: WorkClock, R: RunRenderer>(
    cfg: NodeConfig,
    link: &mut L,
    clock: &mut C,
    renderer: &mut R,
    mut banks: [&mut [u8]; 2],
    report: &mut NodeReport,
) -> Result<(), NodeError> {
    let parts = (link, &NoLanding, clock, renderer);
    run_node_landing(cfg, parts, &mut banks, report).await
}

/// [`run_node`] on a link that takes a scene bank while the node renders from the other
/// ([`SceneLanding`]: broadcast chunks land in it without waiting for the node logic).
/// While a run renders, the bank it does not use is lent; it comes back (with what landed,
/// booked as if the node logic had written it) before anything else touches it. If this
/// future is dropped while a bank is lent, [`restore_lent`] puts it back into `banks`.
pub async fn run_node_landing<'b, L, S, C, R>(
    cfg: NodeConfig,
    (link, landing, clock, renderer): (&mut L, &S, &mut C, &mut R),
    banks: &mut [&'b mut [u8]; 2],
    report: &mut NodeReport,
) -> Result<(), NodeError>
where
    L: NodeLink,
    S: SceneLanding<'b>,
    C: WorkClock,
    R: RunRenderer,
{
    let mut nc = Nc::new(*report);
    let mut pix: [Rgb8; MAX_RUN] = [[0; 3]; MAX_RUN];
    let mut rx = [0u8; MAX_MESSAGE];
    let mut coded = [0u8; 3 * MAX_RUN];
    let mut poll = [0u8; 16];
    while !nc.stopped {
        // 0. A roll call: an idle node with a free slot answers. Without the scene of the
        // frame the RC hands out (it missed its broadcast) it says what it lacks (the RC
        // then sends it point-to-point), else it polls to be handed work.
        let mut woken = false;
        if let Some(frame) = nc.wake.take() {
            if nc.cursor.is_none() && nc.queue.iter().any(|q| q.is_none()) {
                let b = (frame % 2) as usize;
                let bank = &nc.banks[b];
                if bank.ready && bank.frame == Some(frame) {
                    woken = true;
                } else if nc.status.is_none() {
                    nc.status = Some(match nc.bank_state(b) {
                        s @ SceneState::Missing { frame: f, .. } if f == frame => s,
                        // Nothing of it: all of it (the RC sends only the chunks it has).
                        _ => SceneState::Missing {
                            frame,
                            chunks: [u32::MAX; MAX_CHUNKS / 32],
                            pieces: 0,
                        },
                    });
                }
            }
        }
        // 1. Choose what to post.
        if nc.status.is_none() {
            nc.status = nc.deferred.take().map(|b| nc.bank_state(b));
        }
        let mut posted = false;
        if nc.resend < 2 {
            if let Some(s) = &mut nc.slots[nc.resend] {
                s.sent_in = nc.exchanges;
                link.post(&s.buf[..s.len])?;
                nc.report.messages_resent += 1;
                posted = true;
            }
            nc.resend += 1;
        }
        if !posted && nc.unacked() < 2 {
            let ack = nc.last_rc_seq;
            let slot = if let Some(scene) = nc.status.take() {
                nc.push_slot(|seq, buf| wire::encode(seq, ack, &Up::Status { scene }, buf))
            } else if let Some(b) = nc.built.take() {
                let rgb = pix[..b.len].as_flattened();
                let coding = wire::code_pixels(cfg.coding, rgb, &mut coded);
                let run = wire::PixelRun {
                    job: b.job,
                    frame: b.frame,
                    y: b.y,
                    x: b.x,
                    rgb,
                    done: b.done,
                };
                let up = coding.message(run, &coded);
                nc.push_slot(|seq, buf| wire::encode(seq, ack, &up, buf))
            } else {
                None
            };
            if let Some(s) = slot.and_then(|i| nc.slots[i].as_ref()) {
                link.post(&s.buf[..s.len])?;
                posted = true;
                // A new frame goes after any still to be re-sent.
                nc.resend = 2;
            }
        }
        if posted {
            nc.report.messages_posted += 1;
        } else if nc.unacked() > 0 || woken || nc.reask {
            let n = wire::encode(nc.next_seq, nc.last_rc_seq, &Up::Poll, &mut poll).unwrap_or(0);
            link.post(&poll[..n])?;
            nc.report.polls += 1;
            nc.reask = false;
            posted = true;
        }

        // 2. While that frame waits for the bus, render the next run (the other scene bank
        // lent to the link meanwhile).
        let rendered = if nc.built.is_none() {
            let lent = lend_other(&nc, landing, banks);
            let rendered = render_next(&mut nc, banks, renderer, &mut pix, clock).await;
            if lent {
                let back = landing.reclaim().ok_or(NodeError::BankLost)?;
                book_landed(&mut nc, banks, back);
                settle_check(&mut nc, (landing, clock, renderer), banks, report).await?;
            }
            rendered
        } else {
            false
        };
        if !posted && rendered {
            continue;
        }
        // Otherwise wait for our exchange (or, with nothing posted and nothing to render, for
        // a broadcast).

        // 3. Take what arrives until our exchange is done.
        loop {
            let got = link.recv(&mut rx).await?;
            let (len, exchanged) = match got {
                Incoming::Exchanged { len } => (len, true),
                Incoming::Broadcast { len } => (len, false),
            };
            let frame = rx.get(..len).map(wire::decode::<Down>);
            let mut ack = None;
            match frame {
                Some(Ok(env)) => {
                    if exchanged {
                        ack = Some(env.ack);
                        nc.last_rc_seq = env.seq;
                    }
                    handle_down(&mut nc, banks, env.msg, exchanged);
                }
                _ => nc.report.bad_messages += 1,
            }
            settle_check(&mut nc, (landing, clock, renderer), banks, report).await?;
            *report = nc.report;
            if exchanged {
                nc.reask = ack.is_none();
                nc.acknowledge(ack, nc.exchanges);
                nc.exchanges = nc.exchanges.wrapping_add(1);
                // A scene still incomplete after its broadcast: keep telling the RC what is
                // missing (each report fetches a chunk; a lost repair is asked for again).
                if nc.status.is_none() {
                    if let Some(b) = (0..2).find(|&b| nc.banks[b].ended && !nc.banks[b].ready) {
                        nc.status = Some(nc.bank_state(b));
                    }
                }
                break;
            }
            if nc.stopped || !posted {
                break;
            }
        }
    }
    *report = nc.report;
    Ok(())
}

/// A bank just checked (`nc.checked`): charge the check's time (the other bank lent to the
/// link meanwhile) and make sure a kernel of the node reads the scene's storage.
async fn settle_check<'b, S, C, R>(
    nc: &mut Nc,
    (landing, clock, renderer): (&S, &mut C, &mut R),
    banks: &mut [&'b mut [u8]; 2],
    report: &mut NodeReport,
) -> Result<(), NodeError>
where
    S: SceneLanding<'b>,
    C: WorkClock,
    R: RunRenderer,
{
    // Booking what landed meanwhile may complete the other bank: check it in turn.
    while let Some(b) = nc.checked.take() {
        let lent = lend(nc, landing, banks, 1 - b);
        let bank = &nc.banks[b];
        if let Some(view) = bank.frame.and_then(|f| bank.view(banks[b], f)) {
            clock.checked_scene(&view).await;
            let kernels = renderer.kernels();
            if !kernels.run(view.storage()) {
                *report = nc.report;
                let image = view.storage();
                return Err(NodeError::NoKernel { image, kernels });
            }
        }
        if lent {
            let back = landing.reclaim().ok_or(NodeError::BankLost)?;
            book_landed(nc, banks, back);
        }
    }
    Ok(())
}

/// Lend the scene bank the next run does not read to the link; whether it took it.
fn lend_other<'b, S: SceneLanding<'b>>(
    nc: &Nc,
    landing: &S,
    banks: &mut [&'b mut [u8]; 2],
) -> bool {
    let next = nc.cursor.map(|c| c.job).or(nc.queue[0]);
    match next {
        Some(job) => lend(nc, landing, banks, usize::from(job.frame % 2 == 0)),
        None => false,
    }
}

/// Lend scene bank `other` to the link; whether it took it.
fn lend<'b, S: SceneLanding<'b>>(
    nc: &Nc,
    landing: &S,
    banks: &mut [&'b mut [u8]; 2],
    other: usize,
) -> bool {
    let (Some(bank), Some(slot)) = (nc.banks.get(other), banks.get_mut(other)) else {
        return false;
    };
    let holds = match bank.frame {
        Some(frame) if bank.ready => Some(SceneKey {
            frame,
            total: bank.total,
            crc: bank.crc,
        }),
        _ => None,
    };
    let bytes = core::mem::take(slot);
    match landing.lend(LentBank::new(other, bytes, holds)) {
        Ok(()) => true,
        Err(back) => {
            *slot = back.bytes;
            false
        }
    }
}

/// Put a lent bank back and book what landed in it as [`scene_chunk`] books broadcast
/// chunks: the chunks' bits, the count, the end of the broadcast, the check once complete,
/// and the state for the RC if it is ready or still incomplete after the end.
fn book_landed<'b>(nc: &mut Nc, banks: &mut [&'b mut [u8]; 2], back: LentBank<'b>) {
    let LentBank {
        index,
        bytes,
        landed,
        ..
    } = back;
    let Some(slot) = banks.get_mut(index) else {
        return;
    };
    *slot = bytes;
    let Landed {
        key: Some(key),
        count,
        ended,
        ..
    } = landed
    else {
        return;
    };
    if count == 0 {
        return;
    }
    let bank = &mut nc.banks[index];
    bank.expect(key.frame, key.total, key.crc);
    if bank.ready {
        return;
    }
    // Its bytes were written: no longer the ones validated.
    bank.validated = false;
    let per = PIECES_PER_CHUNK as u32;
    let all = key.total.div_ceil(SCENE_PIECE as u32);
    for c in (0..bank.chunks()).filter(|&c| landed.has(c)) {
        bank.got_pieces(c * per, ((c + 1) * per).min(all));
    }
    bank.ended |= ended;
    nc.report.chunks += count;
    check_scene(nc, banks, index);
    if nc.banks[index].ready || nc.banks[index].ended {
        let frame = match nc.status {
            Some(SceneState::Ready { frame } | SceneState::Missing { frame, .. }) => Some(frame),
            _ => None,
        };
        // Never overwrite the other bank's state before the RC has heard it.
        match frame {
            Some(f) if usize::from(f % 2) != index => nc.deferred = Some(index),
            _ => nc.status = Some(nc.bank_state(index)),
        }
    }
}

/// After a [`run_node_landing`] future was dropped: take a bank it had lent back from the
/// link into its slot of `banks` (what landed in it is dropped with the node's state).
pub fn restore_lent<'b, S: SceneLanding<'b>>(landing: &S, banks: &mut [&'b mut [u8]; 2]) {
    if let Some(back) = landing.reclaim() {
        if let Some(slot) = banks.get_mut(back.index) {
            *slot = back.bytes;
        }
    }
}

/// Render the next run of the current (or next queued) job into `pix`, then account for its
/// compute time. Returns whether a run was rendered.
async fn render_next<C: WorkClock, R: RunRenderer>(
    nc: &mut Nc,
    banks: &[&mut [u8]; 2],
    renderer: &mut R,
    pix: &mut [Rgb8; MAX_RUN],
    clock: &mut C,
) -> bool {
    if nc.cursor.is_none() {
        let Some(job) = nc.queue[0].take() else {
            return false;
        };
        nc.queue.rotate_left(1);
        nc.cursor = Some(Cursor {
            job,
            piece: 0,
            offset: 0,
        });
    }
    let Some(mut cur) = nc.cursor else {
        return false;
    };
    let b = (cur.job.frame % 2) as usize;
    let view = nc.banks[b].view(banks[b], cur.job.frame);
    nc.report.opens += u32::from(view.is_some());
    let Some(view) = view else {
        nc.report.bad_jobs += 1;
        nc.cursor = None;
        return false;
    };
    let width = view.camera::<f32>().width;
    let Some((y, x0, plen)) = cur.job.region.piece(width, cur.piece) else {
        nc.report.bad_jobs += 1;
        nc.cursor = None;
        return false;
    };
    let x = x0 + cur.offset;
    let n = (plen - cur.offset).min(nc.run_cap.clamp(1, MAX_RUN) as u32) as usize;
    let (Ok(y16), Ok(x16)) = (u16::try_from(y), u16::try_from(x)) else {
        nc.report.bad_jobs += 1;
        nc.cursor = None;
        return false;
    };
    let stats = match renderer.render(view, cur.job.frame, y, x, &mut pix[..n]) {
        Ok(s) => s,
        Err(_) => {
            nc.report.bad_jobs += 1;
            nc.cursor = None;
            return false;
        }
    };
    cur.offset += n as u32;
    if cur.offset >= plen {
        cur.piece += 1;
        cur.offset = 0;
    }
    let done = cur.job.region.piece(width, cur.piece).is_none();
    nc.cursor = if done {
        nc.report.jobs += 1;
        None
    } else {
        Some(cur)
    };
    nc.built = Some(Built {
        job: cur.job.id,
        frame: cur.job.frame,
        y: y16,
        x: x16,
        len: n,
        done,
    });
    nc.report.pixels += n as u64;
    nc.report.stats.add(&stats);
    clock.worked(&stats).await;
    true
}

fn handle_down(nc: &mut Nc, banks: &mut [&mut [u8]; 2], msg: Down<'_>, exchanged: bool) {
    match msg {
        Down::Work { jobs } => {
            let mut dims = [None; 2];
            for (b, d) in dims.iter_mut().enumerate() {
                let bank = &nc.banks[b];
                if let Some(v) = bank.frame.and_then(|f| bank.view(banks[b], f)) {
                    nc.report.opens += 1;
                    let f = v.camera::<f32>();
                    *d = bank.frame.map(|frame| (frame, f.width, f.height));
                }
            }
            nc.take_jobs(&jobs, dims);
        }
        Down::Scene {
            frame,
            offset,
            total,
            crc,
            data,
        } => {
            if scene_chunk(nc, banks, frame, offset, total, crc, data, exchanged) {
                nc.status = Some(nc.bank_state((frame % 2) as usize));
            }
        }
        Down::SceneEnd { frame, len, crc } => {
            let b = (frame % 2) as usize;
            if len as usize > banks[b].len() || len as usize > wire::MAX_SCENE || len == 0 {
                nc.report.bad_messages += 1;
                return;
            }
            nc.banks[b].expect(frame, len, crc);
            if nc.banks[b].ready {
                return;
            }
            nc.banks[b].ended = true;
            check_scene(nc, banks, b);
            nc.status = Some(nc.bank_state(b));
        }
        Down::Stop => nc.stopped = true,
        Down::Wake { frame } => nc.wake = Some(frame),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequence_order_survives_wrap_around() {
        assert!(seq_le(5, 5) && seq_le(5, 6) && !seq_le(6, 5));
        assert!(seq_le(u16::MAX, 0) && seq_le(u16::MAX - 3, 2) && !seq_le(2, u16::MAX - 3));
    }

    #[test]
    fn bank_bitmap_tracks_missing_chunks() {
        let mut b = Bank::EMPTY;
        b.expect(3, 5 * SCENE_CHUNK as u32 + 1, 0);
        assert_eq!(b.chunks(), 6);
        assert_eq!(b.first_missing(), Some(0));
        b.got[0] = 0b11_1011;
        assert_eq!(b.first_missing(), Some(2));
        b.got[0] |= 0b100;
        assert_eq!(b.first_missing(), None);
        // The same scene again keeps what arrived; another one starts over.
        b.expect(3, 5 * SCENE_CHUNK as u32 + 1, 0);
        assert_eq!(b.first_missing(), None);
        b.expect(5, 5 * SCENE_CHUNK as u32 + 1, 0);
        assert_eq!(b.first_missing(), Some(0));
    }

    #[test]
    fn a_chunk_arrives_in_pieces_in_any_order() {
        let mut b = Bank::EMPTY;
        // Two chunks and one byte: the last chunk is one short piece.
        let total = 2 * SCENE_CHUNK as u32 + 1;
        b.expect(0, total, 0);
        let per = PIECES_PER_CHUNK as u32;
        // Chunk 1 in pieces, the second half first, the first twice over.
        b.got_pieces(per + per / 2, 2 * per);
        assert_eq!(b.first_missing(), Some(0));
        b.got_pieces(per, per + 1);
        assert_eq!(b.pieces_of(1), 0xff01);
        b.got_pieces(per, per + per / 2);
        assert_eq!(b.got[0], 0b010);
        b.got_pieces(0, per);
        assert_eq!(b.first_missing(), Some(2));
        b.got_pieces(2 * per, 2 * per + 1);
        assert_eq!(b.first_missing(), None);
    }

    use crate::testkit::scene::tiny_image;
    use core::future::Future;
    use core::task::{Context, Poll, Waker};

    /// Broadcast `image` as frame 0 in whole chunks into `nc`'s bank 0 (`mem`).
    fn broadcast(nc: &mut Nc, mem: &mut [&mut [u8]; 2], image: &[u8]) {
        let (total, crc) = (image.len() as u32, wire::CRC32.checksum(image));
        for (i, data) in image.chunks(SCENE_CHUNK).enumerate() {
            let offset = (i * SCENE_CHUNK) as u32;
            scene_chunk(nc, mem, 0, offset, total, crc, data, false);
        }
    }

    /// Counts the runs it is asked to render (all black).
    struct Count(u32);
    impl RunRenderer for Count {
        fn render(
            &mut self,
            _: SceneView<'_>,
            _: u16,
            _: u32,
            _: u32,
            _: &mut [Rgb8],
        ) -> Result<Stats, RenderError> {
            self.0 += 1;
            Ok(Stats::default())
        }

        fn kernels(&self) -> Kernels {
            Kernels::F32
        }
    }

    /// Try to render one run of an 8-pixel job on frame 0: (rendered, runs rendered).
    fn render_job(nc: &mut Nc, mem: &[&mut [u8]; 2]) -> (bool, u32) {
        nc.queue[0] = Some(Job {
            id: 1,
            frame: 0,
            region: wire::Region::Span { start: 0, len: 8 },
        });
        let (mut r, mut pix, mut clock) = (Count(0), [[0; 3]; MAX_RUN], RealTime);
        let rendered = {
            let mut fut = core::pin::pin!(render_next(nc, mem, &mut r, &mut pix, &mut clock));
            let mut cx = Context::from_waker(Waker::noop());
            let Poll::Ready(rendered) = fut.as_mut().poll(&mut cx) else {
                panic!("render_next waited on a clock that never waits");
            };
            rendered
        };
        (rendered, r.0)
    }

    #[test]
    fn a_bank_is_validated_once_and_any_write_clears_it() {
        let image = tiny_image(8, &[(1, 0)]);
        assert!(SceneView::new(&image).is_ok());
        let (mut a, mut b) = ([0u8; 2048], [0u8; 2048]);
        let mut mem = [&mut a[..], &mut b[..]];
        let mut nc = Nc::new(NodeReport::default());
        broadcast(&mut nc, &mut mem, &image);
        assert!(nc.banks[0].ready && nc.banks[0].validated);
        assert_eq!((nc.report.validations, nc.checked), (1, Some(0)));
        // Runs open the validated bank cheaply: no second validation.
        assert_eq!(render_job(&mut nc, &mem), (true, 1));
        assert_eq!(render_job(&mut nc, &mem), (true, 1));
        assert_eq!((nc.report.validations, nc.report.opens), (1, 2));
        // The same chunk again is ignored (the bank is ready): still validated.
        broadcast(&mut nc, &mut mem, &image);
        assert!(nc.banks[0].validated);
        // A byte written into the bank: no longer validated, never opened.
        assert!(nc.banks[0].write(mem[0], 0, &image[..4]));
        assert!(nc.banks[0].ready && !nc.banks[0].validated);
        assert!(nc.banks[0].view(mem[0], 0).is_none());
        assert_eq!(render_job(&mut nc, &mem), (false, 0));
        assert_eq!(nc.report.bad_jobs, 1);
        // Another scene for the frame resets the bank: not validated until it completes.
        nc.banks[0].validated = true;
        nc.banks[0].expect(0, image.len() as u32, 1);
        assert!(!nc.banks[0].validated && !nc.banks[0].ready);
    }

    /// A valid scene of several chunks: `tris` triangles, one leaf.
    fn big_image(tris: usize) -> std::vec::Vec<u8> {
        use crate::num::Storage;
        use crate::testkit::scene::SceneBuilder;
        let mut b = SceneBuilder::new(Storage::F32);
        b.camera(8, 8, [-1.0, 1.0, 0.1, 0.1], 0.0).grey_material();
        for i in 0..tris {
            let z = 1.0 + i as f32 * 1e-3;
            b.triangle([0.0, 0.0, z, 1.0, 0.0, z, 0.0, 1.0, z]);
        }
        b.node([-1.0; 3], [1.0; 3], 1, 0);
        b.finish()
    }

    /// Chunks that land in a lent bank and are booked when it comes back leave the bank as
    /// the node logic's own handling of the same broadcasts does: the same bytes, bitmap,
    /// readiness and end, whatever the order, repeats and interleaved scenes (random
    /// sequences of whole chunks of two scenes for the same bank, some chunks missing).
    #[test]
    fn landed_chunks_are_booked_as_the_node_logic_handles_them() {
        let scenes = [big_image(120), big_image(90)];
        assert!(scenes
            .iter()
            .all(|s| SceneView::new(s).is_ok() && s.len() > 2 * SCENE_CHUNK));
        let mut seed = 0x9e37_79b9u32;
        let mut next = |n: u32| {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed % n
        };
        for case in 0..300 {
            // Frames 1 and 3 both go to bank 1; the later scene of the sequence is the one
            // that must win in both paths.
            let len = 1 + next(24) as usize;
            let seq: std::vec::Vec<(usize, u16, usize)> = (0..len)
                .map(|_| {
                    let k = next(2) as usize;
                    let chunks = scenes[k].len().div_ceil(SCENE_CHUNK);
                    (k, 1 + 2 * k as u16, next(chunks as u32) as usize)
                })
                .collect();
            let chunk_of = |&(k, frame, c): &(usize, u16, usize)| {
                let img = &scenes[k];
                let end = ((c + 1) * SCENE_CHUNK).min(img.len());
                let (total, crc) = (img.len() as u32, wire::CRC32.checksum(img));
                (
                    frame,
                    (c * SCENE_CHUNK) as u32,
                    total,
                    crc,
                    &img[c * SCENE_CHUNK..end],
                )
            };
            // (a) The node logic handles each chunk as it arrives.
            let (mut a0, mut a1) = ([0u8; 8192], [0u8; 8192]);
            let mut mem_a = [&mut a0[..], &mut a1[..]];
            let mut nc_a = Nc::new(NodeReport::default());
            for m in &seq {
                let (frame, offset, total, crc, data) = chunk_of(m);
                scene_chunk(
                    &mut nc_a, &mut mem_a, frame, offset, total, crc, data, false,
                );
            }
            // (b) They land in bank 1 lent to the link, booked when it comes back.
            let (mut b0, mut b1) = ([0u8; 8192], [0u8; 8192]);
            let mut nc_b = Nc::new(NodeReport::default());
            let mut lent = LentBank::new(1, &mut b1[..], None);
            for m in &seq {
                let (frame, offset, total, crc, data) = chunk_of(m);
                let msg = Down::Scene {
                    frame,
                    offset,
                    total,
                    crc,
                    data,
                };
                assert_ne!(lent.land(&msg), crate::landing::Landing::NotMine);
            }
            let mut mem_b = [&mut b0[..], &mut []];
            book_landed(&mut nc_b, &mut mem_b, lent);
            let (x, y) = (&nc_a.banks[1], &nc_b.banks[1]);
            let last = seq.last().map(|m| m.0);
            // Both keep the last scene's chunks since the scene last changed (the node
            // logic restarts its bitmap then, the landed record too).
            assert_eq!(x.frame, y.frame, "case {case}: {seq:?}");
            assert_eq!((x.total, x.crc), (y.total, y.crc), "case {case}");
            assert_eq!(x.got, y.got, "case {case}: {seq:?}");
            assert_eq!(
                (x.ready, x.ended),
                (y.ready, y.ended),
                "case {case}: {seq:?}"
            );
            if x.ready {
                let n = x.total as usize;
                assert_eq!(mem_a[1][..n], mem_b[1][..n], "case {case}");
                assert_eq!(last.map(|k| &scenes[k][..]), Some(&mem_b[1][..n]));
                assert_eq!(nc_b.status, Some(nc_b.bank_state(1)), "case {case}");
            }
        }
    }

    #[test]
    fn a_corrupt_scene_with_a_good_crc_is_never_rendered() {
        // The leaf names triangle 5 of 1: the CRC matches, the validation fails.
        let image = tiny_image(8, &[(1, 5)]);
        assert!(SceneView::new(&image).is_err());
        let (mut a, mut b) = ([0u8; 2048], [0u8; 2048]);
        let mut mem = [&mut a[..], &mut b[..]];
        let mut nc = Nc::new(NodeReport::default());
        broadcast(&mut nc, &mut mem, &image);
        assert_eq!(nc.report.validations, 1);
        assert!(!nc.banks[0].ready && !nc.banks[0].validated);
        assert_eq!(nc.checked, None);
        // Taken again from scratch, and no run is rendered from it.
        assert_eq!(nc.banks[0].first_missing(), Some(0));
        assert_eq!(render_job(&mut nc, &mem), (false, 0));
        assert_eq!((nc.report.bad_jobs, nc.report.opens), (1, 0));
    }
}
