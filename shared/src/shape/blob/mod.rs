//! Density spheres (濃度球, metaballs): the iso-surface `F(p) = T` of a sum of radial fields.
//!
//! Each ball `i` (centre `c`, radius `d`, strength `b`, which may be negative) contributes
//! `f_i(r)`, `r = |p - c|`, and nothing beyond `d`. Two kernels:
//!
//! * [`Kernel::Links`] (Nishimura et al., used by LINKS-1):
//!   `f(r) = b(1 - 3r²/d²)` for `r <= d/3`, `(3b/2)(1 - r/d)²` for `d/3 < r <= d`.
//! * [`Kernel::Wyvill`]: `f(r) = b(1 - r²/d²)²` for `r <= d`.
//!
//! The inside of the blob is where `F > T`; the outward normal is `-∇F / |∇F|`.
//! The threshold must be positive (the scene loader enforces it): with `T <= 0` the region
//! far from every ball (`F = 0`) would be "inside", so [`BlobGroup::intersect`] reports no
//! hit for such a group.
//!
//! # Root finding without skipping thin features
//!
//! Along a ray with unit direction `u`, `F(s) = Σ f_i(|o + s u - c_i|)`. The march keeps a
//! *window* `[s, s_end]` in which the set of balls whose influence sphere the ray is inside
//! does not change (`s_end` is the next entry/exit event of any ball). For that window it
//! computes, from only the balls overlapping it:
//!
//! * `L = Σ max|f_i'|`: `|dF/ds| <= L`, because `r(s)` is 1-Lipschitz.
//! * `M = Σ max|d²f_i/ds²|`, a bound on the second derivative along any line.
//! * an upper and a lower bound of `F` over the whole window (each kernel is monotone in `r`,
//!   and `r(s)` is convex, so the extreme distances are the closest point and an end point).
//!
//! If the bounds show `F` stays on the starting side of `T` over the window, the march jumps
//! to `s_end` (in particular every stretch where the ray is inside no influence sphere, where
//! `F = 0 < T`, costs nothing; a ray starting in no influence sphere doesn't even evaluate
//! the field before its first entry). Otherwise it takes the *safe step*
//! `h = max(a / L, 2a / (v + sqrt(v² + 2Ma)))`, `a = |F(s) - T|`, `v` the speed towards `T`
//! (`dF/ds` from outside, `-dF/ds` from inside). The first is the Lipschitz bound; the
//! second is the first root of the Taylor envelope `-a + v h + M h²/2`, which bounds
//! `±(F(s + h) - T)` from above. Both are proven root-free (within the window, which the
//! step never leaves), so their maximum is too. The second converges quadratically onto a
//! transversal root, and near a tangency shrinks geometrically (by a factor of at least
//! `1 - 1/(1 + √2) ≈ 0.59` a step) instead of crawling.
//!
//! When the safe step falls under `tol` the march *probes*: it steps by at most `tol` (twice
//! the Newton estimate when that is smaller) and looks for a sign change, which is then
//! refined by safeguarded Newton/bisection. Consequently **every crossing whose stretch of
//! the ray inside (or outside) the surface is longer than `tol` is found, and the first
//! one is reported**; only features thinner than `tol` along the ray may be missed, and
//! features whose field exceeds `T` by less than the rounding noise of `F` (the sign test
//! uses the computed field). A hit is only ever reported at a bracketed sign change
//! (except at the step cap, see below), so a ray passing close to the surface without
//! touching it never produces a false hit.
//!
//! `tol = max(sqrt(eps)/2 · d_min, 64 eps · scale)`, `d_min` the smallest radius among the
//! balls the ray crosses and `scale` the largest distance from the ray origin to where it
//! leaves one: 1.2e-4 d for f32, 5.3e-9 d for f64, 2e-3 d for Q16.16. Half the
//! significant digits is what a grazing contact can resolve at all: near a tangency
//! `F - T` is quadratic in the distance, so the rounding noise of `F` (`~eps`) blurs the
//! contact over `~sqrt(eps) d`. The second term keeps `tol` above the resolution of `t`
//! itself for origins far from the blob.
//!
//! Fixed point (`Real::ABSOLUTE_ROUNDING`) resolves `t` to a step whatever its size, so
//! there `scale` is 1 and the refinement's resolution is 4 steps (a float's is
//! `8 eps (scale + |t_min|)`); the field's rounding bound is absolute too (see `sample`),
//! and a bracket wider than `tol` is narrowed even where `|F - T|` is within that bound
//! (small balls keep few levels of `q = r²`). The tests run every case in Q16.16 as well,
//! with tolerances derived from its resolution (`tests.rs`); features thinner than the
//! format resolves (a neck whose field exceeds `T` by less than its rounding bound, about
//! 20 steps) are outside the guarantee, as sub-`tol` ones are for floats.
//!
//! Cost: a transversal hit takes ~8 passes over the balls (f32) / ~9 (f64); a miss ~3. Each
//! near-tangency costs `O(log(d / tol))` passes (measured: ~20 in f32, 35-55 in f64 for an
//! exact tangent). The march is capped at [`MAX_STEPS`] passes (the refinement at
//! [`MAX_REFINE`]); only pathological rays reach it, e.g. one running 1e-9 above a row of
//! ten identical bulges (12 Wyvill balls in a line) in f64. At the cap the ray is reported as
//! a hit at the current point, with `t_error = 16 tol`, if `|F - T| <= 16 L tol` there (the
//! surface may be within 16 `tol`), and as a miss otherwise.
//!
//! The code path uses no heap, no recursion, no panics; balls are fetched by index through
//! a closure (the caller decodes them in place from a byte image) and re-fetched on every
//! pass over the group.

