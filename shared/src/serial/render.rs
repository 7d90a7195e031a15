//! One render request from the PC: every frame a full `run_bus` over the bus (the nodes keep
//! the scene in their even bank: it is frame 0 to them), the accepted runs streamed to the PC
//! as they arrive, and the `Resend` answer (the RC renders the span itself: it keeps no frame
//! memory). Generic over the bus, clock and queue, so the host tests run exactly this.

use super::readback::{ByteQueue, Readback, RUN_RESERVE};
use super::throttle::{Room, Throttle};
use crate::backup::{serve_root, BackupRc, NoLine, RcLine, RootWork, ServeConfig};
use crate::image::SceneView;
use crate::link::RootBus;
use crate::render::{render_run, Rgb8, Tracer};
use crate::root::BACKUP_NODES;
use crate::root::{run_bus, RootClock, RootConfig, RootError, RootReport, RootState};
use crate::sched::Policy;
use crate::serial::{Encoder, FrameStreamer, RcError, SerialError, ToPc, MAX_RUN, MAX_TO_PC};
use core::cell::RefCell;
use core::future::poll_fn;
use core::pin::pin;
use core::task::Poll;
use embassy_futures::select::{select, Either};

/// Why a render request did not produce its frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RenderFail {
    /// The uploaded bytes are no usable SceneImage (or exceed the 1024 x 1024 frame); the PC
    /// was sent `Error { NoScene }`.
    BadScene,
    /// The root logic stopped with this error.
    Root(RootError),
    /// A frame ended without every pixel sent once (no `FrameEnd` went out).
    Incomplete(SerialError),
}

impl core::fmt::Display for RenderFail {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            RenderFail::BadScene => write!(f, "the uploaded scene is no usable SceneImage"),
            RenderFail::Root(e) => write!(f, "root logic: {e}"),
            RenderFail::Incomplete(e) => write!(f, "frame incomplete: {e}"),
        }
    }
}

impl core::error::Error for RenderFail {}

/// The nodes a render runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NodeSet {
    pub count: u16,
    /// How long one holding work may stay silent before the root declares it dead (µs).
    pub timeout_us: u64,
    /// How the frame is divided among them.
    pub policy: Policy,
}

impl NodeSet {
    /// `count` nodes of `board`, with its silence bound
    /// ([`BoardProfile::node_timeout_us`](crate::cluster::profile::BoardProfile::node_timeout_us)).
    pub const fn on(board: &crate::cluster::profile::BoardProfile, count: u16) -> Self {
        NodeSet {
            count,
            timeout_us: board.node_timeout_us,
            policy: Policy::DECREASING,
        }
    }

    /// The same nodes behind a tree of relays: their jobs divided by [`Policy::RELAYED`].
    pub const fn relayed(self) -> Self {
        NodeSet {
            policy: Policy::RELAYED,
            ..self
        }
    }
}

/// Queue `bytes` once there is room.
async fn send<R: Room, Q: ByteQueue>(room: &R, queue: &mut Q, bytes: &[u8]) -> bool {
    room.wait_room(bytes.len()).await;
    queue.push(bytes)
}

/// The frame size of `image` for the readback, or (after telling the PC `NoScene`) why not.
async fn frame_dims<R: Room, Q: ByteQueue>(
    image: &[u8],
    enc: &mut Encoder,
    room: &R,
    queue: &mut Q,
) -> Result<(u16, u16), RenderFail> {
    let dims = SceneView::new(image).ok().and_then(|v| {
        let f = v.camera::<f32>();
        let w = u16::try_from(f.width).ok()?;
        let h = u16::try_from(f.height).ok()?;
        FrameStreamer::new(0, w, h).ok().map(|_| (w, h))
    });
    if let Some(d) = dims {
        return Ok(d);
    }
    let mut out = [0u8; MAX_TO_PC];
    let code = RcError::NoScene;
    if let Ok(n) = enc.encode(&ToPc::Error { code }, &mut out) {
        send(room, queue, &out[..n]).await;
    }
    Err(RenderFail::BadScene)
}

