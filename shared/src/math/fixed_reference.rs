//! The Q16.16 arithmetic as it was before issue 14 made it cheaper on integer cores, kept
//! verbatim (type renamed `RefFx`) as the reference the tests compare [`super::Fx`] with:
//! every operation must return the same raw value for every input.
#![allow(dead_code)]

use crate::num::Real;
use core::cmp::Ordering;
use core::fmt;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

const FRAC_BITS: u32 = 16;
const ONE_RAW: i32 = 1 << FRAC_BITS;
const INF_RAW: i32 = i32::MAX;
const NEG_INF_RAW: i32 = -i32::MAX;
const NAN_RAW: i32 = i32::MIN;
/// Largest finite raw value.
const MAX_RAW: i32 = i32::MAX - 1;

/// A Q16.16 fixed-point number with IEEE-like infinities and NaN.
#[derive(Clone, Copy, Default)]
pub struct RefFx(i32);

impl RefFx {
    pub const INFINITY: RefFx = RefFx(INF_RAW);
    pub const NEG_INFINITY: RefFx = RefFx(NEG_INF_RAW);
    pub const NAN: RefFx = RefFx(NAN_RAW);
    /// The step between neighbouring values (2^-16).
    pub const STEP: RefFx = RefFx(1);

    /// The value whose raw representation is `raw` (`x * 65536`).
    #[inline(always)]
    pub const fn from_raw(raw: i32) -> RefFx {
        RefFx(raw)
    }

    /// `x * 65536` (or one of the reserved values for infinities and NaN).
    #[inline(always)]
    pub const fn raw(self) -> i32 {
        self.0
    }

    #[inline(always)]
    pub fn is_nan(self) -> bool {
        self.0 == NAN_RAW
    }

    /// True for the three reserved raw values (both infinities and NaN).
    #[inline(always)]
    fn special(self) -> bool {
        // i32::MAX -> 0, i32::MIN -> 1, i32::MIN + 1 -> 2: one subtract and one compare.
        (self.0.wrapping_sub(i32::MAX) as u32) <= 2
    }

    /// A 64-bit raw result, saturated to an infinity when it leaves the finite range.
    #[inline(always)]
    fn from_wide(v: i64) -> RefFx {
        if v > MAX_RAW as i64 {
            RefFx::INFINITY
        } else if v < -(MAX_RAW as i64) {
            RefFx::NEG_INFINITY
        } else {
            RefFx(v as i32)
        }
    }

    /// The sign of a non-NaN value as -1, 0 or 1.
    #[inline(always)]
    fn signum_i(self) -> i32 {
        self.0.signum()
    }

    #[cold]
    fn add_special(self, o: RefFx) -> RefFx {
        if self.is_nan() || o.is_nan() {
            RefFx::NAN
        } else if self.special() && o.special() {
            // Both infinite: same sign stays, opposite signs are undefined.
            if self.0 == o.0 {
                self
            } else {
                RefFx::NAN
            }
        } else if self.special() {
            self
        } else {
            o
        }
    }

    /// The sum of three products that overflowed an i64 somewhere: it is at least 2^62 in
    /// magnitude (one partial sum passed 2^63 and each product is below 2^62), far beyond
    /// the format, so the infinity of its sign.
    #[cold]
    fn dot3_overflow(p0: i64, p1: i64, p2: i64) -> RefFx {
        if p0 as i128 + p1 as i128 + p2 as i128 > 0 {
            RefFx::INFINITY
        } else {
            RefFx::NEG_INFINITY
        }
    }

    #[cold]
    fn mul_special(self, o: RefFx) -> RefFx {
        if self.is_nan() || o.is_nan() || self.0 == 0 || o.0 == 0 {
            RefFx::NAN
        } else if self.signum_i() == o.signum_i() {
            RefFx::INFINITY
        } else {
            RefFx::NEG_INFINITY
        }
    }

    #[cold]
    fn div_special(self, o: RefFx) -> RefFx {
        if self.is_nan() || o.is_nan() || (self.special() && o.special()) {
            RefFx::NAN
        } else if o.special() {
            // finite / inf
            RefFx(0)
        } else if o.0 == 0 && self.0 == 0 {
            RefFx::NAN
        } else if self.signum_i() * if o.0 == 0 { 1 } else { o.signum_i() } >= 0 {
            RefFx::INFINITY
        } else {
            RefFx::NEG_INFINITY
        }
    }

