//! The DM ("data manipulation" module): compiles a [`SceneDesc`] into a SceneImage.
//!
//! It places every cluster (LINKS-1 4.1), transforms all shape data into view coordinates
//! (4.3: eye at the origin, X right, Y up, +Z into the screen), computes a bounding box per
//! shape and per cluster (4.2) and writes the flat node list the tracer walks. Runs on the
//! host in f64; the image stores f32, with every bounding box rounded outward so it still
//! contains its shape after rounding.
//!
//! Large meshes are split by the DM into sub-clusters of at most [`MESH_LEAF_SIZE`]
//! triangles (a binned-SAH BVH by default, see [`MeshHierarchy`]), so a ray that touches a
//! mesh's box only tests the triangles near it. Each node also gets its screen rectangle
//! (LINKS-1 4.4) for the renderer's Y/X clipping of primary rays.

use crate::desc::{self, Cluster, Light, Node, SceneDesc, Shape, TransparencyMode};
use crate::image::layout::{
    ball, blob_group, boxshape, camera, ellipsoid, light, material, node, normals, rect, texture,
    triangle, uvs,
};
use crate::image::writer::ImageWriter;
use crate::image::{Rect, Section, ShapeKind, ShapeRef, MAX_DEPTH_LIMIT, NONE};
use core::fmt;
use std::string::{String, ToString};
use std::vec::Vec;

/// Largest number of triangles the DM leaves in one mesh sub-cluster.
pub const MESH_LEAF_SIZE: usize = 4;

/// Settings that are not part of the scene file.
#[derive(Clone, Debug, Default)]
pub struct CompileOptions {
    /// Output size; `None` uses the scene's.
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub max_depth: Option<u32>,
    pub transparency: Option<TransparencyMode>,
    /// How the DM organises the triangles of a mesh below its cluster.
    pub mesh_hierarchy: MeshHierarchy,
    /// Render without shadows (no shadow rays; lights always reach a lit surface), as the
    /// paper's load-balancing measurements did.
    pub no_shadows: bool,
}

/// The hierarchy the DM builds inside each mesh cluster.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MeshHierarchy {
    /// LINKS-1's: the mesh is one cluster, every triangle a shape with its own box.
    Flat,
    /// Median split on the longest axis down to [`MESH_LEAF_SIZE`] triangles.
    Median,
    /// Binned surface-area-heuristic BVH (beyond the paper).
    #[default]
    Sah,
}

/// Why a scene could not be compiled.
#[derive(Clone, Debug, PartialEq)]
pub enum DmError {
    /// The eye, look-at and up vectors do not define a view.
    DegenerateCamera(String),
    /// A transform collapses space (zero scale) or is not finite.
    DegenerateTransform {
        cluster: String,
    },
    /// A shape becomes degenerate in view coordinates (after f32 rounding).
    DegenerateShape {
        cluster: String,
        what: String,
    },
    /// Density spheres can only be moved, rotated and scaled uniformly.
    NonUniformBlobScale {
        cluster: String,
    },
    BadIndex {
        what: String,
    },
    BadSetting(String),
    TooLarge {
        what: String,
    },
    /// A value beyond the f32 range in view coordinates (a transform carried a coordinate
    /// of the scene past it): the image would hold an infinity.
    BeyondF32 {
        section: &'static str,
        record: u32,
    },
}

impl fmt::Display for DmError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DmError::DegenerateCamera(s) => write!(f, "camera: {s}"),
            DmError::DegenerateTransform { cluster } => {
                write!(
                    f,
                    "cluster '{cluster}': transform is degenerate (zero scale or not finite)"
                )
            }
            DmError::DegenerateShape { cluster, what } => {
                write!(
                    f,
                    "cluster '{cluster}': {what} is degenerate in view coordinates"
                )
            }
            DmError::NonUniformBlobScale { cluster } => write!(
                f,
                "cluster '{cluster}': density spheres need a uniform scale (balls must stay round)"
            ),
            DmError::BadIndex { what } => write!(f, "{what}"),
            DmError::BadSetting(s) => write!(f, "{s}"),
            DmError::TooLarge { what } => write!(f, "scene too large: {what}"),
            DmError::BeyondF32 { section, record } => write!(
                f,
                "{section} record {record} holds a value beyond the f32 range (about ±3.4e38) \
                 after the cluster and view transforms"
            ),
        }
    }
}

impl std::error::Error for DmError {}

type M3 = [[f64; 3]; 3];

/// An affine map `p -> a p + t` in f64.
#[derive(Clone, Copy, Debug)]
struct Affine {
    a: M3,
    t: [f64; 3],
}

fn mat_mul(x: &M3, y: &M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| x[i][k] * y[k][j]).sum();
        }
    }
    r
}
fn mat_vec(x: &M3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| x[i][0] * v[0] + x[i][1] * v[1] + x[i][2] * v[2])
}
fn transpose(x: &M3) -> M3 {
    [0, 1, 2].map(|i| [x[0][i], x[1][i], x[2][i]])
}
fn det(m: &M3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}
fn inverse(m: &M3) -> Option<M3> {
    let d = det(m);
    let scale = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    if !d.is_finite() || d.abs() <= 1e-12 * scale * scale * scale || scale == 0.0 {
        return None;
    }
    let c =
        |r0: usize, c0: usize, r1: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [c(1, 1, 2, 2), -c(0, 1, 2, 2), c(0, 1, 1, 2)],
        [-c(1, 0, 2, 2), c(0, 0, 2, 2), -c(0, 0, 1, 2)],
        [c(1, 0, 2, 1), -c(0, 0, 2, 1), c(0, 0, 1, 1)],
    ];
    Some(adj.map(|row| row.map(|v| v / d)))
}
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn normalize(a: [f64; 3]) -> Option<[f64; 3]> {
    let l = dot(a, a).sqrt();
    (l > 0.0 && l.is_finite()).then(|| a.map(|v| v / l))
}
fn diag(s: [f64; 3]) -> M3 {
    [[s[0], 0.0, 0.0], [0.0, s[1], 0.0], [0.0, 0.0, s[2]]]
}

/// Rz · Ry · Rx for angles in degrees.
fn rotation(deg: [f64; 3]) -> M3 {
    let [x, y, z] = deg.map(f64::to_radians);
    let rx = [
        [1.0, 0.0, 0.0],
        [0.0, x.cos(), -x.sin()],
        [0.0, x.sin(), x.cos()],
    ];
    let ry = [
        [y.cos(), 0.0, y.sin()],
        [0.0, 1.0, 0.0],
        [-y.sin(), 0.0, y.cos()],
    ];
    let rz = [
        [z.cos(), -z.sin(), 0.0],
        [z.sin(), z.cos(), 0.0],
        [0.0, 0.0, 1.0],
    ];
    mat_mul(&rz, &mat_mul(&ry, &rx))
}

