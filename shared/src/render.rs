//! The tracer: LINKS-1's line-of-sight search with eq. 2.1 shading and eq. 2.2 recursion.
//!
//! The node's unit of work is one run of pixels on one scanline ([`render_run`]). Everything
//! is generic over the number type and reads the SceneImage in place. Recursion depth is
//! bounded by the image's `max_depth` (validated <= [`MAX_DEPTH_LIMIT`]); at the cut-off a
//! transmitted ray continues straight through (non-refractive transparency, LINKS-1 4.5)
//! in a loop, so deep nesting costs no stack.
//!
//! Colours are linear RGB in [0, 1] per channel, written as 8-bit without gamma (as a 1983
//! frame memory would hold them).

use crate::geom::{offset_ray_origin, Ray, RayInv, Vec3};
use crate::image::{
    BlobGroupRec, Frame, LightKind, MapTarget, Material, SceneView, ShapeKind, ShapeRef,
    MAX_DEPTH_LIMIT, NONE,
};
use crate::num::Real;
use crate::shape::blob::{Ball, BlobGroup, BlobStats};
use crate::shape::boxshape::BoxHit;
use crate::shape::ellipsoid::EllipsoidHit;
use crate::trace::clip::RowClip;
use core::fmt;

/// Most recursive rays one pixel may spawn (reflection and transmission, two per surface):
/// far above what any sane scene needs (a depth-6 glass scene needs at most 254), it bounds
/// the work a hostile image can ask for per pixel.
pub const SECONDARY_RAYS_PER_PIXEL: u32 = 4096;

/// Most surfaces a shadow ray or a straight-through ray may cross before it gives up (the
/// light is then treated as blocked, the straight ray as ending in the background).
pub const MAX_CROSSINGS: u32 = 64;

/// An 8-bit RGB pixel.
pub type Rgb8 = [u8; 3];

/// Defines [`Stats`] from one list of counters: the struct, its field names in order, its
/// values in the same order, and addition. Every other list of the counters (the cost model's
/// CSV columns, the firmware's `RUN` line, the CLI's stats line) is derived from
/// [`Stats::NAMES`] and [`Stats::values`], so a new counter is written here once.
macro_rules! define_stats {
    ($(#[$meta:meta])* pub struct $name:ident { $($(#[$fmeta:meta])* $field:ident,)* }) => {
        $(#[$meta])*
        pub struct $name {
            $($(#[$fmeta])* pub $field: u64,)*
        }

        impl $name {
            /// How many counters there are.
            pub const COUNT: usize = [$(stringify!($field)),*].len();
            /// The counters' field names, in declaration order.
            pub const NAMES: [&'static str; Self::COUNT] = [$(stringify!($field)),*];

            /// The counters' values, in [`Self::NAMES`] order.
            pub fn values(&self) -> [u64; Self::COUNT] {
                [$(self.$field),*]
            }

            /// The counts whose values are `values`, in [`Self::NAMES`] order.
            pub fn from_values(values: [u64; Self::COUNT]) -> Self {
                let [$($field),*] = values;
                Self { $($field),* }
            }

            /// Adds `o`'s counts to these.
            pub fn add(&mut self, o: &$name) {
                $(self.$field += o.$field;)*
            }
        }
    };
}

define_stats! {
    /// Deterministic operation counts (the cost model's input).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
    pub struct Stats {
        primary_rays,
        shadow_rays,
        reflect_rays,
        refract_rays,
        /// Straight-through (non-refractive) transmission rays.
        straight_rays,
        box_tests,
        triangle_tests,
        ellipsoid_tests,
        box_shape_tests,
        blob_tests,
        blob_field_evals,
        /// Evaluations of eq. 2.1 (one per shaded surface point).
        shadings,
        /// Integer compares made by Y and X clipping.
        clip_compares,
        /// Runs whose row kept more leaves than the clip buffer holds (plain traversal used).
        clip_overflows,
        /// Shadow rays settled by the first pass (an opaque blocker, or nothing at all in the way).
        shadow_early_exits,
    }
}

impl Stats {
    /// Every ray traced: primary, shadow and the three secondary kinds.
    pub fn rays(&self) -> u64 {
        self.primary_rays
            + self.shadow_rays
            + self.reflect_rays
            + self.refract_rays
            + self.straight_rays
    }

    /// The value of the counter called `name` (one of [`Self::NAMES`]).
    pub fn get(&self, name: &str) -> Option<u64> {
        let at = Self::NAMES.iter().position(|n| *n == name)?;
        Some(self.values()[at])
    }
}

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

/// Why a run could not be rendered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RenderError {
    /// The run does not lie inside the frame.
    RunOutsideFrame { x: u32, y: u32, len: u32 },
}

impl fmt::Display for RenderError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            RenderError::RunOutsideFrame { x, y, len } => {
                write!(f, "pixel run x={x} y={y} len={len} lies outside the frame")
            }
        }
    }
}

impl core::error::Error for RenderError {}

/// Which shape a ray hit, with what each kind needs to finish the hit.
#[derive(Clone, Copy, Debug)]
enum HitDetail<T> {
    Triangle([T; 3]),
    Ellipsoid(EllipsoidHit<T>),
    Box(BoxHit<T>),
    Blob { t_error: T },
}

#[derive(Clone, Copy, Debug)]
struct Hit<T> {
    t: T,
    shape: ShapeRef,
    detail: HitDetail<T>,
}

/// Depth of the closest-hit traversal stack (a node and its box entry distance per entry).
const TRAVERSAL_STACK: usize = 48;
/// Most children of one node visited nearest-first; further hit children are walked in place.
const ORDERED_FANOUT: usize = 8;

/// The nearest hit so far. Equal distances go to the lower node index, so the answer does
/// not depend on the order shapes are tested in (ordered traversal, clipping, plain).
struct Nearest<T> {
    hit: Option<Hit<T>>,
    node: u32,
    t_max: T,
}

impl<T: Real> Nearest<T> {
    fn new(t_max: T) -> Self {
        Self {
            hit: None,
            node: u32::MAX,
            t_max,
        }
    }
    /// Upper bound for tests still worth making: a hit at the current distance may still
    /// win the tie, so a little beyond it; the exact winner is decided in `offer`.
    #[inline]
    fn limit(&self) -> T {
        match &self.hit {
            // Relative slack: a shape lying in its box's face (a flat box) can compute its
            // hit a few ulps before the box's computed entry, and must still be tested.
            Some(h) => h.t * (T::ONE + T::err_gamma(16)),
            None => self.t_max,
        }
    }
    /// Whether a box entered at `t` lies wholly behind the nearest hit (with the same slack).
    #[inline]
    fn beyond(&self, t: T) -> bool {
        self.hit
            .as_ref()
            .is_some_and(|h| t * (T::ONE - T::err_gamma(16)) > h.t)
    }
    #[inline]
    fn offer(&mut self, h: Hit<T>, node: u32) {
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
            self.hit = Some(h);
            self.node = node;
        }
    }
}

