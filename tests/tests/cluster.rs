//! The simulated cluster: frames bit-identical to the single-node render for every node
//! count, bus count, scheduling policy and collection path; recovery from corrupted frames;
//! exact broadcast byte counts; determinism.

use links_core::board::BoardProfile;
use links_core::node::NodeConfig;
use links_core::wire::PixelCoding;

/// Every pixel coding a node may use, for tests that cycle through them.
const CODINGS: [PixelCoding; 3] = [PixelCoding::Raw, PixelCoding::Rle, PixelCoding::Delta];
use links_core::sched::{Policy, Split};
use links_core::wire::{self, Down, SCENE_CHUNK};
use links_host::cluster::relay::{Topology, TreeShape};
use links_host::cluster::spi_bus::LinkModel;
use links_host::cluster::star::{BroadcastDrop, Faults, NodeDeath, Noise};
use links_host::cluster::{simulate, simulate_frame, Collect, SimConfig, SimError, SimReport};

use links_tests::{bundled_image as image, host_reference as reference};

fn run(img: &[u8], cfg: SimConfig) -> SimReport {
    let cfg = SimConfig {
        keep_frames: true,
        ..cfg
    };
    simulate_frame(img, &cfg).unwrap_or_else(|e| panic!("{cfg:?}: {e}"))
}

#[test]
fn cluster_frames_are_bit_identical_to_the_single_node_render() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let cases = [
        (1, 1, Policy::DECREASING),
        (3, 1, Policy::Static { shape: Split::Span }),
        (8, 2, Policy::Static { shape: Split::Rect }),
        (
            5,
            1,
            Policy::Fixed {
                divisions: 48,
                shape: Split::Rect,
            },
        ),
        (
            7,
            3,
            Policy::Fixed {
                divisions: 100,
                shape: Split::Span,
            },
        ),
        (16, 4, Policy::DECREASING),
        (64, 1, Policy::DECREASING),
        (
            200,
            8,
            Policy::Decreasing {
                factor: 1,
                min_pixels: 1,
            },
        ),
    ];
    let boards = [BoardProfile::F407, BoardProfile::IDEAL];
    for (i, (board, (nodes, buses, policy))) in boards
        .iter()
        .flat_map(|b| cases.iter().map(move |c| (*b, *c)))
        .enumerate()
    {
        let r = run(
            &img,
            SimConfig {
                nodes,
                buses,
                policy,
                node: NodeConfig {
                    coding: CODINGS[i % 3],
                },
                ..SimConfig::for_board(board)
            },
        );
        assert_eq!(r.frames.len(), 1);
        assert_eq!(r.profile, board);
        assert!(
            r.frames[0] == want,
            "{} board, {nodes} nodes, {buses} buses, {policy:?}",
            board.name
        );
        assert_eq!(r.root.pixels, 64 * 60);
        assert_eq!(r.root.bad_messages, 0);
        let px: u64 = r.node_reports.iter().map(|n| n.pixels).sum();
        assert_eq!(px, 64 * 60);
        assert!(r.time_s > 0.0);
    }
}

/// Fixed-point nodes: the cluster's frame of the DM's Q16.16 image is bit-identical to the
/// single-node fixed-point render for 1, 3, 8 and 16 nodes under the dynamic and the static
/// policy, on the F207 and the G0B1 (their nodes carry the Q16.16 kernel only) and on the
/// F407 (both kernels; the image picks). Nodes that lack the image's kernel are refused
/// before the run.
#[test]
fn fixed_point_cluster_frames_are_bit_identical_to_the_single_node_fixed_render() {
    use links_core::node::Kernels;
    use links_core::num::Storage;
    use links_host::frame::{fixed_image, render_frame, Precision};
    let img = fixed_image(&image("photo1.ron", 64, 60)).expect("photo1 fits Q16.16");
    let want = render_frame(&img, Precision::Fixed, 1, &|| {})
        .expect("renders")
        .rgb;
    assert!(
        want != reference(&image("photo1.ron", 64, 60)),
        "f32 differs"
    );
    let policies = [Policy::DECREASING, Policy::Static { shape: Split::Rect }];
    let mut times = Vec::new();
    for board in [BoardProfile::F207, BoardProfile::F407, BoardProfile::G0B1] {
        for (nodes, policy) in [1u16, 3, 8, 16]
            .into_iter()
            .flat_map(|n| policies.map(|p| (n, p)))
        {
            let r = run(
                &img,
                SimConfig {
                    nodes,
                    policy,
                    ..SimConfig::buildable(board, nodes)
                },
            );
            let what = format!("{} board, {nodes} nodes, {policy:?}", board.name);
            assert!(r.frames[0] == want, "{what}");
            assert_eq!(r.root.pixels, 64 * 60, "{what}");
            if nodes == 1 && policy == Policy::DECREASING {
                times.push(r.time_s);
            }
        }
    }
    // One F207 node (Cortex-M3, 120 MHz) takes longer than one F407 node (M4F, 168 MHz),
    // one G0B1 node (Cortex-M0+, 64 MHz, about twice the M3's instructions) longer still.
    assert!(times[0] > times[1], "{times:?}");
    assert!(times[2] > 2.0 * times[0], "{times:?}");
    let f32_nodes = SimConfig {
        kernels: Kernels::F32,
        ..SimConfig::for_board(BoardProfile::F407)
    };
    match simulate_frame(&img, &f32_nodes) {
        Err(SimError::NoKernel {
            frame: 0,
            image: Storage::Q16_16,
            kernels: Kernels::F32,
            mixed: false,
        }) => {}
        other => panic!("f32-only nodes sent a Q16.16 image: {other:?}"),
    }
    let f32_img = image("photo1.ron", 64, 60);
    let f207 = SimConfig::for_board(BoardProfile::F207);
    assert!(matches!(
        simulate_frame(&f32_img, &f207),
        Err(SimError::NoKernel {
            image: Storage::F32,
            kernels: Kernels::Fixed,
            ..
        })
    ));
    assert!(matches!(
        simulate(&[&img[..], &f32_img[..]], &SimConfig::default()),
        Err(SimError::NoKernel {
            frame: 1,
            mixed: true,
            ..
        })
    ));
}

/// Fixed-point frames stay bit-identical to the single-node fixed render under every policy
/// (fixed divisions in spans and rectangles, static spans) and past one bus: 24 and 64 nodes
/// on the buildable relay tree (the firmware's relay code, the board's default), and 64
/// nodes through the simulator's relay model (`--relay model`, the F407 board whose nodes
/// carry both kernels).
#[test]
fn fixed_point_frames_are_bit_identical_under_every_policy_and_topology() {
    use links_host::cluster::relay::RelayCode;
    use links_host::frame::{fixed_image, render_frame, Precision};
    let img = fixed_image(&image("photo1.ron", 64, 60)).expect("photo1 fits Q16.16");
    let want = render_frame(&img, Precision::Fixed, 1, &|| {})
        .expect("renders")
        .rgb;
    let policies = [
        Policy::Fixed {
            divisions: 40,
            shape: Split::Span,
        },
        Policy::Fixed {
            divisions: 48,
            shape: Split::Rect,
        },
        Policy::Static { shape: Split::Span },
        Policy::DECREASING,
    ];
    for (board, nodes) in [
        (BoardProfile::F207, 5u16),
        (BoardProfile::G0B1, 24),
        (BoardProfile::F407, 64),
    ] {
        for policy in policies {
            let cfg = SimConfig {
                policy,
                ..SimConfig::buildable(board, nodes)
            };
            let what = format!("{} board, {nodes} nodes, {policy:?}", board.name);
            let r = run(&img, cfg);
            assert!(r.frames[0] == want, "{what}");
            assert_eq!(r.root.pixels, 64 * 60, "{what}");
        }
    }
    let board = SimConfig::buildable(BoardProfile::F407, 64);
    assert!(board.tree().is_some(), "64 F407 nodes are a relay tree");
    assert_eq!(board.relay, RelayCode::Firmware, "the board's relay code");
    let modelled = SimConfig {
        relay: RelayCode::Model,
        ..board
    };
    let r = run(&img, modelled);
    assert!(r.frames[0] == want, "the relay model");
}

