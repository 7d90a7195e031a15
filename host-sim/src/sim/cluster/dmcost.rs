//! The DM's time per frame, from a model of its work (never a host measurement, so virtual
//! time stays deterministic): instructions per record of the SceneImage it writes, at the
//! speed of the machine that runs the DM.
//!
//! For each frame the DM writes the tracks' values into the still scene, places every cluster
//! at its time (composing transforms), takes every vertex and shape into view coordinates,
//! builds the boxes and screen rectangles and the mesh hierarchies, and writes the image with
//! its CRC-32 ([`links_core::anim::Film::compile_frame`]). The model charges
//!
//! ```text
//! instructions = fixed + per_byte · bytes + per_node · nodes + per_vertex · vertices
//!              + per_triangle · triangles + per_shape · (ellipsoids + boxes + balls)
//! ```
//!
//! with the counts read from the image the DM produced. Sources of the weights
//! ([`DmCost::ESTIMATE`]): `per_byte` = the table-driven CRC-32 measured on the node
//! ([`crate::cost::SceneCheckCost::CORTEX_M4F`], 5.4 instructions per byte) plus one to write
//! the byte; the others are operation counts of the compile code (shared/src/scene/compile),
//! rounded up: a vertex is a 3x4 affine transform in f64 (12 multiply-adds, loads and stores,
//! ~40); a triangle its normal, box, screen rectangle and a share of the binned-SAH build
//! (~400); a node the composition of its transform, the union of its children's boxes and the
//! projection of its rectangle (~300); a shape its view-space quadric or box and rectangle
//! (~400); `fixed` the camera, lights, materials and section table (~20 000). They are
//! estimates, not measurements: the figures using them say so.
//!
//! The machine ([`DmMachine`]): the PC that feeds the RC (`links upload`), charged at a
//! modest 10⁹ instructions per second; or, for comparison, the RC's own core (the board
//! profile's clock and cycles per instruction).

use links_core::image::{SceneView, Section};

/// Instructions per record of the SceneImage the DM writes (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DmCost {
    pub fixed: f64,
    pub per_byte: f64,
    pub per_node: f64,
    pub per_vertex: f64,
    pub per_triangle: f64,
    pub per_shape: f64,
}

impl DmCost {
    /// The estimate of the module doc.
    pub const ESTIMATE: DmCost = DmCost {
        fixed: 20_000.0,
        per_byte: 6.4,
        per_node: 300.0,
        per_vertex: 40.0,
        per_triangle: 400.0,
        per_shape: 400.0,
    };

    /// The DM's instructions for the frame whose image is `scene`.
    pub fn instructions(&self, scene: &SceneView<'_>) -> f64 {
        let n = |s: Section| f64::from(scene.count(s));
        self.fixed
            + self.per_byte * scene.bytes().len() as f64
            + self.per_node * n(Section::Nodes)
            + self.per_vertex * n(Section::Vertices)
            + self.per_triangle * n(Section::Triangles)
            + self.per_shape * (n(Section::Ellipsoids) + n(Section::Boxes) + n(Section::Balls))
    }
}

impl Default for DmCost {
    fn default() -> Self {
        Self::ESTIMATE
    }
}

/// The machine that runs the DM, by its instruction rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DmMachine {
    pub name: &'static str,
    pub instructions_per_s: f64,
}

impl DmMachine {
    /// The PC (the DM of `links upload`): an assumed, modest 10⁹ instructions per second.
    pub const PC: DmMachine = DmMachine {
        name: "PC at 1e9 instructions/s, cost model",
        instructions_per_s: 1e9,
    };

    /// The RC's core of `profile`: its clock over the node cost model's cycles per
    /// instruction for that core.
    pub fn rc_core(profile: &links_core::board::BoardProfile) -> DmMachine {
        let cpi = crate::cost::CycleModel::for_core(profile.core).cycles_per_instruction;
        DmMachine {
            name: "the RC's core",
            instructions_per_s: profile.core_clock_hz as f64 / cpi,
        }
    }

    /// Seconds for `instructions`.
    pub fn seconds(&self, instructions: f64) -> f64 {
        instructions / self.instructions_per_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_model_adds_its_terms_by_hand() {
        let img = crate::scene_file::compile_at(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/photo1.ron"),
            48,
            45,
        )
        .expect("photo1 compiles");
        let v = SceneView::new(&img).expect("valid");
        let c = DmCost::ESTIMATE;
        let n = |s| f64::from(v.count(s));
        let by_hand = 20_000.0
            + 6.4 * img.len() as f64
            + 300.0 * n(Section::Nodes)
            + 40.0 * n(Section::Vertices)
            + 400.0 * n(Section::Triangles)
            + 400.0 * (n(Section::Ellipsoids) + n(Section::Boxes) + n(Section::Balls));
        assert_eq!(c.instructions(&v), by_hand);
        // photo1 is the 18,292-byte image of the scene-check test: bytes alone are 117 k.
        assert_eq!(img.len(), 18_292);
        assert!(by_hand > 6.4 * 18_292.0 + 20_000.0);
        assert_eq!(DmMachine::PC.seconds(2e9), 2.0);
        let rc = DmMachine::rc_core(&links_core::board::BoardProfile::F407);
        assert!((rc.instructions_per_s - 168e6 / 1.3).abs() < 1.0, "{rc:?}");
    }
}
