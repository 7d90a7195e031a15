//! Scene-file tests: a full example, defaults, and the position of every kind of error.

use std::path::{Path, PathBuf};

use links_core::desc::*;
use png::{BitDepth, ColorType};

use super::texture::tests::encode_png;
use super::*;

/// A scratch directory removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("links-scene-file-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("assets")).unwrap();
        Scratch(dir)
    }

    fn write(&self, rel: &str, bytes: &[u8]) {
        std::fs::write(self.0.join(rel), bytes).unwrap();
    }

    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

const EXAMPLE: &str = r#"// An example scene: every kind of object, most options.
Scene(
    camera: (eye: (0, 2, -8), look_at: (0, 1, 0), up: (0, 1, 0), fov_y: 45),
    image: (width: 320, height: 240),
    background: (0.05, 0.05, 0.1),
    ambient: 0.2,
    max_depth: 4,
    transparency: NonRefractive,
    textures: { "checker": "assets/checker.png" },
    materials: {
        "red": (diffuse: (0.8, 0.1, 0.1), specular: 0.4, shininess: 30),
        "glass": (
            diffuse: 0, specular: 0.1, specular_edge: 1,
            reflect: 0.05, reflect_edge: 1, transmit: 0.9, ior: 1.5,
        ),
        "floor": (diffuse: 1, map: (texture: "checker", scale: 4)),
        "chrome": (diffuse: 0.1, reflect: 0.8,
                   map: Some((texture: "checker", target: Reflect, scale: (2, 3)))),
    },
    lights: [
        Directional(dir: (0, -2, 0)),
        Point(pos: (0, 5, 0), color: 20, falloff: true),
        Spot(pos: (0, 4, -4), dir: (0, -1, 1), color: (1, 0.5, 0.25),
             inner: 10, outer: 20, exponent: 1),
    ],
    root: (
        name: "world",
        children: [
            Sphere(center: (0, 1, 0), radius: 1),   /* no material: the default */
            Ellipsoid(center: (2, 1, 0), radii: (1, 0.5, 0.5), rotate: (0, 0, 30),
                      cut: (normal: (0, 2, 0), offset: 0.25, capped: false),
                      material: "glass"),
            Box(min: (-10, -1, -10), max: [10, 0, 10], material: "floor"),
            Triangle(
                v: ((0, 0, 0), (1, 0, 0), (0, 1, 0)),
                normals: ((0, 0, -1), (0, 0, -1), (0, 0, -2)),
                uv: ((0, 0), (1, 0), (0, 1)),
                material: "red",
            ),
            Cluster(
                name: "arm",
                transform: (translate: (1, 2, 3), rotate: (0, 30, 0), scale: 2),
                material: "chrome",
                children: [
                    Mesh(file: "assets/tri.obj", smooth: true),
                    Blobs(kernel: Wyvill, threshold: 0.5, balls: [
                        (center: (0, 0, 0), radius: 2),
                        (center: (1, 0, 0), radius: 1.5, strength: -0.5),
                    ]),
                    Cluster(name: "empty", transform: (scale: (1, 2, 3))),
                ],
            ),
        ],
    ),
)
"#;

const TRI_OBJ: &str = "# one triangle\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";

fn write_assets(s: &Scratch) {
    let checker = encode_png(
        2,
        2,
        ColorType::Rgb,
        BitDepth::Eight,
        None,
        &[255, 255, 255, 0, 0, 0, 0, 0, 0, 255, 255, 255],
    );
    s.write("assets/checker.png", &checker);
    s.write("assets/tri.obj", TRI_OBJ.as_bytes());
}

