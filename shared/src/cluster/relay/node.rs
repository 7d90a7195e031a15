//! The relay's logic: [`run_relay`], a node on its parent's link and the root of its bus.

use super::batch::{parse, BatchWriter, Kind, Record, Relayed};
use super::{bit, RelayError, MAX_RELAY_NODES, REPLY_CELL};
use crate::cluster::link::{Incoming, LinkError, NodeId, NodeLink, RootBus};
use crate::cluster::wire::{self, Down, MAX_MESSAGE};
use embassy_futures::select::{select, Either};

/// The relay's buffers (the caller's: on the board they sit in SRAM).
pub struct RelayBuffers<'m> {
    /// What the parent sent (a batch or a forwarded broadcast).
    pub down: &'m mut [u8; MAX_MESSAGE],
    /// The batch being gathered for the parent.
    pub up: &'m mut [u8; MAX_MESSAGE],
    /// A node's frame from the exchange just clocked.
    pub node: &'m mut [u8; MAX_MESSAGE],
    /// A leaf relay's cell per node of its bus for a reply the root sent ahead of the
    /// node's line ([`super::RelayedBus::with_ahead`]): the node is clocked with it the
    /// moment its line rises. Empty: no reply is held ahead (such requests are dropped, and
    /// the root sends them again once the node waits).
    pub ahead: &'m mut [[u8; REPLY_CELL]],
}

/// What a relay did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RelayReport {
    /// Root broadcasts passed on to the relay's bus.
    pub forwarded: u32,
    /// Node exchanges clocked with the root's reply, and node frames sent up.
    pub routed: u32,
    /// Batches posted to the parent.
    pub batches: u32,
    /// Requests for a node not on this bus or not waiting (dropped).
    pub stray_requests: u32,
    /// Parent frames that failed to decode (dropped).
    pub bad_frames: u32,
    /// Of `routed`: node exchanges clocked with a reply held ahead, as the line rose.
    pub ahead: u32,
    /// Replies sent ahead that found no room (a middle relay's bus had none in flight to
    /// spare; a leaf relay has no cell for it, or it is longer than one): dropped, the
    /// exchange ends empty at the root once the node waits.
    pub dropped_ahead: u32,
}

/// Per-node progress, as bitmaps over the relay's bus (bit `i`: node `first + i`).
#[derive(Default)]
struct Nodes {
    /// Reported as waiting in a batch the parent took (a request may come).
    waiting: u32,
    /// A middle relay's (a bus with several exchanges in flight): begun with the root's
    /// reply, its frame not yet taken off the bus.
    flying: u32,
    /// Clocked with the root's reply; the frame is in `up` or in the posted batch.
    answered: u32,
    /// Answered in the batch now posted: idle again once the parent takes it.
    in_post: u32,
    /// A node frame clocked when the batch had no room left for it (its node and length,
    /// in the relay's `node` buffer): it opens the next batch.
    held: Option<(NodeId, u16)>,
    /// A leaf relay's: a reply the root sent ahead of the node's line waits in its cell
    /// (`ahead_len` bytes).
    ahead: u32,
    ahead_len: [u8; MAX_RELAY_NODES as usize],
}

