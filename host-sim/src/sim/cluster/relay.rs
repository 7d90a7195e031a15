//! The cluster's topology: a star (the RC drives `SimConfig::buses` buses itself, one CPU
//! for all) or a tree of relay RCs, the F407 board's way to 64 and 256 nodes
//! (docs/hardware.md, "Reaching 64 and 256 nodes").
//!
//! A relay tree has one leaf relay per [`links_core::board::LinkProfile::nodes_per_bus`]
//! nodes, each an F407 driving one bus of its own (the leaf buses of the star emulation) with
//! its own CPU. Up to `fanout` relays hang off one parent's SPI bus (the parent's link, at
//! the profile's timing): the root's directly (one level, up to `fanout x nodes_per_bus`
//! nodes), or through mid relays (two levels, up to `fanout² x nodes_per_bus`).
//!
//! What the simulator charges ([`Relays`]):
//! - **Scene broadcasts, store-and-forward:** each scene chunk and `SceneEnd` crosses every
//!   link on the way from the root once (a broadcast on that link reaches all its relays);
//!   a leaf relay re-broadcasts it on its bus no earlier than it arrived. A link sends a
//!   chunk when the first relay below it asks for it (no pre-fetch: pessimistic).
//! - **Exchanges, forwarded:** every node frame a leaf relay takes crosses every link up to
//!   the root as an exchange whose down half is the relay's reply (full duplex: the longer
//!   of the two); the root's CPU decodes it and composes the reply
//!   ([`super::rccost::RcCost`]). A frame is complete when the root has taken the last of
//!   its node frames (the pixel collector snoops the root's link). With batching (the
//!   buildable tree's default) the frames a relay gathered while its parent's link was busy
//!   go up in one exchange (one chip-select set-up and hold, header and trailer), up to
//!   [`BATCH_BYTES`] each way; the parent serves its relays in the order they asked.
//! - **Not charged:** the latency of the root's scheduling decision. The relays answer their
//!   nodes from the one job table (`links_core::root::RootState`) as if it were local (the
//!   root keeps each relay a queue of jobs ahead); the root link's time is charged, its
//!   round trip per decision is not.

use super::exec::Ps;
use super::rccost::RcCost;
use super::star::{BusCounters, BusTiming};
use links_core::board::BoardProfile;
use links_core::relay::{RelayReport, RelayedCounters};
use links_core::root::RcWork;
use links_core::wire::{self, Down};
use std::collections::{HashMap, VecDeque};
use std::fmt;

/// How the nodes are wired to the root.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Topology {
    /// The RC drives `SimConfig::buses` buses itself, one CPU for all of them.
    #[default]
    Star,
    /// A tree of relay RCs: one leaf relay per `nodes_per_bus` nodes, `fanout` relays on
    /// each parent's link; `batch`: a relay forwards the node frames waiting for its
    /// parent's link in one exchange (one chip-select handshake), up to [`BATCH_BYTES`].
    RelayTree { fanout: u16, batch: bool },
}

impl Topology {
    /// The root's buses when none are asked for: one for a star, the profile's root links
    /// ([`links_core::board::LinkProfile::root_links`]) under a relay tree.
    pub const fn default_buses(&self, profile: &BoardProfile) -> u16 {
        match self {
            Topology::Star => 1,
            Topology::RelayTree { .. } => profile.link.root_links,
        }
    }

    /// The topology `profile` can be built as for `nodes` nodes: a star while one bus holds
    /// them all, a relay tree of `nodes_per_bus` relays per parent otherwise.
    pub const fn buildable(profile: &BoardProfile, nodes: u16) -> Topology {
        let per_bus = profile.link.nodes_per_bus;
        if nodes <= per_bus {
            Topology::Star
        } else {
            Topology::RelayTree {
                fanout: per_bus,
                batch: true,
            }
        }
    }
}

