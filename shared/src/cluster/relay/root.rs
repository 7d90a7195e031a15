//! The root's end of a relay tree: [`RelayedBus`], the [`RootBus`] of the nodes behind the
//! relays on one link.

use super::batch::{forward, parse, BatchWriter, Kind, Record, Relayed};
use super::{RelayError, MAX_RELAY_NODES, MAX_ROUTED};
use crate::cluster::link::{LinkError, NodeId, RootBus, Transfer};
use crate::cluster::root::{NoClock, RootClock};
use crate::cluster::wire::MAX_MESSAGE;
use embassy_futures::select::{select, Either};

/// Most relays on one link.
pub const MAX_RELAYS: usize = 32;

/// What the root's end of the relay link saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RelayedCounters {
    /// Exchanges with relays (requests down, batches up).
    pub link_exchanges: u32,
    /// Of which carried no request (only gathering what the relay had).
    pub gathering: u32,
    /// Relay batches that failed to decode, or held records of the wrong kind or for a
    /// node not behind that relay.
    pub bad_batches: u32,
    /// Node frames for a node not being asked (dropped).
    pub stray_frames: u32,
    /// Node exchanges given up (handed to the root logic empty) because no frame came up
    /// within the time-out ([`RelayedBus::with_timeout`]): a relay that stopped answering.
    pub timeouts: u32,
}

/// The buffers of a [`RelayedBus`] (6.3 KB: the firmware places them in SRAM beside the
/// scene, since all-zero bytes are a valid value).
pub struct RelayedBuffers {
    /// Two compose buffers (double buffering, as the SPI link's banks).
    pub tx: [[u8; MAX_MESSAGE]; 2],
    /// The node frame that answered the request in flight.
    pub answer: [u8; MAX_MESSAGE],
    /// What the link's last relay exchange brought.
    pub rx: [u8; MAX_MESSAGE],
}

impl RelayedBuffers {
    pub const fn new() -> Self {
        RelayedBuffers {
            tx: [[0; MAX_MESSAGE]; 2],
            answer: [0; MAX_MESSAGE],
            rx: [0; MAX_MESSAGE],
        }
    }
}

impl Default for RelayedBuffers {
    fn default() -> Self {
        Self::new()
    }
}

/// The link operation the root has started and not yet taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Op {
    Exchange(NodeId),
    Broadcast,
}

/// The nodes behind `relays` relays on `link` (relay `r` is the link's node `link_first +
/// r`; its nodes are `first + r * per_relay ..`), as one [`RootBus`] for `run_bus`.
///
/// `link`'s `finish` must be safe to drop while awaited (a relay exchange is started and
/// finished inside `wait_ready`, which `run_bus` races against its timers): the split link
/// ([`crate::spi::MasterFront`]) is; a dropped exchange is taken before the next one.
pub struct RelayedBus<'m, L, C = NoClock> {
    link: L,
    buf: &'m mut RelayedBuffers,
    /// How long a node exchange may wait for its frame (µs; 0: for ever), by `clock`.
    clock: C,
    timeout_us: u64,
    first: NodeId,
    per_relay: u16,
    relays: u16,
    /// Per relay: its nodes waiting to be asked, as it last reported (bit `i`: its `i`-th).
    waiting: [u32; MAX_RELAYS],
    /// Which of `buf.tx` is idle (the other one may be on the wire).
    idle: usize,
    started: Option<(Op, usize)>,
    /// The length of the node frame in `buf.answer` that answered the request in flight.
    answer: Option<usize>,
    /// A relay exchange started on the link and not yet taken (its relay index).
    dangling: Option<u16>,
    next_scan: u16,
    pub counters: RelayedCounters,
}

impl<'m, L: RootBus> RelayedBus<'m, L> {
    /// The nodes `first..first + relays * per_relay` behind every relay on `link`.
    pub fn new(
        link: L,
        buf: &'m mut RelayedBuffers,
        first: NodeId,
        per_relay: u16,
    ) -> Result<Self, RelayError> {
        let relays = link.nodes().1;
        let total = relays as u32 * per_relay as u32;
        if relays as usize > MAX_RELAYS || per_relay > MAX_RELAY_NODES {
            return Err(RelayError::TooManyNodes {
                nodes: total,
                most: MAX_RELAYS as u32 * MAX_RELAY_NODES as u32,
            });
        }
        if first as u32 + total > u16::MAX as u32 {
            return Err(RelayError::TooManyNodes {
                nodes: first as u32 + total,
                most: u16::MAX as u32,
            });
        }
        Ok(RelayedBus {
            link,
            buf,
            clock: NoClock,
            timeout_us: 0,
            first,
            per_relay,
            relays,
            waiting: [0; MAX_RELAYS],
            idle: 0,
            started: None,
            answer: None,
            dangling: None,
            next_scan: 0,
            counters: RelayedCounters::default(),
        })
    }

