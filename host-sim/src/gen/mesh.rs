//! A small triangle-mesh type, a builder with solid-modelling helpers, and a Wavefront OBJ
//! writer, for the procedurally generated assets of the bundled scenes.
//!
//! Conventions:
//! - Triangles wind counter-clockwise seen from outside, so `(b - a) x (c - a)` points out of
//!   the solid. Every helper makes closed solids (unless a cap is [`Cap::Open`]) whose vertices
//!   are shared, so each edge of a closed part belongs to exactly two triangles.
//! - Normals are per face corner. Inside a part, a corner's normal averages (weighted by the
//!   corner angle) the face normals of the triangles around that vertex whose normal is within
//!   the part's crease angle of the face's own: curved surfaces shade smoothly, hard edges stay
//!   sharp (the OBJ shares the position and gives each side its own `vn`).
//! - All arithmetic is IEEE `+ - * / sqrt` only (the trigonometry below is a series, not the
//!   platform libm), and the OBJ prints fixed `{:.6}` decimals, so the output is the same byte
//!   for byte on every machine.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::ops::Range;

/// One corner of a face: position index, optional normal index, optional uv index (0-based).
pub type FaceCorner = (u32, Option<u32>, Option<u32>);

/// A triangle mesh ready to be written as OBJ.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GenMesh {
    pub positions: Vec<[f64; 3]>,
    pub normals: Vec<[f64; 3]>,
    pub uvs: Vec<[f64; 2]>,
    pub faces: Vec<[FaceCorner; 3]>,
    /// Named runs of `faces` (the camera's lens, the building's stair, ...).
    pub parts: Vec<MeshPart>,
}

/// A named, contiguous run of faces.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshPart {
    pub name: String,
    pub faces: Range<usize>,
    /// Whether the part is a closed surface (every edge shared by exactly two of its faces).
    pub closed: bool,
}

impl GenMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.faces.len()
    }

    /// Axis-aligned bounds of the positions used by faces: `(min, max)`.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for f in &self.faces {
            for c in f {
                let p = self.positions[c.0 as usize];
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        (lo, hi)
    }

    /// The three corner positions of face `i`.
    pub fn face_positions(&self, i: usize) -> [[f64; 3]; 3] {
        let f = &self.faces[i];
        [
            self.positions[f[0].0 as usize],
            self.positions[f[1].0 as usize],
            self.positions[f[2].0 as usize],
        ]
    }

    /// Wavefront OBJ text: the header (each line prefixed with `# `), then `v`, `vn`, `vt`
    /// and `f` records with 1-based indices (`f p/t/n`, `f p//n`, `f p/t` or `f p`). Parts
    /// are marked by comments only, so any OBJ reader accepts the file.
    pub fn to_obj(&self, header_comment: &str) -> String {
        let mut s = String::new();
        for line in header_comment.lines() {
            if line.is_empty() {
                s.push_str("#\n");
            } else {
                let _ = writeln!(s, "# {line}");
            }
        }
        let _ = writeln!(
            s,
            "# {} vertices, {} normals, {} uvs, {} triangles",
            self.positions.len(),
            self.normals.len(),
            self.uvs.len(),
            self.faces.len()
        );
        for p in &self.parts {
            let _ = writeln!(
                s,
                "#   {:<20} {:>4} triangles{}",
                p.name,
                p.faces.len(),
                if p.closed { " (closed)" } else { "" }
            );
        }
        for p in &self.positions {
            let _ = writeln!(s, "v {} {} {}", num(p[0]), num(p[1]), num(p[2]));
        }
        for n in &self.normals {
            let _ = writeln!(s, "vn {} {} {}", num(n[0]), num(n[1]), num(n[2]));
        }
        for t in &self.uvs {
            let _ = writeln!(s, "vt {} {}", num(t[0]), num(t[1]));
        }
        let mut part_at: HashMap<usize, &MeshPart> = HashMap::new();
        for p in &self.parts {
            part_at.insert(p.faces.start, p);
        }
        for (i, f) in self.faces.iter().enumerate() {
            if let Some(p) = part_at.get(&i) {
                // One OBJ group per part: the scene loader makes each a sub-cluster.
                let _ = writeln!(s, "g {}", p.name.replace(char::is_whitespace, "_"));
            }
            s.push('f');
            for &(p, n, t) in f {
                let _ = match (t, n) {
                    (Some(t), Some(n)) => write!(s, " {}/{}/{}", p + 1, t + 1, n + 1),
                    (None, Some(n)) => write!(s, " {}//{}", p + 1, n + 1),
                    (Some(t), None) => write!(s, " {}/{}", p + 1, t + 1),
                    (None, None) => write!(s, " {}", p + 1),
                };
            }
            s.push('\n');
        }
        s
    }
}

/// `{:.6}` without a negative zero.
fn num(x: f64) -> String {
    let s = format!("{x:.6}");
    if s == "-0.000000" {
        "0.000000".to_string()
    } else {
        s
    }
}

// ---------------------------------------------------------------------------------------------
// Deterministic small maths.

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub(crate) fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub(crate) fn length(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}
pub(crate) fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = length(a);
    if l > 0.0 {
        scale(a, 1.0 / l)
    } else {
        a
    }
}

