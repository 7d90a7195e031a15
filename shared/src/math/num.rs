//! Number formats the renderer is generic over.
//!
//! The tracer is written once against [`Real`]; `f64` is the host reference, `f32` is what a
//! Cortex-M4F node computes with its FPU, and Q16.16 ([`crate::fixed::Fx`]) implements the same
//! trait: every operation the renderer needs is named here, so nothing in the
//! tracer assumes IEEE floats except through [`Real::epsilon`] (the unit round-off used for
//! error-bounded ray origins) and [`Real::is_finite`].
//!
//! Transcendental functions go through `libm`, a pure-Rust implementation, so a render is
//! bit-identical on the host and on a node for the same number type.

use crate::geom::Vec3;
use crate::math::solid::Triangle;
use crate::shape::triangle::{EdgePlanes, EyeTest};
use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// Number format of the scalars in a SceneImage (header byte 6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Storage {
    /// IEEE binary32, what the float backends read (and widen for f64).
    F32 = 0,
    /// Q16.16 raw `i32`s of a scene scaled by a power of two (header byte 7 is the
    /// exponent), what the fixed-point backend reads without any conversion.
    Q16_16 = 1,
}

impl Storage {
    pub fn from_u8(v: u8) -> Option<Storage> {
        match v {
            0 => Some(Storage::F32),
            1 => Some(Storage::Q16_16),
            _ => None,
        }
    }
    pub const fn name(self) -> &'static str {
        match self {
            Storage::F32 => "f32",
            Storage::Q16_16 => "q16.16",
        }
    }
}

pub use crate::fixed::Fx;

/// A scalar the renderer can compute with.
/// Largest whole exponent [`Real::pow_exponent`] raises to by squaring.
pub const POW_BY_SQUARING_MAX: u32 = 4096;

