//! The simulated LINKS-1 cluster: the shared RC and NC logic (`links_core::{root, node}`)
//! over an emulated SPI star in deterministic virtual time.
//!
//! - [`exec`]: the discrete-event executor (virtual time, fixed poll order).
//! - [`backup`]: the serial backup line (RS-485) with nodes whose SPI link is dead.
//! - [`dm`]: the DM stage (each frame's scene appears after the DM's time for it).
//! - [`dmcost`]: the DM's time per frame from a model of its work.
//! - [`star`]: buses, ready lines, DMA banks, timing, fault injection, the snooping collector.
//! - [`spi_bus`]: the firmware's link (`links_core::spi`) over an emulated SPI peripheral,
//!   the default wherever the board frames transfers as the firmware does; [`star`] is then
//!   the idealised alternative (`LinkModel::Ideal`).
//! - [`framemem`]: the 1024 x 1024 RGB8 frame memory.
//! - [`rccost`]: the RC's CPU (composing, checking, decoding frames) in virtual time.
//! - [`relay`]: the topology: a star, or a tree of relay RCs (the links between RCs, the
//!   root's CPU, scene broadcasts stored and forwarded).
//! - `run`: one simulation stage by stage ([`simulate`], [`simulate_frame`],
//!   [`render_cluster`]).
//!
//! The sweeps over many simulations live in [`crate::studies`] ([`sweep`] and
//! [`reliability`] here are their old paths).
//!
//! Node compute time is [`CycleModel::cycles`] of each run's operation counts at the
//! configured core clock. A simulation is single-threaded and its results depend only on its
//! inputs; sweeps run independent simulations on several host threads.

pub mod backup;
mod backup_run;
pub mod dm;
pub mod dmcost;
pub mod exec;
pub mod framemem;
pub mod rccost;
pub mod relay;
mod relay_run;
mod run;
pub mod spi_bus;
pub mod star;
pub mod timeline;

pub use crate::studies::cluster_sweep as sweep;
pub use crate::studies::faults as reliability;
pub use backup_run::LineCounters;
pub use run::{render_cluster, simulate, simulate_frame, ClusterRender};
pub use sweep::{
    divisions_csv, nodes_csv, steady_state_interval, sweep_divisions, sweep_nodes,
    write_divisions_chart, write_nodes_chart, DivisionPoint, NamedPolicy, NodePoint,
};

use crate::cost::CycleModel;
use exec::ExecError;
use links_core::board::{BoardProfile, NodeBoard};
use links_core::node::{Kernels, NodeConfig, NodeReport};
use links_core::num::Storage;
use links_core::render::{Stats, Techniques};
use links_core::root::{RootError, RootReport};
use links_core::sched::Policy;
use links_core::wire::{self, Job};
use rccost::RcCost;
use relay::{FirmwareRelays, RelayCode, Topology, TreeReport, TreeShape};
use spi_bus::{FirmwareLinkCounters, LinkModel, StuckReady};
use star::{BroadcastDrop, BusCounters, BusTiming, Faults, NodeDeath, Noise};
use std::collections::HashMap;
use std::fmt;
use std::sync::{Arc, Mutex};
use timeline::Timeline;

/// How finished pixels reach the frame memory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Collect {
    /// The collector snoops every bus (IMSU snoop read): pixels never cross the RC.
    #[default]
    Snoop,
    /// The RC writes each accepted run into the frame memory.
    ViaRoot,
}

