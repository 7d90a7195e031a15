//! The SPI link driver (`links_core::spi`, the protocol `nc-fw` and `rc-fw` run) against an
//! emulated bus that enforces the hardware's rules and injects faults
//! ([`links_core::testkit::spi`], shared with the other tests).
//!
//! The end-to-end tests run the real root and node logic (`run_bus`, `run_node`) over the
//! link and compare the frame with the single-node render.

use core::task::Poll;
use embassy_futures::join::{join, join_array};
use embassy_futures::select::{select, Either};
use links_core::link::{Incoming, LinkError, NodeLink, RootBus, Transfer};
use links_core::node::{run_node, NodeConfig, NodeReport, RealTime, Tracing};
use links_core::root::{run_bus, NoClock, RootConfig, RootState};
use links_core::sched::Policy;
use links_core::spi::{ACK, BANK, HEADER, NAK};
use links_core::testkit::serial::{read_back, ReadBack};
use links_core::testkit::spi::*;
use links_core::wire::{self, MAX_MESSAGE};
use links_host::frame::{render_frame, Precision};
use links_tests::{bundled_image, FrameSink};
use std::cell::RefCell;

/// One node posts a frame; the RC exchanges with it; returns (what the RC got, what the
/// node got) after the exchange that delivered the node's frame.
#[test]
fn exchange_swaps_frames_and_a_malformed_frame_is_nakked_and_resent() {
    for fault in [None, Some(Dir::Up), Some(Dir::Down)] {
        let bus = bus(1);
        // Transfer 1 is the first exchange's body phase (0 = header, 2 = trailer).
        if let Some(dir) = fault {
            bus.borrow_mut().faults.push((1, dir, 5));
        }
        let mut master = master_link(&bus, 0);
        let (shared, task, mut port) = slave_link(&bus, 0);
        let up: Vec<u8> = (0..300u32).map(|i| (i * 7) as u8).collect();
        let down: Vec<u8> = (0..40u32).map(|i| (i * 3 + 1) as u8).collect();
        let mut handle = shared.handle();
        handle.post(&up).expect("posts");
        assert_eq!(
            handle.post(&up),
            Err(links_core::link::LinkError::Busy),
            "one frame at a time"
        );
        let rc = async {
            let mut got = Vec::new();
            for _ in 0..4 {
                let node = master.wait_ready().await;
                let mut rx = [0u8; MAX_MESSAGE];
                let n = master
                    .exchange(node, &down, &mut rx)
                    .await
                    .expect("no error");
                if n > 0 {
                    got = rx[..n].to_vec();
                    break;
                }
            }
            got
        };
        let nc = async {
            let mut rx = [0u8; MAX_MESSAGE];
            match handle.recv(&mut rx).await.expect("no error") {
                Incoming::Exchanged { len } => rx[..len].to_vec(),
                Incoming::Broadcast { .. } => panic!("no broadcast was sent"),
            }
        };
        let link = task.run(&mut port, &shared);
        let ((got_up, got_down), _) = match run(select(join(rc, nc), link)) {
            Either::First(v) => (v, ()),
        };
        let b = bus.borrow();
        assert!(b.violations.is_empty(), "{:?}", b.violations);
        let mc = master.counters;
        let sc = shared.counters();
        assert_eq!(
            got_up, up,
            "{fault:?}: the RC receives the node's frame intact"
        );
        match fault {
            None => {
                assert_eq!(got_down, down);
                assert_eq!((mc.naks, sc.retransmits, mc.exchanges), (0, 0, 1));
                assert_eq!(b.trailers, [ACK]);
            }
            Some(Dir::Up) => {
                // The RC counted the malformed frame and asked for it again; the node kept
                // it and sent it once more. The node hears only the exchange that carried
                // its frame home.
                assert_eq!(b.faults_hit, 1);
                assert_eq!((mc.naks, sc.retransmits, mc.exchanges), (1, 1, 2));
                assert_eq!(b.trailers, [NAK, ACK]);
                assert_eq!(got_down, down);
            }
            Some(Dir::Down) => {
                // The node's frame arrived (ACK); the RC's reply did not: the node logic is
                // handed an empty frame, which it counts as bad and recovers from.
                assert_eq!(b.faults_hit, 1);
                assert_eq!(b.trailers, [ACK]);
                assert_eq!(sc.bad_bodies, 1);
                assert!(got_down.is_empty());
            }
        }
    }
}