#[test]
fn full_example_parses_to_the_expected_scene() {
    let s = Scratch::new("example");
    write_assets(&s);
    let got = parse_scene(EXAMPLE, "example.ron", s.path()).unwrap();

    let r2 = 1.0 / 2f64.sqrt();
    let tri_mesh = Mesh {
        source: "assets/tri.obj".into(),
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        normals: vec![],
        uvs: vec![],
        faces: vec![[0, 1, 2].map(|p| FaceVertex {
            position: p,
            normal: None,
            uv: None,
        })],
        groups: vec![],
    };
    let expected = SceneDesc {
        camera: Camera {
            eye: [0.0, 2.0, -8.0],
            look_at: [0.0, 1.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 45.0,
        },
        width: 320,
        height: 240,
        background: [0.05, 0.05, 0.1],
        ambient: [0.2; 3],
        max_depth: 4,
        transparency: TransparencyMode::NonRefractive,
        materials: vec![
            Material {
                name: "red".into(),
                diffuse: [0.8, 0.1, 0.1],
                specular: 0.4,
                specular_edge: 0.4,
                shininess: 30.0,
                ..Material::default()
            },
            Material {
                name: "glass".into(),
                diffuse: [0.0; 3],
                specular: 0.1,
                specular_edge: 1.0,
                reflect: 0.05,
                reflect_edge: 1.0,
                transmit: [0.9; 3],
                ior: 1.5,
                ..Material::default()
            },
            Material {
                name: "floor".into(),
                diffuse: [1.0; 3],
                map: Some(TextureMap {
                    texture: 0,
                    target: MapTarget::Diffuse,
                    scale: [4.0, 4.0],
                }),
                ..Material::default()
            },
            Material {
                name: "chrome".into(),
                diffuse: [0.1; 3],
                reflect: 0.8,
                reflect_edge: 0.8,
                map: Some(TextureMap {
                    texture: 0,
                    target: MapTarget::Reflect,
                    scale: [2.0, 3.0],
                }),
                ..Material::default()
            },
            Material::default(),
        ],
        textures: vec![Texture {
            name: "checker".into(),
            width: 2,
            height: 2,
            rgb: vec![255, 255, 255, 0, 0, 0, 0, 0, 0, 255, 255, 255],
        }],
        lights: vec![
            Light::Directional {
                dir: [0.0, -1.0, 0.0],
                color: [1.0; 3],
            },
            Light::Point {
                pos: [0.0, 5.0, 0.0],
                color: [20.0; 3],
                falloff: true,
            },
            Light::Spot {
                pos: [0.0, 4.0, -4.0],
                dir: [0.0, -r2, r2],
                color: [1.0, 0.5, 0.25],
                inner_deg: 10.0,
                outer_deg: 20.0,
                exponent: 1.0,
            },
        ],
        root: Cluster {
            name: "world".into(),
            transform: Transform::default(),
            children: vec![
                Node::Shape(Shape::Ellipsoid {
                    center: [0.0, 1.0, 0.0],
                    radii: [1.0; 3],
                    rotate_deg: [0.0; 3],
                    cut: None,
                    material: 4,
                }),
                Node::Shape(Shape::Ellipsoid {
                    center: [2.0, 1.0, 0.0],
                    radii: [1.0, 0.5, 0.5],
                    rotate_deg: [0.0, 0.0, 30.0],
                    cut: Some(CutPlane {
                        normal: [0.0, 1.0, 0.0],
                        offset: 0.25,
                        capped: false,
                    }),
                    material: 1,
                }),
                Node::Shape(Shape::Box {
                    min: [-10.0, -1.0, -10.0],
                    max: [10.0, 0.0, 10.0],
                    material: 2,
                }),
                Node::Shape(Shape::Triangle {
                    v: [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                    normals: Some([[0.0, 0.0, -1.0]; 3]),
                    uv: Some([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
                    material: 0,
                }),
                Node::Cluster(Cluster {
                    name: "arm".into(),
                    transform: Transform {
                        translate: [1.0, 2.0, 3.0],
                        rotate_deg: [0.0, 30.0, 0.0],
                        scale: [2.0; 3],
                    },
                    children: vec![
                        Node::Shape(Shape::Mesh {
                            mesh: tri_mesh,
                            material: 3,
                            smooth: true,
                        }),
                        Node::Shape(Shape::Blobs {
                            balls: vec![
                                Ball {
                                    center: [0.0; 3],
                                    radius: 2.0,
                                    strength: 1.0,
                                },
                                Ball {
                                    center: [1.0, 0.0, 0.0],
                                    radius: 1.5,
                                    strength: -0.5,
                                },
                            ],
                            threshold: 0.5,
                            kernel: BlobKernel::Wyvill,
                            material: 3,
                        }),
                        Node::Cluster(Cluster {
                            name: "empty".into(),
                            transform: Transform {
                                scale: [1.0, 2.0, 3.0],
                                ..Transform::default()
                            },
                            children: vec![],
                        }),
                    ],
                }),
            ],
        },
    };
    assert_eq!(got.camera, expected.camera);
    assert_eq!(got.materials, expected.materials);
    assert_eq!(got.textures, expected.textures);
    assert_eq!(got.lights, expected.lights);
    assert_eq!(got.root, expected.root);
    assert_eq!(got, expected);
}

#[test]
fn load_scene_reads_from_disk_relative_to_the_file() {
    let s = Scratch::new("load");
    write_assets(&s);
    s.write("example.ron", EXAMPLE.as_bytes());
    let scene = load_scene(&s.path().join("example.ron")).unwrap();
    assert_eq!(scene.textures.len(), 1);
    assert_eq!(scene.materials.len(), 5);

    let missing = s.path().join("nope.ron");
    let e = load_scene(&missing).unwrap_err();
    assert!(matches!(e, SceneError::Io { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("nope.ron: cannot read the scene file"),
        "{e}"
    );
}

#[test]
fn minimal_scene_gets_the_documented_defaults() {
    let text = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)))";
    let s = parse_scene(text, "min.ron", Path::new(".")).unwrap();
    assert_eq!(
        s,
        SceneDesc {
            camera: Camera {
                eye: [0.0, 0.0, -5.0],
                look_at: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: 45.0,
            },
            width: 512,
            height: 480,
            background: [0.0; 3],
            ambient: [0.1; 3],
            max_depth: 5,
            transparency: TransparencyMode::Refractive,
            materials: vec![],
            textures: vec![],
            lights: vec![],
            root: Cluster::default(),
        }
    );
    // Struct names may be written; `Some(...)` and plain values both work for options.
    let text = "Scene(camera: Camera(eye: (0, 0, -5), look_at: (0, 0, 0)), \
                root: Cluster(children: [Sphere(center: (0, 0, 0), radius: 1, \
                cut: Some(CutPlane(normal: (0, 0, 1))), material: None)]))";
    let s = parse_scene(text, "min.ron", Path::new(".")).unwrap();
    assert_eq!(s.materials, vec![Material::default()]);
    let Node::Shape(Shape::Ellipsoid { cut, material, .. }) = &s.root.children[0] else {
        panic!("{:?}", s.root.children[0]);
    };
    assert_eq!(*material, 0);
    assert_eq!(
        *cut,
        Some(CutPlane {
            normal: [0.0, 0.0, 1.0],
            offset: 0.0,
            capped: true
        })
    );
}

#[test]
fn a_material_named_default_is_used_for_unnamed_shapes() {
    let text = r#"Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),
        materials: { "x": (), "default": (diffuse: 0.5) },
        root: (children: [Sphere(center: (0, 0, 0), radius: 1)]))"#;
    let s = parse_scene(text, "d.ron", Path::new(".")).unwrap();
    assert_eq!(s.materials.len(), 2);
    let Node::Shape(Shape::Ellipsoid { material, .. }) = &s.root.children[0] else {
        panic!();
    };
    assert_eq!(*material, 1);
}

// ---- errors ------------------------------------------------------------------------------------

/// Lines 1-4 of the error scenes; the child under test is on line 5, indented 8 spaces.
const HEAD: &str = "Scene(
    camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),
    materials: { \"red\": () },
    root: (children: [
";
const TAIL: &str = "\n    ]),\n)\n";

fn with_child(child: &str) -> String {
    format!("{HEAD}        {child}{TAIL}")
}

fn error_in(text: &str, dir: &Path) -> SceneError {
    match parse_scene(text, "t.ron", dir) {
        Ok(s) => panic!("expected an error, parsed {s:?}"),
        Err(e) => e,
    }
}

/// (line, col, message) of an error in `text`, which must be Invalid or Syntax as `invalid` says.
fn located(text: &str, invalid: bool) -> (usize, usize, String) {
    let e = error_in(text, Path::new("."));
    let (file, line, col) = e.location().unwrap_or_else(|| panic!("no location: {e}"));
    assert_eq!(file, "t.ron");
    assert_eq!(
        matches!(e, SceneError::Invalid { .. }),
        invalid,
        "wrong kind: {e:?}"
    );
    assert_eq!(
        e.to_string(),
        format!("t.ron:{line}:{col}: {}", e.message())
    );
    (line, col, e.message())
}

/// 1-based (line, col) of the first occurrence of `needle`.
fn pos_of(text: &str, needle: &str) -> (usize, usize) {
    locate::line_col(text, text.find(needle).expect(needle))
}

#[test]
fn nan_radius_points_at_the_number() {
    let t = with_child("Sphere(center: (0, 0, 0), radius: NaN),");
    let (l, c, m) = located(&t, true);
    assert_eq!((l, c), (5, 43));
    assert_eq!((l, c), pos_of(&t, "NaN"));
    assert_eq!(m, "expected a finite radius, found NaN");
}

#[test]
fn zero_and_huge_radius() {
    let t = with_child("Sphere(center: (0, 0, 0), radius: 0),");
    assert_eq!(
        located(&t, true),
        (5, 43, "expected a positive radius, found 0".into())
    );
    // 1e400 overflows to infinity while parsing: still rejected, at the number.
    let t = with_child("Sphere(center: (0, 0, 0), radius: 1e400),");
    assert_eq!(
        located(&t, true),
        (5, 43, "expected a finite radius, found inf".into())
    );
}

/// Every number must survive the conversion to f32, the format the scene compiles to: not
/// beyond f32::MAX (it would become infinite) and not a non-zero below f32::MIN_POSITIVE (it
/// would become 0 or a subnormal).
#[test]
fn numbers_outside_the_f32_range_point_at_the_number() {
    let big = |what: &str, v: &str| {
        format!("expected {what} within the f32 range (about ±3.4e38), found {v}")
    };
    let tiny = |what: &str, v: &str| {
        format!(
            "expected {what} of at least about 1.2e-38 in magnitude (a smaller non-zero number \
             underflows f32), found {v}"
        )
    };
    let cases: &[(&str, &str, String)] = &[
        (
            "Sphere(center: (0, 0, 0), radius: 1e39),",
            "1e39",
            big("a radius", "1e39"),
        ),
        (
            "Sphere(center: (0, 0, 0), radius: 1e-45),",
            "1e-45",
            tiny("a radius", "1e-45"),
        ),
        // Already refused, but by the DM, with no position.
        (
            "Sphere(center: (0, 0, 0), radius: 1e-300),",
            "1e-300",
            tiny("a radius", "1e-300"),
        ),
        (
            "Sphere(center: (0, -1e39, 0), radius: 1),",
            "-1e39",
            big("a coordinate", "-1e39"),
        ),
        (
            "Sphere(center: (0, 2e-40, 0), radius: 1),",
            "2e-40",
            tiny("a coordinate", "2e-40"),
        ),
        (
            "Ellipsoid(center: (0, 0, 0), radii: (1, 3.5e38, 1)),",
            "3.5e38",
            big("a radius", "3.5e38"),
        ),
        (
            "Triangle(v: ((0, 0, 0), (1e39, 0, 0), (0, 1, 0))),",
            "1e39",
            big("a coordinate", "1e39"),
        ),
        (
            "Blobs(threshold: 1e-39, balls: [(center: (0, 0, 0), radius: 1)]),",
            "1e-39",
            tiny("a threshold", "1e-39"),
        ),
        (
            "Cluster(transform: (scale: 1e39)),",
            "1e39",
            big("a scale factor", "1e39"),
        ),
        (
            "Cluster(transform: (rotate: (0, 1e-40, 0))),",
            "1e-40",
            tiny("an angle", "1e-40"),
        ),
    ];
    for (child, at, want) in cases {
        let t = with_child(child);
        let (l, c, m) = located(&t, true);
        assert_eq!(&m, want, "{child}");
        assert_eq!((l, c), pos_of(&t, at), "{child}: {m}");
    }
    let cam = "camera: (eye: (0, 0, -5), look_at: (0, 0, 0))";
    let cases: &[(&str, &str, String)] = &[
        (
            "lights: [Point(pos: (1e39, 0, 0))]",
            "1e39",
            big("a coordinate", "1e39"),
        ),
        (
            "lights: [Spot(pos: (0, 0, 0), dir: (0, 0, 1), outer: 30, inner: 1e-45)]",
            "1e-45",
            tiny("a cone angle in degrees", "1e-45"),
        ),
        (
            "camera: (eye: (0, 0, -1e39), look_at: (0, 0, 0))",
            "-1e39",
            big("a coordinate", "-1e39"),
        ),
    ];
    for (field, at, want) in cases {
        let t = if field.starts_with("camera") {
            format!("Scene({field})")
        } else {
            format!("Scene({cam}, {field})")
        };
        let (l, c, m) = located(&t, true);
        assert_eq!(&m, want, "{field}");
        assert_eq!((l, c), pos_of(&t, at), "{field}: {m}");
    }
    // The extremes themselves are fine.
    let t = with_child("Sphere(center: (3.4028234e38, 1.1754944e-38, 0), radius: 1),");
    parse_scene(&t, "t.ron", Path::new(".")).unwrap();
}

/// Hexadecimal, octal, binary and `_` are refused as documented, at the number, with what
/// was wrong (ron read `0x10` as a 0 followed by junk, reported as "found 0", and `1_0` as
/// 10).
#[test]
fn non_decimal_numbers_and_separators_are_refused_at_the_number() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "Sphere(center: (0, 0, 0), radius: 0x10),",
            "0x10",
            "`0x10`: hexadecimal numbers are not accepted; write numbers in decimal",
        ),
        (
            "Sphere(center: (0, 0, 0), radius: 1_0),",
            "1_0",
            "`1_0`: `_` separators are not accepted in numbers",
        ),
        (
            "Sphere(center: (0, -0b11, 0), radius: 1),",
            "0b11",
            "`0b11`: binary numbers are not accepted; write numbers in decimal",
        ),
        (
            "Sphere(center: (0, 0, 0), radius: 0o7),",
            "0o7",
            "`0o7`: octal numbers are not accepted; write numbers in decimal",
        ),
        (
            "Sphere(center: (0, 0, 1.5e1_0), radius: 1),",
            "1.5e1_0",
            "`1.5e1_0`: `_` separators are not accepted in numbers",
        ),
    ];
    for (child, at, want) in cases {
        let t = with_child(child);
        let (l, c, m) = located(&t, false);
        assert_eq!(&m, want, "{child}");
        assert_eq!((l, c), pos_of(&t, at), "{child}");
    }
    // Integers too (ron reads `0x100` as 256).
    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)), image: (width: 0x100))";
    let (l, c, m) = located(t, false);
    assert_eq!(
        m,
        "`0x100`: hexadecimal numbers are not accepted; write numbers in decimal"
    );
    assert_eq!((l, c), pos_of(t, "0x100"));
    // Digits and underscores inside names, strings and comments are not numbers.
    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)), max_depth: 3, // 0x10 1_0
        /* 0b1 /* 2_2 */ */ materials: { \"m_1\": (), r\"0x_\": (), r#\"a\"0x1\"#: () },
        transparency: NonRefractive, root: (name: \"c_0x1\", children: []))";
    let s = parse_scene(t, "t.ron", Path::new(".")).unwrap();
    assert_eq!(s.materials.len(), 3);
    assert_eq!(s.root.name, "c_0x1");
}

#[test]
fn zero_direction_points_at_the_vector() {
    let t = with_child("Sphere(center: (0, 0, 0), radius: 1, cut: (normal: (0, 0, 0))),");
    let (l, c, m) = located(&t, true);
    assert_eq!((l, c), (5, 60));
    assert_eq!((l, c), pos_of(&t, "(0, 0, 0)))"));
    assert_eq!(
        m,
        "expected a direction (a non-zero vector), found (0, 0, 0)"
    );

    let t = "Scene(
    camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),
    lights: [
        Point(pos: (1, 2, 3)),
        Directional(dir: (0, 0, 0), color: 1),
    ],
)";
    let (l, c, m) = located(t, true);
    assert_eq!((l, c), (5, 26));
    assert!(m.starts_with("expected a direction"), "{m}");
}

