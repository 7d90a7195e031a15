//! The emulated SPI star: buses, chip-selects, ready lines, DMA banks, fault injection (bit
//! flips, bit errors at a rate per direction, lost broadcasts, node deaths), and the snooping
//! pixel collector feeding the frame memory.
//!
//! Timing of one transfer on a bus: `overhead` (handshake: chip-select set-up and hold, DMA
//! start, transfer-complete interrupt) + `(header + body) · 8 / bit_rate`, where an exchange's
//! body is the longer of the two frames (full duplex) and the header phase carries both
//! lengths. A bus does one transfer at a time; different buses run in parallel.

use super::exec::{PollFn, Ps, SharedClock};
use super::framemem::FrameMemory;
use super::relay::Relays;
use super::timeline::{LinkRow, SharedTimeline};
use links_core::board::{BoardProfile, LinkProfile};
use links_core::link::{Incoming, LinkError, NodeId, NodeLink, RootBus, Transfer};
use links_core::wire::MAX_MESSAGE;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

/// Bus timing: a board's link ([`LinkProfile`]) as the simulator charges it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BusTiming {
    /// SPI clock in bits per second (the profile's; `--bit-rate-mhz` overrides it).
    pub bit_rate_hz: f64,
    /// Per-transfer handshake on the wire, in nanoseconds: the profile's chip-select
    /// set-up and hold. The RC's CPU work per transfer (choosing it, composing, decoding) is
    /// not in here: see [`super::rccost`].
    pub overhead_ns: f64,
    /// Bytes of the header phase each transfer starts with.
    pub header_bytes: u32,
    /// Bytes of the trailer phase that ends an exchange (broadcasts have none).
    pub trailer_bytes: u32,
}

impl Default for BusTiming {
    /// The firmware's board's link ([`BoardProfile::F407`]).
    fn default() -> Self {
        Self::of(&BoardProfile::F407.link)
    }
}

impl BusTiming {
    /// What the simulator charges for a transfer on `link`.
    pub fn of(link: &LinkProfile) -> Self {
        Self {
            bit_rate_hz: link.bit_rate_hz as f64,
            overhead_ns: link.handshake_ns() as f64,
            header_bytes: link.header_bytes as u32,
            trailer_bytes: link.trailer_bytes as u32,
        }
    }

    /// Bytes clocked by a transfer of `body` bytes: header, body and, for an exchange,
    /// trailer.
    pub fn clocked_bytes(&self, body: usize, exchange: bool) -> u64 {
        let trailer = if exchange { self.trailer_bytes } else { 0 };
        self.header_bytes as u64 + body as u64 + trailer as u64
    }

    /// Duration of a transfer of `body` bytes: handshake plus every clocked byte.
    pub fn duration_ps(&self, body: usize, exchange: bool) -> Ps {
        let bits = self.clocked_bytes(body, exchange) as f64 * 8.0;
        ((self.overhead_ns * 1e3) + bits * 1e12 / self.bit_rate_hz).ceil() as Ps
    }
}

/// Deterministic fault injection: flip one bit in one of every `n` frames of a kind (0 =
/// never).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Faults {
    /// NC -> RC halves of exchanges.
    pub up_every: u32,
    /// RC -> NC halves of exchanges.
    pub down_every: u32,
    /// Broadcast frames as one node receives them.
    pub broadcast_every: u32,
    /// `None`: exactly every `n`-th frame (of a broadcast, one receiver per hit, in turn).
    /// `Some(seed)`: each frame (each receiver's copy of a broadcast) independently with
    /// probability `1/n`, from a xorshift generator seeded here: still deterministic, but
    /// cannot fall into step with the protocol's own period.
    pub random: Option<u64>,
}

