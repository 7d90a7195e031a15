//! Deterministic trigonometry for the generators: series on IEEE `+ - * / sqrt` only, so the
//! generated assets do not depend on the platform's libm.

use crate::vec3::{cross, dot, length};

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
pub(crate) fn atan(x: f64) -> f64 {
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
pub(crate) fn angle_between(a: [f64; 3], b: [f64; 3]) -> f64 {
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
