//! The SPI link driver's protocol: the IMSU exchange over a real SPI star, independent of the
//! MCU. The firmware (`nc-fw`, `rc-fw`) implements the two small port traits with embassy-stm32
//! (SPI + DMA, chip-select GPIOs, handshake lines, EXTI); host tests implement them with a fake
//! bus that enforces the same rules and injects faults. Everything here is `no_std`, no heap,
//! and nothing read from the bus can make it panic.
//!
//! ## One transfer (chip-select low throughout)
//! ```text
//! RC -> NC   header (8)  | body, L bytes                  | trailer (1, exchange only)
//! NC -> RC   header (8)  | body, L bytes                  | (ignored)
//! header = magic, kind/flags, len u16 LE, CRC-16 of the body u16 LE, CRC-16 of bytes 0..6
//! ```
//! - **exchange** (one chip-select): the RC clocks the 8-byte header phase, reads the node's
//!   header (its frame's length), clocks a body of `L = max(rc_len, nc_len)` bytes (the
//!   shorter side padded), checks the node's body against its CRC and clocks one trailer
//!   byte: [`ACK`] or [`NAK`]. A NAK is the link's **retransmit request**: the node keeps the
//!   frame in its TX bank, raises its ready line again and the frame goes out in the next
//!   exchange; the RC counts the malformed frame and hands the root logic an empty frame
//!   (which it counts as bad, never a crash).
//! - **broadcast** (every chip-select): header and body only; the nodes' MISO output is
//!   ignored (and current-limited by the series resistors in `docs/hardware.md`).
//!
//! The node arms its DMA for a whole bank before a transfer and learns where it ended from
//! the chip-select's rising edge, so a short, truncated or garbled transfer only costs that
//! transfer: banks are zeroed before arming, and every length and CRC is checked.
//!
//! ## Handshake line (one GPIO per node, node -> RC)
//! High = "my DMA is armed with a posted frame in the TX bank and I have a free RX bank".
//! The RC clocks an exchange only with a node whose line is high (and re-checks it just
//! before asserting the chip-select). After a transfer the node drops the line and raises it
//! again once re-armed. A lost edge costs at most one polling period ([`MasterPort::
//! wait_any_ready`] also wakes on a timer), never a hang.
//!
//! ## Banks
//! The node's link owns two TX banks (the one armed in DMA, the one `post` fills: double
//! buffer), two RX banks handed to the node logic in turn (double buffer: a broadcast can
//! land while the node still reads the previous frame) and a scratch bank that absorbs a
//! transfer when both RX banks are full (counted as an overflow; scene chunks lost that way
//! are repaired by the root logic).

use super::link::{Incoming, LinkError, NodeId, NodeLink, RootBus, Transfer};
use super::wire::MAX_FRAME;
use core::cell::RefCell;
use core::future::{poll_fn, Future};
use core::task::{Poll, Waker};
use critical_section::Mutex;

/// Bytes of the header phase.
pub const HEADER: usize = 8;
/// Bytes of the trailer phase (exchange only).
pub const TRAILER: usize = 1;
/// Size of one DMA bank: header, the largest frame, trailer, rounded up to a word.
pub const BANK: usize = (HEADER + MAX_FRAME + TRAILER).div_ceil(4) * 4;
/// One DMA bank. On the STM32F4 banks must sit in SRAM (DMA cannot reach the CCM).
pub type Bank = [u8; BANK];
const _: () = assert!(BANK >= HEADER + MAX_FRAME + TRAILER && BANK.is_multiple_of(4));

/// Trailer byte: the node's frame arrived intact.
pub const ACK: u8 = 0xAC;
/// Trailer byte: the node's frame was malformed; send it again (the retransmit request).
pub const NAK: u8 = 0x4E;

const RC_MAGIC: u8 = 0xA5;
const NC_MAGIC: u8 = 0x5A;
const KIND_EXCHANGE: u8 = 1;
const KIND_BROADCAST: u8 = 2;
/// Node header flag: a frame is posted (the header's length is its length).
const FLAG_POSTED: u8 = 1;

/// CRC-16 of the header and the body (CRC-16/CCITT-FALSE as CRC_16_IBM_3740).
pub const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// What a port could not do (a DMA or bus error). The protocol treats it like a garbled
/// transfer: counted, and the transfer's frames are sent again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PortError;

/// A decoded header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Header {
    /// RC: 1 = exchange, 2 = broadcast. NC: flags (bit 0 = a frame is posted).
    pub kind: u8,
    pub len: u16,
    pub body_crc: u16,
}

