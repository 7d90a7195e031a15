//! Reliability (docs/reliability.md): a node killed at any moment under every policy, the
//! recovery bound, time-outs that false alarms cannot stretch, errors that name their cause.
//! Every number is virtual time; every frame is compared with the single-node render.

use links_core::board::{BoardProfile, NodeBoard};
use links_core::image::SceneView;
use links_core::render::{render_run, Tracer};
use links_core::sched::{Policy, Split};
use links_host::cluster::star::{BroadcastDrop, BusCounters, Faults, NodeDeath, Noise};
use links_host::cluster::{simulate_frame, RunCache, SimConfig, SimReport};
use links_host::cost::{CycleModel, DEFAULT_CLOCK_HZ};

use links_tests::{bundled_image as image, host_reference as reference};

fn run(img: &[u8], cfg: &SimConfig) -> SimReport {
    let cfg = SimConfig {
        keep_frames: true,
        ..cfg.clone()
    };
    simulate_frame(img, &cfg).unwrap_or_else(|e| panic!("{cfg:?}: {e}"))
}

fn killed(cfg: &SimConfig, node: u16, at_s: f64) -> SimConfig {
    SimConfig {
        deaths: vec![NodeDeath { node, at_s }],
        ..cfg.clone()
    }
}

/// The longest a node computes for one scanline (s): no run is longer than a row, so no live
/// node is silent for much longer than this (plus waiting for the bus).
fn longest_row_s(img: &[u8]) -> f64 {
    let view = SceneView::new(img).expect("valid");
    let f = view.camera::<f32>();
    let mut px = vec![[0u8; 3]; f.width as usize];
    (0..f.height)
        .map(|y| {
            let mut t = Tracer::<f32>::new(view);
            render_run(&mut t, y, 0, &mut px).expect("renders");
            CycleModel::default().cycles(&t.stats) as f64 / DEFAULT_CLOCK_HZ
        })
        .fold(0.0, f64::max)
}

/// The recovery bound of docs/reliability.md: one node killed at any moment costs at most
/// two time-outs (the one in force) plus that node's whole work in the fault-free frame.
fn bound_s(clean: &SimReport, timeout_s: f64, node: u16) -> f64 {
    clean.time_s + 2.0 * timeout_s + clean.node_compute_s[node as usize]
}

/// Under the static policy a node that dies before it takes its region
/// (here during the scene broadcast) never asks for it, holds nothing and so was never timed
/// out: the frame never finished ("passed its time limit").
#[test]
fn a_static_region_of_a_node_that_died_before_taking_it_is_reissued() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    for nodes in [2u16, 8] {
        let cfg = SimConfig {
            nodes,
            policy: Policy::Static { shape: Split::Rect },
            node_timeout_s: 0.05,
            ..SimConfig::default()
        };
        let clean = run(&img, &cfg);
        let dead = nodes - 1;
        // The broadcast of the 116 KB scene takes about 25 ms: the node hears part of it.
        let r = run(&img, &killed(&cfg, dead, 0.002));
        assert!(r.frames[0] == want, "{nodes} nodes");
        assert_eq!(r.node_reports[dead as usize].pixels, 0);
        assert_eq!((r.root.timeouts, r.root.revived), (1, 0), "{:?}", r.root);
        assert_eq!(r.root.reissued, 1, "{:?}", r.root);
        let bound = bound_s(&clean, cfg.node_timeout_s, dead);
        assert!(
            r.time_s <= bound,
            "{nodes} nodes: {} s > bound {bound} s",
            r.time_s
        );
    }
}

/// A time-out far shorter than a run gives bursts of false alarms (every
/// node silent for its first run is declared dead, then speaks again). The time-out doubled
/// on each one, without a cap, so one real death afterwards stalled the frame for
/// `2^alarms` time-outs. Now the time-out in force never exceeds twice the longest silence
/// of a node that spoke again, so the recovery stays bounded.
#[test]
fn false_alarms_do_not_stretch_the_recovery_from_a_real_death() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let cfg = SimConfig {
        nodes: 16,
        node_timeout_s: 1e-4,
        cache: Some(RunCache::new()),
        ..SimConfig::default()
    };
    let alarms = run(&img, &cfg);
    assert!(alarms.frames[0] == want);
    assert!(alarms.root.revived >= 4, "{:?}", alarms.root);
    // No live node is silent much longer than its longest run: 2 ms covers the bus.
    let silence = longest_row_s(&img) + 2e-3;
    let timeout = cfg.node_timeout_s.max(2.0 * silence);
    for at in [0.3, 0.5, 0.7] {
        let r = run(&img, &killed(&cfg, 3, at * alarms.time_s));
        assert!(r.frames[0] == want);
        let bound = bound_s(&alarms, timeout, 3);
        assert!(
            r.time_s <= bound,
            "killed at {at}: {} s > bound {bound} s ({:?})",
            r.time_s,
            r.root
        );
    }
}

