//! The firmware's own link in the simulator: an emulated SPI peripheral in virtual time under
//! `links_core::spi` (the RC's split master, [`MasterFront`] + [`MasterTask`], where the
//! board overlaps, else the inline [`MasterLink`]; each node's `SlaveTask` and
//! `SlaveHandle`), so the cluster runs the code the boards run.
//!
//! - **RC side** ([`SpiMaster`], a [`MasterPort`] per bus): chip-selects asserted with the
//!   profile's set-up time, released with its hold time; full-duplex transfers of whole bytes
//!   at the bus's bit rate; MISO read from the one selected node (the multiplexer), ignored
//!   during a broadcast (every node selected); handshake lines read as levels.
//! - **Node side** ([`SpiSlave`], a [`SlavePort`] per node): DMA armed over a whole bank
//!   (bytes land only while armed and selected), the ready line, the end of a transfer on
//!   the chip-select's rising edge.
//! - **Faults on the wire**: bit errors per direction at the [`super::star::Noise`] rates
//!   (every clocked byte exposed: header, body, trailer), the every-`n` body faults of
//!   [`super::star::Faults`], lost broadcasts (the node's DMA hears nothing), a stuck
//!   handshake line ([`StuckReady`]), a node that stops answering (its DMA never re-arms:
//!   [`super::star::NodeDeath`]).
//!
//! Every duration comes from the board profile ([`WireTiming::of`]). The relay tree's
//! links above the leaf buses stay modelled ([`super::relay`]); the star supplies the
//! buses' node ranges, counters, the noise generator, the collector and the timeline.

use super::exec::{Delay, PollFn, Ps, SharedClock};
use super::rccost::{LinkCpu, LinkRole};
use super::star::SharedStar;
use links_core::board::LinkProfile;
use links_core::link::{LinkError, NodeId, RootBus, Transfer};
use links_core::spi::nc_header;
use links_core::spi::{
    Armed, Bank, MasterCounters, MasterFront, MasterLink, MasterPort, MasterShared, MasterTask,
    PortError, Select, SlaveCounters, SlavePort, HEADER, TRAILER,
};
use std::cell::RefCell;
use std::future::Future;
use std::pin::Pin;
use std::rc::Rc;
use std::task::{Context, Poll};

/// Which link the cluster simulation runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkModel {
    /// The firmware's `links_core::spi` over the emulated SPI peripheral (this module).
    Firmware,
    /// The idealised star ([`super::star`]): the same wire time per transfer, no protocol.
    Ideal,
}

impl LinkModel {
    /// The firmware link where the board's framing is the firmware's (header and trailer
    /// of `links_core::spi`), the idealised star otherwise.
    pub fn for_link(link: &LinkProfile) -> Self {
        if Self::firmware_framing(link) {
            LinkModel::Firmware
        } else {
            LinkModel::Ideal
        }
    }

    /// Whether `link` frames transfers as the firmware does (so its code can run on it).
    pub fn firmware_framing(link: &LinkProfile) -> bool {
        link.header_bytes as usize == HEADER && link.trailer_bytes as usize == TRAILER
    }

    pub fn name(self) -> &'static str {
        match self {
            LinkModel::Firmware => "firmware",
            LinkModel::Ideal => "ideal",
        }
    }
}

/// Fault injection: node `node`'s handshake line sticks at `high` from `at_s` seconds of
/// virtual time on, whatever the node drives (firmware link only).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StuckReady {
    pub node: NodeId,
    pub at_s: f64,
    pub high: bool,
}

/// The emulated peripheral's timing, from the board's link profile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WireTiming {
    pub bit_rate_hz: f64,
    pub cs_setup_ps: Ps,
    pub cs_hold_ps: Ps,
}

impl WireTiming {
    /// `link`'s chip-select set-up and hold, at `bit_rate_hz` (the profile's, or the
    /// command line's override).
    pub fn of(link: &LinkProfile, bit_rate_hz: f64) -> Self {
        Self {
            bit_rate_hz,
            cs_setup_ps: link.cs_setup_ns as Ps * 1000,
            cs_hold_ps: link.cs_hold_ns as Ps * 1000,
        }
    }

