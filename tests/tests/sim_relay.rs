//! The cluster simulation with the firmware's relay code in the loop (`--relay firmware`,
//! `SimConfig::relay`): the root's `run_bus` over `links_core::relay::RelayedBus` on an
//! emulated SPI link to its relays, each relay's `run_relay` between a slave link on it and
//! the split master of its own bus, the nodes on the relays' buses, all on the firmware
//! link in virtual time. Frames bit-identical to the single-node render; a relay that stops
//! answering and bit errors on the root's link cost time, never the frame; what the firmware
//! root cannot drive is refused with the reason.

use links_core::board::BoardProfile;
use links_core::sched::{Policy, Split};
use links_host::cluster::relay::{RelayCode, Topology};
use links_host::cluster::spi_bus::LinkModel;
use links_host::cluster::star::{NodeDeath, Noise};
use links_host::cluster::{simulate, simulate_frame, SimConfig, SimReport};
use links_tests::{bundled_image as image, host_reference as reference};

fn run(img: &[u8], cfg: SimConfig) -> SimReport {
    let cfg = SimConfig {
        keep_frames: true,
        ..cfg
    };
    simulate_frame(img, &cfg).unwrap_or_else(|e| panic!("{cfg:?}: {e}"))
}

/// `nodes` nodes on the F407 as built (a relay tree past 8), the firmware's relay code.
fn firmware(nodes: u16) -> SimConfig {
    SimConfig {
        relay: RelayCode::Firmware,
        ..SimConfig::buildable(BoardProfile::F407, nodes)
    }
}

/// What every clean run through the firmware's relays shows.
fn check_clean(what: &str, r: &SimReport, relays: usize) {
    let f = r.relayed.as_ref().expect("the firmware's relay code ran");
    assert_eq!(f.relays.len(), relays, "{what}");
    assert!(
        f.relays.iter().all(Option::is_some),
        "{what}: every relay passed the Stop on"
    );
    let routed: u32 = f.relays.iter().flatten().map(|r| r.routed).sum();
    // Every exchange the root made with a node was clocked by a relay on its bus.
    assert_eq!(routed, r.root.exchanges, "{what}");
    let leaf: u64 = r.bus.iter().map(|b| b.exchanges).sum();
    assert_eq!(leaf, r.root.exchanges as u64, "{what}");
    for rep in f.relays.iter().flatten() {
        // Every root broadcast reached each relay's bus once, and the final Stop.
        assert_eq!(
            rep.forwarded,
            r.root.broadcasts + 1,
            "{what}: {:?} {:?}",
            r.link,
            f.relays
        );
        assert_eq!(rep.bad_frames, 0, "{what}");
    }
    assert_eq!((f.root.timeouts, f.root.bad_batches), (0, 0), "{what}");
    assert_eq!(r.root.bad_messages, 0, "{what}");
    let link = r.link.expect("the firmware link ran");
    assert!(!link.any(), "{what}: {link:?}");
    // A node exchange's request goes down in one exchange on the root's link and the
    // node's frame comes up in a later one, which may carry the next request down: at
    // least one link exchange per node exchange (a relay sends one node frame up per
    // batch). Several are in flight at once (one relay's, and every relay's).
    assert!(
        f.root.link_exchanges >= r.root.exchanges,
        "{what}: {:?}",
        f.root
    );
    let most = f.root.most_in_flight as usize;
    assert!(
        most >= relays.min(2) && most <= links_core::relay::SLOTS,
        "{what}: {:?}",
        f.root
    );
    let tree = r.tree.as_ref().expect("the root link's report");
    let roots = tree.shape.roots as usize;
    let on_links: u64 = tree.links[..roots].iter().map(|l| l.exchanges).sum();
    assert_eq!(on_links, f.root.link_exchanges as u64, "{what}");
    assert_eq!(on_links, f.link.exchanges, "{what}");
    if roots == 2 {
        // Both root links carried exchanges (each has relays).
        assert!(tree.links[..2].iter().all(|l| l.exchanges > 0), "{what}");
    }
    assert!(tree.root_busy_s > 0.0 && r.rc_busy_s > 0.0, "{what}");
}

#[test]
fn the_firmware_relay_code_renders_the_single_node_frame() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let policies = [Policy::DECREASING, Policy::Static { shape: Split::Rect }];
    // The F407's root drives its relays on two links (SPI1, SPI2: `TwoLinks`) unless told
    // one.
    assert_eq!(firmware(64).buses, 2);
    for (nodes, relays, buses) in [(16u16, 2usize, 2u16), (24, 3, 2), (64, 8, 2), (64, 8, 1)] {
        for policy in policies {
            let r = run(
                &img,
                SimConfig {
                    policy,
                    buses,
                    ..firmware(nodes)
                },
            );
            let what = format!("{nodes} nodes, {buses} root link(s), {policy:?}");
            assert!(r.frames[0] == want, "{what}");
            assert_eq!(r.root.pixels, 64 * 60, "{what}");
            check_clean(&what, &r, relays);
        }
    }
}

