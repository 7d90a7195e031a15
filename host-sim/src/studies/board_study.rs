//! `links sweep board`: what the board profile does to the cluster's speed-up. For each
//! profile and node count: the single frame and the steady state (the still repeated: the
//! same scene every frame, not a film), with speed-ups against one node of the same
//! board; then, for the F407, where its bus time goes and what each of its choices and
//! limits is worth (the RC's overlap, against the serial inline link; no chip-select set-up
//! and hold; one bus per 8 nodes as the board is wired; the last two with the overlap).

use crate::sim::cluster::relay::{RelayCode, Topology};
use crate::sim::cluster::spi_bus::LinkModel;
use crate::sim::cluster::{RunCache, SimConfig, SimError, SimReport};
use crate::sim::options::{board_text, topology_text};
use crate::studies::report::table_head;
use crate::studies::sweep_commands::single_and_steady;
use links_core::board::BoardProfile;
use links_core::node::NodeConfig;
use links_core::root::MAX_BUSES;
use links_core::wire::PixelCoding;

/// One measured configuration: single frame and steady state, with their speed-ups.
struct Point {
    single_s: f64,
    speedup: f64,
    steady_s: f64,
    speedup_steady: f64,
    report: SimReport,
}

fn measure(image: &[u8], cfg: &SimConfig) -> Result<Point, SimError> {
    let (one, one_steady, report, steady_s) = single_and_steady(image, cfg)?;
    Ok(Point {
        single_s: report.time_s,
        speedup: one / report.time_s,
        steady_s,
        speedup_steady: one_steady / steady_s,
        report,
    })
}

/// The profiles x node counts table.
fn profiles_table(
    image: &[u8],
    counts: &[u16],
    link: Option<LinkModel>,
    cache: &std::sync::Arc<RunCache>,
    progress: &dyn Fn(&str),
) -> Result<String, SimError> {
    let mut t = table_head([
        "board",
        "link",
        "nodes",
        "topology (buildable)",
        "single frame (s)",
        "speed-up",
        "steady state, repeated still (s/frame)",
        "speed-up",
        "bus busy",
        "RC busy",
        "exchanges",
        "bytes clocked",
    ]);
    // A board whose nodes do not read the image's storage (the F207's carry Q16.16 only)
    // renders the scene converted to Q16.16, as `links render --board f207` does.
    let storage = links_core::image::SceneView::new(image)
        .map(|v| v.storage())
        .map_err(|e| SimError::Config(format!("scene image: {e}")))?;
    let fixed = links_core::fixed_image::to_fixed(image)
        .map(|f| f.bytes)
        .map_err(|e| format!("the scene in Q16.16: {e}"));
    for board in BoardProfile::ALL {
        let image: &[u8] = if board.kernels.run(storage) {
            image
        } else {
            fixed.as_deref().map_err(|e| SimError::Config(e.clone()))?
        };
        for &nodes in counts {
            progress(&format!("board {}, {nodes} nodes", board.name));
            let base = SimConfig::buildable(board, nodes);
            // The relay code the board runs on that link (the model on the idealised one).
            let cfg = SimConfig {
                cache: Some(cache.clone()),
                link: with_link(&base, link),
                ..base
            }
            .with_board_relays();
            let p = measure(image, &cfg)?;
            let r = &p.report;
            t.push_str(&format!(
                "| {} | {} | {nodes} | {} | {:.4} | {:.2} | {:.4} | {:.2} | {:.1}% | {:.1}% | {} | {} |\n",
                board.name,
                cfg.link.name(),
                topology_text(&cfg),
                p.single_s,
                p.speedup,
                p.steady_s,
                p.speedup_steady,
                100.0 * r.bus_utilisation(),
                100.0 * r.rc_utilisation(),
                r.root.exchanges,
                r.bytes_moved()
            ));
        }
    }
    Ok(t)
}

