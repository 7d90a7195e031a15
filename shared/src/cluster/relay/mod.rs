//! Relay RCs: how the F407 board reaches 64 and 256 nodes (`docs/hardware.md`, "Reaching 64
//! and 256 nodes"). A relay is a node on its parent's bus ([`NodeLink`]) and the root of a
//! bus of its own ([`RootBus`]); the root drives its relays through [`RelayedBus`], a
//! [`RootBus`] over the nodes behind them, so `run_bus` and `run_node` run unchanged.
//!
//! - **Broadcasts, store-and-forward:** the root's broadcasts (scene chunks, `SceneEnd`,
//!   `Wake`, `Stop`) cross the parent's link as one link broadcast each, tagged
//!   ([`batch::TAG_FORWARD`]); each relay broadcasts the frame unchanged on its bus once it
//!   has all of it. After forwarding `Stop` the relay ends.
//! - **Exchanges, routed:** the root composes a node's reply before it sees the node's
//!   frame (the link's exchange semantics), so a relay clocks a node only with the root's
//!   reply in hand: it reports the nodes whose ready line is up (`waiting`, in every batch
//!   it posts), the root composes the reply for one of them ([`RelayedBus`]'s `start`), the
//!   reply goes down as a [`Kind::Request`] record, the relay clocks that node's exchange
//!   and sends the node's frame up as a [`Kind::Frame`] record, and `finish` returns it.
//!   The node sees exactly the exchanges of a direct bus.
//! - **Batched:** whatever a relay has gathered when its parent clocks it goes up in one
//!   exchange (one chip-select handshake, header and trailer): the `waiting` bitmap and the
//!   node frames, up to [`BATCH_BYTES`] (one link frame). Routing costs [`RECORD`] bytes
//!   per frame and [`BATCH_HEADER`] per batch; the longest node frame or reply the protocol
//!   produces fits a batch on its own ([`MAX_ROUTED`], checked by a test).
//!
//! Replies are routed by node number: records name a node by its index on its relay's bus
//! (a relay needs no strap to know where it sits; [`RelayedBus`] maps the root's numbers),
//! and a request for a node not on the relay's bus, or not waiting, is counted and dropped.
//! A request goes down once: the root sends it again only when a batch the relay composed
//! after it went down still reports its node waiting (the relay never got it: a damaged
//! half, or no room for it), so a lost down half costs one more exchange and a delivered
//! one costs nothing more. Nothing read from either link can make the relay panic; no heap:
//! the relay's buffers are the caller's.
//!
//! Several node exchanges in flight: [`RelayedBus`] keeps up to [`DEPTH`] per relay
//! ([`SLOTS`] in all; [`RootBus::in_flight`]), so the root's link, the root's CPU and the
//! relays' buses work at once. `run_bus` composes a reply for every node the bus may begin
//! an exchange with ([`RootBus::ready`]) and takes each frame when it comes back
//! ([`RootBus::arrived`], [`RootBus::finish_node`]) without waiting for the others. Each
//! reply waits in its own cell of [`RelayedBuffers`] ([`REPLY_CELL`] bytes; a longer one, a
//! scene repair, in a frame buffer) until it is down and the node's frame is up; the frame
//! stays in the relay batch it came in (one of [`LANDINGS`]) until the root logic takes
//! it, so an exchange in flight costs a cell, not a frame buffer. The root of two levels
//! keeps [`MID_DEPTH`] exchanges in flight per middle relay. The root's link takes, in turn
//! round the
//! relays whose line is up, (1) a relay with a reply to take down for the
//! first time, (2) one whose node's frame may be up, (3) one with nothing in flight and no
//! waiting node the root knows of (it has news). A relay sends one node frame up per batch,
//! so the exchange that brings a frame up usually carries that relay's next request down.
//! A middle relay of a two-level tree runs the same [`run_relay`] with a [`RelayedBus`] over
//! its leaf relays as its bus ([`RootBus::in_flight`] above 1): it begins each requested
//! exchange without waiting, sends each node frame up when its leaf relay brings it, and
//! keeps its bus moving meanwhile ([`RootBus::wait_news`]); its records name the nodes
//! behind its leaf relays 0..32 ([`MAX_RELAY_NODES`]: 4 leaf relays of 8 nodes), and the
//! root's broadcasts cross it still tagged. Its time-out is [`MID_RELAY_TIMEOUT_US`]; the
//! root above waits for both levels ([`root_timeout_us`]).
//! Replies ahead (the root of two levels, [`RelayedBus::with_ahead`]): when a node's frame
//! reaches the root and the node holds jobs (it will post again), the root composes its
//! next reply at once and sends it down as a [`Kind::Ahead`] record; a middle relay begins
//! that exchange with the leaf relay, which keeps the reply in the node's cell
//! ([`RelayBuffers`]' `ahead`) and clocks the node the moment its line rises. So the node's
//! next exchange (a `Poll` too) costs its leaf bus, not a round trip through both levels.
//! Such an exchange waits while the node renders (its time-out is the node's silence bound
//! longer); its reply is sent once and its cell let go at the root, so one that never
//! arrives (the relay later reports the node waiting) ends empty and the node is asked
//! anew. Every node then has an exchange in flight: the root keeps [`TWO_LEVEL_SLOTS`] a
//! link ([`MID_DEPTH`] per middle relay), a middle relay [`MID_SLOTS`].
//! Broadcasts go on the link when the root logic finishes them (as before: a relay forwards
//! one on its bus before it can take the next two). The simulator runs this code (`links
//! render --relay firmware`; `docs/cluster.md`). A relay that stops answering costs the root
//! a time-out per exchange in flight with its nodes ([`RelayedBus::with_timeout`]; without
//! one, those exchanges wait for ever), while the other relays' exchanges go on.

