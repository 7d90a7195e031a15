//! The op-count cost model: node compute time from the renderer's deterministic counters.
//!
//! A node's time for a piece of work is `Σ count_k · weight_k · cycles_per_instruction` over
//! the operation kinds of [`Stats`], at the core clock. Counts are exact and repeatable, so
//! simulated times are too; only the weights are a model.
//!
//! **Calibration**: the weights are instructions per operation on the Cortex-M4F (hard-float
//! `f32`), fitted by non-negative least squares ([`fit`]) to whole frames measured under QEMU
//! with `-icount` (`scripts/qemu-bench` writes `docs/cortex-m-bench.csv`: the exact
//! instruction count and operation counts of every frame). `links calibrate` re-fits them and
//! prints the table to paste below; a test checks the model still predicts every measured
//! frame. Cycles per instruction is an assumption (QEMU counts instructions, not cycles): 1.3
//! for single-cycle FPU/ALU work plus two-cycle loads and flash wait states behind the ART
//! accelerator at 168 MHz.

use links_core::board::Core;
use links_core::num::Storage;
use links_core::render::Stats;
use std::fmt;

/// Defines [`CycleModel`] from one list of weights: each weight's field, the name of the
/// feature it weighs and how that feature is counted from [`Stats`]. [`FEATURES`],
/// [`features`], [`CycleModel::weights`] and [`CycleModel::with_weights`] all follow it.
macro_rules! define_cycle_model {
    ($($(#[$doc:meta])* $weight:ident: $feature:literal = |$s:ident| $count:expr,)*) => {
        /// Instructions per operation and the cycles each instruction takes on average.
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct CycleModel {
            pub name: &'static str,
            $($(#[$doc])* pub $weight: f64,)*
            /// Average cycles per instruction.
            pub cycles_per_instruction: f64,
        }

        /// The counters the model weighs, in [`CycleModel::weights`] order.
        pub const FEATURES: [&str; 11] = [$($feature),*];

        /// The feature vector of some counts, in [`FEATURES`] order.
        pub fn features(s: &Stats) -> [f64; 11] {
            [$({
                let $s = s;
                $count as f64
            }),*]
        }

        impl CycleModel {
            /// The weights in [`FEATURES`] order.
            pub fn weights(&self) -> [f64; 11] {
                [$(self.$weight),*]
            }

            /// A model with these weights (in [`FEATURES`] order).
            pub fn with_weights(
                name: &'static str,
                w: [f64; 11],
                cycles_per_instruction: f64,
            ) -> Self {
                let [$($weight),*] = w;
                CycleModel {
                    name,
                    $($weight,)*
                    cycles_per_instruction,
                }
            }
        }
    };
}

define_cycle_model! {
    /// Per primary ray: pixel set-up, clipping sweep, surface, shading set-up, the write.
    per_primary_ray: "primary_rays" = |s| s.primary_rays,
    /// Per reflected, refracted or straight-through ray (spawn, traversal set-up, surface).
    per_secondary_ray: "secondary_rays" = |s| (s.reflect_rays + s.refract_rays + s.straight_rays),
    /// Per shadow ray (light direction, offset origin, any-hit walk set-up).
    per_shadow_ray: "shadow_rays" = |s| s.shadow_rays,
    /// One node visit: reading the node and its slab test (plus traversal bookkeeping).
    per_box_test: "box_tests" = |s| s.box_tests,
    per_triangle_test: "triangle_tests" = |s| s.triangle_tests,
    per_ellipsoid_test: "ellipsoid_tests" = |s| s.ellipsoid_tests,
    per_box_shape_test: "box_shape_tests" = |s| s.box_shape_tests,
    /// Per density-sphere group test (pre-pass over the balls), plus per field evaluation.
    per_blob_test: "blob_tests" = |s| s.blob_tests,
    per_blob_field_eval: "blob_field_evals" = |s| s.blob_field_evals,
    /// One evaluation of eq. 2.1 (its shadow rays are counted as rays).
    per_shading: "shadings" = |s| s.shadings,
    /// One integer compare of Y/X screen clipping.
    per_clip_compare: "clip_compares" = |s| s.clip_compares,
}

impl CycleModel {
    /// Cortex-M4F at 168 MHz computing in hard-float `f32`: weights fitted by `links calibrate`
    /// to the 53 M4F f32 frames of `docs/cortex-m-bench.csv` (11 scene variants x up to 5
    /// technique sets), re-fitted for the edge-plane kernel (primary rays test cached edge
    /// planes; shadow and secondary rays the sheared test once per ray): one triangle-test
    /// weight now averages a cheap primary test and a dearer secondary one, and the per-shadow-
    /// ray weight took up the any-hit walk's set-up. Worst frames: photo1 primary rays with Y
    /// but no X clipping (type 2/3, whose flat loop over a row's leaves costs less per box test
    /// than the tree walks the one box-test weight also covers) and the plain algorithm (type 4,
    /// all primary tests cheap). Weights are in-situ costs: a box test includes the traversal
    /// around it, the per-primary-ray set-up is absorbed by the per-shading weight (every
    /// primary ray that hits is shaded once).
    pub const CORTEX_M4F_F32: CycleModel = CycleModel {
        name: "cortex-m4f f32 (QEMU-calibrated)",
        per_primary_ray: 0.0,
        per_secondary_ray: 1524.8,
        per_shadow_ray: 611.5,
        per_box_test: 51.8,
        per_triangle_test: 182.8,
        per_ellipsoid_test: 224.8,
        per_box_shape_test: 530.8,
        per_blob_test: 638.5,
        per_blob_field_eval: 839.3,
        per_shading: 707.7,
        per_clip_compare: 0.0,
        cycles_per_instruction: 1.3,
    };

    /// Cortex-M4F computing in Q16.16 (the kernel the F407 nodes run on a Q16.16 image):
    /// weights fitted by `links calibrate --backend q16.16` to the M4F q16.16 frames of
    /// `docs/cortex-m-bench.csv`.
    pub const CORTEX_M4F_Q16: CycleModel = CycleModel {
        name: "cortex-m4f q16.16 (QEMU-calibrated)",
        per_primary_ray: 0.0,
        per_secondary_ray: 3925.9,
        per_shadow_ray: 0.0,
        per_box_test: 742.0,
        per_triangle_test: 552.6,
        per_ellipsoid_test: 6500.0,
        per_box_shape_test: 0.0,
        per_blob_test: 0.0,
        per_blob_field_eval: 5747.6,
        per_shading: 0.0,
        per_clip_compare: 255.2,
        cycles_per_instruction: 1.3,
    };

    /// Cortex-M3 (STM32F207 at 120 MHz) computing in soft-float `f32`: weights fitted by
    /// `links calibrate --target thumbv7m-none-eabi` to the M3 f32 frames of
    /// `docs/cortex-m-bench.csv`. Cycles per instruction as the M4F's (the F2's ART
    /// accelerator hides its 3 flash wait states at 120 MHz as the F4's hides 5 at 168).
    pub const CORTEX_M3_F32: CycleModel = CycleModel {
        name: "cortex-m3 soft-float f32 (QEMU-calibrated)",
        per_primary_ray: 0.0,
        per_secondary_ray: 24469.0,
        per_shadow_ray: 8237.5,
        per_box_test: 718.5,
        per_triangle_test: 2982.1,
        per_ellipsoid_test: 3524.3,
        per_box_shape_test: 8617.7,
        per_blob_test: 5602.9,
        per_blob_field_eval: 16908.4,
        per_shading: 0.0,
        per_clip_compare: 0.0,
        cycles_per_instruction: 1.3,
    };

    /// Cortex-M3 computing in Q16.16 (what the F207 nodes run by default): weights fitted by
    /// `links calibrate --target thumbv7m-none-eabi --backend q16.16`.
    pub const CORTEX_M3_Q16: CycleModel = CycleModel {
        name: "cortex-m3 q16.16 (QEMU-calibrated)",
        per_primary_ray: 0.0,
        per_secondary_ray: 4165.5,
        per_shadow_ray: 0.0,
        per_box_test: 751.3,
        per_triangle_test: 545.1,
        per_ellipsoid_test: 6435.0,
        per_box_shape_test: 0.0,
        per_blob_test: 0.0,
        per_blob_field_eval: 5700.4,
        per_shading: 0.0,
        per_clip_compare: 268.1,
        cycles_per_instruction: 1.3,
    };

    /// Cortex-M0+ (STM32G0B1 at 64 MHz) computing in Q16.16 (what the G0B1 nodes run):
    /// weights fitted by `links calibrate --target thumbv6m-none-eabi --backend q16.16` to the
    /// ARMv6-M q16.16 frames of `docs/cortex-m-bench.csv` (QEMU runs the ARMv6-M code on its
    /// Cortex-M3 board: the instructions a Cortex-M0+ executes). Cycles per instruction is
    /// the other cores' assumption, not measured: the G0's 2 flash wait states at 64 MHz
    /// behind its prefetch buffer and instruction cache, two-cycle loads and taken branches.
    pub const CORTEX_M0P_Q16: CycleModel = CycleModel {
        name: "cortex-m0+ q16.16 (QEMU-calibrated)",
        per_primary_ray: 0.0,
        per_secondary_ray: 9420.6,
        per_shadow_ray: 0.0,
        per_box_test: 1440.5,
        per_triangle_test: 1278.5,
        per_ellipsoid_test: 15536.5,
        per_box_shape_test: 0.0,
        per_blob_test: 0.0,
        per_blob_field_eval: 14450.6,
        per_shading: 0.0,
        per_clip_compare: 549.4,
        cycles_per_instruction: 1.3,
    };

    /// Cortex-M0+ computing in soft-float `f32` (a G0B1 node built with `kernel-f32`):
    /// weights fitted by `links calibrate --target thumbv6m-none-eabi` to the ARMv6-M f32
    /// frames of `docs/cortex-m-bench.csv`; cycles per instruction as [`Self::CORTEX_M0P_Q16`].
    pub const CORTEX_M0P_F32: CycleModel = CycleModel {
        name: "cortex-m0+ soft-float f32 (QEMU-calibrated)",
        per_primary_ray: 0.0,
        per_secondary_ray: 43140.0,
        per_shadow_ray: 14714.3,
        per_box_test: 1367.0,
        per_triangle_test: 5302.0,
        per_ellipsoid_test: 6365.5,
        per_box_shape_test: 14134.5,
        per_blob_test: 10012.9,
        per_blob_field_eval: 30255.7,
        per_shading: 0.0,
        per_clip_compare: 0.0,
        cycles_per_instruction: 1.3,
    };

    /// Instructions the counted work takes.
    pub fn instructions(&self, s: &Stats) -> f64 {
        features(s)
            .iter()
            .zip(self.weights())
            .map(|(c, w)| c * w)
            .sum()
    }

    /// Core cycles the counted work takes (rounded up: a node can't finish mid-cycle).
    pub fn cycles(&self, s: &Stats) -> u64 {
        (self.instructions(s) * self.cycles_per_instruction).ceil() as u64
    }

    /// Seconds at a core clock in Hz.
    pub fn seconds(&self, s: &Stats, clock_hz: f64) -> f64 {
        self.cycles(s) as f64 / clock_hz
    }
}

impl Default for CycleModel {
    fn default() -> Self {
        Self::CORTEX_M4F_F32
    }
}

impl CycleModel {
    /// The weights of a board's core (`links_core::board::BoardProfile::core`) computing in
    /// `f32` (hard-float on the M4F, soft-float on the M3).
    pub const fn for_core(core: Core) -> CycleModel {
        Self::for_kernel(core, Storage::F32)
    }

    /// The weights of a board's core running the kernel of images stored as `storage`.
    pub const fn for_kernel(core: Core, storage: Storage) -> CycleModel {
        match (core, storage) {
            (Core::CortexM4F, Storage::F32) => Self::CORTEX_M4F_F32,
            (Core::CortexM4F, Storage::Q16_16) => Self::CORTEX_M4F_Q16,
            (Core::CortexM3, Storage::F32) => Self::CORTEX_M3_F32,
            (Core::CortexM3, Storage::Q16_16) => Self::CORTEX_M3_Q16,
            (Core::CortexM0Plus, Storage::F32) => Self::CORTEX_M0P_F32,
            (Core::CortexM0Plus, Storage::Q16_16) => Self::CORTEX_M0P_Q16,
        }
    }
}

/// What a node's check of a complete scene costs (`run_node`'s `check_scene`: the CRC-32
/// over the bank, then [`SceneView::new`] once per bank; later runs open the checked bank
/// with `SceneView::open_validated`, which the per-run weights cover). Instructions on the
/// Cortex-M4F, from `scripts/qemu-node`: `unit_scene_crc` / `scene_bytes` (5.4 per byte),
/// `unit_open` (2,080: the header and the section table) and, per record the validator
/// walks, photo1's (39,200 - 2,080) / 1,333 records = 27.8.
///
/// [`SceneView::new`]: links_core::image::SceneView::new
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneCheckCost {
    pub crc_per_byte: f64,
    pub header_and_table: f64,
    pub per_record: f64,
}

impl SceneCheckCost {
    pub const CORTEX_M4F: SceneCheckCost = SceneCheckCost {
        crc_per_byte: 5.4,
        header_and_table: 2080.0,
        per_record: 27.8,
    };

    /// Instructions to check `scene` (its bytes and the records the validator walks).
    pub fn instructions(&self, scene: &links_core::image::SceneView<'_>) -> f64 {
        use links_core::image::Section;
        let walked: u32 = Section::ALL
            .iter()
            .filter(|s| !matches!(s, Section::Texels | Section::Vertices | Section::Normals))
            .filter(|s| !matches!(s, Section::Uvs | Section::Balls | Section::Rects))
            .map(|&s| scene.count(s))
            .sum();
        self.crc_per_byte * scene.bytes().len() as f64
            + self.header_and_table
            + self.per_record * f64::from(walked)
    }
}

impl Default for SceneCheckCost {
    fn default() -> Self {
        Self::CORTEX_M4F
    }
}

/// The reference node clock: STM32F407 at 168 MHz.
pub const DEFAULT_CLOCK_HZ: f64 = links_core::board::BoardProfile::F407.core_clock_hz as f64;

/// One measured frame, a row of `docs/cortex-m-bench.csv`: where it ran, what it rendered,
/// the instructions QEMU counted and every [`Stats`] counter. The QEMU bench's report
/// (`xtask qemu-bench`) writes these rows ([`Sample::csv_head`], [`Sample::csv_line`]) and
/// [`parse_rows`] reads them back, so the row format is defined here once.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    pub target: String,
    /// The number backend by `Real::NAME` (`f32`, `f32-fast`, `q16.16`).
    pub backend: String,
    pub scene: String,
    pub techniques: String,
    pub pixels: u64,
    pub stats: Stats,
    pub instructions: u64,
}

/// The row's columns before the [`Stats`] counters (which follow in [`Stats::NAMES`] order).
pub const CSV_LEAD: [&str; 6] = [
    "target",
    "backend",
    "scene",
    "techniques",
    "pixels",
    "instructions",
];

impl Sample {
    /// The CSV header: [`CSV_LEAD`] then every [`Stats::NAMES`], comma-separated.
    pub fn csv_head() -> String {
        CSV_LEAD
            .iter()
            .chain(Stats::NAMES.iter())
            .copied()
            .collect::<Vec<_>>()
            .join(",")
    }

    /// The row as a CSV line (no newline), in [`Sample::csv_head`]'s column order.
    pub fn csv_line(&self) -> String {
        let mut line = format!(
            "{},{},{},{},{},{}",
            self.target, self.backend, self.scene, self.techniques, self.pixels, self.instructions
        );
        for v in self.stats.values() {
            line.push_str(&format!(",{v}"));
        }
        line
    }
}

/// Why a calibration file could not be used.
#[derive(Debug, PartialEq)]
pub enum CalibrationError {
    MissingColumn(String),
    BadNumber {
        line: usize,
        column: String,
        value: String,
    },
    ShortRow {
        line: usize,
    },
    NoSamples {
        target: String,
    },
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CalibrationError::MissingColumn(c) => write!(f, "calibration CSV has no column '{c}'"),
            CalibrationError::BadNumber {
                line,
                column,
                value,
            } => {
                write!(
                    f,
                    "line {line}: column '{column}' is not a count: '{value}'"
                )
            }
            CalibrationError::ShortRow { line } => write!(f, "line {line}: too few columns"),
            CalibrationError::NoSamples { target } => write!(f, "no samples for target '{target}'"),
        }
    }
}

impl std::error::Error for CalibrationError {}

/// The committed model of the frames of `target` (`thumbv7em-none-eabihf`: the M4F,
/// `thumbv7m-none-eabi`: the M3, `thumbv6m-none-eabi`: the M0+) rendered by `backend` (`f32`,
/// `q16.16`).
pub fn committed_model(target: &str, backend: &str) -> Option<CycleModel> {
    let core = match target {
        "thumbv7em-none-eabihf" => Core::CortexM4F,
        "thumbv7m-none-eabi" => Core::CortexM3,
        "thumbv6m-none-eabi" => Core::CortexM0Plus,
        _ => return None,
    };
    let storage = match backend {
        "f32" => Storage::F32,
        "q16.16" => Storage::Q16_16,
        _ => return None,
    };
    Some(CycleModel::for_kernel(core, storage))
}

/// Read the `f32` samples of `scripts/qemu-bench`'s CSV (`docs/cortex-m-bench.csv`): the
/// model is of f32 code, so rows of other number backends (column `backend`: `f32-fast`,
/// `q16.16`) are left out; a file without that column holds f32 rows only.
pub fn parse_samples(csv: &str) -> Result<Vec<Sample>, CalibrationError> {
    let mut rows = parse_rows(csv)?;
    rows.retain(|r| r.backend == "f32");
    Ok(rows)
}

/// Read every row of `scripts/qemu-bench`'s CSV, whatever its backend. The columns are
/// found by name (header line); `backend` defaults to `f32` and `pixels` to 0 when the file
/// has no such column.
pub fn parse_rows(csv: &str) -> Result<Vec<Sample>, CalibrationError> {
    let mut lines = csv
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let header: Vec<&str> = lines
        .next()
        .map(|(_, h)| h.split(',').map(str::trim).collect())
        .unwrap_or_default();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .ok_or_else(|| CalibrationError::MissingColumn(name.into()))
    };
    let lead = ["target", "scene", "techniques", "instructions"].map(col);
    let [target, scene, techniques, instructions] = lead;
    let (target, scene, techniques, instructions) = (target?, scene?, techniques?, instructions?);
    let counters = Stats::NAMES
        .iter()
        .map(|n| col(n))
        .collect::<Result<Vec<_>, _>>()?;
    let (backend, pixels) = (col("backend").ok(), col("pixels").ok());
    let mut out = Vec::new();
    for (i, line) in lines {
        let line_no = i + 1;
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let cell = |k: usize| {
            cells
                .get(k)
                .copied()
                .ok_or(CalibrationError::ShortRow { line: line_no })
        };
        let num = |k: usize| -> Result<u64, CalibrationError> {
            let v = cell(k)?;
            v.parse().map_err(|_| CalibrationError::BadNumber {
                line: line_no,
                column: header[k].into(),
                value: v.into(),
            })
        };
        let backend = match backend {
            Some(b) => cell(b)?,
            None => "f32",
        };
        let mut values = [0u64; Stats::COUNT];
        for (v, &k) in values.iter_mut().zip(&counters) {
            *v = num(k)?;
        }
        out.push(Sample {
            target: cell(target)?.into(),
            backend: backend.into(),
            scene: cell(scene)?.into(),
            techniques: cell(techniques)?.into(),
            pixels: pixels.map(num).transpose()?.unwrap_or(0),
            stats: Stats::from_values(values),
            instructions: num(instructions)?,
        });
    }
    Ok(out)
}

