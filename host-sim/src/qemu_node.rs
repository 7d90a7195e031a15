//! The RC side of the QEMU node check (issue 6): the real root logic
//! (`links_core::root::run_bus`) drives one node computer in lock step, frame by frame, over
//! the IMSU link, and the frame it assembles is checked against the simulator's.
//!
//! The node is either the firmware's `run_node` on Cortex-M4F under QEMU ([`QemuNode`],
//! `tests/qemu-node`: records over two FIFOs that the firmware opens through semihosting) or
//! the same `run_node` compiled for the host ([`LocalNode`]). Both speak the same record
//! protocol (see `tests/qemu-node/src/main.rs`): the node reports each frame it posts (its
//! ready line goes up) and each time it waits for the link; the RC acts only while the node
//! waits. So the sequence of transfers depends on the two programs alone, not on host timing:
//! the QEMU node must send the very bytes the host node sends ([`compare_transcripts`]), and
//! the RC must assemble exactly the pixels of the simulator's single-node render
//! ([`check_outcome`]).

use crate::cluster::{render_cluster, SimConfig};
use links_core::link::{Incoming, LinkError, NodeId, NodeLink, RootBus, Transfer};
use links_core::node::{run_node, NodeConfig, NodeError, NodeReport, RealTime, Tracing};
use links_core::root::{run_bus, NoClock, PixelSink, RootConfig, RootReport, RootState};
use links_core::sched::Policy;
use links_core::wire::{self, Down, Up, MAX_MESSAGE, MAX_SCENE};
use std::cell::RefCell;
use std::collections::VecDeque;
use std::fmt;
use std::future::Future;
use std::io::{Read, Write};
use std::pin::Pin;
use std::rc::Rc;
use std::task::{Context, Poll, Waker};

/// Record kinds on the link (one byte, then a little-endian u32 length, then the bytes).
pub mod record {
    /// NC -> RC: a frame posted to the TX bank.
    pub const POST: u8 = b'P';
    /// NC -> RC: the node waits in `recv`.
    pub const WAIT: u8 = b'W';
    /// NC -> RC: the node loop returned; a text report follows.
    pub const END: u8 = b'E';
    /// RC -> NC: the RC's half of an exchange.
    pub const EXCHANGE: u8 = b'X';
    /// RC -> NC: a broadcast frame.
    pub const BROADCAST: u8 = b'B';
}

/// How the node ended: its report as `{:?}` text (compared between nodes) and, from the
/// firmware, the instruction counts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeEnd {
    /// `Ok(())` or the node's error, as `{:?}`.
    pub result: String,
    /// The node's [`NodeReport`] as `{:?}`.
    pub report: String,
    /// `key=value` pairs the firmware adds (instructions, link traffic).
    pub counters: Vec<(String, u64)>,
}

impl NodeEnd {
    pub fn counter(&self, key: &str) -> Option<u64> {
        self.counters
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| *v)
    }

    /// Parse the firmware's end record: a line of `key=value` counters, `result=...`,
    /// `report=...`.
    pub fn parse(text: &str) -> Result<NodeEnd, String> {
        let mut lines = text.lines();
        let mut counters = Vec::new();
        for kv in lines.next().unwrap_or("").split_whitespace() {
            let (k, v) = kv
                .split_once('=')
                .ok_or_else(|| format!("end record: `{kv}` is not key=value"))?;
            let v = v
                .parse()
                .map_err(|_| format!("end record: `{kv}` is not a number"))?;
            counters.push((k.to_string(), v));
        }
        let field = |line: Option<&str>, key: &str| {
            line.and_then(|l| l.strip_prefix(key))
                .map(str::to_string)
                .ok_or_else(|| format!("end record lacks `{key}`: {text:?}"))
        };
        let result = field(lines.next(), "result=")?;
        let report = field(lines.next(), "report=")?;
        Ok(NodeEnd {
            result,
            report,
            counters,
        })
    }
}

/// What a node did until it next waits for the link.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Settled {
    /// Waiting in `recv`, having posted these frames (at most one, the TX bank).
    Waiting { posted: Vec<Vec<u8>> },
    /// The node loop returned.
    Ended(NodeEnd),
}

/// One node computer as the lock-step RC sees it.
pub trait NodeSide {
    /// Let the node run until it waits for the link or ends.
    fn settle(&mut self) -> Result<Settled, String>;
    /// Hand the node a frame: the RC's half of an exchange, or a broadcast.
    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String>;
}

