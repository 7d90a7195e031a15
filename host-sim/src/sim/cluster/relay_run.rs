//! The firmware's relay code in the simulator's loop (`SimConfig::relay` =
//! [`RelayCode::Firmware`]): a relay tree of one or two levels run by the code the boards
//! run (`links_core::relay`), in virtual time.
//!
//! - **The root** (`rc-fw --features relay-root`, over two levels `relay-root-mid`):
//!   `run_bus` over [`RelayedBus`]`::new(link, ..).with_timeout(clock,
//!   root_timeout_us(levels))` (up to `links_core::relay::DEPTH` node exchanges in flight per
//!   leaf relay, `MID_DEPTH` per middle relay), on two links through
//!   [`TwoLinks`] as the F407 drives them, where each `link` is the split master of an
//!   emulated SPI bus of its own whose "nodes" are the root's children (the same
//!   [`super::spi_bus`] emulation and board-profile timing as every bus), its CPU charged
//!   by [`RcClock`] (composing, decoding) and [`LinkCpu`] (its `RelayedBus`'s copies).
//! - **Two levels: each middle relay** (`rc-fw --features relay-mid`): `run_relay` between a
//!   slave link on the root's bus and a [`RelayedBus`] over the split master of its own
//!   bus, whose "nodes" are 4 leaf relays (its report to the root has bits for 32 nodes),
//!   given up after `MID_RELAY_TIMEOUT_US`. Built only with the firmware's relay code,
//!   the F407's default for two levels (`SimConfig::with_board_relays`).
//! - **Each leaf relay** (`rc-fw --features relay`): `run_relay` between a slave link on its
//!   parent's bus (`SlaveTask` + `SlaveHandle`) and the split master of its own leaf bus,
//!   its CPU charged by [`LinkCpu`].
//! - **The nodes**: the simulator's node tasks on the leaf buses, unchanged.
//!
//! Faults: the configuration's bit errors and lost broadcasts act on the root's links and
//! the middle relays' buses too (generators of their own, seeded from the same seed); the
//! deterministic every-`n` faults and broadcast drops act on the leaf buses only; a relay
//! that stops answering (`SimConfig::relay_deaths`: one of the root's children) is a dead
//! "node" of the root's bus (its DMA never re-arms).

use super::exec::{Ps, SharedClock, Task, VirtualClock};
use super::rccost::{LinkCpu, LinkRole, RcClock};
use super::relay::{FirmwareRelays, RelayCode, Topology, TreeLink, TreeReport, TreeShape};
use super::run::{on_master_bus, on_slave_link, LinkReport, MasterEnd, RootShared};
use super::spi_bus::{LinkModel, SharedWire, Wire, WireTiming};
use super::star::{BusCounters, Faults, Noise, SharedStar, Star};
use super::timeline::SharedTimeline;
use super::{Collect, SimConfig, SimError};
use links_core::relay::{
    root_timeout_us, run_relay, RelayBuffers, RelayError, RelayReport, RelayedBuffers, RelayedBus,
    RelayedCounters, RelayedFrames, TwoLinks, DEPTH, MAX_RELAYS, MAX_RELAY_NODES, MID_DEPTH,
    MID_RELAY_TIMEOUT_US, MID_SLOTS, REPLY_CELL, TWO_LEVEL_SLOTS, TWO_LINK_LANDINGS,
    TWO_LINK_SLOTS,
};
use links_core::root::{run_bus, RootError};
use links_core::spi::{Bank, BANK};
use links_core::wire::MAX_MESSAGE;
use std::cell::{Cell, RefCell};
use std::rc::Rc;

/// The root link's noise generator is seeded apart from the leaf buses' (same rates).
const ROOT_LINK_SEED: u64 = 0x9e37_79b9_7f4a_7c15;

/// Most SPI buses the firmware's root of relays drives its relays on (`rc-fw --features
/// relay-root`: SPI1 and SPI2 of the F407).
pub(super) const ROOT_LINKS: usize = 2;

