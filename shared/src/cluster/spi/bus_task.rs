//! The RC's link split in two so the wire and the RC's work overlap: [`MasterFront`], the
//! [`RootBus`] the root logic drives (composes, hands a bank over, takes the node's frame),
//! and [`MasterTask`], which owns the [`MasterPort`] and clocks each handed-over transfer
//! (header phase, body, ACK/NAK trailer) on its own. In `rc-fw` the task runs on an
//! interrupt executor above the thread executor, so every DMA completion resumes the
//! clocking at once while the root logic composes the next frame and decodes the last.
//!
//! They share a [`MasterShared`] (a critical section guards every access, so the two may
//! run at different interrupt priorities; no heap): the transfer handed over (its banks
//! move with it), the finished one, the handshake lines as the task last read them, the
//! counters. The banks are the same three as [`super::MasterLink`]'s: two TX (the front
//! composes into one while the task clocks the other) and one RX.

use super::clock::{Clocked, Wire};
use super::framing::*;
use super::master::{copy_frame, MasterCounters, MasterPort};
use crate::cluster::link::{LinkError, NodeId, RootBus, Transfer};
use crate::cluster::wire::MAX_MESSAGE;
use core::cell::RefCell;
use core::future::poll_fn;
use core::task::{Poll, Waker};
use critical_section::Mutex;
use embassy_futures::select::{select, Either};

/// Handshake lines the snapshot holds (one bit each): the most nodes one RC drives.
const LINE_WORDS: usize = crate::cluster::root::MAX_NODES / 32;

/// A transfer handed to the task, with the banks it uses.
struct Job<'b> {
    what: Clocked,
    len: usize,
    tx: &'b mut Bank,
    rx: &'b mut Bank,
}

/// A clocked transfer handed back: its banks and the node frame's length.
struct Done<'b> {
    tx: &'b mut Bank,
    rx: &'b mut Bank,
    len: usize,
}

struct State<'b> {
    job: Option<Job<'b>>,
    /// The task is clocking a transfer it took from `job`.
    clocking: bool,
    done: Option<Done<'b>>,
    /// Handshake line levels as the task last read them, and a count of the readings that
    /// changed them (the front waits for it to move).
    lines: [u32; LINE_WORDS],
    lines_seq: u32,
    /// Nodes (bit per index) whose handshake line stayed high through their selection: a
    /// stuck line or a node not listening. The front does not offer them as ready until
    /// the task sees their line low again, so one stuck line cannot starve the bus (the
    /// root broadcasts only while no node is ready). [`super::MasterLink`]'s rule.
    ignored: [u32; LINE_WORDS],
    /// Bumped on every hand-over, hand-back and line change (see
    /// [`MasterShared::activity`]).
    activity: u32,
    counters: MasterCounters,
    task_waker: Option<Waker>,
    front_waker: Option<Waker>,
}

/// The state [`MasterFront`] and [`MasterTask`] share.
pub struct MasterShared<'b> {
    state: Mutex<RefCell<State<'b>>>,
}

fn wake(w: &mut Option<Waker>) {
    if let Some(w) = w.take() {
        w.wake();
    }
}

impl Default for MasterShared<'_> {
    fn default() -> Self {
        Self::new()
    }
}

impl<'b> MasterShared<'b> {
    /// Nothing handed over, every line low (a `const fn`: it can be a `static`).
    pub const fn new() -> Self {
        MasterShared {
            state: Mutex::new(RefCell::new(State {
                job: None,
                clocking: false,
                done: None,
                lines: [0; LINE_WORDS],
                lines_seq: 0,
                ignored: [0; LINE_WORDS],
                activity: 0,
                counters: MasterCounters {
                    exchanges: 0,
                    broadcasts: 0,
                    naks: 0,
                    bad_headers: 0,
                    not_ready: 0,
                    no_ack: 0,
                    port_errors: 0,
                    bytes: 0,
                },
                task_waker: None,
                front_waker: None,
            })),
        }
    }

