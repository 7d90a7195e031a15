//! Instruction counts of the shared renderer on Cortex-M, under QEMU.
//!
//! The same `links_core::render::{Tracer, render_run}` a node runs renders small SceneImages
//! embedded by `build.rs`; QEMU runs with `-icount shift=0` (one instruction = 1 ns of
//! virtual time) and SysTick counts the 25 MHz CPU clock of the mps2 boards, so
//! `SysTick ticks x 40 = instructions executed`, repeatable to the tick. Built for
//! `thumbv7em-none-eabihf` (mps2-an386, Cortex-M4F, hard-float f32) and
//! `thumbv7m-none-eabi` (mps2-an385, Cortex-M3, soft-float f32); `thumbv6m-none-eabi` also
//! runs on mps2-an385 (the M3 executes ARMv6-M code: the instructions a Cortex-M0 would).
//!
//! Output (semihosting stdout): one `key=value` line per measurement, read by
//! `scripts/qemu-bench`:
//! - `CAL`: a loop of known length, checking the ticks-to-instructions factor;
//! - `RUN`: a whole scene rendered run by run in one backend (`f32`; `f32-fast`, f32 with
//!   micromath's atan2/acos; `q16.16`, the `Fx` fixed-point format on the image rewritten as
//!   Q16.16) with one technique set (`Techniques::ALL` and, in f32, the paper's types 1-4),
//!   with the tracer's `Stats`, the pixels checked against the host's render of the same
//!   image in the same backend (`build.rs`; the same pixels for every technique set) and the
//!   stats against the host's with the same backend and techniques;
//! - `OP`: micro-benchmarks of single operations in loops (net of an empty loop), in f32
//!   and in Q16.16.
//! - `WIRE`: the RC's per-transfer CPU work (wire encode/decode, CRC, RLE, copy) at two
//!   sizes each ([`wire_bench`]), what host-sim's RC cost model is fitted to.
//!
//! Exits through semihosting: status 0 when every check passed.

#![no_std]
#![no_main]

use core::fmt::Write as _;
use core::hint::black_box;
use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hio};
use links_core::geom::{Aabb, Ray, RayInv, Vec3};
use links_core::image::{SceneView, Section};
use links_core::num::{FastF32, Fx, Real};
use links_core::render::{render_run, Rgb8, Stats, Techniques, Tracer};
use links_core::shape::blob::BlobGroup;
use links_core::shape::triangle::Triangle;

/// One embedded scene (see build.rs).
struct SceneData {
    name: &'static str,
    width: u32,
    height: u32,
    /// The backends and technique sets to render the scene with.
    runs: &'static [Run],
}

/// The number type a run renders with.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Backend {
    F32,
    /// f32 with micromath's atan2 and acos.
    F32Fast,
    /// Q16.16 fixed point, on the scene rewritten as Q16.16.
    Fx,
}

impl Backend {
    fn name(self) -> &'static str {
        match self {
            Backend::F32 => <f32 as Real>::NAME,
            Backend::F32Fast => FastF32::NAME,
            Backend::Fx => Fx::NAME,
        }
    }
}

/// One backend and technique set a scene is rendered with (see build.rs).
struct Run {
    backend: Backend,
    /// `all`, `type1` .. `type4`.
    name: &'static str,
    techniques: Techniques,
    /// The host's operation counts for the whole frame with this backend and these
    /// techniques, as `{:?}` text.
    host_stats_debug: &'static str,
    /// The SceneImage in the backend's storage format.
    image: &'static [u8],
    /// The host's render of `image` in this backend, RGB8 rows (the same for every
    /// technique set).
    reference: &'static [u8],
}

include!(concat!(env!("OUT_DIR"), "/scenes.rs"));

