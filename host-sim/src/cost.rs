//! The op-count cost model: node compute time from the renderer's deterministic counters.
//!
//! A node's time for a piece of work is `Σ count_k · instructions_k · cycles_per_instruction`
//! over the operation kinds of [`Stats`], at the core clock. Counts are exact and repeatable,
//! so simulated times are too; only the per-operation weights are a model.
//!
//! **Calibration**: the weights below are the provisional Cortex-M4F (hard-float `f32`)
//! instruction counts per operation: the Möller–Trumbore-class triangle test measured at ~110
//! instructions under QEMU (`../shared/ARCHITECTURE.md`), the rest estimated from the code
//! paths relative to it. The numerics issue measures them on QEMU (`-icount`) and replaces
//! these numbers; everything downstream reads them only through [`CycleModel`].

use links_core::render::Stats;

/// Instructions per operation and the cycles each instruction takes on average.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleModel {
    pub name: &'static str,
    /// Per ray of any kind: set-up (direction, reciprocal, traversal loop entry).
    pub per_ray: f64,
    /// One slab test of a node's box, including reading the node.
    pub per_box_test: f64,
    pub per_triangle_test: f64,
    pub per_ellipsoid_test: f64,
    pub per_box_shape_test: f64,
    /// Per density-sphere group test, plus per field evaluation.
    pub per_blob_test: f64,
    pub per_blob_field_eval: f64,
    /// One evaluation of eq. 2.1 excluding its shadow rays (counted as rays).
    pub per_shading: f64,
    /// Per primary ray: pixel set-up and the write of the result.
    pub per_pixel: f64,
    /// One integer compare (and branch) of Y/X screen clipping.
    pub per_clip_compare: f64,
    /// Average cycles per instruction (wait states, FPU latencies, loads).
    pub cycles_per_instruction: f64,
}

impl CycleModel {
    /// Cortex-M4F at 168 MHz computing in hard-float `f32` (provisional, see module docs).
    pub const CORTEX_M4F_F32: CycleModel = CycleModel {
        name: "cortex-m4f f32 (provisional)",
        per_ray: 60.0,
        per_box_test: 45.0,
        per_triangle_test: 110.0,
        per_ellipsoid_test: 130.0,
        per_box_shape_test: 140.0,
        per_blob_test: 200.0,
        per_blob_field_eval: 70.0,
        per_shading: 400.0,
        per_pixel: 80.0,
        per_clip_compare: 3.0,
        cycles_per_instruction: 1.3,
    };

    /// Instructions the counted work takes.
    pub fn instructions(&self, s: &Stats) -> f64 {
        s.rays() as f64 * self.per_ray
            + s.box_tests as f64 * self.per_box_test
            + s.triangle_tests as f64 * self.per_triangle_test
            + s.ellipsoid_tests as f64 * self.per_ellipsoid_test
            + s.box_shape_tests as f64 * self.per_box_shape_test
            + s.blob_tests as f64 * self.per_blob_test
            + s.blob_field_evals as f64 * self.per_blob_field_eval
            + s.shadings as f64 * self.per_shading
            + s.primary_rays as f64 * self.per_pixel
            + s.clip_compares as f64 * self.per_clip_compare
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

/// The reference node clock: STM32F407 at 168 MHz.
pub const DEFAULT_CLOCK_HZ: f64 = 168e6;

#[cfg(test)]
mod tests {
    use super::*;

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
        let instr = 60.0 + 10.0 * 45.0 + 2.0 * 110.0 + 400.0 + 80.0;
        assert_eq!(m.instructions(&s), instr);
        assert_eq!(m.cycles(&s), (instr * 2.0) as u64);
        assert!((m.seconds(&s, 168e6) - instr * 2.0 / 168e6).abs() < 1e-15);
        assert_eq!(m.cycles(&Stats::default()), 0);
    }
}