    fn with<R>(&self, f: impl FnOnce(&mut State<'b>) -> R) -> R {
        critical_section::with(|cs| f(&mut self.state.borrow_ref_mut(cs)))
    }

    /// What the task's clocking saw so far.
    pub fn counters(&self) -> MasterCounters {
        self.with(|s| s.counters)
    }

    /// Whether a transfer is handed over and not yet clocked to its end.
    pub fn in_flight(&self) -> bool {
        self.with(|s| s.job.is_some() || s.clocking)
    }

    /// A count of the state changes between the two halves (a transfer handed over, taken,
    /// handed back, collected; the lines changing): a single-threaded host executor that
    /// polls both halves in one task re-polls them until it stops moving.
    pub fn activity(&self) -> u32 {
        self.with(|s| s.activity)
    }

    /// Read every handshake line of `port` into the snapshot (forgetting the ignored nodes
    /// whose line is low); wake the front on a change.
    fn publish_lines<P: MasterPort>(&self, port: &P) {
        let mut lines = [0u32; LINE_WORDS];
        for i in 0..port.count().min((LINE_WORDS * 32) as u16) {
            if port.ready(i) {
                lines[i as usize / 32] |= 1 << (i % 32);
            }
        }
        self.with(|s| {
            for (ig, l) in s.ignored.iter_mut().zip(lines) {
                *ig &= l;
            }
            if s.lines != lines {
                s.lines = lines;
                s.lines_seq = s.lines_seq.wrapping_add(1);
                s.activity = s.activity.wrapping_add(1);
                wake(&mut s.front_waker);
            }
        });
    }

    /// The lines up in the snapshot less the ignored nodes'.
    fn offered(&self) -> [u32; LINE_WORDS] {
        self.with(|s| {
            let mut l = s.lines;
            for (w, ig) in l.iter_mut().zip(s.ignored) {
                *w &= !ig;
            }
            l
        })
    }
}

/// The clocking half: owns nothing between transfers but its counters; run it with the
/// port on an executor of its own ([`MasterTask::run`]).
pub struct MasterTask {
    counters: MasterCounters,
}

impl MasterTask {
    pub const fn new() -> Self {
        MasterTask {
            counters: MasterCounters {
                exchanges: 0,
                broadcasts: 0,
                naks: 0,
                bad_headers: 0,
                not_ready: 0,
                no_ack: 0,
                port_errors: 0,
                bytes: 0,
            },
        }
    }

    /// Clock every transfer the front hands over, and keep the handshake snapshot fresh.
    pub async fn run<P: MasterPort>(mut self, port: &mut P, shared: &MasterShared<'_>) -> ! {
        loop {
            self.step(port, shared).await;
        }
    }

    /// Publish the lines, then wait for a handed-over transfer (clock it and hand it back)
    /// or a handshake edge (exposed for tests).
    pub async fn step<'b, P: MasterPort>(&mut self, port: &mut P, shared: &MasterShared<'b>) {
        shared.publish_lines(port);
        let job = poll_fn(|cx| {
            shared.with(|s| match s.job.as_ref() {
                Some(j) => Poll::Ready((j.what, j.len)),
                None => {
                    s.task_waker = Some(cx.waker().clone());
                    Poll::Pending
                }
            })
        });
        let (what, n) = match select(job, port.wait_any_ready()).await {
            Either::First(job) => job,
            Either::Second(()) => return,
        };
        // The banks move to the task for the transfer (the front handed them over and
        // waits for `done`); `clocking` keeps the transfer visible as in flight.
        let Some(Job { tx, rx, .. }) = shared.with(|s| {
            s.clocking = true;
            s.activity = s.activity.wrapping_add(1);
            s.job.take()
        }) else {
            return;
        };
        let no_ack = self.counters.no_ack;
        let mut wire = Wire {
            port: &mut *port,
            tx: &mut *tx,
            rx: &mut *rx,
            counters: &mut self.counters,
        };
        let len = wire.clock(what, n).await;
        let counters = self.counters;
        shared.with(|s| {
            if let (Clocked::Exchange(i), true) = (what, counters.no_ack != no_ack) {
                // Its line stayed high through the selection: not offered until seen low.
                if let Some(w) = s.ignored.get_mut(i as usize / 32) {
                    *w |= 1 << (i % 32);
                }
            }
            s.done = Some(Done { tx, rx, len });
            s.clocking = false;
            s.activity = s.activity.wrapping_add(1);
            s.counters = counters;
            wake(&mut s.front_waker);
        });
        shared.publish_lines(port);
    }
}

impl Default for MasterTask {
    fn default() -> Self {
        Self::new()
    }
}

/// The root logic's end of the split link: [`RootBus`] over [`MasterShared`].
pub struct MasterFront<'s, 'b> {
    shared: &'s MasterShared<'b>,
    first: NodeId,
    count: u16,
    /// The TX bank the RC composes into, the other one once its transfer is done, the RX
    /// bank (each `None` while handed over).
    compose: Option<&'b mut Bank>,
    spare: Option<&'b mut Bank>,
    rx: Option<&'b mut Bank>,
    started: bool,
    next_scan: u16,
}

