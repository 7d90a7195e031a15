//! The firmware's relay code in the simulator's loop (`SimConfig::relay` =
//! [`RelayCode::Firmware`]): a one-level relay tree run by the code the boards run
//! (`links_core::relay`), in virtual time.
//!
//! - **The root** (`rc-fw --features relay-root`): `run_bus` over
//!   [`RelayedBus`]`::new(link, ..).with_timeout(clock, RELAY_TIMEOUT_US)` (up to
//!   `links_core::relay::DEPTH` node exchanges in flight per relay), where `link` is
//!   the split master of an emulated SPI bus of its own whose "nodes" are the relays (the
//!   same [`super::spi_bus`] emulation and board-profile timing as every bus), its CPU
//!   charged by [`RcClock`] (composing, decoding) and [`LinkCpu`] (its `RelayedBus`'s
//!   copies).
//! - **Each relay** (`rc-fw --features relay`): `run_relay` between a slave link on the
//!   root's bus (`SlaveTask` + `SlaveHandle`) and the split master of its own leaf bus,
//!   its CPU charged by [`LinkCpu`].
//! - **The nodes**: the simulator's node tasks on the leaf buses, unchanged.
//!
//! Faults: the configuration's bit errors and lost broadcasts act on the root's link too
//! (its own generator, seeded from the same seed); the deterministic every-`n` faults and
//! broadcast drops act on the leaf buses only; a relay that stops answering
//! (`SimConfig::relay_deaths`) is a dead "node" of the root's bus (its DMA never re-arms).

