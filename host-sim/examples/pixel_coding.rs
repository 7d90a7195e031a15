//! Run-length against delta-coded pixel runs (`--pixel-coding rle|delta`) on the F407's
//! buildable cluster: photo1 at 512x480, single frame and steady state (the still repeated,
//! 8 frames against 4, as `links sweep board` measures it), root link and root CPU.
//!
//! ```sh
//! cargo run --release -p links-host --example pixel_coding -- 64 256
//! ```

use links_core::board::BoardProfile;
use links_core::wire::PixelCoding;
use links_host::cluster::sweep::steady_state_interval;
use links_host::cluster::{simulate_frame, SimConfig};

fn main() {
    let counts: Vec<u16> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("node counts"))
        .collect();
    let counts = if counts.is_empty() {
        vec![64, 256]
    } else {
        counts
    };
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
    let img = links_host::scene_file::compile_at(&path, 512, 480).expect("photo1 compiles");
    let one = SimConfig::buildable(BoardProfile::F407, 1);
    let one_s = simulate_frame(&img, &one).expect("runs").time_s;
    let one_steady = steady_state_interval(&img, &one, 4).expect("runs");
    println!("| nodes | coding | single (s) | speed-up | steady (s/frame) | speed-up | root link busy | root busy | bytes moved |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for &nodes in &counts {
        for coding in [PixelCoding::Rle, PixelCoding::Delta] {
            let mut cfg = SimConfig::buildable(BoardProfile::F407, nodes);
            cfg.node.coding = coding;
            let r = simulate_frame(&img, &cfg).expect("runs");
            let steady = steady_state_interval(&img, &cfg, 8).expect("runs");
            let (link, root) = match &r.tree {
                Some(t) => (t.root_link_busy_s() / r.time_s, t.root_busy_s / r.time_s),
                None => (r.bus_utilisation(), r.rc_utilisation()),
            };
            println!(
                "| {nodes} | {coding:?} | {:.4} | {:.2}x | {:.4} | {:.2}x | {:.1}% | {:.1}% | {} |",
                r.time_s,
                one_s / r.time_s,
                steady,
                one_steady / steady,
                100.0 * link,
                100.0 * root,
                r.bytes_moved(),
            );
        }
    }
}