use crate::geom::{Ray, Vec3};
use crate::num::Real;

/// Most field evaluations of the march before giving up (see the module docs).
pub const MAX_STEPS: u32 = 512;
/// Most field evaluations refining a bracketed crossing.
pub const MAX_REFINE: u32 = 64;
/// Looser tolerance, in units of `tol`, accepted at the step cap.
const LOOSE: i32 = 16;

pub use crate::math::solid::{Ball, Kernel};

/// A blob group: `count` balls fetched by index through `ball(i)` (the caller decodes them
/// from a byte image in place, so no slice of [`Ball`] is available), kernel and threshold.
pub struct BlobGroup<T, F: Fn(usize) -> Ball<T>> {
    pub count: usize,
    pub ball: F,
    pub kernel: Kernel,
    /// Iso-value `T` of the surface; must be > 0.
    pub threshold: T,
}

/// A ray/blob hit: parameter `t` along the caller's ray and an absolute bound on its error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlobHit<T> {
    pub t: T,
    /// First-order bound on `|t - t_exact|` from the refinement bracket and the rounding
    /// error of the field (see [`BlobGroup::intersect`]).
    pub t_error: T,
}

/// Work counters (summed over calls).
#[derive(Default, Clone, Copy, Debug)]
pub struct BlobStats {
    /// Passes over the balls that evaluated the field (march and refinement). Each call
    /// also makes one cheaper pass that only intersects the influence spheres.
    pub field_evals: u32,
    /// March steps (window jumps, safe steps and probes).
    pub steps: u32,
}

