//! glTF import: transforms analytically, the material rule, camera and lights, the three
//! container forms of the real-exporter asset, malformed inputs, and a render of the asset.

use std::path::{Path, PathBuf};

use links_core::desc::{Light, Node, Shape};

use super::transform::{apply_point, mul, IDENTITY};
use super::*;

fn asset() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/assets/gltf/BoxTextured/BoxTextured.gltf")
}

pub(super) fn b64(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = c
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, &b)| n | u32::from(b) << (16 - 8 * i));
        for k in 0..=c.len() {
            s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
        }
    }
    while !s.len().is_multiple_of(4) {
        s.push('=');
    }
    s
}

/// One triangle (0,0,0) (1,0,0) (0,1,0), u16 indices; 44 bytes.
fn triangle_buffer() -> Vec<u8> {
    let mut b = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

/// A document with the triangle mesh; `nodes`, `extra` (more top-level members) spliced in.
pub(super) fn doc(nodes: &str, scene_nodes: &str, extra: &str) -> String {
    let buf = triangle_buffer();
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[{scene_nodes}]}}],
        "nodes":[{nodes}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
            "min":[0,0,0],"max":[1,1,0]}},
          {{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},
          {{"buffer":0,"byteOffset":36,"byteLength":6}}],
        "buffers":[{{"byteLength":44,"uri":"data:application/octet-stream;base64,{}"}}]
        {extra}}}"#,
        b64(&buf)
    )
}

fn import_str(text: &str) -> Result<Imported, GltfError> {
    import_slice(text.as_bytes(), "t.gltf", Path::new("."))
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

#[test]
fn quaternion_to_euler_analytic() {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    // 90 degrees about Z, about Y, about X.
    let e = matrix_to_euler_deg(&quat_to_matrix([0.0, 0.0, h, h]));
    assert!(close(&e, &[0.0, 0.0, 90.0], 1e-9), "{e:?}");
    let e = matrix_to_euler_deg(&quat_to_matrix([h, 0.0, 0.0, h]));
    assert!(close(&e, &[90.0, 0.0, 0.0], 1e-9), "{e:?}");
    // Gimbal lock: 90 about Y then nothing else -> beta = 90, all of the rest on X.
    let e = matrix_to_euler_deg(&quat_to_matrix([0.0, h, 0.0, h]));
    assert!(close(&e, &[0.0, 90.0, 0.0], 1e-9), "{e:?}");
}

#[test]
fn euler_round_trip_random_and_near_gimbal_lock() {
    let mut seed = 0x2545_f491_u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut cases: Vec<[f64; 4]> = (0..500).map(|_| [rnd(), rnd(), rnd(), rnd()]).collect();
    // Near and at gimbal lock: Euler (30, ±90 - tiny, 20) as quaternions.
    for beta in [90.0, 89.99999, 89.9, -90.0, -89.999999] {
        let r = euler_deg_to_matrix([30.0, beta, 20.0]);
        let w = (1.0 + r[0][0] + r[1][1] + r[2][2]).max(0.0).sqrt() / 2.0;
        let q = [
            (r[2][1] - r[1][2]) / (4.0 * w),
            (r[0][2] - r[2][0]) / (4.0 * w),
            (r[1][0] - r[0][1]) / (4.0 * w),
            w,
        ];
        cases.push(q);
    }
    for q in cases {
        let m = quat_to_matrix(q);
        let back = euler_deg_to_matrix(matrix_to_euler_deg(&m));
        for r in 0..3 {
            assert!(close(&m[r], &back[r], 1e-7), "q {q:?}: {m:?} vs {back:?}");
        }
    }
}

/// The world matrix of the first shape's clusters, composed from our Transforms.
fn first_shape_world(c: &links_core::desc::Cluster, above: Mat4) -> Option<(Mat4, Shape)> {
    let here = mul(&above, &transform_matrix(&c.transform));
    for n in &c.children {
        match n {
            Node::Shape(s) => return Some((here, s.clone())),
            Node::Cluster(k) => {
                if let Some(f) = first_shape_world(k, here) {
                    return Some(f);
                }
            }
        }
    }
    None
}

#[test]
fn hierarchy_places_vertices_where_gltf_does() {
    // Parent: T (1,2,3), R 90 about Y, S 2; child: a matrix with rotation about X by 90 and
    // translation (0, 0, 5); the mesh on the child.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let nodes = format!(
        r#"{{"name":"parent","children":[1],"translation":[1,2,3],"rotation":[0,{h},0,{h}],
             "scale":[2,2,2]}},
           {{"name":"child","mesh":0,"matrix":[1,0,0,0, 0,0,1,0, 0,-1,0,0, 0,0,5,1]}}"#
    );
    let imp = import_str(&doc(&nodes, "0", "")).expect("imports");
    let (world, shape) = first_shape_world(&imp.scene.root, IDENTITY).expect("a shape");
    let Shape::Mesh { mesh, .. } = shape else {
        panic!("not a mesh")
    };
    // By hand: child maps (0,1,0) -> (0,0,1) + (0,0,5) = (0,0,6); parent scales to (0,0,12),
    // rotates 90 about Y ((x,z) -> (z,-x)): (12,0,0), translates: (13,2,3).
    let p = apply_point(&world, mesh.positions[2]);
    assert!(close(&p, &[13.0, 2.0, 3.0], 1e-9), "{p:?}");
    let p0 = apply_point(&world, mesh.positions[1]);
    // (1,0,0) -> child (1,0,5) -> scale (2,0,10) -> rotate (10,0,-2) -> (11,2,1).
    assert!(close(&p0, &[11.0, 2.0, 1.0], 1e-9), "{p0:?}");
    let compiled = links_core::dm::compile(&imp.scene, &Default::default());
    assert!(compiled.is_ok(), "DM compile: {:?}", compiled.err());
}

