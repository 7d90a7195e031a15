//! The QEMU bench's outputs: the samples CSV (one [`Sample`] row per frame, the cost model's
//! input) and the Markdown tables of `docs/cortex-m-bench.md`.

use crate::run_log::{Run, RunLog};
use links_host::cost::Sample;
use std::collections::HashMap;
use std::fmt::Write as _;

/// The doc's text before the tables (through the line before the toolchain's).
const HEAD: &str = include_str!("bench_head.md");
/// The doc's text after the tables, before the profile.
const PROFILE_INTRO: &str = include_str!("bench_profile_intro.md");
/// The doc's text after the profile.
const TAIL: &str = include_str!("bench_tail.md");

/// The backends, in the tables' order.
const BACKENDS: [&str; 3] = links_host::studies::backend::Backend::NAMES;
const M4: &str = "thumbv7em-none-eabihf";
const M3: &str = "thumbv7m-none-eabi";

/// The scenes in the tables' order, with what each is.
const SCENES: [(&str, &str); 11] = [
    ("photo1", "photo1 (shadows, reflections to depth 4)"),
    (
        "photo1-d0",
        "photo1, max depth 0 (primary rays + shading + shadows)",
    ),
    (
        "photo1-noshadow",
        "photo1, max depth 0, --no-shadows (primary rays + shading)",
    ),
    (
        "photo1-nolights",
        "photo1, max depth 0, no lights (primary rays + ambient only)",
    ),
    (
        "photo1-16",
        "photo1, smaller (shadows, reflections to depth 4)",
    ),
    ("ellipsoids", "ellipsoids"),
    ("metaballs", "metaballs"),
    ("reflections", "reflections"),
    ("glass", "glass"),
    ("photo2", "photo2"),
    ("photo2-noshadow", "photo2, --no-shadows"),
];

/// A target's long name, short name and what f32 is on it.
fn target_names(t: &str) -> (&'static str, &'static str, &'static str) {
    match t {
        "thumbv7em-none-eabihf" => ("M4F (thumbv7em-none-eabihf)", "M4F", "hard-float"),
        "thumbv7m-none-eabi" => ("M3 (thumbv7m-none-eabi)", "M3", "soft-float"),
        "thumbv6m-none-eabi" => ("M0 ISA (thumbv6m-none-eabi)", "M0 ISA", "soft-float"),
        _ => ("?", "?", "?"),
    }
}
fn name(t: &str) -> &'static str {
    target_names(t).0
}
fn short(t: &str) -> &'static str {
    target_names(t).1
}
fn fl(t: &str) -> &'static str {
    target_names(t).2
}

/// The CSV: the header and every run of every target, in order.
pub fn csv(logs: &[(String, RunLog)]) -> String {
    let mut out = Sample::csv_head() + "\n";
    for (_, log) in logs {
        for r in &log.runs {
            out += &r.sample.csv_line();
            out.push('\n');
        }
    }
    out
}

/// Thousands separators on a number's text.
fn commas(s: &str) -> String {
    let (neg, digits) = match s.strip_prefix('-') {
        Some(d) => ("-", d),
        None => ("", s),
    };
    let mut groups = Vec::new();
    let mut rest = digits;
    while rest.len() > 3 {
        groups.push(&rest[rest.len() - 3..]);
        rest = &rest[..rest.len() - 3];
    }
    groups.push(rest);
    groups.reverse();
    format!("{neg}{}", groups.join(","))
}
fn f0(x: f64) -> String {
    commas(&format!("{x:.0}"))
}
fn f1(x: f64) -> String {
    let s = format!("{x:.1}");
    let (int, frac) = s.split_at(s.find('.').unwrap_or(s.len()));
    commas(int) + frac
}
fn pct(x: f64, tot: f64) -> String {
    format!("{} ({:.0}%)", f0(x), 100.0 * x / tot)
}

