//! Seeded mutation fuzzing of everything that reads bytes from outside, one test per target:
//!
//! - `image`: the SceneImage validator and the renderer. Whatever [`SceneView::new`] accepts
//!   must render without a panic in every number format, and pass the RC's checks.
//! - `wire`: the bus frame decoders (`links_core::wire`), and the node and RC logic that act
//!   on decoded frames (`run_node`, `run_bus`) fed mutated conversations.
//! - `link`: the SPI link's receive paths (`links_core::spi`): the node's link task and the
//!   RC's master link fed mutated bus bytes.
//! - `backup`: the serial backup line (`links_core::backup`): frame decoder, frame reader,
//!   the node's state machine and the RC's roll call fed mutated frames.
//! - `relay`: the relay link (`links_core::relay`): its batch decoder (what decodes must
//!   re-encode to the bytes it came from) and the relay's logic fed mutated parent frames.
//! - `backup_rc`: the RC's side of the backup line's fallback (`backup::BackupRc`): its
//!   pixel-chunk decoder fed valid, mutated and foreign node answers.
//! - `serial`: the PC <-> RC serial protocol (`links_core::serial`) in both directions: the
//!   RC's session (`rc_fw::session`) and the PC's frame assembly fed mutated byte streams.
//!
//! Each target starts from valid inputs (bundled scenes compiled at tiny sizes, real
//! messages), mutates them (bits, bytes, fields chosen by their meaning, lengths), and, where
//! a checksum or a length would stop the mutation at the door, fixes it up most of the time
//! so the mutations reach the deep checks.
//!
//! Budget and seed come from the environment (`scripts/fuzz` sets them):
//! - `LINKS_FUZZ_SECONDS`: seconds per target (default 4, so CI stays bounded);
//! - `LINKS_FUZZ_ITERS`: run exactly this many inputs per target instead;
//! - `LINKS_FUZZ_SEED`: the seed (default fixed: CI tries the same inputs first every time).
//!
//! The inputs follow from the seed alone (the budget only decides where a run stops), so a
//! failure at input `i` replays with `LINKS_FUZZ_SEED=<seed> LINKS_FUZZ_ITERS=<i + 1>`; its
//! bytes are also saved under `target/tmp/fuzz-failures/` to be minimised into a unit test.
//! The tests need overflow checks (the `test` profile has them) and refuse to run without.

use embassy_futures::block_on;
use links_core::dm::{compile, CompileOptions, MeshHierarchy};
use links_core::fixed_image::to_fixed;
use links_core::image::{SceneView, Section, Word, HEADER_SIZE, NONE, SECTION_COUNT};
use links_core::link::{Incoming, LinkError, NodeId, NodeLink, RootBus, Transfer};
use links_core::node::{
    run_node, Kernels, NodeConfig, NodeError, NodeReport, RealTime, RunRenderer, Tracing,
    TracingByImage,
};
use links_core::num::{FastF32, Fx, Real, Storage};
use links_core::render::{render_run, RenderError, Rgb8, Stats, Techniques, Tracer};
use links_core::root::{run_bus, NoClock, PixelSink, RootConfig, RootError, RootState};
use links_core::sched::{Policy, Split};
use links_core::spi::{
    self, Armed, Bank, MasterLink, MasterPort, PortError, Select, SlaveBanks, SlavePort,
    SlaveShared, ACK, BANK, CRC16, HEADER, NAK,
};
use links_core::wire::PixelCoding;
use links_core::wire::{
    self, Down, Job, Region, SceneState, Up, CRC32, MAX_CHUNKS, MAX_MESSAGE, MAX_RUN, MAX_SCENE,
    SCENE_CHUNK,
};
use links_core::{backup, desc::TransparencyMode, relay, serial};
use links_host::scene_file::load_scene;
use links_host::serial_host::FrameAssembly;
use rc_fw::session::{Session, Step};
use std::cell::RefCell;
use std::collections::{BTreeMap, VecDeque};
use std::future::Future;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::pin::pin;
use std::sync::OnceLock;
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

// ---------------------------------------------------------------------------------------
// The driver: budget, seed, tally, panics reported with what reproduces them
// ---------------------------------------------------------------------------------------

/// The seed CI uses.
const DEFAULT_SEED: u64 = 0x4c49_4e4b_5331_1982;
/// Seconds per target when `LINKS_FUZZ_SECONDS` is not set (four targets in parallel test
/// threads: the whole file stays well under 30 s).
const DEFAULT_SECONDS: f64 = 4.0;

#[derive(Clone, Copy, Debug)]
struct Config {
    seed: u64,
    seconds: f64,
    iters: Option<u64>,
}

fn env_parse<T: std::str::FromStr>(name: &str) -> Option<T> {
    let v = std::env::var(name).ok()?;
    Some(
        v.trim()
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v:?} is not a valid value")),
    )
}

fn config() -> Config {
    let seed = std::env::var("LINKS_FUZZ_SEED").ok().map(|v| {
        let v = v.trim();
        let parsed = match v.strip_prefix("0x") {
            Some(hex) => u64::from_str_radix(hex, 16),
            None => v.parse(),
        };
        parsed.unwrap_or_else(|_| panic!("LINKS_FUZZ_SEED={v:?} is not a number"))
    });
    let seconds: f64 = env_parse("LINKS_FUZZ_SECONDS").unwrap_or(DEFAULT_SECONDS);
    assert!(
        seconds.is_finite() && seconds >= 0.0,
        "LINKS_FUZZ_SECONDS must be >= 0"
    );
    Config {
        seed: seed.unwrap_or(DEFAULT_SEED),
        seconds,
        iters: env_parse("LINKS_FUZZ_ITERS"),
    }
}

/// SplitMix64: every seed (0 included) gives a full-period stream.
#[derive(Clone, Debug)]
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn u32(&mut self) -> u32 {
        (self.next() >> 32) as u32
    }
    /// Uniform in 0..n (0 for n = 0).
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            ((self.next() >> 11) % n as u64) as usize
        }
    }
    /// Uniform in lo..=hi.
    fn range(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.next() % (hi - lo + 1)
    }
    fn chance(&mut self, percent: u64) -> bool {
        self.next() % 100 < percent
    }
    fn pick<'a, T>(&mut self, v: &'a [T]) -> &'a T {
        &v[self.below(v.len())]
    }
    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
}

/// What one input did.
enum Verdict {
    Accepted,
    /// Rejected, and why (a short name; tallied).
    Rejected(String),
}

#[derive(Default)]
struct Tally {
    tried: u64,
    accepted: u64,
    rejected: u64,
    reasons: BTreeMap<String, u64>,
    /// Target-specific counts (paths reached, properties checked).
    notes: BTreeMap<&'static str, u64>,
}

impl Tally {
    fn note(&mut self, what: &'static str, n: u64) {
        *self.notes.entry(what).or_default() += n;
    }
    fn max(&mut self, what: &'static str, v: u64) {
        let e = self.notes.entry(what).or_default();
        *e = (*e).max(v);
    }
}

/// Whether arithmetic overflow panics in this build (it must: the fuzzers look for it).
fn overflow_checks_on() -> bool {
    let prev = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let r = catch_unwind(|| std::hint::black_box(u32::MAX) + std::hint::black_box(1u32));
    std::panic::set_hook(prev);
    r.is_err()
}

fn failures_dir() -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-failures")
}

/// Run `target` for the configured budget: `one` makes input number `i` from the shared
/// random stream (writing its bytes into the buffer, for the report) and judges it.
fn fuzz<S>(
    target: &str,
    state: &mut S,
    mut one: impl FnMut(&mut S, &mut Rng, &mut Vec<u8>, &mut Tally) -> Verdict,
) -> Tally {
    static CHECKED: OnceLock<bool> = OnceLock::new();
    assert!(
        *CHECKED.get_or_init(overflow_checks_on),
        "fuzzing needs overflow checks (run it with the test profile, as scripts/fuzz does)"
    );
    let cfg = config();
    // One stream per target, from the seed and the target's name.
    let name_hash = target.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x100_0000_01b3)
    });
    let mut rng = Rng(cfg.seed ^ name_hash);
    let mut tally = Tally::default();
    let mut input = Vec::new();
    let start = Instant::now();
    let budget = Duration::from_secs_f64(cfg.seconds);
    loop {
        let i = tally.tried;
        let done = match cfg.iters {
            Some(n) => i >= n,
            None => start.elapsed() >= budget && i > 0,
        };
        if done {
            break;
        }
        input.clear();
        let r = catch_unwind(AssertUnwindSafe(|| {
            one(state, &mut rng, &mut input, &mut tally)
        }));
        tally.tried += 1;
        match r {
            Ok(Verdict::Accepted) => tally.accepted += 1,
            Ok(Verdict::Rejected(why)) => {
                tally.rejected += 1;
                *tally.reasons.entry(why).or_default() += 1;
            }
            Err(payload) => {
                let msg = payload
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                let dir = failures_dir();
                let path = dir.join(format!("{target}-{:#x}-{i}.bin", cfg.seed));
                let saved = std::fs::create_dir_all(&dir)
                    .and_then(|_| std::fs::write(&path, &input))
                    .map(|_| path.display().to_string())
                    .unwrap_or_else(|e| format!("(not saved: {e})"));
                panic!(
                    "fuzz target '{target}' panicked on input {i} (LINKS_FUZZ_SEED={:#x}): \
                     {msg}\n  input: {} bytes, saved to {saved}\n  replay: \
                     LINKS_FUZZ_SEED={:#x} LINKS_FUZZ_ITERS={} cargo test -p links-tests \
                     --test fuzz {target}",
                    cfg.seed,
                    input.len(),
                    cfg.seed,
                    i + 1
                );
            }
        }
    }
    let secs = start.elapsed().as_secs_f64();
    let mut out = format!(
        "fuzz {target}: seed {:#x}, {} inputs in {secs:.1} s ({:.0}/s): {} accepted, {} rejected",
        cfg.seed,
        tally.tried,
        tally.tried as f64 / secs.max(1e-9),
        tally.accepted,
        tally.rejected
    );
    if !tally.reasons.is_empty() {
        let r: Vec<String> = tally
            .reasons
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        out += &format!("\n  rejected by: {}", r.join(", "));
    }
    if !tally.notes.is_empty() {
        let r: Vec<String> = tally
            .notes
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        out += &format!("\n  {}", r.join(", "));
    }
    println!("{out}");
    tally
}

/// The variant name of an error's Debug form ("BadReference { .. }" -> "BadReference").
fn variant<E: std::fmt::Debug>(e: &E) -> String {
    let s = format!("{e:?}");
    s.split([' ', '(', '{']).next().unwrap_or("").to_string()
}

/// Poll a future once with a waker that does nothing (`None` if it is not ready).
fn poll_once<F: Future>(f: F) -> Option<F::Output> {
    let mut f = pin!(f);
    match f.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
        Poll::Ready(v) => Some(v),
        Poll::Pending => None,
    }
}

// ---------------------------------------------------------------------------------------
// Mutation helpers shared by the targets
// ---------------------------------------------------------------------------------------

/// u32 values that sit on the edges of checks: small counts, powers of two and their
/// neighbours, the u16/i32/u32 limits, products that wrap (65536^2, 2^32 / 3, the pair
/// 1684887088 x 3649452082 x 3 = 2^64 + 32), and the index marker.
const INTERESTING_U32: [u32; 40] = [
    0,
    1,
    2,
    3,
    4,
    7,
    8,
    15,
    16,
    17,
    31,
    32,
    64,
    127,
    128,
    255,
    256,
    1023,
    1024,
    4096,
    0x7fff,
    0x8000,
    0xffff,
    0x1_0000,
    0x1_0001,
    0x5555_5555,
    0x5555_5556,
    0x7fff_fffe,
    0x7fff_ffff,
    0x8000_0000,
    0x8000_0001,
    0xffff_fffe,
    NONE,
    1_684_887_088,
    3_649_452_082,
    0x1000_0000,
    0x2000_0000,
    0x3000_0000,
    0x3fff_ffff,
    0xc000_0000,
];

/// Scalars at the edges of both formats, as stored bits: f32 zeros, units, extremes,
/// subnormals, infinities and NaN; Q16.16 raw values next to its reserved infinities and NaN.
const INTERESTING_SCALARS: [u32; 26] = [
    0x0000_0000, // 0.0 / Q 0
    0x8000_0000, // -0.0 / Q NaN
    0x3f80_0000, // 1.0
    0xbf80_0000, // -1.0
    0x3f00_0000, // 0.5
    0x0000_0001, // smallest subnormal / Q one step
    0x0080_0000, // f32::MIN_POSITIVE
    0x7f7f_ffff, // f32::MAX
    0xff7f_ffff, // -f32::MAX
    0x7f80_0000, // inf
    0xff80_0000, // -inf
    0x7fc0_0000, // NaN
    0xffff_ffff, // -NaN / Q -1 step
    0x3380_0000, // 2^-24
    0x4b80_0000, // 2^24
    0x5f00_0000, // 2^63
    0x1_0000,    // Q 1.0
    0xffff_0000, // Q -1.0
    0x7fff_ffff, // Q inf (f32 NaN)
    0x8000_0001, // Q -inf
    0x7fff_fffe, // Q largest
    0x8000_0002, // Q most negative finite
    0x0000_8000, // Q 0.5
    0x0100_0000, // Q 256
    0x4000_0000, // 2.0 / Q 16384
    0x2000_0000, // tiny f32 / Q 8192
];

fn rd(b: &[u8], at: usize) -> Option<u32> {
    b.get(at..)?
        .first_chunk::<4>()
        .map(|w| u32::from_le_bytes(*w))
}

fn wr(b: &mut [u8], at: usize, v: u32) {
    if let Some(w) = b.get_mut(at..).and_then(|r| r.first_chunk_mut::<4>()) {
        *w = v.to_le_bytes();
    }
}

/// A replacement for the u32 `old`: an interesting value, a neighbour, or random.
fn interesting_u32(rng: &mut Rng, old: u32) -> u32 {
    match rng.below(10) {
        0..=3 => *rng.pick(&INTERESTING_U32),
        4 => old.wrapping_add(1),
        5 => old.wrapping_sub(1),
        6 => old.wrapping_add(rng.range(2, 64) as u32),
        7 => old.wrapping_mul(2),
        8 => old ^ (1 << rng.below(32)),
        _ => rng.u32(),
    }
}