/// Each board's node time-out keeps the F407's margin over the longest run a node renders:
/// the time-outs' ratios follow the one-node frame times of photo1 (each board's own
/// storage) within a factor of two, and 8 G0B1 nodes render photo1 at 256x240 (runs of 256
/// pixels, each longer than the F407's 0.5 s on the M0+) without a false alarm, where the
/// F407's bound raised several.
#[test]
fn node_time_outs_scale_with_the_boards_node_speed() {
    use links_host::frame::fixed_image;
    let f32_img = image("photo1.ron", 64, 60);
    let q_img = fixed_image(&f32_img).expect("photo1 fits Q16.16");
    let one_node =
        |board: BoardProfile, img: &[u8]| run(img, SimConfig::buildable(board, 1)).time_s;
    let f407 = BoardProfile::F407;
    let base = one_node(f407, &f32_img);
    for board in [BoardProfile::F207, BoardProfile::G0B1] {
        let slower = one_node(board, &q_img) / base;
        let bound = board.node_timeout_us as f64 / f407.node_timeout_us as f64;
        assert!(
            (0.5..=2.0).contains(&(bound / slower)),
            "{}: time-out {bound:.1} times the F407's, node {slower:.1} times slower",
            board.name
        );
    }
    let big = fixed_image(&image("photo1.ron", 256, 240)).expect("photo1 fits Q16.16");
    let g0b1 = SimConfig::buildable(BoardProfile::G0B1, 8);
    let r = run(&big, g0b1.clone());
    assert_eq!(r.root.timeouts, 0, "false alarms at the G0B1's own bound");
    let f407_bound = SimConfig {
        node_timeout_s: f407.node_timeout_us as f64 * 1e-6,
        ..g0b1
    };
    let r = run(&big, f407_bound);
    assert!(
        r.root.timeouts > 0,
        "the F407's bound raised no false alarm on the G0B1"
    );
}

/// The relay tree (the F407's buildable topology): frames bit-identical to the single-node
/// render at every node count (one and two levels of relays), policy, with and without
/// batching, under bit errors and a node death; every node frame crosses every link up to
/// the root exactly once, every scene piece every link down exactly once.
#[test]
fn relay_tree_frames_are_bit_identical_and_every_frame_crosses_each_link_once() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let policies = [
        Policy::DECREASING,
        Policy::Static { shape: Split::Rect },
        Policy::Fixed {
            divisions: 100,
            shape: Split::Span,
        },
    ];
    let pieces = img.len().div_ceil(SCENE_CHUNK) as u64 + 1;
    let counts = [9u16, 16, 64, 65, 200, 256];
    for (i, (nodes, batch)) in counts
        .iter()
        .flat_map(|&n| [(n, true), (n, false)])
        .enumerate()
    {
        let policy = policies[i % policies.len()];
        let cfg = SimConfig {
            nodes,
            policy,
            topology: Topology::RelayTree { fanout: 8, batch },
            node: NodeConfig {
                coding: CODINGS[i % 3],
            },
            ..SimConfig::for_board(BoardProfile::F407)
        };
        let what = format!("{nodes} nodes, batch {batch}, {policy:?}");
        let r = run(&img, cfg);
        assert!(r.frames[0] == want, "{what}");
        assert_eq!(r.root.pixels, 64 * 60, "{what}");
        let shape = TreeShape::of(nodes, 8, 8).unwrap();
        assert_eq!(r.buses, shape.leaves, "{what}");
        assert_eq!(r.buses, nodes.div_ceil(8), "{what}");
        let tree = r.tree.as_ref().expect("a relay tree reports its links");
        assert_eq!(tree.links.len(), 1 + shape.mids as usize, "{what}");
        let exchanges: u64 = r.bus.iter().map(|b| b.exchanges).sum();
        assert_eq!(tree.links[0].frames_up, exchanges, "{what}");
        let mid_frames: u64 = tree.links[1..].iter().map(|l| l.frames_up).sum();
        assert_eq!(mid_frames, if shape.mids > 0 { exchanges } else { 0 });
        for l in &tree.links {
            assert_eq!(l.broadcasts, pieces, "{what}");
            if batch {
                assert!(l.exchanges <= l.frames_up, "{what}");
            } else {
                assert_eq!(l.exchanges, l.frames_up, "{what}");
            }
        }
        // Every leaf bus carries the scene pieces and its Stop.
        assert!(r.bus.iter().all(|b| b.broadcasts == pieces + 1), "{what}");
        assert!(tree.root_busy_s > 0.0 && r.time_s > 0.0);
    }
    // Bit errors both ways and a node that dies mid-frame, two levels of relays.
    let base = SimConfig {
        nodes: 72,
        topology: Topology::buildable(&BoardProfile::F407, 72),
        ..SimConfig::for_board(BoardProfile::F407)
    };
    let t0 = run(&img, base.clone()).time_s;
    let r = run(
        &img,
        SimConfig {
            noise: Noise {
                ber_down: 1e-5,
                ber_up: 1e-5,
                drop_broadcast: 0.0,
                seed: 9,
            },
            deaths: vec![NodeDeath {
                node: 70,
                at_s: t0 / 2.0,
            }],
            node_timeout_s: t0 / 4.0,
            ..base
        },
    );
    assert!(r.frames[0] == want);
    assert_eq!(r.tree.as_ref().map(|t| t.shape.mids), Some(2));
    let corrupted: u64 = r.bus.iter().map(|b| b.corrupted()).sum();
    assert!(corrupted > 0, "the noise hit nothing");
}

/// The buildable topology is a star while one bus holds every node, a relay tree otherwise;
/// the idealised link's one bus holds 256.
#[test]
fn the_buildable_topology_keeps_every_bus_within_the_board() {
    for nodes in [1u16, 8, 9, 64, 256] {
        let f = SimConfig::buildable(BoardProfile::F407, nodes);
        assert_eq!(f.overloaded_bus(), None, "{nodes}");
        assert_eq!(
            f.node_buses(),
            if nodes <= 8 { 1 } else { nodes.div_ceil(8) }
        );
        assert_eq!(f.tree().is_some(), nodes > 8);
        let i = SimConfig::buildable(BoardProfile::IDEAL, nodes);
        assert_eq!((i.topology, i.node_buses()), (Topology::Star, 1));
    }
    // The library's default star of one bus overloads the F407's at 64 nodes.
    assert_eq!(
        SimConfig::for_board(BoardProfile::F407).overloaded_bus(),
        Some(64)
    );
}

#[test]
fn render_cluster_reports_the_speed_up_against_one_node() {
    let img = image("photo1.ron", 64, 60);
    let r = links_host::cluster::render_cluster(
        &img,
        &SimConfig {
            nodes: 8,
            ..SimConfig::default()
        },
    )
    .expect("renders");
    assert!(r.report.frames[0] == reference(&img));
    let one = simulate_frame(
        &img,
        &SimConfig {
            nodes: 1,
            ..SimConfig::default()
        },
    )
    .unwrap();
    assert_eq!(r.one_node_s, one.time_s);
    assert_eq!(r.speedup, one.time_s / r.report.time_s);
    assert!(r.speedup > 1.0 && r.speedup <= 8.0, "{}", r.speedup);
}