/// The measurements the tables read: the `all` frames and the single operations.
struct Data<'a> {
    targets: Vec<&'a str>,
    frames: HashMap<(&'a str, &'a str, &'a str), &'a Run>,
    ops: HashMap<(&'a str, &'a str, &'a str), f64>,
    op_order: Vec<&'a str>,
}

impl<'a> Data<'a> {
    fn new(logs: &'a [(String, RunLog)]) -> Self {
        let mut d = Data {
            targets: logs.iter().map(|(t, _)| t.as_str()).collect(),
            frames: HashMap::new(),
            ops: HashMap::new(),
            op_order: Vec::new(),
        };
        for (t, log) in logs {
            for r in log.runs.iter().filter(|r| r.sample.techniques == "all") {
                let s = &r.sample;
                d.frames
                    .insert((t.as_str(), s.backend.as_str(), s.scene.as_str()), r);
            }
            for o in &log.ops {
                if !d.op_order.contains(&o.key.as_str()) {
                    d.op_order.push(&o.key);
                }
                d.ops
                    .insert((t.as_str(), o.backend.as_str(), o.key.as_str()), o.per_op);
            }
        }
        d
    }
    fn frame(&self, t: &str, b: &str, s: &str) -> Option<&'a Run> {
        self.frames.get(&(t, b, s)).copied()
    }
    /// Instructions per pixel of scene `s` on target `t` in backend `b`.
    fn ipp(&self, t: &str, b: &str, s: &str) -> Option<f64> {
        self.frame(t, b, s)
            .map(|r| r.sample.instructions as f64 / r.sample.pixels as f64)
    }
    /// A single operation's cost (0 when not measured, as the tables always read it).
    fn op(&self, t: &str, b: &str, o: &str) -> Option<f64> {
        self.ops.get(&(t, b, o)).copied()
    }
}

/// The Markdown document; `toolchain` is the toolchain line's text, `profile` the
/// `scripts/qemu-profile --markdown` section (None leaves it out, as `--no-doc` does).
pub fn markdown(logs: &[(String, RunLog)], toolchain: &str, profile: Option<&str>) -> String {
    let d = Data::new(logs);
    let nrows: usize = logs.iter().map(|(_, l)| l.runs.len()).sum();
    let mut o = String::from(HEAD);
    let _ = writeln!(o, "Toolchain: {toolchain}.");
    by_backend(&mut o, &d);
    whole_frames(&mut o, &d, nrows);
    photo1(&mut o, &d);
    single_ops(&mut o, &d);
    model_check(&mut o, &d);
    o += PROFILE_INTRO;
    if let Some(p) = profile {
        o += p;
    }
    o += TAIL;
    o
}

fn by_backend(o: &mut String, d: &Data) {
    o.push_str("\n## Instructions per pixel by backend (all techniques)\n\n");
    let (mut h, mut l) = (String::from("| scene"), String::from("|---"));
    for t in &d.targets {
        for b in BACKENDS {
            let what = if b == "f32" {
                format!("{} f32", fl(t))
            } else {
                b.into()
            };
            let _ = write!(h, " | {} {what}", short(t));
            l += "|---";
        }
    }
    let _ = writeln!(o, "{h} |\n{l}|");
    for (s, _) in SCENES {
        let (w, hh) = d
            .frame(M4, "f32", s)
            .map_or((0, 0), |r| (r.width, r.height));
        let mut line = format!("| {s} ({w}x{hh})");
        for t in &d.targets {
            for b in BACKENDS {
                let v = d.ipp(t, b, s).map_or("-".into(), f0);
                let _ = write!(line, " | {v}");
            }
        }
        let _ = writeln!(o, "{line} |");
    }
    o.push_str(
        "\nFixed point against f32 (instructions per pixel, all scenes above summed per target):\n\n",
    );
    for t in &d.targets {
        let sum = |b| -> f64 {
            SCENES
                .iter()
                .map(|(s, _)| d.ipp(t, b, s).unwrap_or(0.0))
                .sum()
        };
        let (tf, tq, tfast) = (sum("f32"), sum("q16.16"), sum("f32-fast"));
        let _ = writeln!(
            o,
            "- {}: q16.16 takes {:.2} times the instructions of {} f32; f32-fast {:.3} times.",
            name(t),
            tq / tf,
            fl(t),
            tfast / tf
        );
    }
}