#[test]
fn sheared_matrix_warns() {
    let nodes = r#"{"mesh":0,"matrix":[1,0,0,0, 0.5,1,0,0, 0,0,1,0, 0,0,0,1]}"#;
    let imp = import_str(&doc(nodes, "0", "")).expect("imports");
    assert!(imp
        .warnings
        .iter()
        .any(|w| matches!(w, Warning::Shear { .. })));
}

#[test]
fn material_rule_by_hand() {
    let p = |base: [f32; 4], m: f32, r: f32| Pbr {
        base,
        metallic: m,
        roughness: r,
        transmission: 0.0,
        blend: false,
        ior: None,
    };
    // Rough dielectric: all diffuse, 4 % specular, exponent clamped to 1.
    let d = eq21_terms("d", &p([0.8, 0.4, 0.2, 1.0], 0.0, 1.0));
    assert_eq!(d.diffuse, [0.8, 0.4, 0.2]);
    assert_eq!(
        (d.specular, d.specular_edge, d.shininess, d.reflect),
        (0.04, 0.04, 1.0, 0.0)
    );
    assert_eq!(d.ior, 1.5);
    // Polished white metal: a mirror.
    let m = eq21_terms("m", &p([1.0, 1.0, 1.0, 1.0], 1.0, 0.0));
    assert_eq!(m.diffuse, [0.0; 3]);
    assert!((m.reflect - 1.0).abs() < 1e-6 && (m.specular - 1.0).abs() < 1e-6);
    assert_eq!(m.shininess, 1000.0);
    // Roughness 0.5: alpha 0.25, n = 2/0.0625 - 2 = 30; s = 0.25.
    let h = eq21_terms("h", &p([1.0, 0.0, 0.0, 1.0], 0.0, 0.5));
    assert!((h.shininess - 30.0).abs() < 1e-4);
    assert!((h.specular_edge - (0.04 + 0.96 * 0.25)).abs() < 1e-6);
    assert!((h.reflect - 0.04 * 0.25).abs() < 1e-7);
    // Alpha blend 0.25: transmit 0.75 of the colour, diffuse a quarter.
    let mut g = p([0.4, 0.8, 1.0, 0.25], 0.0, 1.0);
    g.blend = true;
    g.ior = Some(1.33);
    let g = eq21_terms("g", &g);
    assert_eq!(g.transmit, [0.3, 0.6, 0.75]);
    assert_eq!(g.diffuse, [0.1, 0.2, 0.25]);
    assert_eq!(g.ior, 1.33);
}