/// Render `frames` frames of `image` on the `nodes` nodes of `bus` and stream them to
/// `queue` (frames numbered 0.. for the PC). `last` keeps the last frame's streamer for a
/// later `Resend`. Returns the last frame's root report.
#[allow(clippy::too_many_arguments)]
pub async fn render_frames<B: RootBus, C: RootClock, R: Room, Q: ByteQueue>(
    bus: &mut B,
    clock: &C,
    room: &R,
    queue: &mut Q,
    image: &[u8],
    frames: u16,
    nodes: NodeSet,
    enc: &mut Encoder,
    last: &mut Option<FrameStreamer>,
) -> Result<RootReport, RenderFail> {
    let none: Option<(&mut NoLine, ServeConfig)> = None;
    render_frames_with_line(
        bus, clock, room, queue, image, frames, nodes, enc, last, none,
    )
    .await
}

/// Pixels the RC expands from one backup-line chunk at a time (a chunk goes in parts).
const LINE_RGB: usize = 3 * 32;

/// [`render_frames`] with the serial backup line beside the bus: each frame, nodes the root
/// declares dead on SPI that answer on the line are served there
/// ([`crate::backup::serve_root`], at most [`BACKUP_NODES`]). A line error ends the line's
/// service for that frame (the bus goes on); the line stops when the bus does.
#[allow(clippy::too_many_arguments)]
pub async fn render_frames_with_line<B, C, R, Q, L>(
    bus: &mut B,
    clock: &C,
    room: &R,
    queue: &mut Q,
    image: &[u8],
    frames: u16,
    nodes: NodeSet,
    enc: &mut Encoder,
    last: &mut Option<FrameStreamer>,
    mut line: Option<(&mut L, ServeConfig)>,
) -> Result<RootReport, RenderFail>
where
    B: RootBus,
    C: RootClock,
    R: Room,
    Q: ByteQueue,
    L: RcLine,
{
    let dims = frame_dims(image, enc, room, queue).await?;
    let mut report = RootReport::default();
    for frame in 0..frames.max(1) {
        let mut out = Out { room, queue, enc };
        let line = line.as_mut().map(|(l, cfg)| (&mut **l, *cfg));
        report = render_one(bus, clock, &mut out, image, dims, frame, nodes, last, line).await?;
    }
    Ok(report)
}

/// Render film frame `frame` from `image` (its own scene) and stream it to `queue` tagged
/// with its number; `last` keeps its streamer for a `Resend`.
#[allow(clippy::too_many_arguments)]
pub async fn render_film_frame<B: RootBus, C: RootClock, R: Room, Q: ByteQueue>(
    bus: &mut B,
    clock: &C,
    room: &R,
    queue: &mut Q,
    image: &[u8],
    frame: u16,
    nodes: NodeSet,
    enc: &mut Encoder,
    last: &mut Option<FrameStreamer>,
) -> Result<RootReport, RenderFail> {
    let dims = frame_dims(image, enc, room, queue).await?;
    let mut out = Out { room, queue, enc };
    let none: Option<(&mut NoLine, ServeConfig)> = None;
    render_one(bus, clock, &mut out, image, dims, frame, nodes, last, none).await
}

/// Where a frame's messages go: the queue, the room it waits for, the numbering.
struct Out<'a, R, Q> {
    room: &'a R,
    queue: &'a mut Q,
    enc: &'a mut Encoder,
}

/// One frame: a full `run_bus` of `image` as bus frame 0 (the nodes' even bank), its runs
/// streamed as serial frame `frame`.
#[allow(clippy::too_many_arguments)]
async fn render_one<B: RootBus, C: RootClock, R: Room, Q: ByteQueue, L: RcLine>(
    bus: &mut B,
    clock: &C,
    out: &mut Out<'_, R, Q>,
    image: &[u8],
    (w, h): (u16, u16),
    frame: u16,
    nodes: NodeSet,
    last: &mut Option<FrameStreamer>,
    line: Option<(&mut L, ServeConfig)>,
) -> Result<RootReport, RenderFail> {
    let cfg = RootConfig {
        policy: nodes.policy,
        nodes: nodes.count,
        frames: 1,
        timeout_us: nodes.timeout_us,
        double_buffer: true,
    };
    let scenes = [image];
    let root = RefCell::new(RootState::new(cfg, &scenes[..]).map_err(RenderFail::Root)?);
    // Room for the frame header first (the sink itself never waits).
    out.room.wait_room(MAX_TO_PC).await;
    let mut rb = Readback::new(&mut *out.queue, core::mem::take(out.enc), frame, w, h)
        .map_err(RenderFail::Incomplete)?;
    rb.bus_frame = 0;
    let sink = RefCell::new(rb);
    let mut throttled = Throttle {
        bus: &mut *bus,
        room: out.room,
        need: RUN_RESERVE,
    };
    let r = {
        // Pinned where it is made: moving the bus's future (its RX buffer) into another
        // slot (a parameter, a local) would double it in this future.
        let bus_run = pin!(run_bus(0, &mut throttled, clock, &root, &scenes[..], &sink));
        let mut work = RootWork {
            root: &root,
            scenes: &scenes[..],
            sink: &sink,
        };
        bus_and_line(bus_run, line, clock, &mut work).await
    };
    let ended = sink.into_inner().end();
    *out.enc = ended.enc;
    *last = Some(ended.streamer);
    let report = r.map_err(RenderFail::Root)?;
    ended.result.map_err(RenderFail::Incomplete)?;
    Ok(report)
}