impl<'s, 'b> MasterFront<'s, 'b> {
    /// A bus of `count` nodes numbered `first..first + count` in the root logic (the
    /// task's port must have as many); `tx` (two, double-buffered) and `rx` are the DMA
    /// banks.
    pub fn new(
        shared: &'s MasterShared<'b>,
        first: NodeId,
        count: u16,
        tx: [&'b mut Bank; 2],
        rx: &'b mut Bank,
    ) -> Self {
        let [t0, t1] = tx;
        MasterFront {
            shared,
            first,
            count: count.min((LINE_WORDS * 32) as u16),
            compose: Some(t0),
            spare: Some(t1),
            rx: Some(rx),
            started: false,
            next_scan: 0,
        }
    }

    pub fn counters(&self) -> MasterCounters {
        self.shared.counters()
    }

    /// The next node round the bus (from the one after the last exchanged) whose line is
    /// up in `lines`.
    fn ready_in(&self, lines: &[u32; LINE_WORDS]) -> Option<NodeId> {
        let count = self.count;
        (0..count)
            .map(|i| (self.next_scan + i) % count)
            .find(|&i| lines[i as usize / 32] & (1 << (i % 32)) != 0)
            .map(|i| self.first + i)
    }

    fn index(&self, node: NodeId) -> Result<u16, LinkError> {
        node.checked_sub(self.first)
            .filter(|&i| i < self.count)
            .ok_or(LinkError::NoSuchNode { node })
    }
}

impl RootBus for MasterFront<'_, '_> {
    fn nodes(&self) -> (NodeId, u16) {
        (self.first, self.count)
    }

    async fn wait_ready(&mut self) -> NodeId {
        loop {
            let seq = self.shared.with(|s| s.lines_seq);
            if let Some(n) = self.ready_in(&self.shared.offered()) {
                return n;
            }
            poll_fn(|cx| {
                self.shared.with(|s| {
                    if s.lines_seq != seq {
                        Poll::Ready(())
                    } else {
                        s.front_waker = Some(cx.waker().clone());
                        Poll::Pending
                    }
                })
            })
            .await;
        }
    }

    fn ready(&self) -> Option<NodeId> {
        self.ready_in(&self.shared.offered())
    }

    fn line(&self, node: NodeId) -> bool {
        let lines = self.shared.with(|s| s.lines);
        self.index(node)
            .is_ok_and(|i| lines[i as usize / 32] & (1 << (i % 32)) != 0)
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        match self.compose.as_deref_mut() {
            Some(b) => &mut b[HEADER..HEADER + MAX_MESSAGE],
            // Unreachable by construction (two TX banks, one transfer at a time).
            None => &mut [],
        }
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        if self.started {
            return Err(LinkError::Busy);
        }
        if len > MAX_MESSAGE {
            return Err(LinkError::TooLong {
                len: len as u32,
                max: MAX_MESSAGE as u32,
            });
        }
        let what = match transfer {
            Transfer::Exchange(node) => {
                let i = self.index(node)?;
                self.next_scan = (i + 1) % self.count;
                Clocked::Exchange(i)
            }
            Transfer::Broadcast => Clocked::Broadcast,
        };
        let (Some(tx), Some(rx)) = (self.compose.take(), self.rx.take()) else {
            return Err(LinkError::Busy);
        };
        self.compose = self.spare.take();
        self.started = true;
        self.shared.with(|s| {
            s.job = Some(Job { what, len, tx, rx });
            s.activity = s.activity.wrapping_add(1);
            wake(&mut s.task_waker);
        });
        Ok(())
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        if !self.started {
            return Err(LinkError::Aborted);
        }
        let done = poll_fn(|cx| {
            self.shared.with(|s| match s.done.take() {
                Some(d) => {
                    s.activity = s.activity.wrapping_add(1);
                    Poll::Ready(d)
                }
                None => {
                    s.front_waker = Some(cx.waker().clone());
                    Poll::Pending
                }
            })
        })
        .await;
        self.started = false;
        let r = copy_frame(&done.rx[..], done.len, rx);
        self.spare = Some(done.tx);
        self.rx = Some(done.rx);
        if self.compose.is_none() {
            self.compose = self.spare.take();
        }
        r
    }
}
