//! Screen-space clipping of primary rays (LINKS-1 4.4).
//!
//! The DM gives every node of the cluster tree a screen rectangle. **Y clipping**: when a
//! node computer starts a run of pixels on row y, it walks the tree once with integer
//! compares, skipping every cluster whose rectangle misses the row, and keeps the leaves
//! (shapes) that remain — in tree order. **X clipping**: those leaves are ordered by their
//! rectangles' left edges; sweeping the run left to right, a leaf joins the *active list* when
//! the sweep reaches its left edge and leaves it past its right edge, so each pixel's primary
//! ray tests only shapes whose rectangle contains the pixel.
//!
//! The active list is kept in tree order, so shapes are tested in the same order as the plain
//! traversal and ties between equally distant hits resolve the same way: clipping never
//! changes a pixel. All buffers are fixed-size (no heap); a row with more leaves than
//! [`CLIP_CAPACITY`] falls back to the plain traversal for that run.

use crate::image::SceneView;

/// Most leaves one row may keep after Y clipping: 512 (7 KB of the tracer state) is more than
/// any scene a node's bank holds has in all (photo2, the largest bundled one, 227 nodes);
/// the light rectangles took the other half of the 1,024 this was.
pub const CLIP_CAPACITY: usize = 512;

/// Per-run clipping state: the Y-clipped leaves and the X sweep over them.
pub struct RowClip {
    /// Node indices of the leaves overlapping the row, in tree order.
    leaves: [u32; CLIP_CAPACITY],
    /// The rectangle columns of each leaf: (x_lo, x_hi).
    cols: [(u16, u16); CLIP_CAPACITY],
    n: usize,
    /// `x_lo << 16 | position` of every leaf (positions into `leaves`), ascending: sorted
    /// by (x_lo, position) as plain integers.
    by_x: [u32; CLIP_CAPACITY],
    next: usize,
    /// Positions into `leaves` whose rectangle contains the current column, ascending.
    active: [u16; CLIP_CAPACITY],
    n_active: usize,
    /// The smallest x_hi of the active leaves (`u16::MAX` when none): until the sweep passes
    /// it, no active leaf ends and the drop pass is skipped.
    min_hi: u16,
    row: Option<u16>,
    last_x: Option<u16>,
}

impl Default for RowClip {
    fn default() -> Self {
        Self::new()
    }
}

impl RowClip {
    pub const fn new() -> Self {
        Self {
            leaves: [0; CLIP_CAPACITY],
            cols: [(0, 0); CLIP_CAPACITY],
            n: 0,
            by_x: [0; CLIP_CAPACITY],
            next: 0,
            active: [0; CLIP_CAPACITY],
            n_active: 0,
            min_hi: u16::MAX,
            row: None,
            last_x: None,
        }
    }

    /// The row the state is valid for, if any.
    pub fn row(&self) -> Option<u16> {
        self.row
    }

    /// Forget the current row (the next primary ray uses the plain traversal).
    pub fn clear(&mut self) {
        self.row = None;
        self.last_x = None;
        self.n = 0;
        self.n_active = 0;
        self.min_hi = u16::MAX;
        self.next = 0;
    }

    /// Leaves kept for the row, in tree order.
    pub fn leaves(&self) -> &[u32] {
        &self.leaves[..self.n]
    }