#[test]
fn pixels_through_the_root_give_the_same_frame_and_cost_only_the_copy() {
    let img = image("photo1.ron", 64, 60);
    let cfg = SimConfig {
        nodes: 6,
        ..SimConfig::default()
    };
    let a = run(&img, cfg.clone());
    let b = run(
        &img,
        SimConfig {
            collect: Collect::ViaRoot,
            ..cfg
        },
    );
    assert!(a.frames[0] == b.frames[0]);
    // The RC copies every accepted pixel into the frame memory: 3 bytes per pixel at
    // `copy_per_byte`, nothing else changes (the RC decodes and checks each run either way).
    let cost = SimConfig::default().rc_cost;
    let copy =
        3.0 * (64 * 60) as f64 * cost.copy_per_byte * cost.cycles_per_instruction / cost.clock_hz;
    let extra = b.rc_busy_s - a.rc_busy_s;
    assert!((extra - copy).abs() < 1e-9, "{extra} vs {copy}");
    assert!(
        b.time_s >= a.time_s && b.time_s - a.time_s <= copy,
        "{} vs {}",
        b.time_s,
        a.time_s
    );
}

#[test]
fn corrupted_frames_are_caught_and_resent() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let r = run(
        &img,
        SimConfig {
            nodes: 6,
            buses: 2,
            faults: Faults {
                up_every: 5,
                down_every: 7,
                broadcast_every: 3,
                random: None,
            },
            ..SimConfig::default()
        },
    );
    assert!(r.frames[0] == want);
    let sum =
        |f: fn(&links_host::cluster::star::BusCounters) -> u64| r.bus.iter().map(f).sum::<u64>();
    let (up, down, bcast) = (
        sum(|b| b.corrupted_up),
        sum(|b| b.corrupted_down),
        sum(|b| b.corrupted_broadcast),
    );
    assert!(up > 10 && down > 10 && bcast > 5, "{up} {down} {bcast}");
    // Every corrupted NC frame is caught by the RC's CRC, every corrupted RC frame by the
    // node's, and the lost frames are sent again.
    assert!(r.root.bad_messages > 0);
    let node_bad: u32 = r.node_reports.iter().map(|n| n.bad_messages).sum();
    let resent: u32 = r.node_reports.iter().map(|n| n.messages_resent).sum();
    assert!(node_bad > 0 && resent > 0);
    // The RC sees every exchange it clocks: each corrupted NC frame is caught exactly once.
    assert_eq!(r.root.bad_messages as u64, up);
    // Nodes catch what reaches them (a node that has stopped reads no more).
    assert!(
        node_bad as u64 <= down + bcast && node_bad as u64 >= down / 2,
        "{node_bad}"
    );
    // Broadcast damage was repaired point-to-point.
    assert!(r.root.repairs > 0);
}

#[test]
fn heavy_fault_patterns_never_stall_or_change_a_pixel() {
    let img = image("reflections.ron", 32, 30);
    let want = reference(&img);
    let patterns = [
        (2, 3, 0),
        (3, 2, 5),
        (4, 4, 3),
        (2, 2, 2),
        (6, 5, 4),
        (3, 3, 7),
    ];
    for (i, (up, down, bcast)) in patterns.into_iter().enumerate() {
        for nodes in [1u16, 3, 5] {
            let r = run(
                &img,
                SimConfig {
                    nodes,
                    buses: 1 + (i as u16 % 2),
                    faults: Faults {
                        up_every: up,
                        down_every: down,
                        broadcast_every: bcast,
                        random: Some(1 + i as u64),
                    },
                    ..SimConfig::default()
                },
            );
            assert!(
                r.frames[0] == want,
                "faults {up}/{down}/{bcast}, {nodes} nodes"
            );
        }
    }
}

#[test]
fn faults_in_step_with_the_protocol_are_reported_as_livelock_not_a_hang() {
    // One node, every second NC frame corrupted: the go-back-N resend always lands on an
    // even transfer. A real link is not that adversarial; the simulator must still stop.
    let img = image("reflections.ron", 32, 30);
    let cfg = SimConfig {
        nodes: 1,
        faults: Faults {
            up_every: 2,
            ..Faults::default()
        },
        ..SimConfig::default()
    };
    match simulate_frame(&img, &cfg) {
        Err(e) => assert!(e.to_string().contains("livelock"), "{e}"),
        Ok(r) => assert!(r.frames.is_empty() || r.root.pixels == 32 * 30),
    }
}

#[test]
fn a_node_repairs_a_broadcast_that_lost_every_other_chunk_and_its_end() {
    let img = image("photo1.ron", 64, 60);
    let chunks = img.len().div_ceil(SCENE_CHUNK);
    // One node, every second broadcast frame corrupted: chunks 1, 3, 5, ... are lost, and
    // either the last chunk (even count) or the SceneEnd after it (odd count): the node
    // learns the broadcast ended from whichever arrives.
    let r = run(
        &img,
        SimConfig {
            nodes: 1,
            faults: Faults {
                broadcast_every: 2,
                ..Faults::default()
            },
            ..SimConfig::default()
        },
    );
    assert!(r.frames[0] == reference(&img));
    assert_eq!(r.root.repairs as usize, chunks / 2);
    assert_eq!(
        r.node_reports[0].chunks as usize,
        chunks.div_ceil(2) + chunks / 2
    );
}

#[test]
fn broadcast_bytes_are_exact() {
    let img = image("photo1.ron", 64, 60);
    let r = run(
        &img,
        SimConfig {
            nodes: 4,
            buses: 2,
            node: NodeConfig {
                coding: PixelCoding::Raw,
            },
            ..SimConfig::default()
        },
    );
    // Every bus carries the scene in SCENE_CHUNK pieces, its SceneEnd and a Stop.
    let mut buf = [0u8; wire::MAX_MESSAGE];
    let mut want = 0u64;
    for (i, chunk) in img.chunks(SCENE_CHUNK).enumerate() {
        let m = Down::Scene {
            frame: 0,
            offset: (i * SCENE_CHUNK) as u32,
            total: img.len() as u32,
            crc: wire::CRC32.checksum(&img),
            data: chunk,
        };
        want += wire::encode(0, 0, &m, &mut buf).unwrap() as u64;
    }
    let end = Down::SceneEnd {
        frame: 0,
        len: img.len() as u32,
        crc: wire::CRC32.checksum(&img),
    };
    want += wire::encode(0, 0, &end, &mut buf).unwrap() as u64;
    want += wire::encode(0, 0, &Down::Stop, &mut buf).unwrap() as u64;
    for b in &r.bus {
        assert_eq!(b.broadcast_bytes, want);
        assert_eq!(b.broadcasts, img.len().div_ceil(SCENE_CHUNK) as u64 + 2);
    }
    // Pixel payload: at least 3 bytes per pixel, plus a few bytes of header per run.
    let up: u64 = r.bus.iter().map(|b| b.up_bytes).sum();
    assert!((3 * 64 * 60..4 * 64 * 60).contains(&up), "{up}");
}

#[test]
fn pixel_coding_is_lossless_and_shrinks_the_traffic() {
    let img = image("photo1.ron", 64, 60);
    let cfg = |coding| SimConfig {
        nodes: 4,
        node: NodeConfig { coding },
        ..SimConfig::default()
    };
    let raw = run(&img, cfg(PixelCoding::Raw));
    let rle = run(&img, cfg(PixelCoding::Rle));
    let delta = run(&img, cfg(PixelCoding::Delta));
    assert!(raw.frames[0] == rle.frames[0]);
    assert!(raw.frames[0] == delta.frames[0]);
    let up = |r: &SimReport| r.bus.iter().map(|b| b.up_bytes).sum::<u64>();
    assert!(up(&rle) * 3 < up(&raw) * 2, "{} vs {}", up(&rle), up(&raw));
    // Delta coding also shortens the shaded runs RLE leaves raw.
    assert!(
        up(&delta) * 4 < up(&rle) * 3,
        "{} vs {}",
        up(&delta),
        up(&rle)
    );
}