#[test]
fn degenerate_triangle_points_at_its_vertices() {
    let t = with_child("Triangle(v: ((0, 0, 0), (1, 1, 1), (2, 2, 2))),");
    let (l, c, m) = located(&t, true);
    assert_eq!((l, c), (5, 21));
    assert!(m.starts_with("degenerate triangle"), "{m}");
}

#[test]
fn unknown_material_points_at_the_name() {
    let t = with_child("Sphere(center: (0, 0, 0), radius: 1, material: \"blue\"),");
    let (l, c, m) = located(&t, true);
    assert_eq!((l, c), (5, 56));
    assert_eq!((l, c), pos_of(&t, "\"blue\""));
    assert_eq!(
        m,
        "unknown material \"blue\"; the scene defines materials \"red\""
    );
    // A cluster's material is checked even when no shape uses it; names with escapes work too.
    let t = with_child("Cluster(material: \"b\\u{6c}ue\"),");
    let (l, c, m) = located(&t, true);
    assert_eq!((l, c), (5, 27));
    assert!(m.starts_with("unknown material \"blue\""), "{m}");
}

#[test]
fn unknown_texture_and_duplicate_names() {
    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),
    materials: {
        \"a\": (map: (texture: \"wood\")),
    })";
    let (l, c, m) = located(t, true);
    assert_eq!((l, c), (3, 30));
    assert_eq!((l, c), pos_of(t, "\"wood"));
    assert_eq!(m, "unknown texture \"wood\"; the scene defines no textures");

    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),
    materials: { \"a\": (), \"b\": (), \"a\": () })";
    let (l, c, m) = located(t, true);
    assert_eq!((l, c), (2, 36));
    assert_eq!(m, "the name \"a\" is defined twice");
}