impl Affine {
    fn from_trs(t: [f64; 3], rot_deg: [f64; 3], s: [f64; 3]) -> Self {
        Self {
            a: mat_mul(&rotation(rot_deg), &diag(s)),
            t,
        }
    }
    /// `self ∘ o` (apply `o` first).
    fn then(&self, o: &Affine) -> Affine {
        Affine {
            a: mat_mul(&self.a, &o.a),
            t: add(mat_vec(&self.a, o.t), self.t),
        }
    }
    fn point(&self, p: [f64; 3]) -> [f64; 3] {
        add(mat_vec(&self.a, p), self.t)
    }
    fn is_finite(&self) -> bool {
        self.a
            .iter()
            .flatten()
            .chain(self.t.iter())
            .all(|v| v.is_finite())
    }
}

fn f32s(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}
fn mat_f32(m: &M3) -> [f32; 9] {
    [
        m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
    ]
    .map(|v| v as f32)
}

/// An f32 box that contains an f64 box.
#[derive(Clone, Copy, Debug)]
struct Bounds {
    min: [f32; 3],
    max: [f32; 3],
}

impl Bounds {
    fn empty() -> Self {
        Self {
            min: [f32::MAX; 3],
            max: [f32::MIN; 3],
        }
    }
    fn from_f64(min: [f64; 3], max: [f64; 3]) -> Self {
        let lo = min.map(|v| (v as f32).next_down());
        let hi = max.map(|v| (v as f32).next_up());
        Self { min: lo, max: hi }
    }
    fn union(self, o: Bounds) -> Self {
        Self {
            min: [0, 1, 2].map(|i| self.min[i].min(o.min[i])),
            max: [0, 1, 2].map(|i| self.max[i].max(o.max[i])),
        }
    }
    fn is_empty(&self) -> bool {
        (0..3).any(|i| self.min[i] > self.max[i])
    }
}

fn longest_axis(b: &Bounds) -> usize {
    let ext = [0, 1, 2].map(|k| b.max[k] - b.min[k]);
    if ext[0] >= ext[1] && ext[0] >= ext[2] {
        0
    } else if ext[1] >= ext[2] {
        1
    } else {
        2
    }
}

/// Sort by centroid along the longest axis and split in the middle.
fn median_split(tris: &mut [TriData]) -> usize {
    let all = tris
        .iter()
        .fold(Bounds::empty(), |b, t| b.union(t.bounds()));
    let axis = longest_axis(&all);
    tris.sort_by(|a, b| a.centroid(axis).total_cmp(&b.centroid(axis)));
    tris.len() / 2
}

fn half_area(b: &Bounds) -> f64 {
    if b.is_empty() {
        return 0.0;
    }
    let e = [0, 1, 2].map(|k| f64::from(b.max[k]) - f64::from(b.min[k]));
    e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
}

const SAH_BINS: usize = 16;

/// Centroid bin of a triangle along `axis` for centroids spanning `[lo, hi]`.
fn sah_bin(t: &TriData, axis: usize, lo: f32, hi: f32) -> usize {
    (((t.centroid(axis) - lo) / (hi - lo) * SAH_BINS as f32) as usize).min(SAH_BINS - 1)
}

/// Best bin boundary on one axis: (Σ area·count of both sides, first bin of the right side).
fn sah_best_on_axis(tris: &[TriData], axis: usize, lo: f32, hi: f32) -> Option<(f64, usize)> {
    let mut counts = [0usize; SAH_BINS];
    let mut boxes = [Bounds::empty(); SAH_BINS];
    for t in tris {
        let k = sah_bin(t, axis, lo, hi);
        counts[k] += 1;
        boxes[k] = boxes[k].union(t.bounds());
    }
    let mut best: Option<(f64, usize)> = None;
    for split in 1..SAH_BINS {
        let side = |r: core::ops::Range<usize>| {
            r.fold((Bounds::empty(), 0), |(b, n), k| {
                (b.union(boxes[k]), n + counts[k])
            })
        };
        let ((bl, nl), (br, nr)) = (side(0..split), side(split..SAH_BINS));
        if nl == 0 || nr == 0 {
            continue;
        }
        let c = half_area(&bl) * nl as f64 + half_area(&br) * nr as f64;
        if best.is_none_or(|b| c < b.0) {
            best = Some((c, split));
        }
    }
    best
}

/// Binned SAH split. Costs in units of one box test: a triangle leaf costs its box test
/// plus about two more for the triangle test; a cluster node one box test. Returns the
/// split point after reordering, or `None` to make a leaf run (only when the set is small
/// enough, <= [`MESH_LEAF_SIZE`], and splitting would not pay).
fn sah_split(tris: &mut [TriData]) -> Option<usize> {
    const COST_NODE: f64 = 1.0;
    const COST_TRI: f64 = 3.0;
    let n = tris.len();
    let all = tris
        .iter()
        .fold(Bounds::empty(), |b, t| b.union(t.bounds()));
    let cent = tris.iter().fold(Bounds::empty(), |b, t| {
        let c = [0, 1, 2].map(|k| t.centroid(k));
        b.union(Bounds { min: c, max: c })
    });
    let best = (0..3)
        .filter(|&a| cent.max[a] > cent.min[a])
        .filter_map(|a| sah_best_on_axis(tris, a, cent.min[a], cent.max[a]).map(|(c, k)| (c, a, k)))
        .min_by(|x, y| x.0.total_cmp(&y.0));
    let Some((area_cost, axis, edge)) = best else {
        // All centroids coincide: fall back to a median split for large sets.
        return (n > MESH_LEAF_SIZE).then(|| median_split(tris));
    };
    let cost = 2.0 * COST_NODE + area_cost * COST_TRI / half_area(&all).max(f64::MIN_POSITIVE);
    if n <= MESH_LEAF_SIZE && cost >= n as f64 * COST_TRI {
        return None;
    }
    let (lo, hi) = (cent.min[axis], cent.max[axis]);
    // Stable partition: left bins first, original order kept within each side.
    tris.sort_by_key(|t| sah_bin(t, axis, lo, hi) >= edge);
    Some(
        tris.iter()
            .take_while(|t| sah_bin(t, axis, lo, hi) < edge)
            .count(),
    )
}

/// What the DM produced, with per-section sizes for reports.
#[derive(Clone, Debug)]
pub struct Compiled {
    pub bytes: Vec<u8>,
}

struct Dm<'a> {
    desc: &'a SceneDesc,
    w: ImageWriter,
    opts: &'a CompileOptions,
    proj: Projection,
    /// Screen rectangle per node, in node order.
    rects: Vec<Rect>,
}

/// The screen projection of view coordinates (pixel centres at integer + ½).
#[derive(Clone, Copy, Debug, Default)]
struct Projection {
    x0: f64,
    y0: f64,
    dx: f64,
    dy: f64,
    width: u32,
    height: u32,
}

/// Slack in pixels added around projected extents, far above the rounding of a primary
/// ray's direction (~1e-4 px in f32), so clipping never drops a shape a ray can hit.
const RECT_SLACK_PX: f64 = 0.05;