#[test]
fn animation_frames_are_identical_and_pipelined() {
    let a = image("photo1.ron", 64, 60);
    let b = image("reflections.ron", 64, 60);
    let scenes = [a.clone(), b.clone(), a.clone()];
    let r = simulate(
        &scenes,
        &SimConfig {
            nodes: 8,
            keep_frames: true,
            ..SimConfig::default()
        },
    )
    .expect("simulates");
    let (ra, rb) = (reference(&a), reference(&b));
    assert_eq!(r.frames.len(), 3);
    assert!(r.frames[0] == ra && r.frames[1] == rb && r.frames[2] == ra);
    assert!(r.frame_done_s.windows(2).all(|w| w[0] < w[1]));
}

#[test]
fn virtual_time_is_deterministic() {
    let img = image("photo1.ron", 64, 60);
    let cfg = SimConfig {
        nodes: 12,
        buses: 2,
        faults: Faults {
            up_every: 9,
            ..Faults::default()
        },
        ..SimConfig::default()
    };
    let a = run(&img, cfg.clone());
    // The same simulation on other host threads, concurrently.
    let others: Vec<SimReport> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..3).map(|_| s.spawn(|| run(&img, cfg.clone()))).collect();
        hs.into_iter().map(|h| h.join().expect("thread")).collect()
    });
    for b in others {
        assert_eq!(a.time_s, b.time_s);
        assert_eq!(a.bus, b.bus);
        assert_eq!(a.root, b.root);
        assert_eq!(a.node_compute_s, b.node_compute_s);
        assert!(a.frames == b.frames);
    }
}

#[test]
fn node_and_root_state_fit_the_mcu_budget() {
    use links_core::node::{run_node, NodeReport, RealTime, Tracing};
    use links_core::root::RootState;
    use links_host::cluster::exec::Clock;
    use links_host::cluster::star::{BusTiming, SimNodeLink, Star};
    use std::cell::RefCell;
    use std::rc::Rc;
    let clock = Rc::new(RefCell::new(Clock::default()));
    let star = Star::new(&clock, 1, 1, BusTiming::default(), Faults::default(), None);
    let mut link = SimNodeLink::new(&star, 0);
    let (mut a, mut b) = ([0u8; 16], [0u8; 16]);
    let mut report = NodeReport::default();
    let mut renderer = Tracing::<f32>::new();
    let mut clk = RealTime;
    let fut = run_node(
        NodeConfig::default(),
        &mut link,
        &mut clk,
        &mut renderer,
        [&mut a, &mut b],
        &mut report,
    );
    // The node's whole state besides its two scene banks (the future holds every buffer):
    // two TX banks, the RX buffer, the run being rendered and its coded form.
    let node = std::mem::size_of_val(&fut);
    assert!(node < 12 * 1024, "node state {node} bytes");
    // The RC's table for 256 nodes.
    let root = std::mem::size_of::<RootState>();
    assert!(root < 40 * 1024, "root state {root} bytes");
    println!("node future {node} B, root state {root} B");
}

/// CRC-valid but adversarial frames (random fields, wrong lengths, absurd offsets) and raw
/// garbage, fed straight into the node and root logic: they must neither panic nor hang.
mod hostile_bus {
    use super::*;
    use links_core::link::{Incoming, LinkError, NodeId, NodeLink, RootBus, Transfer};
    use links_core::node::{run_node, NodeReport, RealTime, Tracing};
    use links_core::root::{run_bus, NoClock, RootConfig, RootState};
    use links_core::wire::{Job, Region, SceneState, Up};
    use links_tests::Rng;
    use std::cell::RefCell;
    use std::future::Future;
    use std::pin::pin;
    use std::task::{Context, Waker};

    fn drive<F: Future>(f: F) {
        let mut f = pin!(f);
        let mut cx = Context::from_waker(Waker::noop());
        for _ in 0..100_000 {
            if f.as_mut().poll(&mut cx).is_ready() {
                return;
            }
        }
        panic!("did not finish");
    }

    fn small(r: &mut Rng, max: u64) -> u64 {
        r.next_u64() % max
    }

    fn region(r: &mut Rng) -> Region {
        if r.next_u64().is_multiple_of(2) {
            Region::Span {
                start: small(r, 5000) as u32,
                len: small(r, 800) as u32,
            }
        } else {
            Region::Rect {
                x: small(r, 80) as u16,
                y: small(r, 80) as u16,
                w: small(r, 80) as u16,
                h: small(r, 80) as u16,
            }
        }
    }

    fn down_frame(r: &mut Rng, img: &[u8], buf: &mut [u8]) -> usize {
        let crc = wire::CRC32.checksum(img);
        let data = [0xa5u8; SCENE_CHUNK + 2];
        let n = match r.next_u64() % 7 {
            0 => {
                let job = |r: &mut Rng| Job {
                    id: small(r, 40) as u32,
                    frame: small(r, 3) as u16,
                    region: region(r),
                };
                let jobs = [
                    Some(job(r)),
                    if r.next_u64().is_multiple_of(2) {
                        Some(job(r))
                    } else {
                        None
                    },
                ];
                wire::encode(0, small(r, 9) as u16, &Down::Work { jobs }, buf)
            }
            1 => {
                // A real chunk of the real scene (so some frames do get rendered).
                let c = small(r, img.len().div_ceil(SCENE_CHUNK) as u64) as usize;
                let end = (c * SCENE_CHUNK + SCENE_CHUNK).min(img.len());
                let m = Down::Scene {
                    frame: 0,
                    offset: (c * SCENE_CHUNK) as u32,
                    total: img.len() as u32,
                    crc,
                    data: &img[c * SCENE_CHUNK..end],
                };
                wire::encode(0, 0, &m, buf)
            }
            2 => {
                let len = small(r, SCENE_CHUNK as u64 + 2) as usize;
                let m = Down::Scene {
                    frame: small(r, 4) as u16,
                    offset: r.next_u64() as u32,
                    total: r.next_u64() as u32,
                    crc: r.next_u64() as u32,
                    data: &data[..len],
                };
                wire::encode(0, 0, &m, buf)
            }
            3 => {
                let m = Down::SceneEnd {
                    frame: small(r, 3) as u16,
                    len: if r.next_u64().is_multiple_of(2) {
                        img.len() as u32
                    } else {
                        r.next_u64() as u32
                    },
                    crc,
                };
                wire::encode(0, 0, &m, buf)
            }
            4 => {
                let n = small(r, 64) as usize;
                for b in &mut buf[..n] {
                    *b = r.next_u64() as u8;
                }
                Ok(n)
            }
            _ => {
                let job = Job {
                    id: 1000 + small(r, 1000) as u32,
                    frame: 0,
                    region: Region::Span {
                        start: small(r, 3000) as u32,
                        len: 1 + small(r, 600) as u32,
                    },
                };
                wire::encode(
                    0,
                    small(r, 50) as u16,
                    &Down::Work {
                        jobs: [Some(job), None],
                    },
                    buf,
                )
            }
        };
        n.unwrap_or(0)
    }

    struct ScriptedNodeLink {
        rng: Rng,
        img: Vec<u8>,
        left: u32,
        posted: bool,
    }