/// One simulation's set-up.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// The board the cluster is built of ([`SimConfig::for_board`] sets `timing`,
    /// `clock_hz`, `model`, `board`, `rc_cost` and `rc_double_buffer` from it; reports and
    /// figures name it). Default: the firmware's, [`BoardProfile::F407`].
    pub profile: BoardProfile,
    /// Node computers (1..=256).
    pub nodes: u16,
    /// SPI buses from the RC (1..=8) of a [`Topology::Star`]; nodes are split evenly
    /// across them. A relay tree has one bus per leaf relay instead, and this is the root's
    /// buses to its children (1, the buildable default; the F407 has SPI1/2/3).
    pub buses: u16,
    /// How the nodes are wired to the root. [`SimConfig::for_board`]: a star of `buses`
    /// buses; [`SimConfig::buildable`]: what the board can be built as.
    pub topology: Topology,
    /// Which code runs a relay tree's links above the leaf buses: the model
    /// ([`RelayCode::Model`], the default) or the firmware's relay code
    /// ([`RelayCode::Firmware`]: one level, one root bus, the firmware link). Ignored by a
    /// star.
    pub relay: RelayCode,
    /// Relays that stop answering (the firmware's relay code only): `node` is the relay's
    /// number (0 = the nodes 0.. of the first leaf bus); from `at_s` on its link to the
    /// root never re-arms, as a relay that lost power.
    pub relay_deaths: Vec<NodeDeath>,
    pub policy: Policy,
    pub timing: BusTiming,
    /// Which link the buses run: the firmware's `links_core::spi` over the emulated SPI
    /// peripheral ([`spi_bus`]), or the idealised star ([`star`]). Default: the firmware's
    /// wherever the profile frames transfers as the firmware does ([`LinkModel::for_link`]:
    /// the F407 board), the idealised star otherwise (the ideal board).
    pub link: LinkModel,
    /// Handshake lines that stick high or low (firmware link only).
    pub stuck: Vec<StuckReady>,
    /// Node core clock (Hz).
    pub clock_hz: f64,
    /// The weights a node's work on an f32 image is charged with.
    pub model: CycleModel,
    /// The weights a node's work on a Q16.16 image is charged with.
    pub fixed_model: CycleModel,
    /// The kernels every node carries: a scene of a storage none of them reads is refused
    /// before the run ([`SimError::NoKernel`]). Default: the profile's firmware's.
    pub kernels: Kernels,
    /// The speed techniques the nodes' tracers use (default: all). None changes a pixel;
    /// they change the operation counts and with them the nodes' compute time.
    pub techniques: Techniques,
    pub faults: Faults,
    /// Random bit errors per direction and lost broadcasts.
    pub noise: Noise,
    /// Nodes that die (stop answering) during the run.
    pub deaths: Vec<NodeDeath>,
    /// Nodes that lose some broadcasts whole (off the bus for a while, then back).
    pub drops: Vec<BroadcastDrop>,
    /// Nodes whose SPI link dies at a time while the node lives on: the RC declares them
    /// dead on SPI, finds them on the serial backup line and serves them there (nodes
    /// 0..64, the line's addresses). Turns the backup line on.
    pub spi_dead: Vec<NodeDeath>,
    /// Run the serial backup line ([`backup_run`]) even without `spi_dead` nodes: roll
    /// call at the start, and of every node the RC declares dead.
    pub backup_line: bool,
    /// The node board: a scene larger than its larger scene bank
    /// ([`NodeBoard::largest_bank`]) is refused before the run; the simulated nodes have two
    /// banks that size. Default: the profile's node (the NC firmware's board,
    /// [`nc_fw::plan::BOARD`], for [`BoardProfile::F407`]).
    pub board: NodeBoard,
    /// The RC declares a node holding jobs dead after this long without an exchange (s) and
    /// re-issues its jobs; 0 = never. Default: the board's
    /// ([`BoardProfile::node_timeout_us`]: 0.5 s on the F407).
    pub node_timeout_s: f64,
    /// DM time per frame (s): frame `f`'s scene exists from `(f + 1) · dm_s_per_frame` on.
    /// Default 0: every scene is compiled before the run (see docs/cluster.md).
    pub dm_s_per_frame: f64,
    /// The DM's time for each frame (s), in frame order: when not empty it replaces
    /// `dm_s_per_frame`, and frame `f`'s scene exists from the sum of its first `f + 1`
    /// entries on (a film's DM times from [`dmcost`]). One entry per frame.
    pub dm_frame_s: Vec<f64>,
    pub collect: Collect,
    /// Node options (run-length coded pixel runs).
    pub node: NodeConfig,
    /// The RC's CPU cost of composing and decoding frames.
    pub rc_cost: RcCost,
    /// RC-side DMA double buffering (compose the next transfer and decode the previous
    /// one while a transfer is on the wire); `false`: one transfer at a time.
    pub rc_double_buffer: bool,
    /// Keep a copy of every finished frame in the report.
    pub keep_frames: bool,
    /// Memo of rendered runs shared between simulations of the same scenes (sweeps). The
    /// memo returns exactly what rendering returns, so it changes no result.
    pub cache: Option<Arc<RunCache>>,
    /// Record a [`Timeline`] of at most this many intervals (`None`: no log).
    pub timeline: Option<usize>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self::for_board(BoardProfile::F407)
    }
}