const TAU: f64 = std::f64::consts::TAU;

/// `(sin, cos)` of `turns` whole turns (angle = 2π·turns), by a Taylor series on the reduced
/// angle so the result does not depend on the platform's libm. Quarter turns are exact.
pub fn sin_cos_turns(turns: f64) -> (f64, f64) {
    let q = turns * 4.0;
    if q == q.round() {
        return match (q.round() as i64).rem_euclid(4) {
            0 => (0.0, 1.0),
            1 => (1.0, 0.0),
            2 => (0.0, -1.0),
            _ => (-1.0, 0.0),
        };
    }
    // Reduce to [-1/2, 1/2) turn, then to |x| <= π.
    let t = turns - (turns + 0.5).floor();
    let x = t * TAU;
    let x2 = x * x;
    let (mut s, mut c) = (0.0, 0.0);
    let (mut ts, mut tc) = (x, 1.0);
    for k in 0..30 {
        s += ts;
        c += tc;
        let k2 = 2.0 * k as f64;
        ts *= -x2 / ((k2 + 2.0) * (k2 + 3.0));
        tc *= -x2 / ((k2 + 1.0) * (k2 + 2.0));
    }
    (s, c)
}

/// `atan(x)` for any `x`, deterministic (argument halving and a series).
fn atan(x: f64) -> f64 {
    if x < 0.0 {
        return -atan(-x);
    }
    if x > 1.0 {
        return std::f64::consts::FRAC_PI_2 - atan(1.0 / x);
    }
    // atan(x) = 2 atan(x / (1 + sqrt(1 + x²))), twice: |x| <= tan(π/16) ≈ 0.2.
    let mut y = x;
    for _ in 0..2 {
        y /= 1.0 + (1.0 + y * y).sqrt();
    }
    let y2 = y * y;
    let mut sum = 0.0;
    let mut term = y;
    for k in 0..30 {
        sum += term / (2 * k + 1) as f64;
        term *= -y2;
    }
    4.0 * sum
}

/// The angle between two vectors, deterministic and accurate for small angles.
fn angle_between(a: [f64; 3], b: [f64; 3]) -> f64 {
    let c = length(cross(a, b));
    let d = dot(a, b);
    if d > 0.0 {
        atan(c / d)
    } else if d < 0.0 {
        std::f64::consts::PI - atan(c / -d)
    } else {
        std::f64::consts::FRAC_PI_2
    }
}

/// Twice the signed area of a 2-D polygon (positive when counter-clockwise).
pub(crate) fn signed_area2(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let a = poly[i];
            let b = poly[(i + 1) % n];
            a[0] * b[1] - a[1] * b[0]
        })
        .sum()
}

/// Triangulates a simple polygon (either winding) by ear clipping. Returns index triples
/// wound counter-clockwise; a polygon of `n` vertices gives `n - 2` triangles.
pub fn triangulate_polygon(poly: &[[f64; 2]]) -> Vec<[u32; 3]> {
    let n = poly.len();
    assert!(n >= 3, "polygon needs at least 3 vertices");
    let mut idx: Vec<usize> = (0..n).collect();
    if signed_area2(poly) < 0.0 {
        idx.reverse();
    }
    let cross2 = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    // Tolerance for "on a line", relative to the polygon's size: corners flatter than this
    // are not ears, and a vertex this close to a candidate ear (e.g. on its new diagonal)
    // blocks it.
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in poly {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let eps = 1e-9 * ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2));
    let mut out = Vec::with_capacity(n - 2);
    while idx.len() > 3 {
        let m = idx.len();
        let mut clipped = false;
        for i in 0..m {
            let (ia, ib, ic) = (idx[(i + m - 1) % m], idx[i], idx[(i + 1) % m]);
            let (a, b, c) = (poly[ia], poly[ib], poly[ic]);
            if cross2(a, b, c) <= eps {
                continue; // reflex or flat corner
            }
            let inside = idx.iter().any(|&j| {
                let p = poly[j];
                if j == ia || j == ib || j == ic || p == a || p == b || p == c {
                    return false;
                }
                cross2(a, b, p) > -eps && cross2(b, c, p) > -eps && cross2(c, a, p) > -eps
            });
            if inside {
                continue;
            }
            out.push([ia as u32, ib as u32, ic as u32]);
            idx.remove(i);
            clipped = true;
            break;
        }
        assert!(clipped, "polygon is not simple");
    }
    out.push([idx[0] as u32, idx[1] as u32, idx[2] as u32]);
    out
}

// ---------------------------------------------------------------------------------------------
// The builder.

/// A local frame for the helpers: 2-D cross-section coordinates `(c1, c2)` along `u` and
/// `w`, and a distance `t` along `axis`. `u`, `w`, `axis` are orthonormal with
/// `u x w = axis`, so counter-clockwise in `(c1, c2)` is counter-clockwise seen from `+axis`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub origin: [f64; 3],
    pub u: [f64; 3],
    pub w: [f64; 3],
    pub axis: [f64; 3],
}