// ---------------------------------------------------------------------------------------
// Kernels.
//
// Maximum slope, max over r of |f'(r)| (the Lipschitz constant of p -> f(|p - c|)):
// * Links, inner branch: f' = -6br/d², |f'| grows to 2|b|/d at r = d/3. Outer branch:
//   f' = -(3b/d)(1 - r/d), |f'| falls from (3|b|/d)(2/3) = 2|b|/d at r = d/3 to 0 at d.
//   Both branches meet with value 2b/3 and slope -2b/d, so f is C¹ and L = 2|b|/d.
// * Wyvill: f' = -(4b/d) s(1 - s²), s = r/d; (s - s³)' = 1 - 3s² = 0 at s = 1/√3, where
//   s - s³ = (1/√3)(2/3) = 2/(3√3). L = 8|b|/(3√3 d) ≈ 1.5396 |b|/d. f'(d) = 0 for both
//   kernels, so the cut-off at d keeps f C¹.
//
// Second derivative along a line: with r(s) = sqrt(w² + (s - s_c)²), r' ∈ [-1, 1] and
// r'' = (1 - r'²)/r, so d²f/ds² = f''(r) r'² + (f'(r)/r)(1 - r'²): a convex combination of
// f''(r) and f'(r)/r, and M = max over r of max(|f''|, |f'/r|):
// * Links inner: f'' = f'/r = -6b/d². Outer: f'' = 3b/d², f'/r = -(3b/d²)(d/r - 1) ∈
//   (-6b/d², 0]. M = 6|b|/d². (f'' jumps at d/3 and at d, but f' is Lipschitz with M, which
//   is all the Taylor bound needs.)
// * Wyvill: f'' = -(4b/d²)(1 - 3s²) ∈ [-4b/d², 8b/d²], f'/r = -(4b/d²)(1 - s²) ∈
//   [-4b/d², 0]. M = 8|b|/d².
// ---------------------------------------------------------------------------------------

/// 8/(3√3) = 1.53960071783900..., rounded up so the bound stays safe after rounding to f32.
const WYVILL_SLOPE: f64 = 1.539_601;

impl Kernel {
    /// Field value and its derivative with respect to `q = r²`, for `q < d²`.
    #[inline]
    fn eval<T: Real>(self, q: T, k: &BallConst<T>) -> (T, T) {
        if q >= k.d2 {
            return (T::ZERO, T::ZERO);
        }
        match self {
            Kernel::Links => {
                let three = T::from_i32(3);
                if q * T::from_i32(9) <= k.d2 {
                    let c = three * k.b * k.inv_d2;
                    (k.b - c * q, -c)
                } else {
                    // r > d/3 > 0 here, so the division is safe.
                    let r = q.sqrt();
                    let x = T::ONE - r * k.inv_d;
                    let hb = T::from_f32(1.5) * k.b;
                    (hb * x * x, -(hb * x * k.inv_d) / r)
                }
            }
            Kernel::Wyvill => {
                let x = T::ONE - q * k.inv_d2;
                let bx = k.b * x;
                (bx * x, -T::TWO * bx * k.inv_d2)
            }
        }
    }

    /// Field value only.
    #[inline]
    fn value<T: Real>(self, q: T, k: &BallConst<T>) -> T {
        self.eval(q, k).0
    }

    /// `(L, M)`: bounds on `|df/ds|` and `|d²f/ds²|` along any line (see above).
    ///
    /// (Evaluating these at the worst radius within the window's range of `r` instead
    /// saves ~6% of the steps but costs two more square roots per ball and pass: ~10%
    /// slower overall in a host benchmark, so the global constants are used.)
    #[inline]
    fn line_bounds<T: Real>(self, k: &BallConst<T>) -> (T, T) {
        let ab = k.b.abs();
        match self {
            Kernel::Links => (T::TWO * ab * k.inv_d, T::from_i32(6) * ab * k.inv_d2),
            Kernel::Wyvill => (
                T::from_f64(WYVILL_SLOPE) * ab * k.inv_d,
                T::from_i32(8) * ab * k.inv_d2,
            ),
        }
    }
}

/// Per-ball constants derived once per fetch.
#[derive(Clone, Copy)]
struct BallConst<T> {
    d: T,
    d2: T,
    inv_d: T,
    inv_d2: T,
    b: T,
}

impl<T: Real> BallConst<T> {
    /// `None` for a ball that can't contribute (non-positive or non-finite radius, b = 0).
    #[inline]
    fn new(ball: &Ball<T>) -> Option<Self> {
        let d = ball.radius;
        let ok = d > T::ZERO && d.is_finite() && ball.strength != T::ZERO;
        if !ok {
            return None;
        }
        let inv_d = d.recip();
        Some(Self {
            d,
            d2: d * d,
            inv_d,
            inv_d2: inv_d * inv_d,
            b: ball.strength,
        })
    }
}

