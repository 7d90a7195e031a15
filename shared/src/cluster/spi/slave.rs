//! The NC side: the slave's port trait, the DMA task ([`SlaveTask`]) and the
//! [`NodeLink`] handle the node logic uses, sharing banks through [`SlaveShared`].

use super::framing::*;
use crate::cluster::landing::{Landing, LentBank, SceneLanding};
use crate::cluster::link::{Incoming, LinkError, NodeLink};
use crate::cluster::wire::{self, Down, Envelope, MAX_MESSAGE};
use core::cell::RefCell;
use core::future::{poll_fn, Future};
use core::task::{Poll, Waker};
use critical_section::Mutex;

/// How an armed transfer ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Armed {
    /// The RC selected the node, clocked, and released the chip-select.
    Done,
    /// `cancel` resolved while the node was not selected: the DMA was disarmed unused.
    Cancelled,
}

/// The node's hardware: an SPI slave with DMA and hardware NSS, a chip-select sense input,
/// the handshake output.
#[allow(async_fn_in_trait)]
pub trait SlavePort {
    /// Arm DMA to send `tx` and receive into `rx` (equal lengths, a whole bank), then wait
    /// until the RC has selected the node and released it again ([`Armed::Done`]; `rx`
    /// holds what was clocked, the rest untouched). If `cancel` resolves while the node is
    /// not selected, disarm and return [`Armed::Cancelled`].
    async fn transfer(
        &mut self,
        tx: &[u8],
        rx: &mut [u8],
        cancel: impl Future<Output = ()>,
    ) -> Result<Armed, PortError>;
    /// Drive the handshake line. (The port itself also drops it the moment the chip-select
    /// falls, without waiting for the protocol.)
    fn set_ready(&mut self, high: bool);
}

/// What the node's link saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SlaveCounters {
    pub transfers: u32,
    pub exchanges: u32,
    pub broadcasts: u32,
    /// RC headers that failed their checks (the transfer is dropped).
    pub bad_headers: u32,
    /// RC bodies that failed their CRC (an exchange's is handed on empty, so the node logic
    /// counts it and goes back; a broadcast's is dropped).
    pub bad_bodies: u32,
    /// Our frame answered with NAK (or no trailer): kept and sent again.
    pub retransmits: u32,
    /// Transfers that found both RX banks full (absorbed by the scratch bank) and were not
    /// scene chunks written into a lent scene bank.
    pub overflows: u32,
    /// Broadcast scene chunks written straight into the lent scene bank ([`SceneLanding`]),
    /// or dropped there as already held.
    pub landed: u32,
    /// Armed transfers disarmed unused to take a newly posted frame.
    pub rearms: u32,
    pub port_errors: u32,
}

/// A received frame waiting for the node logic.
struct Delivered<'b> {
    bank: Option<&'b mut Bank>,
    len: usize,
    exchanged: bool,
}

struct SlaveState<'b> {
    /// The TX bank `post` fills, and the length of the frame posted in it.
    spare: Option<&'b mut Bank>,
    spare_len: Option<usize>,
    /// The link task's armed TX bank holds a posted frame not yet acknowledged.
    armed_posted: bool,
    free: [Option<&'b mut Bank>; 2],
    queue: [Option<Delivered<'b>>; 2],
    /// Something changed that the link task should re-arm for (a post, a freed bank).
    changed: bool,
    task_waker: Option<Waker>,
    recv_waker: Option<Waker>,
    counters: SlaveCounters,
    /// The scene bank the node logic lent (see [`crate::cluster::landing`]).
    lent: Option<LentBank<'b>>,
}

/// The state the node's link task and the node logic share (interrupt-safe: a critical
/// section guards every access, so the link task may run at a higher priority).
pub struct SlaveShared<'b> {
    state: Mutex<RefCell<SlaveState<'b>>>,
}