    /// Time to clock `bytes` bytes (rounded up to a picosecond).
    pub fn bytes_ps(&self, bytes: usize) -> Ps {
        (bytes as f64 * 8.0 * 1e12 / self.bit_rate_hz).ceil() as Ps
    }
}

/// A node's DMA armed over a bank.
struct Arm {
    tx: Vec<u8>,
    rx: Vec<u8>,
    pos: usize,
    /// Selected since armed.
    touched: bool,
    /// Selected and released: the transfer is over.
    done: bool,
}

#[derive(Default)]
struct NodePins {
    arm: Option<Arm>,
    /// The level the node drives on its handshake line.
    driven: bool,
    selected: bool,
    /// The bus the node sits on.
    bus: usize,
    stuck: Option<(Ps, bool)>,
}

struct BusPins {
    first: NodeId,
    count: u16,
    selected: Option<Select>,
    /// Transfers since the chip-select fell (0 = header phase, 1 = body phase).
    phase: u32,
    since: Ps,
    clocked: u64,
    /// The frame lengths an exchange's headers announced: the RC's, the node's (the
    /// every-`n` body faults hit only frame bytes, not the padding).
    frames: (usize, usize),
    /// Rising edges the nodes drove on their handshake lines so far.
    edges: u64,
    /// The earliest time the next selection may start: a leaf relay's scene piece is
    /// clocked on its bus only once it has reached the relay (relay tree; 0: at once).
    not_before: Ps,
}

/// The chip-select, handshake and DMA state of every bus and node.
pub struct Wire {
    star: SharedStar,
    clock: SharedClock,
    timing: WireTiming,
    nodes: Vec<NodePins>,
    buses: Vec<BusPins>,
}

pub type SharedWire = Rc<RefCell<Wire>>;

impl Wire {
    /// The pins over `star`'s buses; `stuck` lines stick at their times.
    pub fn new(star: &SharedStar, timing: WireTiming, stuck: &[StuckReady]) -> SharedWire {
        let s = star.borrow();
        let clock = s.clock().clone();
        let buses: Vec<BusPins> = (0..s.bus_count())
            .map(|b| {
                let (first, count) = s.bus_nodes(b);
                BusPins {
                    first,
                    count,
                    selected: None,
                    phase: 0,
                    since: 0,
                    clocked: 0,
                    frames: (0, 0),
                    edges: 0,
                    not_before: 0,
                }
            })
            .collect();
        let n = buses.last().map_or(0, |b| (b.first + b.count) as usize);
        let mut nodes: Vec<NodePins> = (0..n).map(|_| NodePins::default()).collect();
        for (b, bus) in buses.iter().enumerate() {
            for p in &mut nodes[bus.first as usize..(bus.first + bus.count) as usize] {
                p.bus = b;
            }
        }
        for st in stuck {
            let at = (st.at_s * 1e12).round() as Ps;
            if let Some(p) = nodes.get_mut(st.node as usize) {
                p.stuck = Some((at, st.high));
                clock.borrow_mut().at(at);
            }
        }
        drop(s);
        Rc::new(RefCell::new(Wire {
            star: star.clone(),
            clock,
            timing,
            nodes,
            buses,
        }))
    }

    fn now(&self) -> Ps {
        self.clock.borrow().now
    }

    fn touch(&self) {
        self.clock.borrow_mut().changes += 1;
    }

    /// The level of node `n`'s handshake line (a stuck line wins).
    fn level(&self, n: usize) -> bool {
        let Some(p) = self.nodes.get(n) else {
            return false;
        };
        match p.stuck {
            Some((at, high)) if self.now() >= at => high,
            _ => p.driven,
        }
    }

    fn dead(&self, n: usize) -> bool {
        self.star.borrow().is_dead(n)
    }

