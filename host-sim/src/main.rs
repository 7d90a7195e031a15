//! `links`: render LINKS-1 scenes on the host.

use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use links_core::desc::TransparencyMode;
use links_core::dm::{compile, CompileOptions};
use links_core::image::SceneView;
use links_host::ablation::{run_ablation, AblationConfig};
use links_host::cli_cluster;
use links_host::cli_image;
use links_host::cli_serial;
use links_host::cost::{self, CycleModel};
use links_host::frame::{encode_png, render_frame, Precision};
use links_host::limits;
use links_host::scene_file::load_scene;
use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

/// `println!` that ends the program quietly when stdout is closed (`links ... | head`).
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write;
        if let Err(e) = writeln!(std::io::stdout().lock(), $($arg)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
            eprintln!("error: cannot write to stdout: {e}");
            std::process::exit(1);
        }
    }};
}

#[derive(Parser)]
#[command(
    name = "links",
    version,
    about = "LINKS-1 ray tracer: render scenes, inspect scene images"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, ValueEnum)]
enum PrecisionArg {
    F32,
    F64,
    /// Q16.16 fixed point (the DM rescales the scene to fit)
    Fixed,
}

#[derive(Clone, Copy, ValueEnum)]
enum TransparencyArg {
    Refractive,
    NonRefractive,
}

#[derive(clap::Args)]
struct SceneArgs {
    /// Scene file (.ron)
    #[arg(required = true)]
    scene: Option<PathBuf>,
    /// Image width in pixels, 1..=4096 (default: the scene's)
    #[arg(long, value_parser = limits::parse_image_side)]
    width: Option<u32>,
    /// Image height in pixels, 1..=4096 (default: the scene's)
    #[arg(long, value_parser = limits::parse_image_side)]
    height: Option<u32>,
    /// Maximum recursion depth for reflection/refraction, 0..=16 (default: the scene's)
    #[arg(long, value_parser = limits::parse_max_depth)]
    max_depth: Option<u32>,
    /// Override the scene's transparency mode
    #[arg(long, value_enum)]
    transparency: Option<TransparencyArg>,
    /// Render without shadows (no shadow rays)
    #[arg(long)]
    no_shadows: bool,
}

