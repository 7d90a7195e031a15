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

/// The firmware's plan as it is: one large SRAM bank (even frames, every single frame)
/// and 24 KB of CCM for odd frames. Every bundled scene but photo2 renders as a single
/// frame; only the two smallest double-bank.
#[test]
fn every_bundled_scene_against_the_nc_plan_of_today() {
    assert_eq!(nc_fw::plan::BOARD, NodeBoard::F407);
    check_fits(
        &nc_fw::plan::BOARD,
        &[
            ("ellipsoids.ron", Fit::OneBank),
            ("glass.ron", Fit::OneBank),
            ("metaballs.ron", Fit::TwoBanks),
            ("photo1.ron", Fit::OneBank),
            ("photo2.ron", Fit::TooBig),
            ("reflections.ron", Fit::TwoBanks),
        ],
    );
}

/// Two banks of every bundled scene must fit the double-bank plan (two 60 KB SRAM banks),
/// which nc-fw takes once they do. The current truth: photo1 (116,724 bytes) and photo2
/// (187,136 bytes) do not fit yet; with compact SceneImages (photo1 <= 20,000 bytes, photo2
/// <= 40,000 bytes) both become `Fit::TwoBanks` and every row reads the same.
#[test]
fn two_banks_of_every_bundled_scene_against_the_double_bank_plan() {
    check_fits(
        &NodeBoard::F407_DUAL,
        &[
            ("ellipsoids.ron", Fit::TwoBanks),
            ("glass.ron", Fit::TwoBanks),
            ("metaballs.ron", Fit::TwoBanks),
            ("photo1.ron", Fit::TooBig),
            ("photo2.ron", Fit::TooBig),
            ("reflections.ron", Fit::TwoBanks),
        ],
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

/// photo1 at 512x480 (the paper's frame) fits the node's even bank and the root's scene
/// buffer.
#[test]
fn photo1_fits_the_node_and_root_scene_banks() {
    let n = image_len("photo1.ron", Some(512), Some(480));
    assert!(n <= nc_fw::plan::SCENE_EVEN, "{n} bytes");
    assert!(n <= rc_fw::plan::SCENE, "{n} bytes");
}