    /// Give a node exchange up after `timeout_us` of `clock` without its frame: `finish`
    /// hands the root logic an empty frame (counted in `timeouts`), so a relay that stopped
    /// answering costs the root its nodes (their jobs time out and go elsewhere), not its
    /// bus. Without it `finish` waits for ever.
    pub fn with_timeout<C: RootClock>(self, clock: C, timeout_us: u64) -> RelayedBus<'m, L, C> {
        RelayedBus {
            link: self.link,
            buf: self.buf,
            clock,
            timeout_us,
            first: self.first,
            per_relay: self.per_relay,
            relays: self.relays,
            waiting: self.waiting,
            idle: self.idle,
            started: self.started,
            answer: self.answer,
            dangling: self.dangling,
            next_scan: self.next_scan,
            counters: self.counters,
        }
    }
}

impl<L: RootBus, C: RootClock> RelayedBus<'_, L, C> {
    pub fn link(&self) -> &L {
        &self.link
    }

    /// Relay index and bit of `node`.
    fn place(&self, node: NodeId) -> Option<(u16, u32)> {
        let k = node.checked_sub(self.first)?;
        let (r, i) = (k / self.per_relay.max(1), k % self.per_relay.max(1));
        (r < self.relays).then_some((r, 1u32 << i))
    }

    /// `node`'s index on its relay's bus (what the relay's records carry).
    fn local(&self, node: NodeId) -> NodeId {
        node.wrapping_sub(self.first) % self.per_relay.max(1)
    }

    fn ready_in(&self) -> Option<NodeId> {
        let total = self.relays * self.per_relay;
        let busy = match self.started {
            Some((Op::Exchange(n), _)) => Some(n),
            _ => None,
        };
        (0..total)
            .map(|k| (self.next_scan + k) % total)
            .map(|k| self.first + k)
            .find(|&n| {
                Some(n) != busy
                    && self
                        .place(n)
                        .is_some_and(|(r, b)| self.waiting[r as usize] & b != 0)
            })
    }

    /// Start an exchange with relay `r`: the request for `asking` (if it is behind `r`)
    /// down, its batch up.
    fn start_gather(&mut self, r: u16, asking: Option<(NodeId, usize)>) -> Result<(), LinkError> {
        let (link_first, _) = self.link.nodes();
        let request = asking
            .filter(|&(node, _)| self.place(node).is_some_and(|(q, _)| q == r))
            .map(|(node, len)| (self.local(node), len));
        let bank = self.link.tx_bank();
        let mut w = BatchWriter::new(bank).map_err(|_| LinkError::Aborted)?;
        if let Some((node, len)) = request {
            let data = self.buf.tx[self.idle ^ 1].get(..len).unwrap_or(&[]);
            w.push(Record {
                kind: Kind::Request,
                node,
                data,
            })
            .map_err(|_| LinkError::TooLong {
                len: len as u32,
                max: MAX_ROUTED as u32,
            })?;
        }
        let n = w.bytes().len();
        self.link
            .start(Transfer::Exchange(link_first.wrapping_add(r)), n)?;
        self.dangling = Some(r);
        self.counters.link_exchanges += 1;
        self.counters.gathering += u32::from(request.is_none());
        Ok(())
    }

    /// Take the relay exchange on the link (if any) and apply its batch.
    async fn settle(&mut self) -> Result<(), LinkError> {
        let Some(r) = self.dangling else {
            return Ok(());
        };
        let got = self.link.finish(&mut self.buf.rx).await?;
        self.dangling = None;
        self.apply(r, got);
        Ok(())
    }

    /// Apply relay `r`'s batch (`got` bytes in `rx`): its waiting nodes, its node frames.
    fn apply(&mut self, r: u16, got: usize) {
        if got == 0 {
            // Nothing intact came up (the link asks again); keep what we knew.
            return;
        }
        let asking = match self.started {
            Some((Op::Exchange(n), _)) => Some(n),
            _ => None,
        };
        // Records name a relay's nodes by their index on its bus.
        let base = self.first + r * self.per_relay;
        let Ok(Relayed::Batch { waiting, records }) = parse(&self.buf.rx[..got]) else {
            self.counters.bad_batches += 1;
            return;
        };
        let mask = match self.per_relay {
            32.. => u32::MAX,
            p => (1u32 << p) - 1,
        };
        if let Some(w) = self.waiting.get_mut(r as usize) {
            *w = waiting & mask;
        }
        for rec in records {
            match rec {
                Ok(Record {
                    kind: Kind::Frame,
                    node,
                    data,
                }) if asking.is_some_and(|a| a.checked_sub(base) == Some(node))
                    && self.answer.is_none() =>
                {
                    self.buf.answer[..data.len()].copy_from_slice(data);
                    self.answer = Some(data.len());
                }
                Ok(Record {
                    kind: Kind::Frame, ..
                }) => self.counters.stray_frames += 1,
                _ => self.counters.bad_batches += 1,
            }
        }
    }
}