/// A scene larger than a node's scene bank was refused only by the RC, as
/// "frame 0 has no usable scene image". The refusal now comes before the cluster starts and
/// names the image size and the bank (the board's, `nc_fw::plan::SCENE_EVEN`).
#[test]
fn a_scene_larger_than_a_node_bank_is_refused_naming_both_sizes() {
    // A board whose banks are smaller than reflections' small image (the bundled scenes all
    // fit one bank of the F407 once compact, so none of them is too big for long).
    let board = NodeBoard {
        name: "tiny",
        scene_banks: [1024, 512],
        ..NodeBoard::F407
    };
    let img = image("reflections.ron", 64, 60);
    assert!(img.len() > board.largest_bank());
    let e = simulate_frame(
        &img,
        &SimConfig {
            nodes: 4,
            board,
            ..SimConfig::default()
        },
    )
    .expect_err("too big")
    .to_string();
    assert_eq!(
        e,
        format!(
            "frame 0's scene image is {} bytes; the tiny node's scene bank holds 1024 bytes: \
             make the scene smaller (fewer triangles, a smaller texture)",
            img.len()
        )
    );
    assert_eq!(SimConfig::default().board, nc_fw::plan::BOARD);
}

/// A cluster that cannot finish said only "passed its time limit". The
/// error now names the sub-screens never returned, the nodes holding them, and the nodes
/// that never had the scene.
#[test]
fn a_cluster_that_cannot_finish_names_the_nodes_and_what_they_lacked() {
    let img = image("photo1.ron", 64, 60);
    // Every node dies mid-frame: their sub-screens are never returned.
    let cfg = SimConfig {
        nodes: 4,
        node_timeout_s: 0.05,
        deaths: (0..4).map(|node| NodeDeath { node, at_s: 0.1 }).collect(),
        ..SimConfig::default()
    };
    let e = simulate_frame(&img, &cfg)
        .expect_err("cannot finish")
        .to_string();
    println!("{e}");
    assert!(e.contains("frame 0"), "{e}");
    assert!(e.contains("never returned"), "{e}");
    // Every node holding a sub-screen never returned is named and declared dead (which
    // nodes held one when they died depends on the node kernel's speed: a node that had
    // finished its jobs owes nothing and is never declared dead); every death is named.
    let holders: Vec<&str> = e
        .split("held by node ")
        .skip(1)
        .filter_map(|t| t.split_whitespace().next())
        .collect();
    assert!(!holders.is_empty(), "{e}");
    let dead = e
        .split("; nodes ")
        .nth(1)
        .and_then(|t| t.split(" declared dead").next())
        .unwrap_or_default();
    for h in holders {
        assert!(
            dead.split(", ").any(|d| d == h),
            "node {h} not declared dead: {e}"
        );
    }
    for n in 0..4 {
        assert!(e.contains(&format!("node {n} killed at 0.100 s")), "{e}");
    }
    // Node 1 dies at once; node 0 lives but hears no broadcast at all, so it never gets the
    // scene, and no roll call reaches it.
    let cfg = SimConfig {
        nodes: 2,
        node_timeout_s: 0.05,
        deaths: vec![NodeDeath { node: 1, at_s: 0.0 }],
        drops: vec![BroadcastDrop {
            node: 0,
            from: 0,
            to: u64::MAX,
        }],
        ..SimConfig::default()
    };
    let e = simulate_frame(&img, &cfg)
        .expect_err("cannot finish")
        .to_string();
    println!("{e}");
    assert!(e.contains("node 0 never reported frame 0's scene"), "{e}");
    assert!(e.contains("node 1 killed at 0.000 s"), "{e}");
}

