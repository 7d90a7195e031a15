//! The build script of both firmwares (nc-fw and rc-fw name it in their Cargo.toml): link
//! them with their board's memory layout (the workspace's `memory.x`, which includes
//! `board-memory.x` from `shared/board/f407/` or, with the firmware's `board-f207` or
//! `board-g0b1` feature, `shared/board/f207/` or `shared/board/g0b1/`), cortex-m-rt's
//! `link.x` and defmt's `defmt.x`. Only for the MCU: host builds of the library need nothing.
use std::path::PathBuf;

fn main() {
    let dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = dir.parent().map(PathBuf::from).unwrap_or(dir);
    let board = if std::env::var_os("CARGO_FEATURE_BOARD_F207").is_some() {
        "f207"
    } else if std::env::var_os("CARGO_FEATURE_BOARD_G0B1").is_some() {
        "g0b1"
    } else {
        "f407"
    };
    let boards = root.join("shared").join("board");
    println!("cargo:rerun-if-changed={}", root.join("memory.x").display());
    for b in ["f407", "f207", "g0b1"] {
        let file = boards.join(b).join("board-memory.x");
        println!("cargo:rerun-if-changed={}", file.display());
    }
    // (A change to this script rebuilds and reruns it anyway.)
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("none") {
        println!("cargo:rustc-link-search={}", root.display());
        println!("cargo:rustc-link-search={}", boards.join(board).display());
        println!("cargo:rustc-link-arg-bins=--nmagic");
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
