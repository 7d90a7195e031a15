//! The IMSU analog: the RC-NC link over SPI, as traits the node and root logic are generic over.
//!
//! LINKS-1's IMSU swapped two memory banks after a handshake, could write one transfer into
//! several IMSUs at once (overwrite/broadcast), let a second receiver capture what is read
//! (snoop) and add an address offset. Over SPI:
//!
//! - **exchange** = one full-duplex transfer: the node raises its ready line with a frame in
//!   its TX bank; the RC clocks the transfer with the node's chip-select asserted, shifting
//!   its own frame out while the node's shifts in (SPI is a shift-register swap). A short
//!   fixed header phase carries both lengths, the body is the longer of the two.
//! - **broadcast** = the RC asserts several chip-selects and writes one frame; every selected
//!   node receives it.
//! - **snoop** = a further listener on the bus's MISO line (the frame memory's pixel
//!   collector) captures what a node sends while the RC receives it, so pixels do not cross
//!   the RC twice. It is a property of the bus, invisible to these traits.
//! - **address offset** = scene frames carry the byte offset they land at in the bank
//!   ([`crate::wire::Down::Scene`]).
//!
//! DMA double buffering: [`NodeLink::post`] hands a frame to the TX bank and returns at once,
//! so the node renders its next run while the previous one waits for, and crosses, the bus;
//! [`NodeLink::recv`] waits for the transfer to finish. The RC side is double-buffered the
//! same way ([`RootBus::tx_bank`], [`RootBus::start`], [`RootBus::finish`]): the RC composes
//! the next frame and takes the previous node's frame while a transfer is on the wire.

use core::fmt;

/// A node number (0-based, up to 256 nodes).
pub type NodeId = u16;

/// What went wrong on the link itself (frame contents are [`crate::wire`]'s business).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkError {
    /// A frame longer than the bank or the receiver's buffer.
    TooLong { len: u32, max: u32 },
    /// A frame was posted while the TX bank still held one.
    Busy,
    /// The node is not on this bus.
    NoSuchNode { node: NodeId },
    /// The transfer was aborted (bus fault, node vanished).
    Aborted,
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            LinkError::TooLong { len, max } => {
                write!(f, "transfer of {len} bytes exceeds the {max}-byte buffer")
            }
            LinkError::Busy => write!(f, "TX bank still holds an unsent frame"),
            LinkError::NoSuchNode { node } => write!(f, "node {node} is not on this bus"),
            LinkError::Aborted => write!(f, "transfer aborted"),
        }
    }
}

impl core::error::Error for LinkError {}

/// What a node's link delivered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Incoming {
    /// The RC swapped banks with us: our posted frame went out, `len` bytes of the RC's
    /// frame are in the receive buffer.
    Exchanged { len: usize },
    /// A broadcast (overwrite) frame of `len` bytes is in the receive buffer.
    Broadcast { len: usize },
}

/// The node side of the link.
#[allow(async_fn_in_trait)]
pub trait NodeLink {
    /// Put `frame` into the TX bank and raise the ready line. Returns at once; the frame
    /// goes out in the next exchange the RC clocks. Fails with [`LinkError::Busy`] if the
    /// previous frame has not been exchanged yet.
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError>;

    /// Wait for the next transfer addressed to this node (an exchange of the posted frame, or
    /// a broadcast) and copy the received frame into `rx`.
    async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError>;
}

/// What a transfer started with [`RootBus::start`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Transfer {
    /// Swap frames with this node (its chip-select only).
    Exchange(NodeId),
    /// Write to every node of the bus at once (all chip-selects).
    Broadcast,
}

/// One bus of the root's star: the nodes on it, their ready lines, exchange and broadcast.
///
/// RC-side DMA double buffering: the link owns two TX banks. [`RootBus::tx_bank`] is the
/// idle one, where the RC composes its next frame while the other bank is on the wire;
/// [`RootBus::start`] hands the idle bank to the DMA (the banks swap) and returns at once;
/// [`RootBus::finish`] waits for the transfer in flight and copies what the node sent
/// into `rx`. At most one transfer is in flight per bus.
#[allow(async_fn_in_trait)]
pub trait RootBus {
    /// The nodes on this bus: `first..first + count`.
    fn nodes(&self) -> (NodeId, u16);

    /// Wait until some node on this bus has raised its ready line; returns it (lowest
    /// number first when several are ready).
    async fn wait_ready(&mut self) -> NodeId;

    /// A node on this bus whose ready line is up now, if any (the same choice
    /// [`RootBus::wait_ready`] would make).
    fn ready(&self) -> Option<NodeId>;

    /// Whether `node`'s ready line is up now (a relay asks about each of its nodes). The
    /// default knows only the node [`RootBus::ready`] would choose; links that see every
    /// line say so for each.
    fn line(&self, node: NodeId) -> bool {
        self.ready() == Some(node)
    }

