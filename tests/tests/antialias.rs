//! Anti-aliasing (`--aa N`): N x N primary rays per pixel through the centres of a regular
//! sub-pixel grid, averaged on the node. One sample is today's exact pixels; an edge through
//! a pixel's centre gives the analytic mean; clipping stays exact for sub-pixel rays; the
//! cluster writes the host's frame.

use links_core::desc::*;
use links_core::dm::{compile, CompileOptions};
use links_core::fixed_image::to_fixed;
use links_core::image::{camera, SceneView, Section};
use links_core::num::{Fx, Real};
use links_core::render::Techniques;
use links_host::scene_file::load_scene;
use links_tests::*;
use std::path::{Path, PathBuf};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

fn with_aa(desc: &SceneDesc, aa: u32, w: u32, h: u32) -> Vec<u8> {
    let opts = CompileOptions {
        width: Some(w),
        height: Some(h),
        aa: Some(aa),
        ..CompileOptions::default()
    };
    compile(desc, &opts).expect("scene compiles").bytes
}

/// A white quad covering view x >= 0 (z = 5, ambient light only, white ambient) on a black
/// background, seen by a `w` x 3 camera: with `w` odd, the quad's left edge runs through the
/// centre of column `w / 2`.
fn half_plane(w: u32) -> SceneDesc {
    let z = -5.0;
    let tri = |v: [[f64; 3]; 3]| Shape::Triangle {
        v,
        normals: None,
        uv: None,
        material: 0,
    };
    let mut s = scene(
        w,
        3,
        30.0,
        vec![
            tri([[0.0, -10.0, z], [10.0, -10.0, z], [10.0, 10.0, z]]),
            tri([[0.0, -10.0, z], [10.0, 10.0, z], [0.0, 10.0, z]]),
        ],
    );
    s.background = [0.0; 3];
    s.ambient = [1.0; 3];
    s.lights.clear();
    s.materials[0] = matte("white", [1.0; 3]);
    s
}

fn rows<T: Real>(image: &[u8]) -> Vec<u8> {
    render_all::<T>(image)
}

#[test]
fn a_vertical_edge_through_a_pixel_centre_averages_to_half_grey() {
    let w = 5;
    let desc = half_plane(w);
    for n in [2, 4, 8] {
        let img = with_aa(&desc, n, w, 3);
        let fixed = to_fixed(&img).expect("fits Q16.16").bytes;
        for (name, px) in [
            ("f32", rows::<f32>(&img)),
            ("f64", rows::<f64>(&img)),
            ("Q16.16", rows::<Fx>(&fixed)),
        ] {
            for y in 0..3usize {
                let at = |x: usize| &px[(y * w as usize + x) * 3..][..3];
                // Half of the N x N sub-pixel centres lie right of the edge: 127.5 -> 128.
                for k in 0..3 {
                    let v = at(2)[k] as i32;
                    assert!(
                        (v - 128).abs() <= 1,
                        "{name} N={n} row {y}: edge pixel {:?}, want 128 +- 1",
                        at(2)
                    );
                }
                assert_eq!(at(0), [0, 0, 0], "{name} N={n}: left of the edge");
                assert_eq!(at(1), [0, 0, 0], "{name} N={n}: left of the edge");
                assert_eq!(at(3), [255, 255, 255], "{name} N={n}: right of the edge");
                assert_eq!(at(4), [255, 255, 255], "{name} N={n}: right of the edge");
            }
        }
    }
}

/// With N = 3, a third of the sub-pixel columns of the edge pixel (the one at offset 5/6)
/// lie right of an edge a quarter pixel right of its centre: 255/3 = 85.
#[test]
fn an_edge_off_the_centre_gives_the_covered_share_of_the_sub_samples() {
    let w = 5;
    let mut desc = half_plane(w);
    // Pixel width in view units at z = 5 (fov 30 degrees over 3 rows).
    let px = 5.0 * 2.0 * (15.0f64.to_radians()).tan() / 3.0;
    let shift = 0.25 * px;
    for node in &mut desc.root.children {
        if let Node::Shape(Shape::Triangle { v, .. }) = node {
            for p in v.iter_mut() {
                if p[0] == 0.0 {
                    p[0] = shift;
                }
            }
        }
    }
    let img = with_aa(&desc, 3, w, 3);
    let got = rows::<f64>(&img);
    for y in 0..3usize {
        assert_eq!(&got[(y * 5 + 2) * 3..][..3], [85, 85, 85], "row {y}");
    }
}

