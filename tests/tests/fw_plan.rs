//! The firmware memory plans (nc-fw, rc-fw) against the SceneImages the DM really produces.

use links_core::dm::{compile, CompileOptions};
use links_host::scene_file::load_scene;
use std::path::Path;

fn image_len(scene: &str, w: u32, h: u32) -> usize {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(scene);
    let desc = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    let opts = CompileOptions {
        width: Some(w),
        height: Some(h),
        ..Default::default()
    };
    compile(&desc, &opts).expect("compiles").bytes.len()
}

#[test]
fn photo1_fits_the_node_and_root_scene_banks() {
    let n = image_len("photo1.ron", 512, 480);
    assert!(n <= nc_fw::plan::SCENE_EVEN, "{n} bytes");
    assert!(n <= rc_fw::plan::SCENE, "{n} bytes");
    // ... and is why the node has only one large bank: two would not fit the SRAM next to
    // the link's DMA banks (docs/hardware.md, memory plan).
    assert!(2 * n + nc_fw::plan::LINK_BANKS > nc_fw::plan::SRAM);
    assert!(n > nc_fw::plan::SCENE_ODD);
}