#[test]
fn garbled_headers_never_deliver_and_the_link_recovers() {
    // Every byte of the node's header, in turn, flipped on the first try.
    for byte in 0..HEADER {
        let bus = bus(1);
        bus.borrow_mut().faults.push((0, Dir::Up, byte));
        let mut master = master_link(&bus, 0);
        let (shared, task, mut port) = slave_link(&bus, 0);
        let mut handle = shared.handle();
        handle.post(b"hello").unwrap();
        let rc = async {
            let mut tries = 0;
            loop {
                tries += 1;
                let node = master.wait_ready().await;
                let mut rx = [0u8; MAX_MESSAGE];
                let n = master.exchange(node, b"world", &mut rx).await.unwrap();
                if n > 0 {
                    assert_eq!(&rx[..n], b"hello");
                    return tries;
                }
            }
        };
        let link = task.run(&mut port, &shared);
        let Either::First(tries) = run(select(rc, link));
        assert_eq!(tries, 2, "byte {byte}");
        assert_eq!(master.counters.bad_headers, 1);
        // The node saw no trailer: it keeps the frame, as after a NAK.
        assert_eq!(shared.counters().retransmits, 1);
        assert!(bus.borrow().violations.is_empty());
    }
}

/// A handshake line stuck high (node 0's: high, but no DMA armed, so selecting it does not
/// drop it) is clocked once, found not to acknowledge, and ignored until it is seen low;
/// then it counts again. Before, `ready()` kept answering it and the root, which broadcasts
/// only while no node is ready, could never broadcast.
#[test]
fn a_ready_line_stuck_high_is_ignored_until_seen_low() {
    let bus = bus(2);
    let mut master = master_link(&bus, 0);
    bus.borrow_mut().nodes[0].ready = true;
    assert_eq!(master.ready(), Some(0));
    let mut rx = [0u8; MAX_MESSAGE];
    assert_eq!(run(master.exchange(0, b"x", &mut rx)).unwrap(), 0);
    assert_eq!(master.counters.no_ack, 1);
    assert_eq!(bus.borrow().transfers, 0, "nothing clocked");
    assert_eq!(master.ready(), None, "still high, ignored");
    bus.borrow_mut().nodes[1].ready = true;
    assert_eq!(master.ready(), Some(1), "the others are served");
    bus.borrow_mut().nodes[1].ready = false;
    bus.borrow_mut().nodes[0].ready = false;
    assert_eq!(master.ready(), None);
    bus.borrow_mut().nodes[0].ready = true;
    assert_eq!(master.ready(), Some(0), "seen low: counted again");
}

/// The same rule on the split link (`MasterFront` + `MasterTask`): the task clocks node 0's
/// stuck-high line once, sees no acknowledgement, and the front stops offering it until the
/// task's snapshot shows it low; node 1 is served meanwhile.
#[test]
fn split_link_ignores_a_ready_line_stuck_high_until_seen_low() {
    let bus = bus(2);
    let (shared, mut front, mut task, mut mport) = master_split(&bus, 0);
    // The task publishes the lines, then waits for a job or an edge: `polls` lets it run.
    let mut step = |n: u32| run(select(task.step(&mut mport, shared), polls(n)));
    bus.borrow_mut().nodes[0].ready = true;
    step(5);
    assert_eq!(front.ready(), Some(0));
    front.start(Transfer::Exchange(0), 1).unwrap();
    step(200);
    let mut rx = [0u8; MAX_MESSAGE];
    assert_eq!(run(front.finish(&mut rx)), Ok(0));
    assert_eq!(shared.counters().no_ack, 1);
    assert_eq!(bus.borrow().transfers, 0, "nothing clocked");
    step(5);
    assert_eq!(front.ready(), None, "still high, ignored");
    bus.borrow_mut().nodes[1].ready = true;
    step(5);
    assert_eq!(front.ready(), Some(1), "the others are served");
    assert!(front.line(0), "the line itself still reads high");
    bus.borrow_mut().nodes[1].ready = false;
    bus.borrow_mut().nodes[0].ready = false;
    step(5);
    assert_eq!(front.ready(), None);
    bus.borrow_mut().nodes[0].ready = true;
    step(5);
    assert_eq!(front.ready(), Some(0), "seen low: counted again");
}

