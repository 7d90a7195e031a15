//! The RC side: the master's port trait and [`MasterLink`], the [`RootBus`] over it.

use super::clock::{Clocked, Wire};
use super::framing::*;
use crate::cluster::link::{LinkError, NodeId, RootBus, Transfer};
use crate::cluster::wire::MAX_MESSAGE;
use core::cell::Cell;

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

impl MasterCounters {
    /// Both links' counts together (a root driving two links).
    pub fn plus(&self, o: &MasterCounters) -> MasterCounters {
        MasterCounters {
            exchanges: self.exchanges.saturating_add(o.exchanges),
            broadcasts: self.broadcasts.saturating_add(o.broadcasts),
            naks: self.naks.saturating_add(o.naks),
            bad_headers: self.bad_headers.saturating_add(o.bad_headers),
            not_ready: self.not_ready.saturating_add(o.not_ready),
            no_ack: self.no_ack.saturating_add(o.no_ack),
            port_errors: self.port_errors.saturating_add(o.port_errors),
            bytes: self.bytes.saturating_add(o.bytes),
        }
    }
}

/// Whether the firmware's RC clocks the wire while it composes and decodes: yes, `rc-fw`
/// runs [`super::MasterTask`] on an interrupt executor above the thread executor where the
/// root logic drives [`super::MasterFront`] (the inline [`MasterLink`] does not overlap).
/// The F407 board profile's `rc_overlaps` (`links_core::board::LinkProfile::F407`).
pub const RC_OVERLAPS: bool = true;

/// The RC's end of one bus: the [`RootBus`] the root logic drives, over a [`MasterPort`].
///
/// Two TX banks (double buffering): the RC composes the next frame in the idle one
/// ([`RootBus::tx_bank`], the body after the header room) while the other holds the
/// transfer handed over with [`RootBus::start`]. The transfer is clocked in
/// [`RootBus::finish`] (header phase, body, trailer: the phases need the CPU in between, and
/// `MasterPort::transfer` is an async DMA transfer that runs only while awaited), so what
/// the banks buy is that composing never waits for a bank; the wire and the composing do
/// not overlap here. [`super::MasterFront`] + [`super::MasterTask`] is the split link that
/// overlaps them (the firmware's); this one suits a single task (tests, tools).
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
    /// Nodes (bit per index, the first 256) whose handshake line stayed high through their
    /// selection: a stuck line or a node not listening. They are not offered as ready until
    /// their line is seen low again, so one stuck line cannot starve the bus (the root
    /// broadcasts only while no node is ready).
    ignored: Cell<[u32; 8]>,
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
            ignored: Cell::new([0; 8]),
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

    fn is_ignored(&self, i: u16) -> bool {
        let m = self.ignored.get();
        m.get(i as usize / 32)
            .is_some_and(|w| w & (1 << (i % 32)) != 0)
    }

    fn set_ignored(&self, i: u16, on: bool) {
        let mut m = self.ignored.get();
        if let Some(w) = m.get_mut(i as usize / 32) {
            if on {
                *w |= 1 << (i % 32);
            } else {
                *w &= !(1 << (i % 32));
            }
        }
        self.ignored.set(m);
    }

    /// Forget the ignored nodes whose line is low now (alive and listening again).
    fn unignore_low(&self) {
        if self.ignored.get() == [0; 8] {
            return;
        }
        for i in 0..self.port.count() {
            if self.is_ignored(i) && !self.port.ready(i) {
                self.set_ignored(i, false);
            }
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
        self.unignore_low();
        // A node whose exchange was handed over but not clocked still shows its line: it
        // is ready only after that exchange (the root logic then finishes it first).
        (0..count)
            .map(|i| (self.next_scan + i) % count)
            .find(|&i| self.port.ready(i) && !self.is_ignored(i))
            .map(|i| self.first + i)
    }

    fn line(&self, node: NodeId) -> bool {
        self.index(node).is_ok_and(|i| self.port.ready(i))
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        &mut self.tx[self.idle][HEADER..HEADER + MAX_MESSAGE]
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        if self.started.is_some() {
            return Err(LinkError::Busy);
        }
        if len > MAX_MESSAGE {
            return Err(LinkError::TooLong {
                len: len as u32,
                max: MAX_MESSAGE as u32,
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
        let what = match transfer {
            Transfer::Exchange(node) => Clocked::Exchange(self.index(node)?),
            Transfer::Broadcast => Clocked::Broadcast,
        };
        let no_ack = self.counters.no_ack;
        let mut wire = Wire {
            port: &mut self.port,
            tx: &mut *self.tx[self.idle ^ 1],
            rx: &mut *self.rx,
            counters: &mut self.counters,
        };
        let len = wire.clock(what, n).await;
        if let (Clocked::Exchange(i), true) = (what, self.counters.no_ack != no_ack) {
            // Its line stayed high through the selection: not offered again until low.
            self.set_ignored(i, true);
        }
        copy_frame(&self.rx[..], len, rx)
    }
}

/// Copy the node's frame (`len` bytes after the header room of the RX bank) into `rx`.
pub(super) fn copy_frame(bank: &[u8], len: usize, rx: &mut [u8]) -> Result<usize, LinkError> {
    match (rx.get_mut(..len), bank.get(HEADER..HEADER + len)) {
        (Some(dst), Some(src)) => {
            dst.copy_from_slice(src);
            Ok(len)
        }
        _ => Err(LinkError::TooLong {
            len: len as u32,
            max: rx.len() as u32,
        }),
    }
}