/// Which code runs a relay tree's links above the leaf buses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RelayCode {
    /// The model of this module ([`Relays`]): every node frame forwarded up to the root as
    /// the relays take it, batched, the relays answering their nodes from the one job table
    /// as if it were local.
    #[default]
    Model,
    /// The firmware's relay code in the loop (`links_core::relay`, the simulator's
    /// `run::firmware_relays`): the root's `run_bus` over `RelayedBus` on an emulated SPI
    /// bus to its relays, each relay `run_relay` between a slave link on that bus and the
    /// split master of its own bus. One level of relays (as `rc-fw --features relay-root`
    /// drives), one root bus, the firmware link, the same node count behind every relay.
    Firmware,
}

impl RelayCode {
    pub fn name(self) -> &'static str {
        match self {
            RelayCode::Model => "model",
            RelayCode::Firmware => "firmware",
        }
    }
}

/// What the firmware's relay code did in a run ([`RelayCode::Firmware`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FirmwareRelays {
    /// The root's `RelayedBus`: exchanges on its link (of which only gathering: no request
    /// in them), node exchanges given up at the relay time-out, bad batches, stray frames.
    pub root: RelayedCounters,
    /// Each relay's report, once its `run_relay` ended (on the root's `Stop`); `None`: it
    /// had not when the simulation stopped (a relay that stopped answering, or one that
    /// missed the `Stop`).
    pub relays: Vec<Option<RelayReport>>,
    /// The root's link to its relays: transfers, bytes, busy time, what the configured bit
    /// errors and losses did on it.
    pub link: BusCounters,
    /// Two levels: each middle relay's report (`relays` are then the leaf relays').
    pub mids: Vec<Option<RelayReport>>,
    /// Two levels: what the middle relays' `RelayedBus`es counted, summed.
    pub mid: RelayedCounters,
}

/// Why a relay tree cannot be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TreeError {
    /// A fanout below 2 (a chain, not a tree) or nodes per bus of 0.
    Fanout { fanout: u16, nodes_per_bus: u16 },
    /// More nodes than two levels reach.
    TooManyNodes { nodes: u16, most: u32 },
}

impl fmt::Display for TreeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TreeError::Fanout {
                fanout,
                nodes_per_bus,
            } => write!(
                f,
                "a relay tree needs a fanout of at least 2 and at least 1 node per bus (got {fanout} and {nodes_per_bus})"
            ),
            TreeError::TooManyNodes { nodes, most } => write!(
                f,
                "{nodes} nodes: a relay tree of two levels reaches {most}"
            ),
        }
    }
}

impl std::error::Error for TreeError {}

/// The shape of a relay tree: leaf relays (one bus each), mid relays (0: one level).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TreeShape {
    pub leaves: u16,
    pub mids: u16,
    pub fanout: u16,
    /// The root's SPI buses to its children (the F407 has SPI1/2/3): child `c` (a leaf
    /// relay in a one-level tree, a mid relay in a two-level one) hangs off bus `c % roots`.
    pub roots: u16,
}

impl TreeShape {
    /// The tree for `nodes` nodes at `nodes_per_bus` per leaf bus and `fanout` relays per
    /// parent link.
    pub fn of(nodes: u16, nodes_per_bus: u16, fanout: u16) -> Result<TreeShape, TreeError> {
        if fanout < 2 || nodes_per_bus == 0 {
            return Err(TreeError::Fanout {
                fanout,
                nodes_per_bus,
            });
        }
        let leaves = nodes.max(1).div_ceil(nodes_per_bus);
        let mids = if leaves <= fanout {
            0
        } else {
            leaves.div_ceil(fanout)
        };
        if mids > fanout {
            let most = fanout as u32 * fanout as u32 * nodes_per_bus as u32;
            return Err(TreeError::TooManyNodes { nodes, most });
        }
        Ok(TreeShape {
            leaves,
            mids,
            fanout,
            roots: 1,
        })
    }

    /// The same tree with the root's children spread over `roots` buses (at least 1).
    pub fn with_roots(self, roots: u16) -> TreeShape {
        TreeShape {
            roots: roots.max(1),
            ..self
        }
    }

