//! The bus loop: one [`run_bus`] task per SPI bus chooses, composes, starts and completes
//! transfers (broadcasts and exchanges), overlapping them with double buffering.

use super::*;
use crate::cluster::link::{LinkError, NodeId, RootBus, Transfer};
use crate::cluster::wire::{self, Down, MAX_MESSAGE, SCENE_CHUNK};
use core::cell::RefCell;
use embassy_futures::select::{select4, Either4};

/// Take the frame of the transfer that just left the wire (an exchange: account for the
/// decoding, then apply the node's frame; a broadcast: count it).
async fn complete<C: RootClock, P: PixelSink>(
    sent: Sent,
    rx: &[u8],
    clock: &C,
    root: &RefCell<RootState>,
    sink: &RefCell<P>,
) {
    match sent {
        Sent::Exchange(node) => {
            clock.worked(RcWork::Decode { frame: rx }).await;
            let mut r = root.borrow_mut();
            r.report.exchanges += 1;
            r.heard(node, clock.now_us());
            r.take(node, rx, &mut *sink.borrow_mut());
        }
        Sent::Broadcast => root.borrow_mut().report.broadcasts += 1,
    }
}

/// What a bus transfer carried, for [`complete`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sent {
    Exchange(NodeId),
    Broadcast,
}

/// One bus task's own state between transfers.
struct BusState {
    /// Broadcast position: frame, byte offset (None = SceneEnd next).
    bframe: u16,
    boffset: Option<u32>,
    /// When this bus finished broadcasting each of the two latest frames' scenes (µs), by
    /// `frame % 2`: a node owing its static region is timed from then.
    scene_sent: [Option<(u16, u64)>; 2],
    /// Orphaning events this bus has broadcast `Wake` for.
    woken: u16,
    /// Roll calls: when the next may go out while work waits (None: nothing waits), and the
    /// interval after it (doubles while the wait lasts, up to two time-outs: a lost `Wake` is
    /// repeated within a bounded delay, a node that never answers costs one small broadcast
    /// per two time-outs).
    call_at: Option<u64>,
    call_every: u64,
    /// The transfer on the wire (double buffering only).
    inflight: Option<Sent>,
}

impl BusState {
    const NEW: BusState = BusState {
        bframe: 0,
        boffset: Some(0),
        scene_sent: [None; 2],
        woken: 0,
        call_at: None,
        call_every: 0,
        inflight: None,
    };

    /// When this bus finished broadcasting frame `f`'s scene (µs), if it has.
    fn scene_sent(&self, f: u16) -> Option<u64> {
        self.scene_sent[(f % 2) as usize]
            .filter(|&(g, _)| g == f)
            .map(|(_, t)| t)
    }

    /// The frame to call a roll for now, if any: `waiting` is the frame work waits on
    /// ([`RootState::roll_call`]), `orphaned` the RC's count of orphaning events, `every`
    /// the time-out in force.
    fn roll_call(
        &mut self,
        waiting: Option<u16>,
        orphaned: u16,
        every: u64,
        now: u64,
    ) -> Option<u16> {
        let frame = match waiting {
            None => {
                self.call_at = None;
                return None;
            }
            Some(frame) => frame,
        };
        // Jobs became orphans (on any bus): idle nodes must be told to ask for
        // them at once. Otherwise call once the wait has lasted a time-out.
        if orphaned > self.woken {
            self.woken = orphaned;
            self.call_at = Some(now);
            self.call_every = every;
        }
        let at = *self.call_at.get_or_insert_with(|| {
            self.call_every = every;
            now.saturating_add(every)
        });
        if now >= at {
            self.call_at = Some(now.saturating_add(self.call_every));
            self.call_every = self
                .call_every
                .saturating_mul(2)
                .min(every.saturating_mul(2));
            return Some(frame);
        }
        None
    }

    /// No node of `first..first + count` is ready: declare the silent ones dead (their
    /// work goes elsewhere); returns the roll call to broadcast if one is due, whether the
    /// root logic lets a scene broadcast go, and when the scene being handed out was sent.
    fn idle<C: RootClock>(
        &mut self,
        first: NodeId,
        count: u16,
        clock: &C,
        root: &RefCell<RootState>,
    ) -> (Option<u16>, bool, Option<u64>) {
        let now = clock.now_us();
        let sent = self.scene_sent(root.borrow().handing_out());
        root.borrow_mut().expire(first, count, now, sent);
        let (waiting, orphaned, every) = {
            let r = root.borrow();
            (
                r.roll_call(first, count, self.bframe),
                r.orphaned(),
                r.timeout_us(),
            )
        };
        let wake = self.roll_call(waiting, orphaned, every, now);
        (wake, root.borrow().may_broadcast(self.bframe), sent)
    }