/// The firmware's relay tree: the root's children on its links, and under two levels
/// the leaf relays behind each middle relay.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct FirmwareTree {
    /// The root's children: leaf relays (one level) or middle relays (two).
    pub(super) children: u16,
    /// Nodes behind each child.
    pub(super) per_child: u16,
    /// The root's links.
    pub(super) roots: u16,
    /// Leaf relays behind each middle relay (0: one level).
    pub(super) leaves_per_mid: u16,
    /// Nodes on each leaf relay's bus.
    pub(super) per_leaf: u16,
}

impl FirmwareTree {
    /// The leaf relays.
    pub(super) fn leaves(&self) -> u16 {
        self.children * self.leaves_per_mid.max(1)
    }
}

/// The firmware's relay tree `cfg` asks for, if it asks for one (checked by [`check`]):
/// the model's leaf relays (`TreeShape::leaves`); under two levels each middle relay
/// drives as many leaf relays as its report to the root has bits for
/// ([`MAX_RELAY_NODES`] nodes: 4 leaf relays of 8), so 256 nodes are 8 middle relays of 4.
pub(super) fn firmware_tree(cfg: &SimConfig) -> Option<FirmwareTree> {
    if cfg.relay != RelayCode::Firmware || cfg.topology == Topology::Star {
        return None;
    }
    let shape = cfg.tree()?.ok()?;
    let leaves = shape.leaves.max(1);
    let per_leaf = cfg.nodes / leaves;
    if shape.levels() == 1 {
        return Some(FirmwareTree {
            children: leaves,
            per_child: per_leaf,
            roots: shape.roots,
            leaves_per_mid: 0,
            per_leaf,
        });
    }
    let leaves_per_mid = (MAX_RELAY_NODES / per_leaf.max(1)).max(1);
    Some(FirmwareTree {
        children: leaves.div_ceil(leaves_per_mid),
        per_child: per_leaf * leaves_per_mid,
        roots: shape.roots,
        leaves_per_mid,
        per_leaf,
    })
}

/// Refuse what the firmware's relay code cannot run, saying why.
pub(super) fn check(cfg: &SimConfig) -> Result<(), SimError> {
    let no = |s: String| Err(SimError::Config(s));
    let tree = match (cfg.relay, cfg.tree()) {
        (RelayCode::Firmware, Some(Ok(shape))) => shape,
        _ if !cfg.relay_deaths.is_empty() => {
            return no(
                "a relay that stops answering needs a relay tree run by the firmware's relay code (--relay firmware)"
                    .into(),
            )
        }
        _ => return Ok(()),
    };
    let Some(fw) = firmware_tree(cfg) else {
        return Ok(());
    };
    if tree.levels() > 2 {
        return no(format!("{} levels of relays", tree.levels()));
    }
    if tree.roots as usize > ROOT_LINKS || tree.roots > fw.children {
        return no(format!(
            "the firmware's root of relays drives its {} relays on 1 to {} SPI buses, not {} (--buses)",
            fw.children,
            ROOT_LINKS.min(fw.children as usize),
            tree.roots
        ));
    }
    if fw.leaves_per_mid > 0 && tree.leaves % fw.leaves_per_mid != 0 {
        return no(format!(
            "{} leaf relays under middle relays of {}: the firmware's middle relay reports {MAX_RELAY_NODES} nodes (give a multiple of {} nodes)",
            tree.leaves,
            fw.leaves_per_mid,
            fw.leaves_per_mid as u32 * cfg.profile.link.nodes_per_bus as u32
        ));
    }
    if cfg.link != LinkModel::Firmware {
        return no(
            "the firmware's relay code runs over the firmware link (--link firmware)".into(),
        );
    }
    if !cfg.nodes.is_multiple_of(tree.leaves) {
        return no(format!(
            "{} nodes over {} relays: the firmware's RelayedBus puts the same number of nodes behind every relay (give a multiple of {})",
            cfg.nodes, tree.leaves, tree.leaves
        ));
    }
    let per_link = fw.children.div_ceil(fw.roots.max(1));
    if per_link as usize > MAX_RELAYS || fw.per_child > MAX_RELAY_NODES {
        return no(format!(
            "{} relays of {} nodes on {} link(s): the firmware's RelayedBus drives at most {MAX_RELAYS} relays of {MAX_RELAY_NODES} on a link",
            fw.children, fw.per_child, fw.roots
        ));
    }
    if cfg.backup_line || !cfg.spi_dead.is_empty() {
        return no(
            "the serial backup line is not simulated with the firmware's relay code (--relay model)"
                .into(),
        );
    }
    if let Some(d) = cfg
        .relay_deaths
        .iter()
        .find(|d| d.node >= fw.children || !(d.at_s.is_finite() && d.at_s >= 0.0))
    {
        return no(format!(
            "relay {} cannot stop at {} s ({} relays under the root: 0 to {})",
            d.node,
            d.at_s,
            fw.children,
            fw.children - 1
        ));
    }
    Ok(())
}