fn put_header(out: &mut [u8], magic: u8, kind: u8, body: &[u8]) {
    if out.len() < HEADER {
        return;
    }
    let len = body.len().min(u16::MAX as usize) as u16;
    let crc = CRC16.checksum(body);
    out[0] = magic;
    out[1] = kind;
    out[2..4].copy_from_slice(&len.to_le_bytes());
    out[4..6].copy_from_slice(&crc.to_le_bytes());
    let hcrc = CRC16.checksum(&out[..6]);
    out[6..8].copy_from_slice(&hcrc.to_le_bytes());
}

fn get_header(bytes: &[u8], magic: u8) -> Option<Header> {
    let h = bytes.get(..HEADER)?;
    if h[0] != magic || CRC16.checksum(&h[..6]) != u16::from_le_bytes([h[6], h[7]]) {
        return None;
    }
    let len = u16::from_le_bytes([h[2], h[3]]);
    if len as usize > MAX_FRAME {
        return None;
    }
    Some(Header {
        kind: h[1],
        len,
        body_crc: u16::from_le_bytes([h[4], h[5]]),
    })
}

/// Encode the RC's header for a body (exposed for tests and tools).
pub fn rc_header(broadcast: bool, body: &[u8]) -> [u8; HEADER] {
    let mut h = [0u8; HEADER];
    let kind = if broadcast {
        KIND_BROADCAST
    } else {
        KIND_EXCHANGE
    };
    put_header(&mut h, RC_MAGIC, kind, body);
    h
}

/// Decode a node's header (exposed for tests and tools).
pub fn nc_header(bytes: &[u8]) -> Option<Header> {
    get_header(bytes, NC_MAGIC)
}

fn body_ok(bank: &[u8], h: &Header) -> bool {
    bank.get(HEADER..HEADER + h.len as usize)
        .is_some_and(|b| CRC16.checksum(b) == h.body_crc)
}

// ---------------------------------------------------------------------------------------
// RC side
// ---------------------------------------------------------------------------------------

/// Which chip-selects to assert.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Select {
    /// One node (index on this bus, 0-based).
    One(u16),
    /// Every node on the bus (broadcast).
    All,
}

/// The RC's hardware for one bus: an SPI master with DMA, chip-select GPIOs, handshake
/// inputs with edge interrupts.
#[allow(async_fn_in_trait)]
pub trait MasterPort {
    /// Nodes on the bus.
    fn count(&self) -> u16;
    /// Level of node `i`'s handshake line.
    fn ready(&self, i: u16) -> bool;
    /// Resolve when some handshake line may have gone high (an edge interrupt, or a polling
    /// period so that a lost edge costs little).
    async fn wait_any_ready(&mut self);
    /// Assert chip-selects, then wait the set-up time the nodes need to drive MISO.
    async fn select(&mut self, sel: Select);
    /// Release every chip-select (and hold them high for the nodes' re-arm time).
    async fn deselect(&mut self);
    /// One full-duplex DMA transfer; `tx` and `rx` have equal lengths.
    async fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), PortError>;
}

/// What the RC's link saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MasterCounters {
    pub exchanges: u32,
    pub broadcasts: u32,
    /// Exchanges whose node frame was malformed (answered with [`NAK`]).
    pub naks: u32,
    /// Node headers that failed their magic, CRC or length check (the transfer ends after
    /// the header phase and the node is asked again).
    pub bad_headers: u32,
    /// `exchange` called for a node whose handshake line was low (not clocked).
    pub not_ready: u32,
    /// Selected nodes that did not drop their handshake line (not clocked).
    pub no_ack: u32,
    pub port_errors: u32,
    pub bytes: u64,
}

/// The RC's end of one bus: the [`RootBus`] the root logic drives, over a [`MasterPort`].
///
/// Two TX banks (double buffering): the RC composes the next frame in the idle one
/// ([`RootBus::tx_bank`], the body after the header room) while the other holds the
/// transfer handed over with [`RootBus::start`]. The transfer is clocked in
/// [`RootBus::finish`] (header phase, body, trailer: the phases need the CPU in between, and
/// `MasterPort::transfer` is an async DMA transfer that runs only while awaited), so what
/// the banks buy is that composing never waits for a bank; the wire and the composing do
/// not overlap yet (that needs the phases driven from the DMA interrupt: docs/hardware.md).
pub struct MasterLink<'b, P> {
    port: P,
    first: NodeId,
    tx: [&'b mut Bank; 2],
    /// The TX bank the RC composes into.
    idle: usize,
    rx: &'b mut Bank,
    /// The transfer handed over and not yet finished: what, and its frame's length (in the
    /// bank that is not idle).
    started: Option<(Transfer, usize)>,
    next_scan: u16,
    pub counters: MasterCounters,
}

