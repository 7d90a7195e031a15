//! The options of `links render --nodes` that set up a simulated cluster run: the
//! scheduling policy, node deaths and link faults, and the one-line fault summary. Thin glue
//! over [`crate::sim::cluster`]; every number is virtual time.

use crate::sim::cluster::relay::{RelayCode, Topology};
use crate::sim::cluster::spi_bus::{LinkModel, StuckReady};
use crate::sim::cluster::star::{NodeDeath, Noise};
use crate::sim::cluster::{render_cluster, ClusterRender, SimConfig, SimReport};
use links_core::board::BoardProfile;
use links_core::sched::{Policy, Split};
use std::fmt;
use std::str::FromStr;

/// A `--policy` value: `decreasing` (= `decreasing=6,128`), `decreasing=FACTOR,MIN`, `static`,
/// `fixed=N` (runs) or `fixed-rect=N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PolicyArg(pub Policy);

impl FromStr for PolicyArg {
    type Err = OptionError;

    fn from_str(s: &str) -> Result<Self, OptionError> {
        let fixed = |n: &str, shape| {
            n.parse::<u32>()
                .ok()
                .filter(|&d| d > 0)
                .map(|divisions| PolicyArg(Policy::Fixed { divisions, shape }))
                .ok_or_else(|| OptionError::BadDivisions(s.into()))
        };
        match s {
            "decreasing" => Ok(PolicyArg(Policy::DECREASING)),
            "static" => Ok(PolicyArg(Policy::Static { shape: Split::Rect })),
            _ => match s.split_once('=') {
                Some(("fixed", n)) => fixed(n, Split::Span),
                Some(("fixed-rect", n)) => fixed(n, Split::Rect),
                Some(("decreasing", args)) => {
                    // FACTOR,MIN: each job remaining / (FACTOR x nodes) pixels, at least MIN.
                    let bad = || OptionError::BadDecreasing(s.into());
                    let positive = |v: &str| v.trim().parse::<u32>().ok().filter(|&v| v > 0);
                    let (f, m) = args.split_once(',').ok_or_else(bad)?;
                    let factor = positive(f).ok_or_else(bad)?;
                    let min_pixels = positive(m).ok_or_else(bad)?;
                    Ok(PolicyArg(Policy::Decreasing { factor, min_pixels }))
                }
                _ => Err(OptionError::UnknownPolicy(s.into())),
            },
        }
    }
}

/// The known board profiles, borrowed by the command line's arguments (a reference keeps
/// them small).
static BOARDS: [BoardProfile; BoardProfile::ALL.len()] = BoardProfile::ALL;

/// `--board NAME`: a known board profile (`f407`, `f207`, `g0b1`, `ideal`; ASCII case
/// ignored).
pub fn parse_board(s: &str) -> Result<BoardProfile, OptionError> {
    parse_board_arg(s).copied()
}

/// `--board NAME` as the command line keeps it (see [`parse_board`]).
pub fn parse_board_arg(s: &str) -> Result<&'static BoardProfile, OptionError> {
    BOARDS
        .iter()
        .find(|b| b.name.eq_ignore_ascii_case(s))
        .ok_or_else(|| OptionError::UnknownBoard(s.into()))
}

/// The board profile in words, as summaries print it: name, bit rate, per-transfer
/// handshake, header / trailer, nodes per bus, RC overlap.
pub fn board_text(cfg: &SimConfig) -> String {
    let (p, t) = (&cfg.profile, &cfg.timing);
    format!(
        "board {}, {} link: {} MHz, {:.1} us CS set-up+hold, {}+{} B header+trailer, {} nodes/bus, RC {}",
        p.name,
        cfg.link.name(),
        t.bit_rate_hz / 1e6,
        t.overhead_ns * 1e-3,
        t.header_bytes,
        t.trailer_bytes,
        p.link.nodes_per_bus,
        if cfg.rc_double_buffer {
            "overlaps"
        } else {
            "serial"
        }
    )
}

/// `--link NAME`: the firmware's link code over the emulated SPI peripheral (`firmware`)
/// or the idealised star (`ideal`).
pub fn parse_link(s: &str) -> Result<LinkModel, OptionError> {
    match s {
        "firmware" => Ok(LinkModel::Firmware),
        "ideal" => Ok(LinkModel::Ideal),
        _ => Err(OptionError::UnknownLink(s.into())),
    }
}

/// `--relay NAME`: the relay tree's links run by the simulator's model (`model`) or by the
/// firmware's relay code (`firmware`).
pub fn parse_relay(s: &str) -> Result<RelayCode, OptionError> {
    match s {
        "model" => Ok(RelayCode::Model),
        "firmware" => Ok(RelayCode::Firmware),
        _ => Err(OptionError::UnknownRelay(s.into())),
    }
}