impl SimConfig {
    /// The weights a node's work on an image stored as `storage` is charged with.
    pub fn model_for(&self, storage: Storage) -> CycleModel {
        match storage {
            Storage::F32 => self.model,
            Storage::Q16_16 => self.fixed_model,
        }
    }

    /// The default set-up on `profile`: its link's timing, its core's clock and cost-model
    /// weights, its node's scene banks, and an RC that overlaps the wire with its work only
    /// if the profile's does. 64 nodes, 1 bus, decreasing sizes, no faults.
    pub fn for_board(profile: BoardProfile) -> Self {
        Self {
            profile,
            nodes: 64,
            buses: 1,
            topology: Topology::Star,
            relay: RelayCode::Model,
            relay_deaths: Vec::new(),
            policy: Policy::DECREASING,
            timing: BusTiming::of(&profile.link),
            link: LinkModel::for_link(&profile.link),
            stuck: Vec::new(),
            clock_hz: profile.core_clock_hz as f64,
            model: CycleModel::for_kernel(profile.core, Storage::F32),
            fixed_model: CycleModel::for_kernel(profile.core, Storage::Q16_16),
            kernels: profile.kernels,
            techniques: Techniques::ALL,
            faults: Faults::default(),
            noise: Noise::default(),
            deaths: Vec::new(),
            drops: Vec::new(),
            spi_dead: Vec::new(),
            backup_line: false,
            board: profile.node,
            node_timeout_s: profile.node_timeout_us as f64 * 1e-6,
            dm_s_per_frame: 0.0,
            dm_frame_s: Vec::new(),
            collect: Collect::Snoop,
            node: NodeConfig::default(),
            rc_cost: RcCost::for_board(&profile),
            rc_double_buffer: profile.link.rc_overlaps,
            keep_frames: false,
            cache: None,
            timeline: None,
        }
    }

    /// `nodes` nodes on `profile` as the board can be built: a star of one bus while it
    /// holds them all, a relay tree otherwise ([`Topology::buildable`]) whose root drives
    /// its relays on the profile's root links
    /// ([`links_core::board::LinkProfile::root_links`]).
    ///
    /// Under a relay tree its jobs are [`Policy::RELAYED`]'s (as `rc-fw --features
    /// relay-root` divides them) and its relays run the firmware's relay code where it can
    /// ([`Self::with_board_relays`]).
    pub fn buildable(profile: BoardProfile, nodes: u16) -> Self {
        let topology = Topology::buildable(&profile, nodes);
        Self {
            nodes,
            topology,
            buses: topology.default_buses(&profile),
            policy: Self::policy_for(topology),
            ..Self::for_board(profile)
        }
        .with_board_relays()
    }

    /// The jobs' default sizes on `topology`: [`Policy::RELAYED`] under a relay tree (as the
    /// firmware's root of relays divides a frame), [`Policy::DECREASING`] on a star.
    pub const fn policy_for(topology: Topology) -> Policy {
        match topology {
            Topology::Star => Policy::DECREASING,
            Topology::RelayTree { .. } => Policy::RELAYED,
        }
    }

