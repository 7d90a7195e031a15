//! Integer edge planes through the eye for Q16.16 primary rays (issue 14).
//!
//! The float backends test a primary ray against the three planes through the eye and a
//! triangle's edges ([`crate::shape::triangle::EdgePlanes`]). In Q16.16 the planes' products
//! of two coordinates leave the format's range, so they are formed here from the raw
//! integers instead: `n = a x (b - a)` (which equals `a x b` exactly in integers) in 64
//! bits, the lower vertex index first and negated for the other direction, exactly as the
//! floats orient them, then shifted by a power of two into [`EYE_PLANE_BITS`] bits and
//! rounded symmetrically (`round(-v) = -round(v)`). The power is the plane's own, chosen
//! from the exact plane, so the two triangles of a shared edge choose the same one and their
//! planes stay exact negations of each other.
//!
//! The range proof: the DM scales a fixed-point scene so its largest view-space coordinate
//! is at most [`crate::fixed_image::TARGET_EXTENT`] = 32 units = 2^21 raw
//! ([`EYE_VERTEX_LIMIT`]); a component `a_j b_k - a_k b_j` of two such vertices is below
//! 2^43 (shifted by at most 13), the face normal's below 2^45 and the triple product's
//! parts fit 64 bits (checked). A triangle with a vertex beyond the limit (a hand-made
//! image, or a non-finite value) gets planes that decide nothing: every ray goes to the
//! sheared test.
//!
//! The test takes the ray's unit direction `u` (the Q16.16 direction every later step of the
//! ray uses, so the edge planes and the sheared fallback classify the same ray, and
//! distances need no length). `e_k = n_k . u` is three exact i32 x i32 products summed in an
//! i64 (SMULL/SMLAL on the M3; two 32-bit MULS per product on ARMv6-M, [`dot_unit`]). Each
//! plane's rounding moves its `e_k` by at most `(|u_x| + |u_y| + |u_z|) / 2` raw units of its
//! own scale, whatever the scale: one bound per ray, not per plane. A sign within it is
//! uncertain and the triangle goes to the exact sheared test
//! ([`crate::shape::triangle::EyeTest::Uncertain`]); a shared edge's `e` is exactly negated
//! between its two triangles, so both are decided by the same test (watertight). A hit
//! costs two reciprocals (a 128-entry table and two Newton steps, multiplies only: no
//! division at all): the distance `det / f.u` (compared against `t_max` as an integer)
//! and the barycentrics `e_k / sum e`.

use super::{wide, Fx, MAX_RAW};
use crate::geom::Vec3;
use crate::math::solid::Triangle;
use crate::shape::triangle::{EyeTest, TriHit};

/// The largest vertex coordinate (raw Q16.16 magnitude) the integer planes take: 32 units,
/// the DM's [`crate::fixed_image::TARGET_EXTENT`].
pub const EYE_VERTEX_LIMIT: u32 = 1 << 21;
/// Significant bits a plane keeps: `|n_k|`'s largest component is shifted into
/// `[2^29, 2^30]` (or kept exact when below).
pub const EYE_PLANE_BITS: u32 = 30;

/// Bits the face normal keeps (`f`'s largest component in `[2^25, 2^26]`).
const FACE_BITS: u32 = 26;
/// The triple product is kept divided by 2^19 (below 2^30: `|f| <= 2^26`, `|p_0| <= 2^21`).
const DET_SHIFT: u32 = 19;

/// A triangle's three edge planes through the eye in integers (52 bytes, as the f32
/// planes: a node's tracer state holds 256 of either): `n_k` (raw units of Q32) divided by
/// `2^s_k`, its own power of two; the face normal `f = (p_1 - p_0) x (p_2 - p_0)` scaled
/// by a power of two to [`FACE_BITS`] bits, each component shifted left by 4 with
/// `down[k] = max s - s_k` (which brings plane k's `e` to the largest scale of the three)
/// in its low 4 bits; and `det = f . p_0` (exact with the scaled f) divided by
/// 2^[`DET_SHIFT`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FxEyePlanes {
    // Private: `new` keeps every component of n within 2^30 ([`dot_unit`] needs it).
    n: [[i32; 3]; 3],
    f: [i32; 3],
    det: i32,
}

