//! When the nodes compute under the relay tree, the simulator's relay model against the
//! firmware's relay code (`--relay model|firmware`): photo1 at 512x480 on 64 nodes (F407),
//! the share of node-time spent computing in each twentieth of the frame, from the
//! timeline.
//!
//! ```sh
//! cargo run --release -p links-host --example relay_idle
//! ```
use links_core::board::BoardProfile;
use links_host::cluster::relay::RelayCode;
use links_host::cluster::{simulate_frame, SimConfig};

fn main() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
    let img = links_host::scene_file::compile_at(&path, 512, 480).expect("photo1 compiles");
    for relay in [RelayCode::Model, RelayCode::Firmware] {
        let cfg = SimConfig {
            relay,
            timeline: Some(5_000_000),
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
    }
}
