//! The tracer: LINKS-1's line-of-sight search with eq. 2.1 shading and eq. 2.2 recursion.
//!
//! The node's unit of work is one run of pixels on one scanline ([`render_run`]). Everything
//! is generic over the number type and reads the SceneImage in place. Recursion depth is
//! bounded by the image's `max_depth` (validated <= [`crate::image::MAX_DEPTH_LIMIT`]); at the cut-off a
//! transmitted ray continues straight through (non-refractive transparency, LINKS-1 4.5)
//! in a loop, so deep nesting costs no stack.
//!
//! Colours are linear RGB in [0, 1] per channel, written as 8-bit without gamma (as a 1983
//! frame memory would hold them).

use super::stats::Stats;
use super::surface::Surface;
use super::techniques::Techniques;
use crate::geom::{Ray, Vec3};
use crate::image::{Camera, SceneView};
use crate::num::Real;
use crate::shape::boxshape::BoxBounds;
use crate::trace::clip::RowClip;
use crate::trace::light_rects::LightRects;
use crate::trace::primary::{EyeRay, PlaneCache};
use crate::trace::records::Records;
use crate::trace::traversal::{Blocker, WalkSpace};
use core::borrow::BorrowMut;
use core::fmt;

/// Most recursive rays one pixel may spawn (reflection and transmission, two per surface):
/// far above what any sane scene needs (a depth-6 glass scene needs at most 254), it bounds
/// the work a hostile image can ask for per pixel.
pub const SECONDARY_RAYS_PER_PIXEL: u32 = 4096;

/// Most surfaces a shadow ray or a straight-through ray may cross before it gives up (the
/// light is then treated as blocked, the straight ray as ending in the background).
pub const MAX_CROSSINGS: u32 = 64;

/// Lights whose last shadow-ray blocker the tracer remembers (further lights walk the
/// tree every time).
pub const BLOCKER_LIGHTS: usize = 8;

/// Boxes whose [`BoxBounds`] a tracer keeps (the first ones of the scene; the others form
/// theirs per test and per hit, the same values).
pub const CACHED_BOXES: usize = 8;

/// An 8-bit RGB pixel.
pub type Rgb8 = [u8; 3];

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

/// What a tracer keeps from run to run of one scene: the clipping lists, the edge-plane
/// cache, the walk space, the decoded records and the shadow blockers (~29 KB for f32).
///
/// A node renders many short runs of the same scene; with a tracer made per run it zeroed
/// and copied all of this each time and started every run with cold caches (photo1's 32-pixel
/// rows on the Cortex-M4F: 3,599 instructions per pixel against 2,341 with one tracer for the
/// frame). A node therefore keeps one state and lends it to the tracer of each run
/// ([`Tracer::with_state`]); the state forgets everything when the scene changes.
pub struct TracerState<T: Real> {
    pub(super) clip: RowClip,
    pub(super) planes: PlaneCache<T>,
    /// The nodes' rectangles in the lights' views, for shadow rays.
    pub(super) light_rects: LightRects<T>,
    pub(super) walk: WalkSpace<T>,
    /// Per light, the shape that blocked its last shadow ray (tried first on the next).
    pub(super) blockers: [Option<Blocker>; BLOCKER_LIGHTS],
    /// Material and light records, decoded at first use.
    pub(super) records: Records<T>,
    /// The first boxes' error-bound terms (fixed point; formed when the scene changes).
    boxes: [Option<BoxBounds<T>>; CACHED_BOXES],
    /// The scene the caches were filled from.
    key: Option<SceneKey>,
}

/// Which scene a [`TracerState`] holds caches for: where its bytes are, how many, and the
/// frame they are the scene of. The caller promises that the bytes behind one key do not
/// change (a node's bank is written only while it is not ready, and a new scene in a bank
/// comes with a new frame number).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneKey {
    pub addr: usize,
    pub len: usize,
    pub frame: u16,
}

impl SceneKey {
    /// The key of `scene`'s bytes as the scene of `frame`.
    pub fn of(scene: &SceneView<'_>, frame: u16) -> Self {
        let bytes = scene.bytes();
        SceneKey {
            addr: bytes.as_ptr() as usize,
            len: bytes.len(),
            frame,
        }
    }
}

