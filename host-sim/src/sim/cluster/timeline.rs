//! The event log of one simulation, for the picture of a cluster frame (`links render
//! --nodes N --timeline t.svg`): when each node computed, when each of its exchanges was on
//! the wire, every transfer of every bus, the RC's CPU busy time, and which node rendered
//! each pixel of the first frame.
//!
//! The log is bounded: it keeps at most `limit` intervals (back-to-back intervals of one row
//! merge into one and cost nothing) and counts the ones it had to drop; the pixel map is one
//! entry per pixel of a frame that fits the 1024 x 1024 frame memory.

use super::exec::Ps;
use links_core::link::NodeId;
use std::cell::RefCell;
use std::rc::Rc;

/// The log as the star, the nodes' clocks and the RC's clock share it.
pub type SharedTimeline = Rc<RefCell<Timeline>>;

/// A span of virtual time, `start..end` (ps).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Interval {
    pub start: Ps,
    pub end: Ps,
}

impl Interval {
    pub fn len(&self) -> Ps {
        self.end - self.start
    }

    pub fn is_empty(&self) -> bool {
        self.end <= self.start
    }
}

/// One transfer on a bus: an exchange with a node, or a broadcast (`node: None`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BusTransfer {
    pub at: Interval,
    pub node: Option<NodeId>,
}

/// Most rows of links between RCs of one kind (root links, middle relays' buses) the log
/// keeps: more than any tree the simulator builds.
const MAX_LINK_ROWS: usize = 64;

/// What a star's buses are, for the log's rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkRow {
    /// Buses of nodes (a star, or the leaf relays' buses): the bus rows.
    Leaf,
    /// The root's links to its relays (the firmware's relay code): a row per root link.
    Root,
    /// The middle relays' buses to their leaf relays: a row per middle relay.
    Mid,
}

/// No node rendered this pixel (yet).
pub const NO_NODE: u16 = u16::MAX;

/// The recorded intervals of one simulation.
#[derive(Clone, Debug)]
pub struct Timeline {
    budget: Budget,
    /// Per node: its compute (rendering, checking scenes), in time order, never overlapping.
    pub compute: Vec<Vec<Interval>>,
    /// Per node: its exchanges on the wire.
    pub exchanges: Vec<Vec<Interval>>,
    /// Per bus: its transfers.
    pub bus: Vec<Vec<BusTransfer>>,
    /// The root's links to its relays (the firmware's relay code in the loop), one row per
    /// link: its transfers, `node` the relay exchanged with.
    pub root_links: Vec<Vec<BusTransfer>>,
    /// Under two levels, each middle relay's bus to its leaf relays, one row per middle
    /// relay: its transfers, `node` the leaf relay exchanged with.
    pub mid_links: Vec<Vec<BusTransfer>>,
    /// The RC's CPU (one for all buses): composing, checking and decoding frames.
    pub rc: Vec<Interval>,
    /// Frame 0's size and, per pixel (row-major), the node that rendered it ([`NO_NODE`]:
    /// none) and how many times a node rendered it (saturating).
    pub width: u32,
    pub height: u32,
    pub owner: Vec<u16>,
    pub renders: Vec<u8>,
}

/// The log's bound: entries kept, at most `limit`; entries refused.
#[derive(Clone, Copy, Debug)]
struct Budget {
    limit: usize,
    kept: usize,
    dropped: u64,
}

impl Budget {
    /// Take one entry if there is room (counts a drop otherwise).
    fn take(&mut self) -> bool {
        if self.kept < self.limit {
            self.kept += 1;
            true
        } else {
            self.dropped += 1;
            false
        }
    }

    /// Append `iv` to `row`, merged into the last interval when they touch (no entry taken).
    fn push(&mut self, row: &mut Vec<Interval>, iv: Interval) {
        if iv.is_empty() {
            return;
        }
        match row.last_mut() {
            Some(last) if last.end == iv.start => last.end = iv.end,
            _ => {
                if self.take() {
                    row.push(iv);
                }
            }
        }
    }
}

impl Timeline {
    /// An empty log for `nodes` nodes on `buses` buses, frame `width x height`, keeping at
    /// most `limit` intervals.
    pub fn new(nodes: u16, buses: usize, width: u32, height: u32, limit: usize) -> Self {
        let pixels = width as usize * height as usize;
        Self {
            budget: Budget {
                limit,
                kept: 0,
                dropped: 0,
            },
            compute: vec![Vec::new(); nodes as usize],
            exchanges: vec![Vec::new(); nodes as usize],
            bus: vec![Vec::new(); buses],
            root_links: Vec::new(),
            mid_links: Vec::new(),
            rc: Vec::new(),
            width,
            height,
            owner: vec![NO_NODE; pixels],
            renders: vec![0; pixels],
        }
    }