/// Random line noise (fault injection): every bit on a wire is flipped independently with
/// the direction's bit-error rate, and every node's copy of every broadcast is lost whole
/// with probability `drop_broadcast` (its receiver off the bus). Deterministic for a seed.
///
/// The bits exposed are each frame's and its `header_bytes` length header's. An error in the
/// header loses the frame as the board link's header CRC would (`links_core::spi`): the
/// receiver of an exchange gets an empty frame, which it counts as bad; a broadcast copy is
/// dropped. The padding of the shorter side of an exchange, the board link's trailer byte,
/// the chip-select and ready lines are taken to be error-free.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Noise {
    /// Bit-error rate RC -> NC (MOSI): the RC's half of exchanges and every receiver's copy
    /// of a broadcast, each receiver independently.
    pub ber_down: f64,
    /// Bit-error rate NC -> RC (MISO): the nodes' half of exchanges.
    pub ber_up: f64,
    /// Probability that a node loses a broadcast whole.
    pub drop_broadcast: f64,
    /// Seed of the generator (0 is taken as 1).
    pub seed: u64,
}

impl Noise {
    /// Whether any noise is on.
    pub fn any(&self) -> bool {
        self.ber_down > 0.0 || self.ber_up > 0.0 || self.drop_broadcast > 0.0
    }

    /// Check the rates: probabilities, a bit-error rate at most 0.5 (pure noise).
    pub fn check(&self) -> Result<(), String> {
        for (name, v, max) in [
            ("bit-error rate down", self.ber_down, 0.5),
            ("bit-error rate up", self.ber_up, 0.5),
            ("broadcast loss", self.drop_broadcast, 1.0),
        ] {
            if !(v.is_finite() && (0.0..=max).contains(&v)) || (max == 1.0 && v >= 1.0) {
                return Err(format!(
                    "{name} {v}: must be a probability from 0 to {}",
                    if max == 1.0 { "below 1" } else { "0.5" }
                ));
            }
        }
        Ok(())
    }
}

/// What bit errors did to a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Hit {
    None,
    /// Bits of the frame flipped (its CRC-32 fails).
    Bits,
    /// Its header hit: the frame is lost (an exchange's receiver gets an empty frame).
    Header,
}

/// The noise generator: xorshift64* and, per direction, the bits left before its next
/// error (geometric gaps: each bit independently in error with the rate).
struct NoiseGen {
    noise: Noise,
    rng: u64,
    /// Bits before the next error: down, up (`None` until first drawn).
    gap: [Option<u64>; 2],
}

impl NoiseGen {
    fn new(noise: Noise) -> Self {
        Self {
            noise,
            rng: noise.seed.max(1),
            gap: [None; 2],
        }
    }

    /// Uniform in (0, 1].
    fn uniform(&mut self) -> f64 {
        let mut x = self.rng;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.rng = x;
        let r = x.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((r >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }

    /// Bits before the next error at rate `p` (> 0).
    fn draw_gap(&mut self, p: f64) -> u64 {
        if p >= 1.0 {
            return 0;
        }
        let g = (self.uniform().ln() / (-p).ln_1p()).floor();
        if g.is_finite() && g < u64::MAX as f64 {
            g as u64
        } else {
            u64::MAX
        }
    }

    /// Flip bits of one frame sent in direction `dir` (0 = down, 1 = up) behind a
    /// `header`-byte length header.
    fn corrupt(&mut self, dir: usize, header: usize, frame: &mut [u8]) -> Hit {
        let p = if dir == 0 {
            self.noise.ber_down
        } else {
            self.noise.ber_up
        };
        if p.is_nan() || p <= 0.0 || frame.is_empty() {
            return Hit::None;
        }
        let hbits = header as u64 * 8;
        let n = hbits + frame.len() as u64 * 8;
        let mut pos = 0u64;
        let mut hit = Hit::None;
        loop {
            let g = match self.gap[dir] {
                Some(g) => g,
                None => self.draw_gap(p),
            };
            if g >= n - pos {
                self.gap[dir] = Some(g - (n - pos));
                return hit;
            }
            pos += g;
            if pos < hbits {
                hit = Hit::Header;
            } else {
                let bit = pos - hbits;
                frame[(bit / 8) as usize] ^= 1 << (bit % 8);
                if hit == Hit::None {
                    hit = Hit::Bits;
                }
            }
            pos += 1;
            self.gap[dir] = None;
            if pos >= n {
                return hit;
            }
        }
    }

    /// Whether the next broadcast copy is lost.
    fn drop_broadcast(&mut self) -> bool {
        self.noise.drop_broadcast > 0.0 && self.uniform() <= self.noise.drop_broadcast
    }
}

/// Fault injection: node `node` dies (stops answering for good) at `at_s` seconds of
/// virtual time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeDeath {
    pub node: NodeId,
    pub at_s: f64,
}

/// Fault injection: node `node`'s receiver is off the bus for broadcasts number
/// `from..to` of its bus (0-based, in the order the bus sends them: scene chunks, `SceneEnd`,
/// `Wake`, `Stop`); it loses them whole and hears about it from nobody. Exchanges still work.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BroadcastDrop {
    pub node: NodeId,
    pub from: u64,
    pub to: u64,
}