pub trait Real:
    Copy
    + Debug
    + PartialEq
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + Send
    + Sync
    + 'static
{
    /// Short name used in reports ("f32", "f64", ...).
    const NAME: &'static str;
    const ZERO: Self;
    const ONE: Self;
    const HALF: Self;
    const TWO: Self;
    /// Largest finite value (used as "no hit yet").
    const MAX: Self;
    /// Above every finite value (the IEEE infinity; Q16.16's reserved one): nothing compares
    /// greater.
    const INFINITY: Self;
    const PI: Self;
    /// How a SceneImage stores scalars for this type (the image header's number format).
    const STORAGE: Storage = Storage::F32;
    /// Rounding is absolute (fixed point: half a step whatever the magnitude) rather than
    /// relative (floating point). Short vectors then keep few significant bits, so
    /// normalisation and cross products scale them up by [`Real::unit_scale`] first.
    const ABSOLUTE_ROUNDING: bool = false;
    /// What the primary-ray test keeps of a triangle ([`crate::trace::primary::PlaneCache`]):
    /// its planes through the eye. Floats: [`EdgePlanes`] with a rounding bound per plane;
    /// fixed point: integer planes ([`crate::fixed::FxEyePlanes`]).
    type EyePlanes: Copy + Debug + PartialEq + Send + Sync + 'static;
    /// The planes of an empty cache slot.
    const EYE_PLANES_EMPTY: Self::EyePlanes;
    /// The planes of `tri`, whose vertices have indices `index` (shared vertices share an
    /// index, which fixes each edge's orientation), for primary rays whose `|d|_1` is at
    /// most `l1`.
    fn eye_planes(tri: &Triangle<Self>, index: [u32; 3], l1: Self) -> Self::EyePlanes;
    /// The ray from the eye along `d` (`len` = |d|) against `planes` for distances (along
    /// the unit direction) in (0, t_max); [`EyeTest::Uncertain`] asks the sheared test.
    fn eye_test(planes: &Self::EyePlanes, d: Vec3<Self>, len: Self, t_max: Self) -> EyeTest<Self>;

    fn from_f32(v: f32) -> Self;
    fn from_f64(v: f64) -> Self;
    fn from_i32(v: i32) -> Self;
    fn to_f64(self) -> f64;
    fn to_f32(self) -> f32;
    /// a0 b0 + a1 b1 + a2 b2, evaluated left to right. Fixed point sums the exact products
    /// and rounds once (a third of the error, and fewer instructions).
    #[inline(always)]
    fn dot3(a: [Self; 3], b: [Self; 3]) -> Self {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }
    /// A power of two that brings `m` (> 0) up towards [0.5, 1) where the format can
    /// represent it (never scales down); one for floats, which need no help.
    #[inline(always)]
    fn unit_scale(_m: Self) -> Self {
        Self::ONE
    }
    /// `v / |v|`, or `None` when the length is zero or not finite.
    ///
    /// Floats: `v * (1 / |v|)`. Fixed point overrides it: rounding is absolute there, so a
    /// reciprocal of a length far from 1 keeps few significant bits, and the unit vector's
    /// length would be off by up to 2^-16 / (1 / |v|) (2.6e-4 for a primary direction of
    /// length 34); [`crate::fixed::Fx`] computes the length and the quotients from the
    /// integers, each component rounded once.
    #[inline]
    fn normalize3(v: [Self; 3]) -> Option<[Self; 3]> {
        let l = Self::dot3(v, v).sqrt();
        if l > Self::ZERO && l.is_finite() {
            let r = l.recip();
            Some([v[0] * r, v[1] * r, v[2] * r])
        } else {
            None
        }
    }
    /// The edge functions of the sheared triangle test, `x_j y_k - y_j x_k` for the edges
    /// (j, k) = (1, 2), (2, 0), (0, 1), as `(e, k)` with each function `e_i * 2^k`.
    ///
    /// Floats: the products as written, `k = 0` (the triangle test's float path computes
    /// them itself; this default is what it would compute). Fixed point overrides it: a
    /// product rounds by half a step whatever its size, so the edge functions of a
    /// triangle a few hundred steps across keep only a few significant bits and
    /// misplace its edges by a good part of its size; [`crate::fixed::Fx`] forms them
    /// exactly and scales all three by one power of two so the largest has 22 bits.
    #[inline]
    fn edge_functions(x: [Self; 3], y: [Self; 3]) -> ([Self; 3], i32) {
        (
            [
                x[1] * y[2] - y[1] * x[2],
                x[2] * y[0] - y[2] * x[0],
                x[0] * y[1] - y[0] * x[1],
            ],
            0,
        )
    }
    /// `(a b - c d) 2^7`. Fixed point forms it exactly and rounds once: with `a, d` a
    /// vertex's coordinates relative to a ray's origin and `b, c` the ray's direction, it
    /// is the vertex's sheared coordinate times `d_z`, to 2^-23 where a shear by the
    /// rounded `d_x / d_z` put it off by up to half a step times |z| (10 steps at 20 units).
    #[inline]
    fn cross_fine(a: Self, b: Self, c: Self, d: Self) -> Self {
        (a * b - c * d) * Self::from_i32(128)
    }
    /// One Newton step for `|c + d s|² = 1` from `s`: `s - r / (2 (c + d s)·d)` with the
    /// residual `r = |c + d s|² - 1`. Floats return `s` (their roots need no refining and
    /// never call it). Fixed point forms `r` and the slope exactly in 64 bits (a residual
    /// of Q16.16 products is off by steps, which near a grazing hit the step divides by the
    /// small slope again) and declines (returns `s`) where the slope is under 2^-8 or the
    /// step over 64 steps.
    #[inline]
    fn sphere_newton(_c: [Self; 3], _d: [Self; 3], s: Self) -> Self {
        s
    }
    /// `m (rel + dir tc)`, `m` given by its rows. Fixed point keeps the point `rel + dir tc`
    /// to 2^-24 (a Q16.16 point is off by half a step per coordinate, which `m` stretches:
    /// by 2 steps for a row of 4, glass.ron's lens), forms it once for the three rows, and
    /// rounds each row's dot product once.
    #[inline]
    fn local_mat_vec(m: [[Self; 3]; 3], rel: [Self; 3], dir: [Self; 3], tc: Self) -> [Self; 3] {
        let p = [
            rel[0] + dir[0] * tc,
            rel[1] + dir[1] * tc,
            rel[2] + dir[2] * tc,
        ];
        [
            Self::dot3(m[0], p),
            Self::dot3(m[1], p),
            Self::dot3(m[2], p),
        ]
    }
    /// `self * o` where a result beyond the format's range is meant to become an infinity:
    /// a slab test's distance `(bound - origin) / d` for a direction `d` nearly parallel to
    /// the slab (no scene is that far). Floats: the product. Fixed point computes the same
    /// saturating product, and its checked build (`fx-checked`, [`crate::math::overflow`])
    /// does not count it as an overflow.
    #[inline(always)]
    fn mul_beyond(self, o: Self) -> Self {
        self * o
    }
    /// `1 / self` where an infinity is the intended result for a tiny `self` (a slab test's
    /// reciprocal direction); see [`Self::mul_beyond`].
    #[inline(always)]
    fn recip_beyond(self) -> Self {
        self.recip()
    }
    /// `self * 2^k` (saturating in fixed point).
    #[inline]
    fn mul_pow2(self, k: i32) -> Self {
        self * Self::from_f64(libm::ldexp(1.0, k))
    }
    /// A scalar as stored in a SceneImage of format [`Real::STORAGE`].
    #[inline(always)]
    fn from_stored(bits: u32) -> Self {
        Self::from_f32(f32::from_bits(bits))
    }

    /// Unit round-off: half the distance from 1.0 to the next representable value.
    /// Error bounds of intersection routines are multiples of it (pbrt's gamma(n)).
    fn epsilon() -> Self;

    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    fn floor(self) -> Self;
    fn powf(self, e: Self) -> Self;
    /// `self^e` for `self >= 0`, `e >= 0` (specular and spot exponents): by repeated
    /// squaring when `e` is a whole number up to [`POW_BY_SQUARING_MAX`] (a few multiplies
    /// instead of `powf`'s logarithm and exponential), else [`Real::powf`].
    #[inline]
    fn pow_exponent(self, e: Self) -> Self {
        let ef = e.to_f32();
        let k = ef as u32;
        if k as f32 != ef || k > POW_BY_SQUARING_MAX {
            return self.powf(e);
        }
        let (mut k, mut base, mut acc) = (k, self, Self::ONE);
        while k > 0 {
            if k & 1 == 1 {
                acc *= base;
            }
            k >>= 1;
            if k > 0 {
                base *= base;
            }
        }
        acc
    }
    fn atan2(self, x: Self) -> Self;
    fn acos(self) -> Self;
    fn is_finite(self) -> bool;
    /// Whether the sign bit is set (a float's `-0` and `-inf` included).
    fn is_sign_negative(self) -> bool;

    /// The next representable value towards +infinity (a float: one ulp; a fixed-point
    /// format: one step). `offset_ray_origin` relies on the direction: it pushes a
    /// coordinate up when its offset is positive and down when negative.
    fn next_up(self) -> Self;
    /// The next representable value towards -infinity.
    fn next_down(self) -> Self;

    #[inline]
    fn min(self, o: Self) -> Self {
        if o < self {
            o
        } else {
            self
        }
    }
    #[inline]
    fn max(self, o: Self) -> Self {
        if o > self {
            o
        } else {
            self
        }
    }
    #[inline]
    fn clamp01(self) -> Self {
        self.max(Self::ZERO).min(Self::ONE)
    }
    #[inline]
    fn recip(self) -> Self {
        Self::ONE / self
    }
    #[inline]
    fn sq(self) -> Self {
        self * self
    }
    /// A colour channel as 8 bits: clamped to [0, 1], scaled by 255, rounded to nearest
    /// (`as u8` saturates and takes NaN to 0).
    #[inline]
    fn to_unit_u8(self) -> u8 {
        (self.clamp01().to_f32() * 255.0 + 0.5) as u8
    }
    /// pbrt's gamma(n) = n*eps / (1 - n*eps): the bound on relative error after n roundings.
    #[inline]
    fn err_gamma(n: i32) -> Self {
        let ne = Self::from_i32(n) * Self::epsilon();
        ne / (Self::ONE - ne)
    }
}