#[test]
fn rc_refuses_to_clock_a_node_whose_ready_line_is_low() {
    let bus = bus(2);
    let mut master = master_link(&bus, 10);
    assert_eq!(master.nodes(), (10, 2));
    assert_eq!(master.ready(), None);
    let mut rx = [0u8; MAX_MESSAGE];
    let n = run(master.exchange(11, b"x", &mut rx)).unwrap();
    assert_eq!(n, 0);
    assert_eq!(master.counters.not_ready, 1);
    assert_eq!(bus.borrow().transfers, 0, "nothing clocked");
    assert!(
        run(master.exchange(12, b"x", &mut rx)).is_err(),
        "not on this bus"
    );
    assert!(
        run(master.exchange(9, b"x", &mut rx)).is_err(),
        "not on this bus"
    );
    let big = vec![0u8; MAX_MESSAGE + 1];
    assert!(run(master.exchange(10, &big, &mut rx)).is_err());
    assert!(run(master.broadcast(&big)).is_err());
}

/// A scene bank lent to the link (`SceneLanding`): broadcast scene chunks for it are written
/// into it as they arrive, however many, with no RX bank taken; other broadcasts (a chunk of
/// the other bank, a `SceneEnd`) still queue in the RX banks for the node logic.
#[test]
fn broadcast_scene_chunks_land_in_the_lent_bank_and_the_rest_queues() {
    use links_core::landing::{LentBank, SceneKey, SceneLanding};
    use links_core::wire::{Down, SCENE_CHUNK};
    let bus = bus(1);
    let mut master = master_link(&bus, 0);
    let (shared, task, mut port) = slave_link(&bus, 0);
    let scene: &'static mut [u8] = Box::leak(vec![0u8; 6 * SCENE_CHUNK].into_boxed_slice());
    shared
        .lend(LentBank::new(1, scene, None))
        .map_err(|_| "refused")
        .expect("the link takes a bank");
    assert!(
        shared.lend(LentBank::new(0, &mut [], None)).is_err(),
        "one at a time"
    );
    let total = 5 * SCENE_CHUNK as u32 + 10;
    let chunk = |frame: u16, c: u32| {
        let offset = c * SCENE_CHUNK as u32;
        let len = (total - offset).min(SCENE_CHUNK as u32) as usize;
        let data = vec![c as u8 + 1; len];
        let down = Down::Scene {
            frame,
            offset,
            total,
            crc: 9,
            data: &data,
        };
        let mut buf = [0u8; MAX_MESSAGE];
        let n = wire::encode(0, 0, &down, &mut buf).unwrap();
        buf[..n].to_vec()
    };
    let mut end = [0u8; 64];
    let n_end = wire::encode(
        0,
        0,
        &Down::SceneEnd {
            frame: 3,
            len: total,
            crc: 9,
        },
        &mut end,
    )
    .unwrap();
    let rc = async {
        // Frame 3's six chunks (bank 1), then a chunk of frame 2 (bank 0), then SceneEnd.
        let frames = (0..6)
            .map(|c| chunk(3, c))
            .chain([chunk(2, 0), end[..n_end].to_vec()]);
        for f in frames {
            polls(50).await;
            master.broadcast(&f).await.unwrap();
        }
        polls(50).await;
    };
    let link = task.run(&mut port, &shared);
    let Either::First(()) = run(select(rc, link));
    let c = shared.counters();
    assert_eq!((c.broadcasts, c.landed, c.overflows), (8, 6, 0), "{c:?}");
    let back = shared.reclaim().expect("the lent bank comes back");
    let key = SceneKey {
        frame: 3,
        total,
        crc: 9,
    };
    assert_eq!(
        (back.index, back.landed.key, back.landed.count),
        (1, Some(key), 6)
    );
    assert!(back.landed.ended && (0..6).all(|c| back.landed.has(c)));
    assert!(shared.reclaim().is_none());
    for c in 0..6usize {
        let end = ((c + 1) * SCENE_CHUNK).min(total as usize);
        let bytes = &back.bytes[c * SCENE_CHUNK..end];
        assert!(bytes.iter().all(|&b| b == c as u8 + 1), "chunk {c}");
    }
    // The node logic gets the other two, in order.
    let mut handle = shared.handle();
    let mut rx = [0u8; MAX_MESSAGE];
    for want in [chunk(2, 0), end[..n_end].to_vec()] {
        let got = run(handle.recv(&mut rx)).unwrap();
        assert_eq!(got, Incoming::Broadcast { len: want.len() });
        assert_eq!(&rx[..want.len()], &want[..]);
    }
}

