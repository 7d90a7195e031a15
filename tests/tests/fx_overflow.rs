//! The checked fixed-point build (`--features fx-checked`, issue 14): every Q16.16 overflow
//! is counted where it happens (`links_core::math::overflow`). Q16.16 saturates instead of
//! wrapping, and the tracer reads an infinity as "no hit", so an overflow inside a scene
//! would drop a hit silently; the saturations that are the intended answer (a slab test's
//! reciprocal direction and distances for a ray nearly parallel to the slab) are written as
//! `Real::mul_beyond` / `recip_beyond` and not counted.
//!
//! `cargo test --release -p links-tests --features fx-checked --test fx_overflow`
//! (`scripts/test-all` runs it); without the feature this file is empty.
#![cfg(feature = "fx-checked")]

use links_core::fixed::Fx;
use links_core::math::overflow::{self, Kind, OverflowCounts};
use links_core::num::Real;
use links_host::frame::{render_single, Precision};
use std::sync::Mutex;

/// The counters are process-wide: one test at a time.
static SERIAL: Mutex<()> = Mutex::new(());

fn sites() -> Vec<String> {
    let mut s = [None; overflow::SITES];
    let n = overflow::sites(&mut s);
    s[..n]
        .iter()
        .flatten()
        .map(|s| format!("{}:{} {} x{}", s.file, s.line, s.kind, s.count))
        .collect()
}

#[test]
fn the_checked_build_counts_an_overflow_where_it_happens() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    overflow::reset();
    let big = Fx::from_i32(30_000);
    let line = line!() + 1;
    let sum = big + big;
    assert!(!sum.is_finite(), "30000 + 30000 leaves Q16.16's range");
    let product = big * Fx::from_i32(2);
    assert!(!product.is_finite());
    let quotient = big / Fx::from_f32(0.5);
    assert!(!quotient.is_finite());
    let invalid = Fx::ZERO / Fx::ZERO;
    assert!(invalid.is_nan());
    let root = Fx::from_i32(-4).sqrt();
    assert!(root.is_nan());
    // An infinity in, an infinity out: a consequence, not a new overflow.
    let _ = sum + big;
    // The intended saturations are not counted.
    let beyond = big.mul_beyond(big);
    assert!(!beyond.is_finite());
    let inv = Fx::from_raw(1).recip_beyond();
    assert!(!inv.is_finite());
    assert_eq!(
        overflow::counts(),
        OverflowCounts {
            sums: 1,
            products: 1,
            quotients: 1,
            conversions: 0,
            invalid: 2,
        }
    );
    let mut s = [None; overflow::SITES];
    let n = overflow::sites(&mut s);
    let first = s[..n].iter().flatten().next().expect("a site");
    assert_eq!(
        (first.file, first.line, first.kind),
        ("tests/tests/fx_overflow.rs", line, Kind::Sum),
        "the sum's own line: {:?}",
        sites()
    );
    overflow::reset();
    assert_eq!(overflow::counts(), OverflowCounts::default());
    assert!(sites().is_empty());
}

#[test]
fn every_bundled_scene_renders_in_q16_16_without_an_overflow() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let scenes = links_host::studies::chart::bundled_images(&dir, 128, 120).expect("scenes");
    assert!(scenes.len() >= 6, "the bundled stills");
    for (name, image) in scenes {
        overflow::reset();
        let frame = render_single(&image, Precision::Fixed, 0, &|| {}).expect("renders");
        assert!(frame.stats.rays() > 0);
        assert_eq!(
            overflow::counts().total(),
            0,
            "{name}: {} at {:?}",
            overflow::counts(),
            sites()
        );
    }
}