/// Traffic counters of one bus.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BusCounters {
    pub exchanges: u64,
    pub broadcasts: u64,
    /// Bytes clocked (header + body, both directions of an exchange counted once: SPI moves
    /// them simultaneously).
    pub clocked_bytes: u64,
    /// Payload bytes: RC -> NC, NC -> RC, broadcast.
    pub down_bytes: u64,
    pub up_bytes: u64,
    pub broadcast_bytes: u64,
    pub busy_ps: Ps,
    /// Frames corrupted by fault injection: NC -> RC, RC -> NC, broadcast.
    pub corrupted_up: u64,
    pub corrupted_down: u64,
    pub corrupted_broadcast: u64,
    /// Broadcast copies lost by a receiver off the bus ([`BroadcastDrop`], [`Noise`]).
    pub dropped_broadcast: u64,
}

impl BusCounters {
    pub fn corrupted(&self) -> u64 {
        self.corrupted_up + self.corrupted_down + self.corrupted_broadcast
    }

    /// Add another bus's counts (busy time too: the sum over buses).
    pub fn add(&mut self, o: &BusCounters) {
        self.exchanges += o.exchanges;
        self.broadcasts += o.broadcasts;
        self.clocked_bytes += o.clocked_bytes;
        self.down_bytes += o.down_bytes;
        self.up_bytes += o.up_bytes;
        self.broadcast_bytes += o.broadcast_bytes;
        self.busy_ps += o.busy_ps;
        self.corrupted_up += o.corrupted_up;
        self.corrupted_down += o.corrupted_down;
        self.corrupted_broadcast += o.corrupted_broadcast;
        self.dropped_broadcast += o.dropped_broadcast;
    }
}

struct NodeState {
    /// The TX bank (a posted frame) and whether the ready line is up.
    tx: Option<Vec<u8>>,
    inbox: VecDeque<(bool, Vec<u8>)>,
}

/// A transfer on the wire: it takes effect (the node's inbox, the snoop, the RC's RX bank)
/// when virtual time reaches `end`, whoever looks first.
struct Inflight {
    end: Ps,
    /// The exchange's node, or `None` for a broadcast.
    node: Option<NodeId>,
    down: Vec<u8>,
    up: Vec<u8>,
    delivered: bool,
}

struct BusState {
    first: NodeId,
    count: u16,
    busy_until: Ps,
    inflight: Option<Inflight>,
    /// Round-robin position of the ready-line scan.
    next_scan: u16,
    counters: BusCounters,
}

/// Everything on the wires.
pub struct Star {
    clock: SharedClock,
    timing: BusTiming,
    faults: Faults,
    nodes: Vec<NodeState>,
    buses: Vec<BusState>,
    transfers: [u64; 3],
    bcast_victim: usize,
    rng: u64,
    /// The pixel collector listening on every bus's MISO line.
    snoop: Option<Rc<RefCell<FrameMemory>>>,
    /// When each node dies (stops answering: its ready line stays low, it takes no
    /// transfer and posts nothing); `Ps::MAX` = never.
    dead_at: Vec<Ps>,
    drops: Vec<BroadcastDrop>,
    noise: NoiseGen,
    /// Where every transfer is logged, if a timeline is recorded.
    timeline: Option<SharedTimeline>,
    /// The relay tree above the buses (bus `b` is leaf relay `b`'s), if the topology is one.
    relays: Option<Relays>,
    /// Which of the timeline's rows this star's transfers go to.
    row: LinkRow,
}

