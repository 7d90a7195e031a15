//! [`MeshBuilder`]: accumulates a mesh part by part with solid-modelling helpers (boxes,
//! lofts, lathes, extrusions) and computes the per-corner normals (see the conventions in
//! [`super::mesh`]).

use std::collections::HashMap;

use super::basis::Basis;
use super::mesh::{FaceCorner, GenMesh, MeshPart};
use super::polygon::{octagon, signed_area2, triangulate_polygon};
use super::trig::{angle_between, sin_cos_turns};
use crate::vec3::{add, cross, dot, normalize, scale, sub};

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

    /// A loft: cross-section rings `(t, polygon)` along `basis.axis`, in increasing `t`,
    /// all with the same vertex count, joined by quads (2 triangles per ring edge per band),
    /// with caps at both ends. Rings may be given in either winding.
    /// Triangles: `(rings - 1) * 2 * m` plus the caps.
    pub fn add_loft(
        &mut self,
        basis: &Basis,
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
                .map(|c| self.vertex(basis.point(c[0], c[1], *t)))
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
            basis.point(a / ring.len() as f64, b / ring.len() as f64, t)
        };
        let (t0, r0) = &rings[0];
        let (t1, r1) = &rings[rings.len() - 1];
        let first = ids[0].clone();
        let last = ids[ids.len() - 1].clone();
        self.cap(&first, start, centroid(r0, *t0), false);
        self.cap(&last, end, centroid(r1, *t1), true);
    }

    /// A surface of revolution around `basis.axis`: `profile` points are `(radius, t)`; a
    /// radius of exactly 0 at either end is an apex (a fan). The profile may run either
    /// way; the solid is on the side that makes it closed with the axis. `phase` rotates the
    /// segment starting angle (in turns).
    /// Triangles: `segments` per profile edge touching the axis, `2 * segments` per other
    /// edge, plus the caps at ends off the axis.
    pub fn add_lathe(
        &mut self,
        basis: &Basis,
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
                ids.push(vec![self.vertex(basis.point(0.0, 0.0, t))]);
            } else {
                assert!(r > 0.0);
                ids.push(
                    trig.iter()
                        .map(|&(s, c)| self.vertex(basis.point(r * c, r * s, t)))
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
            self.cap(&first, start, basis.point(0.0, 0.0, prof[0][1]), false);
        }
        if last.len() > 1 {
            let k = prof.len() - 1;
            self.cap(&last, end, basis.point(0.0, 0.0, prof[k][1]), true);
        }
    }

    /// A cylinder or cone frustum along `basis.axis` from `t0` (radius `r0`) to `t1`
    /// (radius `r1`) with `segments` sides (smooth if the part's crease angle allows).
    /// Triangles: `2 * segments` for the side plus the caps.
    #[allow(clippy::too_many_arguments)]
    pub fn add_frustum(
        &mut self,
        basis: &Basis,
        r0: f64,
        r1: f64,
        t0: f64,
        t1: f64,
        segments: u32,
        cap0: Cap,
        cap1: Cap,
    ) {
        self.add_lathe(basis, &[[r0, t0], [r1, t1]], segments, 0.0, cap0, cap1);
    }

    /// An axis-aligned box: 12 triangles.
    pub fn add_box(&mut self, min: [f64; 3], max: [f64; 3]) {
        let f = Basis::y_up([0.0; 3]);
        let ring = vec![
            Basis::xz(min[0], min[2]),
            Basis::xz(max[0], min[2]),
            Basis::xz(max[0], max[2]),
            Basis::xz(min[0], max[2]),
        ];
        self.add_loft(
            &f,
            &[(min[1], ring.clone()), (max[1], ring)],
            Cap::Fan,
            Cap::Fan,
        );
    }

    /// A box between `t0` and `t1` along `basis.axis` with rectangular cross-section
    /// `[c1min, c1max] x [c2min, c2max]`: 12 triangles.
    pub fn add_basis_box(
        &mut self,
        basis: &Basis,
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
        self.add_loft(basis, &[(t0, ring.clone()), (t1, ring)], Cap::Fan, Cap::Fan);
    }

    /// A box `[min, max]` with every edge bevelled by `bevel` (and the vertical edges cut by
    /// `corner` in plan): 4 octagonal rings, 60 triangles.
    pub fn add_bevelled_box(&mut self, min: [f64; 3], max: [f64; 3], bevel: f64, corner: f64) {
        let f = Basis::y_up([0.0; 3]);
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

    /// A prism: the simple polygon `poly` (either winding) extruded along `basis.axis`
    /// from `t0` to `t1`. Triangles: `2 * (n - 2)` for the ends plus `2 * n` for the sides.
    pub fn add_extruded_polygon(&mut self, basis: &Basis, poly: &[[f64; 2]], t0: f64, t1: f64) {
        let tris = triangulate_polygon(poly);
        self.add_extruded_triangulation(basis, poly, &tris, t0, t1);
    }

    /// A slab: a planar region given as triangles over `pts` (counter-clockwise, any number
    /// of holes) extruded along `basis.axis` from `t0` to `t1`. Every boundary edge (an edge
    /// of exactly one triangle) becomes a side quad. Triangles: `2 * tris + 2 * edges`.
    pub fn add_extruded_triangulation(
        &mut self,
        basis: &Basis,
        pts: &[[f64; 2]],
        tris: &[[u32; 3]],
        t0: f64,
        t1: f64,
    ) {
        let lo: Vec<u32> = pts
            .iter()
            .map(|c| self.vertex(basis.point(c[0], c[1], t0)))
            .collect();
        let hi: Vec<u32> = pts
            .iter()
            .map(|c| self.vertex(basis.point(c[0], c[1], t1)))
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
