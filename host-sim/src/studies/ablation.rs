//! The analog of LINKS-1's Table 5.2: what each speed technique is worth, in modelled node
//! time.
//!
//! For each technique set ("type") the frame is rendered run by run, exactly as node
//! computers would receive it: the screen is cut into `divisions` sub-screens (each a run of
//! pixels on one scanline, as in the paper), every run is rendered by a fresh node-side
//! tracer, and its operation counts become cycles through the [`CycleModel`]. The runs are
//! then handed out in order to `nodes` node computers, each taking the next run when it
//! finishes (LINKS-1's dynamic division), and the modelled time is when the last one ends.
//! RC-NC communication is not included in that table; beside it, every cell is run again on
//! the simulated cluster, communication included ([`super::ablation_cluster`]). Host wall
//! time is reported beside the model, never instead of it.

use crate::cost::{CycleModel, DEFAULT_CLOCK_HZ};
use crate::studies::ablation_cluster::{self, ClusterCell, ClusterError, Job};
use crate::studies::report::table_head;
use links_core::desc::{SceneDesc, TransparencyMode};
use links_core::dm::{compile, CompileOptions, DmError, MeshHierarchy};
use links_core::image::SceneView;
use links_core::render::{render_run, Stats, Techniques, Tracer};
use rayon::prelude::*;
use std::time::Instant;

/// One column of the table.
#[derive(Clone, Copy, Debug)]
pub struct Variant {
    pub name: &'static str,
    pub what: &'static str,
    pub techniques: Techniques,
    pub hierarchy: MeshHierarchy,
    pub transparency: Option<TransparencyMode>,
}

/// The paper's four types (over its flat mesh clusters) and ours.
pub const VARIANTS: [Variant; 6] = [
    Variant {
        name: "type 1",
        what: "all of the paper's techniques: boxes, Y and X clipping",
        techniques: Techniques::PAPER_TYPE_1,
        hierarchy: MeshHierarchy::Flat,
        transparency: None,
    },
    Variant {
        name: "type 2",
        what: "no X clipping",
        techniques: Techniques::PAPER_TYPE_2,
        hierarchy: MeshHierarchy::Flat,
        transparency: None,
    },
    Variant {
        name: "type 3",
        what: "no X and no Y clipping",
        techniques: Techniques::PAPER_TYPE_3,
        hierarchy: MeshHierarchy::Flat,
        transparency: None,
    },
    Variant {
        name: "type 4",
        what: "no clipping and no bounding boxes (the plain algorithm)",
        techniques: Techniques::PAPER_TYPE_4,
        hierarchy: MeshHierarchy::Flat,
        transparency: None,
    },
    Variant {
        name: "BVH",
        what: "type 1 with a SAH BVH inside each mesh cluster",
        techniques: Techniques::PAPER_TYPE_1,
        hierarchy: MeshHierarchy::Sah,
        transparency: None,
    },
    Variant {
        name: "BVH+exit",
        what: "BVH plus early shadow-ray exit (every technique)",
        techniques: Techniques::ALL,
        hierarchy: MeshHierarchy::Sah,
        transparency: None,
    },
];

#[derive(Clone, Debug)]
pub struct AblationConfig {
    pub width: u32,
    pub height: u32,
    /// Sub-screen counts (table rows); each must be a multiple of the height.
    pub divisions: Vec<u32>,
    /// Node computers, of the model and of the simulated cluster.
    pub nodes: u32,
    pub model: CycleModel,
    pub clock_hz: f64,
}

impl Default for AblationConfig {
    fn default() -> Self {
        Self {
            width: 512,
            height: 480,
            divisions: vec![2400, 480],
            nodes: 16,
            model: CycleModel::CORTEX_M4F_F32,
            clock_hz: DEFAULT_CLOCK_HZ,
        }
    }
}

/// One cell: a variant rendered with one division count.
#[derive(Clone, Debug)]
pub struct Cell {
    pub variant: &'static str,
    pub divisions: u32,
    /// Modelled seconds until the last of `nodes` node computers finishes.
    pub seconds: f64,
    /// Modelled seconds of all work on one node.
    pub total_seconds: f64,
    pub stats: Stats,
    /// Host wall-clock seconds of the renders behind the cell.
    pub host_seconds: f64,
}

