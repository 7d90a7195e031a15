//! Unit quaternions for rotation tracks: from and to the scene format's Euler angles
//! (degrees about X, then Y, then Z: `R = Rz · Ry · Rx`), and spherical interpolation.

/// A quaternion `w + xi + yj + zk`; rotation tracks keep it at unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quat {
    pub w: f64,
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Quat {
    pub fn dot(self, o: Quat) -> f64 {
        self.w * o.w + self.x * o.x + self.y * o.y + self.z * o.z
    }

    pub fn norm(self) -> f64 {
        self.dot(self).sqrt()
    }

    fn scaled(self, s: f64) -> Quat {
        Quat {
            w: self.w * s,
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }

    fn plus(self, o: Quat) -> Quat {
        Quat {
            w: self.w + o.w,
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }

    /// `self / |self|` (the identity for a zero quaternion, which no track produces).
    pub fn normalized(self) -> Quat {
        let n = self.norm();
        if n > 0.0 && n.is_finite() {
            self.scaled(1.0 / n)
        } else {
            Quat::IDENTITY
        }
    }

    pub const IDENTITY: Quat = Quat {
        w: 1.0,
        x: 0.0,
        y: 0.0,
        z: 0.0,
    };

    /// The rotation `Rz · Ry · Rx` of the scene format, angles in degrees.
    pub fn from_euler_deg(deg: [f64; 3]) -> Quat {
        let half = deg.map(|d| d.to_radians() * 0.5);
        let axis = |i: usize| {
            let (s, c) = half[i].sin_cos();
            let mut v = [0.0; 3];
            v[i] = s;
            Quat {
                w: c,
                x: v[0],
                y: v[1],
                z: v[2],
            }
        };
        axis(2) * axis(1) * axis(0)
    }

    /// The rotation matrix of a unit quaternion (rows).
    pub fn matrix(self) -> [[f64; 3]; 3] {
        let Quat { w, x, y, z } = self;
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// Euler angles in degrees `(x, y, z)` with `Rz · Ry · Rx` = this rotation; y in
    /// [-90, 90]. At y = ±90 (gimbal lock) the z angle is taken as 0.
    pub fn to_euler_deg(self) -> [f64; 3] {
        euler_deg_of_matrix(&self.normalized().matrix())
    }

    /// Spherical linear interpolation along the shorter arc from `a` (s = 0) to `b` (s = 1);
    /// `s` outside [0, 1] continues along the same great circle. Unit in, unit out.
    pub fn slerp(a: Quat, b: Quat, s: f64) -> Quat {
        let mut b = b;
        let mut cos = a.dot(b);
        if cos < 0.0 {
            b = -b;
            cos = -cos;
        }
        if cos > 1.0 - 1e-9 {
            // Nearly the same rotation: the chord is the arc to within rounding.
            return a.plus(b.plus(-a).scaled(s)).normalized();
        }
        let theta = cos.min(1.0).acos();
        let sin = theta.sin();
        let wa = ((1.0 - s) * theta).sin() / sin;
        let wb = (s * theta).sin() / sin;
        a.scaled(wa).plus(b.scaled(wb)).normalized()
    }
}

impl core::ops::Mul for Quat {
    type Output = Quat;

    /// The Hamilton product `self · o` (rotate by `o` first, then by `self`).
    fn mul(self, o: Quat) -> Quat {
        Quat {
            w: self.w * o.w - self.x * o.x - self.y * o.y - self.z * o.z,
            x: self.w * o.x + self.x * o.w + self.y * o.z - self.z * o.y,
            y: self.w * o.y - self.x * o.z + self.y * o.w + self.z * o.x,
            z: self.w * o.z + self.x * o.y - self.y * o.x + self.z * o.w,
        }
    }
}

impl core::ops::Neg for Quat {
    type Output = Quat;

    /// The same rotation with the opposite sign (q and -q rotate alike).
    fn neg(self) -> Quat {
        self.scaled(-1.0)
    }
}

/// How far from ±90° the y angle must stay for x and z to be told apart (below it the
/// rotation is gimbal-locked and z is taken as 0).
const GIMBAL_EPS: f64 = 1e-9;

/// The Euler angles `[x, y, z]` in degrees (about X, then Y, then Z: `R = Rz · Ry · Rx`) of a
/// rotation matrix `r` (rows): `r20 = -sin y`, `r21 / r22 = tan x`, `r10 / r00 = tan z`, each
/// through `atan2` (accurate near ±90°, unlike `asin`). At gimbal lock (cos y = 0) z is 0
/// and x = atan2(-r12, r11).
pub fn euler_deg_of_matrix(r: &[[f64; 3]; 3]) -> [f64; 3] {
    let cb = r[0][0].hypot(r[1][0]);
    let y = (-r[2][0]).atan2(cb);
    let (x, z) = if cb > GIMBAL_EPS {
        (r[2][1].atan2(r[2][2]), r[1][0].atan2(r[0][0]))
    } else {
        ((-r[1][2]).atan2(r[1][1]), 0.0)
    };
    [x, y, z].map(f64::to_degrees)
}
