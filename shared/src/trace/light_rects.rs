//! Shadow rays: nodes clipped in the light's view, as primary rays clip them in the eye's.
//!
//! A shadow ray towards a directional light is one point in the light's parallel
//! projection (the plane across its direction), and a shadow ray towards a point light is
//! one point in the central projection from the light (every point of the segment between
//! the surface and the light lies on one line through the light). A node's box projects to
//! a convex region; its bounding rectangle, quantised to 16 bits with a margin of three
//! units, says in two subtractions and two compares that the ray misses the box: LINKS-1's screen-space
//! clipping (4.4) with the light as the eye. The any-opaque walk of shadow rays
//! ([`super::traversal`]) asks the rectangle before the box's slab test and skips the
//! subtree when the ray's point lies outside it.
//!
//! Exact by margin: the rectangle only ever rejects a ray that misses the box by three
//! quantisation units (at least 1/21,000 of the scene's projected extent), far beyond the
//! rounding of the projection or of the slab test, whose answer for such a ray is a miss as
//! well. So the walk visits the same nodes, finds the same blockers, and the pixels do not
//! change; a rejection still counts as a box test (the ray was tested against the box, in
//! the light's view). The rectangles are made when the tracer state takes a new scene (a
//! first version made each on the node's first visit and compared four u16 bounds: with that
//! check photo1-d0 took 6,292 instructions per pixel on the Cortex-M4F, 5,972 in this form,
//! 6,167 without rectangles; `scripts/qemu-profile --scene photo1-d0`). Floating point only: fixed point rounds absolutely (and its shadow rays
//! towards a point light pass the light up to half a scaled unit off), so it keeps the slab
//! test.
//!
//! Triangles the same way, one level down: each of the first [`LIGHT_RECT_TRIANGLES`]
//! triangles (in leaves among the first nodes) gets its rectangle, the hull of its corners'
//! points widened by the same margin, in 4-bit cells of its leaf's rectangle rounded
//! outwards. A shadow ray that passes a leaf's rectangle takes its cell there once
//! ([`LightRects::leaf_cell`]) and skips each triangle whose cells do not hold it before
//! decoding the triangle ([`LightRects::triangle_misses`]); the rejected triangles count as
//! tested, and a leaf's first hit is the same triangle (photo1-d0 on the M4F: 5,972 ->
//! 5,836 per pixel in the profile; 57% of photo1's shadow-ray triangle tests skipped).

use crate::geom::Vec3;
use crate::image::{LightKind, SceneView, ShapeKind};
use crate::num::Real;

/// Nodes (the first ones of the tree) that have rectangles; deeper nodes always take the
/// slab test.
pub const LIGHT_RECT_NODES: usize = 256;

/// Lights (the scene's first ones) whose shadow rays are clipped.
pub const LIGHT_RECT_LIGHTS: usize = 2;

/// Triangles (the scene's first ones, in leaves among the first [`LIGHT_RECT_NODES`]) that
/// have rectangles within their leaf's; the others always take the triangle test. photo1
/// has 738 triangles, photo2 908; 768 keeps the tracer state within half the F407's CCM
/// (`tracer.rs`'s size test).
pub const LIGHT_RECT_TRIANGLES: usize = 768;

/// Cells a triangle's rectangle is quantised to across its leaf's rectangle, per
/// coordinate (4 bits: two bytes a triangle and light, 3 KB in all).
const LEAF_CELLS: u32 = 16;

/// A triangle rectangle that rejects nothing (low end 0, width 15, per coordinate).
const TRIANGLE_EVERYWHERE: u16 = 0xf0f0;

/// Quantisation units between the range's ends (below 65,535, so the margins stay inside
/// the u16 range).
const UNITS: f32 = 64_000.0;

/// A rectangle's margin in quantisation units (truncation is one; rounding far less).
const MARGIN: i32 = 3;

/// A rectangle that rejects nothing.
const EVERYWHERE: [u16; 4] = [0, u16::MAX, 0, u16::MAX];