    /// Levels of relays between the root and the nodes' buses.
    pub fn levels(&self) -> u8 {
        if self.mids == 0 {
            1
        } else {
            2
        }
    }

    /// Links between RCs: the root's (`roots` of them), then each mid relay's.
    pub fn links(&self) -> usize {
        self.roots as usize + self.mids as usize
    }

    /// The root's child above leaf relay `leaf` (the leaf itself in a one-level tree, its
    /// mid relay in a two-level one).
    fn child_of_root(&self, leaf: usize) -> usize {
        if self.mids == 0 {
            leaf
        } else {
            leaf / self.fanout as usize
        }
    }

    /// The root's link to its child `child`.
    fn root_link(&self, child: usize) -> usize {
        child % self.roots.max(1) as usize
    }

    /// The links from the root down to leaf relay `leaf`, root first (1 or 2).
    fn path_down(&self, leaf: usize) -> impl Iterator<Item = usize> {
        let root = self.root_link(self.child_of_root(leaf));
        let mid = (self.mids > 0).then(|| self.roots as usize + leaf / self.fanout as usize);
        std::iter::once(root).chain(mid)
    }

    /// The links from leaf relay `leaf` up to the root, the leaf's parent's first.
    fn path_up(&self, leaf: usize) -> impl Iterator<Item = usize> {
        let root = self.root_link(self.child_of_root(leaf));
        let mid = (self.mids > 0).then(|| self.roots as usize + leaf / self.fanout as usize);
        mid.into_iter().chain(std::iter::once(root))
    }
}

/// Traffic of one link between RCs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TreeLink {
    pub busy_until: Ps,
    pub busy_ps: Ps,
    /// Scene broadcasts and forwarded exchanges (a batch of node frames is one).
    pub broadcasts: u64,
    pub exchanges: u64,
    /// Node frames the exchanges carried up.
    pub frames_up: u64,
    pub clocked_bytes: u64,
}

/// What the relay tree did in a run.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeReport {
    pub shape: TreeShape,
    /// The root's links first (`shape.roots`), then each mid relay's.
    pub links: Vec<TreeLink>,
    /// Time the root's CPU was busy taking forwarded frames (s).
    pub root_busy_s: f64,
}

impl TreeReport {
    /// The busiest of the root's links: its busy time (s).
    pub fn root_link_busy_s(&self) -> f64 {
        let roots = self.shape.roots.max(1) as usize;
        self.links
            .iter()
            .take(roots)
            .map(|l| l.busy_ps)
            .max()
            .unwrap_or(0) as f64
            * 1e-12
    }
}

/// Most bytes one forwarded exchange carries each way: the firmware's relay link, one link
/// frame of routed records (`links_core::relay`: each node frame or reply costs a
/// [`RECORD`] header, each exchange a [`BATCH_HEADER`]).
pub use links_core::relay::BATCH_BYTES;
use links_core::relay::{BATCH_HEADER, RECORD};

/// Node frames a relay has gathered for its parent's link, not on the wire yet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Batch {
    /// The relay (its number among the link's children).
    child: usize,
    /// When its last frame reached the relay.
    ready: Ps,
    up: usize,
    down: usize,
    frames: u64,
    /// The root's CPU time to take them.
    work: Ps,
}

/// The links between RCs and the root's CPU: schedules, and the batches waiting.
#[derive(Clone, Debug)]
struct Wires {
    shape: TreeShape,
    timing: BusTiming,
    /// Whether a relay gathers the node frames that wait for its parent's link into one
    /// exchange (`false`: one exchange per node frame).
    batch: bool,
    links: Vec<TreeLink>,
    /// Per link, the batches waiting for it in the order their relays asked.
    waiting: Vec<VecDeque<Batch>>,
    root_cpu_free: Ps,
    root_busy: Ps,
    /// When the root has taken every node frame put on the links so far.
    taken_up_to: Ps,
}