/// Two levels (`rc-fw --features relay-root-mid` the root, `relay-mid` between it and the
/// leaf relays; the board's default for 256 nodes): 128 and 256 nodes render the
/// single-node frame under decreasing and static sizes, every node exchange is routed once
/// by a middle relay and once by a leaf relay, every root broadcast reaches every relay's
/// bus once, and no exchange times out; with bit errors on every
/// link the frame is still exact.
#[test]
fn two_levels_of_firmware_relays_render_the_single_node_frame() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    assert_eq!(
        SimConfig::buildable(BoardProfile::F407, 256).relay,
        RelayCode::Firmware,
        "`rc-fw --features relay-root-mid` drives middle relays: the board's default is its code"
    );
    for (nodes, mids, policy) in [
        (128u16, 4usize, Policy::RELAYED),
        (256, 8, Policy::RELAYED),
        (256, 8, Policy::Static { shape: Split::Rect }),
    ] {
        let r = run(
            &img,
            SimConfig {
                policy,
                ..firmware(nodes)
            },
        );
        let what = format!("{nodes} nodes, {policy:?}");
        assert!(r.frames[0] == want, "{what}");
        assert_eq!(r.root.pixels, 64 * 60, "{what}");
        let f = r.relayed.as_ref().expect("the firmware's relay code ran");
        assert_eq!((f.mids.len(), f.relays.len()), (mids, nodes as usize / 8));
        for rep in f.mids.iter().chain(&f.relays) {
            let rep = rep.expect("every relay passed the Stop on");
            assert_eq!(rep.forwarded, r.root.broadcasts + 1, "{what}");
            assert_eq!(rep.bad_frames, 0, "{what}");
        }
        // Every node exchange the root made went through a middle relay and a leaf relay
        // once, and none waited past a time-out.
        let mids: u32 = f.mids.iter().flatten().map(|r| r.routed).sum();
        let leaves: u32 = f.relays.iter().flatten().map(|r| r.routed).sum();
        let leaf_bus: u64 = r.bus.iter().map(|b| b.exchanges).sum();
        assert_eq!(
            (mids, leaves, leaf_bus),
            (r.root.exchanges, r.root.exchanges, r.root.exchanges as u64),
            "{what}: {:?} {:?}",
            f.root,
            f.mid
        );
        assert_eq!((f.root.timeouts, f.mid.timeouts), (0, 0), "{what}");
        // Replies went ahead of the nodes' lines (the root composes a node's next reply
        // as its frame comes up), through the middle relays, and waited at the leaf
        // relays for lines to rise; none was lost.
        let held: u32 = f.relays.iter().flatten().map(|r| r.ahead).sum();
        assert!(
            f.root.ahead > 0 && f.mid.ahead > 0 && held > 0,
            "{what}: {:?} {:?} {held}",
            f.root,
            f.mid
        );
        assert!(held <= f.root.ahead, "{what}");
        assert_eq!((f.root.lost_ahead, f.mid.lost_ahead), (0, 0), "{what}");
        assert_eq!((f.root.bad_batches, f.mid.bad_batches), (0, 0), "{what}");
        assert!(f.mid.link_exchanges >= r.root.exchanges, "{what}");
        assert_eq!(r.root.bad_messages, 0, "{what}");
        let link = r.link.expect("the firmware link ran");
        assert!(!link.any(), "{what}: {link:?}");
    }
    let r = run(
        &img,
        SimConfig {
            noise: Noise {
                ber_up: 2e-5,
                ber_down: 2e-5,
                drop_broadcast: 0.0,
                ..Noise::default()
            },
            ..firmware(256)
        },
    );
    assert!(r.frames[0] == want, "bit errors on every link");
    let link = r.link.expect("the firmware link ran");
    assert!(link.any(), "the errors were seen: {link:?}");
}

#[test]
fn a_repeated_still_through_the_firmware_relays_is_exact_every_frame() {
    let img = image("photo1.ron", 48, 45);
    let want = reference(&img);
    let cfg = SimConfig {
        keep_frames: true,
        ..firmware(16)
    };
    let r = simulate(&[&img, &img, &img], &cfg).expect("runs");
    assert_eq!(r.frames.len(), 3);
    assert!(r.frames.iter().all(|f| *f == want));
    check_clean("3 frames", &r, 2);
    assert!(r.frame_done_s.windows(2).all(|w| w[0] < w[1]));
}

#[test]
fn bit_errors_on_the_root_link_cost_retries_never_the_frame() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    for (up, down) in [(3e-5, 0.0), (0.0, 3e-5)] {
        let r = run(
            &img,
            SimConfig {
                noise: Noise {
                    ber_up: up,
                    ber_down: down,
                    drop_broadcast: 0.0,
                    seed: 11,
                },
                ..firmware(16)
            },
        );
        let what = format!("bit errors up {up}, down {down}");
        assert!(r.frames[0] == want, "{what}");
        let f = r.relayed.expect("the firmware's relay code ran");
        assert!(
            f.link.corrupted_up + f.link.corrupted_down > 0,
            "{what}: errors hit the root's link: {:?}",
            f.link
        );
        let link = r.link.expect("the firmware link ran");
        assert!(link.any(), "{what}: the links saw them: {link:?}");
    }
}