/// A shadow ray's point in its light's quantised view: the slot of the light and the two
/// coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LightPoint {
    slot: u8,
    a: u16,
    b: u16,
}

/// How one light sees the scene.
#[derive(Clone, Copy, Debug)]
struct LightView<T> {
    /// The light's position (central projection), or `None` for a parallel projection.
    from: Option<Vec3<T>>,
    /// The projection's axes: `u` and `v` across, `w` along the view.
    u: Vec3<T>,
    v: Vec3<T>,
    w: Vec3<T>,
    /// The least depth (along `w`, from the light) a box or a ray's origin must have for a
    /// central projection; nearer ones are not clipped.
    near: T,
    /// The range's low ends and the units per length of each coordinate.
    low: [T; 2],
    scale: [T; 2],
}

impl<T: Real> LightView<T> {
    /// The view of a light travelling along `dir` (directional) or sitting at `pos` (point
    /// and spot lights), for a scene inside `root` (its box's corners).
    fn new(kind: LightKind, pos: Vec3<T>, dir: Vec3<T>, root: [Vec3<T>; 2]) -> Option<Self> {
        let centre = (root[0] + root[1]) * T::HALF;
        let extent = (root[1] - root[0]).abs();
        let size = extent.x + extent.y + extent.z;
        let (from, w) = match kind {
            LightKind::Directional => (None, -dir),
            LightKind::Point | LightKind::Spot => (Some(pos), (centre - pos).try_normalize()?),
        };
        // Across the view: the axis least along `w`, crossed with it.
        let a = w.abs();
        let axis = if a.x <= a.y && a.x <= a.z {
            Vec3::new(T::ONE, T::ZERO, T::ZERO)
        } else if a.y <= a.z {
            Vec3::new(T::ZERO, T::ONE, T::ZERO)
        } else {
            Vec3::new(T::ZERO, T::ZERO, T::ONE)
        };
        let u = w.cross(axis).try_normalize()?;
        let v = w.cross(u);
        let mut view = LightView {
            from,
            u,
            v,
            w,
            near: size * T::from_f32(1.0 / 256.0),
            low: [T::ZERO; 2],
            scale: [T::ONE; 2],
        };
        // The range: the root box's view, or (a light close to or inside the scene) the
        // directions within 76 degrees of the centre's.
        let range = view.project_box(root).unwrap_or([
            -T::from_i32(4),
            T::from_i32(4),
            -T::from_i32(4),
            T::from_i32(4),
        ]);
        let units = T::from_f32(UNITS);
        for k in 0..2 {
            let span = range[2 * k + 1] - range[2 * k];
            if !(span > T::ZERO && span.is_finite()) {
                return None;
            }
            view.low[k] = range[2 * k];
            view.scale[k] = units / span;
        }
        Some(view)
    }

    /// Where `x` lies in the view (unquantised), if in front of a central projection's
    /// near depth.
    // The negated comparison is deliberate: a NaN depth is not in front.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline(always)]
    fn project(&self, x: Vec3<T>) -> Option<[T; 2]> {
        match self.from {
            None => Some([self.u.dot(x), self.v.dot(x)]),
            Some(l) => {
                let d = x - l;
                let depth = self.w.dot(d);
                if !(depth >= self.near) {
                    return None;
                }
                let r = depth.recip();
                Some([self.u.dot(d) * r, self.v.dot(d) * r])
            }
        }
    }

    /// The bounding rectangle (a_lo, a_hi, b_lo, b_hi) of a box's view, unquantised.
    fn project_box(&self, b: [Vec3<T>; 2]) -> Option<[T; 4]> {
        if self.from.is_none() {
            // Parallel: the centre's point plus and minus the half-extents' reach across.
            let c = (b[0] + b[1]) * T::HALF;
            let h = (b[1] - b[0]) * T::HALF;
            let (a, bb) = (self.u.dot(c), self.v.dot(c));
            let (ra, rb) = (self.u.abs().dot(h), self.v.abs().dot(h));
            let r = [a - ra, a + ra, bb - rb, bb + rb];
            return r.iter().all(|x| x.is_finite()).then_some(r);
        }
        let mut r = [T::MAX, -T::MAX, T::MAX, -T::MAX];
        for k in 0..8 {
            let c = Vec3::new(b[k & 1].x, b[(k >> 1) & 1].y, b[(k >> 2) & 1].z);
            let [a, bb] = self.project(c)?;
            r = [r[0].min(a), r[1].max(a), r[2].min(bb), r[3].max(bb)];
        }
        r.iter().all(|x| x.is_finite()).then_some(r)
    }