#[test]
fn broadcasts_fill_both_rx_banks_then_overflow_into_scratch() {
    let bus = bus(3);
    let mut master = master_link(&bus, 0);
    let (shared, task, mut port) = slave_link(&bus, 1);
    // Node 1 is emulated; nodes 0 and 2 are selected but never armed (they miss bytes).
    let rc = async {
        for k in 0..3u8 {
            // Give the node time to re-arm between broadcasts.
            polls(50).await;
            master.broadcast(&[k; 100]).await.unwrap();
        }
        polls(50).await;
    };
    let link = task.run(&mut port, &shared);
    let Either::First(()) = run(select(rc, link));
    let c = shared.counters();
    assert_eq!(c.broadcasts, 3);
    assert_eq!(c.overflows, 1, "the third found both banks full");
    let mut handle = shared.handle();
    let mut rx = [0u8; MAX_MESSAGE];
    for k in 0..2u8 {
        let got = run(handle.recv(&mut rx)).unwrap();
        assert_eq!(got, Incoming::Broadcast { len: 100 });
        assert!(rx[..100].iter().all(|&b| b == k));
    }
    let b = bus.borrow();
    assert!(b.missed > 0, "unarmed nodes miss what is clocked");
    assert!(b.violations.is_empty(), "{:?}", b.violations);
}

/// RC double buffering: the next frame is composed in the idle TX bank while the started
/// transfer waits in the other; composing never changes what goes out.
#[test]
fn rc_composes_the_next_frame_while_a_transfer_is_started() {
    let bus = bus(1);
    let mut master = master_link(&bus, 0);
    let (shared, task, mut port) = slave_link(&bus, 0);
    let rc = async {
        let mut rx = [0u8; MAX_MESSAGE];
        assert_eq!(master.finish(&mut rx).await, Err(LinkError::Aborted));
        polls(20).await;
        master.tx_bank()[..64].fill(1);
        master.start(Transfer::Broadcast, 64).unwrap();
        assert_eq!(
            master.start(Transfer::Broadcast, 64),
            Err(LinkError::Busy),
            "one transfer at a time"
        );
        // The next frame, composed before the first is clocked.
        master.tx_bank()[..64].fill(2);
        assert_eq!(master.finish(&mut rx).await, Ok(0));
        polls(20).await;
        master.start(Transfer::Broadcast, 64).unwrap();
        master.tx_bank()[..64].fill(3);
        assert_eq!(master.finish(&mut rx).await, Ok(0));
        assert_eq!(
            master.start(Transfer::Exchange(1), 1),
            Err(LinkError::NoSuchNode { node: 1 })
        );
        assert!(matches!(
            master.start(Transfer::Broadcast, MAX_MESSAGE + 1),
            Err(LinkError::TooLong { .. })
        ));
        polls(20).await;
    };
    let link = task.run(&mut port, &shared);
    let Either::First(()) = run(select(rc, link));
    assert_eq!(shared.counters().broadcasts, 2);
    let mut handle = shared.handle();
    let mut rx = [0u8; MAX_MESSAGE];
    for k in 1..=2u8 {
        let got = run(handle.recv(&mut rx)).unwrap();
        assert_eq!(got, Incoming::Broadcast { len: 64 });
        assert!(rx[..64].iter().all(|&b| b == k), "frame {k} as composed");
    }
    assert!(bus.borrow().violations.is_empty());
}

