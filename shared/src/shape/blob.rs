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
//! leaves one: 1.2e-4 d for f32, 5.3e-9 d for f64. Half the significant digits is what a
//! grazing contact can resolve at all: near a tangency `F - T` is quadratic in the distance,
//! so the rounding noise of `F` (`~eps`) blurs the contact over `~sqrt(eps) d`. The second
//! term keeps `tol` above the resolution of `t` itself for origins far from the blob.
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
            out.err += lip * g10 * (sp.tc.abs() + k.d + k.d) + g8 * k.b.abs();
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
        out.err += T::err_gamma(n.saturating_add(2)) * (sum_abs + self.threshold);
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
    /// f64), and hits are reported only at a bracketed sign change. `t_error` bounds
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
        let tol = (eps.sqrt() * T::HALF * d_min).max(T::from_i32(64) * eps * scale);
        let t_res = T::from_i32(8) * eps * (scale + s_min.abs());

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
            let open = width > t_res && best.g != T::ZERO && best.g.abs() > best.err;
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
mod tests {
    use super::*;
    use std::println;
    use std::vec::Vec;

    /// Tiny deterministic generator (Knuth's MMIX LCG), no `rand`.
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, a: f64, b: f64) -> f64 {
            a + (b - a) * self.next()
        }
        fn vec(&mut self, a: f64, b: f64) -> [f64; 3] {
            [self.range(a, b), self.range(a, b), self.range(a, b)]
        }
    }

    fn v<T: Real>(a: [f64; 3]) -> Vec3<T> {
        Vec3::new(T::from_f64(a[0]), T::from_f64(a[1]), T::from_f64(a[2]))
    }

    fn ball<T: Real>(c: [f64; 3], d: f64, b: f64) -> Ball<T> {
        Ball {
            center: v(c),
            radius: T::from_f64(d),
            strength: T::from_f64(b),
        }
    }

    /// The same ball in f64, exactly (f32 -> f64 is exact).
    fn ball64<T: Real>(b: &Ball<T>) -> Ball<f64> {
        Ball {
            center: Vec3::new(
                b.center.x.to_f64(),
                b.center.y.to_f64(),
                b.center.z.to_f64(),
            ),
            radius: b.radius.to_f64(),
            strength: b.strength.to_f64(),
        }
    }

    fn group<T: Real>(
        balls: &[Ball<T>],
        kernel: Kernel,
        thr: T,
    ) -> BlobGroup<T, impl Fn(usize) -> Ball<T> + '_> {
        BlobGroup {
            count: balls.len(),
            ball: move |i| balls[i],
            kernel,
            threshold: thr,
        }
    }

    fn ray<T: Real>(o: [f64; 3], d: [f64; 3]) -> Ray<T> {
        Ray::new(v(o), v(d))
    }

    fn ray64<T: Real>(r: &Ray<T>) -> Ray<f64> {
        Ray::new(
            Vec3::new(
                r.origin.x.to_f64(),
                r.origin.y.to_f64(),
                r.origin.z.to_f64(),
            ),
            Vec3::new(r.dir.x.to_f64(), r.dir.y.to_f64(), r.dir.z.to_f64()),
        )
    }

    fn hit<T: Real, F: Fn(usize) -> Ball<T>>(
        g: &BlobGroup<T, F>,
        r: &Ray<T>,
        t0: f64,
        t1: f64,
    ) -> Option<(f64, f64)> {
        let mut st = BlobStats::default();
        g.intersect(r, T::from_f64(t0), T::from_f64(t1), &mut st)
            .map(|h| (h.t.to_f64(), h.t_error.to_f64()))
    }

    /// Reference: dense f64 sampling of F - T along the ray. Returns the first sample that
    /// is across the level set by more than `noise`, the first sample across at all, and
    /// the bisected crossing before the latter.
    struct Brute {
        robust: Option<f64>,
        first: Option<f64>,
    }
    fn brute<F: Fn(usize) -> Ball<f64>>(
        g: &BlobGroup<f64, F>,
        r: &Ray<f64>,
        t0: f64,
        t1: f64,
        n: usize,
        noise: f64,
    ) -> Brute {
        let gv = |t: f64| g.field(r.at(t)) - g.threshold;
        let inside = gv(t0) > 0.0;
        let across = |x: f64| if inside { x <= 0.0 } else { x >= 0.0 };
        let mut out = Brute {
            robust: None,
            first: None,
        };
        let mut prev = t0;
        for k in 1..=n {
            let t = t0 + (t1 - t0) * k as f64 / n as f64;
            let x = gv(t);
            if out.first.is_none() && across(x) {
                let (mut a, mut b) = (prev, t);
                for _ in 0..100 {
                    let m = 0.5 * (a + b);
                    if across(gv(m)) {
                        b = m
                    } else {
                        a = m
                    }
                }
                out.first = Some(0.5 * (a + b));
            }
            if across(x) && x.abs() > noise {
                out.robust = Some(t);
                break;
            }
            prev = t;
        }
        out
    }

    // Hand-solved surface radii for b = 1, d = 3, T = 0.5.
    // Links: f(d/3 = 1) = 1 - 3/9 = 2/3 > 0.5, so the surface is in the outer branch:
    // 1.5 (1 - r/3)² = 0.5 -> 1 - r/3 = 1/√3 -> r = 3 (1 - 1/√3) = 1.2679491924311228.
    // Wyvill: (1 - r²/9)² = 0.5 -> r²/9 = 1 - 1/√2 -> r = 3 sqrt(1 - 1/√2) = 1.6235893...
    fn links_r() -> f64 {
        3.0 * (1.0 - 1.0 / 3f64.sqrt())
    }
    fn wyvill_r() -> f64 {
        3.0 * (1.0 - 1.0 / 2f64.sqrt()).sqrt()
    }

    fn t_tol<T: Real>() -> f64 {
        if T::NAME == "f32" {
            1e-4
        } else {
            1e-11
        }
    }

    fn single_ball<T: Real>() {
        for (kernel, rs) in [(Kernel::Links, links_r()), (Kernel::Wyvill, wyvill_r())] {
            let balls = [ball::<T>([0.0, 0.0, 0.0], 3.0, 1.0)];
            let g = group(&balls, kernel, T::from_f64(0.5));
            // Through the centre.
            let (t, e) = hit(&g, &ray([0.0, 0.0, -10.0], [0.0, 0.0, 1.0]), 0.0, 1e30).unwrap();
            assert!(
                (t - (10.0 - rs)).abs() <= e,
                "{kernel:?} {}: {t} vs {}",
                T::NAME,
                10.0 - rs
            );
            assert!(e <= t_tol::<T>(), "t_error {e}");
            // Off centre: r² = x² + z².
            let (t, e) = hit(&g, &ray([0.5, 0.0, -10.0], [0.0, 0.0, 1.0]), 0.0, 1e30).unwrap();
            let want = 10.0 - (rs * rs - 0.25).sqrt();
            assert!(
                (t - want).abs() <= e,
                "{kernel:?} {}: {t} vs {want}",
                T::NAME
            );
            // From the centre outwards: the exit.
            let d = [0.6, -0.8, 0.0];
            let (t, e) = hit(&g, &ray([0.0, 0.0, 0.0], d), 0.0, 1e30).unwrap();
            assert!(
                (t - rs).abs() <= e.max(1e-6),
                "{kernel:?} {} exit {t} vs {rs}",
                T::NAME
            );
            // Non-unit direction: t scales by 1/|dir|.
            let (t, e) = hit(&g, &ray([0.0, 0.0, -10.0], [0.0, 0.0, 2.5]), 0.0, 1e30).unwrap();
            assert!((t - (10.0 - rs) / 2.5).abs() <= e, "non-unit {t}");
            // t_max before the surface, and a ray pointing away.
            assert!(hit(&g, &ray([0.0, 0.0, -10.0], [0.0, 0.0, 1.0]), 0.0, 8.0).is_none());
            assert!(hit(&g, &ray([0.0, 0.0, -10.0], [0.0, 0.0, -1.0]), 0.0, 1e30).is_none());
            // t_min past the entry: the exit is found.
            let (t, e) = hit(&g, &ray([0.0, 0.0, -10.0], [0.0, 0.0, 1.0]), 10.0, 1e30).unwrap();
            assert!((t - (10.0 + rs)).abs() <= e, "exit after t_min {t}");
        }
    }

    #[test]
    fn single_ball_matches_hand_solution() {
        single_ball::<f32>();
        single_ball::<f64>();
    }

    #[test]
    fn hand_solution_is_on_the_surface() {
        // Check the hand-derived radii against the kernels themselves.
        let balls = [ball::<f64>([0.0; 3], 3.0, 1.0)];
        let g = group(&balls, Kernel::Links, 0.5);
        assert!((g.field(Vec3::new(links_r(), 0.0, 0.0)) - 0.5).abs() < 1e-15);
        assert!(links_r() > 1.0, "outer branch");
        let g = group(&balls, Kernel::Wyvill, 0.5);
        assert!((g.field(Vec3::new(0.0, wyvill_r(), 0.0)) - 0.5).abs() < 1e-15);
    }

    struct Tally {
        hits: u32,
        misses: u32,
        inside_starts: u32,
        hit_steps: u64,
        hit_evals: u64,
        miss_steps: u64,
        max_steps: u32,
        worst_f: f64,
        worst_e: f64,
    }

    fn random_configs<T: Real>(seed: u64, scale: f64, dist: f64, max_balls: usize) -> Tally {
        let mut rng = Lcg(seed);
        let noise = if T::NAME == "f32" { 2e-5 } else { 1e-11 };
        // Stated tolerance on the surface point: |F(at(t)) - T| <= 2 L t_error + noise,
        // with L the Lipschitz constant of the whole group (the first-order meaning of
        // t_error), and t_error <= 2 tol (the final bracket of at most one probe plus the
        // capped noise term), tol = sqrt(eps)/2 d_min <= sqrt(eps)/2 * 2.5 here.
        let mut tally = Tally {
            hits: 0,
            misses: 0,
            inside_starts: 0,
            hit_steps: 0,
            hit_evals: 0,
            miss_steps: 0,
            max_steps: 0,
            worst_f: 0.0,
            worst_e: 0.0,
        };
        for cfg in 0..60 {
            let n = 2 + (rng.next() * (max_balls - 1) as f64) as usize;
            let mut balls: Vec<Ball<T>> = Vec::new();
            for j in 0..n {
                let b = if j > 0 && rng.next() < 0.25 {
                    rng.range(-0.8, -0.3)
                } else {
                    rng.range(0.5, 1.5)
                };
                let c = rng.vec(-1.5, 1.5);
                let c = [c[0] * scale, c[1] * scale, c[2] * scale];
                balls.push(ball(c, rng.range(1.0, 2.5) * scale, b));
            }
            let kernel = if cfg % 2 == 0 {
                Kernel::Links
            } else {
                Kernel::Wyvill
            };
            let thr = T::from_f64(rng.range(0.3, 0.7));
            let g = group(&balls, kernel, thr);
            let b64: Vec<Ball<f64>> = balls.iter().map(ball64).collect();
            let g64 = group(&b64, kernel, thr.to_f64());
            let lsum: f64 = b64.iter().map(|b| 2.0 * b.strength.abs() / b.radius).sum();
            for k in 0..40 {
                let (o, d) = if k % 5 == 4 {
                    // Start somewhere inside the cluster (often inside the blob).
                    let o = rng.vec(-1.0, 1.0);
                    let o = [o[0] * scale, o[1] * scale, o[2] * scale];
                    let d = [
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                    ];
                    (o, d)
                } else {
                    let mut o = [
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                        rng.range(-1.0, 1.0),
                    ];
                    let l = (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt();
                    let f = dist * scale / l;
                    o = [o[0] * f, o[1] * f, o[2] * f];
                    let tgt = rng.vec(-1.5, 1.5);
                    let tgt = [tgt[0] * scale, tgt[1] * scale, tgt[2] * scale];
                    (o, [tgt[0] - o[0], tgt[1] - o[1], tgt[2] - o[2]])
                };
                let dl = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let r: Ray<T> = ray(o, [d[0] / dl, d[1] / dl, d[2] / dl]);
                let r64 = ray64(&r);
                let g0 = g64.field(r64.at(0.0)) - g64.threshold;
                if g0.abs() < 1e-3 {
                    continue; // ambiguous start, on the surface
                }
                if g0 > 0.0 {
                    tally.inside_starts += 1;
                }
                let t_max = (dist + 13.0) * scale;
                let mut st = BlobStats::default();
                let h = g.intersect(&r, T::ZERO, T::from_f64(t_max), &mut st);
                tally.max_steps = tally.max_steps.max(st.steps);
                let bf = brute(&g64, &r64, 0.0, t_max, 20_000, noise);
                match h {
                    Some(h) => {
                        let (t, e) = (h.t.to_f64(), h.t_error.to_f64());
                        tally.hits += 1;
                        tally.hit_steps += st.steps as u64;
                        tally.hit_evals += st.field_evals as u64;
                        let gf = (g64.field(r64.at(t)) - g64.threshold).abs();
                        tally.worst_f = tally.worst_f.max(gf);
                        tally.worst_e = tally.worst_e.max(e);
                        let eps = T::epsilon().to_f64();
                        let tol_max =
                            (eps.sqrt() * 0.5 * 2.5).max(64.0 * eps * (dist + 8.0)) * scale;
                        assert!(e <= 2.0 * tol_max + 1e-6 * tol_max, "t_error {e}");
                        assert!(
                            gf <= 2.0 * lsum * e + noise,
                            "cfg {cfg} ray {k} {}: |F-T| = {gf} at t {t}, t_error {e}",
                            T::NAME
                        );
                        // First crossing: nothing robustly across before t.
                        if let Some(tr) = bf.robust {
                            assert!(t <= tr + e, "cfg {cfg} ray {k}: hit {t} after robust {tr}");
                        }
                        if let Some(tf) = bf.first {
                            // The reference crossing is the same one, unless the reference
                            // found a noise-level touch first.
                            if (tf - t).abs() > e + 1e-9 {
                                assert!(tf < t, "cfg {cfg} ray {k}: reference {tf} after hit {t}");
                                let depth = (g64.field(r64.at(tf + 1e-7)) - g64.threshold).abs();
                                assert!(
                                    depth <= noise,
                                    "cfg {cfg} ray {k}: skipped {tf} (hit {t})"
                                );
                            }
                        }
                        // Dense check of the stretch before the hit.
                        let inside = g0 > 0.0;
                        let end = t - e - 1e-9;
                        for j in 0..4000 {
                            let s = end * j as f64 / 4000.0;
                            let x = g64.field(r64.at(s)) - g64.threshold;
                            let bad = if inside { x < -noise } else { x > noise };
                            assert!(!bad, "cfg {cfg} ray {k}: crossing at {s} before hit {t}");
                        }
                    }
                    None => {
                        tally.misses += 1;
                        tally.miss_steps += st.steps as u64;
                        assert!(
                            bf.robust.is_none(),
                            "cfg {cfg} ray {k} {}: missed crossing near {:?}",
                            T::NAME,
                            bf.first
                        );
                    }
                }
            }
        }
        tally
    }

    fn report(name: &str, t: &Tally) {
        println!(
            "{name}: {} hits ({} rays started inside), {} misses; steps/hit {:.1}, \
             field evals/hit {:.1}, steps/miss {:.1}, max steps {}, worst |F-T| {:.2e}, \
             worst t_error {:.2e}",
            t.hits,
            t.inside_starts,
            t.misses,
            t.hit_steps as f64 / t.hits.max(1) as f64,
            t.hit_evals as f64 / t.hits.max(1) as f64,
            t.miss_steps as f64 / t.misses.max(1) as f64,
            t.max_steps,
            t.worst_f,
            t.worst_e
        );
    }

    #[test]
    fn random_rays_hit_the_first_crossing_f64() {
        let t = random_configs::<f64>(0x5eed_1983, 1.0, 7.0, 4);
        report("f64", &t);
        assert!(t.hits > 500 && t.misses > 50 && t.inside_starts > 50);
        assert!(t.hit_steps <= 14 * t.hits as u64, "steps per hit regressed");
        assert!(t.worst_e <= 1e-9, "t_error {}", t.worst_e);
    }

    #[test]
    fn random_rays_hit_the_first_crossing_f32() {
        let t = random_configs::<f32>(0x5eed_1983, 1.0, 7.0, 4);
        report("f32", &t);
        assert!(t.hits > 500 && t.misses > 50 && t.inside_starts > 50);
        assert!(t.hit_steps <= 14 * t.hits as u64, "steps per hit regressed");
    }

    /// Two Links balls whose iso-surface has a neck of radius `rho` (about 1e-3 d across):
    /// balls b = 1, d = 3 at x = ±1.5; on the mid-plane F = 2 f(sqrt(2.25 + ρ²)) and the
    /// neck is where that equals T, i.e. T = 2 f(r_n), r_n² = 2.25 + ρ_n².
    fn thin_neck<T: Real>() {
        let rho = 1.5e-3; // neck diameter 3e-3 = 1e-3 d
        let rn = (2.25f64 + rho * rho).sqrt();
        let thr = T::from_f64(3.0 * (1.0 - rn / 3.0) * (1.0 - rn / 3.0));
        // The neck radius for the threshold as rounded to T.
        let tt = thr.to_f64();
        let r_exact = 3.0 * (1.0 - (tt / 3.0).sqrt());
        let rho_t = (r_exact * r_exact - 2.25).sqrt();
        assert!(
            rho_t > 1e-3 && rho_t < 2e-3,
            "{} neck radius {rho_t}",
            T::NAME
        );
        let balls = [
            ball::<T>([-1.5, 0.0, 0.0], 3.0, 1.0),
            ball::<T>([1.5, 0.0, 0.0], 3.0, 1.0),
        ];
        let g = group(&balls, Kernel::Links, thr);
        let b64: Vec<Ball<f64>> = balls.iter().map(ball64).collect();
        let g64 = group(&b64, Kernel::Links, tt);
        let s2 = 0.5f64.sqrt();
        let cases: [([f64; 3], [f64; 3], f64); 4] = [
            ([0.0, -5.0, 0.0], [0.0, 1.0, 0.0], 5.0 - rho_t),
            ([0.0, 0.0, -5.0], [0.0, 0.0, 1.0], 5.0 - rho_t),
            ([0.0, -5.0, -5.0], [0.0, s2, s2], 50f64.sqrt() - rho_t),
            // Off the neck's axis by half its radius: a chord of 2 ρ sqrt(3/4).
            (
                [0.0, -5.0, 0.5 * rho_t],
                [0.0, 1.0, 0.0],
                5.0 - rho_t * 0.75f64.sqrt(),
            ),
        ];
        let tol = if T::NAME == "f32" { 1e-4 } else { 1e-9 };
        for (o, d, want) in cases {
            let r: Ray<T> = ray(o, d);
            let mut st = BlobStats::default();
            let h = g.intersect(&r, T::ZERO, T::from_f64(20.0), &mut st);
            let h = h.unwrap_or_else(|| panic!("{} missed the neck along {d:?}", T::NAME));
            let (t, e) = (h.t.to_f64(), h.t_error.to_f64());
            // Along the neck's diameter F - T has slope only ~1e-3 (F is flat across the
            // saddle), so f32 rounding of F (~1e-7) moves the crossing by ~1e-4: the
            // reported t_error (>= tol = 3.7e-4 here) must cover that.
            let tol = tol.max(e);
            assert!(
                (t - want).abs() <= tol,
                "{}: {t} vs {want} (t_error {e})",
                T::NAME
            );
            let bf = brute(&g64, &ray64(&r), 0.0, 20.0, 40_000, 0.0);
            let tb = bf.first.unwrap();
            assert!((t - tb).abs() <= tol, "{}: {t} vs brute {tb}", T::NAME);
            println!(
                "neck {} {d:?}: t {t} (want {want}, t_error {e:.1e}) steps {} evals {}",
                T::NAME,
                st.steps,
                st.field_evals
            );
        }
        // Beside the neck: nothing to hit (the balls' own surfaces are 0.63 from x = 0).
        let r: Ray<T> = ray([0.0, -5.0, 1.5 * rho_t], [0.0, 1.0, 0.0]);
        assert!(
            hit(&g, &r, 0.0, 20.0).is_none(),
            "{} hit beside the neck",
            T::NAME
        );
    }

    #[test]
    fn thin_neck_is_found() {
        thin_neck::<f32>();
        thin_neck::<f64>();
    }

    /// A Wyvill ball whose peak barely exceeds T: the surface is a sphere of radius
    /// 5e-4 d, so a ray through it is inside for 1e-3 d.
    fn tiny_bump<T: Real>() {
        let rb = 5e-4;
        let thr = T::from_f64((1.0 - rb * rb) * (1.0 - rb * rb));
        let rb_t = (1.0 - thr.to_f64().sqrt()).sqrt(); // radius for the rounded threshold
        let balls = [ball::<T>([0.0, 0.0, 0.0], 1.0, 1.0)];
        let g = group(&balls, Kernel::Wyvill, thr);
        let b64 = [ball64(&balls[0])];
        let g64 = group(&b64, Kernel::Wyvill, thr.to_f64());
        let tol = if T::NAME == "f32" { 1e-4 } else { 1e-9 };
        for (off, chord) in [(0.0, rb_t), (0.8 * rb_t, rb_t * 0.36f64.sqrt())] {
            let r: Ray<T> = ray([off, 0.0, -3.0], [0.0, 0.0, 1.0]);
            let (t, _) = hit(&g, &r, 0.0, 10.0)
                .unwrap_or_else(|| panic!("{} missed the bump at offset {off}", T::NAME));
            assert!(
                (t - (3.0 - chord)).abs() <= tol,
                "{}: bump {t} vs {}",
                T::NAME,
                3.0 - chord
            );
            let tb = brute(&g64, &ray64(&r), 0.0, 10.0, 40_000, 0.0)
                .first
                .unwrap();
            assert!((t - tb).abs() <= tol, "{}: bump {t} vs brute {tb}", T::NAME);
        }
        // Passing at 1.2 times its radius: a near miss.
        let r: Ray<T> = ray([1.2 * rb_t, 0.0, -3.0], [0.0, 0.0, 1.0]);
        assert!(
            hit(&g, &r, 0.0, 10.0).is_none(),
            "{} hit beside the bump",
            T::NAME
        );
    }

    #[test]
    fn tiny_bump_is_found() {
        tiny_bump::<f32>();
        tiny_bump::<f64>();
    }

    /// Tangent rays: a small margin outside misses, as much inside hits.
    fn grazing<T: Real>() {
        let margin = if T::NAME == "f32" { 1e-4 } else { 1e-7 };
        for (kernel, rs) in [(Kernel::Links, links_r()), (Kernel::Wyvill, wyvill_r())] {
            let balls = [ball::<T>([0.3, -0.2, 0.1], 3.0, 1.0)];
            let g = group(&balls, kernel, T::from_f64(0.5));
            for dir in [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]] {
                // Perpendicular offset direction (unit, orthogonal to dir).
                let n = [0.0, 1.0, 0.0];
                let mk = |off: f64| -> Ray<T> {
                    let o = [
                        0.3 + n[0] * off - dir[0] * 8.0,
                        -0.2 + n[1] * off - dir[1] * 8.0,
                        0.1 + n[2] * off - dir[2] * 8.0,
                    ];
                    ray(o, dir)
                };
                let mut st = BlobStats::default();
                let miss = g.intersect(&mk(rs + margin), T::ZERO, T::from_f64(20.0), &mut st);
                assert!(miss.is_none(), "{kernel:?} {}: false hit {miss:?}", T::NAME);
                println!("graze miss {kernel:?} {}: steps {}", T::NAME, st.steps);
                let mut st = BlobStats::default();
                let h = g.intersect(&mk(rs - margin), T::ZERO, T::from_f64(20.0), &mut st);
                let h = h.unwrap_or_else(|| panic!("{kernel:?} {}: missed a clip", T::NAME));
                let half = (rs * rs - (rs - margin) * (rs - margin)).sqrt();
                let want = 8.0 - half;
                let t = h.t.to_f64();
                // Ill-conditioned along the ray: |dt| ~ |dF| / (|F'| cos), allow 1% of the chord.
                assert!(
                    (t - want).abs() <= 0.01 * half,
                    "{kernel:?} {}: {t} vs {want}",
                    T::NAME
                );
                println!(
                    "graze hit {kernel:?} {}: steps {} chord {:.2e}",
                    T::NAME,
                    st.steps,
                    2.0 * half
                );
            }
        }
    }

    #[test]
    fn grazing_rays() {
        grazing::<f32>();
        grazing::<f64>();
    }

    /// Rays starting inside find the exit (refraction rays).
    fn from_inside<T: Real>() {
        // Two overlapping Links balls form one blob; start in the first, leave the second.
        let balls = [
            ball::<T>([0.0, 0.0, 0.0], 3.0, 1.0),
            ball::<T>([2.0, 0.0, 0.0], 3.0, 1.0),
        ];
        let g = group(&balls, Kernel::Links, T::from_f64(0.5));
        let b64: Vec<Ball<f64>> = balls.iter().map(ball64).collect();
        let g64 = group(&b64, Kernel::Links, 0.5);
        let tol = if T::NAME == "f32" { 1e-4 } else { 1e-9 };
        for d in [[1.0, 0.0, 0.0], [0.8, 0.6, 0.0], [-0.6, 0.0, 0.8]] {
            let r: Ray<T> = ray([0.1, 0.0, 0.0], d);
            assert!(g.field(r.origin) > g.threshold);
            let (t, _) = hit(&g, &r, 0.0, 20.0).unwrap();
            let tb = brute(&g64, &ray64(&r), 0.0, 20.0, 20_000, 0.0)
                .first
                .unwrap();
            assert!((t - tb).abs() <= tol, "{} exit {t} vs {tb}", T::NAME);
            let p = r.at(T::from_f64(t));
            assert!((g.field(p) - g.threshold).to_f64().abs() <= 1e3 * tol);
            // The normal there faces along the ray (leaving the blob).
            let n = -g.gradient(p);
            assert!(n.dot(r.dir) > T::ZERO);
        }
        // Start just under the surface of the first ball, heading further in: the exit is
        // on the far side, not at the nearby surface behind the origin.
        let rs = links_r();
        let r: Ray<T> = ray([-(rs - 1e-3), 0.0, 0.0], [0.0, 0.0, 1.0]);
        assert!(g.field(r.origin) > g.threshold);
        let (t, _) = hit(&g, &r, 0.0, 20.0).unwrap();
        let tb = brute(&g64, &ray64(&r), 0.0, 20.0, 20_000, 0.0)
            .first
            .unwrap();
        assert!((t - tb).abs() <= tol && t > 0.01, "{} {t} vs {tb}", T::NAME);
    }

    #[test]
    fn ray_from_inside_finds_the_exit() {
        from_inside::<f32>();
        from_inside::<f64>();
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let mut rng = Lcg(42);
        for kernel in [Kernel::Links, Kernel::Wyvill] {
            let balls = [
                ball::<f64>([0.0, 0.0, 0.0], 3.0, 1.0),
                ball::<f64>([1.2, 0.5, -0.3], 2.0, -0.6),
                ball::<f64>([-0.7, 1.1, 0.4], 1.5, 0.8),
            ];
            let g = group(&balls, kernel, 0.5);
            let mut inner = 0;
            for _ in 0..500 {
                let p = v::<f64>(rng.vec(-2.5, 2.5));
                // Links: count points in an inner branch (r <= d/3) too.
                if balls
                    .iter()
                    .any(|b| (p - b.center).length() < b.radius / 3.0)
                {
                    inner += 1;
                }
                let gr = g.gradient(p);
                let h = 1e-6;
                for (axis, got) in [gr.x, gr.y, gr.z].into_iter().enumerate() {
                    let mut e = Vec3::zero();
                    match axis {
                        0 => e.x = h,
                        1 => e.y = h,
                        _ => e.z = h,
                    }
                    let fd = (g.field(p + e) - g.field(p - e)) / (2.0 * h);
                    assert!(
                        (got - fd).abs() <= 1e-6 * (1.0 + fd.abs()),
                        "{kernel:?} {p:?}: {got} vs {fd}"
                    );
                }
            }
            assert!(inner > 5);
        }
        // f32: same formula, looser.
        let balls = [ball::<f32>([0.0, 0.0, 0.0], 3.0, 1.0)];
        let g = group(&balls, Kernel::Links, 0.5f32);
        let p = Vec3::new(1.3f32, 0.4, -0.2);
        let gr = g.gradient(p);
        let e = Vec3::new(1e-3f32, 0.0, 0.0);
        let fd = (g.field(p + e) - g.field(p - e)) / 2e-3;
        assert!((gr.x - fd).abs() < 1e-3);
    }

    /// A negative ball carves a dent into a positive one.
    fn dent<T: Real>() {
        let plain = [ball::<T>([0.0, 0.0, 0.0], 3.0, 1.0)];
        let dented = [
            ball::<T>([0.0, 0.0, 0.0], 3.0, 1.0),
            ball::<T>([1.5, 0.0, 0.0], 1.5, -0.5),
        ];
        let thr = T::from_f64(0.5);
        let g0 = group(&plain, Kernel::Links, thr);
        let g1 = group(&dented, Kernel::Links, thr);
        let b64: Vec<Ball<f64>> = dented.iter().map(ball64).collect();
        let g64 = group(&b64, Kernel::Links, 0.5);
        let tol = if T::NAME == "f32" { 1e-4 } else { 1e-9 };
        let r: Ray<T> = ray([5.0, 0.0, 0.0], [-1.0, 0.0, 0.0]);
        let (t0, _) = hit(&g0, &r, 0.0, 20.0).unwrap();
        let (t1, _) = hit(&g1, &r, 0.0, 20.0).unwrap();
        assert!((t0 - (5.0 - links_r())).abs() <= tol);
        assert!(t1 > t0 + 0.1, "{}: dent {t1} not deeper than {t0}", T::NAME);
        let tb = brute(&g64, &ray64(&r), 0.0, 20.0, 20_000, 0.0)
            .first
            .unwrap();
        assert!((t1 - tb).abs() <= tol, "{}: {t1} vs brute {tb}", T::NAME);
        // The normal at the bottom of the dent faces the ray.
        let n = -g1.gradient(r.at(T::from_f64(t1)));
        assert!(n.dot(r.dir) < T::ZERO);
        // Rays into the dent's rim, and the far side, untouched by the dent.
        for o in [[5.0, 0.7, 0.0], [5.0, 0.0, 0.9], [5.0, 0.5, 0.5]] {
            let r: Ray<T> = ray(o, [-1.0, 0.0, 0.0]);
            let (t, _) = hit(&g1, &r, 0.0, 20.0).unwrap();
            let tb = brute(&g64, &ray64(&r), 0.0, 20.0, 20_000, 0.0)
                .first
                .unwrap();
            assert!((t - tb).abs() <= tol, "{}: rim {t} vs {tb}", T::NAME);
        }
        let r: Ray<T> = ray([-5.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
        let (ta, _) = hit(&g0, &r, 0.0, 20.0).unwrap();
        let (tb, _) = hit(&g1, &r, 0.0, 20.0).unwrap();
        assert!((ta - tb).abs() <= tol);
        // A negative ball alone is nothing.
        let neg = [ball::<T>([0.0, 0.0, 0.0], 3.0, -1.0)];
        let gn = group(&neg, Kernel::Wyvill, thr);
        assert!(hit(&gn, &ray([0.0, 0.0, -5.0], [0.0, 0.0, 1.0]), 0.0, 20.0).is_none());
    }

    #[test]
    fn negative_ball_carves_a_dent() {
        dent::<f32>();
        dent::<f64>();
    }

    #[test]
    fn bounds_cover_the_positive_balls() {
        let balls = [
            ball::<f64>([0.0, 0.0, 0.0], 3.0, 1.0),
            ball::<f64>([2.0, -1.0, 0.5], 1.0, 0.5),
            ball::<f64>([10.0, 10.0, 10.0], 2.0, -1.0),
        ];
        let g = group(&balls, Kernel::Links, 0.5);
        let (lo, hi) = g.bounds();
        assert_eq!(lo, Vec3::new(-3.0, -3.0, -3.0));
        assert_eq!(hi, Vec3::new(3.0, 3.0, 3.0));
        let none = group(&balls[2..], Kernel::Links, 0.5);
        let (lo, hi) = none.bounds();
        assert!(lo.x > hi.x, "empty");
    }

    #[test]
    fn degenerate_inputs_are_misses() {
        let balls = [ball::<f32>([0.0, 0.0, 0.0], 3.0, 1.0)];
        let r: Ray<f32> = ray([0.0, 0.0, -5.0], [0.0, 0.0, 1.0]);
        let mut st = BlobStats::default();
        assert!(group(&balls, Kernel::Links, 0.0)
            .intersect(&r, 0.0, 10.0, &mut st)
            .is_none());
        assert!(group(&balls, Kernel::Links, 0.5)
            .intersect(&r, 5.0, 5.0, &mut st)
            .is_none());
        let z: Ray<f32> = ray([0.0, 0.0, -5.0], [0.0, 0.0, 0.0]);
        assert!(group(&balls, Kernel::Links, 0.5)
            .intersect(&z, 0.0, 10.0, &mut st)
            .is_none());
        let empty: [Ball<f32>; 0] = [];
        assert!(group(&empty, Kernel::Links, 0.5)
            .intersect(&r, 0.0, 10.0, &mut st)
            .is_none());
        // Unbounded t_max with a non-unit direction doesn't overflow into a miss.
        let r2: Ray<f32> = ray([0.0, 0.0, -5.0], [0.0, 0.0, 4.0]);
        let h = group(&balls, Kernel::Links, 0.5).intersect(&r2, 0.0, f32::MAX, &mut st);
        assert!((h.unwrap().t - (5.0 - links_r() as f32) / 4.0).abs() < 1e-4);
    }

    /// Many balls in a row, ray along the row at the height of the necks' surface: long
    /// near-tangent runs must stay under the step cap and agree with the reference.
    #[test]
    fn long_near_tangent_run() {
        let balls: Vec<Ball<f64>> = (0..12)
            .map(|i| ball([i as f64 * 1.0, 0.0, 0.0], 2.0, 1.0))
            .collect();
        let g = group(&balls, Kernel::Wyvill, 0.9);
        let mut st = BlobStats::default();
        let mut worst = 0;
        for k in 0..40 {
            let y = 0.3 + 0.02 * k as f64;
            let r: Ray<f64> = ray([-3.0, y, 0.0], [1.0, 0.0, 0.0]);
            let mut s = BlobStats::default();
            let h = g.intersect(&r, 0.0, 30.0, &mut s);
            worst = worst.max(s.steps);
            st.steps += s.steps;
            let bf = brute(&g, &r, 0.0, 30.0, 60_000, 1e-11);
            match h {
                Some(h) => {
                    if let Some(tb) = bf.first {
                        assert!(
                            (h.t - tb).abs() <= h.t_error + 1e-9,
                            "y {y}: {} vs {tb}",
                            h.t
                        );
                    }
                }
                None => assert!(bf.robust.is_none(), "y {y}: missed {:?}", bf.first),
            }
        }
        println!("row: worst steps {worst}, total {}", st.steps);
        assert!(worst < MAX_STEPS);
    }

    /// The same checks at other scales, distances and group sizes: tiny and huge scenes
    /// (everything relative), far origins (f32 loses digits: tol grows to 64 eps |t|).
    #[test]
    fn random_rays_other_scales() {
        let cases: [(&str, u64, f64, f64, usize); 3] = [
            ("f32", 11, 0.01, 7.0, 8),
            ("f32", 12, 100.0, 40.0, 6),
            ("f64", 13, 1e-3, 60.0, 8),
        ];
        for (name, seed, scale, dist, n) in cases {
            let t = if name == "f32" {
                random_configs::<f32>(seed, scale, dist, n)
            } else {
                random_configs::<f64>(seed, scale, dist, n)
            };
            report(
                &std::format!("{name} scale {scale} dist {dist} <= {n} balls"),
                &t,
            );
            assert!(t.hits > 300 && t.misses > 50);
        }
    }
}