/// QEMU mps2: SysTick runs at 25 MHz; with `-icount shift=0` the CPU runs at 1 instruction
/// per ns, so one tick is 40 instructions.
const INSTR_PER_TICK: u64 = 40;
const RELOAD: u32 = 0x00FF_FFFF;
/// Largest frame the benchmark renders (pixels); the profile build also takes the larger
/// frames of `scripts/qemu-profile --size` (up to 128x128: 48 KB of pixels on the stack).
#[cfg(not(feature = "profile"))]
const MAX_PIXELS: usize = 1024;
#[cfg(feature = "profile")]
const MAX_PIXELS: usize = 128 * 128;
/// Micro-benchmark rays: an 8x8 grid of primary rays over the frame.
const GRID: u32 = 8;

static WRAPS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    // Only this handler writes WRAPS; main reads it.
    WRAPS.store(
        WRAPS.load(Ordering::Relaxed).wrapping_add(1),
        Ordering::Relaxed,
    );
}

/// SysTick ticks since start (wraps counted by the SysTick exception).
#[inline(always)]
fn ticks() -> u64 {
    loop {
        let w = WRAPS.load(Ordering::SeqCst);
        let cur = SYST::get_current();
        if WRAPS.load(Ordering::SeqCst) == w {
            return ((w as u64) << 24) + (RELOAD - cur) as u64;
        }
    }
}

/// Instructions executed by `f` (net of the cost of reading the counter twice).
#[inline(never)]
fn count<R>(f: impl FnOnce() -> R) -> (R, u64) {
    let t0 = ticks();
    let r = black_box(f());
    let t1 = ticks();
    (r, (t1 - t0) * INSTR_PER_TICK)
}

struct Out(hio::HostStream);
impl core::fmt::Write for Out {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        self.0.write_all(s.as_bytes()).map_err(|_| core::fmt::Error)
    }
}

macro_rules! say {
    ($o:expr, $($arg:tt)*) => {{
        let mut line: linebuf::Line = linebuf::Line::new();
        let _ = write!(line, $($arg)*);
        let _ = line.push('\n');
        let _ = $o.write_str(line.as_str());
    }};
}

/// A fixed-capacity line buffer, so each output line is one semihosting call.
mod linebuf {
    pub struct Line {
        buf: [u8; 768],
        len: usize,
    }
    impl Line {
        pub const fn new() -> Self {
            Self {
                buf: [0; 768],
                len: 0,
            }
        }
        pub fn push(&mut self, c: char) -> Result<(), ()> {
            let mut b = [0u8; 4];
            core::fmt::Write::write_str(self, c.encode_utf8(&mut b)).map_err(|_| ())
        }
        pub fn as_str(&self) -> &str {
            core::str::from_utf8(&self.buf[..self.len]).unwrap_or("<bad utf8>")
        }
    }
    impl core::fmt::Write for Line {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            let b = s.as_bytes();
            if self.len + b.len() > self.buf.len() {
                return Err(core::fmt::Error);
            }
            self.buf[self.len..self.len + b.len()].copy_from_slice(b);
            self.len += b.len();
            Ok(())
        }
    }
}

/// Every `Stats` counter as `name=value`, in [`Stats::NAMES`] order (the RUN line's counters;
/// `xtask qemu-bench` reads them back by those names, so a new counter needs no change here).
fn stats_kv(s: &Stats) -> StatsKv<'_> {
    StatsKv(s)
}
struct StatsKv<'a>(&'a Stats);
impl core::fmt::Display for StatsKv<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        for (i, (name, value)) in Stats::NAMES.iter().zip(self.0.values()).enumerate() {
            let sep = if i == 0 { "" } else { " " };
            write!(f, "{sep}{name}={value}")?;
        }
        Ok(())
    }
}

fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn scene(name: &str) -> &'static SceneData {
    SCENES
        .iter()
        .find(|s| s.name == name)
        .expect("scene embedded by build.rs")
}