impl<L: RootBus, C: RootClock> RootBus for RelayedBus<'_, L, C> {
    fn nodes(&self) -> (NodeId, u16) {
        (self.first, self.relays * self.per_relay)
    }

    async fn wait_ready(&mut self) -> NodeId {
        loop {
            if let Some(n) = self.ready_in() {
                return n;
            }
            // Gather from a relay whose line is up (it has news).
            if self.settle().await.is_err() {
                self.dangling = None;
            }
            if let Some(n) = self.ready_in() {
                return n;
            }
            let relay = self.link.wait_ready().await;
            let r = relay.wrapping_sub(self.link.nodes().0);
            if self.start_gather(r, None).is_ok() && self.settle().await.is_err() {
                self.dangling = None;
            }
        }
    }

    fn ready(&self) -> Option<NodeId> {
        self.ready_in()
    }

    fn line(&self, node: NodeId) -> bool {
        self.place(node)
            .is_some_and(|(r, b)| self.waiting[r as usize] & b != 0)
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        &mut self.buf.tx[self.idle][..MAX_ROUTED]
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        if self.started.is_some() {
            return Err(LinkError::Busy);
        }
        if len > MAX_ROUTED {
            return Err(LinkError::TooLong {
                len: len as u32,
                max: MAX_ROUTED as u32,
            });
        }
        let op = match transfer {
            Transfer::Exchange(node) => {
                let (r, b) = self.place(node).ok_or(LinkError::NoSuchNode { node })?;
                self.waiting[r as usize] &= !b;
                self.next_scan = (node - self.first + 1) % (self.relays * self.per_relay);
                Op::Exchange(node)
            }
            Transfer::Broadcast => Op::Broadcast,
        };
        self.started = Some((op, len));
        self.answer = None;
        self.idle ^= 1;
        // Put the request on the link now if its relay's line is up and the link is free:
        // the root logic decodes the last frame and composes the next reply while it
        // crosses (else `finish` sends it).
        if let (Op::Exchange(node), None) = (op, self.dangling) {
            let (link_first, _) = self.link.nodes();
            if let Some((r, _)) = self.place(node) {
                if self.link.line(link_first.wrapping_add(r)) {
                    // A failure leaves it to `finish`, which sends it again.
                    let _ = self.start_gather(r, Some((node, len)));
                }
            }
        }
        Ok(())
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        let (op, len) = self.started.ok_or(LinkError::Aborted)?;
        self.settle().await?;
        match op {
            Op::Broadcast => {
                let n = forward(&self.buf.tx[self.idle ^ 1][..len], self.link.tx_bank()).map_err(
                    |_| LinkError::TooLong {
                        len: len as u32 + 1,
                        max: MAX_MESSAGE as u32,
                    },
                )?;
                self.link.start(Transfer::Broadcast, n)?;
                self.link.finish(&mut []).await?;
                self.started = None;
                Ok(0)
            }
            Op::Exchange(node) => {
                // Gather from ready relays (round the link) until the node's frame is up,
                // with the request to every exchange with its relay; give up at the
                // deadline (a relay that stopped answering). The node's relay goes first
                // whenever its line is up: the round would come back to it last (the
                // link's scan starts after the relay last exchanged with), and only its
                // exchanges bring the frame that ends this one.
                let deadline = self.clock.now_us().saturating_add(self.timeout_us);
                let (link_first, _) = self.link.nodes();
                let own = self.place(node).map(|(r, _)| link_first.wrapping_add(r));
                while self.answer.is_none() {
                    // (Checked before waiting too: other relays may be ready all the time.)
                    let late = self.timeout_us > 0 && self.clock.now_us() >= deadline;
                    let relay = if late {
                        None
                    } else if let Some(own) = own.filter(|&r| self.link.line(r)) {
                        Some(own)
                    } else if self.timeout_us == 0 {
                        Some(self.link.wait_ready().await)
                    } else {
                        match select(self.link.wait_ready(), self.clock.at_us(deadline)).await {
                            Either::First(relay) => Some(relay),
                            Either::Second(()) => None,
                        }
                    };
                    let Some(relay) = relay else {
                        self.started = None;
                        self.counters.timeouts += 1;
                        return Ok(0);
                    };
                    let r = relay.wrapping_sub(self.link.nodes().0);
                    self.start_gather(r, Some((node, len)))?;
                    self.settle().await?;
                }
                self.started = None;
                let n = self.answer.take().unwrap_or(0);
                let max = rx.len() as u32;
                let dst = rx
                    .get_mut(..n)
                    .ok_or(LinkError::TooLong { len: n as u32, max })?;
                dst.copy_from_slice(&self.buf.answer[..n]);
                Ok(n)
            }
        }
    }
}