impl Wires {
    /// Put a transfer of `body` bytes on `link` no earlier than `at`; its end.
    fn claim(&mut self, link: usize, at: Ps, body: usize, exchange: bool) -> Ps {
        let d = self.timing.duration_ps(body, exchange);
        let l = &mut self.links[link];
        let start = at.max(l.busy_until);
        l.busy_until = start + d;
        l.busy_ps += d;
        l.clocked_bytes += self.timing.clocked_bytes(body, exchange);
        if exchange {
            l.exchanges += 1;
        } else {
            l.broadcasts += 1;
        }
        start + d
    }

    /// Node frames `b` wait for `link`: with the relay's frames already waiting if it
    /// batches and they fit, otherwise behind everything waiting.
    fn enqueue(&mut self, link: usize, b: Batch) {
        let q = &mut self.waiting[link];
        let joined = self.batch
            && q.iter_mut()
                .find(|w| w.child == b.child)
                .filter(|w| w.up + b.up <= BATCH_BYTES && w.down + b.down <= BATCH_BYTES)
                .map(|w| {
                    w.ready = w.ready.max(b.ready);
                    w.up += b.up;
                    w.down += b.down;
                    w.frames += b.frames;
                    w.work += b.work;
                })
                .is_some();
        if !joined {
            q.push_back(b);
        }
    }

    /// Put on the wire every waiting batch that starts by `t`: the mid relays' links
    /// first (what they deliver waits for the root's), then the root's (the root's CPU
    /// takes what it delivers).
    fn commit_until(&mut self, t: Ps) {
        let roots = self.shape.roots.max(1) as usize;
        for link in (roots..self.links.len()).chain(0..roots) {
            while let Some(b) = self.waiting[link].front().copied() {
                let start = b.ready.max(self.links[link].busy_until);
                if start > t {
                    break;
                }
                self.waiting[link].pop_front();
                let end = self.claim(link, start, BATCH_HEADER + b.up.max(b.down), true);
                self.links[link].frames_up += b.frames;
                if link < roots {
                    let done = end.max(self.root_cpu_free) + b.work;
                    self.root_cpu_free = done;
                    self.root_busy += b.work;
                    self.taken_up_to = self.taken_up_to.max(done);
                } else {
                    let mid = link - roots;
                    let up = Batch {
                        child: mid,
                        ready: end,
                        ..b
                    };
                    self.enqueue(self.shape.root_link(mid), up);
                }
            }
        }
    }
}

/// The relay tree in virtual time: its links' schedules, the root's CPU, when each scene
/// piece reached the far end of each link.
pub struct Relays {
    wires: Wires,
    cost: RcCost,
    /// (link, frame, chunk offset or `None` for `SceneEnd`) -> arrival at that link's far end.
    arrived: HashMap<(usize, u16, Option<u32>), Ps>,
}

impl Relays {
    /// The tree `shape` on links of `timing`, the root's CPU costing `cost`; `batch`: a
    /// relay gathers the node frames waiting for its parent's link into one exchange.
    pub fn new(shape: TreeShape, batch: bool, timing: BusTiming, cost: RcCost) -> Self {
        Self {
            wires: Wires {
                shape,
                timing,
                batch,
                links: vec![TreeLink::default(); shape.links()],
                waiting: vec![VecDeque::new(); shape.links()],
                root_cpu_free: 0,
                root_busy: 0,
                taken_up_to: 0,
            },
            cost,
            arrived: HashMap::new(),
        }
    }

