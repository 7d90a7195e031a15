//! Validated numbers and vectors for the scene-file structs.
//!
//! Every check runs *inside* deserialisation and fails with `serde::de::Error::custom`, so ron
//! attaches the position of the offending value to the error. Single numbers are checked as soon
//! as they are read (the error points at the number, even inside a tuple); checks that need the
//! whole value (a zero direction, a degenerate triangle) fail just after its closing bracket, and
//! [`super::locate`] moves the reported position back to the value's opening bracket.
//!
//! The functions named after a field (`radius`, `fov`, ...) are for `#[serde(deserialize_with)]`;
//! the newtypes are for places where the value sits inside an `Option`.

use std::fmt;

use serde::de::{self, DeserializeSeed, Deserializer, SeqAccess, Visitor};
use serde::Deserialize;

/// Largest accepted image side and texture side, in pixels ([`crate::limits::MAX_IMAGE_SIDE`]).
pub(super) const MAX_IMAGE_SIDE: i64 = crate::limits::MAX_IMAGE_SIDE as i64;
/// Largest accepted `max_depth`: the deepest recursion a SceneImage may ask for.
pub(super) const MAX_DEPTH: i64 = links_core::image::MAX_DEPTH_LIMIT as i64;

/// Formats a number for an error message: `0`, `0.5`, `-1`, `NaN`, `inf`, `1e300`.
pub(super) struct Num(pub f64);

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = self.0;
        if v.is_finite() && v != 0.0 && !(1e-6..1e9).contains(&v.abs()) {
            write!(f, "{v:e}")
        } else {
            write!(f, "{v}")
        }
    }
}

/// Formats a vector for an error message: `(0, 0, 0)`.
pub(super) struct NumVec<'a>(pub &'a [f64]);

impl fmt::Display for NumVec<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("(")?;
        for (i, v) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{}", Num(*v))?;
        }
        f.write_str(")")
    }
}

/// "a" or "an" before `word`.
fn a(word: &str) -> &'static str {
    if word.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    }
}

/// The range a number must fall in.
#[derive(Clone, Copy, Debug)]
pub(super) enum Check {
    /// Any finite number.
    Finite,
    /// Finite and > 0.
    Positive,
    /// Finite and >= 0.
    NonNegative,
    /// In [0, 1].
    Unit,
    /// Finite and >= the bound.
    AtLeast(f64),
    /// Strictly between the bounds.
    Between(f64, f64),
    /// Finite and not zero.
    NonZero,
}

/// Why a finite number does not survive the conversion to f32, the format every scene
/// compiles to (a Q16.16 image is made from the f32 one): beyond `f32::MAX` it would become
/// infinite, and a non-zero below `f32::MIN_POSITIVE` would become 0 or a subnormal (tiny
/// lengths and directions are refused rather than silently zeroed). `what` is "a radius".
pub(super) fn f32_range_error(v: f64, what: &str, shown: &dyn fmt::Display) -> Option<String> {
    let m = v.abs();
    if m > f64::from(f32::MAX) {
        Some(format!(
            "expected {what} within the f32 range (about ±3.4e38), found {shown}"
        ))
    } else if m != 0.0 && m < f64::from(f32::MIN_POSITIVE) {
        Some(format!(
            "expected {what} of at least about 1.2e-38 in magnitude (a smaller non-zero number \
             underflows f32), found {shown}"
        ))
    } else {
        None
    }
}

/// Checks one number; `what` names it in the message ("radius", "x of scale"). Every number
/// must be finite and within the f32 range ([`f32_range_error`]).
pub(super) fn check_number(v: f64, what: &str, check: Check) -> Result<f64, String> {
    if !v.is_finite() {
        return Err(format!("expected a finite {what}, found {}", Num(v)));
    }
    if let Some(e) = f32_range_error(v, &format!("{} {what}", a(what)), &Num(v)) {
        return Err(e);
    }
    let ok = match check {
        Check::Finite => true,
        Check::Positive => v > 0.0,
        Check::NonNegative => v >= 0.0,
        Check::Unit => (0.0..=1.0).contains(&v),
        Check::AtLeast(lo) => v >= lo,
        Check::Between(lo, hi) => v > lo && v < hi,
        Check::NonZero => v != 0.0,
    };
    if ok {
        return Ok(v);
    }
    Err(match check {
        Check::Finite => unreachable!("finite numbers pass Check::Finite"),
        Check::Positive => format!("expected a positive {what}, found {}", Num(v)),
        Check::NonNegative => format!("expected a non-negative {what}, found {}", Num(v)),
        Check::Unit => format!(
            "expected {} {what} between 0 and 1, found {}",
            a(what),
            Num(v)
        ),
        Check::AtLeast(lo) => format!(
            "expected {} {what} of at least {}, found {}",
            a(what),
            Num(lo),
            Num(v)
        ),
        Check::Between(lo, hi) => format!(
            "expected {} {what} strictly between {} and {}, found {}",
            a(what),
            Num(lo),
            Num(hi),
            Num(v)
        ),
        Check::NonZero => format!("expected a non-zero {what}, found 0"),
    })
}