fn whole_frames(o: &mut String, d: &Data, nrows: usize) {
    o.push_str("\n## Whole frames (render_run per scanline)\n\n");
    o.push_str("| target | backend | scene | pixels | instructions/pixel | rays/pixel | instructions/ray | box tests/pixel | primitive tests/pixel | pixels equal host |\n");
    o.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
    for t in &d.targets {
        for b in BACKENDS {
            for (s, what) in SCENES {
                let Some(r) = d.frame(t, b, s) else { continue };
                let st = &r.sample.stats;
                let np = r.sample.pixels;
                let (npf, ins, rays) = (np as f64, r.sample.instructions as f64, st.rays() as f64);
                let prim =
                    (st.triangle_tests + st.ellipsoid_tests + st.box_shape_tests + st.blob_tests)
                        as f64;
                let backend = if b == "f32" {
                    format!("{b} {}", fl(t))
                } else {
                    b.into()
                };
                let _ = writeln!(
                    o,
                    "| {} | {backend} | {what} ({}x{}) | {np} | **{}** | {:.2} | {} | {:.1} | {:.1} | {}/{np} |",
                    name(t),
                    r.width,
                    r.height,
                    f0(ins / npf),
                    rays / npf,
                    f0(ins / rays),
                    st.box_tests as f64 / npf,
                    prim / npf,
                    np - r.mismatched,
                );
            }
        }
    }
    o.push_str(
        include_str!("bench_frames_note.md")
            .replace("{nrows}", &nrows.to_string())
            .as_str(),
    );
}

fn photo1(o: &mut String, d: &Data) {
    o.push_str(include_str!("bench_photo1_intro.md"));
    let mut p: HashMap<(&str, &str), (f64, f64)> = HashMap::new();
    for t in &d.targets {
        for b in BACKENDS {
            let full = d.ipp(t, b, "photo1");
            let nl = d.ipp(t, b, "photo1-nolights");
            let (Some(d0), Some(ns0)) = (d.ipp(t, b, "photo1-d0"), d.ipp(t, b, "photo1-noshadow"))
            else {
                continue;
            };
            p.insert((t, b), (d0, ns0));
            let what = if b == "f32" {
                format!("{} f32", fl(t))
            } else {
                b.into()
            };
            let _ = writeln!(
                o,
                "| {} {what} | {} | **{}** | **{}** | {} | {} | {} |",
                short(t),
                full.map_or("-".into(), f0),
                f0(d0),
                f0(ns0),
                nl.map_or("-".into(), f0),
                f0(d0 - ns0),
                nl.map_or("-".into(), |nl| f0(ns0 - nl)),
            );
        }
    }
    let per_pixel = |s: &str, f: fn(&Run) -> u64| {
        d.frame(M4, "f32", s).map_or(f64::NAN, |r| {
            f(r) as f64
                / d.frame(M4, "f32", "photo1-d0")
                    .map_or(f64::NAN, |r| r.sample.pixels as f64)
        })
    };
    let _ = writeln!(
        o,
        "\nShadow rays: {:.2} per pixel; eq. 2.1 for both lights at {:.2} shaded points per pixel (f32 counts).",
        per_pixel("photo1-d0", |r| r.sample.stats.shadow_rays),
        per_pixel("photo1-noshadow", |r| r.sample.stats.shadings),
    );
    o.push_str("\nThe speed target's numbers, as one list (instructions per pixel, primary rays + shading,\nthen with shadows):\n\n");
    let get = |t, b| p.get(&(t, b)).copied().unwrap_or((0.0, 0.0));
    for (label, t, b) in [
        ("Cortex-M4F hard-float f32", M4, "f32"),
        ("Cortex-M3 soft-float f32", M3, "f32"),
        ("fixed point (Q16.16) on the Cortex-M4F", M4, "q16.16"),
        ("fixed point (Q16.16) on the Cortex-M3", M3, "q16.16"),
    ] {
        let (d0, ns) = get(t, b);
        let _ = writeln!(o, "- {label}: **{}**, with shadows **{}**", f0(ns), f0(d0));
    }
    let (d0, ns0) = get(M4, "f32");
    let verdict = |v: f64, target: f64| {
        if v > target {
            format!("not met: {}, {:.2} times the target", f0(v), v / target)
        } else {
            format!("met: {}", f0(v))
        }
    };
    let _ = writeln!(
        o,
        "\nSpeed targets on the M4F, f32, all techniques: photo1 primary + shading (`--max-depth 0 --no-shadows`) <= 800 instructions/pixel: {}; with shadows (`--max-depth 0`) <= 3,000: {}.",
        verdict(ns0, 800.0),
        verdict(d0, 3000.0)
    );
}

