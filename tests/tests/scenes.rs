//! Every bundled scene: loads, compiles, renders; golden images; f32 vs f64 agreement.
//!
//! Golden images live in `tests/golden/<scene>.png`, rendered in f64 at [`GOLDEN_W`] x
//! [`GOLDEN_H`]. Tolerance: every channel within 2/255 of the golden value on at least
//! 99.5% of pixels, and PSNR >= 45 dB (renders are deterministic on one platform; the slack
//! covers libm and compiler differences elsewhere). Regenerate with
//! `UPDATE_GOLDEN=1 cargo test -p links-tests --test scenes` after a deliberate change.

use links_core::dm::{compile, CompileOptions, MeshHierarchy};
use links_core::render::Techniques;
use links_host::frame::{decode_png_rgb, encode_png, psnr};
use links_host::scene_file::load_scene;
use links_tests::{render_all, render_all_with};
use std::path::{Path, PathBuf};

const GOLDEN_W: u32 = 96;
const GOLDEN_H: u32 = 90;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn bundled_scenes() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("scenes"))
        .expect("scenes/ exists")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "ron"))
        // The films (tests/tests/films.rs) are a still scene of this set plus tracks.
        .filter(|p| links_host::scene_file::load_film(p).map_or(true, |f| f.is_still()))
        .collect();
    v.sort();
    v
}

fn small_image(path: &Path) -> Vec<u8> {
    small_image_with(path, MeshHierarchy::default())
}

fn small_image_with(path: &Path, mesh_hierarchy: MeshHierarchy) -> Vec<u8> {
    let desc = load_scene(path).unwrap_or_else(|e| panic!("{e}"));
    let opts = CompileOptions {
        width: Some(GOLDEN_W),
        height: Some(GOLDEN_H),
        mesh_hierarchy,
        ..Default::default()
    };
    compile(&desc, &opts)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .bytes
}

#[test]
fn the_bundled_scene_set_is_complete() {
    let names: Vec<String> = bundled_scenes()
        .iter()
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    for required in [
        "photo1",
        "photo2",
        "metaballs",
        "glass",
        "ellipsoids",
        "reflections",
    ] {
        assert!(
            names.iter().any(|n| n == required),
            "scenes/{required}.ron missing (have {names:?})"
        );
    }
}

#[test]
fn golden_images_match() {
    let update = std::env::var_os("UPDATE_GOLDEN").is_some();
    let dir = root().join("tests/golden");
    std::fs::create_dir_all(&dir).unwrap();
    let mut failures = Vec::new();
    for scene in bundled_scenes() {
        let name = scene.file_stem().unwrap().to_string_lossy().into_owned();
        let rgb = render_all::<f64>(&small_image(&scene));
        let golden = dir.join(format!("{name}.png"));
        if update {
            std::fs::write(&golden, encode_png(GOLDEN_W, GOLDEN_H, &rgb).unwrap()).unwrap();
            continue;
        }
        let bytes = std::fs::read(&golden)
            .unwrap_or_else(|_| panic!("{} missing: run with UPDATE_GOLDEN=1", golden.display()));
        let (w, h, want) = decode_png_rgb(&bytes).unwrap();
        assert_eq!((w, h), (GOLDEN_W, GOLDEN_H), "{name}: golden size");
        let off = rgb
            .chunks(3)
            .zip(want.chunks(3))
            .filter(|(a, b)| a.iter().zip(*b).any(|(x, y)| x.abs_diff(*y) > 2))
            .count();
        let frac = off as f64 / (w * h) as f64;
        let p = psnr(&rgb, &want);
        println!(
            "{name:<12} golden: {:.2}% pixels off by > 2/255, PSNR {p:.1} dB",
            frac * 100.0
        );
        if frac > 0.005 || p < 45.0 {
            failures.push(format!(
                "{name}: {:.2}% pixels off, PSNR {p:.1} dB",
                frac * 100.0
            ));
        }
    }
    assert!(failures.is_empty(), "golden mismatches: {failures:?}");
}

#[test]
fn f32_and_f64_renders_agree_to_50_db() {
    println!(
        "{:<12} {:>10} {:>10} {:>8} {:>10}",
        "scene", "PSNR (dB)", "max error", "NaN/inf", "hit diffs"
    );
    for scene in bundled_scenes() {
        let name = scene.file_stem().unwrap().to_string_lossy().into_owned();
        let a = links_host::accuracy::compare_f32_to_f64(&small_image(&scene)).unwrap();
        println!(
            "{name:<12} {:>10.1} {:>10} {:>8} {:>10}",
            a.psnr_db, a.max_channel_error, a.non_finite_pixels, a.hit_mismatches
        );
        assert!(
            a.psnr_db >= 50.0,
            "{name}: f32 vs f64 PSNR {:.1} dB < 50 dB",
            a.psnr_db
        );
        assert_eq!(a.non_finite_pixels, 0, "{name}: NaN or infinite colours");
        assert_eq!(
            a.hit_mismatches_off_silhouette, 0,
            "{name}: f32 hit another shape away from a silhouette"
        );
    }
}

#[test]
fn every_technique_gives_the_plain_algorithms_pixels() {
    // Plain = LINKS-1's type 4 (no boxes, no clipping) over the paper's flat mesh clusters.
    let variants = [
        ("all", Techniques::ALL),
        ("type 1", Techniques::PAPER_TYPE_1),
        ("type 2", Techniques::PAPER_TYPE_2),
        ("type 3", Techniques::PAPER_TYPE_3),
        (
            "boxes, no early shadow exit",
            Techniques {
                shadow_early_exit: false,
                ..Techniques::PAPER_TYPE_3
            },
        ),
        (
            "Y clip only",
            Techniques {
                x_clip: false,
                shadow_early_exit: true,
                ..Techniques::ALL
            },
        ),
    ];
    for scene in bundled_scenes() {
        let name = scene.file_stem().unwrap().to_string_lossy().into_owned();
        let flat = small_image_with(&scene, MeshHierarchy::Flat);
        let (plain, plain_stats) = render_all_with::<f32>(&flat, Techniques::PAPER_TYPE_4);
        assert_eq!(
            plain_stats.box_tests, 0,
            "{name}: the plain algorithm tests no boxes"
        );
        for hierarchy in [
            MeshHierarchy::Flat,
            MeshHierarchy::Median,
            MeshHierarchy::Sah,
        ] {
            let img = small_image_with(&scene, hierarchy);
            for (label, t) in variants {
                let (rgb, stats) = render_all_with::<f32>(&img, t);
                let off = rgb.iter().zip(&plain).filter(|(a, b)| a != b).count();
                assert_eq!(off, 0, "{name} {hierarchy:?} {label}: {off} channel values differ from the plain algorithm");
                assert_eq!(
                    stats.rays(),
                    plain_stats.rays(),
                    "{name} {hierarchy:?} {label}: same rays"
                );
                if t.y_clip {
                    assert!(
                        stats.clip_compares > 0 && stats.clip_overflows == 0,
                        "{name} {label}: clipping ran"
                    );
                }
            }
        }
    }
}
