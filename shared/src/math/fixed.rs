//! Q16.16 fixed point: the integer-only number format (LINKS-1's NCs computed in integers
//! until the 8087 arrived; Table 5.1 of the paper is the same trade).
//!
//! A value is an `i32` holding `x * 65536`. Products and quotients use 64-bit intermediates
//! and round to nearest. Three raw values are reserved so that overflow is never wrapped:
//! it becomes an infinity, exactly as in IEEE arithmetic, and invalid operations
//! (`inf - inf`, `0 * inf`, `0 / 0`, `sqrt(-1)`) become NaN. The tracer already treats
//! non-finite values as "no hit" (it is written NaN-safe for floats), and
//! [`Real::is_finite`] reports them, so an overflow is detected where it happens and counted
//! in the pixel's result, never turned into a wrong but plausible number.
//!
//! Range: about +-32767.99998 with a step of 2^-16 (1.5e-5). The DM chooses the scale of a
//! scene so that it fits this range with the most precision left (`fixed_image`).

use crate::num::Real;
use core::cmp::Ordering;
use core::fmt;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// Fraction bits.
pub const FRAC_BITS: u32 = 16;
const ONE_RAW: i32 = 1 << FRAC_BITS;
const INF_RAW: i32 = i32::MAX;
const NEG_INF_RAW: i32 = -i32::MAX;
const NAN_RAW: i32 = i32::MIN;
/// Largest finite raw value.
const MAX_RAW: i32 = i32::MAX - 1;

/// A Q16.16 fixed-point number with IEEE-like infinities and NaN.
#[derive(Clone, Copy, Default)]
pub struct Fx(i32);

impl Fx {
    pub const INFINITY: Fx = Fx(INF_RAW);
    pub const NEG_INFINITY: Fx = Fx(NEG_INF_RAW);
    pub const NAN: Fx = Fx(NAN_RAW);
    /// The step between neighbouring values (2^-16).
    pub const STEP: Fx = Fx(1);

