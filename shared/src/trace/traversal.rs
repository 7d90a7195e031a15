//! Traversal: the nearest hit along a ray (the node tree nearest-first behind its boxes,
//! the Y/X-clipped leaves for primary rays, or every shape for the plain algorithm) and the
//! any-opaque test of shadow rays. It returns hits; completing and shading them is
//! [`super::surface`]'s and [`super::shading`]'s business.

use super::tracer::{Tracer, TracerState};
use crate::geom::{Aabb, Ray, RayInv, SlabSpan};
use crate::image::{BlobGroupRec, Leaf, MapTarget, NodeRef, SceneView, ShapeKind, ShapeRef, NONE};
use crate::num::Real;
use crate::shape::blob::{Ball, BlobGroup, BlobStats};
use crate::shape::boxshape::BoxHit;
use crate::shape::ellipsoid::EllipsoidHit;
use crate::shape::triangle::Shear;
use crate::trace::light_rects::{LeafCell, LightPoint};
use crate::trace::primary::EyeRay;
use core::borrow::BorrowMut;

/// A ray with what every test along it shares: the reciprocal direction of the slab tests
/// and the shear of the triangle tests, made once per ray.
#[derive(Clone, Copy, Debug)]
pub(super) struct Probe<T> {
    pub(super) ray: Ray<T>,
    pub(super) inv: RayInv<T>,
    shear: Shear<T>,
    /// A primary ray: triangles are tested against their edge planes through the eye.
    eye: Option<EyeRay<T>>,
}

impl<T: Real> Probe<T> {
    /// The probe of `ray` (a primary ray when `eye` is given); `triangles`: whether the
    /// scene has any (the shear is made only then).
    #[inline]
    pub(super) fn new(ray: &Ray<T>, eye: Option<EyeRay<T>>, triangles: bool) -> Self {
        Self {
            ray: *ray,
            inv: RayInv::new(ray.dir),
            shear: if triangles {
                Shear::new(ray)
            } else {
                Shear::unused()
            },
            eye,
        }
    }

    /// The slab test ([`Aabb::entry`]): where the ray enters `b` within `[0, t_max]`.
    #[inline]
    pub(super) fn entry(&self, b: &Aabb<T>, t_max: T) -> Option<T> {
        b.entry(&self.ray, &self.inv, t_max)
    }

    #[inline]
    pub(super) fn hits(&self, b: &Aabb<T>, t_max: T) -> bool {
        self.entry(b, t_max).is_some()
    }
}

/// Which shape a ray hit, with what each kind needs to finish the hit.
#[derive(Clone, Copy, Debug)]
pub(super) enum HitDetail<T> {
    /// Barycentric coordinates, and the material of the triangle's leaf.
    Triangle {
        b: [T; 3],
        material: u32,
    },
    Ellipsoid(EllipsoidHit<T>),
    Box(BoxHit<T>),
    Blob {
        t_error: T,
    },
}

#[derive(Clone, Copy, Debug)]
pub(super) struct Hit<T> {
    pub(super) t: T,
    pub(super) shape: ShapeRef,
    pub(super) detail: HitDetail<T>,
}

/// A shape that stopped a shadow ray: the `k`-th shape of `leaf`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Blocker {
    leaf: Leaf,
    k: u32,
}

/// The closest-hit walk's work space: the stack of nodes still to visit with their box
/// entry distances, and one node's hit children being ordered.
pub(super) struct WalkSpace<T> {
    pub(super) stack: [(u32, T); TRAVERSAL_STACK],
    pub(super) kids: [(u32, T); ORDERED_FANOUT],
}

impl<T: Real> WalkSpace<T> {
    pub(super) fn new() -> Self {
        Self {
            stack: [(0, T::ZERO); TRAVERSAL_STACK],
            kids: [(0, T::ZERO); ORDERED_FANOUT],
        }
    }
}

/// Depth of the closest-hit traversal stack (a node and its box entry distance per entry).
pub(super) const TRAVERSAL_STACK: usize = 48;
/// Most children of one node visited nearest-first; further hit children are walked in place.
pub(super) const ORDERED_FANOUT: usize = 8;

/// The nearest hit so far. Equal distances go to the lower shape key (node index, then
/// position in the leaf), so the answer does not depend on the order shapes are tested in
/// (ordered traversal, clipping, plain).
pub(super) struct Nearest<T> {
    pub(super) hit: Option<Hit<T>>,
    pub(super) node: u32,
    /// [`Nearest::limit`] (the walk's `t_max` until a hit) and the nearest hit's distance (infinite without one), kept as
    /// scalars of their own: the walk reads them for every box, and reading them back out of
    /// `hit` (its tag and distance, just stored whole by `offer`) stalled the host's walk.
    limit: T,
    best_t: T,
}

