//! glTF node transforms -> [`Transform`] (`p' = T · Rz · Ry · Rx · S · p`, Euler angles in
//! degrees about X, then Y, then Z), and the 4x4 matrices used for world positions.

use links_core::anim::quat::{euler_deg_of_matrix, Quat};
use links_core::desc::Transform;

/// A glTF matrix: column-major, `m[col][row]`.
pub type Mat4 = [[f64; 4]; 4];

/// A 3x3 rotation, row-major: `r[row][col]`.
pub type Mat3 = [[f64; 3]; 3];

pub const IDENTITY: Mat4 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// How far from orthogonal a decomposed rotation may be before it counts as shear.
const SHEAR_EPS: f64 = 1e-4;

pub fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for (c, col) in m.iter_mut().enumerate() {
        for (r, v) in col.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

pub fn apply_point(m: &Mat4, p: [f64; 3]) -> [f64; 3] {
    core::array::from_fn(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
}

pub fn apply_dir(m: &Mat4, d: [f64; 3]) -> [f64; 3] {
    core::array::from_fn(|r| m[0][r] * d[0] + m[1][r] * d[1] + m[2][r] * d[2])
}

pub fn from_f32(m: [[f32; 4]; 4]) -> Mat4 {
    m.map(|c| c.map(f64::from))
}

/// The rotation of a unit quaternion `[x, y, z, w]` (glTF order); normalised first (a zero
/// quaternion is the identity).
pub fn quat_to_matrix(q: [f64; 4]) -> Mat3 {
    Quat {
        w: q[3],
        x: q[0],
        y: q[1],
        z: q[2],
    }
    .normalized()
    .matrix()
}

/// `Rz(γ) · Ry(β) · Rx(α)` for `[α, β, γ]` in degrees: the rotation a [`Transform`] means.
pub fn euler_deg_to_matrix(e: [f64; 3]) -> Mat3 {
    let [a, b, g] = e.map(f64::to_radians);
    let (sa, ca) = a.sin_cos();
    let (sb, cb) = b.sin_cos();
    let (sg, cg) = g.sin_cos();
    [
        [cg * cb, cg * sb * sa - sg * ca, cg * sb * ca + sg * sa],
        [sg * cb, sg * sb * sa + cg * ca, sg * sb * ca - cg * sa],
        [-sb, cb * sa, cb * ca],
    ]
}

/// The Euler angles `[α, β, γ]` (degrees, X then Y then Z) of a rotation matrix (the
/// films' own conversion, [`euler_deg_of_matrix`]).
pub fn matrix_to_euler_deg(r: &Mat3) -> [f64; 3] {
    euler_deg_of_matrix(r)
}

/// A TRS node's transform.
pub fn from_trs(t: [f32; 3], q: [f32; 4], s: [f32; 3]) -> Transform {
    Transform {
        translate: t.map(f64::from),
        rotate_deg: matrix_to_euler_deg(&quat_to_matrix(q.map(f64::from))),
        scale: s.map(f64::from),
    }
}

/// A matrix node's transform, and whether the matrix had shear or projection (then the
/// rotation is the decomposed columns' nearest fit and the caller warns).
pub fn decompose(m: &Mat4) -> (Transform, bool) {
    let cols: [[f64; 3]; 3] = core::array::from_fn(|c| [m[c][0], m[c][1], m[c][2]]);
    let mut scale = cols.map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt());
    if det3(&cols) < 0.0 {
        scale[0] = -scale[0];
    }
    let unit: [[f64; 3]; 3] = core::array::from_fn(|c| {
        let s = if scale[c] != 0.0 { scale[c] } else { 1.0 };
        cols[c].map(|v| v / s)
    });
    let r: Mat3 = core::array::from_fn(|row| core::array::from_fn(|col| unit[col][row]));
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let skew = [(0, 1), (0, 2), (1, 2)]
        .iter()
        .any(|&(i, j)| dot(unit[i], unit[j]).abs() > SHEAR_EPS);
    let projective = m[0][3] != 0.0 || m[1][3] != 0.0 || m[2][3] != 0.0 || m[3][3] != 1.0;
    let t = Transform {
        translate: [m[3][0], m[3][1], m[3][2]],
        rotate_deg: matrix_to_euler_deg(&r),
        scale,
    };
    (t, skew || projective)
}

fn det3(c: &[[f64; 3]; 3]) -> f64 {
    c[0][0] * (c[1][1] * c[2][2] - c[2][1] * c[1][2])
        - c[1][0] * (c[0][1] * c[2][2] - c[2][1] * c[0][2])
        + c[2][0] * (c[0][1] * c[1][2] - c[1][1] * c[0][2])
}

/// The matrix a [`Transform`] stands for (`T · Rz · Ry · Rx · S`), column-major.
pub fn transform_matrix(t: &Transform) -> Mat4 {
    let r = euler_deg_to_matrix(t.rotate_deg);
    let mut m = IDENTITY;
    for c in 0..3 {
        for row in 0..3 {
            m[c][row] = r[row][c] * t.scale[c];
        }
    }
    m[3] = [t.translate[0], t.translate[1], t.translate[2], 1.0];
    m
}