impl Projection {
    fn full(&self) -> Rect {
        Rect {
            x_lo: 0,
            x_hi: (self.width - 1) as u16,
            y_lo: 0,
            y_hi: (self.height - 1) as u16,
        }
    }

    /// Pixels whose primary ray can meet the convex hull of `pts` (view coordinates).
    fn rect_of(&self, pts: &[[f64; 3]]) -> Rect {
        // Primary rays have z > 0 everywhere: nothing entirely behind the eye is visible.
        if pts.iter().all(|p| p[2] <= 0.0) {
            return Rect::EMPTY;
        }
        // A hull that reaches the eye's plane projects without bound.
        let near = 1e-9
            * pts
                .iter()
                .map(|p| p[0].abs().max(p[1].abs()).max(p[2].abs()))
                .fold(0.0, f64::max);
        if pts.iter().any(|p| p[2] <= near) {
            return self.full();
        }
        let (mut sx0, mut sx1, mut sy0, mut sy1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in pts {
            // Continuous screen coordinates: pixel x's centre is at x + ½.
            let sx = (p[0] / p[2] - self.x0) / self.dx;
            let sy = (self.y0 - p[1] / p[2]) / self.dy;
            sx0 = sx0.min(sx);
            sx1 = sx1.max(sx);
            sy0 = sy0.min(sy);
            sy1 = sy1.max(sy);
        }
        let lo = |v: f64, n: u32| ((v - 0.5 - RECT_SLACK_PX).ceil().max(0.0)).min(n as f64) as i64;
        let hi = |v: f64, n: u32| {
            ((v - 0.5 + RECT_SLACK_PX).floor().min(n as f64 - 1.0)).max(-1.0) as i64
        };
        let (xl, xh) = (lo(sx0, self.width), hi(sx1, self.width));
        let (yl, yh) = (lo(sy0, self.height), hi(sy1, self.height));
        if xl > xh || yl > yh {
            return Rect::EMPTY;
        }
        Rect {
            x_lo: xl as u16,
            x_hi: xh as u16,
            y_lo: yl as u16,
            y_hi: yh as u16,
        }
    }

    fn rect_of_bounds(&self, b: &Bounds) -> Rect {
        if b.is_empty() {
            return Rect::EMPTY;
        }
        let mut pts = [[0.0; 3]; 8];
        for (k, p) in pts.iter_mut().enumerate() {
            for (a, c) in p.iter_mut().enumerate() {
                *c = f64::from(if k >> a & 1 == 0 { b.min[a] } else { b.max[a] });
            }
        }
        self.rect_of(&pts)
    }
}

/// A triangle ready to write: view-space vertices and optional normals / uvs.
struct TriData {
    p: [[f32; 3]; 3],
    n: Option<[[f32; 3]; 3]>,
    uv: Option<[[f32; 2]; 3]>,
    material: u32,
}

impl TriData {
    /// World -> view mirrors space (right-handed world, left-handed view), which would turn
    /// counter-clockwise (outward-facing) triangles clockwise: swap two vertices to undo it.
    fn keep_winding(&mut self, full: &Affine) {
        if det(&full.a) < 0.0 {
            self.p.swap(1, 2);
            if let Some(n) = &mut self.n {
                n.swap(1, 2);
            }
            if let Some(uv) = &mut self.uv {
                uv.swap(1, 2);
            }
        }
    }
    /// Drop vertex normals that all equal the face normal: a flat face shades the same
    /// without them, and the image carries only what the scene needs.
    fn drop_flat_normals(&mut self) {
        let Some(n) = self.n else { return };
        let v = self.p.map(|p| p.map(f64::from));
        let Some(face) = normalize(cross(sub(v[1], v[0]), sub(v[2], v[0]))) else {
            return;
        };
        let flat = n.iter().all(|vn| {
            let vn = vn.map(f64::from);
            // Same direction and orientation: without vertex normals the renderer takes the
            // outside from the winding, so only normals that agree with it may go.
            dot(vn, face) > 1.0 - 1e-6
        });
        if flat {
            self.n = None;
        }
    }

    fn centroid(&self, axis: usize) -> f32 {
        (self.p[0][axis] + self.p[1][axis] + self.p[2][axis]) / 3.0
    }
    fn bounds(&self) -> Bounds {
        // The stored vertices are f32 already, so their box is exact.
        let mut b = Bounds::empty();
        for v in &self.p {
            b = b.union(Bounds { min: *v, max: *v });
        }
        b
    }
}

/// Compile a scene for one frame.
pub fn compile(desc: &SceneDesc, opts: &CompileOptions) -> Result<Compiled, DmError> {
    let mut dm = Dm {
        desc,
        w: ImageWriter::new(),
        opts,
        proj: Projection::default(),
        rects: Vec::new(),
    };
    dm.run()?;
    let bytes = dm.w.finish();
    // Every scene-file number fits f32, but a transform can carry a coordinate past it.
    match crate::fixed_image::first_non_finite(&bytes) {
        Ok(None) => Ok(Compiled { bytes }),
        Ok(Some((section, record))) => Err(DmError::BeyondF32 {
            section: section.name(),
            record,
        }),
        Err(e) => Err(DmError::TooLarge {
            what: format!("the image the DM wrote is not valid: {e}"),
        }),
    }
}

impl Dm<'_> {
    fn run(&mut self) -> Result<(), DmError> {
        let d = self.desc;
        let width = self.opts.width.unwrap_or(d.width);
        let height = self.opts.height.unwrap_or(d.height);
        if width == 0 || height == 0 || width > 65535 || height > 65535 {
            return Err(DmError::BadSetting(format!(
                "image size {width}x{height} out of range 1..65535"
            )));
        }
        let max_depth = self.opts.max_depth.unwrap_or(d.max_depth);
        if max_depth > MAX_DEPTH_LIMIT {
            return Err(DmError::BadSetting(format!(
                "max depth {max_depth} exceeds the node limit {MAX_DEPTH_LIMIT}"
            )));
        }
        let mode = self.opts.transparency.unwrap_or(d.transparency);

        // View transform: rows are the screen's right, up and forward axes in world space.
        let cam = &d.camera;
        let fwd = normalize(sub(cam.look_at, cam.eye))
            .ok_or_else(|| DmError::DegenerateCamera("eye and look_at coincide".into()))?;
        let right = normalize(cross(fwd, cam.up)).ok_or_else(|| {
            DmError::DegenerateCamera("up is parallel to the view direction".into())
        })?;
        let up = cross(right, fwd);
        let rot = [right, up, fwd];
        let view = Affine {
            a: rot,
            t: mat_vec(&rot, cam.eye).map(|v| -v),
        };
        if !(cam.fov_y_deg > 0.0 && cam.fov_y_deg < 180.0) {
            return Err(DmError::DegenerateCamera(format!(
                "fov_y {} not in (0, 180)",
                cam.fov_y_deg
            )));
        }

        // Camera record: pixel centres on the z = 1 plane.
        let tan_half = (cam.fov_y_deg.to_radians() * 0.5).tan();
        let dy = 2.0 * tan_half / height as f64;
        let dx = dy;
        let x0 = -dx * width as f64 * 0.5;
        // Project with the values the renderer will use (rounded to f32).
        self.proj = Projection {
            x0: f64::from(x0 as f32),
            y0: f64::from(tan_half as f32),
            dx: f64::from(dx as f32),
            dy: f64::from(dy as f32),
            width,
            height,
        };
        let flags = u32::from(mode == TransparencyMode::NonRefractive)
            | (u32::from(self.opts.no_shadows) << 1);
        self.w
            .push(Section::Camera)
            .1
            .u(camera::WIDTH, width)
            .u(camera::HEIGHT, height)
            .f(camera::X0, x0 as f32)
            .f(camera::Y0, tan_half as f32)
            .f(camera::DX, dx as f32)
            .f(camera::DY, dy as f32)
            .fs(camera::BACKGROUND, &d.background)
            .fs(camera::AMBIENT, &d.ambient)
            .u(camera::MAX_DEPTH, max_depth)
            .u(camera::FLAGS, flags)
            .f(camera::DZ, 1.0);

        for (i, t) in d.textures.iter().enumerate() {
            // The byte count in u32, checked: the image's texel section counts bytes in u32.
            let bytes = t.width.checked_mul(t.height).and_then(|n| n.checked_mul(3));
            if t.width == 0 || t.height == 0 || bytes.map(|n| n as usize) != Some(t.rgb.len()) {
                return Err(DmError::BadIndex {
                    what: format!("texture {i} ('{}') has a bad size", t.name),
                });
            }
            let off = self.w.push_texels(&t.rgb);
            self.w
                .push(Section::Textures)
                .1
                .u(texture::WIDTH, t.width)
                .u(texture::HEIGHT, t.height)
                .u(texture::TEXELS, off);
        }
        // The texel section must keep later sections aligned: the writer pads.
        for m in &d.materials {
            self.material(m)?;
        }
        for l in &d.lights {
            self.light(l, &view)?;
        }
        self.cluster(&d.root, &view, d.root.name.as_str())?;
        for r in std::mem::take(&mut self.rects) {
            self.w
                .push(Section::Rects)
                .1
                .h(rect::X_LO, r.x_lo)
                .h(rect::X_HI, r.x_hi)
                .h(rect::Y_LO, r.y_lo)
                .h(rect::Y_HI, r.y_hi);
        }
        if self.w.count(Section::Nodes) >= (1 << ShapeRef::INDEX_BITS) {
            return Err(DmError::TooLarge {
                what: "too many nodes".into(),
            });
        }
        Ok(())
    }

