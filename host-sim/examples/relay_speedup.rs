//! The relay tree's speed-ups on the F407, the simulator's relay model against the
//! firmware's relay code (`--relay model|firmware`): photo1 at 512x480, single frame and
//! steady state (the still repeated, 8 frames against 4, as `links sweep board` measures
//! it), against one node of the same board.
//!
//! ```sh
//! cargo run --release -p links-host --example relay_speedup -- 16 32 64
//! ```

use links_core::board::BoardProfile;
use links_host::cluster::relay::RelayCode;
use links_host::cluster::{simulate_frame, SimConfig};
use links_host::studies::cluster_sweep::steady_state_interval;

fn main() {
    let mut counts: Vec<u16> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("node counts"))
        .collect();
    if counts.is_empty() {
        counts = vec![16, 32, 64];
    }
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
    let img = links_host::scene_file::compile_at(&path, 512, 480).expect("photo1 compiles");
    let one_cfg = SimConfig::buildable(BoardProfile::F407, 1);
    let one = simulate_frame(&img, &one_cfg).expect("runs").time_s;
    let one_steady = steady_state_interval(&img, &one_cfg, 4).expect("runs");
    println!("1 node: {one:.4} s, steady {one_steady:.4} s/frame");
    for &n in &counts {
        for relay in [RelayCode::Model, RelayCode::Firmware] {
            let cfg = SimConfig {
                relay,
                ..SimConfig::buildable(BoardProfile::F407, n)
            };
            let r = simulate_frame(&img, &cfg).expect("runs");
            let steady = steady_state_interval(&img, &cfg, 8).expect("runs");
            let compute: f64 = r.node_compute_s.iter().sum();
            println!(
                "{n} nodes, {} relay code: {:.4} s, speed-up {:.2}x; steady {:.4} s/frame, {:.2}x; nodes computing {:.1}%, {} node exchanges",
                relay.name(),
                r.time_s,
                one / r.time_s,
                steady,
                one_steady / steady,
                100.0 * compute / (n as f64 * r.time_s),
                r.root.exchanges,
            );
        }
    }
}