/// Render a whole frame run by run (one run = one scanline, as a node gets it).
#[inline(never)]
fn render_frame<R: Real>(tracer: &mut Tracer<'_, R>, w: u32, h: u32, out: &mut [Rgb8]) {
    for y in 0..h {
        let row = &mut out[(y * w) as usize..((y + 1) * w) as usize];
        render_run(tracer, y, 0, row).expect("run inside the frame");
    }
}

/// `GRID x GRID` primary rays spread over the frame, with their reciprocal directions.
fn grid_rays<R: Real>(tracer: &Tracer<'_, R>) -> [(Ray<R>, RayInv<R>); (GRID * GRID) as usize] {
    let (w, h) = (tracer.camera().width, tracer.camera().height);
    let mut rays = [(
        Ray::new(Vec3::zero(), Vec3::zero()),
        RayInv::new(Vec3::splat(R::ONE)),
    ); (GRID * GRID) as usize];
    for j in 0..GRID {
        for i in 0..GRID {
            let r = tracer.primary_ray((2 * i + 1) * w / (2 * GRID), (2 * j + 1) * h / (2 * GRID));
            rays[(j * GRID + i) as usize] = (r, RayInv::new(r.dir));
        }
    }
    rays
}

/// The loops below with nothing inside: what each micro-benchmark subtracts.
#[inline(never)]
fn loop_empty<X, R: Real>(items: &[X], rays: &[(Ray<R>, RayInv<R>)]) -> u32 {
    let mut acc = 0u32;
    for _ in rays {
        for it in items {
            if (black_box(it) as *const X as usize) & 4 == 0 {
                acc += 1;
            }
        }
    }
    acc
}

#[inline(never)]
fn loop_empty_index<R: Real>(n: u32, rays: &[(Ray<R>, RayInv<R>)], reps: u32) -> u32 {
    let mut acc = 0u32;
    for _ in 0..reps {
        for _ in rays {
            for i in 0..n {
                if black_box(i) & 4 == 0 {
                    acc += 1;
                }
            }
        }
    }
    acc
}

#[inline(never)]
fn loop_aabb<R: Real>(boxes: &[Aabb<R>], rays: &[(Ray<R>, RayInv<R>)]) -> u32 {
    let mut hits = 0u32;
    for (r, inv) in rays {
        for b in boxes {
            if black_box(b).hit(r, inv, R::MAX) {
                hits += 1;
            }
        }
    }
    hits
}

#[inline(never)]
fn loop_node<R: Real>(view: &SceneView<'_>, rays: &[(Ray<R>, RayInv<R>)]) -> u32 {
    let mut hits = 0u32;
    for (r, inv) in rays {
        for i in 0..view.node_count() {
            if black_box(view).node::<R>(i).bounds.hit(r, inv, R::MAX) {
                hits += 1;
            }
        }
    }
    hits
}

#[inline(never)]
fn loop_triangle<R: Real>(tris: &[Triangle<R>], rays: &[(Ray<R>, RayInv<R>)]) -> u32 {
    let mut hits = 0u32;
    for (r, _) in rays {
        for t in tris {
            if black_box(t).intersect(r, R::MAX).is_some() {
                hits += 1;
            }
        }
    }
    hits
}

#[inline(never)]
fn loop_triangle_rec<R: Real>(view: &SceneView<'_>, rays: &[(Ray<R>, RayInv<R>)]) -> u32 {
    let mut hits = 0u32;
    for (r, _) in rays {
        for i in 0..view.count(Section::Triangles) {
            if black_box(view)
                .triangle::<R>(i)
                .tri
                .intersect(r, R::MAX)
                .is_some()
            {
                hits += 1;
            }
        }
    }
    hits
}

#[inline(never)]
fn loop_ellipsoid<R: Real>(view: &SceneView<'_>, rays: &[(Ray<R>, RayInv<R>)]) -> u32 {
    let mut hits = 0u32;
    for (r, _) in rays {
        for i in 0..view.count(Section::Ellipsoids) {
            if black_box(view)
                .ellipsoid::<R>(i)
                .shape
                .intersect(r, R::MAX)
                .is_some()
            {
                hits += 1;
            }
        }
    }
    hits
}