/// `--pixel-coding NAME`: how nodes may code their pixel runs.
pub fn parse_pixel_coding(s: &str) -> Result<links_core::wire::PixelCoding, OptionError> {
    use links_core::wire::PixelCoding;
    match s {
        "raw" => Ok(PixelCoding::Raw),
        "rle" => Ok(PixelCoding::Rle),
        "delta" => Ok(PixelCoding::Delta),
        _ => Err(OptionError::UnknownPixelCoding(s.into())),
    }
}

/// `--kill-relay` values (RELAY@SECONDS, FIRST-LAST@SECONDS) for a tree of `relays` relays.
pub fn relay_deaths(values: &[String], relays: u16) -> Result<Vec<NodeDeath>, OptionError> {
    node_times(values, relays).map_err(|e| match e {
        OptionError::NoSuchNode { text, node, nodes } => OptionError::NoSuchRelay {
            text,
            relay: node,
            relays: nodes,
        },
        e => e,
    })
}

/// A `--topology` value: `buildable` (what the board can be wired as: a relay tree when
/// one bus cannot hold the nodes), `star` (every node on the RC's `--buses` buses) or `relay`
/// (a relay tree whatever the count).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TopologyArg {
    Buildable,
    Star,
    Relay,
}

impl FromStr for TopologyArg {
    type Err = OptionError;

    fn from_str(s: &str) -> Result<Self, OptionError> {
        match s {
            "buildable" => Ok(TopologyArg::Buildable),
            "star" => Ok(TopologyArg::Star),
            "relay" => Ok(TopologyArg::Relay),
            _ => Err(OptionError::UnknownTopology(s.into())),
        }
    }
}

impl TopologyArg {
    /// The topology for `nodes` nodes on `board`; a relay tree has as many relays per
    /// parent as the board has nodes per bus (at most [`links_core::root::MAX_BUSES`]).
    pub fn topology(self, board: &BoardProfile, nodes: u16) -> Topology {
        let fanout = board
            .link
            .nodes_per_bus
            .min(links_core::root::MAX_BUSES as u16);
        match self {
            TopologyArg::Buildable => Topology::buildable(board, nodes),
            TopologyArg::Star => Topology::Star,
            TopologyArg::Relay => Topology::RelayTree {
                fanout,
                batch: true,
            },
        }
    }
}

/// The topology in words, as summaries print it: `star, 1 bus` or `relay tree: 8 relays
/// x 8 nodes, 1 level`.
pub fn topology_text(cfg: &SimConfig) -> String {
    match cfg.tree() {
        None => format!("star, {} bus(es)", cfg.buses),
        Some(Err(e)) => e.to_string(),
        Some(Ok(t)) => format!(
            "relay tree: {} relays x {} nodes, {} level(s){}{}",
            t.leaves,
            cfg.profile.link.nodes_per_bus,
            t.levels(),
            match (cfg.mid_relays(), t.roots) {
                (0, 1) => String::new(),
                (0, r) => format!(" (the root on {r} buses)"),
                (m, 1) => format!(" ({m} mid relays)"),
                (m, r) => format!(" ({m} mid relays, the root on {r} buses)"),
            },
            match (cfg.relay, t.levels()) {
                (RelayCode::Model, 1) => ", modelled relays (--relay firmware runs their code)",
                (RelayCode::Model, _) =>
                    ", modelled relays (--relay firmware runs their code: 4 leaf relays per mid relay)",
                (RelayCode::Firmware, _) => ", the firmware's relay code",
            }
        ),
    }
}

/// The relay tree's share of the run, for the render's stats line ("" for a star): the
/// RC figure before it is the mean leaf relay's; the root's link and CPU busy fractions.
pub fn tree_summary(r: &SimReport) -> String {
    let Some(t) = &r.tree else {
        return String::new();
    };
    let root_link = t.root_link_busy_s();
    let code = match &r.relayed {
        None => String::new(),
        Some(f) => format!(
            " ({} exchanges on it for {} node frames, {} of them only gathering; {} relay time-outs{})",
            f.root.link_exchanges,
            t.links.first().map_or(0, |l| l.frames_up),
            f.root.gathering,
            f.root.timeouts,
            match (f.link.corrupted(), f.link.dropped_broadcast) {
                (0, 0) => String::new(),
                (c, d) => format!("; {c} transfers corrupted, {d} broadcast copies lost on it"),
            }
        ),
    };
    format!(
        " per relay; root link busy {:.1}%{code}, root busy {:.1}%",
        100.0 * root_link / r.time_s,
        100.0 * t.root_busy_s / r.time_s
    )
}