/// Flip bits, set bytes, insert or delete bytes, truncate or extend: for byte streams with
/// no structure the mutator knows.
fn mutate_bytes(rng: &mut Rng, b: &mut Vec<u8>, max_len: usize) {
    for _ in 0..rng.range(1, 4) {
        match rng.below(8) {
            0 | 1 if !b.is_empty() => {
                let i = rng.below(b.len());
                b[i] ^= 1 << rng.below(8);
            }
            2 if !b.is_empty() => {
                let i = rng.below(b.len());
                let r = rng.next() as u8;
                b[i] = *rng.pick(&[0, 1, 0x7f, 0x80, 0xff, r]);
            }
            3 if b.len() < max_len => {
                let i = rng.below(b.len() + 1);
                let n = rng.range(1, 8) as usize;
                let ins = rng.bytes(n);
                b.splice(i..i, ins);
            }
            4 if !b.is_empty() => {
                let i = rng.below(b.len());
                let n = rng.below(8).min(b.len() - i);
                b.drain(i..i + n);
            }
            5 => {
                let n = rng.below(b.len() + 1);
                b.truncate(n);
            }
            6 if b.len() >= 4 => {
                // A varint-sized field set large (postcard lengths, enum tags).
                let i = rng.below(b.len());
                for k in i..(i + rng.range(1, 5) as usize).min(b.len()) {
                    b[k] = 0xff;
                }
            }
            _ => {
                if b.len() < max_len {
                    let n = rng.range(1, 16) as usize;
                    let extra = rng.bytes(n);
                    b.extend(extra);
                }
            }
        }
    }
    b.truncate(max_len);
}

// ---------------------------------------------------------------------------------------
// Target: image
// ---------------------------------------------------------------------------------------

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// The starting images: every bundled scene compiled at tiny sizes with varied options,
/// as f32 images and (where the scene fits the format) their Q16.16 rewrites.
fn seed_images() -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut names: Vec<PathBuf> = std::fs::read_dir(scenes_dir())
        .expect("scenes/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "ron"))
        .collect();
    names.sort();
    assert!(names.len() >= 6, "bundled scenes: {names:?}");
    let sizes = [(4, 3), (2, 5), (7, 2)];
    for (k, path) in names.iter().enumerate() {
        let desc = load_scene(path).unwrap_or_else(|e| panic!("{e}"));
        for (j, &(w, h)) in sizes.iter().enumerate() {
            let opts = CompileOptions {
                width: Some(w),
                height: Some(h),
                max_depth: Some([2, 5, 16][j]),
                transparency: (j == 1).then_some(TransparencyMode::NonRefractive),
                mesh_hierarchy: [
                    MeshHierarchy::Sah,
                    MeshHierarchy::Flat,
                    MeshHierarchy::Median,
                ][(j + k) % 3],
                no_shadows: j == 2,
                leaf_size: Some([4, 1, 31][(j + 2 * k) % 3]),
                aa: Some([1, 2, 3][j]),
            };
            let img = compile(&desc, &opts)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
                .bytes;
            if let Ok(f) = to_fixed(&img) {
                out.push(f.bytes);
            }
            out.push(img);
        }
    }
    out
}

/// The section table of possibly damaged bytes (zeros where it is missing).
fn table(img: &[u8]) -> [(u32, u32); SECTION_COUNT] {
    let mut t = [(0, 0); SECTION_COUNT];
    for (i, e) in t.iter_mut().enumerate() {
        *e = (
            rd(img, 16 + 8 * i).unwrap_or(0),
            rd(img, 20 + 8 * i).unwrap_or(0),
        );
    }
    t
}

/// A record of a section that lies inside the bytes: (section, its byte offset).
fn some_record(rng: &mut Rng, img: &[u8]) -> Option<(Section, usize)> {
    let t = table(img);
    let present: Vec<Section> = Section::ALL
        .into_iter()
        .filter(|&s| {
            let (off, n) = t[s as usize];
            n > 0 && (off as usize) < img.len()
        })
        .collect();
    if present.is_empty() {
        return None;
    }
    let s = *rng.pick(&present);
    let (off, n) = t[s as usize];
    let size = s.record_size();
    let room = (img.len() - off as usize) / size;
    let r = rng.below((n as usize).min(room).max(1));
    Some((s, off as usize + r * size))
}

/// Words of a record that hold integers (indices, counts, sizes, kinds, flags), by section:
/// the `Word::U` words of the one record layout (`links_core::image::layout`).
fn integer_words(s: Section) -> Vec<usize> {
    s.words()
        .unwrap_or(&[])
        .iter()
        .enumerate()
        .filter(|(_, w)| **w == Word::U)
        .map(|(i, _)| i)
        .collect()
}

/// One u16 field of a record of integers: another section's count (or one past it), the
/// absent marker, a leaf info byte pair, or an interesting value.
fn mutate_u16_field(rng: &mut Rng, img: &mut [u8], s: Section, at: usize) {
    let k = 2 * rng.below((s.record_size() / 2).max(1));
    let t = table(img);
    let v: u16 = match rng.below(5) {
        0 => (t[rng.below(SECTION_COUNT)].1 as u16).wrapping_add(rng.below(2) as u16),
        1 => u16::MAX,
        // A node's info and material bytes: kind 0..7, count 0..31.
        2 => ((rng.below(8) as u16) << 5) | rng.below(32) as u16 | (rng.below(4) as u16) << 8,
        3 => interesting_u32(rng, 0) as u16,
        _ => rng.next() as u16,
    };
    if let Some(b) = img.get_mut(at + k..at + k + 2) {
        b.copy_from_slice(&v.to_le_bytes());
    }
}

/// One structure-aware change to an image.
fn mutate_image_once(rng: &mut Rng, img: &mut Vec<u8>, corpus: &[Vec<u8>]) {
    match rng.below(100) {
        // An integer field of a record: an index, count, size, kind or flag.
        0..=29 => {
            if let Some((s, at)) = some_record(rng, img) {
                if s.words().is_none() && s != Section::Texels {
                    // Records of u16 indices and bytes (nodes, triangles, corners, normals,
                    // rectangles): one u16 field.
                    mutate_u16_field(rng, img, s, at);
                    return;
                }
                let ints = integer_words(s);
                let words = s.record_size() / 4;
                let w = if !ints.is_empty() && rng.chance(80) {
                    *rng.pick(&ints)
                } else {
                    rng.below(words.max(1))
                };
                // Sometimes the whole record's integers at once (a texture's w and h).
                let all = rng.chance(25);
                for &k in if all {
                    &ints[..]
                } else {
                    std::slice::from_ref(&w)
                } {
                    let old = rd(img, at + 4 * k).unwrap_or(0);
                    let t = table(img);
                    let v = match rng.below(6) {
                        // Another section's count, or one past it: the index bounds.
                        0 => {
                            let c = t[rng.below(SECTION_COUNT)].1;
                            c.wrapping_add(rng.below(2) as u32)
                        }
                        _ => interesting_u32(rng, old),
                    };
                    wr(img, at + 4 * k, v);
                }
            }
        }
        // A scalar field: an edge of either format.
        30..=44 => {
            if let Some((s, at)) = some_record(rng, img) {
                let words = (s.record_size() / 4).max(1);
                let v = *rng.pick(&INTERESTING_SCALARS);
                wr(img, at + 4 * rng.below(words), v);
            }
        }
        // The section table: an offset or a count.
        45..=54 => {
            let i = rng.below(SECTION_COUNT);
            let t = table(img);
            let at = 16 + 8 * i + 4 * rng.below(2);
            let old = rd(img, at).unwrap_or(0);
            let v = match rng.below(4) {
                0 => t[rng.below(SECTION_COUNT)].0,
                1 => img.len() as u32,
                2 => (img.len() as u32).wrapping_sub(rng.below(64) as u32 * 4),
                _ => interesting_u32(rng, old),
            };
            wr(img, at, v);
        }
        // The header: version, number format, scale.
        55..=59 => {
            let at = rng.range(4, 7) as usize;
            if let Some(b) = img.get_mut(at) {
                let r = rng.next() as u8;
                *b = *rng.pick(&[0, 1, 2, 3, 0x7f, 0x80, 0xff, r]);
            }
        }
        // Copy one record over another of the same section, or swap two nodes' words.
        60..=64 => {
            if let (Some((s, a)), Some((s2, b))) = (some_record(rng, img), some_record(rng, img)) {
                if s == s2 && a != b {
                    let n = s.record_size();
                    if let Some(rec) = img.get(a..a + n).map(|r| r.to_vec()) {
                        if let Some(dst) = img.get_mut(b..b + n) {
                            dst.copy_from_slice(&rec);
                        }
                    }
                }
            }
        }
        // Splice bytes from another image at the same place.
        65..=69 => {
            let other = rng.pick(corpus);
            let n = img.len().min(other.len());
            if n > 0 {
                let at = rng.below(n);
                let len = rng.below(256).min(n - at);
                img[at..at + len].copy_from_slice(&other[at..at + len]);
            }
        }
        // Truncate or extend.
        70..=74 => {
            if rng.chance(50) {
                let n = rng.below(img.len() + 1);
                img.truncate(n);
            } else {
                let n = rng.range(1, 64) as usize * 4;
                let extra = rng.bytes(n);
                img.extend(extra);
            }
        }
        // Any aligned word.
        75..=84 => {
            if img.len() >= 4 {
                let at = rng.below(img.len() / 4) * 4;
                let old = rd(img, at).unwrap_or(0);
                let v = if rng.chance(50) {
                    interesting_u32(rng, old)
                } else {
                    *rng.pick(&INTERESTING_SCALARS)
                };
                wr(img, at, v);
            }
        }
        // Bits and bytes.
        _ => mutate_bytes(rng, img, MAX_SCENE + 4096),
    }
}

/// Bytes that are not derived from a scene: random, sometimes behind a plausible header.
fn random_image(rng: &mut Rng) -> Vec<u8> {
    let n = rng.below(700);
    let mut b = rng.bytes(n);
    if rng.chance(70) && b.len() >= HEADER_SIZE {
        b[0..4].copy_from_slice(b"LNK1");
        b[4..6].copy_from_slice(&3u16.to_le_bytes());
        b[6] = rng.below(2) as u8;
        b[7] = 0;
        // Small counts at aligned offsets inside the bytes.
        for i in 0..SECTION_COUNT {
            let off = (HEADER_SIZE + rng.below(b.len() - HEADER_SIZE + 1)) as u32 & !3;
            wr(&mut b, 16 + 8 * i, off);
            wr(&mut b, 20 + 8 * i, rng.below(4) as u32);
        }
    }
    b
}

/// Render a bounded set of pixels of `view` with number type `T`: every pixel of a frame of
/// at most 16, else, on the first row, the last row and a random row, runs of up to 4
/// pixels at the left edge, the right edge and a random column. Nothing in the tracer
/// depends on the pixel other than the ray's direction and the clipping compares against
/// the row and column, so the frame's corners and edges (the extreme directions and the
/// ends of every rectangle range) plus a moving sample keep the guarantee's spirit
/// ("every pixel renders") at a cost bounded per image; runs exercise the X-clipping sweep.
fn render_sample<T: Real>(
    view: SceneView<'_>,
    techniques: Techniques,
    rng: &mut Rng,
    tally: &mut Tally,
) -> Result<(), RenderError> {
    let f = view.camera::<f32>();
    let (w, h) = (f.width, f.height);
    let mut tracer = Tracer::<T>::with_techniques(view, techniques);
    let mut runs: Vec<(u32, u32, u32)> = Vec::new();
    if w as u64 * h as u64 <= 16 {
        runs.extend((0..h).map(|y| (y, 0, w)));
    } else {
        let rows = [0, h - 1, rng.below(h as usize) as u32];
        for y in rows {
            let n = w.min(4);
            runs.push((y, 0, n));
            runs.push((y, w - n, n));
            let x = rng.below((w - n + 1) as usize) as u32;
            runs.push((y, x, n));
        }
    }
    let mut px: Vec<Rgb8> = vec![[0; 3]; 8];
    let mut pixels = 0;
    for (y, x, n) in runs {
        px.resize(n as usize, [0; 3]);
        let before = tracer.stats;
        render_run(&mut tracer, y, x, &mut px)?;
        pixels += n as u64;
        // The most work one run asked for (deterministic counts, not time).
        let d = diff(&tracer.stats, &before);
        tally.max("max rays per run", d.rays());
        tally.max("max blob field evals per run", d.blob_field_evals);
    }
    tally.note("pixels rendered", pixels);
    Ok(())
}

fn diff(a: &Stats, b: &Stats) -> Stats {
    Stats {
        primary_rays: a.primary_rays - b.primary_rays,
        shadow_rays: a.shadow_rays - b.shadow_rays,
        reflect_rays: a.reflect_rays - b.reflect_rays,
        refract_rays: a.refract_rays - b.refract_rays,
        straight_rays: a.straight_rays - b.straight_rays,
        blob_field_evals: a.blob_field_evals - b.blob_field_evals,
        ..Stats::default()
    }
}

const TECHNIQUES: [Techniques; 5] = [
    Techniques::ALL,
    Techniques::PAPER_TYPE_1,
    Techniques::PAPER_TYPE_2,
    Techniques::PAPER_TYPE_3,
    Techniques::PAPER_TYPE_4,
];

/// Everything that must hold for an accepted image.
fn check_accepted(img: &[u8], view: SceneView<'_>, rng: &mut Rng, tally: &mut Tally) {
    // Node firmware renders whatever image it holds with its own number type (it does not
    // compare the image's storage format), so every backend must survive every accepted
    // image: f32, the fast-f32 variant, f64 and Q16.16. The node's path uses all
    // techniques; the others are the host's and the ablation's.
    let tech = if rng.chance(70) {
        Techniques::ALL
    } else {
        *rng.pick(&TECHNIQUES)
    };
    let f = view.camera::<f32>();
    let outside = |e: RenderError| panic!("a run inside the {}x{} frame: {e}", f.width, f.height);
    render_sample::<f32>(view, tech, rng, tally).unwrap_or_else(outside);
    render_sample::<FastF32>(view, tech, rng, tally).unwrap_or_else(outside);
    render_sample::<f64>(view, tech, rng, tally).unwrap_or_else(outside);
    render_sample::<Fx>(view, tech, rng, tally).unwrap_or_else(outside);
    // The DM's fixed-point rewrite of an accepted f32 image is itself accepted.
    if view.storage() == Storage::F32 {
        if let Ok(fixed) = to_fixed(img) {
            let v = SceneView::new(&fixed.bytes)
                .unwrap_or_else(|e| panic!("to_fixed's output is rejected: {e}"));
            tally.note("to_fixed rewrites", 1);
            render_sample::<Fx>(v, tech, rng, tally).unwrap_or_else(outside);
        }
    }
    // The RC's checks: an image a node accepts is one the RC takes (if it fits a bank),
    // with its frame's size.
    let divisions = rng.range(1, 64) as u32;
    let cfg = RootConfig {
        policy: *rng.pick(&[
            Policy::DECREASING,
            Policy::Static { shape: Split::Rect },
            Policy::Fixed {
                divisions,
                shape: Split::Span,
            },
        ]),
        nodes: rng.range(1, 16) as u16,
        frames: 1,
        timeout_us: RootConfig::DEFAULT_TIMEOUT_US,
        double_buffer: rng.chance(50),
    };
    match RootState::new(cfg, &[img][..]) {
        Ok(root) => {
            assert_eq!(root.size(), (f.width, f.height));
            tally.note("RC accepted", 1);
        }
        Err(RootError::SceneTooLarge { len, max, .. }) => {
            assert!(
                img.len() > MAX_SCENE,
                "RC rejects a valid image as too large"
            );
            assert_eq!((len as usize, max as usize), (img.len(), MAX_SCENE));
            tally.note("RC refused a scene larger than a bank", 1);
        }
        Err(RootError::Sched(_)) => tally.note("RC scheduler refused the frame", 1),
        Err(e) => panic!("RC: {e}"),
    }
}

