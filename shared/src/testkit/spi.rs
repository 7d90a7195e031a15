//! SPI fakes: an emulated bus for `links_core::spi`'s master and slave links that enforces
//! the hardware's rules and injects faults.
//!
//! - a master transfer is full duplex: transmit and receive lengths are equal;
//! - bytes move only while a chip-select is asserted, and only into a node whose DMA is
//!   armed (others miss them, as real hardware would);
//! - handshake ordering: the RC may select one node only while its ready line is high;
//! - several nodes selected at once (broadcast) drive MISO together: the RC reads garbage;
//! - faults: a flipped bit in a chosen transfer (either direction), lost ready-line edges.
//!
//! [`FakeMaster`] is the RC's [`MasterPort`], [`FakeSlave`] node `i`'s [`SlavePort`]; both
//! share one [`Bus`] ([`bus`]). Every future here re-polls itself, so [`run`] drives them
//! with a waker that does nothing.

use crate::link::NodeId;
use crate::spi::{
    Armed, Bank, MasterFront, MasterLink, MasterPort, MasterShared, MasterTask, PortError, Select,
    SlaveBanks, SlavePort, SlaveShared, SlaveTask, BANK,
};
use core::future::Future;
use core::pin::pin;
use core::task::{Context, Poll};
use std::cell::RefCell;
use std::rc::Rc;

/// Which direction a fault hits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dir {
    /// What the RC receives (MISO).
    Up,
    /// What the nodes receive (MOSI).
    Down,
}

/// A node's armed DMA transfer (what it will send, what it received so far).
pub struct Arm {
    pub tx: Vec<u8>,
    pub rx: Vec<u8>,
    pub pos: usize,
    /// Selected at least once since armed.
    pub touched: bool,
    /// Selected and released: the transfer is over.
    pub done: bool,
}

/// One node as the bus sees it: its armed DMA, its ready line, its chip-select.
#[derive(Default)]
pub struct FakeNode {
    pub arm: Option<Arm>,
    pub ready: bool,
    pub selected: bool,
}

/// The emulated bus: the nodes, the fault plan and what was observed.
#[derive(Default)]
pub struct Bus {
    pub nodes: Vec<FakeNode>,
    pub selected: Option<Select>,
    /// Master transfers so far (each header, body and trailer phase counts one).
    pub transfers: u64,
    /// Flip bit 0 of byte `.2` of master transfer number `.0` in direction `.1`.
    pub faults: Vec<(u64, Dir, usize)>,
    pub faults_hit: u32,
    /// Ready-line rising edges to lose (the RC's interrupt never fires for them).
    pub lose_edges: u32,
    pub edges_lost: u32,
    pub edge: bool,
    /// Rule violations (each a description); a test fails if any occur.
    pub violations: Vec<String>,
    /// Bytes clocked while a selected node was not armed.
    pub missed: u64,
    /// Trailer bytes the RC sent (single-byte transfers).
    pub trailers: Vec<u8>,
}

/// The bus shared by the master and slave fakes.
pub type SharedBus = Rc<RefCell<Bus>>;

/// A bus with `nodes` idle nodes.
pub fn bus(nodes: usize) -> SharedBus {
    Rc::new(RefCell::new(Bus {
        nodes: (0..nodes).map(|_| FakeNode::default()).collect(),
        ..Bus::default()
    }))
}

/// The RC's [`MasterPort`] over the emulated bus.
pub struct FakeMaster {
    pub bus: SharedBus,
}

/// Resolve after `n` polls (the polling fallback of a real `wait_any_ready`, or a delay).
pub async fn polls(n: u32) {
    let mut k = 0;
    core::future::poll_fn(|cx| {
        k += 1;
        cx.waker().wake_by_ref();
        if k > n {
            Poll::Ready(())
        } else {
            Poll::Pending
        }
    })
    .await
}

impl MasterPort for FakeMaster {
    fn count(&self) -> u16 {
        self.bus.borrow().nodes.len() as u16
    }

    fn ready(&self, i: u16) -> bool {
        self.bus
            .borrow()
            .nodes
            .get(i as usize)
            .is_some_and(|n| n.ready)
    }