/// Non-negative least squares (Lawson and Hanson): `min |A x - b|` with `x >= 0`. Rows of `a`
/// are samples. Columns are scaled to unit length first, so counts of very different sizes
/// (box tests vs blob tests) are treated alike; features never used get weight 0.
pub fn nnls(a: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let n = a.first().map_or(0, Vec::len);
    let scale: Vec<f64> = (0..n)
        .map(|j| {
            let s = a.iter().map(|r| r[j] * r[j]).sum::<f64>().sqrt();
            if s > 0.0 {
                s
            } else {
                0.0
            }
        })
        .collect();
    let col = |i: usize, j: usize| {
        if scale[j] > 0.0 {
            a[i][j] / scale[j]
        } else {
            0.0
        }
    };
    let m = a.len();
    let mut x = vec![0.0; n];
    let mut passive = vec![false; n];
    let residual = |x: &[f64]| -> Vec<f64> {
        (0..m)
            .map(|i| b[i] - (0..n).map(|j| col(i, j) * x[j]).sum::<f64>())
            .collect()
    };
    // Least squares on the passive set via the normal equations.
    let solve_passive = |passive: &[bool]| -> Vec<f64> {
        let p: Vec<usize> = (0..n).filter(|&j| passive[j]).collect();
        let k = p.len();
        let mut g = vec![vec![0.0; k + 1]; k];
        for (r, &jr) in p.iter().enumerate() {
            for (c, &jc) in p.iter().enumerate() {
                g[r][c] = (0..m).map(|i| col(i, jr) * col(i, jc)).sum();
            }
            g[r][k] = (0..m).map(|i| col(i, jr) * b[i]).sum();
        }
        // Gaussian elimination with partial pivoting.
        for c in 0..k {
            let piv = (c..k)
                .max_by(|&u, &v| g[u][c].abs().total_cmp(&g[v][c].abs()))
                .unwrap_or(c);
            g.swap(c, piv);
            let d = g[c][c];
            if d.abs() < 1e-12 {
                continue;
            }
            let pivot_row = g[c].clone();
            for (r, row) in g.iter_mut().enumerate() {
                if r != c {
                    let f = row[c] / d;
                    for (x, p) in row.iter_mut().zip(&pivot_row).skip(c) {
                        *x -= f * p;
                    }
                }
            }
        }
        let mut z = vec![0.0; n];
        for (r, &j) in p.iter().enumerate() {
            z[j] = if g[r][r].abs() < 1e-12 {
                0.0
            } else {
                g[r][k] / g[r][r]
            };
        }
        z
    };
    for _outer in 0..(3 * n + 10) {
        let r = residual(&x);
        let w: Vec<f64> = (0..n)
            .map(|j| (0..m).map(|i| col(i, j) * r[i]).sum())
            .collect();
        let Some(t) = (0..n)
            .filter(|&j| {
                !passive[j]
                    && scale[j] > 0.0
                    && w[j] > 1e-9 * b.iter().map(|v| v.abs()).sum::<f64>()
            })
            .max_by(|&u, &v| w[u].total_cmp(&w[v]))
        else {
            break;
        };
        passive[t] = true;
        for _inner in 0..(3 * n + 10) {
            let z = solve_passive(&passive);
            if (0..n).filter(|&j| passive[j]).all(|j| z[j] > 0.0) {
                x = z;
                break;
            }
            // Step back towards x until a passive weight hits zero, then drop it.
            let alpha = (0..n)
                .filter(|&j| passive[j] && z[j] <= 0.0)
                .map(|j| x[j] / (x[j] - z[j]))
                .fold(f64::INFINITY, f64::min);
            for j in 0..n {
                x[j] += alpha * (z[j] - x[j]);
                if passive[j] && x[j] <= 1e-12 {
                    passive[j] = false;
                    x[j] = 0.0;
                }
            }
        }
    }
    (0..n)
        .map(|j| if scale[j] > 0.0 { x[j] / scale[j] } else { 0.0 })
        .collect()
}