    /// When leaf relay `leaf` holds the broadcast `frame` it wants to send at `now`: a scene
    /// chunk or `SceneEnd` once it has crossed every link from the root; anything else (the
    /// relay's own `Wake` and `Stop`) at once.
    pub fn broadcast_ready(&mut self, leaf: usize, frame: &[u8], now: Ps) -> Ps {
        let key = match wire::decode::<Down>(frame).map(|e| e.msg) {
            Ok(Down::Scene { frame, offset, .. }) => (frame, Some(offset)),
            Ok(Down::SceneEnd { frame, .. }) => (frame, None),
            _ => return now,
        };
        self.wires.commit_until(now);
        let mut t = now;
        for link in self.wires.shape.path_down(leaf) {
            t = match self.arrived.get(&(link, key.0, key.1)) {
                Some(&a) => t.max(a),
                None => {
                    let end = self.wires.claim(link, t, frame.len(), false);
                    self.arrived.insert((link, key.0, key.1), end);
                    end
                }
            };
        }
        t
    }

    /// Leaf relay `leaf` took node frame `up` (and replied `down_len` bytes) at `at`: it
    /// forwards it to the root (through its mid relay, if any), whose CPU decodes it and
    /// composes the reply.
    pub fn forward_up(&mut self, leaf: usize, up: &[u8], down_len: usize, at: Ps) {
        let work = self.cost.duration_ps(&RcWork::Decode { frame: up }, false)
            + self
                .cost
                .duration_ps(&RcWork::Encode { bytes: down_len }, false);
        self.wires.commit_until(at);
        let shape = self.wires.shape;
        let link = shape.path_up(leaf).next().unwrap_or(0);
        let child = if shape.mids == 0 {
            leaf
        } else {
            leaf % shape.fanout as usize
        };
        let b = Batch {
            child,
            ready: at,
            up: RECORD + up.len(),
            down: RECORD + down_len,
            frames: 1,
            work,
        };
        self.wires.enqueue(link, b);
    }

    /// When the root will have taken every node frame forwarded so far.
    pub fn taken_up_to(&self) -> Ps {
        let mut w = self.wires.clone();
        w.commit_until(Ps::MAX);
        w.taken_up_to
    }