    fn select(&mut self, bus: usize, sel: Select) {
        let now = self.now();
        let b = &mut self.buses[bus];
        b.selected = Some(sel);
        b.phase = 0;
        b.since = now;
        b.clocked = 0;
        let (first, count) = (b.first, b.count);
        for i in 0..count {
            if sel != Select::All && sel != Select::One(i) {
                continue;
            }
            let n = (first + i) as usize;
            let p = &mut self.nodes[n];
            p.selected = true;
            if let Some(a) = &mut p.arm {
                // The node's port drops its ready line the moment its chip-select falls.
                p.driven = false;
                a.touched = true;
            }
        }
        self.touch();
    }

    /// One full-duplex transfer on `bus`: MOSI into every selected armed node, MISO from
    /// the one selected node (none: the line floats high). Returns its duration: the bytes
    /// of a selection are clocked back to back, so their time is rounded once per selection.
    fn transfer(&mut self, bus: usize, tx: &[u8], rx: &mut [u8]) -> Ps {
        let Some(sel) = self.buses[bus].selected else {
            return 0;
        };
        let phase = self.buses[bus].phase;
        self.buses[bus].phase += 1;
        let before = self.buses[bus].clocked;
        self.buses[bus].clocked += tx.len() as u64;
        let after = self.buses[bus].clocked;
        let d = self.timing.bytes_ps(after as usize) - self.timing.bytes_ps(before as usize);
        let first = self.buses[bus].first;
        rx.fill(0xFF);
        match sel {
            Select::One(i) => self.exchange_bytes(bus, (first + i) as usize, phase, tx, rx),
            Select::All => self.broadcast_bytes(bus, tx, rx),
        }
        self.touch();
        d
    }

    fn exchange_bytes(&mut self, bus: usize, n: usize, phase: u32, tx: &[u8], rx: &mut [u8]) {
        let mut down = tx.to_vec();
        if phase == 0 {
            let rc = tx
                .get(2..4)
                .map_or(0, |l| u16::from_le_bytes([l[0], l[1]]) as usize);
            let nc = self.nodes[n]
                .arm
                .as_ref()
                .and_then(|a| nc_header(&a.tx))
                .filter(|h| h.kind & 1 != 0)
                .map_or(0, |h| h.len as usize);
            self.buses[bus].frames = (rc, nc);
        }
        let (rc_len, nc_len) = self.buses[bus].frames;
        let mut star = self.star.borrow_mut();
        if phase == 1 {
            let k = rc_len.min(down.len());
            star.body_fault(1, &mut down[..k], bus);
        }
        let hit_down = star.wire_noise(0, &mut down);
        if let Some(a) = self.nodes[n].arm.as_mut().filter(|a| !a.done) {
            let end = (a.pos + down.len()).min(a.rx.len());
            let k = end.saturating_sub(a.pos);
            a.rx[a.pos..end].copy_from_slice(&down[..k]);
            let src_end = (a.pos + rx.len()).min(a.tx.len());
            let m = src_end.saturating_sub(a.pos);
            rx[..m].copy_from_slice(&a.tx[a.pos..src_end]);
            a.pos += down.len();
        }
        if phase == 1 {
            let k = nc_len.min(rx.len());
            star.body_fault(0, &mut rx[..k], bus);
        }
        let hit_up = star.wire_noise(1, rx);
        if let Some(c) = star.counters_mut(bus) {
            c.corrupted_down += u64::from(hit_down);
            c.corrupted_up += u64::from(hit_up);
        }
    }