/// A finished hit: where, how accurately, which way the surface faces, what it is made of.
#[derive(Clone, Copy, Debug)]
pub struct Surface<T> {
    pub p: Vec3<T>,
    pub p_error: Vec3<T>,
    /// Geometric normal, unit, pointing out of the object.
    pub ng: Vec3<T>,
    /// Shading normal (interpolated on smooth triangles), unit, same side as `ng`.
    pub ns: Vec3<T>,
    pub uv: [T; 2],
    pub material: u32,
    pub shape: ShapeRef,
}

/// A material with its texture map already applied at a surface point.
#[derive(Clone, Copy, Debug)]
struct Mat<T> {
    diffuse: Vec3<T>,
    specular: T,
    specular_edge: T,
    shininess: T,
    reflect: T,
    reflect_edge: T,
    transmit: Vec3<T>,
    ior: T,
}

fn schlick<T: Real>(at_normal: T, at_edge: T, cos: T) -> T {
    let m = (T::ONE - cos.clamp01()).max(T::ZERO);
    let m2 = m * m;
    at_normal + (at_edge - at_normal) * (m2 * m2 * m)
}

/// The tracer for one scene and number type.
pub struct Tracer<'a, T: Real> {
    scene: SceneView<'a>,
    frame: Frame<T>,
    techniques: Techniques,
    clip: RowClip,
    /// Recursive (reflected, refracted, straight) rays the current pixel may still spawn.
    secondary_left: u32,
    pub stats: Stats,
}

impl<'a, T: Real> Tracer<'a, T> {
    /// A tracer using every technique.
    pub fn new(scene: SceneView<'a>) -> Self {
        Self::with_techniques(scene, Techniques::ALL)
    }

    pub fn with_techniques(scene: SceneView<'a>, techniques: Techniques) -> Self {
        let frame = scene.frame::<T>();
        Self {
            scene,
            frame,
            techniques,
            clip: RowClip::new(),
            secondary_left: SECONDARY_RAYS_PER_PIXEL,
            stats: Stats::default(),
        }
    }

