//! The cluster hierarchy (LINKS-1 4.1): the flat node list the tracer walks, each cluster
//! opened before its children and closed with their union box and screen rectangle.
//!
//! Nodes are collected here while the shapes are written, then [`Dm::write_tree`] drops
//! clusters with a single child (their child's box is the same or tighter), puts every box
//! on the image's power-of-two grid (rounded outward) and writes the nodes and their
//! screen rectangles.

use super::*;

/// A node as the DM builds it, before the grid is known.
#[derive(Clone, Copy, Debug)]
pub(super) struct BuildNode {
    pub(super) b: Bounds,
    pub(super) rect: Rect,
    /// First node after this node's subtree.
    pub(super) skip: u32,
    pub(super) leaf: Option<Leaf>,
}

/// Grid coordinates span i16 (Q16.16 holds them as integers).
const GRID_MIN: f64 = i16::MIN as f64;
const GRID_MAX: f64 = i16::MAX as f64;

/// The node grid: per axis a power-of-two step and an origin that is a multiple of it,
/// chosen so the root box fits in i16 coordinates and `origin + q * step` is exact in f32.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct NodeGrid {
    pub(super) origin: [f32; 3],
    pub(super) step: [f32; 3],
}

impl NodeGrid {
    pub(super) fn for_box(b: &Bounds) -> Result<Self, DmError> {
        let finite = b.min.iter().chain(&b.max).all(|v| v.is_finite());
        // An empty scene needs no grid; a non-finite one is refused after writing
        // ([`DmError::BeyondF32`] names its record).
        if b.is_empty() || !finite {
            return Ok(Self {
                origin: [0.0; 3],
                step: [1.0; 3],
            });
        }
        let mut origin = [0.0f32; 3];
        let mut step = [0.0f32; 3];
        for k in 0..3 {
            let (lo, hi) = (f64::from(b.min[k]), f64::from(b.max[k]));
            let center = 0.5 * (lo + hi);
            // Fine enough for the extent, coarse enough that |origin / step| + 2^15 < 2^24.
            let need = ((hi - lo) / 65000.0)
                .max(center.abs() / f64::from(1u32 << 23))
                .max(f64::from(f32::MIN_POSITIVE));
            let mut e = need.log2().ceil().clamp(-149.0, 128.0) as i32;
            loop {
                let s = 2f64.powi(e);
                let o = (center / s).round() * s;
                if (lo - o) / s >= GRID_MIN && (hi - o) / s <= GRID_MAX {
                    origin[k] = o as f32;
                    step[k] = s as f32;
                    break;
                }
                e += 1;
                if e > 126 {
                    return Err(DmError::TooLarge {
                        what: "the scene's extent exceeds the node grid".into(),
                    });
                }
            }
        }
        Ok(Self { origin, step })
    }

    /// A box's grid corners, rounded outward (an empty box stays empty).
    pub(super) fn quantise(&self, b: &Bounds) -> ([i16; 3], [i16; 3]) {
        if b.is_empty() {
            return ([i16::MAX; 3], [i16::MIN; 3]);
        }
        let q = |v: f32, k: usize, up: bool| {
            // Exact in f64: f32 values and power-of-two steps.
            let t = (f64::from(v) - f64::from(self.origin[k])) / f64::from(self.step[k]);
            let t = if up { t.ceil() } else { t.floor() };
            t.clamp(GRID_MIN, GRID_MAX) as i16
        };
        (
            [0, 1, 2].map(|k| q(b.min[k], k, false)),
            [0, 1, 2].map(|k| q(b.max[k], k, true)),
        )
    }
}

/// The smallest shift that brings every pixel coordinate of a `width` x `height` image into
/// a byte.
pub(super) fn rect_shift(width: u32, height: u32) -> u32 {
    let mut s = 0;
    while (width.max(height).saturating_sub(1) >> s) > 255 {
        s += 1;
    }
    s
}