impl Frame {
    /// A frame at `origin` with the given axis; `u_hint` is made perpendicular to it.
    pub fn new(origin: [f64; 3], axis: [f64; 3], u_hint: [f64; 3]) -> Self {
        let axis = normalize(axis);
        let u = normalize(sub(u_hint, scale(axis, dot(u_hint, axis))));
        let w = cross(axis, u);
        Self { origin, u, w, axis }
    }

    /// Axis `+y` and `u = +x`, so `(c1, c2) = (x, -z)`; use [`Frame::xz`] to write rings in
    /// world `(x, z)`.
    pub fn y_up(origin: [f64; 3]) -> Self {
        Self::new(origin, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    }

    /// Cross-section coordinates of the world offset `(x, z)` in a [`Frame::y_up`] frame.
    pub fn xz(x: f64, z: f64) -> [f64; 2] {
        [x, -z]
    }

    /// The world point at cross-section `(c1, c2)` and height `t`.
    pub fn point(&self, c1: f64, c2: f64, t: f64) -> [f64; 3] {
        add(
            self.origin,
            add(
                scale(self.u, c1),
                add(scale(self.w, c2), scale(self.axis, t)),
            ),
        )
    }
}

/// How the open end of a loft or lathe is closed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cap {
    /// Left open (the part is then not closed).
    Open,
    /// A fan from a new centre vertex: `n` triangles for an `n`-gon.
    Center,
    /// A fan from the ring's first vertex (convex rings only): `n - 2` triangles.
    Fan,
}

struct Part {
    name: String,
    start: usize,
    closed: bool,
    crease_deg: f64,
}

/// Accumulates triangles part by part; [`MeshBuilder::finish`] computes the normals.
#[derive(Default)]
pub struct MeshBuilder {
    positions: Vec<[f64; 3]>,
    uvs: Vec<[f64; 2]>,
    tris: Vec<([u32; 3], Option<[u32; 3]>)>,
    parts: Vec<Part>,
}

