//! The serial backup line simulated (`links_host::cluster::backup`): nodes whose SPI link is
//! dead render over the RS-485 line alone; the frame is bit-identical to the single-node
//! render, the roll call finds dead nodes, and the time is the line's bit-rate model.

use links_core::board::BoardProfile;
use links_host::cluster::backup::{simulate_backup, BackupConfig, BackupReport};
use links_tests::{bundled_image as image, host_reference as reference};

fn run(img: &[u8], cfg: &BackupConfig) -> BackupReport {
    let r = simulate_backup(img, cfg).unwrap_or_else(|e| panic!("{cfg:?}: {e}"));
    println!(
        "backup line, {} node(s), dead {:?}, {}x{}: {:.3} s (roll call {:.4} s, scene by {:.3} s), \
         {} frames, {} bytes, {} time-outs, {} pixel frames ({} RLE bytes), jobs {:?}",
        cfg.nodes,
        cfg.dead,
        r.width,
        r.height,
        r.time_s,
        r.roll_call_s,
        r.scene_s,
        r.line_frames,
        r.line_bytes,
        r.timeouts,
        r.pixel_frames,
        r.pixel_bytes,
        r.jobs
    );
    r
}

#[test]
fn backup_only_frames_are_bit_identical_with_1_and_3_nodes() {
    let img = image("photo1.ron", 48, 30);
    let want = reference(&img);
    for nodes in [1, 3] {
        let r = run(&img, &BackupConfig::for_board(&BoardProfile::F407, nodes));
        assert_eq!(r.frame, want, "{nodes} node(s)");
        assert_eq!(r.jobs.iter().map(|j| j.1).sum::<u32>(), 30);
        assert!(r.jobs.iter().all(|j| j.1 > 0), "every node took work");
        assert_eq!(r.timeouts, 0);
    }
}

#[test]
fn roll_call_finds_a_dead_node_and_the_others_finish_the_frame() {
    let img = image("photo1.ron", 40, 24);
    let mut cfg = BackupConfig::for_board(&BoardProfile::F407, 3);
    cfg.dead = vec![2];
    let r = run(&img, &cfg);
    let absent: Vec<u8> = r
        .roll_call
        .iter()
        .filter(|c| c.1.is_none())
        .map(|c| c.0)
        .collect();
    assert_eq!(absent, vec![2]);
    let h = r.roll_call[0].1.expect("node 1 answered");
    assert_eq!(h.firmware, links_core::backup::FIRMWARE_ID);
    assert_eq!((h.jobs_done, h.errors, h.scene_ok), (0, 0, false));
    assert_eq!(r.jobs.iter().map(|j| j.0).collect::<Vec<_>>(), vec![1, 3]);
    // Asked once, in the roll call; never again.
    assert_eq!(r.timeouts, 1);
    assert_eq!(r.frame, reference(&img));
}

/// With an instant core the line alone sets the pace: the elapsed time is exactly every
/// byte at 10 bits per byte and 1 Mbit/s, 20 µs of turnaround per frame (the F407 board's
/// line), nothing else; with the real core the node's compute hides behind the line or adds.
#[test]
fn a_backup_only_node_moves_at_the_line_bit_rate() {
    let img = image("photo1.ron", 32, 20);
    let line = BoardProfile::F407.backup;
    assert_eq!((line.bit_rate_hz, line.bits_per_byte), (1_000_000, 10));
    let mut cfg = BackupConfig::for_board(&BoardProfile::F407, 1);
    cfg.clock_hz = 1e18;
    let r = run(&img, &cfg);
    let ns = r.line_frames * 20_000 + r.line_bytes * 10_000 + r.timeouts * 1_000_000;
    assert!(
        (r.time_s * 1e9 - ns as f64).abs() < 1.0,
        "{} s vs {ns} ns",
        r.time_s
    );
    assert_eq!(r.line_busy_s, r.time_s);
    // Bit rate over the time the line was clocking bytes (turnarounds taken out).
    let clocking = r.time_s - r.line_frames as f64 * 20e-6;
    let rate = r.line_bytes as f64 * 10.0 / clocking;
    assert!((rate - 1e6).abs() < 1.0, "{rate} bit/s");
    // The scene went by broadcast once: its bytes dominate the scene phase.
    assert!(r.line_bytes as usize > img.len());
    assert_eq!(r.frame, reference(&img));

    let real = run(&img, &BackupConfig::for_board(&BoardProfile::F407, 1));
    assert!(real.time_s >= r.time_s && real.time_s >= real.node_compute_s[0]);
    assert_eq!(real.frame, r.frame);
}

/// In the cluster: a node whose SPI link dies (the node lives on) is declared dead by the
/// RC, found on the backup line, and renders over it; the frame is still the single-node
/// render's, and the report counts the line's bytes and time.
#[test]
fn a_node_whose_spi_link_died_renders_over_the_backup_line() {
    use links_host::cluster::star::NodeDeath;
    use links_host::cluster::{simulate_frame, SimConfig};
    let img = image("photo1.ron", 128, 96);
    let want = reference(&img);
    // (nodes, when node 0's SPI link dies, the RC's time-out): the default 0.5 s, or 20 ms
    // (longer than the scene's SPI broadcast) so the line is found before the frame ends.
    for (nodes, at_s, timeout_s) in [(1, 0.0, 0.5), (3, 0.0, 0.02), (3, 0.03, 0.02)] {
        let cfg = SimConfig {
            nodes,
            keep_frames: true,
            node_timeout_s: timeout_s,
            spi_dead: vec![NodeDeath { node: 0, at_s }],
            ..SimConfig::default()
        };
        let r = simulate_frame(&img, &cfg).unwrap_or_else(|e| panic!("{nodes} nodes: {e}"));
        assert_eq!(r.frames[0], want, "{nodes} nodes, SPI dead at {at_s} s");
        let line = r.backup.expect("the line ran");
        println!(
            "{nodes} nodes, node 0's SPI dead at {at_s} s: {:.4} s, line {} frames {} bytes \
             {:.4} s busy, served {:?}, {} jobs {} pixels over the line",
            r.time_s, line.frames, line.bytes, line.busy_s, line.served, line.jobs, line.pixels
        );
        // Node 0 at least; another node the 20 ms time-out falsely declared dead while it
        // rendered may be taken to the line too (and goes back to SPI when it speaks).
        assert_eq!(line.served.first(), Some(&0));
        assert!(line.absent.is_empty());
        assert_eq!(r.root.backup_runs > 0, line.jobs > 0);
        if nodes == 1 {
            // Nobody else: every pixel came over the line.
            assert_eq!(line.pixels, 128 * 96);
        }
        if at_s == 0.0 {
            assert!(line.jobs > 0, "the node found at the start took work");
        }
        assert!(line.bytes > 0 && line.busy_s > 0.0);
    }
}
