//! What every QEMU bench run must show before its numbers are reported: the benchmark
//! finished, its pixels and counts equal the host's, it rendered exactly the frames asked
//! for, the instruction clock is calibrated, the scene variants are what they claim, and
//! every target rendered the same pixels.

use crate::run_log::{Run, RunLog};
use crate::BenchError;
use std::collections::BTreeMap;

/// Most a loop of known length may differ from its expected count (ticks x 40 quantises).
const CAL_TOLERANCE: i64 = 80;

fn fail(msg: String) -> Result<(), BenchError> {
    Err(BenchError::Check(msg))
}

/// The checks of one target's output; `want` is the expected `scene techniques backend`
/// of every `RUN` line, in order.
pub fn target(t: &str, log: &RunLog, want: &[String]) -> Result<(), BenchError> {
    if !log.ended_ok {
        return fail(format!("{t}: the benchmark did not finish with ok=true"));
    }
    let bad: Vec<String> = log
        .runs
        .iter()
        .filter(|r| r.mismatched != 0 || !r.stats_match)
        .map(|r| {
            format!(
                "{} {} {}",
                r.sample.scene, r.sample.techniques, r.sample.backend
            )
        })
        .collect();
    if !bad.is_empty() {
        return fail(format!(
            "{t}: pixels or operation counts differ from the host's render: {}",
            bad.join("; ")
        ));
    }
    let got: Vec<String> = log.runs.iter().map(key).collect();
    if got != want {
        return fail(format!(
            "{t}: the benchmark did not render each scene with each technique set and backend \
             (build.rs lists them): want [{}], got [{}]",
            want.join(", "),
            got.join(", ")
        ));
    }
    if log
        .calibrations
        .iter()
        .any(|(m, e)| (m - e).abs() > CAL_TOLERANCE)
    {
        return fail(format!(
            "{t}: a loop of known length did not count as expected (ticks x 40 != instructions)"
        ));
    }
    variants(t, log, want)
}

/// `scene techniques backend` of a run.
pub fn key(r: &Run) -> String {
    let s = &r.sample;
    format!("{} {} {}", s.scene, s.techniques, s.backend)
}

/// The photo1 and photo2 variants are what their names say (with every technique set): at
/// max depth 0 no reflection or refraction ray; `--no-shadows` and no lights cast no shadow
/// ray, the default does. photo2-noshadow casts no shadow ray, photo2 does.
fn variants(t: &str, log: &RunLog, want: &[String]) -> Result<(), BenchError> {
    let scene_of = |k: &String| k.split(' ').next().unwrap_or("").to_string();
    let photo2 = |s: &str| s == "photo2" || s == "photo2-noshadow";
    let photo1 = |s: &str| matches!(s, "photo1-d0" | "photo1-noshadow" | "photo1-nolights");
    let n2 = want.iter().filter(|k| photo2(&scene_of(k))).count();
    let n1 = want.iter().filter(|k| photo1(&scene_of(k))).count();
    let mut seen2 = 0;
    let mut seen1 = 0;
    for r in &log.runs {
        let (s, st) = (r.sample.scene.as_str(), &r.sample.stats);
        if photo2(s) {
            if (s == "photo2") == (st.shadow_rays == 0) {
                return fail(format!(
                    "{t}: the photo2 variants are not what they claim: {}",
                    key(r)
                ));
            }
            seen2 += 1;
        }
        if photo1(s) {
            let bad = st.reflect_rays != 0
                || st.refract_rays != 0
                || st.primary_rays != r.sample.pixels
                || (s == "photo1-d0") == (st.shadow_rays == 0);
            if bad {
                return fail(format!(
                    "{t}: the photo1 variants (d0, noshadow, nolights) are not what they claim: {} has {:?}",
                    key(r),
                    st
                ));
            }
            seen1 += 1;
        }
    }
    if seen2 != n2 {
        return fail(format!("{t}: the photo2 variants are missing"));
    }
    if seen1 != n1 {
        return fail(format!(
            "{t}: the photo1 variants (d0, noshadow, nolights) are missing"
        ));
    }
    Ok(())
}

/// Every target and every technique set rendered the same pixels in each backend (each
/// already equals the host's render in that backend).
pub fn same_pixels(logs: &[(String, RunLog)]) -> Result<(), BenchError> {
    let mut hashes: BTreeMap<(&str, &str), &str> = BTreeMap::new();
    for (_, log) in logs {
        for r in &log.runs {
            let k = (r.sample.scene.as_str(), r.sample.backend.as_str());
            match hashes.get(&k) {
                Some(h) if *h != r.hash => {
                    return fail(format!(
                        "the targets' renders differ: {}/{} {} and {}",
                        k.0, k.1, h, r.hash
                    ))
                }
                _ => {
                    hashes.insert(k, &r.hash);
                }
            }
        }
    }
    Ok(())
}