#[test]
fn missing_mesh_file_points_at_the_path() {
    let s = Scratch::new("missing-mesh");
    let t = with_child("Mesh(file: \"nope.obj\"),");
    let e = error_in(&t, s.path());
    let SceneError::Asset {
        line,
        col,
        kind,
        ref path,
        ..
    } = e
    else {
        panic!("{e:?}");
    };
    assert_eq!((line, col, kind), (5, 20, "mesh"));
    assert_eq!(*path, s.path().join("nope.obj"));
    assert!(
        e.to_string()
            .starts_with("t.ron:5:20: cannot read mesh file "),
        "{e}"
    );
}

#[test]
fn oversized_and_special_asset_files_are_refused_at_the_path() {
    let s = Scratch::new("big-assets");
    // Sparse files one byte over the limits: nothing is written to disk or read.
    let big = |rel: &str, len: u64| {
        let f = std::fs::File::create(s.path().join(rel)).unwrap();
        f.set_len(len).unwrap();
    };
    big("assets/big.obj", crate::limits::MAX_MESH_BYTES + 1);
    big("assets/big.png", crate::limits::MAX_TEXTURE_BYTES + 1);

    let t = with_child("Mesh(file: \"assets/big.obj\"),");
    let e = error_in(&t, s.path());
    assert!(matches!(e, SceneError::Asset { kind: "mesh", .. }), "{e:?}");
    assert_eq!(
        e.to_string(),
        format!(
            "t.ron:5:20: cannot read mesh file {}: it is 67108865 bytes, over the 64 MiB \
             (67108864 bytes) limit for a mesh file",
            s.path().join("assets/big.obj").display()
        )
    );

    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),\n  textures: {\"t\": \"assets/big.png\"})";
    let e = error_in(t, s.path());
    assert_eq!(
        e.to_string(),
        format!(
            "t.ron:2:19: cannot read texture file {}: it is 67108865 bytes, over the 64 MiB \
             (67108864 bytes) limit for a texture file",
            s.path().join("assets/big.png").display()
        )
    );

    // A device never ends: refused unread (absolute paths are allowed).
    #[cfg(unix)]
    {
        let t = with_child("Mesh(file: \"/dev/zero\"),");
        let e = error_in(&t, s.path());
        assert_eq!(
            e.to_string(),
            "t.ron:5:20: cannot read mesh file /dev/zero: it is a character device, not a \
             regular file"
        );
    }
}

