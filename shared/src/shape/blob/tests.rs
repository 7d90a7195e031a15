//! Tests of the density-sphere intersection.

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

/// A value per number type: f32, f64, Q16.16.
fn pick<T: Real>(f32v: f64, f64v: f64, fxv: f64) -> f64 {
    match T::NAME {
        "f32" => f32v,
        "f64" => f64v,
        _ => fxv,
    }
}

/// `tol` for floats; for Q16.16 the larger of `tol` and the hit's reported t_error, where a
/// test's crossing is shallower than FX_TOL assumes.
fn fx_or<T: Real>(tol: f64, t_error: f64) -> f64 {
    if T::ABSOLUTE_ROUNDING {
        tol.max(t_error)
    } else {
        tol
    }
}

fn t_tol<T: Real>() -> f64 {
    pick::<T>(1e-4, 1e-11, FX_T_TOL)
}

// Q16.16's tolerances, from its resolution. A step is δ = 2^-16 = 1.5e-5, absolute. The
// root finder bounds the rounding of the computed field by (3 lip + curv + |b| (1 + d +
// d²/4) + 2) δ per ball (`BlobGroup::sample`): 10.9 δ = 1.7e-4 for the b = 1, d = 3 balls
// used here, FX_FIELD for two that overlap. Where the field crosses T with slope g along
// the ray the crossing is placed to FX_FIELD / g; the refinement reports at most twice
// (|F - T| + bound) / g, plus 4 δ.
const FX_FIELD: f64 = 22.0 / 65536.0;
/// The reported t_error of a transversal hit on one ball (slope 0.58 at the surface of
/// b = 1, d = 3): 2 (10.9 δ) / 0.58 + 4 δ = 6.3e-4.
const FX_T_TOL: f64 = 1e-3;
/// Where a computed transversal crossing may be, against the f64 reference (slopes of
/// 0.4 and more): FX_FIELD / 0.4 = 8.4e-4. Shallower ones are held to their reported
/// t_error (`fx_or`).
const FX_TOL: f64 = FX_FIELD / 0.4;
// The neck's field margin stays above the field bound.
const _: () = assert!(2.0 * FX_FIELD < FX_NECK * FX_NECK / 3.0);
/// The neck radius: the field on the neck's axis exceeds T by ρ²/3 (F = 2 f(sqrt(2.25 +
/// ρ²)), f'(1.5) = -1/2); 0.05 gives 8.3e-4 = 54 δ, 2.5 FX_FIELD. (The floats' 1.5e-3
/// exceeds T by 7.5e-7 = 0.05 δ: below the format's resolution.)
const FX_NECK: f64 = 0.05;
/// The bump radius: the peak of the b = 1, d = 1 Wyvill ball exceeds T by about 2 rb²;
/// 0.02 gives 8e-4 = 52 δ, three times its field bound (16.9 δ: lip 1.54, curv 8). (The
/// floats' 5e-4 exceeds T by 5e-7 = 0.03 δ.)
const FX_BUMP: f64 = 0.02;
/// The tangent rays' offset h: |F - T| there is about |∇F| h = 0.58 h (b = 1, d = 3);
/// 4e-3 gives 2.3e-3 = 150 δ, 14 times the field bound.
const FX_GRAZE: f64 = 4e-3;
/// The clipped ray's crossing, against the hand solution, as a share of the half chord
/// c = sqrt(2 R h) (R = 1.27 for Links, 1.62 for Wyvill): along the ray the field rises
/// with slope |∇F| c / R (0.046 for Links, |∇F| = 0.58; 0.036 for Wyvill, 0.51), so the
/// computed crossing is within one field bound over that slope of the exact one (3.6% of
/// c for Links, 4% for Wyvill), and the refinement stops within another: 8%. (Measured:
/// 1.6%. The floats allow 1%.)
const FX_GRAZE_CHORD: f64 = 0.08;
/// The long near-tangent run (Wyvill balls b = 1, d = 2, one unit apart): up to four
/// balls reach a point, 10.3 δ each (lip 0.77, curv 2), so the reference's noise level
/// (a crossing it may find and the march may not) is 41 δ; 45 δ used.
const FX_ROW_NOISE: f64 = 45.0 / 65536.0;

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
    single_ball::<crate::num::Fx>();
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
    let noise = pick::<T>(2e-5, 1e-11, 2e-5);
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
                    // Fixed point: tol's second term and t_res (4 steps) are absolute.
                    let tol_max = pick::<T>(
                        (eps.sqrt() * 0.5 * 2.5).max(64.0 * eps * (dist + 8.0)) * scale,
                        (eps.sqrt() * 0.5 * 2.5).max(64.0 * eps * (dist + 8.0)) * scale,
                        (eps.sqrt() * 0.5 * 2.5 * scale).max(64.0 * eps),
                    );
                    let t_res = pick::<T>(1e-6 * tol_max, 1e-6 * tol_max, 4.0 * eps);
                    assert!(e <= 2.0 * tol_max + t_res, "t_error {e}");
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
                            assert!(depth <= noise, "cfg {cfg} ray {k}: skipped {tf} (hit {t})");
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
fn random_rays_hit_the_first_crossing_q16_16() {
    let t = random_configs::<crate::num::Fx>(0x5eed_1983, 1.0, 7.0, 4);
    report("q16.16", &t);
    assert!(t.hits > 500 && t.misses > 50 && t.inside_starts > 50);
    assert!(t.hit_steps <= 14 * t.hits as u64, "steps per hit regressed");
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
    // Neck diameter 3e-3 = 1e-3 d; in Q16.16 0.1 = 3.3e-2 d (FX_NECK: a neck whose field
    // rises above T by 2.5 times the field's rounding bound).
    let rho = pick::<T>(1.5e-3, 1.5e-3, FX_NECK);
    let rn = (2.25f64 + rho * rho).sqrt();
    let thr = T::from_f64(3.0 * (1.0 - rn / 3.0) * (1.0 - rn / 3.0));
    // The neck radius for the threshold as rounded to T.
    let tt = thr.to_f64();
    let r_exact = 3.0 * (1.0 - (tt / 3.0).sqrt());
    let rho_t = (r_exact * r_exact - 2.25).sqrt();
    assert!(
        rho_t > rho * 0.66 && rho_t < rho * 1.33,
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
    let tol = pick::<T>(1e-4, 1e-9, FX_TOL);
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
    thin_neck::<crate::num::Fx>();
}

/// A Wyvill ball whose peak barely exceeds T: the surface is a sphere of radius
/// 5e-4 d, so a ray through it is inside for 1e-3 d.
fn tiny_bump<T: Real>() {
    // Q16.16: see FX_BUMP.
    let rb = pick::<T>(5e-4, 5e-4, FX_BUMP);
    let thr = T::from_f64((1.0 - rb * rb) * (1.0 - rb * rb));
    let rb_t = (1.0 - thr.to_f64().sqrt()).sqrt(); // radius for the rounded threshold
    let balls = [ball::<T>([0.0, 0.0, 0.0], 1.0, 1.0)];
    let g = group(&balls, Kernel::Wyvill, thr);
    let b64 = [ball64(&balls[0])];
    let g64 = group(&b64, Kernel::Wyvill, thr.to_f64());
    let tol = pick::<T>(1e-4, 1e-9, FX_TOL);
    for (off, chord) in [(0.0, rb_t), (0.8 * rb_t, rb_t * 0.36f64.sqrt())] {
        let r: Ray<T> = ray([off, 0.0, -3.0], [0.0, 0.0, 1.0]);
        let (t, e) = hit(&g, &r, 0.0, 10.0)
            .unwrap_or_else(|| panic!("{} missed the bump at offset {off}", T::NAME));
        // Q16.16: the bump's field rises with slope 0.05 to 0.08 along these rays (4 rb
        // times the chord's sine), under FX_TOL's 0.4: the reported t_error covers it.
        let tol = fx_or::<T>(tol, e);
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
    tiny_bump::<crate::num::Fx>();
}

/// Tangent rays: a small margin outside misses, as much inside hits.
fn grazing<T: Real>() {
    let margin = pick::<T>(1e-4, 1e-7, FX_GRAZE);
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
                (t - want).abs() <= pick::<T>(0.01, 0.01, FX_GRAZE_CHORD) * half,
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
    grazing::<crate::num::Fx>();
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
    let tol = pick::<T>(1e-4, 1e-9, FX_TOL);
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
    let (t, e) = hit(&g, &r, 0.0, 20.0).unwrap();
    let tb = brute(&g64, &ray64(&r), 0.0, 20.0, 20_000, 0.0)
        .first
        .unwrap();
    // Q16.16: this ray runs along the surface, 1e-3 under it, and leaves with slope 0.023
    // (0.58 times the chord's sine, 0.05 / 1.27), far under FX_TOL's 0.4: the reported
    // t_error (the field's bound over that slope, about 7e-3) covers it.
    let tol = fx_or::<T>(tol, e);
    assert!((t - tb).abs() <= tol && t > 0.01, "{} {t} vs {tb}", T::NAME);
}

#[test]
fn ray_from_inside_finds_the_exit() {
    from_inside::<f32>();
    from_inside::<f64>();
    from_inside::<crate::num::Fx>();
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
    // Q16.16 against the f64 gradient (checked above) of the same balls: each ball's term
    // 2 (df/dq)(p - c) is four roundings of half a step (products and the quotient by r,
    // all of magnitude <= 2) plus 1/d's half step carried by |b| 2r/d <= 2: under 5 steps
    // per ball, 16 for three (measured 7.2).
    for kernel in [Kernel::Links, Kernel::Wyvill] {
        use crate::num::Fx;
        let balls = [
            ball::<Fx>([0.0, 0.0, 0.0], 3.0, 1.0),
            ball::<Fx>([1.2, 0.5, -0.3], 2.0, -0.6),
            ball::<Fx>([-0.7, 1.1, 0.4], 1.5, 0.8),
        ];
        let g = group(&balls, kernel, Fx::HALF);
        let b64: Vec<Ball<f64>> = balls.iter().map(ball64).collect();
        let g64 = group(&b64, kernel, 0.5);
        for _ in 0..2000 {
            let p = v::<Fx>(rng.vec(-2.5, 2.5));
            let got = g.gradient(p).to_f64();
            let want = g64.gradient(Vec3::new(p.x.to_f64(), p.y.to_f64(), p.z.to_f64()));
            for (a, b) in got.iter().zip([want.x, want.y, want.z]) {
                assert!(
                    (a - b).abs() <= 16.0 / 65536.0,
                    "{kernel:?} {p:?}: {a} vs {b}"
                );
            }
        }
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
    let tol = pick::<T>(1e-4, 1e-9, FX_TOL);
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
    dent::<crate::num::Fx>();
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

fn degenerate<T: Real>() {
    let balls = [ball::<T>([0.0, 0.0, 0.0], 3.0, 1.0)];
    let r: Ray<T> = ray([0.0, 0.0, -5.0], [0.0, 0.0, 1.0]);
    let mut st = BlobStats::default();
    let (zero, five, ten, half) = (T::ZERO, T::from_i32(5), T::from_i32(10), T::HALF);
    assert!(group(&balls, Kernel::Links, zero)
        .intersect(&r, zero, ten, &mut st)
        .is_none());
    assert!(group(&balls, Kernel::Links, half)
        .intersect(&r, five, five, &mut st)
        .is_none());
    let z: Ray<T> = ray([0.0, 0.0, -5.0], [0.0, 0.0, 0.0]);
    assert!(group(&balls, Kernel::Links, half)
        .intersect(&z, zero, ten, &mut st)
        .is_none());
    let empty: [Ball<T>; 0] = [];
    assert!(group(&empty, Kernel::Links, half)
        .intersect(&r, zero, ten, &mut st)
        .is_none());
    // Unbounded t_max with a non-unit direction doesn't overflow into a miss.
    let r2: Ray<T> = ray([0.0, 0.0, -5.0], [0.0, 0.0, 4.0]);
    let h = group(&balls, Kernel::Links, half).intersect(&r2, zero, T::MAX, &mut st);
    let want = (5.0 - links_r()) / 4.0;
    assert!(
        (h.unwrap().t.to_f64() - want).abs() < t_tol::<T>(),
        "{}: {h:?}",
        T::NAME
    );
    // Special values: a NaN or infinite ray or limit, and a ball whose field overflows
    // (fixed point: every such value is a miss, never a wrapped number).
    let nan_ray: Ray<T> = Ray::new(
        Vec3::new(T::ZERO, T::ZERO, T::from_i32(-5)),
        Vec3::new(T::ZERO, T::ZERO, T::from_f64(f64::NAN)),
    );
    assert!(group(&balls, Kernel::Links, half)
        .intersect(&nan_ray, zero, ten, &mut st)
        .is_none());
    let inf = T::ONE / T::ZERO;
    assert!(group(&balls, Kernel::Links, half)
        .intersect(&r, inf, ten, &mut st)
        .is_none());
    let far = [ball::<T>([0.0, 0.0, 3.0e4], 3.0, 1.0)];
    assert!(group(&far, Kernel::Wyvill, half)
        .intersect(&r, zero, T::MAX, &mut st)
        .is_none_or(|h| h.t.is_finite()));
}

#[test]
fn degenerate_inputs_are_misses() {
    degenerate::<f32>();
    degenerate::<f64>();
    degenerate::<crate::num::Fx>();
}

/// Many balls in a row, ray along the row at the height of the necks' surface: long
/// near-tangent runs must stay under the step cap and agree with the reference.
fn near_tangent_run<T: Real>() {
    let balls: Vec<Ball<T>> = (0..12)
        .map(|i| ball([i as f64 * 1.0, 0.0, 0.0], 2.0, 1.0))
        .collect();
    let thr = T::from_f64(0.9);
    let g = group(&balls, Kernel::Wyvill, thr);
    let b64: Vec<Ball<f64>> = balls.iter().map(ball64).collect();
    let g64 = group(&b64, Kernel::Wyvill, thr.to_f64());
    let noise = pick::<T>(1e-5, 1e-11, FX_ROW_NOISE);
    let slack = pick::<T>(1e-5, 1e-9, FX_TOL);
    let mut st = BlobStats::default();
    let mut worst = 0;
    for k in 0..40 {
        let y = 0.3 + 0.02 * k as f64;
        let r: Ray<T> = ray([-3.0, y, 0.0], [1.0, 0.0, 0.0]);
        let mut s = BlobStats::default();
        let h = g.intersect(&r, T::ZERO, T::from_i32(30), &mut s);
        worst = worst.max(s.steps);
        st.steps += s.steps;
        let bf = brute(&g64, &ray64(&r), 0.0, 30.0, 60_000, noise);
        match h {
            Some(h) => {
                if let Some(tb) = bf.first {
                    let (t, e) = (h.t.to_f64(), h.t_error.to_f64());
                    assert!(
                        (t - tb).abs() <= e + slack,
                        "{} y {y}: {t} vs {tb}",
                        T::NAME
                    );
                }
            }
            None => assert!(
                bf.robust.is_none(),
                "{} y {y}: missed {:?}",
                T::NAME,
                bf.first
            ),
        }
    }
    println!("row {}: worst steps {worst}, total {}", T::NAME, st.steps);
    assert!(worst < MAX_STEPS);
}

#[test]
fn long_near_tangent_run() {
    near_tangent_run::<f64>();
    near_tangent_run::<crate::num::Fx>();
}

/// The same checks at other scales, distances and group sizes: tiny and huge scenes
/// (everything relative), far origins (f32 loses digits: tol grows to 64 eps |t|).
#[test]
fn random_rays_other_scales() {
    // Q16.16 at the sizes a DM-scaled scene has (extent <= 32): balls of 0.1 to 0.25 and
    // of 3 to 7.5, rays from up to 20 units away.
    let cases: [(&str, u64, f64, f64, usize); 5] = [
        ("f32", 11, 0.01, 7.0, 8),
        ("f32", 12, 100.0, 40.0, 6),
        ("f64", 13, 1e-3, 60.0, 8),
        ("q16.16", 14, 0.1, 7.0, 8),
        ("q16.16", 15, 3.0, 5.0, 6),
    ];
    for (name, seed, scale, dist, n) in cases {
        let t = match name {
            "f32" => random_configs::<f32>(seed, scale, dist, n),
            "f64" => random_configs::<f64>(seed, scale, dist, n),
            _ => random_configs::<crate::num::Fx>(seed, scale, dist, n),
        };
        report(
            &std::format!("{name} scale {scale} dist {dist} <= {n} balls"),
            &t,
        );
        assert!(t.hits > 300 && t.misses > 50);
    }
}
