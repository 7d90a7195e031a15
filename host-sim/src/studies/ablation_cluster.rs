//! Table 5.2 on the simulated cluster, communication included.
//!
//! Each ablation variant's image is rendered by the cluster simulator
//! ([`crate::sim::cluster`]) on `nodes` node computers with the variant's techniques: the RC
//! broadcasts the scene into every node's bank, hands out sub-screens in job exchanges and
//! takes the pixel runs back, all in virtual time on the simulator's default board (bus
//! timing, RC cost, one bus). The policy is [`Policy::Fixed`] with span-shaped sub-screens:
//! with a division count that is a multiple of the height it cuts every row into the very
//! runs the modelled table renders ([`super::ablation::runs`]) and hands them out in the same
//! order, so the two tables differ by what the simulator adds: communication and the nodes'
//! waiting for it. Every cluster frame must equal the host render of the same image; a frame
//! that does not is an error, never a table cell.

use crate::sim::cluster::{simulate_frame, SimConfig, SimError, SimReport};
use crate::sim::single::{render_single, FrameError, Precision};
use crate::studies::ablation::{AblationConfig, Variant};
use links_core::render::Stats;
use links_core::sched::{Policy, Split};
use rayon::prelude::*;
use std::fmt;
use std::time::Instant;

/// One cell of the cluster table: a variant's frame on the simulated cluster.
#[derive(Clone, Debug)]
pub struct ClusterCell {
    pub variant: &'static str,
    pub divisions: u32,
    /// Virtual seconds until the frame is complete (broadcast, work, pixels back).
    pub seconds: f64,
    /// Node compute seconds summed over all nodes.
    pub compute_s: f64,
    /// Node efficiency: compute over nodes x frame time.
    pub efficiency: f64,
    /// Busy fraction of the (busiest) bus over the frame.
    pub bus_busy: f64,
    /// The SceneImage's bytes.
    pub image_bytes: usize,
    /// Broadcast payload bytes, summed over the buses: the scene's chunks with their
    /// headers, its end, roll calls and the final stop.
    pub broadcast_bytes: u64,
    /// Bytes clocked on all buses (headers, broadcast, exchanges both ways).
    pub bytes_moved: u64,
    /// Sub-screens the RC handed out.
    pub jobs: u32,
    /// Nodes the RC declared dead (silent past the time-out while holding jobs), and the
    /// jobs it handed out again because of it.
    pub timeouts: u32,
    pub reissued: u32,
    /// Operation counts summed over the nodes.
    pub stats: Stats,
    /// Host wall-clock seconds of the simulation.
    pub host_seconds: f64,
}

/// Why a cluster cell could not be measured.
#[derive(Debug)]
pub enum ClusterError {
    /// The simulator refused or could not finish the frame.
    Sim {
        variant: &'static str,
        divisions: u32,
        error: SimError,
    },
    /// The host reference render failed.
    Reference(FrameError),
    /// The cluster's frame differs from the host render of the same image.
    NotIdentical {
        variant: &'static str,
        divisions: u32,
        /// Pixels that differ, and the first of them (x, y).
        differing: usize,
        first: (u32, u32),
    },
}

impl fmt::Display for ClusterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ClusterError::Sim {
                variant,
                divisions,
                error,
            } => write!(
                f,
                "{variant} on the simulated cluster ({divisions} sub-screens): {error}"
            ),
            ClusterError::Reference(e) => write!(f, "host reference render: {e}"),
            ClusterError::NotIdentical {
                variant,
                divisions,
                differing,
                first: (x, y),
            } => write!(
                f,
                "{variant} on the simulated cluster ({divisions} sub-screens): {differing} \
                 pixels differ from the host render of the same image, the first at ({x}, {y})"
            ),
        }
    }
}

impl std::error::Error for ClusterError {}

/// The simulation of one cell: `nodes` nodes with the variant's techniques, the ablation's
/// cycle model and clock, fixed span sub-screens, the frame kept; everything else default.
pub fn sim_config(v: &Variant, divisions: u32, cfg: &AblationConfig) -> SimConfig {
    SimConfig {
        // More than u16 nodes is refused by the simulator like any count over 256.
        nodes: u16::try_from(cfg.nodes).unwrap_or(u16::MAX),
        policy: Policy::Fixed {
            divisions,
            shape: Split::Span,
        },
        model: cfg.model,
        clock_hz: cfg.clock_hz,
        techniques: v.techniques,
        keep_frames: true,
        // A type 4 sub-screen keeps a node busy for seconds (2.98 s on average at 480
        // divisions): with the default 0.5 s time-out the RC declares working nodes dead and
        // hands their work out twice. Nobody dies here, so no time-out fires.
        node_timeout_s: STUDY_NODE_TIMEOUT_S,
        ..SimConfig::default()
    }
}