    fn broadcast_bytes(&mut self, bus: usize, tx: &[u8], rx: &mut [u8]) {
        let (first, count) = (self.buses[bus].first, self.buses[bus].count);
        let mut star = self.star.borrow_mut();
        for i in 0..count {
            let n = first + i;
            let p = &mut self.nodes[n as usize];
            let Some(a) = p.arm.as_mut().filter(|a| !a.done) else {
                continue;
            };
            let mut copy = tx.to_vec();
            if !star.broadcast_copy(bus, (n, i, count), &mut copy) {
                // Off the bus for this broadcast: its DMA hears nothing.
                continue;
            }
            let end = (a.pos + copy.len()).min(a.rx.len());
            let k = end.saturating_sub(a.pos);
            a.rx[a.pos..end].copy_from_slice(&copy[..k]);
            a.pos += copy.len();
        }
        // Every selected node drives MISO: the RC ignores what it reads.
        rx.fill(0);
    }

    /// Chip-selects rise: every touched armed transfer is over. Returns the selection's
    /// wire time so far (set-up and bytes) and what it was.
    fn deselect(&mut self, bus: usize) -> Option<(Select, Ps, u64)> {
        let b = &mut self.buses[bus];
        let sel = b.selected.take()?;
        let (first, count, since, clocked) = (b.first, b.count, b.since, b.clocked);
        for n in first..first + count {
            let p = &mut self.nodes[n as usize];
            if std::mem::take(&mut p.selected) {
                if let Some(a) = p.arm.as_mut().filter(|a| a.touched) {
                    a.done = true;
                }
            }
        }
        self.touch();
        Some((sel, since, clocked))
    }
}

/// The RC's SPI master, chip-selects and handshake inputs of one bus.
pub struct SpiMaster {
    wire: SharedWire,
    bus: usize,
    /// Wire time of the open selection not yet waited for (set-up and bytes).
    owed: Ps,
}

impl SpiMaster {
    pub fn new(wire: &SharedWire, bus: usize) -> Self {
        Self {
            wire: wire.clone(),
            bus,
            owed: 0,
        }
    }

    fn delay(&self, ps: Ps) -> Delay {
        let w = self.wire.borrow();
        let now = w.now();
        Delay::new(&w.clock, now + ps)
    }
}

impl MasterPort for SpiMaster {
    fn count(&self) -> u16 {
        self.wire.borrow().buses[self.bus].count
    }

    fn ready(&self, i: u16) -> bool {
        let w = self.wire.borrow();
        let first = w.buses[self.bus].first;
        i < w.buses[self.bus].count && w.level((first + i) as usize)
    }

    async fn wait_any_ready(&mut self) {
        // The edge interrupt: a rising edge the nodes drive, or a line found high that was
        // low when the wait began (a line sticking high). A line stuck high from before
        // does not wake it (the link ignores such a node until it is seen low).
        let edges = self.wire.borrow().buses[self.bus].edges;
        let low: Vec<bool> = (0..self.count()).map(|i| !self.ready(i)).collect();
        PollFn(|| {
            let rose = self.wire.borrow().buses[self.bus].edges != edges;
            let high = low
                .iter()
                .enumerate()
                .any(|(i, &l)| l && self.ready(i as u16));
            (rose || high).then_some(())
        })
        .await
    }

    async fn select(&mut self, sel: Select) {
        // A relay's broadcast waits for its scene piece (the split master's task takes the
        // transfer the moment the front hands it over).
        let (now, not_before, clock) = {
            let mut w = self.wire.borrow_mut();
            let at = std::mem::take(&mut w.buses[self.bus].not_before);
            (w.now(), at, w.clock.clone())
        };
        if not_before > now {
            Delay::new(&clock, not_before).await;
        }
        self.wire.borrow_mut().select(self.bus, sel);
        self.owed = self.wire.borrow().timing.cs_setup_ps;
    }