    /// This configuration with the relay code the board runs: the firmware's
    /// ([`RelayCode::Firmware`]) where the board's root of relays is built for the tree
    /// and the code can run it (one level of relays, as `rc-fw --features relay-root`
    /// builds the root, or two on a board whose root drives two links, as `relay-root-mid`
    /// builds it for the F407; the firmware link, the same node count behind every relay,
    /// no serial backup line; `relay_run::check`), the model otherwise.
    pub fn with_board_relays(self) -> Self {
        if self.topology == Topology::Star {
            return self;
        }
        let two_levels = self.tree().is_some_and(|t| t.is_ok_and(|t| t.levels() > 1));
        if two_levels && self.profile.link.root_links < 2 {
            return Self {
                relay: RelayCode::Model,
                ..self
            };
        }
        let firmware = Self {
            relay: RelayCode::Firmware,
            ..self
        };
        if relay_run::check(&firmware).is_ok() {
            firmware
        } else {
            Self {
                relay: RelayCode::Model,
                ..firmware
            }
        }
    }

    /// The relay tree's shape, if the topology is one (an error if it cannot be built).
    pub fn tree(&self) -> Option<Result<TreeShape, relay::TreeError>> {
        match self.topology {
            Topology::Star => None,
            Topology::RelayTree { fanout, .. } => Some(
                TreeShape::of(self.nodes, self.profile.link.nodes_per_bus, fanout)
                    .map(|t| t.with_roots(self.buses)),
            ),
        }
    }

    /// The middle relays of the tree as the relay code in the loop builds it: the
    /// firmware's (`relay_run::firmware_tree`: each drives as many leaf relays as its report
    /// to the root has bits for, 8 for 256 F407 nodes) or the model's (`TreeShape::mids`).
    pub fn mid_relays(&self) -> u16 {
        match (relay_run::firmware_tree(self), self.tree()) {
            (Some(fw), _) if fw.leaves_per_mid > 0 => fw.children,
            (_, Some(Ok(t))) => t.mids,
            _ => 0,
        }
    }

    /// The buses the nodes sit on: the star's, or one per leaf relay.
    pub fn node_buses(&self) -> u16 {
        match self.tree() {
            Some(Ok(t)) => t.leaves,
            _ => self.buses,
        }
    }

    /// Nodes on the busiest bus, if more than the profile's link drives
    /// ([`links_core::board::LinkProfile::nodes_per_bus`]): a star the board cannot be
    /// wired as.
    pub fn overloaded_bus(&self) -> Option<u16> {
        let buses = self.node_buses().clamp(1, self.nodes.max(1));
        let per_bus = self.nodes.div_ceil(buses);
        (per_bus > self.profile.link.nodes_per_bus).then_some(per_bus)
    }
}

/// What a simulation measured (all times virtual).
#[derive(Clone, Debug)]
pub struct SimReport {
    /// The board profile it ran on.
    pub profile: BoardProfile,
    pub nodes: u16,
    pub buses: u16,
    pub policy: Policy,
    pub width: u32,
    pub height: u32,
    /// Completion time of each frame (s).
    pub frame_done_s: Vec<f64>,
    /// Time of the last frame's completion (s).
    pub time_s: f64,
    /// Compute time summed over all nodes (s): the work a single node would do alone,
    /// without any communication.
    pub compute_s: f64,
    /// Compute time of each node (s).
    pub node_compute_s: Vec<f64>,
    /// Time the RC's CPU was busy composing and decoding frames (s).
    pub rc_busy_s: f64,
    pub bus: Vec<BusCounters>,
    pub root: RootReport,
    pub node_reports: Vec<NodeReport>,
    /// The frames (RGB8 rows) if `keep_frames`.
    pub frames: Vec<Vec<u8>>,
    /// Operation counts summed over all nodes.
    pub stats: Stats,
    /// The event log, if [`SimConfig::timeline`] asked for one.
    pub timeline: Option<Timeline>,
    /// The relay tree's links and root, if the topology is one. `rc_busy_s` is then the
    /// leaf relays' CPU time summed.
    pub tree: Option<TreeReport>,
    /// What the firmware's relay code did, if it ran ([`RelayCode::Firmware`]; `tree` then
    /// has the root link's traffic and the root's CPU).
    pub relayed: Option<FirmwareRelays>,
    /// What the serial backup line did, if it ran.
    pub backup: Option<LineCounters>,
    /// What the firmware link's two ends counted (NAKs, retransmits, refused headers), if
    /// it ran.
    pub link: Option<FirmwareLinkCounters>,
}