struct ImageState {
    seeds: usize,
    corpus: Vec<Vec<u8>>,
}

#[test]
fn image() {
    let corpus = seed_images();
    let mut state = ImageState {
        seeds: corpus.len(),
        corpus,
    };
    let t = fuzz("image", &mut state, |st, rng, input, tally| {
        // The seeds first, unchanged, then mutants.
        let i = tally.tried as usize;
        if i < st.seeds {
            input.extend_from_slice(&st.corpus[i]);
        } else if rng.chance(3) {
            input.extend(random_image(rng));
        } else {
            let base = rng.below(st.corpus.len());
            input.extend_from_slice(&st.corpus[base]);
            for _ in 0..rng.range(1, 4) {
                mutate_image_once(rng, input, &st.corpus);
            }
            // Most of the time the header's length matches, so the deep checks run.
            if rng.chance(90) {
                let n = input.len() as u32;
                wr(input, 8, n);
            }
        }
        let view = match SceneView::new(input) {
            Ok(v) => v,
            Err(e) => return Verdict::Rejected(variant(&e)),
        };
        check_accepted(input, view, rng, tally);
        if i < st.seeds {
            tally.note("seeds", 1);
        } else if st.corpus.len() < st.seeds + 256 {
            st.corpus.push(input.clone());
        } else {
            let k = st.seeds + rng.below(256);
            st.corpus[k] = input.clone();
        }
        Verdict::Accepted
    });
    if t.tried >= state.seeds as u64 {
        assert_eq!(
            t.notes.get("seeds").copied(),
            Some(state.seeds as u64),
            "every seed image is accepted"
        );
    }
}

// ---------------------------------------------------------------------------------------
// Target: wire (frame decoders, and the node and RC logic acting on decoded frames)
// ---------------------------------------------------------------------------------------

/// A small u32 for a field that is usually small, sometimes an edge value.
fn small_or_edge(rng: &mut Rng, small: u64) -> u32 {
    if rng.chance(75) {
        rng.range(0, small) as u32
    } else {
        interesting_u32(rng, 0)
    }
}

fn some_region(rng: &mut Rng, w: u32, h: u32) -> Region {
    if rng.chance(50) {
        Region::Span {
            start: small_or_edge(rng, (w * h) as u64),
            len: small_or_edge(rng, (w * h) as u64),
        }
    } else {
        Region::Rect {
            x: small_or_edge(rng, w as u64) as u16,
            y: small_or_edge(rng, h as u64) as u16,
            w: small_or_edge(rng, w as u64) as u16,
            h: small_or_edge(rng, h as u64) as u16,
        }
    }
}

fn some_job(rng: &mut Rng, w: u32, h: u32) -> Job {
    Job {
        id: small_or_edge(rng, 64),
        frame: small_or_edge(rng, 3) as u16,
        region: some_region(rng, w, h),
    }
}

fn some_scene_state(rng: &mut Rng) -> SceneState {
    match rng.below(3) {
        0 => SceneState::Ready {
            frame: small_or_edge(rng, 3) as u16,
        },
        1 => {
            let mut chunks = [0u32; MAX_CHUNKS / 32];
            for c in chunks.iter_mut() {
                *c = if rng.chance(50) { 0 } else { rng.u32() };
            }
            SceneState::Missing {
                frame: small_or_edge(rng, 3) as u16,
                chunks,
                pieces: if rng.chance(50) { 0 } else { rng.u32() as u16 },
            }
        }
        _ => SceneState::None,
    }
}

/// A random RC -> NC message (`data`: the payload a scene chunk borrows).
fn some_down<'a>(rng: &mut Rng, data: &'a [u8], w: u32, h: u32) -> Down<'a> {
    match rng.below(5) {
        0 => Down::Work {
            jobs: [
                rng.chance(80).then(|| some_job(rng, w, h)),
                rng.chance(50).then(|| some_job(rng, w, h)),
            ],
        },
        1 => {
            let n = rng.below(data.len().min(SCENE_CHUNK) + 1);
            let at = rng.below(data.len() - n + 1);
            Down::Scene {
                frame: small_or_edge(rng, 3) as u16,
                offset: small_or_edge(rng, 4).wrapping_mul(SCENE_CHUNK as u32),
                total: small_or_edge(rng, data.len() as u64),
                crc: rng.u32(),
                data: &data[at..at + n],
            }
        }
        2 => Down::SceneEnd {
            frame: small_or_edge(rng, 3) as u16,
            len: small_or_edge(rng, data.len() as u64),
            crc: rng.u32(),
        },
        3 => Down::Stop,
        _ => Down::Wake {
            frame: small_or_edge(rng, 3) as u16,
        },
    }
}

/// A random NC -> RC message (`buf`: the bytes a pixel run borrows).
fn some_up<'a>(rng: &mut Rng, buf: &'a [u8], w: u32, h: u32) -> Up<'a> {
    let n = rng.below(buf.len() + 1);
    let bytes = &buf[..n];
    match rng.below(5) {
        0 => Up::Status {
            scene: some_scene_state(rng),
        },
        1 => Up::Poll,
        2 => Up::Pixels {
            job: small_or_edge(rng, 64),
            frame: small_or_edge(rng, 3) as u16,
            y: small_or_edge(rng, h as u64) as u16,
            x: small_or_edge(rng, w as u64) as u16,
            rgb: bytes,
            done: rng.chance(30),
        },
        3 => Up::PixelsRle {
            job: small_or_edge(rng, 64),
            frame: small_or_edge(rng, 3) as u16,
            y: small_or_edge(rng, h as u64) as u16,
            x: small_or_edge(rng, w as u64) as u16,
            len: small_or_edge(rng, MAX_RUN as u64) as u16,
            data: bytes,
            done: rng.chance(30),
        },
        _ => Up::PixelsDelta {
            job: small_or_edge(rng, 64),
            frame: small_or_edge(rng, 3) as u16,
            y: small_or_edge(rng, h as u64) as u16,
            x: small_or_edge(rng, w as u64) as u16,
            len: small_or_edge(rng, MAX_RUN as u64) as u16,
            data: bytes,
            done: rng.chance(30),
        },
    }
}

/// Recompute a wire frame's trailing CRC-32 (so byte mutations reach the decoder).
fn fix_wire_crc(b: &mut [u8]) {
    if b.len() >= 4 {
        let n = b.len() - 4;
        let c = CRC32.checksum(&b[..n]).to_le_bytes();
        b[n..].copy_from_slice(&c);
    }
}

/// A message of either direction, encoded as a wire frame.
trait WireMsg {
    fn frame(&self, seq: u16, ack: u16) -> Vec<u8>;
}

macro_rules! wire_msg {
    ($t:ident) => {
        impl WireMsg for $t<'_> {
            fn frame(&self, seq: u16, ack: u16) -> Vec<u8> {
                let mut buf = vec![0u8; 2 * MAX_MESSAGE];
                let n = wire::encode(seq, ack, self, &mut buf).expect("fits two frames");
                buf.truncate(n);
                buf
            }
        }
    };
}
wire_msg!(Down);
wire_msg!(Up);

fn wire_frame<M: WireMsg>(seq: u16, ack: u16, msg: &M) -> Vec<u8> {
    msg.frame(seq, ack)
}

/// A region's pieces tile it: each inside the frame, together exactly its pixels.
fn check_region(r: Region, w: u32, h: u32, tally: &mut Tally) {
    let _ = r.pixels();
    if !r.fits(w, h) {
        for i in [0, 1, u32::MAX] {
            let _ = r.piece(w, i);
        }
        return;
    }
    let (mut sum, mut i) = (0u64, 0u32);
    while let Some((y, x, len)) = r.piece(w, i) {
        assert!(
            y < h && len > 0 && x as u64 + len as u64 <= w as u64,
            "{r:?} in {w}x{h}: piece {i} = ({y}, {x}, {len})"
        );
        sum += len as u64;
        i += 1;
        assert!(i <= h + 1, "{r:?} in {w}x{h}: more pieces than rows");
    }
    assert_eq!(sum, r.pixels() as u64, "{r:?} in {w}x{h}");
    tally.note("regions tiled", 1);
}

/// Decode bytes as both directions' messages and check what decodes.
fn check_wire_bytes(bytes: &[u8], rng: &mut Rng, tally: &mut Tally) -> Verdict {
    let (w, h) = if rng.chance(50) {
        (rng.range(1, 64) as u32, rng.range(1, 64) as u32)
    } else {
        (
            rng.range(1, u16::MAX as u64) as u32,
            rng.range(1, u16::MAX as u64) as u32,
        )
    };
    let down = wire::decode::<Down>(bytes);
    let up = wire::decode::<Up>(bytes);
    if let Ok(env) = &down {
        // What decodes re-encodes to a frame that decodes the same.
        let again = wire_frame(env.seq, env.ack, &env.msg);
        assert_eq!(wire::decode::<Down>(&again).as_ref(), Ok(env));
        if let Down::Work { jobs } = env.msg {
            for j in jobs.iter().flatten() {
                check_region(j.region, w, h, tally);
            }
        }
    }
    if let Ok(env) = &up {
        let again = wire_frame(env.seq, env.ack, &env.msg);
        assert_eq!(wire::decode::<Up>(&again).as_ref(), Ok(env));
        type Codec = (
            fn(&[u8], &mut [u8]) -> Result<(), wire::WireError>,
            fn(&[u8], &mut [u8]) -> Option<usize>,
            &'static str,
        );
        let codec: Option<(u16, &[u8], Codec)> = match env.msg {
            Up::PixelsRle { len, data, .. } => Some((
                len,
                data,
                (wire::rle_decode, wire::rle_encode, "rle round trips"),
            )),
            Up::PixelsDelta { len, data, .. } => Some((
                len,
                data,
                (wire::delta_decode, wire::delta_encode, "delta round trips"),
            )),
            _ => None,
        };
        if let Some((len, data, (decode, encode, note))) = codec {
            let mut out = vec![0u8; 3 * len as usize];
            if decode(data, &mut out).is_ok() {
                // Decoded pixels code and decode back to themselves, and the encoder's own
                // coding is never longer than the data it decoded from.
                let mut coded = vec![0u8; 4 * len as usize];
                let n = encode(&out, &mut coded).expect("room for every pixel");
                let mut back = vec![0u8; out.len()];
                decode(&coded[..n], &mut back).expect("own coding decodes");
                assert_eq!(back, out);
                assert!(n <= data.len(), "{note}: {n} > {}", data.len());
                tally.note(note, 1);
            }
        }
    }
    match (down, up) {
        (Ok(_), _) | (_, Ok(_)) => Verdict::Accepted,
        (Err(e), _) => Verdict::Rejected(variant(&e)),
    }
}

/// A renderer that renders at most `left` more pixels (then fails the run, which the node
/// counts as a bad job): a hostile job on a huge frame must not take the test's time.
struct Budgeted {
    left: usize,
}

impl RunRenderer for Budgeted {
    fn render(
        &mut self,
        scene: SceneView<'_>,
        frame: u16,
        y: u32,
        x: u32,
        out: &mut [Rgb8],
    ) -> Result<Stats, RenderError> {
        if out.len() > self.left {
            return Err(RenderError::RunOutsideFrame {
                x,
                y,
                len: out.len() as u32,
            });
        }
        self.left -= out.len();
        Tracing::<f32>::new().render(scene, frame, y, x, out)
    }

    fn kernels(&self) -> Kernels {
        Kernels::F32
    }
}

/// One frame the scripted RC sends a node: exchanged (else broadcast), the message, and
/// the seed of a byte mutation to apply after encoding.
struct NodeItem<'a> {
    exchanged: bool,
    msg: Down<'a>,
    mutate: Option<u64>,
}

/// The RC's side of a node's link, from a script: acknowledges what the node posted last,
/// and records the pixels the node sends.
struct ScriptLink<'a> {
    items: VecDeque<NodeItem<'a>>,
    seq: u16,
    last_posted: Option<u16>,
    fix_crc: bool,
    /// (y, x) -> colour of every pixel posted.
    pixels: BTreeMap<(u16, u16), Rgb8>,
    posts: u64,
}

impl NodeLink for ScriptLink<'_> {
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        assert!(
            frame.len() <= MAX_MESSAGE,
            "a node frame of {}",
            frame.len()
        );
        // The node sends only frames that decode, whatever it was sent.
        let env = wire::decode::<Up>(frame).expect("the node posts valid frames");
        self.posts += 1;
        if env.msg != Up::Poll {
            self.last_posted = Some(env.seq);
        }
        let mut buf = [0u8; 3 * MAX_RUN];
        let (y, x, rgb): (u16, u16, &[u8]) = match env
            .msg
            .pixel_run(&mut buf)
            .expect("the node's coding decodes")
        {
            Some(r) => (r.y, r.x, r.rgb),
            None => return Ok(()),
        };
        for (k, px) in rgb.chunks_exact(3).enumerate() {
            self.pixels.insert((y, x + k as u16), [px[0], px[1], px[2]]);
        }
        Ok(())
    }

    async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
        let item = self.items.pop_front().ok_or(LinkError::Aborted)?;
        let ack = self.last_posted.unwrap_or(0);
        let mut f = wire_frame(self.seq, ack, &item.msg);
        self.seq = self.seq.wrapping_add(1);
        if let Some(seed) = item.mutate {
            mutate_bytes(&mut Rng(seed), &mut f, MAX_MESSAGE + 8);
            if self.fix_crc {
                fix_wire_crc(&mut f);
            }
        }
        // A frame longer than the buffer arrives as nothing, as on the link.
        let len = match rx.get_mut(..f.len()) {
            Some(dst) => {
                dst.copy_from_slice(&f);
                f.len()
            }
            None => 0,
        };
        Ok(if item.exchanged {
            Incoming::Exchanged { len }
        } else {
            Incoming::Broadcast { len }
        })
    }
}