/// A ball as seen from a ray `o + s u` (unit `u`).
#[derive(Clone, Copy)]
struct Span<T> {
    k: BallConst<T>,
    /// Parameter of the point closest to the centre.
    tc: T,
    /// Squared distance from the centre to the line.
    w2: T,
    /// Where the line enters and leaves the influence sphere.
    t_in: T,
    t_out: T,
}

impl<T: Real> Span<T> {
    /// Squared distance to the centre at parameter `s`.
    #[inline]
    fn q_at(&self, s: T) -> T {
        let ds = s - self.tc;
        self.w2 + ds * ds
    }
}

/// What one pass over the balls learns at `s` about the window `[s, s_end]`.
#[derive(Clone, Copy)]
struct Sample<T> {
    /// `F(s)`.
    f: T,
    /// `dF/ds` at `s`.
    df: T,
    /// Bound on `|dF/ds|` over the window.
    lip: T,
    /// Bound on `|d²F/ds²|` over the window.
    curv: T,
    /// Bounds of `F` over the window.
    upper: T,
    lower: T,
    /// Estimated bound on the rounding error of the computed `F(s)`.
    err: T,
    /// The two smallest distinct entry/exit events after `s`.
    e1: T,
    e2: T,
}

/// Largest root-free step, at most `w` (the rest of the window), from a point where
/// `|F - T| = a`, approaching `T` at speed `v` (`v < 0`: moving away), given `|F'| <= lip`
/// and `|F''| <= curv` over the window. Quotients are only formed when they are below `w`,
/// so a format without infinities can't overflow.
#[inline]
fn safe_step<T: Real>(a: T, v: T, lip: T, curv: T, w: T) -> T {
    // Lipschitz bound: |F - T| can't fall to 0 before a / lip.
    let h1 = if a < lip * w { a / lip } else { w };
    // Taylor envelope: smallest positive root of a - v h - curv h²/2 = 0, in the
    // cancellation-free form 2a / (v + sqrt(v² + 2 curv a)).
    let den = v + (v * v + T::TWO * curv * a).sqrt();
    let h2 = if a + a < den * w { (a + a) / den } else { w };
    h1.max(h2)
}

impl<T: Real, F: Fn(usize) -> Ball<T>> BlobGroup<T, F> {
    /// Field value `Σ f_i(|p - c_i|)` at `p`.
    pub fn field(&self, p: Vec3<T>) -> T {
        let mut sum = T::ZERO;
        for i in 0..self.count {
            let ball = (self.ball)(i);
            if let Some(k) = BallConst::new(&ball) {
                sum += self.kernel.value((p - ball.center).length_sq(), &k);
            }
        }
        sum
    }

    /// Gradient of the field at `p`: `Σ (df/dq) 2 (p - c_i)`. The outward surface normal is
    /// `-gradient` normalised (the field decreases out of the blob).
    pub fn gradient(&self, p: Vec3<T>) -> Vec3<T> {
        let mut g = Vec3::zero();
        for i in 0..self.count {
            let ball = (self.ball)(i);
            if let Some(k) = BallConst::new(&ball) {
                let rel = p - ball.center;
                let (_, dfdq) = self.kernel.eval(rel.length_sq(), &k);
                g = g + rel * (dfdq + dfdq);
            }
        }
        g
    }

    /// Axis-aligned bounds of the surface: the union of the positive balls' influence
    /// spheres (outside them `F <= 0 < T`). With no positive ball the box is inverted
    /// (`min = MAX`, `max = -MAX`), i.e. empty.
    pub fn bounds(&self) -> (Vec3<T>, Vec3<T>) {
        let mut lo = Vec3::splat(T::MAX);
        let mut hi = Vec3::splat(-T::MAX);
        for i in 0..self.count {
            let ball = (self.ball)(i);
            if ball.strength > T::ZERO && ball.radius > T::ZERO {
                let r = Vec3::splat(ball.radius);
                lo = lo.min(ball.center - r);
                hi = hi.max(ball.center + r);
            }
        }
        (lo, hi)
    }