/// The split link (`MasterFront` + `MasterTask`, the firmware's): the task clocks the
/// exchange while the RC composes the next frame. The RC writes its next frame only once
/// the emulated bus shows the node selected and the exchange's trailer not yet clocked, so
/// a link that clocks only inside `finish` (no overlap) stalls here and fails the test.
#[test]
fn split_link_composes_while_the_task_clocks_the_transfer() {
    let bus = bus(1);
    let (shared, mut front, task, mut mport) = master_split(&bus, 0);
    let (nshared, ntask, mut nport) = slave_link(&bus, 0);
    let up: Vec<u8> = (0..700u32).map(|i| (i * 5 + 2) as u8).collect();
    let mut handle = nshared.handle();
    handle.post(&up).unwrap();
    let seen = RefCell::new(None);
    let rc = async {
        let mut rx = [0u8; MAX_MESSAGE];
        assert_eq!(front.finish(&mut rx).await, Err(LinkError::Aborted));
        let node = front.wait_ready().await;
        assert_eq!(node, 0);
        front.tx_bank()[..40].fill(7);
        front.start(Transfer::Exchange(0), 40).unwrap();
        assert_eq!(front.start(Transfer::Broadcast, 1), Err(LinkError::Busy));
        // Wait until the task has the node selected: the exchange is on the wire.
        core::future::poll_fn(|cx| {
            if bus.borrow().selected.is_some() {
                Poll::Ready(())
            } else {
                cx.waker().wake_by_ref();
                Poll::Pending
            }
        })
        .await;
        // Compose the next frame now, and note what the wire was doing meanwhile.
        front.tx_bank()[..64].fill(9);
        *seen.borrow_mut() = Some((
            shared.in_flight(),
            bus.borrow().selected.is_some(),
            bus.borrow().trailers.len(),
        ));
        let n = front.finish(&mut rx).await.unwrap();
        assert!(!shared.in_flight());
        polls(50).await;
        front.start(Transfer::Broadcast, 64).unwrap();
        front.finish(&mut []).await.unwrap();
        polls(50).await;
        rx[..n].to_vec()
    };
    let nc = async {
        let mut rx = [0u8; MAX_MESSAGE];
        let a = handle.recv(&mut rx).await.unwrap();
        let down = rx[..40].to_vec();
        let b = handle.recv(&mut rx).await.unwrap();
        (a, down, b, rx[..64].to_vec())
    };
    let tasks = select(
        task.run(&mut mport, shared),
        ntask.run(&mut nport, &nshared),
    );
    // The link tasks never end (`!`): only the first arm exists.
    let Either::First((got_up, (a, down, b, bcast))) = run(select(join(rc, nc), tasks));
    assert_eq!(
        *seen.borrow(),
        Some((true, true, 0)),
        "composed while the exchange was selected and before its trailer"
    );
    assert_eq!(got_up, up, "the node's frame crossed intact");
    assert_eq!(a, Incoming::Exchanged { len: 40 });
    assert_eq!(down, [7u8; 40], "the frame composed before start went out");
    assert_eq!(b, Incoming::Broadcast { len: 64 });
    assert_eq!(
        bcast, [9u8; 64],
        "the frame composed during the transfer went out"
    );
    let c = shared.counters();
    assert_eq!((c.exchanges, c.broadcasts, c.naks), (1, 1, 0));
    assert_eq!(bus.borrow().trailers, [ACK]);
    assert!(bus.borrow().violations.is_empty());
}