#[test]
fn camera_and_lights_from_nodes() {
    let nodes = r#"{"mesh":0},{"camera":0,"translation":[0,0,5]},
        {"extensions":{"KHR_lights_punctual":{"light":0}},"translation":[0,3,0]},
        {"extensions":{"KHR_lights_punctual":{"light":1}},"rotation":[0.7071067811865476,0,0,0.7071067811865476]}"#;
    let extra = r#","cameras":[{"type":"perspective","perspective":{"yfov":0.8,"aspectRatio":2.0,"znear":0.1}}],
        "extensionsUsed":["KHR_lights_punctual"],
        "extensions":{"KHR_lights_punctual":{"lights":[
            {"type":"point","color":[1,0.5,0.25],"intensity":2},
            {"type":"directional","intensity":3}]}},
        "animations":[]"#;
    let imp = import_str(&doc(nodes, "0,1,2,3", extra)).expect("imports");
    let s = &imp.scene;
    assert!(close(&s.camera.eye, &[0.0, 0.0, 5.0], 1e-12));
    assert!(close(&s.camera.look_at, &[0.0, 0.0, 4.0], 1e-12));
    assert!(close(&s.camera.up, &[0.0, 1.0, 0.0], 1e-12));
    assert!((s.camera.fov_y_deg - 0.8f32.to_degrees() as f64).abs() < 1e-5);
    assert_eq!((s.width, s.height), (512, 256));
    assert_eq!(s.lights.len(), 2);
    let Light::Point {
        pos,
        color,
        falloff,
    } = &s.lights[0]
    else {
        panic!("{:?}", s.lights)
    };
    assert!(close(pos, &[0.0, 3.0, 0.0], 1e-12) && *falloff);
    assert_eq!(*color, [2.0, 1.0, 0.5]);
    // The light shines along its node's -Z; Rx(90°) takes (0, 0, -1) to (0, 1, 0).
    let Light::Directional { dir, color } = &s.lights[1] else {
        panic!()
    };
    assert!(close(dir, &[0.0, 1.0, 0.0], 1e-6), "{dir:?}");
    assert_eq!(*color, [3.0; 3]);
    assert!(imp.warnings.is_empty(), "{:?}", imp.warnings);
}

#[test]
fn defaults_are_warned_and_a_one_key_animation_imports() {
    let extra = r#","animations":[{"name":"spin","channels":[{"sampler":0,"target":{"node":0,"path":"rotation"}}],
        "samplers":[{"input":2,"output":3}]}]"#;
    let text = doc(r#"{"mesh":0}"#, "0", extra).replace(
        r#"{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}]"#,
        r#"{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"},
            {"bufferView":0,"componentType":5126,"count":1,"type":"SCALAR","min":[0],"max":[0]},
            {"bufferView":0,"componentType":5126,"count":1,"type":"VEC4"}]"#,
    );
    let imp = import_str(&text).expect("imports");
    // One key at 0 s: the identity quaternion (0, 0, 0, 1) of the triangle's first bytes.
    assert_eq!(imp.animation.tracks.len(), 1);
    assert_eq!(imp.animation.timeline.frames(), 0..1);
    let film = imp.film().expect("a film");
    assert_eq!(film.scene_at(0).expect("frame 0"), imp.scene);
    assert!(imp.warnings.contains(&Warning::DefaultCamera));
    assert!(imp.warnings.contains(&Warning::DefaultLight));
    // The default camera sees the bounding sphere: its centre is straight ahead.
    let c = &imp.scene.camera;
    assert!(close(&c.look_at, &[0.5, 0.5, 0.0], 1e-12));
}