/// Where the F407's bus time goes in one report: handshakes, header and trailer, payload.
fn bus_split(cfg: &SimConfig, r: &SimReport) -> String {
    let t = &cfg.timing;
    let busy: f64 = r.bus.iter().map(|b| b.busy_ps as f64 * 1e-12).sum();
    let transfers: u64 = r.bus.iter().map(|b| b.exchanges + b.broadcasts).sum();
    let exchanges: u64 = r.bus.iter().map(|b| b.exchanges).sum();
    let framing = (transfers * t.header_bytes as u64 + exchanges * t.trailer_bytes as u64) as f64;
    let byte_s = 8.0 / t.bit_rate_hz;
    let handshake = transfers as f64 * t.overhead_ns * 1e-9;
    format!(
        "{:.1} ms on the wire: {:.1} ms chip-select set-up and hold ({transfers} transfers x {:.0} us), {:.1} ms header and trailer, {:.1} ms frames",
        busy * 1e3,
        handshake * 1e3,
        t.overhead_ns * 1e-3,
        framing * byte_s * 1e3,
        (busy - handshake - framing * byte_s) * 1e3
    )
}

/// The F407's limits at `nodes` nodes, each lifted in turn.
fn lifts_table(
    image: &[u8],
    nodes: u16,
    link: Option<LinkModel>,
    cache: &std::sync::Arc<RunCache>,
    progress: &dyn Fn(&str),
) -> Result<String, SimError> {
    let base = SimConfig::for_board(BoardProfile::F407);
    let f407 = SimConfig {
        nodes,
        cache: Some(cache.clone()),
        link: with_link(&base, link),
        ..base
    };
    let wired = BoardProfile::F407.buses_for(nodes).min(MAX_BUSES as u16);
    // The idealised link (the same wire and the same overlapping RC, but a node inbox
    // without bound) shows what the node's two RX banks cost; a link without chip-select
    // time is not what the firmware's code does: those variants run on the idealised link.
    let mut no_cs = SimConfig {
        link: LinkModel::Ideal,
        ..f407.clone()
    };
    no_cs.timing.overhead_ns = 0.0;
    let variants = [
        ("F407, one bus (a star)", f407.clone()),
        (
            "idealised link (node inbox unbounded)",
            SimConfig {
                link: LinkModel::Ideal,
                ..f407.clone()
            },
        ),
        ("no chip-select set-up/hold (idealised link)", no_cs.clone()),
        (
            "8 nodes per bus (as wired), at most 8 buses",
            SimConfig {
                buses: wired,
                ..f407.clone()
            },
        ),
        (
            "all three (idealised link)",
            SimConfig {
                buses: wired,
                rc_double_buffer: true,
                ..no_cs
            },
        ),
    ];
    let mut t = table_head([
        "F407 variant",
        "buses",
        "single (s)",
        "speed-up",
        "steady (s/frame)",
        "speed-up",
        "bus busy",
        "RC busy",
    ]);
    let mut split = String::new();
    for (name, cfg) in variants {
        progress(&format!("{nodes} nodes, {name}"));
        let p = measure(image, &cfg)?;
        let r = &p.report;
        if split.is_empty() {
            split = bus_split(&cfg, r);
        }
        t.push_str(&format!(
            "| {name} | {} | {:.4} | {:.2} | {:.4} | {:.2} | {:.1}% | {:.1}% |\n",
            r.buses,
            p.single_s,
            p.speedup,
            p.steady_s,
            p.speedup_steady,
            100.0 * r.bus_utilisation(),
            100.0 * r.rc_busy_s / r.time_s,
        ));
    }
    Ok(format!(
        "{nodes} nodes, F407 star of one bus, single frame: {split}\n\n{t}"
    ))
}