/// One transfer on the link, in order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Event {
    /// The node posted this frame.
    Up(Vec<u8>),
    /// The RC sent this frame (exchange reply or broadcast).
    Down { exchanged: bool, frame: Vec<u8> },
}

struct BusInner<N> {
    node: N,
    /// The node has run to its next wait since the last delivery.
    settled: bool,
    /// The node's TX bank (ready line up).
    tx: Option<Vec<u8>>,
    ended: Option<NodeEnd>,
    transcript: Vec<Event>,
    error: Option<String>,
}

impl<N: NodeSide> BusInner<N> {
    fn fail(&mut self, e: String) {
        if self.error.is_none() {
            self.error = Some(e);
        }
    }

    fn sync(&mut self) {
        if self.settled || self.error.is_some() || self.ended.is_some() {
            return;
        }
        self.settled = true;
        match self.node.settle() {
            Ok(Settled::Waiting { posted }) => {
                for p in posted {
                    if self.tx.is_some() {
                        self.fail("the node posted a second frame before the RC exchanged the first (its link must answer Busy)".into());
                        return;
                    }
                    self.transcript.push(Event::Up(p.clone()));
                    self.tx = Some(p);
                }
            }
            Ok(Settled::Ended(end)) => self.ended = Some(end),
            Err(e) => self.fail(e),
        }
    }

    fn send(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), LinkError> {
        self.sync();
        if self.error.is_some() {
            return Err(LinkError::Aborted);
        }
        if self.ended.is_some() {
            self.fail("the node loop ended while the RC was still sending".into());
            return Err(LinkError::Aborted);
        }
        if let Err(e) = self.node.deliver(exchanged, frame) {
            self.fail(e);
            return Err(LinkError::Aborted);
        }
        self.transcript.push(Event::Down {
            exchanged,
            frame: frame.to_vec(),
        });
        self.settled = false;
        Ok(())
    }
}

/// A one-node bus whose RC acts only while the node waits.
struct LockstepBus<N> {
    inner: RefCell<BusInner<N>>,
    /// The RC's two TX banks; `idle` is the one it composes into.
    banks: [Vec<u8>; 2],
    idle: usize,
    /// The node's frame of the transfer started and not yet finished (empty: a broadcast).
    inflight: Option<Vec<u8>>,
}

impl<N: NodeSide> RootBus for LockstepBus<N> {
    fn nodes(&self) -> (NodeId, u16) {
        (0, 1)
    }

    fn ready(&self) -> Option<NodeId> {
        let mut s = self.inner.borrow_mut();
        s.sync();
        s.tx.as_ref().map(|_| 0)
    }

    async fn wait_ready(&mut self) -> NodeId {
        if let Some(n) = self.ready() {
            return n;
        }
        // The node waits for a broadcast and the RC waits for the node: nothing can move.
        // (The driver sees the RC pending and reports this.)
        {
            let mut s = self.inner.borrow_mut();
            let e = if s.ended.is_some() {
                "the node loop ended before the RC finished the frame"
            } else {
                "deadlock: the node waits for a broadcast while the RC waits for the node's ready line"
            };
            s.fail(e.into());
        }
        core::future::pending().await
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        &mut self.banks[self.idle]
    }

    /// The node takes the frame at once and runs to its next wait (lock step), so the
    /// transfer is over when `start` returns; [`RootBus::finish`] only hands over the node's
    /// frame. Double buffering is then real on the RC's side (it composes into the other
    /// bank and decodes the previous frame after starting the next) and costs nothing.
    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        if self.inflight.is_some() {
            return Err(LinkError::Busy);
        }
        let bank = self.idle;
        let max = self.banks[bank].len() as u32;
        let down = self.banks[bank].get(..len).ok_or(LinkError::TooLong {
            len: len as u32,
            max,
        })?;
        let mut s = self.inner.borrow_mut();
        let up = match transfer {
            Transfer::Exchange(0) => {
                s.sync();
                let Some(up) = s.tx.take() else {
                    s.fail("the RC exchanged with a node whose ready line is down".into());
                    return Err(LinkError::Aborted);
                };
                s.send(true, down)?;
                up
            }
            Transfer::Exchange(node) => return Err(LinkError::NoSuchNode { node }),
            Transfer::Broadcast => {
                s.send(false, down)?;
                Vec::new()
            }
        };
        drop(s);
        // The DMA owns the bank just started; the RC composes into the other.
        self.idle ^= 1;
        self.inflight = Some(up);
        Ok(())
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        let up = self.inflight.take().ok_or(LinkError::Aborted)?;
        let max = rx.len() as u32;
        let dst = rx.get_mut(..up.len()).ok_or(LinkError::TooLong {
            len: up.len() as u32,
            max,
        })?;
        dst.copy_from_slice(&up);
        Ok(up.len())
    }
}