/// The node time-out of the study's simulations: longer than any sub-screen takes.
pub const STUDY_NODE_TIMEOUT_S: f64 = 600.0;

/// The cell of a finished simulation.
pub fn cell_of(
    v: &Variant,
    divisions: u32,
    image_bytes: usize,
    r: &SimReport,
    host_seconds: f64,
) -> ClusterCell {
    ClusterCell {
        image_bytes,
        variant: v.name,
        divisions,
        seconds: r.time_s,
        compute_s: r.compute_s,
        efficiency: r.efficiency(),
        bus_busy: r.bus_utilisation(),
        broadcast_bytes: r.bus.iter().map(|b| b.broadcast_bytes).sum(),
        bytes_moved: r.bytes_moved(),
        jobs: r.root.jobs,
        timeouts: r.root.timeouts,
        reissued: r.root.reissued,
        stats: r.stats,
        host_seconds,
    }
}

/// The first differing pixel (x, y) of two RGB8 frames `width` wide, and how many differ.
fn compare(a: &[u8], b: &[u8], width: u32) -> Option<(usize, (u32, u32))> {
    if a.len() != b.len() {
        return Some((a.len().max(b.len()) / 3, (0, 0)));
    }
    let mut differing = a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .enumerate()
        .filter(|(_, (p, q))| p != q)
        .map(|(i, _)| i);
    let first = differing.next()?;
    let w = width.max(1) as usize;
    Some((
        1 + differing.count(),
        ((first % w) as u32, (first / w) as u32),
    ))
}

/// One cell to simulate: a variant, its compiled image, the host render of that image.
pub struct Job<'a> {
    pub variant: Variant,
    pub divisions: u32,
    pub image: &'a [u8],
    pub reference: &'a [u8],
}

/// Simulate one cell and check its frame against the reference.
pub fn run_job(job: &Job<'_>, cfg: &AblationConfig) -> Result<ClusterCell, ClusterError> {
    let v = &job.variant;
    let sim_err = |error| ClusterError::Sim {
        variant: v.name,
        divisions: job.divisions,
        error,
    };
    let start = Instant::now();
    let report = simulate_frame(job.image, &sim_config(v, job.divisions, cfg)).map_err(sim_err)?;
    let frame = report.frames.first().map_or(&[][..], |f| &f[..]);
    if let Some((differing, first)) = compare(frame, job.reference, report.width) {
        return Err(ClusterError::NotIdentical {
            variant: v.name,
            divisions: job.divisions,
            differing,
            first,
        });
    }
    Ok(cell_of(
        v,
        job.divisions,
        job.image.len(),
        &report,
        start.elapsed().as_secs_f64(),
    ))
}

/// The host render (all techniques, f32, every core) every cluster frame of `image` must
/// equal.
pub fn reference(image: &[u8]) -> Result<Vec<u8>, ClusterError> {
    render_single(image, Precision::F32, 0, &|| {})
        .map(|f| f.rgb)
        .map_err(ClusterError::Reference)
}

