//! The build script of both firmwares (nc-fw and rc-fw name it in their Cargo.toml): link
//! them with the workspace's `memory.x` (cortex-m-rt's `link.x`, defmt's `defmt.x`). Only for
//! the MCU: host builds of the library need nothing.
use std::path::PathBuf;

fn main() {
    let dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = dir.parent().map(PathBuf::from).unwrap_or(dir);
    println!("cargo:rerun-if-changed={}", root.join("memory.x").display());
    // (A change to this script rebuilds and reruns it anyway.)
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("none") {
        println!("cargo:rustc-link-search={}", root.display());
        println!("cargo:rustc-link-arg-bins=--nmagic");
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