pub type SharedStar = Rc<RefCell<Star>>;

impl Star {
    pub fn new(
        clock: &SharedClock,
        nodes: u16,
        buses: u16,
        timing: BusTiming,
        faults: Faults,
        snoop: Option<Rc<RefCell<FrameMemory>>>,
    ) -> SharedStar {
        let buses = buses.clamp(1, nodes.max(1));
        let bus_states = (0..buses)
            .map(|b| {
                let first = (b as u32 * nodes as u32 / buses as u32) as u16;
                let end = ((b as u32 + 1) * nodes as u32 / buses as u32) as u16;
                BusState {
                    first,
                    count: end - first,
                    busy_until: 0,
                    inflight: None,
                    next_scan: 0,
                    counters: BusCounters::default(),
                }
            })
            .collect();
        Rc::new(RefCell::new(Star {
            clock: clock.clone(),
            timing,
            faults,
            nodes: (0..nodes)
                .map(|_| NodeState {
                    tx: None,
                    inbox: VecDeque::new(),
                })
                .collect(),
            buses: bus_states,
            transfers: [0; 3],
            bcast_victim: 0,
            rng: faults.random.unwrap_or(1).max(1),
            snoop,
            dead_at: vec![Ps::MAX; nodes as usize],
            drops: Vec::new(),
            noise: NoiseGen::new(Noise::default()),
            timeline: None,
            relays: None,
            row: LinkRow::Leaf,
        }))
    }

    /// Random bit errors and broadcast losses from now on (fault injection).
    pub fn set_noise(&mut self, noise: Noise) {
        self.noise = NoiseGen::new(noise);
    }

    /// Log every transfer from now on into `log`.
    pub fn set_timeline(&mut self, log: SharedTimeline) {
        self.timeline = Some(log);
    }

    /// Log every transfer from now on into `log`'s rows of links between RCs: this star's
    /// buses are the root's links to its relays (`LinkRow::Root`) or the middle relays'
    /// buses (`LinkRow::Mid`), its "nodes" relays.
    pub fn set_link_timeline(&mut self, log: SharedTimeline, row: LinkRow) {
        self.timeline = Some(log);
        self.row = row;
    }

    /// Put a relay tree above the buses: bus `b` is leaf relay `b`'s.
    pub fn set_relays(&mut self, relays: Relays) {
        self.relays = Some(relays);
    }

    /// The relay tree, if there is one.
    pub fn relays(&self) -> Option<&Relays> {
        self.relays.as_ref()
    }

    /// A node loses some broadcasts (fault injection).
    pub fn drop_broadcasts(&mut self, d: BroadcastDrop) {
        self.drops.push(d);
    }

    /// Node `node` dies at virtual time `at` (fault injection).
    pub fn kill_at(&mut self, node: NodeId, at: Ps) {
        if let Some(d) = self.dead_at.get_mut(node as usize) {
            *d = at;
        }
    }

    /// Whether `node` has died by now.
    pub fn is_dead(&self, node: usize) -> bool {
        self.dead_at
            .get(node)
            .is_some_and(|&d| self.clock.borrow().now >= d)
    }

    pub fn bus_count(&self) -> usize {
        self.buses.len()
    }

    pub fn counters(&self) -> Vec<BusCounters> {
        self.buses.iter().map(|b| b.counters).collect()
    }

    fn touch(&self) {
        self.clock.borrow_mut().changes += 1;
    }

    /// Deliver every transfer whose end has come (bus order: deterministic). Called by
    /// everything that can observe a delivery, so a transfer takes effect at its end time
    /// for every observer whether or not the RC is busy then.
    fn settle(&mut self) {
        let now = self.clock.borrow().now;
        for bus in 0..self.buses.len() {
            let due = self.buses[bus]
                .inflight
                .as_ref()
                .is_some_and(|t| !t.delivered && t.end <= now);
            if due {
                self.deliver(bus);
            }
        }
    }

