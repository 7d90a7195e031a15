//! The root's end of a relay tree: [`RelayedBus`], the [`RootBus`] of the nodes behind the
//! relays on one link.

use super::batch::{forward, parse, BatchWriter, Kind, Record, Relayed};
use super::{RelayError, CAST_WAIT_US, MAX_RELAY_NODES, MAX_ROUTED};
use crate::cluster::link::{LinkError, NodeId, RootBus, Transfer};
use crate::cluster::root::{NoClock, RootClock};
use crate::cluster::wire::{self, Down, MAX_MESSAGE};
use core::task::Poll;
use embassy_futures::poll_once;
use embassy_futures::select::{select, Either};

/// Most relays on one link: a bus drives 8 devices on every board (the profiles'
/// `nodes_per_bus`, checked by a test), and the root of relays keeps this much per relay
/// per link in its CCM.
pub const MAX_RELAYS: usize = 8;

/// Most node exchanges a [`RelayedBus`] keeps in flight at once unless told otherwise
/// ([`RelayedBus::with_slots`]; each holds a reply cell of [`RelayedBuffers`], or a frame
/// buffer, until its reply is down and, unless it went ahead, the node's frame is back).
pub const SLOTS: usize = 16;

/// Reply cells, and node exchanges in flight, on each link when the root drives its relays
/// on two links ([`super::TwoLinks`], each link's buffers `RelayedFrames<TWO_LINK_SLOTS>`):
/// four leaf relays of a one-level tree use 8 of them, at [`DEPTH`]. Under two levels the
/// link keeps [`TWO_LEVEL_SLOTS`] exchanges, most of them ahead and holding no cell.
pub const TWO_LINK_SLOTS: usize = 32;

/// Node exchanges in flight per middle relay at the root of two levels (`rc-fw --features
/// relay-root-mid`, and the simulator's): one for each of a middle relay's 32 nodes, since
/// their replies go ahead ([`RelayedBus::with_ahead`]) and wait at the leaf relays while
/// the nodes render (8 before replies went ahead: 2 on each of its 4 leaf buses).
pub const MID_DEPTH: u16 = MAX_RELAY_NODES;

/// Node exchanges in flight on each of the two links of the root of two levels: one for
/// every node behind its 4 middle relays ([`MID_DEPTH`] each).
pub const TWO_LEVEL_SLOTS: usize = MAX_RELAYS / 2 * MAX_RELAY_NODES as usize;

/// Node exchanges in flight at a middle relay ([`RelayedBus`] over its leaf relays, with
/// replies ahead): one for each of the nodes behind it.
pub const MID_SLOTS: usize = MAX_RELAY_NODES as usize;

/// Bytes of a reply kept in its exchange's own cell: the longest job hand-out (`Down::Work`
/// with its two jobs, envelope and CRC: at most 56 bytes, a test checks it) fits; a longer reply (a
/// scene repair) waits in a full frame buffer.
pub const REPLY_CELL: usize = 64;

/// Full frame buffers of a [`RelayedBus`]: one to compose in, one for the broadcast waiting
/// to go, two for replies longer than a cell (one at a time is let begin, so a broadcast
/// always finds a buffer).
pub const FRAMES: usize = 4;

/// Relay batches a [`RelayedBus`] keeps while the root logic has not taken every node frame
/// in them (the next exchange lands in a free one; none free, the link waits), unless its
/// buffers say otherwise ([`RelayedFrames`]'s second parameter): a middle relay's.
pub const LANDINGS: usize = 4;

/// Relay batches kept on each of the root's two links ([`super::TwoLinks`]): its CPU takes
/// the node frames of 4 middle relays, and with [`LANDINGS`] the link waited for it (256
/// nodes, steady: 200.91x with 4, 209.64x with 5, 209.28x with 6, 212.05x with 8; the
/// middle relays gain nothing from more than 4).
pub const TWO_LINK_LANDINGS: usize = 5;

/// Most relay batches a [`RelayedBus`] keeps.
pub const MAX_LANDINGS: usize = 8;

/// Node exchanges in flight per relay unless told otherwise ([`RelayedBus::with_depth`]):
/// one being clocked on the relay's bus, one more whose reply is already down (or goes
/// down in the exchange that brings the first one's frame up).
pub const DEPTH: u16 = 2;

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
    /// The most node exchanges that were in flight at once.
    pub most_in_flight: u32,
    /// Node exchanges begun ahead of the node's line ([`RelayedBus::with_ahead`]).
    pub ahead: u32,
    /// Of those, the ones whose reply never reached the relay: ended empty (the node,
    /// waiting there, was composed a new one).
    pub lost_ahead: u32,
}

/// The buffers of a [`RelayedBus`] with up to `CELLS` node exchanges in flight (the
/// firmware places them in SRAM beside the scene, since all-zero bytes are a valid value):
/// a reply cell per exchange, [`FRAMES`] full frame buffers, [`LANDINGS`] relay batches.
/// Replies are short and a batch carries several node frames, so an exchange costs
/// [`REPLY_CELL`] bytes, not a frame buffer of its own (`RelayedFrames<32, 5>`: 16,232
/// bytes, against 55,160 with a frame buffer per exchange).
pub struct RelayedFrames<const CELLS: usize, const LANDS: usize = LANDINGS> {
    /// Replies waiting to go down (any free cell; an exchange holds its cell until its
    /// frame is up, or, a reply ahead, until it is down).
    pub cells: [[u8; REPLY_CELL]; CELLS],
    /// One to compose the next frame in, one for the broadcast waiting to go, and the
    /// replies longer than a cell.
    pub frames: [[u8; MAX_MESSAGE]; FRAMES],
    /// What the link's relay exchanges brought: each kept until the root logic has taken
    /// its last node frame.
    pub landings: [[u8; MAX_MESSAGE]; LANDS],
}

/// The buffers of a [`RelayedBus`] with [`SLOTS`] node exchanges in flight (13,632 bytes;
/// 29,944 while each exchange kept a frame buffer).
pub type RelayedBuffers = RelayedFrames<SLOTS>;

impl<const CELLS: usize, const LANDS: usize> RelayedFrames<CELLS, LANDS> {
    pub const fn new() -> Self {
        RelayedFrames {
            cells: [[0; REPLY_CELL]; CELLS],
            frames: [[0; MAX_MESSAGE]; FRAMES],
            landings: [[0; MAX_MESSAGE]; LANDS],
        }
    }
}

impl<const CELLS: usize, const LANDS: usize> Default for RelayedFrames<CELLS, LANDS> {
    fn default() -> Self {
        Self::new()
    }
}

/// Where an exchange's reply waits to go down.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reply {
    /// In cell `n`.
    Cell(u8),
    /// In frame buffer `n` (longer than a cell).
    Frame(u8),
    /// Down and let go: a reply sent ahead of its node's line waits at the relay, and its
    /// buffer here serves the next (lost on the way, the exchange ends empty and the root
    /// logic composes the node a new one).
    Gone,
}

/// Where a node exchange in flight is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    /// The reply (`len` bytes) waits to go down (`sent_in` None), or went down in the
    /// relay's exchange number `sent_in` ([`RelayedBus`]'s `gathers`); it goes down again
    /// when a batch of a later exchange still reports the node waiting (the relay never
    /// got it). Given up at its slot's `deadline` (with a time-out). `ahead`: begun before
    /// the node's line rose ([`RelayedBus::with_ahead`]).
    Asked {
        reply: Reply,
        len: u16,
        sent_in: Option<u16>,
        ahead: bool,
    },
    /// The node's frame is `len` bytes at `at` in landing buffer `landing`.
    Answered { landing: u8, at: u16, len: u16 },
    /// A reply sent ahead never reached the relay (its node waits there unasked): the
    /// exchange ends empty.
    Lost,
}

/// A node exchange in flight: the node, its stage, when it is given up (µs, with a
/// time-out; beside the stage, not in it, so a slot takes 24 bytes, not 32).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Slot {
    deadline: u64,
    node: NodeId,
    stage: Stage,
}

const _: () = assert!(core::mem::size_of::<Option<Slot>>() <= 24);

/// An operation on the root's link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LinkOp {
    /// An exchange with relay `r`: the requests for its nodes down, its batch up.
    Gather(u16),
    /// The pending root broadcast.
    Broadcast,
}

/// The root broadcast started and not yet taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Cast {
    /// In frame buffer `buf` (`len` bytes): it goes on the link in `finish` (as the link's
    /// own broadcasts end there; the relays forward each one on their buses before they can
    /// take the next, two at most, so the root does not send them back to back).
    Queued { buf: u8, len: usize },
    /// On the link.
    OnLink,
    /// Off the link, with how it went.
    Done(Result<(), LinkError>),
}