/// A node with one kernel, broadcast a scene of the other storage: once the scene is
/// complete and checked it stops with the typed error, having rendered nothing; with the
/// image's own kernel (or both) the same conversation ends with `Stop` and the whole frame
/// as the single-node render of that kernel has it.
#[test]
fn a_node_renders_with_the_images_kernel_and_stops_on_one_it_lacks() {
    let f = links_tests::bundled_image("photo1.ron", 24, 18);
    let q = links_host::frame::fixed_image(&f).expect("photo1 fits Q16.16");
    let session =
        |img: &[u8], renderer: &mut dyn FnMut(&mut ScriptLink<'_>) -> Result<(), NodeError>| {
            let (crc, total) = (CRC32.checksum(img), img.len() as u32);
            let mut items: Vec<NodeItem<'_>> = img
                .chunks(SCENE_CHUNK)
                .enumerate()
                .map(|(c, data)| NodeItem {
                    exchanged: false,
                    msg: Down::Scene {
                        frame: 0,
                        offset: (c * SCENE_CHUNK) as u32,
                        total,
                        crc,
                        data,
                    },
                    mutate: None,
                })
                .collect();
            let job = Job {
                id: 1,
                frame: 0,
                region: Region::Span {
                    start: 0,
                    len: 24 * 18,
                },
            };
            let mut jobs = [None; wire::JOB_QUEUE];
            jobs[0] = Some(job);
            let work = (0..64).map(|_| (true, Down::Work { jobs }));
            let tail = [(
                false,
                Down::SceneEnd {
                    frame: 0,
                    len: total,
                    crc,
                },
            )]
            .into_iter()
            .chain(work)
            .chain([(true, Down::Stop)]);
            items.extend(tail.map(|(exchanged, msg)| NodeItem {
                exchanged,
                msg,
                mutate: None,
            }));
            let mut link = ScriptLink {
                items: items.into(),
                seq: 0,
                last_posted: None,
                fix_crc: false,
                pixels: BTreeMap::new(),
                posts: 0,
            };
            let r = renderer(&mut link);
            let px: Vec<u8> = link.pixels.values().flatten().copied().collect();
            (r, px)
        };
    fn node<R: RunRenderer>(link: &mut ScriptLink<'_>, mut r: R) -> Result<(), NodeError> {
        let (mut b0, mut b1) = (vec![0u8; MAX_SCENE], vec![0u8; MAX_SCENE]);
        let mut report = NodeReport::default();
        let banks = [b0.as_mut_slice(), b1.as_mut_slice()];
        let cfg = NodeConfig::default();
        block_on(run_node(
            cfg,
            link,
            &mut RealTime,
            &mut r,
            banks,
            &mut report,
        ))
    }
    let want = |img: &[u8], p| {
        links_host::frame::render_frame(img, p, 1, &|| {})
            .expect("renders")
            .rgb
    };
    use links_host::frame::Precision;
    let (want_f, want_q) = (want(&f, Precision::F32), want(&q, Precision::Fixed));
    assert_ne!(want_f, want_q);
    let lacks = |image, kernels| Err(NodeError::NoKernel { image, kernels });
    let (r, px) = session(&q, &mut |l| node(l, Tracing::<f32>::new()));
    assert_eq!((r, px.len()), (lacks(Storage::Q16_16, Kernels::F32), 0));
    let (r, px) = session(&f, &mut |l| node(l, Tracing::<Fx>::new()));
    assert_eq!((r, px.len()), (lacks(Storage::F32, Kernels::Fixed), 0));
    let (r, px) = session(&q, &mut |l| node(l, Tracing::<Fx>::new()));
    assert_eq!(r, Ok(()));
    assert!(px == want_q, "the Q16.16 node's frame");
    for (img, want) in [(&q, &want_q), (&f, &want_f)] {
        let (r, px) = session(img, &mut |l| node(l, TracingByImage::default()));
        assert_eq!(r, Ok(()));
        assert!(px == *want, "a node with both kernels");
    }
}

/// A node's whole conversation: the scene broadcast, exchanges handing it work, `Stop`;
/// then (unless `pct` is 0) each frame replaced, mutated, dropped or repeated with
/// probability `pct`%. Unmutated, the node must deliver every pixel of its jobs exactly as
/// the single-node render has them.
fn node_session(img: &[u8], reference: &[Rgb8], rng: &mut Rng, tally: &mut Tally) {
    let view = SceneView::new(img).expect("valid image");
    let f = view.camera::<f32>();
    let (w, h) = (f.width, f.height);
    let pct = *rng.pick(&[0, 0, 3, 10, 30]);
    let crc = CRC32.checksum(img);
    let total = img.len() as u32;
    let frame = 0u16;
    let mut script: Vec<NodeItem<'_>> = Vec::new();
    for (c, data) in img.chunks(SCENE_CHUNK).enumerate() {
        script.push(NodeItem {
            exchanged: false,
            msg: Down::Scene {
                frame,
                offset: (c * SCENE_CHUNK) as u32,
                total,
                crc,
                data,
            },
            mutate: None,
        });
    }
    script.push(NodeItem {
        exchanged: false,
        msg: Down::SceneEnd {
            frame,
            len: total,
            crc,
        },
        mutate: None,
    });
    // Two jobs covering the frame: its first row as a span, the rest as a rectangle.
    let jobs = [
        Some(Job {
            id: 1,
            frame,
            region: Region::Span { start: 0, len: w },
        }),
        (h > 1).then_some(Job {
            id: 2,
            frame,
            region: Region::Rect {
                x: 0,
                y: 1,
                w: w as u16,
                h: (h - 1) as u16,
            },
        }),
    ];
    for _ in 0..(2 * h + 8) {
        script.push(NodeItem {
            exchanged: true,
            msg: Down::Work { jobs },
            mutate: None,
        });
    }
    script.push(NodeItem {
        exchanged: true,
        msg: Down::Stop,
        mutate: None,
    });
    let mutated = pct > 0;
    if mutated {
        let mut out = Vec::new();
        for mut item in script {
            if rng.chance(pct) {
                match rng.below(5) {
                    0 => item.msg = some_down(rng, img, w, h),
                    1 => item.mutate = Some(rng.next()),
                    2 => continue,
                    3 => item.exchanged = !item.exchanged,
                    _ => {
                        let again = NodeItem {
                            exchanged: item.exchanged,
                            msg: item.msg,
                            mutate: None,
                        };
                        out.push(again);
                    }
                }
            }
            out.push(item);
        }
        script = out;
    }
    let mut link = ScriptLink {
        items: script.into(),
        seq: 0,
        last_posted: None,
        fix_crc: rng.chance(85),
        pixels: BTreeMap::new(),
        posts: 0,
    };
    let (mut b0, mut b1) = (vec![0u8; img.len().max(4096)], vec![0u8; MAX_SCENE]);
    let mut report = NodeReport::default();
    let mut renderer = Budgeted { left: 4096 };
    let r = block_on(run_node(
        NodeConfig {
            coding: [PixelCoding::Raw, PixelCoding::Rle, PixelCoding::Delta][rng.below(3)],
        },
        &mut link,
        &mut RealTime,
        &mut renderer,
        [b0.as_mut_slice(), b1.as_mut_slice()],
        &mut report,
    ));
    tally.note("node sessions", 1);
    tally.note("node frames posted", link.posts);
    if !mutated {
        assert_eq!(r, Ok(()), "an intact conversation ends with Stop");
        assert_eq!(
            link.pixels.len() as u32,
            w * h,
            "every pixel sent: {report:?}"
        );
        for ((y, x), c) in &link.pixels {
            assert_eq!(
                *c,
                reference[*y as usize * w as usize + *x as usize],
                "pixel ({x}, {y})"
            );
        }
        tally.note("node sessions complete", 1);
    }
}

/// A fake node's state on the scripted bus.
#[derive(Default)]
struct FakeNc {
    next_seq: u16,
    /// Frames sent and not acknowledged, oldest first: (seq, bytes).
    unacked: VecDeque<(u16, Vec<u8>)>,
    /// Messages to send, as (job, frame, y, x, len, done) runs or a status.
    todo: VecDeque<FakeMsg>,
    seen_jobs: Vec<u32>,
}

#[derive(Clone, Copy)]
enum FakeMsg {
    Ready(u16),
    Run {
        job: u32,
        frame: u16,
        y: u16,
        x: u16,
        len: u16,
        done: bool,
    },
}

/// The RC's bus with scripted nodes behind it: they report each frame's scene ready, render
/// every job handed to them as flat-coloured runs, and (with probability `pct`% per frame)
/// send something else: a message with fields at their edges, damaged bytes with a fixed
/// CRC, an empty frame.
struct ScriptBus {
    nodes: Vec<FakeNc>,
    next: u16,
    tx: Vec<u8>,
    started: Option<(Transfer, usize)>,
    reply: Vec<u8>,
    transfers: u32,
    limit: u32,
    rng: Rng,
    pct: u64,
    w: u32,
    h: u32,
}

impl ScriptBus {
    /// The node's reply to an exchange whose RC frame is `down`.
    fn reply(&mut self, node: usize, down: &wire::Envelope<Down<'_>>) -> Vec<u8> {
        let (w, h, pct) = (self.w, self.h, self.pct);
        let nc = &mut self.nodes[node];
        // Acknowledged frames are done with; the rest go again, oldest first.
        let ack = down.ack;
        while nc
            .unacked
            .front()
            .is_some_and(|(s, _)| s.wrapping_sub(ack) as i16 <= 0)
        {
            nc.unacked.pop_front();
        }
        if let Down::Work { jobs } = down.msg {
            for j in jobs.iter().flatten() {
                if nc.seen_jobs.contains(&j.id) || !j.region.fits(w, h) {
                    continue;
                }
                nc.seen_jobs.push(j.id);
                let mut i = 0;
                let mut pieces = Vec::new();
                while let Some((y, x, len)) = j.region.piece(w, i) {
                    pieces.push((y, x, len));
                    i += 1;
                }
                let last = pieces.len().saturating_sub(1);
                for (k, (y, x, len)) in pieces.into_iter().enumerate() {
                    nc.todo.push_back(FakeMsg::Run {
                        job: j.id,
                        frame: j.frame,
                        y: y as u16,
                        x: x as u16,
                        len: len as u16,
                        done: k == last,
                    });
                }
            }
        }
        let rng = &mut self.rng;
        if rng.chance(pct) {
            // Something else entirely.
            let mut buf = rng.bytes(3 * MAX_RUN);
            buf.iter_mut().for_each(|b| *b &= 0x7f);
            return match rng.below(4) {
                0 => {
                    let up = some_up(rng, &buf, w, h);
                    let seq = if rng.chance(50) {
                        nc.next_seq
                    } else {
                        rng.u32() as u16
                    };
                    let f = wire_frame(seq, 0, &up);
                    if seq == nc.next_seq && up != Up::Poll {
                        nc.next_seq = nc.next_seq.wrapping_add(1);
                        nc.unacked.push_back((seq, f.clone()));
                    }
                    f
                }
                1 => {
                    let mut f = nc
                        .unacked
                        .front()
                        .map(|(_, f)| f.clone())
                        .unwrap_or_else(|| wire_frame(nc.next_seq, 0, &Up::Poll));
                    mutate_bytes(rng, &mut f, MAX_MESSAGE);
                    if rng.chance(85) {
                        fix_wire_crc(&mut f);
                    }
                    f
                }
                2 => Vec::new(),
                _ => {
                    let n = rng.below(64);
                    rng.bytes(n)
                }
            };
        }
        if nc.unacked.len() < 2 {
            if let Some(m) = nc.todo.pop_front() {
                let seq = nc.next_seq;
                let rgb = [0x40u8; 3 * MAX_RUN];
                let f = match m {
                    FakeMsg::Ready(frame) => wire_frame(
                        seq,
                        0,
                        &Up::Status {
                            scene: SceneState::Ready { frame },
                        },
                    ),
                    FakeMsg::Run {
                        job,
                        frame,
                        y,
                        x,
                        len,
                        done,
                    } => wire_frame(
                        seq,
                        0,
                        &Up::Pixels {
                            job,
                            frame,
                            y,
                            x,
                            rgb: &rgb[..3 * len as usize],
                            done,
                        },
                    ),
                };
                nc.next_seq = seq.wrapping_add(1);
                nc.unacked.push_back((seq, f.clone()));
                return f;
            }
        }
        match nc.unacked.front() {
            Some((_, f)) => f.clone(),
            None => wire_frame(nc.next_seq, 0, &Up::Poll),
        }
    }
}

impl RootBus for ScriptBus {
    fn nodes(&self) -> (NodeId, u16) {
        (0, self.nodes.len() as u16)
    }
    async fn wait_ready(&mut self) -> NodeId {
        self.next
    }
    fn ready(&self) -> Option<NodeId> {
        Some(self.next)
    }
    fn tx_bank(&mut self) -> &mut [u8] {
        &mut self.tx
    }
    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        if self.started.is_some() {
            return Err(LinkError::Busy);
        }
        assert!(len <= MAX_MESSAGE);
        // The RC sends only frames that decode.
        let sent = self.tx[..len].to_vec();
        let env = wire::decode::<Down>(&sent).expect("the RC sends valid frames");
        if let Transfer::Exchange(node) = transfer {
            assert!(
                (node as usize) < self.nodes.len(),
                "exchange with node {node}"
            );
            self.reply = self.reply(node as usize, &env);
            self.next = (node + 1) % self.nodes.len() as u16;
        }
        self.started = Some((transfer, len));
        Ok(())
    }
    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        let (transfer, _) = self.started.take().ok_or(LinkError::Aborted)?;
        self.transfers += 1;
        if self.transfers > self.limit {
            return Err(LinkError::Aborted);
        }
        match transfer {
            Transfer::Broadcast => Ok(0),
            Transfer::Exchange(_) => {
                let n = self.reply.len().min(rx.len());
                rx[..n].copy_from_slice(&self.reply[..n]);
                Ok(n)
            }
        }
    }
}

