//! The DM's f64 linear algebra: 3x3 matrices, vectors and the affine maps that carry world
//! coordinates through the cluster tree into view coordinates.

pub(super) type M3 = [[f64; 3]; 3];

/// An affine map `p -> a p + t` in f64.
#[derive(Clone, Copy, Debug)]
pub(super) struct Affine {
    pub(super) a: M3,
    pub(super) t: [f64; 3],
}

pub(super) fn mat_mul(x: &M3, y: &M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| x[i][k] * y[k][j]).sum();
        }
    }
    r
}
pub(super) fn mat_vec(x: &M3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| x[i][0] * v[0] + x[i][1] * v[1] + x[i][2] * v[2])
}
pub(super) fn transpose(x: &M3) -> M3 {
    [0, 1, 2].map(|i| [x[0][i], x[1][i], x[2][i]])
}
pub(super) fn det(m: &M3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}
pub(super) fn inverse(m: &M3) -> Option<M3> {
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
pub(super) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(super) fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub(super) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(super) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub(super) fn normalize(a: [f64; 3]) -> Option<[f64; 3]> {
    let l = dot(a, a).sqrt();
    (l > 0.0 && l.is_finite()).then(|| a.map(|v| v / l))
}
pub(super) fn diag(s: [f64; 3]) -> M3 {
    [[s[0], 0.0, 0.0], [0.0, s[1], 0.0], [0.0, 0.0, s[2]]]
}

/// Rz · Ry · Rx for angles in degrees.
pub(super) fn rotation(deg: [f64; 3]) -> M3 {
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
    pub(super) fn from_trs(t: [f64; 3], rot_deg: [f64; 3], s: [f64; 3]) -> Self {
        Self {
            a: mat_mul(&rotation(rot_deg), &diag(s)),
            t,
        }
    }
    /// `self ∘ o` (apply `o` first).
    pub(super) fn then(&self, o: &Affine) -> Affine {
        Affine {
            a: mat_mul(&self.a, &o.a),
            t: add(mat_vec(&self.a, o.t), self.t),
        }
    }
    pub(super) fn point(&self, p: [f64; 3]) -> [f64; 3] {
        add(mat_vec(&self.a, p), self.t)
    }
    pub(super) fn is_finite(&self) -> bool {
        self.a
            .iter()
            .flatten()
            .chain(self.t.iter())
            .all(|v| v.is_finite())
    }
}

pub(super) fn f32s(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}
pub(super) fn mat_f32(m: &M3) -> [f32; 9] {
    [
        m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
    ]
    .map(|v| v as f32)
}