/// Where link operation `op` lands: a relay exchange's batch in landing buffer `landing`; a
/// broadcast brings nothing.
fn landing_of(landings: &mut [[u8; MAX_MESSAGE]], landing: u8, op: LinkOp) -> &mut [u8] {
    match op {
        LinkOp::Gather(_) => landings
            .get_mut(landing as usize)
            .map_or(&mut [][..], |l| &mut l[..]),
        LinkOp::Broadcast => &mut [],
    }
}

/// The nodes behind `relays` relays on `link` (relay `r` is the link's node `link_first +
/// r`; its nodes are `first + r * per_relay ..`), as one [`RootBus`] for `run_bus`, with
/// up to [`DEPTH`] node exchanges in flight per relay ([`RootBus::in_flight`]).
///
/// `link`'s `finish` must be safe to drop while awaited (a relay exchange is started and
/// finished inside `wait_ready`, which `run_bus` races against its timers): the split link
/// ([`crate::spi::MasterFront`]) is; a dropped exchange is taken before the next one.
pub struct RelayedBus<'m, L, C = NoClock, const S: usize = SLOTS> {
    link: L,
    /// The buffers ([`RelayedFrames`]).
    cells: &'m mut [[u8; REPLY_CELL]],
    frames: &'m mut [[u8; MAX_MESSAGE]; FRAMES],
    landings: &'m mut [[u8; MAX_MESSAGE]],
    /// Per landing buffer: node frames in it the root logic has not taken.
    held: [u16; MAX_LANDINGS],
    /// The landing buffer the relay exchange in flight lands in.
    landing: u8,
    /// Node exchanges in flight at most, over all relays (`S`; each holds a cell, or a
    /// frame buffer, until its reply is down and, unless it went ahead, its frame up).
    slot_count: u16,
    /// How long a node exchange may wait for its frame (µs; 0: for ever), by `clock`.
    clock: C,
    timeout_us: u64,
    /// How long an exchange begun ahead of its node's line may wait (µs; 0: none begun
    /// ahead, [`RelayedBus::with_ahead`]).
    ahead_us: u64,
    first: NodeId,
    per_relay: u16,
    relays: u16,
    /// Most node exchanges in flight per relay.
    depth: u16,
    /// Per relay: its nodes waiting to be asked, as it last reported (bit `i`: its `i`-th).
    waiting: [u32; MAX_RELAYS],
    /// Per relay: the number of the last exchange with it (wrapping), so a batch is judged
    /// against the requests that went down before it was composed.
    gathers: [u16; MAX_RELAYS],
    /// The node exchanges in flight.
    slots: [Option<Slot>; S],
    /// The frame buffer the next reply is composed in (no slot's).
    compose: u8,
    cast: Option<Cast>,
    /// The link operation started and not yet taken.
    dangling: Option<LinkOp>,
    next_scan: u16,
    /// Where the next scan of the relays for a link exchange starts (round the link).
    next_link: u16,
    /// Broadcasts put on the link in this run (until `Stop`), and per relay how many it
    /// reported passed on to its bus ([`Kind::Forwarded`]): the next broadcast waits until
    /// every relay has passed on all but one (a relay has two receive banks).
    casts: u16,
    acked: [u16; MAX_RELAYS],
    /// Relays that did not report within the time-out while a broadcast waited for them
    /// (bit `r`; no longer waited for until they report again).
    deaf: u32,
    /// When a broadcast waiting for the relays' reports goes anyway (µs).
    cast_until: Option<u64>,
    pub counters: RelayedCounters,
}

impl<'m, L: RootBus> RelayedBus<'m, L> {
    /// The nodes `first..first + relays * per_relay` behind every relay on `link`, with
    /// `CELLS` node exchanges in flight at most (at most [`SLOTS`] before
    /// [`RelayedBus::with_slots`]).
    pub fn new<const CELLS: usize, const LANDS: usize>(
        link: L,
        buf: &'m mut RelayedFrames<CELLS, LANDS>,
        first: NodeId,
        per_relay: u16,
    ) -> Result<Self, RelayError> {
        const {
            assert!(CELLS >= 1, "a relayed bus needs a reply cell");
            assert!(
                CELLS <= 64,
                "a relayed bus keeps at most 64 reply cells (a bitmap)"
            );
            assert!(
                LANDS >= 2 && LANDS <= MAX_LANDINGS,
                "a relayed bus keeps 2 to MAX_LANDINGS relay batches"
            );
        };
        let slot_count = SLOTS as u16;
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
        let RelayedFrames {
            cells,
            frames,
            landings,
        } = buf;
        Ok(RelayedBus {
            link,
            cells,
            frames,
            landings,
            held: [0; MAX_LANDINGS],
            landing: 0,
            slot_count,
            clock: NoClock,
            timeout_us: 0,
            ahead_us: 0,
            first,
            per_relay,
            relays,
            depth: DEPTH,
            waiting: [0; MAX_RELAYS],
            gathers: [0; MAX_RELAYS],
            slots: [None; SLOTS],
            compose: 0,
            cast: None,
            dangling: None,
            next_scan: 0,
            next_link: 0,
            casts: 0,
            acked: [0; MAX_RELAYS],
            deaf: 0,
            cast_until: None,
            counters: RelayedCounters::default(),
        })
    }

    /// The same bus keeping state for `T` node exchanges in flight instead of [`SLOTS`]
    /// (each also needs a free reply cell to begin, unless its reply is longer than one):
    /// the root of relays on two links keeps [`TWO_LINK_SLOTS`] on each, or
    /// [`TWO_LEVEL_SLOTS`] under two levels. Before the first exchange (it starts with none
    /// in flight).
    pub fn with_slots<const T: usize>(self) -> RelayedBus<'m, L, NoClock, T> {
        let timeout_us = self.timeout_us;
        self.rebuilt(NoClock, timeout_us, [None; T])
    }
}

impl<'m, L: RootBus, const S: usize> RelayedBus<'m, L, NoClock, S> {
    /// Give a node exchange up after `timeout_us` of `clock` without its frame: it ends
    /// with an empty frame (counted in `timeouts`), so a relay that stopped answering costs
    /// the root its nodes (their jobs time out and go elsewhere), not its bus. Without it an
    /// exchange waits for ever.
    pub fn with_timeout<C: RootClock>(self, clock: C, timeout_us: u64) -> RelayedBus<'m, L, C, S> {
        let slots = self.slots;
        self.rebuilt(clock, timeout_us, slots)
    }
}

impl<'m, L, C, const S: usize> RelayedBus<'m, L, C, S> {
    /// This bus with another clock, time-out and slot table (its slots bound by the table's
    /// length).
    fn rebuilt<C2, const T: usize>(
        self,
        clock: C2,
        timeout_us: u64,
        slots: [Option<Slot>; T],
    ) -> RelayedBus<'m, L, C2, T> {
        let slot_count = T as u16;
        RelayedBus {
            link: self.link,
            cells: self.cells,
            frames: self.frames,
            landings: self.landings,
            held: self.held,
            landing: self.landing,
            slot_count,
            clock,
            timeout_us,
            ahead_us: self.ahead_us,
            first: self.first,
            per_relay: self.per_relay,
            relays: self.relays,
            depth: self.depth,
            waiting: self.waiting,
            gathers: self.gathers,
            slots,
            compose: self.compose,
            cast: self.cast,
            dangling: self.dangling,
            next_scan: self.next_scan,
            next_link: self.next_link,
            casts: self.casts,
            acked: self.acked,
            deaf: self.deaf,
            cast_until: self.cast_until,
            counters: self.counters,
        }
    }
}