/// Checks every pixel run the RC accepts: inside the frame.
struct CheckSink {
    w: u32,
    h: u32,
    frames: u16,
    pixels: u64,
}

impl PixelSink for CheckSink {
    fn pixels(&mut self, frame: u16, y: u16, x: u16, rgb: &[u8]) {
        assert!(frame < self.frames, "pixels of frame {frame}");
        assert!(
            (y as u32) < self.h
                && rgb.len().is_multiple_of(3)
                && x as u32 + (rgb.len() / 3) as u32 <= self.w,
            "run of {} bytes at ({x}, {y}) accepted for a {}x{} frame",
            rgb.len(),
            self.w,
            self.h
        );
        self.pixels += (rgb.len() / 3) as u64;
    }
}

/// The RC driving scripted nodes through whole frames. Unmutated, it must finish with every
/// pixel delivered once per frame.
fn root_session(img: &[u8], rng: &mut Rng, tally: &mut Tally) {
    let f = SceneView::new(img).expect("valid image").camera::<f32>();
    let (w, h) = (f.width, f.height);
    let pct = *rng.pick(&[0, 0, 2, 10, 40]);
    let frames = rng.range(1, 2) as u16;
    let nodes = rng.range(1, 4) as u16;
    let cfg = RootConfig {
        policy: *rng.pick(&[
            Policy::DECREASING,
            Policy::Static { shape: Split::Rect },
            Policy::Static { shape: Split::Span },
            Policy::Decreasing {
                factor: 2,
                min_pixels: 1,
            },
        ]),
        nodes,
        frames,
        timeout_us: 0,
        double_buffer: rng.chance(50),
    };
    let scenes = vec![img; frames as usize];
    let root = RefCell::new(RootState::new(cfg, &scenes[..]).expect("RC takes the image"));
    let mut bus = ScriptBus {
        nodes: (0..nodes)
            .map(|_| FakeNc {
                todo: (0..frames).map(FakeMsg::Ready).collect(),
                ..FakeNc::default()
            })
            .collect(),
        next: 0,
        tx: vec![0u8; MAX_MESSAGE],
        started: None,
        reply: Vec::new(),
        transfers: 0,
        limit: 600,
        rng: Rng(rng.next()),
        pct,
        w,
        h,
    };
    let sink = RefCell::new(CheckSink {
        w,
        h,
        frames,
        pixels: 0,
    });
    let r = block_on(run_bus(0, &mut bus, &NoClock, &root, &scenes[..], &sink));
    tally.note("RC sessions", 1);
    tally.note("RC transfers", bus.transfers as u64);
    if pct == 0 {
        let report = r.expect("an intact conversation finishes");
        assert_eq!(
            sink.borrow().pixels,
            (w * h) as u64 * frames as u64,
            "{report:?}"
        );
        tally.note("RC sessions complete", 1);
    }
}

struct WireState {
    /// Small valid images for the node and RC sessions, and their f32 renders.
    images: Vec<(Vec<u8>, Vec<Rgb8>)>,
    corpus: Vec<Vec<u8>>,
}

fn render_all_f32(img: &[u8]) -> Vec<Rgb8> {
    let view = SceneView::new(img).expect("valid image");
    let f = view.camera::<f32>();
    let mut t = Tracer::<f32>::new(view);
    let mut out = vec![[0u8; 3]; (f.width * f.height) as usize];
    for (y, row) in out.chunks_mut(f.width as usize).enumerate() {
        render_run(&mut t, y as u32, 0, row).expect("inside");
    }
    out
}

/// The smallest seed images (the node and RC sessions send them over and over).
fn small_images(n: usize) -> Vec<Vec<u8>> {
    let mut v: Vec<Vec<u8>> = seed_images()
        .into_iter()
        .filter(|i| SceneView::new(i).is_ok_and(|v| v.storage() == Storage::F32))
        .collect();
    v.sort_by_key(|i| i.len());
    v.truncate(n);
    v
}

#[test]
fn wire() {
    let images: Vec<(Vec<u8>, Vec<Rgb8>)> = small_images(3)
        .into_iter()
        .map(|i| {
            let r = render_all_f32(&i);
            (i, r)
        })
        .collect();
    let mut st = WireState {
        images,
        corpus: Vec::new(),
    };
    let t = fuzz("wire", &mut st, |st, rng, input, tally| {
        match rng.below(100) {
            // The node acting on a scripted RC.
            0..=2 => {
                let (img, reference) = &st.images[rng.below(st.images.len())];
                input.extend_from_slice(img);
                node_session(img, reference, rng, tally);
                return Verdict::Accepted;
            }
            // The RC acting on scripted nodes.
            3..=5 => {
                let (img, _) = &st.images[rng.below(st.images.len())];
                input.extend_from_slice(img);
                root_session(img, rng, tally);
                return Verdict::Accepted;
            }
            _ => {}
        }
        // A frame: a fresh message or a corpus frame, mutated, its CRC mostly fixed.
        let (w, h) = (rng.range(1, 64) as u32, rng.range(1, 64) as u32);
        if st.corpus.is_empty() || rng.chance(40) {
            let data = rng.bytes(3 * MAX_RUN);
            let seq = small_or_edge(rng, 8) as u16;
            let ack = small_or_edge(rng, 8) as u16;
            let f = match rng.below(5) {
                0 | 1 => wire_frame(seq, ack, &some_down(rng, &data, w, h)),
                2 | 3 => wire_frame(seq, ack, &some_up(rng, &data, w, h)),
                _ => {
                    // A run the node's own coding produced (random bytes rarely are one).
                    let len = rng.range(1, MAX_RUN as u64) as usize;
                    let grey = rng.range(2, 200) as u8;
                    let px: Vec<u8> = (0..3 * len)
                        .map(|k| if rng.chance(80) { grey } else { k as u8 })
                        .collect();
                    let mut coded = vec![0u8; 4 * len];
                    let n = wire::rle_encode(&px, &mut coded).expect("room for every pixel");
                    let up = Up::PixelsRle {
                        job: small_or_edge(rng, 64),
                        frame: 0,
                        y: small_or_edge(rng, h as u64) as u16,
                        x: small_or_edge(rng, w as u64) as u16,
                        len: len as u16,
                        data: &coded[..n],
                        done: rng.chance(30),
                    };
                    wire_frame(seq, ack, &up)
                }
            };
            input.extend(f);
        } else {
            input.extend_from_slice(&st.corpus[rng.below(st.corpus.len())]);
        }
        if rng.chance(80) {
            mutate_bytes(rng, input, MAX_MESSAGE + 64);
            if rng.chance(85) {
                fix_wire_crc(input);
            }
        }
        let v = check_wire_bytes(input, rng, tally);
        if matches!(v, Verdict::Accepted) {
            if st.corpus.len() < 512 {
                st.corpus.push(input.clone());
            } else {
                let k = rng.below(512);
                st.corpus[k] = input.clone();
            }
        }
        v
    });
    if t.tried >= 200 {
        assert!(t
            .notes
            .get("node sessions complete")
            .is_some_and(|&n| n > 0));
        assert!(t.notes.get("RC sessions complete").is_some_and(|&n| n > 0));
    }
}

// ---------------------------------------------------------------------------------------
// Target: link (the SPI link's receive paths)
// ---------------------------------------------------------------------------------------

/// A node's SPI port: each armed transfer receives the next scripted bus bytes.
struct FuzzSlave {
    /// What the RC clocks into the node's bank per transfer (`None`: a port error).
    script: VecDeque<Option<Vec<u8>>>,
    /// What was clocked in the transfer that just ended (padded as the zeroed bank is).
    last: Vec<u8>,
    cancel_next: bool,
}

impl SlavePort for FuzzSlave {
    async fn transfer(
        &mut self,
        _tx: &[u8],
        rx: &mut [u8],
        _cancel: impl Future<Output = ()>,
    ) -> Result<Armed, PortError> {
        if std::mem::take(&mut self.cancel_next) {
            return Ok(Armed::Cancelled);
        }
        let Some(bytes) = self.script.pop_front().flatten() else {
            return Err(PortError);
        };
        let n = bytes.len().min(rx.len());
        rx[..n].copy_from_slice(&bytes[..n]);
        self.last = rx.to_vec();
        Ok(Armed::Done)
    }
    fn set_ready(&mut self, _high: bool) {}
}

/// What an RC transfer looks like on MOSI: a header for the body (broadcast or exchange),
/// the body (a real frame or random bytes), a trailer byte; then damaged.
fn rc_transfer(rng: &mut Rng, corpus: &[Vec<u8>]) -> Vec<u8> {
    let body = if !corpus.is_empty() && rng.chance(70) {
        corpus[rng.below(corpus.len())].clone()
    } else {
        let n = rng.below(MAX_MESSAGE + 1);
        rng.bytes(n)
    };
    let broadcast = rng.chance(40);
    let mut t = spi::rc_header(broadcast, &body).to_vec();
    t.extend_from_slice(&body);
    t.push(*rng.pick(&[ACK, NAK, 0, 0xff]));
    if rng.chance(50) {
        mutate_link_bytes(rng, &mut t);
    }
    t
}

/// Damage a link transfer: anywhere, or its header's length or kind with the header's CRC
/// fixed so the damage reaches the body checks.
fn mutate_link_bytes(rng: &mut Rng, t: &mut Vec<u8>) {
    if t.len() >= HEADER && rng.chance(60) {
        match rng.below(3) {
            0 => {
                let len = u16::from_le_bytes([t[2], t[3]]);
                let v = match rng.below(4) {
                    0 => len.wrapping_add(1),
                    1 => len.wrapping_sub(1),
                    2 => *rng.pick(&[0, MAX_MESSAGE as u16, MAX_MESSAGE as u16 + 1, u16::MAX]),
                    _ => rng.next() as u16,
                };
                t[2..4].copy_from_slice(&v.to_le_bytes());
            }
            1 => t[1] = *rng.pick(&[0, 1, 2, 3, 0xff]),
            _ => t[0] = *rng.pick(&[0xa5, 0x5a, 0]),
        }
        if rng.chance(80) {
            let c = CRC16.checksum(&t[..6]).to_le_bytes();
            t[6..8].copy_from_slice(&c);
        }
    } else {
        mutate_bytes(rng, t, BANK + 16);
    }
}

/// The node's link task over scripted transfers: only intact RC frames reach the node
/// logic, byte for byte; an exchange whose body is damaged arrives empty.
fn slave_session(rng: &mut Rng, corpus: &[Vec<u8>], input: &mut Vec<u8>, tally: &mut Tally) -> u64 {
    let n = rng.range(1, 12) as usize;
    let script: VecDeque<Option<Vec<u8>>> = (0..n)
        .map(|_| rng.chance(95).then(|| rc_transfer(rng, corpus)))
        .collect();
    for t in script.iter().flatten() {
        input.extend_from_slice(&(t.len() as u32).to_le_bytes());
        input.extend_from_slice(t);
    }
    let mut banks: Vec<Bank> = vec![[0u8; BANK]; 5];
    let [tx0, tx1, rx0, rx1, scratch] = &mut banks[..] else {
        unreachable!()
    };
    let (shared, mut task) = SlaveShared::new(SlaveBanks {
        tx: [tx0, tx1],
        rx: [rx0, rx1],
        scratch,
    });
    let mut port = FuzzSlave {
        script,
        last: Vec::new(),
        cancel_next: false,
    };
    let mut handle = shared.handle();
    let mut rx = vec![0u8; MAX_MESSAGE];
    let mut delivered = 0u64;
    for _ in 0..n + 2 {
        port.cancel_next = rng.chance(5);
        port.last.clear();
        block_on(task.step(&mut port, &shared));
        let clocked = std::mem::take(&mut port.last);
        if rng.chance(30) {
            // The node posts a frame (sometimes too long): the link takes it or refuses it.
            let len = if rng.chance(90) {
                rng.below(MAX_MESSAGE + 1)
            } else {
                MAX_MESSAGE + 1
            };
            let f = rng.bytes(len);
            let r = handle.post(&f);
            assert!(
                len <= MAX_MESSAGE || r.is_err(),
                "an oversize frame was posted"
            );
        }
        // Take what arrived (the queue holds at most two frames).
        for _ in 0..2 {
            let Some(got) = poll_once(handle.recv(&mut rx)) else {
                break;
            };
            let got = got.expect("recv only fails on its own errors");
            let (len, broadcast) = match got {
                Incoming::Exchanged { len } => (len, false),
                Incoming::Broadcast { len } => (len, true),
            };
            assert!(len <= MAX_MESSAGE);
            if len > 0 && !clocked.is_empty() {
                // Delivered bytes are a body whose header (kind, length, CRC) is intact.
                let body = &clocked[HEADER..HEADER + len];
                assert_eq!(
                    &clocked[..HEADER],
                    &spi::rc_header(broadcast, body)[..],
                    "a damaged frame was delivered"
                );
                assert_eq!(&rx[..len], body);
                delivered += 1;
            }
        }
    }
    let c = shared.counters();
    assert!(c.exchanges + c.broadcasts + c.bad_headers <= c.transfers + c.rearms);
    tally.note("node link frames delivered", delivered);
    tally.note("node link bad headers", c.bad_headers as u64);
    tally.note("node link bad bodies", c.bad_bodies as u64);
    delivered
}

/// The RC's SPI port with one scripted node behind it.
struct FuzzMaster {
    nodes: u16,
    /// What the selected node drives on MISO for the exchange (`None`: a port error).
    miso: Option<Vec<u8>>,
    at: usize,
    selected: bool,
    ready_before: bool,
    ready_after: bool,
    /// The trailer byte the RC sent last.
    trailer: Option<u8>,
}

impl MasterPort for FuzzMaster {
    fn count(&self) -> u16 {
        self.nodes
    }
    fn ready(&self, _i: u16) -> bool {
        if self.selected {
            self.ready_after
        } else {
            self.ready_before
        }
    }
    async fn wait_any_ready(&mut self) {}
    async fn select(&mut self, _sel: Select) {
        self.selected = true;
        self.at = 0;
    }
    async fn deselect(&mut self) {
        self.selected = false;
    }
    async fn transfer(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), PortError> {
        assert_eq!(tx.len(), rx.len(), "full duplex");
        assert!(self.selected, "clocked without a chip-select");
        let miso = self.miso.as_ref().ok_or(PortError)?;
        for (k, b) in rx.iter_mut().enumerate() {
            *b = miso.get(self.at + k).copied().unwrap_or(0);
        }
        self.at += rx.len();
        if tx.len() == 1 {
            self.trailer = Some(tx[0]);
        }
        Ok(())
    }
}