impl SimReport {
    /// Busy fraction of the busiest bus over the whole run.
    pub fn bus_utilisation(&self) -> f64 {
        let t = self.time_s * 1e12;
        self.bus
            .iter()
            .map(|b| b.busy_ps as f64 / t)
            .fold(0.0, f64::max)
    }
    /// Bytes clocked on all buses.
    pub fn bytes_moved(&self) -> u64 {
        self.bus.iter().map(|b| b.clocked_bytes).sum()
    }
    /// Steady-state time per frame: mean interval between frame completions after the
    /// first (the first frame's time if there is only one).
    pub fn frame_interval_s(&self) -> f64 {
        match self.frame_done_s.as_slice() {
            [] => 0.0,
            [t] => *t,
            [first, .., last] => (last - first) / (self.frame_done_s.len() - 1) as f64,
        }
    }
    /// Busy fraction of one RC's CPU: the star's RC, or the mean leaf relay.
    pub fn rc_utilisation(&self) -> f64 {
        let rcs = if self.tree.is_some() {
            self.buses.max(1)
        } else {
            1
        };
        self.rc_busy_s / (rcs as f64 * self.time_s)
    }
    /// Node efficiency: compute time over nodes x elapsed time.
    pub fn efficiency(&self) -> f64 {
        self.compute_s / (self.nodes as f64 * self.time_s)
    }
}

/// Why a simulation could not run or finish.
#[derive(Debug)]
pub enum SimError {
    Config(String),
    /// Frame `frame`'s scene image (`bytes`) does not fit the scene bank (`bank` bytes) of
    /// the node board `node` ([`SimConfig::board`]); found before the cluster starts.
    SceneTooBig {
        frame: u16,
        bytes: usize,
        node: &'static str,
        bank: usize,
    },
    Root(RootError),
    /// The cluster could not finish: what it waited for when the simulation stopped.
    Unfinished(Box<Unfinished>),
    /// A frame differs from the single-node render (a broken promise, never expected).
    NotIdentical {
        what: String,
    },
    /// Frame `frame`'s scene is stored as `image`, which none of the nodes' kernels reads
    /// ([`SimConfig::kernels`]), or its storage differs from frame 0's (`mixed`).
    NoKernel {
        frame: u16,
        image: Storage,
        kernels: Kernels,
        mixed: bool,
    },
    /// An error of one point of a sweep.
    Context {
        what: String,
        error: Box<SimError>,
    },
}

/// What a cluster that cannot finish lacks, when the simulation stopped (stalled, no pixel
/// accepted for a long time, or past its time limit).
#[derive(Clone, Debug)]
pub struct Unfinished {
    /// Why the simulation stopped.
    pub cause: ExecError,
    /// The first frame not complete, and how many frames there are.
    pub frame: u16,
    pub frames: u16,
    /// Sub-screens handed out and never returned: (holder, job, holder declared dead).
    pub never_returned: Vec<(u16, Job, bool)>,
    /// Sub-screens of the frame being handed out (`handing_out`) never handed out.
    pub unissued: u32,
    pub handing_out: u16,
    /// Static split: nodes whose region of that frame still waits for them to ask.
    pub reserved_for: Vec<u16>,
    /// Nodes the RC has declared dead.
    pub declared_dead: Vec<u16>,
    /// Nodes not killed that never reported the scene of the frame being handed out.
    pub no_scene: Vec<u16>,
    /// Nodes killed by fault injection: (node, when, s).
    pub killed: Vec<(u16, f64)>,
}

/// "node 3" or "nodes 0, 1, 2" (at most 12 listed).
fn node_list(nodes: &[u16]) -> String {
    let mut s = String::from(if nodes.len() == 1 { "node " } else { "nodes " });
    let shown: Vec<String> = nodes.iter().take(12).map(|n| n.to_string()).collect();
    s.push_str(&shown.join(", "));
    if nodes.len() > 12 {
        s.push_str(&format!(" and {} more", nodes.len() - 12));
    }
    s
}

fn region_text(r: &wire::Region) -> String {
    match *r {
        wire::Region::Span { start, len } => format!("pixels {start}..{}", start + len),
        wire::Region::Rect { x, y, w, h } => format!("{w}x{h} at ({x}, {y})"),
    }
}