    impl NodeLink for ScriptedNodeLink {
        fn post(&mut self, _frame: &[u8]) -> Result<(), LinkError> {
            self.posted = true;
            Ok(())
        }
        async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
            if self.left == 0 {
                return Err(LinkError::Aborted);
            }
            self.left -= 1;
            let len = down_frame(&mut self.rng, &self.img, rx);
            if self.posted && self.rng.next_u64().is_multiple_of(2) {
                self.posted = false;
                Ok(Incoming::Exchanged { len })
            } else {
                Ok(Incoming::Broadcast { len })
            }
        }
    }

    #[test]
    fn a_node_survives_hostile_frames() {
        let img = image("reflections.ron", 32, 30);
        let (mut jobs, mut bad_jobs) = (0, 0);
        for seed in 1..=20u64 {
            let mut link = ScriptedNodeLink {
                rng: Rng(seed * 7919),
                img: img.clone(),
                left: 3000,
                posted: false,
            };
            let (mut a, mut b) = (vec![0u8; img.len()], vec![0u8; img.len() + 100]);
            let mut report = NodeReport::default();
            drive(run_node(
                NodeConfig::default(),
                &mut link,
                &mut RealTime,
                &mut Tracing::<f32>::new(),
                [&mut a, &mut b],
                &mut report,
            ));
            assert!(report.bad_messages > 0 && report.chunks > 0, "{report:?}");
            jobs += report.jobs;
            bad_jobs += report.bad_jobs;
        }
        // Some scenes completed and jobs were rendered; absurd regions were refused.
        assert!(jobs > 0 && bad_jobs > 0, "{jobs} {bad_jobs}");
    }

    struct HostileBus {
        rng: Rng,
        left: u32,
        tx: [u8; wire::MAX_MESSAGE],
        inflight: Option<Transfer>,
    }

    impl RootBus for HostileBus {
        fn nodes(&self) -> (NodeId, u16) {
            (0, 4)
        }
        fn ready(&self) -> Option<NodeId> {
            Some((self.rng.0 % 6) as NodeId) // sometimes a node that does not exist
        }
        async fn wait_ready(&mut self) -> NodeId {
            0
        }
        fn tx_bank(&mut self) -> &mut [u8] {
            &mut self.tx
        }
        fn start(&mut self, transfer: Transfer, _len: usize) -> Result<(), LinkError> {
            if self.inflight.is_some() {
                return Err(LinkError::Busy);
            }
            self.inflight = Some(transfer);
            Ok(())
        }
        async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
            match self.inflight.take() {
                None => Err(LinkError::Aborted),
                Some(Transfer::Broadcast) => {
                    self.rng.next_u64();
                    Ok(0)
                }
                Some(Transfer::Exchange(_)) => self.reply(rx),
            }
        }
    }

    impl HostileBus {
        fn reply(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
            if self.left == 0 {
                return Err(LinkError::Aborted);
            }
            self.left -= 1;
            let r = &mut self.rng;
            let rgb = [0x33u8; 3 * 600];
            let coded = [0x01u8, 2, 3, 4, 200, 5, 6, 7, 9];
            let msg = match r.next_u64() % 6 {
                0 => Up::Pixels {
                    job: small(r, 30) as u32,
                    frame: small(r, 2) as u16,
                    y: small(r, 40) as u16,
                    x: small(r, 40) as u16,
                    rgb: &rgb[..small(r, 1700) as usize],
                    done: r.next_u64().is_multiple_of(2),
                },
                1 => Up::PixelsRle {
                    job: small(r, 30) as u32,
                    frame: 0,
                    y: small(r, 40) as u16,
                    x: small(r, 40) as u16,
                    len: small(r, 70000) as u16,
                    data: &coded[..small(r, 10) as usize],
                    done: r.next_u64().is_multiple_of(2),
                },
                2 => Up::Status {
                    scene: SceneState::Ready {
                        frame: small(r, 3) as u16,
                    },
                },
                3 => Up::Status {
                    scene: SceneState::Missing {
                        frame: small(r, 3) as u16,
                        chunks: [r.next_u64() as u32, r.next_u64() as u32, 0, u32::MAX],
                        pieces: r.next_u64() as u16,
                    },
                },
                4 => Up::Poll,
                _ => {
                    let n = small(r, 40) as usize;
                    for b in &mut rx[..n] {
                        *b = r.next_u64() as u8;
                    }
                    return Ok(n);
                }
            };
            Ok(wire::encode(small(r, 4) as u16, 0, &msg, rx).unwrap_or(0))
        }
    }

    #[test]
    fn the_root_survives_hostile_frames() {
        let img = image("reflections.ron", 32, 30);
        for seed in 1..=20u64 {
            let cfg = RootConfig {
                policy: Policy::DECREASING,
                nodes: 4,
                frames: 2,
                timeout_us: 0,
                double_buffer: seed % 2 == 0,
            };
            let root =
                RefCell::new(RootState::new(cfg, &[img.clone(), img.clone()][..]).expect("valid"));
            let sink = RefCell::new(());
            let mut bus = HostileBus {
                rng: Rng(seed * 104729),
                left: 3000,
                tx: [0; wire::MAX_MESSAGE],
                inflight: None,
            };
            drive(async {
                let r = run_bus(
                    0,
                    &mut bus,
                    &NoClock,
                    &root,
                    &[img.clone(), img.clone()][..],
                    &sink,
                )
                .await;
                assert_eq!(
                    r.err(),
                    Some(links_core::root::RootError::Link(LinkError::Aborted))
                );
            });
            let rep = root.borrow().report();
            assert!(
                rep.bad_messages > 0 && rep.rejected > 0 && rep.accepted > 0,
                "{rep:?}"
            );
        }
    }
}

/// The DM stage: with a DM slower than the cluster, frames come out at the DM's pace; with
/// a fast one, only the start moves.
#[test]
fn a_slow_dm_sets_the_frame_interval_and_a_fast_one_changes_nothing() {
    use links_host::cluster::steady_state_interval;
    let img = image("photo1.ron", 64, 60);
    // The F407's firmware link (the default): the next frame's scene lands in the nodes'
    // lent banks while they render.
    let cfg = SimConfig {
        nodes: 8,
        ..SimConfig::default()
    };
    let render = steady_state_interval(&img, &cfg, 8).expect("simulates");
    let single = simulate_frame(&img, &cfg).expect("simulates").time_s;
    assert!(render > 0.0 && render < single, "{render} vs {single}");

    // Slow DM: twice the single-frame time, so frames never overlap. The interval is the
    // DM's to within a few bus bytes (job ids and sequence numbers are varints and grow).
    let dm = 2.0 * single;
    let slow = SimConfig {
        dm_s_per_frame: dm,
        ..cfg.clone()
    };
    let interval = steady_state_interval(&img, &slow, 8).expect("simulates");
    assert!((interval - dm).abs() < 1e-5, "{interval} vs DM {dm}");
    let scenes = [img.clone(), img.clone(), img.clone()];
    let r = simulate(
        &scenes,
        &SimConfig {
            keep_frames: true,
            ..slow.clone()
        },
    )
    .expect("simulates");
    let want = reference(&img);
    assert!(r.frames.iter().all(|f| *f == want));
    // Each frame starts when the DM delivers it and takes one single-frame time (to within
    // the few µs by which the protocol's exchange pattern differs from frame to frame).
    for (f, t) in r.frame_done_s.iter().enumerate() {
        let expect = (f + 1) as f64 * dm + single;
        assert!((t - expect).abs() < 1e-5, "frame {f}: {t} vs {expect}");
    }

    // Fast DM: a tenth of the interval; the whole run shifts by one DM time.
    let fast = SimConfig {
        dm_s_per_frame: render / 10.0,
        ..cfg.clone()
    };
    let interval = steady_state_interval(&img, &fast, 8).expect("simulates");
    // Not slower, and within 3%: the DM's delivery times move when the RC broadcasts the
    // next frame among this frame's exchanges. With a 116 KB image the broadcast filled the
    // bus and the two intervals were equal; photo1's 18 KB image at 64x60 leaves gaps, and a
    // fast DM's later broadcast lands in them (measured: 2.2% shorter with the edge-plane
    // kernel, whose shorter runs leave more of them; 1.4% before).
    assert!(
        interval <= render + 1e-9 && interval >= 0.97 * render,
        "{interval} vs {render}"
    );
    let t = simulate_frame(&img, &fast).expect("simulates").time_s;
    assert!((t - single - render / 10.0).abs() < 1e-9, "{t} vs {single}");
}