#[derive(Clone, Debug)]
pub struct AblationReport {
    pub config: AblationConfig,
    pub cells: Vec<Cell>,
    /// Type 1 at the first division count with refractive transparency instead.
    pub refractive: Cell,
    /// The same cells on the simulated cluster, communication included.
    pub cluster: Vec<ClusterCell>,
}

#[derive(Debug)]
pub enum AblationError {
    Compile(DmError),
    Image(links_core::image::ImageError),
    BadDivisions { divisions: u32, height: u32 },
    Cluster(ClusterError),
}

impl std::fmt::Display for AblationError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AblationError::Compile(e) => write!(f, "{e}"),
            AblationError::Image(e) => write!(f, "{e}"),
            AblationError::BadDivisions { divisions, height } => write!(
                f,
                "{divisions} sub-screens can't be cut from {height} rows: use a multiple of the height"
            ),
            AblationError::Cluster(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for AblationError {}

/// The runs of one division count: `(y, x, len)`, row-major, each row cut into equal parts.
pub fn runs(
    width: u32,
    height: u32,
    divisions: u32,
) -> Result<Vec<(u32, u32, u32)>, AblationError> {
    if divisions == 0 || !divisions.is_multiple_of(height) || divisions / height > width {
        return Err(AblationError::BadDivisions { divisions, height });
    }
    let per_row = divisions / height;
    let mut out = Vec::with_capacity(divisions as usize);
    for y in 0..height {
        for k in 0..per_row {
            let x0 = width * k / per_row;
            let x1 = width * (k + 1) / per_row;
            out.push((y, x0, x1 - x0));
        }
    }
    Ok(out)
}

/// Render every run with a fresh tracer and return each run's counts.
fn run_costs(
    image: &[u8],
    techniques: Techniques,
    runs: &[(u32, u32, u32)],
) -> Result<Vec<Stats>, AblationError> {
    let view = SceneView::new(image).map_err(AblationError::Image)?;
    Ok(runs
        .par_iter()
        .map(|&(y, x, len)| {
            let mut tracer = Tracer::<f32>::with_techniques(view, techniques);
            let mut px = vec![[0u8; 3]; len as usize];
            // Runs come from `runs()`, so they always lie inside the frame.
            let _ = render_run(&mut tracer, y, x, &mut px);
            tracer.stats
        })
        .collect())
}

/// Hand runs out in order to the first free node; the time the last node finishes.
pub fn makespan(cycles: &[u64], nodes: u32) -> u64 {
    let mut free_at = vec![0u64; nodes.max(1) as usize];
    for &c in cycles {
        // The node that becomes free first (lowest index on ties) takes the next run.
        let (i, _) = free_at
            .iter()
            .enumerate()
            .min_by_key(|&(i, t)| (*t, i))
            .unwrap_or((0, &0));
        free_at[i] += c;
    }
    free_at.into_iter().max().unwrap_or(0)
}

fn cell(
    variant: &'static str,
    divisions: u32,
    per_run: &[Stats],
    cfg: &AblationConfig,
    host_seconds: f64,
) -> Cell {
    let cycles: Vec<u64> = per_run.iter().map(|s| cfg.model.cycles(s)).collect();
    let mut stats = Stats::default();
    per_run.iter().for_each(|s| stats.add(s));
    Cell {
        variant,
        divisions,
        seconds: makespan(&cycles, cfg.nodes) as f64 / cfg.clock_hz,
        total_seconds: cycles.iter().sum::<u64>() as f64 / cfg.clock_hz,
        stats,
        host_seconds,
    }
}

/// Merge consecutive groups of `k` runs' counts (finer runs -> coarser runs), valid for
/// techniques whose per-pixel work does not depend on the run (no Y clipping).
fn merge_runs(per_run: &[Stats], k: usize) -> Vec<Stats> {
    per_run
        .chunks(k)
        .map(|c| {
            let mut s = Stats::default();
            c.iter().for_each(|x| s.add(x));
            s
        })
        .collect()
}

/// Build the table. `progress` is told each step's name as it starts.
pub fn run_ablation(
    desc: &SceneDesc,
    cfg: &AblationConfig,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<AblationReport, AblationError> {
    let compile_with = |h: MeshHierarchy, t: Option<TransparencyMode>| {
        let opts = CompileOptions {
            width: Some(cfg.width),
            height: Some(cfg.height),
            mesh_hierarchy: h,
            transparency: t,
            ..Default::default()
        };
        compile(desc, &opts)
            .map(|c| c.bytes)
            .map_err(AblationError::Compile)
    };
    let finest = *cfg.divisions.iter().max().unwrap_or(&cfg.height);
    let fine_runs = runs(cfg.width, cfg.height, finest)?;
    let mut cells = Vec::new();
    let mut images = Vec::new();
    for v in VARIANTS {
        images.push(compile_with(v.hierarchy, v.transparency)?);
        let image = images.last().map_or(&[][..], |i| &i[..]);
        if v.techniques.y_clip {
            // Y clipping happens per run: each division count is its own render.
            for &d in &cfg.divisions {
                progress(&format!("{} ({d} sub-screens)", v.name));
                let start = Instant::now();
                let per_run = run_costs(image, v.techniques, &runs(cfg.width, cfg.height, d)?)?;
                cells.push(cell(
                    v.name,
                    d,
                    &per_run,
                    cfg,
                    start.elapsed().as_secs_f64(),
                ));
            }
        } else {
            // The same pixels cost the same however the screen is cut: render the finest
            // division once and merge runs for the coarser ones.
            progress(&format!("{} (all division counts)", v.name));
            let start = Instant::now();
            let per_run = run_costs(image, v.techniques, &fine_runs)?;
            let host = start.elapsed().as_secs_f64();
            for &d in &cfg.divisions {
                runs(cfg.width, cfg.height, d)?;
                let merged = merge_runs(&per_run, (finest / d) as usize);
                cells.push(cell(v.name, d, &merged, cfg, host));
            }
        }
    }
    progress("type 1, refractive transparency");
    let image = compile_with(MeshHierarchy::Flat, Some(TransparencyMode::Refractive))?;
    let start = Instant::now();
    let per_run = run_costs(
        &image,
        Techniques::PAPER_TYPE_1,
        &runs(cfg.width, cfg.height, finest)?,
    )?;
    let refractive = cell(
        "type 1 refractive",
        finest,
        &per_run,
        cfg,
        start.elapsed().as_secs_f64(),
    );
    let cluster = cluster_cells(&images, &cells, cfg, progress)?;
    Ok(AblationReport {
        config: cfg.clone(),
        cells,
        refractive,
        cluster,
    })
}

/// Every cell again on the simulated cluster (`images[i]` is `VARIANTS[i]`'s image), each
/// frame checked against the host render of its image; the dearest cells (by modelled
/// node time) start first. The cells come back in table order.
fn cluster_cells(
    images: &[Vec<u8>],
    modelled: &[Cell],
    cfg: &AblationConfig,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Vec<ClusterCell>, AblationError> {
    let mut refs: Vec<(&[u8], Vec<u8>)> = Vec::new();
    for image in images {
        if !refs.iter().any(|(i, _)| *i == &image[..]) {
            progress("the host reference render of an image");
            let r = ablation_cluster::reference(image).map_err(AblationError::Cluster)?;
            refs.push((image, r));
        }
    }
    let reference = |image: &[u8]| {
        refs.iter()
            .find(|(i, _)| *i == image)
            .map_or(&[][..], |(_, r)| &r[..])
    };
    let mut jobs: Vec<(usize, f64, Job<'_>)> = Vec::new();
    for (v, image) in VARIANTS.iter().zip(images) {
        for &divisions in &cfg.divisions {
            let cost = modelled
                .iter()
                .find(|c| c.variant == v.name && c.divisions == divisions)
                .map_or(0.0, |c| c.total_seconds);
            let job = Job {
                variant: *v,
                divisions,
                image,
                reference: reference(image),
            };
            jobs.push((jobs.len(), cost, job));
        }
    }
    jobs.sort_by(|a, b| b.1.total_cmp(&a.1));
    let (order, jobs): (Vec<usize>, Vec<Job<'_>>) =
        jobs.into_iter().map(|(i, _, job)| (i, job)).unzip();
    let cells = ablation_cluster::run_jobs(&jobs, cfg, progress).map_err(AblationError::Cluster)?;
    let mut cells: Vec<(usize, ClusterCell)> = order.into_iter().zip(cells).collect();
    cells.sort_by_key(|(i, _)| *i);
    Ok(cells.into_iter().map(|(_, c)| c).collect())
}

impl AblationReport {
    pub fn cell(&self, variant: &str, divisions: u32) -> Option<&Cell> {
        self.cells
            .iter()
            .find(|c| c.variant == variant && c.divisions == divisions)
    }

    /// The Table 5.2 analog as Markdown: modelled seconds and ratios to type 1.
    pub fn table(&self) -> String {
        let mut s =
            table_head(std::iter::once("sub-screens").chain(VARIANTS.iter().map(|v| v.name)));
        for &d in &self.config.divisions {
            let base = self.cell("type 1", d).map_or(f64::NAN, |c| c.seconds);
            s.push_str(&format!("| {d} |"));
            for v in VARIANTS {
                match self.cell(v.name, d) {
                    Some(c) => {
                        s.push_str(&format!(" {:.3} s ({:.2}x) |", c.seconds, c.seconds / base))
                    }
                    None => s.push_str(" - |"),
                }
            }
            s.push('\n');
        }
        s
    }

    pub fn cluster_cell(&self, variant: &str, divisions: u32) -> Option<&ClusterCell> {
        self.cluster
            .iter()
            .find(|c| c.variant == variant && c.divisions == divisions)
    }

    /// Table 5.2 on the simulated cluster as Markdown: frame seconds and ratios to type 1.
    pub fn cluster_table(&self) -> String {
        let mut s =
            table_head(std::iter::once("sub-screens").chain(VARIANTS.iter().map(|v| v.name)));
        for &d in &self.config.divisions {
            let base = self
                .cluster_cell("type 1", d)
                .map_or(f64::NAN, |c| c.seconds);
            s.push_str(&format!("| {d} |"));
            for v in VARIANTS {
                match self.cluster_cell(v.name, d) {
                    Some(c) => {
                        s.push_str(&format!(" {:.3} s ({:.2}x) |", c.seconds, c.seconds / base))
                    }
                    None => s.push_str(" - |"),
                }
            }
            s.push('\n');
        }
        s
    }

    /// Operation counts and host time per cell.
    pub fn counts_table(&self) -> String {
        let mut s = table_head([
            "variant",
            "sub-screens",
            "rays",
            "box tests",
            "triangle tests",
            "other shape tests",
            "clip compares",
            "shadow early exits",
            "modelled Mcycles (1 node)",
            "host s",
        ]);
        for c in self.cells.iter().chain(std::iter::once(&self.refractive)) {
            let st = &c.stats;
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {:.1} | {:.2} |\n",
                c.variant,
                c.divisions,
                st.rays(),
                st.box_tests,
                st.triangle_tests,
                st.ellipsoid_tests + st.box_shape_tests + st.blob_tests,
                st.clip_compares,
                st.shadow_early_exits,
                c.total_seconds * self.config.clock_hz / 1e6,
                c.host_seconds
            ));
        }
        s
    }

    /// Refractive over non-refractive time for type 1 at the finest division.
    pub fn refractive_ratio(&self) -> f64 {
        let d = self.refractive.divisions;
        self.refractive.seconds / self.cell("type 1", d).map_or(f64::NAN, |c| c.seconds)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_cover_every_pixel_once() {
        let r = runs(512, 480, 2400).unwrap();
        assert_eq!(r.len(), 2400);
        assert_eq!(r.iter().map(|r| r.2).sum::<u32>(), 512 * 480);
        assert_eq!(
            &r[..5],
            &[
                (0, 0, 102),
                (0, 102, 102),
                (0, 204, 103),
                (0, 307, 102),
                (0, 409, 103)
            ]
        );
        assert_eq!(runs(512, 480, 480).unwrap()[7], (7, 0, 512));
        assert!(runs(512, 480, 1000).is_err());
    }

    #[test]
    fn makespan_is_list_scheduling_in_order() {
        // Two nodes: 5 -> n0, 3 -> n1, 2 -> n1 (free at 3), 4 -> n0 (free at 5) => max(9, 5).
        assert_eq!(makespan(&[5, 3, 2, 4], 2), 9);
        assert_eq!(makespan(&[5, 3, 2, 4], 1), 14);
        assert_eq!(makespan(&[], 4), 0);
        assert_eq!(makespan(&[7; 16], 16), 7);
    }
}