    fn deliver(&mut self, bus: usize) {
        let Some(mut t) = self.buses[bus].inflight.take() else {
            return;
        };
        t.delivered = true;
        match t.node {
            Some(node) => {
                let (fu, fd) = (self.faults.up_every, self.faults.down_every);
                self.maybe_corrupt(0, fu, &mut t.up, bus);
                self.maybe_corrupt(1, fd, &mut t.down, bus);
                let header = self.timing.header_bytes as usize;
                for (dir, f) in [(1, &mut t.up), (0, &mut t.down)] {
                    let hit = self.noise.corrupt(dir, header, f);
                    if hit == Hit::Header {
                        f.clear();
                    }
                    if hit != Hit::None {
                        let c = &mut self.buses[bus].counters;
                        if dir == 1 {
                            c.corrupted_up += 1;
                        } else {
                            c.corrupted_down += 1;
                        }
                    }
                }
                let c = &mut self.buses[bus].counters;
                c.exchanges += 1;
                c.up_bytes += t.up.len() as u64;
                c.down_bytes += t.down.len() as u64;
                if let Some(fm) = &self.snoop {
                    fm.borrow_mut().snoop(&t.up);
                }
                if let Some(r) = &mut self.relays {
                    r.forward_up(bus, &t.up, t.down.len(), t.end);
                }
                self.nodes[node as usize]
                    .inbox
                    .push_back((true, t.down.clone()));
            }
            None => {
                let (first, count) = (self.buses[bus].first, self.buses[bus].count);
                let index = self.buses[bus].counters.broadcasts;
                let c = &mut self.buses[bus].counters;
                c.broadcasts += 1;
                c.broadcast_bytes += t.down.len() as u64;
                let every = self.faults.broadcast_every;
                for n in first..first + count {
                    if self.is_dead(n as usize) {
                        continue;
                    }
                    if self
                        .drops
                        .iter()
                        .any(|d| d.node == n && (d.from..d.to).contains(&index))
                        || self.noise.drop_broadcast()
                    {
                        self.buses[bus].counters.dropped_broadcast += 1;
                        continue;
                    }
                    let mut f = t.down.clone();
                    // One receiver per hit, in turn, sees the corruption.
                    let victim = self.bcast_victim % count as usize == (n - first) as usize;
                    if every > 0 && (victim || self.faults.random.is_some()) {
                        self.maybe_corrupt(2, every, &mut f, bus);
                    }
                    let header = self.timing.header_bytes as usize;
                    let hit = self.noise.corrupt(0, header, &mut f);
                    if hit != Hit::None {
                        self.buses[bus].counters.corrupted_broadcast += 1;
                    }
                    if hit == Hit::Header {
                        continue;
                    }
                    self.nodes[n as usize].inbox.push_back((false, f));
                }
                self.bcast_victim += 1;
            }
        }
        self.buses[bus].inflight = Some(t);
        self.touch();
    }

    /// Corrupt `frame` if this is the `every`-th transfer of kind `k`.
    fn next_rand(&mut self) -> u64 {
        let mut x = self.rng;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.rng = x;
        x
    }

    fn maybe_corrupt(&mut self, k: usize, every: u32, frame: &mut [u8], bus: usize) {
        self.transfers[k] += 1;
        let hit = every > 0
            && match self.faults.random {
                None => self.transfers[k].is_multiple_of(every as u64),
                Some(_) => self.next_rand().is_multiple_of(every as u64),
            };
        if hit && !frame.is_empty() {
            let bit = (self.next_rand() % (frame.len() as u64 * 8)) as usize;
            frame[bit / 8] ^= 1 << (bit % 8);
            let c = &mut self.buses[bus].counters;
            match k {
                0 => c.corrupted_up += 1,
                1 => c.corrupted_down += 1,
                _ => c.corrupted_broadcast += 1,
            }
        }
    }
}

/// What the firmware link's emulated wire ([`super::spi_bus`]) borrows from the star: the
/// buses' node ranges and counters, the fault plan and noise, the collector, the relay tree
/// and the timeline. (The star's own idealised transfers are not used then.)
impl Star {
    pub fn clock(&self) -> &SharedClock {
        &self.clock
    }

