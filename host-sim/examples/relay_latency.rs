//! Where a node exchange's time goes under the firmware's relay code (`--relay firmware`):
//! photo1 at W x H on N nodes, one frame, from the simulation's timeline.
//!
//! ```sh
//! cargo run --release -p links-host --example relay_latency -- 64 512 480
//! ```
//!
//! For every node exchange a relay clocked on its bus it finds, on the root's link to that
//! relay, the exchange that carried the request down (the last one with that relay starting
//! before the node's chip-select fell: a transfer ends for the slave when its chip-select
//! rises, before the master's hold time, which the timeline's interval includes) and the
//! one that brought the node's frame up (the next one with that relay); every other
//! exchange on the root's link only gathered. The breakdown assumes one node exchange in
//! flight (as `RelayedBus` had before it kept several, `links_core::relay::DEPTH` per relay:
//! `docs/cluster.md`), so the node exchanges follow each other: the cycle from one frame's
//! arrival at the root to the next's is split into its parts; with several in flight its
//! parts overlap and only the frame time and the nodes' share are meaningful.

use links_core::board::BoardProfile;
use links_host::cluster::exec::Ps;
use links_host::cluster::relay::{RelayCode, Topology};
use links_host::cluster::timeline::{BusTransfer, Timeline};
use links_host::cluster::{simulate_frame, SimConfig};

fn main() {
    let args: Vec<u32> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("N W H"))
        .collect();
    let (nodes, w, h) = match args[..] {
        [n, w, h] => (n as u16, w, h),
        _ => (64, 512, 480),
    };
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
    let img = links_host::scene_file::compile_at(&path, w, h).expect("photo1 compiles");
    for relay in [RelayCode::Model, RelayCode::Firmware] {
        let cfg = SimConfig {
            relay,
            timeline: Some(5_000_000),
            ..SimConfig::buildable(BoardProfile::F407, nodes)
        };
        assert!(matches!(cfg.topology, Topology::RelayTree { .. }));
        let r = simulate_frame(&img, &cfg).expect("runs");
        let t = r.timeline.as_ref().expect("a timeline");
        assert!(t.complete(), "the timeline kept every interval");
        let compute: f64 = r.node_compute_s.iter().sum();
        println!(
            "{} relay code, {nodes} nodes, {w}x{h}: frame {:.4} s, {} node exchanges; nodes computing {:.1}% of node-time, idle {:.2} ms per node exchange",
            relay.name(),
            r.time_s,
            r.root.exchanges,
            100.0 * compute / (nodes as f64 * r.time_s),
            1e3 * (nodes as f64 * r.time_s - compute) / r.root.exchanges as f64,
        );
        if relay == RelayCode::Firmware {
            breakdown(t, r.time_s, r.root.exchanges as usize);
        }
    }
}

fn us(ps: Ps) -> f64 {
    ps as f64 * 1e-6
}

