//! Integer edge planes through the eye for Q16.16 primary rays (issue 14).
//!
//! The float backends test a primary ray against the three planes through the eye and a
//! triangle's edges ([`crate::shape::triangle::EdgePlanes`]). In Q16.16 the planes' products
//! of two coordinates leave the format's range, so they are formed here from the raw
//! integers instead: `n = a x (b - a)` (which equals `a x b` exactly in integers) in 64
//! bits, the lower vertex index first and negated for the other direction, exactly as the
//! floats orient them, then shifted by one power of two for every plane
//! ([`EYE_PLANE_SHIFT`]) and rounded symmetrically (`round(-v) = -round(v)`), so the planes
//! of a shared edge stay exact negations of each other.
//!
//! The range proof: the DM scales a fixed-point scene so its largest view-space coordinate
//! is at most [`crate::fixed_image::TARGET_EXTENT`] = 32 units = 2^21 raw
//! ([`EYE_VERTEX_LIMIT`]); a component `a_j b_k - a_k b_j` of two such vertices is below
//! 2^43, and the shift by 13 leaves it below 2^30. A triangle with a vertex beyond the limit
//! (a hand-made image, or a non-finite value) gets planes that decide nothing: every ray
//! goes to the sheared test.
//!
//! The test takes the ray's unit direction `u` (the Q16.16 direction every later step of the
//! ray uses, so the edge planes and the sheared fallback classify the same ray).
//! `e_k = n_k . u` is three exact i32 x i32 products summed in an i64 (SMLAL on the M3).
//! Every plane has the same scale, so the rounding of the planes moves each `e_k` by at most
//! `(|u_x| + |u_y| + |u_z|) / 2` raw units: one bound per ray, not per plane. A sign within
//! it is uncertain and the triangle goes to the exact sheared test
//! ([`crate::shape::triangle::EyeTest::Uncertain`]); a shared edge's `e` is exactly negated
//! between its two triangles, so both are decided by the same test (watertight). A hit
//! costs one reciprocal (a 128-entry table and two Newton steps, multiplies only: no
//! division at all), from which come the distance (compared against `t_max` as a
//! product) and the barycentrics.

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

/// A triangle's three edge planes through the eye in integers: `n_k` (raw units of Q32)
/// divided by `2^s_k`, its own power of two (`n[k]`; `down[k] = max s - s_k` brings plane
/// k's `e` to the largest scale of the three), and the face normal `f = (p_1 - p_0) x (p_2 -
/// p_0)` and the triple product `det = p_0 . f` (Q48), both divided by one power of two.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FxEyePlanes {
    pub n: [[i32; 3]; 3],
    pub f: [i32; 3],
    pub det: i64,
    pub down: [u8; 3],
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
    wide::mul_i32(n[0], u[0]) + wide::mul_i32(n[1], u[1]) + wide::mul_i32(n[2], u[2])
}

impl FxEyePlanes {
    /// Planes that decide nothing: every `e` is zero, within any bound, so every ray is
    /// [`EyeTest::Uncertain`] (an empty cache slot, or a triangle the integers can't take).
    pub const UNDECIDED: FxEyePlanes = FxEyePlanes {
        n: [[0; 3]; 3],
        f: [0; 3],
        det: 0,
        down: [0; 3],
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
        let top = s0.max(s1).max(s2);
        // det = p_0 . ((p_1 - p_0) x (p_2 - p_0)) exactly: the face normal f below 2^45,
        // split as f = h 2^16 + l so both dot products fit 64 bits, det = H 2^16 + L, and
        // floor(det / 2^sf) = H 2^(16 - sf) + floor(L / 2^sf) (checked: a huge, thin
        // triangle could leave 64 bits; it decides nothing then). The distance is det / f.u:
        // f.u (the sum of the e, without their cancellation near an edge: the planes' 30
        // bits gave distances off by 5 steps on small far triangles, f's 30 bits by 1).
        let sub = |a: [i32; 3], b: [i32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
        let c = |j: usize, k: usize| wide::mul_i32(e1[j], e2[k]) - wide::mul_i32(e1[k], e2[j]);
        let f = [c(1, 2), c(2, 0), c(0, 1)];
        let hi = dot(&f.map(|v| (v >> 16) as i32), p[0]);
        let lo = dot(&f.map(|v| (v & 0xffff) as i32), p[0]);
        let fm = f.iter().map(|v| v.unsigned_abs()).max().unwrap_or(0);
        let sf = (64 - fm.leading_zeros()).saturating_sub(EYE_PLANE_BITS); // at most 15
        let det = hi
            .checked_mul(1 << (16 - sf))
            .and_then(|h| h.checked_add(lo >> sf));
        match det {
            // det = 0: the plane passes through the eye (sign(det) is exact otherwise:
            // floor keeps a negative value negative, and a positive one is at least 2^sf).
            Some(det) if det != 0 => FxEyePlanes {
                n: [n0, n1, n2],
                f: f.map(|v| round_shift(v, sf)),
                det,
                down: [top - s0, top - s1, top - s2].map(|d| d as u8),
            },
            _ => Self::UNDECIDED,
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
        let fu = dot(&self.f, u);
        if fu == 0 || (fu > 0) != (e0 > 0) {
            return EyeTest::Uncertain;
        }
        self.hit(
            [e0, e1, e2].map(i64::unsigned_abs),
            fu.unsigned_abs(),
            self.det.unsigned_abs(),
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
            e[0] >> self.down[0],
            e[1] >> self.down[1],
            e[2] >> self.down[2],
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

    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    fn fx(v: Vec3<f64>) -> Vec3<Fx> {
        Vec3::new(Fx::from_f64(v.x), Fx::from_f64(v.y), Fx::from_f64(v.z))
    }

    fn back(v: Vec3<Fx>) -> Vec3<f64> {
        Vec3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64())
    }

    /// The planes' test, or the sheared test when it is uncertain (as the tracer asks).
    fn eye(planes: &FxEyePlanes, tri: &Triangle<Fx>, u: Vec3<Fx>, t_max: Fx) -> Option<TriHit<Fx>> {
        let shear = Shear::new(&Ray::new(Vec3::zero(), u));
        planes
            .test(u, Fx::ONE, t_max)
            .or_sheared(|| *tri, &shear, t_max)
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