/// What a node drives during an exchange: its header (a posted frame's length and CRC, or
/// none) and the frame; then damaged.
fn nc_transfer(rng: &mut Rng, corpus: &[Vec<u8>]) -> Vec<u8> {
    let body = if !corpus.is_empty() && rng.chance(70) {
        corpus[rng.below(corpus.len())].clone()
    } else {
        let n = rng.below(MAX_MESSAGE + 1);
        rng.bytes(n)
    };
    // The node header: magic 0x5a, flags (bit 0: posted), length, body CRC, header CRC.
    let posted = rng.chance(85);
    let mut t = vec![0x5a, posted as u8];
    t.extend_from_slice(&(body.len() as u16).to_le_bytes());
    t.extend_from_slice(&CRC16.checksum(&body).to_le_bytes());
    let c = CRC16.checksum(&t[..6]).to_le_bytes();
    t.extend_from_slice(&c);
    t.extend_from_slice(&body);
    if rng.chance(50) {
        mutate_link_bytes(rng, &mut t);
    }
    t
}

/// The RC's master link over scripted nodes: `finish` hands on only intact node frames,
/// acknowledges exactly those, and never more than the caller's buffer.
fn master_session(
    rng: &mut Rng,
    corpus: &[Vec<u8>],
    input: &mut Vec<u8>,
    tally: &mut Tally,
) -> u64 {
    let mut banks: Vec<Bank> = vec![[0u8; BANK]; 3];
    let [tx0, tx1, rxb] = &mut banks[..] else {
        unreachable!()
    };
    let nodes = rng.range(1, 4) as u16;
    let port = FuzzMaster {
        nodes,
        miso: None,
        at: 0,
        selected: false,
        ready_before: true,
        ready_after: false,
        trailer: None,
    };
    let mut link = MasterLink::new(port, 0, [tx0, tx1], rxb);
    let mut delivered = 0u64;
    for _ in 0..rng.range(1, 8) {
        let miso = rng.chance(97).then(|| nc_transfer(rng, corpus));
        if let Some(m) = &miso {
            input.extend_from_slice(&(m.len() as u32).to_le_bytes());
            input.extend_from_slice(m);
        }
        let p = link.port_mut();
        p.miso = miso.clone();
        p.ready_before = rng.chance(95);
        p.ready_after = rng.chance(5);
        p.trailer = None;
        let len = if rng.chance(95) {
            rng.below(MAX_MESSAGE + 1)
        } else {
            MAX_MESSAGE + 1 + rng.below(8)
        };
        let out = rng.bytes(len.min(MAX_MESSAGE));
        link.tx_bank()[..out.len()].copy_from_slice(&out);
        let transfer = if rng.chance(25) {
            Transfer::Broadcast
        } else {
            Transfer::Exchange(rng.below(nodes as usize + 1) as u16)
        };
        match link.start(transfer, len) {
            Ok(()) => {}
            Err(e) => {
                assert!(
                    len > MAX_MESSAGE || matches!(transfer, Transfer::Exchange(n) if n >= nodes),
                    "start refused: {e}"
                );
                continue;
            }
        }
        let mut rx = vec![
            0u8;
            if rng.chance(90) {
                MAX_MESSAGE
            } else {
                rng.below(64)
            }
        ];
        let got = block_on(link.finish(&mut rx));
        let trailer = link.port().trailer;
        match got {
            Ok(n) if n > 0 => {
                // What the node drove, as clocked: zeros after its last byte.
                let mut m = miso.clone().expect("a frame came from the node");
                m.resize(m.len().max(HEADER + n), 0);
                let h = spi::nc_header(&m).expect("an intact header");
                assert_eq!(h.len as usize, n);
                assert_eq!(&rx[..n], &m[HEADER..HEADER + n]);
                assert_eq!(CRC16.checksum(&rx[..n]), h.body_crc);
                assert_eq!(trailer, Some(ACK), "an intact frame is acknowledged");
                delivered += 1;
            }
            Ok(_) => {
                // Nothing handed on: a NAK if a damaged posted body was clocked.
                if let Some(t) = trailer {
                    assert!(t == ACK || t == NAK);
                }
            }
            Err(LinkError::TooLong { .. }) => tally.note("RC link frames longer than rx", 1),
            Err(e) => panic!("finish: {e}"),
        }
    }
    let c = link.counters;
    tally.note("RC link frames delivered", delivered);
    tally.note("RC link NAKs", c.naks as u64);
    tally.note("RC link bad headers", c.bad_headers as u64);
    delivered
}

#[test]
fn link() {
    // Real frames of both directions for bodies.
    let mut rng0 = Rng(7);
    let data = rng0.bytes(3 * MAX_RUN);
    let mut corpus: Vec<Vec<u8>> = (0..64)
        .map(|k| {
            if k % 2 == 0 {
                wire_frame(k, 0, &some_down(&mut rng0, &data, 16, 16))
            } else {
                wire_frame(k, 0, &some_up(&mut rng0, &data, 16, 16))
            }
        })
        .collect();
    corpus.retain(|f| f.len() <= MAX_MESSAGE);
    // An input is a session of up to 12 transfers; "accepted": some frame was handed on.
    fuzz("link", &mut corpus, |corpus, rng, input, tally| {
        let delivered = if rng.chance(50) {
            slave_session(rng, corpus, input, tally)
        } else {
            master_session(rng, corpus, input, tally)
        };
        if delivered > 0 {
            Verdict::Accepted
        } else {
            Verdict::Rejected("no intact frame".into())
        }
    });
}

// ---------------------------------------------------------------------------------------
// Target: serial (the PC <-> RC protocol, both directions)
// ---------------------------------------------------------------------------------------

fn cobs_encode(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8];
    let mut code_at = 0;
    for &b in data {
        if b == 0 {
            out[code_at] = (out.len() - code_at) as u8;
            code_at = out.len();
            out.push(0);
        } else {
            out.push(b);
            if out.len() - code_at == 0xff {
                out[code_at] = 0xff;
                code_at = out.len();
                out.push(0);
            }
        }
    }
    out[code_at] = (out.len() - code_at) as u8;
    out
}

fn cobs_decode(enc: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < enc.len() {
        let code = enc[i] as usize;
        if code == 0 || i + code > enc.len() {
            return None;
        }
        out.extend_from_slice(&enc[i + 1..i + code]);
        i += code;
        if code < 0xff && i < enc.len() {
            out.push(0);
        }
    }
    Some(out)
}

/// A serial frame's body (postcard and CRC, COBS removed), for mutating; `None` if the
/// frame is not one.
fn serial_body(frame: &[u8]) -> Option<Vec<u8>> {
    cobs_decode(frame.strip_prefix(&[0])?.strip_suffix(&[0])?)
}

/// Frame a body: CRC fixed if asked, COBS, delimiters.
fn serial_frame(body: &[u8], fix_crc: bool) -> Vec<u8> {
    let mut b = body.to_vec();
    if fix_crc {
        fix_wire_crc(&mut b);
    }
    let mut f = vec![0];
    f.extend(cobs_encode(&b));
    f.push(0);
    f
}

/// Damage a frame on the line: in its body (CRC mostly fixed) or as raw bytes (stuffing,
/// delimiters, garbage between frames, an overlong frame).
fn mutate_serial(rng: &mut Rng, f: &mut Vec<u8>, max: usize) {
    match (rng.below(10), serial_body(f)) {
        (0..=5, Some(mut body)) => {
            mutate_bytes(rng, &mut body, max);
            *f = serial_frame(&body, rng.chance(85));
        }
        (6, _) => {
            // Longer than any receive buffer: non-zero bytes up to the next delimiter.
            let n = rng.range(max as u64, 2 * max as u64) as usize;
            f.splice(1..1, std::iter::repeat_n(0x55, n));
        }
        _ => mutate_bytes(rng, f, 2 * max),
    }
}

fn encode_to_rc(seq: u16, msg: &serial::ToRc<'_>) -> Vec<u8> {
    let mut buf = vec![0u8; serial::MAX_TO_RC];
    let n = serial::encode_packet(seq, msg, &mut buf).expect("fits");
    buf.truncate(n);
    buf
}

fn encode_to_pc(seq: u16, msg: &serial::ToPc<'_>) -> Vec<u8> {
    let mut buf = vec![0u8; serial::MAX_TO_PC];
    let n = serial::encode_packet(seq, msg, &mut buf).expect("fits");
    buf.truncate(n);
    buf
}

/// An unbounded USB queue (the RC's readback output) that keeps every byte.
#[derive(Default)]
struct Sent(RefCell<Vec<u8>>);

impl rc_fw::readback::ByteQueue for &Sent {
    fn free(&self) -> usize {
        usize::MAX
    }
    fn push(&mut self, bytes: &[u8]) -> bool {
        self.0.borrow_mut().extend_from_slice(bytes);
        true
    }
}

impl rc_fw::throttle::Room for &Sent {
    fn has_room(&self, _n: usize) -> bool {
        true
    }
    async fn wait_room(&self, _n: usize) {}
}

/// Every frame in `bytes` (what the RC sent) decoded as the PC would: all must be valid.
fn pc_reads(bytes: &[u8]) -> Vec<String> {
    let mut dec = serial::Decoder::<{ serial::MAX_TO_PC }>::new();
    let mut msgs = Vec::new();
    for &b in bytes {
        if let Some(r) = dec.feed::<serial::ToPc>(b) {
            let p = r.unwrap_or_else(|e| panic!("the RC sent a bad frame: {e}"));
            msgs.push(variant(&p.msg));
        }
    }
    msgs
}

/// The RC's session fed an upload of `img` (then render, resend and acknowledgement
/// requests), its frames damaged with probability `pct`%. Every reply must be a valid frame;
/// an intact upload must complete with the image; a resend is served as the firmware does.
fn rc_serial_session(img: &[u8], rng: &mut Rng, input: &mut Vec<u8>, tally: &mut Tally) -> bool {
    use serial::ToRc;
    let pct = *rng.pick(&[0, 0, 5, 20, 60]);
    let crc = CRC32.checksum(img);
    let len = img.len() as u32;
    let mut msgs: Vec<ToRc<'_>> = vec![ToRc::SceneBegin { len, crc }];
    for (k, c) in img.chunks(serial::MAX_CHUNK).enumerate() {
        msgs.push(ToRc::SceneChunk {
            offset: (k * serial::MAX_CHUNK) as u32,
            data: c,
        });
    }
    msgs.push(ToRc::StartRender {
        frames: small_or_edge(rng, 3) as u16,
    });
    for _ in 0..rng.range(0, 3) {
        msgs.push(match rng.below(3) {
            0 => ToRc::Resend {
                frame: small_or_edge(rng, 2) as u16,
                start: small_or_edge(rng, 64),
                len: small_or_edge(rng, 64),
            },
            1 => ToRc::FrameAck {
                frame: small_or_edge(rng, 2) as u16,
            },
            _ => {
                let at = rng.below(img.len());
                let n = rng.below((img.len() - at).min(serial::MAX_CHUNK + 1));
                ToRc::SceneChunk {
                    offset: small_or_edge(rng, len as u64),
                    data: &img[at..at + n],
                }
            }
        });
    }
    let mut line = Vec::new();
    for (seq, m) in msgs.iter().enumerate() {
        let mut f = encode_to_rc(seq as u16, m);
        if rng.chance(pct) {
            mutate_serial(rng, &mut f, serial::MAX_TO_RC);
        }
        line.extend(f);
    }
    input.extend_from_slice(&line);
    // The scene buffer: sometimes too small for the upload.
    let mut store = vec![
        0u8;
        if rng.chance(90) {
            img.len() + 64
        } else {
            img.len() / 2
        }
    ];
    let mut s = Session::new(&mut store);
    let mut replies = Vec::new();
    let mut resends = Vec::new();
    for &b in &line {
        match s.feed(b) {
            Step::Nothing => {}
            Step::Reply(n) => replies.extend_from_slice(s.reply(n)),
            Step::Render { frames } => {
                assert!(frames >= 1);
                assert!(s.upload.image().is_some(), "render without a scene");
                tally.note("serial render requests", 1);
            }
            Step::Resend { frame, start, len } => resends.push((frame, start, len)),
            Step::Acked { .. } => tally.note("serial frame acks", 1),
        }
    }
    let replied = pc_reads(&replies);
    tally.note("serial RC replies", replied.len() as u64);
    let image = s.upload.image().map(|i| i.to_vec());
    if let Some(i) = &image {
        assert_eq!(
            CRC32.checksum(i),
            crc,
            "a completed upload holds what was announced"
        );
        tally.note("serial uploads complete", 1);
    } else {
        assert!(
            pct > 0 || store.len() < img.len(),
            "an intact upload completes: {replied:?}"
        );
    }
    // A resend is served as the firmware does: the RC renders the span of its scene.
    if let (Some(i), Some(&(frame, start, len))) = (&image, resends.first()) {
        let Ok(view) = SceneView::new(i) else {
            return image.is_some();
        };
        let f = view.camera::<f32>();
        if let Ok(fs) = serial::FrameStreamer::new(frame, f.width as u16, f.height as u16) {
            let sent = Sent::default();
            let mut enc = serial::Encoder::new();
            let r = block_on(rc_fw::render::resend_span(
                &fs, i, start, len, &mut enc, &&sent, &mut &sent,
            ));
            // Nothing counted, so the frame is incomplete; every run sent is a valid frame.
            assert!(
                matches!(r, Err(rc_fw::render::RenderFail::Incomplete(_))),
                "{r:?}"
            );
            let got = pc_reads(&sent.0.borrow());
            assert!(got.iter().all(|m| m == "Pixels" || m == "PixelsRle"));
            tally.note("serial resends served", 1);
        }
    }
    image.is_some()
}

