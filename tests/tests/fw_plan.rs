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
    // ... and, compact, fits the odd frames' bank too: two banks on the node.
    assert!(n <= nc_fw::plan::SCENE_ODD, "{n} bytes");
}