impl<'b, P: MasterPort> MasterLink<'b, P> {
    /// A bus whose nodes are numbered `first..first + port.count()` in the root logic; `tx`
    /// (two, double-buffered) and `rx` are the DMA banks.
    pub fn new(port: P, first: NodeId, tx: [&'b mut Bank; 2], rx: &'b mut Bank) -> Self {
        Self {
            port,
            first,
            tx,
            idle: 0,
            rx,
            started: None,
            next_scan: 0,
            counters: MasterCounters::default(),
        }
    }

    pub fn port(&self) -> &P {
        &self.port
    }

    pub fn port_mut(&mut self) -> &mut P {
        &mut self.port
    }

    /// The node index on this bus of `node`.
    fn index(&self, node: NodeId) -> Result<u16, LinkError> {
        node.checked_sub(self.first)
            .filter(|&i| i < self.port.count())
            .ok_or(LinkError::NoSuchNode { node })
    }

    /// The node frame of an exchange (after the header phase): clock the body and trailer
    /// from TX bank `b`. Returns the node frame's length if intact.
    async fn body(&mut self, b: usize, n: usize) -> Result<Option<usize>, PortError> {
        let Some(h) = nc_header(&self.rx[..HEADER]) else {
            self.counters.bad_headers += 1;
            return Ok(None);
        };
        let nlen = if h.kind & FLAG_POSTED != 0 {
            h.len as usize
        } else {
            0
        };
        let l = n.max(nlen);
        let tx = &mut *self.tx[b];
        tx[HEADER + n..HEADER + l].fill(0);
        self.port
            .transfer(&tx[HEADER..HEADER + l], &mut self.rx[HEADER..HEADER + l])
            .await?;
        let ok = nlen == 0 || body_ok(&self.rx[..], &h);
        let t = [if ok { ACK } else { NAK }];
        let mut back = [0u8];
        self.port.transfer(&t, &mut back).await?;
        self.counters.bytes += (HEADER + l + TRAILER) as u64;
        if ok {
            Ok(Some(nlen))
        } else {
            self.counters.naks += 1;
            Ok(None)
        }
    }

    /// Clock an exchange of TX bank `b` (`n` bytes of frame) with node index `i`; the
    /// node's frame is then in the RX bank. Returns its length (0: none, or not intact).
    async fn clock_exchange(&mut self, b: usize, i: u16, n: usize) -> usize {
        // Handshake ordering: never clock a node that is not armed.
        if !self.port.ready(i) {
            self.counters.not_ready += 1;
            return 0;
        }
        let h = rc_header(false, &self.tx[b][HEADER..HEADER + n]);
        self.tx[b][..HEADER].copy_from_slice(&h);
        self.rx[..HEADER].fill(0);
        self.port.select(Select::One(i)).await;
        if self.port.ready(i) {
            // The node drops its line when selected (the handshake's acknowledgement); a
            // line still high means it is not listening: clock nothing.
            self.port.deselect().await;
            self.counters.no_ack += 1;
            return 0;
        }
        let got = match self
            .port
            .transfer(&self.tx[b][..HEADER], &mut self.rx[..HEADER])
            .await
        {
            Ok(()) => self.body(b, n).await,
            Err(e) => Err(e),
        };
        self.port.deselect().await;
        self.counters.exchanges += 1;
        match got {
            Ok(Some(len)) => len,
            Ok(None) => 0,
            Err(PortError) => {
                self.counters.port_errors += 1;
                0
            }
        }
    }

    /// Clock a broadcast of TX bank `b` (`n` bytes of frame) to every node.
    async fn clock_broadcast(&mut self, b: usize, n: usize) {
        let h = rc_header(true, &self.tx[b][HEADER..HEADER + n]);
        self.tx[b][..HEADER].copy_from_slice(&h);
        self.port.select(Select::All).await;
        let r = self
            .port
            .transfer(&self.tx[b][..HEADER + n], &mut self.rx[..HEADER + n])
            .await;
        self.port.deselect().await;
        self.counters.broadcasts += 1;
        self.counters.bytes += (HEADER + n) as u64;
        if r.is_err() {
            self.counters.port_errors += 1;
        }
    }
}

impl<P: MasterPort> RootBus for MasterLink<'_, P> {
    fn nodes(&self) -> (NodeId, u16) {
        (self.first, self.port.count())
    }

    async fn wait_ready(&mut self) -> NodeId {
        loop {
            if let Some(n) = self.ready() {
                return n;
            }
            self.port.wait_any_ready().await;
        }
    }