impl Dm<'_> {
    /// Start a cluster node; returns its index so `close` can patch skip and bounds.
    pub(super) fn open_node(&mut self) -> u32 {
        let i = self.nodes.len() as u32;
        self.nodes.push(BuildNode {
            b: Bounds::empty(),
            rect: Rect::EMPTY,
            skip: 0,
            leaf: None,
        });
        i
    }

    pub(super) fn close_node(&mut self, i: u32, b: Bounds) {
        let skip = self.nodes.len() as u32;
        // A cluster's rectangle is the union of its children's (tighter than its box's).
        let r = self.nodes[i as usize + 1..]
            .iter()
            .fold(Rect::EMPTY, |a, n| a.union(n.rect));
        let n = &mut self.nodes[i as usize];
        n.rect = r;
        n.skip = skip;
        n.b = b;
    }

    /// A leaf for one shape; its screen rectangle comes from its box's corners.
    pub(super) fn leaf(&mut self, kind: ShapeKind, index: u32, b: Bounds) {
        let rect = self.proj.rect_of_bounds(&b);
        self.leaf_with_rect(
            Leaf {
                kind,
                first: index,
                count: 1,
                material: 0,
            },
            b,
            rect,
        );
    }

    pub(super) fn leaf_with_rect(&mut self, leaf: Leaf, b: Bounds, rect: Rect) {
        let i = self.nodes.len() as u32;
        self.nodes.push(BuildNode {
            b,
            rect,
            skip: i + 1,
            leaf: Some(leaf),
        });
    }

    pub(super) fn cluster(
        &mut self,
        c: &Cluster,
        parent: &Affine,
        path: &str,
    ) -> Result<Bounds, DmError> {
        let t = &c.transform;
        let local = Affine::from_trs(t.translate, t.rotate_deg, t.scale);
        let full = parent.then(&local);
        if !full.is_finite() || inverse(&full.a).is_none() {
            return Err(DmError::DegenerateTransform {
                cluster: path.to_string(),
            });
        }
        let node = self.open_node();
        let mut b = Bounds::empty();
        for child in &c.children {
            let cb = match child {
                Node::Cluster(sub) => {
                    let p = format!("{path}/{}", sub.name);
                    self.cluster(sub, &full, &p)?
                }
                Node::Shape(s) => self.shape(s, &full, path)?,
            };
            b = b.union(cb);
        }
        self.close_node(node, b);
        Ok(b)
    }

    pub(super) fn check_material(&self, m: u32) -> Result<u32, DmError> {
        if (m as usize) < self.desc.materials.len() {
            Ok(m)
        } else {
            Err(DmError::BadIndex {
                what: format!("shape uses missing material {m}"),
            })
        }
    }

    /// Write the collected nodes: single-child clusters dropped, boxes on the grid, the
    /// grid and rectangle unit into the camera record, rectangles when clipping uses them.
    pub(super) fn write_tree(&mut self, width: u32, height: u32) -> Result<(), DmError> {
        let nodes = collapse(&core::mem::take(&mut self.nodes));
        if nodes.len() > u16::MAX as usize {
            return Err(DmError::TooLarge {
                what: format!("{} tree nodes (at most {})", nodes.len(), u16::MAX),
            });
        }
        let root = nodes.first().map_or(Bounds::empty(), |n| n.b);
        let grid = NodeGrid::for_box(&root)?;
        let shift = rect_shift(width, height);
        for k in 0..3 {
            let cam = |at: usize| (Section::Camera, 0, at + 4 * k);
            let (s, r, at) = cam(camera::GRID_ORIGIN);
            self.w.patch_u32(s, r, at, grid.origin[k].to_bits());
            let (s, r, at) = cam(camera::GRID_STEP);
            self.w.patch_u32(s, r, at, grid.step[k].to_bits());
        }
        self.w
            .patch_u32(Section::Camera, 0, camera::RECT_SHIFT, shift);
        for n in &nodes {
            let (lo, hi) = grid.quantise(&n.b);
            let (index, info, material) = match n.leaf {
                Some(l) => (l.first as u16, l.info(), l.material as u8),
                None => (n.skip as u16, 0, 0),
            };
            self.w
                .push(Section::Nodes)
                .1
                .hs(node::LO, &lo.map(|q| q as u16))
                .hs(node::HI, &hi.map(|q| q as u16))
                .h(node::INDEX, index)
                .b(node::INFO, info)
                .b(node::MATERIAL, material);
        }
        {
            for n in &nodes {
                let r = if n.rect.is_empty() {
                    [1, 0, 1, 0]
                } else {
                    [n.rect.x_lo, n.rect.x_hi, n.rect.y_lo, n.rect.y_hi]
                        .map(|v| (v >> shift).min(255) as u8)
                };
                self.w
                    .push(Section::Rects)
                    .1
                    .b(rect::X_LO, r[0])
                    .b(rect::X_HI, r[1])
                    .b(rect::Y_LO, r[2])
                    .b(rect::Y_HI, r[3]);
            }
        }
        Ok(())
    }
}

/// The node list with every cluster that has exactly one child replaced by that child
/// (preorder and leaf order kept; skips renumbered).
fn collapse(nodes: &[BuildNode]) -> Vec<BuildNode> {
    let mut out = Vec::with_capacity(nodes.len());
    if !nodes.is_empty() {
        emit(nodes, 0, &mut out);
    }
    out
}

/// Most children a cluster gets by taking in its child clusters' children.
pub(super) const WIDE_FANOUT: usize = 4;

/// Append node `i`'s subtree to `out`, collapsed.
fn emit(nodes: &[BuildNode], i: usize, out: &mut Vec<BuildNode>) {
    let n = nodes[i];
    if n.leaf.is_some() {
        out.push(BuildNode {
            skip: out.len() as u32 + 1,
            ..n
        });
        return;
    }
    let children = widen(nodes, child_starts(nodes, i));
    if children.len() == 1 {
        emit(nodes, children[0], out);
        return;
    }
    let at = out.len();
    out.push(n);
    for c in children {
        emit(nodes, c, out);
    }
    out[at].skip = out.len() as u32;
}

/// A wider tree: while it stays within [`WIDE_FANOUT`], the child cluster with the largest
/// box is replaced by its own children (in place, so leaf order is kept). Fewer cluster
/// records, and a ray tests the same boxes it would have tested one level down.
fn widen(nodes: &[BuildNode], mut children: Vec<usize>) -> Vec<usize> {
    loop {
        let best = children
            .iter()
            .enumerate()
            .filter(|(_, &c)| nodes[c].leaf.is_none())
            .map(|(k, &c)| (k, child_starts(nodes, c)))
            .filter(|(_, g)| children.len() - 1 + g.len() <= WIDE_FANOUT)
            .max_by(|a, b| {
                half_area(&nodes[children[a.0]].b).total_cmp(&half_area(&nodes[children[b.0]].b))
            });
        let Some((k, grand)) = best else {
            return children;
        };
        children.splice(k..=k, grand);
    }
}

/// The first node of each child subtree of cluster `i`.
fn child_starts(nodes: &[BuildNode], i: usize) -> Vec<usize> {
    let mut v = Vec::new();
    let mut c = i + 1;
    while c < nodes[i].skip as usize {
        v.push(c);
        c = nodes[c].skip as usize;
    }
    v
}
