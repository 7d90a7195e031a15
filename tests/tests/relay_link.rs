//! Relay RCs (`links_core::relay`) over the emulated SPI buses of `links_core::testkit::spi`:
//! the root's `run_bus` drives `RelayedBus` over its link to the relays; each relay runs
//! `run_relay` (a node on the root's bus through the firmware's `SlaveTask`, the root of its
//! own bus through the split master link); the nodes run `run_node` on the relays' buses.
//! The frame must equal the single-node render bit for bit.

use core::future::Future;
use core::pin::Pin;
use core::task::Poll;
use embassy_futures::join::join;
use embassy_futures::select::{select, Either};
use links_core::node::{run_node, NodeConfig, NodeReport, RealTime, Tracing};
use links_core::relay::{
    run_relay, RelayBuffers, RelayReport, RelayedBuffers, RelayedBus, RelayedCounters, DEPTH,
    REPLY_CELL, SLOTS,
};
use links_core::root::{run_bus, NoClock, RootClock, RootConfig, RootReport, RootState};
use links_core::sched::Policy;
use links_core::testkit::spi::*;
use links_core::wire::MAX_MESSAGE;
use links_host::frame::{render_frame, Precision};
use links_tests::{bundled_image, FrameSink};
use std::cell::RefCell;

type Task<T> = Pin<Box<dyn Future<Output = T>>>;

/// Poll every future until all are done; their outputs in order.
async fn join_all<T>(mut futs: Vec<Task<T>>) -> Vec<T> {
    let mut out: Vec<Option<T>> = futs.iter().map(|_| None).collect();
    core::future::poll_fn(|cx| {
        for (f, o) in futs.iter_mut().zip(out.iter_mut()) {
            if o.is_none() {
                if let Poll::Ready(v) = f.as_mut().poll(cx) {
                    *o = Some(v);
                }
            }
        }
        if out.iter().all(Option::is_some) {
            Poll::Ready(())
        } else {
            Poll::Pending
        }
    })
    .await;
    out.into_iter().flatten().collect()
}

fn leak<T>(v: T) -> &'static mut T {
    Box::leak(Box::new(v))
}

/// Node `i` of a relay's bus: `run_node` beside its link task, on scene banks of its own.
fn node(bus: SharedBus, i: usize, scene_len: usize) -> Task<NodeReport> {
    Box::pin(async move {
        let (shared, task, mut port) = slave_link(&bus, i);
        let shared = leak(shared);
        let mut handle = shared.handle();
        let mut report = NodeReport::default();
        let (mut clock, mut tracer) = (RealTime, Tracing::<f32>::new());
        let scene = leak(vec![0u8; scene_len]);
        let odd = leak(vec![0u8; scene_len]);
        let logic = run_node(
            NodeConfig::default(),
            &mut handle,
            &mut clock,
            &mut tracer,
            [&mut scene[..], &mut odd[..]],
            &mut report,
        );
        match select(logic, task.run(&mut port, shared)).await {
            Either::First(r) => r.expect("node ends on Stop"),
        }
        report
    })
}

/// Relay `r`: a node (index `r`) on the root's bus, the root of `bus` (its nodes numbered
/// from 0: the relay's records name its nodes by their place on its bus), with a cell per
/// node for replies sent ahead.
fn relay(root_bus: SharedBus, r: usize, bus: SharedBus) -> Task<RelayReport> {
    Box::pin(async move {
        let (pshared, ptask, mut pport) = slave_link(&root_bus, r);
        let pshared = leak(pshared);
        let mut parent = pshared.handle();
        let (bshared, mut front, btask, mut bport) = master_split(&bus, 0);
        let buffers = RelayBuffers {
            down: leak([0u8; MAX_MESSAGE]),
            up: leak([0u8; MAX_MESSAGE]),
            node: leak([0u8; MAX_MESSAGE]),
            ahead: &mut leak([[0u8; REPLY_CELL]; 8])[..],
        };
        let logic = run_relay(&mut parent, &mut front, buffers);
        let links = select(
            ptask.run(&mut pport, pshared),
            btask.run(&mut bport, bshared),
        );
        match select(logic, links).await {
            Either::First(r) => r.expect("relay ends on Stop"),
        }
    })
}

struct Run {
    root: RootReport,
    /// What the root's `RelayedBus` counted.
    counters: RelayedCounters,
    relays: Vec<RelayReport>,
    nodes: Vec<NodeReport>,
    root_bus: SharedBus,
    relay_buses: Vec<SharedBus>,
}

/// Render photo1 at 24x16 through `relays` relays of `per` nodes each; the frame must be
/// the single-node render.
fn tree(
    relays: usize,
    per: usize,
    faults: Vec<(u64, Dir, usize)>,
    relay0_faults: Vec<(u64, Dir, usize)>,
) -> Run {
    tree_at_depth(relays, per, faults, relay0_faults, (DEPTH, false))
}