mod batch;
mod node;
mod root;
mod two;

pub use batch::{
    forward, parse, BatchWriter, Kind, Record, Records, Relayed, BATCH_BYTES, BATCH_HEADER,
    MAX_RELAY_NODES, MAX_ROUTED, RECORD, TAG_BATCH, TAG_FORWARD,
};
pub use node::{run_relay, RelayBuffers, RelayReport};
pub use root::{
    RelayedBuffers, RelayedBus, RelayedCounters, RelayedFrames, DEPTH, LANDINGS, MAX_LANDINGS,
    MAX_RELAYS, MID_DEPTH, MID_SLOTS, REPLY_CELL, SLOTS, TWO_LEVEL_SLOTS, TWO_LINK_LANDINGS,
    TWO_LINK_SLOTS,
};
pub use two::TwoLinks;

#[cfg(doc)]
use crate::cluster::link::RootBus;
use crate::cluster::link::{LinkError, NodeId};
use core::fmt;

/// How long the root of a relay tree lets a node exchange through a relay wait for the
/// node's frame before it gives the exchange up ([`RelayedBus::with_timeout`], µs): the
/// firmware's (`rc_fw::link::RELAY_TIMEOUT_US`) and the simulator's. A live relay answers
/// within a few exchanges on each bus (each well under a millisecond); the root logic's own
/// node time-out (`RootConfig::DEFAULT_TIMEOUT_US`) then retires the nodes of a relay that
/// stopped.
pub const RELAY_TIMEOUT_US: u64 = 20_000;

/// How long a middle relay of a two-level tree (`rc-fw --features relay-mid`, and the
/// simulator's) lets a node exchange through one of its leaf relays wait: as long as the
/// root of a one-level tree (a leaf relay forwards the scene's broadcasts for a few ms
/// while requests wait; 10 ms timed some out). The root above it waits for both levels
/// ([`root_timeout_us`]), so a leaf relay that stopped costs the middle relay's exchange
/// (sent up empty) before the root gives up on the middle relay.
pub const MID_RELAY_TIMEOUT_US: u64 = RELAY_TIMEOUT_US;

/// How long the root lets a node exchange through `levels` levels of relays wait
/// ([`RELAY_TIMEOUT_US`] a level).
pub const fn root_timeout_us(levels: u16) -> u64 {
    RELAY_TIMEOUT_US * levels as u64
}

/// How long a root broadcast waits for a relay's report that it has passed on all but the
/// last one (µs; [`Kind::Forwarded`], with [`RelayedBus::with_timeout`]'s clock): a relay
/// forwards the largest broadcast in about 0.5 ms on the F407, so a report lost to a bit
/// error (or a relay that stopped) costs a broadcast this once; that relay is then not
/// waited for until it reports again.
pub const CAST_WAIT_US: u64 = 2_000;