/// The banks of a node's link: two TX, two RX, one scratch.
pub struct SlaveBanks<'b> {
    pub tx: [&'b mut Bank; 2],
    pub rx: [&'b mut Bank; 2],
    pub scratch: &'b mut Bank,
}

fn wake(w: &mut Option<Waker>) {
    if let Some(w) = w.take() {
        w.wake();
    }
}

impl<'b> SlaveShared<'b> {
    /// Shared state over the two RX banks and the spare TX bank; returns it with the TX
    /// bank and scratch bank the link task keeps.
    pub fn new(banks: SlaveBanks<'b>) -> (Self, SlaveTask<'b>) {
        let [tx0, tx1] = banks.tx;
        let [rx0, rx1] = banks.rx;
        let shared = SlaveShared {
            state: Mutex::new(RefCell::new(SlaveState {
                spare: Some(tx1),
                spare_len: None,
                armed_posted: false,
                free: [Some(rx0), Some(rx1)],
                queue: [None, None],
                changed: false,
                task_waker: None,
                recv_waker: None,
                counters: SlaveCounters::default(),
                lent: None,
            })),
        };
        let task = SlaveTask {
            armed: Some(tx0),
            armed_len: None,
            scratch: Some(banks.scratch),
        };
        (shared, task)
    }

    fn with<R>(&self, f: impl FnOnce(&mut SlaveState<'b>) -> R) -> R {
        critical_section::with(|cs| f(&mut self.state.borrow_ref_mut(cs)))
    }

    pub fn counters(&self) -> SlaveCounters {
        self.with(|s| s.counters)
    }

    /// The node logic's end of the link.
    pub fn handle(&self) -> SlaveHandle<'_, 'b> {
        SlaveHandle { shared: self }
    }
}

/// What the link task owns between transfers.
pub struct SlaveTask<'b> {
    armed: Option<&'b mut Bank>,
    armed_len: Option<usize>,
    scratch: Option<&'b mut Bank>,
}

impl<'b> SlaveTask<'b> {
    /// Run the node's link forever: arm, wait for a transfer, hand frames on.
    pub async fn run<P: SlavePort>(mut self, port: &mut P, shared: &SlaveShared<'b>) -> ! {
        loop {
            self.step(port, shared).await;
        }
    }

    /// One armed transfer (exposed for tests).
    pub async fn step<P: SlavePort>(&mut self, port: &mut P, shared: &SlaveShared<'b>) {
        // Take a newly posted frame if the armed bank is idle (TX double buffer).
        let (rxb, from_free) = shared.with(|s| self.take_posted(s));
        let (Some(txb), Some(rxb)) = (self.armed.take(), rxb.or_else(|| self.scratch.take()))
        else {
            // Unreachable by construction; recover rather than panic.
            return;
        };
        if self.armed_len.is_none() {
            put_header(&mut txb[..], NC_MAGIC, 0, &[]);
        }
        rxb.fill(0);
        port.set_ready(self.armed_len.is_some() && from_free);
        let cancel = poll_fn(|cx| {
            shared.with(|s| {
                if s.changed {
                    Poll::Ready(())
                } else {
                    s.task_waker = Some(cx.waker().clone());
                    Poll::Pending
                }
            })
        });
        let r = port.transfer(&txb[..], &mut rxb[..], cancel).await;
        port.set_ready(false);
        let outcome = match r {
            Ok(Armed::Done) => Some(self.finish(&rxb[..])),
            Ok(Armed::Cancelled) => None,
            Err(PortError) => {
                shared.with(|s| s.counters.port_errors += 1);
                None
            }
        };
        self.armed = Some(txb);
        // A broadcast, decoded here (outside the critical section) if a scene bank is lent.
        let landable = match outcome {
            Some(Outcome::Deliver {
                len,
                exchanged: false,
                body: true,
            }) if shared.with(|s| s.lent.is_some()) => decode_down(&rxb[..], len),
            _ => None,
        };
        let landed = landable.is_some_and(|env| {
            shared.with(|s| {
                let done = s
                    .lent
                    .as_mut()
                    .is_some_and(|lent| lent.land(&env.msg) != Landing::NotMine);
                s.counters.landed += u32::from(done);
                done
            })
        });
        shared.with(|s| {
            let mut deliver = count(&mut s.counters, outcome);
            if landed {
                // In the scene bank: nothing to queue for the node logic.
                deliver = None;
            }
            if let Some((_, true)) = deliver {
                // Our frame went out and was acknowledged: the armed bank is idle.
                self.armed_len = None;
                s.armed_posted = false;
            }
            let mut bank = Some(rxb);
            if let Some((len, exchanged)) = deliver {
                if !from_free {
                    s.counters.overflows += 1;
                }
                // Without a free RX bank a broadcast is dropped; an exchange is still
                // reported (empty), so the node logic learns its frame went out.
                let slot = s.queue.iter_mut().find(|q| q.is_none());
                match slot {
                    Some(slot) if from_free || exchanged => {
                        *slot = Some(Delivered {
                            bank: if from_free { bank.take() } else { None },
                            len: if from_free { len } else { 0 },
                            exchanged,
                        });
                        wake(&mut s.recv_waker);
                    }
                    _ => {}
                }
            }
            if let Some(b) = bank {
                if from_free {
                    if let Some(slot) = s.free.iter_mut().find(|f| f.is_none()) {
                        *slot = Some(b);
                    }
                } else {
                    self.scratch = Some(b);
                }
            }
        });
    }

    /// Swap a newly posted frame into the armed TX bank if that bank is idle (TX double
    /// buffer) and take a free RX bank; returns it and whether it was one (not scratch).
    #[inline(always)]
    fn take_posted(&mut self, s: &mut SlaveState<'b>) -> (Option<&'b mut Bank>, bool) {
        s.changed = false;
        if let (None, Some(len)) = (self.armed_len, s.spare_len) {
            if let Some(spare) = s.spare.take() {
                s.spare = self.armed.take();
                self.armed = Some(spare);
                self.armed_len = Some(len);
                s.spare_len = None;
            }
        }
        s.armed_posted = self.armed_len.is_some();
        match s.free.iter_mut().find_map(|b| b.take()) {
            Some(b) => (Some(b), true),
            None => (None, false),
        }
    }

    /// Judge a finished transfer.
    fn finish(&self, rx: &[u8]) -> Outcome {
        let Some(h) = get_header(rx, RC_MAGIC) else {
            return Outcome::BadHeader;
        };
        let body = body_ok(rx, &h);
        match h.kind {
            KIND_BROADCAST if body => Outcome::Deliver {
                len: h.len as usize,
                exchanged: false,
                body,
            },
            KIND_BROADCAST => Outcome::BadBroadcast,
            KIND_EXCHANGE => {
                let mine = self.armed_len.unwrap_or(0);
                let l = (h.len as usize).max(mine);
                let acked = rx.get(HEADER + l) == Some(&ACK);
                if self.armed_len.is_some() && !acked {
                    Outcome::Retransmit { body }
                } else {
                    Outcome::Deliver {
                        len: h.len as usize,
                        exchanged: true,
                        body,
                    }
                }
            }
            _ => Outcome::BadHeader,
        }
    }
}

/// The `Down` message in the body of a received frame of `len` bytes, if it decodes.
fn decode_down(rx: &[u8], len: usize) -> Option<Envelope<Down<'_>>> {
    let body = rx.get(HEADER..HEADER.checked_add(len)?)?;
    wire::decode::<Down>(body).ok()
}

