//! The cluster hierarchy (LINKS-1 4.1): the flat node list the tracer walks, each cluster
//! opened before its children and closed with their union box and screen rectangle.

use super::*;

impl Dm<'_> {
    /// Start a cluster node; returns its index so `close` can patch skip and bounds.
    pub(super) fn open_node(&mut self) -> u32 {
        let (i, r) = self.w.push(Section::Nodes);
        r.fs(node::MIN, &[0.0; 3])
            .fs(node::MAX, &[0.0; 3])
            .u(node::SKIP, 0)
            .u(node::SHAPE, NONE);
        self.rects.push(Rect::EMPTY);
        i
    }

    pub(super) fn close_node(&mut self, i: u32, b: Bounds) {
        let skip = self.w.count(Section::Nodes);
        // A cluster's rectangle is the union of its children's (tighter than its box's).
        let r = self.rects[i as usize + 1..skip as usize]
            .iter()
            .fold(Rect::EMPTY, |a, r| a.union(*r));
        self.rects[i as usize] = r;
        self.w.patch_u32(Section::Nodes, i, node::SKIP, skip);
        for k in 0..3 {
            self.w
                .patch_u32(Section::Nodes, i, node::MIN + 4 * k, b.min[k].to_bits());
            self.w
                .patch_u32(Section::Nodes, i, node::MAX + 4 * k, b.max[k].to_bits());
        }
    }

    /// A leaf for one shape; its screen rectangle comes from its box's corners.
    pub(super) fn leaf(&mut self, shape: ShapeRef, b: Bounds) {
        let rect = self.proj.rect_of_bounds(&b);
        self.leaf_with_rect(shape, b, rect);
    }

    pub(super) fn leaf_with_rect(&mut self, shape: ShapeRef, b: Bounds, rect: Rect) {
        let (i, r) = self.w.push(Section::Nodes);
        r.fs(node::MIN, &b.min)
            .fs(node::MAX, &b.max)
            .u(node::SKIP, i + 1)
            .u(node::SHAPE, shape.encode());
        self.rects.push(rect);
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
}