    /// The links' traffic and the root's busy time, every forwarded frame taken.
    pub fn report(&self) -> TreeReport {
        let mut w = self.wires.clone();
        w.commit_until(Ps::MAX);
        TreeReport {
            shape: w.shape,
            links: w.links,
            root_busy_s: w.root_busy as f64 * 1e-12,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use links_core::board::BoardProfile;

    #[test]
    fn trees_have_one_relay_per_bus_and_fanout_relays_per_link() {
        let s = |n| TreeShape::of(n, 8, 8).map(|s| (s.leaves, s.mids, s.levels()));
        assert_eq!(s(9), Ok((2, 0, 1)));
        assert_eq!(s(64), Ok((8, 0, 1)));
        assert_eq!(s(65), Ok((9, 2, 2)));
        assert_eq!(s(256), Ok((32, 4, 2)));
        assert_eq!(s(512), Ok((64, 8, 2)));
        assert!(matches!(
            TreeShape::of(513, 8, 8),
            Err(TreeError::TooManyNodes { most: 512, .. })
        ));
        assert!(TreeShape::of(64, 8, 1).is_err());
        let t = TreeShape::of(256, 8, 8).unwrap();
        assert_eq!(t.path_down(17).collect::<Vec<_>>(), [0, 3]);
        assert_eq!(t.path_up(31).collect::<Vec<_>>(), [4, 0]);
        // The root on three buses: mid relay m on bus m % 3, the mids' links after them.
        let t3 = t.with_roots(3);
        assert_eq!(t3.links(), 3 + 4);
        assert_eq!(t3.path_down(17).collect::<Vec<_>>(), [2, 5]);
        assert_eq!(t3.path_up(31).collect::<Vec<_>>(), [6, 0]);
        let one = TreeShape::of(64, 8, 8).unwrap().with_roots(3);
        assert_eq!(one.path_up(7).collect::<Vec<_>>(), [1]);
        assert_eq!(Topology::buildable(&BoardProfile::F407, 8), Topology::Star);
        assert_eq!(
            Topology::buildable(&BoardProfile::F407, 64),
            Topology::RelayTree {
                fanout: 8,
                batch: true
            }
        );
        assert_eq!(
            Topology::buildable(&BoardProfile::IDEAL, 256),
            Topology::Star
        );
    }

    /// A scene chunk crosses the root's link once, whichever relay asks first; the others
    /// find it there. Worked by hand on a 1 MHz link with no handshake and a 1-byte header:
    /// an encoded chunk of `n` bytes takes (1 + n) x 8 us.
    #[test]
    fn scene_chunks_are_stored_and_forwarded_once_per_link() {
        let timing = BusTiming {
            bit_rate_hz: 1e6,
            overhead_ns: 0.0,
            header_bytes: 1,
            trailer_bytes: 0,
        };
        let shape = TreeShape::of(256, 8, 8).unwrap();
        let mut r = Relays::new(shape, false, timing, RcCost::FREE);
        let mut buf = [0u8; 256];
        let msg = Down::Scene {
            frame: 0,
            offset: 0,
            total: 100,
            crc: 7,
            data: &[5u8; 100],
        };
        let n = wire::encode(0, 0, &msg, &mut buf).unwrap();
        let hop = (1 + n as u64) * 8 * 1_000_000;
        // Leaf 0 asks at t = 0: root link, then mid relay 1's link.
        assert_eq!(r.broadcast_ready(0, &buf[..n], 0), 2 * hop);
        // Leaf 1 (same mid relay) finds it there; leaf 8 (mid relay 2) waits for one hop.
        assert_eq!(r.broadcast_ready(1, &buf[..n], 5), 2 * hop);
        assert_eq!(r.broadcast_ready(8, &buf[..n], 2 * hop), 3 * hop);
        let rep = r.report();
        assert_eq!(rep.links[0].broadcasts, 1);
        assert_eq!((rep.links[1].broadcasts, rep.links[2].broadcasts), (1, 1));
        // A relay's own broadcast (Stop) waits for nothing.
        let n = wire::encode(0, 0, &Down::Stop, &mut buf).unwrap();
        assert_eq!(r.broadcast_ready(3, &buf[..n], 42), 42);
        // A forwarded exchange of 10 bytes up, 20 down, each routed in a 5-byte record of a
        // batch with a 5-byte header: 31 bytes (link header + 5 + 5 + 20) per hop.
        r.forward_up(0, &[0u8; 10], 20, 10_000_000_000);
        assert_eq!((BATCH_HEADER, RECORD), (5, 5));
        let ex = 31 * 8 * 1_000_000;
        assert_eq!(r.taken_up_to(), 10_000_000_000 + 2 * ex);
    }

    /// Frames a relay gathers while its parent's link is busy go up in one exchange; worked
    /// by hand on a 1 MHz link, no handshake, a 1-byte header: a 10-byte frame routed alone
    /// (5-byte batch header, 5-byte record) takes (1 + 5 + 15) x 8 = 168 us, two in one
    /// exchange (1 + 5 + 30) x 8 = 288 us.
    #[test]
    fn a_relay_batches_the_frames_that_wait_for_its_link() {
        let timing = BusTiming {
            bit_rate_hz: 1e6,
            overhead_ns: 0.0,
            header_bytes: 1,
            trailer_bytes: 0,
        };
        let shape = TreeShape::of(16, 8, 8).unwrap();
        let us = 1_000_000;
        let run = |batch| {
            let mut r = Relays::new(shape, batch, timing, RcCost::FREE);
            r.forward_up(0, &[0u8; 10], 0, 0); // on the wire 0..88 us
            r.forward_up(0, &[0u8; 10], 0, 0); // waits for the link
            r.forward_up(0, &[0u8; 10], 0, 1); // joins it if batching
            r.forward_up(1, &[0u8; 10], 0, 2); // another relay: its own exchange
            let l = r.report().links[0];
            (l.exchanges, l.frames_up, r.taken_up_to())
        };
        assert_eq!(run(true), (3, 4, (168 + 288 + 168) * us));
        assert_eq!(run(false), (4, 4, 4 * 168 * us));
    }
}