    /// Compose the next transfer into `tx`: the reply to `ready` (its ready line is up: the
    /// node is alive), else the roll call `wake`, else the next piece of the scene; returns
    /// what it is and its length.
    fn compose<C: RootClock, S: SceneSource + ?Sized>(
        &mut self,
        ready: Option<NodeId>,
        wake: Option<u16>,
        tx: &mut [u8],
        clock: &C,
        root: &RefCell<RootState>,
        scenes: &S,
    ) -> Result<(Sent, usize), RootError> {
        Ok(match (ready, wake) {
            (Some(node), _) => {
                let mut r = root.borrow_mut();
                r.heard(node, clock.now_us());
                (Sent::Exchange(node), r.reply(node, scenes, tx))
            }
            (None, Some(frame)) => (
                Sent::Broadcast,
                wire::encode(0, 0, &Down::Wake { frame }, tx).unwrap_or(0),
            ),
            (None, None) => (
                Sent::Broadcast,
                self.compose_scene(clock, root, scenes, tx)?,
            ),
        })
    }

    /// Compose the next broadcast of the scene (a chunk, or `SceneEnd` after the last) into
    /// `tx`; returns its length.
    fn compose_scene<C: RootClock, S: SceneSource + ?Sized>(
        &mut self,
        clock: &C,
        root: &RefCell<RootState>,
        scenes: &S,
        tx: &mut [u8],
    ) -> Result<usize, RootError> {
        let bframe = self.bframe;
        let scene = scenes
            .scene(bframe)
            .ok_or(RootError::BadScene { frame: bframe })?;
        let crc = root
            .borrow_mut()
            .scene_crc(bframe, scene, scenes.scene_crc(bframe));
        let n = match self.boffset {
            Some(off) => {
                let start = off as usize;
                let end = (start + SCENE_CHUNK).min(scene.len());
                let msg = Down::Scene {
                    frame: bframe,
                    offset: off,
                    total: scene.len() as u32,
                    crc,
                    data: &scene[start..end],
                };
                self.boffset = (end < scene.len()).then_some(end as u32);
                wire::encode(0, 0, &msg, tx).unwrap_or(0)
            }
            None => {
                let msg = Down::SceneEnd {
                    frame: bframe,
                    len: scene.len() as u32,
                    crc,
                };
                self.scene_sent[(bframe % 2) as usize] = Some((bframe, clock.now_us()));
                self.bframe += 1;
                self.boffset = Some(0);
                wire::encode(0, 0, &msg, tx).unwrap_or(0)
            }
        };
        Ok(n)
    }
}

/// Every frame is complete: take the transfer still on the wire, broadcast `Stop`.
async fn stop<B: RootBus, C: RootClock, P: PixelSink>(
    st: &mut BusState,
    rx: &mut [u8],
    bus: &mut B,
    clock: &C,
    root: &RefCell<RootState>,
    sink: &RefCell<P>,
) -> Result<RootReport, RootError> {
    if let Some(sent) = st.inflight.take() {
        let got = bus.finish(rx).await?;
        complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
    }
    let n = wire::encode(0, 0, &Down::Stop, bus.tx_bank()).unwrap_or(0);
    clock.worked(RcWork::Encode { bytes: n }).await;
    bus.start(Transfer::Broadcast, n)?;
    bus.finish(rx).await?;
    Ok(root.borrow().report())
}