/// Run a relay until the root's `Stop` has been passed on: forward the parent's broadcasts
/// to `bus`, report the nodes waiting to be asked, clock each requested node with the
/// root's reply and send its frame up (see the module doc).
///
/// A middle relay of a two-level tree runs this too, its `bus` a
/// [`super::RelayedBus`] over its child relays (a bus with several exchanges in flight,
/// [`RootBus::in_flight`] above 1): it begins each requested exchange without waiting for
/// it, sends each node frame up as it comes back, and meanwhile keeps its bus moving
/// ([`RootBus::wait_news`]). Its parent's broadcasts go down already tagged: the child
/// relays unwrap them.
pub async fn run_relay<L: NodeLink, B: RootBus>(
    parent: &mut L,
    bus: &mut B,
    buf: RelayBuffers<'_>,
) -> Result<RelayReport, RelayError> {
    let (first, count) = bus.nodes();
    if count > MAX_RELAY_NODES {
        return Err(RelayError::TooManyNodes {
            nodes: count as u32,
            most: MAX_RELAY_NODES as u32,
        });
    }
    let RelayBuffers {
        down,
        up,
        node,
        ahead: cells,
    } = buf;
    let mut up = BatchWriter::new(&mut up[..])?;
    let mut report = RelayReport::default();
    let mut nodes = Nodes::default();
    let mut posted = false;
    let overlapped = bus.in_flight() > 1;
    // The broadcasts passed on as last told to the parent.
    let mut told: u16 = 0;
    loop {
        // 0. A middle relay: the node frames its bus has brought back go up.
        if overlapped {
            collect(bus, &mut nodes, &mut up, node, &mut report).await?;
        }
        // 1. A node with a reply held ahead is clocked as its line rises; the others whose
        // line is up and that are not being served wait to be asked.
        if nodes.ahead != 0 {
            clock_ahead(bus, &mut nodes, cells, &mut up, node, &mut report).await?;
        }
        let mut fresh = 0u32;
        let mut busy_line = false;
        let mut ahead_up = false;
        for i in 0..count {
            if bus.line(first + i) {
                let b = 1u32 << i;
                if (nodes.waiting | nodes.flying | nodes.answered | nodes.ahead) & b == 0 {
                    fresh |= b;
                } else if nodes.ahead & b != 0 && nodes.held.is_none() && !posted {
                    ahead_up = true;
                } else {
                    busy_line = true;
                }
            }
        }
        // 2. Post a batch when there is news, or a node waits for its request (the line to
        // the parent stays up so the request can come down).
        let report_waiting = nodes.waiting | fresh;
        let forwarded = report.forwarded as u16;
        if !posted && (up.records() > 0 || report_waiting != 0 || forwarded != told) {
            up.set_waiting(report_waiting);
            // How many broadcasts it has passed on (when that changed and it fits; else
            // in the next batch).
            if forwarded != told
                && up
                    .push(Record {
                        kind: Kind::Forwarded,
                        node: 0,
                        data: &forwarded.to_le_bytes(),
                    })
                    .is_ok()
            {
                told = forwarded;
            }
            match parent.post(up.bytes()) {
                Ok(()) => {}
                // A batch of an earlier run (before the last `Stop`) still waits for the
                // parent: it goes first, this one after it.
                Err(LinkError::Busy) => {
                    posted = true;
                    continue;
                }
                Err(e) => return Err(e.into()),
            }
            posted = true;
            report.batches += 1;
            let held = nodes.held.and_then(|(n, _)| bit(0, count, n)).unwrap_or(0);
            nodes.in_post = nodes.answered & !held;
            nodes.waiting = report_waiting;
            up.clear();
            if let Some((n, len)) = nodes.held.take() {
                up.push(Record {
                    kind: Kind::Frame,
                    node: n,
                    data: node.get(..len as usize).unwrap_or(&[]),
                })?;
            }
        }
        // 3. Wait for the parent, or (when no line is up) for a node's line; a middle
        // relay's bus moves meanwhile and says when it has news (also while a frame is
        // held for the next batch: its exchanges in flight go on).
        if ahead_up {
            // A held reply's line rose after `clock_ahead` looked: clock it now.
            continue;
        }
        let got = if overlapped {
            match select(parent.recv(&mut down[..]), bus.wait_news()).await {
                Either::First(got) => got?,
                Either::Second(()) => continue,
            }
        } else if busy_line || fresh != 0 {
            parent.recv(&mut down[..]).await?
        } else {
            match select(parent.recv(&mut down[..]), bus.wait_ready()).await {
                Either::First(got) => got?,
                Either::Second(_) => continue,
            }
        };
        match got {
            Incoming::Broadcast { len } => {
                if forward(bus, &down[..len.min(MAX_MESSAGE)], &mut report).await? {
                    return Ok(report);
                }
            }
            Incoming::Exchanged { len } => {
                // Our batch went up: its answered nodes are idle again.
                posted = false;
                nodes.answered &= !nodes.in_post;
                nodes.in_post = 0;
                let frame = &down[..len.min(MAX_MESSAGE)];
                let bufs = (&mut up, &mut *node, &mut *cells);
                serve(bus, frame, &mut nodes, bufs, &mut report).await?;
            }
        }
    }
}