    /// The ball `i` against the line `o + s u`, or `None` if the line misses its influence
    /// sphere (or the ball is degenerate).
    #[inline]
    fn span(&self, i: usize, o: Vec3<T>, u: Vec3<T>) -> Option<Span<T>> {
        let ball = (self.ball)(i);
        let k = BallConst::new(&ball)?;
        let oc = ball.center - o;
        let tc = oc.dot(u);
        // Distance to the line from the perpendicular vector, not |oc|² - tc², which
        // cancels when the ball is far from the origin compared with its radius.
        let w2 = (oc - u * tc).length_sq();
        let crosses = w2 < k.d2;
        if !crosses {
            return None;
        }
        let hc = (k.d2 - w2).sqrt();
        // Roots of s² - 2 tc s + (|oc|² - d²): the larger-magnitude one without
        // cancellation, the other from the product of the roots. |q| >= hc > 0.
        let c = oc.length_sq() - k.d2;
        let (t_in, t_out) = if tc >= T::ZERO {
            let q = tc + hc;
            ((c / q).min(q), q)
        } else {
            let q = tc - hc;
            (q, (c / q).max(q))
        };
        Some(Span {
            k,
            tc,
            w2,
            t_in,
            t_out,
        })
    }

    /// The first entry/exit event after `s` (or `T::MAX`).
    fn next_event(&self, o: Vec3<T>, u: Vec3<T>, s: T) -> T {
        let mut e = T::MAX;
        for i in 0..self.count {
            if let Some(sp) = self.span(i, o, u) {
                if sp.t_in > s {
                    e = e.min(sp.t_in);
                } else if sp.t_out > s {
                    e = e.min(sp.t_out);
                }
            }
        }
        e
    }

    /// One pass over the balls: the field at `s` and its bounds over `[s, s_end]`.
    fn sample(&self, o: Vec3<T>, u: Vec3<T>, s: T, s_end: T) -> Sample<T> {
        let mut out = Sample {
            f: T::ZERO,
            df: T::ZERO,
            lip: T::ZERO,
            curv: T::ZERO,
            upper: T::ZERO,
            lower: T::ZERO,
            err: T::ZERO,
            e1: T::MAX,
            e2: T::MAX,
        };
        let mut n: i32 = 0;
        let mut sum_abs = T::ZERO;
        let g10 = T::err_gamma(10);
        let g8 = T::err_gamma(8);
        for i in 0..self.count {
            let Some(sp) = self.span(i, o, u) else {
                continue;
            };
            push_event(&mut out.e1, &mut out.e2, s, sp.t_in);
            push_event(&mut out.e1, &mut out.e2, s, sp.t_out);
            let overlaps = sp.t_out >= s && sp.t_in <= s_end;
            if !overlaps {
                continue;
            }
            let k = &sp.k;
            let q = sp.q_at(s);
            // Range of q over the window (clipped to the ball's span): the closest point,
            // and the farther window end if the ball covers the window, else its boundary.
            let lo = s.max(sp.t_in);
            let hi = s_end.min(sp.t_out);
            let q_near = sp.q_at(sp.tc.max(lo).min(hi));
            let covers = sp.t_in <= s && sp.t_out >= s_end;
            let q_far = if covers { q.max(sp.q_at(s_end)) } else { k.d2 };
            let (lip, curv) = self.kernel.line_bounds(k);
            let (f, dfdq) = self.kernel.eval(q, k);
            out.f += f;
            out.df += dfdq * T::TWO * (s - sp.tc);
            out.lip += lip;
            out.curv += curv;
            // Rounding (standard model, first order): oc, tc and w carry absolute errors
            // <= gamma(7)|oc|, so q = w² + (s - tc)² is off by <= 2√2 r gamma(7)|oc| +
            // gamma(4) r², i.e. r by <= gamma(10)|oc| + gamma(2) d, with |oc| <= |tc| + d.
            // That moves f by at most |f'| <= lip times as much; the kernel adds
            // gamma(8)|b|.
            //
            // Fixed point rounds absolutely, so none of that grows with |oc| (the relative
            // model made it 160 steps times lip for a ball 10 units away): oc is exact, tc
            // and the perpendicular oc - u tc are off by half a step per coordinate, so q
            // by at most (2.74 r + 1) steps, which moves f by |df/dq| <= min(lip / 2r,
            // curv / 2) times as much: at most (1.4 lip + curv / 2) steps; the square
            // root's half step moves it by lip / 2 more. The kernel's own rounding, with
            // the reciprocals 1/d and 1/d² rounded once each, is at most
            // |b| (1 + d + d²/4) steps and 2 more (measured: 2.3 steps for d = 3, b = 1;
            // 28.5 for d = 10, b = 1.5; 2.6 for d = 0.3, b = 0.5). The sums are exact.
            out.err += if T::ABSOLUTE_ROUNDING {
                let d2_4 = k.d2 * T::HALF * T::HALF;
                (lip * T::from_i32(3) + curv + k.b.abs() * (T::ONE + k.d + d2_4) + T::TWO)
                    * T::epsilon()
            } else {
                lip * g10 * (sp.tc.abs() + k.d + k.d) + g8 * k.b.abs()
            };
            sum_abs += f.abs();
            n = n.saturating_add(1);
            // Extremes of f over the window: each kernel decreases with r (for b > 0).
            let f_near = self.kernel.value(q_near, k);
            let f_far = self.kernel.value(q_far, k);
            if k.b > T::ZERO {
                out.upper += f_near;
                out.lower += f_far;
            } else {
                out.upper += f_far;
                out.lower += f_near;
            }
        }
        if !T::ABSOLUTE_ROUNDING {
            out.err += T::err_gamma(n.saturating_add(2)) * (sum_abs + self.threshold);
        }
        out
    }