/// The RC's frame memory for this check: every pixel, and how often each was written.
struct FrameSink {
    width: usize,
    rgb: Vec<u8>,
    writes: Vec<u32>,
    /// Runs for another animation frame or outside the screen.
    stray: u32,
}

impl PixelSink for FrameSink {
    fn pixels(&mut self, frame: u16, y: u16, x: u16, rgb: &[u8]) {
        let at = y as usize * self.width + x as usize;
        let n = rgb.len() / 3;
        if frame != 0 || x as usize + n > self.width || at + n > self.writes.len() {
            self.stray += 1;
            return;
        }
        self.rgb[3 * at..3 * (at + n)].copy_from_slice(rgb);
        for w in &mut self.writes[at..at + n] {
            *w += 1;
        }
    }
}

/// What one lock-step run produced.
#[derive(Clone, Debug)]
pub struct RcOutcome {
    pub width: u32,
    pub height: u32,
    /// The frame the RC assembled (RGB8 rows).
    pub frame: Vec<u8>,
    /// How many times each pixel was written.
    pub writes: Vec<u32>,
    pub stray_runs: u32,
    pub root: RootReport,
    pub transcript: Vec<Event>,
    pub end: NodeEnd,
}

/// Run the real RC logic over one node until the frame is complete, the `Stop` is broadcast
/// and the node has ended.
pub fn run_rc<N: NodeSide>(image: &[u8], node: N) -> Result<RcOutcome, String> {
    run_rc_buffered(image, node, true)
}

/// [`run_rc`] with the RC's DMA double buffering on or off ([`RootConfig::double_buffer`]).
pub fn run_rc_buffered<N: NodeSide>(
    image: &[u8],
    node: N,
    double_buffer: bool,
) -> Result<RcOutcome, String> {
    let cfg = RootConfig {
        policy: Policy::DECREASING,
        nodes: 1,
        frames: 1,
        timeout_us: 0,
        double_buffer,
    };
    let scenes = [image];
    let root = RefCell::new(RootState::new(cfg, &scenes[..]).map_err(|e| e.to_string())?);
    let (width, height) = root.borrow().size();
    let n = (width * height) as usize;
    let sink = RefCell::new(FrameSink {
        width: width as usize,
        rgb: vec![0; 3 * n],
        writes: vec![0; n],
        stray: 0,
    });
    let mut bus = LockstepBus {
        inner: RefCell::new(BusInner {
            node,
            settled: false,
            tx: None,
            ended: None,
            transcript: Vec::new(),
            error: None,
        }),
        banks: [vec![0; MAX_MESSAGE], vec![0; MAX_MESSAGE]],
        idle: 0,
        inflight: None,
    };
    let result = {
        let fut = run_bus(0, &mut bus, &NoClock, &root, &scenes[..], &sink);
        let mut fut = std::pin::pin!(fut);
        // Every transfer completes at once (the node runs to its next wait inside it), so
        // the RC either finishes in one poll or can never move again.
        match fut.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
            Poll::Ready(r) => Some(r),
            Poll::Pending => None,
        }
    };
    let mut inner = bus.inner.into_inner();
    inner.sync();
    if let Some(e) = inner.error {
        return Err(e);
    }
    let root_report = match result {
        Some(Ok(r)) => r,
        Some(Err(e)) => return Err(format!("root: {e}")),
        None => return Err("the RC stalled".into()),
    };
    let Some(end) = inner.ended else {
        return Err(
            "the node did not end after the RC's Stop broadcast (it waits for more)".into(),
        );
    };
    let sink = sink.into_inner();
    Ok(RcOutcome {
        width,
        height,
        frame: sink.rgb,
        writes: sink.writes,
        stray_runs: sink.stray,
        root: root_report,
        transcript: inner.transcript,
        end,
    })
}

/// The simulator's single-node render of `image` (`render_cluster` with one node): the
/// frame the lock-step RC must assemble.
pub fn simulated_frame(image: &[u8]) -> Result<Vec<u8>, String> {
    let cfg = SimConfig {
        nodes: 1,
        buses: 1,
        ..SimConfig::default()
    };
    let mut r = render_cluster(image, &cfg).map_err(|e| e.to_string())?;
    r.report
        .frames
        .pop()
        .ok_or_else(|| "the simulator kept no frame".to_string())
}