    /// The value whose raw representation is `raw` (`x * 65536`).
    #[inline(always)]
    pub const fn from_raw(raw: i32) -> Fx {
        Fx(raw)
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
    fn from_wide(v: i64) -> Fx {
        if v > MAX_RAW as i64 {
            Fx::INFINITY
        } else if v < -(MAX_RAW as i64) {
            Fx::NEG_INFINITY
        } else {
            Fx(v as i32)
        }
    }

    /// The sign of a non-NaN value as -1, 0 or 1.
    #[inline(always)]
    fn signum_i(self) -> i32 {
        self.0.signum()
    }

    #[cold]
    fn add_special(self, o: Fx) -> Fx {
        if self.is_nan() || o.is_nan() {
            Fx::NAN
        } else if self.special() && o.special() {
            // Both infinite: same sign stays, opposite signs are undefined.
            if self.0 == o.0 {
                self
            } else {
                Fx::NAN
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
    fn dot3_overflow(p0: i64, p1: i64, p2: i64) -> Fx {
        if p0 as i128 + p1 as i128 + p2 as i128 > 0 {
            Fx::INFINITY
        } else {
            Fx::NEG_INFINITY
        }
    }

    #[cold]
    fn mul_special(self, o: Fx) -> Fx {
        if self.is_nan() || o.is_nan() || self.0 == 0 || o.0 == 0 {
            Fx::NAN
        } else if self.signum_i() == o.signum_i() {
            Fx::INFINITY
        } else {
            Fx::NEG_INFINITY
        }
    }

    #[cold]
    fn div_special(self, o: Fx) -> Fx {
        if self.is_nan() || o.is_nan() || (self.special() && o.special()) {
            Fx::NAN
        } else if o.special() {
            // finite / inf
            Fx(0)
        } else if o.0 == 0 && self.0 == 0 {
            Fx::NAN
        } else if self.signum_i() * if o.0 == 0 { 1 } else { o.signum_i() } >= 0 {
            Fx::INFINITY
        } else {
            Fx::NEG_INFINITY
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
    fn exp2_q30(x: i64) -> Fx {
        let ip = x >> 30; // floor
        let fp = x & ((1 << 30) - 1); // [0, 1) in Q30
        if ip >= 15 {
            return Fx::INFINITY;
        }
        if ip < -17 {
            return Fx(0);
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
        Fx::from_wide(v)
    }

    /// atan(z) for z in [0, 1] (minimax polynomial, error under 1e-5 rad plus rounding).
    fn atan_unit(z: Fx) -> Fx {
        const C: [f64; 6] = [
            0.999_977_26,
            -0.332_623_47,
            0.193_543_46,
            -0.116_432_87,
            0.052_653_32,
            -0.011_721_20,
        ];
        let z2 = z * z;
        let mut acc = Fx::from_f64(C[5]);
        let mut i = C.len() - 1;
        while i > 0 {
            i -= 1;
            acc = acc * z2 + Fx::from_f64(C[i]);
        }
        acc * z
    }
}

impl fmt::Debug for Fx {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            NAN_RAW => f.write_str("Fx(NaN)"),
            INF_RAW => f.write_str("Fx(inf)"),
            NEG_INF_RAW => f.write_str("Fx(-inf)"),
            r => write!(f, "Fx({})", r as f64 / ONE_RAW as f64),
        }
    }
}

impl PartialEq for Fx {
    #[inline(always)]
    fn eq(&self, o: &Fx) -> bool {
        self.0 == o.0 && self.0 != NAN_RAW
    }
}

impl PartialOrd for Fx {
    #[inline(always)]
    fn partial_cmp(&self, o: &Fx) -> Option<Ordering> {
        if self.0 == NAN_RAW || o.0 == NAN_RAW {
            None
        } else {
            Some(self.0.cmp(&o.0))
        }
    }
    #[inline(always)]
    fn lt(&self, o: &Fx) -> bool {
        self.0 < o.0 && self.0 != NAN_RAW && o.0 != NAN_RAW
    }
    #[inline(always)]
    fn le(&self, o: &Fx) -> bool {
        self.0 <= o.0 && self.0 != NAN_RAW && o.0 != NAN_RAW
    }
    #[inline(always)]
    fn gt(&self, o: &Fx) -> bool {
        o.lt(self)
    }
    #[inline(always)]
    fn ge(&self, o: &Fx) -> bool {
        o.le(self)
    }
}

impl Add for Fx {
    type Output = Fx;
    #[inline(always)]
    fn add(self, o: Fx) -> Fx {
        if self.special() || o.special() {
            return self.add_special(o);
        }
        Fx::from_wide(self.0 as i64 + o.0 as i64)
    }
}

impl Sub for Fx {
    type Output = Fx;
    #[inline(always)]
    fn sub(self, o: Fx) -> Fx {
        self + (-o)
    }
}

impl Neg for Fx {
    type Output = Fx;
    #[inline(always)]
    fn neg(self) -> Fx {
        // The finite range and the infinities are symmetric; NaN stays NaN.
        if self.0 == NAN_RAW {
            self
        } else {
            Fx(-self.0)
        }
    }
}

impl Mul for Fx {
    type Output = Fx;
    #[inline(always)]
    fn mul(self, o: Fx) -> Fx {
        if self.special() || o.special() {
            return self.mul_special(o);
        }
        let p = self.0 as i64 * o.0 as i64;
        Fx::from_wide((p + (1 << (FRAC_BITS - 1))) >> FRAC_BITS)
    }
}

impl Div for Fx {
    type Output = Fx;
    #[inline(always)]
    fn div(self, o: Fx) -> Fx {
        if self.special() || o.special() || o.0 == 0 {
            return self.div_special(o);
        }
        // Quotient of magnitudes, rounded to nearest, then the sign.
        let (n, d) = (self.0.unsigned_abs() as u64, o.0.unsigned_abs() as u64);
        let q = ((n << FRAC_BITS) + (d >> 1)) / d;
        let q = q.min(MAX_RAW as u64 + 1) as i64;
        Fx::from_wide(if (self.0 < 0) != (o.0 < 0) { -q } else { q })
    }
}

macro_rules! fx_assign {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for Fx {
            #[inline(always)]
            fn $f(&mut self, o: Fx) {
                *self = *self $op o;
            }
        }
    };
}
fx_assign!(AddAssign, add_assign, +);
fx_assign!(SubAssign, sub_assign, -);
fx_assign!(MulAssign, mul_assign, *);

impl Real for Fx {
    const NAME: &'static str = "q16.16";
    const ZERO: Fx = Fx(0);
    const ONE: Fx = Fx(ONE_RAW);
    const HALF: Fx = Fx(ONE_RAW / 2);
    const TWO: Fx = Fx(ONE_RAW * 2);
    const MAX: Fx = Fx(MAX_RAW);
    /// pi rounded to the nearest step.
    const PI: Fx = Fx(205_887);
    const STORAGE: crate::num::Storage = crate::num::Storage::Q16_16;
    const ABSOLUTE_ROUNDING: bool = true;

    #[inline]
    fn dot3(a: [Fx; 3], b: [Fx; 3]) -> Fx {
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
            Some(p) => Fx::from_wide(p.saturating_add(1 << (FRAC_BITS - 1)) >> FRAC_BITS),
            None => Fx::dot3_overflow(p0, p1, p2),
        }
    }

    #[inline]
    fn unit_scale(m: Fx) -> Fx {
        if m.0 <= 0 || m.special() {
            return Fx::ONE;
        }
        // Shift the leading one to bit 15 (m in [0.5, 1)), at most 2^14 (the format's limit).
        let msb = 31 - m.0.leading_zeros() as i32;
        let s = (15 - msb).clamp(0, 14);
        Fx(ONE_RAW << s)
    }

    #[inline(always)]
    fn from_f32(v: f32) -> Fx {
        Fx::from_f64(v as f64)
    }
    #[inline]
    fn from_f64(v: f64) -> Fx {
        if v.is_nan() {
            return Fx::NAN;
        }
        let s = v * ONE_RAW as f64;
        // Round half away from zero, then saturate to an infinity.
        let r = if s >= 0.0 { s + 0.5 } else { s - 0.5 };
        if r >= MAX_RAW as f64 + 1.0 {
            Fx::INFINITY
        } else if r <= -(MAX_RAW as f64) - 1.0 {
            Fx::NEG_INFINITY
        } else {
            Fx(r as i32)
        }
    }
    #[inline(always)]
    fn from_i32(v: i32) -> Fx {
        Fx::from_wide((v as i64) << FRAC_BITS)
    }
    #[inline(always)]
    fn from_stored(bits: u32) -> Fx {
        Fx(bits as i32)
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
    fn epsilon() -> Fx {
        Fx(1)
    }
    #[inline]
    fn sqrt(self) -> Fx {
        // Negative numbers, -inf and NaN (its raw value is negative too).
        if self.0 < 0 {
            return Fx::NAN;
        }
        if self.0 == INF_RAW {
            return self;
        }
        // sqrt(r / 2^16) * 2^16 = sqrt(r * 2^16).
        Fx(Fx::isqrt_rounded((self.0 as u64) << FRAC_BITS) as i32)
    }
    #[inline(always)]
    fn abs(self) -> Fx {
        if self.0 < 0 {
            -self
        } else {
            self
        }
    }
    #[inline]
    fn floor(self) -> Fx {
        if self.special() {
            self
        } else {
            Fx(self.0 & !(ONE_RAW - 1))
        }
    }
    fn powf(self, e: Fx) -> Fx {
        if self.special() || e.special() {
            return Fx::from_f64(libm::pow(self.to_f64(), e.to_f64()));
        }
        if self.0 < 0 {
            return Fx::NAN;
        }
        if self.0 == 0 {
            return if e.0 > 0 { Fx(0) } else { Fx::NAN };
        }
        if e.0 == 0 {
            return Fx::ONE;
        }
        // e * log2(x) with 30 fraction bits (a Q16 exponent would lose 120 * 2^-17).
        let p = (e.0 as i128 * self.log2_q30() as i128) >> FRAC_BITS;
        if p > (40i128 << 30) {
            return Fx::INFINITY;
        }
        if p < -(40i128 << 30) {
            return Fx(0);
        }
        Fx::exp2_q30(p as i64)
    }
    fn atan2(self, x: Fx) -> Fx {
        let y = self;
        if y.special() || x.special() {
            return Fx::from_f64(libm::atan2(y.to_f64(), x.to_f64()));
        }
        if x.0 == 0 && y.0 == 0 {
            return Fx(0);
        }
        let (ax, ay) = (x.abs(), y.abs());
        let a = if ax >= ay {
            Fx::atan_unit(ay / ax)
        } else {
            Fx(Fx::PI.0 / 2) - Fx::atan_unit(ax / ay)
        };
        let a = if x.0 < 0 { Fx::PI - a } else { a };
        if y.0 < 0 {
            -a
        } else {
            a
        }
    }
    fn acos(self) -> Fx {
        if !self.is_finite() || self.abs() > Fx::ONE {
            return Fx::NAN;
        }
        (Fx::ONE - self * self).sqrt().atan2(self)
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
    fn next_up(self) -> Fx {
        if self.special() || self.0 == MAX_RAW {
            self
        } else {
            Fx(self.0 + 1)
        }
    }
    #[inline]
    fn next_down(self) -> Fx {
        if self.special() || self.0 == -MAX_RAW {
            self
        } else {
            Fx(self.0 - 1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dot3_of_large_vectors_saturates_instead_of_wrapping() {
        // Found by the image fuzzer (an ellipsoid with coordinates near the format's limit):
        // three products of nearly 2^62 each overflowed the i64 sum.
        let m = Fx::MAX;
        let big = [m, m, m];
        assert_eq!(Fx::dot3(big, big).raw(), Fx::INFINITY.raw());
        assert_eq!(Fx::dot3(big, [-m, -m, -m]).raw(), Fx::NEG_INFINITY.raw());
        // The first two products overflow, the third brings the sum back to 2^62: still
        // far beyond the range.
        assert_eq!(Fx::dot3([m, m, -m], big).raw(), Fx::INFINITY.raw());
        // In range, the one rounding of the exact sum as before.
        let h = Fx::from_f64(100.0);
        assert_eq!(
            Fx::dot3([h, h, -h], [h, h, h]).raw(),
            Fx::from_f64(10000.0).raw()
        );
        let e = Fx::from_raw(3);
        assert_eq!(Fx::dot3([e, e, e], [Fx::HALF; 3]).raw(), 5);
    }

    fn fx(v: f64) -> Fx {
        Fx::from_f64(v)
    }

    #[test]
    fn arithmetic_rounds_to_nearest() {
        assert_eq!((fx(1.5) + fx(-0.25)).to_f64(), 1.25);
        assert_eq!((fx(1.5) * fx(-0.25)).to_f64(), -0.375);
        assert_eq!((fx(1.5) / fx(-0.25)).to_f64(), -6.0);
        // 1/3 = 21845.33 steps -> 21845.
        assert_eq!((Fx::ONE / fx(3.0)).raw(), 21_845);
        // 2/3 = 43690.67 steps -> 43691.
        assert_eq!((Fx::TWO / fx(3.0)).raw(), 43_691);
        // Products: 0.5 step * 1 rounds up (half away... to +inf for positive).
        assert_eq!((Fx::from_raw(1) * Fx::HALF).raw(), 1);
        assert_eq!((Fx::from_raw(3) * Fx::HALF).raw(), 2);
    }

    #[test]
    fn overflow_becomes_infinity_never_wraps() {
        let big = fx(30_000.0);
        assert_eq!(big + big, Fx::INFINITY);
        assert_eq!(-big - big, Fx::NEG_INFINITY);
        assert_eq!(big * fx(2.0), Fx::INFINITY);
        assert_eq!(big * fx(-2.0), Fx::NEG_INFINITY);
        assert_eq!(big / fx(0.5), Fx::INFINITY);
        assert_eq!(Fx::ONE / Fx::ZERO, Fx::INFINITY);
        assert_eq!(-Fx::ONE / Fx::ZERO, Fx::NEG_INFINITY);
        assert!(!(big * big).is_finite());
        assert_eq!(Fx::from_i32(40_000), Fx::INFINITY);
        assert_eq!(fx(1e9), Fx::INFINITY);
        // Still finite right at the edge.
        assert!((fx(16_000.0) + fx(16_000.0)).is_finite());
        assert_eq!((fx(181.0) * fx(181.0)).to_f64(), 32_761.0);
    }

    #[test]
    fn invalid_operations_give_nan_and_nan_propagates() {
        for v in [
            Fx::INFINITY - Fx::INFINITY,
            Fx::ZERO * Fx::INFINITY,
            Fx::ZERO / Fx::ZERO,
            fx(-1.0).sqrt(),
            Fx::NAN + Fx::ONE,
            Fx::NAN * Fx::ZERO,
            fx(-2.0).acos(),
        ] {
            assert!(v.is_nan(), "{v:?}");
            assert!(v != v);
            assert_eq!(v.partial_cmp(&Fx::ONE), None);
            assert!(v.partial_cmp(&v).is_none());
            assert!((v < Fx::ONE, v > Fx::ONE, v >= Fx::ONE) == (false, false, false));
        }
        assert_eq!(Fx::INFINITY + Fx::INFINITY, Fx::INFINITY);
        assert_eq!(Fx::ONE / Fx::INFINITY, Fx::ZERO);
        assert!(Fx::NEG_INFINITY < Fx::MAX.neg() && Fx::MAX < Fx::INFINITY);
    }

    #[test]
    fn sqrt_is_correctly_rounded() {
        let mut x = 1u32;
        while x < i32::MAX as u32 - 2 {
            let v = Fx::from_raw(x as i32);
            let exact = (x as f64 * 65536.0).sqrt().round();
            assert_eq!(v.sqrt().raw() as f64, exact, "sqrt of raw {x}");
            x = x.saturating_mul(3) / 2 + 7;
        }
        assert_eq!(fx(4.0).sqrt().to_f64(), 2.0);
        assert_eq!(Fx::ZERO.sqrt(), Fx::ZERO);
    }

    #[test]
    fn transcendental_functions_within_stated_bounds() {
        let (mut worst_pow, mut worst_atan2, mut worst_acos) = (0f64, 0f64, 0f64);
        for i in 1..1000 {
            let c = i as f64 / 1000.0;
            for n in [1.5, 5.0, 20.0, 40.0, 120.0] {
                // Against the exact power of the quantised input (x^120 amplifies the
                // input's own rounding 120-fold; that is the format, not powf).
                let e = fx(c).to_f64().powf(n);
                let got = fx(c).powf(fx(n)).to_f64();
                worst_pow = worst_pow.max((got - e).abs());
            }
            let x = c * 2.0 - 1.0;
            worst_acos = worst_acos.max((fx(x).acos().to_f64() - fx(x).to_f64().acos()).abs());
            for j in 0..20 {
                let ang = j as f64 * 0.33;
                let (y, xx) = (ang.sin() * c, ang.cos() * c);
                let got = fx(y).atan2(fx(xx)).to_f64();
                let exact = fx(y).to_f64().atan2(fx(xx).to_f64());
                let mut d = (got - exact).abs();
                if d > core::f64::consts::PI {
                    d = 2.0 * core::f64::consts::PI - d;
                }
                worst_atan2 = worst_atan2.max(d);
            }
        }
        // Absolute errors against the exact function of the quantised inputs (a step is
        // 1.5e-5); acos near +-1 amplifies the square root's last step.
        assert!(worst_pow < 1e-4, "powf {worst_pow}");
        assert!(worst_atan2 < 1e-4, "atan2 {worst_atan2}");
        assert!(worst_acos < 2e-3, "acos {worst_acos}");
        assert_eq!(fx(2.0).powf(fx(3.0)).to_f64(), 8.0);
    }

    #[test]
    fn dot3_rounds_once_and_overflows_to_infinity() {
        let third = Fx::from_raw(21_845); // ~1/3
        let a = [third; 3];
        let b = [Fx::from_raw(1); 3];
        // Each product is 0.33 of a step (rounds to 0); the exact sum is 1 step.
        assert_eq!(Fx::dot3(a, b).raw(), 1);
        assert_eq!((a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).raw(), 0);
        let big = [fx(150.0); 3];
        assert_eq!(Fx::dot3(big, big), Fx::INFINITY);
        assert!(Fx::dot3([Fx::NAN, Fx::ONE, Fx::ONE], big).is_nan());
        assert_eq!(
            Fx::dot3([fx(2.0), fx(-3.0), fx(0.5)], [fx(1.0), fx(1.0), fx(4.0)]).to_f64(),
            1.0
        );
    }

    #[test]
    fn floor_and_steps() {
        assert_eq!(fx(-1.25).floor().to_f64(), -2.0);
        assert_eq!(fx(1.75).floor().to_f64(), 1.0);
        assert_eq!(Fx::ONE.next_up().raw(), ONE_RAW + 1);
        assert_eq!(Fx::ONE.next_down().raw(), ONE_RAW - 1);
        assert_eq!(Fx::INFINITY.next_down(), Fx::INFINITY);
    }
}