#[inline(never)]
fn loop_boxshape<R: Real>(view: &SceneView<'_>, rays: &[(Ray<R>, RayInv<R>)], reps: u32) -> u32 {
    let mut hits = 0u32;
    for _ in 0..reps {
        for (r, _) in rays {
            for i in 0..view.count(Section::Boxes) {
                if black_box(view)
                    .boxshape::<R>(i)
                    .shape
                    .intersect(r, R::MAX)
                    .is_some()
                {
                    hits += 1;
                }
            }
        }
    }
    hits
}

/// Deterministic points inside a box (a 32-bit LCG).
struct Lcg(u32);
impl Lcg {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32
    }
}

const BLOB_POINTS: u32 = 256;

fn blob_points<R: Real>(lo: Vec3<R>, hi: Vec3<R>) -> [Vec3<R>; BLOB_POINTS as usize] {
    let mut rng = Lcg(12345);
    let mut pts = [Vec3::zero(); BLOB_POINTS as usize];
    for p in pts.iter_mut() {
        let (a, b, c) = (
            R::from_f32(rng.unit()),
            R::from_f32(rng.unit()),
            R::from_f32(rng.unit()),
        );
        *p = Vec3::new(
            lo.x + (hi.x - lo.x) * a,
            lo.y + (hi.y - lo.y) * b,
            lo.z + (hi.z - lo.z) * c,
        );
    }
    pts
}

/// `field` of blob group `g` at each point, the balls decoded in place as the tracer does.
#[inline(never)]
fn loop_field<R: Real>(view: &SceneView<'_>, g: u32, pts: &[Vec3<R>]) -> R {
    let rec = view.blob_group::<R>(g);
    let scene = *view;
    let group = BlobGroup {
        count: rec.count as usize,
        ball: |k: usize| scene.ball::<R>(rec.first + k as u32),
        kernel: rec.kernel,
        threshold: rec.threshold,
    };
    let mut acc = R::ZERO;
    for p in pts {
        acc += black_box(&group).field(*p);
    }
    acc
}

#[inline(never)]
fn loop_empty_points<R: Real>(pts: &[Vec3<R>]) -> R {
    let mut acc = R::ZERO;
    for p in pts {
        acc += black_box(p).x;
    }
    acc
}

const SQRT_INPUTS: usize = 1024;

/// Positive finite f32 values spread over every exponent.
fn sqrt_inputs() -> [f32; SQRT_INPUTS] {
    let mut rng = Lcg(777);
    let mut v = [0.0f32; SQRT_INPUTS];
    for x in v.iter_mut() {
        rng.unit();
        *x = f32::from_bits((rng.0 >> 1) % 0x7f80_0000);
    }
    v
}

/// `Real::sqrt` for f32, as the tracer calls it (VSQRT.F32 on eabihf, libm elsewhere).
#[inline(never)]
fn loop_sqrt_real(xs: &[f32], out: &mut [f32]) {
    for (x, y) in xs.iter().zip(out.iter_mut()) {
        *y = Real::sqrt(black_box(*x));
    }
}

/// libm's software `sqrtf` (what `Real::sqrt` is on targets without an FPU square root).
#[inline(never)]
fn loop_sqrt_softlibm(xs: &[f32], out: &mut [f32]) {
    for (x, y) in xs.iter().zip(out.iter_mut()) {
        *y = libm::sqrtf(black_box(*x));
    }
}

#[inline(never)]
fn loop_sqrt_none(xs: &[f32], out: &mut [f32]) {
    for (x, y) in xs.iter().zip(out.iter_mut()) {
        *y = black_box(*x);
    }
}

#[inline(never)]
fn loop_powf(xs: &[f32], e: f32, out: &mut [f32]) {
    for (x, y) in xs.iter().zip(out.iter_mut()) {
        *y = Real::powf(black_box(*x), e);
    }
}