#[derive(Subcommand)]
enum Cmd {
    /// Render a scene (or a compiled SceneImage, --image) to a PNG file
    #[command(mut_arg("scene", |a| a.required(false).required_unless_present("image")))]
    Render {
        #[command(flatten)]
        scene: SceneArgs,
        /// Render this compiled SceneImage file (as `info --image` writes) instead of a scene
        #[arg(long, value_name = "FILE.bin", conflicts_with_all = ["scene", "width", "height", "max_depth", "transparency", "no_shadows"])]
        image: Option<PathBuf>,
        /// Output PNG file
        #[arg(short, long, default_value = "out.png")]
        output: PathBuf,
        /// Host threads (0 = all cores, at most 256; single-host render only); the image does
        /// not depend on it
        #[arg(long, default_value_t = 0, value_parser = limits::parse_threads)]
        threads: usize,
        /// Number type of the render (default: f32; fixed for an --image that stores Q16.16)
        #[arg(long, value_enum)]
        precision: Option<PrecisionArg>,
        /// No progress bar or stats line
        #[arg(short, long)]
        quiet: bool,
        /// Render on a simulated LINKS-1 cluster of this many node computers (1..=256)
        #[arg(long)]
        nodes: Option<u16>,
        /// SPI buses from the root computer (cluster only)
        #[arg(long, default_value_t = 1)]
        buses: u16,
        /// SPI bit rate in MHz, 0.001..=10000 (cluster only)
        #[arg(long, default_value_t = 42.0, value_parser = limits::parse_bit_rate_mhz)]
        bit_rate_mhz: f64,
        /// Sub-screen policy (cluster only): decreasing, static, fixed=N, fixed-rect=N
        #[arg(long, default_value = "decreasing")]
        policy: String,
        /// DM time per frame in ms: frame f's scene exists at (f+1) x this (cluster only)
        #[arg(long, default_value_t = 0.0)]
        dm_ms: f64,
        #[command(flatten)]
        faults: cli_cluster::FaultArgs,
        /// How long the RC waits for a silent node holding work before re-issuing it, in ms
        #[arg(long, default_value_t = 500.0)]
        timeout_ms: f64,
        /// A single-buffered RC: it composes, clocks and decodes one transfer at a time
        /// (default: double-buffered, the bus busy while the RC works; cluster only)
        #[arg(long)]
        rc_single_buffer: bool,
    },
    /// Check a compiled SceneImage file and print its size by section
    CheckImage {
        /// SceneImage file (as `info --image` writes)
        image: PathBuf,
    },
    /// Compile a scene and print its SceneImage size by section
    Info {
        #[command(flatten)]
        scene: SceneArgs,
        /// Also write the SceneImage bytes to this file
        #[arg(long)]
        image: Option<PathBuf>,
    },
    /// Render a scene in a number format and in f64 and report how far apart they are
    Compare {
        #[command(flatten)]
        scene: SceneArgs,
        /// The number format to measure: f32, f32-fast (micromath's approximations) or fixed
        /// (Q16.16)
        #[arg(long, default_value = "f32")]
        backend: String,
        /// Host threads (0 = all cores, at most 256)
        #[arg(long, default_value_t = 0, value_parser = limits::parse_threads)]
        threads: usize,
    },
    /// Compile a scene and send its SceneImage to a real RC over a serial port
    Upload {
        #[command(flatten)]
        scene: SceneArgs,
        /// Serial port of the RC (e.g. /dev/ttyACM0)
        #[arg(long)]
        port: String,
        /// Baud rate (a USB CDC port ignores it)
        #[arg(long, default_value_t = links_host::serial_host::DEFAULT_BAUD)]
        baud: u32,
        /// How long to wait for the RC's answer to one message before sending it again, in ms
        #[arg(long, default_value_t = 1000)]
        timeout_ms: u64,
        /// Give up after this many seconds in all (default: from the scene size and baud rate; 0: never)
        #[arg(long)]
        deadline_s: Option<u64>,
        /// Then ask the RC to render this many frames
        #[arg(long)]
        render: Option<u16>,
        /// No progress bar or summary line
        #[arg(short, long)]
        quiet: bool,
    },
    /// Read a rendered frame from a real RC over a serial port and write it as a PNG
    Readback {
        /// Serial port of the RC (e.g. /dev/ttyACM0)
        #[arg(long)]
        port: String,
        /// Output PNG file
        #[arg(short, long, default_value = "frame.png")]
        output: PathBuf,
        /// Baud rate (a USB CDC port ignores it)
        #[arg(long, default_value_t = links_host::serial_host::DEFAULT_BAUD)]
        baud: u32,
        /// Longest silence from the RC before giving up (or asking again), in ms
        #[arg(long, default_value_t = 5000)]
        timeout_ms: u64,
        /// Give up after this many seconds in all (default: none, the progress rules of docs/serial.md end a misbehaving RC)
        #[arg(long)]
        deadline_s: Option<u64>,
        /// No progress bar or summary line
        #[arg(short, long)]
        quiet: bool,
    },
    /// Measurement sweeps
    #[command(subcommand)]
    Sweep(SweepCmd),
    /// Charts of measured results
    #[command(subcommand)]
    Chart(ChartCmd),
    /// Fit the cycle model's weights to QEMU-measured frames (scripts/qemu-bench's CSV)
    Calibrate {
        /// CSV written by scripts/qemu-bench
        #[arg(long, default_value = "docs/cortex-m-bench.csv")]
        csv: PathBuf,
        /// Which target's samples to fit
        #[arg(long, default_value = "thumbv7em-none-eabihf")]
        target: String,
    },
    /// Regenerate the procedural meshes and textures of the bundled scenes
    GenAssets {
        /// Output directory
        #[arg(long, default_value = "scenes/assets")]
        dir: PathBuf,
    },
}

#[derive(Subcommand)]
enum ChartCmd {
    /// Speed (Cortex-M instructions per pixel) against accuracy (PSNR vs f64) for every
    /// number backend and bundled scene; writes the SVG, a PNG and a CSV beside it, and the
    /// table in docs/numerics.md
    Accuracy {
        /// The SVG to write (the PNG and CSV get the same name with their extension)
        #[arg(short, long, default_value = "docs/accuracy.svg")]
        output: PathBuf,
        /// Instruction counts measured by scripts/qemu-bench
        #[arg(long, default_value = "docs/cortex-m-bench.csv")]
        bench: PathBuf,
        /// Directory of the bundled scenes
        #[arg(long, default_value = "scenes")]
        scenes: PathBuf,
        /// Document whose generated table section to replace ("" = none)
        #[arg(long, default_value = "docs/numerics.md")]
        doc: PathBuf,
        #[arg(long, default_value_t = links_host::chart::WIDTH, value_parser = limits::parse_image_side)]
        width: u32,
        #[arg(long, default_value_t = links_host::chart::HEIGHT, value_parser = limits::parse_image_side)]
        height: u32,
    },
}