    /// The idle TX bank (at least [`crate::wire::MAX_MESSAGE`] bytes): compose the next frame
    /// here, also while a transfer is in flight.
    fn tx_bank(&mut self) -> &mut [u8];

    /// Start clocking the first `len` bytes of the idle TX bank as `transfer` (for an
    /// exchange the node's chip-select is asserted now, committing its TX bank). Fails with
    /// [`LinkError::Busy`] while a transfer is in flight.
    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError>;

    /// Wait for the transfer in flight to end; copy the node's frame (an exchange) into
    /// `rx` and return its length (0 for a broadcast). [`LinkError::Aborted`] if nothing
    /// is in flight.
    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError>;

    /// Most exchanges this bus keeps in flight at once. 1 (the default, every link): one
    /// transfer at a time, each [`RootBus::start`] after the last one's `finish`. More (a
    /// bus of relays, [`crate::relay::RelayedBus`]): `start` may begin an exchange with
    /// another node while some are in flight (it fails with [`LinkError::Busy`] when none
    /// may begin), [`RootBus::ready`] names only nodes an exchange may begin with now,
    /// [`RootBus::wait_ready`] also returns when a frame came back, and each exchange is
    /// taken with [`RootBus::finish_node`] once [`RootBus::arrived`] names it.
    fn in_flight(&self) -> u16 {
        1
    }

    /// A node whose exchange in flight has ended (its frame is here, or it was given up):
    /// [`RootBus::finish_node`] takes it without waiting. Only buses with
    /// [`RootBus::in_flight`] above 1 say.
    fn arrived(&self) -> Option<NodeId> {
        None
    }

    /// How many exchanges are in flight now (started and not yet taken), where the bus
    /// keeps count (only buses with [`RootBus::in_flight`] above 1; 0 otherwise).
    fn flying(&self) -> u16 {
        0
    }

    /// A node with an exchange in flight, if any (only buses with [`RootBus::in_flight`]
    /// above 1 say): the root logic takes them all before it ends.
    fn pending(&self) -> Option<NodeId> {
        None
    }

    /// Whether an exchange with `node` may begin now although its line is not up: its
    /// reply composed ahead, as soon as the node's previous frame was taken, waits below
    /// (at its relay) and the node is clocked the moment its line rises, so its next
    /// exchange costs no round trip through the relays ([`crate::relay::RelayedBus::with_ahead`]).
    /// The root logic asks only for nodes that will post again (they hold jobs). Default:
    /// no (a direct bus clocks a node only with its line up).
    fn ask_ahead(&self, node: NodeId) -> bool {
        let _ = node;
        false
    }

    /// Wait for the exchange with `node` to end and take its frame, as `finish` does (the
    /// default: `finish`).
    async fn finish_node(&mut self, node: NodeId, rx: &mut [u8]) -> Result<usize, LinkError> {
        let _ = node;
        self.finish(rx).await
    }

    /// Take what the link under the bus has finished and start what it can, without
    /// waiting (the root logic calls it whenever it looks for work; a no-op by default).
    fn poll(&mut self) {}

    /// Wait until the bus has news for a relay above it: a node's line rose, or (buses
    /// with [`RootBus::in_flight`] above 1) a frame came back or a node newly waits. The
    /// default: [`RootBus::wait_ready`]. A bus of relays ([`crate::relay::RelayedBus`])
    /// keeps its link moving meanwhile and does not return for nodes it already reported
    /// waiting (a middle relay waits for the root's requests for those).
    async fn wait_news(&mut self) {
        self.wait_ready().await;
    }

    /// Swap frames with `node`: send `tx`, receive its frame into `rx`; returns the number
    /// of bytes received (start + finish, nothing else in flight).
    async fn exchange(
        &mut self,
        node: NodeId,
        tx: &[u8],
        rx: &mut [u8],
    ) -> Result<usize, LinkError> {
        self.begin_exchange(node, tx)?;
        self.finish(rx).await
    }

    /// Begin an exchange with `node`: `tx` into the idle TX bank, then `start` (a bus with
    /// several exchanges in flight takes each one's frame later, [`RootBus::finish_node`]).
    fn begin_exchange(&mut self, node: NodeId, tx: &[u8]) -> Result<(), LinkError> {
        let bank = self.tx_bank();
        let max = bank.len() as u32;
        bank.get_mut(..tx.len())
            .ok_or(LinkError::TooLong {
                len: tx.len() as u32,
                max,
            })?
            .copy_from_slice(tx);
        self.start(Transfer::Exchange(node), tx.len())
    }

    /// Write `frame` to every node on this bus at once (all chip-selects asserted).
    async fn broadcast(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        let bank = self.tx_bank();
        let max = bank.len() as u32;
        bank.get_mut(..frame.len())
            .ok_or(LinkError::TooLong {
                len: frame.len() as u32,
                max,
            })?
            .copy_from_slice(frame);
        self.start(Transfer::Broadcast, frame.len())?;
        self.finish(&mut []).await.map(|_| ())
    }
}