fn single_ops(o: &mut String, d: &Data) {
    o.push_str(include_str!("bench_ops_intro.md"));
    let (mut h, mut l) = (
        String::from("| operation (instructions per call) | backend"),
        String::from("|---|---"),
    );
    for t in &d.targets {
        let _ = write!(h, " | {}", name(t));
        l += "|---";
    }
    let _ = writeln!(o, "{h} |\n{l}|");
    for b in BACKENDS {
        for op in &d.op_order {
            if !d.targets.iter().any(|t| d.op(t, b, op).is_some()) {
                continue;
            }
            let mut line = format!("| {op} | {b}");
            for t in &d.targets {
                let v = d.op(t, b, op).map_or("- (no FPU)".into(), f1);
                let _ = write!(line, " | {v}");
            }
            let _ = writeln!(o, "{line} |");
        }
    }
    let m4 = |op| d.op(M4, "f32", op);
    if let (Some(sq), Some(sw), Some(hw)) = (
        m4("Real::sqrt_f32"),
        m4("libm::sqrtf"),
        m4("vsqrt.f32_inline_asm"),
    ) {
        let what = if sq > 2.0 * hw + 5.0 {
            "it is a software routine, not the FPU's square root."
        } else {
            "it is the FPU's square root, inlined (VMOV in, VSQRT.F32, VMOV out); on a real M4F VSQRT.F32 itself takes 14 cycles."
        };
        let _ = writeln!(o, "\nOn the M4F, `Real::sqrt` for f32 costs {} instructions per call against {} for the bare VSQRT.F32 and {} for libm's software `sqrtf`: {what}", f1(sq), f1(hw), f1(sw));
    }
}

/// Per target and backend (not f32-fast), photo1's instructions per pixel split into box
/// tests, triangle tests, box-shape tests and the rest, with the total.
fn model_check(o: &mut String, d: &Data) {
    o.push_str(include_str!("bench_model_intro.md"));
    let (mut h, mut l) = (String::from("| per pixel"), String::from("|---"));
    let mut cols = Vec::new();
    for b in BACKENDS.into_iter().filter(|b| *b != "f32-fast") {
        for t in &d.targets {
            let _ = write!(h, " | {} {b}", short(t));
            l += "|---";
            if let Some(r) = d.frame(t, b, "photo1") {
                let (st, p) = (&r.sample.stats, r.sample.pixels as f64);
                let op = |name| d.op(t, b, name).unwrap_or(0.0);
                let cb = st.box_tests as f64 * op("node_decode+aabb_hit") / p;
                let ct = st.triangle_tests as f64 * op("triangle_decode+intersect") / p;
                let cx = st.box_shape_tests as f64 * op("boxshape_decode+intersect") / p;
                let tot = r.sample.instructions as f64 / p;
                cols.push([cb, ct, cx, tot - cb - ct - cx, tot]);
            }
        }
    }
    let _ = writeln!(o, "{h} |\n{l}|");
    let (m4, p) = match d.frame(M4, "f32", "photo1") {
        Some(r) => (r.sample.stats, r.sample.pixels as f64),
        None => (Default::default(), f64::NAN),
    };
    let mut rows = [
        format!(
            "| box tests ({:.1} per pixel) x node decode + slab test",
            m4.box_tests as f64 / p
        ),
        format!(
            "| triangle tests ({:.1}) x decode + test",
            m4.triangle_tests as f64 / p
        ),
        format!(
            "| box-shape tests ({:.1}) x decode + test",
            m4.box_shape_tests as f64 / p
        ),
        "| everything else".into(),
        "| measured total".into(),
    ];
    for c in &cols {
        for (k, row) in rows.iter_mut().enumerate() {
            let cell = if k == 4 { f0(c[4]) } else { pct(c[k], c[4]) };
            let _ = write!(row, " | {cell}");
        }
    }
    for row in rows {
        let _ = writeln!(o, "{row} |");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_formatted_as_the_doc_has_them() {
        assert_eq!(f0(1234567.5), "1,234,568");
        assert_eq!(f0(-1234.0), "-1,234");
        assert_eq!(f0(999.4), "999");
        assert_eq!(f1(12345.25), "12,345.2");
        assert_eq!(pct(25.0, 100.0), "25 (25%)");
    }
}
