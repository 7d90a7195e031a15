//! When the nodes compute under the relay tree, the simulator's relay model against the
//! firmware's relay code (`--relay model|firmware`): photo1 at 512x480 on 64 nodes (F407),
//! the share of node-time spent computing in each twentieth of the frame, from the
//! timeline; then, for the frame's first and last 50 ms in 10 ms windows, how busy the root's
//! link (the firmware's relay code only; the model keeps no link) and the RC's CPU are and
//! how much of node-time is computing. `--policy FACTOR,MIN`: decreasing sizes with that
//! factor and smallest job (default 6,128, the CLI's `decreasing`).
//!
//! ```sh
//! cargo run --release -p links-host --example relay_idle [-- --policy 6,256]
//! ```
use links_core::board::BoardProfile;
use links_core::sched::Policy;
use links_host::cluster::relay::RelayCode;
use links_host::cluster::timeline::Interval;
use links_host::cluster::{simulate_frame, SimConfig};

/// Busy time of `spans` inside `[a, z)` (ps).
fn busy_in(spans: impl Iterator<Item = Interval>, a: u64, z: u64) -> u64 {
    spans
        .map(|iv| iv.end.min(z).saturating_sub(iv.start.max(a)))
        .sum()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let policy = match args.as_slice() {
        [] => Policy::DECREASING,
        [flag, v] if flag == "--policy" => {
            let (f, m) = v.split_once(',').expect("--policy FACTOR,MIN");
            Policy::Decreasing {
                factor: f.parse().expect("FACTOR: a positive integer"),
                min_pixels: m.parse().expect("MIN: a positive integer"),
            }
        }
        _ => panic!("usage: relay_idle [--policy FACTOR,MIN]"),
    };
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
    let img = links_host::scene_file::compile_at(&path, 512, 480).expect("photo1 compiles");
    for relay in [RelayCode::Model, RelayCode::Firmware] {
        let cfg = SimConfig {
            relay,
            timeline: Some(5_000_000),
            policy,
            ..SimConfig::buildable(BoardProfile::F407, 64)
        };
        let r = simulate_frame(&img, &cfg).expect("runs");
        let t = r.timeline.as_ref().expect("timeline");
        let end = (r.time_s * 1e12) as u64;
        let mut busy = [0u64; 20];
        for node in &t.compute {
            for iv in node {
                for b in 0..20u64 {
                    let (s, e) = (end * b / 20, end * (b + 1) / 20);
                    let (a, z) = (iv.start.max(s), iv.end.min(e));
                    if z > a {
                        busy[b as usize] += z - a;
                    }
                }
            }
        }
        let per = end / 20 * 64;
        let v: Vec<String> = busy
            .iter()
            .map(|&b| format!("{:.0}", 100.0 * b as f64 / per as f64))
            .collect();
        let first = t
            .compute
            .iter()
            .filter_map(|n| n.first().map(|i| i.start))
            .min()
            .unwrap_or(0);
        let mut last: Vec<f64> = t
            .compute
            .iter()
            .map(|n| {
                n.last()
                    .map_or(0.0, |i| (end - i.end.min(end)) as f64 * 1e-9)
            })
            .collect();
        last.sort_by(f64::total_cmp);
        println!(
            "{}: nodes' last computing ends before the frame's end (ms): min {:.2}, median {:.2}, max {:.2}",
            relay.name(),
            last[0],
            last[last.len() / 2],
            last[last.len() - 1]
        );
        println!(
            "{}: {:.4} s, first compute at {:.2} ms; % computing per twentieth: {}",
            relay.name(),
            r.time_s,
            first as f64 * 1e-9,
            v.join(" ")
        );
        const WINDOW: u64 = 10_000_000_000; // 10 ms in ps
        let starts = (0..5)
            .map(|w| w * WINDOW)
            .chain((0..5).map(|w| end - (5 - w) * WINDOW));
        for a in starts {
            let z = a + WINDOW;
            let link = busy_in(t.root_link_transfers().map(|x| x.at), a, z);
            let transfers = t
                .root_link_transfers()
                .filter(|x| x.at.start >= a && x.at.start < z)
                .count();
            let rc = busy_in(t.rc.iter().copied(), a, z);
            let nodes: u64 = t
                .compute
                .iter()
                .map(|n| busy_in(n.iter().copied(), a, z))
                .sum();
            let pct = |b: u64, n: usize| 100.0 * b as f64 / (WINDOW as f64 * n as f64);
            println!(
                "{}:   {:5.1}..{:5.1} ms: root link {:3.0}% busy ({transfers} transfers), RC CPU {:3.0}%, nodes computing {:3.0}%",
                relay.name(),
                a as f64 * 1e-9,
                z as f64 * 1e-9,
                pct(link, 1),
                pct(rc, 1),
                pct(nodes, t.compute.len())
            );
        }
    }
}