impl fmt::Display for Unfinished {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the cluster cannot finish frame {} of {}",
            self.frame, self.frames
        )?;
        let mut parts: Vec<String> = Vec::new();
        if !self.never_returned.is_empty() {
            let items: Vec<String> = self
                .never_returned
                .iter()
                .take(8)
                .map(|(n, j, dead)| {
                    format!(
                        "frame {} {} held by node {n}{}",
                        j.frame,
                        region_text(&j.region),
                        if *dead { " (declared dead)" } else { "" }
                    )
                })
                .collect();
            let more = self.never_returned.len().saturating_sub(8);
            parts.push(format!(
                "{} sub-screen(s) never returned: {}{}",
                self.never_returned.len(),
                items.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            ));
        }
        if self.unissued > 0 {
            let mut s = format!(
                "{} sub-screen(s) of frame {} never handed out",
                self.unissued, self.handing_out
            );
            if !self.reserved_for.is_empty() {
                s.push_str(&format!(
                    " (static regions of {}, who never asked)",
                    node_list(&self.reserved_for)
                ));
            }
            parts.push(s);
        }
        if !self.declared_dead.is_empty() {
            parts.push(format!("{} declared dead", node_list(&self.declared_dead)));
        }
        if !self.no_scene.is_empty() {
            parts.push(format!(
                "{} never reported frame {}'s scene",
                node_list(&self.no_scene),
                self.handing_out
            ));
        }
        if !self.killed.is_empty() {
            let items: Vec<String> = self
                .killed
                .iter()
                .take(12)
                .map(|(n, t)| format!("node {n} killed at {t:.3} s"))
                .collect();
            let more = self.killed.len().saturating_sub(12);
            parts.push(format!(
                "{}{}",
                items.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            ));
        }
        if parts.is_empty() {
            parts.push("nothing is pending (the RC's last broadcast was lost)".into());
        }
        write!(f, ": {} (the simulation {})", parts.join("; "), self.cause)
    }
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimError::Config(s) => write!(f, "{s}"),
            SimError::SceneTooBig {
                frame,
                bytes,
                node,
                bank,
            } => write!(
                f,
                "frame {frame}'s scene image is {bytes} bytes; the {node} node's scene bank holds {bank} bytes: make the scene smaller (fewer triangles, a smaller texture)"
            ),
            SimError::NoKernel {
                frame,
                image,
                mixed: true,
                ..
            } => write!(
                f,
                "frame {frame}'s scene is {}, frame 0's is not: a run renders one storage",
                image.name()
            ),
            SimError::NoKernel {
                frame,
                image,
                kernels,
                mixed: false,
            } => write!(
                f,
                "frame {frame}'s scene is {} but the nodes carry {kernels} only (--node-kernels)",
                image.name()
            ),
            SimError::Root(e) => write!(f, "root: {e}"),
            SimError::Unfinished(u) => write!(f, "{u}"),
            SimError::NotIdentical { what } => {
                write!(f, "{what}: the frame differs from the single-node render")
            }
            SimError::Context { what, error } => write!(f, "{what}: {error}"),
        }
    }
}

impl std::error::Error for SimError {}

/// (scene CRC, techniques, y, x, length) of a run.
type RunKey = (u32, u8, u32, u32, u32);

/// The techniques as a key: one bit each (the same run costs differently under each set).
fn techniques_key(t: Techniques) -> u8 {
    u8::from(t.bounding_boxes)
        | u8::from(t.y_clip) << 1
        | u8::from(t.x_clip) << 2
        | u8::from(t.shadow_early_exit) << 3
}

/// Memo of rendered runs keyed by (scene CRC, techniques, y, x, length).
#[derive(Default)]
pub struct RunCache {
    map: Mutex<HashMap<RunKey, (Vec<u8>, Stats)>>,
}

impl fmt::Debug for RunCache {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.map.lock().map(|m| m.len()).unwrap_or(0);
        write!(f, "RunCache({n} runs)")
    }
}

impl RunCache {
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }
}