macro_rules! impl_float_real {
    ($t:ty, $name:literal, $bits:ty, $sqrt:path, $floor:path, $pow:path, $atan2:path, $acos:path) => {
        impl Real for $t {
            const NAME: &'static str = $name;
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const HALF: Self = 0.5;
            const TWO: Self = 2.0;
            const MAX: Self = <$t>::MAX;
            const INFINITY: Self = <$t>::INFINITY;
            const PI: Self = core::f64::consts::PI as $t;
            type EyePlanes = EdgePlanes<$t>;
            const EYE_PLANES_EMPTY: EdgePlanes<$t> = EdgePlanes::ZERO;
            #[inline]
            fn eye_planes(tri: &Triangle<$t>, index: [u32; 3], l1: $t) -> EdgePlanes<$t> {
                EdgePlanes::new(tri, index, l1)
            }
            #[inline(always)]
            fn eye_test(p: &EdgePlanes<$t>, d: Vec3<$t>, len: $t, t_max: $t) -> EyeTest<$t> {
                p.intersect_from_eye(d, len, t_max)
            }

            #[inline]
            fn from_f32(v: f32) -> Self {
                v as $t
            }
            #[inline]
            fn from_f64(v: f64) -> Self {
                v as $t
            }
            #[inline]
            fn from_i32(v: i32) -> Self {
                v as $t
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn to_f32(self) -> f32 {
                self as f32
            }
            #[inline]
            fn epsilon() -> Self {
                <$t>::EPSILON * 0.5
            }
            #[inline]
            fn sqrt(self) -> Self {
                $sqrt(self)
            }
            #[inline]
            fn abs(self) -> Self {
                // Clear the sign bit: branch-free and exact, also for -0.0.
                <$t>::from_bits(self.to_bits() & (<$bits>::MAX >> 1))
            }
            #[inline]
            fn floor(self) -> Self {
                $floor(self)
            }
            #[inline]
            fn powf(self, e: Self) -> Self {
                $pow(self, e)
            }
            #[inline]
            fn atan2(self, x: Self) -> Self {
                $atan2(self, x)
            }
            #[inline]
            fn acos(self) -> Self {
                $acos(self)
            }
            #[inline]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            #[inline(always)]
            fn is_sign_negative(self) -> bool {
                <$t>::is_sign_negative(self)
            }
            #[inline]
            fn next_up(self) -> Self {
                <$t>::next_up(self)
            }
            #[inline]
            fn next_down(self) -> Self {
                <$t>::next_down(self)
            }
        }
    };
}

/// Square root on the Cortex-M4F's FPU: VSQRT.F32 is correctly rounded like libm's routine
/// (same bits, checked under QEMU on 1,024 inputs) but 3 instructions instead of ~53.
#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
#[allow(unsafe_code)]
#[inline(always)]
fn sqrt_f32(x: f32) -> f32 {
    let mut bits = x.to_bits();
    // SAFETY: moves a value through the scratch register s14 and takes its square root;
    // touches no memory, stack or flags (the asm operands and options say exactly that).
    unsafe {
        core::arch::asm!(
            "vmov s14, {0}",
            "vsqrt.f32 s14, s14",
            "vmov {0}, s14",
            inout(reg) bits,
            out("s14") _,
            options(pure, nomem, nostack, preserves_flags)
        );
    }
    f32::from_bits(bits)
}

/// Square root elsewhere: libm's correctly rounded routine (same bits as the FPU's).
#[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
#[inline(always)]
fn sqrt_f32(x: f32) -> f32 {
    libm::sqrtf(x)
}

impl_float_real!(
    f32,
    "f32",
    u32,
    sqrt_f32,
    libm::floorf,
    libm::powf,
    libm::atan2f,
    libm::acosf
);
impl_float_real!(
    f64,
    "f64",
    u64,
    libm::sqrt,
    libm::floor,
    libm::pow,
    libm::atan2,
    libm::acos
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_f32_approximates_only_where_micromath_is_accurate_enough() {
        let (a, b) = (FastF32(1.5), FastF32(-0.25));
        assert_eq!(((a + b).0, (a * b).0, (a / b).0), (1.25, -0.375, -6.0));
        let (mut worst_pow_mm, mut worst_acos, mut worst_atan2, mut worst_sqrt_mm) =
            (0f64, 0f64, 0f64, 0f64);
        for i in 1..1000 {
            let c = i as f32 / 1000.0;
            // Exact where micromath is not good enough: bit-identical to f32.
            for n in [5.0f32, 20.0, 40.0, 120.0] {
                assert_eq!(FastF32(c).powf(FastF32(n)).0, Real::powf(c, n));
                let e = (c as f64).powf(n as f64);
                if e > 1e-3 {
                    let mm = <f32 as micromath::F32Ext>::powf(c, n) as f64;
                    worst_pow_mm = worst_pow_mm.max(((mm - e) / e).abs());
                }
            }
            assert_eq!(FastF32(c).sqrt().0, Real::sqrt(c));
            let s = (c as f64).sqrt();
            worst_sqrt_mm =
                worst_sqrt_mm.max(((<f32 as micromath::F32Ext>::sqrt(c) as f64 - s) / s).abs());
            // Approximated: within the stated bounds.
            let x = c * 2.0 - 1.0;
            worst_acos = worst_acos.max((FastF32(x).acos().0 as f64 - (x as f64).acos()).abs());
            for j in 0..20 {
                let ang = j as f64 * 0.33;
                let (y, xx) = (ang.sin() * c as f64, ang.cos() * c as f64);
                let got = FastF32(y as f32).atan2(FastF32(xx as f32)).0 as f64;
                worst_atan2 = worst_atan2.max((got - y.atan2(xx)).abs());
            }
        }
        assert!(
            worst_atan2 < 0.003 && worst_acos < 0.03,
            "atan2 {worst_atan2}, acos {worst_acos}"
        );
        // Why powf and sqrt stay exact (the measurement behind the choice).
        assert!(
            worst_pow_mm > 0.5 && worst_sqrt_mm > 0.05,
            "powf {worst_pow_mm}, sqrt {worst_sqrt_mm}"
        );
    }

    #[test]
    fn abs_clears_only_the_sign() {
        assert_eq!(Real::abs(-2.5f32), 2.5);
        assert_eq!(Real::abs(-2.5f64), 2.5);
        assert_eq!(Real::abs(3.0f32), 3.0);
        assert_eq!(Real::abs(-0.0f64).to_bits(), 0);
    }

    #[test]
    fn gamma_matches_pbrt() {
        let g = f32::err_gamma(3);
        let e = f32::EPSILON as f64 * 0.5;
        assert!((g as f64 - 3.0 * e / (1.0 - 3.0 * e)).abs() < 1e-12);
    }

    #[test]
    fn libm_functions_agree_with_std() {
        assert_eq!(Real::sqrt(2.0f64), 2.0f64.sqrt());
        assert!((Real::powf(0.5f32, 10.0) - 0.5f32.powi(10)).abs() < 1e-7);
        assert!((Real::atan2(1.0f64, 1.0) - core::f64::consts::FRAC_PI_4).abs() < 1e-15);
        // Whole exponents by squaring: exact where the products are (powers of two), close
        // to powf elsewhere; anything else goes to powf.
        assert_eq!(Real::pow_exponent(0.5f32, 10.0), 1.0 / 1024.0);
        assert_eq!(Real::pow_exponent(0.5f64, 0.0), 1.0);
        assert_eq!(Real::pow_exponent(3.0f64, 5.0), 243.0);
        let c = 0.93f32;
        let want = (c as f64).powi(40);
        assert!((Real::pow_exponent(c, 40.0) as f64 - want).abs() < 8.0 * f32::EPSILON as f64);
        assert_eq!(Real::pow_exponent(c, 2.5), Real::powf(c, 2.5));
        assert_eq!(Real::pow_exponent(c, 1e6), Real::powf(c, 1e6));
    }
}

/// `f32` with micromath's fast approximations where they are acceptable. Measured against
/// f64 over their whole input range (`docs/numerics.md`): `atan2` is within 0.003 rad and
/// `acos` within 0.029 rad (spherical texture coordinates: under 1% of the texture), so
/// both are used; `powf` is off by up to 99.7% for Phong exponents of 5 to 120 (a highlight
/// would vanish or flare) and `sqrt` by up to 6% (every normal and reflection would bend), so
/// those stay exact (libm's `powf`; the FPU's square root). Everything else is IEEE `f32`.
#[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd)]
pub struct FastF32(pub f32);

macro_rules! fast_binop {
    ($tr:ident, $f:ident, $atr:ident, $af:ident, $op:tt) => {
        impl $tr for FastF32 {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                FastF32(self.0 $op o.0)
            }
        }
        impl $atr for FastF32 {
            #[inline(always)]
            fn $af(&mut self, o: Self) {
                self.0 = self.0 $op o.0;
            }
        }
    };
}
fast_binop!(Add, add, AddAssign, add_assign, +);
fast_binop!(Sub, sub, SubAssign, sub_assign, -);
fast_binop!(Mul, mul, MulAssign, mul_assign, *);