fn with_deaths(
    img: &[u8],
    nodes: u16,
    buses: u16,
    deaths: &[(u16, f64)],
    timeout: f64,
) -> SimReport {
    run(
        img,
        SimConfig {
            nodes,
            buses,
            node_timeout_s: timeout,
            deaths: deaths
                .iter()
                .map(|&(node, at_s)| NodeDeath { node, at_s })
                .collect(),
            ..SimConfig::default()
        },
    )
}

#[test]
fn work_of_a_node_that_dies_is_reissued() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let t0 = run(
        &img,
        SimConfig {
            nodes: 8,
            ..SimConfig::default()
        },
    )
    .time_s;
    let timeout = t0 / 4.0;
    // Mid-frame.
    let r = with_deaths(&img, 8, 1, &[(3, t0 / 2.0)], timeout);
    assert!(r.frames[0] == want);
    assert_eq!((r.root.timeouts, r.root.revived), (1, 0));
    assert!(r.root.reissued >= 1, "{:?}", r.root);
    assert!(
        r.time_s > t0 && r.time_s < t0 + 2.0 * timeout,
        "{} vs {t0}",
        r.time_s
    );
    assert_eq!(r.root.bad_messages, 0);
    // The last node, late in the frame, on the second of two buses (its `Wake` and the
    // re-issue cross buses).
    let r = with_deaths(&img, 8, 2, &[(7, 0.8 * t0)], timeout);
    assert!(r.frames[0] == want);
    assert_eq!((r.root.timeouts, r.root.revived), (1, 0));
    assert!(r.root.reissued >= 1, "{:?}", r.root);
    // All but one, at staggered times, on three buses.
    // Node 1 dies 1 µs in, during the scene broadcast; the others at staggered times.
    let deaths: Vec<(u16, f64)> = (1..6)
        .map(|n| {
            (
                n,
                if n == 1 {
                    1e-6
                } else {
                    t0 * (0.1 + 0.1 * n as f64)
                },
            )
        })
        .collect();
    let r = with_deaths(&img, 6, 3, &deaths, timeout);
    assert!(r.frames[0] == want);
    // Node 1 died during the scene broadcast, before it held a job: nothing to re-issue,
    // so it is never timed out. The other four held jobs.
    assert_eq!(r.node_reports[1].pixels, 0);
    assert_eq!((r.root.timeouts, r.root.revived), (4, 0));
    assert!(r.root.reissued >= 4, "{:?}", r.root);
    // The survivor rendered everything no one else finished: about 6x its share.
    assert!(r.time_s > 3.0 * t0, "{} vs {t0}", r.time_s);
    // Every node dead: the simulation reports the stall, nothing panics.
    let all: Vec<(u16, f64)> = (0..4).map(|n| (n, t0 / 2.0)).collect();
    let e = simulate_frame(
        &img,
        &SimConfig {
            nodes: 4,
            node_timeout_s: timeout,
            deaths: all
                .iter()
                .map(|&(node, at_s)| NodeDeath { node, at_s })
                .collect(),
            ..SimConfig::default()
        },
    );
    assert!(matches!(e, Err(SimError::Unfinished(_))), "{e:?}");
}

#[test]
fn a_death_during_an_animation_and_false_alarms_keep_every_frame_exact() {
    let a = image("photo1.ron", 64, 60);
    let b = image("reflections.ron", 64, 60);
    let scenes = [a.clone(), b.clone(), a.clone()];
    // The F407's firmware link (the default).
    let cfg = SimConfig {
        nodes: 8,
        keep_frames: true,
        ..SimConfig::default()
    };
    let t = simulate(&scenes, &cfg).expect("simulates").frame_done_s;
    let r = simulate(
        &scenes,
        &SimConfig {
            node_timeout_s: t[0] / 4.0,
            // In the middle of the last frame (node 2 holds jobs of it).
            deaths: vec![NodeDeath {
                node: 2,
                at_s: (t[1] + t[2]) / 2.0,
            }],
            ..cfg.clone()
        },
    )
    .expect("simulates");
    let (ra, rb) = (reference(&a), reference(&b));
    assert!(r.frames[0] == ra && r.frames[1] == rb && r.frames[2] == ra);
    assert_eq!((r.root.timeouts, r.root.revived), (1, 0));
    // A time-out far shorter than a run: live nodes are declared dead, speak again, and
    // the time-out doubles until the alarms stop. Work is lost, no pixel is wrong.
    let r = simulate(
        &scenes,
        &SimConfig {
            node_timeout_s: 1e-5,
            ..cfg
        },
    )
    .expect("simulates");
    assert!(r.frames[0] == ra && r.frames[1] == rb && r.frames[2] == ra);
    assert!(
        r.root.revived > 0 && r.root.revived == r.root.timeouts,
        "{:?}",
        r.root
    );
}

/// RC-side double buffering: the RC composes the next transfer and decodes the previous
/// one while a transfer is on the wire. Same frame either way; the single-buffered RC adds
/// its work to the bus's critical path, most visibly in the scene broadcast that every
/// node waits for (the RC encodes ~1 KB chunks, each while the previous one is on the wire).
#[test]
fn rc_double_buffering_hides_the_rcs_work_and_keeps_the_frame() {
    use links_core::root::RcWork;
    use links_host::cluster::rccost::RcCost;
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    // The idealised link: there the switch is the RC's buffering alone. On the firmware
    // link it chooses between two masters (split as rc-fw's, or clocking inside `finish`)
    // whose transfers also start at different times, so even a free RC's frame moves (by
    // 0.05% here).
    let cfg = |double, rc_cost| SimConfig {
        nodes: 16,
        rc_double_buffer: double,
        rc_cost,
        link: LinkModel::Ideal,
        ..SimConfig::default()
    };
    let double = run(&img, cfg(true, RcCost::CORTEX_M4F));
    let single = run(&img, cfg(false, RcCost::CORTEX_M4F));
    let free = run(&img, cfg(true, RcCost::FREE));
    let free_single = run(&img, cfg(false, RcCost::FREE));
    for r in [&double, &single, &free, &free_single] {
        assert!(r.frames[0] == want);
        assert_eq!(r.root.pixels, 64 * 60);
    }
    // An RC without CPU time: buffering changes nothing at all.
    assert_eq!(free.time_s, free_single.time_s);
    assert_eq!(free.bus, free_single.bus);
    assert_eq!(free.rc_busy_s, 0.0);
    assert!(free.time_s < double.time_s && double.time_s < single.time_s);
    // The broadcast's chunk encoding is hidden behind the wire when double-buffered, and
    // serial with it when not: the single-buffered frame is later by at least that.
    let chunks = img.len().div_ceil(SCENE_CHUNK);
    let mut buf = [0u8; wire::MAX_MESSAGE];
    let n = wire::encode(
        0,
        0,
        &Down::Scene {
            frame: 0,
            offset: 0,
            total: img.len() as u32,
            crc: 0,
            data: &img[..SCENE_CHUNK],
        },
        &mut buf,
    )
    .unwrap();
    let chunk_ps = RcCost::CORTEX_M4F.duration_ps(&RcWork::Encode { bytes: n }, false);
    let encode_s = chunks as f64 * chunk_ps as f64 * 1e-12;
    let gap = single.time_s - double.time_s;
    assert!(gap >= 0.9 * encode_s, "{gap} vs {encode_s}");
    // A chunk encodes faster than it crosses the wire, so double buffering hides it fully:
    // the double-buffered RC's broadcast costs what the free RC's does, to within the
    // encoding of the first chunk and the rest of the frame's per-transfer RC work.
    let wire_ps = SimConfig::default().timing.duration_ps(n, false);
    assert!(chunk_ps < wire_ps, "{chunk_ps} vs {wire_ps}");
    assert!(
        double.time_s - free.time_s < 0.5 * gap,
        "{} {} {}",
        free.time_s,
        double.time_s,
        single.time_s
    );
    // The RC did the same work either way (within the few transfers that differ).
    assert!((single.rc_busy_s - double.rc_busy_s).abs() < 0.05 * double.rc_busy_s);
    println!(
        "free {:.6} double {:.6} single {:.6} (RC busy {:.6} / {:.6} s, chunk encode {:.6} s)",
        free.time_s, double.time_s, single.time_s, double.rc_busy_s, single.rc_busy_s, encode_s
    );
}