    fn material(&mut self, m: &desc::Material) -> Result<(), DmError> {
        let (tex, target, scale) = match &m.map {
            Some(map) => {
                if map.texture as usize >= self.desc.textures.len() {
                    return Err(DmError::BadIndex {
                        what: format!("material '{}' uses missing texture {}", m.name, map.texture),
                    });
                }
                (map.texture, map.target as u32, map.scale)
            }
            None => (NONE, 0, [1.0, 1.0]),
        };
        self.w
            .push(Section::Materials)
            .1
            .fs(material::DIFFUSE, &m.diffuse)
            .f(material::SPECULAR, m.specular)
            .f(material::SPECULAR_EDGE, m.specular_edge)
            .f(material::SHININESS, m.shininess)
            .f(material::REFLECT, m.reflect)
            .f(material::REFLECT_EDGE, m.reflect_edge)
            .fs(material::TRANSMIT, &m.transmit)
            .f(material::IOR, m.ior)
            .u(material::TEXTURE, tex)
            .u(material::TARGET, target)
            .fs(material::SCALE, &scale);
        Ok(())
    }

    fn light(&mut self, l: &Light, view: &Affine) -> Result<(), DmError> {
        let dir_of = |d: [f64; 3]| {
            normalize(mat_vec(&view.a, d))
                .ok_or_else(|| DmError::BadSetting("light direction is zero".into()))
        };
        let (kind, color, pos, dir, ci, co, e, fall) = match l {
            Light::Directional { dir, color } => {
                (0, color, [0.0; 3], dir_of(*dir)?, 1.0, 1.0, 0.0, false)
            }
            Light::Point {
                pos,
                color,
                falloff,
            } => (
                1,
                color,
                view.point(*pos),
                [0.0; 3],
                1.0,
                1.0,
                0.0,
                *falloff,
            ),
            Light::Spot {
                pos,
                dir,
                color,
                inner_deg,
                outer_deg,
                exponent,
            } => (
                2,
                color,
                view.point(*pos),
                dir_of(*dir)?,
                inner_deg.to_radians().cos(),
                outer_deg.to_radians().cos(),
                *exponent,
                false,
            ),
        };
        self.w
            .push(Section::Lights)
            .1
            .u(light::KIND, kind)
            .fs(light::COLOR, color)
            .fs(light::POS, &f32s(pos))
            .fs(light::DIR, &f32s(dir))
            .f(light::COS_INNER, ci as f32)
            .f(light::COS_OUTER, co as f32)
            .f(light::EXPONENT, e)
            .u(light::FALLOFF, u32::from(fall));
        Ok(())
    }

    /// Start a cluster node; returns its index so `close` can patch skip and bounds.
    fn open_node(&mut self) -> u32 {
        let (i, r) = self.w.push(Section::Nodes);
        r.fs(node::MIN, &[0.0; 3])
            .fs(node::MAX, &[0.0; 3])
            .u(node::SKIP, 0)
            .u(node::SHAPE, NONE);
        self.rects.push(Rect::EMPTY);
        i
    }