#[derive(Subcommand)]
enum SweepCmd {
    /// LINKS-1 Table 5.2 analog: modelled node time of each speed technique
    Ablation {
        /// Scene file (.ron)
        scene: PathBuf,
        #[arg(long, default_value_t = 512, value_parser = limits::parse_image_side)]
        width: u32,
        #[arg(long, default_value_t = 480, value_parser = limits::parse_image_side)]
        height: u32,
        /// Node computers the sub-screens are shared among (1..=256)
        #[arg(long, default_value_t = 16, value_parser = limits::parse_nodes)]
        nodes: u32,
        /// Sub-screen counts (multiples of the height), one table row each
        #[arg(long, value_delimiter = ',', default_value = "2400,480")]
        divisions: Vec<u32>,
        /// Markdown report to write
        #[arg(short, long, default_value = "docs/techniques.md")]
        output: PathBuf,
    },
    /// LINKS-1 Fig. 5.1 analog: cluster speed-up against node count (and the bus study)
    Nodes {
        /// Scene file (.ron)
        scene: PathBuf,
        /// Directory for nodes.csv and nodes.svg
        #[arg(short, long, default_value = "docs/cluster")]
        output: PathBuf,
    },
    /// Reliability: frame time against the moment a node dies (every policy, with the
    /// recovery bound), the bit-error rate and the fraction of nodes killed; writes the
    /// table into docs/reliability.md and the chart beside it
    Faults {
        /// Scene file (.ron)
        scene: PathBuf,
        #[command(flatten)]
        opts: cli_cluster::FaultSweepArgs,
    },
    /// LINKS-1 Fig. 5.2 analog: frame time against the number of sub-screens at 64 nodes
    Divisions {
        /// Scene file (.ron)
        scene: PathBuf,
        /// Directory for divisions[-noshadows].csv/svg
        #[arg(short, long, default_value = "docs/cluster")]
        output: PathBuf,
    },
}

/// Scene arguments with every option at the scene's own setting.
fn plain_args(scene: &std::path::Path) -> SceneArgs {
    SceneArgs {
        scene: Some(scene.to_path_buf()),
        width: None,
        height: None,
        max_depth: None,
        transparency: None,
        no_shadows: false,
    }
}

/// The scene file of `a` (clap requires it wherever `--image` is not given).
fn scene_path(a: &SceneArgs) -> Result<&std::path::Path, String> {
    a.scene
        .as_deref()
        .ok_or_else(|| "a scene file is required".to_string())
}

fn compile_scene(a: &SceneArgs) -> Result<Vec<u8>, String> {
    let path = scene_path(a)?;
    let desc = load_scene(path).map_err(|e| e.to_string())?;
    let opts = CompileOptions {
        width: a.width,
        height: a.height,
        max_depth: a.max_depth,
        transparency: a.transparency.map(|t| match t {
            TransparencyArg::Refractive => TransparencyMode::Refractive,
            TransparencyArg::NonRefractive => TransparencyMode::NonRefractive,
        }),
        mesh_hierarchy: Default::default(),
        no_shadows: a.no_shadows,
    };
    let compiled = compile(&desc, &opts).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(compiled.bytes)
}