/// The root's links to its relays (emulated SPI buses whose "nodes" are the relays, relay
/// `r` on link `r * links / relays`), what their two ends counted, and what the relay code
/// reported.
pub(super) struct RelayLink {
    /// The root's links; their "nodes" are the root's children.
    pub(super) links: RcLinks,
    /// The root's children and the nodes behind each.
    relays: u16,
    per_relay: u16,
    /// The root's CPU: its `RcClock` and its `RelayedBus`'s link work.
    root_busy: Rc<Cell<Ps>>,
    /// Two levels: the middle relays' buses to their leaf relays.
    pub(super) mid: Option<MidLinks>,
}

/// The middle relays' buses of a two-level tree (emulated SPI buses whose "nodes" are the
/// leaf relays: leaf `l` on middle relay `l / leaves_per_mid`'s bus).
pub(super) struct MidLinks {
    /// Bus `m`: middle relay `m`'s; its "nodes" are the leaf relays.
    pub(super) links: RcLinks,
    leaves_per_mid: u16,
    per_leaf: u16,
}

/// Links between RCs (the root's to its children, or the middle relays' to their leaf
/// relays): emulated SPI buses whose "nodes" are relays, what their two ends counted, what
/// the `RelayedBus`es driving them counted (summed), and the relays' reports.
pub(super) struct RcLinks {
    pub(super) star: SharedStar,
    wire: SharedWire,
    pub(super) counters: LinkReport,
    relayed: RefCell<RelayedCounters>,
    reports: RefCell<Vec<Option<Result<RelayReport, RelayError>>>>,
}

impl RcLinks {
    /// `relays` relays over `buses` buses at `cfg`'s timing, their noise seeded with `seed`.
    fn new(clock: &SharedClock, cfg: &SimConfig, relays: u16, buses: u16, seed: u64) -> Self {
        let star = Star::new(clock, relays, buses, cfg.timing, Faults::default(), None);
        star.borrow_mut().set_noise(Noise {
            seed: cfg.noise.seed ^ seed,
            ..cfg.noise
        });
        let timing = WireTiming::of(&cfg.profile.link, cfg.timing.bit_rate_hz);
        let wire = Wire::new(&star, timing, &[]);
        RcLinks {
            star,
            wire,
            counters: LinkReport::new(buses.clamp(1, relays.max(1)) as usize, relays),
            relayed: RefCell::new(RelayedCounters::default()),
            reports: RefCell::new(vec![None; relays as usize]),
        }
    }
}

/// The middle relays' buses' noise generator (same rates as the leaf buses').
const MID_LINK_SEED: u64 = 0x6a09_e667_f3bc_c909;

impl RelayLink {
    /// The firmware tree `tree` at `cfg`'s timing: the root's children on its links, and
    /// under two levels the middle relays' buses.
    pub(super) fn new(clock: &SharedClock, cfg: &SimConfig, tree: FirmwareTree) -> Self {
        let relays = tree.children;
        let links = RcLinks::new(clock, cfg, relays, tree.roots, ROOT_LINK_SEED);
        for d in &cfg.relay_deaths {
            links
                .star
                .borrow_mut()
                .kill_at(d.node, (d.at_s * 1e12).round() as Ps);
        }
        let mid = (tree.leaves_per_mid > 0).then(|| MidLinks {
            links: RcLinks::new(clock, cfg, tree.leaves(), relays, MID_LINK_SEED),
            leaves_per_mid: tree.leaves_per_mid,
            per_leaf: tree.per_leaf,
        });
        Self {
            links,
            relays,
            per_relay: tree.per_child,
            root_busy: Rc::new(Cell::new(0)),
            mid,
        }
    }

