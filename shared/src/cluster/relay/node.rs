//! The relay's logic: [`run_relay`], a node on its parent's link and the root of its bus.

use super::batch::{parse, BatchWriter, Kind, Record, Relayed};
use super::{bit, RelayError, MAX_RELAY_NODES};
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
    let RelayBuffers { down, up, node } = buf;
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
        // 1. Nodes whose line is up and that are not being served wait to be asked.
        let mut fresh = 0u32;
        let mut busy_line = false;
        for i in 0..count {
            if bus.line(first + i) {
                let b = 1u32 << i;
                if (nodes.waiting | nodes.flying | nodes.answered) & b == 0 {
                    fresh |= b;
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
                serve(bus, frame, &mut nodes, &mut up, node, &mut report).await?;
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
    up: &mut BatchWriter<'_>,
    rx: &mut [u8; MAX_MESSAGE],
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
        let Ok(Record {
            kind: Kind::Request,
            node,
            data,
        }) = r
        else {
            report.bad_frames += 1;
            continue;
        };
        // Records name the node by its index on this bus.
        let b = match bit(0, count, node) {
            Some(b) if nodes.waiting & b != 0 => b,
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
        if bus.in_flight() > 1 {
            // A middle relay: begin the exchange; its frame goes up when it comes back. A
            // bus with no room for it now leaves the node waiting (the root asks again).
            if bus.begin_exchange(first + node as NodeId, data).is_ok() {
                nodes.waiting &= !b;
                nodes.flying |= b;
            }
            continue;
        }
        let got = bus
            .exchange(first + node as NodeId, data, &mut rx[..])
            .await?;
        queue_frame(up, nodes, node, &rx[..], got)?;
        nodes.waiting &= !b;
        nodes.answered |= b;
        report.routed += 1;
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