/// The FPU's square root (VSQRT.F32), correctly rounded like `libm::sqrtf`.
#[cfg(target_abi = "eabihf")]
#[inline(always)]
fn sqrt_vsqrt(x: f32) -> f32 {
    let mut bits = x.to_bits();
    // SAFETY: moves a value through s14 (declared clobbered) and takes its square root;
    // touches no memory and no flags.
    unsafe {
        core::arch::asm!(
            "vmov s14, {0}",
            "vsqrt.f32 s14, s14",
            "vmov {0}, s14",
            inout(reg) bits,
            out("s14") _,
            options(pure, nomem, nostack, preserves_flags),
        );
    }
    f32::from_bits(bits)
}

#[cfg(target_abi = "eabihf")]
#[inline(never)]
fn loop_sqrt_vsqrt(xs: &[f32], out: &mut [f32]) {
    for (x, y) in xs.iter().zip(out.iter_mut()) {
        *y = sqrt_vsqrt(black_box(*x));
    }
}

/// Square root per call: `Real::sqrt` for f32 (what the tracer runs), libm's software
/// `sqrtf`, and with an FPU the bare VSQRT.F32; `Real::sqrt` and VSQRT are checked to give
/// libm's bits on every input.
fn sqrt_bench(o: &mut Out) -> bool {
    let xs = sqrt_inputs();
    let mut a = [0.0f32; SQRT_INPUTS];
    let mut l = [0.0f32; SQRT_INPUTS];
    let n = SQRT_INPUTS as u64;
    let (_, empty) = count(|| loop_sqrt_none(&xs, &mut a));
    let (_, t) = count(|| loop_sqrt_real(&xs, &mut a));
    op(o, Backend::F32, "Real::sqrt_f32", n, 0, t, empty);
    let (_, t) = count(|| loop_sqrt_softlibm(&xs, &mut l));
    op(o, Backend::F32, "libm::sqrtf", n, 0, t, empty);
    let differ = |p: &[f32], q: &[f32]| {
        p.iter()
            .zip(q.iter())
            .filter(|(x, y)| x.to_bits() != y.to_bits())
            .count()
    };
    let real_differ = differ(&a, &l);
    // powf as Phong's cos^shininess uses it: a cosine in (0, 1], photo1's exponent 40.
    let cosines: [f32; SQRT_INPUTS] =
        core::array::from_fn(|i| (i as f32 + 0.5) / SQRT_INPUTS as f32);
    let mut p = [0.0f32; SQRT_INPUTS];
    let (_, t) = count(|| loop_powf(&cosines, black_box(40.0), &mut p));
    op(o, Backend::F32, "Real::powf_f32_cos^40", n, 0, t, empty);
    #[cfg(target_abi = "eabihf")]
    {
        let mut b = [0.0f32; SQRT_INPUTS];
        let (_, t) = count(|| loop_sqrt_vsqrt(&xs, &mut b));
        op(o, Backend::F32, "vsqrt.f32_inline_asm", n, 0, t, empty);
        let vsqrt_differ = differ(&b, &l);
        say!(
            o,
            "SQRT inputs={} real_vs_libm_differ={} vsqrt_vs_libm_differ={}",
            SQRT_INPUTS,
            real_differ,
            vsqrt_differ
        );
        return real_differ == 0 && vsqrt_differ == 0;
    }
    #[allow(unreachable_code)]
    {
        say!(
            o,
            "SQRT inputs={} real_vs_libm_differ={}",
            SQRT_INPUTS,
            real_differ
        );
        real_differ == 0
    }
}

mod wire_bench;

/// [`wire_bench::Meter`] over the SysTick counter.
struct WireMeter<'a> {
    o: &'a mut Out,
    overhead: u64,
}

