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
use super::star::{Faults, Noise, SharedStar, Star};
use super::timeline::SharedTimeline;
use super::{Collect, SimConfig, SimError};
use links_core::relay::{
    run_relay, RelayBuffers, RelayError, RelayReport, RelayedBuffers, RelayedBus, RelayedCounters,
    MAX_RELAYS, MAX_RELAY_NODES, RELAY_TIMEOUT_US,
};
use links_core::root::{run_bus, RootError};
use links_core::spi::{Bank, BANK};
use links_core::wire::MAX_MESSAGE;
use std::cell::{Cell, RefCell};
use std::rc::Rc;

/// The root link's noise generator is seeded apart from the leaf buses' (same rates).
const ROOT_LINK_SEED: u64 = 0x9e37_79b9_7f4a_7c15;

/// The relays and nodes per relay of the firmware's relay tree `cfg` asks for, if it asks
/// for one (checked by [`check`]).
pub(super) fn firmware_tree(cfg: &SimConfig) -> Option<(u16, u16)> {
    if cfg.relay != RelayCode::Firmware || cfg.topology == Topology::Star {
        return None;
    }
    let shape = cfg.tree()?.ok()?;
    Some((shape.leaves, cfg.nodes / shape.leaves.max(1)))
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
    if tree.roots > 1 {
        return no(format!(
            "the firmware's root of relays drives its relays on one SPI bus, not {} (--buses 1, or --relay model)",
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

/// The root's link to its relays (an emulated SPI bus whose "nodes" are the relays), what
/// its two ends counted, and what the relay code reported.
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
    /// `relays` relays of `per_relay` nodes on the root's link at `cfg`'s timing.
    pub(super) fn new(clock: &SharedClock, cfg: &SimConfig, relays: u16, per_relay: u16) -> Self {
        let star = Star::new(clock, relays, 1, cfg.timing, Faults::default(), None);
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
            counters: LinkReport::new(1, relays),
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

    /// The root link's traffic and the root's CPU, as the relay model reports them;
    /// `frames_up`: the node frames the relays clocked.
    pub(super) fn report(&self, shape: TreeShape, frames_up: u64) -> TreeReport {
        let c = self.star.borrow().counters()[0];
        TreeReport {
            shape,
            links: vec![TreeLink {
                busy_until: 0,
                busy_ps: c.busy_ps,
                broadcasts: c.broadcasts,
                exchanges: c.exchanges,
                frames_up,
                clocked_bytes: c.clocked_bytes,
            }],
            root_busy_s: self.root_busy.get() as f64 * 1e-12,
        }
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
        Ok(FirmwareRelays {
            root: *self.relayed.borrow(),
            relays,
            link: self.star.borrow().counters()[0],
        })
    }
}

/// The tasks of a firmware relay tree: the root (`run_bus` over `RelayedBus` on its link),
/// then one per relay (`run_relay` between its slave link on the root's bus and the master
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
    let rc_clock = RcClock {
        clock: clock.clone(),
        cost: cfg.rc_cost,
        sink_pixels: cfg.collect == Collect::ViaRoot,
        cpu_free: root_cpu_free.clone(),
        busy: link.root_busy.clone(),
        timeline: log.clone(),
    };
    let end = MasterEnd {
        split: true,
        report: link.counters.master.clone(),
        cpu: Some(cpu(LinkRole::Root, &link.root_busy, root_cpu_free)),
    };
    let (root_wire, per) = (link.wire.clone(), link.per_relay);
    let timeout_clock = VirtualClock(clock.clone());
    let mut tasks: Vec<Option<Task<'a>>> = Vec::new();
    tasks.push(Some(Box::pin(async move {
        let rc_clock = &rc_clock;
        on_master_bus(&root_wire, 0, end, async move |bus| {
            let mut bufs = Box::new(RelayedBuffers::new());
            let r = match RelayedBus::new(bus, &mut bufs, 0, per) {
                Ok(relayed) => {
                    let mut relayed = relayed.with_timeout(timeout_clock, RELAY_TIMEOUT_US);
                    let r = run_bus(0, &mut relayed, rc_clock, root, dm, sink).await;
                    *link.relayed.borrow_mut() = relayed.counters;
                    r
                }
                Err(_) => Err(RootError::TooManyNodes {
                    nodes: link.relays.saturating_mul(per),
                }),
            };
            bus_results.borrow_mut()[0] = Some(r);
        })
        .await
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