/// Simulate every job, several at a time on the host's threads (each simulation is
/// single-threaded). Jobs start in the order given (put the dearest first); `progress` is
/// told each as it starts. The cells come back in the order of `jobs`.
pub fn run_jobs(
    jobs: &[Job<'_>],
    cfg: &AblationConfig,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Vec<ClusterCell>, ClusterError> {
    let mut done: Vec<(usize, ClusterCell)> = jobs
        .iter()
        .enumerate()
        .par_bridge()
        .map(|(i, job)| {
            progress(&format!(
                "{} on {} simulated nodes ({} sub-screens)",
                job.variant.name, cfg.nodes, job.divisions
            ));
            run_job(job, cfg).map(|c| (i, c))
        })
        .collect::<Result<_, _>>()?;
    done.sort_by_key(|(i, _)| *i);
    Ok(done.into_iter().map(|(_, c)| c).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::studies::ablation::{run_ablation, VARIANTS};
    use links_core::dm::{compile, CompileOptions};

    /// The ablation of photo1 at 32x24 (sub-screens: 48 and 24) with its compiled images.
    fn tiny() -> (crate::studies::ablation::AblationReport, Vec<Vec<u8>>) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
        let desc = crate::scene_file::load_scene(&path).expect("photo1 loads");
        let cfg = AblationConfig {
            width: 32,
            height: 24,
            divisions: vec![48, 24],
            nodes: 4,
            ..AblationConfig::default()
        };
        let report = run_ablation(&desc, &cfg, &|_| {}).expect("the ablation runs");
        let images = VARIANTS
            .iter()
            .map(|v| {
                let opts = CompileOptions {
                    width: Some(32),
                    height: Some(24),
                    mesh_hierarchy: v.hierarchy,
                    transparency: v.transparency,
                    ..Default::default()
                };
                compile(&desc, &opts).expect("compiles").bytes
            })
            .collect();
        (report, images)
    }

    #[test]
    fn a_cluster_row_is_a_direct_simulation_with_the_variants_techniques() {
        let (report, images) = tiny();
        assert_eq!(report.cluster.len(), VARIANTS.len() * 2);
        for (v, image) in VARIANTS.iter().zip(&images) {
            for d in [48, 24] {
                let cell = report
                    .cluster_cell(v.name, d)
                    .expect("a cell per variant and row");
                let direct =
                    simulate_frame(image, &sim_config(v, d, &report.config)).expect("simulates");
                assert_eq!(cell.seconds, direct.time_s, "{} {d}", v.name);
                assert_eq!(cell.stats, direct.stats, "{} {d}", v.name);
                assert_eq!(cell.jobs, d, "{} {d}", v.name);
                assert_eq!(cell.image_bytes, image.len());
                assert_eq!(
                    cell.broadcast_bytes, direct.bus[0].broadcast_bytes,
                    "{} {d}",
                    v.name
                );
                // The same runs as the modelled table: the same operation counts.
                let modelled = report.cell(v.name, d).expect("modelled cell");
                assert_eq!(cell.stats, modelled.stats, "{} {d}", v.name);
                assert!(cell.seconds > modelled.seconds * 0.9, "{} {d}", v.name);
                // The techniques reach every node: the plain algorithm tests no box, the
                // others do; every node rendered something.
                let boxes: Vec<u64> = direct
                    .node_reports
                    .iter()
                    .map(|n| n.stats.box_tests)
                    .collect();
                if v.techniques.bounding_boxes {
                    assert!(boxes.iter().all(|&b| b > 0), "{} {d}: {boxes:?}", v.name);
                } else {
                    assert_eq!(boxes, vec![0; 4], "{} {d}", v.name);
                    assert!(direct.stats.triangle_tests > cell_of_type1(&report, d));
                }
            }
        }
    }

    /// Type 1's triangle tests in row `d`.
    fn cell_of_type1(report: &crate::studies::ablation::AblationReport, d: u32) -> u64 {
        report
            .cluster_cell("type 1", d)
            .map_or(u64::MAX, |c| c.stats.triangle_tests)
    }

    #[test]
    fn a_frame_that_differs_from_the_reference_fails_loudly() {
        let (report, images) = tiny();
        let mut wrong = reference(&images[0]).expect("renders");
        wrong[3 * (32 * 5 + 7)] ^= 1;
        let job = Job {
            variant: VARIANTS[0],
            divisions: 24,
            image: &images[0],
            reference: &wrong,
        };
        let e = run_job(&job, &report.config).unwrap_err();
        assert!(matches!(
            e,
            ClusterError::NotIdentical {
                differing: 1,
                first: (7, 5),
                ..
            }
        ));
        assert_eq!(
            e.to_string(),
            "type 1 on the simulated cluster (24 sub-screens): 1 pixels differ from the host \
             render of the same image, the first at (7, 5)"
        );
    }

    #[test]
    fn compare_counts_differing_pixels_and_finds_the_first() {
        let a = [0u8; 12];
        let mut b = a;
        assert_eq!(compare(&a, &b, 2), None);
        b[7] = 1; // pixel 2: (0, 1)
        b[9] = 1; // pixel 3: (1, 1)
        assert_eq!(compare(&a, &b, 2), Some((2, (0, 1))));
        assert_eq!(compare(&a, &b[..6], 2), Some((4, (0, 0))));
    }
}
