//! The `links` command as a user runs it.

use links_host::frame::decode_png_rgb;
use std::path::{Path, PathBuf};
use std::process::Command;

fn links() -> Command {
    Command::new(env!("CARGO_BIN_EXE_links"))
}

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(name)
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("links-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn render_writes_a_png_of_the_requested_size_and_a_stats_line() {
    let out = tmp("photo1.png");
    let o = links()
        .args([
            "render",
            scene("photo1.ron").to_str().unwrap(),
            "--width",
            "64",
            "--height",
            "60",
            "-o",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (w, h, rgb) = decode_png_rgb(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!((w, h), (64, 60));
    assert!(rgb.iter().any(|&c| c > 0));
    let err = String::from_utf8_lossy(&o.stderr);
    for word in [
        "primary",
        "shadow",
        "box",
        "triangle",
        "Mrays/s",
        "scene image",
    ] {
        assert!(err.contains(word), "stats line lacks '{word}': {err}");
    }
}

#[test]
fn the_image_does_not_depend_on_the_thread_count() {
    let mut pngs = Vec::new();
    for threads in ["1", "2", "3"] {
        let out = tmp(&format!("glass-{threads}.png"));
        let o = links()
            .args([
                "render",
                scene("glass.ron").to_str().unwrap(),
                "--width",
                "48",
                "--height",
                "40",
                "--quiet",
            ])
            .args(["--threads", threads, "-o"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success());
        pngs.push(std::fs::read(&out).unwrap());
    }
    assert_eq!(pngs[0], pngs[1]);
    assert_eq!(pngs[0], pngs[2]);
}

#[test]
fn bad_input_gives_one_line_naming_file_line_and_column_and_fails() {
    let bad = tmp("bad.ron");
    std::fs::write(
        &bad,
        "Scene(\n    camera: (eye: (0, 0, -5), look_at: (0, 0, 0)),\n    root: (children: [\n        Sphere(center: (0, 0, 0), radius: 0),\n    ]),\n)\n",
    )
    .unwrap();
    let o = links()
        .args(["render", bad.to_str().unwrap(), "-o"])
        .arg(tmp("never.png"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains("bad.ron:4:"), "names file and line: {err}");
    assert!(err.contains("radius"), "says what was wrong: {err}");
    assert!(!tmp("never.png").exists());

    let o = links()
        .args(["render", "no/such/scene.ron"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no/such/scene.ron"));
}

#[test]
fn info_reports_the_scene_image_size_by_section() {
    let o = links()
        .args(["info", scene("photo1.ron").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("SceneImage") && text.contains("triangles") && text.contains("738"),
        "{text}"
    );
}

#[test]
fn cluster_render_gives_the_host_render_and_reports_virtual_time() {
    let (host, cluster) = (tmp("host.png"), tmp("cluster.png"));
    let args = |out: &Path| {
        let mut c = links();
        c.args([
            "render",
            scene("photo1.ron").to_str().unwrap(),
            "--width",
            "64",
            "--height",
            "60",
            "-o",
        ])
        .arg(out);
        c
    };
    assert!(args(&host).arg("--quiet").status().unwrap().success());
    let o = args(&cluster)
        .args(["--nodes", "8", "--policy", "fixed=64"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read(&host).unwrap(),
        std::fs::read(&cluster).unwrap()
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("8 simulated nodes") && err.contains("virtual") && err.contains("speed-up"),
        "{err}"
    );
    let bad = links()
        .args([
            "render",
            scene("photo1.ron").to_str().unwrap(),
            "--nodes",
            "0",
            "-o",
        ])
        .arg(tmp("x.png"))
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("1 to 256"));
}

#[test]
fn fixed_point_render_is_close_to_f64_and_compare_reports_it() {
    let render = |precision: &str| {
        let out = tmp(&format!("ellipsoids-{precision}.png"));
        let o = links()
            .args([
                "render",
                scene("ellipsoids.ron").to_str().unwrap(),
                "--width",
                "48",
                "--height",
                "45",
                "--precision",
                precision,
                "-o",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains(if precision == "fixed" {
                "q16.16"
            } else {
                precision
            })
        );
        decode_png_rgb(&std::fs::read(&out).unwrap()).unwrap().2
    };
    let (fixed, f64) = (render("fixed"), render("f64"));
    let psnr = links_host::frame::psnr(&fixed, &f64);
    assert!(psnr > 35.0 && psnr.is_finite(), "{psnr} dB");
    let o = links()
        .args([
            "compare",
            scene("ellipsoids.ron").to_str().unwrap(),
            "--width",
            "48",
            "--height",
            "45",
            "--backend",
            "fixed",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let line = String::from_utf8_lossy(&o.stdout);
    assert!(
        line.contains("fixed vs f64: PSNR") && line.contains("0 NaN/inf pixels"),
        "{line}"
    );
    // The cluster's nodes compute in f32: a clear refusal, not a silent f32 render.
    let o = links()
        .args([
            "render",
            scene("ellipsoids.ron").to_str().unwrap(),
            "--nodes",
            "2",
            "--precision",
            "fixed",
            "-o",
        ])
        .arg(tmp("x.png"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("nodes compute in f32"));
}

/// Fault injection from the command line: bit errors both ways, lost broadcasts and nodes
/// killed (one under the static split before it takes its region) give the host's image and
/// a stats line that says what the faults did; bad fault options and a scene too large for
/// a node's bank are one clear line each.
#[test]
fn cluster_render_with_faults_gives_the_host_render_and_bad_fault_options_say_why() {
    let host = tmp("faults-host.png");
    let base = |out: &Path| {
        let mut c = links();
        c.args([
            "render",
            scene("reflections.ron").to_str().unwrap(),
            "--width",
            "64",
            "--height",
            "60",
            "-o",
        ])
        .arg(out);
        c
    };
    assert!(base(&host).arg("--quiet").status().unwrap().success());
    let want = std::fs::read(&host).unwrap();
    let cases: [&[&str]; 2] = [
        &[
            "--nodes",
            "8",
            "--ber-down",
            "1e-3",
            "--ber-up",
            "1e-3",
            "--drop-broadcast",
            "0.2",
            "--fault-seed",
            "3",
            "--kill",
            "1@0.02",
            "--kill",
            "5-6@0.025",
            "--timeout-ms",
            "50",
        ],
        // Static split, node 3 dead before it takes its region.
        &[
            "--nodes",
            "4",
            "--policy",
            "static",
            "--kill",
            "3@0",
            "--timeout-ms",
            "20",
        ],
    ];
    for (i, args) in cases.iter().enumerate() {
        let out = tmp(&format!("faults-{i}.png"));
        let o = base(&out).args(*args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{args:?}: {err}");
        assert_eq!(std::fs::read(&out).unwrap(), want, "{args:?}");
        assert!(err.contains("| faults: "), "{err}");
        assert!(err.contains("re-issued"), "{err}");
    }
    let fails = |args: &[&str], want: &str| {
        let o = base(&tmp("bad.png")).args(args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    };
    fails(
        &["--nodes", "8", "--ber-up", "0.7"],
        "--ber-up 0.7: a bit-error rate",
    );
    fails(
        &["--nodes", "8", "--drop-broadcast", "1"],
        "--drop-broadcast 1",
    );
    fails(
        &["--nodes", "8", "--kill", "8@0.1"],
        "node 8 does not exist (8 nodes: 0 to 7)",
    );
    fails(&["--nodes", "8", "--kill", "2@soon"], "NODE@SECONDS");
    // photo2's scene image (187 KB) does not fit a node's 120 KB bank.
    let o = links()
        .args([
            "render",
            scene("photo2.ron").to_str().unwrap(),
            "--nodes",
            "4",
            "-o",
        ])
        .arg(tmp("photo2.png"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        err.contains("187136 bytes") && err.contains("122880 bytes"),
        "{err}"
    );
}