#[test]
fn one_sample_is_the_default_image_and_each_pixel_traces_n_squared_primary_rays() {
    let desc = load_scene(&repo("scenes/photo1.ron")).expect("photo1 loads");
    let (w, h) = (24, 18);
    let plain = compile(
        &desc,
        &CompileOptions {
            width: Some(w),
            height: Some(h),
            ..CompileOptions::default()
        },
    )
    .expect("compiles")
    .bytes;
    assert_eq!(with_aa(&desc, 1, w, h), plain, "--aa 1 is today's image");
    for n in [1u32, 2, 3] {
        let img = with_aa(&desc, n, w, h);
        let view = SceneView::new(&img).expect("valid");
        assert_eq!(view.camera::<f32>().aa, n);
        let (_, stats) = render_all_with::<f32>(&img, Techniques::ALL);
        assert_eq!(stats.primary_rays, u64::from(w * h * n * n), "N={n}");
    }
}

/// Sub-pixel rays of pixel x stay inside the rectangles the DM gave the nodes of column x:
/// with and without Y/X clipping every pixel is the same.
#[test]
fn clipped_equals_unclipped_with_three_by_three_samples() {
    let unclipped = Techniques {
        y_clip: false,
        x_clip: false,
        ..Techniques::ALL
    };
    for name in [
        "photo1",
        "photo2",
        "metaballs",
        "reflections",
        "ellipsoids",
        "glass",
    ] {
        let path = repo(&format!("scenes/{name}.ron"));
        let desc = load_scene(&path).expect("scene loads");
        let img = with_aa(&desc, 3, 40, 30);
        assert!(SceneView::new(&img).expect("valid").has_rects());
        let (clipped, cs) = render_all_with::<f32>(&img, Techniques::ALL);
        let (plain, _) = render_all_with::<f32>(&img, unclipped);
        assert!(cs.clip_compares > 0, "{name}: clipping was used");
        assert!(clipped == plain, "{name}: clipping changed a pixel");
        let one = with_aa(&desc, 1, 40, 30);
        assert!(
            render_all::<f32>(&one) != clipped,
            "{name}: --aa 3 changes edges"
        );
    }
}

#[test]
fn the_image_validates_the_sample_grid() {
    let desc = half_plane(5);
    let img = with_aa(&desc, 8, 5, 3);
    assert_eq!(SceneView::new(&img).expect("valid").camera::<f32>().aa, 8);
    let flags_at = {
        let off = u32::from_le_bytes(img[16..20].try_into().unwrap()) as usize;
        assert_eq!(Section::Camera as usize, 0);
        off + camera::FLAGS
    };
    let flags = u32::from_le_bytes(img[flags_at..flags_at + 4].try_into().unwrap());
    assert_eq!((flags & camera::AA_MASK) >> camera::AA_SHIFT, 7);
    for bad in [
        8u32 << camera::AA_SHIFT,
        0xff << camera::AA_SHIFT,
        1 << 20,
        4,
    ] {
        let mut b = img.clone();
        b[flags_at..flags_at + 4].copy_from_slice(&(bad | (flags & 3)).to_le_bytes());
        assert!(SceneView::new(&b).is_err(), "flags {bad:#x} accepted");
    }
    let e = compile(
        &desc,
        &CompileOptions {
            aa: Some(9),
            ..CompileOptions::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("anti-aliasing 9"), "{e}");
}

/// `links render ... -o OUT --quiet`, through the library.
fn links_render(args: &[&str], out: &str) {
    let mut argv = vec!["links", "render"];
    argv.extend_from_slice(args);
    argv.extend_from_slice(&["-o", out, "--quiet"]);
    links_host::cli::run_from(argv).unwrap_or_else(|e| panic!("{args:?}: {e}"));
}

#[test]
fn the_cluster_writes_the_hosts_anti_aliased_frame_and_film() {
    let dir = std::env::temp_dir().join(format!("links-aa-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let at = |name: &str| format!("{}/{name}", dir.display());
    let read = |p: &str| std::fs::read(p).unwrap_or_else(|e| panic!("{p}: {e}"));
    let scene = repo("scenes/photo1.ron");
    let scene = scene.to_str().unwrap();
    let common = [scene, "--width", "48", "--height", "36", "--aa", "2"];
    links_render(&common, &at("h.png"));
    let mut nodes = common.to_vec();
    nodes.extend_from_slice(&["--nodes", "8"]);
    links_render(&nodes, &at("c.png"));
    links_render(&common[..5], &at("p.png"));
    assert!(
        read(&at("h.png")) == read(&at("c.png")),
        "8 nodes differ from the host"
    );
    assert!(
        read(&at("h.png")) != read(&at("p.png")),
        "--aa 2 changed nothing"
    );

    let orbit = repo("scenes/photo1-orbit.ron");
    let orbit = orbit.to_str().unwrap();
    let mut film = vec![orbit, "--frames", "0..2", "--width", "32", "--height", "30"];
    film.extend_from_slice(&["--aa", "2"]);
    links_render(&film, &at("host/"));
    film.extend_from_slice(&["--nodes", "4"]);
    links_render(&film, &at("cluster/"));
    for f in 0..2 {
        let name = links_host::cli::film::frame_file_name(f);
        assert!(
            read(&at(&format!("host/{name}"))) == read(&at(&format!("cluster/{name}"))),
            "film frame {f}: the cluster differs from the host"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
