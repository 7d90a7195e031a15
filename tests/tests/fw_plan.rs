//! The firmware memory plans (nc-fw, rc-fw) against the SceneImages the DM really produces:
//! every bundled scene (`scenes/*.ron`) at its own resolution.

use links_core::board::{Fit, NodeBoard};
use links_core::dm::{compile, CompileOptions};
use links_host::scene_file::load_scene;
use std::path::{Path, PathBuf};

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

fn image_len(scene: &str, w: Option<u32>, h: Option<u32>) -> usize {
    let desc = load_scene(&scenes_dir().join(scene)).unwrap_or_else(|e| panic!("{e}"));
    let opts = CompileOptions {
        width: w,
        height: h,
        ..Default::default()
    };
    compile(&desc, &opts).expect("compiles").bytes.len()
}

/// Every bundled scene's file name and SceneImage size at its own resolution, by name.
fn bundled() -> Vec<(String, usize)> {
    let mut names: Vec<String> = std::fs::read_dir(scenes_dir())
        .expect("scenes/")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".ron"))
        // Films: each frame is compiled like its still scene (tests/tests/films.rs).
        .filter(|n| {
            links_host::scene_file::load_film(&scenes_dir().join(n)).map_or(true, |f| f.is_still())
        })
        .collect();
    names.sort();
    names
        .into_iter()
        .map(|n| {
            let len = image_len(&n, None, None);
            (n, len)
        })
        .collect()
}

/// How every bundled scene fits `board`, against what each is expected to do.
fn check_fits(board: &NodeBoard, expected: &[(&str, Fit)]) {
    let got: Vec<(String, usize, Fit)> = bundled()
        .into_iter()
        .map(|(n, len)| (n, len, board.fit(len)))
        .collect();
    let names: Vec<&str> = got.iter().map(|(n, _, _)| n.as_str()).collect();
    let want: Vec<&str> = expected.iter().map(|(n, _)| *n).collect();
    assert_eq!(names, want, "the bundled scenes changed: update the table");
    for ((name, len, fit), (_, want)) in got.iter().zip(expected) {
        assert_eq!(
            fit, want,
            "{name}: SceneImage {len} bytes against {} banks {:?}",
            board.name, board.scene_banks
        );
    }
}

/// Two banks of every bundled scene fit the node's plan (two 60 KB SRAM banks): the next
/// frame can be broadcast into one while the other renders (compact SceneImages: photo1
/// 18,292 bytes, photo2 38,948 bytes at 512x480).
#[test]
fn two_banks_of_every_bundled_scene_fit_the_nc_plan() {
    assert_eq!(nc_fw::plan::BOARD, NodeBoard::F407);
    check_fits(
        &nc_fw::plan::BOARD,
        &[
            ("ellipsoids.ron", Fit::TwoBanks),
            ("glass.ron", Fit::TwoBanks),
            ("metaballs.ron", Fit::TwoBanks),
            ("photo1.ron", Fit::TwoBanks),
            ("photo2.ron", Fit::TwoBanks),
            ("reflections.ron", Fit::TwoBanks),
        ],
    );
}

/// The G0B1's nodes are sent Q16.16 images (its profile's storage): every bundled still, in
/// Q16.16 at its own resolution (as long as its f32 image), against its 40 + 32 KB banks.
/// photo2 takes the even bank alone; every other scene double-banks.
#[test]
fn every_bundled_scene_in_q16_16_fits_the_g0b1_plan() {
    use links_core::board::BoardProfile;
    let board = BoardProfile::G0B1.node;
    assert_eq!(BoardProfile::G0B1.storage, links_core::num::Storage::Q16_16);
    let got: Vec<(String, usize, Fit)> = bundled()
        .into_iter()
        .map(|(name, f32_len)| {
            let desc = load_scene(&scenes_dir().join(&name)).unwrap_or_else(|e| panic!("{e}"));
            let img = compile(&desc, &CompileOptions::default()).expect("compiles");
            let fixed = links_core::fixed_image::to_fixed(&img.bytes)
                .unwrap_or_else(|e| panic!("{name} in Q16.16: {e}"))
                .bytes;
            // The same records, each number in 4 bytes either way.
            assert_eq!(fixed.len(), f32_len, "{name}");
            (name, fixed.len(), board.fit(fixed.len()))
        })
        .collect();
    let fits: Vec<(&str, Fit)> = got.iter().map(|(n, _, f)| (n.as_str(), *f)).collect();
    assert_eq!(
        fits,
        [
            ("ellipsoids.ron", Fit::TwoBanks),
            ("glass.ron", Fit::TwoBanks),
            ("metaballs.ron", Fit::TwoBanks),
            ("photo1.ron", Fit::TwoBanks),
            ("photo2.ron", Fit::OneBank),
            ("reflections.ron", Fit::TwoBanks),
        ],
        "{got:?} against the G0B1's banks {:?}",
        board.scene_banks
    );
}

/// The NC's plan is the board's data; the RC holds any scene a node's bank holds.
#[test]
fn the_nc_plan_is_the_boards_and_the_rc_holds_what_a_node_bank_holds() {
    use nc_fw::plan;
    let b = plan::BOARD;
    assert_eq!(
        [plan::SCENE_EVEN, plan::SCENE_ODD, plan::LINK_BANKS],
        [b.scene_banks[0], b.scene_banks[1], b.link_banks]
    );
    // (The plan's sums against the RAM are const asserts in `nc_fw::plan`.)
    for board in NodeBoard::ALL {
        assert!(board.largest_bank() <= rc_fw::plan::SCENE, "{}", board.name);
    }
}

/// photo1 and photo2 at 512x480 (the paper's frames) fit both of the node's banks and the
/// root's scene buffer, within the compact image's targets.
#[test]
fn photo1_and_photo2_fit_the_node_and_root_scene_banks() {
    for (scene, target) in [("photo1.ron", 20_000), ("photo2.ron", 40_000)] {
        let n = image_len(scene, Some(512), Some(480));
        assert!(n <= target, "{scene}: {n} bytes");
        assert!(n <= nc_fw::plan::SCENE_ODD, "{scene}: {n} bytes");
        assert!(n <= rc_fw::plan::SCENE, "{scene}: {n} bytes");
    }
}