    pub fn techniques(&self) -> Techniques {
        self.techniques
    }

    /// Prepare a run on row `y` (Y clipping). Pixels of the run must then be rendered left
    /// to right with [`Self::pixel`]; any other call order falls back to the plain traversal.
    pub fn begin_run(&mut self, y: u32) {
        self.clip.clear();
        if self.techniques.y_clip && self.techniques.bounding_boxes {
            let row = y.min(u16::MAX as u32) as u16;
            if !self
                .clip
                .y_clip(&self.scene, row, &mut self.stats.clip_compares)
                && self.scene.has_rects()
            {
                self.stats.clip_overflows += 1;
            }
        }
    }

    pub fn frame(&self) -> &Frame<T> {
        &self.frame
    }

    /// The primary ray through the centre of pixel (x, y): from the eye at the origin.
    pub fn primary_ray(&self, x: u32, y: u32) -> Ray<T> {
        let f = &self.frame;
        let half = T::HALF;
        let dx = f.x0 + (T::from_i32(x as i32) + half) * f.dx;
        let dy = f.y0 - (T::from_i32(y as i32) + half) * f.dy;
        Ray::new(Vec3::zero(), Vec3::new(dx, dy, f.dz).normalize())
    }

    /// Colour of the primary ray through pixel (x, y), linear RGB.
    pub fn pixel(&mut self, x: u32, y: u32) -> Vec3<T> {
        self.stats.primary_rays += 1;
        self.secondary_left = SECONDARY_RAYS_PER_PIXEL;
        let ray = self.primary_ray(x, y);
        let hit = if self.clip.row() == Some(y.min(u16::MAX as u32) as u16) {
            self.closest_hit_clipped(&ray, x)
        } else {
            self.closest_hit(&ray, T::MAX)
        };
        self.shade_hit(&ray, hit, 0)
    }

    /// The primary ray's nearest hit among the Y-clipped leaves (and, with X clipping, only
    /// those whose rectangle contains column `x`), each behind its own box test.
    fn closest_hit_clipped(&mut self, ray: &Ray<T>, x: u32) -> Option<Hit<T>> {
        let inv = RayInv::new(ray.dir);
        let mut near = Nearest::new(T::MAX);
        let col = x.min(u16::MAX as u32) as u16;
        let swept = self.techniques.x_clip && self.clip.advance(col, &mut self.stats.clip_compares);
        let n = if swept {
            self.clip.active_len()
        } else {
            self.clip.leaves().len()
        };
        for k in 0..n {
            let leaf = if swept {
                self.clip.active_leaf(k)
            } else {
                self.clip.leaves()[k]
            };
            let node = self.scene.node::<T>(leaf);
            self.stats.box_tests += 1;
            if !node.bounds.hit(ray, &inv, near.limit()) {
                continue;
            }
            if let Some(shape) = node.shape {
                self.offer(&mut near, shape, leaf, ray);
            }
        }
        near.hit
    }

