//! Films: `links render --frames` writes the same frames on the host and on the simulated
//! cluster, and a moving cluster's boxes and screen rectangles contain its shapes at every
//! frame (the DM compiles each frame afresh).

use std::path::{Path, PathBuf};

use links_core::anim::{
    Film, Interpolation, Key, Keys, Target, Timeline, Track, TransformProperty,
};
use links_core::desc::*;
use links_core::dm::CompileOptions;
use links_core::geom::Vec3;
use links_core::image::{SceneView, ShapeKind};
use links_host::cli::film::{frame_file_name, FILM_FILE_NAME};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

/// An empty scratch directory, removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("links-films-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        Scratch(dir)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// `links render <args> -o <dir>/ --quiet`, through the library.
fn links_render(args: &[&str], dir: &Path) -> Result<(), String> {
    let out = format!("{}/", dir.display());
    let mut argv = vec!["links", "render"];
    argv.extend_from_slice(args);
    argv.extend_from_slice(&["-o", &out, "--quiet"]);
    links_host::cli::run_from(argv).map_err(|e| e.to_string())
}

#[test]
fn photo1_orbit_frames_differ_and_the_cluster_writes_the_same_bytes() {
    let scene = repo("scenes/photo1-orbit.ron");
    let scene = scene.to_str().unwrap();
    let common = [scene, "--frames", "0..4", "--width", "64", "--height", "60"];
    let host = Scratch::new("host");
    let cluster = Scratch::new("cluster");
    links_render(&common, &host.0).unwrap();
    let mut with_nodes = common.to_vec();
    with_nodes.extend_from_slice(&["--nodes", "16"]);
    links_render(&with_nodes, &cluster.0).unwrap();
    let read = |dir: &Path, name: &str| std::fs::read(dir.join(name)).unwrap();
    let frames: Vec<Vec<u8>> = (0..4).map(|f| read(&host.0, &frame_file_name(f))).collect();
    for (f, bytes) in frames.iter().enumerate() {
        let (w, h, _) = links_host::frame::decode_png_rgb(bytes).unwrap();
        assert_eq!((w, h), (64, 60));
        assert!(
            *bytes == read(&cluster.0, &frame_file_name(f as u32)),
            "frame {f}: the 16-node cluster wrote different bytes"
        );
        for (g, other) in frames.iter().enumerate().take(f) {
            assert!(bytes != other, "frames {g} and {f} are the same picture");
        }
    }
    assert!(!host.0.join(frame_file_name(4)).exists());
    assert_eq!(
        read(&host.0, FILM_FILE_NAME),
        read(&cluster.0, FILM_FILE_NAME)
    );
    // The animated PNG holds the four frames.
    let film = read(&host.0, FILM_FILE_NAME);
    let reader = png::Decoder::new(std::io::Cursor::new(film))
        .read_info()
        .unwrap();
    assert_eq!(reader.info().animation_control.unwrap().num_frames, 4);
}

/// A glTF animation from a real exporter (BoxAnimated, Cesium, CC BY 4.0) renders as a film:
/// its frames differ, and the simulated cluster writes the same files.
#[test]
fn a_gltf_animation_renders_as_a_film_on_host_and_cluster_alike() {
    let model = repo("tests/assets/gltf/BoxAnimated/BoxAnimated.gltf");
    let model = model.to_str().unwrap();
    // Frames 0, 1, 2: the inner box rising (the translation channel's first segment).
    let common = [model, "--frames", "0..3", "--width", "48", "--height", "45"];
    let host = Scratch::new("gltf-host");
    let cluster = Scratch::new("gltf-cluster");
    links_render(&common, &host.0).unwrap();
    let mut with_nodes = common.to_vec();
    with_nodes.extend_from_slice(&["--nodes", "4"]);
    links_render(&with_nodes, &cluster.0).unwrap();
    let read = |dir: &Path, f: u32| std::fs::read(dir.join(frame_file_name(f))).unwrap();
    for f in 0..3 {
        assert!(read(&host.0, f) == read(&cluster.0, f), "frame {f}");
    }
    assert!(read(&host.0, 0) != read(&host.0, 1) && read(&host.0, 1) != read(&host.0, 2));
    // Its frames are 0..89 (3.708 s at 24 per second): 89..90 is outside.
    let e = links_render(&[model, "--frames", "88..90"], &host.0).unwrap_err();
    assert!(e.contains("has frames 0..89"), "{e}");
}