/// The messages of a film of `frames` (each `FrameBegin` and its chunks, then its
/// `FrameAck`), with stray film messages mixed in when `stray`.
fn film_messages<'a>(frames: &'a [Vec<u8>], rng: &mut Rng, stray: bool) -> Vec<serial::ToRc<'a>> {
    use serial::ToRc;
    let mut msgs = Vec::new();
    for (k, img) in frames.iter().enumerate() {
        msgs.push(ToRc::FrameBegin {
            frame: k as u16,
            frames: frames.len() as u16,
            len: img.len() as u32,
            crc: CRC32.checksum(img),
        });
        for (c, data) in img.chunks(serial::MAX_CHUNK).enumerate() {
            let offset = (c * serial::MAX_CHUNK) as u32;
            msgs.push(ToRc::SceneChunk { offset, data });
        }
        if stray && rng.chance(30) {
            msgs.push(ToRc::FrameBegin {
                frame: small_or_edge(rng, 4) as u16,
                frames: rng.u32() as u16,
                len: small_or_edge(rng, 1 << 17),
                crc: rng.u32(),
            });
        }
        msgs.push(ToRc::FrameAck { frame: k as u16 });
    }
    msgs
}

/// The RC's session with two banks fed a film (frames `FrameBegin`, chunks, `FrameAck`),
/// frames damaged with probability `pct`%, the cluster finishing each started frame at
/// random moments. Every reply must be a valid frame; a stored frame never waits beside an
/// idle cluster; the two frames held are in different banks; an intact film stores every
/// frame with its bytes, in order.
fn rc_film_session(img: &[u8], rng: &mut Rng, input: &mut Vec<u8>, tally: &mut Tally) -> bool {
    use serial::film::bank_of;
    let pct = *rng.pick(&[0, 0, 5, 20, 60]);
    let frames: Vec<Vec<u8>> = (0..3u8)
        .map(|k| img.iter().map(|&b| b ^ k).collect())
        .collect();
    let mut line = Vec::new();
    for (seq, m) in film_messages(&frames, rng, pct > 0).iter().enumerate() {
        let mut f = encode_to_rc(seq as u16, m);
        if rng.chance(pct) {
            mutate_serial(rng, &mut f, serial::MAX_TO_RC);
        }
        line.extend(f);
    }
    input.extend_from_slice(&line);
    let (mut even, mut odd) = (vec![0u8; img.len() + 64], vec![0u8; img.len() + 64]);
    let mut s = Session::with_banks(&mut even, &mut odd);
    let mut replies = Vec::new();
    let mut started = Vec::new();
    for &b in &line {
        if let Step::Reply(n) = s.feed(b) {
            replies.extend_from_slice(s.reply(n));
        }
        // The cluster: finishes the frame it renders now and then (in an intact film,
        // always before the PC's FrameAck for it arrives).
        if let Some(c) = s.film.current {
            if pct == 0 || rng.chance(10) {
                s.film.rendered(c.frame);
            }
        }
        if let Some((frame, n)) = s.start_next() {
            replies.extend_from_slice(s.reply(n));
            let image = s.bank(bank_of(frame)).image().map(<[u8]>::to_vec);
            started.push((frame, image));
        }
        let f = s.film;
        if let (Some(l), Some(c)) = (f.loading, f.current) {
            assert_ne!(bank_of(l.frame), bank_of(c.frame), "{f:?}");
        }
        assert!(
            !f.loading.is_some_and(|l| l.stored) || f.current.is_some(),
            "a stored frame waits beside an idle cluster: {f:?}"
        );
    }
    let replied = pc_reads(&replies);
    tally.note("serial film RC replies", replied.len() as u64);
    let whole = started.len() == frames.len()
        && started
            .iter()
            .enumerate()
            .all(|(k, (f, i))| *f as usize == k && i.as_deref() == Some(&frames[k][..]));
    if pct == 0 {
        assert!(
            whole,
            "an intact film starts every frame with its bytes: {replied:?}"
        );
        tally.note("serial films complete", 1);
    }
    whole
}

/// The PC's side fed a frame's readback (header, runs, end, progress, upload replies), its
/// frames damaged with probability `pct`%: the frame assembly takes what fits and reports
/// what does not; intact, it holds the frame exactly.
fn pc_serial_session(rng: &mut Rng, input: &mut Vec<u8>, tally: &mut Tally) -> bool {
    use serial::ToPc;
    let pct = *rng.pick(&[0, 0, 5, 20, 60]);
    let (w, h) = (rng.range(1, 24) as u16, rng.range(1, 8) as u16);
    let frame = rng.below(3) as u16;
    let rgb: Vec<u8> = (0..3 * w as usize * h as usize)
        .map(|k| if rng.chance(70) { 9 } else { k as u8 })
        .collect();
    let mut fs = serial::FrameStreamer::new(frame, w, h).expect("small frame");
    let mut enc = serial::Encoder::new();
    let mut out = vec![0u8; serial::MAX_TO_PC];
    let mut frames: Vec<Vec<u8>> = Vec::new();
    let n = fs.header(&mut enc, &mut out).expect("fits");
    frames.push(out[..n].to_vec());
    for y in 0..h {
        let row = &rgb[3 * (y as usize * w as usize)..3 * ((y as usize + 1) * w as usize)];
        let n = fs.run(y, 0, row, &mut enc, &mut out).expect("fits");
        frames.push(out[..n].to_vec());
        if rng.chance(20) {
            let n = fs
                .progress(y as u32 * w as u32, &mut enc, &mut out)
                .expect("fits");
            frames.push(out[..n].to_vec());
        }
    }
    let n = fs.end(&mut enc, &mut out).expect("every pixel counted");
    frames.push(out[..n].to_vec());
    // Other messages a PC may see, with fields at their edges (in damaged sessions: a
    // second header or stray pixels change what the frame holds).
    let extra = if pct > 0 { rng.range(0, 3) } else { 0 };
    for _ in 0..extra {
        let n = rng.below(3 * serial::MAX_RUN);
        let data = rng.bytes(n);
        let m = match rng.below(7) {
            0 => ToPc::Ack {
                offset: small_or_edge(rng, 4096),
            },
            1 => ToPc::FrameHeader {
                frame,
                width: small_or_edge(rng, 64) as u16,
                height: small_or_edge(rng, 64) as u16,
            },
            2 => ToPc::Pixels {
                frame,
                y: small_or_edge(rng, h as u64) as u16,
                x: small_or_edge(rng, w as u64) as u16,
                rgb: &data,
            },
            3 => ToPc::PixelsRle {
                frame,
                y: small_or_edge(rng, h as u64) as u16,
                x: small_or_edge(rng, w as u64) as u16,
                len: small_or_edge(rng, 300) as u16,
                data: &data,
            },
            4 => ToPc::Progress {
                frame,
                done: rng.u32(),
                total: rng.u32(),
            },
            5 => ToPc::FrameStarted {
                frame: small_or_edge(rng, 4) as u16,
            },
            _ => ToPc::Error {
                code: serial::RcError::SceneTooLarge {
                    len: rng.u32(),
                    max: rng.u32(),
                },
            },
        };
        let at = rng.below(frames.len() + 1);
        frames.insert(at, encode_to_pc(rng.u32() as u16, &m));
    }
    let mut line = Vec::new();
    for mut f in frames {
        if pct > 0 && rng.chance(pct) {
            mutate_serial(rng, &mut f, serial::MAX_TO_PC);
        }
        line.extend(f);
    }
    input.extend_from_slice(&line);
    let mut dec = serial::Decoder::<{ serial::MAX_TO_PC }>::new();
    let mut asm: Option<FrameAssembly> = None;
    let mut ended = false;
    for &b in &line {
        let Some(Ok(p)) = dec.feed::<ToPc>(b) else {
            continue;
        };
        match p.msg {
            ToPc::FrameHeader {
                frame: f,
                width,
                height,
            } => {
                if let Ok(a) = FrameAssembly::new(f, width, height) {
                    asm = Some(a);
                }
            }
            ToPc::Pixels { .. } | ToPc::PixelsRle { .. } => {
                let n = serial::pixel_count(&p.msg);
                let mut px = vec![0u8; 3 * n];
                let _ = serial::pixels_into(&p.msg, &mut px);
                if let Some(a) = &mut asm {
                    let _ = a.put(&p.msg);
                }
            }
            ToPc::FrameEnd { .. } => {
                ended = true;
                if let Some(a) = &asm {
                    let _ = a.missing_span();
                }
            }
            _ => {}
        }
    }
    tally.note("serial PC packets decoded", dec.good_packets() as u64);
    let whole = asm
        .as_ref()
        .is_some_and(|a| a.frame == frame && a.missing_span().is_none());
    if pct == 0 {
        let a = asm.expect("the header arrived");
        assert!(ended && whole, "an intact readback is whole");
        assert_eq!(a.rgb, rgb);
        tally.note("serial readbacks complete", 1);
    }
    whole
}

#[test]
fn serial() {
    let mut images = small_images(2);
    let t = fuzz("serial", &mut images, |images, rng, input, tally| {
        let ok = if rng.chance(35) {
            let img = images[rng.below(images.len())].clone();
            rc_serial_session(&img, rng, input, tally)
        } else if rng.chance(40) {
            let img = images[rng.below(images.len())].clone();
            rc_film_session(&img, rng, input, tally)
        } else {
            pc_serial_session(rng, input, tally)
        };
        if ok {
            Verdict::Accepted
        } else {
            Verdict::Rejected("incomplete".into())
        }
    });
    if t.tried >= 100 {
        assert!(t
            .notes
            .get("serial uploads complete")
            .is_some_and(|&n| n > 0));
        assert!(t
            .notes
            .get("serial readbacks complete")
            .is_some_and(|&n| n > 0));
        assert!(t.notes.get("serial films complete").is_some_and(|&n| n > 0));
    }
}

// ---------------------------------------------------------------------------------------
// Target: backup
// ---------------------------------------------------------------------------------------

/// A valid RC frame for node `addr` (or broadcast), of a random kind.
fn backup_rc_frame(rng: &mut Rng, addr: u8, scene: &[u8], ack: u16) -> Vec<u8> {
    let mut buf = [0u8; backup::MAX_FRAME];
    let at = rng.below(scene.len().div_ceil(backup::SCENE_DATA).max(1)) * backup::SCENE_DATA;
    let end = (at + backup::SCENE_DATA).min(scene.len());
    let msg = match rng.below(4) {
        0 => backup::Msg::RollCall,
        1 => backup::Msg::Scene {
            frame: 1,
            offset: at as u32,
            total: scene.len() as u32,
            crc: links_core::wire::CRC32.checksum(scene),
            data: &scene[at.min(end)..end],
        },
        2 => backup::Msg::Work {
            job: links_core::wire::Job {
                id: rng.u32(),
                frame: 1,
                region: links_core::wire::Region::Span {
                    start: rng.u32() % 4096,
                    len: 1 + rng.u32() % 512,
                },
            },
        },
        _ => backup::Msg::Poll { ack },
    };
    let n = backup::encode(addr, &msg, &mut buf).expect("a valid message fits");
    buf[..n].to_vec()
}

/// Mutate a frame; most of the time fix its length byte and CRC so the body is reached.
fn backup_mutate(rng: &mut Rng, f: &mut Vec<u8>) {
    mutate_bytes(rng, f, backup::MAX_FRAME + 8);
    if rng.chance(70) && f.len() >= backup::FRAME_OVERHEAD {
        f[0] = backup::SYNC;
        let body = (f.len() - backup::FRAME_OVERHEAD).min(backup::MAX_BODY);
        f.truncate(body + backup::FRAME_OVERHEAD);
        f[2] = body as u8;
        let crc = links_core::wire::CRC32.checksum(&f[1..3 + body]);
        f[3 + body..].copy_from_slice(&crc.to_le_bytes());
    }
}

/// One conversation: valid and mutated RC frames through a node's frame reader into its
/// state machine, every reply checked, then the node's replies mutated into a roll call.
fn backup_conversation(rng: &mut Rng, input: &mut Vec<u8>, tally: &mut Tally) -> bool {
    let len = rng.range(1, 600) as usize;
    let scene: Vec<u8> = rng.bytes(len);
    let mut bank = vec![0u8; 512];
    let mut node = backup::BackupNode::new(3, &mut bank);
    let mut reader = backup::FrameReader::new();
    let mut reply = [0u8; backup::MAX_FRAME];
    let mut replies = Vec::new();
    let mut ack = 0u16;
    for _ in 0..rng.range(1, 12) {
        let addr = *rng.pick(&[3, 3, 3, 4, backup::BROADCAST]);
        let mut f = backup_rc_frame(rng, addr, &scene, ack);
        if rng.chance(60) {
            backup_mutate(rng, &mut f);
        }
        input.extend_from_slice(&f);
        // A direct decode agrees with re-encoding.
        if let Ok((a, m)) = backup::decode(&f) {
            let mut again = [0u8; backup::MAX_FRAME];
            let n = backup::encode(a, &m, &mut again).expect("a decoded message re-encodes");
            assert_eq!(backup::decode(&again[..n]), Ok((a, m)));
            tally.note("backup frames decoded", 1);
        }
        for &b in &f {
            let Some(n) = reader.push(b) else { continue };
            if let Ok(Some(r)) = node.handle(reader.frame(n), &mut reply) {
                let (from, m) = backup::decode(&reply[..r]).expect("a node's reply decodes");
                assert_eq!(from, 3);
                if let backup::Msg::Pixels { .. } = m {
                    ack = ack.wrapping_add(1);
                }
                replies.push(reply[..r].to_vec());
            }
        }
        if let Some(job) = node.take_job() {
            let n = 3 * rng.range(1, 40) as usize;
            let rgb = rng.bytes(n);
            let _ = node.push_pixels(&job, 0, 0, &rgb, true);
        }
    }
    if let Some((_, s)) = node.scene.ready() {
        assert_eq!(s, &scene[..], "a CRC-checked scene is the one sent");
        tally.note("backup scenes complete", 1);
    }
    // The node's replies, some mutated, as answers to a roll call of node 3.
    let mut present = false;
    for mut r in replies.into_iter().take(3) {
        if rng.chance(50) {
            backup_mutate(rng, &mut r);
        }
        let mut rc = backup::RollCall::new(3);
        let _ = (rc.answered(None), rc.answered(None));
        let res = rc.answered(Some(&r));
        let found = rc.absent().count() == 2;
        assert_eq!(found, rc.health(3).is_some());
        assert!(!found || res.is_ok());
        present |= found;
    }
    present
}

#[test]
fn backup() {
    let t = fuzz("backup", &mut (), |_, rng, input, tally| {
        if backup_conversation(rng, input, tally) {
            Verdict::Accepted
        } else {
            Verdict::Rejected("no roll-call answer".into())
        }
    });
    if t.tried >= 100 {
        assert!(t.notes.get("backup frames decoded").is_some_and(|&n| n > 0));
    }
}

// ---------------------------------------------------------------------------------------
// Target: relay (the relay link's batches and the relay's logic)
// ---------------------------------------------------------------------------------------