    async fn wait_any_ready(&mut self) {
        // An edge wakes at once; without one, a polling period (a lost edge costs this).
        let mut k = 0;
        core::future::poll_fn(|cx| {
            k += 1;
            let mut b = self.bus.borrow_mut();
            if std::mem::take(&mut b.edge) || k > 200 {
                Poll::Ready(())
            } else {
                cx.waker().wake_by_ref();
                Poll::Pending
            }
        })
        .await
    }

    async fn select(&mut self, sel: Select) {
        {
            let mut b = self.bus.borrow_mut();
            if b.selected.is_some() {
                b.violations.push("select while selected".into());
            }
            if let Select::One(i) = sel {
                if !b.nodes[i as usize].ready {
                    b.violations
                        .push(format!("node {i} selected with its ready line low"));
                }
            }
            b.selected = Some(sel);
            let all = matches!(sel, Select::All);
            for (k, n) in b.nodes.iter_mut().enumerate() {
                if all || sel == Select::One(k as u16) {
                    n.selected = true;
                    // The node's port drops its ready line when its chip-select falls.
                    if n.arm.is_some() {
                        n.ready = false;
                    }
                    if let Some(a) = &mut n.arm {
                        a.touched = true;
                    }
                }
            }
        }
        // Chip-select set-up time.
        polls(2).await;
    }

    async fn deselect(&mut self) {
        {
            let mut b = self.bus.borrow_mut();
            if b.selected.is_none() {
                b.violations.push("deselect while not selected".into());
            }
            b.selected = None;
            for n in b.nodes.iter_mut() {
                if std::mem::take(&mut n.selected) {
                    if let Some(a) = &mut n.arm {
                        if a.touched {
                            a.done = true;
                        }
                    }
                }
            }
        }
        // Hold time: the nodes re-arm.
        polls(2).await;
    }

    async fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), PortError> {
        polls(1).await;
        let mut b = self.bus.borrow_mut();
        let b = &mut *b;
        if tx.len() != rx.len() {
            b.violations
                .push(format!("transfer of {} out, {} in", tx.len(), rx.len()));
            return Err(PortError);
        }
        let Some(sel) = b.selected else {
            b.violations.push("transfer without chip-select".into());
            return Err(PortError);
        };
        let t = b.transfers;
        b.transfers += 1;
        if tx.len() == 1 {
            b.trailers.push(tx[0]);
        }
        let mut down = tx.to_vec();
        for &(at, dir, byte) in &b.faults {
            if at == t && dir == Dir::Down && !down.is_empty() {
                down[byte % tx.len()] ^= 1;
                b.faults_hit += 1;
            }
        }
        rx.fill(0xff);
        let mut driving = 0;
        for n in b.nodes.iter_mut().filter(|n| n.selected) {
            driving += 1;
            match &mut n.arm {
                Some(a) if !a.done => {
                    for (k, &byte) in down.iter().enumerate() {
                        if let Some(d) = a.rx.get_mut(a.pos + k) {
                            *d = byte;
                        }
                        if let (Some(&s), true) = (a.tx.get(a.pos + k), sel != Select::All) {
                            rx[k] = s;
                        }
                    }
                    a.pos += down.len();
                }
                _ => b.missed += down.len() as u64,
            }
        }
        if driving > 1 {
            // Contention on MISO: what the RC reads is meaningless.
            rx.fill(0x00);
        }
        for &(at, dir, byte) in &b.faults {
            if at == t && dir == Dir::Up && !rx.is_empty() {
                let k = byte % rx.len();
                rx[k] ^= 1;
                b.faults_hit += 1;
            }
        }
        Ok(())
    }
}

/// Node `i`'s [`SlavePort`] over the emulated bus.
pub struct FakeSlave {
    pub bus: SharedBus,
    pub i: usize,
}