    /// Bus `bus`'s nodes: the first and how many.
    pub fn bus_nodes(&self, bus: usize) -> (NodeId, u16) {
        self.buses.get(bus).map_or((0, 0), |b| (b.first, b.count))
    }

    pub fn counters_mut(&mut self, bus: usize) -> Option<&mut BusCounters> {
        self.buses.get_mut(bus).map(|b| &mut b.counters)
    }

    /// Flip bits of `bytes` clocked in direction `dir` (0 = MOSI, 1 = MISO) at the noise's
    /// bit-error rate (every byte exposed: header, body, trailer); whether any flipped.
    pub fn wire_noise(&mut self, dir: usize, bytes: &mut [u8]) -> bool {
        self.noise.corrupt(dir, 0, bytes) != Hit::None
    }

    /// The deterministic every-`n` faults on one frame body: `k` 0 = NC -> RC, 1 = RC -> NC.
    pub fn body_fault(&mut self, k: usize, bytes: &mut [u8], bus: usize) {
        let every = if k == 0 {
            self.faults.up_every
        } else {
            self.faults.down_every
        };
        self.maybe_corrupt(k, every, bytes, bus);
    }

    /// Receiver `n` (index `i` of `count` on `bus`) of a broadcast copy `bytes`: whether it
    /// is off the bus for it ([`BroadcastDrop`], [`Noise::drop_broadcast`]); otherwise the
    /// every-`n` broadcast fault (one receiver per hit, in turn) and the MOSI noise hit it.
    pub fn broadcast_copy(
        &mut self,
        bus: usize,
        (n, i, count): (NodeId, u16, u16),
        bytes: &mut [u8],
    ) -> bool {
        let index = self.buses[bus].counters.broadcasts;
        let off = self
            .drops
            .iter()
            .any(|d| d.node == n && (d.from..d.to).contains(&index))
            || self.noise.drop_broadcast();
        if off {
            self.buses[bus].counters.dropped_broadcast += 1;
            return false;
        }
        let every = self.faults.broadcast_every;
        let victim = self.bcast_victim % count.max(1) as usize == i as usize;
        if every > 0 && (victim || self.faults.random.is_some()) {
            self.maybe_corrupt(2, every, bytes, bus);
        }
        if self.wire_noise(0, bytes) {
            self.buses[bus].counters.corrupted_broadcast += 1;
        }
        true
    }

    /// A broadcast on `bus` ended (the next hit of the every-`n` fault goes to the next
    /// receiver).
    pub fn broadcast_done(&mut self, bus: usize) {
        self.bcast_victim += 1;
        if let Some(c) = self.counters_mut(bus) {
            c.broadcasts += 1;
        }
    }

    /// The collector's capture of a node frame off MISO.
    pub fn snoop(&self, bytes: &[u8]) {
        if let Some(fm) = &self.snoop {
            fm.borrow_mut().snoop(bytes);
        }
    }

    pub fn relays_mut(&mut self) -> Option<&mut Relays> {
        self.relays.as_mut()
    }

    /// Log a transfer on the timeline, if one is recorded.
    pub fn log_transfer(&self, bus: usize, node: Option<NodeId>, start: Ps, end: Ps) {
        if let Some(log) = &self.timeline {
            log.borrow_mut().transfer(self.row, bus, node, start, end);
        }
    }
}

/// A node's end of the link.
pub struct SimNodeLink {
    star: SharedStar,
    id: usize,
}

impl SimNodeLink {
    pub fn new(star: &SharedStar, id: NodeId) -> Self {
        Self {
            star: star.clone(),
            id: id as usize,
        }
    }
}

impl NodeLink for SimNodeLink {
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        let mut s = self.star.borrow_mut();
        if s.is_dead(self.id) {
            return Ok(());
        }
        if s.nodes[self.id].tx.is_some() {
            return Err(LinkError::Busy);
        }
        s.nodes[self.id].tx = Some(frame.to_vec());
        s.touch();
        Ok(())
    }

    async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
        let (exchanged, frame) = PollFn(|| {
            let mut s = self.star.borrow_mut();
            s.settle();
            if s.is_dead(self.id) {
                return None;
            }
            let got = s.nodes[self.id].inbox.pop_front();
            if got.is_some() {
                s.touch();
            }
            got
        })
        .await;
        let len = frame.len();
        let max = rx.len() as u32;
        let dst = rx.get_mut(..len).ok_or(LinkError::TooLong {
            len: len as u32,
            max,
        })?;
        dst.copy_from_slice(&frame);
        Ok(if exchanged {
            Incoming::Exchanged { len }
        } else {
            Incoming::Broadcast { len }
        })
    }
}