/// The acceptance sweep: for every policy, one node killed at moments across the whole frame
/// (during the scene broadcast, before and after it takes work, mid-job, after its last job)
/// finishes within the bound, bit-identical to the single-node render.
#[test]
fn one_node_killed_at_any_moment_finishes_within_the_bound_under_every_policy() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let policies = [
        Policy::DECREASING,
        Policy::Static { shape: Split::Rect },
        Policy::Fixed {
            divisions: 48,
            shape: Split::Span,
        },
        Policy::Fixed {
            divisions: 48,
            shape: Split::Rect,
        },
    ];
    let cache = RunCache::new();
    let mut worst: f64 = 0.0;
    for policy in policies {
        for (nodes, buses, dead) in [(8u16, 1u16, 3u16), (5, 2, 4)] {
            let cfg = SimConfig {
                nodes,
                buses,
                policy,
                node_timeout_s: 0.05,
                cache: Some(cache.clone()),
                ..SimConfig::default()
            };
            let clean = run(&img, &cfg);
            assert_eq!(clean.root.timeouts, 0);
            for i in 0..=20 {
                let at = clean.time_s * i as f64 / 20.0;
                let r = run(&img, &killed(&cfg, dead, at));
                assert!(
                    r.frames[0] == want,
                    "{policy:?} {nodes} nodes, node {dead} killed at {at}"
                );
                let bound = bound_s(&clean, cfg.node_timeout_s, dead);
                let extra = (r.time_s - clean.time_s) / (bound - clean.time_s);
                worst = worst.max(extra);
                assert!(
                    r.time_s <= bound,
                    "{policy:?} {nodes} nodes, node {dead} killed at {at}: {} s > bound {bound} s ({:?})",
                    r.time_s,
                    r.root
                );
            }
        }
    }
    println!(
        "worst delay: {:.0}% of the bound's allowance",
        100.0 * worst
    );
}

/// Acceptance: bit errors at a rate of 1e-3 in both directions, and a quarter of
/// the nodes killed in the middle of that noisy frame: every frame bit-identical to the
/// single-node render, within the recovery bound. Photo1's 116 KB scene gets through the
/// broadcast to no node (a 1 KB chunk survives with probability 2.4e-4), so its frame is
/// mostly scene repair, in pieces (the killed nodes die before they get the scene and hold
/// no work); reflections' 1.5 KB scene leaves the frame to rendering, so its killed nodes
/// die holding jobs that are re-issued. The cost is bounded here and reported in
/// docs/reliability.md.
#[test]
fn bit_errors_of_1e_3_both_ways_and_a_quarter_of_the_nodes_killed_keep_the_frame_exact() {
    let cases = [
        (BoardProfile::IDEAL, "photo1.ron", 20.0),
        (BoardProfile::IDEAL, "reflections.ron", 4.0),
        (BoardProfile::F407, "photo1.ron", 20.0),
        (BoardProfile::F407, "reflections.ron", 4.0),
    ];
    for (board, scene, max_cost) in cases {
        let img = image(scene, 64, 60);
        let want = reference(&img);
        let cfg = SimConfig {
            nodes: 8,
            node_timeout_s: 0.05,
            cache: Some(RunCache::new()),
            ..SimConfig::for_board(board)
        };
        let clean = run(&img, &cfg);
        for seed in [1, 2, 3] {
            let noisy_cfg = SimConfig {
                noise: Noise {
                    ber_down: 1e-3,
                    ber_up: 1e-3,
                    drop_broadcast: 0.0,
                    seed,
                },
                ..cfg.clone()
            };
            let noisy = run(&img, &noisy_cfg);
            assert!(noisy.frames[0] == want, "{scene} seed {seed}");
            let sum = |f: fn(&BusCounters) -> u64| noisy.bus.iter().map(f).sum::<u64>();
            let (up, down, bcast) = (
                sum(|b| b.corrupted_up),
                sum(|b| b.corrupted_down),
                sum(|b| b.corrupted_broadcast),
            );
            assert!(
                up > 50 && down > 50 && bcast > 0,
                "{scene} seed {seed}: {up} {down}"
            );
            // The RC catches every corrupted node frame, once: on the idealised star each
            // corrupted frame is one; on the firmware link every clocked byte is exposed
            // (padding and trailer too), and what the root sees as bad is each NAKed frame
            // and each refused node header.
            let caught = match noisy.link {
                None => up,
                Some(l) => l.naks + l.rc_bad_headers,
            };
            assert_eq!(
                noisy.root.bad_messages as u64, caught,
                "{scene} seed {seed}"
            );
            // What it costs (virtual time), bounded: 1 KB scene chunks alone would have
            // taken photo1 hundreds of seconds.
            let cost = noisy.time_s / clean.time_s;
            assert!(cost < max_cost, "{scene} seed {seed}: {cost}");
            // A quarter of the nodes (2 of 8) killed in the middle of the noisy frame.
            let mid = noisy.time_s / 2.0;
            let killed = [1u16, 5];
            let r = run(
                &img,
                &SimConfig {
                    deaths: killed
                        .iter()
                        .map(|&node| NodeDeath { node, at_s: mid })
                        .collect(),
                    ..noisy_cfg.clone()
                },
            );
            assert!(r.frames[0] == want, "{scene} seed {seed}, 2 of 8 killed");
            if scene == "reflections.ron" && board == BoardProfile::IDEAL {
                // At least one of them held jobs when it died (the other may just have
                // finished its last one). On the idealised link's timing; on the F407's
                // both may die idle at mid-frame (seed 2 does), which the bound covers too.
                assert!(r.root.timeouts >= 1, "{scene} seed {seed}: {:?}", r.root);
                assert!(r.root.reissued >= 1, "{scene} seed {seed}: {:?}", r.root);
            }
            let work: f64 = killed
                .iter()
                .map(|&n| noisy.node_compute_s[n as usize])
                .sum();
            let bound = noisy.time_s + 2.0 * r.root.timeout_us as f64 * 1e-6 + work;
            assert!(
                r.time_s <= bound,
                "{scene} seed {seed}: {} s > {bound} s ({:?})",
                r.time_s,
                r.root
            );
            println!(
                "{scene} seed {seed}: fault-free {:.4} s; bit errors 1e-3 both ways {:.4} s ({cost:.2}x; {up} up / {down} down / {bcast} broadcast messages corrupted, {} scene repairs); and nodes 1, 5 killed at {mid:.4} s: {:.4} s ({:.2}x; {} declared dead, {} re-issued)",
                clean.time_s,
                noisy.time_s,
                noisy.root.repairs,
                r.time_s,
                r.time_s / clean.time_s,
                r.root.timeouts,
                r.root.reissued,
            );
        }
    }
}