/// Reads one number (integers are accepted) and checks it at once, so the error points at it.
struct NumberSeed<'a> {
    what: &'a str,
    check: Check,
}

impl<'de> DeserializeSeed<'de> for NumberSeed<'_> {
    type Value = f64;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<f64, D::Error> {
        let v = f64::deserialize(d)?;
        check_number(v, self.what, self.check).map_err(de::Error::custom)
    }
}

fn number<'de, D: Deserializer<'de>>(d: D, what: &str, check: Check) -> Result<f64, D::Error> {
    NumberSeed { what, check }.deserialize(d)
}

/// Reads `N` numbers written `(a, b, c)` or `[a, b, c]`; with `splat`, a single number `a` stands
/// for `(a, a, a)`.
struct VectorVisitor<'a, const N: usize> {
    what: &'a str,
    check: Check,
    splat: bool,
}

impl<const N: usize> VectorVisitor<'_, N> {
    fn scalar<E: de::Error>(self, v: f64) -> Result<[f64; N], E> {
        if !self.splat {
            return Err(de::Error::custom(format!(
                "expected {} {what} written as a {N}-tuple {example}, found the single number {}",
                a(self.what),
                Num(v),
                what = self.what,
                example = example(N)
            )));
        }
        let v = check_number(v, self.what, self.check).map_err(de::Error::custom)?;
        Ok([v; N])
    }
}

fn example(n: usize) -> &'static str {
    match n {
        2 => "(u, v)",
        3 => "(x, y, z)",
        _ => "(...)",
    }
}

impl<'de, const N: usize> Visitor<'de> for VectorVisitor<'_, N> {
    type Value = [f64; N];

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.splat {
            write!(
                f,
                "{} {} written as a number or a {N}-tuple {}",
                a(self.what),
                self.what,
                example(N)
            )
        } else {
            write!(
                f,
                "{} {} written as a {N}-tuple {}",
                a(self.what),
                self.what,
                example(N)
            )
        }
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
        self.scalar(v)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
        self.scalar(v as f64)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
        self.scalar(v as f64)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut out = [0.0; N];
        for (i, slot) in out.iter_mut().enumerate() {
            let seed = NumberSeed {
                what: self.what,
                check: self.check,
            };
            *slot = seq
                .next_element_seed(seed)?
                .ok_or_else(|| de::Error::invalid_length(i, &self))?;
        }
        let mut extra = 0;
        while seq.next_element::<de::IgnoredAny>()?.is_some() {
            extra += 1;
        }
        if extra > 0 {
            return Err(de::Error::invalid_length(N + extra, &self));
        }
        Ok(out)
    }
}

fn vector<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
    what: &str,
    check: Check,
    splat: bool,
) -> Result<[f64; N], D::Error> {
    d.deserialize_any(VectorVisitor::<N> { what, check, splat })
}

fn to_f32<const N: usize>(v: [f64; N]) -> [f32; N] {
    v.map(|x| x as f32)
}

pub(super) use crate::vec3::{cross, length, sub};

/// `v / |v|`, or `None` when `v` has no usable direction (zero, or so small/large that the
/// length is zero or infinite).
/// The same function tracks normalise with ([`links_core::anim::unit`]), so a direction a track
/// produced and the same direction written into a still scene get the same bits.
pub(super) fn normalize(v: [f64; 3]) -> Option<[f64; 3]> {
    links_core::anim::unit(v)
}

/// Relative tolerance below which a triangle counts as having zero area: |e1 × e2| is compared
/// with the square of the longest edge.
pub(super) const DEGENERATE_REL: f64 = 1e-12;

/// True when the triangle has (numerically) zero area.
pub(super) fn degenerate_triangle(v: &[[f64; 3]; 3]) -> bool {
    let e1 = sub(v[1], v[0]);
    let e2 = sub(v[2], v[0]);
    let e3 = sub(v[2], v[1]);
    let area2 = length(cross(e1, e2));
    let longest = length(e1).max(length(e2)).max(length(e3));
    // Written so that NaN (from overflowing coordinates) also counts as degenerate.
    let nondegenerate = area2 > DEGENERATE_REL * longest * longest && longest > 0.0;
    !nondegenerate
}

// ---- field deserialisers (for `#[serde(deserialize_with = "...")]`) ----------------------------

/// A point in scene units: `(x, y, z)`.
pub(super) fn point<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    vector(d, "coordinate", Check::Finite, false)
}