    /// 64-bit intermediate square root: floor(sqrt(n)) with the remainder's rounding.
    fn isqrt_rounded(n: u64) -> u64 {
        if n == 0 {
            return 0;
        }
        // Start from a power of two at or above the root and refine bit by bit from the top.
        let shift = (63 - n.leading_zeros()) & !1;
        let mut bit = 1u64 << shift;
        let (mut rem, mut root) = (n, 0u64);
        while bit != 0 {
            if rem >= root + bit {
                rem -= root + bit;
                root = (root >> 1) + bit;
            } else {
                root >>= 1;
            }
            bit >>= 2;
        }
        // Round to nearest: root + 0.5 squared = root^2 + root + 0.25.
        if rem > root {
            root + 1
        } else {
            root
        }
    }

    /// log2(x) for finite x > 0 with 30 fraction bits.
    fn log2_q30(self) -> i64 {
        let raw = self.0 as u32;
        // Normalise to m in [1, 2) with 30 fraction bits: x = m * 2^e.
        let msb = 31 - raw.leading_zeros() as i32;
        let e = msb - FRAC_BITS as i32;
        let m = if msb >= 30 {
            (raw >> (msb - 30)) as u64
        } else {
            (raw as u64) << (30 - msb)
        };
        // Fraction bits of log2(m) by repeated squaring (one bit per step).
        let mut frac: i64 = 0;
        let mut y = m; // Q2.30 in [1, 2)
        let mut i = 0;
        while i < 30 {
            y = (y * y) >> 30;
            frac <<= 1;
            if y >= 2u64 << 30 {
                y >>= 1;
                frac |= 1;
            }
            i += 1;
        }
        ((e as i64) << 30) + frac
    }

    /// 2^x for x given with 30 fraction bits, in Q16.16.
    fn exp2_q30(x: i64) -> RefFx {
        let ip = x >> 30; // floor
        let fp = x & ((1 << 30) - 1); // [0, 1) in Q30
        if ip >= 15 {
            return RefFx::INFINITY;
        }
        if ip < -17 {
            return RefFx(0);
        }
        // 2^f for f in [0, 1): 2^f = e^(f ln2), Taylor series in Q30 (terms fall fast).
        const LN2_Q30: i64 = 744_261_118; // ln 2 * 2^30
        let z = (fp * LN2_Q30) >> 30; // f*ln2 in Q30, < 0.7 * 2^30
        let mut term: i64 = 1 << 30;
        let mut sum: i64 = 1 << 30;
        let mut k = 1;
        while k <= 11 {
            term = ((term * z) >> 30) / k;
            sum += term;
            k += 1;
        }
        // sum = 2^f in Q30; scale by 2^ip into Q16 with rounding.
        let shift = 30 - FRAC_BITS as i64 - ip;
        let v = if shift > 0 {
            (sum + (1 << (shift - 1))) >> shift
        } else {
            sum << -shift
        };
        RefFx::from_wide(v)
    }

    /// atan(z) for z in [0, 1] (minimax polynomial, error under 1e-5 rad plus rounding).
    fn atan_unit(z: RefFx) -> RefFx {
        const C: [f64; 6] = [
            0.999_977_26,
            -0.332_623_47,
            0.193_543_46,
            -0.116_432_87,
            0.052_653_32,
            -0.011_721_20,
        ];
        let z2 = z * z;
        let mut acc = RefFx::from_f64(C[5]);
        let mut i = C.len() - 1;
        while i > 0 {
            i -= 1;
            acc = acc * z2 + RefFx::from_f64(C[i]);
        }
        acc * z
    }
}

impl fmt::Debug for RefFx {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            NAN_RAW => f.write_str("RefFx(NaN)"),
            INF_RAW => f.write_str("RefFx(inf)"),
            NEG_INF_RAW => f.write_str("RefFx(-inf)"),
            r => write!(f, "RefFx({})", r as f64 / ONE_RAW as f64),
        }
    }
}

impl PartialEq for RefFx {
    #[inline(always)]
    fn eq(&self, o: &RefFx) -> bool {
        self.0 == o.0 && self.0 != NAN_RAW
    }
}

impl PartialOrd for RefFx {
    #[inline(always)]
    fn partial_cmp(&self, o: &RefFx) -> Option<Ordering> {
        if self.0 == NAN_RAW || o.0 == NAN_RAW {
            None
        } else {
            Some(self.0.cmp(&o.0))
        }
    }
    #[inline(always)]
    fn lt(&self, o: &RefFx) -> bool {
        self.0 < o.0 && self.0 != NAN_RAW && o.0 != NAN_RAW
    }
    #[inline(always)]
    fn le(&self, o: &RefFx) -> bool {
        self.0 <= o.0 && self.0 != NAN_RAW && o.0 != NAN_RAW
    }
    #[inline(always)]
    fn gt(&self, o: &RefFx) -> bool {
        o.lt(self)
    }
    #[inline(always)]
    fn ge(&self, o: &RefFx) -> bool {
        o.le(self)
    }
}