#[test]
fn film_render_errors_are_clear() {
    let orbit = repo("scenes/photo1-orbit.ron");
    let still = repo("scenes/photo1.ron");
    let dir = Scratch::new("errors");
    let run = |scene: &Path, frames: &str| {
        let args = [
            scene.to_str().unwrap(),
            "--frames",
            frames,
            "--width",
            "8",
            "--height",
            "6",
        ];
        links_render(&args, &dir.0)
    };
    let e = run(&orbit, "3..3").unwrap_err();
    assert!(e.contains("the range is empty"), "{e}");
    let e = run(&orbit, "40..49").unwrap_err();
    assert!(e.contains("has frames 0..48"), "{e}");
    let e = run(&still, "0..2").unwrap_err();
    assert!(
        e.contains("is a still scene: it has the one frame 0..1"),
        "{e}"
    );
    // A still scene's one frame renders.
    run(&still, "0..1").unwrap();
    assert!(dir.0.join(frame_file_name(0)).is_file());
    // -o naming a file.
    let file = dir.0.join(frame_file_name(0));
    let args = [orbit.to_str().unwrap(), "--frames", "0..1"];
    let mut argv = vec!["links", "render"];
    argv.extend_from_slice(&args);
    argv.extend_from_slice(&["-o", file.to_str().unwrap(), "--quiet"]);
    let e = links_host::cli::run_from(argv).unwrap_err().to_string();
    assert!(
        e.contains("the output is a directory, and this is a file"),
        "{e}"
    );
}

// ---- a moving cluster's boxes and rectangles ---------------------------------------------------