/// What went wrong on a relay link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RelayError {
    /// A frame ended inside a header.
    Truncated,
    /// A frame whose first byte is no relay tag.
    UnknownTag { tag: u8 },
    /// A record of an unknown kind.
    UnknownKind { kind: u8 },
    /// A length beyond the frame or buffer.
    TooLong { len: u32, max: u32 },
    /// A record that does not fit the batch being built.
    Full,
    /// A bus with more nodes than a relay reports ([`MAX_RELAY_NODES`]), or a tree whose
    /// node numbers do not fit.
    TooManyNodes { nodes: u32, most: u32 },
    /// The link under the relay logic failed.
    Link(LinkError),
}

impl fmt::Display for RelayError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            RelayError::Truncated => write!(f, "relay frame ends inside a header"),
            RelayError::UnknownTag { tag } => write!(f, "relay frame with unknown tag {tag:#04x}"),
            RelayError::UnknownKind { kind } => write!(f, "relay record of unknown kind {kind}"),
            RelayError::TooLong { len, max } => {
                write!(f, "relay record of {len} bytes exceeds the {max} left")
            }
            RelayError::Full => write!(f, "relay batch is full"),
            RelayError::TooManyNodes { nodes, most } => {
                write!(f, "{nodes} nodes behind a relay link, at most {most}")
            }
            RelayError::Link(e) => write!(f, "relay link: {e}"),
        }
    }
}

impl core::error::Error for RelayError {}

impl From<LinkError> for RelayError {
    fn from(e: LinkError) -> Self {
        RelayError::Link(e)
    }
}

/// Bit of node `node` in a relay's `waiting` bitmap, for a bus from `first` (None: not on
/// it, or beyond the bitmap).
fn bit(first: NodeId, count: u16, node: NodeId) -> Option<u32> {
    node.checked_sub(first)
        .filter(|&i| i < count && i < MAX_RELAY_NODES)
        .map(|i| 1u32 << i)
}

/// Every link frame a relay exchanges fits both ends' banks.
const _: () = assert!(BATCH_HEADER + RECORD + MAX_ROUTED == crate::cluster::wire::MAX_MESSAGE);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::wire::{self, Down, Job, Region, Up, JOB_QUEUE, MAX_RUN, SCENE_CHUNK};

    /// The longest frames the node and root logic produce fit one routed record.
    #[test]
    fn the_longest_protocol_frames_fit_a_routed_record() {
        let mut buf = [0u8; 4096];
        let rgb = [0xffu8; 3 * MAX_RUN];
        let up = Up::Pixels {
            job: u32::MAX,
            frame: u16::MAX,
            y: u16::MAX,
            x: u16::MAX,
            rgb: &rgb,
            done: true,
        };
        let n = wire::encode(u16::MAX, u16::MAX, &up, &mut buf).unwrap();
        assert!(
            n <= MAX_ROUTED,
            "largest Up is {n} bytes, routed {MAX_ROUTED}"
        );
        let data = [0xffu8; SCENE_CHUNK];
        let scene = Down::Scene {
            frame: u16::MAX,
            offset: u32::MAX,
            total: u32::MAX,
            crc: u32::MAX,
            data: &data,
        };
        let n = wire::encode(u16::MAX, u16::MAX, &scene, &mut buf).unwrap();
        assert!(n <= MAX_ROUTED, "largest Scene is {n} bytes");
        let job = Job {
            id: u32::MAX,
            frame: u16::MAX,
            region: Region::Rect {
                x: u16::MAX,
                y: u16::MAX,
                w: u16::MAX,
                h: u16::MAX,
            },
        };
        let work = Down::Work {
            jobs: [Some(job); JOB_QUEUE],
        };
        let n = wire::encode(u16::MAX, u16::MAX, &work, &mut buf).unwrap();
        assert!(n <= MAX_ROUTED);
        assert_eq!(bit(8, 8, 9), Some(2));
        assert_eq!(bit(8, 8, 16), None);
        assert_eq!(bit(8, 8, 7), None);
        assert_eq!(bit(0, 40, 33), None, "beyond the bitmap");
    }
}
