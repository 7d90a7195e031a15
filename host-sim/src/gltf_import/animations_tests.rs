//! glTF animations as tracks: the real exporter's BoxAnimated (values at and between keys
//! against the file's own keyframes, frames that differ), STEP and CUBICSPLINE on a file made
//! here, and malformed channels.

use std::path::{Path, PathBuf};

use links_core::anim::{track_value, Interpolation, Keys, Target, TransformProperty, Value};
use links_core::dm::CompileOptions;

use super::transform::{euler_deg_to_matrix, quat_to_matrix, Mat3};
use super::*;

fn box_animated() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/assets/gltf/BoxAnimated/BoxAnimated.gltf")
}

fn f32s(bytes: &[u8]) -> Vec<f64> {
    bytes
        .chunks_exact(4)
        .map(|c| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
        .collect()
}

/// The asset's buffer, decoded here from its data URI (independently of the importer).
fn box_buffer() -> Vec<u8> {
    let text = std::fs::read_to_string(box_animated()).expect("asset");
    let start = text.find("base64,").expect("data uri") + 7;
    let end = start + text[start..].find('"').expect("end of uri");
    super::base64::decode(&text[start..end]).expect("base64")
}

fn vector(v: Option<Value>) -> [f64; 3] {
    match v {
        Some(Value::Vector(v)) => v,
        other => panic!("not a vector: {other:?}"),
    }
}

fn close3(a: &Mat3, b: &Mat3, tol: f64) -> bool {
    (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
}

fn track_of(imp: &Imported, property: TransformProperty) -> &links_core::anim::Track {
    imp.animation
        .tracks
        .iter()
        .find(|t| matches!(&t.target, Target::Cluster { property: p, .. } if *p == property))
        .expect("a track")
}

#[test]
fn box_animated_tracks_match_the_files_keyframes() {
    let imp = import(&box_animated()).expect("imports");
    let b = box_buffer();
    // bufferViews 2 (times), 3 (rotations), 4 (translations), as the file lays them out.
    let rot_times = f32s(&b[7760..7768]);
    let tr_times = f32s(&b[7768..7784]);
    let rots = f32s(&b[0..32]);
    let trs = f32s(&b[32..80]);
    assert_eq!(rot_times, [1.25, 2.5]);
    assert_eq!(imp.animation.tracks.len(), 2);
    // 3.7083 s at 24 frames per second: frame 88.99, so frames 0..=88.
    assert_eq!(imp.animation.timeline.frames(), 0..89);
    assert_eq!(imp.animation.timeline.rate, DEFAULT_RATE);

    let tr = track_of(&imp, TransformProperty::Translate);
    assert_eq!(tr.interpolation, Interpolation::Linear);
    // Node 0 is the scene's second root node: cluster [1].
    assert!(matches!(&tr.target, Target::Cluster { path, .. } if path == &[1]));
    for (k, &t) in tr_times.iter().enumerate() {
        let v = vector(track_value(tr, t * DEFAULT_RATE));
        assert_eq!(v, [trs[3 * k], trs[3 * k + 1], trs[3 * k + 2]], "key {k}");
    }
    // Halfway between the first two keys (0 s and 1.25 s): the mean of their values.
    let mid = vector(track_value(tr, 0.625 * DEFAULT_RATE));
    assert!((mid[1] - 0.5 * (trs[1] + trs[4])).abs() < 1e-12, "{mid:?}");

    let rot = track_of(&imp, TransformProperty::Rotate);
    // Node 2 is node 1's only child, node 1 node 0's; neither has a mesh: [1, 0, 0].
    assert!(matches!(&rot.target, Target::Cluster { path, .. } if path == &[1, 0, 0]));
    for (k, &t) in rot_times.iter().enumerate() {
        let q = [0, 1, 2, 3].map(|i| rots[4 * k + i]);
        let got = euler_deg_to_matrix(vector(track_value(rot, t * DEFAULT_RATE)));
        assert!(close3(&got, &quat_to_matrix(q), 1e-9), "key {k}: {got:?}");
    }
    // Halfway (1.875 s) between the identity and a half turn about x: a quarter turn about x.
    let got = euler_deg_to_matrix(vector(track_value(rot, 1.875 * DEFAULT_RATE)));
    assert!((got[0][0] - 1.0).abs() < 1e-9, "{got:?}");
    assert!(got[1][1].abs() < 1e-6 && got[2][2].abs() < 1e-6, "{got:?}");
    assert!((got[1][2].abs() - 1.0).abs() < 1e-6, "{got:?}");
}

#[test]
fn box_animated_frames_differ_and_warnings_name_no_animation() {
    let imp = import(&box_animated()).expect("imports");
    assert!(
        !imp.warnings.iter().any(|w| matches!(
            w,
            Warning::AnimationTarget { .. } | Warning::CubicSpline { .. }
        )),
        "{:?}",
        imp.warnings
    );
    let film = imp.film().expect("a film");
    let opts = CompileOptions {
        width: Some(32),
        height: Some(30),
        ..Default::default()
    };
    let image = |f: u32| film.compile_frame(f, &opts).expect("compiles").bytes;
    let frames: Vec<Vec<u8>> = [0, 15, 30, 45].into_iter().map(image).collect();
    for i in 0..frames.len() {
        for j in i + 1..frames.len() {
            assert_ne!(frames[i], frames[j], "frames {i} and {j}");
        }
    }
    // Frame 0 is the file's rest pose (every track's first key is its rest value here).
    assert_eq!(
        image(0),
        links_core::dm::compile(&imp.scene, &opts).expect("c").bytes
    );
}

/// The triangle document with one animation on node 0: `path`, `interp`, times and outputs
/// (floats) of `out_type`, in a second buffer.
fn anim_doc(path: &str, interp: &str, times: &[f32], outputs: &[f32], out_type: &str) -> String {
    let mut buf = Vec::new();
    for v in times.iter().chain(outputs) {
        buf.extend_from_slice(&v.to_le_bytes());
    }
    let (nt, no) = (times.len(), outputs.len());
    let width = match out_type {
        "VEC4" => 4,
        "SCALAR" => 1,
        _ => 3,
    };
    let extra = format!(
        r#","animations":[{{"channels":[{{"sampler":0,"target":{{"node":0,"path":"{path}"}}}}],
        "samplers":[{{"input":2,"output":3,"interpolation":"{interp}"}}]}}]"#
    );
    let base = super::tests::doc(r#"{"mesh":0}"#, "0", &extra);
    base.replace(
        r#"{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}]"#,
        &format!(
            r#"{{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}},
            {{"bufferView":2,"componentType":5126,"count":{nt},"type":"SCALAR"}},
            {{"bufferView":3,"componentType":5126,"count":{},"type":"{out_type}"}}]"#,
            no / width
        ),
    )
    .replace(
        r#"{"buffer":0,"byteOffset":36,"byteLength":6}]"#,
        &format!(
            r#"{{"buffer":0,"byteOffset":36,"byteLength":6}},
            {{"buffer":1,"byteOffset":0,"byteLength":{}}},
            {{"buffer":1,"byteOffset":{},"byteLength":{}}}]"#,
            4 * nt,
            4 * nt,
            4 * no
        ),
    )
    .replace(
        r#""buffers":["#,
        &format!(
            r#""buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}},"#,
            buf.len(),
            super::tests::b64(&buf)
        ),
    )
    // The triangle's buffer is now buffers[1]; the animation's, buffers[0].
    .replace(r#"{"buffer":0,"#, r#"{"buffer":X,"#)
    .replace(r#"{"buffer":1,"#, r#"{"buffer":0,"#)
    .replace(r#"{"buffer":X,"#, r#"{"buffer":1,"#)
}

fn import_text(text: &str) -> Result<Imported, GltfError> {
    import_slice(text.as_bytes(), "a.gltf", Path::new("."))
}

#[test]
fn step_holds_and_seconds_become_frames_at_the_rate() {
    let text = anim_doc(
        "translation",
        "STEP",
        &[0.0, 0.5],
        &[0., 0., 0., 2., 4., 6.],
        "VEC3",
    );
    let imp = import_text(&text).expect("imports");
    let t = &imp.animation.tracks[0];
    assert_eq!(t.interpolation, Interpolation::Step);
    let Keys::Vector(keys) = &t.keys else {
        panic!("vector keys")
    };
    assert_eq!(keys[1].frame, 12.0); // 0.5 s at 24 frames per second
    assert_eq!(imp.animation.timeline.frames(), 0..13);
    assert_eq!(vector(track_value(t, 11.9)), [0.0; 3]);
    assert_eq!(vector(track_value(t, 12.0)), [2.0, 4.0, 6.0]);
    let film = imp.film().expect("film");
    let s = film.scene_at(12).expect("frame 12");
    let links_core::desc::Node::Cluster(c) = &s.root.children[0] else {
        panic!("a cluster")
    };
    assert_eq!(c.transform.translate, [2.0, 4.0, 6.0]);
}

#[test]
fn cubicspline_keeps_the_key_values_and_warns() {
    // (in-tangent, value, out-tangent) per key; scale 1 -> 3 over 1 s.
    let out = [
        9., 9., 9., 1., 1., 1., 9., 9., 9., 9., 9., 9., 3., 3., 3., 9., 9., 9.,
    ];
    let text = anim_doc("scale", "CUBICSPLINE", &[0.0, 1.0], &out, "VEC3");
    let imp = import_text(&text).expect("imports");
    assert!(imp
        .warnings
        .iter()
        .any(|w| matches!(w, Warning::CubicSpline { .. })));
    let t = &imp.animation.tracks[0];
    assert_eq!(t.interpolation, Interpolation::Smooth);
    assert_eq!(vector(track_value(t, 0.0)), [1.0; 3]);
    assert_eq!(vector(track_value(t, 24.0)), [3.0; 3]);
    // Two keys on a line: Catmull-Rom is that line; halfway is 2.
    let mid = vector(track_value(t, 12.0));
    assert!(mid.iter().all(|x| (x - 2.0).abs() < 1e-12), "{mid:?}");
}

#[test]
fn slerp_between_keys_is_exact_for_a_quarter_turn() {
    let s = std::f32::consts::FRAC_1_SQRT_2;
    // Identity -> 90 degrees about y over 1 s; at 0.5 s: 45 degrees about y.
    let text = anim_doc(
        "rotation",
        "LINEAR",
        &[0.0, 1.0],
        &[0., 0., 0., 1., 0., s, 0., s],
        "VEC4",
    );
    let imp = import_text(&text).expect("imports");
    let t = &imp.animation.tracks[0];
    let got = euler_deg_to_matrix(vector(track_value(t, 12.0)));
    let h = std::f64::consts::FRAC_PI_8;
    let want = quat_to_matrix([0.0, h.sin(), 0.0, h.cos()]);
    assert!(close3(&got, &want, 1e-6), "{got:?}");
}

#[test]
fn malformed_channels_give_a_clear_error() {
    let cases = [
        (
            anim_doc("translation", "LINEAR", &[1.0, 0.5], &[0.; 6], "VEC3"),
            "strictly increasing",
        ),
        (
            anim_doc("translation", "LINEAR", &[0.0, 0.5], &[0.; 9], "VEC3"),
            "2 input times and 3 outputs",
        ),
        (
            anim_doc("translation", "CUBICSPLINE", &[0.0, 0.5], &[0.; 6], "VEC3"),
            "CUBICSPLINE interpolation needs 6",
        ),
        (
            anim_doc("rotation", "LINEAR", &[0.0, 0.5], &[0.; 6], "VEC3"),
            "a Rotate channel needs Vec4",
        ),
    ];
    for (text, want) in cases {
        let e = import_text(&text).expect_err("malformed");
        let msg = e.to_string();
        assert!(matches!(e, GltfError::Animation { .. }), "{msg}");
        assert!(
            msg.contains("a.gltf: animations[0].channels[0]: malformed animation channel")
                && msg.contains(want),
            "{msg}"
        );
    }
}

#[test]
fn the_default_camera_frames_what_the_animation_sweeps() {
    let imp = import(&box_animated()).expect("imports");
    // Rest: y from -0.5 to 0.5; the inner box rises by 2.52: the swept box's centre is
    // about 2.52 / 2 higher than the rest box's (0).
    let look = imp.scene.camera.look_at;
    assert!(look[1] > 1.0 && look[1] < 1.6, "{look:?}");
    // At frame 40 (1.67 s) the inner box is at the top, turning: its purple is in the picture.
    let film = imp.film().expect("a film");
    let opts = CompileOptions {
        width: Some(40),
        height: Some(38),
        ..Default::default()
    };
    let image = film.compile_frame(40, &opts).expect("compiles").bytes;
    let rgb = crate::frame::render_frame(&image, crate::frame::Precision::F32, 1, &|| {})
        .expect("renders")
        .rgb;
    // Inner (purple, red ~ blue > green) against outer (blue, red < green).
    let purple = rgb
        .chunks_exact(3)
        .filter(|p| u32::from(p[0]) > u32::from(p[1]) + 20)
        .count();
    assert!(purple > 20, "{purple} purple pixels");
}