#[test]
fn missing_texture_file_points_at_the_path() {
    let s = Scratch::new("missing-png");
    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),\n  textures: {\"t\": \"t.png\"})";
    let e = error_in(t, s.path());
    assert!(
        matches!(
            e,
            SceneError::Asset {
                kind: "texture",
                ..
            }
        ),
        "{e:?}"
    );
    assert_eq!(e.location(), Some(("t.ron", 2, 19)));
}

#[test]
fn bad_obj_line_names_the_obj_file() {
    let s = Scratch::new("bad-obj");
    s.write("assets/bad.obj", b"v 0 0 0\nv 1 0 0\nv 1 0 zz\nf 1 2 3\n");
    let t = with_child("Mesh(file: \"assets/bad.obj\"),");
    let e = error_in(&t, s.path());
    let SceneError::Obj {
        ref file,
        line,
        col,
        ref message,
    } = e
    else {
        panic!("{e:?}");
    };
    assert!(file.ends_with("bad.obj"), "{file}");
    assert_eq!((line, col), (Some(3), Some(7)));
    assert_eq!(message, "expected a number, found `zz`");
    assert!(
        e.to_string()
            .ends_with("bad.obj:3:7: expected a number, found `zz`"),
        "{e}"
    );
}

#[test]
fn shape_level_checks_point_at_the_shape() {
    let t = with_child("Box(min: (0, 0, 0), max: (1, 0, 1)),");
    let (l, c, m) = located(&t, true);
    assert_eq!((l, c), (5, 9));
    assert_eq!(
        m,
        "a box needs min < max on every axis, but on y min = 0 and max = 0"
    );

    let t =
        with_child("Blobs(threshold: 1, balls: [(center: (0, 0, 0), radius: 1, strength: -1)]),");
    let (l, c, m) = located(&t, true);
    assert_eq!((l, c), (5, 9));
    assert!(m.contains("positive strength"), "{m}");

    let t =
        with_child("Sphere(center: (0, 0, 0), radius: 1, cut: (normal: (0, 1, 0), offset: -1)),");
    let (l, c, m) = located(&t, true);
    assert_eq!((l, c), (5, 9));
    assert!(
        m.starts_with("the cut plane removes the whole ellipsoid"),
        "{m}"
    );
}