/// The cycle of the firmware relays' node exchanges, in parts.
fn breakdown(t: &Timeline, time_s: f64, exchanges: usize) {
    let link: Vec<&BusTransfer> = t
        .root_link_transfers()
        .filter(|x| x.node.is_some())
        .collect();
    let mut used = vec![false; link.len()];
    // (request end, leaf start, leaf end, frame-up start, frame-up end, request duration,
    // frame-up duration)
    let mut rows: Vec<[Ps; 7]> = Vec::new();
    for (relay, bus) in t.bus.iter().enumerate() {
        for leaf in bus.iter().filter(|x| x.node.is_some()) {
            let with = |x: &&BusTransfer| x.node == Some(relay as u16);
            let req = link
                .iter()
                .enumerate()
                .rfind(|(_, x)| with(x) && x.at.start < leaf.at.start);
            let up = link
                .iter()
                .enumerate()
                .find(|(_, x)| with(x) && x.at.start > leaf.at.start);
            if let (Some((i, req)), Some((j, up))) = (req, up) {
                used[i] = true;
                used[j] = true;
                rows.push([
                    req.at.end,
                    leaf.at.start,
                    leaf.at.end,
                    up.at.start,
                    up.at.end,
                    req.at.len(),
                    up.at.len(),
                ]);
            }
        }
    }
    rows.sort_by_key(|r| r[4]);
    let n = rows.len() as f64;
    let mean = |f: &dyn Fn(&[Ps; 7]) -> Ps| rows.iter().map(|r| us(f(r))).sum::<f64>() / n;
    let busy: Ps = link.iter().map(|x| x.at.len()).sum();
    let bcast: Ps = t
        .root_link_transfers()
        .filter(|x| x.node.is_none())
        .map(|x| x.at.len())
        .sum();
    let gathering: Vec<&&BusTransfer> = link
        .iter()
        .zip(&used)
        .filter(|(_, &u)| !u)
        .map(|(x, _)| x)
        .collect();
    let gather_busy: Ps = gathering.iter().map(|x| x.at.len()).sum();
    // Cycles: from one node frame's arrival at the root to the next's.
    let cycles: Vec<Ps> = rows.windows(2).map(|w| w[1][4] - w[0][4]).collect();
    let cycle = cycles.iter().map(|&c| us(c)).sum::<f64>() / cycles.len().max(1) as f64;
    // Gathering exchanges inside each cycle: from the previous frame's arrival to this
    // request's start, and between the node's clocking and its frame-up exchange.
    let inside = |a: Ps, b: Ps| {
        gathering
            .iter()
            .filter(|x| x.at.start >= a && x.at.end <= b)
            .map(|x| x.at.len())
            .sum::<Ps>()
    };
    let before_req: f64 = rows
        .windows(2)
        .map(|w| us(inside(w[0][4], w[1][0] - w[1][5])))
        .sum::<f64>()
        / cycles.len().max(1) as f64;
    let before_up: f64 = rows.iter().map(|r| us(inside(r[2], r[3]))).sum::<f64>() / n;
    println!(
        "  root link: busy {:.1}% ({:.1} ms): {} exchanges, {:.1} ms carrying a request or a frame, {} only gathering ({:.1} ms), broadcasts {:.1} ms",
        100.0 * (busy + bcast) as f64 * 1e-12 / time_s,
        (busy + bcast) as f64 * 1e-9,
        link.len(),
        (busy - gather_busy) as f64 * 1e-9,
        gathering.len(),
        gather_busy as f64 * 1e-9,
        bcast as f64 * 1e-9
    );
    let mut sorted = cycles.clone();
    sorted.sort_unstable();
    let pct = |p: usize| sorted.get(sorted.len() * p / 100).map_or(0.0, |&c| us(c));
    println!(
        "  {} node exchanges matched of {exchanges}; mean cycle {cycle:.1} us (x {} = {:.1} ms; 10th percentile {:.1} us, median {:.1} us, 90th {:.1} us):",
        rows.len(),
        rows.len(),
        cycle * rows.len() as f64 * 1e-3,
        pct(10),
        pct(50),
        pct(90)
    );
    // A transfer is over for the slave when its chip-select rises, the hold before the
    // interval's end.
    let hold = BoardProfile::F407.link.cs_hold_ns as f64 * 1e-3;
    // The cycles by tenth of the frame: the node exchanges ending in it, their mean cycle.
    let end = (time_s * 1e12) as Ps;
    let tenths: Vec<String> = (0..10)
        .map(|k| {
            let (a, b) = (end * k / 10, end * (k + 1) / 10);
            let c: Vec<Ps> = rows
                .windows(2)
                .filter(|w| w[1][4] > a && w[1][4] <= b)
                .map(|w| w[1][4] - w[0][4])
                .collect();
            let m = c.iter().map(|&x| us(x)).sum::<f64>() / c.len().max(1) as f64;
            format!("{} x {m:.0}", c.len())
        })
        .collect();
    println!(
        "    by tenth of the frame (node exchanges x mean cycle, us): {}",
        tenths.join(", ")
    );
    let req_len = mean(&|r| r[5]);
    let relay_react = mean(&|r| r[1]) - (mean(&|r| r[0]) - hold);
    let leaf = mean(&|r| r[2] - r[1]);
    let wait_up = mean(&|r| r[3]) - (mean(&|r| r[2]) - hold);
    let up_len = mean(&|r| r[6]);
    let to_req = cycle - req_len - relay_react - (leaf - hold) - wait_up - up_len;
    println!(
        "    from the last frame's arrival to the request's exchange ending: {:.1} us (request exchange {req_len:.1} us; gathering with other relays {before_req:.1} us; the rest the root's CPU, and waiting while no node waits to be asked)",
        to_req + req_len
    );
    println!("    request at the relay (the chip-select rising) to the node's chip-select falling: {relay_react:.1} us");
    println!(
        "    the node's exchange on the relay's bus: {leaf:.1} us, {:.1} us to its chip-select rising",
        leaf - hold
    );
    println!(
        "    node's frame at the relay to the root's exchange with it: {wait_up:.1} us (of it gathering with other relays {before_up:.1} us)"
    );
    println!("    the exchange bringing the frame up: {up_len:.1} us");
}