impl SlavePort for FakeSlave {
    async fn transfer(
        &mut self,
        tx: &[u8],
        rx: &mut [u8],
        cancel: impl Future<Output = ()>,
    ) -> Result<Armed, PortError> {
        {
            let mut b = self.bus.borrow_mut();
            if tx.len() != rx.len() {
                b.violations.push("slave DMA lengths differ".into());
                return Err(PortError);
            }
            let n = &mut b.nodes[self.i];
            n.arm = Some(Arm {
                tx: tx.to_vec(),
                rx: rx.to_vec(),
                pos: 0,
                touched: n.selected,
                done: false,
            });
        }
        let mut cancel = pin!(cancel);
        core::future::poll_fn(|cx: &mut Context<'_>| {
            let mut b = self.bus.borrow_mut();
            let n = &mut b.nodes[self.i];
            if n.arm.as_ref().is_some_and(|a| a.done) {
                if let Some(a) = n.arm.take() {
                    rx.copy_from_slice(&a.rx);
                }
                return Poll::Ready(Ok(Armed::Done));
            }
            let idle = !n.selected && !n.arm.as_ref().is_some_and(|a| a.touched);
            if idle && cancel.as_mut().poll(cx).is_ready() {
                n.arm = None;
                return Poll::Ready(Ok(Armed::Cancelled));
            }
            cx.waker().wake_by_ref();
            Poll::Pending
        })
        .await
    }

    fn set_ready(&mut self, high: bool) {
        let mut b = self.bus.borrow_mut();
        let was = b.nodes[self.i].ready;
        b.nodes[self.i].ready = high;
        if high && !was {
            if b.lose_edges > 0 {
                b.lose_edges -= 1;
                b.edges_lost += 1;
            } else {
                b.edge = true;
            }
        }
    }
}

/// Poll `f` to completion with a waker that does nothing (every future here re-polls
/// itself); a stall fails the test instead of hanging it.
pub fn run<F: Future>(f: F) -> F::Output {
    let mut f = pin!(f);
    let mut cx = Context::from_waker(std::task::Waker::noop());
    for _ in 0..50_000_000u64 {
        if let Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
    }
    panic!("the link stalled");
}

/// `N` zeroed link banks.
pub fn banks<const N: usize>() -> Vec<Bank> {
    vec![[0u8; BANK]; N]
}

/// A node's banks from five: two TX, two RX, scratch.
pub fn slave_banks(v: &mut [Bank]) -> SlaveBanks<'_> {
    let [a, b, c, d, e] = v else {
        panic!("five banks")
    };
    SlaveBanks {
        tx: [a, b],
        rx: [c, d],
        scratch: e,
    }
}

/// The RC's master link over `bus` (node ids from `first`), on banks of its own (leaked: a
/// test's link lives as long as the test).
pub fn master_link(bus: &SharedBus, first: NodeId) -> MasterLink<'static, FakeMaster> {
    let [tx0, tx1, rx] = Box::leak(Box::new([[0u8; BANK]; 3]));
    let port = FakeMaster { bus: bus.clone() };
    MasterLink::new(port, first, [tx0, tx1], rx)
}

/// The RC's split link over `bus` (node ids from `first`): the shared state, the
/// [`MasterFront`] the root logic drives, the [`MasterTask`] and the port it clocks (run the
/// task beside the root logic). Banks and shared state are leaked, as in [`master_link`].
pub fn master_split(
    bus: &SharedBus,
    first: NodeId,
) -> (
    &'static MasterShared<'static>,
    MasterFront<'static, 'static>,
    MasterTask,
    FakeMaster,
) {
    let [tx0, tx1, rx] = Box::leak(Box::new([[0u8; BANK]; 3]));
    let shared: &'static MasterShared<'static> = Box::leak(Box::new(MasterShared::new()));
    let port = FakeMaster { bus: bus.clone() };
    let front = MasterFront::new(shared, first, port.count(), [tx0, tx1], rx);
    (shared, front, MasterTask::new(), port)
}

/// Node `i`'s link (shared state, link task, port) over `bus`, on banks of its own (leaked).
pub fn slave_link(
    bus: &SharedBus,
    i: usize,
) -> (SlaveShared<'static>, SlaveTask<'static>, FakeSlave) {
    let banks: &'static mut [Bank; 5] = Box::leak(Box::new([[0u8; BANK]; 5]));
    let (shared, task) = SlaveShared::new(slave_banks(banks));
    let port = FakeSlave {
        bus: bus.clone(),
        i,
    };
    (shared, task, port)
}