/// Rotation angles in degrees: `(x, y, z)`.
pub(super) fn angles<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    vector(d, "angle", Check::Finite, false)
}

/// A direction: any non-zero vector, returned normalised.
pub(super) fn direction<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    let v = vector(d, "direction component", Check::Finite, false)?;
    normalize(v).ok_or_else(|| {
        de::Error::custom(format!(
            "expected a direction (a non-zero vector), found {}",
            NumVec(&v)
        ))
    })
}

/// Per-axis scale factors: a number (uniform) or `(x, y, z)`, each > 0.
pub(super) fn scale3<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    vector(d, "scale factor", Check::Positive, true)
}

/// Ellipsoid radii: a number (sphere) or `(x, y, z)`, each > 0.
pub(super) fn radii<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    vector(d, "radius", Check::Positive, true)
}

pub(super) fn radius<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    number(d, "radius", Check::Positive)
}

pub(super) fn threshold<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    number(d, "threshold", Check::Positive)
}

pub(super) fn strength<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    number(d, "strength", Check::NonZero)
}

pub(super) fn offset<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    number(d, "offset", Check::Finite)
}

pub(super) fn fov<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    number(
        d,
        "vertical field of view in degrees",
        Check::Between(0.0, 180.0),
    )
}

/// A spot light's cone half-angle in degrees, [0, 180).
pub(super) fn cone_angle<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let v = number(d, "cone angle in degrees", Check::NonNegative)?;
    if v >= 180.0 {
        return Err(de::Error::custom(format!(
            "expected a cone angle in degrees below 180, found {}",
            Num(v)
        )));
    }
    Ok(v)
}

/// A colour or light intensity: a number (grey) or `(r, g, b)`, each >= 0, no upper bound.
pub(super) fn color<'de, D: Deserializer<'de>>(d: D) -> Result<[f32; 3], D::Error> {
    vector(d, "colour component", Check::NonNegative, true).map(to_f32)
}

/// A reflectance per channel: a number (grey) or `(r, g, b)`, each in [0, 1].
pub(super) fn rgb01<'de, D: Deserializer<'de>>(d: D) -> Result<[f32; 3], D::Error> {
    vector(d, "colour coefficient", Check::Unit, true).map(to_f32)
}

/// A coefficient in [0, 1].
pub(super) fn coef<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
    number(d, "coefficient", Check::Unit).map(|v| v as f32)
}

pub(super) fn shininess<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
    number(d, "shininess exponent", Check::NonNegative).map(|v| v as f32)
}

pub(super) fn exponent<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
    number(d, "exponent", Check::NonNegative).map(|v| v as f32)
}

pub(super) fn ior<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
    number(d, "index of refraction", Check::AtLeast(1.0)).map(|v| v as f32)
}

/// Texture repeats per unit of (u, v): a number or `(u, v)`, each > 0.
pub(super) fn map_scale<'de, D: Deserializer<'de>>(d: D) -> Result<[f32; 2], D::Error> {
    vector(d, "texture scale", Check::Positive, true).map(to_f32)
}

fn integer<'de, D: Deserializer<'de>>(d: D, what: &str, lo: i64, hi: i64) -> Result<u32, D::Error> {
    let v = i64::deserialize(d)?;
    if (lo..=hi).contains(&v) {
        Ok(v as u32)
    } else {
        Err(de::Error::custom(format!(
            "expected {what} between {lo} and {hi}, found {v}"
        )))
    }
}

pub(super) fn image_side<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    integer(d, "an image size in pixels", 1, MAX_IMAGE_SIDE)
}

pub(super) fn max_depth<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    integer(d, "a maximum ray depth", 0, MAX_DEPTH)
}

/// Largest frame number a film may name (`frames: (end: ...)`).
pub(super) const MAX_FRAME: i64 = 1_000_000;

/// A film's first frame, `frames: (start: ...)`.
pub(super) fn frame_start<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    integer(d, "a first frame", 0, MAX_FRAME - 1)
}

/// One past a film's last frame, `frames: (end: ...)`.
pub(super) fn frame_end<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    integer(d, "an end frame", 1, MAX_FRAME)
}

/// Frames per second.
pub(super) fn rate<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    number(d, "frame rate", Check::Positive)
}

/// A key's time, in frames (fractions allowed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct KeyTime(pub f64);

impl<'de> Deserialize<'de> for KeyTime {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        number(d, "key time", Check::Finite).map(KeyTime)
    }
}

/// A key's value as written: a number or a 3-vector, each number finite and within the f32
/// range; what it must be beyond that depends on the track's target (checked on resolving).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum KeyValue {
    Number(f64),
    Vector([f64; 3]),
}

struct KeyValueVisitor;