/// Nothing to send: wait for a node's ready line (returned), the end of the last frame,
/// the next deadline or roll call, or (`can_send`) the DM producing frame `bframe`.
#[allow(clippy::too_many_arguments)]
async fn wait_for_work<B: RootBus, C: RootClock, S: SceneSource + ?Sized>(
    index: usize,
    bus: &mut B,
    clock: &C,
    root: &RefCell<RootState>,
    scenes: &S,
    st: &BusState,
    sent: Option<u64>,
    can_send: bool,
) -> Option<NodeId> {
    let (first, count) = bus.nodes();
    let deadline = match (root.borrow().next_deadline(first, count, sent), st.call_at) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    };
    let timer = async {
        match deadline {
            Some(t) => clock.at_us(t).await,
            None => core::future::pending::<()>().await,
        }
    };
    let bframe = st.bframe;
    let dm = async {
        if can_send {
            scenes.wait_produced(bframe).await
        } else {
            core::future::pending::<()>().await
        }
    };
    let end = Finished { root, slot: index };
    match select4(bus.wait_ready(), end, timer, dm).await {
        Either4::First(n) => Some(n),
        _ => None,
    }
}

/// Drive one bus until every frame is complete, then broadcast `Stop`. `index` numbers the
/// bus tasks (0..[`MAX_BUSES`]) sharing `root`.
///
/// With [`RootConfig::double_buffer`] the RC works while the bus does: it composes transfer
/// `k + 1` in the idle TX bank while transfer `k` is on the wire, starts it the moment `k`
/// ends, and decodes and applies `k`'s node frame while `k + 1` is on the wire. The bus
/// waits for the RC only when composing `k + 1` takes longer than transfer `k`. Without it,
/// each transfer is composed, clocked and taken in turn.
pub async fn run_bus<B: RootBus, C: RootClock, S: SceneSource + ?Sized, P: PixelSink>(
    index: usize,
    bus: &mut B,
    clock: &C,
    root: &RefCell<RootState>,
    scenes: &S,
    sink: &RefCell<P>,
) -> Result<RootReport, RootError> {
    let double = root.borrow().cfg.double_buffer;
    // One receive buffer for either loop: a buffer of each would both live in this future
    // (1.5 KB more on every RC, as its statics).
    let mut rx = [0u8; MAX_MESSAGE];
    if double && bus.in_flight() > 1 {
        return run_overlapped(index, bus, clock, root, scenes, sink, &mut rx).await;
    }
    let mut st = BusState::NEW;
    let (first, count) = bus.nodes();
    loop {
        if root.borrow().finished() {
            return stop(&mut st, &mut rx, bus, clock, root, sink).await;
        }
        // 1. Choose the next transfer and compose it into the idle TX bank.
        let mut ready = bus.ready();
        let mut wake: Option<u16> = None;
        if ready.is_none() {
            let (can_send, sent);
            (wake, can_send, sent) = st.idle(first, count, clock, root);
            if wake.is_none() && !(can_send && scenes.produced(st.bframe)) {
                // Nothing to send now. The frame on the wire may change that: take it first.
                if let Some(sent) = st.inflight.take() {
                    let got = bus.finish(&mut rx).await?;
                    complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
                    continue;
                }
                match wait_for_work(index, bus, clock, root, scenes, &st, sent, can_send).await {
                    Some(n) => ready = Some(n),
                    None => continue,
                }
            }
        }
        // A node whose exchange is still on the wire (or not yet taken) that is ready again
        // already has our reply: take its last frame before composing the next reply.
        if let (Some(node), Some(Sent::Exchange(busy))) = (ready, st.inflight) {
            if node == busy {
                st.inflight = None;
                let got = bus.finish(&mut rx).await?;
                complete(
                    Sent::Exchange(node),
                    &rx[..got.min(rx.len())],
                    clock,
                    root,
                    sink,
                )
                .await;
                continue;
            }
        }
        let (next, n) = st.compose(ready, wake, bus.tx_bank(), clock, root, scenes)?;
        let crc_bytes = root.borrow_mut().take_crc_work();
        if crc_bytes > 0 {
            clock.worked(RcWork::Checksum { bytes: crc_bytes }).await;
        }
        clock.worked(RcWork::Encode { bytes: n }).await;
        // 2. The transfer on the wire must end before this one starts; then take its frame
        // while this one is on the wire.
        let prev = match st.inflight.take() {
            Some(sent) => Some((sent, bus.finish(&mut rx).await?)),
            None => None,
        };
        let transfer = match next {
            Sent::Exchange(node) => Transfer::Exchange(node),
            Sent::Broadcast => Transfer::Broadcast,
        };
        bus.start(transfer, n)?;
        if let Some((sent, got)) = prev {
            complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
        }
        if double {
            st.inflight = Some(next);
        } else {
            let got = bus.finish(&mut rx).await?;
            complete(next, &rx[..got.min(rx.len())], clock, root, sink).await;
        }
    }
}