    async fn deselect(&mut self) {
        // The set-up and the bytes of this selection, charged in one step: nothing the
        // master or the nodes do depends on the time inside a selection (a node sees its
        // transfer only when the chip-select rises), and one event instead of one per phase
        // keeps large clusters fast to simulate.
        let owed = std::mem::take(&mut self.owed);
        if owed > 0 {
            self.delay(owed).await;
        }
        let done = self.wire.borrow_mut().deselect(self.bus);
        let (hold, star) = {
            let w = self.wire.borrow();
            (w.timing.cs_hold_ps, w.star.clone())
        };
        if let Some((sel, since, clocked)) = done {
            let end = self.wire.borrow().now() + hold;
            let node = match sel {
                Select::One(i) => Some(self.wire.borrow().buses[self.bus].first + i),
                Select::All => None,
            };
            let mut s = star.borrow_mut();
            s.log_transfer(self.bus, node, since, end);
            if let Some(c) = s.counters_mut(self.bus) {
                c.busy_ps += end - since;
                c.clocked_bytes += clocked;
            }
        }
        self.delay(hold).await;
    }

    async fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), PortError> {
        if tx.len() != rx.len() {
            return Err(PortError);
        }
        let d = self.wire.borrow_mut().transfer(self.bus, tx, rx);
        self.owed += d;
        Ok(())
    }
}

/// Node `node`'s SPI slave with DMA, chip-select sense and handshake output.
pub struct SpiSlave {
    wire: SharedWire,
    node: usize,
}

impl SpiSlave {
    pub fn new(wire: &SharedWire, node: NodeId) -> Self {
        Self {
            wire: wire.clone(),
            node: node as usize,
        }
    }
}

impl SlavePort for SpiSlave {
    async fn transfer(
        &mut self,
        tx: &[u8],
        rx: &mut [u8],
        cancel: impl Future<Output = ()>,
    ) -> Result<Armed, PortError> {
        if tx.len() != rx.len() {
            return Err(PortError);
        }
        if self.wire.borrow().dead(self.node) {
            // A node that stopped answering never re-arms its DMA.
            return core::future::pending().await;
        }
        {
            let mut w = self.wire.borrow_mut();
            let p = &mut w.nodes[self.node];
            let touched = p.selected;
            p.arm = Some(Arm {
                tx: tx.to_vec(),
                rx: vec![0; rx.len()],
                pos: 0,
                touched,
                done: false,
            });
            w.touch();
        }
        let mut cancel = std::pin::pin!(cancel);
        core::future::poll_fn(|cx: &mut Context<'_>| {
            let mut w = self.wire.borrow_mut();
            if w.dead(self.node) {
                w.nodes[self.node].arm = None;
                return Poll::Pending;
            }
            let p = &mut w.nodes[self.node];
            if p.arm.as_ref().is_some_and(|a| a.done) {
                if let Some(a) = p.arm.take() {
                    let n = a.pos.min(rx.len());
                    rx[..n].copy_from_slice(&a.rx[..n]);
                }
                w.touch();
                return Poll::Ready(Ok(Armed::Done));
            }
            let idle = !p.selected && !p.arm.as_ref().is_some_and(|a| a.touched);
            if idle && cancel.as_mut().poll(cx).is_ready() {
                p.arm = None;
                w.touch();
                return Poll::Ready(Ok(Armed::Cancelled));
            }
            Poll::Pending
        })
        .await
    }

    fn set_ready(&mut self, high: bool) {
        let mut w = self.wire.borrow_mut();
        let high = high && !w.dead(self.node);
        if w.nodes[self.node].driven != high {
            w.nodes[self.node].driven = high;
            if high {
                let b = w.nodes[self.node].bus;
                w.buses[b].edges += 1;
            }
            w.touch();
        }
    }
}

/// The RC's link code on one bus: the inline [`MasterLink`] (clocks inside `finish`), or
/// the split [`MasterFront`] whose [`MasterTask`] clocks over the port while the RC
/// composes (the board's, where the profile's `rc_overlaps` holds; run the pair with
/// [`Overlapped`]).
pub enum MasterEnd<'s, 'b> {
    Inline(MasterLink<'b, SpiMaster>),
    Split(MasterFront<'s, 'b>),
}

impl MasterEnd<'_, '_> {
    fn counters(&self) -> MasterCounters {
        match self {
            MasterEnd::Inline(l) => l.counters,
            MasterEnd::Split(f) => f.counters(),
        }
    }
}

impl RootBus for MasterEnd<'_, '_> {
    fn nodes(&self) -> (NodeId, u16) {
        match self {
            MasterEnd::Inline(l) => l.nodes(),
            MasterEnd::Split(f) => f.nodes(),
        }
    }