/// Relay 1 of 2 stops answering at one of several moments of a 64x60 frame (before its
/// nodes hold work, while they do, near the end): the frame is always the single-node
/// render. Among the moments, the root gives a node exchange up at the relay time-out, and
/// its node time-out retires the dead relay's nodes, whose work goes to relay 0's.
#[test]
fn a_relay_that_stops_answering_costs_its_nodes_not_the_frame() {
    let img = image("photo1.ron", 64, 60);
    let want = reference(&img);
    let (mut relay_timeouts, mut declared_dead) = (0, 0);
    for ms in [5.0, 10.0, 12.0, 15.0, 20.0, 25.0, 30.0] {
        let r = run(
            &img,
            SimConfig {
                relay_deaths: vec![NodeDeath {
                    node: 1,
                    at_s: ms * 1e-3,
                }],
                node_timeout_s: 0.05,
                ..firmware(16)
            },
        );
        assert!(r.frames[0] == want, "relay 1 dead at {ms} ms");
        let f = r.relayed.expect("the firmware's relay code ran");
        assert!(
            f.relays[0].is_some() && f.relays[1].is_none(),
            "{ms} ms: {:?}",
            f.relays
        );
        relay_timeouts += f.root.timeouts;
        declared_dead += r.root.timeouts;
        if r.root.timeouts > 0 {
            let behind_dead: u64 = r.node_reports[8..].iter().map(|n| n.pixels).sum();
            let behind_live: u64 = r.node_reports[..8].iter().map(|n| n.pixels).sum();
            assert!(
                behind_live > behind_dead,
                "{ms} ms: {behind_live} vs {behind_dead}"
            );
        }
    }
    assert!(
        relay_timeouts > 0,
        "a node exchange given up at the relay time-out"
    );
    assert!(
        declared_dead > 0,
        "nodes behind the dead relay declared dead"
    );
}

#[test]
fn what_the_firmware_root_cannot_drive_is_refused_with_the_reason() {
    let img = image("photo1.ron", 16, 15);
    let err = |cfg: SimConfig| simulate_frame(&img, &cfg).unwrap_err().to_string();
    // Two levels: a middle relay reports 32 nodes, 4 leaf relays of 8.
    let e = err(firmware(72));
    assert!(e.contains("multiple of 32 nodes"), "{e}");
    // The root's children on three buses, the idealised link, uneven relays.
    let e = err(SimConfig {
        buses: 3,
        ..firmware(64)
    });
    assert!(e.contains("1 to 2 SPI buses, not 3"), "{e}");
    let e = err(SimConfig {
        link: LinkModel::Ideal,
        ..firmware(16)
    });
    assert!(e.contains("firmware link"), "{e}");
    let e = err(firmware(20));
    assert!(e.contains("same number of nodes"), "{e}");
    // A dead relay needs relays run by the firmware's code.
    let dead = vec![NodeDeath { node: 0, at_s: 0.0 }];
    let e = err(SimConfig {
        relay_deaths: dead.clone(),
        relay: RelayCode::Model,
        ..firmware(16)
    });
    assert!(e.contains("--relay firmware"), "{e}");
    let e = err(SimConfig {
        relay_deaths: vec![NodeDeath { node: 2, at_s: 0.0 }],
        ..firmware(16)
    });
    assert!(e.contains("relay 2"), "{e}");
    // A star has no relays: the option changes nothing there.
    let star = run(&img, firmware(8));
    assert!(star.relayed.is_none() && star.tree.is_none());
    assert_eq!(
        firmware(8).topology,
        Topology::Star,
        "8 nodes are one bus on the F407"
    );
}

/// A node behind two levels of relays dies mid-frame: its work goes to the others and the
/// frame is exact. A reply ahead of a dead node's line ends empty (its middle relay gives it
/// up); before a reply was sent ahead only after a frame came up, the root asked the dead
/// node ahead again after each empty end, hearing from it each time, and the frame never
/// finished (found by a review).
#[test]
fn a_node_that_dies_behind_two_levels_costs_its_work_not_the_frame() {
    let img = image("photo1.ron", 1024, 1024);
    let want = reference(&img);
    let t0 = run(&img, firmware(128)).time_s;
    let r = run(
        &img,
        SimConfig {
            deaths: vec![NodeDeath {
                node: 5,
                at_s: 0.03 * t0,
            }],
            ..firmware(128)
        },
    );
    assert!(r.frames[0] == want, "node 5 died at {:.4} s", 0.03 * t0);
    assert_eq!(r.root.timeouts, 1, "node 5 declared dead once");
    let f = r.relayed.as_ref().expect("the firmware's relay code ran");
    assert!(f.root.ahead > 0, "{:?}", f.root);
}