/// A job list lost on its way to an idle node (the RC's reply to the `Poll` with which the
/// node answered a roll call, corrupted) left the node silent with nothing to do while the RC
/// believed it was rendering the adopted job: a time-out later it was declared dead, the job
/// re-issued again and the time-out raised (seen as a false alarm with bit errors and
/// deaths). A node whose exchange brought an unreadable reply now asks again.
#[test]
fn an_idle_node_that_lost_its_job_list_asks_again() {
    let img = image("reflections.ron", 64, 60);
    let want = reference(&img);
    let mut lost = 0;
    for seed in 1..=8 {
        let r = run(
            &img,
            &SimConfig {
                nodes: 4,
                policy: Policy::Static { shape: Split::Span },
                node_timeout_s: 0.02,
                // Node 3 dies at once: its region is adopted by an idle node after a roll
                // call, through exchanges that lose half the RC's replies.
                deaths: vec![NodeDeath { node: 3, at_s: 0.0 }],
                faults: Faults {
                    down_every: 2,
                    random: Some(seed),
                    ..Faults::default()
                },
                ..SimConfig::default()
            },
        );
        assert!(r.frames[0] == want);
        lost += r.bus.iter().map(|b| b.corrupted_down).sum::<u64>();
        assert_eq!(
            (r.root.timeouts, r.root.revived),
            (1, 0),
            "seed {seed}: {:?}",
            r.root
        );
    }
    assert!(lost > 50, "{lost}");
}

/// Broadcast copies lost at random (a receiver off the bus for one broadcast): lost scene
/// chunks are repaired, lost `Wake`s repeated, the frame exact, for every policy.
#[test]
fn lost_broadcasts_are_repaired_under_every_policy() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    for policy in [
        Policy::DECREASING,
        Policy::Static { shape: Split::Rect },
        Policy::Fixed {
            divisions: 48,
            shape: Split::Span,
        },
    ] {
        let cfg = SimConfig {
            nodes: 6,
            policy,
            node_timeout_s: 0.05,
            noise: Noise {
                drop_broadcast: 0.3,
                seed: 5,
                ..Noise::default()
            },
            deaths: vec![NodeDeath {
                node: 2,
                at_s: 0.06,
            }],
            ..SimConfig::default()
        };
        let r = run(&img, &cfg);
        assert!(r.frames[0] == want, "{policy:?}");
        let dropped: u64 = r.bus.iter().map(|b| b.dropped_broadcast).sum();
        // photo1's image at 64x60 is 19 chunks, to 6 nodes: about 34 drops at 0.3.
        assert!(dropped > 20, "{policy:?}: {dropped}");
        assert!(r.root.repairs > 10, "{policy:?}: {:?}", r.root);
    }
}