#[test]
fn camera_checks() {
    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0), up: (0, 0, 2)))";
    let (l, c, m) = located(t, true);
    assert_eq!((l, c), (1, 15));
    assert!(m.contains("is parallel to its view direction"), "{m}");

    let t = "Scene(camera: (eye: (1, 1, 1), look_at: (1, 1, 1)))";
    let (_, c, m) = located(t, true);
    assert_eq!(c, 15);
    assert!(m.contains("same point"), "{m}");

    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0), fov_y: 180))";
    assert_eq!(
        located(t, true),
        (
            1,
            60,
            "expected a vertical field of view in degrees strictly between 0 and 180, found 180"
                .into()
        )
    );
}

#[test]
fn element_errors_point_at_the_element() {
    // A bad component inside a tuple is reported at the component, not the tuple.
    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),
    materials: { \"red\": (diffuse: (1, -0.5, 0)) })";
    assert_eq!(
        located(t, true),
        (
            2,
            39,
            "expected a colour coefficient between 0 and 1, found -0.5".into()
        )
    );
    let t = "Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)), image: (width: 0))";
    assert_eq!(
        located(t, true),
        (
            1,
            69,
            "expected an image size in pixels between 1 and 4096, found 0".into()
        )
    );
}

#[test]
fn syntax_errors_come_from_ron_with_positions() {
    // Missing comma: at the token where the comma should be.
    let t = with_child("Sphere(center: (0, 0, 0) radius: 1),");
    let (l, c, m) = located(&t, false);
    assert_eq!((l, c), (5, 34), "{m}");
    assert_eq!(m, "Expected comma");

    // Missing field: at the start of the struct that lacks it.
    let t = with_child("/* ) */ Sphere(center: (0, 0, 0)),");
    let (l, c, m) = located(&t, false);
    assert_eq!((l, c), (5, 17));
    assert_eq!(m, "missing field `radius` in `Sphere`");

    // Wrong vector length: at the vector.
    let t = with_child("Sphere(center: (0, 0), radius: 1),");
    let (l, c, m) = located(&t, false);
    assert_eq!((l, c), (5, 24));
    assert!(m.contains("3-tuple"), "{m}");

    // Typo in a field name.
    let t = with_child("Sphere(center: (0, 0, 0), radious: 1),");
    let (l, c, m) = located(&t, false);
    assert_eq!((l, c), (5, 35));
    assert!(m.starts_with("Unexpected field named `radious`"), "{m}");

    // Unknown shape.
    let t = with_child("Cone(),");
    let (l, c, m) = located(&t, false);
    assert_eq!((l, c), (5, 9));
    assert!(m.starts_with("Unexpected variant named `Cone`"), "{m}");
}