impl<L: RootBus, C: RootClock, const S: usize> RelayedBus<'_, L, C, S> {
    pub fn link(&self) -> &L {
        &self.link
    }

    /// At most `depth` node exchanges in flight per relay (1 to the buffers' slots;
    /// [`DEPTH`] unless told).
    pub fn with_depth(mut self, depth: u16) -> Self {
        self.depth = depth.clamp(1, self.slot_count);
        self
    }

    /// Let the root logic begin an exchange with a node whose line is not up
    /// ([`RootBus::ask_ahead`]): its reply goes down to its relay, which clocks the node the
    /// moment its line rises. Such an exchange waits up to `ahead_us` for the node's frame
    /// (a node renders a run meanwhile) besides the time-out. The relays below must hold
    /// replies ahead (leaf relays: [`super::RelayBuffers`]' `ahead` cells).
    pub fn with_ahead(mut self, ahead_us: u64) -> Self {
        self.ahead_us = ahead_us;
        self
    }

    /// Whether an exchange with `node` may begin now whether or not it waits: none in
    /// flight with it, its relay below `depth`, room ([`RelayedBus::has_room`]), no
    /// broadcast queued.
    fn may_begin(&self, node: NodeId) -> bool {
        self.cast.is_none()
            && self.has_room()
            && self.slot_of(node).is_none()
            && self
                .place(node)
                .is_some_and(|(r, _)| self.on_relay(r).0 < self.depth)
    }

    /// Relay index and bit of `node`.
    fn place(&self, node: NodeId) -> Option<(u16, u32)> {
        let k = node.checked_sub(self.first)?;
        let (r, i) = (k / self.per_relay.max(1), k % self.per_relay.max(1));
        (r < self.relays).then_some((r, 1u32 << i))
    }

    fn relay_of(&self, node: NodeId) -> Option<u16> {
        self.place(node).map(|(r, _)| r)
    }

    /// A reply cell no exchange holds.
    /// (The lowest: one pass over the slots, on every `ready`, `ask_ahead` and `start`.)
    fn free_cell(&self) -> Option<u8> {
        let taken = self
            .slots
            .iter()
            .flatten()
            .fold(0u64, |m, s| match s.stage {
                Stage::Asked {
                    reply: Reply::Cell(c),
                    ..
                } => m | 1u64.checked_shl(c as u32).unwrap_or(0),
                _ => m,
            });
        let c = (!taken).trailing_zeros() as usize;
        (c < self.cells.len()).then_some(c as u8)
    }

    /// Room for one more exchange: a slot, a reply cell, and frame buffers enough for a
    /// reply longer than a cell while one is left for a broadcast (the one composed in,
    /// and two more).
    fn has_room(&self) -> bool {
        self.free_slot().is_some() && self.free_cell().is_some() && self.untaken_frames() >= 3
    }

    /// A slot no exchange holds, among the buffers' `slot_count`.
    fn free_slot(&self) -> Option<usize> {
        self.slots
            .iter()
            .take(self.slot_count as usize)
            .position(Option::is_none)
    }

    /// The slot of `node`'s exchange in flight.
    fn slot_of(&self, node: NodeId) -> Option<usize> {
        self.slots
            .iter()
            .position(|s| s.is_some_and(|s| s.node == node))
    }

    /// Node exchanges in flight through relay `r`, and whether one waits to go down for the
    /// first time, or to come up.
    fn on_relay(&self, r: u16) -> (u16, bool, bool) {
        let (mut n, mut unsent, mut asked) = (0, false, false);
        for s in self.slots.iter().flatten() {
            if self.relay_of(s.node) == Some(r) {
                n += 1;
                if let Stage::Asked { sent_in, .. } = s.stage {
                    unsent |= sent_in.is_none();
                    asked |= sent_in.is_some();
                }
            }
        }
        (n, unsent, asked)
    }

    /// Bits of relay `r`'s nodes with an exchange in flight.
    fn busy_bits(&self, r: u16) -> u32 {
        self.slots
            .iter()
            .flatten()
            .filter_map(|s| self.place(s.node))
            .filter(|&(q, _)| q == r)
            .fold(0, |m, (_, b)| m | b)
    }

    /// Whether frame buffer `b` is taken: by the broadcast waiting to go, or by a reply
    /// longer than a cell waiting to go down.
    fn frame_taken(&self, b: u8) -> bool {
        matches!(self.cast, Some(Cast::Queued { buf, .. }) if buf == b)
            || self
                .slots
                .iter()
                .flatten()
                .any(|s| matches!(s.stage, Stage::Asked { reply: Reply::Frame(f), .. } if f == b))
    }

    /// Frame buffers not taken (the one composed in among them).
    fn untaken_frames(&self) -> usize {
        (0..FRAMES as u8).filter(|&b| !self.frame_taken(b)).count()
    }

    /// A landing buffer the next relay exchange may land in: none of its node frames
    /// waiting for the root logic, not the one an exchange in flight lands in.
    fn free_landing(&self) -> Option<u8> {
        (0..self.landings.len() as u8).find(|&l| {
            self.held[l as usize] == 0
                && !(matches!(self.dangling, Some(LinkOp::Gather(_))) && l == self.landing)
        })
    }

    /// A node an exchange may begin with now: waiting, none in flight with it, its relay
    /// below `depth`, a slot free, and frame buffers enough for a reply longer than a cell
    /// while one is left for a broadcast (the one composed in, and two more).
    fn ready_in(&self) -> Option<NodeId> {
        if !self.has_room() {
            return None;
        }
        let total = self.relays * self.per_relay;
        (0..total)
            .map(|k| (self.next_scan + k) % total)
            .map(|k| self.first + k)
            .find(|&n| {
                self.place(n).is_some_and(|(r, b)| {
                    self.waiting[r as usize] & b != 0
                        && self.busy_bits(r) & b == 0
                        && self.on_relay(r).0 < self.depth
                })
            })
    }

    /// The node exchanges in flight that have ended: their frame is here, or their time is
    /// up.
    fn ended(&self) -> impl Iterator<Item = &Slot> {
        let now = (self.timeout_us > 0).then(|| self.clock.now_us());
        self.slots.iter().flatten().filter(move |s| match s.stage {
            Stage::Answered { .. } | Stage::Lost => true,
            Stage::Asked { .. } => now.is_some_and(|t| t >= s.deadline),
        })
    }

    /// A node exchange that has ended.
    fn arrived_in(&self) -> Option<NodeId> {
        self.ended().next().map(|s| s.node)
    }

    /// How many exchanges in flight have ended.
    fn ended_count(&self) -> usize {
        self.ended().count()
    }

    /// The earliest time-out of an exchange in flight, or of a broadcast waiting for the
    /// relays' reports.
    fn deadline(&self) -> Option<u64> {
        self.deadline_after(0)
    }

    /// The earliest of those time-outs after `t`.
    fn deadline_after(&self, t: u64) -> Option<u64> {
        if self.timeout_us == 0 {
            return None;
        }
        self.slots
            .iter()
            .flatten()
            .filter_map(|s| match s.stage {
                Stage::Asked { .. } => Some(s.deadline),
                Stage::Answered { .. } | Stage::Lost => None,
            })
            .chain(self.cast_until)
            .filter(|&d| d > t)
            .min()
    }

    /// Whether relay `r` has not reported passing on all but the last broadcast (and is
    /// waited for).
    fn lags(&self, r: u16) -> bool {
        self.deaf & (1u32 << (r as u32 % 32)) == 0
            && self.casts.wrapping_sub(self.acked[r as usize % MAX_RELAYS]) > 1
    }

    /// The link operation worth starting now, if the link is free: the pending broadcast;
    /// else, round the link from `next_link`, a relay whose line is up that (1) has a reply
    /// to take down for the first time, or else (2) has one down whose frame may be up, or
    /// has no exchange in flight and no waiting node the root knows of (it has news). The
    /// two of (2) take turns: a relay whose frames may be up keeps its line up (it reports
    /// its other nodes waiting) for as long as its exchange takes below it, so ranking it
    /// first would never gather a relay with news, and the root would never learn of that
    /// relay's waiting nodes.
    fn pick(&self) -> Option<LinkOp> {
        if self.dangling.is_some() {
            return None;
        }
        if self.cast == Some(Cast::OnLink) {
            return None;
        }
        // Every relay exchange may bring node frames: it needs a landing buffer.
        self.free_landing()?;
        let (link_first, _) = self.link.nodes();
        let relays = self.relays.max(1);
        let mut best: Option<(u8, u16)> = None;
        for k in 0..relays {
            let r = (self.next_link + k) % relays;
            if !self.link.line(link_first.wrapping_add(r)) {
                continue;
            }
            let (n, unsent, asked) = self.on_relay(r);
            let lagging = matches!(self.cast, Some(Cast::Queued { .. })) && self.lags(r);
            let class = if unsent || lagging {
                0
            } else if asked || (n == 0 && self.waiting[r as usize] == 0) {
                1
            } else {
                continue;
            };
            if best.is_none_or(|(c, _)| class < c) {
                best = Some((class, r));
            }
        }
        best.map(|(_, r)| LinkOp::Gather(r))
    }

    /// Start `op` on the link.
    fn begin(&mut self, op: LinkOp) -> Result<(), LinkError> {
        let (link_first, _) = self.link.nodes();
        match op {
            LinkOp::Broadcast => {
                if let Some(Cast::Queued { buf, len }) = self.cast {
                    let frame = self.frames[buf as usize].get(..len).unwrap_or(&[]);
                    let n =
                        forward(frame, self.link.tx_bank()).map_err(|_| LinkError::TooLong {
                            len: len as u32 + 1,
                            max: MAX_MESSAGE as u32,
                        })?;
                    let stop = matches!(wire::decode::<Down>(frame).map(|e| e.msg), Ok(Down::Stop));
                    self.link.start(Transfer::Broadcast, n)?;
                    self.cast = Some(Cast::OnLink);
                    self.dangling = Some(LinkOp::Broadcast);
                    self.casts = self.casts.wrapping_add(1);
                    if stop {
                        // The relays end with it; the next run counts from 0 again.
                        self.casts = 0;
                        self.acked = [0; MAX_RELAYS];
                        self.deaf = 0;
                    }
                }
                Ok(())
            }
            LinkOp::Gather(r) => {
                // Every reply for the relay's nodes not yet down (or lost on the way: see
                // `apply`), as many as fit. One the relay got is not sent again: the
                // relay's batches stop reporting its node waiting.
                let (first, per) = (self.first, self.per_relay.max(1));
                let base = first.wrapping_add(r.wrapping_mul(per));
                let landing = self.free_landing().ok_or(LinkError::Busy)?;
                let mut w =
                    BatchWriter::new(self.link.tx_bank()).map_err(|_| LinkError::Aborted)?;
                let mut carried = [false; S];
                let mut requests = 0u32;
                for (i, s) in self.slots.iter().enumerate() {
                    let Some(Slot {
                        node,
                        stage:
                            Stage::Asked {
                                reply,
                                len,
                                sent_in: None,
                                ahead,
                            },
                        ..
                    }) = *s
                    else {
                        continue;
                    };
                    let local = node.wrapping_sub(base);
                    if node < base || local >= per {
                        continue;
                    }
                    let data = match reply {
                        Reply::Cell(c) => self
                            .cells
                            .get(c as usize)
                            .and_then(|c| c.get(..len as usize)),
                        Reply::Frame(b) => self
                            .frames
                            .get(b as usize)
                            .and_then(|f| f.get(..len as usize)),
                        Reply::Gone => None,
                    }
                    .unwrap_or(&[]);
                    if w.push(Record {
                        kind: if ahead { Kind::Ahead } else { Kind::Request },
                        node: local,
                        data,
                    })
                    .is_ok()
                    {
                        carried[i] = true;
                        requests += 1;
                    }
                }
                let n = w.bytes().len();
                self.link
                    .start(Transfer::Exchange(link_first.wrapping_add(r)), n)?;
                let number = match self.gathers.get_mut(r as usize) {
                    Some(g) => {
                        *g = g.wrapping_add(1);
                        *g
                    }
                    None => 0,
                };
                for (s, c) in self.slots.iter_mut().zip(carried) {
                    if let Some(Slot {
                        stage:
                            Stage::Asked {
                                sent_in,
                                reply,
                                ahead,
                                ..
                            },
                        ..
                    }) = s
                    {
                        if c {
                            *sent_in = Some(number);
                            // A reply ahead waits at the relay: its buffer is let go.
                            if *ahead {
                                *reply = Reply::Gone;
                            }
                        }
                    }
                }
                self.dangling = Some(LinkOp::Gather(r));
                self.landing = landing;
                self.next_link = (r + 1) % self.relays.max(1);
                self.counters.link_exchanges += 1;
                self.counters.gathering += u32::from(requests == 0);
                Ok(())
            }
        }
    }

    /// What the link operation `op` ended with.
    fn landed(&mut self, op: LinkOp, got: Result<usize, LinkError>) -> Result<(), LinkError> {
        self.dangling = None;
        match op {
            LinkOp::Broadcast => {
                self.cast = Some(Cast::Done(got.map(|_| ())));
                Ok(())
            }
            LinkOp::Gather(r) => {
                self.apply(r, got?);
                Ok(())
            }
        }
    }

    /// Take the link operation in flight (if any), waiting for it.
    async fn settle(&mut self) -> Result<(), LinkError> {
        let Some(op) = self.dangling else {
            return Ok(());
        };
        let into = landing_of(self.landings, self.landing, op);
        let got = self.link.finish(into).await;
        self.landed(op, got)
    }

    /// One step of the link: take the operation in flight, or start the one worth
    /// starting, or wait for a relay's line (or the earliest time-out) and exchange with it.
    async fn pump(&mut self) -> Result<(), LinkError> {
        if self.dangling.is_some() {
            return self.settle().await;
        }
        if let Some(op) = self.pick() {
            return self.begin(op);
        }
        if self.free_landing().is_none() {
            // Every landing buffer holds node frames the root logic has not taken: nothing
            // can come up until it does, or a time-out still to come passes (one passed
            // already is the caller's to take: waiting for it again would spin).
            match self.deadline_after(self.clock.now_us()) {
                Some(t) => self.clock.at_us(t).await,
                None => core::future::pending::<()>().await,
            }
            return Ok(());
        }
        let relay = match self.deadline() {
            None => self.link.wait_ready().await,
            Some(t) => match select(self.link.wait_ready(), self.clock.at_us(t)).await {
                Either::First(relay) => relay,
                Either::Second(()) => return Ok(()),
            },
        };
        // Nothing better: gather from a relay whose line is up (it has news).
        let op = self
            .pick()
            .unwrap_or(LinkOp::Gather(relay.wrapping_sub(self.link.nodes().0)));
        self.begin(op)
    }

    /// Apply relay `r`'s batch (`got` bytes in `rx`): its waiting nodes, its node frames.
    fn apply(&mut self, r: u16, got: usize) {
        if got == 0 {
            // Nothing intact came up (the link asks again); keep what we knew.
            return;
        }
        // Records name a relay's nodes by their index on its bus.
        let per = self.per_relay;
        let base = self.first.wrapping_add(r.wrapping_mul(per));
        let landing = self.landing;
        let Some(rx) = self.landings.get(landing as usize) else {
            return;
        };
        let held = &mut self.held[landing as usize];
        let Ok(Relayed::Batch { waiting, records }) = parse(rx.get(..got).unwrap_or(&[])) else {
            self.counters.bad_batches += 1;
            return;
        };
        let mask = match per {
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
                }) if node < per => {
                    let node = base.wrapping_add(node);
                    let slot = self
                        .slots
                        .iter_mut()
                        .flatten()
                        .find(|s| s.node == node && matches!(s.stage, Stage::Asked { .. }));
                    match slot {
                        Some(s) => {
                            // The frame stays where it landed; its reply is no longer
                            // needed (a cell or frame buffer freed).
                            let at = data.as_ptr() as usize - rx.as_ptr() as usize;
                            s.stage = Stage::Answered {
                                landing,
                                at: at as u16,
                                len: data.len() as u16,
                            };
                            *held += 1;
                        }
                        None => self.counters.stray_frames += 1,
                    }
                }
                Ok(Record {
                    kind: Kind::Forwarded,
                    data: &[lo, hi],
                    ..
                }) => {
                    // (A count above ours is from an earlier run's batch: ignored.)
                    let done = u16::from_le_bytes([lo, hi]);
                    if let Some(a) = self.acked.get_mut(r as usize) {
                        if done <= self.casts {
                            *a = done;
                            self.deaf &= !(1u32 << (r as u32 % 32));
                        }
                    }
                }
                _ => self.counters.bad_batches += 1,
            }
        }
        // A request that went down before this batch was composed (an earlier exchange
        // with the relay) while the batch still reports its node waiting never reached
        // the relay (a damaged half, or the relay had no room for it): it goes down again.
        let number = self.gathers.get(r as usize).copied().unwrap_or(0);
        for s in self.slots.iter_mut().flatten() {
            let local = s.node.wrapping_sub(base);
            if s.node < base || local >= per || local >= MAX_RELAY_NODES {
                continue;
            }
            if let Stage::Asked { sent_in, reply, .. } = &mut s.stage {
                if sent_in.is_some_and(|k| k != number) && waiting & (1u32 << local) != 0 {
                    if *reply == Reply::Gone {
                        // A reply ahead, let go: the exchange ends empty; the node, waiting,
                        // is composed a new one.
                        s.stage = Stage::Lost;
                    } else {
                        *sent_in = None;
                    }
                }
            }
        }
    }
}