/// A warning when the star puts more nodes on a bus than the profile's link drives ("" if
/// not).
pub fn topology_note(cfg: &SimConfig) -> String {
    match cfg.overloaded_bus() {
        Some(n) => format!(
            " | note: {n} nodes on a bus, the {} board drives {} (a topology not yet buildable)",
            cfg.profile.name, cfg.profile.link.nodes_per_bus
        ),
        None => String::new(),
    }
}

/// A policy as `--policy` takes it (`decreasing=6,128`, `static`, `fixed=N`,
/// `fixed-rect=N`).
pub fn policy_text(p: Policy) -> String {
    match p {
        Policy::Decreasing { factor, min_pixels } => format!("decreasing={factor},{min_pixels}"),
        Policy::Static { .. } => "static".into(),
        Policy::Fixed {
            divisions,
            shape: Split::Span,
        } => format!("fixed={divisions}"),
        Policy::Fixed {
            divisions,
            shape: Split::Rect,
        } => format!("fixed-rect={divisions}"),
    }
}

/// Parse a scheduling policy (see [`PolicyArg`]).
pub fn parse_policy(s: &str) -> Result<Policy, OptionError> {
    s.parse::<PolicyArg>().map(|p| p.0)
}

/// A `--kill` value: `NODE@SECONDS` or `FIRST-LAST@SECONDS` (nodes `FIRST..=LAST` all stop
/// answering at that virtual time).
#[derive(Clone, Debug, PartialEq)]
pub struct Kill {
    /// The text as given (errors about the nodes quote it).
    pub text: String,
    pub first: u16,
    pub last: u16,
    pub at_s: f64,
}

impl FromStr for Kill {
    type Err = OptionError;

    fn from_str(s: &str) -> Result<Self, OptionError> {
        let bad = || OptionError::BadKill(s.into());
        let (nodes, at) = s.split_once('@').ok_or_else(bad)?;
        let at_s: f64 = at.trim().parse().map_err(|_| bad())?;
        if !(at_s.is_finite() && at_s >= 0.0) {
            return Err(OptionError::KillTime(s.into()));
        }
        let (first, last) = nodes.split_once('-').unwrap_or((nodes, nodes));
        let first: u16 = first.trim().parse().map_err(|_| bad())?;
        let last: u16 = last.trim().parse().map_err(|_| bad())?;
        if last < first {
            return Err(OptionError::EmptyRange {
                text: s.into(),
                first,
                last,
            });
        }
        Ok(Kill {
            text: s.into(),
            first,
            last,
            at_s,
        })
    }
}

impl Kill {
    /// One death per node of the range.
    pub fn deaths(&self) -> impl Iterator<Item = NodeDeath> + '_ {
        (self.first..=self.last).map(|node| NodeDeath {
            node,
            at_s: self.at_s,
        })
    }
}

/// Parse `NODE@SECONDS` or `FIRST-LAST@SECONDS` into one death per node (see [`Kill`]).
pub fn parse_deaths(s: &str) -> Result<Vec<NodeDeath>, OptionError> {
    Ok(s.parse::<Kill>()?.deaths().collect())
}

/// Why a cluster option was refused (the text names the option and the value).
#[derive(Clone, Debug, PartialEq)]
pub enum OptionError {
    UnknownPolicy(String),
    /// `--topology` with no such topology.
    UnknownTopology(String),
    /// `--link` with no such link.
    UnknownLink(String),
    /// `--relay` with no such relay code.
    UnknownRelay(String),
    UnknownPixelCoding(String),
    /// `--kill-relay` of a relay the tree does not have.
    NoSuchRelay {
        text: String,
        relay: u16,
        relays: u16,
    },
    /// `--board NAME` with no such profile.
    UnknownBoard(String),
    /// `fixed=N` / `fixed-rect=N` with N not a positive integer.
    BadDivisions(String),
    /// `decreasing=FACTOR,MIN` without two positive integers.
    BadDecreasing(String),
    BadKill(String),
    KillTime(String),
    EmptyRange {
        text: String,
        first: u16,
        last: u16,
    },
    NoSuchNode {
        text: String,
        node: u16,
        nodes: u16,
    },
    /// `--ber-down` / `--ber-up` outside 0..=0.5.
    BitErrorRate {
        option: &'static str,
        rate: f64,
    },
    DropProbability(f64),
}