#[test]
fn a_corrupt_broadcast_is_counted_and_dropped() {
    let bus = bus(1);
    bus.borrow_mut().faults.push((0, Dir::Down, HEADER + 3));
    let mut master = master_link(&bus, 0);
    let (shared, task, mut port) = slave_link(&bus, 0);
    let rc = async {
        polls(20).await;
        master.broadcast(&[9u8; 64]).await.unwrap();
        polls(20).await;
        master.broadcast(&[8u8; 64]).await.unwrap();
        polls(20).await;
    };
    let Either::First(()) = run(select(rc, task.run(&mut port, &shared)));
    let c = shared.counters();
    assert_eq!((c.broadcasts, c.bad_bodies), (2, 1));
    let mut rx = [0u8; MAX_MESSAGE];
    let got = run(shared.handle().recv(&mut rx)).unwrap();
    assert_eq!(got, Incoming::Broadcast { len: 64 });
    assert_eq!(rx[..64], [8u8; 64], "only the intact one is delivered");
}

// ---------------------------------------------------------------------------------------
// End to end: root and node logic over the link
// ---------------------------------------------------------------------------------------

async fn node(
    bus: SharedBus,
    i: usize,
    scene: &mut [u8],
    odd: &mut [u8],
) -> (NodeReport, links_core::spi::SlaveCounters) {
    let (shared, task, mut port) = slave_link(&bus, i);
    let mut report = NodeReport::default();
    let mut handle = shared.handle();
    let (mut clock, mut tracer) = (RealTime, Tracing::<f32>::new());
    let logic = run_node(
        NodeConfig::default(),
        &mut handle,
        &mut clock,
        &mut tracer,
        [scene, odd],
        &mut report,
    );
    match select(logic, task.run(&mut port, &shared)).await {
        Either::First(r) => r.expect("node ends on Stop"),
    }
    (report, shared.counters())
}

/// Which RC link drives the cluster.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum RcLink {
    /// `MasterLink`: clocked inside `finish`.
    Inline,
    /// `MasterFront` + `MasterTask` (the firmware's): clocked while the RC composes.
    Split,
}

fn cluster(faults: Vec<(u64, Dir, usize)>, lose_edges: u32, link: RcLink) {
    let (w, h) = (24u32, 16u32);
    let img = bundled_image("photo1.ron", w, h);
    let want = render_frame(&img, Precision::F32, 1, &|| {})
        .expect("renders")
        .rgb;
    let bus = bus(2);
    bus.borrow_mut().faults = faults.clone();
    bus.borrow_mut().lose_edges = lose_edges;
    let cfg = RootConfig {
        policy: Policy::DECREASING,
        nodes: 2,
        frames: 1,
        timeout_us: 0,
        double_buffer: true,
    };
    let scenes = [img.as_slice()];
    let root = RefCell::new(RootState::new(cfg, &scenes[..]).expect("valid"));
    let sink = RefCell::new(FrameSink::new(w, h));
    let mut scene_banks: Vec<Vec<u8>> = (0..4).map(|_| vec![0u8; img.len()]).collect();
    let [s0, s1, s2, s3] = &mut scene_banks[..] else {
        unreachable!()
    };
    let nodes = join_array([node(bus.clone(), 0, s0, s1), node(bus.clone(), 1, s2, s3)]);
    let (rr, nodes, mc) = match link {
        RcLink::Inline => {
            let mut master = master_link(&bus, 0);
            let rc = run_bus(0, &mut master, &NoClock, &root, &scenes[..], &sink);
            let (rr, nodes) = run(join(rc, nodes));
            (rr, nodes, master.counters)
        }
        RcLink::Split => {
            let (shared, mut front, task, mut port) = master_split(&bus, 0);
            let rc = async {
                let logic = run_bus(0, &mut front, &NoClock, &root, &scenes[..], &sink);
                match select(logic, task.run(&mut port, shared)).await {
                    Either::First(r) => r,
                }
            };
            let (rr, nodes) = run(join(rc, nodes));
            (rr, nodes, shared.counters())
        }
    };
    let rr = rr.expect("root runs");
    assert_eq!(
        sink.borrow().rgb,
        want,
        "frame equals the single-node render"
    );
    let b = bus.borrow();
    assert!(b.violations.is_empty(), "{:?}", b.violations);
    let pixels: u64 = nodes.iter().map(|(r, _)| r.pixels).sum();
    assert!(pixels >= (w * h) as u64);
    assert!(rr.broadcasts > 0 && mc.exchanges > 0);
    if faults.is_empty() && lose_edges == 0 {
        assert_eq!(mc.naks + mc.bad_headers, 0);
        assert_eq!(rr.bad_messages, 0);
    } else {
        let hit = b.faults_hit as u64;
        let node_bad: u32 = nodes
            .iter()
            .map(|(_, c)| c.bad_bodies + c.bad_headers)
            .sum();
        let resent: u32 = nodes.iter().map(|(_, c)| c.retransmits).sum();
        assert_eq!(
            hit,
            faults.len() as u64,
            "every fault landed ({} transfers)",
            b.transfers
        );
        assert!(
            (mc.naks + mc.bad_headers) as u64 + node_bad as u64 >= 1,
            "faults were noticed"
        );
        assert!(
            resent >= mc.naks,
            "every NAK was answered by a retransmission"
        );
        assert_eq!(b.edges_lost, lose_edges);
    }
}