    /// A coordinate in quantisation units (truncated; saturating), if finite.
    #[inline(always)]
    fn units(&self, k: usize, x: T) -> Option<i32> {
        let q = ((x - self.low[k]) * self.scale[k]).to_f32();
        q.is_finite().then_some(q as i32)
    }
}

/// A rectangle as the walk reads it: per coordinate one word, the low end in the low half
/// and the width in the high half, so a point is inside when `point - low` (16-bit
/// wrapping) is at most the width: two subtractions and two compares.
type Packed = [u32; 2];

/// A rectangle that rejects nothing.
const PACKED_EVERYWHERE: Packed = [0xffff_0000; 2];

fn pack(r: [u16; 4]) -> Packed {
    let word = |lo: u16, hi: u16| lo as u32 | ((hi.saturating_sub(lo) as u32) << 16);
    [word(r[0], r[1]), word(r[2], r[3])]
}

/// A shadow ray's point in the cells of a leaf's rectangle ([`LightRects::leaf_cell`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LeafCell {
    slot: u8,
    a: u8,
    b: u8,
}

/// How many bits a leaf rectangle's width in units is shifted down by to give cells: the
/// least that leaves it below [`LEAF_CELLS`].
#[inline(always)]
fn cell_shift(width: u32) -> u32 {
    32 - (width / LEAF_CELLS).leading_zeros()
}

/// The light views, the nodes' rectangles in them, and the triangles' within their leaves'.
pub struct LightRects<T: Real> {
    views: [Option<LightView<T>>; LIGHT_RECT_LIGHTS],
    rects: [[Packed; LIGHT_RECT_NODES]; LIGHT_RECT_LIGHTS],
    /// Per triangle a byte a coordinate: the low end in cells in the low nibble, the width
    /// in the high nibble.
    triangles: [[u16; LIGHT_RECT_TRIANGLES]; LIGHT_RECT_LIGHTS],
}

impl<T: Real> LightRects<T> {
    pub fn new() -> Self {
        Self {
            views: [None; LIGHT_RECT_LIGHTS],
            rects: [[PACKED_EVERYWHERE; LIGHT_RECT_NODES]; LIGHT_RECT_LIGHTS],
            triangles: [[TRIANGLE_EVERYWHERE; LIGHT_RECT_TRIANGLES]; LIGHT_RECT_LIGHTS],
        }
    }