impl fmt::Display for OptionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OptionError::UnknownPolicy(s) => write!(
                f,
                "unknown policy '{s}' (expected decreasing, decreasing=FACTOR,MIN, static, fixed=N or fixed-rect=N)"
            ),
            OptionError::BadDecreasing(s) => write!(
                f,
                "bad policy '{s}': decreasing=FACTOR,MIN takes two positive integers (each job is the remaining pixels / (FACTOR x nodes), at least MIN; the default is decreasing=6,128)"
            ),
            OptionError::UnknownTopology(s) => write!(
                f,
                "unknown topology '{s}' (expected buildable, star or relay)"
            ),
            OptionError::UnknownLink(s) => {
                write!(f, "unknown link '{s}' (expected firmware or ideal)")
            }
            OptionError::UnknownRelay(s) => {
                write!(f, "unknown relay code '{s}' (expected model or firmware)")
            }
            OptionError::UnknownPixelCoding(s) => {
                write!(f, "unknown pixel coding '{s}' (expected raw, rle or delta)")
            }
            OptionError::NoSuchRelay { text, relay, relays: 0 } => write!(
                f,
                "--kill-relay '{text}': relay {relay} does not exist (no relay tree)"
            ),
            OptionError::NoSuchRelay {
                text,
                relay,
                relays,
            } => write!(
                f,
                "--kill-relay '{text}': relay {relay} does not exist ({relays} relays: 0 to {})",
                relays - 1
            ),
            OptionError::UnknownBoard(s) => {
                let known: Vec<&str> = BoardProfile::ALL.iter().map(|b| b.name).collect();
                write!(f, "unknown board '{s}' (known: {})", known.join(", "))
            }
            OptionError::BadDivisions(s) => {
                write!(f, "'{s}': the sub-screen count must be a positive integer")
            }
            OptionError::BadKill(s) => write!(
                f,
                "--kill '{s}': expected NODE@SECONDS or FIRST-LAST@SECONDS, e.g. 10@0.3"
            ),
            OptionError::KillTime(s) => {
                write!(f, "--kill '{s}': the time must be a number of seconds >= 0")
            }
            OptionError::EmptyRange { text, first, last } => {
                write!(f, "--kill '{text}': the range {first}-{last} is empty")
            }
            OptionError::NoSuchNode { text, node, nodes } => write!(
                f,
                "--kill '{text}': node {node} does not exist ({nodes} nodes: 0 to {})",
                nodes.saturating_sub(1)
            ),
            OptionError::BitErrorRate { option, rate } => write!(
                f,
                "{option} {rate}: a bit-error rate is a probability per bit, from 0 to 0.5"
            ),
            OptionError::DropProbability(p) => write!(
                f,
                "--drop-broadcast {p}: a probability from 0 to below 1 (at 1 no node hears any broadcast)"
            ),
        }
    }
}

impl std::error::Error for OptionError {}

/// Fault injection options of `links render --nodes N`.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct FaultArgs {
    /// A node that stops answering: NODE@SECONDS or FIRST-LAST@SECONDS of virtual time
    /// (repeatable; cluster only)
    #[arg(long = "kill", value_name = "NODE@SECONDS")]
    pub kills: Vec<String>,
    /// Bit-error rate RC -> nodes (exchanges and broadcasts, each bit independently), e.g.
    /// 1e-4 (cluster only)
    #[arg(long, value_name = "RATE", default_value_t = 0.0)]
    pub ber_down: f64,
    /// Bit-error rate nodes -> RC (cluster only)
    #[arg(long, value_name = "RATE", default_value_t = 0.0)]
    pub ber_up: f64,
    /// Probability that a node loses a broadcast whole (cluster only)
    #[arg(long, value_name = "P", default_value_t = 0.0)]
    pub drop_broadcast: f64,
    /// Seed of the bit errors and losses (a run is deterministic for a seed; cluster only)
    #[arg(long, default_value_t = 1)]
    pub fault_seed: u64,
    /// A node whose SPI link dies while the node lives on: NODE@SECONDS or
    /// FIRST-LAST@SECONDS (repeatable; nodes 0-63). The RC finds it on the serial backup
    /// line and serves it there (cluster only)
    #[arg(long = "spi-dead", value_name = "NODE@SECONDS")]
    pub spi_dead: Vec<String>,
    /// Run the serial backup line (roll call at the start and of every node declared
    /// dead) even without --spi-dead (cluster only)
    #[arg(long)]
    pub backup_line: bool,
    /// A node whose handshake (ready) line sticks low from then on, whatever it drives:
    /// NODE@SECONDS or FIRST-LAST@SECONDS (repeatable; firmware link only)
    #[arg(long = "stuck-low", value_name = "NODE@SECONDS")]
    pub stuck_low: Vec<String>,
    /// A node whose handshake line sticks high (repeatable; firmware link only)
    #[arg(long = "stuck-high", value_name = "NODE@SECONDS")]
    pub stuck_high: Vec<String>,
}

