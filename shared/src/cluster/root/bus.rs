//! The bus loop: one [`run_bus`] task per SPI bus chooses, composes, starts and completes
//! transfers (broadcasts and exchanges), overlapping them with double buffering.

use super::*;
use crate::cluster::link::{NodeId, RootBus, Transfer};
use crate::cluster::wire::{self, Down, MAX_FRAME, SCENE_CHUNK};
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
    let mut rx = [0u8; MAX_FRAME];
    let double = root.borrow().cfg.double_buffer;
    // Broadcast position: frame, byte offset (None = SceneEnd next).
    let mut bframe: u16 = 0;
    let mut boffset: Option<u32> = Some(0);
    // When this bus finished broadcasting each of the two latest frames' scenes (µs), by
    // `frame % 2`: a node owing its static region is timed from then.
    let mut scene_sent: [Option<(u16, u64)>; 2] = [None; 2];
    // Orphaning events this bus has broadcast `Wake` for.
    let mut woken: u16 = 0;
    // Roll calls: when the next may go out while work waits (None: nothing waits), and the
    // interval after it (doubles while the wait lasts, up to two time-outs: a lost `Wake` is
    // repeated within a bounded delay, a node that never answers costs one small broadcast
    // per two time-outs).
    let mut call_at: Option<u64> = None;
    let mut call_every: u64 = 0;
    // The transfer on the wire (double buffering only).
    let mut inflight: Option<Sent> = None;
    let (first, count) = bus.nodes();
    loop {
        if root.borrow().finished() {
            if let Some(sent) = inflight.take() {
                let got = bus.finish(&mut rx).await?;
                complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
            }
            let n = wire::encode(0, 0, &Down::Stop, bus.tx_bank()).unwrap_or(0);
            clock.worked(RcWork::Encode { bytes: n }).await;
            bus.start(Transfer::Broadcast, n)?;
            bus.finish(&mut rx).await?;
            return Ok(root.borrow().report());
        }
        // 1. Choose the next transfer and compose it into the idle TX bank.
        let mut ready = bus.ready();
        let mut wake: Option<u16> = None;
        if ready.is_none() {
            let now = clock.now_us();
            let f = root.borrow().handing_out();
            let sent = scene_sent[(f % 2) as usize]
                .filter(|&(g, _)| g == f)
                .map(|(_, t)| t);
            root.borrow_mut().expire(first, count, now, sent);
            let waiting = root.borrow().roll_call(first, count, bframe);
            let every = root.borrow().timeout_us();
            match waiting {
                None => call_at = None,
                Some(frame) => {
                    // Jobs became orphans (on any bus): idle nodes must be told to ask for
                    // them at once. Otherwise call once the wait has lasted a time-out.
                    if root.borrow().orphaned() > woken {
                        woken = root.borrow().orphaned();
                        call_at = Some(now);
                        call_every = every;
                    }
                    let at = *call_at.get_or_insert_with(|| {
                        call_every = every;
                        now.saturating_add(every)
                    });
                    if now >= at {
                        wake = Some(frame);
                        call_at = Some(now.saturating_add(call_every));
                        call_every = call_every.saturating_mul(2).min(every.saturating_mul(2));
                    }
                }
            }
            let can_send = root.borrow().may_broadcast(bframe);
            if wake.is_none() && !(can_send && scenes.produced(bframe)) {
                // Nothing to send now. The frame on the wire may change that: take it first.
                if let Some(sent) = inflight.take() {
                    let got = bus.finish(&mut rx).await?;
                    complete(sent, &rx[..got.min(rx.len())], clock, root, sink).await;
                    continue;
                }
                let deadline = match (root.borrow().next_deadline(first, count, sent), call_at) {
                    (Some(a), Some(b)) => Some(a.min(b)),
                    (a, b) => a.or(b),
                };
                let timer = async {
                    match deadline {
                        Some(t) => clock.at_us(t).await,
                        None => core::future::pending::<()>().await,
                    }
                };
                let dm = async {
                    if can_send {
                        scenes.wait_produced(bframe).await
                    } else {
                        core::future::pending::<()>().await
                    }
                };
                let end = Finished { root, slot: index };
                match select4(bus.wait_ready(), end, timer, dm).await {
                    Either4::First(n) => ready = Some(n),
                    _ => continue,
                }
            }
        }
        // A node whose exchange is still on the wire (or not yet taken) that is ready again
        // already has our reply: take its last frame before composing the next reply.
        if let (Some(node), Some(Sent::Exchange(busy))) = (ready, inflight) {
            if node == busy {
                inflight = None;
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
        let (next, n) = match ready {
            Some(node) => {
                // Its ready line is up: the node is alive.
                let mut r = root.borrow_mut();
                r.heard(node, clock.now_us());
                (Sent::Exchange(node), r.reply(node, scenes, bus.tx_bank()))
            }
            None if wake.is_some() => (
                Sent::Broadcast,
                wire::encode(
                    0,
                    0,
                    &Down::Wake {
                        frame: wake.unwrap_or(0),
                    },
                    bus.tx_bank(),
                )
                .unwrap_or(0),
            ),
            None => {
                let scene = scenes
                    .scene(bframe)
                    .ok_or(RootError::BadScene { frame: bframe })?;
                let crc = root
                    .borrow_mut()
                    .scene_crc(bframe, scene, scenes.scene_crc(bframe));
                let tx = bus.tx_bank();
                let n = match boffset {
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
                        boffset = (end < scene.len()).then_some(end as u32);
                        wire::encode(0, 0, &msg, tx).unwrap_or(0)
                    }
                    None => {
                        let msg = Down::SceneEnd {
                            frame: bframe,
                            len: scene.len() as u32,
                            crc,
                        };
                        scene_sent[(bframe % 2) as usize] = Some((bframe, clock.now_us()));
                        bframe += 1;
                        boffset = Some(0);
                        wire::encode(0, 0, &msg, tx).unwrap_or(0)
                    }
                };
                (Sent::Broadcast, n)
            }
        };
        let crc_bytes = root.borrow_mut().take_crc_work();
        if crc_bytes > 0 {
            clock.worked(RcWork::Checksum { bytes: crc_bytes }).await;
        }
        clock.worked(RcWork::Encode { bytes: n }).await;
        // 2. The transfer on the wire must end before this one starts; then take its frame
        // while this one is on the wire.
        let prev = match inflight.take() {
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
            inflight = Some(next);
        } else {
            let got = bus.finish(&mut rx).await?;
            complete(next, &rx[..got.min(rx.len())], clock, root, sink).await;
        }
    }
}