/// Count a transfer's outcome (`None`: re-armed without one); returns what to hand the node
/// logic: the body's length (0 if damaged) and whether it was an exchange.
#[inline(always)]
fn count(counters: &mut SlaveCounters, outcome: Option<Outcome>) -> Option<(usize, bool)> {
    if outcome.is_some() {
        counters.transfers += 1;
    } else {
        counters.rearms += 1;
    }
    match outcome {
        Some(Outcome::Deliver {
            len,
            exchanged,
            body,
        }) => {
            if exchanged {
                counters.exchanges += 1;
            } else {
                counters.broadcasts += 1;
            }
            if !body {
                counters.bad_bodies += 1;
            }
            Some((if body { len } else { 0 }, exchanged))
        }
        Some(Outcome::Retransmit { body }) => {
            counters.exchanges += 1;
            counters.retransmits += 1;
            if !body {
                counters.bad_bodies += 1;
            }
            None
        }
        Some(Outcome::BadBroadcast) => {
            counters.broadcasts += 1;
            counters.bad_bodies += 1;
            None
        }
        Some(Outcome::BadHeader) => {
            counters.bad_headers += 1;
            None
        }
        None => None,
    }
}

enum Outcome {
    Deliver {
        len: usize,
        exchanged: bool,
        body: bool,
    },
    Retransmit {
        body: bool,
    },
    BadBroadcast,
    BadHeader,
}

/// The node logic lends the scene bank it is not rendering from: broadcast chunks for it
/// are written in by the link task as they arrive.
impl<'b> SceneLanding<'b> for SlaveShared<'b> {
    fn lend(&self, bank: LentBank<'b>) -> Result<(), LentBank<'b>> {
        self.with(|s| {
            if s.lent.is_some() {
                return Err(bank);
            }
            s.lent = Some(bank);
            Ok(())
        })
    }

    fn reclaim(&self) -> Option<LentBank<'b>> {
        self.with(|s| s.lent.take())
    }
}

/// The node logic's end of the link: [`NodeLink`] over the shared state.
pub struct SlaveHandle<'s, 'b> {
    shared: &'s SlaveShared<'b>,
}

impl NodeLink for SlaveHandle<'_, '_> {
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        if frame.len() > MAX_MESSAGE {
            return Err(LinkError::TooLong {
                len: frame.len() as u32,
                max: MAX_MESSAGE as u32,
            });
        }
        self.shared.with(|s| {
            if s.spare_len.is_some() || s.armed_posted {
                return Err(LinkError::Busy);
            }
            let Some(bank) = s.spare.as_deref_mut() else {
                return Err(LinkError::Busy);
            };
            put_header(&mut bank[..], NC_MAGIC, FLAG_POSTED, frame);
            bank[HEADER..HEADER + frame.len()].copy_from_slice(frame);
            s.spare_len = Some(frame.len());
            s.changed = true;
            wake(&mut s.task_waker);
            Ok(())
        })
    }

    async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
        poll_fn(|cx| {
            self.shared.with(|s| {
                let Some(d) = s.queue[0].take() else {
                    s.recv_waker = Some(cx.waker().clone());
                    return Poll::Pending;
                };
                s.queue.rotate_left(1);
                let mut len = d.len;
                if let Some(bank) = d.bank {
                    match (rx.get_mut(..len), bank.get(HEADER..HEADER + len)) {
                        (Some(dst), Some(src)) => dst.copy_from_slice(src),
                        _ => len = 0,
                    }
                    if let Some(slot) = s.free.iter_mut().find(|f| f.is_none()) {
                        *slot = Some(bank);
                    }
                    // A free bank may let the link raise its ready line.
                    s.changed = true;
                    wake(&mut s.task_waker);
                }
                Poll::Ready(Ok(if d.exchanged {
                    Incoming::Exchanged { len }
                } else {
                    Incoming::Broadcast { len }
                }))
            })
        })
        .await
    }
}