#[test]
fn cluster_over_the_link_equals_the_single_node_render() {
    cluster(Vec::new(), 0, RcLink::Inline);
}

#[test]
fn cluster_over_the_split_link_equals_the_single_node_render() {
    cluster(Vec::new(), 0, RcLink::Split);
}

#[test]
fn cluster_over_the_split_link_survives_corrupt_bytes_and_lost_edges() {
    cluster(fault_plan(), 3, RcLink::Split);
}

#[test]
fn cluster_over_the_link_survives_corrupt_bytes_and_lost_edges() {
    cluster(fault_plan(), 3, RcLink::Inline);
}

/// Transfers in all three phases of several exchanges and broadcasts, both directions
/// (transfers 10 to 87 of the run's ~100).
fn fault_plan() -> Vec<(u64, Dir, usize)> {
    (0..12u64)
        .map(|k| {
            let dir = if k % 2 == 0 { Dir::Up } else { Dir::Down };
            (10 + 7 * k, dir, (k as usize * 5) % 9)
        })
        .collect()
}

#[test]
fn wire_frames_fit_a_bank() {
    let mut buf = [0u8; MAX_MESSAGE];
    let n = wire::encode(1, 2, &wire::Down::Stop, &mut buf).unwrap();
    assert!(HEADER + n < BANK);
}

// ---------------------------------------------------------------------------------------
// The RC firmware's render request (rc_fw::render) over the link, read back as the PC would
// ---------------------------------------------------------------------------------------

/// A small USB queue drained a few bytes per poll, as the CDC endpoint drains the RC's.
struct UsbQueue {
    queued: std::collections::VecDeque<u8>,
    cap: usize,
    sent: Vec<u8>,
    /// Bytes that did not fit (pushes refused).
    refused: u32,
}

#[derive(Clone, Copy)]
struct Q<'a>(&'a RefCell<UsbQueue>);

impl rc_fw::readback::ByteQueue for Q<'_> {
    fn free(&self) -> usize {
        let q = self.0.borrow();
        q.cap - q.queued.len()
    }
    fn push(&mut self, bytes: &[u8]) -> bool {
        let mut q = self.0.borrow_mut();
        if bytes.len() > q.cap - q.queued.len() {
            q.refused += 1;
            return false;
        }
        q.queued.extend(bytes);
        true
    }
}

impl rc_fw::throttle::Room for Q<'_> {
    fn has_room(&self, n: usize) -> bool {
        let q = self.0.borrow();
        q.cap - q.queued.len() >= n
    }
    async fn wait_room(&self, n: usize) {
        core::future::poll_fn(|cx| {
            let q = self.0.borrow();
            if q.cap - q.queued.len() >= n {
                Poll::Ready(())
            } else {
                cx.waker().wake_by_ref();
                Poll::Pending
            }
        })
        .await
    }
}