/// Pass a root broadcast on to the bus; whether it was `Stop`.
async fn forward<B: RootBus>(
    bus: &mut B,
    frame: &[u8],
    report: &mut RelayReport,
) -> Result<bool, RelayError> {
    match parse(frame) {
        Ok(Relayed::Forward(msg)) => {
            bus.broadcast(msg).await?;
            report.forwarded += 1;
            Ok(matches!(
                wire::decode::<Down>(msg).map(|e| e.msg),
                Ok(Down::Stop)
            ))
        }
        _ => {
            report.bad_frames += 1;
            Ok(false)
        }
    }
}

/// Clock every waiting node the parent's batch has a request for, and queue its frame (one
/// that no longer fits the batch is held for the next; while one is held, requests wait).
async fn serve<B: RootBus>(
    bus: &mut B,
    frame: &[u8],
    nodes: &mut Nodes,
    (up, rx, cells): (
        &mut BatchWriter<'_>,
        &mut [u8; MAX_MESSAGE],
        &mut [[u8; REPLY_CELL]],
    ),
    report: &mut RelayReport,
) -> Result<(), RelayError> {
    let (first, count) = bus.nodes();
    // An empty frame: the parent's half was damaged; it asks again next time.
    let records = match parse(frame) {
        Ok(Relayed::Batch { records, .. }) => records,
        _ => {
            report.bad_frames += u32::from(!frame.is_empty());
            return Ok(());
        }
    };
    for r in records {
        let (ahead, node, data) = match r {
            Ok(Record {
                kind: kind @ (Kind::Request | Kind::Ahead),
                node,
                data,
            }) => (kind == Kind::Ahead, node, data),
            _ => {
                report.bad_frames += 1;
                continue;
            }
        };
        // Records name the node by its index on this bus.
        let overlapped = bus.in_flight() > 1;
        let b = match bit(0, count, node) {
            Some(b) if nodes.waiting & b != 0 => b,
            // A reply sent ahead of the node's line (only these: a request sent again may
            // come after its node was served): a middle relay begins the exchange (its
            // leaf relay holds it), a leaf relay keeps it in the node's cell.
            Some(b) if ahead && overlapped && (nodes.flying | nodes.answered) & b == 0 => b,
            // A newer one replaces a reply still held (the exchange it was for was given up
            // above, which sent this one).
            Some(b) if ahead && !overlapped && nodes.answered & b == 0 => {
                match cells.get_mut(node as usize) {
                    Some(cell) if data.len() <= REPLY_CELL => {
                        cell[..data.len()].copy_from_slice(data);
                        nodes.ahead_len[node as usize] = data.len() as u8;
                        nodes.ahead |= b;
                    }
                    _ => report.dropped_ahead += 1,
                }
                continue;
            }
            _ => {
                report.stray_requests += 1;
                continue;
            }
        };
        // The node's frame goes into the batch, or is held for the next one (one at most:
        // while one is held, leave the node waiting; the root asks again).
        if nodes.held.is_some() {
            continue;
        }
        if overlapped {
            // A middle relay: begin the exchange; its frame goes up when it comes back. A
            // bus with no room for it now leaves the node waiting (the root asks again; a
            // reply ahead is dropped: the root asks anew once the node waits).
            if bus.begin_exchange(first + node as NodeId, data).is_ok() {
                nodes.waiting &= !b;
                nodes.flying |= b;
            } else if ahead {
                report.dropped_ahead += 1;
            }
            continue;
        }
        clock(bus, node, data, nodes, (up, rx), report).await?;
    }
    Ok(())
}