impl<T: Real> Default for TracerState<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> TracerState<T> {
    /// A state holding no scene.
    pub fn new() -> Self {
        TracerState {
            clip: RowClip::new(),
            planes: PlaneCache::new(T::ZERO),
            light_rects: LightRects::new(),
            walk: WalkSpace::new(),
            blockers: [None; BLOCKER_LIGHTS],
            records: Records::new(),
            boxes: [None; CACHED_BOXES],
            key: None,
        }
    }

    /// Box `i`'s [`BoxBounds`], if kept.
    #[inline]
    pub(super) fn box_bounds(&self, i: u32) -> Option<BoxBounds<T>> {
        self.boxes.get(i as usize).copied().flatten()
    }

    /// Forget which scene the caches hold: the next run refills them (the bytes behind a
    /// key changed: a bank reused for another path's scene).
    pub fn forget(&mut self) {
        self.key = None;
    }

    /// Forget every cache unless they were filled from the scene `key` names.
    fn prepare(&mut self, scene: &SceneView<'_>, camera: &Camera<T>, key: Option<SceneKey>) {
        if key.is_some() && self.key == key {
            return;
        }
        self.clip.clear();
        self.planes.reset(PlaneCache::max_l1(camera));
        self.light_rects.reset(scene);
        self.blockers = [None; BLOCKER_LIGHTS];
        self.records = Records::new();
        self.boxes = [None; CACHED_BOXES];
        if T::ABSOLUTE_ROUNDING {
            let count = scene.count(crate::image::Section::Boxes) as usize;
            for (i, slot) in self.boxes.iter_mut().enumerate().take(count) {
                *slot = Some(scene.boxshape::<T>(i as u32).shape.bounds());
            }
        }
        self.key = key;
    }
}

/// The tracer for one scene and number type. `S` holds its [`TracerState`]: owned (the
/// default, for one frame or one test) or borrowed from a node that renders run after run.
pub struct Tracer<'a, T: Real, S: BorrowMut<TracerState<T>> = TracerState<T>> {
    pub(super) scene: SceneView<'a>,
    pub(super) camera: Camera<T>,
    pub(super) techniques: Techniques,
    pub(super) state: S,
    /// Whether the scene has triangles (rays of a scene without make no triangle set-up).
    pub(super) has_triangles: bool,
    /// Recursive (reflected, refracted, straight) rays the current pixel may still spawn.
    pub(super) secondary_left: u32,
    pub stats: Stats,
}

impl<'a, T: Real> Tracer<'a, T> {
    /// A tracer using every technique.
    pub fn new(scene: SceneView<'a>) -> Self {
        Self::with_techniques(scene, Techniques::ALL)
    }

    pub fn with_techniques(scene: SceneView<'a>, techniques: Techniques) -> Self {
        Tracer::build(scene, techniques, TracerState::new(), None)
    }
}

impl<'a, 's, T: Real> Tracer<'a, T, &'s mut TracerState<T>> {
    /// A tracer of `scene` (the scene of the frame `key` names) working in `state`, whose
    /// caches it keeps when they were filled from the same scene.
    pub fn with_state(
        scene: SceneView<'a>,
        techniques: Techniques,
        state: &'s mut TracerState<T>,
        key: SceneKey,
    ) -> Self {
        Tracer::build(scene, techniques, state, Some(key))
    }
}