    /// Take `scene`'s lights and make the rectangles of its first nodes in their views.
    pub fn reset(&mut self, scene: &SceneView<'_>) {
        self.views = [None; LIGHT_RECT_LIGHTS];
        self.rects = [[PACKED_EVERYWHERE; LIGHT_RECT_NODES]; LIGHT_RECT_LIGHTS];
        self.triangles = [[TRIANGLE_EVERYWHERE; LIGHT_RECT_TRIANGLES]; LIGHT_RECT_LIGHTS];
        if T::ABSOLUTE_ROUNDING || scene.node_count() == 0 {
            return;
        }
        let node_box = |i: u32| {
            let b = scene.node::<T>(i).bounds;
            [b.min, b.max]
        };
        let root = node_box(0);
        let count = (scene.light_count() as usize).min(LIGHT_RECT_LIGHTS);
        let made = (scene.node_count() as usize).min(LIGHT_RECT_NODES);
        for slot in 0..count {
            let l = scene.light::<T>(slot as u32);
            let Some(view) = LightView::new(l.kind, l.pos, l.dir, root) else {
                continue;
            };
            self.views[slot] = Some(view);
            for (i, r) in self.rects[slot].iter_mut().enumerate().take(made) {
                *r = pack(rect(&view, &node_box(i as u32)));
            }
            // Each triangle once: one referenced by a second leaf keeps the rectangle that
            // rejects nothing (the compiler gives every triangle one leaf; this is not
            // relied on).
            let mut seen = [0u32; LIGHT_RECT_TRIANGLES / 32];
            for i in 0..made {
                let Some(leaf) = scene.node::<T>(i as u32).leaf else {
                    continue;
                };
                if leaf.kind != ShapeKind::Triangle {
                    continue;
                }
                let within = self.rects[slot][i];
                for k in 0..leaf.count {
                    let t = leaf.first.saturating_add(k) as usize;
                    if t >= LIGHT_RECT_TRIANGLES {
                        break;
                    }
                    let (word, bit) = (t / 32, 1u32 << (t % 32));
                    self.triangles[slot][t] = if seen[word] & bit == 0 {
                        let (_, tri) = scene.triangle_corners::<T>(t as u32);
                        within_leaf(triangle_rect(&view, &tri.p), within)
                    } else {
                        TRIANGLE_EVERYWHERE
                    };
                    seen[word] |= bit;
                }
            }
        }
    }

    /// The point of `light`'s shadow ray from `origin` in the light's view, when the light
    /// has one and the ray's point lies in front of it.
    #[inline]
    pub(super) fn point(&self, light: u32, origin: Vec3<T>) -> Option<LightPoint> {
        let slot = light as usize;
        let view = self.views.get(slot)?.as_ref()?;
        let [a, b] = view.project(origin)?;
        let clamp = |q: i32| q.clamp(0, u16::MAX as i32) as u16;
        Some(LightPoint {
            slot: slot as u8,
            a: clamp(view.units(0, a)?),
            b: clamp(view.units(1, b)?),
        })
    }

    /// Whether the ray at `p` certainly misses node `i`'s box. Nodes past
    /// [`LIGHT_RECT_NODES`] are never missed here.
    #[inline(always)]
    pub(super) fn misses(&self, p: LightPoint, i: u32) -> bool {
        let Some(r) = self.rects[p.slot as usize % LIGHT_RECT_LIGHTS].get(i as usize) else {
            return false;
        };
        let outside = |q: u16, w: u32| q.wrapping_sub(w as u16) as u32 > w >> 16;
        outside(p.a, r[0]) || outside(p.b, r[1])
    }

    /// The ray at `p` in the cells of node `i`'s rectangle, for [`Self::triangle_misses`]
    /// on the triangles of that leaf. Only for a node whose rectangle holds `p` (that
    /// [`Self::misses`] kept): `None` past [`LIGHT_RECT_NODES`].
    #[inline(always)]
    pub(super) fn leaf_cell(&self, p: LightPoint, i: u32) -> Option<LeafCell> {
        let r = self.rects[p.slot as usize % LIGHT_RECT_LIGHTS].get(i as usize)?;
        // Within the rectangle `q - low` is at most the width, so the cell at most 15.
        let cell = |q: u16, w: u32| {
            let c = (q.wrapping_sub(w as u16) as u32) >> cell_shift(w >> 16);
            c.min(LEAF_CELLS - 1) as u8
        };
        Some(LeafCell {
            slot: p.slot,
            a: cell(p.a, r[0]),
            b: cell(p.b, r[1]),
        })
    }

    /// Whether the ray in leaf cell `c` certainly misses triangle `t` of that leaf.
    /// Triangles past [`LIGHT_RECT_TRIANGLES`] are never missed here.
    #[inline(always)]
    pub(super) fn triangle_misses(&self, c: LeafCell, t: u32) -> bool {
        let Some(&r) = self.triangles[c.slot as usize % LIGHT_RECT_LIGHTS].get(t as usize) else {
            return false;
        };
        let r = r as u32;
        let outside = |c: u8, byte: u32| (c as u32).wrapping_sub(byte & 15) > (byte >> 4) & 15;
        outside(c.a, r) || outside(c.b, r >> 8)
    }
}