    fn ready(&self) -> Option<NodeId> {
        match self {
            MasterEnd::Inline(l) => l.ready(),
            MasterEnd::Split(f) => f.ready(),
        }
    }

    fn line(&self, node: NodeId) -> bool {
        match self {
            MasterEnd::Inline(l) => l.line(node),
            MasterEnd::Split(f) => f.line(node),
        }
    }

    async fn wait_ready(&mut self) -> NodeId {
        match self {
            MasterEnd::Inline(l) => l.wait_ready().await,
            MasterEnd::Split(f) => f.wait_ready().await,
        }
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        match self {
            MasterEnd::Inline(l) => l.tx_bank(),
            MasterEnd::Split(f) => f.tx_bank(),
        }
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        match self {
            MasterEnd::Inline(l) => l.start(transfer, len),
            MasterEnd::Split(f) => f.start(transfer, len),
        }
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        match self {
            MasterEnd::Inline(l) => l.finish(rx).await,
            MasterEnd::Split(f) => f.finish(rx).await,
        }
    }
}

/// The RC's bus logic (over a [`MasterEnd::Split`]) and its [`MasterTask`] polled as one
/// simulated task: the task, then the logic, again while a pass moved the state they share
/// (the executor detects quiescence by the world's change counter, which a hand-over alone
/// does not touch). On the board they are two executors at two interrupt priorities.
pub struct Overlapped<'s, 'b, F, T> {
    pub shared: &'s MasterShared<'b>,
    pub logic: Pin<Box<F>>,
    pub task: Pin<Box<T>>,
}

impl<F: Future, T: Future> Future for Overlapped<'_, '_, F, T> {
    type Output = F::Output;
    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<F::Output> {
        loop {
            let before = self.shared.activity();
            let _ = self.task.as_mut().poll(cx);
            if let Poll::Ready(v) = self.logic.as_mut().poll(cx) {
                return Poll::Ready(v);
            }
            if self.shared.activity() == before {
                return Poll::Pending;
            }
        }
    }
}

/// The clocking half of the split link over the emulated port, as a future for
/// [`Overlapped`].
pub async fn master_task(wire: SharedWire, bus: usize, shared: &MasterShared<'_>) {
    let mut port = SpiMaster::new(&wire, bus);
    MasterTask::new().run(&mut port, shared).await
}

/// The RC's end of one bus on the firmware link: its link code ([`MasterEnd`]) over
/// [`SpiMaster`], with what the star's bus did around it (a relay tree's scene pieces
/// arriving, node frames forwarded up, the collector's snoop, the bus's counters).
pub struct FirmwareBus<'s, 'b> {
    link: MasterEnd<'s, 'b>,
    wire: SharedWire,
    star: SharedStar,
    clock: SharedClock,
    bus: usize,
    /// The started transfer: a broadcast's earliest start (relay tree) and its length.
    started: Option<(Transfer, Ps, usize)>,
    /// A finished transfer whose result waits for the relay code's CPU work after it (until
    /// the time given): kept so that a caller that drops `finish` while it waits (a middle
    /// relay races its bus against its parent) gets the result when it calls again.
    after: Option<(Ps, usize)>,
    /// Where the link's counters are kept for the report.
    report: Rc<RefCell<Vec<MasterCounters>>>,
    /// The relay code's CPU work around each transfer (firmware relay tree), if charged.
    cpu: Option<LinkCpu>,
}

impl<'s, 'b> FirmwareBus<'s, 'b> {
    /// Bus `bus` over `banks` (two TX, one RX): the split link over `split` (whose task
    /// the caller runs, see [`Overlapped`]), the inline one without.
    pub fn new(
        wire: &SharedWire,
        bus: usize,
        banks: &'b mut [Bank; 3],
        split: Option<&'s MasterShared<'b>>,
        report: Rc<RefCell<Vec<MasterCounters>>>,
    ) -> Self {
        let (star, first, count) = {
            let w = wire.borrow();
            (w.star.clone(), w.buses[bus].first, w.buses[bus].count)
        };
        let clock = star.borrow().clock().clone();
        let [tx0, tx1, rx] = banks;
        let link = match split {
            Some(shared) => {
                MasterEnd::Split(MasterFront::new(shared, first, count, [tx0, tx1], rx))
            }
            None => MasterEnd::Inline(MasterLink::new(
                SpiMaster::new(wire, bus),
                first,
                [tx0, tx1],
                rx,
            )),
        };
        Self {
            link,
            wire: wire.clone(),
            star,
            clock,
            bus,
            started: None,
            after: None,
            report,
            cpu: None,
        }
    }