impl wire_bench::Meter for WireMeter<'_> {
    fn instr(&mut self, f: &mut dyn FnMut()) -> u64 {
        let t0 = ticks();
        f();
        let t1 = ticks();
        ((t1 - t0) * INSTR_PER_TICK).saturating_sub(self.overhead)
    }
    fn line(&mut self, name: &str, bytes: usize, n: usize, instr: u64) {
        say!(
            self.o,
            "WIRE name={} bytes={} n={} instr={}",
            name,
            bytes,
            n,
            instr
        );
    }
}

fn calibrate(n: u32) {
    // Two instructions per iteration: subs + bne.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {0}, {0}, #1",
            "bne 2b",
            inout(reg) n => _,
            options(nomem, nostack),
        );
    }
}

#[entry]
fn main() -> ! {
    let mut cp = cortex_m::Peripherals::take().expect("core peripherals");
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(RELOAD);
    cp.SYST.clear_current();
    cp.SYST.enable_interrupt();
    cp.SYST.enable_counter();

    let mut o = Out(hio::hstdout().expect("semihosting stdout"));
    let mut ok = true;
    say!(
        o,
        "BENCH target={} fpu={}",
        env!("QEMU_BENCH_TARGET"),
        cfg!(target_abi = "eabihf")
    );

    // Counter overhead and the ticks-to-instructions factor.
    let (_, overhead) = count(|| ());
    let cal_n = 1_000_000u32;
    let (_, cal) = count(|| calibrate(black_box(cal_n)));
    say!(
        o,
        "CAL loop_iters={} expected_instr={} measured_instr={} counter_overhead={}",
        cal_n,
        2 * cal_n as u64,
        cal - overhead,
        overhead
    );

    let mut pixels = [[0u8; 3]; MAX_PIXELS];
    // `--features profile` (scripts/qemu-profile): one frame only (photo1 primary rays +
    // shading unless LINKS_PROFILE_SCENE names another scene at build time; in f32 unless
    // LINKS_PROFILE_BACKEND names another backend by `Real::NAME`, with Techniques::ALL),
    // the window an instruction trace of QEMU is taken over.
    #[cfg(feature = "profile")]
    {
        let s = scene(option_env!("LINKS_PROFILE_SCENE").unwrap_or("photo1-noshadow"));
        let want = option_env!("LINKS_PROFILE_BACKEND").unwrap_or(<f32 as Real>::NAME);
        let r = s
            .runs
            .iter()
            .find(|r| r.backend.name() == want && r.name == "all")
            .expect("LINKS_PROFILE_BACKEND names a backend the scene is rendered in");
        ok &= match r.backend {
            Backend::F32 => render_scene::<f32>(&mut o, s, r, &mut pixels, overhead),
            Backend::F32Fast => render_scene::<FastF32>(&mut o, s, r, &mut pixels, overhead),
            Backend::Fx => render_scene::<Fx>(&mut o, s, r, &mut pixels, overhead),
        };
        say!(o, "END ok={}", ok);
        debug::exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
    }

    // Whole frames, run by run, with each backend and technique set, checked against the
    // host's render.
    for s in SCENES {
        for r in s.runs {
            ok &= match r.backend {
                Backend::F32 => render_scene::<f32>(&mut o, s, r, &mut pixels, overhead),
                Backend::F32Fast => render_scene::<FastF32>(&mut o, s, r, &mut pixels, overhead),
                Backend::Fx => render_scene::<Fx>(&mut o, s, r, &mut pixels, overhead),
            };
        }
    }

    // Micro-benchmarks, in f32 and in Q16.16 (f32-fast differs from f32 in atan2 and acos
    // only, which these operations do not call).
    micro::<f32>(&mut o, Backend::F32);
    micro::<Fx>(&mut o, Backend::Fx);

    ok &= sqrt_bench(&mut o);
    ok &= wire_bench::run(&mut WireMeter {
        o: &mut o,
        overhead,
    });

    say!(o, "END ok={}", ok);
    if ok {
        debug::exit(debug::EXIT_SUCCESS);
    } else {
        debug::exit(debug::EXIT_FAILURE);
    }
    loop {
        cortex_m::asm::wfi();
    }
}