/// The F407's ways to `nodes` nodes (docs/hardware.md, "Reaching 64 and 256 nodes"): one
/// RC driving its three SPI buses, one bus of buffered segments (the same bit rate), a
/// tree of relay RCs (the simulator's model and the firmware's relay code on the firmware
/// link; the model also with the root's children spread over its three SPI buses: the
/// lift tried for the root's link), and for comparison one RC with 8 buses (no F407 has
/// them).
fn topology_table(
    image: &[u8],
    nodes: u16,
    link: Option<LinkModel>,
    cache: &std::sync::Arc<RunCache>,
    progress: &dyn Fn(&str),
) -> Result<String, SimError> {
    let base = SimConfig::for_board(BoardProfile::F407);
    let star = |buses| SimConfig {
        nodes,
        buses,
        cache: Some(cache.clone()),
        link: with_link(&base, link),
        ..base.clone()
    };
    // A relay tree divides the frame as the firmware's root of relays does.
    let tree = |batch, buses| {
        let topology = Topology::RelayTree { fanout: 8, batch };
        SimConfig {
            topology,
            policy: SimConfig::policy_for(topology),
            ..star(buses)
        }
    };
    // The root of relays drives them on the board's root links (SPI1 and SPI2 on the F407).
    let root_links = BoardProfile::F407.link.root_links;
    // The firmware's relay code (links_core::relay) drives one or two levels of relays on
    // the firmware link, on the root's two links (`TwoLinks`) or one: the board's
    // (buildable, `rc-fw --features relay-root` or `relay-root-mid`).
    let firmware = |buses| SimConfig {
        relay: RelayCode::Firmware,
        link: LinkModel::Firmware,
        ..tree(true, buses)
    };
    let variants = vec![
        ("(a) one RC, SPI1/2/3 (3 buses)", star(3)),
        ("(b) one bus of buffered segments", star(1)),
        (
            "(c) relay tree, one exchange per node frame",
            tree(false, root_links),
        ),
        (
            "(c) relay tree, batched, the model (the root on SPI1/2)",
            tree(true, root_links),
        ),
        (
            "(c) the firmware's relay code (buildable: the root on SPI1/2)",
            firmware(root_links),
        ),
        ("(c) batched, the root on one bus (SPI1)", tree(true, 1)),
        (
            "(c) the firmware's relay code, the root on one bus (SPI1)",
            firmware(1),
        ),
        (
            "(c) batched, the root's children on SPI1/2/3 (3 root buses)",
            tree(true, 3),
        ),
        (
            "(c) batched, RLE-coded pixels only (--pixel-coding rle)",
            SimConfig {
                node: NodeConfig {
                    coding: PixelCoding::Rle,
                },
                ..tree(true, root_links)
            },
        ),
        ("one RC with 8 buses (not an F407)", star(8)),
    ];
    let mut t = table_head([
        "topology",
        "nodes per bus",
        "single (s)",
        "speed-up",
        "steady (s/frame)",
        "speed-up",
        "busiest bus",
        "RC busy (per RC)",
        "root link busy",
        "root busy",
    ]);
    for (name, cfg) in variants {
        progress(&format!("{nodes} nodes, {name}"));
        let p = measure(image, &cfg)?;
        let r = &p.report;
        let (link, root) = match &r.tree {
            Some(tr) => (tr.root_link_busy_s() / r.time_s, tr.root_busy_s / r.time_s),
            None => (0.0, r.rc_busy_s / r.time_s),
        };
        t.push_str(&format!(
            "| {name} | {} | {:.4} | {:.2} | {:.4} | {:.2} | {:.1}% | {:.1}% | {:.1}% | {:.1}% |\n",
            nodes.div_ceil(r.buses.max(1)),
            p.single_s,
            p.speedup,
            p.steady_s,
            p.speedup_steady,
            100.0 * r.bus_utilisation(),
            100.0 * r.rc_utilisation(),
            100.0 * link,
            100.0 * root,
        ));
    }
    Ok(format!("{nodes} nodes on the F407, by topology:\n\n{t}"))
}

/// The link a configuration runs: `link` if given and the board's framing allows it, the
/// board's default otherwise.
fn with_link(cfg: &SimConfig, link: Option<LinkModel>) -> LinkModel {
    match link {
        Some(LinkModel::Firmware) if !LinkModel::firmware_framing(&cfg.profile.link) => cfg.link,
        Some(l) => l,
        None => cfg.link,
    }
}

/// The whole study as Markdown; `link` overrides the F407's link (the ideal board always
/// runs the idealised one).
pub fn board_study(
    image: &[u8],
    counts: &[u16],
    lift_at: &[u16],
    link: Option<LinkModel>,
    progress: &dyn Fn(&str),
) -> Result<String, String> {
    let e = |e: SimError| e.to_string();
    let cache = RunCache::new();
    let mut s = String::new();
    for b in BoardProfile::ALL {
        s.push_str(&format!("- {}\n", board_text(&SimConfig::for_board(b))));
    }
    s.push('\n');
    s.push_str(&profiles_table(image, counts, link, &cache, progress).map_err(e)?);
    for &n in lift_at {
        s.push('\n');
        s.push_str(&lifts_table(image, n, link, &cache, progress).map_err(e)?);
        s.push('\n');
        s.push_str(&topology_table(image, n, link, &cache, progress).map_err(e)?);
    }
    Ok(s)
}