/// Broadcasts of one frame's scene on a bus: its chunks and its `SceneEnd`.
fn scene_broadcasts(img: &[u8]) -> u64 {
    img.len().div_ceil(SCENE_CHUNK) as u64 + 1
}

/// A node off the bus for a whole scene broadcast (chunks and `SceneEnd`) never hears of
/// the scene. Alone, it must still be found and sent the scene point-to-point.
#[test]
fn a_node_that_missed_a_whole_scene_broadcast_is_sent_the_scene() {
    let img = image("photo1.ron", 64, 60);
    let chunks = img.len().div_ceil(SCENE_CHUNK);
    let r = run(
        &img,
        SimConfig {
            nodes: 1,
            node_timeout_s: 0.01,
            drops: vec![BroadcastDrop {
                node: 0,
                from: 0,
                to: scene_broadcasts(&img),
            }],
            ..SimConfig::default()
        },
    );
    assert!(r.frames[0] == reference(&img));
    assert_eq!(r.bus[0].dropped_broadcast, scene_broadcasts(&img));
    // Every chunk was re-sent to it, once.
    assert_eq!(r.root.repairs as usize, chunks);
    assert_eq!(r.node_reports[0].chunks as usize, chunks);
    assert_eq!(r.root.pixels, 64 * 60);
}

/// In an animation a node misses frame 0's scene and gets frame 1's: it must not be handed
/// frame-0 work it cannot do (its bank 0 is empty); it gets frame 0's scene or none of its
/// work, and every frame is exact.
#[test]
fn a_node_that_missed_one_frames_scene_gets_it_or_no_work_of_that_frame() {
    let a = image("photo1.ron", 64, 60);
    let b = image("reflections.ron", 64, 60);
    let scenes = [a.clone(), b.clone(), a.clone()];
    let cfg = SimConfig {
        nodes: 4,
        keep_frames: true,
        node_timeout_s: 0.1,
        ..SimConfig::default()
    };
    let clean = simulate(&scenes, &cfg).expect("simulates");
    assert_eq!(clean.root.timeouts, 0);
    for node in [0u16, 3] {
        let r = simulate(
            &scenes,
            &SimConfig {
                drops: vec![BroadcastDrop {
                    node,
                    from: 0,
                    to: scene_broadcasts(&a),
                }],
                ..cfg.clone()
            },
        )
        .unwrap_or_else(|e| panic!("node {node}: {e}"));
        let (ra, rb) = (reference(&a), reference(&b));
        assert!(r.frames[0] == ra && r.frames[1] == rb && r.frames[2] == ra);
        assert_eq!(r.bus[0].dropped_broadcast, scene_broadcasts(&a));
        // No node was declared dead: the node never held work it could not do.
        assert_eq!((r.root.timeouts, r.root.revived), (0, 0), "node {node}");
        assert_eq!(r.root.pixels, 3 * 64 * 60);
        // Not much later than without the loss (no time-out of a node holding work; at
        // most a roll call after one time-out and the repair).
        assert!(
            r.time_s < clean.time_s + 2.0 * cfg.node_timeout_s,
            "node {node}: {} vs {}",
            r.time_s,
            clean.time_s
        );
    }
}

/// A node idle when the RC broadcasts `Wake` (a node died holding work) misses it: the RC
/// must call again, or the dead node's work waits forever. Static split on two nodes: node
/// 0 renders its half and falls silent; node 1 dies early in its half and is declared dead
/// (the time-out is longer than node 0's half) only after node 0 went idle.
#[test]
fn a_node_that_missed_a_wake_broadcast_is_woken_again() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let cfg = SimConfig {
        nodes: 2,
        policy: Policy::Static { shape: Split::Span },
        ..SimConfig::default()
    };
    let clean = run(&img, cfg.clone());
    let t0 = clean.time_s;
    let r = run(
        &img,
        SimConfig {
            node_timeout_s: t0,
            deaths: vec![NodeDeath {
                node: 1,
                at_s: 0.2 * t0,
            }],
            // Node 0 hears the scene, and loses the next broadcast: the first `Wake`.
            drops: vec![BroadcastDrop {
                node: 0,
                from: scene_broadcasts(&img),
                to: scene_broadcasts(&img) + 1,
            }],
            ..cfg
        },
    );
    assert!(r.frames[0] == want);
    assert_eq!((r.root.timeouts, r.root.revived), (1, 0));
    assert_eq!(r.root.reissued, 1, "{:?}", r.root);
    // The first Wake was lost, and at least one more went out.
    let wakes = r.root.broadcasts as u64 - scene_broadcasts(&img);
    assert!(wakes >= 2, "{wakes} Wake broadcasts");
    assert_eq!(r.bus[0].dropped_broadcast, 1);
    // Node 0 rendered the whole frame: its half, then node 1's again.
    assert_eq!(r.node_reports[0].pixels, 64 * 60);
    assert!(r.time_s < 5.0 * t0, "{} vs {t0}", r.time_s);
}

/// photo2 (the paper's Table 5.2 scene) runs on the cluster since its SceneImage fits a node
/// bank: on 1, 16 and 64 nodes every frame equals the host render bit for bit.
#[test]
fn photo2_renders_on_16_and_64_nodes_as_on_one() {
    let img = image("photo2.ron", 96, 90);
    assert!(img.len() <= nc_fw::plan::SCENE_EVEN, "{} bytes", img.len());
    let want = reference(&img);
    for nodes in [1, 16, 64] {
        let r = run(
            &img,
            SimConfig {
                nodes,
                ..SimConfig::default()
            },
        );
        assert!(r.frames[0] == want, "{nodes} nodes");
    }
}

/// The board profile sets the link the star charges: the same frame on both, and the F407's
/// slower link (21 MHz, 23 us of chip-select set-up and hold, 9 bytes of header and trailer)
/// makes every transfer and the frame longer than the idealised link's. Both RCs overlap
/// the wire with their work (the F407's bus task runs on an interrupt executor).
#[test]
fn the_board_profile_sets_the_links_cost_and_keeps_the_frame() {
    let img = image("photo1.ron", 64, 60);
    let cfg = |b| SimConfig {
        nodes: 16,
        ..SimConfig::for_board(b)
    };
    let f407 = run(&img, cfg(BoardProfile::F407));
    let ideal = run(&img, cfg(BoardProfile::IDEAL));
    assert!(f407.frames[0] == ideal.frames[0]);
    assert!(cfg(BoardProfile::F407).rc_double_buffer && cfg(BoardProfile::IDEAL).rc_double_buffer);
    let (bf, bi) = (&f407.bus[0], &ideal.bus[0]);
    // Both broadcast the same scene: its chunks, its end and the stop.
    assert_eq!(bf.broadcasts, bi.broadcasts);
    // Busy time of the bus: 23 us + 8 bits / 21 MHz per clocked byte on the F407.
    let want_ps = bf.exchanges as f64 * 23e6
        + bf.broadcasts as f64 * 23e6
        + bf.clocked_bytes as f64 * 8.0 * 1e12 / 21e6;
    let got = bf.busy_ps as f64;
    assert!(
        (got - want_ps).abs() <= (bf.exchanges + bf.broadcasts) as f64,
        "{got} vs {want_ps}"
    );
    assert!(
        f407.time_s > ideal.time_s,
        "{} vs {}",
        f407.time_s,
        ideal.time_s
    );
    assert!(
        bf.busy_ps > 2 * bi.busy_ps,
        "{} vs {}",
        bf.busy_ps,
        bi.busy_ps
    );
}

