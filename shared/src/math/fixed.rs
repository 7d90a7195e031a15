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

#[cfg(feature = "fx-checked")]
use super::overflow;
use super::overflow::Kind;
use crate::num::Real;
use core::cmp::Ordering;
use core::fmt;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

#[cfg(test)]
#[path = "fixed_reference.rs"]
mod reference;

#[path = "fixed_eye.rs"]
mod eye;
pub use eye::{FxEyePlanes, EYE_PLANE_BITS, EYE_VERTEX_LIMIT};

/// `r`, the result of a `kind` operation on `inputs`, as the checked build counts it
/// ([`Fx::checked`]); just `r` without the `fx-checked` feature, so the default build's
/// operators are exactly what they were (not even a call for the inliner to weigh).
macro_rules! checked {
    ($kind:expr, $inputs:expr, $r:expr $(,)?) => {{
        #[cfg(feature = "fx-checked")]
        let r = Fx::checked($kind, $inputs, $r);
        #[cfg(not(feature = "fx-checked"))]
        let (_, r): (Kind, Fx) = ($kind, $r);
        r
    }};
}

/// A conversion's result as the checked build counts it ([`Fx::checked_conversion`]).
macro_rules! checked_conversion {
    ($finite:expr, $r:expr $(,)?) => {{
        #[cfg(feature = "fx-checked")]
        let r = Fx::checked_conversion($finite, $r);
        #[cfg(not(feature = "fx-checked"))]
        let r = $r;
        r
    }};
}

/// Fraction bits.
pub const FRAC_BITS: u32 = 16;
const ONE_RAW: i32 = 1 << FRAC_BITS;
/// Up to this `n`, Q16.16's `err_gamma(n)` is `n` steps (see its doc).
const GAMMA_EXACT: i32 = 180;
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
    ///
    /// One compare of the high word against the low word's sign decides whether `v` fits
    /// an i32; inside the i32 range the only values outside the finite range are
    /// `i32::MAX` (which already is [`INF_RAW`]) and `i32::MIN`, `i32::MIN + 1` (both
    /// become [`NEG_INF_RAW`], the larger of the two): a `max`.
    /// The rare overflow is a cold call, so the common case is one compare and a branch
    /// not taken.
    #[inline(always)]
    fn from_wide(v: i64) -> Fx {
        let lo = v as i32;
        if (v >> 32) as i32 == lo >> 31 {
            Fx(lo.max(NEG_INF_RAW))
        } else {
            Fx::wide_overflow(v)
        }
    }

    /// One row of [`Real::local_mat_vec`]: `m · p` for the Q24 point `p` (finite `rel`,
    /// `dir`, `tc`), summed in Q40 and rounded once, saturated to an infinity beyond the
    /// range. In 64 bits while the point is under 128 (`p_small`) and the row under 4096
    /// (each product below 2^59), else in 128 bits. A row with a special entry takes the
    /// Q16.16 point.
    #[inline(always)]
    fn local_row(m: [Fx; 3], p: [i64; 3], p_small: bool, rel: [Fx; 3], dir: [Fx; 3], tc: Fx) -> Fx {
        if m.iter().any(|v| v.special()) {
            return Fx::dot3(
                m,
                [
                    rel[0] + dir[0] * tc,
                    rel[1] + dir[1] * tc,
                    rel[2] + dir[2] * tc,
                ],
            );
        }
        if p_small && m.iter().all(|v| v.0.unsigned_abs() < 1 << 28) {
            // 32-bit factors (no 64-bit multiply call on ARMv6-M), and the sum (below
            // 2^61) rounded in 64 bits: the same value as the 128-bit path, without its
            // four-word adds and shifts.
            let mp = |i: usize| wide::mul_i32(m[i].0, p[i] as i32);
            return Fx::from_wide((mp(0) + mp(1) + mp(2) + (1 << 23)) >> 24);
        }
        let s: i128 = (0..3).map(|i| m[i].0 as i128 * p[i] as i128).sum();
        let r = (s + (1 << 23)) >> 24;
        match i64::try_from(r) {
            Ok(v) => Fx::from_wide(v),
            Err(_) => Fx::wide_overflow(if r < 0 { -1 } else { 1 }),
        }
    }

    /// `r`, the result of a `kind` operation on `inputs`, as the checked build sees it: a
    /// non-finite result from finite inputs is counted ([`overflow`]). Nothing without the
    /// `fx-checked` feature.
    #[cfg(feature = "fx-checked")]
    #[inline(always)]
    #[track_caller]
    fn checked<const N: usize>(kind: Kind, inputs: [Fx; N], r: Fx) -> Fx {
        if r.special() && !inputs.iter().any(|x| x.special()) {
            overflow::record(if r.is_nan() { Kind::Invalid } else { kind });
        }
        r
    }

    /// A conversion's result as the checked build sees it: a finite input (`finite`) that
    /// gave a non-finite value is counted.
    #[cfg(feature = "fx-checked")]
    #[inline(always)]
    #[track_caller]
    fn checked_conversion(finite: bool, r: Fx) -> Fx {
        if finite && r.special() {
            overflow::record(Kind::Conversion);
        }
        r
    }

    /// The product, saturated to an infinity beyond the range (not counted: see
    /// [`Real::mul_beyond`]).
    #[inline(always)]
    fn mul_saturating(self, o: Fx) -> Fx {
        if self.special() || o.special() {
            self.mul_special(o)
        } else if wide::HALVES {
            Fx::mul_finite_halves(self.0, o.0)
        } else {
            Fx::from_wide(wide::mul_q16(self.0, o.0))
        }
    }

    /// The dot product of finite raw values, rounded once. Three exact products below
    /// 2^62 each; their sum fits an i64 unless it is far beyond the format (then an
    /// infinity).
    #[inline(always)]
    fn dot3_finite(a: [i32; 3], b: [i32; 3]) -> Fx {
        let (p0, p1, p2) = (
            wide::mul_i32(a[0], b[0]),
            wide::mul_i32(a[1], b[1]),
            wide::mul_i32(a[2], b[2]),
        );
        match p0.checked_add(p1).and_then(|s| s.checked_add(p2)) {
            Some(p) => Fx::from_wide(p.saturating_add(1 << (FRAC_BITS - 1)) >> FRAC_BITS),
            None => Fx::dot3_overflow(p0, p1, p2),
        }
    }

    /// [`Fx::dot3_finite`] on a core without a 32x32->64 multiply: 32-bit steps when they
    /// all fit, else the 64-bit path (out of line).
    #[inline(always)]
    fn dot3_finite_halves(a: [i32; 3], b: [i32; 3]) -> Fx {
        match wide::dot3_q16_i32(a, b) {
            Some(p) => Fx(p.max(NEG_INF_RAW)),
            None => Fx::dot3_finite_wide(a, b),
        }
    }

    #[cold]
    #[inline(never)]
    fn dot3_finite_wide(a: [i32; 3], b: [i32; 3]) -> Fx {
        Fx::dot3_finite(a, b)
    }

    /// The product of two finite raw values on a core without a 32x32->64 multiply: in
    /// 32-bit steps when they all fit (the common case), else through the 64-bit product.
    #[inline(always)]
    fn mul_finite_halves(a: i32, b: i32) -> Fx {
        match wide::mul_q16_i32(a, b) {
            Some(p) => Fx(p.max(NEG_INF_RAW)),
            None => Fx::mul_finite_wide(a, b),
        }
    }

    /// The rare products whose 32-bit steps overflow (out of line).
    #[cold]
    #[inline(never)]
    fn mul_finite_wide(a: i32, b: i32) -> Fx {
        Fx::from_wide(wide::mul_q16(a, b))
    }

    /// The infinity of `v`'s sign (`v` is outside the i32 range).
    #[cold]
    #[inline(never)]
    fn wide_overflow(v: i64) -> Fx {
        if v < 0 {
            Fx::NEG_INFINITY
        } else {
            Fx::INFINITY
        }
    }

    /// The sum of two finite raw values: an i32 add whose overflow flag picks the infinity
    /// (the sum of two finite values is within twice the range, so its sign is the
    /// operands' sign when it overflows).
    #[inline(always)]
    fn add_finite(a: i32, b: i32) -> Fx {
        match a.checked_add(b) {
            Some(s) => Fx(s.max(NEG_INF_RAW)),
            None => Fx::sum_overflow(a),
        }
    }

    /// The difference of two finite raw values, `a + (-b)` (see [`Fx::add_finite`]).
    #[inline(always)]
    fn sub_finite(a: i32, b: i32) -> Fx {
        match a.checked_sub(b) {
            Some(s) => Fx(s.max(NEG_INF_RAW)),
            None => Fx::sum_overflow(a),
        }
    }

    /// The infinity of `a`'s sign: a sum of two finite values of `a`'s sign overflowed.
    #[cold]
    #[inline(never)]
    fn sum_overflow(a: i32) -> Fx {
        if a < 0 {
            Fx::NEG_INFINITY
        } else {
            Fx::INFINITY
        }
    }

    /// `+-mag`, or the infinity of that sign from `MAX_RAW + 1` up.
    #[inline(always)]
    fn from_sign_magnitude(negative: bool, mag: u32) -> Fx {
        // INF_RAW is MAX_RAW + 1, and NEG_INF_RAW its negation.
        let m = mag.min(INF_RAW as u32) as i32;
        Fx(if negative { -m } else { m })
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
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn add(self, o: Fx) -> Fx {
        let r = if self.special() || o.special() {
            self.add_special(o)
        } else {
            Fx::add_finite(self.0, o.0)
        };
        checked!(Kind::Sum, [self, o], r)
    }
}

