//! The relay tree's speed-ups on the F407, the simulator's relay model against the
//! firmware's relay code (`--relay model|firmware`): photo1 at 512x480, single frame and
//! steady state (the still repeated, 8 frames against 4, as `links sweep board` measures
//! it), against one node of the same board.
//!
//! ```sh
//! cargo run --release -p links-host --example relay_speedup -- 16 32 64
//! cargo run --release -p links-host --example relay_speedup -- --buses 1 --policy 6,192 64
//! cargo run --release -p links-host --example relay_speedup -- --firmware-only 256
//! ```

use links_core::board::BoardProfile;
use links_core::sched::Policy;
use links_host::cluster::relay::RelayCode;
use links_host::cluster::{simulate_frame, SimConfig};
use links_host::studies::cluster_sweep::steady_state_interval;

fn main() {
    // Node counts, and optionally `--buses B` (the root's links; the board's by default),
    // `--policy FACTOR,MIN` (decreasing sizes; the relay tree's 6,192 by default) and
    // `--firmware-only` (not the model: half the time).
    let mut counts: Vec<u16> = Vec::new();
    let (mut buses, mut policy, mut codes) =
        (None, None, &[RelayCode::Model, RelayCode::Firmware][..]);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--buses" => buses = args.next().and_then(|b| b.parse().ok()),
            "--firmware-only" => codes = &[RelayCode::Firmware],
            "--policy" => {
                let v = args.next().unwrap_or_default();
                let (f, m) = v.split_once(',').expect("--policy FACTOR,MIN");
                policy = Some(Policy::Decreasing {
                    factor: f.parse().expect("a factor"),
                    min_pixels: m.parse().expect("a smallest job"),
                });
            }
            n => counts.push(n.parse().expect("node counts")),
        }
    }
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
    let img = links_host::scene_file::compile_at(&path, 512, 480).expect("photo1 compiles");
    let one_cfg = SimConfig::buildable(BoardProfile::F407, 1);
    let one = simulate_frame(&img, &one_cfg).expect("runs").time_s;
    let one_steady = steady_state_interval(&img, &one_cfg, 4).expect("runs");
    println!("1 node: {one:.4} s, steady {one_steady:.4} s/frame");
    for &n in &counts {
        for &relay in codes {
            let board = SimConfig::buildable(BoardProfile::F407, n);
            let cfg = SimConfig {
                relay,
                policy: policy.unwrap_or(board.policy),
                buses: buses.unwrap_or(board.buses),
                ..board
            };
            let r = simulate_frame(&img, &cfg).expect("runs");
            let steady = steady_state_interval(&img, &cfg, 8).expect("runs");
            let compute: f64 = r.node_compute_s.iter().sum();
            println!(
                "{n} nodes, {} relay code: {:.4} s, speed-up {:.2}x; steady {:.4} s/frame, {:.2}x; nodes computing {:.1}%, {} node exchanges ({} of them polls)",
                relay.name(),
                r.time_s,
                one / r.time_s,
                steady,
                one_steady / steady,
                100.0 * compute / (n as f64 * r.time_s),
                r.root.exchanges,
                r.root.polls,
            );
        }
    }
}