impl MeshBuilder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Starts a new part; following triangles belong to it. Faces meeting at less than
    /// `crease_deg` degrees share smooth normals.
    pub fn begin_part(&mut self, name: &str, closed: bool, crease_deg: f64) {
        self.parts.push(Part {
            name: name.to_string(),
            start: self.tris.len(),
            closed,
            crease_deg,
        });
    }

    /// Triangles so far.
    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Adds a vertex position, returning its index.
    pub fn vertex(&mut self, p: [f64; 3]) -> u32 {
        self.positions.push(p);
        (self.positions.len() - 1) as u32
    }

    /// Adds a texture coordinate, returning its index.
    pub fn uv(&mut self, t: [f64; 2]) -> u32 {
        self.uvs.push(t);
        (self.uvs.len() - 1) as u32
    }

    /// Adds a triangle (counter-clockwise from outside).
    pub fn tri(&mut self, a: u32, b: u32, c: u32) {
        assert!(!self.parts.is_empty(), "begin_part first");
        self.tris.push(([a, b, c], None));
    }

    /// Adds a triangle with texture coordinates.
    pub fn tri_uv(&mut self, p: [u32; 3], t: [u32; 3]) {
        assert!(!self.parts.is_empty(), "begin_part first");
        self.tris.push((p, Some(t)));
    }

    /// Adds the quad `a b c d` (counter-clockwise from outside) as triangles `a b c`, `a c d`.
    pub fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.tri(a, b, c);
        self.tri(a, c, d);
    }

    /// Adds the quad `a b c d` with uvs `ta tb tc td`.
    pub fn quad_uv(&mut self, p: [u32; 4], t: [u32; 4]) {
        self.tri_uv([p[0], p[1], p[2]], [t[0], t[1], t[2]]);
        self.tri_uv([p[0], p[2], p[3]], [t[0], t[2], t[3]]);
    }

    /// Closes a ring of vertices (counter-clockwise seen from `+axis`) facing `+axis` when
    /// `forward`, else facing `-axis`.
    fn cap(&mut self, ring: &[u32], cap: Cap, centre: [f64; 3], forward: bool) {
        let n = ring.len();
        match cap {
            Cap::Open => {}
            Cap::Center => {
                let c = self.vertex(centre);
                for j in 0..n {
                    let (a, b) = (ring[j], ring[(j + 1) % n]);
                    if forward {
                        self.tri(c, a, b);
                    } else {
                        self.tri(c, b, a);
                    }
                }
            }
            Cap::Fan => {
                for j in 1..n - 1 {
                    let (a, b) = (ring[j], ring[j + 1]);
                    if forward {
                        self.tri(ring[0], a, b);
                    } else {
                        self.tri(ring[0], b, a);
                    }
                }
            }
        }
    }

    /// Connects consecutive rings (same length, counter-clockwise seen from `+axis`) with
    /// quads; rings of length 1 are apexes (fans).
    fn stitch(&mut self, rings: &[Vec<u32>]) {
        for pair in rings.windows(2) {
            let (r0, r1) = (&pair[0], &pair[1]);
            let n = r0.len().max(r1.len());
            for j in 0..n {
                let k = (j + 1) % n;
                match (r0.len(), r1.len()) {
                    (1, _) => self.tri(r0[0], r1[k], r1[j]),
                    (_, 1) => self.tri(r0[j], r0[k], r1[0]),
                    _ => self.quad(r0[j], r0[k], r1[k], r1[j]),
                }
            }
        }
    }

    /// A loft: cross-section rings `(t, polygon)` along `frame.axis`, in increasing `t`,
    /// all with the same vertex count, joined by quads (2 triangles per ring edge per band),
    /// with caps at both ends. Rings may be given in either winding.
    /// Triangles: `(rings - 1) * 2 * m` plus the caps.
    pub fn add_loft(
        &mut self,
        frame: &Frame,
        rings: &[(f64, Vec<[f64; 2]>)],
        start: Cap,
        end: Cap,
    ) {
        assert!(rings.len() >= 2);
        let m = rings[0].1.len();
        let flip = signed_area2(&rings[0].1) < 0.0;
        let mut ids: Vec<Vec<u32>> = Vec::new();
        for (t, ring) in rings {
            assert_eq!(ring.len(), m, "loft rings differ in size");
            let mut r: Vec<u32> = ring
                .iter()
                .map(|c| self.vertex(frame.point(c[0], c[1], *t)))
                .collect();
            if flip {
                r.reverse();
            }
            ids.push(r);
        }
        self.stitch(&ids);
        let centroid = |ring: &[[f64; 2]], t: f64| {
            let (mut a, mut b) = (0.0, 0.0);
            for c in ring {
                a += c[0];
                b += c[1];
            }
            frame.point(a / ring.len() as f64, b / ring.len() as f64, t)
        };
        let (t0, r0) = &rings[0];
        let (t1, r1) = &rings[rings.len() - 1];
        let first = ids[0].clone();
        let last = ids[ids.len() - 1].clone();
        self.cap(&first, start, centroid(r0, *t0), false);
        self.cap(&last, end, centroid(r1, *t1), true);
    }

    /// A surface of revolution around `frame.axis`: `profile` points are `(radius, t)`; a
    /// radius of exactly 0 at either end is an apex (a fan). The profile may run either
    /// way; the solid is on the side that makes it closed with the axis. `phase` rotates the
    /// segment starting angle (in turns).
    /// Triangles: `segments` per profile edge touching the axis, `2 * segments` per other
    /// edge, plus the caps at ends off the axis.
    pub fn add_lathe(
        &mut self,
        frame: &Frame,
        profile: &[[f64; 2]],
        segments: u32,
        phase: f64,
        start: Cap,
        end: Cap,
    ) {
        assert!(profile.len() >= 2 && segments >= 3);
        // Orient: the (r, t) polygon closed along the axis must be counter-clockwise.
        let mut closed_poly: Vec<[f64; 2]> = Vec::new();
        closed_poly.push([0.0, profile[0][1]]);
        closed_poly.extend_from_slice(profile);
        closed_poly.push([0.0, profile[profile.len() - 1][1]]);
        let mut prof: Vec<[f64; 2]> = profile.to_vec();
        let (mut start, mut end) = (start, end);
        if signed_area2(&closed_poly) < 0.0 {
            prof.reverse();
            std::mem::swap(&mut start, &mut end);
        }
        let n = segments as usize;
        let trig: Vec<(f64, f64)> = (0..n)
            .map(|j| sin_cos_turns(phase + j as f64 / n as f64))
            .collect();
        let mut ids: Vec<Vec<u32>> = Vec::new();
        for (i, &[r, t]) in prof.iter().enumerate() {
            if r == 0.0 {
                assert!(i == 0 || i == prof.len() - 1, "apex inside a lathe profile");
                ids.push(vec![self.vertex(frame.point(0.0, 0.0, t))]);
            } else {
                assert!(r > 0.0);
                ids.push(
                    trig.iter()
                        .map(|&(s, c)| self.vertex(frame.point(r * c, r * s, t)))
                        .collect(),
                );
            }
        }
        self.stitch(&ids);
        let first = ids[0].clone();
        let last = ids[ids.len() - 1].clone();
        // With the (r, t) outline counter-clockwise, the first ring's cap always faces -t
        // and the last ring's faces +t.
        if first.len() > 1 {
            self.cap(&first, start, frame.point(0.0, 0.0, prof[0][1]), false);
        }
        if last.len() > 1 {
            let k = prof.len() - 1;
            self.cap(&last, end, frame.point(0.0, 0.0, prof[k][1]), true);
        }
    }

    /// A cylinder or cone frustum along `frame.axis` from `t0` (radius `r0`) to `t1`
    /// (radius `r1`) with `segments` sides (smooth if the part's crease angle allows).
    /// Triangles: `2 * segments` for the side plus the caps.
    #[allow(clippy::too_many_arguments)]
    pub fn add_frustum(
        &mut self,
        frame: &Frame,
        r0: f64,
        r1: f64,
        t0: f64,
        t1: f64,
        segments: u32,
        cap0: Cap,
        cap1: Cap,
    ) {
        self.add_lathe(frame, &[[r0, t0], [r1, t1]], segments, 0.0, cap0, cap1);
    }

    /// An axis-aligned box: 12 triangles.
    pub fn add_box(&mut self, min: [f64; 3], max: [f64; 3]) {
        let f = Frame::y_up([0.0; 3]);
        let ring = vec![
            Frame::xz(min[0], min[2]),
            Frame::xz(max[0], min[2]),
            Frame::xz(max[0], max[2]),
            Frame::xz(min[0], max[2]),
        ];
        self.add_loft(
            &f,
            &[(min[1], ring.clone()), (max[1], ring)],
            Cap::Fan,
            Cap::Fan,
        );
    }

    /// A box between `t0` and `t1` along `frame.axis` with rectangular cross-section
    /// `[c1min, c1max] x [c2min, c2max]`: 12 triangles.
    pub fn add_frame_box(
        &mut self,
        frame: &Frame,
        c_min: [f64; 2],
        c_max: [f64; 2],
        t0: f64,
        t1: f64,
    ) {
        let ring = vec![
            [c_min[0], c_min[1]],
            [c_max[0], c_min[1]],
            [c_max[0], c_max[1]],
            [c_min[0], c_max[1]],
        ];
        self.add_loft(frame, &[(t0, ring.clone()), (t1, ring)], Cap::Fan, Cap::Fan);
    }

    /// A box `[min, max]` with every edge bevelled by `bevel` (and the vertical edges cut by
    /// `corner` in plan): 4 octagonal rings, 60 triangles.
    pub fn add_bevelled_box(&mut self, min: [f64; 3], max: [f64; 3], bevel: f64, corner: f64) {
        let f = Frame::y_up([0.0; 3]);
        let c = [(min[0] + max[0]) / 2.0, (min[2] + max[2]) / 2.0];
        let h = [(max[0] - min[0]) / 2.0, (max[2] - min[2]) / 2.0];
        let outer = octagon(c, h, corner);
        let inner = octagon(c, [h[0] - bevel, h[1] - bevel], corner * 0.6);
        self.add_loft(
            &f,
            &[
                (min[1], inner.clone()),
                (min[1] + bevel, outer.clone()),
                (max[1] - bevel, outer),
                (max[1], inner),
            ],
            Cap::Fan,
            Cap::Fan,
        );
    }

    /// A prism: the simple polygon `poly` (either winding) extruded along `frame.axis`
    /// from `t0` to `t1`. Triangles: `2 * (n - 2)` for the ends plus `2 * n` for the sides.
    pub fn add_extruded_polygon(&mut self, frame: &Frame, poly: &[[f64; 2]], t0: f64, t1: f64) {
        let tris = triangulate_polygon(poly);
        self.add_extruded_triangulation(frame, poly, &tris, t0, t1);
    }

    /// A slab: a planar region given as triangles over `pts` (counter-clockwise, any number
    /// of holes) extruded along `frame.axis` from `t0` to `t1`. Every boundary edge (an edge
    /// of exactly one triangle) becomes a side quad. Triangles: `2 * tris + 2 * edges`.
    pub fn add_extruded_triangulation(
        &mut self,
        frame: &Frame,
        pts: &[[f64; 2]],
        tris: &[[u32; 3]],
        t0: f64,
        t1: f64,
    ) {
        let lo: Vec<u32> = pts
            .iter()
            .map(|c| self.vertex(frame.point(c[0], c[1], t0)))
            .collect();
        let hi: Vec<u32> = pts
            .iter()
            .map(|c| self.vertex(frame.point(c[0], c[1], t1)))
            .collect();
        for t in tris {
            let [a, b, c] = t.map(|i| i as usize);
            self.tri(hi[a], hi[b], hi[c]);
            self.tri(lo[a], lo[c], lo[b]);
        }
        // Boundary edges, in the order the triangles list them.
        let mut count: HashMap<(u32, u32), usize> = HashMap::new();
        for t in tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        for t in tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if count[&(a.min(b), a.max(b))] == 1 {
                    let (a, b) = (a as usize, b as usize);
                    self.quad(lo[a], lo[b], hi[b], hi[a]);
                }
            }
        }
    }

    /// Finishes the mesh: computes per-corner normals part by part (see the module docs),
    /// shares identical normals, and returns the [`GenMesh`].
    pub fn finish(self) -> GenMesh {
        let face_normal = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|i| self.positions[i as usize]);
            normalize(cross(sub(b, a), sub(c, a)))
        };
        let normals_f: Vec<[f64; 3]> = self.tris.iter().map(|(t, _)| face_normal(t)).collect();
        let corner_angle = |t: &[u32; 3], k: usize| {
            let p = self.positions[t[k] as usize];
            let a = self.positions[t[(k + 1) % 3] as usize];
            let b = self.positions[t[(k + 2) % 3] as usize];
            angle_between(sub(a, p), sub(b, p))
        };
        let mut normals: Vec<[f64; 3]> = Vec::new();
        let mut normal_ids: HashMap<[i64; 3], u32> = HashMap::new();
        let mut faces: Vec<[FaceCorner; 3]> = Vec::with_capacity(self.tris.len());
        let mut parts = Vec::new();
        for (pi, part) in self.parts.iter().enumerate() {
            let end = self.parts.get(pi + 1).map_or(self.tris.len(), |p| p.start);
            let cos_crease = sin_cos_turns(part.crease_deg / 360.0).1;
            let mut around: HashMap<u32, Vec<usize>> = HashMap::new();
            for f in part.start..end {
                for &v in &self.tris[f].0 {
                    around.entry(v).or_default().push(f);
                }
            }
            for f in part.start..end {
                let (t, uv) = &self.tris[f];
                let nf = normals_f[f];
                let mut corners = [(0u32, None, None); 3];
                for k in 0..3 {
                    let mut sum = [0.0; 3];
                    for &g in &around[&t[k]] {
                        let ng = normals_f[g];
                        if g == f || dot(nf, ng) >= cos_crease {
                            let tg = &self.tris[g].0;
                            let kg = tg.iter().position(|&v| v == t[k]).unwrap();
                            sum = add(sum, scale(ng, corner_angle(tg, kg)));
                        }
                    }
                    let n = normalize(sum);
                    let key = n.map(|x| {
                        let r = (x * 1e6).round() as i64;
                        if r == 0 {
                            0
                        } else {
                            r
                        }
                    });
                    let id = *normal_ids.entry(key).or_insert_with(|| {
                        normals.push(n);
                        (normals.len() - 1) as u32
                    });
                    corners[k] = (t[k], Some(id), uv.map(|u| u[k]));
                }
                faces.push(corners);
            }
            parts.push(MeshPart {
                name: part.name.clone(),
                faces: part.start..end,
                closed: part.closed,
            });
        }
        GenMesh {
            positions: self.positions,
            normals,
            uvs: self.uvs,
            faces,
            parts,
        }
    }
}