/// The SceneImage of `s` in `backend`'s storage format (its `all` run's image).
fn scene_view(s: &SceneData, backend: Backend) -> SceneView<'static> {
    let r = s
        .runs
        .iter()
        .find(|r| r.backend == backend)
        .expect("build.rs renders the micro-benchmark scenes in every backend");
    SceneView::new(r.image).expect("valid SceneImage")
}

/// Single operations in `R` (loops of one call, net of the empty loop) on photo1's nodes,
/// triangles and boxes, the ellipsoids scene's ellipsoids and metaballs' density fields,
/// each decoded in place from the SceneImage in `R`'s storage format.
fn micro<R: Real>(o: &mut Out, backend: Backend) {
    {
        let view = scene_view(scene("photo1"), backend);
        let tracer = Tracer::<R>::new(view);
        let rays = grid_rays(&tracer);
        let nr = rays.len() as u64;

        let nodes = view.node_count();
        let mut boxes = [Aabb {
            min: Vec3::zero(),
            max: Vec3::zero(),
        }; 2048];
        assert!(nodes as usize <= boxes.len());
        for (i, b) in boxes.iter_mut().enumerate().take(nodes as usize) {
            *b = view.node::<R>(i as u32).bounds;
        }
        let boxes = &boxes[..nodes as usize];
        let (_, empty) = count(|| loop_empty(boxes, &rays));
        let (hits, t) = count(|| loop_aabb(boxes, &rays));
        op(o, backend, "aabb_hit", nr * nodes as u64, hits, t, empty);
        let (_, empty) = count(|| loop_empty_index(nodes, &rays, 1));
        let (hits, t) = count(|| loop_node(&view, &rays));
        op(
            o,
            backend,
            "node_decode+aabb_hit",
            nr * nodes as u64,
            hits,
            t,
            empty,
        );

        let ntri = view.count(Section::Triangles);
        let mut tris = [Triangle {
            p: [Vec3::zero(); 3],
        }; 1024];
        assert!(ntri as usize <= tris.len());
        for (i, t) in tris.iter_mut().enumerate().take(ntri as usize) {
            *t = view.triangle::<R>(i as u32).tri;
        }
        let tris = &tris[..ntri as usize];
        let (_, empty) = count(|| loop_empty(tris, &rays));
        let (hits, t) = count(|| loop_triangle(tris, &rays));
        op(
            o,
            backend,
            "triangle_intersect",
            nr * ntri as u64,
            hits,
            t,
            empty,
        );
        let (_, empty) = count(|| loop_empty_index(ntri, &rays, 1));
        let (hits, t) = count(|| loop_triangle_rec(&view, &rays));
        op(
            o,
            backend,
            "triangle_decode+intersect",
            nr * ntri as u64,
            hits,
            t,
            empty,
        );

        let nbox = view.count(Section::Boxes);
        let reps = 16;
        let (_, empty) = count(|| loop_empty_index(nbox, &rays, reps));
        let (hits, t) = count(|| loop_boxshape(&view, &rays, reps));
        op(
            o,
            backend,
            "boxshape_decode+intersect",
            nr * (nbox * reps) as u64,
            hits,
            t,
            empty,
        );
    }
    {
        let view = scene_view(scene("ellipsoids"), backend);
        let tracer = Tracer::<R>::new(view);
        let rays = grid_rays(&tracer);
        let n = view.count(Section::Ellipsoids);
        let (_, empty) = count(|| loop_empty_index(n, &rays, 1));
        let (hits, t) = count(|| loop_ellipsoid(&view, &rays));
        op(
            o,
            backend,
            "ellipsoid_decode+intersect",
            rays.len() as u64 * n as u64,
            hits,
            t,
            empty,
        );
    }
    {
        let view = scene_view(scene("metaballs"), backend);
        for g in 0..view.count(Section::BlobGroups) {
            let rec = view.blob_group::<R>(g);
            let scene = view;
            let group = BlobGroup {
                count: rec.count as usize,
                ball: |k: usize| scene.ball::<R>(rec.first + k as u32),
                kernel: rec.kernel,
                threshold: rec.threshold,
            };
            let (lo, hi) = group.bounds();
            let pts = blob_points(lo, hi);
            let (_, empty) = count(|| loop_empty_points(&pts));
            let (_, t) = count(|| loop_field(&view, g, &pts));
            let net = t.saturating_sub(empty);
            say!(
            o,
            "OP name=blob_field_eval backend={} group={} balls={} kernel={:?} n={} instr={} per_op={}.{:02}",
            backend.name(),
            g,
            rec.count,
            rec.kernel,
            BLOB_POINTS,
            net,
            net / BLOB_POINTS as u64,
            (net % BLOB_POINTS as u64) * 100 / BLOB_POINTS as u64
        );
        }
    }
}