/// The tie-break key of the `k`-th shape of leaf `node` (a leaf holds at most 31).
#[inline(always)]
fn shape_key(node: u32, k: u32) -> u32 {
    (node << 5) | k
}

impl<T: Real> Nearest<T> {
    pub(super) fn new(t_max: T) -> Self {
        Self {
            hit: None,
            node: u32::MAX,
            limit: t_max,
            best_t: T::INFINITY,
        }
    }
    /// Upper bound for tests still worth making: a hit at the current distance may still
    /// win the tie, so a little beyond it; the exact winner is decided in `offer`.
    #[inline]
    pub(super) fn limit(&self) -> T {
        self.limit
    }
    /// Whether a box entered at `t` lies wholly behind the nearest hit (with the same slack;
    /// never without a hit: nothing compares above the infinite `best_t`).
    #[inline]
    pub(super) fn beyond(&self, t: T) -> bool {
        t * (T::ONE - T::err_gamma(16)) > self.best_t
    }
    #[inline]
    pub(super) fn offer(&mut self, h: Hit<T>, node: u32) {
        // A non-finite distance (from non-finite geometry) never wins: it would compare
        // false against everything and make the answer depend on test order.
        if !h.t.is_finite() {
            return;
        }
        let better = match &self.hit {
            None => true,
            Some(b) => h.t < b.t || (h.t == b.t && node < self.node),
        };
        if better {
            // Relative slack: a shape lying in its box's face (a flat box) can compute its
            // hit a few ulps before the box's computed entry, and must still be tested.
            self.limit = h.t * (T::ONE + T::err_gamma(16));
            self.best_t = h.t;
            self.hit = Some(h);
            self.node = node;
        }
    }
}

/// The slab test of a node's box, decoding its axes in `order` and stopping at the first
/// that empties the interval: where the ray enters the box, as [`Aabb::entry`] on the
/// decoded box answers (slabs clip in any order to the same interval).
#[inline(always)]
fn box_entry<T: Real>(
    node: &NodeRef<'_>,
    order: [usize; 3],
    ray: &Ray<T>,
    inv: &RayInv<T>,
    t_max: T,
) -> Option<T> {
    let mut span = SlabSpan::new(t_max);
    for axis in order {
        // Sign-specialised: the ray's direction picks the entry bound, no compare-and-swap.
        let (near, far) = node.slab::<T>(axis, inv.inv_dir[axis].is_sign_negative());
        if !span.clip_entering(near, far, ray.origin[axis], inv.inv_dir[axis]) {
            return None;
        }
    }
    Some(span.t0)
}

/// [`box_entry`] as a yes or no.
#[inline(always)]
fn box_hit<T: Real>(
    node: &NodeRef<'_>,
    order: [usize; 3],
    ray: &Ray<T>,
    inv: &RayInv<T>,
    t_max: T,
) -> bool {
    box_entry(node, order, ray, inv, t_max).is_some()
}

/// The order walks decode a box's axes in: depth (view z) first, where most boxes a
/// secondary or shadow ray misses are told apart (photo1-d0 on the M4F: 7,181 instructions
/// per pixel in x, y, z order, 7,287 y first, 7,048 in this order).
const WALK_AXES: [usize; 3] = [2, 1, 0];