impl<T: Real> Default for LightRects<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// The quantised rectangle of box `b` in `view`, widened by [`MARGIN`] units; the rectangle
/// that rejects nothing when the box reaches behind a central projection's near depth.
#[inline(never)]
fn rect<T: Real>(view: &LightView<T>, b: &[Vec3<T>; 2]) -> [u16; 4] {
    let Some(r) = view.project_box(*b) else {
        return EVERYWHERE;
    };
    let mut q = [0u16; 4];
    for k in 0..2 {
        let (Some(lo), Some(hi)) = (view.units(k, r[2 * k]), view.units(k, r[2 * k + 1])) else {
            return EVERYWHERE;
        };
        q[2 * k] = lo.saturating_sub(MARGIN).clamp(0, u16::MAX as i32) as u16;
        q[2 * k + 1] = hi.saturating_add(MARGIN).clamp(0, u16::MAX as i32) as u16;
    }
    q
}

/// The quantised rectangle of a triangle with corners `p` in `view`, widened by [`MARGIN`]
/// units; the rectangle that rejects nothing when a corner lies behind a central
/// projection's near depth (the triangle's view is the hull of its corners' points).
fn triangle_rect<T: Real>(view: &LightView<T>, p: &[Vec3<T>; 3]) -> [u16; 4] {
    let mut r = [i32::MAX, i32::MIN, i32::MAX, i32::MIN];
    for x in p {
        let Some(q) = view.project(*x) else {
            return EVERYWHERE;
        };
        for k in 0..2 {
            let Some(u) = view.units(k, q[k]) else {
                return EVERYWHERE;
            };
            r[2 * k] = r[2 * k].min(u);
            r[2 * k + 1] = r[2 * k + 1].max(u);
        }
    }
    let clamp = |u: i32| u.clamp(0, u16::MAX as i32) as u16;
    [
        clamp(r[0].saturating_sub(MARGIN)),
        clamp(r[1].saturating_add(MARGIN)),
        clamp(r[2].saturating_sub(MARGIN)),
        clamp(r[3].saturating_add(MARGIN)),
    ]
}