impl Add for RefFx {
    type Output = RefFx;
    #[inline(always)]
    fn add(self, o: RefFx) -> RefFx {
        if self.special() || o.special() {
            return self.add_special(o);
        }
        RefFx::from_wide(self.0 as i64 + o.0 as i64)
    }
}

impl Sub for RefFx {
    type Output = RefFx;
    #[inline(always)]
    fn sub(self, o: RefFx) -> RefFx {
        self + (-o)
    }
}

impl Neg for RefFx {
    type Output = RefFx;
    #[inline(always)]
    fn neg(self) -> RefFx {
        // The finite range and the infinities are symmetric; NaN stays NaN.
        if self.0 == NAN_RAW {
            self
        } else {
            RefFx(-self.0)
        }
    }
}

impl Mul for RefFx {
    type Output = RefFx;
    #[inline(always)]
    fn mul(self, o: RefFx) -> RefFx {
        if self.special() || o.special() {
            return self.mul_special(o);
        }
        let p = self.0 as i64 * o.0 as i64;
        RefFx::from_wide((p + (1 << (FRAC_BITS - 1))) >> FRAC_BITS)
    }
}

impl Div for RefFx {
    type Output = RefFx;
    #[inline(always)]
    fn div(self, o: RefFx) -> RefFx {
        if self.special() || o.special() || o.0 == 0 {
            return self.div_special(o);
        }
        // Quotient of magnitudes, rounded to nearest, then the sign.
        let (n, d) = (self.0.unsigned_abs() as u64, o.0.unsigned_abs() as u64);
        let q = ((n << FRAC_BITS) + (d >> 1)) / d;
        let q = q.min(MAX_RAW as u64 + 1) as i64;
        RefFx::from_wide(if (self.0 < 0) != (o.0 < 0) { -q } else { q })
    }
}

macro_rules! fx_assign {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for RefFx {
            #[inline(always)]
            fn $f(&mut self, o: RefFx) {
                *self = *self $op o;
            }
        }
    };
}
fx_assign!(AddAssign, add_assign, +);
fx_assign!(SubAssign, sub_assign, -);
fx_assign!(MulAssign, mul_assign, *);

impl Real for RefFx {
    const NAME: &'static str = "q16.16";
    const ZERO: RefFx = RefFx(0);
    const ONE: RefFx = RefFx(ONE_RAW);
    const HALF: RefFx = RefFx(ONE_RAW / 2);
    const TWO: RefFx = RefFx(ONE_RAW * 2);
    const MAX: RefFx = RefFx(MAX_RAW);
    const INFINITY: RefFx = RefFx(INF_RAW);
    /// pi rounded to the nearest step.
    const PI: RefFx = RefFx(205_887);
    const STORAGE: crate::num::Storage = crate::num::Storage::Q16_16;
    const ABSOLUTE_ROUNDING: bool = true;
    // Never renders (operations only): the generic planes.
    type EyePlanes = crate::shape::triangle::EdgePlanes<RefFx>;
    const EYE_PLANES_EMPTY: Self::EyePlanes = crate::shape::triangle::EdgePlanes::ZERO;
    fn eye_planes(
        tri: &crate::math::solid::Triangle<RefFx>,
        index: [u32; 3],
        l1: RefFx,
    ) -> Self::EyePlanes {
        crate::shape::triangle::EdgePlanes::new(tri, index, l1)
    }
    fn eye_test(
        p: &Self::EyePlanes,
        d: crate::geom::Vec3<RefFx>,
        len: RefFx,
        t_max: RefFx,
    ) -> crate::shape::triangle::EyeTest<RefFx> {
        p.intersect_from_eye(d, len, t_max)
    }

    #[inline]
    fn dot3(a: [RefFx; 3], b: [RefFx; 3]) -> RefFx {
        if a[0].special()
            || a[1].special()
            || a[2].special()
            || b[0].special()
            || b[1].special()
            || b[2].special()
        {
            return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        }
        // Three exact products below 2^62 each; their sum fits an i64 unless it is far
        // beyond the format (then an infinity); one rounding at the end.
        let (p0, p1, p2) = (
            a[0].0 as i64 * b[0].0 as i64,
            a[1].0 as i64 * b[1].0 as i64,
            a[2].0 as i64 * b[2].0 as i64,
        );
        match p0.checked_add(p1).and_then(|s| s.checked_add(p2)) {
            Some(p) => RefFx::from_wide(p.saturating_add(1 << (FRAC_BITS - 1)) >> FRAC_BITS),
            None => RefFx::dot3_overflow(p0, p1, p2),
        }
    }

    #[inline]
    fn unit_scale(m: RefFx) -> RefFx {
        if m.0 <= 0 || m.special() {
            return RefFx::ONE;
        }
        // Shift the leading one to bit 15 (m in [0.5, 1)), at most 2^14 (the format's limit).
        let msb = 31 - m.0.leading_zeros() as i32;
        let s = (15 - msb).clamp(0, 14);
        RefFx(ONE_RAW << s)
    }