impl<L: RootBus, C: RootClock, const S: usize> RootBus for RelayedBus<'_, L, C, S> {
    fn nodes(&self) -> (NodeId, u16) {
        (self.first, self.relays * self.per_relay)
    }

    async fn wait_ready(&mut self) -> NodeId {
        loop {
            self.poll();
            if let Some(n) = self.arrived_in().or_else(|| self.ready_in()) {
                return n;
            }
            if self.pump().await.is_err() {
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

    fn ask_ahead(&self, node: NodeId) -> bool {
        self.ahead_us > 0 && self.may_begin(node)
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        &mut self.frames[self.compose as usize][..MAX_ROUTED]
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        if self.cast.is_some() {
            return Err(LinkError::Busy);
        }
        if len > MAX_ROUTED {
            return Err(LinkError::TooLong {
                len: len as u32,
                max: MAX_ROUTED as u32,
            });
        }
        match transfer {
            Transfer::Exchange(node) => {
                let (r, b) = self.place(node).ok_or(LinkError::NoSuchNode { node })?;
                let free = self.free_slot();
                let (Some(i), None) = (free, self.slot_of(node)) else {
                    return Err(LinkError::Busy);
                };
                if self.on_relay(r).0 >= self.depth {
                    return Err(LinkError::Busy);
                }
                // A reply longer than a cell keeps its frame buffer: it may, while that
                // leaves one for a broadcast besides the next to compose in.
                if len > REPLY_CELL && self.untaken_frames() < 3 {
                    return Err(LinkError::Busy);
                }
                let cell = self.free_cell().filter(|_| len <= REPLY_CELL);
                if len <= REPLY_CELL && cell.is_none() {
                    return Err(LinkError::Busy);
                }
                // Begun ahead of the node's line: it may wait while the node renders.
                let ahead = self.ahead_us > 0 && self.waiting[r as usize] & b == 0;
                self.waiting[r as usize] &= !b;
                self.next_scan = (node - self.first + 1) % (self.relays * self.per_relay);
                let wait = self.timeout_us + if ahead { self.ahead_us } else { 0 };
                let deadline = self.clock.now_us().saturating_add(wait);
                self.counters.ahead += u32::from(ahead);
                // A reply that fits its cell moves there; a longer one keeps its buffer.
                let composed = self
                    .frames
                    .get(self.compose as usize)
                    .and_then(|f| f.get(..len));
                let into = cell.and_then(|c| Some((c, self.cells.get_mut(c as usize)?)));
                let reply = match (composed, into) {
                    (Some(src), Some((c, cell))) => {
                        cell[..len].copy_from_slice(src);
                        Reply::Cell(c)
                    }
                    _ => Reply::Frame(self.compose),
                };
                self.slots[i] = Some(Slot {
                    node,
                    stage: Stage::Asked {
                        reply,
                        len: len as u16,
                        sent_in: None,
                        ahead,
                    },
                    deadline,
                });
                let busy = self.slots.iter().flatten().count() as u32;
                self.counters.most_in_flight = self.counters.most_in_flight.max(busy);
            }
            Transfer::Broadcast => {
                // (Always true: an exchange leaves two.)
                if self.untaken_frames() < 2 {
                    return Err(LinkError::Busy);
                }
                self.cast = Some(Cast::Queued {
                    buf: self.compose,
                    len,
                });
            }
        }
        // The next frame goes into a buffer no exchange or broadcast holds (one is left:
        // checked above).
        if let Some(b) = (0..FRAMES as u8).find(|&b| !self.frame_taken(b)) {
            self.compose = b;
        }
        // Put it on the link now if the link is free.
        self.poll();
        Ok(())
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        if self.cast.is_some() {
            loop {
                match self.cast {
                    Some(Cast::Done(res)) => {
                        self.cast = None;
                        return res.map(|()| 0);
                    }
                    Some(Cast::Queued { .. }) if self.dangling.is_none() => {
                        // Every relay must have passed on all but the last broadcast (it
                        // reports that in its batches); one that does not report within
                        // CAST_WAIT_US (a report lost to a bit error, a relay that stopped)
                        // is not waited for again until it reports. Without a time-out
                        // (no clock) broadcasts are not held back; nor while every landing
                        // holds node frames the root logic has not taken (no report can come
                        // up before it takes them: a relay that lags drops the broadcast,
                        // and its nodes have it repaired).
                        let stalled = self.free_landing().is_none();
                        if self.timeout_us == 0
                            || stalled
                            || (0..self.relays).all(|r| !self.lags(r))
                        {
                            self.cast_until = None;
                            self.begin(LinkOp::Broadcast)?;
                            continue;
                        }
                        let now = self.clock.now_us();
                        let wait = self.timeout_us.min(CAST_WAIT_US);
                        let until = *self.cast_until.get_or_insert(now.saturating_add(wait));
                        if now >= until {
                            for r in 0..self.relays {
                                if self.lags(r) {
                                    self.deaf |= 1u32 << (r as u32 % 32);
                                }
                            }
                            continue;
                        }
                        self.pump().await?
                    }
                    _ => self.settle().await?,
                }
            }
        }
        // The first exchange to end (not a chosen one: its frame may come after others
        // that fill the landings).
        loop {
            if let Some(node) = self.arrived_in() {
                return self.finish_node(node, rx).await;
            }
            if self.slots.iter().all(Option::is_none) {
                return Err(LinkError::Aborted);
            }
            self.pump().await?;
        }
    }

    fn in_flight(&self) -> u16 {
        self.depth
            .saturating_mul(self.relays)
            .clamp(1, self.slot_count)
    }

    fn arrived(&self) -> Option<NodeId> {
        self.arrived_in()
    }

    fn flying(&self) -> u16 {
        self.slots.iter().flatten().count() as u16
    }

    fn pending(&self) -> Option<NodeId> {
        self.slots.iter().flatten().map(|s| s.node).next()
    }

    async fn finish_node(&mut self, node: NodeId, rx: &mut [u8]) -> Result<usize, LinkError> {
        loop {
            let i = self.slot_of(node).ok_or(LinkError::Aborted)?;
            let Some(slot) = self.slots[i] else {
                return Err(LinkError::Aborted);
            };
            match slot.stage {
                Stage::Answered { landing, at, len } => {
                    self.slots[i] = None;
                    if let Some(h) = self.held.get_mut(landing as usize) {
                        *h = h.saturating_sub(1);
                    }
                    let (at, n) = (at as usize, len as usize);
                    let max = rx.len() as u32;
                    let dst = rx
                        .get_mut(..n)
                        .ok_or(LinkError::TooLong { len: n as u32, max })?;
                    let src = self
                        .landings
                        .get(landing as usize)
                        .and_then(|l| l.get(at..at + n))
                        .ok_or(LinkError::Aborted)?;
                    dst.copy_from_slice(src);
                    return Ok(n);
                }
                Stage::Lost => {
                    self.slots[i] = None;
                    self.counters.lost_ahead += 1;
                    return Ok(0);
                }
                Stage::Asked { .. }
                    if self.timeout_us > 0 && self.clock.now_us() >= slot.deadline =>
                {
                    self.slots[i] = None;
                    self.counters.timeouts += 1;
                    return Ok(0);
                }
                // Every landing holds frames of other exchanges: they are to be taken
                // first (`RootBus::arrived`), or this one could wait for ever.
                Stage::Asked { .. } if self.dangling.is_none() && self.free_landing().is_none() => {
                    return Err(LinkError::Busy)
                }
                Stage::Asked { .. } => self.pump().await?,
            }
        }
    }

    async fn wait_news(&mut self) {
        let known = self.waiting;
        let ended = self.ended_count();
        loop {
            self.poll();
            let fresh = self
                .waiting
                .iter()
                .zip(known)
                .any(|(&now, was)| now & !was != 0);
            if fresh || self.ended_count() > ended {
                return;
            }
            if self.pump().await.is_err() {
                self.dangling = None;
            }
        }
    }

    fn poll(&mut self) {
        if let Some(op) = self.dangling {
            let into = landing_of(self.landings, self.landing, op);
            match poll_once(self.link.finish(into)) {
                Poll::Pending => return,
                Poll::Ready(got) => {
                    // A failed relay exchange is asked again; a failed broadcast is
                    // `finish`'s to report.
                    let _ = self.landed(op, got);
                }
            }
        }
        if let Some(op) = self.pick() {
            // A failure leaves it to the next look.
            let _ = self.begin(op);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::cell::Cell;
    use core::task::Poll;
    use embassy_futures::block_on;

    /// Time that jumps to whatever is waited for.
    struct Jump(Cell<u64>);

    std::thread_local! {
        /// Waits on a `Jump` clock (a loop that waits for a time already passed spins).
        static WAITS: Cell<u32> = const { Cell::new(0) };
    }

    impl RootClock for &Jump {
        fn now_us(&self) -> u64 {
            self.0.get()
        }
        async fn at_us(&self, t: u64) {
            let waits = WAITS.with(|w| {
                w.set(w.get() + 1);
                w.get()
            });
            assert!(waits < 100_000, "waited for {t} µs {waits} times: a spin");
            self.0.set(self.0.get().max(t));
        }
    }

    /// A link to relays that answer each request in their next exchange with a two-byte
    /// frame (0xAA, the node's index on the relay); relays not `alive` never raise their
    /// line. Each transfer takes 50 µs of `clock`.
    struct Relays<'c> {
        clock: &'c Jump,
        alive: Vec<bool>,
        bank: [u8; MAX_MESSAGE],
        started: Option<(Transfer, usize)>,
        /// Per relay: the requests it has and will answer next time, and those it answered
        /// (a request seen again is dropped, as a relay does).
        owed: Vec<Vec<NodeId>>,
        done: Vec<Vec<NodeId>>,
        broadcasts: u32,
        /// Per relay: nodes it reports waiting until their request comes (bitmap).
        waits: Vec<u32>,
        /// Requests sent down (also in halves lost), per relay and node index.
        requests: Vec<[u32; 4]>,
        /// Down halves still to be lost (as to a bit error).
        lose_down: u32,
        /// Per relay and node index: the last request's bytes.
        got: Vec<[Vec<u8>; 4]>,
        /// (relay, node, exchanges): the node's frame comes up only after that many more
        /// exchanges with its relay.
        late: Vec<(usize, NodeId, u32)>,
    }

    impl<'c> Relays<'c> {
        fn new(clock: &'c Jump, alive: Vec<bool>) -> Self {
            let n = alive.len();
            Relays {
                clock,
                alive,
                bank: [0; MAX_MESSAGE],
                started: None,
                owed: vec![Vec::new(); n],
                done: vec![Vec::new(); n],
                broadcasts: 0,
                waits: vec![0; n],
                requests: vec![[0; 4]; n],
                lose_down: 0,
                got: vec![Default::default(); n],
                late: Vec::new(),
            }
        }
    }

    impl RootBus for Relays<'_> {
        fn nodes(&self) -> (NodeId, u16) {
            (0, self.alive.len() as u16)
        }
        async fn wait_ready(&mut self) -> NodeId {
            match self.alive.iter().position(|&a| a) {
                Some(r) => r as NodeId,
                None => core::future::pending().await,
            }
        }
        fn ready(&self) -> Option<NodeId> {
            self.alive.iter().position(|&a| a).map(|r| r as NodeId)
        }
        fn line(&self, node: NodeId) -> bool {
            self.alive.get(node as usize) == Some(&true)
        }
        fn tx_bank(&mut self) -> &mut [u8] {
            &mut self.bank
        }
        fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
            if self.started.replace((transfer, len)).is_some() {
                return Err(LinkError::Busy);
            }
            Ok(())
        }
        async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
            let (transfer, len) = self.started.take().ok_or(LinkError::Aborted)?;
            self.clock.0.set(self.clock.0.get() + 50);
            let Transfer::Exchange(r) = transfer else {
                self.broadcasts += 1;
                return Ok(0);
            };
            let mut w = BatchWriter::new(rx).map_err(|_| LinkError::Aborted)?;
            for l in self.late.iter_mut().filter(|l| l.0 == r as usize) {
                l.2 = l.2.saturating_sub(1);
            }
            let held: Vec<NodeId> = (self.late.iter())
                .filter(|l| l.0 == r as usize && l.2 > 0)
                .map(|l| l.1)
                .collect();
            let owed = core::mem::take(&mut self.owed[r as usize]);
            let (keep, go): (Vec<NodeId>, Vec<NodeId>) =
                owed.into_iter().partition(|n| held.contains(n));
            self.owed[r as usize] = keep;
            for node in go {
                self.done[r as usize].push(node);
                w.push(Record {
                    kind: Kind::Frame,
                    node,
                    data: &[0xAA, node as u8],
                })
                .map_err(|_| LinkError::Aborted)?;
            }
            w.set_waiting(self.waits[r as usize]);
            let n = w.bytes().len();
            if let Ok(Relayed::Batch { records, .. }) = parse(&self.bank[..len]) {
                for rec in records.flatten() {
                    if let Some(c) = self.requests[r as usize].get_mut(rec.node as usize) {
                        *c += 1;
                        self.got[r as usize][rec.node as usize] = rec.data.to_vec();
                    }
                }
            }
            if self.lose_down > 0 {
                self.lose_down -= 1;
                return Ok(n);
            }
            if let Ok(Relayed::Batch { records, .. }) = parse(&self.bank[..len]) {
                for rec in records.flatten() {
                    self.waits[r as usize] &= !(1u32 << rec.node);
                    let seen = self.owed[r as usize].contains(&rec.node)
                        || self.done[r as usize].contains(&rec.node);
                    if !seen {
                        self.owed[r as usize].push(rec.node);
                    }
                }
            }
            Ok(n)
        }
    }

    /// Start an exchange with every node the bus lets begin one with, each reply `len`
    /// bytes of the node's number; returns the nodes started.
    fn start_ready(bus: &mut RelayedBus<'_, Relays<'_>, &Jump>, len: usize) -> Vec<NodeId> {
        let mut started = Vec::new();
        while let Some(n) = bus.ready() {
            bus.tx_bank()[..len].fill(n as u8);
            bus.start(Transfer::Exchange(n), len).unwrap();
            started.push(n);
        }
        started
    }

    /// A node frame stays in the relay batch it came in until the root logic takes it; with
    /// every landing buffer holding frames not taken the link stops gathering (nothing is
    /// lost or overwritten), and goes on once they are taken.
    #[test]
    fn frames_wait_in_their_batches_and_full_landings_hold_the_link_back() {
        let clock = Jump(Cell::new(0));
        let mut relays = Relays::new(&clock, vec![true]);
        relays.waits = vec![u32::MAX];
        let mut bufs = Box::new(RelayedBuffers::new());
        let bus = RelayedBus::new(relays, &mut *bufs, 0, 32).unwrap();
        let mut bus = bus.with_timeout(&clock, 1_000_000).with_depth(SLOTS as u16);
        let mut started = Vec::new();
        for _ in 0..4 * MAX_LANDINGS {
            bus.poll();
            started.extend(start_ready(&mut bus, 2));
        }
        assert!(
            bus.held[..LANDINGS].iter().all(|&h| h > 0),
            "{:?}",
            bus.held
        );
        let exchanges = bus.counters.link_exchanges;
        for _ in 0..8 {
            bus.poll();
        }
        assert_eq!(bus.counters.link_exchanges, exchanges, "held back");
        // Every frame that came up is intact; the rest come once those are taken.
        let mut rx = [0u8; MAX_MESSAGE];
        let mut taken = Vec::new();
        while taken.len() < started.len() {
            let node = block_on(bus.wait_ready());
            assert_eq!(block_on(bus.finish_node(node, &mut rx)), Ok(2));
            assert_eq!(rx[..2], [0xAA, node as u8]);
            taken.push(node);
        }
        taken.sort_unstable();
        let mut want = started.clone();
        want.sort_unstable();
        assert_eq!(taken, want);
        assert!(started.len() >= SLOTS);
        assert_eq!(bus.held, [0; MAX_LANDINGS]);
        assert_eq!((bus.counters.stray_frames, bus.counters.timeouts), (0, 0));
    }

    /// A reply longer than a cell (a scene repair) waits in a frame buffer and goes down
    /// whole; while one does, one more may begin, so a broadcast always finds a buffer.
    #[test]
    fn a_reply_longer_than_a_cell_waits_in_a_frame_buffer() {
        let clock = Jump(Cell::new(0));
        let mut relays = Relays::new(&clock, vec![true]);
        relays.waits = vec![0b1111];
        let mut bufs = Box::new(RelayedBuffers::new());
        let bus = RelayedBus::new(relays, &mut *bufs, 0, 4).unwrap();
        let mut bus = bus.with_timeout(&clock, 1_000_000).with_depth(4);
        bus.poll();
        bus.poll();
        let long = REPLY_CELL + 100;
        assert_eq!(start_ready(&mut bus, long), [0, 1]);
        assert_eq!(bus.untaken_frames(), 2);
        assert_eq!(bus.ready(), None, "nodes 2 and 3 wait for a frame buffer");
        // The requests go down whole; the frames come back, freeing both buffers.
        let mut rx = [0u8; MAX_MESSAGE];
        for _ in 0..2 {
            let node = block_on(bus.wait_ready());
            assert_eq!(block_on(bus.finish_node(node, &mut rx)), Ok(2));
        }
        assert_eq!(bus.link.requests[0][..2], [1, 1]);
        assert_eq!(bus.link.got[0][..2], [vec![0u8; long], vec![1u8; long]]);
        assert_eq!(bus.untaken_frames(), FRAMES);
        assert_eq!(start_ready(&mut bus, 2), [2, 3]);
    }

    /// One relay of 32 waiting nodes, `started` exchanges begun (node 0's frame late by
    /// `late` exchanges), then every landing filled with frames not taken.
    fn full_landings<'b, 'c>(
        clock: &'c Jump,
        bufs: &'b mut RelayedBuffers,
        timeout_us: u64,
        late: u32,
    ) -> RelayedBus<'b, Relays<'c>, &'c Jump> {
        let mut relays = Relays::new(clock, vec![true]);
        relays.waits = vec![u32::MAX];
        relays.late = vec![(0, 0, late)];
        let bus = RelayedBus::new(relays, bufs, 0, 32).unwrap();
        let mut bus = bus.with_timeout(clock, timeout_us).with_depth(SLOTS as u16);
        for _ in 0..4 * MAX_LANDINGS {
            bus.poll();
            start_ready(&mut bus, 2);
        }
        assert!(
            bus.held[..LANDINGS].iter().all(|&h| h > 0),
            "{:?}",
            bus.held
        );
        let node0 = bus.slots.iter().flatten().find(|s| s.node == 0);
        assert!(late == 0 || matches!(node0.map(|s| s.stage), Some(Stage::Asked { .. })));
        bus
    }

    /// With the landings full of other frames, the exchange asked first is not waited for
    /// (its frame cannot come up before they are taken): `finish_node` says so (Busy, and
    /// `run_bus` takes the others first), and `finish` takes the first frame back instead,
    /// so nothing hangs and the late frame is not timed out.
    #[test]
    fn a_late_frame_is_not_waited_for_while_the_others_fill_the_landings() {
        for timeout_us in [0, 1_000_000] {
            let clock = Jump(Cell::new(0));
            let mut bufs = Box::new(RelayedBuffers::new());
            let mut bus = full_landings(&clock, &mut bufs, timeout_us, 40);
            let mut rx = [0u8; MAX_MESSAGE];
            let first = embassy_futures::poll_once(bus.finish_node(0, &mut rx));
            assert_eq!(first, Poll::Ready(Err(LinkError::Busy)));
            let mut taken = Vec::new();
            while bus.flying() > 0 {
                let got = {
                    let mut fin = core::pin::pin!(bus.finish(&mut rx));
                    (0..1000).find_map(|_| match embassy_futures::poll_once(fin.as_mut()) {
                        Poll::Ready(r) => Some(r),
                        Poll::Pending => None,
                    })
                };
                assert_eq!(got, Some(Ok(2)), "timeout {timeout_us}: finish hung");
                taken.push(rx[1]);
            }
            assert_eq!(taken.last(), Some(&0), "node 0's frame comes last");
            assert_eq!(bus.counters.timeouts, 0);
        }
    }

    /// A broadcast waits for the relays' reports that they passed the ones before on; with
    /// every landing full none can come up, so it goes at once instead of waiting
    /// CAST_WAIT_US and marking the relay deaf.
    #[test]
    fn a_broadcast_does_not_wait_for_reports_that_cannot_come_up() {
        let clock = Jump(Cell::new(0));
        let mut bufs = Box::new(RelayedBuffers::new());
        let mut bus = full_landings(&clock, &mut bufs, 1_000_000, 0);
        let mut rx = [0u8; MAX_MESSAGE];
        for k in 0..3u8 {
            let t = clock.0.get();
            bus.tx_bank()[..2].copy_from_slice(&[9, k]);
            bus.start(Transfer::Broadcast, 2).unwrap();
            assert_eq!(block_on(bus.finish(&mut rx)), Ok(0));
            assert!(clock.0.get() - t <= 100, "broadcast {k} waited");
        }
        assert_eq!((bus.link.broadcasts, bus.deaf), (3, 0));
    }

    /// A time-out that passed while every landing was full is the caller's to take: the
    /// bus waits for news without waiting for that time again and again (a spin).
    #[test]
    fn a_passed_time_out_is_not_waited_for_again() {
        let clock = Jump(Cell::new(0));
        let mut bufs = Box::new(RelayedBuffers::new());
        let mut bus = full_landings(&clock, &mut bufs, 1_000, 40);
        clock.0.set(5_000);
        WAITS.with(|w| w.set(0));
        {
            let mut news = core::pin::pin!(bus.wait_news());
            for _ in 0..100 {
                assert_eq!(embassy_futures::poll_once(news.as_mut()), Poll::Pending);
            }
        }
        assert_eq!(WAITS.with(Cell::get), 0);
        let mut rx = [0u8; MAX_MESSAGE];
        assert_eq!(block_on(bus.finish_node(0, &mut rx)), Ok(0));
        assert_eq!(bus.counters.timeouts, 1);
    }

    /// Replies longer than a cell never take the last two frame buffers, whoever begins
    /// them (a middle relay begins the root's requests without asking `ready`): a third is
    /// refused (the root asks again), short ones still go, a broadcast still finds a buffer
    /// and the long replies waiting are intact.
    #[test]
    fn long_replies_never_take_the_last_frame_buffers() {
        let clock = Jump(Cell::new(0));
        let relays = Relays::new(&clock, vec![false, false, false]);
        let mut bufs = Box::new(RelayedBuffers::new());
        let bus = RelayedBus::new(relays, &mut *bufs, 0, 4).unwrap();
        let mut bus = bus.with_timeout(&clock, 1_000_000);
        let long = REPLY_CELL + 10;
        assert_eq!(bus.begin_exchange(0, &vec![1; long]), Ok(()));
        assert_eq!(bus.begin_exchange(1, &vec![2; long]), Ok(()));
        assert_eq!(bus.begin_exchange(4, &vec![3; long]), Err(LinkError::Busy));
        assert_eq!(bus.begin_exchange(8, &[0xEE; 10]), Ok(()));
        bus.tx_bank()[..2].copy_from_slice(&[0xBB, 0xBB]);
        assert_eq!(bus.start(Transfer::Broadcast, 2), Ok(()));
        for (node, byte) in [(0, 1u8), (1, 2)] {
            let slot = bus.slots.iter().flatten().find(|s| s.node == node).unwrap();
            let Stage::Asked {
                reply: Reply::Frame(b),
                ..
            } = slot.stage
            else {
                panic!("node {node}: {:?}", slot.stage);
            };
            assert!(bus.frames[b as usize][..long].iter().all(|&x| x == byte));
        }
        assert_eq!(bus.slots.iter().flatten().count(), 3);
    }

    /// The longest job hand-out fits a reply cell, so only scene repairs (and the root's
    /// broadcasts) take a frame buffer.
    #[test]
    fn the_longest_job_hand_out_fits_a_reply_cell() {
        use crate::cluster::wire::{encode, Job, Region, JOB_QUEUE};
        let job = |region| {
            Some(Job {
                id: u32::MAX,
                frame: u16::MAX,
                region,
            })
        };
        let widest = [
            Region::Span {
                start: u32::MAX,
                len: u32::MAX,
            },
            Region::Rect {
                x: u16::MAX,
                y: u16::MAX,
                w: u16::MAX,
                h: u16::MAX,
            },
        ];
        let mut buf = [0u8; MAX_MESSAGE];
        for region in widest {
            let msg = Down::Work {
                jobs: [job(region); JOB_QUEUE],
            };
            let n = encode(u16::MAX, u16::MAX, &msg, &mut buf).unwrap();
            assert_eq!(
                n,
                if matches!(region, Region::Span { .. }) {
                    52
                } else {
                    56
                }
            );
            assert!(n <= REPLY_CELL);
        }
    }

    #[test]
    fn exchanges_through_two_relays_are_in_flight_at_once_and_a_dead_relays_time_out() {
        let clock = Jump(Cell::new(0));
        let link = Relays::new(&clock, vec![true, false]);
        let mut bufs = Box::new(RelayedBuffers::new());
        let mut bus = RelayedBus::new(link, &mut bufs, 0, 3)
            .unwrap()
            .with_timeout(&clock, 1_000);
        assert_eq!(bus.in_flight(), 4);
        // Two exchanges with relay 0's nodes, one with relay 1's: all in flight at once.
        for node in [0, 1, 3] {
            bus.tx_bank()[..3].copy_from_slice(&[1, 2, node as u8]);
            assert_eq!(bus.start(Transfer::Exchange(node), 3), Ok(()));
        }
        assert_eq!(bus.flying(), 3);
        // Relay 0 has two in flight (its depth); a node in flight cannot begin again.
        assert_eq!(bus.start(Transfer::Exchange(2), 3), Err(LinkError::Busy));
        assert_eq!(bus.start(Transfer::Exchange(3), 3), Err(LinkError::Busy));
        let mut rx = [0u8; MAX_MESSAGE];
        // Relay 0's frames come back (in either order); relay 1's exchange ends at its
        // time-out, empty, counted.
        assert_eq!(block_on(bus.finish_node(1, &mut rx)), Ok(2));
        assert_eq!(rx[..2], [0xAA, 1]);
        assert_eq!(block_on(bus.finish_node(0, &mut rx)), Ok(2));
        assert_eq!(rx[..2], [0xAA, 0]);
        assert_eq!(bus.counters.timeouts, 0);
        assert_eq!(bus.pending(), Some(3));
        assert_eq!(block_on(bus.finish_node(3, &mut rx)), Ok(0));
        assert!(clock.0.get() >= 1_000);
        assert_eq!(bus.counters.timeouts, 1);
        assert_eq!((bus.flying(), bus.pending()), (0, None));
        assert_eq!(bus.counters.most_in_flight, 3);
        assert_eq!(bus.counters.stray_frames, 0);
        // A broadcast goes on the link when finished (relay 1 is not waited for beyond
        // CAST_WAIT_US: it never reports).
        for k in 0..3u8 {
            bus.tx_bank()[..2].copy_from_slice(&[9, k]);
            assert_eq!(bus.start(Transfer::Broadcast, 2), Ok(()));
            assert_eq!(block_on(bus.finish(&mut rx)), Ok(0));
        }
        assert_eq!(bus.link().broadcasts, 3);
    }

    /// A relay whose frame may be up (its line up meanwhile) does not keep the link from a
    /// relay with news the root has not heard: both are gathered in turn, so the root learns
    /// of the second relay's waiting node while the first one's frame is still late.
    #[test]
    fn a_relay_with_news_is_gathered_while_another_ones_frame_is_late() {
        let clock = Jump(Cell::new(0));
        let mut link = Relays::new(&clock, vec![true, true]);
        // Relay 0's node 0 answers only after many exchanges; relay 1's node (2) waits.
        link.late = vec![(0, 0, 1_000)];
        link.waits[1] = 0b1;
        let mut bufs = Box::new(RelayedBuffers::new());
        let mut bus = RelayedBus::new(link, &mut bufs, 0, 2)
            .unwrap()
            .with_timeout(&clock, 1_000_000);
        bus.tx_bank()[..2].copy_from_slice(&[7, 0]);
        assert_eq!(bus.start(Transfer::Exchange(0), 2), Ok(()));
        for _ in 0..8 {
            bus.poll();
        }
        assert!(bus.line(2), "relay 1 was never gathered: {:?}", bus.gathers);
        assert_eq!(bus.ready(), Some(2));
        assert_eq!(bus.flying(), 1);
    }

    /// A request goes down once when the relay gets it, and again only when a batch
    /// composed after it went down still reports its node waiting: with the down halves of
    /// the next `lost` exchanges lost, each costs the request it carried one more sending,
    /// and nothing else goes down twice. (Node 0's request goes on the free link at once,
    /// node 1's in the next exchange; each lost half's batch was composed before it, so the
    /// loss shows in the batch after.)
    #[test]
    fn a_request_goes_down_again_only_when_the_relay_did_not_get_it() {
        for (lost, expect) in [(0, [1, 1]), (1, [2, 1]), (3, [3, 2])] {
            let clock = Jump(Cell::new(0));
            let mut link = Relays::new(&clock, vec![true]);
            link.waits[0] = 0b11;
            let mut bufs = Box::new(RelayedBuffers::new());
            let mut bus = RelayedBus::new(link, &mut bufs, 0, 2)
                .unwrap()
                .with_timeout(&clock, 10_000);
            let mut rx = [0u8; MAX_MESSAGE];
            // The root learns of the waiting nodes, asks both, and takes both frames.
            block_on(bus.wait_news());
            bus.link.lose_down = lost;
            for node in [0, 1] {
                bus.tx_bank()[..2].copy_from_slice(&[7, node as u8]);
                assert_eq!(bus.start(Transfer::Exchange(node), 2), Ok(()));
            }
            for node in [0, 1] {
                assert_eq!(
                    block_on(bus.finish_node(node, &mut rx)),
                    Ok(2),
                    "lost {lost}"
                );
                assert_eq!(rx[..2], [0xAA, node as u8]);
            }
            assert_eq!(bus.link().requests[0][..2], expect, "lost {lost}");
            assert_eq!(bus.counters.timeouts, 0);
        }
    }

    /// A reply sent ahead of its node's line goes down once and lets its cell go (one cell
    /// serves any number of them); it waits at the relay past the time-out, up to the
    /// time ahead besides; one that never reached the relay (the relay then reports its
    /// node waiting) ends empty, and the node, waiting, is asked anew.
    #[test]
    fn a_reply_ahead_lets_its_cell_go_and_one_lost_ends_empty() {
        let clock = Jump(Cell::new(0));
        let link = Relays::new(&clock, vec![true]);
        let mut bufs = Box::new(RelayedFrames::<1>::new());
        let bus = RelayedBus::new(link, &mut bufs, 0, 4)
            .unwrap()
            .with_timeout(&clock, 1_000)
            .with_depth(4);
        let mut rx = [0u8; MAX_MESSAGE];
        // Without `with_ahead`, nothing begins before a node's line.
        assert!(!bus.ask_ahead(0));
        let mut bus = bus.with_ahead(10_000);
        assert!(bus.ask_ahead(0));
        // Node 0's frame will come up only some exchanges after its reply went down.
        bus.link.late.push((0, 0, 30));
        bus.tx_bank()[..3].copy_from_slice(&[7, 0, 0]);
        assert_eq!(bus.start(Transfer::Exchange(0), 3), Ok(()));
        // It went on the link at once (the link was free): the one cell is free again.
        assert_eq!(bus.dangling, Some(LinkOp::Gather(0)));
        assert!(bus.ask_ahead(1), "the reply is down: its cell is free");
        block_on(bus.settle()).unwrap();
        // Node 1's reply ahead is lost on the way, and node 1 then waits at the relay.
        bus.link.lose_down = 1;
        bus.tx_bank()[..3].copy_from_slice(&[7, 1, 1]);
        assert_eq!(bus.start(Transfer::Exchange(1), 3), Ok(()));
        block_on(bus.settle()).unwrap();
        assert_eq!(bus.link().requests[0][..2], [1, 1]);
        bus.link.waits[0] = 0b10;
        // The exchanges go on (the link is asked again): node 1's ends empty, node 0's
        // frame comes up though its time-out (1 ms) has passed.
        let mut ended = Vec::new();
        while ended.len() < 2 {
            let n = block_on(bus.wait_ready());
            if bus.arrived() == Some(n) {
                let got = block_on(bus.finish_node(n, &mut rx)).unwrap();
                ended.push((n, got));
            }
        }
        ended.sort();
        assert_eq!(ended, [(0, 2), (1, 0)]);
        assert!(
            clock.0.get() > 1_000,
            "node 0 was waited for past the time-out"
        );
        assert_eq!(bus.counters.ahead, 2);
        assert_eq!(bus.counters.lost_ahead, 1);
        assert_eq!(bus.counters.timeouts, 0);
        // Node 1, waiting, is the bus's to ask now, with its line: not ahead.
        assert_eq!(bus.ready(), Some(1));
        bus.tx_bank()[..3].copy_from_slice(&[7, 1, 2]);
        assert_eq!(bus.start(Transfer::Exchange(1), 3), Ok(()));
        assert_eq!(block_on(bus.finish_node(1, &mut rx)), Ok(2));
        assert_eq!(bus.counters.ahead, 2);
        assert_eq!(bus.link().got[0][1], [7, 1, 2]);
    }
}