/// An octagon: the rectangle centred at `c` with half-extents `h`, corners cut by `k`.
pub fn octagon(c: [f64; 2], h: [f64; 2], k: f64) -> Vec<[f64; 2]> {
    let (x0, x1, y0, y1) = (c[0] - h[0], c[0] + h[0], c[1] - h[1], c[1] + h[1]);
    vec![
        [x0 + k, y0],
        [x1 - k, y0],
        [x1, y0 + k],
        [x1, y1 - k],
        [x1 - k, y1],
        [x0 + k, y1],
        [x0, y1 - k],
        [x0, y0 + k],
    ]
}

// ---------------------------------------------------------------------------------------------
// Checks shared by the generators' tests.

#[cfg(test)]
pub(crate) mod check {
    use super::*;

    /// Every face has area > 1e-9 and in-range indices; every normal is unit length.
    pub fn well_formed(m: &GenMesh) {
        for (i, f) in m.faces.iter().enumerate() {
            for c in f {
                assert!(
                    (c.0 as usize) < m.positions.len(),
                    "face {i}: position index"
                );
                if let Some(n) = c.1 {
                    assert!((n as usize) < m.normals.len(), "face {i}: normal index");
                }
                if let Some(t) = c.2 {
                    assert!((t as usize) < m.uvs.len(), "face {i}: uv index");
                }
            }
            let [a, b, c] = m.face_positions(i);
            let area = length(cross(sub(b, a), sub(c, a))) / 2.0;
            assert!(area > 1e-9, "face {i} is degenerate (area {area})");
        }
        for (i, n) in m.normals.iter().enumerate() {
            assert!(
                (length(*n) - 1.0).abs() < 1e-6,
                "normal {i} is not unit: {n:?}"
            );
        }
        // The parts tile the faces.
        let mut next = 0;
        for p in &m.parts {
            assert_eq!(p.faces.start, next, "parts must be contiguous");
            next = p.faces.end;
        }
        assert_eq!(next, m.faces.len());
    }