/// A valid relay-link frame: a forwarded broadcast, or a batch of requests and frames for
/// nodes 0..4 (some beyond the relay's three), data cut from the corpus.
fn relay_frame(rng: &mut Rng, corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_MESSAGE];
    if rng.chance(20) {
        let body = rng.pick(corpus);
        let body = &body[..body.len().min(MAX_MESSAGE - 1)];
        let n = relay::forward(body, &mut buf).expect("fits");
        buf.truncate(n);
        return buf;
    }
    let mut w = relay::BatchWriter::new(&mut buf).expect("room");
    w.set_waiting(rng.u32() & 0xf);
    for _ in 0..rng.below(4) {
        let src = rng.pick(corpus);
        let take = rng.below(src.len() + 1).min(w.room());
        let kind = match rng.below(10) {
            0..=5 => relay::Kind::Request,
            6..=7 => relay::Kind::Ahead,
            _ => relay::Kind::Frame,
        };
        let rec = relay::Record {
            kind,
            node: rng.below(5) as u16,
            data: &src[..take],
        };
        if w.push(rec).is_err() {
            break;
        }
    }
    w.bytes().to_vec()
}

/// Decode one frame: records stay inside it, and re-encoding what decoded gives back the
/// bytes it came from.
fn check_relay_bytes(bytes: &[u8], tally: &mut Tally) -> Verdict {
    match relay::parse(bytes) {
        Err(e) => Verdict::Rejected(variant(&e)),
        Ok(relay::Relayed::Forward(f)) => {
            assert_eq!(f, &bytes[1..]);
            *tally.notes.entry("forwards").or_default() += 1;
            Verdict::Accepted
        }
        Ok(relay::Relayed::Batch { waiting, records }) => {
            let mut buf = vec![0u8; MAX_MESSAGE];
            let mut w = relay::BatchWriter::new(&mut buf).expect("room");
            w.set_waiting(waiting);
            let mut bad = None;
            for r in records {
                match r {
                    Ok(rec) => w.push(rec).expect("what decoded from a frame fits one"),
                    Err(e) => bad = Some(variant(&e)),
                }
            }
            let n = w.bytes().len();
            assert_eq!(w.bytes(), &bytes[..n], "re-encoded records are the input");
            *tally.notes.entry("records").or_default() += w.records() as u64;
            match bad {
                Some(why) => Verdict::Rejected(why),
                None => {
                    assert_eq!(n, bytes.len(), "a clean batch is consumed whole");
                    Verdict::Accepted
                }
            }
        }
    }
}

/// The relay's parent, scripted: delivers the frames of `script` in turn (odd ones as
/// exchanges, which the relay answers by its next post).
struct ScriptParent {
    script: VecDeque<(bool, Vec<u8>)>,
    posts: u32,
}

impl NodeLink for ScriptParent {
    fn post(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        assert!(frame.len() <= MAX_MESSAGE, "the relay posts a link frame");
        assert!(
            matches!(relay::parse(frame), Ok(relay::Relayed::Batch { .. })),
            "the relay posts batches"
        );
        self.posts += 1;
        Ok(())
    }
    async fn recv(&mut self, rx: &mut [u8]) -> Result<Incoming, LinkError> {
        match self.script.pop_front() {
            Some((exchanged, f)) => {
                let n = f.len().min(rx.len());
                rx[..n].copy_from_slice(&f[..n]);
                Ok(if exchanged {
                    Incoming::Exchanged { len: n }
                } else {
                    Incoming::Broadcast { len: n }
                })
            }
            None => core::future::pending().await,
        }
    }
}

/// The relay's bus, scripted: three nodes whose lines are up, each exchange answered with
/// a corpus frame.
struct RelayBus {
    tx: Vec<u8>,
    started: Option<(Transfer, usize)>,
    answer: Vec<u8>,
    exchanges: u32,
}

impl RootBus for RelayBus {
    fn nodes(&self) -> (NodeId, u16) {
        (0, 3)
    }
    async fn wait_ready(&mut self) -> NodeId {
        0
    }
    fn ready(&self) -> Option<NodeId> {
        Some(0)
    }
    fn line(&self, node: NodeId) -> bool {
        node < 3
    }
    fn tx_bank(&mut self) -> &mut [u8] {
        &mut self.tx
    }
    fn start(&mut self, transfer: Transfer, len: usize) -> Result<(), LinkError> {
        assert!(self.started.is_none() && len <= MAX_MESSAGE);
        if let Transfer::Exchange(node) = transfer {
            assert!(node < 3, "the relay clocks only its own nodes");
        }
        self.started = Some((transfer, len));
        Ok(())
    }
    async fn finish(&mut self, rx: &mut [u8]) -> Result<usize, LinkError> {
        let (transfer, _) = self.started.take().ok_or(LinkError::Aborted)?;
        match transfer {
            Transfer::Broadcast => Ok(0),
            Transfer::Exchange(_) => {
                self.exchanges += 1;
                let n = self.answer.len().min(rx.len());
                rx[..n].copy_from_slice(&self.answer[..n]);
                Ok(n)
            }
        }
    }
}

/// Run the relay over a mutated conversation until it waits for more; it must never panic,
/// clock only its nodes, and clock no more exchanges than it was sent requests.
fn relay_session(
    rng: &mut Rng,
    corpus: &[Vec<u8>],
    input: &mut Vec<u8>,
    tally: &mut Tally,
) -> Verdict {
    let mut script = VecDeque::new();
    let mut requests = 0u32;
    for _ in 0..1 + rng.below(6) {
        let mut f = relay_frame(rng, corpus);
        if rng.chance(60) {
            mutate_bytes(rng, &mut f, MAX_MESSAGE);
        }
        if let Ok(relay::Relayed::Batch { records, .. }) = relay::parse(&f) {
            requests += records.filter(|r| r.is_ok()).count() as u32;
        }
        input.extend_from_slice(&(f.len() as u16).to_le_bytes());
        input.extend_from_slice(&f);
        script.push_back((rng.chance(70), f));
    }
    let mut parent = ScriptParent { script, posts: 0 };
    let mut bus = RelayBus {
        tx: vec![0; MAX_MESSAGE],
        started: None,
        answer: rng.pick(corpus).clone(),
        exchanges: 0,
    };
    let mut bufs = ([0u8; MAX_MESSAGE], [0u8; MAX_MESSAGE], [0u8; MAX_MESSAGE]);
    // A cell per node for replies held ahead (`Kind::Ahead` records).
    let mut cells = [[0u8; relay::REPLY_CELL]; 8];
    let report = {
        let buffers = relay::RelayBuffers {
            down: &mut bufs.0,
            up: &mut bufs.1,
            node: &mut bufs.2,
            ahead: &mut cells,
        };
        let fut = relay::run_relay(&mut parent, &mut bus, buffers);
        let mut fut = pin!(fut);
        let mut cx = Context::from_waker(Waker::noop());
        let mut out = None;
        for _ in 0..64 {
            if let Poll::Ready(r) = fut.as_mut().poll(&mut cx) {
                out = Some(r);
                break;
            }
        }
        out
    };
    assert!(
        bus.exchanges <= requests,
        "{} exchanges for {requests} requests",
        bus.exchanges
    );
    *tally.notes.entry("relay exchanges").or_default() += bus.exchanges as u64;
    match report {
        Some(Ok(r)) => {
            assert_eq!(r.routed, bus.exchanges);
            *tally.notes.entry("stopped").or_default() += 1;
            Verdict::Accepted
        }
        Some(Err(e)) => Verdict::Rejected(variant(&e)),
        None if bus.exchanges > 0 => Verdict::Accepted,
        None => Verdict::Rejected("nothing routed".into()),
    }
}

// ---------------------------------------------------------------------------------------
// Target: backup_rc
// ---------------------------------------------------------------------------------------

/// The RC's side of the backup line ([`backup::BackupRc`]) against a node that answers with
/// valid, mutated and foreign frames: the RC's pixel-chunk decoder (run-length expansion in
/// parts into the work) never panics, hands the work only whole pixels inside the chunk it
/// decoded, and takes a chunk only once every part was taken.
struct FuzzLine<'r> {
    rng: &'r mut Rng,
    input: &'r mut Vec<u8>,
}

impl backup::RcLine for FuzzLine<'_> {
    type Error = backup::BackupError;
    async fn exchange(
        &mut self,
        to: u8,
        buf: &mut [u8; backup::MAX_FRAME],
        len: usize,
    ) -> Result<Option<usize>, backup::BackupError> {
        let (ack, work) = match backup::decode(&buf[..len]) {
            Ok((_, backup::Msg::Poll { ack })) => (ack, false),
            Ok((_, backup::Msg::Work { .. })) => (0, true),
            _ => (self.rng.u32() as u16, false),
        };
        if self.rng.chance(10) {
            return Ok(None);
        }
        let mut f = if work && self.rng.chance(80) {
            let mut b = [0u8; backup::MAX_FRAME];
            let n = backup::encode(to, &backup::Msg::Ack, &mut b).expect("an ack fits");
            b[..n].to_vec()
        } else {
            backup_node_reply(self.rng, to, ack)
        };
        if self.rng.chance(40) {
            backup_mutate(self.rng, &mut f);
        }
        self.input.extend_from_slice(&f);
        let n = f.len().min(backup::MAX_FRAME);
        buf[..n].copy_from_slice(&f[..n]);
        Ok(Some(n))
    }
}

/// A node's answer: mostly a pixel chunk of job 7 at sequence `ack` whose runs add up to
/// its length (sometimes not), else another message.
fn backup_node_reply(rng: &mut Rng, addr: u8, ack: u16) -> Vec<u8> {
    let mut rle = Vec::new();
    let mut len = 0u32;
    // Mostly short runs (a chunk inside the 64-pixel row), sometimes up to 56 of 256.
    let (runs, longest) = if rng.chance(70) { (12, 8) } else { (56, 256) };
    for _ in 0..rng.range(0, runs) {
        let count = rng.below(longest) as u8;
        len += count as u32 + 1;
        rle.push(count);
        rle.extend_from_slice(&rng.bytes(3));
    }
    let msg = match rng.below(6) {
        0 => backup::Msg::Idle,
        1 => backup::Msg::Ack,
        _ => backup::Msg::Pixels {
            seq: if rng.chance(85) {
                ack
            } else {
                rng.u32() as u16
            },
            job: if rng.chance(90) { 7 } else { rng.u32() },
            frame: 0,
            y: small_or_edge(rng, 20) as u16,
            x: small_or_edge(rng, 80) as u16,
            len: if rng.chance(85) {
                len as u16
            } else {
                rng.u32() as u16
            },
            done: rng.chance(20),
            rle: &rle,
        },
    };
    let mut buf = [0u8; backup::MAX_FRAME];
    let n = backup::encode(addr, &msg, &mut buf).expect("a valid message fits");
    buf[..n].to_vec()
}

/// The work: job 7 for node 3, a 64 x 16 frame; refuses runs outside it.
#[derive(Default)]
struct FuzzWork {
    taken_px: u64,
    parts: Vec<(u16, u16, usize)>,
    lost: bool,
}

impl backup::BackupWork for FuzzWork {
    fn assign(&mut self, addr: u8) -> Option<links_core::wire::Job> {
        assert_eq!(addr, 3);
        Some(links_core::wire::Job {
            id: 7,
            frame: 0,
            region: links_core::wire::Region::Span {
                start: 0,
                len: 1024,
            },
        })
    }
    fn missing_scene(&self, _: u8) -> Option<u16> {
        None
    }
    fn scene(&self, _: u16) -> Option<&[u8]> {
        None
    }
    fn scene_ready(&mut self, _: u8, _: u16) {}
    fn pixels(&mut self, addr: u8, job: u32, y: u16, x: u16, rgb: &[u8], _: bool) -> bool {
        assert_eq!((addr, job), (3, 7));
        assert!(!rgb.is_empty() && rgb.len().is_multiple_of(3));
        self.parts.push((y, x, rgb.len() / 3));
        let ok = y < 16 && x as usize + rgb.len() / 3 <= 64;
        if ok {
            self.taken_px += (rgb.len() / 3) as u64;
        }
        ok
    }
    fn lost(&mut self, _: u8) {
        self.lost = true;
    }
}

#[test]
fn relay() {
    let mut rng0 = Rng(11);
    let data = rng0.bytes(3 * MAX_RUN);
    let mut corpus: Vec<Vec<u8>> = (0..32)
        .map(|k| {
            if k % 2 == 0 {
                wire_frame(k, 0, &some_down(&mut rng0, &data, 16, 16))
            } else {
                wire_frame(k, 0, &some_up(&mut rng0, &data, 16, 16))
            }
        })
        .collect();
    corpus.push(wire_frame(0, 0, &Down::Stop));
    corpus.retain(|f| f.len() <= relay::MAX_ROUTED);
    fuzz("relay", &mut corpus, |corpus, rng, input, tally| {
        if rng.chance(50) {
            let mut f = relay_frame(rng, corpus);
            mutate_bytes(rng, &mut f, MAX_MESSAGE);
            input.extend_from_slice(&f);
            check_relay_bytes(&f, tally)
        } else {
            relay_session(rng, corpus, input, tally)
        }
    });
}

#[test]
fn backup_rc() {
    let t = fuzz("backup_rc", &mut (), |_, rng, input, tally| {
        let mut rc = backup::BackupRc::<2>::new();
        assert_eq!(rc.serve(3), Some(0));
        let mut work = FuzzWork::default();
        let mut rgb = vec![0u8; 3 * rng.range(1, 40) as usize];
        let mut line = FuzzLine { rng, input };
        let mut chunks = 0;
        for _ in 0..12 {
            let turn = embassy_futures::block_on(rc.turn(0, &mut line, &mut work, &mut rgb))
                .expect("the fuzz line never fails");
            if let backup::Turn::Pixels { len, .. } = turn {
                chunks += 1;
                tally.note("backup chunks taken", 1);
                assert!(len > 0);
            }
            if turn == backup::Turn::Lost {
                assert!(work.lost);
                break;
            }
        }
        // The RC counts a chunk's pixels only when the work took every part of it; no part
        // is longer than the RC's buffer.
        assert!(rc.counters.pixels <= work.taken_px);
        assert!(work.parts.iter().all(|p| p.2 <= rgb.len() / 3));
        if chunks > 0 {
            Verdict::Accepted
        } else {
            Verdict::Rejected("no chunk taken".into())
        }
    });
    if t.tried >= 100 {
        assert!(t.notes.get("backup chunks taken").is_some_and(|&n| n > 0));
    }
}