/// Move up to 63 bytes (one CDC packet) from the queue to `sent` per poll, until `done`.
async fn drain(q: &RefCell<UsbQueue>, done: &core::cell::Cell<bool>) {
    core::future::poll_fn(|cx| {
        let mut q = q.borrow_mut();
        for _ in 0..63 {
            match q.queued.pop_front() {
                Some(b) => q.sent.push(b),
                None => break,
            }
        }
        if done.get() && q.queued.is_empty() {
            Poll::Ready(())
        } else {
            cx.waker().wake_by_ref();
            Poll::Pending
        }
    })
    .await
}

#[test]
fn rc_render_request_streams_the_frame_over_usb_and_answers_resend() {
    let (w, h) = (24u32, 16u32);
    let img = bundled_image("photo1.ron", w, h);
    let want = render_frame(&img, Precision::F32, 1, &|| {})
        .expect("renders")
        .rgb;
    let bus = bus(2);
    let mut master = master_link(&bus, 0);
    let mut scene_banks: Vec<Vec<u8>> = (0..4).map(|_| vec![0u8; img.len()]).collect();
    let [s0, s1, s2, s3] = &mut scene_banks[..] else {
        unreachable!()
    };
    // A queue smaller than a frame: the bus must wait for USB, never drop.
    let usb = RefCell::new(UsbQueue {
        queued: Default::default(),
        cap: 2 * rc_fw::readback::RUN_RESERVE,
        sent: Vec::new(),
        refused: 0,
    });
    let done = core::cell::Cell::new(false);
    let mut enc = links_core::serial::Encoder::new();
    let mut last = None;
    let rc = async {
        let r = rc_fw::render::render_frames(
            &mut master,
            &NoClock,
            &Q(&usb),
            &mut Q(&usb),
            &img,
            1,
            rc_fw::render::NodeSet::on(&links_core::board::BoardProfile::F407, 2),
            &mut enc,
            &mut last,
        )
        .await;
        done.set(true);
        r
    };
    let nodes = join_array([node(bus.clone(), 0, s0, s1), node(bus.clone(), 1, s2, s3)]);
    let (((r, nodes), ()), ()) = (run(join(join(rc, nodes), drain(&usb, &done))), ());
    let report = r.expect("frame rendered");
    assert!(report.pixels >= (w * h) as u64);
    assert!(nodes.iter().all(|(n, _)| n.pixels > 0), "both nodes worked");
    let sent = std::mem::take(&mut usb.borrow_mut().sent);
    let ReadBack { rgb: got, ends, .. } = read_back(&sent, w as usize, h as usize);
    assert_eq!(got, want, "the PC assembles the single-node render");
    assert_eq!(ends, [wire::CRC32.checksum(&want)]);
    assert_eq!(usb.borrow().refused, 0);

    // Resend of a span that crosses a row: rendered again on the RC, then FrameEnd again.
    let fs = last.expect("the last frame is kept");
    done.set(false);
    let resend = async {
        rc_fw::render::resend_span(&fs, &img, 20, 30, &mut enc, &Q(&usb), &mut Q(&usb))
            .await
            .expect("resent");
        done.set(true);
    };
    run(join(resend, drain(&usb, &done)));
    let sent = std::mem::take(&mut usb.borrow_mut().sent);
    let ReadBack {
        rgb: again,
        ends,
        runs,
        ..
    } = read_back(&sent, w as usize, h as usize);
    assert_eq!(
        runs, 3,
        "row 0 from column 20, row 1 whole, row 2 up to column 2"
    );
    assert_eq!(again[3 * 20..3 * 50], want[3 * 20..3 * 50]);
    assert!(
        again[..3 * 20].iter().all(|&b| b == 0),
        "nothing else resent"
    );
    assert_eq!(ends, [wire::CRC32.checksum(&want)]);
}