    /// Y clipping: collect the leaves whose rectangles overlap row `y`, walking the tree and
    /// skipping clusters that miss it. Returns false (and clears) when the image has no
    /// rectangles or the row keeps more than [`CLIP_CAPACITY`] leaves. `compares` counts
    /// the integer compares made.
    pub fn y_clip(&mut self, scene: &SceneView<'_>, y: u16, compares: &mut u64) -> bool {
        self.clear();
        if !scene.has_rects() {
            return false;
        }
        let count = scene.node_count();
        let mut i = 0;
        while i < count {
            let node_rect = scene.rect(i);
            *compares += 2;
            if !node_rect.contains_row(y) || node_rect.is_empty() {
                i = scene.node_skip(i);
                continue;
            }
            if scene.node_is_leaf(i) {
                if self.n == CLIP_CAPACITY {
                    self.clear();
                    return false;
                }
                self.leaves[self.n] = i;
                self.cols[self.n] = (node_rect.x_lo, node_rect.x_hi);
                self.n += 1;
            }
            i += 1;
        }
        // Order for the X sweep: by left edge, ties by tree order (a total order, so the
        // unstable sort is deterministic), as one integer key per leaf.
        for k in 0..self.n {
            self.by_x[k] = (self.cols[k].0 as u32) << 16 | k as u32;
        }
        self.by_x[..self.n].sort_unstable();
        *compares += (self.n as u64) * (usize::BITS - self.n.leading_zeros()) as u64;
        self.row = Some(y);
        true
    }

    /// X clipping: move the sweep to column `x` (columns must not decrease within a run).
    /// Returns false (and changes nothing) without a Y-clipped row or when `x` goes back;
    /// the active leaves are then read with [`Self::active_leaf`], in tree order.
    pub fn advance(&mut self, x: u16, compares: &mut u64) -> bool {
        if self.row.is_none() || self.last_x.is_some_and(|l| x < l) {
            return false;
        }
        self.last_x = Some(x);
        // Counted in a local and added once: through the reference the 64-bit count was
        // stored back on every compare.
        let mut n_cmp = 1u32;
        // Drop leaves whose rectangle ended left of x (keeps ascending order); none did
        // while x is at most the smallest right edge.
        if x > self.min_hi {
            let mut kept = 0;
            let mut min_hi = u16::MAX;
            for k in 0..self.n_active {
                let pos = self.active[k];
                let hi = self.cols[pos as usize].1;
                n_cmp += 1;
                if hi >= x {
                    self.active[kept] = pos;
                    kept += 1;
                    min_hi = min_hi.min(hi);
                }
            }
            self.n_active = kept;
            self.min_hi = min_hi;
        }
        // Admit leaves whose rectangle starts at or before x.
        while self.next < self.n {
            let key = self.by_x[self.next];
            let pos = (key & 0xffff) as u16;
            let lo = (key >> 16) as u16;
            n_cmp += 1;
            if lo > x {
                break;
            }
            self.next += 1;
            let hi = self.cols[pos as usize].1;
            n_cmp += 1;
            if hi < x {
                continue;
            }
            self.min_hi = self.min_hi.min(hi);
            // Sorted insert by position (tree order).
            let mut at = self.n_active;
            while at > 0 && self.active[at - 1] > pos {
                self.active[at] = self.active[at - 1];
                at -= 1;
                n_cmp += 1;
            }
            self.active[at] = pos;
            self.n_active += 1;
        }
        *compares += n_cmp as u64;
        true
    }

    /// Node index of the `k`-th active leaf (tree order), `k < active_len()`.
    #[inline]
    pub fn active_leaf(&self, k: usize) -> u32 {
        self.leaves[self.active[k] as usize]
    }

    pub fn active_len(&self) -> usize {
        self.n_active
    }
}