#[test]
fn flexible_syntax_is_accepted() {
    let text = "#![enable(implicit_some)]\r\n\
        // CRLF line ends, struct names, [lists], Some(..), trailing commas\r\n\
        Scene(\r\n\
        \x20 camera: Camera(eye: [0, 0, -5], look_at: (0, 0, 0), fov_y: 60.5,),\r\n\
        \x20 materials: {\"m\": Material(specular: 0.5, specular_edge: Some(0.75), reflect_edge: 0.5)},\r\n\
        \x20 lights: [Spot(pos: (0, 0, 0), dir: (0, 0, 1), outer: 30)],\r\n\
        \x20 root: (transform: (scale: (1, 2, 3)), children: [\r\n\
        \x20   Ellipsoid (center: (0,0,0), radii: 2, material: Some(\"m\")),\r\n\
        \x20 ]),\r\n\
        )\r\n";
    let s = parse_scene(text, "f.ron", Path::new(".")).unwrap();
    assert_eq!(s.camera.fov_y_deg, 60.5);
    let m = &s.materials[0];
    assert_eq!(
        (m.specular, m.specular_edge, m.reflect, m.reflect_edge),
        (0.5, 0.75, 0.0, 0.5)
    );
    assert_eq!(
        s.lights[0],
        Light::Spot {
            pos: [0.0; 3],
            dir: [0.0, 0.0, 1.0],
            color: [1.0; 3],
            inner_deg: 30.0,
            outer_deg: 30.0,
            exponent: 0.0,
        }
    );
    assert_eq!(s.root.transform.scale, [1.0, 2.0, 3.0]);
    let Node::Shape(Shape::Ellipsoid {
        radii, material, ..
    }) = &s.root.children[0]
    else {
        panic!();
    };
    assert_eq!((*radii, *material), ([2.0; 3], 0));

    // Positions are right with CRLF line ends too.
    let t = with_child("Sphere(center: (0, 0, 0), radius: -1),").replace('\n', "\r\n");
    assert_eq!(
        located(&t, true),
        (5, 43, "expected a positive radius, found -1".into())
    );
}