/// [`tree`] with at most `depth` node exchanges in flight per relay, and (`ahead`) the
/// replies sent ahead of the nodes' lines ([`RelayedBus::with_ahead`]).
fn tree_at_depth(
    relays: usize,
    per: usize,
    faults: Vec<(u64, Dir, usize)>,
    relay0_faults: Vec<(u64, Dir, usize)>,
    (depth, ahead): (u16, bool),
) -> Run {
    let (w, h) = (24u32, 16u32);
    let img = bundled_image("photo1.ron", w, h);
    let want = render_frame(&img, Precision::F32, 1, &|| {})
        .expect("renders")
        .rgb;
    let nodes = relays * per;
    let cfg = RootConfig {
        policy: Policy::DECREASING,
        nodes: nodes as u16,
        frames: 1,
        timeout_us: 0,
        double_buffer: true,
    };
    let scenes = [img.as_slice()];
    let root = RefCell::new(RootState::new(cfg, &scenes[..]).expect("valid"));
    let sink = RefCell::new(FrameSink::new(w, h));
    let root_bus = bus(relays);
    root_bus.borrow_mut().faults = faults;
    let relay_buses: Vec<SharedBus> = (0..relays).map(|_| bus(per)).collect();
    relay_buses[0].borrow_mut().faults = relay0_faults;
    let (shared, front, task, mut port) = master_split(&root_bus, 0);
    let mut bufs = Box::new(RelayedBuffers::new());
    let mut relayed = RelayedBus::new(front, &mut bufs, 0, per as u16)
        .expect("a tree that fits")
        .with_depth(depth)
        .with_ahead(if ahead { 1_000_000 } else { 0 });
    let rc = async {
        let logic = run_bus(0, &mut relayed, &NoClock, &root, &scenes[..], &sink);
        match select(logic, task.run(&mut port, shared)).await {
            Either::First(r) => r.expect("root runs"),
        }
    };
    let relay_tasks: Vec<Task<RelayReport>> = (0..relays)
        .map(|r| relay(root_bus.clone(), r, relay_buses[r].clone()))
        .collect();
    let node_tasks: Vec<Task<NodeReport>> = (0..nodes)
        .map(|k| node(relay_buses[k / per].clone(), k % per, img.len()))
        .collect();
    let (root_report, (relay_reports, node_reports)) =
        run(join(rc, join(join_all(relay_tasks), join_all(node_tasks))));
    assert_eq!(
        sink.borrow().rgb,
        want,
        "the frame through {relays} relay(s) equals the single-node render"
    );
    for b in std::iter::once(&root_bus).chain(&relay_buses) {
        let b = b.borrow();
        assert!(b.violations.is_empty(), "{:?}", b.violations);
    }
    let counters = relayed.counters;
    assert!(
        counters.most_in_flight as usize <= (depth as usize * relays).min(SLOTS),
        "{counters:?}"
    );
    Run {
        root: root_report,
        counters,
        relays: relay_reports,
        nodes: node_reports,
        root_bus,
        relay_buses,
    }
}

#[test]
fn one_relay_of_three_nodes_renders_the_single_node_frame() {
    let run = tree(1, 3, Vec::new(), Vec::new());
    let pixels: u64 = run.nodes.iter().map(|n| n.pixels).sum();
    assert!(pixels >= 24 * 16);
    assert!(run.nodes.iter().all(|n| n.pixels > 0), "every node worked");
    let r = run.relays[0];
    // Every root broadcast reached the relay's bus once (store-and-forward), and the final
    // Stop (which the root's report does not count) after them.
    assert_eq!(r.forwarded, run.root.broadcasts + 1);
    // Every exchange the root made with a node was clocked by the relay.
    assert_eq!(r.routed, run.root.exchanges);
    assert_eq!((r.bad_frames, run.root.bad_messages), (0, 0));
    // Each request goes down once: none reaches the relay again after it was served (it
    // went down twice before, the second dropped as stray).
    assert_eq!(r.stray_requests, 0);
    assert!(run.relay_buses[0].borrow().transfers > 0);
}

#[test]
fn two_relays_under_one_root_render_the_single_node_frame() {
    let run = tree(2, 3, Vec::new(), Vec::new());
    // Six nodes share a 24x16 frame of three sub-screens: who renders them depends on who
    // reported its scene first; every node is exchanged with through its relay.
    let pixels: u64 = run.nodes.iter().map(|n| n.pixels).sum();
    assert!(pixels >= 24 * 16);
    let routed: u32 = run.relays.iter().map(|r| r.routed).sum();
    assert_eq!(routed, run.root.exchanges);
    for r in &run.relays {
        assert_eq!(
            r.forwarded,
            run.root.broadcasts + 1,
            "both relays forwarded all"
        );
        assert!(r.routed > 0);
    }
    assert_eq!(run.root.bad_messages, 0);
}

