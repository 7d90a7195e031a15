//! A film on the simulated cluster, as LINKS-1 made one: the DM compiles every frame
//! ([`Film::compile_frame`]; its time charged by the [`dmcost`] model, so frame `f`'s scene
//! exists once the DM has spent the time of frames `0..=f`), and ONE simulation renders all
//! the frames, so the RC broadcasts frame `n + 1` into the nodes' other scene bank while frame
//! `n` renders ([`crate::cluster::simulate`]). The steady-state interval is the mean time
//! between frame completions after the first ([`SimReport::frame_interval_s`]); the speed-up
//! is against the same film on one node (same board, same DM).

use std::ops::Range;

use links_core::anim::{Film, FrameError};
use links_core::dm::CompileOptions;
use links_core::image::SceneView;

use super::cluster::dmcost::{self, DmCost, DmMachine};
use super::cluster::relay::Topology;
use super::cluster::{simulate, SimConfig, SimError, SimReport};

/// The DM's output for a range of frames: each frame's SceneImage and the instructions the
/// [`dmcost`] model charges for it.
#[derive(Clone, Debug)]
pub struct FilmImages {
    /// The film's frame number of `images[0]`.
    pub first: u32,
    pub images: Vec<Vec<u8>>,
    pub dm_instructions: Vec<f64>,
}

impl FilmImages {
    /// Mean SceneImage size (bytes).
    pub fn mean_bytes(&self) -> f64 {
        let total: usize = self.images.iter().map(Vec::len).sum();
        total as f64 / self.images.len().max(1) as f64
    }
}

/// Why a film could not be compiled or simulated.
#[derive(Debug)]
pub enum FilmError {
    Frame(FrameError),
    /// A compiled frame does not read back as a SceneImage (a DM bug).
    Image {
        frame: u32,
        message: String,
    },
    Sim(SimError),
}

impl std::fmt::Display for FilmError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FilmError::Frame(e) => write!(f, "{e}"),
            FilmError::Image { frame, message } => write!(f, "frame {frame}: {message}"),
            FilmError::Sim(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for FilmError {}

/// The DM's work for frames `frames` of `film`: every frame compiled, and its cost.
pub fn compile_film(
    film: &Film,
    frames: Range<u32>,
    opts: &CompileOptions,
    cost: &DmCost,
) -> Result<FilmImages, FilmError> {
    let mut images = Vec::new();
    let mut dm_instructions = Vec::new();
    for f in frames.clone() {
        let bytes = film.compile_frame(f, opts).map_err(FilmError::Frame)?.bytes;
        let view = SceneView::new(&bytes).map_err(|e| FilmError::Image {
            frame: f,
            message: format!("{e:?}"),
        })?;
        dm_instructions.push(cost.instructions(&view));
        images.push(bytes);
    }
    Ok(FilmImages {
        first: frames.start,
        images,
        dm_instructions,
    })
}

/// One simulation of a whole film, with its one-node reference.
#[derive(Clone, Debug)]
pub struct FilmRun {
    pub report: SimReport,
    /// The same film on one node (no faults): its report.
    pub one_node: SimReport,
    pub machine: DmMachine,
    /// The DM's time was the fixed `dm_s_per_frame`, not the model's.
    pub fixed_dm: bool,
    /// The DM's time for each frame (s).
    pub dm_s: Vec<f64>,
}

impl FilmRun {
    /// Steady-state time per frame (s): mean interval between frame completions after the
    /// first (the frame time for a one-frame film).
    pub fn steady_s(&self) -> f64 {
        self.report.frame_interval_s()
    }

    /// The one-node reference's steady-state time per frame (s).
    pub fn one_node_steady_s(&self) -> f64 {
        self.one_node.frame_interval_s()
    }

    /// Steady-state speed-up against one node.
    pub fn speedup(&self) -> f64 {
        self.one_node_steady_s() / self.steady_s()
    }

    /// Mean DM time per frame (s).
    pub fn dm_s_per_frame(&self) -> f64 {
        self.dm_s.iter().sum::<f64>() / self.dm_s.len().max(1) as f64
    }

    /// Broadcast payload per frame, all buses (bytes).
    pub fn broadcast_bytes_per_frame(&self) -> f64 {
        let total: u64 = self.report.bus.iter().map(|b| b.broadcast_bytes).sum();
        total as f64 / self.report.frame_done_s.len().max(1) as f64
    }
}

/// Simulates `film` on `cfg`'s cluster with the DM on `machine` (`cfg.dm_frame_s` is set
/// from the film's DM costs; a fixed `cfg.dm_s_per_frame` > 0 replaces the model), and the
/// same on one node for the speed-up.
pub fn simulate_film(
    film: &FilmImages,
    cfg: &SimConfig,
    machine: DmMachine,
) -> Result<FilmRun, SimError> {
    let fixed_dm = cfg.dm_s_per_frame > 0.0;
    let dm_s: Vec<f64> = if fixed_dm {
        vec![cfg.dm_s_per_frame; film.images.len()]
    } else {
        film.dm_instructions
            .iter()
            .map(|&i| machine.seconds(i))
            .collect()
    };
    let cache = cfg.cache.clone().unwrap_or_default();
    let cfg = SimConfig {
        dm_frame_s: dm_s.clone(),
        cache: Some(cache),
        ..cfg.clone()
    };
    let report = simulate(&film.images, &cfg)?;
    let one = SimConfig {
        nodes: 1,
        buses: 1,
        topology: Topology::Star,
        keep_frames: false,
        deaths: Vec::new(),
        relay_deaths: Vec::new(),
        timeline: None,
        ..cfg
    };
    let one_node = simulate(&film.images, &one)?;
    Ok(FilmRun {
        report,
        one_node,
        machine,
        fixed_dm,
        dm_s,
    })
}

/// The DM model's name and weights, for reports.
pub fn dm_model_note() -> String {
    let c = dmcost::DmCost::ESTIMATE;
    format!(
        "DM cost model (estimate, host-sim/src/sim/cluster/dmcost.rs): {} + {}/byte + {}/node + \
         {}/vertex + {}/triangle + {}/shape instructions",
        c.fixed, c.per_byte, c.per_node, c.per_vertex, c.per_triangle, c.per_shape
    )
}