/// Run the bus's future and, if there is a line, serve it beside the bus until the bus is
/// done (the frame complete, or the bus failed): the bus's result.
async fn bus_and_line<F, L, C, S, P>(
    mut bus_run: core::pin::Pin<&mut F>,
    line: Option<(&mut L, ServeConfig)>,
    clock: &C,
    work: &mut RootWork<'_, S, P>,
) -> F::Output
where
    F: core::future::Future,
    L: RcLine,
    C: RootClock,
    S: crate::root::SceneSource + ?Sized,
    P: crate::root::PixelSink,
{
    let Some((line, cfg)) = line else {
        return bus_run.await;
    };
    let mut rc = BackupRc::<BACKUP_NODES>::new();
    let mut rgb = [0u8; LINE_RGB];
    let served = serve_root(&mut rc, line, clock, work, cfg, &mut rgb);
    let out = match select(bus_run.as_mut(), pin!(served)).await {
        Either::First(r) => r,
        Either::Second(_) => bus_run.await,
    };
    out
}

/// Queue space an upload reply may take while a frame renders: the reply only goes out
/// when, after it, the two exchanges' worth the throttle reserves ([`RUN_RESERVE`] each)
/// are still free, so a reply never costs a pixel run its room.
pub const fn reply_room(reply: usize) -> usize {
    2 * RUN_RESERVE + reply
}

/// Answer a `Resend { start, len }` of the frame `fs` streamed: render the span again from
/// the scene (the same tracer the nodes run, so the same pixels), yielding between runs, then
/// send the `FrameEnd` again.
pub async fn resend_span<R: Room, Q: ByteQueue>(
    fs: &FrameStreamer,
    image: &[u8],
    start: u32,
    len: u32,
    enc: &mut Encoder,
    room: &R,
    queue: &mut Q,
) -> Result<(), RenderFail> {
    let view = SceneView::new(image).map_err(|_| RenderFail::BadScene)?;
    let render = |y: u16, x: u16, px: &mut [Rgb8]| {
        let mut tracer = Tracer::<f32>::new(view);
        render_run(&mut tracer, y as u32, x as u32, px).map_err(|_| RenderFail::BadScene)
    };
    resend_runs(fs, start, len, enc, room, queue, render).await
}

/// [`resend_span`] with the pixels from `pixels(y, x, run)` (which fills `run`): each run of
/// the span sent again, yielding between runs, then the `FrameEnd` again.
pub async fn resend_runs<R: Room, Q: ByteQueue, F>(
    fs: &FrameStreamer,
    start: u32,
    len: u32,
    enc: &mut Encoder,
    room: &R,
    queue: &mut Q,
    mut pixels: F,
) -> Result<(), RenderFail>
where
    F: FnMut(u16, u16, &mut [Rgb8]) -> Result<(), RenderFail>,
{
    let mut out = [0u8; MAX_TO_PC];
    let mut pix: [Rgb8; MAX_RUN] = [[0; 3]; MAX_RUN];
    for (y, x, n) in fs.span_runs(start, len) {
        let px = &mut pix[..n as usize];
        pixels(y, x, px)?;
        let m = fs
            .resend(y, x, px.as_flattened(), enc, &mut out)
            .map_err(RenderFail::Incomplete)?;
        send(room, queue, &out[..m]).await;
        yield_once().await;
    }
    let m = fs.end(enc, &mut out).map_err(RenderFail::Incomplete)?;
    send(room, queue, &out[..m]).await;
    Ok(())
}

/// Let the other tasks (USB) run between two runs of a resend.
async fn yield_once() {
    let mut yielded = false;
    poll_fn(|cx| {
        if yielded {
            Poll::Ready(())
        } else {
            yielded = true;
            cx.waker().wake_by_ref();
            Poll::Pending
        }
    })
    .await
}