/// Take node `node`'s frame of an exchange in flight (`RootBus::finish_node`) and hand it to
/// the root logic.
async fn take_node<B: RootBus, C: RootClock, P: PixelSink>(
    node: NodeId,
    bus: &mut B,
    rx: &mut [u8],
    clock: &C,
    root: &RefCell<RootState>,
    sink: &RefCell<P>,
) -> Result<usize, RootError> {
    let got = bus.finish_node(node, rx).await?;
    complete(
        Sent::Exchange(node),
        &rx[..got.min(rx.len())],
        clock,
        root,
        sink,
    )
    .await;
    Ok(got)
}

/// [`run_bus`] on a bus that keeps several exchanges in flight ([`RootBus::in_flight`] > 1,
/// a bus of relays): take every frame that came back ([`RootBus::arrived`]) first, then
/// compose and start an exchange with every node the bus may begin one with
/// ([`RootBus::ready`]), without waiting for the ones in flight; broadcasts, roll calls,
/// time-outs and the end as [`run_bus`] (a broadcast ends before the next transfer starts).
async fn run_overlapped<B: RootBus, C: RootClock, S: SceneSource + ?Sized, P: PixelSink>(
    index: usize,
    bus: &mut B,
    clock: &C,
    root: &RefCell<RootState>,
    scenes: &S,
    sink: &RefCell<P>,
    rx: &mut [u8; MAX_MESSAGE],
) -> Result<RootReport, RootError> {
    let mut st = BusState::NEW;
    let (first, count) = bus.nodes();
    loop {
        bus.poll();
        if root.borrow().finished() {
            // Take the exchanges still in flight (each ends, or times out), then `Stop`.
            while let Some(node) = bus.arrived().or(bus.pending()) {
                match take_node(node, bus, &mut rx[..], clock, root, sink).await {
                    // Others' frames came first and are to be taken before this one.
                    Err(RootError::Link(LinkError::Busy)) if bus.arrived().is_some() => {}
                    r => {
                        r?;
                    }
                }
            }
            return stop(&mut st, &mut rx[..], bus, clock, root, sink).await;
        }
        // 1. A node's frame came back: take it. A node that will post again (it holds
        // jobs) has its next reply composed now, where the bus holds replies ahead of a
        // node's line ([`RootBus::ask_ahead`]).
        let mut ahead = None;
        if let Some(node) = bus.arrived() {
            let got = take_node(node, bus, &mut rx[..], clock, root, sink).await?;
            // (Not after an exchange that ended empty, a time-out or a reply ahead lost: that
            // is no word from the node, which may be dead.)
            if !(got > 0 && bus.ask_ahead(node) && root.borrow_mut().will_post(node)) {
                continue;
            }
            ahead = Some(node);
        }
        // 2. Choose the next transfer and compose it.
        let ready = ahead.or_else(|| bus.ready());
        let mut wake: Option<u16> = None;
        if ready.is_none() {
            let (can_send, sent);
            (wake, can_send, sent) = st.idle(first, count, clock, root);
            if wake.is_none() && !(can_send && scenes.produced(st.bframe)) {
                if let Some(sent) = st.inflight.take() {
                    let got = bus.finish(&mut rx[..]).await?;
                    complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
                    continue;
                }
                // Returns on a ready node or a frame back (looked at next round).
                let _ = wait_for_work(index, bus, clock, root, scenes, &st, sent, can_send).await;
                continue;
            }
        }
        let (next, n) = st.compose(ready, wake, bus.tx_bank(), clock, root, scenes)?;
        let crc_bytes = root.borrow_mut().take_crc_work();
        if crc_bytes > 0 {
            clock.worked(RcWork::Checksum { bytes: crc_bytes }).await;
        }
        clock.worked(RcWork::Encode { bytes: n }).await;
        // 3. A broadcast still on the link ends first; exchanges in flight run on.
        if let Some(sent) = st.inflight.take() {
            let got = bus.finish(&mut rx[..]).await?;
            complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
        }
        let transfer = match next {
            Sent::Exchange(node) => Transfer::Exchange(node),
            Sent::Broadcast => Transfer::Broadcast,
        };
        bus.start(transfer, n)?;
        if next == Sent::Broadcast {
            st.inflight = Some(next);
        }
    }
}