    /// First crossing of `field == threshold` along the ray for `t` in `(t_min, t_max)`.
    ///
    /// Works from outside (`F < T` at `t_min`, finds the entry) and from inside (`F > T`,
    /// e.g. refraction rays, finds the exit); the side is the sign of `F(t_min) - T`.
    /// `ray.dir` need not be unit length (it is normalised internally; a unit direction, as
    /// the renderer passes, is used as is so `t` is bit-for-bit the caller's parameter).
    ///
    /// Guarantees (module docs): no crossing is skipped unless the ray's stretch through
    /// it is shorter than `tol` (1.2e-4 of the smallest crossed radius in f32, 5.3e-9 in
    /// f64, 2e-3 in Q16.16), and hits are reported only at a bracketed sign change. `t_error` bounds
    /// `|t - t_exact|` to first order: the final bracket, widened by the field's rounding
    /// error divided by the slope along the ray. Where the ray meets the surface almost
    /// tangentially that quotient is capped at `tol` (the position along the ray is
    /// ill-conditioned there, while the distance to the surface along the normal stays
    /// small). Returns `None` for a threshold `<= 0`, a zero or non-finite direction, and
    /// an empty interval.
    pub fn intersect(
        &self,
        ray: &Ray<T>,
        t_min: T,
        t_max: T,
        stats: &mut BlobStats,
    ) -> Option<BlobHit<T>> {
        let thr = self.threshold;
        let len2 = ray.dir.length_sq();
        let valid = thr > T::ZERO && t_max > t_min && len2 > T::ZERO && len2.is_finite();
        if !valid {
            return None;
        }
        let unit = (len2 - T::ONE).abs() <= T::err_gamma(4);
        let (u, len) = if unit {
            (ray.dir, T::ONE)
        } else {
            let l = len2.sqrt();
            (ray.dir * l.recip(), l)
        };
        let o = ray.origin;
        let s_min = t_min * len;
        let s_max = if len > T::ONE && t_max > T::MAX / len {
            T::MAX
        } else {
            t_max * len
        };

        // Pre-pass: which balls matter, their smallest radius, the scale of the
        // coordinates, and the first event.
        let mut any_positive = false;
        let mut d_min = T::MAX;
        let mut scale = T::ZERO;
        let (mut e1, mut e2) = (T::MAX, T::MAX);
        let mut covered = false;
        for i in 0..self.count {
            if let Some(sp) = self.span(i, o, u) {
                push_event(&mut e1, &mut e2, s_min, sp.t_in);
                push_event(&mut e1, &mut e2, s_min, sp.t_out);
                covered |= sp.t_in <= s_min && sp.t_out > s_min;
                if sp.t_out > s_min && sp.t_in < s_max {
                    any_positive |= sp.k.b > T::ZERO;
                    d_min = d_min.min(sp.k.d);
                    scale = scale.max(sp.tc.abs() + sp.k.d + sp.k.d);
                }
            }
        }
        if !any_positive {
            return None;
        }
        let eps = T::epsilon();
        // Fixed point resolves s to a step whatever its size: the scale terms, which keep
        // a float's tol and t_res above the resolution of s near `scale`, are absolute
        // there (relative, they stopped the refinement at 8 eps (scale + s), 2e-3 for a
        // ball 10 units away, 130 steps).
        let scale = if T::ABSOLUTE_ROUNDING { T::ONE } else { scale };
        let tol = (eps.sqrt() * T::HALF * d_min).max(T::from_i32(64) * eps * scale);
        let t_res = if T::ABSOLUTE_ROUNDING {
            T::from_i32(4) * eps
        } else {
            T::from_i32(8) * eps * (scale + s_min.abs())
        };

        let mut s = s_min;
        let mut s_end = e1.min(s_max);
        let mut inside = false;
        // Last point of the march, still on the starting side.
        let mut prev: Option<Point<T>> = None;
        if !covered {
            // The origin is in no influence sphere: F = 0 < T there and up to the first
            // event, so start outside at that event without evaluating anything.
            if e1 >= s_max {
                return None;
            }
            prev = Some(Point {
                s: s_min,
                g: -thr,
                dg: T::ZERO,
                err: T::ZERO,
            });
            s = e1;
            s_end = e2.min(s_max);
        }
        let mut steps = 0u32;
        loop {
            let smp = self.sample(o, u, s, s_end);
            steps += 1;
            stats.steps = stats.steps.saturating_add(1);
            stats.field_evals = stats.field_evals.saturating_add(1);
            let g = smp.f - thr;
            if !g.is_finite() {
                return None;
            }
            let here = Point {
                s,
                g,
                dg: smp.df,
                err: smp.err,
            };
            match prev {
                None => inside = g > T::ZERO,
                Some(p) => {
                    let crossed = if inside { g <= T::ZERO } else { g >= T::ZERO };
                    if crossed {
                        let range = (s_min, s_max);
                        let r = self.refine(o, u, inside, p, here, t_res, tol, range, stats);
                        return r.map(|(t, e)| to_hit(t, e, len, unit));
                    }
                }
            }
            if s >= s_max {
                return None;
            }
            let a = g.abs();
            if steps >= MAX_STEPS {
                let near = a <= T::from_i32(LOOSE) * tol * smp.lip;
                let accept = near && s > s_min;
                return if accept {
                    Some(to_hit(s, T::from_i32(LOOSE) * tol, len, unit))
                } else {
                    None
                };
            }
            prev = Some(here);
            let skip = if inside {
                smp.lower > thr + smp.err
            } else {
                smp.upper < thr - smp.err
            };
            let mut s_new = if skip {
                s_end
            } else {
                let v = if inside { -smp.df } else { smp.df };
                let mut h = safe_step(a, v, smp.lip, smp.curv, s_end - s);
                if h < tol {
                    // Probe: at most tol, so a feature longer than tol can't be jumped.
                    let newton = if a < v * tol { a / v } else { tol };
                    h = h.max((newton + newton).min(tol));
                }
                s + h.max(t_res)
            };
            let before_end = s_new < s_end;
            if !before_end {
                // Also catches NaN. Entering the next window: its end is the next event.
                s_new = s_end;
                let next = if smp.e1 > s_new {
                    smp.e1
                } else if smp.e2 > s_new {
                    smp.e2
                } else {
                    self.next_event(o, u, s_new)
                };
                s_end = next.min(s_max);
            }
            s = s_new;
        }
    }