impl<T: Real, S: BorrowMut<TracerState<T>>> Tracer<'_, T, S> {
    /// The primary ray's nearest hit among the Y-clipped leaves (and, with X clipping, only
    /// those whose rectangle contains column `x`), each behind its own box test.
    pub(super) fn closest_hit_clipped(
        &mut self,
        ray: &Ray<T>,
        eye: Option<EyeRay<T>>,
        x: u32,
    ) -> Option<Hit<T>> {
        let probe = Probe::new(ray, eye, self.has_triangles);
        let mut near = Nearest::new(T::MAX);
        let col = x.min(u16::MAX as u32) as u16;
        let swept = self.techniques.x_clip
            && self
                .state
                .borrow_mut()
                .clip
                .advance(col, &mut self.stats.clip_compares);
        let n = if swept {
            self.state.borrow_mut().clip.active_len()
        } else {
            self.state.borrow_mut().clip.leaves().len()
        };
        for k in 0..n {
            let leaf = if swept {
                self.state.borrow_mut().clip.active_leaf(k)
            } else {
                self.state.borrow_mut().clip.leaves()[k]
            };
            self.stats.box_tests += 1;
            // The slab test depth (view z) first: the leaf's screen rectangle already holds
            // the pixel, so x and y rarely reject it, while a leaf behind the nearest hit so
            // far is rejected by z alone, before its x and y are decoded. One node at a time:
            // a node table kept across the loop's calls cost more in spilled registers than
            // it saved (photo1-noshadow +36 instructions per pixel).
            let node = self.scene.node_ref(leaf);
            if !box_hit(&node, [2, 0, 1], &probe.ray, &probe.inv, near.limit()) {
                continue;
            }
            if let Some(l) = self.scene.node_leaf(leaf) {
                self.offer(&mut near, l, leaf, &probe);
            }
        }
        near.hit
    }

    /// Nearest shape along `ray` in (0, t_max): walk the node tree nearest-first, skipping
    /// the subtree of every box the ray misses (LINKS-1 4.2) or enters beyond the nearest
    /// hit so far; a small fixed stack holds the children still to visit.
    pub(super) fn closest_hit(&mut self, ray: &Ray<T>, t_max: T) -> Option<Hit<T>> {
        self.closest_hit_from(ray, None, t_max)
    }

    /// [`Self::closest_hit`], for a primary ray when `eye` is given.
    #[inline(never)]
    pub(super) fn closest_hit_from(
        &mut self,
        ray: &Ray<T>,
        eye: Option<EyeRay<T>>,
        t_max: T,
    ) -> Option<Hit<T>> {
        let probe = Probe::new(ray, eye, self.has_triangles);
        if !self.techniques.bounding_boxes {
            return self.closest_hit_plain(&probe, t_max);
        }
        let nodes = self.scene.node_table();
        let mut near = Nearest::new(t_max);
        // The walk's stack and child list live in the tracer (a walk never nests in another),
        // so no call zeroes them: that cost 6% of the glass scene on the M4F.
        self.stats.box_tests += 1;
        let t_root = probe.entry(&self.scene.node::<T>(0).bounds, t_max)?;
        self.state.borrow_mut().walk.stack[0] = (0, t_root);
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (i, t_in) = self.state.borrow_mut().walk.stack[sp];
            if near.beyond(t_in) {
                continue;
            }
            let node = nodes.get(i);
            if let Some(l) = node.leaf() {
                self.offer(&mut near, l, i, &probe);
                continue;
            }
            // Test the children's boxes; visit the nearest first so later ones can be pruned.
            let mut nk = 0;
            let mut c = i + 1;
            let end = node.skip(i);
            while c < end {
                let child = nodes.get(c);
                self.stats.box_tests += 1;
                let entry = box_entry(&child, WALK_AXES, &probe.ray, &probe.inv, near.limit());
                if let Some(t) = entry {
                    if nk < ORDERED_FANOUT && sp + nk < TRAVERSAL_STACK {
                        self.state.borrow_mut().walk.kids[nk] = (c, t);
                        nk += 1;
                    } else {
                        // No room to order it: walk its subtree in place.
                        let (leaf, skip) = (child.leaf(), child.skip(c));
                        self.walk_hit_subtree(c, leaf, skip, &probe, &mut near);
                    }
                }
                c = child.skip(c);
            }
            // Push farthest first (insertion sort of at most ORDERED_FANOUT entries).
            let kids = &mut self.state.borrow_mut().walk.kids;
            for k in 1..nk {
                let mut j = k;
                while j > 0 && kids[j - 1].1 < kids[j].1 {
                    kids.swap(j - 1, j);
                    j -= 1;
                }
            }
            for k in 0..nk {
                self.state.borrow_mut().walk.stack[sp] = self.state.borrow_mut().walk.kids[k];
                sp += 1;
            }
        }
        near.hit
    }

    /// Depth-first walk (in node order) of a subtree whose root box the ray already hit.
    pub(super) fn walk_hit_subtree(
        &mut self,
        root: u32,
        root_leaf: Option<Leaf>,
        end: u32,
        probe: &Probe<T>,
        near: &mut Nearest<T>,
    ) {
        if let Some(l) = root_leaf {
            self.offer(near, l, root, probe);
            return;
        }
        let mut i = root + 1;
        while i < end {
            let node = self.scene.node::<T>(i);
            self.stats.box_tests += 1;
            if !probe.hits(&node.bounds, near.limit()) {
                i = node.skip;
                continue;
            }
            if let Some(l) = node.leaf {
                self.offer(near, l, i, probe);
            }
            i += 1;
        }
    }

    /// Test a leaf's shapes and keep each that is the nearest so far.
    #[inline]
    pub(super) fn offer(&mut self, near: &mut Nearest<T>, leaf: Leaf, node: u32, probe: &Probe<T>) {
        if leaf.kind == ShapeKind::Triangle {
            return match &probe.eye {
                // The plain algorithm (no bounding boxes) makes each triangle's planes on
                // the spot: it tests more triangles per ray than the cache holds.
                Some(eye) if self.techniques.bounding_boxes => {
                    self.offer_triangles_from_eye::<true>(near, leaf, node, probe, eye)
                }
                Some(eye) => self.offer_triangles_from_eye::<false>(near, leaf, node, probe, eye),
                // One loop per axis permutation, matched once per leaf (as for shadow rays).
                None => match probe.shear.kz() {
                    0 => self.offer_triangles_permuted::<1, 2, 0>(near, leaf, node, probe),
                    1 => self.offer_triangles_permuted::<2, 0, 1>(near, leaf, node, probe),
                    _ => self.offer_triangles_permuted::<0, 1, 2>(near, leaf, node, probe),
                },
            };
        }
        for k in 0..leaf.count {
            if let Some(h) = self.intersect_shape(leaf, k, probe, near.limit()) {
                near.offer(h, shape_key(node, k));
            }
        }
    }

    /// [`Self::offer`] for a leaf of triangles and a primary ray: each triangle against
    /// its edge planes, cached (`CACHED`) or made on the spot.
    fn offer_triangles_from_eye<const CACHED: bool>(
        &mut self,
        near: &mut Nearest<T>,
        leaf: Leaf,
        node: u32,
        probe: &Probe<T>,
        eye: &EyeRay<T>,
    ) {
        self.stats.triangle_tests += leaf.count as u64;
        let mut limit = near.limit();
        for k in 0..leaf.count {
            let index = leaf.first + k;
            let scene = &self.scene;
            let state = self.state.borrow_mut();
            let made;
            let planes = if CACHED {
                state.planes.get(scene, index)
            } else {
                made = state.planes.made_now(scene, index);
                &made
            };
            let test = T::eye_test(planes, eye.d, eye.len, limit);
            let tri = || scene.triangle::<T>(index).tri;
            if let Some(h) = test.or_sheared(tri, &probe.shear, limit) {
                let hit = Hit {
                    t: h.t,
                    shape: leaf.shape(k),
                    detail: HitDetail::Triangle {
                        b: h.b,
                        material: leaf.material,
                    },
                };
                near.offer(hit, shape_key(node, k));
                limit = near.limit();
            }
        }
    }

    /// [`Self::offer`] for a leaf of triangles and a ray of one axis permutation (not from
    /// the eye): the sheared test inlined, the vertices read straight into registers.
    #[inline(always)]
    fn offer_triangles_permuted<const KX: usize, const KY: usize, const KZ: usize>(
        &mut self,
        near: &mut Nearest<T>,
        leaf: Leaf,
        node: u32,
        probe: &Probe<T>,
    ) {
        self.stats.triangle_tests += leaf.count as u64;
        let mut limit = near.limit();
        for k in 0..leaf.count {
            let (_, tri) = self.scene.triangle_corners::<T>(leaf.first + k);
            if let Some(h) = tri.intersect_permuted_inline::<KX, KY, KZ>(&probe.shear, limit) {
                let hit = Hit {
                    t: h.t,
                    shape: leaf.shape(k),
                    detail: HitDetail::Triangle {
                        b: h.b,
                        material: leaf.material,
                    },
                };
                near.offer(hit, shape_key(node, k));
                limit = near.limit();
            }
        }
    }

    /// The plain algorithm: every shape, no boxes (the paper's type 4).
    pub(super) fn closest_hit_plain(&mut self, probe: &Probe<T>, t_max: T) -> Option<Hit<T>> {
        let mut near = Nearest::new(t_max);
        for i in 0..self.scene.node_count() {
            if let Some(l) = self.scene.node_leaf(i) {
                self.offer(&mut near, l, i, probe);
            }
        }
        near.hit
    }

    /// Whether any opaque surface lies along the probe's ray in (0, t_max) (stops at the
    /// first, and says which shape it was), and whether a transparent one was seen on the
    /// way. Which opaque shape is found first depends on the order of the walk, whether
    /// one is found does not. `leaving`: a convex shape the ray starts on and leaves
    /// outwards, which it cannot meet again ([`super::lights`]), so it is not tested.
    ///
    /// `seen`: the ray's point in its light's view ([`super::light_rects`]), when it has
    /// one: a node whose rectangle there does not hold it is skipped before its slab test.
    pub(super) fn any_opaque(
        &mut self,
        probe: &Probe<T>,
        t_max: T,
        leaving: Option<ShapeRef>,
        seen: Option<LightPoint>,
    ) -> (Option<Blocker>, bool) {
        let nodes = self.scene.node_table();
        let mut transparent = false;
        let mut i = 0;
        // Fixed point has no rectangles: the checks compile away there.
        let seen = seen.filter(|_| !T::ABSOLUTE_ROUNDING && self.techniques.bounding_boxes);
        while i < nodes.len() {
            // The box is decoded one axis at a time and the leaf only past it: most nodes
            // a shadow ray visits are missed on their first or second axis.
            let node = nodes.get(i);
            if self.techniques.bounding_boxes {
                self.stats.box_tests += 1;
                if let Some(p) = seen {
                    if self.state.borrow().light_rects.misses(p, i) {
                        i = node.skip(i);
                        continue;
                    }
                }
                if !box_hit(&node, WALK_AXES, &probe.ray, &probe.inv, t_max) {
                    i = node.skip(i);
                    continue;
                }
            }
            if let Some(l) = node.leaf() {
                if l.kind == ShapeKind::Triangle {
                    // The ray's cell in the leaf's rectangle (which holds it: the node was
                    // not rejected), for the triangles' rectangles.
                    let cell = seen.and_then(|p| self.state.borrow().light_rects.leaf_cell(p, i));
                    // One material for the whole leaf: its first hit decides it.
                    if let Some(k) = self.first_triangle_hit(l, probe, t_max, cell) {
                        if self.material_is_opaque(l.material) {
                            return (Some(Blocker { leaf: l, k }), transparent);
                        }
                        transparent = true;
                    }
                } else {
                    for k in 0..l.count {
                        if leaving == Some(l.shape(k)) {
                            continue;
                        }
                        if let Some(h) = self.intersect_shape(l, k, probe, t_max) {
                            if self.is_opaque(&h) {
                                return (Some(Blocker { leaf: l, k }), transparent);
                            }
                            transparent = true;
                        }
                    }
                }
            }
            i += 1;
        }
        (None, transparent)
    }

    /// The first triangle of a leaf the probe's ray crosses in (0, t_max), in leaf order.
    /// `cell`: the ray in the cells of the leaf's rectangle in its light's view
    /// ([`super::light_rects`]): a triangle whose rectangle there does not hold it is
    /// skipped before its test (and still counted as tested).
    fn first_triangle_hit(
        &mut self,
        leaf: Leaf,
        probe: &Probe<T>,
        t_max: T,
        cell: Option<LeafCell>,
    ) -> Option<u32> {
        // One loop per axis permutation, matched once per leaf (shadow rays on photo1-d0:
        // each test called out of line spilled the vertices to the stack and back).
        let (k, hit) = match probe.shear.kz() {
            0 => self.first_hit_permuted::<1, 2, 0>(leaf, probe, t_max, cell),
            1 => self.first_hit_permuted::<2, 0, 1>(leaf, probe, t_max, cell),
            _ => self.first_hit_permuted::<0, 1, 2>(leaf, probe, t_max, cell),
        };
        self.stats.triangle_tests += k as u64;
        hit
    }

    /// [`Self::first_triangle_hit`] for rays of one permutation: (tests made, the hit).
    #[inline(always)]
    fn first_hit_permuted<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        leaf: Leaf,
        probe: &Probe<T>,
        t_max: T,
        cell: Option<LeafCell>,
    ) -> (u32, Option<u32>) {
        for k in 0..leaf.count {
            let t = leaf.first + k;
            if let Some(c) = cell {
                if self.state.borrow().light_rects.triangle_misses(c, t) {
                    continue;
                }
            }
            let (_, tri) = self.scene.triangle_corners::<T>(t);
            if tri
                .intersect_permuted_inline::<KX, KY, KZ>(&probe.shear, t_max)
                .is_some()
            {
                return (k + 1, Some(k));
            }
        }
        (leaf.count, None)
    }

    /// Whether `blocker` stops the probe's ray within (0, t_max).
    #[inline]
    pub(super) fn blocks(&mut self, blocker: Blocker, probe: &Probe<T>, t_max: T) -> bool {
        self.intersect_shape(blocker.leaf, blocker.k, probe, t_max)
            .is_some_and(|h| self.is_opaque(&h))
    }

    /// Whether a hit surface lets no light through (no transmission, no transmission map).
    fn is_opaque(&mut self, h: &Hit<T>) -> bool {
        self.material_is_opaque(self.material_of(h))
    }

    fn material_is_opaque(&mut self, material: u32) -> bool {
        let m = self
            .state
            .borrow_mut()
            .records
            .material(&self.scene, material);
        let mapped = m.texture != NONE && m.target == MapTarget::Transmit;
        m.transmit.max_component() <= T::ZERO && !mapped
    }

    pub(super) fn material_of(&self, hit: &Hit<T>) -> u32 {
        let s = &self.scene;
        if let HitDetail::Triangle { material, .. } = hit.detail {
            return material;
        }
        match hit.shape.kind {
            ShapeKind::Triangle => 0,
            ShapeKind::Ellipsoid => s.ellipsoid::<T>(hit.shape.index).material,
            ShapeKind::Box => s.boxshape::<T>(hit.shape.index).material,
            ShapeKind::Blob => s.blob_group::<T>(hit.shape.index).material,
        }
    }

    /// Test the `k`-th shape of `leaf`.
    pub(super) fn intersect_shape(
        &mut self,
        leaf: Leaf,
        k: u32,
        probe: &Probe<T>,
        t_max: T,
    ) -> Option<Hit<T>> {
        let s = &self.scene;
        let ray = &probe.ray;
        let shape = leaf.shape(k);
        match shape.kind {
            ShapeKind::Triangle => {
                self.stats.triangle_tests += 1;
                let tri = || s.triangle::<T>(shape.index).tri;
                let h = match &probe.eye {
                    Some(eye) => {
                        let planes = self.state.borrow_mut().planes.get(s, shape.index);
                        T::eye_test(planes, eye.d, eye.len, t_max).or_sheared(
                            tri,
                            &probe.shear,
                            t_max,
                        )
                    }
                    None => tri().intersect_sheared(&probe.shear, t_max),
                };
                h.map(|h| Hit {
                    t: h.t,
                    shape,
                    detail: HitDetail::Triangle {
                        b: h.b,
                        material: leaf.material,
                    },
                })
            }
            ShapeKind::Ellipsoid => {
                self.stats.ellipsoid_tests += 1;
                let rec = self.state.borrow_mut().records.ellipsoid(s, shape.index);
                rec.shape.intersect(ray, t_max).map(|h| Hit {
                    t: h.t,
                    shape,
                    detail: HitDetail::Ellipsoid(h),
                })
            }
            ShapeKind::Box => {
                self.stats.box_shape_tests += 1;
                let bounds = self.state.borrow().box_bounds(shape.index);
                let rec = self.state.borrow_mut().records.boxshape(s, shape.index);
                let origin_error = bounds.map(|b| b.origin);
                rec.shape
                    .intersect_bounded(ray, t_max, origin_error)
                    .map(|h| Hit {
                        t: h.t,
                        shape,
                        detail: HitDetail::Box(h),
                    })
            }
            ShapeKind::Blob => {
                self.stats.blob_tests += 1;
                let (_, group) = blob_group(*s, shape.index);
                let mut bs = BlobStats::default();
                let h = group.intersect(ray, T::ZERO, t_max, &mut bs);
                self.stats.blob_field_evals += bs.field_evals as u64;
                h.map(|h| Hit {
                    t: h.t,
                    shape,
                    detail: HitDetail::Blob { t_error: h.t_error },
                })
            }
        }
    }
}

/// A density-sphere group record and the group itself, its balls read in place.
pub(super) fn blob_group<T: Real>(
    scene: SceneView<'_>,
    index: u32,
) -> (
    BlobGroupRec<T>,
    BlobGroup<T, impl Fn(usize) -> Ball<T> + '_>,
) {
    let g = scene.blob_group::<T>(index);
    let first = g.first;
    let group = BlobGroup {
        count: g.count as usize,
        ball: move |k: usize| scene.ball::<T>(first + k as u32),
        kernel: g.kernel,
        threshold: g.threshold,
    };
    (g, group)
}