// These tests build scenes with the DM, which needs `std`.
#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::desc::*;
    use crate::dm::{compile, CompileOptions};

    /// Three boxes in a row across the screen, in one cluster; camera at the origin looking
    /// down -Z (view = world x, y, -z).
    fn three_boxes() -> Vec<u8> {
        let b = |x: f64, y: f64| {
            Node::Shape(Shape::Box {
                min: [x - 1.0, y - 1.0, -11.0],
                max: [x + 1.0, y + 1.0, -9.0],
                material: 0,
            })
        };
        let s = SceneDesc {
            camera: Camera {
                eye: [0.0; 3],
                look_at: [0.0, 0.0, -1.0],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: 60.0,
            },
            width: 64,
            height: 48,
            background: [0.0; 3],
            ambient: [0.1; 3],
            max_depth: 2,
            transparency: TransparencyMode::Refractive,
            materials: vec![Material::default()],
            textures: vec![],
            lights: vec![],
            root: Cluster {
                name: "r".into(),
                transform: Transform::default(),
                children: vec![
                    Node::Cluster(Cluster {
                        name: "row".into(),
                        transform: Transform::default(),
                        children: vec![b(-4.0, 0.0), b(0.0, 0.0), b(4.0, 0.0)],
                    }),
                    b(0.0, 4.0),
                ],
            },
        };
        compile(&s, &CompileOptions::default()).unwrap().bytes
    }

    #[test]
    fn rectangles_are_conservative_projections() {
        let img = three_boxes();
        let v = SceneView::new(&img).unwrap();
        assert!(v.has_rects());
        // Brute force: a leaf's rectangle must contain every pixel whose primary ray hits it.
        let mut t = crate::render::Tracer::<f64>::new(v);
        for y in 0..48u32 {
            for x in 0..64u32 {
                let ray = t.primary_ray(x, y);
                if let Some((_, s)) = t.first_surface(&ray) {
                    let leaf = (0..v.node_count())
                        .find(|&i| {
                            v.node_leaf(i).is_some_and(|l| {
                                l.kind == s.shape.kind
                                    && (l.first..l.first + l.count).contains(&s.shape.index)
                            })
                        })
                        .unwrap();
                    let r = v.rect(leaf);
                    assert!(
                        r.contains_row(y as u16) && r.contains_column(x as u16),
                        "({x},{y}) outside {r:?}"
                    );
                    // And every enclosing cluster's rectangle contains the leaf's.
                    for i in 0..leaf {
                        if v.node_skip(i) > leaf {
                            let c = v.rect(i);
                            assert!(
                                c.x_lo <= r.x_lo
                                    && c.x_hi >= r.x_hi
                                    && c.y_lo <= r.y_lo
                                    && c.y_hi >= r.y_hi
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn y_clip_keeps_exactly_the_leaves_overlapping_the_row_in_tree_order() {
        let img = three_boxes();
        let v = SceneView::new(&img).unwrap();
        let mut clip = RowClip::new();
        let mut compares = 0;
        for y in 0..48u16 {
            assert!(clip.y_clip(&v, y, &mut compares));
            let want: Vec<u32> = (0..v.node_count())
                .filter(|&i| {
                    v.node_is_leaf(i) && v.rect(i).contains_row(y) && !v.rect(i).is_empty()
                })
                .collect();
            assert_eq!(clip.leaves(), &want[..], "row {y}");
        }
        // The middle row sees the three boxes of the row cluster, not the upper box.
        assert!(clip.y_clip(&v, 24, &mut compares));
        assert_eq!(clip.leaves().len(), 3);
        assert!(compares > 0);
    }

    #[test]
    fn x_sweep_activates_exactly_the_leaves_containing_each_column() {
        let img = three_boxes();
        let v = SceneView::new(&img).unwrap();
        let mut clip = RowClip::new();
        let mut compares = 0;
        for y in [10u16, 24, 30] {
            clip.y_clip(&v, y, &mut compares);
            for x in 0..64u16 {
                assert!(clip.advance(x, &mut compares));
                let got: Vec<u32> = (0..clip.active_len())
                    .map(|k| clip.active_leaf(k))
                    .collect();
                let want: Vec<u32> = clip
                    .leaves()
                    .iter()
                    .copied()
                    .filter(|&i| v.rect(i).contains_column(x))
                    .collect();
                assert_eq!(got, want, "row {y} column {x}");
            }
            // Columns may not go back within a run.
            assert!(!clip.advance(3, &mut compares));
        }
        // Boundary pixels: a leaf is active on its first and last column, not beyond.
        clip.y_clip(&v, 24, &mut compares);
        let leaf = clip.leaves()[1];
        let r = v.rect(leaf);
        for x in 0..64u16 {
            clip.advance(x, &mut compares);
            let active = (0..clip.active_len()).any(|k| clip.active_leaf(k) == leaf);
            assert_eq!(active, x >= r.x_lo && x <= r.x_hi, "column {x} vs {r:?}");
        }
    }
}