    fn ready(&self) -> Option<NodeId> {
        let count = self.port.count();
        // A node whose exchange was handed over but not clocked still shows its line: it
        // is ready only after that exchange (the root logic then finishes it first).
        (0..count)
            .map(|i| (self.next_scan + i) % count)
            .find(|&i| self.port.ready(i))
            .map(|i| self.first + i)
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        &mut self.tx[self.idle][HEADER..HEADER + MAX_FRAME]
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        if self.started.is_some() {
            return Err(LinkError::Busy);
        }
        if len > MAX_FRAME {
            return Err(LinkError::TooLong {
                len: len as u32,
                max: MAX_FRAME as u32,
            });
        }
        if let Transfer::Exchange(node) = transfer {
            let i = self.index(node)?;
            self.next_scan = (i + 1) % self.port.count();
        }
        self.started = Some((transfer, len));
        self.idle ^= 1;
        Ok(())
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        let (transfer, n) = self.started.take().ok_or(LinkError::Aborted)?;
        let b = self.idle ^ 1;
        let len = match transfer {
            Transfer::Exchange(node) => {
                let i = self.index(node)?;
                self.clock_exchange(b, i, n).await
            }
            Transfer::Broadcast => {
                self.clock_broadcast(b, n).await;
                0
            }
        };
        match rx.get_mut(..len) {
            Some(dst) => {
                dst.copy_from_slice(&self.rx[HEADER..HEADER + len]);
                Ok(len)
            }
            None => Err(LinkError::TooLong {
                len: len as u32,
                max: rx.len() as u32,
            }),
        }
    }
}

// ---------------------------------------------------------------------------------------
// NC side
// ---------------------------------------------------------------------------------------

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
    /// Transfers that found both RX banks full (absorbed by the scratch bank).
    pub overflows: u32,
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
        let (rxb, from_free) = shared.with(|s| {
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
        });
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
        shared.with(|s| {
            if outcome.is_some() {
                s.counters.transfers += 1;
            } else {
                s.counters.rearms += 1;
            }
            let deliver = match outcome {
                Some(Outcome::Deliver {
                    len,
                    exchanged,
                    body,
                }) => {
                    if exchanged {
                        s.counters.exchanges += 1;
                    } else {
                        s.counters.broadcasts += 1;
                    }
                    if !body {
                        s.counters.bad_bodies += 1;
                    }
                    Some((if body { len } else { 0 }, exchanged))
                }
                Some(Outcome::Retransmit { body }) => {
                    s.counters.exchanges += 1;
                    s.counters.retransmits += 1;
                    if !body {
                        s.counters.bad_bodies += 1;
                    }
                    None
                }
                Some(Outcome::BadBroadcast) => {
                    s.counters.broadcasts += 1;
                    s.counters.bad_bodies += 1;
                    None
                }
                Some(Outcome::BadHeader) => {
                    s.counters.bad_headers += 1;
                    None
                }
                None => None,
            };
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

/// The node logic's end of the link: [`NodeLink`] over the shared state.
pub struct SlaveHandle<'s, 'b> {
    shared: &'s SlaveShared<'b>,
}

impl NodeLink for SlaveHandle<'_, '_> {
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        if frame.len() > MAX_FRAME {
            return Err(LinkError::TooLong {
                len: frame.len() as u32,
                max: MAX_FRAME as u32,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_round_trip_and_reject_damage() {
        let body = [1u8, 2, 3, 4, 5];
        let h = rc_header(false, &body);
        let got = get_header(&h, RC_MAGIC).expect("valid");
        assert_eq!(got.kind, KIND_EXCHANGE);
        assert_eq!(got.len, 5);
        assert_eq!(got.body_crc, CRC16.checksum(&body));
        for bit in 0..HEADER * 8 {
            let mut d = h;
            d[bit / 8] ^= 1 << (bit % 8);
            assert_eq!(get_header(&d, RC_MAGIC), None, "bit {bit}");
        }
        assert_eq!(get_header(&h[..7], RC_MAGIC), None);
        assert_eq!(nc_header(&h), None, "an RC header is no node header");
        // A length beyond a frame is refused even with a valid CRC.
        let mut big = [0u8; HEADER];
        big[0] = NC_MAGIC;
        big[2..4].copy_from_slice(&(MAX_FRAME as u16 + 1).to_le_bytes());
        let c = CRC16.checksum(&big[..6]).to_le_bytes();
        big[6..8].copy_from_slice(&c);
        assert_eq!(nc_header(&big), None);
    }
}