impl Div for FastF32 {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        FastF32(self.0 / o.0)
    }
}

impl Neg for FastF32 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        FastF32(-self.0)
    }
}

impl Real for FastF32 {
    const NAME: &'static str = "f32-fast";
    const ZERO: Self = FastF32(0.0);
    const ONE: Self = FastF32(1.0);
    const HALF: Self = FastF32(0.5);
    const TWO: Self = FastF32(2.0);
    const MAX: Self = FastF32(f32::MAX);
    const INFINITY: Self = FastF32(f32::INFINITY);
    const PI: Self = FastF32(core::f32::consts::PI);
    type EyePlanes = EdgePlanes<FastF32>;
    const EYE_PLANES_EMPTY: EdgePlanes<FastF32> = EdgePlanes::ZERO;
    #[inline]
    fn eye_planes(tri: &Triangle<FastF32>, index: [u32; 3], l1: FastF32) -> EdgePlanes<FastF32> {
        EdgePlanes::new(tri, index, l1)
    }
    #[inline(always)]
    fn eye_test(
        p: &EdgePlanes<FastF32>,
        d: Vec3<FastF32>,
        len: FastF32,
        t_max: FastF32,
    ) -> EyeTest<FastF32> {
        p.intersect_from_eye(d, len, t_max)
    }