    /// Nearest shape along `ray` in (0, t_max): walk the node tree nearest-first, skipping
    /// the subtree of every box the ray misses (LINKS-1 4.2) or enters beyond the nearest
    /// hit so far; a small fixed stack holds the children still to visit.
    fn closest_hit(&mut self, ray: &Ray<T>, t_max: T) -> Option<Hit<T>> {
        if !self.techniques.bounding_boxes {
            return self.closest_hit_plain(ray, t_max);
        }
        let inv = RayInv::new(ray.dir);
        let mut near = Nearest::new(t_max);
        let mut stack = [(0u32, T::ZERO); TRAVERSAL_STACK];
        self.stats.box_tests += 1;
        let t_root = self.scene.node::<T>(0).bounds.entry(ray, &inv, t_max)?;
        stack[0] = (0, t_root);
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (i, t_in) = stack[sp];
            if near.beyond(t_in) {
                continue;
            }
            let node = self.scene.node::<T>(i);
            if let Some(shape) = node.shape {
                self.offer(&mut near, shape, i, ray);
                continue;
            }
            // Test the children's boxes; visit the nearest first so later ones can be pruned.
            let mut kids = [(0u32, T::ZERO); ORDERED_FANOUT];
            let mut nk = 0;
            let mut c = i + 1;
            while c < node.skip {
                let child = self.scene.node::<T>(c);
                self.stats.box_tests += 1;
                if let Some(t) = child.bounds.entry(ray, &inv, near.limit()) {
                    if nk < ORDERED_FANOUT && sp + nk < TRAVERSAL_STACK {
                        kids[nk] = (c, t);
                        nk += 1;
                    } else {
                        // No room to order it: walk its subtree in place.
                        self.walk_hit_subtree(c, child.shape, child.skip, ray, &inv, &mut near);
                    }
                }
                c = child.skip;
            }
            // Push farthest first (insertion sort of at most ORDERED_FANOUT entries).
            for k in 1..nk {
                let mut j = k;
                while j > 0 && kids[j - 1].1 < kids[j].1 {
                    kids.swap(j - 1, j);
                    j -= 1;
                }
            }
            for kid in &kids[..nk] {
                stack[sp] = *kid;
                sp += 1;
            }
        }
        near.hit
    }

    /// Depth-first walk (in node order) of a subtree whose root box the ray already hit.
    fn walk_hit_subtree(
        &mut self,
        root: u32,
        root_shape: Option<ShapeRef>,
        end: u32,
        ray: &Ray<T>,
        inv: &RayInv<T>,
        near: &mut Nearest<T>,
    ) {
        if let Some(shape) = root_shape {
            self.offer(near, shape, root, ray);
            return;
        }
        let mut i = root + 1;
        while i < end {
            let node = self.scene.node::<T>(i);
            self.stats.box_tests += 1;
            if !node.bounds.hit(ray, inv, near.limit()) {
                i = node.skip;
                continue;
            }
            if let Some(shape) = node.shape {
                self.offer(near, shape, i, ray);
            }
            i += 1;
        }
    }

    /// Test a shape and keep it if it is the nearest so far.
    #[inline]
    fn offer(&mut self, near: &mut Nearest<T>, shape: ShapeRef, node: u32, ray: &Ray<T>) {
        if let Some(h) = self.intersect_shape(shape, ray, near.limit()) {
            near.offer(h, node);
        }
    }

    /// The plain algorithm: every shape, no boxes (the paper's type 4).
    fn closest_hit_plain(&mut self, ray: &Ray<T>, t_max: T) -> Option<Hit<T>> {
        let mut near = Nearest::new(t_max);
        for i in 0..self.scene.node_count() {
            if let Some(shape) = self.scene.node::<T>(i).shape {
                self.offer(&mut near, shape, i, ray);
            }
        }
        near.hit
    }

    /// Whether any opaque surface lies along `ray` in (0, t_max) (stops at the first), and
    /// whether a transparent one was seen on the way.
    fn any_opaque(&mut self, ray: &Ray<T>, t_max: T) -> (bool, bool) {
        let inv = RayInv::new(ray.dir);
        let n = self.scene.node_count();
        let mut transparent = false;
        let mut i = 0;
        while i < n {
            let node = self.scene.node::<T>(i);
            if self.techniques.bounding_boxes {
                self.stats.box_tests += 1;
                if !node.bounds.hit(ray, &inv, t_max) {
                    i = node.skip;
                    continue;
                }
            }
            if let Some(shape) = node.shape {
                if let Some(h) = self.intersect_shape(shape, ray, t_max) {
                    let m = self.scene.material::<T>(self.material_of(&h));
                    let mapped = m.texture != NONE && m.target == MapTarget::Transmit;
                    if m.transmit.max_component() <= T::ZERO && !mapped {
                        return (true, transparent);
                    }
                    transparent = true;
                }
            }
            i += 1;
        }
        (false, transparent)
    }

    fn material_of(&self, hit: &Hit<T>) -> u32 {
        let s = &self.scene;
        match hit.shape.kind {
            ShapeKind::Triangle => s.triangle::<T>(hit.shape.index).material,
            ShapeKind::Ellipsoid => s.ellipsoid::<T>(hit.shape.index).material,
            ShapeKind::Box => s.boxshape::<T>(hit.shape.index).material,
            ShapeKind::Blob => s.blob_group::<T>(hit.shape.index).material,
        }
    }

    fn intersect_shape(&mut self, shape: ShapeRef, ray: &Ray<T>, t_max: T) -> Option<Hit<T>> {
        let s = &self.scene;
        match shape.kind {
            ShapeKind::Triangle => {
                self.stats.triangle_tests += 1;
                let rec = s.triangle::<T>(shape.index);
                rec.tri.intersect(ray, t_max).map(|h| Hit {
                    t: h.t,
                    shape,
                    detail: HitDetail::Triangle(h.b),
                })
            }
            ShapeKind::Ellipsoid => {
                self.stats.ellipsoid_tests += 1;
                let rec = s.ellipsoid::<T>(shape.index);
                rec.shape.intersect(ray, t_max).map(|h| Hit {
                    t: h.t,
                    shape,
                    detail: HitDetail::Ellipsoid(h),
                })
            }
            ShapeKind::Box => {
                self.stats.box_shape_tests += 1;
                let rec = s.boxshape::<T>(shape.index);
                rec.shape.intersect(ray, t_max).map(|h| Hit {
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

    /// Complete a hit: position with error bound, normals, texture coordinates.
    fn surface(&self, ray: &Ray<T>, hit: &Hit<T>) -> Surface<T> {
        let s = &self.scene;
        let shape = hit.shape;
        match hit.detail {
            HitDetail::Triangle(b) => {
                let rec = s.triangle::<T>(shape.index);
                let (p, p_error) = rec.tri.point(b);
                let mut ng = rec.tri.face_normal().normalize();
                let ns = if rec.normals != NONE {
                    let n = s.normals::<T>(rec.normals);
                    let ns = (n[0] * b[0] + n[1] * b[1] + n[2] * b[2]).normalize();
                    // Vertex normals say which side is outside; make ng agree.
                    if ns.dot(ng) < T::ZERO {
                        ng = -ng;
                    }
                    ns
                } else {
                    ng
                };
                let uv = if rec.uvs != NONE {
                    let t = s.uvs::<T>(rec.uvs);
                    [
                        t[0][0] * b[0] + t[1][0] * b[1] + t[2][0] * b[2],
                        t[0][1] * b[0] + t[1][1] * b[1] + t[2][1] * b[2],
                    ]
                } else {
                    [b[1], b[2]]
                };
                Surface {
                    p,
                    p_error,
                    ng,
                    ns,
                    uv,
                    material: rec.material,
                    shape,
                }
            }
            HitDetail::Ellipsoid(h) => {
                let rec = s.ellipsoid::<T>(shape.index);
                let ls = rec.shape.surface(ray, &h, s.storage_epsilon());
                let q = ls.local;
                // Spherical mapping in the unit frame (v = 1 at the +Y pole, the image's top
                // row); the cap maps planar.
                let uv = if h.part == crate::shape::ellipsoid::EllipsoidPart::Cap {
                    [(q.x + T::ONE) * T::HALF, (q.z + T::ONE) * T::HALF]
                } else {
                    let two_pi = T::TWO * T::PI;
                    [
                        T::HALF + q.z.atan2(q.x) / two_pi,
                        T::ONE - q.y.max(-T::ONE).min(T::ONE).acos() / T::PI,
                    ]
                };
                Surface {
                    p: ls.p,
                    p_error: ls.p_error,
                    ng: ls.n,
                    ns: ls.n,
                    uv,
                    material: rec.material,
                    shape,
                }
            }
            HitDetail::Box(h) => {
                let rec = s.boxshape::<T>(shape.index);
                let ls = rec.shape.surface(ray, &h, s.storage_epsilon());
                let q = ls.local;
                // Planar mapping on each face from the two other local axes.
                let (a, b) = match h.face & 3 {
                    0 => (q.z, q.y),
                    1 => (q.x, q.z),
                    _ => (q.x, q.y),
                };
                let uv = [(a + T::ONE) * T::HALF, (b + T::ONE) * T::HALF];
                Surface {
                    p: ls.p,
                    p_error: ls.p_error,
                    ng: ls.n,
                    ns: ls.n,
                    uv,
                    material: rec.material,
                    shape,
                }
            }
            HitDetail::Blob { t_error } => {
                let (g, group) = blob_group(*s, shape.index);
                let p = ray.at(hit.t);
                let n = (-group.gradient(p)).normalize();
                let p_error = ray.dir.abs() * t_error + p.abs() * T::err_gamma(4);
                Surface {
                    p,
                    p_error,
                    ng: n,
                    ns: n,
                    uv: [T::ZERO, T::ZERO],
                    material: g.material,
                    shape,
                }
            }
        }
    }

    /// Material at a surface point, with its texture or coefficient map applied (bilinear).
    fn material_at(&self, surf: &Surface<T>) -> Mat<T> {
        let m: Material<T> = self.scene.material(surf.material);
        let mut out = Mat {
            diffuse: m.diffuse,
            specular: m.specular,
            specular_edge: m.specular_edge,
            shininess: m.shininess,
            reflect: m.reflect,
            reflect_edge: m.reflect_edge,
            transmit: m.transmit,
            ior: m.ior,
        };
        if m.texture != NONE {
            let texel =
                self.texture_lookup(m.texture, surf.uv[0] * m.scale[0], surf.uv[1] * m.scale[1]);
            let lum = texel.x * T::from_f32(0.299)
                + texel.y * T::from_f32(0.587)
                + texel.z * T::from_f32(0.114);
            match m.target {
                MapTarget::Diffuse => out.diffuse = out.diffuse.mul_elem(texel),
                MapTarget::Specular => {
                    out.specular *= lum;
                    out.specular_edge *= lum;
                }
                MapTarget::Reflect => {
                    out.reflect *= lum;
                    out.reflect_edge *= lum;
                }
                MapTarget::Transmit => out.transmit = out.transmit * lum,
            }
        }
        out
    }

    /// Bilinear, wrapping texture lookup; v = 0 is the bottom row of the image.
    fn texture_lookup(&self, index: u32, u: T, v: T) -> Vec3<T> {
        let tex = self.scene.texture(index);
        // A validated image's textures are 1 .. 2^31 texels wide and high and hold exactly
        // w * h * 3 bytes (`SceneView::texture`); anything else reads black, never panics.
        let (Ok(w), Ok(h)) = (i32::try_from(tex.width), i32::try_from(tex.height)) else {
            return Vec3::zero();
        };
        if w == 0 || h == 0 {
            return Vec3::zero();
        }
        let u = u - u.floor();
        let v = v - v.floor();
        let x = u * T::from_i32(w) - T::HALF;
        let y = (T::ONE - v) * T::from_i32(h) - T::HALF;
        let xf = x.floor();
        let yf = y.floor();
        let fx = x - xf;
        let fy = y - yf;
        let xi = xf.to_f32() as i32;
        let yi = yf.to_f32() as i32;
        let texel = |xx: i32, yy: i32| -> Vec3<T> {
            let xx = xx.rem_euclid(w) as usize;
            let yy = yy.rem_euclid(h) as usize;
            let rgb = yy
                .checked_mul(w as usize)
                .and_then(|i| i.checked_add(xx)?.checked_mul(3))
                .and_then(|at| tex.rgb.get(at..)?.first_chunk::<3>())
                .copied()
                .unwrap_or([0; 3]);
            let c = |k: usize| T::from_i32(rgb[k] as i32) / T::from_i32(255);
            Vec3::new(c(0), c(1), c(2))
        };
        let top = texel(xi, yi) * (T::ONE - fx) + texel(xi + 1, yi) * fx;
        let bot = texel(xi, yi + 1) * (T::ONE - fx) + texel(xi + 1, yi + 1) * fx;
        top * (T::ONE - fy) + bot * fy
    }

    /// Direction to light `i` from `p`, its distance (MAX for parallel light) and the
    /// light's intensity arriving at `p` before shadowing.
    fn light_at(&self, i: u32, p: Vec3<T>) -> Option<(Vec3<T>, T, Vec3<T>)> {
        let l = self.scene.light::<T>(i);
        match l.kind {
            LightKind::Directional => Some((-l.dir, T::MAX, l.color)),
            LightKind::Point | LightKind::Spot => {
                let to = l.pos - p;
                let d2 = to.length_sq();
                let d = d2.sqrt();
                if d == T::ZERO {
                    return None;
                }
                let dir = to * d.recip();
                let mut c = l.color;
                if l.kind == LightKind::Point {
                    if l.falloff {
                        c = c * d2.recip();
                    }
                } else {
                    let cos_axis = -dir.dot(l.dir);
                    if cos_axis <= l.cos_outer {
                        return None;
                    }
                    let edge = if cos_axis >= l.cos_inner || l.cos_inner <= l.cos_outer {
                        T::ONE
                    } else {
                        let s = (cos_axis - l.cos_outer) / (l.cos_inner - l.cos_outer);
                        s * s * (T::from_i32(3) - T::TWO * s)
                    };
                    let shape = if l.exponent > T::ZERO {
                        cos_axis.max(T::ZERO).powf(l.exponent)
                    } else {
                        T::ONE
                    };
                    c = c * (edge * shape);
                }
                Some((dir, d, c))
            }
        }
    }

    /// Light transmitted from `surf` towards a light `dist` away along `dir`: the product of
    /// the transmittances of every surface crossed (LINKS-1: transparent objects cast
    /// lighter shadows).
    fn shadow(&mut self, surf: &Surface<T>, dir: Vec3<T>, dist: T) -> Vec3<T> {
        let mut atten = Vec3::splat(T::ONE);
        if self.frame.no_shadows {
            return atten;
        }
        self.stats.shadow_rays += 1;
        let mut origin = offset_ray_origin(surf.p, surf.p_error, surf.ng, dir);
        let far = dist < T::MAX;
        let light_pos = surf.p + dir * dist;
        if self.techniques.shadow_early_exit {
            // Any opaque blocker makes the answer exactly zero, as the stepping below would
            // find; nothing at all in the way makes it exactly one.
            let t_max = if far {
                (light_pos - origin).dot(dir)
            } else {
                T::MAX
            };
            if t_max > T::ZERO {
                let (opaque, transparent) = self.any_opaque(&Ray::new(origin, dir), t_max);
                if opaque || !transparent {
                    self.stats.shadow_early_exits += 1;
                    return if opaque { Vec3::zero() } else { atten };
                }
            }
        }
        let mut k = 0;
        while k < MAX_CROSSINGS {
            let t_max = if far {
                (light_pos - origin).dot(dir)
            } else {
                T::MAX
            };
            if t_max <= T::ZERO {
                return atten;
            }
            let ray = Ray::new(origin, dir);
            let Some(hit) = self.closest_hit(&ray, t_max) else {
                return atten;
            };
            let s = self.surface(&ray, &hit);
            let m = self.material_at(&s);
            atten = atten.mul_elem(m.transmit);
            if atten.max_component() < T::from_f32(1.0 / 1024.0) {
                return Vec3::zero();
            }
            origin = offset_ray_origin(s.p, s.p_error, s.ng, dir);
            k += 1;
        }
        Vec3::zero()
    }

    /// Eq. 2.1 at a surface point seen along `view` (unit, towards the eye).
    fn local_shade(&mut self, surf: &Surface<T>, m: &Mat<T>, view: Vec3<T>) -> Vec3<T> {
        self.stats.shadings += 1;
        let n = if surf.ns.dot(view) < T::ZERO {
            -surf.ns
        } else {
            surf.ns
        };
        let mut c = m.diffuse.mul_elem(self.frame.ambient);
        for i in 0..self.scene.light_count() {
            let Some((ldir, dist, ls)) = self.light_at(i, surf.p) else {
                continue;
            };
            let cos_t = n.dot(ldir);
            if cos_t <= T::ZERO {
                continue;
            }
            let t = self.shadow(surf, ldir, dist);
            if t.max_component() <= T::ZERO {
                continue;
            }
            let ls = ls.mul_elem(t);
            c = c + m.diffuse.mul_elem(ls) * cos_t;
            let src = schlick(m.specular, m.specular_edge, cos_t);
            if src > T::ZERO {
                // Mirror of the light direction about n, against the view direction.
                let r = n * (T::TWO * cos_t) - ldir;
                let cos_p = r.dot(view);
                if cos_p > T::ZERO {
                    c = c + ls * (src * cos_p.powf(m.shininess));
                }
            }
        }
        c
    }

    /// Eq. 2.2: local shading plus reflected and transmitted light, recursively.
    pub fn trace(&mut self, ray: &Ray<T>, depth: u32) -> Vec3<T> {
        let hit = self.closest_hit(ray, T::MAX);
        self.shade_hit(ray, hit, depth)
    }

    /// Eq. 2.2 for a ray whose nearest hit is known.
    fn shade_hit(&mut self, ray: &Ray<T>, hit: Option<Hit<T>>, depth: u32) -> Vec3<T> {
        let Some(hit) = hit else {
            return self.frame.background;
        };
        let surf = self.surface(ray, &hit);
        let m = self.material_at(&surf);
        let view = -ray.dir;
        let mut c = self.local_shade(&surf, &m, view);

        let entering = surf.ng.dot(ray.dir) < T::ZERO;
        let n = if entering { surf.ns } else { -surf.ns };
        let can_recurse =
            depth < self.frame.max_depth && depth < MAX_DEPTH_LIMIT && self.secondary_left >= 2;
        if can_recurse {
            // Reserve both branches: a pixel's ray tree is at most 2^(depth+1) rays, and
            // the budget keeps a hostile image (everything mirror and glass, depth 16) from
            // taking minutes per pixel; past it, rays end as at the depth cap.
            self.secondary_left -= 2;
        }
        let cos_v = n.dot(view).clamp01();

        let rc = schlick(m.reflect, m.reflect_edge, cos_v);
        if rc > T::ZERO && can_recurse {
            self.stats.reflect_rays += 1;
            let rdir = ray.dir.reflect(n).normalize();
            let r = Ray::new(offset_ray_origin(surf.p, surf.p_error, surf.ng, rdir), rdir);
            c = c + self.trace(&r, depth + 1) * rc;
        }

        let tc = m.transmit;
        if tc.max_component() > T::ZERO {
            let it = if !can_recurse {
                self.straight_through(&surf, ray.dir)
            } else if self.frame.non_refractive {
                self.stats.straight_rays += 1;
                let r = Ray::new(
                    offset_ray_origin(surf.p, surf.p_error, surf.ng, ray.dir),
                    ray.dir,
                );
                self.trace(&r, depth + 1)
            } else {
                // Snell's law; the outside is air.
                let eta = if entering { m.ior.recip() } else { m.ior };
                let cos_i = cos_v;
                let k = T::ONE - eta * eta * (T::ONE - cos_i * cos_i);
                let dir = if k < T::ZERO {
                    // Total internal reflection: the transmitted share reflects.
                    self.stats.reflect_rays += 1;
                    ray.dir.reflect(n).normalize()
                } else {
                    self.stats.refract_rays += 1;
                    (ray.dir * eta + n * (eta * cos_i - k.sqrt())).normalize()
                };
                let r = Ray::new(offset_ray_origin(surf.p, surf.p_error, surf.ng, dir), dir);
                self.trace(&r, depth + 1)
            };
            c = c + it.mul_elem(tc);
        }
        c
    }

    /// Non-refractive transparency without recursion: follow the ray straight on, adding
    /// each crossed surface's eq. 2.1 light weighted by the transmittance so far.
    fn straight_through(&mut self, from: &Surface<T>, dir: Vec3<T>) -> Vec3<T> {
        let mut acc = Vec3::zero();
        let mut w = Vec3::splat(T::ONE);
        let mut origin = offset_ray_origin(from.p, from.p_error, from.ng, dir);
        let mut k = 0;
        while k < MAX_CROSSINGS {
            self.stats.straight_rays += 1;
            let ray = Ray::new(origin, dir);
            let Some(hit) = self.closest_hit(&ray, T::MAX) else {
                return acc + w.mul_elem(self.frame.background);
            };
            let s = self.surface(&ray, &hit);
            let m = self.material_at(&s);
            acc = acc + w.mul_elem(self.local_shade(&s, &m, -dir));
            w = w.mul_elem(m.transmit);
            if w.max_component() < T::from_f32(1.0 / 1024.0) {
                return acc;
            }
            origin = offset_ray_origin(s.p, s.p_error, s.ng, dir);
            k += 1;
        }
        acc
    }

    /// The nearest surface a ray hits, for tests and tools.
    pub fn first_surface(&mut self, ray: &Ray<T>) -> Option<(T, Surface<T>)> {
        let hit = self.closest_hit(ray, T::MAX)?;
        Some((hit.t, self.surface(ray, &hit)))
    }
}

/// A density-sphere group record and the group itself, its balls read in place.
fn blob_group<T: Real>(
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

/// Quantise a linear colour to 8 bits (clamped, rounded to nearest).
pub fn to_rgb8<T: Real>(c: Vec3<T>) -> Rgb8 {
    let q = |v: T| {
        let x = v.clamp01().to_f32() * 255.0 + 0.5;
        if x >= 255.0 {
            255
        } else if x > 0.0 {
            x as u8
        } else {
            0
        }
    };
    [q(c.x), q(c.y), q(c.z)]
}

/// Render `out.len()` pixels of scanline `y` starting at column `x`: the node's unit of work.
pub fn render_run<T: Real>(
    tracer: &mut Tracer<'_, T>,
    y: u32,
    x: u32,
    out: &mut [Rgb8],
) -> Result<(), RenderError> {
    let f = tracer.frame();
    let len = out.len() as u32;
    if y >= f.height || x.checked_add(len).is_none_or(|end| end > f.width) {
        return Err(RenderError::RunOutsideFrame { x, y, len });
    }
    tracer.begin_run(y);
    for (i, px) in out.iter_mut().enumerate() {
        *px = to_rgb8(tracer.pixel(x + i as u32, y));
    }
    Ok(())
}
