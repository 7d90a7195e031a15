//! 2-D polygons for the generators' cross-sections: signed area, ear-clipping triangulation,
//! and the octagon outline.

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