/// A leaf relay: clock node `index` of its bus with `reply` and queue its frame; the node
/// is answered (no longer waiting; a reply held ahead for it is used, or stale now).
async fn clock<B: RootBus>(
    bus: &mut B,
    index: NodeId,
    reply: &[u8],
    nodes: &mut Nodes,
    (up, rx): (&mut BatchWriter<'_>, &mut [u8; MAX_MESSAGE]),
    report: &mut RelayReport,
) -> Result<(), RelayError> {
    let (first, _) = bus.nodes();
    let got = bus.exchange(first + index, reply, &mut rx[..]).await?;
    queue_frame(up, nodes, index, &rx[..], got)?;
    let b = 1u32.checked_shl(index as u32).unwrap_or(0);
    nodes.waiting &= !b;
    nodes.ahead &= !b;
    nodes.answered |= b;
    report.routed += 1;
    Ok(())
}

/// A leaf relay: clock every node whose reply waits ahead in its cell and whose line is up,
/// and queue its frame (while no frame is held for the next batch).
async fn clock_ahead<B: RootBus>(
    bus: &mut B,
    nodes: &mut Nodes,
    cells: &[[u8; REPLY_CELL]],
    up: &mut BatchWriter<'_>,
    rx: &mut [u8; MAX_MESSAGE],
    report: &mut RelayReport,
) -> Result<(), RelayError> {
    let (first, count) = bus.nodes();
    for i in 0..count.min(MAX_RELAY_NODES) {
        let b = 1u32 << i;
        if nodes.held.is_some() {
            break;
        }
        if nodes.ahead & b == 0 || !bus.line(first + i) {
            continue;
        }
        let len = nodes.ahead_len[i as usize] as usize;
        let reply = cells
            .get(i as usize)
            .and_then(|c| c.get(..len))
            .unwrap_or(&[]);
        clock(bus, i, reply, nodes, (&mut *up, &mut *rx), report).await?;
        report.ahead += 1;
    }
    Ok(())
}

/// Queue the frame (`got` bytes in `rx`) of node `index` on the relay's bus for the
/// parent: into the batch, or held for the next one when it no longer fits. A frame too
/// long to route (or none: a child relay that stopped) goes up empty (the root counts it
/// bad, the node's go-back sends it again).
fn queue_frame(
    up: &mut BatchWriter<'_>,
    nodes: &mut Nodes,
    index: NodeId,
    rx: &[u8],
    got: usize,
) -> Result<(), RelayError> {
    let len = if got <= super::MAX_ROUTED { got } else { 0 };
    if len <= up.room() {
        up.push(Record {
            kind: Kind::Frame,
            node: index,
            data: rx.get(..len).unwrap_or(&[]),
        })?;
    } else {
        nodes.held = Some((index, len as u16));
    }
    Ok(())
}

/// A middle relay: take every node frame its bus has brought back into the batch (one
/// that no longer fits is held for the next batch; while one is held the others wait on
/// the bus).
async fn collect<B: RootBus>(
    bus: &mut B,
    nodes: &mut Nodes,
    up: &mut BatchWriter<'_>,
    rx: &mut [u8; MAX_MESSAGE],
    report: &mut RelayReport,
) -> Result<(), RelayError> {
    let (first, count) = bus.nodes();
    bus.poll();
    while nodes.held.is_none() {
        let Some(n) = bus.arrived() else {
            return Ok(());
        };
        let got = bus.finish_node(n, &mut rx[..]).await?;
        let Some(b) = bit(first, count, n) else {
            continue;
        };
        queue_frame(up, nodes, n - first, &rx[..], got)?;
        nodes.flying &= !b;
        nodes.answered |= b;
        report.routed += 1;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::link::Transfer;
    use core::cell::Cell;
    use core::task::Poll;
    use std::collections::VecDeque;
    use std::vec::Vec;

    /// A parent that hands the relay its scripted frames as exchanges, then nothing.
    struct Parent {
        script: VecDeque<Vec<u8>>,
        posts: u32,
    }
    impl NodeLink for Parent {
        fn post(&mut self, _frame: &[u8]) -> Result<(), LinkError> {
            self.posts += 1;
            Ok(())
        }
        async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
            match self.script.pop_front() {
                Some(f) => {
                    rx[..f.len()].copy_from_slice(&f);
                    Ok(Incoming::Exchanged { len: f.len() })
                }
                None => core::future::pending().await,
            }
        }
    }

    /// A leaf bus of 2 nodes: node 0's line rises at its `rise_at`-th look (and stays up
    /// until it is clocked).
    struct Bus {
        looks: Cell<u32>,
        rise_at: u32,
        clocked: u32,
        started: bool,
        tx: [u8; MAX_MESSAGE],
    }
    impl Bus {
        fn up(&self, node: NodeId) -> bool {
            if node != 0 || self.clocked > 0 {
                return false;
            }
            self.looks.set(self.looks.get() + 1);
            self.looks.get() >= self.rise_at
        }
    }
    impl RootBus for Bus {
        fn nodes(&self) -> (NodeId, u16) {
            (0, 2)
        }
        async fn wait_ready(&mut self) -> NodeId {
            loop {
                if self.up(0) {
                    return 0;
                }
                core::future::pending::<()>().await;
            }
        }
        fn ready(&self) -> Option<NodeId> {
            None
        }
        fn line(&self, node: NodeId) -> bool {
            self.up(node)
        }
        fn tx_bank(&mut self) -> &mut [u8] {
            &mut self.tx
        }
        fn start(&mut self, t: Transfer, _len: usize) -> Result<(), LinkError> {
            if let Transfer::Exchange(_) = t {
                self.started = true;
            }
            Ok(())
        }
        async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
            if core::mem::take(&mut self.started) {
                self.clocked += 1;
                rx[..2].copy_from_slice(&[0xAA, 0]);
                return Ok(2);
            }
            Ok(0)
        }
    }

    /// Node 0's line rises between `clock_ahead`'s look at it and the scan of
    /// step 1 (it is then "busy", `nodes.ahead`): with nothing to post, the relay waits
    /// on its parent alone (its line down: the parent never gathers it) and never clocks
    /// the node.
    #[test]
    fn a_line_rising_right_after_clock_ahead_looked_is_still_clocked() {
        let mut frame = [0u8; MAX_MESSAGE];
        let mut w = BatchWriter::new(&mut frame[..]).unwrap();
        w.push(Record {
            kind: Kind::Ahead,
            node: 0,
            data: &[7, 0, 0],
        })
        .unwrap();
        let down_frame = w.bytes().to_vec();
        let mut parent = Parent {
            script: VecDeque::from([down_frame]),
            posts: 0,
        };
        // Looks at node 0's line: 1 (scan, before the record), 2 (clock_ahead), 3 (scan).
        let mut bus = Bus {
            looks: Cell::new(0),
            rise_at: 3,
            clocked: 0,
            started: false,
            tx: [0; MAX_MESSAGE],
        };
        let (mut d, mut u, mut n) = ([0u8; MAX_MESSAGE], [0u8; MAX_MESSAGE], [0u8; MAX_MESSAGE]);
        let mut cells = [[0u8; REPLY_CELL]; 2];
        let bufs = RelayBuffers {
            down: &mut d,
            up: &mut u,
            node: &mut n,
            ahead: &mut cells,
        };
        {
            let fut = run_relay(&mut parent, &mut bus, bufs);
            let mut fut = core::pin::pin!(fut);
            for _ in 0..100 {
                assert!(matches!(
                    embassy_futures::poll_once(fut.as_mut()),
                    Poll::Pending
                ));
            }
        }
        assert_eq!(bus.clocked, 1, "node 0, its line up, was never clocked");
    }
}