/// Every check of one run against the expected frame; the first failure, or Ok.
/// `corrupted`: RC -> NC frames damaged on purpose ([`Corrupt`]): the node must count
/// exactly these as bad, and the RC may then see re-sent duplicates (a lost acknowledgement),
/// nothing else.
pub fn check_outcome(o: &RcOutcome, want: &[u8], corrupted: u32) -> Result<(), String> {
    let r = &o.root;
    let dup = if corrupted == 0 { r.out_of_order } else { 0 };
    if r.bad_frames > 0 || r.rejected > 0 || dup > 0 {
        return Err(format!(
            "the RC could not use every node frame: {} failed CRC/decoding, {} rejected, {} out of order",
            r.bad_frames, r.rejected, r.out_of_order
        ));
    }
    if o.end.result != "Ok(())" {
        return Err(format!("the node loop failed: {}", o.end.result));
    }
    for want in [format!("bad_frames: {corrupted},"), "bad_jobs: 0,".into()] {
        if !o.end.report.contains(&want) {
            return Err(format!(
                "the node's count of bad input is wrong (want {want}): {}",
                o.end.report
            ));
        }
    }
    if o.stray_runs > 0 {
        return Err(format!("{} pixel runs outside the frame", o.stray_runs));
    }
    if let Some(i) = o.writes.iter().position(|&w| w != 1) {
        return Err(format!(
            "pixel ({}, {}) was written {} times (every pixel exactly once)",
            i % o.width as usize,
            i / o.width as usize,
            o.writes[i]
        ));
    }
    if want.len() != o.frame.len() {
        return Err(format!(
            "the reference frame has {} bytes, the RC's {}",
            want.len(),
            o.frame.len()
        ));
    }
    let diff: Vec<usize> = (0..o.frame.len() / 3)
        .filter(|&p| o.frame[3 * p..3 * p + 3] != want[3 * p..3 * p + 3])
        .collect();
    if let Some(&p) = diff.first() {
        let w = o.width as usize;
        return Err(format!(
            "{} of {} pixels differ from the simulator's render; the first at ({}, {}): {:?}, want {:?}",
            diff.len(),
            o.frame.len() / 3,
            p % w,
            p / w,
            &o.frame[3 * p..3 * p + 3],
            &want[3 * p..3 * p + 3]
        ));
    }
    Ok(())
}

fn describe(e: &Event) -> String {
    match e {
        Event::Up(f) => match wire::decode::<Up>(f) {
            Ok(env) => {
                let msg = match env.msg {
                    Up::Pixels {
                        job, y, x, rgb, done, ..
                    } => format!("Pixels {{ job: {job}, y: {y}, x: {x}, {} pixels, done: {done} }}", rgb.len() / 3),
                    Up::PixelsRle {
                        job, y, x, len, data, done, ..
                    } => format!(
                        "PixelsRle {{ job: {job}, y: {y}, x: {x}, {len} pixels in {} bytes, done: {done} }}",
                        data.len()
                    ),
                    m => format!("{m:?}"),
                };
                format!(
                    "NC -> RC {} bytes, seq {} ack {}: {msg}",
                    f.len(),
                    env.seq,
                    env.ack
                )
            }
            Err(err) => format!("NC -> RC {} bytes: {err}", f.len()),
        },
        Event::Down { exchanged, frame } => {
            let how = if *exchanged { "exchange" } else { "broadcast" };
            match wire::decode::<Down>(frame) {
                Ok(env) => {
                    let msg = match env.msg {
                        Down::Scene {
                            frame: f,
                            offset,
                            total,
                            data,
                            ..
                        } => format!(
                            "Scene {{ frame: {f}, offset: {offset}, total: {total}, {} bytes }}",
                            data.len()
                        ),
                        m => format!("{m:?}"),
                    };
                    format!(
                        "RC -> NC {how} {} bytes, ack {}: {msg}",
                        frame.len(),
                        env.ack
                    )
                }
                Err(err) => format!("RC -> NC {how} {} bytes: {err}", frame.len()),
            }
        }
    }
}

