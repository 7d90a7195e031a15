//! Tests of the mesh builder, the deterministic maths and the OBJ writer.

use std::f64::consts::TAU;

use super::check;
use super::mesh::*;
use super::polygon::signed_area2;
use super::trig::atan;
use crate::vec3::{cross, normalize, sub};

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
    let f = Basis::y_up([0.0; 3]);
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
        &Basis::new([5.0, 5.0, 5.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]),
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
    b.add_extruded_triangulation(&Basis::y_up([0.0; 3]), &pts, &tris, 0.0, 0.5);
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