/// The asset as .glb and as .gltf + external .bin, written to a temporary directory.
fn converted(dir: &Path) -> (PathBuf, PathBuf) {
    let text = std::fs::read_to_string(asset()).expect("asset");
    let start = text
        .find("data:application/octet-stream;base64,")
        .expect("buffer uri");
    let end = start + text[start..].find('"').expect("end quote");
    let b64text = &text[start + "data:application/octet-stream;base64,".len()..end];
    let bin = base64::decode(b64text).expect("base64");
    std::fs::write(dir.join("box.bin"), &bin).unwrap();
    let external = format!("{}box.bin{}", &text[..start], &text[end..]);
    std::fs::write(dir.join("external.gltf"), &external).unwrap();
    // GLB: the buffer's uri removed (the BIN chunk), chunks padded to 4 bytes.
    let uri_key = text[..start].rfind(",\n").expect("comma before uri");
    let mut json = format!("{}{}", &text[..uri_key], &text[end + 1..]).into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin4 = bin.clone();
    while !bin4.len().is_multiple_of(4) {
        bin4.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin4.len();
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    for v in [2u32, total as u32, json.len() as u32, 0x4E4F_534A] {
        glb.extend_from_slice(&v.to_le_bytes());
    }
    glb.extend_from_slice(&json);
    for v in [bin4.len() as u32, 0x004E_4942] {
        glb.extend_from_slice(&v.to_le_bytes());
    }
    glb.extend_from_slice(&bin4);
    std::fs::write(dir.join("box.glb"), glb).unwrap();
    (dir.join("box.glb"), dir.join("external.gltf"))
}

fn mesh_of(s: &links_core::desc::SceneDesc) -> links_core::desc::Mesh {
    match first_shape_world(&s.root, IDENTITY) {
        Some((_, Shape::Mesh { mesh, .. })) => mesh,
        other => panic!("{other:?}"),
    }
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("links-gltf-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn glb_external_and_data_uri_import_alike() {
    let dir = temp_dir("forms");
    let (glb, external) = converted(&dir);
    let embedded = import(&asset()).expect("embedded");
    let e = &embedded.scene;
    assert_eq!(e.textures.len(), 1);
    assert_eq!((e.textures[0].width, e.textures[0].height), (211, 211));
    let m = mesh_of(e);
    assert_eq!(
        (
            m.positions.len(),
            m.faces.len(),
            m.uvs.len(),
            m.normals.len()
        ),
        (24, 12, 24, 24)
    );
    // The first UV is (6, 0) in the file: v flips to 1.
    assert_eq!(m.uvs[0], [6.0, 1.0]);
    for path in [glb, external] {
        let other = import(&path).unwrap_or_else(|e| panic!("{e}"));
        let o = &other.scene;
        let om = mesh_of(o);
        assert_eq!(
            (om.positions, om.faces, om.uvs),
            (m.positions.clone(), m.faces.clone(), m.uvs.clone())
        );
        assert_eq!(
            (&o.materials, &o.textures, &o.camera),
            (&e.materials, &e.textures, &e.camera)
        );
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn malformed_inputs_give_their_error() {
    assert!(matches!(
        import_str("{not json"),
        Err(GltfError::Parse { .. })
    ));
    let bad_mesh = doc(r#"{"mesh":7}"#, "0", "");
    match import_str(&bad_mesh) {
        Err(GltfError::Invalid { path, .. }) => assert!(path.contains("nodes[0]"), "{path}"),
        other => panic!("{other:?}"),
    }
    let short = doc(r#"{"mesh":0}"#, "0", "").replace(r#""byteLength":44"#, r#""byteLength":400"#);
    assert!(matches!(
        import_str(&short),
        Err(GltfError::Buffer { buffer: 0, .. })
    ));
    let view = doc(r#"{"mesh":0}"#, "0", "")
        .replace(r#""count":3,"type":"VEC3""#, r#""count":4,"type":"VEC3""#);
    assert!(
        matches!(import_str(&view), Err(GltfError::Accessor { .. })),
        "{:?}",
        import_str(&view).err()
    );
    let ext = doc(
        r#"{"mesh":0}"#,
        "0",
        r#","extensionsRequired":["EXT_unknown"],"extensionsUsed":["EXT_unknown"]"#,
    );
    match import_str(&ext) {
        Err(GltfError::RequiredExtension { name, .. }) => assert_eq!(name, "EXT_unknown"),
        other => panic!("{other:?}"),
    }
    let missing = doc(r#"{"mesh":0}"#, "0", "");
    let start = missing.find("data:").unwrap();
    let end = start + missing[start..].find('"').unwrap();
    let missing = format!("{}nowhere.bin{}", &missing[..start], &missing[end..]);
    assert!(matches!(import_str(&missing), Err(GltfError::Read(_))));
    // Index 5 of 3 vertices: u16 indices 0,1,2 -> 0,1,5.
    let mut buf = triangle_buffer();
    buf[40] = 5;
    let good = doc(r#"{"mesh":0}"#, "0", "");
    let bad_index = good.replace(&b64(&triangle_buffer()), &b64(&buf));
    assert!(matches!(
        import_str(&bad_index),
        Err(GltfError::VertexIndex {
            index: 5,
            vertices: 3,
            ..
        })
    ));
    let err = import(Path::new("/nonexistent/model.glb"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("/nonexistent/model.glb"), "{err}");
}

#[test]
fn real_exporter_asset_renders_lit_and_deterministic() {
    let imp = import(&asset()).expect("imports");
    let opts = links_core::dm::CompileOptions {
        width: Some(128),
        height: Some(120),
        ..Default::default()
    };
    let image = links_core::dm::compile(&imp.scene, &opts)
        .expect("compiles")
        .bytes;
    let render = || {
        crate::frame::render_single(&image, crate::frame::Precision::F32, 1, &|| {})
            .expect("renders")
            .rgb
    };
    let a = render();
    let lit = a.chunks(3).filter(|p| p.iter().any(|&c| c > 40)).count();
    // The box covers about half of the frame (measured 45-55 %); at least 30 % is lit.
    assert!(
        lit * 100 > 30 * 128 * 120,
        "{lit} lit pixels of {}",
        128 * 120
    );
    assert_eq!(a, render());
}