    #[inline(always)]
    fn from_f32(v: f32) -> Self {
        FastF32(v)
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        FastF32(v as f32)
    }
    #[inline(always)]
    fn from_i32(v: i32) -> Self {
        FastF32(v as f32)
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self.0 as f64
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self.0
    }
    #[inline(always)]
    fn epsilon() -> Self {
        FastF32(f32::EPSILON * 0.5)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        FastF32(sqrt_f32(self.0))
    }
    #[inline(always)]
    fn abs(self) -> Self {
        FastF32(Real::abs(self.0))
    }
    #[inline(always)]
    fn floor(self) -> Self {
        FastF32(libm::floorf(self.0))
    }
    #[inline(always)]
    fn powf(self, e: Self) -> Self {
        FastF32(libm::powf(self.0, e.0))
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        // Fully qualified: on the host, std's exact inherent methods would win otherwise.
        FastF32(<f32 as micromath::F32Ext>::atan2(self.0, x.0))
    }
    #[inline(always)]
    fn acos(self) -> Self {
        FastF32(<f32 as micromath::F32Ext>::acos(self.0))
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        self.0.is_finite()
    }
    #[inline(always)]
    fn is_sign_negative(self) -> bool {
        self.0.is_sign_negative()
    }
    #[inline(always)]
    fn next_up(self) -> Self {
        FastF32(self.0.next_up())
    }
    #[inline(always)]
    fn next_down(self) -> Self {
        FastF32(self.0.next_down())
    }
}