    /// Whether every relay has ended (passed the `Stop` on) or stopped answering (with the
    /// leaf relays behind it).
    pub(super) fn ended(&self) -> bool {
        let star = self.links.star.borrow();
        let children = self
            .links
            .reports
            .borrow()
            .iter()
            .enumerate()
            .all(|(r, rep)| rep.is_some() || star.is_dead(r));
        children
            && self.mid.as_ref().is_none_or(|m| {
                m.links.reports.borrow().iter().enumerate().all(|(l, rep)| {
                    rep.is_some() || star.is_dead(l / m.leaves_per_mid.max(1) as usize)
                })
            })
    }

    /// The root links' traffic and the root's CPU, as the relay model reports them;
    /// `frames_up`: the node frames the relays clocked (each link's share by its relays'
    /// nodes' transfers is not known here: all are put on the first link).
    pub(super) fn report(&self, shape: TreeShape, frames_up: u64) -> TreeReport {
        let links = self
            .links
            .star
            .borrow()
            .counters()
            .iter()
            .enumerate()
            .map(|(k, c)| TreeLink {
                busy_until: 0,
                busy_ps: c.busy_ps,
                broadcasts: c.broadcasts,
                exchanges: c.exchanges,
                frames_up: if k == 0 { frames_up } else { 0 },
                clocked_bytes: c.clocked_bytes,
            })
            .collect();
        TreeReport {
            shape,
            links,
            root_busy_s: self.root_busy.get() as f64 * 1e-12,
        }
    }

    /// The root's links.
    pub(super) fn links(&self) -> usize {
        self.links.star.borrow().bus_count()
    }

    /// What the relay code reported (a relay's error is the run's).
    pub(super) fn firmware_relays(&self) -> Result<FirmwareRelays, SimError> {
        let reports = |all: &RefCell<Vec<Option<Result<RelayReport, RelayError>>>>, what| {
            let mut out = Vec::new();
            for (r, rep) in all.borrow().iter().enumerate() {
                match rep {
                    Some(Err(e)) => return Err(SimError::Config(format!("{what} {r}: {e}"))),
                    Some(Ok(rep)) => out.push(Some(*rep)),
                    None => out.push(None),
                }
            }
            Ok(out)
        };
        let children = reports(&self.links.reports, "relay")?;
        let (relays, mids, mid) = match &self.mid {
            None => (children, Vec::new(), RelayedCounters::default()),
            Some(m) => (
                reports(&m.links.reports, "leaf relay")?,
                children,
                *m.links.relayed.borrow(),
            ),
        };
        let star = self.links.star.borrow();
        let mut link = BusCounters::default();
        for c in star.counters() {
            link.add(&c);
        }
        Ok(FirmwareRelays {
            root: *self.links.relayed.borrow(),
            relays,
            link,
            mids,
            mid,
        })
    }
}