/// The two runs' transfers must be the same bytes in the same order, and the nodes' reports
/// equal.
pub fn compare_transcripts(got: &RcOutcome, want: &RcOutcome) -> Result<(), String> {
    if let Some(i) = (0..got.transcript.len().max(want.transcript.len()))
        .find(|&i| got.transcript.get(i) != want.transcript.get(i))
    {
        let show = |e: Option<&Event>| e.map_or("nothing".to_string(), describe);
        return Err(format!(
            "transfer {i} of {} differs from the host node's:\n  got  {}\n  want {}",
            want.transcript.len(),
            show(got.transcript.get(i)),
            show(want.transcript.get(i))
        ));
    }
    if got.end.report != want.end.report {
        return Err(format!(
            "the node reports differ:\n  got  {}\n  want {}",
            got.end.report, want.end.report
        ));
    }
    Ok(())
}

/// A node whose link damages some of the RC's frames on the way in: one bit flipped in the
/// middle of deliveries number `at` (0-based, broadcasts and exchange replies counted
/// together), as a bus error would. The transcript keeps what the RC sent.
pub struct Corrupt<N> {
    pub inner: N,
    pub at: Vec<usize>,
    delivered: usize,
    /// What each damaged frame was, in order.
    pub hits: Vec<String>,
}

impl<N> Corrupt<N> {
    pub fn new(inner: N, at: Vec<usize>) -> Self {
        Self {
            inner,
            at,
            delivered: 0,
            hits: Vec::new(),
        }
    }
}

impl<N: NodeSide> NodeSide for Corrupt<N> {
    fn settle(&mut self) -> Result<Settled, String> {
        self.inner.settle()
    }

    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String> {
        let i = self.delivered;
        self.delivered += 1;
        if !self.at.contains(&i) || frame.is_empty() {
            return self.inner.deliver(exchanged, frame);
        }
        self.hits.push(format!(
            "delivery {i}: {}",
            describe(&Event::Down {
                exchanged,
                frame: frame.to_vec()
            })
        ));
        let mut bad = frame.to_vec();
        bad[frame.len() / 2] ^= 0x10;
        self.inner.deliver(exchanged, &bad)
    }
}

// --- the host's node ------------------------------------------------------------------------

#[derive(Default)]
struct LocalShared {
    inbox: VecDeque<(bool, Vec<u8>)>,
    posted: Vec<Vec<u8>>,
    tx_full: bool,
}

struct LocalLink(Rc<RefCell<LocalShared>>);

impl NodeLink for LocalLink {
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        let mut s = self.0.borrow_mut();
        if s.tx_full {
            return Err(LinkError::Busy);
        }
        s.tx_full = true;
        s.posted.push(frame.to_vec());
        Ok(())
    }

    async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
        let (exchanged, frame) =
            std::future::poll_fn(|_| match self.0.borrow_mut().inbox.pop_front() {
                Some(f) => Poll::Ready(f),
                None => Poll::Pending,
            })
            .await;
        let len = frame.len();
        let max = rx.len() as u32;
        rx.get_mut(..len)
            .ok_or(LinkError::TooLong {
                len: len as u32,
                max,
            })?
            .copy_from_slice(&frame);
        Ok(if exchanged {
            self.0.borrow_mut().tx_full = false;
            Incoming::Exchanged { len }
        } else {
            Incoming::Broadcast { len }
        })
    }
}

type NodeFuture = Pin<Box<dyn Future<Output = (Result<(), NodeError>, NodeReport)>>>;

/// `run_node` compiled for the host, with 128 KB banks as the firmware's.
pub struct LocalNode {
    shared: Rc<RefCell<LocalShared>>,
    fut: NodeFuture,
    end: Option<NodeEnd>,
}

impl Default for LocalNode {
    fn default() -> Self {
        Self::new()
    }
}

impl LocalNode {
    pub fn new() -> Self {
        let shared = Rc::new(RefCell::new(LocalShared::default()));
        let mut link = LocalLink(shared.clone());
        let fut: NodeFuture = Box::pin(async move {
            let mut b0 = vec![0u8; MAX_SCENE];
            let mut b1 = vec![0u8; MAX_SCENE];
            let mut report = NodeReport::default();
            let r = run_node(
                NodeConfig::default(),
                &mut link,
                &mut RealTime,
                &mut Tracing::<f32>::new(),
                [b0.as_mut_slice(), b1.as_mut_slice()],
                &mut report,
            )
            .await;
            (r, report)
        });
        Self {
            shared,
            fut,
            end: None,
        }
    }
}