    /// Each closed part: every directed edge appears once and its reverse once (so every
    /// edge is shared by exactly two faces, consistently wound), and the enclosed volume is
    /// positive (faces point outwards). Also: each corner normal faces the same way as its
    /// face.
    pub fn closed_parts_watertight(m: &GenMesh) {
        for p in &m.parts {
            for f in p.faces.clone() {
                let [a, b, c] = m.face_positions(f);
                let nf = normalize(cross(sub(b, a), sub(c, a)));
                for corner in &m.faces[f] {
                    if let Some(n) = corner.1 {
                        assert!(
                            dot(nf, m.normals[n as usize]) > 0.0,
                            "part {}: face {f} has a corner normal facing inwards",
                            p.name
                        );
                    }
                }
            }
            if !p.closed {
                continue;
            }
            let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
            let mut volume = 0.0;
            for f in p.faces.clone() {
                let t = m.faces[f];
                for k in 0..3 {
                    *directed.entry((t[k].0, t[(k + 1) % 3].0)).or_default() += 1;
                }
                let [a, b, c] = m.face_positions(f);
                volume += dot(a, cross(b, c)) / 6.0;
            }
            for (&(a, b), &n) in &directed {
                assert_eq!(n, 1, "part {}: edge {a}->{b} used {n} times", p.name);
                assert_eq!(
                    directed.get(&(b, a)),
                    Some(&1),
                    "part {}: edge {a}-{b} is not shared by two faces",
                    p.name
                );
            }
            assert!(volume > 0.0, "part {}: negative volume {volume}", p.name);
        }
    }