    /// Narrow a bracketed crossing: `lo` on the starting side, `hi` crossed. Safeguarded
    /// Newton (the derivative comes with every sample) with bisection whenever a step
    /// would leave the bracket or the bracket stopped halving. Returns `(s, s_error)`.
    #[allow(clippy::too_many_arguments)]
    fn refine(
        &self,
        o: Vec3<T>,
        u: Vec3<T>,
        inside: bool,
        lo: Point<T>,
        hi: Point<T>,
        t_res: T,
        tol: T,
        (s_min, s_max): (T, T),
        stats: &mut BlobStats,
    ) -> Option<(T, T)> {
        let mut lo = lo;
        let mut hi = hi;
        let mut best = if lo.g.abs() < hi.g.abs() { lo } else { hi };
        let mut prev_width = (hi.s - lo.s) * T::TWO;
        let mut it = 0;
        while it < MAX_REFINE {
            let width = hi.s - lo.s;
            // Fixed point also narrows a bracket wider than tol whose field is within its
            // rounding bound of T: that bound is large for small balls (|F - T| is known
            // to ~900 steps for d = 0.1, where q = r² keeps 655 levels), and stopping on
            // it left brackets of 3e-3 where tol is 1e-3. The crossing the computed signs
            // bracket is then within tol, and the t_error within 2 tol, as for floats.
            let open = width > t_res
                && ((best.g != T::ZERO && best.g.abs() > best.err)
                    || (T::ABSOLUTE_ROUNDING && width > tol));
            if !open {
                break;
            }
            let mut x = lo.s + width * T::HALF;
            if width <= prev_width * T::HALF && best.dg != T::ZERO {
                let xn = best.s - best.g / best.dg;
                if xn > lo.s && xn < hi.s {
                    x = xn;
                }
            }
            prev_width = width;
            let smp = self.sample(o, u, x, x);
            stats.field_evals = stats.field_evals.saturating_add(1);
            let p = Point {
                s: x,
                g: smp.f - self.threshold,
                dg: smp.df,
                err: smp.err,
            };
            if !p.g.is_finite() {
                break;
            }
            let crossed = if inside {
                p.g <= T::ZERO
            } else {
                p.g >= T::ZERO
            };
            if crossed {
                hi = p;
            } else {
                lo = p;
            }
            if p.g.abs() <= best.g.abs() {
                best = p;
            }
            it += 1;
        }
        // The interval is open at t_min: a best point there stands for the crossing just
        // after it. It is open at t_max too (hi <= s_max always).
        if best.s <= s_min {
            best = hi;
        }
        if best.s >= s_max {
            return None;
        }
        let slope = best.dg.abs();
        let bracket = (best.s - lo.s).max(hi.s - best.s);
        let mut e = bracket + tol;
        if slope > T::ZERO {
            let noise = (best.err / slope).min(tol);
            let local = (best.g.abs() + best.err) / slope;
            e = (bracket + noise).min(local + local);
        }
        Some((best.s, e + t_res))
    }
}

/// Keep `e1 < e2` the two smallest distinct events after `s`.
#[inline]
fn push_event<T: Real>(e1: &mut T, e2: &mut T, s: T, e: T) {
    if e > s {
        if e < *e1 {
            *e2 = *e1;
            *e1 = e;
        } else if e > *e1 && e < *e2 {
            *e2 = e;
        }
    }
}

/// A sampled point of the march or the refinement.
#[derive(Clone, Copy)]
struct Point<T> {
    s: T,
    g: T,
    dg: T,
    err: T,
}

/// Back from the unit-direction parameter `s` to the caller's `t`.
#[inline]
fn to_hit<T: Real>(s: T, e: T, len: T, unit: bool) -> BlobHit<T> {
    if unit {
        BlobHit { t: s, t_error: e }
    } else {
        let inv = len.recip();
        BlobHit {
            t: s * inv,
            t_error: (e * inv) * (T::ONE + T::err_gamma(3)) + (s * inv).abs() * T::err_gamma(3),
        }
    }
}

#[cfg(test)]
mod tests;