/// A cluster of two triangles and an ellipsoid that flies across the view and turns.
fn moving_film() -> Film {
    let tri = |v| {
        Node::Shape(Shape::Triangle {
            v,
            normals: None,
            uv: None,
            material: 0,
        })
    };
    let children = vec![
        tri([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.5, 0.3]]),
        tri([[-1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [1.0, 0.0, 0.0]]),
        Node::Shape(Shape::Ellipsoid {
            center: [0.0, 0.5, -0.5],
            radii: [0.6, 0.3, 0.4],
            rotate_deg: [0.0, 0.0, 30.0],
            cut: None,
            material: 0,
        }),
    ];
    let mover = Cluster {
        name: "mover".into(),
        transform: Transform::default(),
        children,
    };
    let camera = Camera {
        eye: [0.0, 1.0, -10.0],
        look_at: [0.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 40.0,
    };
    let floor = Node::Shape(Shape::Box {
        min: [-4.0, -2.0, -4.0],
        max: [4.0, -1.5, 4.0],
        material: 0,
    });
    let scene = SceneDesc {
        materials: vec![Material::default()],
        ..links_core::testkit::scene::scene_desc(camera, 48, 36, vec![floor, Node::Cluster(mover)])
    };
    let key = |frame: f64, value| Key { frame, value };
    let path = vec![1];
    let tracks = vec![
        Track {
            target: Target::Cluster {
                path: path.clone(),
                property: TransformProperty::Translate,
            },
            interpolation: Interpolation::Smooth,
            keys: Keys::Vector(vec![
                key(0.0, [-4.0, 0.0, 0.0]),
                key(5.0, [0.0, 1.5, 2.0]),
                key(11.0, [4.0, -0.5, -3.0]),
            ]),
        },
        Track {
            target: Target::Cluster {
                path,
                property: TransformProperty::Rotate,
            },
            interpolation: Interpolation::Linear,
            keys: Keys::Vector(vec![key(0.0, [0.0; 3]), key(11.0, [40.0, 200.0, -30.0])]),
        },
    ];
    let timeline = Timeline {
        start: 0,
        end: 12,
        rate: 12.0,
    };
    Film::new(scene, timeline, tracks).unwrap()
}

/// Points of leaf `leaf`'s shapes in view coordinates (triangle corners, ellipsoid surface
/// samples) and its triangles.
fn leaf_points(v: &SceneView<'_>, leaf: u32) -> (Vec<Vec3<f64>>, Vec<[Vec3<f64>; 3]>) {
    let Some(l) = v.node::<f64>(leaf).leaf else {
        return (Vec::new(), Vec::new());
    };
    let (mut pts, mut tris) = (Vec::new(), Vec::new());
    for k in 0..l.count {
        match l.kind {
            ShapeKind::Triangle => {
                let p = v.triangle::<f64>(l.first + k).tri.p;
                pts.extend(p);
                tris.push(p);
            }
            ShapeKind::Ellipsoid => {
                let e = v.ellipsoid::<f64>(l.first + k).shape;
                for a in 0..24 {
                    for b in 0..12 {
                        let (th, ph) = (f64::from(a) * 0.2618, f64::from(b) * 0.2618 + 0.1);
                        let q = Vec3::new(ph.sin() * th.cos(), ph.cos(), ph.sin() * th.sin());
                        pts.push(e.center + e.l.mul_vec(q));
                    }
                }
            }
            _ => {}
        }
    }
    (pts, tris)
}

/// The pixels whose centre ray passes inside triangle `t` (view coordinates, in front).
fn covered_pixels(v: &SceneView<'_>, t: &[Vec3<f64>; 3]) -> Vec<(u16, u16)> {
    let c = v.camera::<f64>();
    let s = t.map(|p| (p.x / p.z * c.dz, p.y / p.z * c.dz));
    let edge = |a: (f64, f64), b: (f64, f64), p: (f64, f64)| {
        (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0)
    };
    let mut out = Vec::new();
    for y in 0..c.height {
        for x in 0..c.width {
            let p = (
                c.x0 + (f64::from(x) + 0.5) * c.dx,
                c.y0 - (f64::from(y) + 0.5) * c.dy,
            );
            let e = [
                edge(s[0], s[1], p),
                edge(s[1], s[2], p),
                edge(s[2], s[0], p),
            ];
            if e.iter().all(|&d| d > 1e-9) || e.iter().all(|&d| d < -1e-9) {
                out.push((x as u16, y as u16));
            }
        }
    }
    out
}

#[test]
fn a_moving_clusters_boxes_and_rectangles_contain_its_shapes_at_every_frame() {
    let film = moving_film();
    let mut leaf_rects = Vec::new();
    for frame in film.timeline().frames() {
        let img = film
            .compile_frame(frame, &CompileOptions::default())
            .unwrap()
            .bytes;
        let v = SceneView::new(&img).unwrap();
        assert!(v.has_rects());
        let mut covered_somewhere = 0;
        for leaf in 0..v.node_count() {
            let (pts, tris) = leaf_points(&v, leaf);
            let pixels: Vec<(u16, u16)> = tris
                .iter()
                .filter(|t| t.iter().all(|p| p.z > 0.0))
                .flat_map(|t| covered_pixels(&v, t))
                .collect();
            covered_somewhere += pixels.len();
            // The leaf and every cluster above it (nodes i <= leaf < skip).
            for i in (0..=leaf).filter(|&i| v.node::<f64>(i).skip > leaf) {
                let n = v.node::<f64>(i);
                for p in &pts {
                    assert!(
                        n.bounds.contains(*p),
                        "frame {frame}: node {i} misses {p:?}"
                    );
                }
                let r = v.rect(i);
                for &(x, y) in &pixels {
                    let inside = (r.x_lo..=r.x_hi).contains(&x) && (r.y_lo..=r.y_hi).contains(&y);
                    assert!(
                        inside,
                        "frame {frame}: node {i} rect {r:?} misses pixel ({x}, {y})"
                    );
                }
            }
            if !pixels.is_empty() {
                let r = v.rect(leaf);
                leaf_rects.push((r.x_lo, r.x_hi, r.y_lo, r.y_hi));
            }
        }
        assert!(
            covered_somewhere > 0,
            "frame {frame}: the triangles cover no pixel"
        );
    }
    // The rectangles follow the motion: they are not all the same.
    leaf_rects.sort_unstable();
    leaf_rects.dedup();
    assert!(leaf_rects.len() > 6, "{leaf_rects:?}");
}