    fn close_node(&mut self, i: u32, b: Bounds) {
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
    fn leaf(&mut self, shape: ShapeRef, b: Bounds) {
        let rect = self.proj.rect_of_bounds(&b);
        self.leaf_with_rect(shape, b, rect);
    }

    fn leaf_with_rect(&mut self, shape: ShapeRef, b: Bounds, rect: Rect) {
        let (i, r) = self.w.push(Section::Nodes);
        r.fs(node::MIN, &b.min)
            .fs(node::MAX, &b.max)
            .u(node::SKIP, i + 1)
            .u(node::SHAPE, shape.encode());
        self.rects.push(rect);
    }

    fn cluster(&mut self, c: &Cluster, parent: &Affine, path: &str) -> Result<Bounds, DmError> {
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

    fn check_material(&self, m: u32) -> Result<u32, DmError> {
        if (m as usize) < self.desc.materials.len() {
            Ok(m)
        } else {
            Err(DmError::BadIndex {
                what: format!("shape uses missing material {m}"),
            })
        }
    }

    fn shape(&mut self, s: &Shape, full: &Affine, path: &str) -> Result<Bounds, DmError> {
        let normal_m =
            transpose(
                &inverse(&full.a).ok_or_else(|| DmError::DegenerateTransform {
                    cluster: path.to_string(),
                })?,
            );
        let xn = |n: [f64; 3]| normalize(mat_vec(&normal_m, n)).map(f32s);
        match s {
            Shape::Triangle {
                v,
                normals,
                uv,
                material,
            } => {
                let material = self.check_material(*material)?;
                let p = v.map(|p| f32s(full.point(p)));
                let n = match normals {
                    Some(ns) => {
                        let mut out = [[0.0f32; 3]; 3];
                        for k in 0..3 {
                            out[k] = xn(ns[k]).ok_or_else(|| DmError::DegenerateShape {
                                cluster: path.to_string(),
                                what: "a triangle vertex normal".into(),
                            })?;
                        }
                        Some(out)
                    }
                    None => None,
                };
                let mut tri = TriData {
                    p,
                    n,
                    uv: uv.map(|u| u.map(|q| q.map(|x| x as f32))),
                    material,
                };
                tri.keep_winding(full);
                tri.drop_flat_normals();
                self.check_triangle(&tri, path)?;
                Ok(self.triangles(vec![tri]))
            }
            Shape::Mesh {
                mesh,
                material,
                smooth,
            } => {
                let material = self.check_material(*material)?;
                let mut tris =
                    self.mesh_triangles(mesh, *smooth, material, full, &normal_m, path)?;
                let node = self.open_node();
                let b = if mesh.groups.len() <= 1 {
                    self.triangles(tris)
                } else {
                    // One sub-cluster per group (the model's parts), last group first so the
                    // tail of `tris` can be split off; then written in file order.
                    let mut parts = Vec::with_capacity(mesh.groups.len());
                    for g in mesh.groups.iter().rev() {
                        let at = (g.first_face as usize).min(tris.len());
                        parts.push(tris.split_off(at));
                    }
                    if !tris.is_empty() {
                        // Faces before the first group form a part of their own.
                        parts.push(tris);
                    }
                    let mut b = Bounds::empty();
                    for part in parts.into_iter().rev().filter(|p| !p.is_empty()) {
                        let sub = self.open_node();
                        let pb = self.triangles(part);
                        self.close_node(sub, pb);
                        b = b.union(pb);
                    }
                    b
                };
                self.close_node(node, b);
                Ok(b)
            }
            Shape::Ellipsoid {
                center,
                radii,
                rotate_deg,
                cut,
                material,
            } => {
                let material = self.check_material(*material)?;
                let obj = Affine::from_trs(*center, *rotate_deg, *radii);
                let m = full.then(&obj);
                let inv = inverse(&m.a).ok_or_else(|| DmError::DegenerateShape {
                    cluster: path.to_string(),
                    what: "an ellipsoid".into(),
                })?;
                let (flags, cn, cd) = match cut {
                    Some(c) => {
                        let sn = [
                            c.normal[0] * radii[0],
                            c.normal[1] * radii[1],
                            c.normal[2] * radii[2],
                        ];
                        let len = dot(sn, sn).sqrt();
                        if len == 0.0 || !len.is_finite() {
                            return Err(DmError::DegenerateShape {
                                cluster: path.to_string(),
                                what: "an ellipsoid's cut plane".into(),
                            });
                        }
                        (
                            1 | (u32::from(c.capped) << 1),
                            sn.map(|v| v / len),
                            c.offset / len,
                        )
                    }
                    None => (0, [0.0; 3], 0.0),
                };
                let (i, r) = self.w.push(Section::Ellipsoids);
                r.fs(ellipsoid::CENTER, &f32s(m.t))
                    .fs(ellipsoid::M, &mat_f32(&inv))
                    .fs(ellipsoid::L, &mat_f32(&m.a))
                    .u(ellipsoid::MATERIAL, material)
                    .u(ellipsoid::FLAGS, flags)
                    .fs(ellipsoid::CUT_N, &f32s(cn))
                    .f(ellipsoid::CUT_D, cd as f32);
                // Half-extent of a transformed unit sphere along axis i: |row i of L|.
                let half = [0, 1, 2].map(|k| dot(m.a[k], m.a[k]).sqrt());
                let b = Bounds::from_f64(sub(m.t, half), add(m.t, half));
                self.leaf(
                    ShapeRef {
                        kind: ShapeKind::Ellipsoid,
                        index: i,
                    },
                    b,
                );
                Ok(b)
            }
            Shape::Box { min, max, material } => {
                let material = self.check_material(*material)?;
                let c = [0, 1, 2].map(|k| 0.5 * (min[k] + max[k]));
                let h = [0, 1, 2].map(|k| 0.5 * (max[k] - min[k]));
                let m = full.then(&Affine { a: diag(h), t: c });
                let inv = inverse(&m.a).ok_or_else(|| DmError::DegenerateShape {
                    cluster: path.to_string(),
                    what: "a box".into(),
                })?;
                let (i, r) = self.w.push(Section::Boxes);
                r.fs(boxshape::CENTER, &f32s(m.t))
                    .fs(boxshape::M, &mat_f32(&inv))
                    .fs(boxshape::L, &mat_f32(&m.a))
                    .u(boxshape::MATERIAL, material);
                let half = [0, 1, 2].map(|k| m.a[k].iter().map(|v| v.abs()).sum::<f64>());
                let b = Bounds::from_f64(sub(m.t, half), add(m.t, half));
                self.leaf(
                    ShapeRef {
                        kind: ShapeKind::Box,
                        index: i,
                    },
                    b,
                );
                Ok(b)
            }
            Shape::Blobs {
                balls,
                threshold,
                kernel,
                material,
            } => {
                let material = self.check_material(*material)?;
                // Uniform scale s: columns of the linear part are orthogonal with equal length.
                let ata = mat_mul(&transpose(&full.a), &full.a);
                let s2 = ata[0][0];
                let tol = 1e-9 * s2;
                let uniform = (0..3).all(|i| {
                    (0..3).all(|j| (ata[i][j] - if i == j { s2 } else { 0.0 }).abs() <= tol)
                });
                if !uniform || s2 <= 0.0 {
                    return Err(DmError::NonUniformBlobScale {
                        cluster: path.to_string(),
                    });
                }
                if balls.is_empty() {
                    return Err(DmError::DegenerateShape {
                        cluster: path.to_string(),
                        what: "an empty blob group".into(),
                    });
                }
                let s = s2.sqrt();
                let first = self.w.count(Section::Balls);
                let mut lo = [f64::MAX; 3];
                let mut hi = [f64::MIN; 3];
                for ball in balls {
                    let c = full.point(ball.center);
                    let r = ball.radius * s;
                    self.w
                        .push(Section::Balls)
                        .1
                        .fs(ball::CENTER, &f32s(c))
                        .f(ball::RADIUS, r as f32)
                        .f(ball::STRENGTH, ball.strength as f32);
                    if ball.strength > 0.0 {
                        for k in 0..3 {
                            lo[k] = lo[k].min(c[k] - r);
                            hi[k] = hi[k].max(c[k] + r);
                        }
                    }
                }
                let (i, r) = self.w.push(Section::BlobGroups);
                let k = match kernel {
                    desc::BlobKernel::Links => 0,
                    desc::BlobKernel::Wyvill => 1,
                };
                r.u(blob_group::MATERIAL, material)
                    .u(blob_group::KERNEL, k)
                    .f(blob_group::THRESHOLD, *threshold as f32)
                    .u(blob_group::FIRST, first)
                    .u(blob_group::COUNT, balls.len() as u32);
                // Grow by a relative margin: the root finder may stop a tolerance outside.
                let pad = [0, 1, 2].map(|k| 1e-4 * (hi[k] - lo[k]).abs());
                let b = if lo[0] > hi[0] {
                    Bounds::empty()
                } else {
                    Bounds::from_f64(sub(lo, pad), add(hi, pad))
                };
                self.leaf(
                    ShapeRef {
                        kind: ShapeKind::Blob,
                        index: i,
                    },
                    b,
                );
                Ok(b)
            }
        }
    }

    fn check_triangle(&self, t: &TriData, path: &str) -> Result<(), DmError> {
        let v = t.p.map(|p| p.map(f64::from));
        let area2 = cross(sub(v[1], v[0]), sub(v[2], v[0]));
        if dot(area2, area2) == 0.0 || !t.p.iter().flatten().all(|x| x.is_finite()) {
            return Err(DmError::DegenerateShape {
                cluster: path.to_string(),
                what: "a triangle".into(),
            });
        }
        Ok(())
    }

    fn mesh_triangles(
        &self,
        mesh: &desc::Mesh,
        smooth: bool,
        material: u32,
        full: &Affine,
        normal_m: &M3,
        path: &str,
    ) -> Result<Vec<TriData>, DmError> {
        let bad = |what: String| DmError::BadIndex {
            what: format!("mesh '{}': {what}", mesh.source),
        };
        let pos = |i: u32| {
            mesh.positions
                .get(i as usize)
                .copied()
                .ok_or_else(|| bad(format!("position {i} missing")))
        };
        // Area-weighted vertex normals for smooth meshes without their own.
        let computed: Option<Vec<[f64; 3]>> = (smooth && mesh.normals.is_empty()).then(|| {
            let mut acc = vec![[0.0; 3]; mesh.positions.len()];
            for f in &mesh.faces {
                let p: Vec<[f64; 3]> = f
                    .iter()
                    .filter_map(|v| mesh.positions.get(v.position as usize).copied())
                    .collect();
                if p.len() == 3 {
                    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
                    for v in f {
                        if let Some(a) = acc.get_mut(v.position as usize) {
                            *a = add(*a, n);
                        }
                    }
                }
            }
            acc
        });
        let mut out = Vec::with_capacity(mesh.faces.len());
        for (fi, f) in mesh.faces.iter().enumerate() {
            let mut p = [[0.0f32; 3]; 3];
            let mut n = [[0.0f32; 3]; 3];
            let mut has_n = true;
            let mut uv = [[0.0f32; 2]; 3];
            let mut has_uv = true;
            for k in 0..3 {
                let v = f[k];
                p[k] = f32s(full.point(pos(v.position)?));
                let world_n = match (&computed, v.normal) {
                    (Some(c), _) => c.get(v.position as usize).copied(),
                    (None, Some(ni)) => Some(
                        mesh.normals
                            .get(ni as usize)
                            .copied()
                            .ok_or_else(|| bad(format!("normal {ni} missing")))?,
                    ),
                    (None, None) => None,
                };
                match world_n.and_then(|wn| normalize(mat_vec(normal_m, wn))) {
                    Some(vn) => n[k] = f32s(vn),
                    None => has_n = false,
                }
                match v.uv {
                    Some(ti) => {
                        let t = mesh
                            .uvs
                            .get(ti as usize)
                            .copied()
                            .ok_or_else(|| bad(format!("uv {ti} missing")))?;
                        uv[k] = [t[0] as f32, t[1] as f32];
                    }
                    None => has_uv = false,
                }
            }
            let mut tri = TriData {
                p,
                n: has_n.then_some(n),
                uv: has_uv.then_some(uv),
                material,
            };
            tri.keep_winding(full);
            tri.drop_flat_normals();
            self.check_triangle(
                &tri,
                &format!("{path} (mesh '{}', face {})", mesh.source, fi + 1),
            )?;
            out.push(tri);
        }
        Ok(out)
    }

    /// Write triangles as leaves, splitting into sub-clusters per [`MeshHierarchy`].
    fn triangles(&mut self, mut tris: Vec<TriData>) -> Bounds {
        let split = match self.opts.mesh_hierarchy {
            _ if tris.len() <= 1 => None,
            MeshHierarchy::Flat => None,
            MeshHierarchy::Median if tris.len() <= MESH_LEAF_SIZE => None,
            MeshHierarchy::Median => Some(median_split(&mut tris)),
            MeshHierarchy::Sah => sah_split(&mut tris),
        };
        let Some(mid) = split else {
            let mut b = Bounds::empty();
            for t in tris {
                let tb = t.bounds();
                // Triangles are projected directly (LINKS-1 4.4): tighter than their box.
                let rect = self.proj.rect_of(&t.p.map(|p| p.map(f64::from)));
                let idx = self.write_triangle(t);
                self.leaf_with_rect(
                    ShapeRef {
                        kind: ShapeKind::Triangle,
                        index: idx,
                    },
                    tb,
                    rect,
                );
                b = b.union(tb);
            }
            return b;
        };
        let right = tris.split_off(mid);
        let mut b = Bounds::empty();
        for half in [tris, right] {
            let node = self.open_node();
            let hb = self.triangles(half);
            self.close_node(node, hb);
            b = b.union(hb);
        }
        b
    }

    fn write_triangle(&mut self, t: TriData) -> u32 {
        let ni = match t.n {
            Some(n) => {
                let (i, r) = self.w.push(Section::Normals);
                r.fs(normals::N, &n[0])
                    .fs(normals::N + normals::STRIDE, &n[1])
                    .fs(normals::N + 2 * normals::STRIDE, &n[2]);
                i
            }
            None => NONE,
        };
        let ui = match t.uv {
            Some(uv) => {
                let (i, r) = self.w.push(Section::Uvs);
                r.fs(uvs::UV, &uv[0])
                    .fs(uvs::UV + uvs::STRIDE, &uv[1])
                    .fs(uvs::UV + 2 * uvs::STRIDE, &uv[2]);
                i
            }
            None => NONE,
        };
        let (i, r) = self.w.push(Section::Triangles);
        r.fs(triangle::P, &t.p[0])
            .fs(triangle::P + triangle::VERTEX_STRIDE, &t.p[1])
            .fs(triangle::P + 2 * triangle::VERTEX_STRIDE, &t.p[2])
            .u(triangle::MATERIAL, t.material)
            .u(triangle::NORMALS, ni)
            .u(triangle::UVS, ui);
        i
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::desc::*;
    use crate::image::SceneView;

    fn scene(children: Vec<Node>) -> SceneDesc {
        SceneDesc {
            camera: Camera {
                eye: [0.0, 0.0, 5.0],
                look_at: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: 40.0,
            },
            width: 16,
            height: 16,
            background: [0.0; 3],
            ambient: [0.1; 3],
            max_depth: 3,
            transparency: TransparencyMode::Refractive,
            materials: vec![Material::default()],
            textures: vec![],
            lights: vec![],
            root: Cluster {
                name: "root".into(),
                transform: Transform::default(),
                children,
            },
        }
    }

    fn quad_mesh(normal: [f64; 3]) -> Mesh {
        let fv = |p, n| FaceVertex {
            position: p,
            normal: Some(n),
            uv: None,
        };
        Mesh {
            source: "quad".into(),
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            normals: vec![normal, [0.3, 0.0, 0.954]],
            uvs: vec![],
            faces: vec![
                [fv(0, 0), fv(1, 0), fv(2, 0)],
                [fv(0, 0), fv(2, 0), fv(3, 1)],
            ],
            groups: vec![],
        }
    }

    #[test]
    fn flat_vertex_normals_are_dropped_and_smooth_ones_kept() {
        let s = scene(vec![Node::Shape(Shape::Mesh {
            mesh: quad_mesh([0.0, 0.0, 1.0]),
            material: 0,
            smooth: false,
        })]);
        let img = compile(&s, &CompileOptions::default()).unwrap().bytes;
        let v = SceneView::new(&img).unwrap();
        assert_eq!(v.count(Section::Triangles), 2);
        assert_eq!(
            v.count(Section::Normals),
            1,
            "the face whose corners all carry the face normal needs none"
        );
        // Normals that disagree with the winding are kept: they say which side is outside.
        let s = scene(vec![Node::Shape(Shape::Mesh {
            mesh: quad_mesh([0.0, 0.0, -1.0]),
            material: 0,
            smooth: false,
        })]);
        let img = compile(&s, &CompileOptions::default()).unwrap().bytes;
        assert_eq!(SceneView::new(&img).unwrap().count(Section::Normals), 2);
    }

    #[test]
    fn every_shape_is_reachable_exactly_once_in_every_hierarchy() {
        let mut mesh = quad_mesh([0.0, 0.0, 1.0]);
        // Make a bigger mesh: 40 quads in a strip, in two groups.
        let base = mesh.clone();
        for k in 1..40u32 {
            let off = mesh.positions.len() as u32;
            mesh.positions.extend(
                base.positions
                    .iter()
                    .map(|p| [p[0] + k as f64, p[1], p[2] + 0.1 * k as f64]),
            );
            mesh.faces.extend(base.faces.iter().map(|f| {
                f.map(|v| FaceVertex {
                    position: v.position + off,
                    ..v
                })
            }));
        }
        mesh.groups = vec![
            MeshGroup {
                name: "a".into(),
                first_face: 0,
            },
            MeshGroup {
                name: "b".into(),
                first_face: 33,
            },
        ];
        let blob = Shape::Blobs {
            balls: vec![Ball {
                center: [0.0; 3],
                radius: 1.0,
                strength: 1.0,
            }],
            threshold: 0.5,
            kernel: BlobKernel::Links,
            material: 0,
        };
        let inner = Cluster {
            name: "inner".into(),
            transform: Transform {
                translate: [1.0, 2.0, 3.0],
                ..Transform::default()
            },
            children: vec![
                Node::Shape(Shape::Box {
                    min: [0.0; 3],
                    max: [1.0; 3],
                    material: 0,
                }),
                Node::Shape(blob),
                Node::Cluster(Cluster::default()),
            ],
        };
        let s = scene(vec![
            Node::Shape(Shape::Mesh {
                mesh,
                material: 0,
                smooth: true,
            }),
            Node::Cluster(inner),
            Node::Shape(Shape::Ellipsoid {
                center: [0.0; 3],
                radii: [1.0; 3],
                rotate_deg: [0.0; 3],
                cut: None,
                material: 0,
            }),
        ]);
        for h in [
            MeshHierarchy::Flat,
            MeshHierarchy::Median,
            MeshHierarchy::Sah,
        ] {
            let img = compile(
                &s,
                &CompileOptions {
                    mesh_hierarchy: h,
                    ..Default::default()
                },
            )
            .unwrap()
            .bytes;
            let v = SceneView::new(&img).unwrap();
            let mut seen = std::collections::HashMap::new();
            for i in 0..v.node_count() {
                if let Some(r) = v.node::<f64>(i).shape {
                    *seen.entry((r.kind as u8, r.index)).or_insert(0) += 1;
                }
                // Subtrees nest: a child's subtree ends no later than its parent's.
                let skip = v.node_skip(i);
                for j in i + 1..skip {
                    assert!(
                        v.node_skip(j) <= skip,
                        "{h:?}: node {j} leaves its parent {i}"
                    );
                }
            }
            assert_eq!(
                v.node_skip(0),
                v.node_count(),
                "{h:?}: the root spans everything"
            );
            assert_eq!(
                seen.len(),
                80 + 3,
                "{h:?}: 80 triangles, a box, a blob group, an ellipsoid"
            );
            assert!(
                seen.values().all(|&n| n == 1),
                "{h:?}: every shape in exactly one leaf"
            );
        }
    }

    #[test]
    fn mesh_groups_become_sub_clusters() {
        let mut mesh = quad_mesh([0.0, 0.0, 1.0]);
        mesh.groups = vec![
            MeshGroup {
                name: "a".into(),
                first_face: 0,
            },
            MeshGroup {
                name: "b".into(),
                first_face: 1,
            },
        ];
        let s = scene(vec![Node::Shape(Shape::Mesh {
            mesh,
            material: 0,
            smooth: false,
        })]);
        let opts = CompileOptions {
            mesh_hierarchy: MeshHierarchy::Flat,
            ..Default::default()
        };
        let img = compile(&s, &opts).unwrap().bytes;
        let v = SceneView::new(&img).unwrap();
        // root, mesh, group a, its triangle, group b, its triangle.
        let skips: Vec<u32> = (0..v.node_count()).map(|i| v.node_skip(i)).collect();
        let leaves: Vec<bool> = (0..v.node_count()).map(|i| v.node_is_leaf(i)).collect();
        assert_eq!(skips, [6, 6, 4, 4, 6, 6]);
        assert_eq!(leaves, [false, false, false, true, false, true]);
    }

    #[test]
    fn boxes_contain_their_shapes_after_transforms() {
        let t = Transform {
            translate: [1.0, -2.0, 0.5],
            rotate_deg: [30.0, 45.0, 10.0],
            scale: [2.0, 0.5, 1.5],
        };
        let shapes = vec![
            Node::Shape(Shape::Ellipsoid {
                center: [0.5, 0.0, 0.0],
                radii: [1.0, 2.0, 0.5],
                rotate_deg: [10.0, 0.0, 70.0],
                cut: None,
                material: 0,
            }),
            Node::Shape(Shape::Box {
                min: [-1.0, -1.0, -1.0],
                max: [1.0, 0.5, 2.0],
                material: 0,
            }),
            Node::Shape(Shape::Triangle {
                v: [[0.0, 0.0, 0.0], [3.0, 0.0, 1.0], [0.0, 2.0, -1.0]],
                normals: None,
                uv: None,
                material: 0,
            }),
        ];
        let s = scene(vec![Node::Cluster(Cluster {
            name: "c".into(),
            transform: t,
            children: shapes,
        })]);
        let img = compile(&s, &CompileOptions::default()).unwrap().bytes;
        let v = SceneView::new(&img).unwrap();
        // Sample each shape's surface densely (through its own local frame) and check the leaf
        // box and every enclosing cluster box contain the samples.
        let contains_all = |pts: &[crate::geom::Vec3<f64>], leaf: u32| {
            for i in 0..v.node_count() {
                let n = v.node::<f64>(i);
                if i <= leaf && n.skip > leaf {
                    for p in pts {
                        assert!(
                            n.bounds.contains(*p),
                            "node {i} box {:?} misses {p:?}",
                            n.bounds
                        );
                    }
                }
            }
        };
        for leaf in 0..v.node_count() {
            let Some(r) = v.node::<f64>(leaf).shape else {
                continue;
            };
            let mut pts = Vec::new();
            for a in 0..24 {
                for b in 0..12 {
                    let (th, ph) = (a as f64 * 0.2618, b as f64 * 0.2618 + 0.1);
                    let q =
                        crate::geom::Vec3::new(ph.sin() * th.cos(), ph.cos(), ph.sin() * th.sin());
                    match r.kind {
                        ShapeKind::Ellipsoid => {
                            let e = v.ellipsoid::<f64>(r.index).shape;
                            pts.push(e.center + e.l.mul_vec(q));
                        }
                        ShapeKind::Box => {
                            let bx = v.boxshape::<f64>(r.index).shape;
                            let c = q * (1.0 / q.abs().max_component());
                            pts.push(bx.center + bx.l.mul_vec(c));
                        }
                        _ => {}
                    }
                }
            }
            if r.kind == ShapeKind::Triangle {
                pts.extend(v.triangle::<f64>(r.index).tri.p);
            }
            assert!(!pts.is_empty());
            contains_all(&pts, leaf);
        }
    }

    #[test]
    fn texture_sizes_whose_byte_count_overflows_are_rejected() {
        let quad = || {
            Node::Shape(Shape::Mesh {
                mesh: quad_mesh([0.0, 0.0, 1.0]),
                material: 0,
                smooth: false,
            })
        };
        // 65536 x 65536 x 3 wraps a u32 to 0 bytes: no texels "needed".
        for (width, height) in [(65_536, 65_536), (u32::MAX, 2), (3, 4)] {
            let mut s = scene(vec![quad()]);
            s.textures = vec![Texture {
                name: "t".into(),
                width,
                height,
                rgb: vec![],
            }];
            assert_eq!(
                compile(&s, &CompileOptions::default()).err(),
                Some(DmError::BadIndex {
                    what: "texture 0 ('t') has a bad size".into()
                }),
                "{width} x {height}"
            );
        }
    }

    #[test]
    fn degenerate_inputs_are_rejected() {
        let zero_scale = Transform {
            scale: [1.0, 0.0, 1.0],
            ..Transform::default()
        };
        let s = scene(vec![Node::Cluster(Cluster {
            name: "flat".into(),
            transform: zero_scale,
            children: vec![],
        })]);
        assert!(matches!(
            compile(&s, &CompileOptions::default()),
            Err(DmError::DegenerateTransform { .. })
        ));
        let stretch = Transform {
            scale: [1.0, 2.0, 1.0],
            ..Transform::default()
        };
        let blobs = Shape::Blobs {
            balls: vec![Ball {
                center: [0.0; 3],
                radius: 1.0,
                strength: 1.0,
            }],
            threshold: 0.5,
            kernel: BlobKernel::Links,
            material: 0,
        };
        let s = scene(vec![Node::Cluster(Cluster {
            name: "s".into(),
            transform: stretch,
            children: vec![Node::Shape(blobs)],
        })]);
        let e = compile(&s, &CompileOptions::default()).unwrap_err();
        assert_eq!(
            e,
            DmError::NonUniformBlobScale {
                cluster: "root/s".into()
            }
        );
        let mut s = scene(vec![]);
        s.camera.up = [0.0, 0.0, 1.0];
        assert!(matches!(
            compile(&s, &CompileOptions::default()),
            Err(DmError::DegenerateCamera(_))
        ));
        let s = scene(vec![]);
        let opts = CompileOptions {
            max_depth: Some(99),
            ..Default::default()
        };
        assert!(matches!(compile(&s, &opts), Err(DmError::BadSetting(_))));
    }

    /// Every number of a scene file fits f32, but a transform can carry one beyond it: the
    /// image would hold infinities (and f32 and f64 renders of it differ).
    #[test]
    fn values_beyond_f32_after_the_transforms_are_rejected() {
        let sphere = |center| {
            Node::Shape(Shape::Ellipsoid {
                center,
                radii: [1.0; 3],
                rotate_deg: [0.0; 3],
                cut: None,
                material: 0,
            })
        };
        // 3e38 is an f32; scaled by 10 it is not.
        let s = scene(vec![Node::Cluster(Cluster {
            name: "far".into(),
            transform: Transform {
                scale: [10.0; 3],
                ..Transform::default()
            },
            children: vec![sphere([0.0, 0.0, -3e38])],
        })]);
        assert_eq!(
            compile(&s, &CompileOptions::default()).unwrap_err(),
            DmError::BeyondF32 {
                section: Section::Ellipsoids.name(),
                record: 0
            }
        );
        // A point light 3e38 behind an eye at 3e38 is 6e38 away in view coordinates.
        let mut s = scene(vec![sphere([0.0; 3])]);
        s.camera.eye = [0.0, 0.0, 3e38];
        s.lights = vec![Light::Point {
            pos: [0.0, 0.0, -3e38],
            color: [1.0; 3],
            falloff: false,
        }];
        let e = compile(&s, &CompileOptions::default()).unwrap_err();
        assert_eq!(
            e,
            DmError::BeyondF32 {
                section: "lights",
                record: 0
            }
        );
        assert_eq!(
            e.to_string(),
            "lights record 0 holds a value beyond the f32 range (about ±3.4e38) after the \
             cluster and view transforms"
        );
        // The same scene nearer the origin compiles.
        s.camera.eye = [0.0, 0.0, 3e37];
        s.lights = vec![Light::Point {
            pos: [0.0, 0.0, -3e37],
            color: [1.0; 3],
            falloff: false,
        }];
        compile(&s, &CompileOptions::default()).unwrap();
    }
}