    /// Charge `cpu` with the relay code's work around each transfer: the wire does not
    /// clock a transfer before the work that precedes it is done, and the work after an
    /// exchange or broadcast delays the next one (a relay's also the return of `finish`).
    pub fn with_cpu(self, cpu: Option<LinkCpu>) -> Self {
        Self { cpu, ..self }
    }
}

impl RootBus for FirmwareBus<'_, '_> {
    fn nodes(&self) -> (NodeId, u16) {
        self.link.nodes()
    }

    fn ready(&self) -> Option<NodeId> {
        self.link.ready()
    }

    fn line(&self, node: NodeId) -> bool {
        // The link's, which sees every line (a relay reports each waiting node).
        self.link.line(node)
    }

    async fn wait_ready(&mut self) -> NodeId {
        self.link.wait_ready().await
    }

    fn tx_bank(&mut self) -> &mut [u8] {
        self.link.tx_bank()
    }

    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        let now = self.clock.borrow().now;
        let mut at = now;
        if transfer == Transfer::Broadcast {
            let bank = self.link.tx_bank();
            let frame = bank.get(..len).unwrap_or(&[]).to_vec();
            if let Some(r) = self.star.borrow_mut().relays_mut() {
                at = r.broadcast_ready(self.bus, &frame, now);
            }
        }
        if let Some(cpu) = &self.cpu {
            at = at.max(cpu.charge(cpu.before_instructions(len)));
        }
        // The wire does not clock it before then, whichever master half clocks it.
        self.wire.borrow_mut().buses[self.bus].not_before = at;
        self.link.start(transfer, len)?;
        self.started = Some((transfer, at, len));
        Ok(())
    }

    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        // `started` is taken only once the link's `finish` is done, and a finished transfer's
        // result is kept until the relay's CPU work after it is over: a caller may drop this
        // future while it waits (`RelayedBus` races its link against time-outs, a middle
        // relay against its parent) and call again, with the same `rx`, for the same
        // transfer.
        if let Some((end, got)) = self.after {
            if end > self.clock.borrow().now {
                Delay::new(&self.clock, end).await;
            }
            self.after = None;
            return Ok(got);
        }
        let Some((transfer, at, down)) = self.started else {
            return self.link.finish(rx).await;
        };
        if at > self.clock.borrow().now {
            // A relay's scene piece goes out once it has reached this leaf relay (and any
            // transfer once the relay code's CPU work before it is done).
            Delay::new(&self.clock, at).await;
        }
        let got = self.link.finish(rx).await;
        self.started = None;
        let got = got?;
        let broadcast = transfer == Transfer::Broadcast;
        let after = self.cpu.as_ref().map(|cpu| {
            let end = cpu.charge(cpu.after_instructions(broadcast, down, got));
            (end, cpu.role == LinkRole::Relay)
        });
        self.account(transfer, down, rx, got);
        if let Some((end, true)) = after {
            // The relay logic goes on once it has copied (or checked) what came.
            if end > self.clock.borrow().now {
                self.after = Some((end, got));
                Delay::new(&self.clock, end).await;
                self.after = None;
            }
        }
        Ok(got)
    }
}

