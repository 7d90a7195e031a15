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

pub use super::basis::Basis;
pub use super::builder::{Cap, MeshBuilder};
pub use super::polygon::{octagon, triangulate_polygon};
pub use super::trig::sin_cos_turns;
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