/// Render scene `s` in `R` with the technique set of `r`, check it against the host's render
/// and print its `RUN` line; true when pixels and counts equal the host's.
fn render_scene<R: Real>(
    o: &mut Out,
    s: &SceneData,
    r: &Run,
    pixels: &mut [Rgb8; MAX_PIXELS],
    overhead: u64,
) -> bool {
    assert!(r.backend.name() == R::NAME, "the run's backend is R");
    let ((), validate) = count(|| {
        black_box(SceneView::new(black_box(r.image)).expect("valid SceneImage"));
    });
    let view = SceneView::new(r.image).expect("valid SceneImage");
    view.check_storage::<R>()
        .expect("the image is in the backend's storage format");
    let mut tracer = Tracer::<R>::with_techniques(view, r.techniques);
    let n = (s.width * s.height) as usize;
    assert!(n <= MAX_PIXELS, "frame too large for the benchmark");
    let out = &mut pixels[..n];
    let ((), instr) = count(|| render_frame(&mut tracer, s.width, s.height, out));
    let mut mismatched = 0u32;
    let mut max_diff = 0u8;
    assert!(r.reference.len() == 3 * n, "reference size");
    for (px, want) in out.iter().zip(r.reference.chunks_exact(3)) {
        if px[..] != want[..] {
            mismatched += 1;
        }
        for k in 0..3 {
            max_diff = max_diff.max(px[k].abs_diff(want[k]));
        }
    }
    let mut dbg = linebuf::Line::new();
    let _ = write!(dbg, "{:?}", tracer.stats);
    let stats_match = dbg.as_str() == r.host_stats_debug;
    say!(
        o,
        "RUN scene={} techniques={} backend={} w={} h={} pixels={} bytes={} instr={} validate_instr={} {} mismatched={} max_diff={} stats_match={} hash={:016x} host_hash={:016x}",
        s.name,
        r.name,
        r.backend.name(),
        s.width,
        s.height,
        n,
        r.image.len(),
        instr - overhead,
        validate - overhead,
        stats_kv(&tracer.stats),
        mismatched,
        max_diff,
        stats_match,
        fnv1a(out.as_flattened()),
        fnv1a(r.reference)
    );
    mismatched == 0 && stats_match
}

/// Print one micro-benchmark: instructions per operation net of the empty loop.
fn op(o: &mut Out, backend: Backend, name: &str, n: u64, hits: u32, instr: u64, empty: u64) {
    let net = instr.saturating_sub(empty);
    say!(
        o,
        "OP name={} backend={} n={} hits={} instr={} empty_loop={} per_op={}.{:02}",
        name,
        backend.name(),
        n,
        hits,
        net,
        empty,
        net / n,
        (net % n) * 100 / n
    );
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    if let Ok(s) = hio::hstdout() {
        let mut o = Out(s);
        say!(o, "PANIC {}", info);
    }
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}
