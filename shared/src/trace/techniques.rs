//! The speed techniques of LINKS-1 (section 4) and ours, each switchable for measurement.

/// LINKS-1's speed techniques (section 4) and ours, each switchable for measurement. None of
/// them changes a pixel (asserted by tests on every bundled scene).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Techniques {
    /// Test a node's bounding box before descending into it (4.2). Off: every ray tests
    /// every shape.
    pub bounding_boxes: bool,
    /// Y clipping of primary rays per run (4.4).
    pub y_clip: bool,
    /// X clipping of primary rays per pixel (4.4); needs `y_clip`.
    pub x_clip: bool,
    /// Shadow rays first look for any opaque blocker (stop at the first) and only step
    /// through transparent surfaces when there are some (beyond the paper).
    pub shadow_early_exit: bool,
}

impl Techniques {
    /// Everything on (the paper's type 1, plus early shadow exit).
    pub const ALL: Techniques = Techniques {
        bounding_boxes: true,
        y_clip: true,
        x_clip: true,
        shadow_early_exit: true,
    };
    /// The paper's type 1: boxes, Y and X clipping.
    pub const PAPER_TYPE_1: Techniques = Techniques {
        shadow_early_exit: false,
        ..Self::ALL
    };
    /// Type 2: no X clipping.
    pub const PAPER_TYPE_2: Techniques = Techniques {
        x_clip: false,
        ..Self::PAPER_TYPE_1
    };
    /// Type 3: no X and no Y clipping.
    pub const PAPER_TYPE_3: Techniques = Techniques {
        y_clip: false,
        ..Self::PAPER_TYPE_2
    };
    /// Type 4: no clipping and no bounding boxes: the plain algorithm.
    pub const PAPER_TYPE_4: Techniques = Techniques {
        bounding_boxes: false,
        ..Self::PAPER_TYPE_3
    };
}

impl Default for Techniques {
    fn default() -> Self {
        Self::ALL
    }
}
