//! The lock-step bus: the real root logic (`run_bus`) drives one [`NodeSide`] through it,
//! transfer by transfer, into the RC's frame memory ([`run_rc`], [`RcOutcome`]).

use super::*;
use links_core::link::{LinkError, NodeId, RootBus, Transfer};
use links_core::root::{run_bus, NoClock, PixelSink, RootConfig, RootReport, RootState};
use links_core::sched::Policy;
use links_core::wire::MAX_MESSAGE;
use std::cell::RefCell;
use std::future::Future;
use std::task::{Context, Poll, Waker};

pub(super) struct BusInner<N> {
    pub(super) node: N,
    /// The node has run to its next wait since the last delivery.
    pub(super) settled: bool,
    /// The node's TX bank (ready line up).
    pub(super) tx: Option<Vec<u8>>,
    pub(super) ended: Option<NodeEnd>,
    pub(super) transcript: Vec<Event>,
    pub(super) error: Option<String>,
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
        if let Some(end) = &self.ended {
            let msg = format!(
                "the node loop ended while the RC was still sending: {}",
                end.result
            );
            self.fail(msg);
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
pub(super) struct LockstepBus<N> {
    pub(super) inner: RefCell<BusInner<N>>,
    /// The RC's two TX banks; `idle` is the one it composes into.
    pub(super) banks: [Vec<u8>; 2],
    pub(super) idle: usize,
    /// The node's frame of the transfer started and not yet finished (empty: a broadcast).
    pub(super) inflight: Option<Vec<u8>>,
}

impl<N> LockstepBus<N> {
    /// A bus to `node`, which has not yet run, with nothing in flight.
    pub(super) fn new(node: N) -> Self {
        LockstepBus {
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
        }
    }
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
    let mut bus = LockstepBus::new(node);
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