impl NodeSide for LocalNode {
    fn settle(&mut self) -> Result<Settled, String> {
        if let Some(e) = &self.end {
            return Ok(Settled::Ended(e.clone()));
        }
        match self
            .fut
            .as_mut()
            .poll(&mut Context::from_waker(Waker::noop()))
        {
            Poll::Ready((r, report)) => {
                let end = NodeEnd {
                    result: format!("{r:?}"),
                    report: format!("{report:?}"),
                    counters: Vec::new(),
                };
                self.end = Some(end.clone());
                Ok(Settled::Ended(end))
            }
            Poll::Pending => Ok(Settled::Waiting {
                posted: std::mem::take(&mut self.shared.borrow_mut().posted),
            }),
        }
    }

    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String> {
        self.shared
            .borrow_mut()
            .inbox
            .push_back((exchanged, frame.to_vec()));
        Ok(())
    }
}

// --- the QEMU node --------------------------------------------------------------------------

/// The firmware's end of the link: records over a byte stream each way (the FIFOs the
/// firmware opens through semihosting).
pub struct StreamNode<R, W> {
    up: R,
    down: W,
    end: Option<NodeEnd>,
}

impl<R: Read, W: Write> StreamNode<R, W> {
    /// `up`: what the node writes (NC -> RC); `down`: what it reads.
    pub fn new(up: R, down: W) -> Self {
        Self {
            up,
            down,
            end: None,
        }
    }

    fn record(&mut self) -> Result<(u8, Vec<u8>), String> {
        let gone =
            |e: std::io::Error| format!("the node's link closed ({e}): QEMU exited or crashed");
        let mut head = [0u8; 5];
        self.up.read_exact(&mut head).map_err(gone)?;
        let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
        if len > MAX_SCENE {
            return Err(format!(
                "record of {len} bytes from the node: the link is out of step"
            ));
        }
        let mut body = vec![0u8; len];
        self.up.read_exact(&mut body).map_err(gone)?;
        Ok((head[0], body))
    }
}

/// The QEMU firmware's link (FIFO files).
pub type QemuNode = StreamNode<std::io::BufReader<std::fs::File>, std::fs::File>;

impl<R: Read, W: Write> NodeSide for StreamNode<R, W> {
    fn settle(&mut self) -> Result<Settled, String> {
        if let Some(e) = &self.end {
            return Ok(Settled::Ended(e.clone()));
        }
        let mut posted = Vec::new();
        loop {
            let (kind, body) = self.record()?;
            match kind {
                record::POST => posted.push(body),
                record::WAIT => return Ok(Settled::Waiting { posted }),
                record::END => {
                    if !posted.is_empty() {
                        return Err("the node ended with a frame just posted".into());
                    }
                    let text = String::from_utf8(body)
                        .map_err(|_| "the node's end record is not UTF-8".to_string())?;
                    let end = NodeEnd::parse(&text)?;
                    self.end = Some(end.clone());
                    return Ok(Settled::Ended(end));
                }
                k => return Err(format!("unknown record kind {k:#04x} from the node")),
            }
        }
    }

    fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String> {
        let kind = if exchanged {
            record::EXCHANGE
        } else {
            record::BROADCAST
        };
        let mut rec = Vec::with_capacity(5 + frame.len());
        rec.push(kind);
        rec.extend_from_slice(&(frame.len() as u32).to_le_bytes());
        rec.extend_from_slice(frame);
        self.down
            .write_all(&rec)
            .and_then(|_| self.down.flush())
            .map_err(|e| format!("cannot write to the node's link ({e}): QEMU exited or crashed"))
    }
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&describe(self))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use links_core::dm::{compile, CompileOptions};

    fn image(scene: &str, w: u32, h: u32) -> Vec<u8> {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes")
            .join(scene);
        let desc = crate::scene_file::load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
        let opts = CompileOptions {
            width: Some(w),
            height: Some(h),
            ..Default::default()
        };
        compile(&desc, &opts).expect("compiles").bytes
    }

    /// A node that changes what it posts: `f` may rewrite the `n`-th posted frame.
    struct Tamper<F> {
        inner: LocalNode,
        n: usize,
        seen: usize,
        f: F,
    }

    impl<F: FnMut(&mut Vec<u8>) -> bool> NodeSide for Tamper<F> {
        fn settle(&mut self) -> Result<Settled, String> {
            let mut s = self.inner.settle()?;
            if let Settled::Waiting { posted } = &mut s {
                for p in posted {
                    if self.seen >= self.n && (self.f)(p) {
                        self.n = usize::MAX;
                    }
                    self.seen += 1;
                }
            }
            Ok(s)
        }
        fn deliver(&mut self, exchanged: bool, frame: &[u8]) -> Result<(), String> {
            self.inner.deliver(exchanged, frame)
        }
    }

    #[test]
    fn lock_step_rc_and_host_node_give_the_simulators_frame() {
        let img = image("photo1.ron", 24, 20);
        let want = simulated_frame(&img).unwrap();
        let a = run_rc(&img, LocalNode::new()).unwrap();
        check_outcome(&a, &want, 0).unwrap();
        assert_eq!(a.root.pixels, 24 * 20);
        // The scene went out chunk by chunk, each once, and the last broadcast is the Stop.
        let bcasts: Vec<Down> = a
            .transcript
            .iter()
            .filter_map(|e| match e {
                Event::Down {
                    exchanged: false,
                    frame,
                } => Some(wire::decode::<Down>(frame).unwrap().msg),
                _ => None,
            })
            .collect();
        let chunks = bcasts
            .iter()
            .filter(|d| matches!(d, Down::Scene { .. }))
            .count();
        assert_eq!(chunks, img.len().div_ceil(wire::SCENE_CHUNK));
        assert_eq!(bcasts.last(), Some(&Down::Stop));
        // Deterministic: a second run transfers the same bytes.
        let b = run_rc(&img, LocalNode::new()).unwrap();
        compare_transcripts(&b, &a).unwrap();
    }

    #[test]
    fn lock_step_rc_single_and_double_buffered_assemble_the_same_frame() {
        let img = image("photo1.ron", 24, 20);
        let want = simulated_frame(&img).unwrap();
        let single = run_rc_buffered(&img, LocalNode::new(), false).unwrap();
        let double = run_rc_buffered(&img, LocalNode::new(), true).unwrap();
        check_outcome(&single, &want, 0).unwrap();
        check_outcome(&double, &want, 0).unwrap();
        assert_eq!(single.frame, double.frame);
        assert_eq!(single.root.pixels, double.root.pixels);
    }

    #[test]
    fn lock_step_bus_keeps_one_transfer_in_flight() {
        let mut bus = LockstepBus {
            inner: RefCell::new(BusInner {
                node: LocalNode::new(),
                settled: false,
                tx: None,
                ended: None,
                transcript: Vec::new(),
                error: None,
            }),
            banks: [vec![0; MAX_MESSAGE], vec![0; MAX_MESSAGE]],
            idle: 0,
            inflight: None,
        };
        let mut rx = [0u8; MAX_MESSAGE];
        fn poll<F: Future>(f: F) -> F::Output {
            let mut f = std::pin::pin!(f);
            match f.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
                Poll::Ready(r) => r,
                Poll::Pending => panic!("lock-step transfers never wait"),
            }
        }
        // Nothing in flight: finish fails instead of waiting forever.
        assert_eq!(poll(bus.finish(&mut rx)), Err(LinkError::Aborted));
        let n = wire::encode(0, 0, &Down::Stop, bus.tx_bank()).unwrap();
        let first = bus.idle;
        bus.start(Transfer::Broadcast, n).unwrap();
        assert_ne!(bus.idle, first, "the RC composes into the other bank");
        assert_eq!(bus.start(Transfer::Broadcast, n), Err(LinkError::Busy));
        assert_eq!(poll(bus.finish(&mut rx)), Ok(0));
        // Past the bank, and nodes not on the bus, are errors.
        assert!(matches!(
            bus.start(Transfer::Broadcast, MAX_MESSAGE + 1),
            Err(LinkError::TooLong { .. })
        ));
        assert_eq!(
            bus.start(Transfer::Exchange(1), n),
            Err(LinkError::NoSuchNode { node: 1 })
        );
    }

    /// Re-encode a pixel frame with one byte of its colours changed (a valid frame: only the
    /// pixel comparison can catch it).
    fn flip_pixel(f: &mut Vec<u8>) -> bool {
        let Ok(env) = wire::decode::<Up>(f) else {
            return false;
        };
        let mut data = match env.msg {
            Up::Pixels { rgb, .. } => rgb.to_vec(),
            Up::PixelsRle { data, .. } => data.to_vec(),
            _ => return false,
        };
        // The RLE's colour bytes are 1..4 of each quadruple; raw runs, every byte.
        data[1] ^= 1;
        let msg = match env.msg {
            Up::Pixels {
                job,
                frame,
                y,
                x,
                done,
                ..
            } => Up::Pixels {
                job,
                frame,
                y,
                x,
                rgb: &data,
                done,
            },
            Up::PixelsRle {
                job,
                frame,
                y,
                x,
                len,
                done,
                ..
            } => Up::PixelsRle {
                job,
                frame,
                y,
                x,
                len,
                data: &data,
                done,
            },
            _ => unreachable!(),
        };
        let mut buf = vec![0u8; wire::MAX_MESSAGE];
        let n = wire::encode(env.seq, env.ack, &msg, &mut buf).unwrap();
        buf.truncate(n);
        *f = buf;
        true
    }

    #[test]
    fn one_changed_pixel_byte_fails_the_check() {
        let img = image("photo1.ron", 24, 20);
        let want = simulated_frame(&img).unwrap();
        let good = run_rc(&img, LocalNode::new()).unwrap();
        let node = Tamper {
            inner: LocalNode::new(),
            n: 5,
            seen: 0,
            f: flip_pixel,
        };
        let bad = run_rc(&img, node).unwrap();
        let e = check_outcome(&bad, &want, 0).unwrap_err();
        assert!(e.contains("of 480 pixels differ"), "{e}");
        let e = compare_transcripts(&bad, &good).unwrap_err();
        assert!(e.contains("differs from the host node's"), "{e}");
        // And the RC's frame alone, one byte changed, fails too.
        let mut o = good.clone();
        o.frame[3 * 100 + 2] ^= 0x80;
        assert!(check_outcome(&o, &want, 0).is_err());
        check_outcome(&good, &want, 0).unwrap();
    }

    #[test]
    fn a_frame_failing_its_crc_fails_the_check() {
        let img = image("photo1.ron", 24, 20);
        let want = simulated_frame(&img).unwrap();
        let node = Tamper {
            inner: LocalNode::new(),
            n: 3,
            seen: 0,
            f: |f: &mut Vec<u8>| {
                let last = f.len() - 1;
                f[last] ^= 4;
                true
            },
        };
        // The node sends the frame again (go-back-N), so the frame completes, but the bad
        // frame is counted and the check fails.
        let o = run_rc(&img, node).unwrap();
        assert_eq!(o.root.bad_frames, 1);
        let e = check_outcome(&o, &want, 0).unwrap_err();
        assert!(e.contains("1 failed CRC"), "{e}");
    }

    #[test]
    fn damaged_rc_frames_are_counted_repaired_and_change_no_pixel() {
        let img = image("photo1.ron", 24, 20);
        let want = simulated_frame(&img).unwrap();
        let good = run_rc(&img, LocalNode::new()).unwrap();
        let downs = good
            .transcript
            .iter()
            .filter(|e| matches!(e, Event::Down { .. }))
            .count();
        // A scene chunk, and a frame late in the run (an exchange reply: the repair only
        // adds deliveries, so it exists).
        let node = Corrupt::new(LocalNode::new(), vec![3, downs - 10]);
        let o = run_rc(&img, node).unwrap();
        check_outcome(&o, &want, 2).unwrap();
        // The lost chunk came back as a repair; the count must match exactly.
        assert!(o.root.repairs >= 1, "{:?}", o.root);
        assert!(check_outcome(&o, &want, 1).is_err());
        assert!(check_outcome(&o, &want, 0).is_err());
    }

    #[test]
    fn stream_node_speaks_the_record_protocol() {
        // A node that posts one frame, waits, then ends: as the firmware writes it.
        let mut up = Vec::new();
        for (k, body) in [
            (record::POST, &b"abc"[..]),
            (record::WAIT, &b""[..]),
            (
                record::END,
                &b"instr_total=120 instr_render=80\nresult=Ok(())\nreport=NodeReport { jobs: 1 }"[..],
            ),
        ] {
            up.push(k);
            up.extend_from_slice(&(body.len() as u32).to_le_bytes());
            up.extend_from_slice(body);
        }
        let mut node = StreamNode::new(&up[..], Vec::new());
        assert_eq!(
            node.settle().unwrap(),
            Settled::Waiting {
                posted: vec![b"abc".to_vec()]
            }
        );
        node.deliver(true, b"xy").unwrap();
        assert_eq!(node.down, [b'X', 2, 0, 0, 0, b'x', b'y']);
        let Settled::Ended(end) = node.settle().unwrap() else {
            panic!("not ended")
        };
        assert_eq!(end.counter("instr_render"), Some(80));
        assert_eq!(end.result, "Ok(())");
        assert_eq!(end.report, "NodeReport { jobs: 1 }");
        // A truncated stream is an error, not a hang or a panic.
        let mut cut = StreamNode::new(&up[..7], Vec::new());
        assert!(cut.settle().unwrap_err().contains("QEMU exited"));
    }
}