impl Sub for Fx {
    type Output = Fx;
    #[inline(always)]
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn sub(self, o: Fx) -> Fx {
        // The same as self + (-o): an i32 subtract instead of a negation and an add.
        let r = if self.special() || o.special() {
            self.add_special(-o)
        } else {
            Fx::sub_finite(self.0, o.0)
        };
        checked!(Kind::Sum, [self, o], r)
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
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn mul(self, o: Fx) -> Fx {
        checked!(Kind::Product, [self, o], self.mul_saturating(o))
    }
}

impl Div for Fx {
    type Output = Fx;
    #[inline(always)]
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn div(self, o: Fx) -> Fx {
        let r = if self.special() || o.special() || o.0 == 0 {
            self.div_special(o)
        } else {
            // Quotient of magnitudes, rounded to nearest, at most MAX_RAW + 1 (= INF_RAW,
            // whose negation is NEG_INF_RAW), then the sign.
            let q = wide::div_q16(self.0.unsigned_abs(), o.0.unsigned_abs()) as i32;
            Fx(if (self.0 < 0) != (o.0 < 0) { -q } else { q })
        };
        checked!(Kind::Quotient, [self, o], r)
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
    const INFINITY: Fx = Fx(INF_RAW);
    /// pi rounded to the nearest step.
    const PI: Fx = Fx(205_887);
    const STORAGE: crate::num::Storage = crate::num::Storage::Q16_16;
    const ABSOLUTE_ROUNDING: bool = true;
    /// Integer planes ([`FxEyePlanes`]): exact products of the raw vertices, one scale for
    /// every plane, one rounding bound per ray.
    type EyePlanes = FxEyePlanes;
    const EYE_PLANES_EMPTY: FxEyePlanes = FxEyePlanes::UNDECIDED;

    #[inline]
    fn eye_planes(tri: &crate::math::solid::Triangle<Fx>, index: [u32; 3], _l1: Fx) -> FxEyePlanes {
        FxEyePlanes::new(tri, index)
    }

    #[inline(always)]
    fn eye_test(
        planes: &FxEyePlanes,
        d: crate::geom::Vec3<Fx>,
        len: Fx,
        t_max: Fx,
    ) -> crate::shape::triangle::EyeTest<Fx> {
        planes.test(d, len, t_max)
    }

    // Always inlined as `Vec3::sub` is (see there): 2% of the M3's photo1 frame.
    #[cfg_attr(all(target_arch = "arm", not(target_has_atomic = "32")), inline)]
    #[cfg_attr(
        not(all(target_arch = "arm", not(target_has_atomic = "32"))),
        inline(always)
    )]
    #[cfg_attr(feature = "fx-checked", track_caller)]
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
        let (ra, rb) = (a.map(Fx::raw), b.map(Fx::raw));
        let r = if wide::HALVES {
            Fx::dot3_finite_halves(ra, rb)
        } else {
            Fx::dot3_finite(ra, rb)
        };
        checked!(Kind::Product, [a[0], a[1], a[2], b[0], b[1], b[2]], r)
    }

    /// `v / |v|` from the integers: the components shifted (exactly, or by at most one bit
    /// from the top of the range) so the largest magnitude is in [2^22, 2^23), their exact
    /// sum of squares (below 2^48), its rounded square root `L` (23 to 24 significant bits),
    /// a 32-bit reciprocal `R = floor(2^53 / L)` ([`wide::recip_2p53`]) and each quotient
    /// `w * R / 2^37` rounded once. Each component is then within half a step of the exact
    /// `v_i / |v|` plus 2^-6 step (2^-7 each from the shift's and the root's rounding),
    /// whatever `|v|` is: a vector of length 34 keeps its unit vector's length to 1.5e-5
    /// (the reciprocal 1 / 34 in Q16.16 is off by 2.6e-4 of itself, and so was the length).
    fn normalize3(v: [Fx; 3]) -> Option<[Fx; 3]> {
        if v.iter().any(|c| c.special()) {
            return None;
        }
        let m = v.iter().map(|c| c.0.unsigned_abs()).max().unwrap_or(0);
        if m == 0 {
            return None;
        }
        // Top bit of m at 22: shift left by up to 22, or right by up to 9 (rounded; the
        // direction changes by at most 2^-23 relative).
        let top = 31 - m.leading_zeros() as i32;
        let shift = |c: Fx| {
            let r = c.0 as i64;
            if top <= 22 {
                r << (22 - top)
            } else {
                let sh = top - 22;
                (r + (1 << (sh - 1))) >> sh
            }
        };
        // Element by element, not `map` (see `dot3`).
        let w = [shift(v[0]), shift(v[1]), shift(v[2])];
        // |w| < 2^23: 32-bit factors (no 64-bit multiply call on ARMv6-M).
        let sum: u64 = w
            .iter()
            .map(|&x| wide::mul_i32(x as i32, x as i32) as u64)
            .sum();
        let l = wide::isqrt_rounded(sum) as u64; // in [2^22, 2^24)
        let r = wide::recip_2p53(l as u32); // at most 2^31
        let unit = |x: i64| {
            let mag = (wide::mul_u32(x.unsigned_abs() as u32, r) + (1 << 36)) >> 37; // <= 2^16 + 1
            let mag = mag.min(ONE_RAW as u64) as i32;
            Fx(if x < 0 { -mag } else { mag })
        };
        Some([unit(w[0]), unit(w[1]), unit(w[2])])
    }

    /// The three 2x2 determinants exactly (each product of two raw values is below 2^62,
    /// their difference below 2^63), then one power of two for all three so the largest
    /// magnitude is in [2^21, 2^22) raw, rounded to nearest; a nonzero value never rounds
    /// to zero (it becomes one step of its sign), so every sign is exact: neighbouring
    /// triangles, which compute their shared edge's function from the same two vertices,
    /// see exactly opposite signs (watertight), and a zero is an exact zero.
    #[inline(always)]
    fn edge_functions(x: [Fx; 3], y: [Fx; 3]) -> ([Fx; 3], i32) {
        if x.iter().chain(&y).any(|c| c.special()) {
            return ([Fx::NAN; 3], 0);
        }
        let cross =
            |j: usize, k: usize| wide::mul_i32(x[j].0, y[k].0) - wide::mul_i32(y[j].0, x[k].0);
        let e = [cross(1, 2), cross(2, 0), cross(0, 1)];
        let m = e.iter().map(|v| v.unsigned_abs()).max().unwrap_or(0);
        if m == 0 {
            return ([Fx(0); 3], 0);
        }
        // e (Q32) = e' (Q16 raw) * 2^sh, so e in real units is e' * 2^(sh - 16).
        let sh = (63 - m.leading_zeros() as i32) - 21;
        let scale = |v: i64| {
            let r = if sh > 0 {
                (v + (1 << (sh - 1))) >> sh
            } else {
                v << -sh
            };
            let r = if r == 0 { v.signum() } else { r };
            Fx(r as i32)
        };
        // Element by element, not `map` (see `dot3`).
        (
            [scale(e[0]), scale(e[1]), scale(e[2])],
            sh - FRAC_BITS as i32,
        )
    }

    /// Exact products, their difference exact in 64 bits, one rounding from Q32 to Q23
    /// (Q16.16 raw times 2^7), saturated to an infinity beyond the range.
    #[inline(always)]
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn cross_fine(a: Fx, b: Fx, c: Fx, d: Fx) -> Fx {
        if a.special() || b.special() || c.special() || d.special() {
            return a * b - c * d;
        }
        let v = wide::mul_i32(a.0, b.0) - wide::mul_i32(c.0, d.0);
        checked!(
            Kind::Product,
            [a, b, c, d],
            Fx::from_wide((v + (1 << 8)) >> 9),
        )
    }

    /// The point in Q24 (`rel` exact, `dir tc` rounded from Q32), formed once; each row's
    /// products with it in Q40, summed and rounded once ([`Fx::local_row`]).
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn local_mat_vec(m: [[Fx; 3]; 3], rel: [Fx; 3], dir: [Fx; 3], tc: Fx) -> [Fx; 3] {
        if rel.iter().chain(&dir).any(|v| v.special()) || tc.special() {
            let p = [
                rel[0] + dir[0] * tc,
                rel[1] + dir[1] * tc,
                rel[2] + dir[2] * tc,
            ];
            return [Fx::dot3(m[0], p), Fx::dot3(m[1], p), Fx::dot3(m[2], p)];
        }
        // Below 2^39 + 2^54: fits an i64.
        let point =
            |i: usize| ((rel[i].0 as i64) << 8) + ((wide::mul_i32(dir[i].0, tc.0) + (1 << 7)) >> 8);
        // Element by element, not `map` (see `dot3`).
        let p = [point(0), point(1), point(2)];
        let p_small = p.iter().all(|v| v.unsigned_abs() < 1 << 31);
        let row = |r: [Fx; 3]| {
            let out = Fx::local_row(r, p, p_small, rel, dir, tc);
            checked!(
                Kind::Product,
                [r[0], r[1], r[2], rel[0], rel[1], rel[2], dir[0], dir[1], dir[2], tc],
                out,
            )
        };
        [row(m[0]), row(m[1]), row(m[2])]
    }

    /// In 64-bit integers: `q = c + d s` in Q32 (exact), the residual in Q48 as
    /// `(|c|² - 1) 2^16 + 2 s (c·d) + s² |d|² / 2^16` (the last term rounded, 2^-48), the
    /// slope `2 q·d` in Q32 (rounded from Q48), the step rounded to Q16.
    fn sphere_newton(c: [Fx; 3], d: [Fx; 3], s: Fx) -> Fx {
        if c.iter().chain(&d).any(|v| v.special()) || s.special() {
            return s;
        }
        // A root's inputs are a few units at most (a unit-frame point near the sphere, a
        // unit direction, a parameter within a chord): with |c|, |s| below 16 and |d| below
        // 4 every sum below stays under 2^62.
        let below = |v: Fx, bits: u32| v.0.unsigned_abs() < 1 << bits;
        if !(c.iter().all(|&v| below(v, 20)) && d.iter().all(|&v| below(v, 18)) && below(s, 20)) {
            return s;
        }
        // Products of two raw values in 32-bit factors (no 64-bit multiply call on ARMv6-M).
        let dot =
            |a: [Fx; 3], b: [Fx; 3]| -> i64 { (0..3).map(|i| wide::mul_i32(a[i].0, b[i].0)).sum() };
        let (cc, cd, dd) = (dot(c, c), dot(c, d), dot(d, d)); // Q32
        let s64 = s.0 as i64; // Q16
        let s2 = wide::mul_i32(s.0, s.0); // Q32
                                          // s² |d|²: Q64, below 2^96 here; in two halves to stay in i64.
        let s2dd = ((s2 >> 16) * dd) + (((s2 & 0xffff) * dd) >> 16); // Q48
        let r = ((cc - (1i64 << 32)) << 16) + 2 * s64 * cd + s2dd; // Q48
                                                                   // q·d = c·d + s |d|²: Q32 + (Q16 Q32 = Q48) >> 16.
        let qd = cd + ((s64 * dd) >> 16); // Q32
        let g = 2 * qd; // Q32
        if g.unsigned_abs() < 1 << 24 {
            return s; // slope under 2^-8
        }
        // r / g is Q16; rounded to nearest.
        let num = r;
        let den = g;
        let step = (num.abs() + den.abs() / 2) / den.abs();
        let step = if (num < 0) != (den < 0) { -step } else { step };
        if step.unsigned_abs() > 64 {
            return s;
        }
        Fx(s.0 - step as i32)
    }

    /// `self * 2^k`, rounded to nearest, saturated to an infinity beyond the range.
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn mul_pow2(self, k: i32) -> Fx {
        if self.special() || k == 0 {
            return self;
        }
        let v = self.0 as i64;
        if k > 0 {
            let r = if k >= 32 {
                if v > 0 {
                    Fx::INFINITY
                } else {
                    Fx::NEG_INFINITY
                }
            } else {
                Fx::from_wide(v << k)
            };
            checked!(Kind::Conversion, [self], r)
        } else if k <= -33 {
            Fx(0)
        } else {
            Fx::from_wide((v + (1 << (-k - 1))) >> -k)
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

    /// Exactly `from_f64(v as f64)`, from the f32's bits (no float arithmetic: the M3
    /// and M0 have no FPU).
    #[inline]
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn from_f32(v: f32) -> Fx {
        let bits = v.to_bits();
        let exp = (bits >> 23) & 0xff;
        let frac = bits & ((1 << 23) - 1);
        if exp == 0xff && frac != 0 {
            return Fx::NAN;
        }
        // s = |v| * 2^16 = m * 2^(exp - 134); at or above 2^31 (|v| >= 2^15, infinities
        // included) it saturates, below 1/2 (|v| < 2^-17, subnormals included) it rounds
        // to 0 (the f64 sum s + 0.5 is exact for every such f32 s, so no tie rounds up).
        let mag = if exp >= 142 {
            INF_RAW as u32
        } else if exp <= 109 {
            0
        } else if exp >= 134 {
            // A whole number of steps below 2^31.
            (frac | 1 << 23) << (exp - 134)
        } else {
            let k = 134 - exp;
            ((frac | 1 << 23) + (1 << (k - 1))) >> k
        };
        checked_conversion!(exp != 0xff, Fx::from_sign_magnitude(bits >> 31 != 0, mag))
    }
    /// `v * 2^16` rounded half away from zero, saturated to an infinity; from the f64's
    /// bits (the same result as that float arithmetic, including the one input where the
    /// float sum `s + 0.5` rounds up to 1: see below).
    #[inline]
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn from_f64(v: f64) -> Fx {
        let bits = v.to_bits();
        let exp = ((bits >> 52) & 0x7ff) as u32;
        let frac = bits & ((1 << 52) - 1);
        if exp == 0x7ff && frac != 0 {
            return Fx::NAN;
        }
        // |v| * 2^16 = m * 2^(exp - 1059) with m = frac + 2^52.
        let mag = if exp >= 1038 {
            INF_RAW as u32
        } else if exp <= 1004 {
            // |v| below 2^-18 (subnormals included), so s < 1/4: 0.
            0
        } else {
            let (k, m) = (1059 - exp, frac | 1 << 52);
            if k <= 53 {
                ((m + (1 << (k - 1))) >> k) as u32
            } else {
                // s = m / 2^k < 1/2, so s + 1/2 rounds to 0, except s = 1/2 - 2^-54: the
                // float sum 1 - 2^-54 is a tie between 1 - 2^-53 and 1, and goes to the
                // even one, 1.
                (k == 54 && m == (1 << 53) - 1) as u32
            }
        };
        checked_conversion!(exp != 0x7ff, Fx::from_sign_magnitude(bits >> 63 != 0, mag))
    }
    #[inline(always)]
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn from_i32(v: i32) -> Fx {
        checked_conversion!(true, Fx::from_wide((v as i64) << FRAC_BITS))
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
        // One rounding of the same value as `to_f64() as f32` (the i32 to f32 conversion;
        // the power-of-two scale is exact), without the soft-float f64 arithmetic of
        // integer cores.
        match self.0 {
            NAN_RAW => f32::NAN,
            INF_RAW => f32::INFINITY,
            NEG_INF_RAW => f32::NEG_INFINITY,
            r => r as f32 * (1.0 / ONE_RAW as f32),
        }
    }
    /// The default's value in integers: for `r` in [0, 2^16], `r * 255 + 2^15 < 2^24`, so the
    /// f32 formula's product and sum are exact and its truncation is this shift.
    #[inline]
    fn to_unit_u8(self) -> u8 {
        let c = self.clamp01();
        match c.0 {
            r @ 0..=ONE_RAW => ((r as u32 * 255 + ONE_RAW as u32 / 2) >> 16) as u8,
            _ => (c.to_f32() * 255.0 + 0.5) as u8,
        }
    }
    /// gamma(n) = n eps / (1 - n eps) with eps one step: `n / (2^16 - n)` steps rounded to
    /// nearest is `n` itself while `n^2 < 2^15 - n/2`; the generic formula (two products and
    /// a 64-bit division per call) gives the same bits.
    #[inline]
    fn err_gamma(n: i32) -> Fx {
        if (0..=GAMMA_EXACT).contains(&n) {
            Fx(n)
        } else {
            let ne = Fx::from_i32(n) * Fx::epsilon();
            ne / (Fx::ONE - ne)
        }
    }
    /// `ONE / self` (the same bits) with one 32-bit division instead of a 64-bit one: every
    /// primary ray takes four reciprocals (its length, its direction's three for the slab
    /// tests).
    #[inline]
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn recip(self) -> Fx {
        checked!(Kind::Quotient, [self], self.recip_beyond())
    }
    #[inline(always)]
    fn mul_beyond(self, o: Fx) -> Fx {
        self.mul_saturating(o)
    }
    /// The reciprocal, an infinity for zero or beyond the range (not counted).
    #[inline]
    fn recip_beyond(self) -> Fx {
        if self.special() || self.0 == 0 {
            return Fx::ONE.div_special(self);
        }
        let q = wide::recip_q16(self.0.unsigned_abs()) as i32;
        Fx(if self.0 < 0 { -q } else { q })
    }
    /// One step relative to 1.0. Fixed-point rounding is absolute (half a step per
    /// operation), so relative error bounds built from this hold near magnitude 1 and above.
    #[inline(always)]
    fn epsilon() -> Fx {
        Fx(1)
    }
    #[inline]
    #[cfg_attr(feature = "fx-checked", track_caller)]
    fn sqrt(self) -> Fx {
        // Negative numbers, -inf and NaN (its raw value is negative too).
        if self.0 < 0 {
            return checked!(Kind::Invalid, [self], Fx::NAN);
        }
        if self.0 == INF_RAW {
            return self;
        }
        // sqrt(r / 2^16) * 2^16 = sqrt(r * 2^16), below 2^23.5.
        Fx(wide::isqrt_rounded((self.0 as u64) << FRAC_BITS) as i32)
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

/// The integer kernels under [`Fx`]'s arithmetic, written for 32-bit integer cores (issue 14):
/// every function returns exactly what the 64-bit expression in its doc comment gives, but
/// without 64-bit division and, on ARMv6-M (Cortex-M0/M0+: no 32x32->64 multiply, no
/// divide), without the `__aeabi_lmul` call that a 64-bit product costs there.
mod wide {
    use super::FRAC_BITS;

    /// ARMv6-M: no `UMULL`/`SMULL` (a 64-bit product is a library call), so products are
    /// built from 16-bit halves with the 32-bit `MULS`. Everything else (Cortex-M3/M4, the
    /// host) has a single-instruction 32x32->64 multiply. Stable Rust exposes no ARM
    /// target feature to `cfg`; ARMv6-M is the one 32-bit ARM profile without atomic
    /// read-modify-write (LDREX/STREX), which is what `target_has_atomic` reports.
    pub(super) const HALVES: bool = cfg!(all(target_arch = "arm", not(target_has_atomic = "32")));

    /// `a * b` exactly.
    #[inline(always)]
    pub(super) fn mul_i32(a: i32, b: i32) -> i64 {
        if HALVES {
            mul_i32_halves(a, b)
        } else {
            a as i64 * b as i64
        }
    }

    /// `a * b` exactly, from four 16x16-bit products: with `a = ah * 2^16 + al` (`ah`
    /// signed, `al` in `[0, 2^16)`), `a * b = ah*bh * 2^32 + (ah*bl + al*bh) * 2^16 + al*bl`;
    /// each partial product fits 32 bits (|ah*bh| <= 2^30, |ah*bl| < 2^31, al*bl < 2^32).
    #[inline(always)]
    pub(super) fn mul_i32_halves(a: i32, b: i32) -> i64 {
        let (ah, al) = (a >> 16, a & 0xffff);
        let (bh, bl) = (b >> 16, b & 0xffff);
        let hh = ah * bh;
        let cross = (ah * bl) as i64 + (al * bh) as i64;
        let ll = (al as u32).wrapping_mul(bl as u32);
        ((hh as i64) << 32) + (cross << 16) + ll as i64
    }

    /// `a * b` exactly, unsigned.
    #[inline(always)]
    pub(super) fn mul_u32(a: u32, b: u32) -> u64 {
        if HALVES {
            mul_u32_halves(a, b)
        } else {
            a as u64 * b as u64
        }
    }

    /// [`mul_u32`] from four 16x16-bit products (see [`mul_i32_halves`]).
    #[inline(always)]
    pub(super) fn mul_u32_halves(a: u32, b: u32) -> u64 {
        let (ah, al) = (a >> 16, a & 0xffff);
        let (bh, bl) = (b >> 16, b & 0xffff);
        let cross = (ah * bl) as u64 + (al * bh) as u64;
        (((ah * bh) as u64) << 32) + (cross << 16) + (al * bl) as u64
    }

    /// The Q16.16 product of two raw values rounded to nearest (ties up):
    /// `(a * b + 2^15) >> 16`, exact in 64 bits.
    #[inline(always)]
    pub(super) fn mul_q16(a: i32, b: i32) -> i64 {
        (mul_i32(a, b) + (1 << (FRAC_BITS - 1))) >> FRAC_BITS
    }

    /// [`mul_q16`] in 32-bit arithmetic only, when every step fits an i32 (`None`
    /// otherwise: the product is large, or an intermediate overflowed; then the 64-bit
    /// path decides). `(a * b + 2^15) >> 16 = ah*bh * 2^16 + ah*bl + al*bh +
    /// ((al*bl + 2^15) >> 16)`, the first three terms being whole multiples of 2^16 before
    /// the shift.
    #[inline(always)]
    pub(super) fn mul_q16_i32(a: i32, b: i32) -> Option<i32> {
        let (ah, al) = (a >> 16, a & 0xffff);
        let (bh, bl) = (b >> 16, b & 0xffff);
        // ll is at most (2^16 - 1)^2; (ll + 2^15) >> 16 without overflowing is
        // ((ll >> 15) + 1) >> 1.
        let ll = (al as u32) * (bl as u32);
        let low = (((ll >> 15) + 1) >> 1) as i32;
        let c = (ah * bl).checked_add(al * bh)?.checked_add(low)?;
        let hh = ah * bh; // |hh| <= 2^30
        if !(-(1 << 15)..1 << 15).contains(&hh) {
            return None;
        }
        (hh << 16).checked_add(c)
    }

    /// `(a0 b0 + a1 b1 + a2 b2 + 2^15) >> 16` (one rounding of the exact sum) in 32-bit
    /// steps when they all fit, as [`mul_q16_i32`] does for one product; the low
    /// products (up to 2^32 each) are summed as their high and low halves:
    /// `(sum ll + 2^15) >> 16 = sum (ll >> 16) + ((sum (ll & 0xffff) + 2^15) >> 16)`.
    #[inline(always)]
    pub(super) fn dot3_q16_i32(a: [i32; 3], b: [i32; 3]) -> Option<i32> {
        let (mut hh, mut c, mut ll_hi, mut ll_lo) = (0i32, 0i32, 0u32, 0u32);
        for i in 0..3 {
            let (ah, al) = (a[i] >> 16, a[i] & 0xffff);
            let (bh, bl) = (b[i] >> 16, b[i] & 0xffff);
            let ll = (al as u32) * (bl as u32);
            ll_hi += ll >> 16; // three terms below 2^16 each
            ll_lo += ll & 0xffff;
            c = c.checked_add(ah * bl)?.checked_add(al * bh)?;
            hh = hh.checked_add(ah * bh)?;
        }
        let low = (ll_hi + ((ll_lo + (1 << 15)) >> 16)) as i32;
        let c = c.checked_add(low)?;
        if !(-(1 << 15)..1 << 15).contains(&hh) {
            return None;
        }
        (hh << 16).checked_add(c)
    }

    /// The rounded Q16.16 quotient of two magnitudes,
    /// `min(((n << 16) + d / 2) / d, i32::MAX)` for `d != 0`, `n < 2^31`. A numerator
    /// below 2^32 (`n` below 1.0) takes one 32-bit division (UDIV on the M3; on photo1
    /// no numerator is that small, so it did not move the benchmark); the others the
    /// compiler's 64-bit division. (A hand-written 64/32 long division with 16-bit
    /// digits, Hacker's Delight `divlu`, measured 30% slower than `__aeabi_uldivmod` on
    /// the M3, whose compiler-builtins already divides by a 32-bit divisor with UDIV, and
    /// slower on the M0 too; not kept.)
    #[inline]
    pub(super) fn div_q16(n: u32, d: u32) -> u32 {
        let num = ((n as u64) << FRAC_BITS) + (d >> 1) as u64;
        let d = core::num::NonZeroU32::new(d).unwrap_or(core::num::NonZeroU32::MIN);
        let q = match u32::try_from(num) {
            Ok(num) => num / d,
            Err(_) => (num / core::num::NonZeroU64::from(d)).min(i32::MAX as u64) as u32,
        };
        q.min(i32::MAX as u32)
    }

    /// [`div_q16`] of one (`n = 2^16`): `min((2^32 + d / 2) / d, i32::MAX)` for `d != 0`,
    /// by one 32-bit division: `2^32 - 1 = q d + r` (UDIV on the M3), and the rest of the
    /// numerator, `r + 1 + d / 2 < 2d`, adds at most one.
    #[inline]
    pub(super) fn recip_q16(d: u32) -> u32 {
        let d = core::num::NonZeroU32::new(d).unwrap_or(core::num::NonZeroU32::MIN);
        let q = u32::MAX / d;
        let r = u32::MAX - q * d.get();
        let bump = u64::from(r + 1 + (d.get() >> 1) >= d.get());
        (q as u64 + bump).min(i32::MAX as u64) as u32
    }

    /// Initial `1/σ` for `σ = s / 2^32` in `[0.5 + i/256, 0.5 + (i + 1)/256)`, `i` in
    /// `0..128`, at the interval's middle, in Q15: `round(2^24 / (257 + 2i))`.
    const RECIP_SEED: [u16; 128] = {
        let mut t = [0u16; 128];
        let mut i = 0;
        while i < 128 {
            let d = 257 + 2 * i as u32;
            t[i] = (((1u32 << 24) + d / 2) / d) as u16;
            i += 1;
        }
        t
    };

    /// `r ~ 2^62 / s` for `s` in `[2^31, 2^32)` (so `r` in `(2^30, 2^31)`), within a few
    /// units, without a division: a 128-entry seed (`1/σ` to 2^-8) and two Newton steps
    /// `r += r (1 - σ r)`, each squaring the relative error (2^-16, then the format's
    /// 2^-30). Multiplies only (two 32x32->64 products per step).
    #[inline]
    pub(super) fn recip_q62(s: u32) -> u32 {
        let mut r = (RECIP_SEED[((s >> 24) & 127) as usize] as u32) << 15;
        for _ in 0..2 {
            // s r ~ 2^62 (1 - δ), below 2^63; δ 2^32 is below 2^25 in magnitude.
            let p = mul_u32(s, r) as i64;
            let d = ((1i64 << 62) - p) >> 30;
            let step = mul_i32(r as i32, d as i32) >> 32;
            r = (r as i64 + step).clamp(1 << 30, i32::MAX as i64) as u32;
        }
        r
    }

    /// `floor(2^53 / l)` for `l` in `[2^22, 2^24)` ([`Real::normalize3`]'s root), without
    /// the 64-bit software division (`__aeabi_uldivmod`, about 100 instructions on the M3
    /// and more on the M0): [`recip_q62`] of `l` shifted to `[2^31, 2^32)`, then the exact
    /// remainder `2^53 - q l` moves `q` the few units to the floor.
    #[inline]
    pub(super) fn recip_2p53(l: u32) -> u32 {
        let l = l.clamp(1 << 22, (1 << 24) - 1);
        let z = l.leading_zeros(); // 8 or 9
                                   // recip_q62(l 2^z) ~ 2^(62 - z) / l, which is 2^53 / l times 2^(9 - z).
        let mut q = recip_q62(l << z) >> (9 - z);
        let mut rem = (1i64 << 53) - mul_u32(q, l) as i64;
        while rem < 0 {
            q -= 1;
            rem += l as i64;
        }
        while rem >= l as i64 {
            q += 1;
            rem -= l as i64;
        }
        q
    }

    /// Initial `1/sqrt(x)` for `x = (i + 0.5) / 64`, `i` in `16..64` (x in [1/4, 1)), in
    /// Q2.30: `round(2^30 / sqrt((2i + 1) / 128))`, computed at compile time.
    const RSQRT_SEED: [u32; 48] = {
        let mut t = [0u32; 48];
        let mut i = 0;
        while i < 48 {
            // 2^30 * sqrt(128 / (2i + 33)) = sqrt(2^67 / (2i + 33)), rounded.
            let v = (1u128 << 69) / (2 * i as u128 + 33);
            t[i] = v.isqrt().div_ceil(2) as u32;
            i += 1;
        }
        t
    };

    /// `round(sqrt(n))` for `n < 2^48`: the floor root `s`, plus one when `n - s^2 > s`
    /// (`n` is an integer, so there are no ties). A reciprocal square root from a 48-entry
    /// table and two Newton steps (about 25 correct bits, multiplies only) gives an
    /// estimate within a few units; an exact correction on `n - r^2` then finds the one `r`
    /// with `r^2 - r < n <= r^2 + r`, whatever the estimate's error.
    #[inline(never)]
    pub(super) fn isqrt_rounded(n: u64) -> u32 {
        if n == 0 {
            return 0;
        }
        // n = x / 2^(2k) with x's top bit at 62 or 63, a = x's high word in [2^30, 2^32).
        let z = n.leading_zeros() & !1;
        let a = ((n << z) >> 32) as u32;
        let k = z / 2;
        // y ~ 1/sqrt(a / 2^32) in Q2.30; Newton: y' = y * (3 - a y^2) / 2.
        let mut y = RSQRT_SEED[((a >> 26) as usize).saturating_sub(16).min(47)];
        for _ in 0..2 {
            let ay = (mul_u32(a, y) >> 32) as u32; // a/2^32 * y, Q2.30
            let ay2 = (mul_u32(ay, y) >> 30) as u32; // a/2^32 * y^2, Q2.30, ~2^30
            let h = (3u32 << 30).saturating_sub(ay2); // (3 - a y^2), Q2.30
            y = (mul_u32(y, h) >> 31) as u32;
        }
        // sqrt(x) ~ a * y / 2^30 (about 2^32), sqrt(n) = sqrt(x) / 2^k, k >= 8.
        let root_x = mul_u32(a, y) >> 30;
        let r = ((root_x + ((1u64 << k) >> 1)) >> k) as i64;
        round_root(n, r)
    }

    /// The `r` with `r^2 - r < n <= r^2 + r` (the rounded square root of `n`), from an
    /// estimate a few units off: walks `n - r^2` to that window one step at a time.
    #[inline(always)]
    fn round_root(n: u64, r: i64) -> u32 {
        // r < 2^25 and n < 2^48: all of this fits an i64.
        let mut r = r.clamp(0, 1 << 25);
        let mut e = n as i64 - mul_u32(r as u32, r as u32) as i64;
        while e > r {
            // (r + 1)^2 = r^2 + 2r + 1
            e -= 2 * r + 1;
            r += 1;
        }
        while e <= -r {
            e += 2 * r - 1;
            r -= 1;
        }
        r as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Raw values to check conversions on: the special values, the edges of [0, 1], and a
    /// spread of others.
    fn probe_raws() -> impl Iterator<Item = i32> {
        let mut x = 0x9e37_79b9u32;
        let spread = (0..20_000).map(move |_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as i32 >> (x % 24)
        });
        [
            NAN_RAW,
            INF_RAW,
            NEG_INF_RAW,
            MAX_RAW,
            -MAX_RAW,
            0,
            1,
            -1,
            ONE_RAW,
            ONE_RAW - 1,
            ONE_RAW + 1,
            ONE_RAW / 2,
            (1 << 24) + 1,
            -(1 << 24) - 1,
        ]
        .into_iter()
        .chain(-70_000..70_000)
        .chain(spread)
    }

    /// The division-free reciprocal of `normalize3` is the floor quotient for every length
    /// its root can take.
    #[test]
    fn recip_2p53_is_the_floor_quotient() {
        for l in (1u32 << 22)..(1 << 24) {
            assert_eq!(wide::recip_2p53(l) as u64, (1u64 << 53) / l as u64, "{l}");
        }
    }

    /// The shortcuts for integer cores give the generic definitions' bits.
    #[test]
    fn conversions_and_gamma_equal_their_generic_definitions() {
        for r in probe_raws() {
            let v = Fx(r);
            let want = v.to_f64() as f32;
            let got = v.to_f32();
            assert!(
                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                "to_f32 of raw {r}: {got} against {want}"
            );
            let want = (v.clamp01().to_f64() as f32 * 255.0 + 0.5) as u8;
            assert_eq!(v.to_unit_u8(), want, "to_unit_u8 of raw {r}");
        }
        for r in probe_raws() {
            let v = Fx(r);
            assert_eq!(v.recip().0, (Fx::ONE / v).0, "recip of raw {r}");
        }
        for n in -5..=400 {
            let ne = Fx::from_i32(n) * Fx::epsilon();
            let want = ne / (Fx::ONE - ne);
            assert_eq!(Fx::err_gamma(n), want, "gamma({n})");
        }
        // The range the shortcut takes is exactly where the formula gives n steps.
        let ne = Fx::from_i32(GAMMA_EXACT + 1) * Fx::epsilon();
        assert_ne!((ne / (Fx::ONE - ne)).0, GAMMA_EXACT + 1);
    }

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

    /// Unit vectors from vectors of every length the format holds: each component within
    /// half a step (plus 2^-6 step) of the exact `v_i / |v|`, so the length within 1.5
    /// steps of 1 (`v * (1 / |v|)` is off by as much as the reciprocal's rounding, half a
    /// step of `1 / |v|`: up to 17 steps for a primary direction of length 34).
    #[test]
    fn normalize3_rounds_each_component_once() {
        let mut seed = 0x5eed_u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            seed >> 33
        };
        let mut worst = 0f64;
        for k in 0..200_000 {
            // Magnitudes from one step up to the end of the range.
            let bits = (k % 31) as u32;
            let v: [Fx; 3] = core::array::from_fn(|_| {
                let r = (next() as u32 >> (31 - bits)) as i32;
                Fx::from_raw(if next() & 1 == 0 { r } else { -r })
            });
            let Some(u) = Fx::normalize3(v) else {
                assert!(v.iter().all(|c| c.raw() == 0), "{v:?}");
                continue;
            };
            let f: [f64; 3] = v.map(|c| c.raw() as f64);
            let len = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
            for i in 0..3 {
                let exact = f[i] / len * 65536.0;
                let err = (u[i].raw() as f64 - exact).abs();
                worst = worst.max(err);
                assert!(err <= 0.5 + 1.0 / 64.0, "{v:?}: {:?} vs {exact}", u[i]);
            }
        }
        assert!(worst > 0.49, "{worst}");
        // A primary direction of length 34 (the case that motivated it).
        let u = Fx::normalize3([fx(-12.4), fx(11.6), fx(32.0)]).unwrap();
        let l2: f64 = u.iter().map(|c| c.to_f64() * c.to_f64()).sum();
        assert!((l2.sqrt() - 1.0).abs() < 1.5 / 65536.0, "{l2}");
        // What it replaces was that far off.
        let l = Fx::dot3(
            [fx(-12.4), fx(11.6), fx(32.0)],
            [fx(-12.4), fx(11.6), fx(32.0)],
        );
        let r = l.sqrt().recip();
        let old: f64 = [fx(-12.4), fx(11.6), fx(32.0)]
            .iter()
            .map(|&c| (c * r).to_f64().powi(2))
            .sum();
        assert!((old.sqrt() - 1.0).abs() > 3.0 / 65536.0, "{old}");
        // No direction: zero, or a special value anywhere.
        assert!(Fx::normalize3([Fx::ZERO; 3]).is_none());
        assert!(Fx::normalize3([Fx::ONE, Fx::NAN, Fx::ZERO]).is_none());
        assert!(Fx::normalize3([Fx::ONE, Fx::ZERO, Fx::INFINITY]).is_none());
        // Exact where the direction is an axis, at any length.
        for r in [1, 3, 1 << 16, i32::MAX - 1] {
            let u = Fx::normalize3([Fx::ZERO, Fx::from_raw(-r), Fx::ZERO]).unwrap();
            assert_eq!(u.map(Fx::raw), [0, -ONE_RAW, 0]);
        }
    }

    /// One Newton step from a root off by up to 40 steps (6e-4) lands within 0.8 steps of
    /// the exact root of the same (rounded) c and d where the half chord h is 0.05 or more:
    /// half a step of rounding and the step's quadratic error, (6e-4)² / 2h = 0.25 steps.
    #[test]
    fn sphere_newton_refines_a_root_to_its_rounding() {
        let mut seed = 0x1234_5678_u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut worst = 0f64;
        for _ in 0..20_000 {
            // A unit direction, a closest point at distance rho from the centre.
            let d = Fx::normalize3([fx(next() - 0.5), fx(next() - 0.5), fx(next() - 0.5)]).unwrap();
            let df = d.map(|v| v.to_f64());
            let rho = 0.9987 * next(); // half chord >= 0.05
            let (a, b) = (next() - 0.5, next() - 0.5);
            let mut p = [a, b, 0.3];
            let k = p[0] * df[0] + p[1] * df[1] + p[2] * df[2];
            p = [0, 1, 2].map(|i| p[i] - k * df[i]);
            let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            let c = p.map(|v| fx(v / l * rho));
            // The exact roots of the rounded c and d.
            let cf = c.map(|v| v.to_f64());
            let dd: f64 = df.iter().map(|v| v * v).sum();
            let cd: f64 = (0..3).map(|i| cf[i] * df[i]).sum();
            let cc: f64 = cf.iter().map(|v| v * v).sum();
            let disc = cd * cd - dd * (cc - 1.0);
            for sign in [-1.0, 1.0] {
                let root = (-cd + sign * disc.sqrt()) / dd;
                let start = fx(root + (next() - 0.5) * 80.0 / 65536.0);
                let got = Fx::sphere_newton(c, d, start).to_f64();
                let err = (got - root).abs() * 65536.0;
                worst = worst.max(err);
                assert!(err <= 0.8, "{c:?} {d:?}: {got} vs {root} ({err} steps)");
            }
        }
        assert!(worst > 0.4, "{worst}");
        // Declines a slope under 2^-8 (tangent) and inputs out of range.
        let c = [fx(1.0), fx(0.0), fx(0.0)];
        let d = [fx(0.0), fx(1.0), fx(0.0)];
        assert_eq!(Fx::sphere_newton(c, d, fx(0.001)).raw(), fx(0.001).raw());
        assert_eq!(Fx::sphere_newton(c, d, fx(100.0)).raw(), fx(100.0).raw());
    }

    /// Each row of `m (rel + dir tc)` within half a step and the point's 2^-25 per
    /// coordinate (times the row) of the exact value, in both the 64-bit and the 128-bit
    /// range; where the Q16.16 point `rel + dir * tc` carried half a step per coordinate
    /// times the row.
    #[test]
    fn local_mat_vec_keeps_the_point_to_2_pow_minus_24() {
        let mut seed = 99u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut worst, mut worst_q16) = (0f64, 0f64);
        for k in 0..50_000 {
            // Rows of 10,000 take the 128-bit path (one row in three here, the others
            // stay small: each row picks its own path).
            let big = if k % 10 == 0 { 10_000.0 } else { 4.0 };
            let m = [0; 3].map(|r| {
                let scale = if r == 1 { big } else { 4.0 };
                [0; 3].map(|_| fx((next() - 0.5) * 2.0 * scale))
            });
            let reach = if k % 10 == 0 { 0.02 } else { 60.0 };
            let rel = [0; 3].map(|_| fx((next() - 0.5) * reach));
            let dir = Fx::normalize3([0; 3].map(|_| fx(next() - 0.5))).unwrap();
            let tc = fx((next() - 0.5) * reach);
            let f = |v: Fx| v.to_f64();
            let got = Fx::local_mat_vec(m, rel, dir, tc);
            for (r, got) in m.iter().zip(got) {
                let exact: f64 = (0..3)
                    .map(|i| f(r[i]) * (f(rel[i]) + f(dir[i]) * f(tc)))
                    .sum();
                if !got.is_finite() {
                    assert!(exact.abs() > 32_000.0, "{exact}");
                    continue;
                }
                let row: f64 = r.iter().map(|v| f(*v).abs()).sum();
                let err = (got.to_f64() - exact).abs() * 65536.0;
                assert!(err <= 0.5 + row / 512.0 + 1e-6, "{err} steps (row {row})");
                worst = worst.max(err / (0.5 + row / 512.0));
                let q16 = Fx::dot3(
                    *r,
                    [
                        rel[0] + dir[0] * tc,
                        rel[1] + dir[1] * tc,
                        rel[2] + dir[2] * tc,
                    ],
                );
                worst_q16 =
                    worst_q16.max((q16.to_f64() - exact).abs() * 65536.0 / (0.5 + row / 512.0));
            }
        }
        assert!(
            worst > 0.5 && worst_q16 > 10.0 * worst,
            "{worst} {worst_q16}"
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

/// Issue 14: the integer kernels return exactly what the arithmetic before them returned
/// ([`reference::RefFx`], kept verbatim), for every operation, on random raw values and on
/// the edges: zero, one step, the ends of the finite range, the three reserved values,
/// operands whose products and quotients land on rounding ties or just beside them.
#[cfg(test)]
mod same_as_reference {
    use super::reference::RefFx;
    use super::*;

    /// SplitMix64: a fixed sequence, so a failure reproduces.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }
        /// A raw value of a random magnitude class (so small, mid and huge values all
        /// appear, not just ones near 2^31), sometimes an edge value.
        fn raw(&mut self) -> i32 {
            let r = self.next();
            if r.is_multiple_of(8) {
                return EDGES[(r >> 8) as usize % EDGES.len()];
            }
            let bits = (r >> 8) % 32;
            let v = ((r >> 16) as u32 >> (31 - bits)) as i32;
            if r & 0x10 != 0 {
                v.wrapping_neg()
            } else {
                v
            }
        }
    }

    const EDGES: [i32; 24] = [
        0,
        1,
        -1,
        2,
        3,
        0x8000,
        -0x8000,
        ONE_RAW,
        -ONE_RAW,
        ONE_RAW / 2,
        ONE_RAW + 1,
        181 << 16,
        -(181 << 16),
        46_341 << 8,
        MAX_RAW,
        -MAX_RAW,
        MAX_RAW - 1,
        -MAX_RAW + 1,
        1 << 30,
        -(1 << 30),
        INF_RAW,
        NEG_INF_RAW,
        NAN_RAW,
        0x7fff,
    ];

    fn pairs(n: usize, seed: u64) -> impl Iterator<Item = (i32, i32)> {
        let mut rng = Rng(seed);
        let edges = EDGES
            .iter()
            .flat_map(|&a| EDGES.iter().map(move |&b| (a, b)));
        let random: Vec<(i32, i32)> = (0..n).map(|_| (rng.raw(), rng.raw())).collect();
        edges.chain(random)
    }

    fn same(what: &str, a: i32, b: i32, got: Fx, want: RefFx) {
        assert_eq!(
            got.raw(),
            want.raw(),
            "{what}: raw {a} and {b} (new {got:?}, reference {want:?})"
        );
    }

    #[test]
    fn add_sub_mul_div_neg_match_bit_for_bit() {
        for (a, b) in pairs(400_000, 1) {
            let (x, y) = (Fx::from_raw(a), Fx::from_raw(b));
            let (rx, ry) = (RefFx::from_raw(a), RefFx::from_raw(b));
            same("add", a, b, x + y, rx + ry);
            same("sub", a, b, x - y, rx - ry);
            same("mul", a, b, x * y, rx * ry);
            same("div", a, b, x / y, rx / ry);
            same("neg", a, b, -x, -rx);
            if x.is_finite() && y.is_finite() {
                // The ARMv6-M product path, whichever target runs the test.
                let halves = Fx::mul_finite_halves(a, b);
                same("mul (halves)", a, b, halves, rx * ry);
            }
        }
    }

    #[test]
    fn products_and_quotients_on_rounding_ties_match() {
        // a * b with a product of exactly k + 1/2 steps (ties: rounded up), and one
        // below and above it; quotients whose exact value is k + 1/2 +- 2^-32.
        let mut rng = Rng(2);
        for _ in 0..100_000 {
            let a = (rng.raw() | 1) >> 1; // any magnitude, odd or even
            for b in [
                ONE_RAW / 2,
                ONE_RAW / 2 + 1,
                ONE_RAW / 2 - 1,
                3 << 15,
                -(3 << 15),
            ] {
                same("mul tie", a, b, Fx::from_raw(a) * Fx::from_raw(b), {
                    RefFx::from_raw(a) * RefFx::from_raw(b)
                });
            }
            let d = rng.raw();
            for n in [
                d,
                d / 2,
                d.wrapping_mul(3) / 2,
                d / 2 + 1,
                d / 2 - 1,
                d >> 17,
            ] {
                same("div tie", n, d, Fx::from_raw(n) / Fx::from_raw(d), {
                    RefFx::from_raw(n) / RefFx::from_raw(d)
                });
            }
        }
    }

    #[test]
    fn dot3_matches_bit_for_bit() {
        let mut rng = Rng(3);
        for _ in 0..200_000 {
            let a: [i32; 3] = core::array::from_fn(|_| rng.raw());
            let b: [i32; 3] = core::array::from_fn(|_| rng.raw());
            let got = Fx::dot3(a.map(Fx::from_raw), b.map(Fx::from_raw));
            let want = RefFx::dot3(a.map(RefFx::from_raw), b.map(RefFx::from_raw));
            assert_eq!(got.raw(), want.raw(), "dot3 {a:?} {b:?}");
            if a.iter().chain(&b).all(|&v| Fx::from_raw(v).is_finite()) {
                // The ARMv6-M path, whichever target runs the test.
                let halves = Fx::dot3_finite_halves(a, b);
                assert_eq!(halves.raw(), want.raw(), "dot3 (halves) {a:?} {b:?}");
                let exact: i64 = (0..3).map(|i| a[i] as i64 * b[i] as i64).sum();
                if let Some(p) = wide::dot3_q16_i32(a, b) {
                    assert_eq!(p as i64, (exact + (1 << 15)) >> 16, "{a:?} . {b:?}");
                }
            }
        }
    }

    #[test]
    fn sqrt_matches_bit_for_bit_on_every_octave_and_square() {
        let mut rng = Rng(4);
        let squares = (0..46_341).flat_map(|r: i32| {
            let s = r * r;
            [s, s - 1, s + 1, s + r, s + r + 1, s - r, s - r + 1]
        });
        let random = (0..300_000).map(|_| rng.raw());
        for a in EDGES.into_iter().chain(squares).chain(random) {
            same(
                "sqrt",
                a,
                0,
                Fx::from_raw(a).sqrt(),
                RefFx::from_raw(a).sqrt(),
            );
        }
        // Every raw value below 2^20 (the small ones use the deepest normalisation).
        for a in 0..1 << 20 {
            same(
                "sqrt",
                a,
                0,
                Fx::from_raw(a).sqrt(),
                RefFx::from_raw(a).sqrt(),
            );
        }
    }

    #[test]
    fn transcendental_and_other_operations_match() {
        for (a, b) in pairs(100_000, 5) {
            let (x, y) = (Fx::from_raw(a), Fx::from_raw(b));
            let (rx, ry) = (RefFx::from_raw(a), RefFx::from_raw(b));
            same("powf", a, b, x.abs().powf(y), rx.abs().powf(ry));
            same("atan2", a, b, x.atan2(y), rx.atan2(ry));
            same("acos", a, b, (x / (y.abs() + Fx::ONE)).acos(), {
                (rx / (ry.abs() + RefFx::ONE)).acos()
            });
            same("floor", a, b, x.floor(), rx.floor());
            same("unit_scale", a, b, Fx::unit_scale(x), RefFx::unit_scale(rx));
            same(
                "from_i32",
                a,
                b,
                Fx::from_i32(a >> 8),
                RefFx::from_i32(a >> 8),
            );
            same("next_up", a, b, x.next_up(), rx.next_up());
            same("next_down", a, b, x.next_down(), rx.next_down());
        }
    }

    #[test]
    fn kernels_equal_their_64_bit_definitions() {
        // The two product paths (long multiply and 16-bit halves) on every target, not
        // just the one the host compiles in.
        for (a, b) in pairs(300_000, 6) {
            let exact = a as i64 * b as i64;
            assert_eq!(wide::mul_i32_halves(a, b), exact, "{a} * {b}");
            let (ua, ub) = (a as u32, b as u32);
            assert_eq!(wide::mul_u32_halves(ua, ub), ua as u64 * ub as u64);
            assert_eq!(wide::mul_u32(ua, ub), ua as u64 * ub as u64);
            assert_eq!(wide::mul_i32(a, b), exact);
            if let Some(p) = wide::mul_q16_i32(a, b) {
                assert_eq!(p as i64, (exact + (1 << 15)) >> 16, "{a} * {b} rounded");
            }
            if b != 0 && a != i32::MIN {
                let (n, d) = (a.unsigned_abs(), b.unsigned_abs());
                let want = ((((n as u64) << 16) + (d >> 1) as u64) / d as u64).min(i32::MAX as u64);
                assert_eq!(wide::div_q16(n, d) as u64, want, "{n} / {d}");
            }
        }
    }

    #[test]
    fn float_conversions_match_bit_for_bit() {
        let mut rng = Rng(7);
        let check64 = |v: f64| {
            let (got, want) = (Fx::from_f64(v), RefFx::from_f64(v));
            assert_eq!(
                got.raw(),
                want.raw(),
                "from_f64({v:e}) bits {:#x}",
                v.to_bits()
            );
        };
        // Halves of a step and their neighbours, the range's ends, the tie that f64's own
        // rounding of s + 1/2 takes up to 1 (s = 1/2 - 2^-54), specials.
        for k in 0..40 {
            for m in [0.5, 1.0, 1.5, 2.5, 32767.5, 32768.0] {
                let v = m * 2f64.powi(-16) * 2f64.powi(k);
                for x in [v, -v] {
                    check64(x);
                    check64(f64::from_bits(x.to_bits() + 1));
                    check64(f64::from_bits(x.to_bits() - 1));
                }
            }
        }
        for v in [
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
        ] {
            check64(v);
        }
        let tie = (0.5 - 2f64.powi(-54)) / 65536.0;
        check64(tie);
        check64(-tie);
        assert_eq!(Fx::from_f64(tie).raw(), 1);
        for _ in 0..300_000 {
            let r = rng.next();
            // Random bits, and random values of a random magnitude near the format.
            check64(f64::from_bits(r));
            let v = (r >> 11) as f64 / (1u64 << 53) as f64 * 2f64.powi((r % 50) as i32 - 25);
            check64(if r & 1 == 0 { v } else { -v });
            let w = f32::from_bits(r as u32);
            let (got, want) = (Fx::from_f32(w), RefFx::from_f32(w));
            assert_eq!(
                got.raw(),
                want.raw(),
                "from_f32({w:e}) bits {:#x}",
                w.to_bits()
            );
            let w = v as f32;
            assert_eq!(
                Fx::from_f32(w).raw(),
                RefFx::from_f32(w).raw(),
                "from_f32({w:e})"
            );
        }
    }
}