impl FirmwareBus<'_, '_> {
    /// What the bus did in a transfer that ended now: the counters, the collector's snoop,
    /// a relay model's forwarded frame.
    fn account(&mut self, transfer: Transfer, down: usize, rx: &[u8], got: usize) {
        let now = self.clock.borrow().now;
        let mut s = self.star.borrow_mut();
        if let Some(c) = s.counters_mut(self.bus) {
            match transfer {
                Transfer::Exchange(_) => {
                    c.exchanges += 1;
                    c.down_bytes += down as u64;
                    c.up_bytes += got as u64;
                }
                Transfer::Broadcast => c.broadcast_bytes += down as u64,
            }
        }
        match transfer {
            Transfer::Exchange(_) => {
                let up = rx.get(..got).unwrap_or(&[]);
                if !up.is_empty() {
                    s.snoop(up);
                }
                if let Some(r) = s.relays_mut() {
                    r.forward_up(self.bus, up, down, now);
                }
            }
            Transfer::Broadcast => s.broadcast_done(self.bus),
        }
        if let Some(slot) = self.report.borrow_mut().get_mut(self.bus) {
            *slot = self.link.counters();
        }
    }
}

/// A node on the firmware link: its link task (`SlaveTask::run`) and its logic (`run_node`
/// over a [`SlaveHandle`]) polled together, the link again after the logic (so a frame the
/// logic posts or a bank it frees re-arms the DMA in the same pass); done when the logic is.
pub struct NodeOnLink<L, N> {
    pub link: Pin<Box<L>>,
    pub logic: Pin<Box<N>>,
}

impl<L: Future, N: Future> Future for NodeOnLink<L, N> {
    type Output = N::Output;
    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<N::Output> {
        let _ = self.link.as_mut().poll(cx);
        if let Poll::Ready(v) = self.logic.as_mut().poll(cx) {
            return Poll::Ready(v);
        }
        let _ = self.link.as_mut().poll(cx);
        Poll::Pending
    }
}

/// What the firmware link's two ends counted over a run (summed over buses and nodes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FirmwareLinkCounters {
    /// Node frames the RC found malformed and answered with NAK.
    pub naks: u64,
    /// Node frames sent again after a NAK (or a lost trailer).
    pub retransmits: u64,
    /// Node headers the RC refused.
    pub rc_bad_headers: u64,
    /// RC headers / bodies the nodes refused.
    pub node_bad_headers: u64,
    pub node_bad_bodies: u64,
    /// Selected nodes that did not drop their ready line (not clocked).
    pub no_ack: u64,
    /// Exchanges the root asked of a node whose line was low (not clocked).
    pub not_ready: u64,
    /// Transfers that found both of a node's RX banks full (scene chunks written into a
    /// lent scene bank not counted).
    pub overflows: u64,
    /// Broadcast scene chunks the nodes' links wrote straight into a lent scene bank (not a
    /// fault).
    pub landed: u64,
}

impl FirmwareLinkCounters {
    /// The sums of the RC's and the nodes' counters.
    pub fn of(master: &[MasterCounters], slaves: &[SlaveCounters]) -> Self {
        let mut c = Self::default();
        for m in master {
            c.naks += m.naks as u64;
            c.rc_bad_headers += m.bad_headers as u64;
            c.no_ack += m.no_ack as u64;
            c.not_ready += m.not_ready as u64;
        }
        for s in slaves {
            c.retransmits += s.retransmits as u64;
            c.node_bad_headers += s.bad_headers as u64;
            c.node_bad_bodies += s.bad_bodies as u64;
            c.overflows += s.overflows as u64;
            c.landed += s.landed as u64;
        }
        c
    }

    /// Whether anything went wrong on the link.
    pub fn any(&self) -> bool {
        Self { landed: 0, ..*self } != Self::default()
    }
}