    /// Parses OBJ text back: (positions, normals, uvs, triangles); checks each `f` has three
    /// in-range corners.
    pub fn parse_obj(text: &str) -> (usize, usize, usize, usize) {
        let (mut v, mut vn, mut vt, mut f) = (0, 0, 0, 0);
        for line in text.lines() {
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => {
                    assert_eq!(it.clone().count(), 3, "{line}");
                    for x in it {
                        x.parse::<f64>().unwrap();
                    }
                    v += 1;
                }
                Some("vn") => {
                    assert_eq!(it.clone().count(), 3, "{line}");
                    vn += 1;
                }
                Some("vt") => {
                    assert_eq!(it.clone().count(), 2, "{line}");
                    vt += 1;
                }
                Some("f") => {
                    let corners: Vec<&str> = it.collect();
                    assert_eq!(corners.len(), 3, "{line}");
                    for c in corners {
                        let mut parts = c.split('/');
                        let p: usize = parts.next().unwrap().parse().unwrap();
                        assert!(p >= 1 && p <= v, "{line}");
                        if let Some(t) = parts.next().filter(|s| !s.is_empty()) {
                            let t: usize = t.parse().unwrap();
                            assert!(t >= 1 && t <= vt, "{line}");
                        }
                        if let Some(n) = parts.next() {
                            let n: usize = n.parse().unwrap();
                            assert!(n >= 1 && n <= vn, "{line}");
                        }
                    }
                    f += 1;
                }
                Some(x) if x.starts_with('#') => {}
                Some("g") => assert_eq!(it.count(), 1, "{line}"),
                None => {}
                Some(other) => panic!("unexpected OBJ record {other:?}"),
            }
        }
        (v, vn, vt, f)
    }

    /// Everything above plus the OBJ round trip.
    /// No sliver triangles, even after the OBJ's rounding to 6 decimals: twice the area over
    /// the longest edge squared (about the smallest angle, in radians) stays above 1e-3, far
    /// from the scene loader's 1e-12 "degenerate" cut-off.
    pub fn no_slivers(m: &GenMesh) {
        let round = |p: [f64; 3]| p.map(|x| (x * 1e6).round() / 1e6);
        for i in 0..m.faces.len() {
            let [a, b, c] = m.face_positions(i).map(round);
            let area2 = length(cross(sub(b, a), sub(c, a)));
            let longest = length(sub(b, a))
                .max(length(sub(c, a)))
                .max(length(sub(c, b)));
            let shape = area2 / (longest * longest);
            assert!(shape > 1e-3, "face {i} is a sliver ({shape})");
        }
    }

    pub fn all(m: &GenMesh) {
        well_formed(m);
        no_slivers(m);
        closed_parts_watertight(m);
        let (v, vn, vt, f) = parse_obj(&m.to_obj("test"));
        assert_eq!(
            (v, vn, vt, f),
            (
                m.positions.len(),
                m.normals.len(),
                m.uvs.len(),
                m.faces.len()
            )
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trig_and_atan_match_std() {
        for i in -40..=40 {
            let t = i as f64 / 17.0;
            let (s, c) = sin_cos_turns(t);
            assert!((s - (t * TAU).sin()).abs() < 1e-14, "sin {t}");
            assert!((c - (t * TAU).cos()).abs() < 1e-14, "cos {t}");
            let x = i as f64 / 7.0;
            assert!((atan(x) - x.atan()).abs() < 1e-14, "atan {x}");
        }
        assert_eq!(sin_cos_turns(0.75), (-1.0, 0.0));
    }

    #[test]
    fn helper_triangle_counts() {
        let f = Frame::y_up([0.0; 3]);
        let mut b = MeshBuilder::new();
        b.begin_part("box", true, 30.0);
        b.add_box([0.0; 3], [1.0, 2.0, 3.0]);
        assert_eq!(b.triangle_count(), 12);
        b.begin_part("bevelled", true, 30.0);
        b.add_bevelled_box([2.0, 0.0, 0.0], [5.0, 2.0, 3.0], 0.2, 0.3);
        assert_eq!(b.triangle_count(), 12 + 60);
        b.begin_part("cylinder", true, 40.0);
        b.add_frustum(&f, 1.0, 1.0, 0.0, 2.0, 12, Cap::Center, Cap::Fan);
        assert_eq!(b.triangle_count(), 72 + 24 + 12 + 10);
        b.begin_part("cone", true, 40.0);
        b.add_lathe(
            &f,
            &[[0.0, 3.0], [1.0, 3.0], [0.0, 5.0]],
            8,
            0.0,
            Cap::Open,
            Cap::Open,
        );
        assert_eq!(b.triangle_count(), 118 + 16);
        b.begin_part("reversed lathe", true, 40.0);
        b.add_lathe(
            &Frame::new([5.0, 5.0, 5.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]),
            &[[0.0, 2.0], [1.0, 2.0], [1.0, 0.5], [0.5, 0.0]],
            10,
            0.25,
            Cap::Open,
            Cap::Center,
        );
        assert_eq!(b.triangle_count(), 134 + 10 + 20 + 20 + 10);
        b.begin_part("L prism", true, 30.0);
        let l = [
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 1.0],
            [1.0, 1.0],
            [1.0, 3.0],
            [0.0, 3.0],
        ];
        b.add_extruded_polygon(&f, &l, 6.0, 7.0);
        assert_eq!(b.triangle_count(), 194 + 4 * 6 - 4);
        b.begin_part("open tube", false, 40.0);
        b.add_frustum(&f, 2.0, 1.0, 8.0, 9.0, 6, Cap::Open, Cap::Open);
        let m = b.finish();
        check::all(&m);
        // Smooth sides: a cylinder's side normals are radial (no y component).
        let cyl = &m.parts[2];
        for fi in cyl.faces.clone() {
            let [a, b, c] = m.face_positions(fi);
            let nf = normalize(cross(sub(b, a), sub(c, a)));
            if nf[1].abs() < 1e-9 {
                for corner in &m.faces[fi] {
                    let n = m.normals[corner.1.unwrap() as usize];
                    let p = m.positions[corner.0 as usize];
                    assert!(n[1].abs() < 1e-9);
                    assert!((n[0] * p[2] - n[2] * p[0]).abs() < 1e-9, "not radial");
                }
            }
        }
    }

    #[test]
    fn slab_with_a_hole() {
        // A square with a square hole, hand-triangulated: 8 triangles, 8 boundary edges.
        let pts = [
            [0.0, 0.0],
            [3.0, 0.0],
            [3.0, 3.0],
            [0.0, 3.0],
            [1.0, 1.0],
            [2.0, 1.0],
            [2.0, 2.0],
            [1.0, 2.0],
        ];
        let tris = [
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7],
        ];
        let mut b = MeshBuilder::new();
        b.begin_part("frame", true, 30.0);
        b.add_extruded_triangulation(&Frame::y_up([0.0; 3]), &pts, &tris, 0.0, 0.5);
        let m = b.finish();
        assert_eq!(m.triangle_count(), 32);
        check::all(&m);
    }

    #[test]
    fn obj_format() {
        let mut b = MeshBuilder::new();
        b.begin_part("quad", false, 30.0);
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ]
        .map(|q| b.vertex(q));
        let t = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]].map(|q| b.uv(q));
        b.quad_uv(p, t);
        b.begin_part("tri", false, 30.0);
        let q = [[0.0, 0.0, -0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]].map(|q| b.vertex(q));
        b.tri(q[0], q[1], q[2]);
        let m = b.finish();
        let obj = m.to_obj("hello\n\nworld");
        let expected = "# hello\n#\n# world\n\
            # 7 vertices, 2 normals, 4 uvs, 3 triangles\n\
            #   quad                    2 triangles\n\
            #   tri                     1 triangles\n\
            v 0.000000 0.000000 0.000000\n\
            v 1.000000 0.000000 0.000000\n\
            v 1.000000 1.000000 0.000000\n\
            v 0.000000 1.000000 0.000000\n\
            v 0.000000 0.000000 0.000000\n\
            v 0.000000 0.000000 1.000000\n\
            v 0.000000 1.000000 0.000000\n\
            vn 0.000000 0.000000 1.000000\n\
            vn -1.000000 0.000000 0.000000\n\
            vt 0.000000 0.000000\n\
            vt 1.000000 0.000000\n\
            vt 1.000000 1.000000\n\
            vt 0.000000 1.000000\n\
            g quad\n\
            f 1/1/1 2/2/1 3/3/1\n\
            f 1/1/1 3/3/1 4/4/1\n\
            g tri\n\
            f 5//2 6//2 7//2\n";
        assert_eq!(obj, expected);
        assert_eq!(check::parse_obj(&obj), (7, 2, 4, 3));
    }

    #[test]
    fn ear_clipping() {
        let comb = [
            [0.0, 0.0],
            [5.0, 0.0],
            [5.0, 2.0],
            [4.0, 1.0],
            [3.0, 2.0],
            [2.0, 1.0],
            [1.0, 2.0],
            [0.0, 1.0],
        ];
        let mut rev = comb;
        rev.reverse();
        // A stair section: the step noses are collinear, and so are the inner corners and
        // the bottom corner (with rounding noise), which trips naive ear clipping.
        let mut stair = vec![[-3.0 - 6.0 * 1.6, 0.8]];
        for i in 0..6 {
            let y = 0.8 + (i + 1) as f64 * (6.8 - 0.8) / 6.0;
            stair.push([-3.0 - (6 - i) as f64 * 1.6, y]);
            stair.push([-3.0 - (5 - i) as f64 * 1.6, y]);
        }
        stair.push([-3.0, 4.6]);
        for poly in [&comb[..], &rev[..], &stair[..]] {
            let tris = triangulate_polygon(poly);
            assert_eq!(tris.len(), poly.len() - 2);
            let mut area = 0.0;
            for t in &tris {
                let [a, b, c] = t.map(|i| poly[i as usize]);
                let a2 = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
                assert!(a2 > 1e-9, "degenerate ear {t:?}");
                area += a2;
            }
            assert!((area - signed_area2(poly).abs()).abs() < 1e-12);
        }
    }
}