impl<'a, T: Real, S: BorrowMut<TracerState<T>>> Tracer<'a, T, S> {
    fn build(
        scene: SceneView<'a>,
        techniques: Techniques,
        mut state: S,
        key: Option<SceneKey>,
    ) -> Self {
        let camera = scene.camera::<T>();
        state.borrow_mut().prepare(&scene, &camera, key);
        Self {
            scene,
            camera,
            techniques,
            state,
            has_triangles: scene.count(crate::image::Section::Triangles) != 0,
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
        self.state.borrow_mut().clip.clear();
        if self.techniques.y_clip && self.techniques.bounding_boxes {
            let row = y.min(u16::MAX as u32) as u16;
            if !self
                .state
                .borrow_mut()
                .clip
                .y_clip(&self.scene, row, &mut self.stats.clip_compares)
                && self.scene.has_rects()
            {
                self.stats.clip_overflows += 1;
            }
        }
    }

    pub fn camera(&self) -> &Camera<T> {
        &self.camera
    }

    /// The direction from the eye through the point (x + ox, y + oy) of the screen (pixel
    /// (x, y)'s centre at ox = oy = ½), before normalising.
    #[inline]
    fn eye_direction(&self, x: u32, y: u32, ox: T, oy: T) -> Vec3<T> {
        let f = &self.camera;
        let dx = f.x0 + f.across(T::from_i32(x as i32) + ox);
        let dy = f.y0 - f.down(T::from_i32(y as i32) + oy);
        Vec3::new(dx, dy, f.dz)
    }

    /// The primary ray through the centre of pixel (x, y): from the eye at the origin.
    pub fn primary_ray(&self, x: u32, y: u32) -> Ray<T> {
        Ray::new(
            Vec3::zero(),
            self.eye_direction(x, y, T::HALF, T::HALF).normalize(),
        )
    }

    /// Colour of pixel (x, y), linear RGB: its primary ray's, or with anti-aliasing
    /// (camera `aa` = N > 1) the mean of the N x N rays through the centres of its
    /// sub-pixels, (x + (i + ½)/N, y + (j + ½)/N), summed row by row with each clamped to
    /// [0, 1] (as the frame memory would hold it).
    pub fn pixel(&mut self, x: u32, y: u32) -> Vec3<T> {
        let n = self.camera.aa.min(crate::image::camera::MAX_AA) as i32;
        if n <= 1 {
            return self.sample(x, y, T::HALF, T::HALF);
        }
        let twice_n = T::from_i32(2 * n);
        let mut sum = Vec3::zero();
        for j in 0..n {
            let oy = T::from_i32(2 * j + 1) / twice_n;
            for i in 0..n {
                let ox = T::from_i32(2 * i + 1) / twice_n;
                let c = self.sample(x, y, ox, oy);
                sum = sum + Vec3::new(c.x.clamp01(), c.y.clamp01(), c.z.clamp01());
            }
        }
        sum * (T::ONE / T::from_i32(n * n))
    }

    /// Colour of the primary ray through (x + ox, y + oy), a point of pixel (x, y) (0 < ox,
    /// oy < 1: the ray lies in the pixel's row and column, which its clipping lists cover).
    fn sample(&mut self, x: u32, y: u32, ox: T, oy: T) -> Vec3<T> {
        self.stats.primary_rays += 1;
        self.secondary_left = SECONDARY_RAYS_PER_PIXEL;
        let d = self.eye_direction(x, y, ox, oy);
        let (ray, eye) = if T::ABSOLUTE_ROUNDING {
            // Fixed point tests its integer edge planes with the unit direction itself (the
            // ray the sheared fallback and everything after it use): one ray for both tests,
            // distances with no length to scale by.
            let unit = d.normalize();
            (
                Ray::new(Vec3::zero(), unit),
                Some(EyeRay {
                    d: unit,
                    len: T::ONE,
                }),
            )
        } else {
            // What `normalize` computes, with the length kept for the edge-plane test.
            let len = d.length();
            let unit = if len > T::ZERO && len.is_finite() {
                d * len.recip()
            } else {
                d
            };
            (Ray::new(Vec3::zero(), unit), Some(EyeRay { d, len }))
        };
        let hit = if self.state.borrow_mut().clip.row() == Some(y.min(u16::MAX as u32) as u16) {
            self.closest_hit_clipped(&ray, eye, x)
        } else {
            self.closest_hit_from(&ray, eye, T::MAX)
        };
        self.shade_hit(&ray, hit, 0)
    }

    /// Eq. 2.2: local shading plus reflected and transmitted light, recursively.
    pub fn trace(&mut self, ray: &Ray<T>, depth: u32) -> Vec3<T> {
        let hit = self.closest_hit(ray, T::MAX);
        self.shade_hit(ray, hit, depth)
    }

    /// The nearest surface a ray hits, for tests and tools.
    pub fn first_surface(&mut self, ray: &Ray<T>) -> Option<(T, Surface<T>)> {
        let hit = self.closest_hit(ray, T::MAX)?;
        Some((hit.t, self.surface(ray, &hit)))
    }
}

/// Quantise a linear colour to 8 bits (clamped, rounded to nearest).
#[inline]
pub fn to_rgb8<T: Real>(c: Vec3<T>) -> Rgb8 {
    [c.x.to_unit_u8(), c.y.to_unit_u8(), c.z.to_unit_u8()]
}

/// Render `out.len()` pixels of scanline `y` starting at column `x`: the node's unit of work.
pub fn render_run<T: Real, S: BorrowMut<TracerState<T>>>(
    tracer: &mut Tracer<'_, T, S>,
    y: u32,
    x: u32,
    out: &mut [Rgb8],
) -> Result<(), RenderError> {
    let f = tracer.camera();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::NodeBoard;

    /// A node keeps one tracer state (clipping lists, plane cache, walk stack) in its node
    /// task, which lives in the F407's 64 KB CCM beside the firmware's other statics
    /// (`scripts/fw-size`) and the stack: the state must leave room for both. The tracer of
    /// each run, on the stack, only borrows it.
    #[test]
    fn a_tracer_state_fits_half_the_node_cpu_ram_and_a_run_borrows_it() {
        let state = core::mem::size_of::<TracerState<f32>>();
        assert!(
            state <= NodeBoard::F407.ccm / 2,
            "TracerState<f32> is {state} bytes, over half of the F407's {} B CCM",
            NodeBoard::F407.ccm
        );
        // The plane cache is the largest part: 256 slots of 13 f32 and a tag.
        assert!(state > crate::trace::primary::PLANE_SLOTS * 56);
        let per_run = core::mem::size_of::<Tracer<'static, f32, &'static mut TracerState<f32>>>();
        assert!(per_run <= 1024, "a run's tracer is {per_run} bytes");
    }

    /// A state lent to the tracers of several runs and scenes gives each run the pixels of a
    /// tracer of its own, and keeps its caches only while the scene stays the same.
    #[cfg(feature = "std")]
    #[test]
    fn a_lent_state_gives_the_pixels_of_a_fresh_tracer_across_scenes() {
        use crate::desc::{Camera, Light, Node, Shape};
        use crate::dm::{compile, CompileOptions};
        let scene = |shift: f64| {
            let camera = Camera {
                eye: [0.0, 0.0, -4.0],
                look_at: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: 50.0,
            };
            let tri = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
                Node::Shape(Shape::Triangle {
                    v: [a, b, c],
                    normals: None,
                    uv: None,
                    material: 0,
                })
            };
            let mut desc = crate::testkit::scene::scene_desc(
                camera,
                24,
                16,
                std::vec![
                    tri(
                        [-1.0 + shift, -1.0, 0.0],
                        [1.0, -1.0, 0.5],
                        [0.0, 1.0 + shift, 0.0]
                    ),
                    tri(
                        [-2.0, -1.5, 1.0],
                        [2.0, -1.5, 1.0],
                        [0.0, -1.0 - shift, -1.0]
                    ),
                ],
            );
            desc.ambient = [0.2; 3];
            desc.lights = std::vec![Light::Point {
                pos: [1.0, 2.0, -3.0],
                color: [0.9, 0.8, 0.7],
                falloff: false,
            }];
            compile(&desc, &CompileOptions::default())
                .expect("compiles")
                .bytes
        };
        let (a, b) = (scene(0.0), scene(0.4));
        let mut state = TracerState::<f32>::new();
        // Scene a as frame 0, b as frame 1, then a again: the same bytes as frame 2.
        for (bytes, frame) in [(&a, 0u16), (&b, 1), (&a, 2), (&a, 2)] {
            let view = SceneView::new(bytes).expect("valid");
            for y in 0..16 {
                let mut want = [[0u8; 3]; 24];
                render_run(&mut Tracer::<f32>::new(view), y, 0, &mut want).expect("run");
                let mut got = [[0u8; 3]; 24];
                let key = SceneKey::of(&view, frame);
                let mut t = Tracer::with_state(view, Techniques::ALL, &mut state, key);
                render_run(&mut t, y, 0, &mut got).expect("run");
                assert_eq!(got, want, "frame {frame} row {y}");
            }
            assert_eq!(state.key, Some(SceneKey::of(&view, frame)));
        }
    }
}