/// Set the faults of `args` on `cfg` (whose node count is already set), with errors that
/// name the option.
pub fn apply_faults(cfg: &mut SimConfig, args: &FaultArgs) -> Result<(), OptionError> {
    for (option, rate) in [("--ber-down", args.ber_down), ("--ber-up", args.ber_up)] {
        if !(rate.is_finite() && (0.0..=0.5).contains(&rate)) {
            return Err(OptionError::BitErrorRate { option, rate });
        }
    }
    let p = args.drop_broadcast;
    if !(p.is_finite() && (0.0..1.0).contains(&p)) {
        return Err(OptionError::DropProbability(p));
    }
    cfg.noise = Noise {
        ber_down: args.ber_down,
        ber_up: args.ber_up,
        drop_broadcast: p,
        seed: args.fault_seed,
    };
    cfg.deaths = node_times(&args.kills, cfg.nodes)?;
    cfg.spi_dead = node_times(&args.spi_dead, cfg.nodes)?;
    cfg.backup_line = args.backup_line;
    cfg.stuck.clear();
    for (values, high) in [(&args.stuck_low, false), (&args.stuck_high, true)] {
        for d in node_times(values, cfg.nodes)? {
            cfg.stuck.push(StuckReady {
                node: d.node,
                at_s: d.at_s,
                high,
            });
        }
    }
    Ok(())
}

/// `--kill`-style values (NODE@SECONDS, FIRST-LAST@SECONDS) for a cluster of `nodes`.
fn node_times(values: &[String], nodes: u16) -> Result<Vec<NodeDeath>, OptionError> {
    let mut out = Vec::new();
    for k in values {
        let kill: Kill = k.parse()?;
        for d in kill.deaths() {
            if d.node >= nodes {
                return Err(OptionError::NoSuchNode {
                    text: kill.text.clone(),
                    node: d.node,
                    nodes,
                });
            }
            out.push(d);
        }
    }
    Ok(out)
}

/// What the serial backup line did, for the render's stats line ("" if it did not run).
pub fn backup_summary(r: &SimReport) -> String {
    let Some(b) = &r.backup else {
        return String::new();
    };
    format!(
        " | backup line: {} bytes in {} frames, busy {:.3} s, {} absent at roll call, nodes {:?} served, {} jobs and {} pixels over it",
        b.bytes,
        b.frames,
        b.busy_s,
        b.absent.len(),
        b.served,
        b.jobs,
        b.pixels
    )
}

/// What the faults did, for the render's stats line ("" without faults).
pub fn fault_summary(r: &SimReport) -> String {
    let root = &r.root;
    let corrupted: u64 = r.bus.iter().map(|b| b.corrupted()).sum();
    let dropped: u64 = r.bus.iter().map(|b| b.dropped_broadcast).sum();
    if root.timeouts == 0 && corrupted == 0 && dropped == 0 && root.repairs == 0 {
        return backup_summary(r) + &link_summary(r);
    }
    backup_summary(r) + &link_summary(r) + &format!(
        " | faults: {} declared dead ({} revived), {} sub-screens re-issued, time-out {:.3} s; {corrupted} messages corrupted, {} rejected by CRC at the RC; {dropped} broadcast copies lost, {} scene repairs",
        root.timeouts,
        root.revived,
        root.reissued,
        root.timeout_us as f64 * 1e-6,
        root.bad_messages,
        root.repairs
    )
}

/// What the firmware link's ends counted, for the render's stats line ("" on the idealised
/// link or when nothing went wrong).
pub fn link_summary(r: &SimReport) -> String {
    match &r.link {
        Some(c) if c.any() => format!(
            " | firmware link: {} NAKs, {} retransmits, {} bad node headers at the RC, {} bad RC headers and {} bad bodies at the nodes, {} not ready, {} no ack, {} RX overflows",
            c.naks,
            c.retransmits,
            c.rc_bad_headers,
            c.node_bad_headers,
            c.node_bad_bodies,
            c.not_ready,
            c.no_ack,
            c.overflows
        ),
        _ => String::new(),
    }
}