/// The RC's end of one bus, with its two TX banks.
pub struct SimBus {
    star: SharedStar,
    clock: SharedClock,
    bus: usize,
    banks: [Vec<u8>; 2],
    idle: usize,
}

impl SimBus {
    pub fn new(star: &SharedStar, bus: usize) -> Self {
        let clock = star.borrow().clock.clone();
        Self {
            star: star.clone(),
            clock,
            bus,
            banks: [vec![0; MAX_MESSAGE], vec![0; MAX_MESSAGE]],
            idle: 0,
        }
    }

    /// Claim the bus for a transfer of `body` bytes to `node` (an exchange) or every node
    /// (`None`, a broadcast), starting no earlier than `ready`; returns its end time.
    fn claim(&self, body: usize, node: Option<NodeId>, ready: Ps) -> Ps {
        let mut s = self.star.borrow_mut();
        let now = self.clock.borrow().now;
        let exchange = node.is_some();
        let d = s.timing.duration_ps(body, exchange);
        let clocked = s.timing.clocked_bytes(body, exchange);
        let b = &mut s.buses[self.bus];
        let start = now.max(b.busy_until).max(ready);
        b.busy_until = start + d;
        b.counters.busy_ps += d;
        b.counters.clocked_bytes += clocked;
        s.log_transfer(self.bus, node, start, start + d);
        start + d
    }
}

impl RootBus for SimBus {
    fn nodes(&self) -> (NodeId, u16) {
        let s = self.star.borrow();
        (s.buses[self.bus].first, s.buses[self.bus].count)
    }

    fn ready(&self) -> Option<NodeId> {
        let s = self.star.borrow();
        let b = &s.buses[self.bus];
        (0..b.count)
            .map(|i| b.first + (b.next_scan + i) % b.count)
            .find(|&n| s.nodes[n as usize].tx.is_some() && !s.is_dead(n as usize))
    }