/// Fit the weights to the samples of one target, relative error per sample (each frame
/// counts alike however long it is).
pub fn fit(
    samples: &[Sample],
    target: &str,
    cycles_per_instruction: f64,
) -> Result<CycleModel, CalibrationError> {
    let rows: Vec<&Sample> = samples.iter().filter(|s| s.target == target).collect();
    if rows.is_empty() {
        return Err(CalibrationError::NoSamples {
            target: target.into(),
        });
    }
    let a: Vec<Vec<f64>> = rows
        .iter()
        .map(|s| {
            features(&s.stats)
                .map(|f| f / s.instructions as f64)
                .to_vec()
        })
        .collect();
    let b = vec![1.0; rows.len()];
    let w = nnls(&a, &b);
    let mut weights = [0.0; 11];
    for (k, v) in w.iter().enumerate().take(11) {
        weights[k] = (v * 10.0).round() / 10.0;
    }
    Ok(CycleModel::with_weights(
        "fitted",
        weights,
        cycles_per_instruction,
    ))
}

/// Predicted over measured instructions, per sample of `target`.
pub fn prediction_ratios<'s>(
    model: &CycleModel,
    samples: &'s [Sample],
    target: &str,
) -> Vec<(&'s Sample, f64)> {
    samples
        .iter()
        .filter(|s| s.target == target)
        .map(|s| (s, model.instructions(&s.stats) / s.instructions as f64))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scene_check_costs_what_the_m4f_measured_on_photo1() {
        // scripts/qemu-node on photo1 at 48x45 (an 18,292-byte image): one validation
        // 39,200 instructions, the CRC-32 over the scene 98,400.
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron");
        let img = crate::scene_file::compile_at(&path, 48, 45).unwrap();
        assert_eq!(img.len(), 18_292);
        let v = links_core::image::SceneView::new(&img).unwrap();
        let got = SceneCheckCost::CORTEX_M4F.instructions(&v);
        let measured = 39_200.0 + 98_400.0;
        assert!(
            (got - measured).abs() / measured < 0.01,
            "{got} vs {measured}"
        );
    }

    #[test]
    fn cycles_are_the_weighted_sum_of_counts() {
        let m = CycleModel {
            cycles_per_instruction: 2.0,
            ..CycleModel::CORTEX_M4F_F32
        };
        let s = Stats {
            primary_rays: 1,
            box_tests: 10,
            triangle_tests: 2,
            shadings: 1,
            ..Stats::default()
        };
        let w = CycleModel::CORTEX_M4F_F32;
        let instr =
            w.per_primary_ray + 10.0 * w.per_box_test + 2.0 * w.per_triangle_test + w.per_shading;
        assert!((m.instructions(&s) - instr).abs() < 1e-9);
        assert_eq!(m.cycles(&s), (instr * 2.0).ceil() as u64);
        assert_eq!(m.cycles(&Stats::default()), 0);
    }

    #[test]
    fn nnls_recovers_known_weights_and_keeps_them_non_negative() {
        // b = 3 x0 + 0.5 x2, exactly; x1 would want to be negative.
        let a = vec![
            vec![1.0, 2.0, 0.0],
            vec![2.0, 1.0, 4.0],
            vec![0.0, 3.0, 1.0],
            vec![5.0, 0.0, 2.0],
        ];
        let b: Vec<f64> = a
            .iter()
            .map(|r| 3.0 * r[0] + 0.5 * r[2] - 0.01 * r[1])
            .collect();
        let x = nnls(&a, &b);
        assert!(x.iter().all(|&v| v >= 0.0), "{x:?}");
        assert!(
            (x[0] - 3.0).abs() < 0.05 && (x[2] - 0.5).abs() < 0.05 && x[1] < 0.02,
            "{x:?}"
        );
    }

    #[test]
    fn csv_parses_and_reports_bad_cells() {
        let head = "target,scene,techniques,pixels,instructions,primary_rays,shadow_rays,reflect_rays,refract_rays,straight_rays,box_tests,triangle_tests,ellipsoid_tests,box_shape_tests,blob_tests,blob_field_evals,shadings,clip_compares,clip_overflows,shadow_early_exits";
        let ok = format!("{head}\nm4,photo1,all,4,1000,4,2,1,0,0,30,5,0,1,0,0,3,20,0,1\n");
        let s = parse_samples(&ok).unwrap();
        assert_eq!(s.len(), 1);
        assert_eq!(
            (
                s[0].instructions,
                s[0].stats.box_tests,
                s[0].stats.clip_compares
            ),
            (1000, 30, 20)
        );
        let bad = format!("{head}\nm4,photo1,all,4,x,4,2,1,0,0,30,5,0,1,0,0,3,20,0,1\n");
        assert!(matches!(
            parse_samples(&bad),
            Err(CalibrationError::BadNumber { line: 2, .. })
        ));
        assert!(matches!(
            parse_samples("a,b\n1,2\n"),
            Err(CalibrationError::MissingColumn(_))
        ));
    }

    #[test]
    fn csv_keeps_the_f32_rows_only() {
        let head = "target,backend,scene,techniques,pixels,instructions,primary_rays,shadow_rays,reflect_rays,refract_rays,straight_rays,box_tests,triangle_tests,ellipsoid_tests,box_shape_tests,blob_tests,blob_field_evals,shadings,clip_compares,clip_overflows,shadow_early_exits";
        let csv = format!(
            "{head}\n\
             m4,f32,photo1,all,4,1000,4,2,1,0,0,30,5,0,1,0,0,3,20,0,1\n\
             m4,q16.16,photo1,all,4,5000,4,2,1,0,0,30,5,0,1,0,0,3,20,0,1\n\
             m4,f32-fast,photo1,all,4,990,4,2,1,0,0,30,5,0,1,0,0,3,20,0,1\n\
             m4,f32,glass,all,4,2000,4,2,1,0,0,31,5,0,1,0,0,3,20,0,1\n"
        );
        let s = parse_samples(&csv).unwrap();
        let got: Vec<(&str, u64)> = s
            .iter()
            .map(|s| (s.scene.as_str(), s.instructions))
            .collect();
        assert_eq!(got, [("photo1", 1000), ("glass", 2000)]);
        assert!(matches!(
            parse_samples(&format!("{head}\nm4\n")),
            Err(CalibrationError::ShortRow { line: 2 })
        ));
    }

    /// `docs/cortex-m-bench.csv`, as committed.
    fn committed_csv() -> String {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/cortex-m-bench.csv");
        std::fs::read_to_string(path)
            .unwrap_or_else(|e| panic!("{path}: {e} (run scripts/qemu-bench)"))
    }

    /// The row writer reproduces the committed CSV byte for byte from the rows it reads.
    #[test]
    fn committed_csv_round_trips_through_the_row_type() {
        let csv = committed_csv();
        let rows = parse_rows(&csv).unwrap();
        let mut again = Sample::csv_head() + "\n";
        for r in &rows {
            again += &r.csv_line();
            again.push('\n');
        }
        assert_eq!(again, csv);
    }

    /// The Q16.16 and soft-float models predict the frames of their core and backend (the
    /// committed CSV; the q16.16 rows are 11 frames, one technique set each).
    #[test]
    fn committed_fixed_point_and_m3_models_predict_their_frames() {
        let rows = parse_rows(&committed_csv()).unwrap();
        // (target, backend, frames at least, worst and mean error below): the q16.16 fits
        // are within 8.4 %; the M3's and the M0+'s f32 frames span every technique set, as
        // the M4F's (whose test allows 40 %). Their soft-float shadow rays are where the
        // light rectangles (`links_core::trace::light_rects`) gain most, and only with
        // bounding boxes: a shadow ray's box or triangle test skipped by a rectangle still
        // counts as a test (the CSV's columns stay as issue 13 fixed them) but costs ~10
        // instructions against ~700 for a soft-float slab test and ~2,000 for the sheared
        // triangle test, which one weight per count cannot express for every technique set.
        // Refitted in session 20 (triangles in their leaves' cells took 17-18% off the
        // shadowed frames): worst 41.4 % and 41.0 %, mean 9.7 % and 9.9 % (session 19: worst
        // 39 and 38 %).
        for (target, backend, min, worst_below, mean_below) in [
            ("thumbv7em-none-eabihf", "q16.16", 11, 0.10, 0.10),
            ("thumbv7m-none-eabi", "q16.16", 11, 0.10, 0.10),
            ("thumbv7m-none-eabi", "f32", 50, 0.45, 0.10),
            ("thumbv6m-none-eabi", "q16.16", 11, 0.10, 0.10),
            ("thumbv6m-none-eabi", "f32", 50, 0.45, 0.10),
        ] {
            let model = committed_model(target, backend).unwrap();
            let of: Vec<Sample> = rows
                .iter()
                .filter(|r| r.backend == backend)
                .cloned()
                .collect();
            let ratios = prediction_ratios(&model, &of, target);
            assert!(ratios.len() >= min, "{target} {backend}: {}", ratios.len());
            let off: Vec<f64> = ratios.iter().map(|(_, r)| (r - 1.0).abs()).collect();
            let worst = off.iter().copied().fold(0.0, f64::max);
            let mean = off.iter().sum::<f64>() / off.len() as f64;
            assert!(
                worst < worst_below && mean < mean_below,
                "{target} {backend} off by up to {:.0}% (mean {:.0}%): re-run `links calibrate --target {target} --backend {backend}`",
                worst * 100.0,
                mean * 100.0
            );
        }
        assert_eq!(committed_model("thumbv8m.main-none-eabi", "f32"), None);
        assert_eq!(committed_model("thumbv6m-none-eabi", "f32-fast"), None);
        let m3 = CycleModel::for_kernel(Core::CortexM3, Storage::Q16_16);
        assert_eq!(m3, CycleModel::CORTEX_M3_Q16);
        let m0 = CycleModel::for_kernel(Core::CortexM0Plus, Storage::Q16_16);
        assert_eq!(m0, CycleModel::CORTEX_M0P_Q16);
    }

    /// The committed model must predict every frame QEMU measured (the committed CSV).
    #[test]
    fn committed_model_predicts_the_measured_frames() {
        let csv = committed_csv();
        let samples = parse_samples(&csv).unwrap();
        let ratios = prediction_ratios(
            &CycleModel::CORTEX_M4F_F32,
            &samples,
            "thumbv7em-none-eabihf",
        );
        assert!(ratios.len() >= 10, "too few M4F samples: {}", ratios.len());
        let worst = ratios
            .iter()
            .map(|(_, r)| (r - 1.0).abs())
            .fold(0.0, f64::max);
        let mean = ratios.iter().map(|(_, r)| (r - 1.0).abs()).sum::<f64>() / ratios.len() as f64;
        assert!(
            worst < 0.40 && mean < 0.10,
            "model off by up to {:.0}% (mean {:.0}%): re-run `links calibrate`",
            worst * 100.0,
            mean * 100.0
        );
    }
}