/// The tasks of a firmware relay tree: the root (`run_bus` over `RelayedBus` on each of its
/// links), then one per relay (`run_relay` between its slave link on the root's bus and the master
/// of leaf bus `r` of `wire`). The leaf relays' CPU time adds up in `rc_busy`.
pub(super) fn relay_tasks<'a, S: AsRef<[u8]>>(
    cfg: &SimConfig,
    clock: &SharedClock,
    (wire, counters): (&SharedWire, &LinkReport),
    link: &'a RelayLink,
    (rc_busy, log): (&Rc<Cell<Ps>>, &Option<SharedTimeline>),
    (root, sink, bus_results, dm): RootShared<'a, S>,
) -> Vec<Option<Task<'a>>> {
    let cpu = |role, busy: &Rc<Cell<Ps>>, cpu_free| LinkCpu {
        clock: clock.clone(),
        cost: cfg.rc_cost,
        role,
        cpu_free,
        busy: busy.clone(),
    };
    let root_cpu_free = Rc::new(Cell::new(0 as Ps));
    let rc_clock = Rc::new(RcClock {
        clock: clock.clone(),
        cost: cfg.rc_cost,
        sink_pixels: cfg.collect == Collect::ViaRoot,
        cpu_free: root_cpu_free.clone(),
        busy: link.root_busy.clone(),
        timeline: log.clone(),
    });
    let per = link.per_relay;
    // The root waits for every level below it.
    let root_timeout = root_timeout_us(if link.mid.is_some() { 2 } else { 1 });
    // Under two levels replies go ahead and wait at the leaf relays while the nodes render
    // a run: as long as a node may be silent.
    let ahead_us = (cfg.node_timeout_s * 1e6) as u64;
    let mut tasks: Vec<Option<Task<'a>>> = Vec::new();
    // Each root link's master end; the root's one CPU is shared.
    let [end0, end1] = [0, 1].map(|_| MasterEnd {
        split: true,
        report: link.links.counters.master.clone(),
        cpu: Some(cpu(LinkRole::Root, &link.root_busy, root_cpu_free.clone())),
    });
    let (root_wire, wire1) = (link.links.wire.clone(), link.links.wire.clone());
    let (timeout_clock, clock2) = (VirtualClock(clock.clone()), VirtualClock(clock.clone()));
    tasks.push(Some(Box::pin(async move {
        let rc_clock = &*rc_clock;
        let failed = RootError::TooManyNodes {
            nodes: link.relays.saturating_mul(per),
        };
        let r = if link.links() == 1 {
            // One link: `RelayedBus` with SLOTS exchanges in flight.
            on_master_bus(&root_wire, 0, end0, async move |bus| {
                let mut bufs = Box::new(RelayedBuffers::new());
                let Ok(relayed) = RelayedBus::new(bus, &mut *bufs, 0, per) else {
                    return Err(failed);
                };
                let mut relayed = relayed.with_timeout(timeout_clock, root_timeout);
                let r = run_bus(0, &mut relayed, rc_clock, root, dm, sink).await;
                add_counters(&mut link.links.relayed.borrow_mut(), &relayed.counters);
                r
            })
            .await
        } else {
            // Two links, as `rc-fw --features relay-root` (and `relay-root-mid`) drives them:
            // `TwoLinks` over a `RelayedBus` on each (TWO_LINK_SLOTS exchanges in flight on
            // each, DEPTH per leaf relay; under two levels MID_DEPTH per middle relay,
            // TWO_LEVEL_SLOTS a link, replies ahead).
            let second_first = link.links.star.borrow().bus_nodes(1).0.saturating_mul(per);
            let (depth, ahead_us) = match link.mid {
                Some(_) => (MID_DEPTH, ahead_us),
                None => (DEPTH, 0),
            };
            on_master_bus(&root_wire, 0, end0, async move |bus0| {
                on_master_bus(&wire1, 1, end1, async move |bus1| {
                    let mut bufs = Box::new([
                        RelayedFrames::<TWO_LINK_SLOTS, TWO_LINK_LANDINGS>::new(),
                        RelayedFrames::new(),
                    ]);
                    let [b0, b1] = &mut *bufs;
                    let (Ok(r0), Ok(r1)) = (
                        RelayedBus::new(bus0, b0, 0, per)
                            .map(|b| b.with_slots::<TWO_LEVEL_SLOTS>()),
                        RelayedBus::new(bus1, b1, second_first, per)
                            .map(|b| b.with_slots::<TWO_LEVEL_SLOTS>()),
                    ) else {
                        return Err(failed);
                    };
                    let Ok(mut two) = TwoLinks::new(
                        r0.with_timeout(timeout_clock, root_timeout)
                            .with_depth(depth)
                            .with_ahead(ahead_us),
                        r1.with_timeout(clock2, root_timeout)
                            .with_depth(depth)
                            .with_ahead(ahead_us),
                    ) else {
                        return Err(failed);
                    };
                    let r = run_bus(0, &mut two, rc_clock, root, dm, sink).await;
                    let (l0, l1) = two.links();
                    add_counters(&mut link.links.relayed.borrow_mut(), &l0.counters);
                    add_counters(&mut link.links.relayed.borrow_mut(), &l1.counters);
                    r
                })
                .await
            })
            .await
        };
        bus_results.borrow_mut()[0] = Some(r);
    })));
    // The leaf relays: `run_relay` between a slave link on their parent's bus (the root's,
    // or under two levels their middle relay's) and the master of their own leaf bus.
    let (parents, leaf_reports) = match &link.mid {
        None => (
            (&link.links.wire, &link.links.counters),
            &link.links.reports,
        ),
        Some(m) => ((&m.links.wire, &m.links.counters), &m.links.reports),
    };
    let leaves = leaf_reports.borrow().len() as u16;
    for l in 0..leaves {
        let (parent_wire, slots) = (parents.0.clone(), parents.1.slaves.clone());
        let end = MasterEnd {
            split: true,
            report: counters.master.clone(),
            cpu: Some(cpu(LinkRole::Relay, rc_busy, Rc::new(Cell::new(0)))),
        };
        let leaf_wire = wire.clone();
        tasks.push(Some(Box::pin(async move {
            let mut banks: Box<[Bank; 5]> = Box::new([[0u8; BANK]; 5]);
            let out = on_slave_link(&parent_wire, l, slots, &mut banks, async move |shared| {
                let mut parent = shared.handle();
                on_master_bus(&leaf_wire, l as usize, end, async move |mut bus| {
                    let mut bufs = Box::new([[0u8; MAX_MESSAGE]; 3]);
                    let mut cells = Box::new([[0u8; REPLY_CELL]; MAX_RELAY_NODES as usize]);
                    // A reply cell per node of its bus, for replies sent ahead.
                    let [down, up, node] = &mut *bufs;
                    let ahead = &mut cells[..];
                    let buffers = RelayBuffers {
                        down,
                        up,
                        node,
                        ahead,
                    };
                    run_relay(&mut parent, &mut bus, buffers).await
                })
                .await
            })
            .await;
            leaf_reports.borrow_mut()[l as usize] = Some(out);
        })));
    }
    // Two levels: each middle relay, `run_relay` between a slave link on the root's bus and
    // a `RelayedBus` over its leaf relays (as `rc-fw --features relay-mid` runs it), with
    // its own time-out below the root's.
    if let Some(mid) = &link.mid {
        for m in 0..link.relays {
            let (root_wire, slots) = (link.links.wire.clone(), link.links.counters.slaves.clone());
            let end = MasterEnd {
                split: true,
                report: mid.links.counters.master.clone(),
                cpu: Some(cpu(LinkRole::Relay, rc_busy, Rc::new(Cell::new(0)))),
            };
            let (mid_wire, per_leaf) = (mid.links.wire.clone(), mid.per_leaf);
            let timeout_clock = VirtualClock(clock.clone());
            tasks.push(Some(Box::pin(async move {
                let mut banks: Box<[Bank; 5]> = Box::new([[0u8; BANK]; 5]);
                let out = on_slave_link(&root_wire, m, slots, &mut banks, async move |shared| {
                    let mut parent = shared.handle();
                    on_master_bus(&mid_wire, m as usize, end, async move |bus| {
                        let mut frames = Box::new(RelayedFrames::<MID_SLOTS>::new());
                        let mut bufs = Box::new([[0u8; MAX_MESSAGE]; 3]);
                        let [down, up, node] = &mut *bufs;
                        // An exchange in flight for every node behind it, replies ahead.
                        let mut leaves = RelayedBus::new(bus, &mut *frames, 0, per_leaf)?
                            .with_slots::<MID_SLOTS>()
                            .with_timeout(timeout_clock, MID_RELAY_TIMEOUT_US)
                            .with_ahead(ahead_us)
                            .with_depth(per_leaf);
                        let buffers = RelayBuffers {
                            down,
                            up,
                            node,
                            ahead: &mut [],
                        };
                        let r = run_relay(&mut parent, &mut leaves, buffers).await;
                        add_counters(&mut mid.links.relayed.borrow_mut(), &leaves.counters);
                        r
                    })
                    .await
                })
                .await;
                link.links.reports.borrow_mut()[m as usize] = Some(out);
            })));
        }
    }
    tasks
}

/// `b`'s counts added to `a`'s (the most in flight: the larger).
fn add_counters(a: &mut RelayedCounters, b: &RelayedCounters) {
    a.link_exchanges += b.link_exchanges;
    a.gathering += b.gathering;
    a.bad_batches += b.bad_batches;
    a.stray_frames += b.stray_frames;
    a.timeouts += b.timeouts;
    a.most_in_flight = a.most_in_flight.max(b.most_in_flight);
    a.ahead += b.ahead;
    a.lost_ahead += b.lost_ahead;
}
