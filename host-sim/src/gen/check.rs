//! Checks shared by the generators' tests: well-formed faces, watertight closed parts, no
//! slivers, and the OBJ round trip through the scene loader's OBJ reader.

use std::collections::HashMap;

use super::mesh::GenMesh;
use crate::vec3::{cross, dot, length, normalize, sub};

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

/// Reads OBJ text back with the scene loader's OBJ reader: (positions, normals, uvs,
/// triangles). The reader checks every index is in range.
pub fn parse_obj(text: &str) -> (usize, usize, usize, usize) {
    let m = crate::scene_file::obj::parse_obj(text, "test.obj", "test.obj")
        .unwrap_or_else(|e| panic!("the scene loader refuses the OBJ: {e}"));
    (
        m.positions.len(),
        m.normals.len(),
        m.uvs.len(),
        m.faces.len(),
    )
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

/// [`all`], and every part is a closed solid.
pub fn all_closed(m: &GenMesh) {
    all(m);
    assert!(m.parts.iter().all(|p| p.closed));
}

/// The bounds and size of a mesh that must rest on `y = 0`: `(min, max, max - min)`.
pub fn resting_bounds(m: &GenMesh) -> ([f64; 3], [f64; 3], [f64; 3]) {
    let (lo, hi) = m.bounds();
    assert_eq!(lo[1], 0.0, "rests on y = 0");
    (lo, hi, [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]])
}
