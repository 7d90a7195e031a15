//! Sampling a keyframed track at a time: step, linear and smooth (Catmull-Rom) interpolation,
//! generic over what is interpolated (numbers, vectors, unit quaternions).
//!
//! Smooth is the Catmull-Rom spline through the keys in the Barry-Goldman pyramid form: three
//! levels of [`Blend::blend`] between the two keys around `t` and their neighbours, weighted
//! by the key times (non-uniform spacing is allowed; with equal spacing it is the classic
//! uniform Catmull-Rom). At either end a missing neighbour is extrapolated along the first or
//! last segment, so keys on a straight line give that line. Built from blends only, it works
//! unchanged for quaternions, where every blend is a slerp and the result stays unit length.

use super::quat::Quat;

/// How a track's value moves between its keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Interpolation {
    /// Hold each key's value until the next key.
    Step,
    /// Straight from key to key (slerp for rotations).
    #[default]
    Linear,
    /// Catmull-Rom through the keys (spherical for rotations).
    Smooth,
}

/// One key: a value at a time (in frames; fractional times are allowed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Key<V> {
    pub frame: f64,
    pub value: V,
}

/// A value that can be blended: `blend(a, b, s)` is `a` at 0, `b` at 1, and continues past.
pub trait Blend: Copy {
    fn blend(a: Self, b: Self, s: f64) -> Self;
}

impl Blend for f64 {
    fn blend(a: f64, b: f64, s: f64) -> f64 {
        a + (b - a) * s
    }
}

impl Blend for [f64; 3] {
    fn blend(a: [f64; 3], b: [f64; 3], s: f64) -> [f64; 3] {
        [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * s)
    }
}

impl Blend for Quat {
    fn blend(a: Quat, b: Quat, s: f64) -> Quat {
        Quat::slerp(a, b, s)
    }
}

/// The value of `keys` (sorted by strictly increasing time, at least one) at time `t`. At a
/// key's time it is that key's value exactly; before the first key the first value holds,
/// after the last the last. `None` only for an empty list.
pub fn sample<V: Blend>(keys: &[Key<V>], interp: Interpolation, t: f64) -> Option<V> {
    let first = keys.first()?;
    let last = keys.last()?;
    if t <= first.frame {
        return Some(first.value);
    }
    if t >= last.frame {
        return Some(last.value);
    }
    // keys[i].frame <= t < keys[i + 1].frame; both exist because first < t < last.
    let i = keys.partition_point(|k| k.frame <= t).saturating_sub(1);
    let (k1, k2) = (keys.get(i)?, keys.get(i + 1)?);
    if t == k1.frame {
        return Some(k1.value);
    }
    let u = (t - k1.frame) / (k2.frame - k1.frame);
    Some(match interp {
        Interpolation::Step => k1.value,
        Interpolation::Linear => V::blend(k1.value, k2.value, u),
        Interpolation::Smooth => {
            let k0 = match i.checked_sub(1).and_then(|j| keys.get(j)) {
                Some(k) => *k,
                None => extrapolate(k1, k2, -1.0),
            };
            let k3 = match keys.get(i + 2) {
                Some(k) => *k,
                None => extrapolate(k1, k2, 2.0),
            };
            catmull_rom([k0, *k1, *k2, k3], t)
        }
    })
}

/// A virtual key along the segment `a`-`b`, at `s` segment lengths from `a`.
fn extrapolate<V: Blend>(a: &Key<V>, b: &Key<V>, s: f64) -> Key<V> {
    Key {
        frame: a.frame + (b.frame - a.frame) * s,
        value: V::blend(a.value, b.value, s),
    }
}

/// The Barry-Goldman pyramid for `k[1].frame < t < k[2].frame`.
fn catmull_rom<V: Blend>(k: [Key<V>; 4], t: f64) -> V {
    let at = |a: &Key<V>, b: &Key<V>| (t - a.frame) / (b.frame - a.frame);
    let a1 = V::blend(k[0].value, k[1].value, at(&k[0], &k[1]));
    let a2 = V::blend(k[1].value, k[2].value, at(&k[1], &k[2]));
    let a3 = V::blend(k[2].value, k[3].value, at(&k[2], &k[3]));
    let b1 = V::blend(a1, a2, at(&k[0], &k[2]));
    let b2 = V::blend(a2, a3, at(&k[1], &k[3]));
    V::blend(b1, b2, at(&k[1], &k[2]))
}

/// The keys of `t`'s segment (the last key at or before `t`, the first after it): the bounds a
/// smooth bounded property is clamped to. `None` outside the keys or for a single key.
pub fn segment<V: Copy>(keys: &[Key<V>], t: f64) -> Option<(V, V)> {
    let i = keys.partition_point(|k| k.frame <= t).checked_sub(1)?;
    Some((keys.get(i)?.value, keys.get(i + 1)?.value))
}