/// `v / 2^s` rounded to nearest, ties away from zero: symmetric, so the negated plane of a
/// shared edge rounds to the negated plane.
#[inline(always)]
fn round_shift(v: i64, s: u32) -> i32 {
    let m = if s == 0 {
        v.unsigned_abs()
    } else {
        (v.unsigned_abs() + (1 << (s - 1))) >> s
    };
    // At most 2^30 for the caller's shift.
    let m = m.min(i32::MAX as u64) as i32;
    if v < 0 {
        -m
    } else {
        m
    }
}

/// `n . u` exactly: three products below 2^61 each (|n| <= 2^30), their sum below 2^63.
#[inline(always)]
fn dot(n: &[i32; 3], u: [i32; 3]) -> i64 {
    if wide::HALVES && u.iter().all(|c| c.unsigned_abs() < 1 << 16) {
        dot_unit(n, u)
    } else {
        wide::mul_i32(n[0], u[0]) + wide::mul_i32(n[1], u[1]) + wide::mul_i32(n[2], u[2])
    }
}

/// [`dot`] for `|n_i| <= 2^30` and `|u_i| < 2^16` (a unit direction's components) with
/// two 32-bit multiplies per term, for ARMv6-M (no 32x32->64 multiply: the general
/// product takes four and the 64-bit sums of their halves): `n = h 2^15 + l` with
/// `|h| <= 2^15`, `l` in `[0, 2^15)`, so `h u` and `l u` are below 2^31 each.
#[inline(always)]
fn dot_unit(n: &[i32; 3], u: [i32; 3]) -> i64 {
    let (mut hi, mut lo) = (0i64, 0i64);
    for i in 0..3 {
        hi += ((n[i] >> 15) * u[i]) as i64;
        lo += ((n[i] & 0x7fff) * u[i]) as i64;
    }
    (hi << 15) + lo
}

impl FxEyePlanes {
    /// Planes that decide nothing: every `e` is zero, within any bound, so every ray is
    /// [`EyeTest::Uncertain`] (an empty cache slot, or a triangle the integers can't take).
    pub const UNDECIDED: FxEyePlanes = FxEyePlanes {
        n: [[0; 3]; 3],
        f: [0; 3],
        det: 0,
    };

