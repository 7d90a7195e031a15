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

/// `links render <scene> --width 64 --height 60 -o <out>`.
fn render_64x60(scene_name: &str, out: &Path) -> Command {
    let mut c = links();
    c.args([
        "render",
        scene(scene_name).to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "60",
        "-o",
    ])
    .arg(out);
    c
}

#[test]
fn cluster_render_gives_the_host_render_and_reports_virtual_time() {
    let (host, cluster) = (tmp("host.png"), tmp("cluster.png"));
    let args = |out: &Path| render_64x60("photo1.ron", out);
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
    // The cluster's nodes run the Q16.16 kernel on the DM's fixed-point image: the host's
    // fixed-point frame, bit for bit.
    let out = tmp("cluster-fixed.png");
    let o = links()
        .args(["render", scene("ellipsoids.ron").to_str().unwrap()])
        .args([
            "--width",
            "48",
            "--height",
            "45",
            "--nodes",
            "2",
            "--precision",
            "fixed",
        ])
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(decode_png_rgb(&std::fs::read(&out).unwrap()).unwrap().2 == fixed);
}

/// Runs `links` with `args` in `dir`: (exit code, stderr). `None` is death by a signal (an
/// abort on a failed allocation).
fn run_in(dir: &Path, args: &[&str]) -> (Option<i32>, String) {
    let o = links().current_dir(dir).args(args).output().unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn run(args: &[&str]) -> (Option<i32>, String) {
    run_in(&std::env::temp_dir(), args)
}

#[test]
fn oversized_image_dimensions_are_refused_before_anything_is_allocated() {
    let photo = scene("photo1.ron");
    let p = photo.to_str().unwrap();
    let out = tmp("huge.png");
    let o = out.to_str().unwrap();
    // Commands that write into their working directory run in a scratch one.
    let dir = tmp("dims");
    std::fs::create_dir_all(&dir).unwrap();
    let cases: &[&[&str]] = &[
        // The command: a 65535 x 65535 frame is 12 GB.
        &[
            "render", p, "--width", "65535", "--height", "65535", "-o", o,
        ],
        &["render", p, "--width", "4097", "-o", o],
        &["render", p, "--height", "0", "-o", o],
        &["render", p, "--width", "4097", "--nodes", "2", "-o", o],
        &["info", p, "--width", "4097"],
        &["compare", p, "--height", "4097"],
        &["upload", p, "--port", "/no/such/port", "--width", "4097"],
        &[
            "chart", "accuracy", "--width", "4097", "--bench", "none.csv",
        ],
        &["sweep", "ablation", p, "--height", "4097"],
    ];
    for args in cases {
        let (code, err) = run_in(&dir, args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(
            err.contains("an image side is 1 to 4096 pixels"),
            "{args:?}: {err}"
        );
    }
    assert!(!out.exists());
    // 4096 itself is accepted (info compiles, nothing is rendered).
    let (code, err) = run(&["info", p, "--width", "4096", "--height", "4096"]);
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn other_sizes_from_the_command_line_are_bounded() {
    let photo = scene("photo1.ron");
    let p = photo.to_str().unwrap();
    let out = tmp("never-threads.png");
    let o = out.to_str().unwrap();
    let dir = tmp("sizes");
    std::fs::create_dir_all(&dir).unwrap();
    let cases: &[(&[&str], &str)] = &[
        // 100000 OS threads were started until the system refused.
        (
            &["render", p, "--threads", "100000", "-o", o],
            "expected 0 (one per core) to 256 threads",
        ),
        (
            &["compare", p, "--threads", "100000"],
            "expected 0 (one per core) to 256 threads",
        ),
        // The model's per-node table was allocated for 4e9 nodes (a 32 GB abort).
        (
            &["sweep", "ablation", p, "--nodes", "4000000000"],
            "a cluster has 1 to 256 node computers",
        ),
        (
            &["info", p, "--max-depth", "17"],
            "the recursion depth is 0 to 16",
        ),
        // A byte took longer than the u64 picoseconds of virtual time hold: a panic.
        (
            &[
                "render",
                p,
                "--nodes",
                "2",
                "--bit-rate-mhz",
                "1e-300",
                "-o",
                o,
            ],
            "the SPI bit rate is 0.001 to 10000 MHz",
        ),
        (
            &[
                "render",
                p,
                "--nodes",
                "2",
                "--bit-rate-mhz",
                "NaN",
                "-o",
                o,
            ],
            "the SPI bit rate is 0.001 to 10000 MHz",
        ),
    ];
    for (args, want) in cases {
        let (code, err) = run_in(&dir, args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
    assert!(!out.exists());
}

#[cfg(unix)]
#[test]
fn scene_paths_that_are_not_regular_files_or_too_large_are_refused() {
    let out = tmp("never-file.png");
    let o = out.to_str().unwrap();
    // /dev/zero never ends: it was read until memory ran out.
    let (code, err) = run(&["render", "/dev/zero", "-o", o]);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(
        err.trim_end(),
        "error: /dev/zero: cannot read the scene file: it is a character device, not a regular file"
    );

    // A FIFO: opening it waited forever for a writer. This writer is there so that a
    // regression reads its text and fails the assertion instead of hanging the test.
    let fifo = tmp("scene-fifo.ron");
    let _ = std::fs::remove_file(&fifo);
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            use std::io::Write;
            let mut w = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
            let _ = w.write_all(b"Scene()");
        })
    };
    let (code, err) = run(&["render", fifo.to_str().unwrap(), "-o", o]);
    // Release the writer: a non-blocking open for reading never waits.
    let release = {
        use std::os::unix::fs::OpenOptionsExt;
        std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&fifo)
            .unwrap()
    };
    writer.join().unwrap();
    drop(release);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(
        err.trim_end(),
        format!(
            "error: {}: cannot read the scene file: it is a FIFO (named pipe), not a regular file",
            fifo.display()
        )
    );

    // 100 MB (sparse: no disk space, and nothing is read).
    let big = tmp("big.ron");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(100_000_000)
        .unwrap();
    let (code, err) = run(&["render", big.to_str().unwrap(), "-o", o]);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(
        err.trim_end(),
        format!(
            "error: {}: cannot read the scene file: it is 100000000 bytes, over the 16 MiB \
             (16777216 bytes) limit for a scene file",
            big.display()
        )
    );
    assert!(!out.exists());
}

/// Byte offset of `section`'s record `record` in a SceneImage (the header's section table).
fn record_at(image: &[u8], section: links_core::image::Section, record: usize) -> usize {
    let t = 16 + 8 * section as usize;
    let off = u32::from_le_bytes(image[t..t + 4].try_into().unwrap()) as usize;
    off + record * section.record_size()
}

/// `info --image` writes a scene's SceneImage; returns the file and `info`'s table.
fn compile_to_file(scene_name: &str, name: &str) -> (PathBuf, String) {
    let bin = tmp(name);
    let o = links()
        .args(["info", scene(scene_name).to_str().unwrap()])
        .args(["--width", "64", "--height", "60", "--image"])
        .arg(&bin)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (bin, String::from_utf8(o.stdout).unwrap())
}

/// Renders with `args` into a fresh PNG and returns its bytes.
fn render_png(name: &str, args: &[&str]) -> Vec<u8> {
    let out = tmp(name);
    let _ = std::fs::remove_file(&out);
    let o = links()
        .arg("render")
        .args(args)
        .args(["--quiet", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    std::fs::read(&out).unwrap()
}

#[test]
fn a_compiled_image_checks_and_renders_like_its_scene() {
    let (bin, info) = compile_to_file("photo1.ron", "photo1.bin");
    let b = bin.to_str().unwrap();

    let o = links().args(["check-image", b]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let len = std::fs::metadata(&bin).unwrap().len();
    // The first line's form is an interface: `<file>: SceneImage <N> bytes (<W>x<H>)`.
    assert_eq!(
        text.lines().next().unwrap(),
        format!("{b}: SceneImage {len} bytes (64x60)")
    );
    assert_eq!(text.lines().nth(1), Some("  number format: f32"));
    let first = info.lines().next().unwrap();
    assert!(
        first.ends_with(&format!(": SceneImage {len} bytes (64x60)")),
        "links info's first line: {first}"
    );
    // The same table as `info`, then the verdict.
    let table = |t: &str| t.lines().skip(1).map(String::from).collect::<Vec<_>>();
    let mut want = table(&info);
    want.push("valid".to_string());
    assert_eq!(table(&text), want);
    assert!(
        text.contains("triangles") && text.contains(" 738 "),
        "{text}"
    );

    // Host (f32, f64) and cluster renders of the image are the scene's.
    let photo = scene("photo1.ron");
    let p = photo.to_str().unwrap();
    let dims = ["--width", "64", "--height", "60"];
    let from_scene = render_png("scene-f32.png", &[&[p][..], &dims].concat());
    assert_eq!(render_png("image-f32.png", &["--image", b]), from_scene);
    assert_eq!(
        render_png("image-f64.png", &["--image", b, "--precision", "f64"]),
        render_png(
            "scene-f64.png",
            &[&[p, "--precision", "f64"][..], &dims].concat()
        )
    );
    assert_eq!(
        render_png("image-cluster.png", &["--image", b, "--nodes", "4"]),
        from_scene
    );

    // An image that stores Q16.16 renders in fixed point, like the scene with --precision
    // fixed, and nothing else reads it.
    let (bin, _) = compile_to_file("ellipsoids.ron", "ellipsoids.bin");
    let fixed = links_core::fixed_image::to_fixed(&std::fs::read(&bin).unwrap()).unwrap();
    let fbin = tmp("ellipsoids-q16.bin");
    std::fs::write(&fbin, &fixed.bytes).unwrap();
    let f = fbin.to_str().unwrap();
    let o = links().args(["check-image", f]).output().unwrap();
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(
        text.lines().next().unwrap().ends_with(" bytes (64x60)"),
        "{text}"
    );
    assert_eq!(
        text.lines().nth(1),
        Some(
            format!(
                "  number format: q16.16, lengths scaled by 2^{}",
                fixed.scale_exponent
            )
            .as_str()
        ),
        "{text}"
    );
    let e = scene("ellipsoids.ron");
    assert_eq!(
        render_png("image-fixed.png", &["--image", f]),
        render_png(
            "scene-fixed.png",
            &[&[e.to_str().unwrap(), "--precision", "fixed"][..], &dims].concat()
        )
    );
    // On the cluster the nodes take the image's kernel (Q16.16): the host's frame.
    assert_eq!(
        render_png("image-fixed-nodes.png", &["--image", f, "--nodes", "2"]),
        render_png("image-fixed-host.png", &["--image", f])
    );
    for (extra, who) in [
        (&["--precision", "f32"][..], "an f32 render"),
        (&["--nodes", "2", "--precision", "f32"][..], "an f32 render"),
    ] {
        let mut args = vec!["render", "--image", f, "-o", "never.png"];
        args.extend_from_slice(extra);
        let (code, err) = run(&args);
        assert_eq!(code, Some(1), "{err}");
        assert_eq!(
            err.trim_end(),
            format!(
                "error: {f}: the image stores q16.16 scalars, which {who} can't read (render \
                 it with --precision fixed)"
            )
        );
    }
}

#[test]
fn a_bad_image_file_is_refused_naming_what_is_wrong() {
    use links_core::image::Section;
    let (bin, _) = compile_to_file("photo1.ron", "photo1-bad.bin");
    let good = std::fs::read(&bin).unwrap();
    let out = tmp("never-image.png");
    let o = out.to_str().unwrap();
    // (bytes, the error after "FILE: ")
    // Triangle 3's first vertex index (a u16 at the record's start) past the vertices.
    let mut bad_vertex = good.clone();
    let at = record_at(&good, Section::Triangles, 3);
    bad_vertex[at..at + 2].copy_from_slice(&65000u16.to_le_bytes());
    let cases: Vec<(Vec<u8>, String)> = vec![
        (
            bad_vertex,
            "not a valid SceneImage: triangles record 3 refers to a missing record".into(),
        ),
        (
            good[..1000].to_vec(),
            format!(
                "not a valid SceneImage: scene image says {} bytes but 1000 were given",
                good.len()
            ),
        ),
        // A scene file given for its image.
        (
            std::fs::read(scene("photo1.ron")).unwrap(),
            "not a valid SceneImage: not a scene image (bad magic)".into(),
        ),
    ];
    for (i, (bytes, want)) in cases.iter().enumerate() {
        let file = tmp(&format!("bad-{i}.bin"));
        std::fs::write(&file, bytes).unwrap();
        let f = file.to_str().unwrap();
        for args in [
            vec!["check-image", f],
            vec!["render", "--image", f, "-o", o],
            vec!["render", "--image", f, "--nodes", "2", "-o", o],
        ] {
            let (code, err) = run(&args);
            assert_eq!(code, Some(1), "{args:?}: {err}");
            assert_eq!(err.trim_end(), format!("error: {f}: {want}"), "{args:?}");
        }
    }

    // Files that are not regular or too large: refused unread.
    let big = tmp("big.bin");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(300_000_000)
        .unwrap();
    for (path, want) in [
        (
            "/dev/zero".to_string(),
            "it is a character device, not a regular file".to_string(),
        ),
        (
            big.to_str().unwrap().to_string(),
            "it is 300000000 bytes, over the 256 MiB (268435456 bytes) limit for a SceneImage \
             file"
                .to_string(),
        ),
    ] {
        for args in [
            vec!["check-image", &path],
            vec!["render", "--image", &path, "-o", o],
        ] {
            let (code, err) = run(&args);
            assert_eq!(code, Some(1), "{args:?}: {err}");
            assert_eq!(
                err.trim_end(),
                format!("error: {path}: cannot read the SceneImage file: {want}")
            );
        }
    }

    // A valid image with a frame larger than the host renders: checked, not rendered.
    let desc = links_host::scene_file::load_scene(&scene("reflections.ron")).unwrap();
    let opts = links_core::dm::CompileOptions {
        width: Some(5000),
        height: Some(5000),
        ..Default::default()
    };
    let wide = tmp("wide.bin");
    std::fs::write(&wide, links_core::dm::compile(&desc, &opts).unwrap().bytes).unwrap();
    let w = wide.to_str().unwrap();
    let o2 = links().args(["check-image", w]).output().unwrap();
    assert!(o2.status.success());
    assert_eq!(
        String::from_utf8(o2.stdout).unwrap().lines().last(),
        Some("valid, but the host renders frames of at most 4096x4096 pixels")
    );
    let (code, err) = run(&["render", "--image", w, "-o", o]);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(
        err.trim_end(),
        format!(
            "error: {w}: the frame is 5000x5000 pixels; the host renders 1 to 4096 pixels per side"
        )
    );
    assert!(!out.exists());
}

#[test]
fn render_takes_a_scene_or_an_image_not_both() {
    let photo = scene("photo1.ron");
    let p = photo.to_str().unwrap();
    for args in [
        vec!["render", "-o", "x.png"],
        vec!["render", p, "--image", "x.bin", "-o", "x.png"],
        vec!["render", "--image", "x.bin", "--width", "8", "-o", "x.png"],
        vec!["render", "--image", "x.bin", "--no-shadows", "-o", "x.png"],
    ] {
        let (code, err) = run(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
    }
}

/// Fault injection from the command line: bit errors both ways, lost broadcasts and nodes
/// killed (one under the static split before it takes its region) give the host's image and
/// a stats line that says what the faults did; bad fault options and a scene too large for
/// a node's bank are one clear line each.
#[test]
fn cluster_render_with_faults_gives_the_host_render_and_bad_fault_options_say_why() {
    let host = tmp("faults-host.png");
    let base = |out: &Path| render_64x60("reflections.ron", out);
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
}

/// A scene of `k` small spheres in a grid (a SceneImage as large as `k` asks).
fn spheres_scene(name: &str, k: usize) -> PathBuf {
    let spheres: Vec<String> = (0..k)
        .map(|i| {
            format!(
                "Sphere(center: ({}, {}, 5), radius: 0.2, material: \"m\")",
                (i % 50) as f32 * 0.5,
                (i / 50) as f32 * 0.5
            )
        })
        .collect();
    let path = tmp(name);
    std::fs::write(
        &path,
        format!(
            "Scene(camera: (eye: (12, 10, -20), look_at: (12, 10, 5), fov_y: 60), \
             image: (width: 64, height: 48), background: (0, 0, 0), ambient: (0.1, 0.1, 0.1), \
             max_depth: 1, materials: {{ \"m\": (diffuse: (0.8, 0.2, 0.2)) }}, \
             lights: [Directional(dir: (0, -1, 1), color: (1, 1, 1))], \
             root: (name: \"w\", children: [{}]))",
            spheres.join(", ")
        ),
    )
    .unwrap();
    path
}

/// The size `links info` prints on its first line (`<file>: SceneImage <N> bytes (<W>x<H>)`).
fn info_size(scene: &Path) -> usize {
    let o = links().arg("info").arg(scene).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let first = text.lines().next().unwrap();
    let rest = first.split(": SceneImage ").nth(1).unwrap();
    rest.split(' ').next().unwrap().parse().unwrap()
}

#[test]
fn info_with_a_node_gives_section_shares_and_the_fit_of_both_banks() {
    use links_core::board::NodeBoard;
    use links_host::cli::node::grouped;
    let b = NodeBoard::F407;
    let path = scene("reflections.ron");
    let n = info_size(&path);
    let o = links()
        .arg("info")
        .arg(&path)
        .args(["--node", "f407"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        format!("{}: SceneImage {n} bytes (512x480)", path.display())
    );
    assert!(lines[2].ends_with("share"), "{text}");
    assert!(text.contains("  header "), "{text}");
    for (which, bank) in ["even frames", "odd frames"].iter().zip(b.scene_banks) {
        let line = format!(
            "    {which:<12} {:>10} bytes: {} bytes free",
            grouped(bank),
            grouped(bank - n)
        );
        assert!(lines.contains(&line.as_str()), "no '{line}' in {text}");
    }
    assert_eq!(lines.last(), Some(&"  f407: fits two banks"), "{text}");

    // Without --node: no share column, no fit.
    let o = links().arg("info").arg(&path).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!text.contains("share") && !text.contains("f407"), "{text}");

    let (code, err) = run(&["info", path.to_str().unwrap(), "--node", "f999"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("unknown node board 'f999'; known: f407"),
        "{err}"
    );
}

#[test]
fn a_scene_no_bank_holds_is_refused_before_anything_is_sent() {
    use links_core::board::NodeBoard;
    use links_host::cli::node::grouped;
    let big = spheres_scene("spheres.ron", 4000);
    let n = info_size(&big);
    let bank = NodeBoard::F407.bank(0);
    assert!(
        n > NodeBoard::F407.largest_bank(),
        "{n} bytes: the test needs a larger scene"
    );
    let want = format!(
        "error: {}: SceneImage {} bytes does not fit the f407 node's scene bank ({} bytes)",
        big.display(),
        grouped(n),
        grouped(bank)
    );
    let o = links()
        .arg("info")
        .arg(&big)
        .args(["--node", "F407"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success());
    assert_eq!(text.lines().last(), Some("  f407: does not fit"), "{text}");

    let out = tmp("spheres.png");
    let (code, err) = run(&[
        "render",
        big.to_str().unwrap(),
        "--nodes",
        "4",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!((code, err.trim_end()), (Some(1), want.as_str()));
    assert!(!out.exists());
    // The serial upload refuses it before it opens the port.
    let (code, err) = run(&["upload", big.to_str().unwrap(), "--port", "/no/such/port"]);
    assert_eq!((code, err.trim_end()), (Some(1), want.as_str()));
}

/// `--board` picks the profile the summary names, `speed-up <X>x` is on the summary line, an
/// unknown board is refused by name, and `--timeline` writes the picture naming the board.
#[test]
fn cluster_render_names_its_board_and_draws_the_timeline() {
    let (host, cluster, svg) = (tmp("b-host.png"), tmp("b-cluster.png"), tmp("t.svg"));
    assert!(render_64x60("photo1.ron", &host)
        .arg("--quiet")
        .status()
        .unwrap()
        .success());
    for board in ["f407", "ideal"] {
        let o = render_64x60("photo1.ron", &cluster)
            .args(["--nodes", "4", "--board", board, "--timeline"])
            .arg(&svg)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert_eq!(
            std::fs::read(&host).unwrap(),
            std::fs::read(&cluster).unwrap()
        );
        let link = if board == "f407" { "firmware" } else { "ideal" };
        assert!(
            err.contains(&format!("board {board}, {link} link: ")),
            "{err}"
        );
        let x = err
            .split("speed-up ")
            .nth(1)
            .and_then(|t| t.split_once("x "))
            .map(|(n, _)| n.parse::<f64>());
        assert!(matches!(x, Some(Ok(v)) if v > 1.0 && v <= 4.0), "{err}");
        let pic = std::fs::read_to_string(&svg).unwrap();
        assert!(pic.starts_with("<svg") && pic.trim_end().ends_with("</svg>"));
        assert!(pic.contains(&format!("board {board}, {link} link: ")) && pic.contains("node 3"));
    }
    let o = render_64x60("photo1.ron", &cluster)
        .args(["--nodes", "4", "--board", "f429"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("unknown board 'f429'"),
        "{err}"
    );
}