impl<'de> Visitor<'de> for KeyValueVisitor {
    type Value = KeyValue;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a key value: a number or a 3-tuple (x, y, z)")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<KeyValue, E> {
        check_number(v, "key value", Check::Finite)
            .map(KeyValue::Number)
            .map_err(de::Error::custom)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<KeyValue, E> {
        self.visit_f64(v as f64)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<KeyValue, E> {
        self.visit_f64(v as f64)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<KeyValue, A::Error> {
        let inner = VectorVisitor::<3> {
            what: "key value",
            check: Check::Finite,
            splat: false,
        };
        inner.visit_seq(seq).map(KeyValue::Vector)
    }
}

impl<'de> Deserialize<'de> for KeyValue {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(KeyValueVisitor)
    }
}

// ---- newtypes for values inside an `Option` ---------------------------------------------------

/// An optional coefficient (`specular_edge`, `reflect_edge`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Coef(pub f32);

impl<'de> Deserialize<'de> for Coef {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        coef(d).map(Coef)
    }
}

/// An optional reflectance per channel (a material's `ambient`): a number or `(r, g, b)`,
/// each in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Rgb01(pub [f32; 3]);

impl<'de> Deserialize<'de> for Rgb01 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        rgb01(d).map(Rgb01)
    }
}

/// An optional cone angle (a spot light's `inner`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct ConeAngle(pub f64);

impl<'de> Deserialize<'de> for ConeAngle {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        cone_angle(d).map(ConeAngle)
    }
}

/// A seed reading one `N`-vector of finite numbers.
struct VectorSeed<'a, const N: usize> {
    what: &'a str,
}

impl<'de, const N: usize> DeserializeSeed<'de> for VectorSeed<'_, N> {
    type Value = [f64; N];

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<[f64; N], D::Error> {
        vector(d, self.what, Check::Finite, false)
    }
}

/// Reads `((..), (..), (..))`: three `N`-vectors (or `[..]` lists).
struct ThreeVectors<'a, const N: usize> {
    what: &'a str,
    expecting: &'a str,
}

impl<'de, const N: usize> Visitor<'de> for ThreeVectors<'_, N> {
    type Value = [[f64; N]; 3];

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.expecting)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut out = [[0.0; N]; 3];
        for (i, slot) in out.iter_mut().enumerate() {
            let seed = VectorSeed::<N> { what: self.what };
            *slot = seq
                .next_element_seed(seed)?
                .ok_or_else(|| de::Error::invalid_length(i, &self))?;
        }
        let mut extra = 0;
        while seq.next_element::<de::IgnoredAny>()?.is_some() {
            extra += 1;
        }
        if extra > 0 {
            return Err(de::Error::invalid_length(3 + extra, &self));
        }
        Ok(out)
    }
}

fn three_vectors<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
    what: &str,
    expecting: &str,
) -> Result<[[f64; N]; 3], D::Error> {
    d.deserialize_any(ThreeVectors::<N> { what, expecting })
}

/// A triangle's corners `((x, y, z), (x, y, z), (x, y, z))`; rejects zero area.
pub(super) fn triangle<'de, D: Deserializer<'de>>(d: D) -> Result<[[f64; 3]; 3], D::Error> {
    let v = three_vectors::<D, 3>(
        d,
        "coordinate",
        "three vertices ((x, y, z), (x, y, z), (x, y, z))",
    )?;
    if degenerate_triangle(&v) {
        return Err(de::Error::custom(format!(
            "degenerate triangle: the vertices {}, {}, {} have zero area \
             (they coincide or lie on one line)",
            NumVec(&v[0]),
            NumVec(&v[1]),
            NumVec(&v[2])
        )));
    }
    Ok(v)
}

/// Per-vertex normals of a triangle: three non-zero vectors, returned normalised.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Normals(pub [[f64; 3]; 3]);

impl<'de> Deserialize<'de> for Normals {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = three_vectors::<D, 3>(
            d,
            "normal component",
            "three normals ((x, y, z), (x, y, z), (x, y, z))",
        )?;
        let mut out = [[0.0; 3]; 3];
        for (o, n) in out.iter_mut().zip(v.iter()) {
            *o = normalize(*n).ok_or_else(|| {
                de::Error::custom(format!(
                    "expected three non-zero normals, found {}",
                    NumVec(n)
                ))
            })?;
        }
        Ok(Normals(out))
    }
}

/// Per-vertex texture coordinates of a triangle: `((u, v), (u, v), (u, v))`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Uvs(pub [[f64; 2]; 3]);

impl<'de> Deserialize<'de> for Uvs {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        three_vectors::<D, 2>(
            d,
            "texture coordinate",
            "three texture coordinates ((u, v), (u, v), (u, v))",
        )
        .map(Uvs)
    }
}