/// A triangle's rectangle `t` in the cells of its leaf's rectangle `leaf`, rounded
/// outwards: a cell below the low end's cell lies below the low end, and one above the
/// high end's above it. One that is not inside the leaf's rejects nothing.
fn within_leaf(t: [u16; 4], leaf: Packed) -> u16 {
    let mut out = 0u16;
    for k in 0..2 {
        let (low, width) = ((leaf[k] & 0xffff) as i32, (leaf[k] >> 16) as i32);
        let shift = cell_shift(width as u32);
        let (lo, hi) = (t[2 * k] as i32 - low, t[2 * k + 1] as i32 - low);
        if lo > width || hi < 0 || lo > hi {
            return TRIANGLE_EVERYWHERE;
        }
        let (lo, hi) = (lo.max(0) >> shift, hi.min(width) >> shift);
        out |= ((lo | ((hi - lo) << 4)) as u16) << (8 * k);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::{Aabb, Ray, RayInv};

    /// The scene box of the random tests, and their lights: a directional one, a point
    /// light beside the scene and one above it (kind, position, direction).
    const TEST_ROOT: [[f32; 3]; 2] = [[-60.0, -1.0, -60.0], [60.0, 30.0, 60.0]];
    const TEST_LIGHTS: [(LightKind, [f32; 3], [f32; 3]); 3] = [
        (LightKind::Directional, [0.0; 3], [0.6, -1.0, 0.45]),
        (LightKind::Point, [-20.0, 14.0, -6.0], [0.0; 3]),
        (LightKind::Point, [5.0, 80.0, 3.0], [0.0; 3]),
    ];

    fn v3(a: [f32; 3]) -> Vec3<f32> {
        Vec3::new(a[0], a[1], a[2])
    }

    fn xorshift(seed: u64) -> impl FnMut() -> f32 {
        let mut x = seed;
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// Random boxes in a scene, random ray origins, both kinds of light: whenever the
    /// rectangle rejects a ray, the slab test misses the box too; and the rectangles reject
    /// most of the rays the slab test misses (they are not vacuous).
    #[test]
    fn a_rejected_ray_misses_the_box() {
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        for (kind, pos, dir) in
            TEST_LIGHTS.map(|(k, p, d)| (k, v3(p), v3(d).try_normalize().unwrap_or(Vec3::zero())))
        {
            let view = LightView::new(kind, pos, dir, [v3(TEST_ROOT[0]), v3(TEST_ROOT[1])])
                .expect("a view");
            let (mut missed, mut rejected) = (0u32, 0u32);
            for _ in 0..3000 {
                let c = Vec3::new(next() * 100.0 - 50.0, next() * 25.0, next() * 100.0 - 50.0);
                let h = Vec3::new(next(), next(), next()) * 4.0f32;
                let b = [c - h, c + h];
                let r = rect(&view, &b);
                for _ in 0..8 {
                    // Origins near the box, so that many rays pass close to it.
                    let o = c + Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 20.0f32;
                    let (d, t_max) = match kind {
                        LightKind::Directional => (-dir, f32::MAX),
                        _ => ((pos - o).normalize(), (pos - o).length()),
                    };
                    let ray = Ray::new(o, d);
                    let hit = Aabb {
                        min: b[0],
                        max: b[1],
                    }
                    .entry(&ray, &RayInv::new(d), t_max)
                    .is_some();
                    let mut rects = LightRects::<f32>::new();
                    rects.views[0] = Some(view);
                    rects.rects[0][0] = pack(r);
                    let Some(p) = rects.point(0, o) else {
                        continue;
                    };
                    let out = p.a < r[0] || p.a > r[1] || p.b < r[2] || p.b > r[3];
                    assert_eq!(out, rects.misses(p, 0), "the packed test");
                    if out {
                        assert!(!hit, "{kind:?}: rejected a ray that hits {b:?} from {o:?}");
                        rejected += 1;
                    }
                    if !hit {
                        missed += 1;
                    }
                }
            }
            assert!(
                rejected * 10 > missed * 6,
                "{kind:?}: {rejected} of {missed} misses rejected"
            );
        }
    }

    /// Random triangles in random leaves (each leaf's box the triangle's grown by up to
    /// four units each way, as a leaf of several triangles is), both kinds of light: a
    /// triangle rejected in its leaf's cells is missed by the triangle test too, and the
    /// cells reject a good share of the rays that pass the leaf's rectangle and miss.
    #[test]
    fn a_rejected_ray_misses_the_triangle() {
        use crate::shape::triangle::Triangle;
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        for (kind, pos, dir) in
            TEST_LIGHTS.map(|(k, p, d)| (k, v3(p), v3(d).try_normalize().unwrap_or(Vec3::zero())))
        {
            let view = LightView::new(kind, pos, dir, [v3(TEST_ROOT[0]), v3(TEST_ROOT[1])])
                .expect("a view");
            let (mut missed, mut rejected) = (0u32, 0u32);
            for _ in 0..3000 {
                let c = Vec3::new(next() * 100.0 - 50.0, next() * 25.0, next() * 100.0 - 50.0);
                let mut corner = || c + Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 6.0;
                let tri = Triangle {
                    p: [corner(), corner(), corner()],
                };
                let lo = tri.p[0].min(tri.p[1]).min(tri.p[2]);
                let hi = tri.p[0].max(tri.p[1]).max(tri.p[2]);
                let grow = Vec3::new(next(), next(), next()) * 4.0f32;
                let leaf = pack(rect(&view, &[lo - grow, hi + grow]));
                let mut rects = LightRects::<f32>::new();
                rects.views[0] = Some(view);
                rects.rects[0][0] = leaf;
                rects.triangles[0][0] = within_leaf(triangle_rect(&view, &tri.p), leaf);
                for _ in 0..8 {
                    let o = c + Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 20.0f32;
                    let (d, t_max) = match kind {
                        LightKind::Directional => (-dir, f32::MAX),
                        _ => ((pos - o).normalize(), (pos - o).length()),
                    };
                    let Some(p) = rects.point(0, o) else {
                        continue;
                    };
                    if rects.misses(p, 0) {
                        continue;
                    }
                    let hit = tri.intersect(&Ray::new(o, d), t_max).is_some();
                    let cell = rects.leaf_cell(p, 0).expect("node 0 has a rectangle");
                    assert!(cell.a < 16 && cell.b < 16, "{cell:?}");
                    if rects.triangle_misses(cell, 0) {
                        assert!(
                            !hit,
                            "{kind:?}: rejected a ray that hits {tri:?} from {o:?}"
                        );
                        rejected += 1;
                    }
                    if !hit {
                        missed += 1;
                    }
                }
            }
            assert!(
                rejected * 10 > missed * 4,
                "{kind:?}: {rejected} of {missed} misses rejected"
            );
        }
    }

    /// Cells of a leaf rectangle round a triangle's rectangle outwards, every width.
    #[test]
    fn leaf_cells_round_outwards() {
        let mut next = xorshift(77);
        for _ in 0..20_000 {
            let mut unit = |span: f32| (next() * span) as u16;
            let (a, b) = (unit(65_535.0), unit(65_535.0));
            let (low, high) = (a.min(b), a.max(b));
            let leaf = pack([low, high, 0, u16::MAX]);
            let (c, d) = (unit(65_535.0), unit(65_535.0));
            let t = [c.min(d), c.max(d), 0, u16::MAX];
            let packed = within_leaf(t, leaf);
            let mut rects = LightRects::<f32>::new();
            rects.rects[0][0] = leaf;
            rects.triangles[0][0] = packed;
            for _ in 0..16 {
                let q = low + unit((high - low) as f32).min(high - low);
                let p = LightPoint {
                    slot: 0,
                    a: q,
                    b: unit(65_535.0),
                };
                assert!(!rects.misses(p, 0));
                let cell = rects.leaf_cell(p, 0).unwrap();
                if rects.triangle_misses(cell, 0) {
                    assert!(q < t[0] || q > t[1], "{q} in {t:?} (leaf {low}..{high})");
                }
            }
        }
        // The whole range: cells of 4,096 units.
        assert_eq!(cell_shift(u16::MAX as u32), 12);
        assert_eq!(
            within_leaf(EVERYWHERE, PACKED_EVERYWHERE),
            TRIANGLE_EVERYWHERE
        );
    }

    /// A box reaching behind a point light is never rejected; rays from behind the light's
    /// near depth are not clipped.
    #[test]
    fn boxes_and_origins_behind_the_light_are_not_clipped() {
        let root = [
            Vec3::new(-10.0f32, -10.0, -10.0),
            Vec3::new(10.0, 10.0, 10.0),
        ];
        let view = LightView::new(
            LightKind::Point,
            Vec3::new(0.0, 0.0, -30.0),
            Vec3::zero(),
            root,
        )
        .expect("a view");
        let around = [Vec3::new(-1.0f32, -1.0, -31.0), Vec3::new(1.0, 1.0, -29.0)];
        assert_eq!(rect(&view, &around), EVERYWHERE);
        assert_eq!(pack(EVERYWHERE), PACKED_EVERYWHERE);
        let mut rects = LightRects::<f32>::new();
        rects.views[0] = Some(view);
        assert!(rects.point(0, Vec3::new(0.0, 0.0, -40.0)).is_none());
        assert!(rects.point(0, Vec3::new(0.0, 0.0, 5.0)).is_some());
        // NaN gives no point.
        assert!(rects.point(0, Vec3::new(f32::NAN, 0.0, 5.0)).is_none());
        // A light the view cannot be made for (no lights past the slots).
        assert!(rects.point(1, Vec3::new(0.0, 0.0, 5.0)).is_none());
    }
}