/// A cluster configuration from the command line's settings: the board profile's, with
/// the bit rate overridden if one is given and the topology's policy unless one is
/// ([`SimConfig::policy_for`]).
pub fn config(
    board: BoardProfile,
    nodes: u16,
    buses: Option<u16>,
    bit_rate_mhz: Option<f64>,
    policy: Option<Policy>,
    topology: TopologyArg,
) -> SimConfig {
    let topology = topology.topology(&board, nodes);
    let mut cfg = SimConfig {
        nodes,
        buses: buses.unwrap_or(topology.default_buses(&board)),
        policy: policy.unwrap_or(SimConfig::policy_for(topology)),
        topology,
        ..SimConfig::for_board(board)
    };
    if let Some(mhz) = bit_rate_mhz {
        cfg.timing.bit_rate_hz = mhz * 1e6;
    }
    cfg
}

/// Render one frame through the simulated cluster.
pub fn render(image: &[u8], cfg: &SimConfig) -> Result<ClusterRender, String> {
    render_cluster(image, cfg).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `config` at the board's bit rate with LINKS-1's decreasing sizes.
    fn decreasing(
        board: BoardProfile,
        nodes: u16,
        buses: Option<u16>,
        topology: TopologyArg,
    ) -> SimConfig {
        config(
            board,
            nodes,
            buses,
            None,
            Some(Policy::DECREASING),
            topology,
        )
    }

    #[test]
    fn policies_parse_and_bad_ones_say_why() {
        assert_eq!(parse_policy("decreasing"), Ok(Policy::DECREASING));
        assert_eq!(
            parse_policy("fixed=1024"),
            Ok(Policy::Fixed {
                divisions: 1024,
                shape: Split::Span
            })
        );
        assert_eq!(
            parse_policy("fixed-rect=64"),
            Ok(Policy::Fixed {
                divisions: 64,
                shape: Split::Rect
            })
        );
        assert_eq!(
            parse_policy("static"),
            Ok(Policy::Static { shape: Split::Rect })
        );
        assert!(parse_policy("fixed=0")
            .unwrap_err()
            .to_string()
            .contains("positive"));
        assert_eq!(
            parse_policy("decreasing=4,256"),
            Ok(Policy::Decreasing {
                factor: 4,
                min_pixels: 256
            })
        );
        assert_eq!(
            parse_policy("decreasing=6,128"),
            Ok(Policy::DECREASING),
            "the default spelled out"
        );
        for bad in [
            "decreasing=0,128",
            "decreasing=6,0",
            "decreasing=6",
            "decreasing=a,b",
        ] {
            let e = parse_policy(bad).unwrap_err().to_string();
            assert!(
                e.contains("decreasing=FACTOR,MIN takes two positive integers"),
                "{bad}: {e}"
            );
        }
        assert!(parse_policy("round-robin")
            .unwrap_err()
            .to_string()
            .contains("unknown policy"));
    }

    #[test]
    fn boards_parse_and_set_the_link() {
        assert_eq!(parse_board("F407"), Ok(BoardProfile::F407));
        assert_eq!(parse_board("f207"), Ok(BoardProfile::F207));
        assert_eq!(parse_board("G0B1"), Ok(BoardProfile::G0B1));
        let e = parse_board("f429").unwrap_err().to_string();
        assert!(
            e.contains("unknown board 'f429'") && e.contains("f407, f207, g0b1, ideal"),
            "{e}"
        );
        let star = TopologyArg::Star;
        let f = decreasing(BoardProfile::F407, 64, Some(1), star);
        assert_eq!(f.timing.bit_rate_hz, 21e6);
        assert_eq!((f.timing.header_bytes, f.timing.trailer_bytes), (8, 1));
        assert_eq!(f.timing.overhead_ns, 23_000.0);
        assert!(
            f.rc_double_buffer,
            "the F407's RC overlaps (spi::RC_OVERLAPS)"
        );
        assert_eq!(f.overloaded_bus(), Some(64));
        let text = board_text(&f);
        assert!(
            text.starts_with("board f407, firmware link: 21 MHz, 23.0 us"),
            "{text}"
        );
        assert_eq!(f.link, LinkModel::Firmware);
        assert!(topology_note(&f).contains("drives 8"));
        let i = config(
            BoardProfile::IDEAL,
            256,
            Some(1),
            Some(10.0),
            Some(Policy::DECREASING),
            star,
        );
        assert_eq!((i.timing.bit_rate_hz, i.timing.overhead_ns), (10e6, 500.0));
        assert!(i.rc_double_buffer && i.overloaded_bus().is_none());
        assert_eq!(i.link, LinkModel::Ideal);
        assert_eq!(parse_link("ideal"), Ok(LinkModel::Ideal));
        assert_eq!(parse_link("firmware"), Ok(LinkModel::Firmware));
        let e = parse_link("fast").unwrap_err().to_string();
        assert!(e.contains("unknown link 'fast'"), "{e}");
        assert_eq!(topology_note(&i), "");
        let eight = decreasing(BoardProfile::F407, 64, Some(8), star);
        assert_eq!(eight.overloaded_bus(), None);
    }

    #[test]
    fn pixel_codings_parse() {
        use links_core::wire::PixelCoding;
        assert_eq!(parse_pixel_coding("raw"), Ok(PixelCoding::Raw));
        assert_eq!(parse_pixel_coding("rle"), Ok(PixelCoding::Rle));
        assert_eq!(parse_pixel_coding("delta"), Ok(PixelCoding::Delta));
        let e = parse_pixel_coding("qoi").unwrap_err().to_string();
        assert!(e.contains("unknown pixel coding 'qoi'"), "{e}");
    }

    #[test]
    fn relay_codes_and_dead_relays_parse() {
        assert_eq!(parse_relay("model"), Ok(RelayCode::Model));
        assert_eq!(parse_relay("firmware"), Ok(RelayCode::Firmware));
        let e = parse_relay("fast").unwrap_err().to_string();
        assert!(e.contains("unknown relay code 'fast'"), "{e}");
        let d = relay_deaths(&["1@0.5".into(), "2-3@1".into()], 8).unwrap();
        assert_eq!(
            d.iter().map(|d| (d.node, d.at_s)).collect::<Vec<_>>(),
            [(1, 0.5), (2, 1.0), (3, 1.0)]
        );
        let e = relay_deaths(&["8@0".into()], 8).unwrap_err().to_string();
        assert!(
            e.contains("relay 8 does not exist (8 relays: 0 to 7)"),
            "{e}"
        );
        let e = relay_deaths(&["0@0".into()], 0).unwrap_err().to_string();
        assert!(e.contains("no relay tree"), "{e}");
        let mut f = config(
            BoardProfile::F407,
            64,
            None,
            None,
            Some(Policy::DECREASING),
            TopologyArg::Buildable,
        );
        f.relay = RelayCode::Firmware;
        assert_eq!(
            topology_text(&f),
            "relay tree: 8 relays x 8 nodes, 1 level(s) (the root on 2 buses), the firmware's relay code"
        );
    }

    #[test]
    fn topologies_parse_and_the_buildable_one_fits_the_board() {
        assert_eq!("relay".parse(), Ok(TopologyArg::Relay));
        let e = "ring".parse::<TopologyArg>().unwrap_err().to_string();
        assert!(e.contains("unknown topology 'ring'"), "{e}");
        let b = TopologyArg::Buildable;
        let f = decreasing(BoardProfile::F407, 64, None, b);
        assert_eq!(f.overloaded_bus(), None);
        assert_eq!(topology_note(&f), "");
        // The root drives its relays on the board's two root links unless told.
        assert_eq!(
            topology_text(&f),
            "relay tree: 8 relays x 8 nodes, 1 level(s) (the root on 2 buses), modelled relays (--relay firmware runs their code)"
        );
        let f = decreasing(BoardProfile::F407, 64, Some(1), b);
        assert_eq!(
            topology_text(&f),
            "relay tree: 8 relays x 8 nodes, 1 level(s), modelled relays (--relay firmware runs their code)"
        );
        let f = decreasing(BoardProfile::F407, 256, None, b);
        assert_eq!(
            topology_text(&f),
            "relay tree: 32 relays x 8 nodes, 2 level(s) (4 mid relays, the root on 2 buses), modelled relays (--relay firmware runs their code: 4 leaf relays per mid relay)"
        );
        let f = decreasing(BoardProfile::F407, 8, None, b);
        assert_eq!(topology_text(&f), "star, 1 bus(es)");
        let i = decreasing(BoardProfile::IDEAL, 256, None, b);
        assert_eq!(i.topology, Topology::Star);
    }

    /// Without `--policy` a relay tree's jobs are the firmware root of relays' sizes, a
    /// star's LINKS-1's defaults; the board's relay code is the firmware's where it runs.
    #[test]
    fn the_default_policy_and_relay_code_follow_the_topology() {
        let b = TopologyArg::Buildable;
        let tree = config(BoardProfile::F407, 64, None, None, None, b);
        assert_eq!(tree.policy, Policy::RELAYED);
        assert_eq!(policy_text(tree.policy), "decreasing=6,192");
        let star = config(BoardProfile::F407, 8, None, None, None, b);
        assert_eq!(star.policy, Policy::DECREASING);
        assert_eq!(policy_text(star.policy), "decreasing=6,128");
        assert_eq!(tree.clone().with_board_relays().relay, RelayCode::Firmware);
        let two_levels = config(BoardProfile::F407, 256, None, None, None, b);
        // Two levels too: `rc-fw --features relay-root-mid` drives middle relays on the
        // F407's two root links; it is not built for the F207's one.
        assert_eq!(two_levels.with_board_relays().relay, RelayCode::Firmware);
        let f207 = config(BoardProfile::F207, 256, None, None, None, b);
        assert_eq!(f207.with_board_relays().relay, RelayCode::Model);
        // The serial backup line is simulated with the model only.
        let line = SimConfig {
            backup_line: true,
            ..tree
        };
        assert_eq!(line.with_board_relays().relay, RelayCode::Model);
        assert_eq!(
            SimConfig::buildable(BoardProfile::F407, 64).relay,
            RelayCode::Firmware
        );
        for p in ["static", "fixed=12", "fixed-rect=64", "decreasing=4,256"] {
            assert_eq!(policy_text(parse_policy(p).unwrap()), p);
        }
    }

    #[test]
    fn deaths_parse_single_nodes_and_ranges() {
        assert_eq!(
            parse_deaths("3@0.25"),
            Ok(vec![NodeDeath {
                node: 3,
                at_s: 0.25
            }])
        );
        let r = parse_deaths("4-6@1").unwrap();
        assert_eq!(r.iter().map(|d| d.node).collect::<Vec<_>>(), vec![4, 5, 6]);
        assert!(r.iter().all(|d| d.at_s == 1.0));
        assert!(parse_deaths("6-4@1")
            .unwrap_err()
            .to_string()
            .contains("empty"));
        assert!(parse_deaths("3")
            .unwrap_err()
            .to_string()
            .contains("NODE@SECONDS"));
        assert!(parse_deaths("3@-1")
            .unwrap_err()
            .to_string()
            .contains(">= 0"));
        assert!(parse_deaths("x@1")
            .unwrap_err()
            .to_string()
            .contains("NODE@SECONDS"));
    }

    #[test]
    fn fault_options_are_checked_and_set() {
        let star = TopologyArg::Star;
        let mut cfg = config(
            BoardProfile::IDEAL,
            8,
            Some(1),
            Some(42.0),
            Some(Policy::DECREASING),
            star,
        );
        let args = FaultArgs {
            kills: vec!["2@0.1".into(), "5-7@0.2".into()],
            ber_down: 1e-4,
            ber_up: 2e-4,
            drop_broadcast: 0.1,
            fault_seed: 9,
            spi_dead: vec!["3@0.05".into()],
            backup_line: false,
            stuck_low: vec!["1@0.01".into()],
            stuck_high: vec!["4-5@0.02".into()],
        };
        apply_faults(&mut cfg, &args).unwrap();
        assert_eq!(
            cfg.stuck
                .iter()
                .map(|s| (s.node, s.at_s, s.high))
                .collect::<Vec<_>>(),
            vec![(1, 0.01, false), (4, 0.02, true), (5, 0.02, true)]
        );
        assert_eq!(
            cfg.spi_dead
                .iter()
                .map(|d| (d.node, d.at_s))
                .collect::<Vec<_>>(),
            vec![(3, 0.05)]
        );
        assert_eq!(
            cfg.noise,
            Noise {
                ber_down: 1e-4,
                ber_up: 2e-4,
                drop_broadcast: 0.1,
                seed: 9
            }
        );
        assert_eq!(
            cfg.deaths.iter().map(|d| d.node).collect::<Vec<_>>(),
            vec![2, 5, 6, 7]
        );
        let bad = |f: FaultArgs| apply_faults(&mut cfg.clone(), &f).unwrap_err().to_string();
        let e = bad(FaultArgs {
            kills: vec!["8@0.1".into()],
            ..args.clone()
        });
        assert!(
            e.contains("node 8 does not exist") && e.contains("0 to 7"),
            "{e}"
        );
        let e = bad(FaultArgs {
            ber_up: 0.7,
            ..args.clone()
        });
        assert!(e.starts_with("--ber-up 0.7"), "{e}");
        let e = bad(FaultArgs {
            ber_down: f64::NAN,
            ..args.clone()
        });
        assert!(e.starts_with("--ber-down NaN"), "{e}");
        let e = bad(FaultArgs {
            drop_broadcast: 1.0,
            ..args.clone()
        });
        assert!(e.starts_with("--drop-broadcast 1"), "{e}");
    }
}