#[test]
fn more_range_checks() {
    let cam = "camera: (eye: (0, 0, -5), look_at: (0, 0, 0))";
    let cases: &[(&str, &str)] = &[
        ("max_depth: 17", "expected a maximum ray depth between 0 and 16, found 17"),
        ("ambient: (0.1, -1, 0)", "expected a non-negative colour component, found -1"),
        ("materials: {\"m\": (ior: 0.9)}", "expected an index of refraction of at least 1, found 0.9"),
        ("materials: {\"m\": (reflect: 1.5)}", "expected a coefficient between 0 and 1, found 1.5"),
        ("materials: {\"m\": (shininess: -2)}", "expected a non-negative shininess exponent, found -2"),
        ("materials: {\"m\": (transmit: 3e38, diffuse: 1e39)}", "expected a colour coefficient between 0 and 1, found 3e38"),
        ("lights: [Point(pos: (0, 0, 0), color: 1e39)]", "expected a colour component within the f32 range (about ±3.4e38), found 1e39"),
        ("lights: [Point(pos: (0, 0, 0), color: 1e-40)]", "expected a colour component of at least about 1.2e-38 in magnitude (a smaller non-zero number underflows f32), found 1e-40"),
        ("lights: [Spot(pos: (0, 0, 0), dir: (0, 0, 1), inner: 40, outer: 30)]", "a spot light's inner angle (40) must not exceed its outer angle (30)"),
        ("lights: [Spot(pos: (0, 0, 0), dir: (0, 0, 1), outer: 180)]", "expected a cone angle in degrees below 180, found 180"),
        ("root: (transform: (scale: (1, 0, 1)))", "expected a positive scale factor, found 0"),
        ("root: (children: [Blobs(threshold: 0, balls: [])])", "expected a positive threshold, found 0"),
        ("root: (children: [Blobs(threshold: 1, balls: [])])", "a Blobs shape needs at least one ball"),
        ("root: (children: [Blobs(threshold: 1, balls: [(center: (0, 0, 0), radius: 1, strength: 0)])])", "expected a non-zero strength, found 0"),
        ("root: (children: [Triangle(v: ((0, 0, 0), (1, 0, 0), (0, 1, 0)), normals: ((0, 0, 1), (0, 0, 0), (0, 0, 1)))])", "expected three non-zero normals, found (0, 0, 0)"),
        ("root: (children: [Sphere(center: 0, radius: 1)])", "expected a coordinate written as a 3-tuple (x, y, z), found the single number 0"),
    ];
    for (field, want) in cases {
        let t = format!("Scene({cam}, {field})");
        let (l, c, m) = located(&t, true);
        assert_eq!(&m, want, "{field}");
        assert_eq!(l, 1, "{field}");
        assert!(c > cam.len() + 7, "{field}: column {c} is not in the field");
    }
}

#[test]
fn clusters_nest_fifty_deep() {
    fn nested(depth: usize) -> String {
        let mut inner = String::from("Sphere(center: (0, 0, 0), radius: 1)");
        for _ in 0..depth {
            inner = format!("Cluster(children: [{inner}])");
        }
        format!("Scene(camera: (eye: (0, 0, -5), look_at: (0, 0, 0)), root: (children: [{inner}]))")
    }
    // On a small (1 MiB) stack, to leave room for larger frames in unoptimised builds.
    std::thread::Builder::new()
        .stack_size(1 << 20)
        .spawn(|| {
            let mut s = parse_scene(&nested(50), "n.ron", Path::new(".")).unwrap();
            for _ in 0..50 {
                let Some(Node::Cluster(c)) = s.root.children.pop() else {
                    panic!()
                };
                s.root = c;
            }
            let e = parse_scene(&nested(55), "n.ron", Path::new(".")).unwrap_err();
            assert!(e.message().starts_with("nested too deeply"), "{e}");
        })
        .unwrap()
        .join()
        .unwrap();
}

/// The ```ron blocks of docs/scene-format.md.
fn doc_examples() -> Vec<String> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/scene-format.md");
    let doc = std::fs::read_to_string(&path).unwrap();
    doc.split("```ron\n")
        .skip(1)
        .map(|b| b.split("```").next().unwrap().to_string())
        .collect()
}

#[test]
fn the_documentation_examples_parse() {
    let blocks = doc_examples();
    assert_eq!(
        blocks.len(),
        4,
        "hello, cluster tree, film, complete example"
    );
    // The complete example is this module's EXAMPLE.
    assert_eq!(blocks[3], EXAMPLE);
    let film = parse_film(&blocks[2], "film.ron", Path::new(".")).unwrap();
    assert_eq!(film.timeline().frames(), 0..48);
    // Five as written and the specular edge that follows "red"'s specular.
    assert_eq!(film.tracks().len(), 6);
    film.scene_at(47).unwrap();
    parse_scene(&blocks[0], "hello.ron", Path::new(".")).unwrap();
    let tree = format!(
        "Scene(camera: (eye: (0, 1, -5), look_at: (0, 1, 0)), {})",
        blocks[1].trim().trim_end_matches(',')
    );
    let s = parse_scene(&tree, "tree.ron", Path::new(".")).unwrap();
    let Node::Cluster(arm) = &s.root.children[0] else {
        panic!()
    };
    assert_eq!(arm.transform.rotate_deg, [0.0, 0.0, -20.0]);
}