    #[inline(always)]
    fn from_f32(v: f32) -> RefFx {
        RefFx::from_f64(v as f64)
    }
    #[inline]
    fn from_f64(v: f64) -> RefFx {
        if v.is_nan() {
            return RefFx::NAN;
        }
        let s = v * ONE_RAW as f64;
        // Round half away from zero, then saturate to an infinity.
        let r = if s >= 0.0 { s + 0.5 } else { s - 0.5 };
        if r >= MAX_RAW as f64 + 1.0 {
            RefFx::INFINITY
        } else if r <= -(MAX_RAW as f64) - 1.0 {
            RefFx::NEG_INFINITY
        } else {
            RefFx(r as i32)
        }
    }
    #[inline(always)]
    fn from_i32(v: i32) -> RefFx {
        RefFx::from_wide((v as i64) << FRAC_BITS)
    }
    #[inline(always)]
    fn from_stored(bits: u32) -> RefFx {
        RefFx(bits as i32)
    }
    fn to_f64(self) -> f64 {
        match self.0 {
            NAN_RAW => f64::NAN,
            INF_RAW => f64::INFINITY,
            NEG_INF_RAW => f64::NEG_INFINITY,
            r => r as f64 / ONE_RAW as f64,
        }
    }
    fn to_f32(self) -> f32 {
        self.to_f64() as f32
    }
    /// One step relative to 1.0. Fixed-point rounding is absolute (half a step per
    /// operation), so relative error bounds built from this hold near magnitude 1 and above.
    #[inline(always)]
    fn epsilon() -> RefFx {
        RefFx(1)
    }
    #[inline]
    fn sqrt(self) -> RefFx {
        // Negative numbers, -inf and NaN (its raw value is negative too).
        if self.0 < 0 {
            return RefFx::NAN;
        }
        if self.0 == INF_RAW {
            return self;
        }
        // sqrt(r / 2^16) * 2^16 = sqrt(r * 2^16).
        RefFx(RefFx::isqrt_rounded((self.0 as u64) << FRAC_BITS) as i32)
    }
    #[inline(always)]
    fn abs(self) -> RefFx {
        if self.0 < 0 {
            -self
        } else {
            self
        }
    }
    #[inline]
    fn floor(self) -> RefFx {
        if self.special() {
            self
        } else {
            RefFx(self.0 & !(ONE_RAW - 1))
        }
    }
    fn powf(self, e: RefFx) -> RefFx {
        if self.special() || e.special() {
            return RefFx::from_f64(libm::pow(self.to_f64(), e.to_f64()));
        }
        if self.0 < 0 {
            return RefFx::NAN;
        }
        if self.0 == 0 {
            return if e.0 > 0 { RefFx(0) } else { RefFx::NAN };
        }
        if e.0 == 0 {
            return RefFx::ONE;
        }
        // e * log2(x) with 30 fraction bits (a Q16 exponent would lose 120 * 2^-17).
        let p = (e.0 as i128 * self.log2_q30() as i128) >> FRAC_BITS;
        if p > (40i128 << 30) {
            return RefFx::INFINITY;
        }
        if p < -(40i128 << 30) {
            return RefFx(0);
        }
        RefFx::exp2_q30(p as i64)
    }
    fn atan2(self, x: RefFx) -> RefFx {
        let y = self;
        if y.special() || x.special() {
            return RefFx::from_f64(libm::atan2(y.to_f64(), x.to_f64()));
        }
        if x.0 == 0 && y.0 == 0 {
            return RefFx(0);
        }
        let (ax, ay) = (x.abs(), y.abs());
        let a = if ax >= ay {
            RefFx::atan_unit(ay / ax)
        } else {
            RefFx(RefFx::PI.0 / 2) - RefFx::atan_unit(ax / ay)
        };
        let a = if x.0 < 0 { RefFx::PI - a } else { a };
        if y.0 < 0 {
            -a
        } else {
            a
        }
    }
    fn acos(self) -> RefFx {
        if !self.is_finite() || self.abs() > RefFx::ONE {
            return RefFx::NAN;
        }
        (RefFx::ONE - self * self).sqrt().atan2(self)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        !self.special()
    }
    #[inline(always)]
    fn is_sign_negative(self) -> bool {
        self.0 < 0
    }
    #[inline]
    fn next_up(self) -> RefFx {
        if self.special() || self.0 == MAX_RAW {
            self
        } else {
            RefFx(self.0 + 1)
        }
    }
    #[inline]
    fn next_down(self) -> RefFx {
        if self.special() || self.0 == -MAX_RAW {
            self
        } else {
            RefFx(self.0 - 1)
        }
    }
}