/// The timeline of a cluster frame: a row's intervals never overlap, each node's compute sums
/// to what the simulator reports, every bus transfer is counted, and the map names exactly
/// one node for every pixel (rendered once).
#[test]
fn the_timeline_accounts_for_every_node_transfer_and_pixel() {
    use links_host::cluster::timeline::{Interval, NO_NODE};
    let img = image("photo1.ron", 64, 60);
    for board in [BoardProfile::F407, BoardProfile::IDEAL] {
        let r = run(
            &img,
            SimConfig {
                nodes: 8,
                buses: 2,
                timeline: Some(1_000_000),
                ..SimConfig::for_board(board)
            },
        );
        let t = r.timeline.as_ref().expect("a timeline was asked for");
        assert!(t.complete());
        let apart = |row: &[Interval]| row.windows(2).all(|w| w[0].end <= w[1].start);
        for (n, row) in t.compute.iter().enumerate() {
            assert!(
                apart(row) && row.iter().all(|i| i.start < i.end),
                "node {n}"
            );
            let secs = t.compute_ps(n) as f64 * 1e-12;
            assert_eq!(secs, r.node_compute_s[n], "node {n}");
            assert!(apart(&t.exchanges[n]), "node {n}'s exchanges");
        }
        assert!(apart(&t.rc));
        let rc_ps: u64 = t.rc.iter().map(Interval::len).sum();
        assert_eq!(rc_ps as f64 * 1e-12, r.rc_busy_s);
        for (b, row) in t.bus.iter().enumerate() {
            let spans: Vec<Interval> = row.iter().map(|x| x.at).collect();
            assert!(apart(&spans), "bus {b}");
            let c = &r.bus[b];
            assert_eq!(row.len() as u64, c.exchanges + c.broadcasts, "bus {b}");
            let busy: u64 = spans.iter().map(Interval::len).sum();
            assert_eq!(busy, c.busy_ps, "bus {b}");
        }
        let per_node: usize = t.exchanges.iter().map(Vec::len).sum();
        assert_eq!(
            per_node as u64,
            r.bus.iter().map(|c| c.exchanges).sum::<u64>()
        );
        assert_eq!((t.width, t.height), (64, 60));
        assert!(t.owner.iter().all(|&o| o != NO_NODE && o < 8));
        assert!(t.renders.iter().all(|&k| k == 1));
        // Each node's pixels in the map are the pixels it reports.
        for (n, rep) in r.node_reports.iter().enumerate() {
            let mine = t.owner.iter().filter(|&&o| o == n as u16).count() as u64;
            assert_eq!(mine, rep.pixels, "node {n}");
        }
    }
}

/// Under two levels of the firmware's relays the timeline has a row for each root link and
/// each middle relay's bus: each row's transfers apart in time, the root links' rows
/// accounting for every transfer and all the busy time of their links.
#[test]
fn the_timeline_draws_every_link_between_rcs() {
    use links_host::cluster::relay::RelayCode;
    use links_host::cluster::timeline::Interval;
    let img = image("photo1.ron", 64, 60);
    let r = run(
        &img,
        SimConfig {
            relay: RelayCode::Firmware,
            timeline: Some(1_000_000),
            ..SimConfig::buildable(BoardProfile::F407, 256)
        },
    );
    let t = r.timeline.as_ref().expect("a timeline was asked for");
    assert!(t.complete());
    let tree = r.tree.as_ref().expect("a relay tree");
    // The root on two links; 8 middle relays of 4 leaf relays.
    assert_eq!((t.root_links.len(), t.mid_links.len()), (2, 8));
    assert_eq!(tree.links.len(), 2);
    let apart = |row: &[Interval]| row.windows(2).all(|w| w[0].end <= w[1].start);
    for (k, row) in t.root_links.iter().enumerate() {
        let spans: Vec<Interval> = row.iter().map(|x| x.at).collect();
        assert!(apart(&spans), "root link {k}");
        let c = &tree.links[k];
        assert_eq!(
            row.len() as u64,
            c.exchanges + c.broadcasts,
            "root link {k}"
        );
        let busy: u64 = spans.iter().map(Interval::len).sum();
        assert_eq!(busy, c.busy_ps, "root link {k}");
        // Its relays are the middle relays on it (4 a link).
        assert!(
            row.iter().flat_map(|x| x.node).all(|m| m < 8),
            "root link {k}"
        );
    }
    for (m, row) in t.mid_links.iter().enumerate() {
        let spans: Vec<Interval> = row.iter().map(|x| x.at).collect();
        assert!(apart(&spans), "middle relay {m}");
        assert!(
            row.iter().any(|x| x.node.is_some()),
            "middle relay {m} exchanged"
        );
        assert!(
            row.iter().any(|x| x.node.is_none()),
            "middle relay {m} broadcast"
        );
        // Its "nodes" are its leaf relays, numbered over all of them.
        assert!(row.iter().flat_map(|x| x.node).all(|l| l / 4 == m as u16));
    }
    // The leaf relays' buses are the bus rows.
    assert_eq!(t.bus.len(), 32);
}

/// `links render --nodes N --precision fixed` writes the host's fixed-point PNG byte for
/// byte, on the F407 (asked), the F207 and the G0B1 (their default); f32 on f32-less F207
/// nodes and an f64 cluster are refused with one line each.
#[test]
fn the_cli_renders_fixed_point_on_the_cluster_as_the_host_does() {
    let dir = std::env::temp_dir().join(format!("links-fixed-nodes-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let at = |name: &str| format!("{}/{name}", dir.display());
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
    let scene = scene.to_str().unwrap();
    let render = |args: &[&str], out: &str| {
        let mut argv = vec!["links", "render", scene, "--width", "40", "--height", "30"];
        argv.extend_from_slice(args);
        argv.extend_from_slice(&["-o", out, "--quiet"]);
        links_host::cli::run_from(argv).map_err(|e| e.to_string())
    };
    let read = |p: &str| std::fs::read(p).unwrap_or_else(|e| panic!("{p}: {e}"));
    render(&["--precision", "fixed"], &at("host.png")).unwrap();
    render(&["--precision", "f32"], &at("host-f32.png")).unwrap();
    render(&["--nodes", "3", "--precision", "fixed"], &at("f407.png")).unwrap();
    render(&["--nodes", "8", "--board", "f207"], &at("f207.png")).unwrap();
    render(&["--nodes", "4", "--board", "g0b1"], &at("g0b1.png")).unwrap();
    let host = read(&at("host.png"));
    assert!(read(&at("f407.png")) == host, "f407 nodes in Q16.16");
    assert!(read(&at("f207.png")) == host, "f207 nodes");
    assert!(read(&at("g0b1.png")) == host, "g0b1 nodes");
    assert!(read(&at("host-f32.png")) != host);
    let e = render(
        &["--nodes", "2", "--board", "f207", "--precision", "f32"],
        &at("x.png"),
    )
    .unwrap_err();
    assert!(e.contains("f32") && e.contains("Q16.16 kernel only"), "{e}");
    let e = render(&["--nodes", "2", "--precision", "f64"], &at("x.png")).unwrap_err();
    assert!(e.contains("f32 or Q16.16"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