use super::exec::{Ps, SharedClock, Task, VirtualClock};
use super::rccost::{LinkCpu, LinkRole, RcClock};
use super::relay::{FirmwareRelays, RelayCode, Topology, TreeLink, TreeReport, TreeShape};
use super::run::{on_master_bus, on_slave_link, LinkReport, MasterEnd, RootShared};
use super::spi_bus::{LinkModel, SharedWire, Wire, WireTiming};
use super::star::{BusCounters, Faults, Noise, SharedStar, Star};
use super::timeline::SharedTimeline;
use super::{Collect, SimConfig, SimError};
use links_core::relay::{
    run_relay, RelayBuffers, RelayError, RelayReport, RelayedBuffers, RelayedBus, RelayedCounters,
    RelayedFrames, TwoLinks, MAX_RELAYS, MAX_RELAY_NODES, RELAY_TIMEOUT_US, TWO_LINK_SLOTS,
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

/// The relays and nodes per relay of the firmware's relay tree `cfg` asks for, if it asks
/// for one (checked by [`check`]).
pub(super) fn firmware_tree(cfg: &SimConfig) -> Option<(u16, u16, u16)> {
    if cfg.relay != RelayCode::Firmware || cfg.topology == Topology::Star {
        return None;
    }
    let shape = cfg.tree()?.ok()?;
    Some((shape.leaves, cfg.nodes / shape.leaves.max(1), shape.roots))
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
    let fanout = tree.fanout as u32;
    let per_bus = cfg.profile.link.nodes_per_bus as u32;
    if tree.levels() > 1 {
        return no(format!(
            "{} nodes need two levels of relays ({} leaf relays under {} mid relays); the firmware's root of relays (rc-fw --features relay-root) drives one level: at most {fanout} relays x {per_bus} nodes = {} nodes on the {} board (--relay model simulates two levels)",
            cfg.nodes,
            tree.leaves,
            tree.mids,
            fanout * per_bus,
            cfg.profile.name
        ));
    }
    if tree.roots as usize > ROOT_LINKS || tree.roots > tree.leaves {
        return no(format!(
            "the firmware's root of relays drives its {} relays on 1 to {} SPI buses, not {} (--buses)",
            tree.leaves,
            ROOT_LINKS.min(tree.leaves as usize),
            tree.roots
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
    let per = cfg.nodes / tree.leaves;
    if tree.leaves as usize > MAX_RELAYS || per > MAX_RELAY_NODES {
        return no(format!(
            "{} relays of {per} nodes: the firmware's RelayedBus drives at most {MAX_RELAYS} relays of {MAX_RELAY_NODES}",
            tree.leaves
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
        .find(|d| d.node >= tree.leaves || !(d.at_s.is_finite() && d.at_s >= 0.0))
    {
        return no(format!(
            "relay {} cannot stop at {} s ({} relays: 0 to {})",
            d.node,
            d.at_s,
            tree.leaves,
            tree.leaves - 1
        ));
    }
    Ok(())
}

/// The root's links to its relays (emulated SPI buses whose "nodes" are the relays, relay
/// `r` on link `r * links / relays`), what their two ends counted, and what the relay code
/// reported.
pub(super) struct RelayLink {
    pub(super) star: SharedStar,
    wire: SharedWire,
    pub(super) counters: LinkReport,
    relays: u16,
    per_relay: u16,
    /// The root's CPU: its `RcClock` and its `RelayedBus`'s link work.
    root_busy: Rc<Cell<Ps>>,
    relayed: RefCell<RelayedCounters>,
    reports: RefCell<Vec<Option<Result<RelayReport, RelayError>>>>,
}

impl RelayLink {
    /// `relays` relays of `per_relay` nodes on `links` root links at `cfg`'s timing.
    pub(super) fn new(
        clock: &SharedClock,
        cfg: &SimConfig,
        (relays, per_relay, links): (u16, u16, u16),
    ) -> Self {
        let star = Star::new(clock, relays, links, cfg.timing, Faults::default(), None);
        star.borrow_mut().set_noise(Noise {
            seed: cfg.noise.seed ^ ROOT_LINK_SEED,
            ..cfg.noise
        });
        for d in &cfg.relay_deaths {
            star.borrow_mut()
                .kill_at(d.node, (d.at_s * 1e12).round() as Ps);
        }
        let timing = WireTiming::of(&cfg.profile.link, cfg.timing.bit_rate_hz);
        let wire = Wire::new(&star, timing, &[]);
        Self {
            star,
            wire,
            counters: LinkReport::new(links.clamp(1, relays.max(1)) as usize, relays),
            relays,
            per_relay,
            root_busy: Rc::new(Cell::new(0)),
            relayed: RefCell::new(RelayedCounters::default()),
            reports: RefCell::new(vec![None; relays as usize]),
        }
    }

    /// Whether every relay has ended (passed the `Stop` on) or stopped answering.
    pub(super) fn ended(&self) -> bool {
        let star = self.star.borrow();
        self.reports
            .borrow()
            .iter()
            .enumerate()
            .all(|(r, rep)| rep.is_some() || star.is_dead(r))
    }

    /// The root links' traffic and the root's CPU, as the relay model reports them;
    /// `frames_up`: the node frames the relays clocked (each link's share by its relays'
    /// nodes' transfers is not known here: all are put on the first link).
    pub(super) fn report(&self, shape: TreeShape, frames_up: u64) -> TreeReport {
        let links = self
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
        self.star.borrow().bus_count()
    }

    /// What the relay code reported (a relay's error is the run's).
    pub(super) fn firmware_relays(&self) -> Result<FirmwareRelays, SimError> {
        let mut relays = Vec::new();
        for (r, rep) in self.reports.borrow().iter().enumerate() {
            match rep {
                Some(Err(e)) => return Err(SimError::Config(format!("relay {r}: {e}"))),
                Some(Ok(rep)) => relays.push(Some(*rep)),
                None => relays.push(None),
            }
        }
        let star = self.star.borrow();
        let mut link = BusCounters::default();
        for c in star.counters() {
            link.add(&c);
        }
        Ok(FirmwareRelays {
            root: *self.relayed.borrow(),
            relays,
            link,
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
    let mut tasks: Vec<Option<Task<'a>>> = Vec::new();
    // Each root link's master end; the root's one CPU is shared.
    let [end0, end1] = [0, 1].map(|_| MasterEnd {
        split: true,
        report: link.counters.master.clone(),
        cpu: Some(cpu(LinkRole::Root, &link.root_busy, root_cpu_free.clone())),
    });
    let (root_wire, wire1) = (link.wire.clone(), link.wire.clone());
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
                let mut relayed = relayed.with_timeout(timeout_clock, RELAY_TIMEOUT_US);
                let r = run_bus(0, &mut relayed, rc_clock, root, dm, sink).await;
                add_counters(&mut link.relayed.borrow_mut(), &relayed.counters);
                r
            })
            .await
        } else {
            // Two links, as `rc-fw --features relay-root` drives them: `TwoLinks` over a
            // `RelayedBus` on each (TWO_LINK_SLOTS exchanges in flight on each).
            let second_first = link.star.borrow().bus_nodes(1).0.saturating_mul(per);
            on_master_bus(&root_wire, 0, end0, async move |bus0| {
                on_master_bus(&wire1, 1, end1, async move |bus1| {
                    let mut bufs = Box::new([
                        RelayedFrames::<{ TWO_LINK_SLOTS + 2 }>::new(),
                        RelayedFrames::new(),
                    ]);
                    let [b0, b1] = &mut *bufs;
                    let (Ok(r0), Ok(r1)) = (
                        RelayedBus::new(bus0, b0, 0, per).map(|b| b.with_slots::<TWO_LINK_SLOTS>()),
                        RelayedBus::new(bus1, b1, second_first, per)
                            .map(|b| b.with_slots::<TWO_LINK_SLOTS>()),
                    ) else {
                        return Err(failed);
                    };
                    let Ok(mut two) = TwoLinks::new(
                        r0.with_timeout(timeout_clock, RELAY_TIMEOUT_US),
                        r1.with_timeout(clock2, RELAY_TIMEOUT_US),
                    ) else {
                        return Err(failed);
                    };
                    let r = run_bus(0, &mut two, rc_clock, root, dm, sink).await;
                    let (l0, l1) = two.links();
                    add_counters(&mut link.relayed.borrow_mut(), &l0.counters);
                    add_counters(&mut link.relayed.borrow_mut(), &l1.counters);
                    r
                })
                .await
            })
            .await
        };
        bus_results.borrow_mut()[0] = Some(r);
    })));
    for r in 0..link.relays {
        let (root_wire, slots) = (link.wire.clone(), link.counters.slaves.clone());
        let end = MasterEnd {
            split: true,
            report: counters.master.clone(),
            cpu: Some(cpu(LinkRole::Relay, rc_busy, Rc::new(Cell::new(0)))),
        };
        let leaf_wire = wire.clone();
        tasks.push(Some(Box::pin(async move {
            let mut banks: Box<[Bank; 5]> = Box::new([[0u8; BANK]; 5]);
            let out = on_slave_link(&root_wire, r, slots, &mut banks, async move |shared| {
                let mut parent = shared.handle();
                on_master_bus(&leaf_wire, r as usize, end, async move |mut bus| {
                    let mut bufs = Box::new([[0u8; MAX_MESSAGE]; 3]);
                    let [down, up, node] = &mut *bufs;
                    run_relay(&mut parent, &mut bus, RelayBuffers { down, up, node }).await
                })
                .await
            })
            .await;
            link.reports.borrow_mut()[r as usize] = Some(out);
        })));
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
}