#[test]
fn several_node_exchanges_are_in_flight_and_each_frame_comes_back_once() {
    // Two relays of three nodes, two exchanges in flight per relay: at times four at
    // once, and still every exchange the root took is one a relay clocked, every frame
    // taken once (no stray frames), no exchange given up.
    let run = tree(2, 3, Vec::new(), Vec::new());
    let c = run.counters;
    assert!(c.most_in_flight > 2, "{c:?}");
    assert_eq!(
        (c.stray_frames, c.timeouts, c.bad_batches),
        (0, 0, 0),
        "{c:?}"
    );
    let routed: u32 = run.relays.iter().map(|r| r.routed).sum();
    assert_eq!(routed, run.root.exchanges);
    // A link exchange brings at most one node frame up.
    assert!(c.link_exchanges >= run.root.exchanges, "{c:?}");
    // One exchange in flight per relay: at most two at once, the same frame.
    let one = tree_at_depth(2, 3, Vec::new(), Vec::new(), (1, false));
    assert!(one.counters.most_in_flight <= 2, "{:?}", one.counters);
    let routed: u32 = one.relays.iter().map(|r| r.routed).sum();
    assert_eq!(routed, one.root.exchanges);
}

/// Ten corrupted bytes on the root's link (its relays' batches and the forwarded
/// broadcasts), both directions.
fn root_link_faults() -> Vec<(u64, Dir, usize)> {
    (0..10u64)
        .map(|k| {
            let dir = if k % 2 == 0 { Dir::Up } else { Dir::Down };
            (20 + 11 * k, dir, (k as usize * 7) % 9)
        })
        .collect()
}

#[test]
fn corrupt_bytes_on_the_root_link_cost_retries_never_the_frame() {
    let faults = root_link_faults();
    let n = faults.len() as u32;
    let run = tree(2, 3, faults, Vec::new());
    assert_eq!(run.root_bus.borrow().faults_hit, n, "every fault landed");
}

#[test]
fn replies_sent_ahead_wait_at_the_relays_and_the_frame_is_the_same() {
    // Every node one exchange in flight: the root composes a node's next reply as its
    // frame comes up (the node holds jobs) and the relay clocks the node with it as its
    // line rises.
    let run = tree_at_depth(2, 3, Vec::new(), Vec::new(), (3, true));
    let c = run.counters;
    let ahead: u32 = run.relays.iter().map(|r| r.ahead).sum();
    // (A node here posts again before its reply ahead is down, mostly: the relay clocks
    // it as soon as the reply arrives; the 256-node simulation has them wait in cells.)
    assert!(c.ahead > 0 && ahead <= c.ahead, "{c:?} {ahead}");
    assert_eq!(
        (c.lost_ahead, c.stray_frames, c.timeouts),
        (0, 0, 0),
        "{c:?}"
    );
    let routed: u32 = run.relays.iter().map(|r| r.routed).sum();
    assert_eq!(routed, run.root.exchanges);
    assert!(run.relays.iter().all(|r| r.stray_requests == 0));
    // With bytes corrupted on the root's link, some replies ahead never arrive: those
    // exchanges end empty and the nodes are asked anew; the frame is the same.
    let faults = root_link_faults();
    let n = faults.len() as u32;
    let run = tree_at_depth(2, 3, faults, Vec::new(), (3, true));
    assert_eq!(run.root_bus.borrow().faults_hit, n, "every fault landed");
    assert!(run.counters.ahead > 0, "{:?}", run.counters);
}

#[test]
fn corrupt_bytes_on_a_relays_bus_are_the_nodes_business_as_on_a_direct_bus() {
    // Transfers on relay 0's own bus (its broadcasts and its node exchanges), both
    // directions: the node link's NAK and go-back repair them, the relay routes on.
    let faults: Vec<_> = (0..8u64)
        .map(|k| {
            let dir = if k % 2 == 0 { Dir::Up } else { Dir::Down };
            (15 + 9 * k, dir, (k as usize * 5) % 9)
        })
        .collect();
    let n = faults.len() as u32;
    let run = tree(2, 3, Vec::new(), faults);
    assert_eq!(
        run.relay_buses[0].borrow().faults_hit,
        n,
        "every fault landed"
    );
    let routed: u32 = run.relays.iter().map(|r| r.routed).sum();
    assert_eq!(routed, run.root.exchanges);
}