    /// Whether the log kept every interval.
    pub fn complete(&self) -> bool {
        self.budget.dropped == 0
    }

    /// Intervals not kept because the log was full.
    pub fn dropped(&self) -> u64 {
        self.budget.dropped
    }

    /// Node `node` computed from `start` to `end`.
    pub fn compute(&mut self, node: NodeId, start: Ps, end: Ps) {
        if let Some(row) = self.compute.get_mut(node as usize) {
            self.budget.push(row, Interval { start, end });
        }
    }

    /// The RC's CPU worked from `start` to `end`.
    pub fn rc_work(&mut self, start: Ps, end: Ps) {
        self.budget.push(&mut self.rc, Interval { start, end });
    }

    /// Bus `bus` of the kind `row` carried a transfer from `start` to `end`: an exchange
    /// with `node` (a node, or on links between RCs a relay), or a broadcast. A node bus's
    /// exchange also goes to the node's row.
    pub fn transfer(&mut self, row: LinkRow, bus: usize, node: Option<NodeId>, start: Ps, end: Ps) {
        let at = Interval { start, end };
        let rows = match row {
            LinkRow::Leaf => &mut self.bus,
            LinkRow::Root => &mut self.root_links,
            LinkRow::Mid => &mut self.mid_links,
        };
        // Node buses are laid out up front; rows of links between RCs grow as they appear.
        if row != LinkRow::Leaf && bus < MAX_LINK_ROWS && rows.len() <= bus {
            rows.resize(bus + 1, Vec::new());
        }
        let Some(transfers) = rows.get_mut(bus) else {
            return;
        };
        if at.is_empty() || !self.budget.take() {
            return;
        }
        transfers.push(BusTransfer { at, node });
        if row != LinkRow::Leaf {
            return;
        }
        if let Some(row) = node.and_then(|n| self.exchanges.get_mut(n as usize)) {
            if self.budget.take() {
                row.push(at);
            }
        }
    }

    /// Every root link's transfers, in no particular order.
    pub fn root_link_transfers(&self) -> impl Iterator<Item = &BusTransfer> {
        self.root_links.iter().flatten()
    }

    /// Node `node` rendered `len` pixels of frame 0's row `y` from column `x`.
    pub fn rendered(&mut self, node: NodeId, y: u32, x: u32, len: usize) {
        if y >= self.height || x >= self.width {
            return;
        }
        let row = y as usize * self.width as usize;
        let end = (x as usize).saturating_add(len).min(self.width as usize);
        for i in row + x as usize..row + end {
            self.owner[i] = node;
            self.renders[i] = self.renders[i].saturating_add(1);
        }
    }

    /// Compute time of node `node` in the log (ps).
    pub fn compute_ps(&self, node: usize) -> Ps {
        self.compute
            .get(node)
            .map_or(0, |r| r.iter().map(Interval::len).sum())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn touching_intervals_merge_and_the_limit_counts_drops() {
        let mut t = Timeline::new(2, 1, 4, 1, 3);
        t.compute(0, 0, 10);
        t.compute(0, 10, 25);
        t.compute(0, 30, 40);
        assert_eq!(
            t.compute[0],
            [
                Interval { start: 0, end: 25 },
                Interval { start: 30, end: 40 }
            ]
        );
        assert_eq!(t.compute_ps(0), 35);
        t.transfer(LinkRow::Leaf, 0, Some(1), 40, 50);
        // Full: the bus row took the third entry, the node's exchange is dropped.
        assert_eq!(
            (t.bus[0].len(), t.exchanges[1].len(), t.dropped()),
            (1, 0, 1)
        );
        t.compute(1, 0, 5);
        assert_eq!((t.compute[1].len(), t.dropped()), (0, 2));
        // Still merged when full: a touching interval costs no entry.
        t.compute(0, 40, 45);
        assert_eq!((t.compute_ps(0), t.dropped()), (40, 2));
        assert!(!t.complete());
    }

    #[test]
    fn the_pixel_map_records_each_render_and_clips_to_the_frame() {
        let mut t = Timeline::new(2, 1, 4, 2, 10);
        t.rendered(0, 0, 0, 3);
        t.rendered(1, 0, 3, 5);
        t.rendered(1, 1, 1, 2);
        t.rendered(1, 2, 0, 4);
        assert_eq!(t.owner, [0, 0, 0, 1, NO_NODE, 1, 1, NO_NODE]);
        assert_eq!(t.renders, [1, 1, 1, 1, 0, 1, 1, 0]);
    }
}