    /// The planes of `tri`, whose vertices have indices `index` (shared vertices share an
    /// index, which fixes each edge's orientation).
    ///
    /// Each plane has its own power of two, chosen from the exact plane alone, so the two
    /// triangles of a shared edge choose the same one and round to exact negations; one
    /// power for the whole scene (scaled for its largest vertex) left a small triangle far
    /// from the eye with 15 significant bits in its planes and, through the cancellation in
    /// `n . u` close to an edge, distances off by 2% and barycentrics by 0.1.
    pub fn new(tri: &Triangle<Fx>, index: [u32; 3]) -> Self {
        let p = tri.p.map(|v| [v.x.raw(), v.y.raw(), v.z.raw()]);
        // Checked where the sizes are read: beyond the limit the products below could
        // overflow (and the reserved raw values are beyond it too).
        if p.iter()
            .flatten()
            .any(|c| c.unsigned_abs() > EYE_VERTEX_LIMIT)
        {
            return Self::UNDECIDED;
        }
        let edge = |i: usize, j: usize| {
            let forward = index[i] < index[j];
            let (a, b) = if forward { (p[i], p[j]) } else { (p[j], p[i]) };
            // a x (b - a) = a x b exactly; each product below 2^42, each component below
            // 2^43.
            let c = |j: usize, k: usize| wide::mul_i32(a[j], b[k]) - wide::mul_i32(a[k], b[j]);
            let exact = [c(1, 2), c(2, 0), c(0, 1)];
            let m = exact.iter().map(|v| v.unsigned_abs()).max().unwrap_or(0);
            let s = (64 - m.leading_zeros()).saturating_sub(EYE_PLANE_BITS);
            let n = exact.map(|v| round_shift(v, s));
            (if forward { n } else { n.map(|v| -v) }, s)
        };
        let (n0, s0) = edge(1, 2);
        let (n1, s1) = edge(2, 0);
        let (n2, s2) = edge(0, 1);
        // At most 13.
        let top = s0.max(s1).max(s2);
        // The face normal exactly (edges below 2^22, components below 2^45), then scaled
        // to FACE_BITS bits (up exactly, or down rounded): the distance is det / f.u with
        // det = f . p_0 for this f, the plane through p_0 with a normal turned by at most
        // 2^-25. (Not the sum of the e: near an edge their cancellation left the
        // distances of small far triangles 5 steps off; f's bits keep them within 0.5.)
        let sub = |a: [i32; 3], b: [i32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
        let c = |j: usize, k: usize| wide::mul_i32(e1[j], e2[k]) - wide::mul_i32(e1[k], e2[j]);
        let f = [c(1, 2), c(2, 0), c(0, 1)];
        let fm = f.iter().map(|v| v.unsigned_abs()).max().unwrap_or(0);
        let bits = 64 - fm.leading_zeros();
        let f = if bits > FACE_BITS {
            f.map(|v| round_shift(v, bits - FACE_BITS))
        } else {
            f.map(|v| (v << (FACE_BITS - bits)) as i32)
        };
        // Below 2^49; off from the exact triple product (times f's scale) by at most
        // sum|p_0| / 2 (f's rounding): within that, or below det's own step, the plane
        // passes (nearly) through the eye and which side the eye is on is uncertain; the
        // sheared test decides those triangles. Otherwise its sign is exact.
        let det = dot(&f, p[0]);
        let bound = (p[0].iter().map(|c| c.unsigned_abs() as i64).sum::<i64>() + 1) >> 1;
        if fm == 0 || det.abs() <= bound.max(1 << DET_SHIFT) {
            return Self::UNDECIDED;
        }
        let down = [top - s0, top - s1, top - s2];
        FxEyePlanes {
            n: [n0, n1, n2],
            f: [0, 1, 2].map(|k| (f[k] << 4) | down[k] as i32),
            det: round_shift(det, DET_SHIFT),
        }
    }

    /// Intersect the ray from the eye along the unit direction `d` (`len` = |d|, one for a
    /// unit direction; distances are along the unit direction) for distances in
    /// (0, t_max). Two-sided.
    #[inline(always)]
    pub fn test(&self, d: Vec3<Fx>, len: Fx, t_max: Fx) -> EyeTest<Fx> {
        let u = [d.x.raw(), d.y.raw(), d.z.raw()];
        // The rounding of a plane moves its e by at most sum|u_i| / 2 in its own scale,
        // whatever that is (any u: three magnitudes below 2^31 sum easily).
        let b = (u.iter().map(|c| c.unsigned_abs() as i64).sum::<i64>() + 1) >> 1;
        let e0 = dot(&self.n[0], u);
        let e1 = dot(&self.n[1], u);
        // Most rays miss: two planes certainly on opposite sides decide it.
        if (e0 > b && e1 < -b) || (e0 < -b && e1 > b) {
            return EyeTest::Miss;
        }
        let e2 = dot(&self.n[2], u);
        if (e2 > b && (e0 < -b || e1 < -b)) || (e2 < -b && (e0 > b || e1 > b)) {
            return EyeTest::Miss;
        }
        if !(e0.abs() > b && e1.abs() > b && e2.abs() > b) {
            // Near an edge or vertex: the whole triangle goes to the sheared test, as does
            // every triangle sharing that edge (its e is exactly negated here).
            return EyeTest::Uncertain;
        }
        // All three certain and none opposite: all of one sign. In front of the eye when
        // det has the same sign (det is never zero: such planes are UNDECIDED).
        if (e0 > 0) != (self.det > 0) {
            return EyeTest::Miss;
        }
        // f.u is the exact sum of the e (f to 30 bits): same sign, unless grazing.
        let fu = dot(&self.f.map(|v| v >> 4), u);
        if fu == 0 || (fu > 0) != (e0 > 0) {
            return EyeTest::Uncertain;
        }
        self.hit(
            [e0, e1, e2].map(i64::unsigned_abs),
            fu.unsigned_abs(),
            (self.det.unsigned_abs() as u64) << DET_SHIFT,
            len,
            t_max,
        )
    }

    /// The distance and barycentrics of a ray certainly inside, from the magnitudes of
    /// its e (each in its plane's scale), f.u and det: two reciprocals, no division.
    #[inline(always)]
    fn hit(&self, e: [u64; 3], fu: u64, det: u64, len: Fx, t_max: Fx) -> EyeTest<Fx> {
        let len = len.raw();
        if len <= 0 || len >= MAX_RAW {
            return EyeTest::Uncertain;
        }
        // t = det len / f.u along the unit direction: with f.u = s 2^(32 - z) (s's top bit
        // set, the low bits dropped: 2^-31 of it), 1 / f.u = r 2^(z - 94), r ~ 2^62 / s,
        // and det = dd 2^(32 - zd): t_raw = dd r len 2^(z - zd - 62) = q len
        // 2^(z - zd - 31), q = dd r 2^-31.
        let z = fu.leading_zeros();
        let r = wide::recip_q62(((fu << z) >> 32) as u32);
        let zd = det.leading_zeros();
        let dd = ((det << zd) >> 32) as u32;
        let q = (wide::mul_u32(dd, r) >> 31) as u32;
        let v = wide::mul_u32(q, len as u32);
        let sh = 31 + zd as i32 - z as i32;
        let t = if sh >= 64 {
            0
        } else if sh > 0 {
            (v + (1u64 << (sh - 1))) >> sh
        } else if ((-sh) as u32) < v.leading_zeros() {
            v << -sh
        } else {
            u64::MAX
        };
        // Compared as raw integers: t_max NaN (i32::MIN) rejects every hit.
        if !(t > 0 && t < MAX_RAW as u64 && (t as i32) < t_max.raw()) {
            return EyeTest::Miss;
        }
        // The barycentrics from the e in one scale (each below 2^48, their sum below
        // 2^50): b_k = e_k 2^16 / sum = ek r 2^-46 with sum = s 2^(32 - z) as above and
        // e_k = ek 2^(32 - z) (e_k <= sum, so the shift keeps it), rounded once; the third
        // from the sum of one.
        let e = [
            e[0] >> (self.f[0] & 15),
            e[1] >> (self.f[1] & 15),
            e[2] >> (self.f[2] & 15),
        ];
        let sum = e[0] + e[1] + e[2];
        if sum == 0 {
            return EyeTest::Uncertain;
        }
        let z = sum.leading_zeros();
        let r = wide::recip_q62(((sum << z) >> 32) as u32);
        let bary = |e: u64| {
            let ek = ((e << z) >> 32) as u32;
            ((wide::mul_u32(ek, r) + (1 << 45)) >> 46) as i32
        };
        let (b0, b1) = (bary(e[0]), bary(e[1]));
        EyeTest::Hit(TriHit {
            t: Fx::from_raw(t as i32),
            b: [
                Fx::from_raw(b0),
                Fx::from_raw(b1),
                Fx::from_raw((1 << 16) - b0 - b1),
            ],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Ray;
    use crate::num::Real;
    use crate::shape::triangle::Shear;
    use crate::testkit::numbers::{back, fx, lcg};

    /// The planes' test, or the sheared test when it is uncertain (as the tracer asks).
    fn eye(planes: &FxEyePlanes, tri: &Triangle<Fx>, u: Vec3<Fx>, t_max: Fx) -> Option<TriHit<Fx>> {
        let shear = Shear::new(&Ray::new(Vec3::zero(), u));
        planes
            .test(u, Fx::ONE, t_max)
            .or_sheared(|| *tri, &shear, t_max)
    }

    /// A node's tracer state holds either kernel's plane cache (an enum of both): the
    /// integer planes take no more room than the f32 ones.
    #[test]
    fn the_planes_are_as_small_as_the_f32_ones() {
        let f32_planes = core::mem::size_of::<crate::shape::triangle::EdgePlanes<f32>>();
        assert_eq!(core::mem::size_of::<FxEyePlanes>(), f32_planes);
    }

    #[test]
    fn the_two_multiply_dot_product_is_exact() {
        let mut st = 77u64;
        let mut raw = |bits: u32| {
            let v = (lcg(&mut st) * 2.0 - 1.0) * (1u64 << bits) as f64;
            v as i64 as i32
        };
        let ends = [-(1 << 30), (1 << 30), 0, -1, 1, (1 << 15) - 1, -(1 << 15)];
        for k in 0..100_000 {
            let mut n = [raw(30), raw(30), raw(30)];
            let mut u = [raw(16), raw(16), raw(16)].map(|c| c.clamp(-65535, 65535));
            if k < 49 {
                n = [ends[k % 7], ends[k / 7], ends[(k + 3) % 7]];
                u = [65535, -65535, [65535, -65535, 0, 1, -1, 7, 3][k % 7]];
            }
            let want: i64 = (0..3).map(|i| n[i] as i64 * u[i] as i64).sum();
            assert_eq!(dot_unit(&n, u), want, "{n:?} . {u:?}");
            assert_eq!(dot(&n, u), want);
        }
    }

    #[test]
    fn the_reciprocal_is_within_a_few_units_of_2_pow_62() {
        let mut st = 5u64;
        let mut worst = 0f64;
        let ss = (0..20_000)
            .map(|_| (1u64 << 31) + (lcg(&mut st) * (1u64 << 31) as f64) as u64)
            .chain([1u64 << 31, (1u64 << 32) - 1, 3 << 30]);
        for s in ss {
            let s = s as u32;
            let r = wide::recip_q62(s) as f64;
            let want = 2f64.powi(62) / s as f64;
            worst = worst.max((r - want).abs());
        }
        assert!(worst <= 4.0, "{worst} units of 2^-30");
    }

    #[test]
    fn hits_centre_with_the_distance_and_barycentrics_of_f64() {
        let tri = Triangle {
            p: [
                Vec3::new(-1.0, -1.0, 5.0),
                Vec3::new(1.0, -1.0, 5.0),
                Vec3::new(0.0, 1.0, 5.0),
            ]
            .map(fx),
        };
        let planes = FxEyePlanes::new(&tri, [0, 1, 2]);
        let u = fx(Vec3::new(0.0, 0.0, 1.0));
        let EyeTest::Hit(h) = planes.test(u, Fx::ONE, Fx::MAX) else {
            panic!("no certain hit")
        };
        assert_eq!(h.t.to_f64(), 5.0);
        assert_eq!(h.b.map(|b| b.to_f64()), [0.25, 0.25, 0.5]);
        // A length of two: distances along the unit direction times two.
        let EyeTest::Hit(h) = planes.test(u, Fx::TWO, Fx::MAX) else {
            panic!()
        };
        assert_eq!(h.t.to_f64(), 10.0);
        assert!(matches!(
            planes.test(u, Fx::ONE, Fx::from_f64(4.9)),
            EyeTest::Miss
        ));
        assert!(matches!(planes.test(-u, Fx::ONE, Fx::MAX), EyeTest::Miss));
        // Out of range and degenerate triangles decide nothing.
        let far = Triangle {
            p: [tri.p[0], tri.p[1], fx(Vec3::new(0.0, 1.0, 40.0))],
        };
        assert_eq!(FxEyePlanes::new(&far, [0, 1, 2]), FxEyePlanes::UNDECIDED);
        let edge_on = Triangle {
            p: [
                Vec3::new(0.0, -1.0, 5.0),
                Vec3::new(0.0, 1.0, 5.0),
                Vec3::new(0.0, 0.0, 7.0),
            ]
            .map(fx),
        };
        assert_eq!(
            FxEyePlanes::new(&edge_on, [0, 1, 2]),
            FxEyePlanes::UNDECIDED
        );
        assert!(matches!(
            FxEyePlanes::UNDECIDED.test(u, Fx::ONE, Fx::MAX),
            EyeTest::Uncertain
        ));
    }

    /// Random triangles and rays at photo1's and photo2's scales: the planes (with the
    /// sheared test where uncertain) classify every ray as the sheared test alone does,
    /// except within the sheared test's own rounding of an edge, and give the same distance
    /// and barycentrics to within their bounds.
    #[test]
    fn agrees_with_the_sheared_test_on_random_rays() {
        let mut st = 12345u64;
        let (mut hits, mut certain) = (0, 0);
        let (mut worst_t, mut worst_b, mut sheared_t, mut sheared_b) = (0f64, 0f64, 0f64, 0f64);
        for i in 0..6000 {
            let size = if i % 2 == 0 { 4.0 } else { 0.01 };
            let c = Vec3::new(
                lcg(&mut st) * 16.0 - 8.0,
                lcg(&mut st) * 16.0 - 8.0,
                4.0 + lcg(&mut st) * 24.0,
            );
            let mut corner =
                || c + Vec3::new(lcg(&mut st) - 0.5, lcg(&mut st) - 0.5, lcg(&mut st) - 0.5) * size;
            let tri = Triangle {
                p: [corner(), corner(), corner()].map(fx),
            };
            let aim = c + Vec3::new(lcg(&mut st) - 0.5, lcg(&mut st) - 0.5, 0.0) * size;
            let u = fx(aim).normalize();
            let planes = FxEyePlanes::new(&tri, [0, 1, 2]);
            let test = planes.test(u, Fx::ONE, Fx::MAX);
            certain += !matches!(test, EyeTest::Uncertain) as u32;
            let a = tri.intersect_sheared(&Shear::new(&Ray::new(Vec3::zero(), u)), Fx::MAX);
            let b = eye(&planes, &tri, u, Fx::MAX);
            match (a, b) {
                (Some(a), Some(b)) => {
                    hits += 1;
                    // Both against f64 on the same numbers.
                    let (t64, u64) = (Triangle { p: tri.p.map(back) }, back(u));
                    let h = t64
                        .intersect(&Ray::new(Vec3::zero(), u64), f64::MAX)
                        .expect("f64 hits too");
                    let steps = |v: Fx, w: f64| (v.to_f64() - w).abs() * 65536.0;
                    worst_t = worst_t.max(steps(b.t, h.t));
                    sheared_t = sheared_t.max(steps(a.t, h.t));
                    for k in 0..3 {
                        worst_b = worst_b.max(steps(b.b[k], h.b[k]));
                        sheared_b = sheared_b.max(steps(a.b[k], h.b[k]));
                    }
                }
                (None, None) => {}
                (a, b) => {
                    // Only where the f64 classification of the same numbers is within the
                    // sheared test's rounding of an edge.
                    let (t64, u64) = (Triangle { p: tri.p.map(back) }, back(u));
                    let e = |a: Vec3<f64>, b: Vec3<f64>| a.cross(b).dot(u64);
                    let es = [
                        e(t64.p[1], t64.p[2]),
                        e(t64.p[2], t64.p[0]),
                        e(t64.p[0], t64.p[1]),
                    ];
                    let sum: f64 = es.iter().sum();
                    let margin = es.iter().map(|v| (v / sum).abs()).fold(f64::MAX, f64::min);
                    assert!(
                        margin < 1e-3,
                        "sheared {a:?} vs planes {b:?} for {tri:?} along {u:?}"
                    );
                }
            }
        }
        assert!(
            hits > 400 && certain > 5000,
            "{hits} hits, {certain} certain"
        );
        std::eprintln!("planes: t {worst_t} b {worst_b}; sheared: t {sheared_t} b {sheared_b}");
        assert!(
            worst_t <= 1.0 && worst_b <= 1.0,
            "t {worst_t} steps, b {worst_b} steps"
        );
    }

    /// A closed fan of triangles around a vertex (with shared vertex indices and mixed
    /// windings) and a strip sharing edges, rays fired exactly at the shared edges and the
    /// shared vertex and near them: every ray meets exactly one triangle.
    #[test]
    fn rays_at_shared_edges_and_vertices_hit_exactly_one_triangle() {
        let centre = Vec3::new(0.3, -0.2, 6.0);
        let k = 7;
        let mut v = std::vec![fx(centre)];
        for i in 0..k {
            let a = i as f64 * core::f64::consts::TAU / k as f64;
            v.push(fx(centre
                + Vec3::new(a.cos(), a.sin(), 0.3 * (i as f64 - 3.0) / 3.0)
                    * 1.5));
        }
        let fan: std::vec::Vec<[u32; 3]> = (0..k as u32)
            .map(|i| {
                let (a, b) = (1 + i, 1 + (i + 1) % k as u32);
                match i % 3 {
                    0 => [0, a, b],
                    1 => [b, 0, a],
                    _ => [0, b, a],
                }
            })
            .collect();
        let tris: std::vec::Vec<Triangle<Fx>> = fan
            .iter()
            .map(|i| Triangle {
                p: i.map(|j| v[j as usize]),
            })
            .collect();
        let planes: std::vec::Vec<FxEyePlanes> = tris
            .iter()
            .zip(&fan)
            .map(|(t, i)| FxEyePlanes::new(t, *i))
            .collect();
        let mut st = 99u64;
        let (mut rays, mut via_planes) = (0, 0);
        for n in 0..6000 {
            let s = lcg(&mut st);
            let spoke = 1 + (n / 3) % k;
            let p = match n % 3 {
                // On a spoke (a shared edge), exactly along the stored vertices.
                0 => back(v[0]) + (back(v[spoke]) - back(v[0])) * (0.02 + 0.96 * s),
                // Just beside a spoke.
                1 => {
                    let next = 1 + spoke % k;
                    let w = (lcg(&mut st) - 0.5) * 1e-4;
                    back(v[0])
                        + (back(v[spoke]) - back(v[0])) * (0.02 + 0.96 * s)
                        + (back(v[next]) - back(v[0])) * w.abs()
                }
                // Anywhere inside the fan.
                _ => {
                    let next = 1 + spoke % k;
                    let t = lcg(&mut st);
                    back(v[0])
                        + (back(v[spoke]) - back(v[0])) * (s * (1.0 - t))
                        + (back(v[next]) - back(v[0])) * (s * t)
                }
            };
            // Exactly at the shared vertex, and at the stored edge points themselves.
            let aim = if n % 500 == 0 { back(v[0]) } else { p };
            let u = fx(aim).normalize();
            rays += 1;
            let mut count = 0;
            for (pl, tri) in planes.iter().zip(&tris) {
                let test = pl.test(u, Fx::ONE, Fx::MAX);
                via_planes += matches!(test, EyeTest::Hit(_)) as u32;
                count += eye(pl, tri, u, Fx::MAX).is_some() as u32;
            }
            if count != 1 {
                for (pl, tri) in planes.iter().zip(&tris) {
                    let shear = Shear::new(&Ray::new(Vec3::zero(), u));
                    std::eprintln!(
                        "{:?} {:?}",
                        pl.test(u, Fx::ONE, Fx::MAX),
                        tri.intersect_sheared(&shear, Fx::MAX)
                    );
                }
            }
            assert_eq!(
                count, 1,
                "ray {n} towards {aim:?} ({u:?}) hit {count} triangles"
            );
        }
        assert!(
            rays == 6000 && via_planes > 1000,
            "{via_planes} hits decided by the planes"
        );
        // A shared edge's planes are exact negations (or equal, where the two windings
        // run along it the same way).
        for (i, f) in fan.iter().enumerate() {
            let g = fan[(i + 1) % k];
            let directed = |tri: &[u32; 3]| {
                let o = tri
                    .iter()
                    .position(|x| !g.contains(x) || !f.contains(x))
                    .unwrap();
                (o, tri[(o + 1) % 3], tri[(o + 2) % 3])
            };
            let ((of, fa, _), (og, ga, _)) = (directed(f), directed(&g));
            let (na, nb) = (planes[i].n[of], planes[(i + 1) % k].n[og]);
            if fa == ga {
                assert_eq!(na, nb, "edge of {f:?} and {g:?}");
            } else {
                assert_eq!(na.map(|c| -c), nb, "edge of {f:?} and {g:?}");
            }
            assert_ne!(na, [0; 3]);
        }
    }
}