    async fn wait_ready(&mut self) -> NodeId {
        PollFn(|| self.ready()).await
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        &mut self.banks[self.idle]
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        let max = MAX_MESSAGE as u32;
        let down = self.banks[self.idle]
            .get(..len)
            .ok_or(LinkError::TooLong {
                len: len as u32,
                max,
            })?
            .to_vec();
        let (node, up) = {
            let mut s = self.star.borrow_mut();
            if s.buses[self.bus].inflight.is_some() {
                return Err(LinkError::Busy);
            }
            match transfer {
                Transfer::Exchange(node) => {
                    let b = &mut s.buses[self.bus];
                    let (first, count) = (b.first, b.count);
                    if node < first || node >= first + count {
                        return Err(LinkError::NoSuchNode { node });
                    }
                    // Chip-select asserted: the node's TX bank is committed to this transfer.
                    b.next_scan = (node - first + 1) % count;
                    let up = s.nodes[node as usize].tx.take().ok_or(LinkError::Aborted)?;
                    (Some(node), up)
                }
                Transfer::Broadcast => (None, Vec::new()),
            }
        };
        // Under a relay tree a scene piece goes out once it has reached this leaf relay.
        let now = self.clock.borrow().now;
        let ready = match (&mut self.star.borrow_mut().relays, node) {
            (Some(r), None) => r.broadcast_ready(self.bus, &down, now),
            _ => now,
        };
        let end = self.claim(down.len().max(up.len()), node, ready);
        self.clock.borrow_mut().at(end);
        let mut s = self.star.borrow_mut();
        s.buses[self.bus].inflight = Some(Inflight {
            end,
            node,
            down,
            up,
            delivered: false,
        });
        s.touch();
        self.idle ^= 1;
        Ok(())
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        let bus = self.bus;
        let star = self.star.clone();
        let t = PollFn(|| {
            let mut s = star.borrow_mut();
            s.settle();
            let b = &mut s.buses[bus];
            match &b.inflight {
                None => Some(None),
                Some(t) if t.delivered => Some(b.inflight.take()),
                Some(_) => None,
            }
        })
        .await
        .ok_or(LinkError::Aborted)?;
        self.star.borrow_mut().touch();
        let max = rx.len() as u32;
        let dst = rx.get_mut(..t.up.len()).ok_or(LinkError::TooLong {
            len: t.up.len() as u32,
            max,
        })?;
        dst.copy_from_slice(&t.up);
        Ok(t.up.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The generator flips each bit independently at the rate: over 8 million bits at 1e-3
    /// about 8,000 flips (the Poisson spread is ~90), spread over every bit position, and the
    /// same seed flips the same bits.
    #[test]
    fn bit_errors_come_at_the_rate_and_are_deterministic() {
        let noise = Noise {
            ber_down: 1e-3,
            ber_up: 0.0,
            drop_broadcast: 0.0,
            seed: 42,
        };
        let run = || {
            let mut g = NoiseGen::new(noise);
            let (mut flips, mut hit, mut header) = (0u64, 0u32, 0u32);
            let mut per_bit = [0u32; 8];
            let mut first = Vec::new();
            for i in 0..1000 {
                let mut f = vec![0u8; 996];
                match g.corrupt(0, 4, &mut f) {
                    Hit::None => {}
                    Hit::Bits => hit += 1,
                    Hit::Header => {
                        hit += 1;
                        header += 1;
                    }
                }
                let ones: u32 = f.iter().map(|b| b.count_ones()).sum();
                flips += ones as u64;
                for b in &f {
                    for (k, c) in per_bit.iter_mut().enumerate() {
                        *c += (b >> k) as u32 & 1;
                    }
                }
                if i == 0 {
                    first = f.clone();
                }
                // The up direction has rate 0: never touched.
                let mut u = vec![0u8; 100];
                assert_eq!(g.corrupt(1, 4, &mut u), Hit::None);
            }
            (flips, hit, per_bit, first, header)
        };
        let (flips, hit, per_bit, first, header) = run();
        // 1000 frames x 996 bytes x 8 bits x 1e-3 = 7968 expected errors in the frames, and
        // 1000 x 32 x 1e-3 = 32 header bits hit (1 - e^-0.032 of the frames, ~31).
        assert!((7680..=8260).contains(&flips), "{flips}");
        assert!((15..=50).contains(&header), "{header}");
        // A frame of 8000 bits escapes with probability e^-8: essentially every one is hit.
        assert!(hit >= 998, "{hit}");
        assert!(
            per_bit.iter().all(|&c| (850..=1150).contains(&c)),
            "{per_bit:?}"
        );
        assert_eq!(run().3, first);
        assert_eq!((run().0, run().4), (flips, header));
    }

    #[test]
    fn lost_broadcasts_come_at_the_rate_and_rates_are_checked() {
        let mut g = NoiseGen::new(Noise {
            drop_broadcast: 0.25,
            seed: 3,
            ..Noise::default()
        });
        let lost = (0..10_000).filter(|_| g.drop_broadcast()).count();
        assert!((2350..=2650).contains(&lost), "{lost}");
        let mut none = NoiseGen::new(Noise::default());
        assert!(!(0..1000).any(|_| none.drop_broadcast()));
        let mut f = [0u8; 64];
        assert!(none.corrupt(0, 4, &mut f) == Hit::None && f == [0u8; 64]);
        assert!(Noise::default().check().is_ok());
        for bad in [
            Noise {
                ber_up: 0.6,
                ..Noise::default()
            },
            Noise {
                ber_down: -1e-3,
                ..Noise::default()
            },
            Noise {
                drop_broadcast: 1.0,
                ..Noise::default()
            },
            Noise {
                ber_down: f64::NAN,
                ..Noise::default()
            },
        ] {
            assert!(bad.check().is_err(), "{bad:?}");
        }
    }
}