/// The SceneImage to render: the `--image` file (validated, frame within the host's limit),
/// or the scene compiled; and the number type its storage allows.
fn image_to_render(
    a: &SceneArgs,
    file: Option<&std::path::Path>,
    precision: Option<PrecisionArg>,
    cluster: bool,
) -> Result<(Vec<u8>, Precision), String> {
    let asked = precision.map(|p| match p {
        PrecisionArg::F32 => Precision::F32,
        PrecisionArg::F64 => Precision::F64,
        PrecisionArg::Fixed => Precision::Fixed,
    });
    match file {
        Some(path) => cli_image::for_render(path, asked, cluster).map_err(|e| e.to_string()),
        None => Ok((compile_scene(a)?, asked.unwrap_or_default())),
    }
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.cmd {
        Cmd::Render {
            scene,
            image,
            output,
            threads: _,
            precision,
            quiet,
            nodes: Some(nodes),
            buses,
            bit_rate_mhz,
            policy,
            dm_ms,
            faults,
            timeout_ms,
            rc_single_buffer,
        } => {
            if !matches!(precision, None | Some(PrecisionArg::F32)) {
                return Err(
                    "the cluster's nodes compute in f32: drop --precision or --nodes".into(),
                );
            }
            if !(1..=256).contains(&nodes) {
                return Err(format!(
                    "--nodes {nodes}: a cluster has 1 to 256 node computers"
                ));
            }
            let (image, _) = image_to_render(&scene, image.as_deref(), precision, true)?;
            let mut cfg = cli_cluster::config(
                nodes,
                buses,
                bit_rate_mhz,
                cli_cluster::parse_policy(&policy)?,
            );
            if !(dm_ms.is_finite() && dm_ms >= 0.0 && timeout_ms.is_finite() && timeout_ms > 0.0) {
                return Err("--dm-ms must be >= 0 and --timeout-ms > 0".into());
            }
            cfg.dm_s_per_frame = dm_ms * 1e-3;
            cfg.node_timeout_s = timeout_ms * 1e-3;
            cfg.rc_double_buffer = !rc_single_buffer;
            cli_cluster::apply_faults(&mut cfg, &faults)?;
            let start = std::time::Instant::now();
            let r = cli_cluster::render(&image, &cfg)?;
            let rep = &r.report;
            let frame = rep.frames.first().ok_or("the simulation kept no frame")?;
            let png = encode_png(rep.width, rep.height, frame).map_err(|e| e.to_string())?;
            std::fs::write(&output, png).map_err(|e| format!("{}: {e}", output.display()))?;
            if !quiet {
                eprintln!(
                    "{}: {}x{} on {nodes} simulated nodes ({buses} bus(es) at {bit_rate_mhz} MHz, {policy}): {:.4} s virtual, speed-up {:.2}x vs 1 node ({:.3} s) | bus busy {:.1}%, RC busy {:.1}% ({}-buffered), {} bytes moved{} | host {:.2} s",
                    output.display(),
                    rep.width,
                    rep.height,
                    rep.time_s,
                    r.speedup,
                    r.one_node_s,
                    100.0 * rep.bus_utilisation(),
                    100.0 * rep.rc_busy_s / rep.time_s,
                    if rc_single_buffer { "single" } else { "double" },
                    rep.bytes_moved(),
                    cli_cluster::fault_summary(rep),
                    start.elapsed().as_secs_f64()
                );
            }
            Ok(())
        }
        Cmd::Render {
            scene,
            image,
            output,
            threads,
            precision,
            quiet,
            nodes: None,
            ..
        } => {
            let (image, precision) = image_to_render(&scene, image.as_deref(), precision, false)?;
            let view = SceneView::new(&image).map_err(|e| e.to_string())?;
            let f = view.camera::<f32>();
            let bar = if quiet || !std::io::stderr().is_terminal() {
                ProgressBar::hidden()
            } else {
                let b = ProgressBar::with_draw_target(
                    Some(f.height as u64),
                    ProgressDrawTarget::stderr(),
                );
                b.set_style(
                    ProgressStyle::with_template(
                        "{spinner} {bar:40} {pos}/{len} rows, {elapsed} (eta {eta})",
                    )
                    .map_err(|e| e.to_string())?,
                );
                b
            };
            let frame = render_frame(&image, precision, threads, &|| bar.inc(1))
                .map_err(|e| e.to_string())?;
            bar.finish_and_clear();
            let png =
                encode_png(frame.width, frame.height, &frame.rgb).map_err(|e| e.to_string())?;
            std::fs::write(&output, png).map_err(|e| format!("{}: {e}", output.display()))?;
            if !quiet {
                let s = &frame.stats;
                let secs = frame.elapsed.as_secs_f64();
                eprintln!(
                    "{}: {}x{} {} in {:.3} s, {:.3} Mrays/s | rays: primary {}, shadow {}, reflect {}, refract {}, straight {} | tests: box {}, triangle {}, ellipsoid {}, box-shape {}, blob {} (field evals {}) | shadings {} | clip compares {} | scene image {} B",
                    output.display(),
                    frame.width,
                    frame.height,
                    precision.name(),
                    secs,
                    s.rays() as f64 / secs.max(1e-9) / 1e6,
                    s.primary_rays,
                    s.shadow_rays,
                    s.reflect_rays,
                    s.refract_rays,
                    s.straight_rays,
                    s.box_tests,
                    s.triangle_tests,
                    s.ellipsoid_tests,
                    s.box_shape_tests,
                    s.blob_tests,
                    s.blob_field_evals,
                    s.shadings,
                    s.clip_compares,
                    image.len()
                );
            }
            Ok(())
        }
        Cmd::CheckImage { image } => {
            for line in cli_image::check_image(&image).map_err(|e| e.to_string())? {
                outln!("{line}");
            }
            Ok(())
        }
        Cmd::Info { scene, image } => {
            let bytes = compile_scene(&scene)?;
            let view = SceneView::new(&bytes).map_err(|e| e.to_string())?;
            for line in cli_image::describe(&scene_path(&scene)?.display().to_string(), &view) {
                outln!("{line}");
            }
            if let Some(path) = image {
                std::fs::write(&path, &bytes).map_err(|e| format!("{}: {e}", path.display()))?;
            }
            Ok(())
        }
        Cmd::Compare {
            scene,
            threads,
            backend,
        } => {
            let image = compile_scene(&scene)?;
            let measure = match backend.as_str() {
                "f32" => links_host::accuracy::compare_to_f64::<f32>,
                "f32-fast" => links_host::accuracy::compare_to_f64::<links_core::num::FastF32>,
                "fixed" | "q16.16" => links_host::accuracy::compare_to_f64::<links_core::num::Fx>,
                other => {
                    return Err(format!(
                        "unknown backend '{other}' (expected f32, f32-fast or fixed)"
                    ))
                }
            };
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| e.to_string())?;
            let a = pool
                .install(|| measure(&image))
                .map_err(|e| e.to_string())?;
            outln!(
                "{}: {}x{} {backend} vs f64: PSNR {:.1} dB, max channel error {}/255, {:.3}% pixels off by > 1/255, {} NaN/inf pixels, {} hit-mask mismatches ({} off silhouettes)",
                scene_path(&scene)?.display(),
                a.width,
                a.height,
                a.psnr_db,
                a.max_channel_error,
                100.0 * a.frac_off_by_more_than_1,
                a.non_finite_pixels,
                a.hit_mismatches,
                a.hit_mismatches_off_silhouette
            );
            Ok(())
        }
        Cmd::Upload {
            scene,
            port,
            baud,
            timeout_ms,
            deadline_s,
            render,
            quiet,
        } => {
            let image = compile_scene(&scene)?;
            let line = cli_serial::upload_command(
                &image, &port, baud, timeout_ms, deadline_s, render, quiet,
            )?;
            if !quiet {
                eprintln!("{line}");
            }
            Ok(())
        }
        Cmd::Readback {
            port,
            output,
            baud,
            timeout_ms,
            deadline_s,
            quiet,
        } => {
            let line =
                cli_serial::readback_command(&port, &output, baud, timeout_ms, deadline_s, quiet)?;
            if !quiet {
                eprintln!("{line}");
            }
            Ok(())
        }
        Cmd::Chart(ChartCmd::Accuracy {
            output,
            bench,
            scenes,
            doc,
            width,
            height,
        }) => {
            use links_host::chart;
            let bench_csv = limits::read_text_bounded(&bench, limits::MAX_TEXT_BYTES, "CSV file")
                .map_err(|e| format!("{e} (run scripts/qemu-bench first)"))?;
            let speed = chart::parse_bench(&bench_csv).map_err(|e| e.to_string())?;
            let images =
                chart::bundled_images(&scenes, width, height).map_err(|e| e.to_string())?;
            eprintln!(
                "measuring {} backends x {} scenes at {width}x{height} against f64 ...",
                chart::BACKENDS.len(),
                images.len()
            );
            let acc = chart::measure(&images).map_err(|e| e.to_string())?;
            let pts = chart::points(&acc, &speed);
            chart::write(
                &output,
                chart::svg(&pts).map_err(|e| e.to_string())?.as_bytes(),
            )
            .map_err(|e| e.to_string())?;
            let png_path = output.with_extension("png");
            chart::write(&png_path, &chart::png(&pts).map_err(|e| e.to_string())?)
                .map_err(|e| e.to_string())?;
            let csv_path = output.with_extension("csv");
            chart::write(&csv_path, chart::csv(&acc, &speed).as_bytes())
                .map_err(|e| e.to_string())?;
            if !doc.as_os_str().is_empty() {
                let text = limits::read_text_bounded(&doc, limits::MAX_TEXT_BYTES, "document")
                    .map_err(|e| e.to_string())?;
                let new = chart::replace_table(&text, &chart::markdown(&acc, &speed))
                    .map_err(|e| format!("{}: {e}", doc.display()))?;
                chart::write(&doc, new.as_bytes()).map_err(|e| e.to_string())?;
            }
            outln!(
                "{} points; wrote {}, {}, {}{}",
                pts.len(),
                output.display(),
                png_path.display(),
                csv_path.display(),
                if doc.as_os_str().is_empty() {
                    String::new()
                } else {
                    format!(" and the table in {}", doc.display())
                }
            );
            Ok(())
        }
        Cmd::Sweep(SweepCmd::Ablation {
            scene,
            width,
            height,
            nodes,
            divisions,
            output,
        }) => {
            let desc = load_scene(&scene).map_err(|e| e.to_string())?;
            let cfg = AblationConfig {
                width,
                height,
                nodes,
                divisions,
                ..AblationConfig::default()
            };
            let report = run_ablation(&desc, &cfg, &|step| eprintln!("rendering {step} ..."))
                .map_err(|e| format!("{}: {e}", scene.display()))?;
            let command = std::env::args().skip(1).collect::<Vec<_>>().join(" ");
            let doc =
                links_host::ablation_doc::render(&report, &scene.display().to_string(), &command);
            outln!("{}", report.table());
            outln!(
                "refractive / non-refractive (type 1): {:.2}x",
                report.refractive_ratio()
            );
            std::fs::write(&output, doc).map_err(|e| format!("{}: {e}", output.display()))?;
            eprintln!("wrote {}", output.display());
            Ok(())
        }
        Cmd::Sweep(SweepCmd::Nodes { scene, output }) => {
            let image = compile_scene(&plain_args(&scene))?;
            let text =
                cli_cluster::nodes_study(&image, &output, &|s| eprintln!("simulating {s} ..."))?;
            outln!("{text}");
            eprintln!("wrote {}/nodes.csv and nodes.svg", output.display());
            Ok(())
        }
        Cmd::Sweep(SweepCmd::Faults { scene, opts }) => {
            let text = cli_cluster::faults_study(&scene, &opts, &|s| eprintln!("{s}"))?;
            outln!("{text}");
            Ok(())
        }
        Cmd::Sweep(SweepCmd::Divisions { scene, output }) => {
            let image = compile_scene(&plain_args(&scene))?;
            let no_shadows = compile_scene(&SceneArgs {
                no_shadows: true,
                ..plain_args(&scene)
            })?;
            let text = cli_cluster::divisions_study(
                &[("divisions-noshadows", &no_shadows), ("divisions", &image)],
                &output,
                &|s| eprintln!("simulating {s} ..."),
            )?;
            outln!("{text}");
            eprintln!("wrote {}/divisions*.csv and .svg", output.display());
            Ok(())
        }
        Cmd::Calibrate { csv, target } => {
            let text = limits::read_text_bounded(&csv, limits::MAX_TEXT_BYTES, "CSV file")
                .map_err(|e| e.to_string())?;
            let samples =
                cost::parse_samples(&text).map_err(|e| format!("{}: {e}", csv.display()))?;
            let fitted = cost::fit(
                &samples,
                &target,
                CycleModel::CORTEX_M4F_F32.cycles_per_instruction,
            )
            .map_err(|e| format!("{}: {e}", csv.display()))?;
            outln!(
                "fitted instructions per operation ({target}, {} frames):",
                samples.iter().filter(|s| s.target == target).count()
            );
            for (name, w) in cost::FEATURES.iter().zip(fitted.weights()) {
                outln!("  {name:<18} {w:>9.1}");
            }
            outln!(
                "\n{:<28} {:>12} {:>12} {:>12}",
                "frame",
                "measured",
                "fitted",
                "committed"
            );
            let committed = cost::prediction_ratios(&CycleModel::CORTEX_M4F_F32, &samples, &target);
            for ((s, r), (_, rc)) in cost::prediction_ratios(&fitted, &samples, &target)
                .iter()
                .zip(&committed)
            {
                outln!(
                    "{:<28} {:>12} {:>11.1}% {:>11.1}%",
                    format!("{} {}", s.scene, s.techniques),
                    s.instructions,
                    (r - 1.0) * 100.0,
                    (rc - 1.0) * 100.0
                );
            }
            Ok(())
        }
        Cmd::GenAssets { dir } => {
            std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
            let written = links_host::gen::write_bundled_assets(&dir)
                .map_err(|e| format!("{}: {e}", dir.display()))?;
            for p in written {
                outln!("wrote {}", p.display());
            }
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