/// Time for the harness, which has no other: each poll of a pending `at_us` is a
/// microsecond, and each transfer on the root's bus 50 (as on the wire).
struct PollClock {
    now: std::cell::Cell<u64>,
    bus: SharedBus,
}

impl RootClock for &PollClock {
    fn now_us(&self) -> u64 {
        self.now.get() + 50 * self.bus.borrow().transfers
    }
    async fn at_us(&self, t: u64) {
        core::future::poll_fn(|cx| {
            if self.now_us() >= t {
                return Poll::Ready(());
            }
            self.now.set(self.now.get() + 1);
            cx.waker().wake_by_ref();
            Poll::Pending
        })
        .await
    }
}

/// A relay that stops answering mid-frame (its task dropped: its links disarmed, its ready
/// line low for good) costs the root its nodes, not the frame:
/// `RelayedBus` gives the exchange up at its time-out, the root logic's node time-out retires
/// the nodes behind the dead relay and their jobs go to the other relay's nodes. Without the
/// relay time-out the root waited for ever in `finish`.
#[test]
fn a_relay_that_stops_answering_costs_its_nodes_not_the_frame() {
    // Relay 1 dies once its own bus has carried the scene (19 broadcasts) and a few node
    // exchanges, at several moments: with exchanges in flight through it, while its nodes
    // hold jobs. Every frame is the single-node render; the exchanges in flight through
    // the dead relay end at the relay time-out (counted), and at some moment the root logic
    // declares its nodes dead.
    let (mut given_up, mut declared_dead) = (0, 0);
    for after in 20..=26 {
        let (report, counters) = relay_dies_after(after);
        given_up += counters.timeouts;
        declared_dead += report.timeouts;
    }
    assert!(
        given_up > 0 && declared_dead > 0,
        "{given_up} {declared_dead}"
    );
}

/// Render through two relays of two nodes, relay 1 dying once its bus has carried `after`
/// transfers; the frame must be the single-node render.
fn relay_dies_after(after: u64) -> (RootReport, RelayedCounters) {
    let (w, h, per) = (24u32, 16u32, 2usize);
    let img = bundled_image("photo1.ron", w, h);
    let want = render_frame(&img, Precision::F32, 1, &|| {})
        .expect("renders")
        .rgb;
    let cfg = RootConfig {
        policy: Policy::DECREASING,
        nodes: (2 * per) as u16,
        frames: 1,
        timeout_us: 200_000,
        double_buffer: true,
    };
    let scenes = [img.as_slice()];
    let root = RefCell::new(RootState::new(cfg, &scenes[..]).expect("valid"));
    let sink = RefCell::new(FrameSink::new(w, h));
    let root_bus = bus(2);
    let relay_buses: Vec<SharedBus> = (0..2).map(|_| bus(per)).collect();
    let (shared, front, task, mut port) = master_split(&root_bus, 0);
    let clock = PollClock {
        now: std::cell::Cell::new(0),
        bus: root_bus.clone(),
    };
    let mut bufs = Box::new(RelayedBuffers::new());
    let mut relayed = RelayedBus::new(front, &mut bufs, 0, per as u16)
        .expect("a tree that fits")
        .with_timeout(&clock, 20_000);
    let root_clock = &clock;
    let rc = async {
        let logic = run_bus(0, &mut relayed, &root_clock, &root, &scenes[..], &sink);
        match select(logic, task.run(&mut port, shared)).await {
            Either::First(r) => r.expect("root runs"),
        }
    };
    let dying: Task<()> = {
        let bus1 = relay_buses[1].clone();
        let relay1 = relay(root_bus.clone(), 1, bus1.clone());
        let died = core::future::poll_fn(move |cx| {
            if bus1.borrow().transfers > after {
                return Poll::Ready(());
            }
            cx.waker().wake_by_ref();
            Poll::Pending
        });
        Box::pin(async move {
            let _ = select(relay1, died).await;
            core::future::pending::<()>().await
        })
    };
    let others: Vec<Task<()>> = std::iter::once(relay(root_bus.clone(), 0, relay_buses[0].clone()))
        .map(|t| -> Task<()> {
            Box::pin(async move {
                t.await;
                core::future::pending::<()>().await
            })
        })
        .chain(std::iter::once(dying))
        .chain((0..2 * per).map(|k| -> Task<()> {
            let n = node(relay_buses[k / per].clone(), k % per, img.len());
            Box::pin(async move {
                n.await;
                core::future::pending::<()>().await
            })
        }))
        .collect();
    let report = match run(select(rc, join_all(others))) {
        Either::First(r) => r,
        Either::Second(_) => unreachable!("the others never end"),
    };
    assert_eq!(
        sink.borrow().rgb,
        want,
        "the frame is the single-node render"
    );
    (report, relayed.counters)
}
