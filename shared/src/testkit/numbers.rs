//! Numbers for tests: a small deterministic generator and the vector conversions between
//! f64 and Q16.16 that the fixed-point tests compare through.

use crate::fixed::Fx;
use crate::geom::Vec3;
use crate::num::Real;

/// The next value in [0, 1) of a 64-bit linear congruential generator (tests need no crate
/// for it); `state` is the generator.
pub fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

/// `v` rounded to Q16.16.
pub fn fx(v: Vec3<f64>) -> Vec3<Fx> {
    Vec3::new(Fx::from_f64(v.x), Fx::from_f64(v.y), Fx::from_f64(v.z))
}

/// `v` exactly in f64.
pub fn back(v: Vec3<Fx>) -> Vec3<f64> {
    Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64())
}
