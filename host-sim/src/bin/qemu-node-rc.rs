//! The RC for the QEMU node check: compiles a scene (in f32, or rewritten as Q16.16 for the
//! fixed-point kernel), runs the firmware's node loop (`tests/qemu-node`) on Cortex-M4F or
//! Cortex-M3 under QEMU with the real root logic driving it over semihosting FIFOs, and
//! checks the assembled frame against the simulator's single-node render of the same image
//! and every transfer against the same node loop run on the host. See docs/qemu-node.md;
//! scripts/qemu-node builds the firmware and runs this.

use clap::{Parser, ValueEnum};
use links_core::dm::{compile, CompileOptions};
use links_core::node::Kernels;
use links_host::frame::fixed_image;
use links_host::qemu_node::{
    check_outcome, check_single_render, compare_transcripts, run_rc, simulated_frame, Corrupt,
    Event, LocalNode, QemuNode, RcOutcome,
};
use links_host::scene_file::load_scene;
use std::fs::{self, File, OpenOptions};
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The core QEMU emulates for the node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Core {
    /// Cortex-M4F on mps2-an386 (tests/qemu-node built for thumbv7em-none-eabihf)
    M4f,
    /// Cortex-M3 on mps2-an385, no FPU (tests/qemu-node built for thumbv7m-none-eabi)
    M3,
}

impl Core {
    /// QEMU's board and CPU.
    fn machine(self) -> [&'static str; 4] {
        match self {
            Core::M4f => ["-M", "mps2-an386", "-cpu", "cortex-m4"],
            Core::M3 => ["-M", "mps2-an385", "-cpu", "cortex-m3"],
        }
    }

    /// As `--core` spells it.
    fn name(self) -> &'static str {
        match self {
            Core::M4f => "m4f",
            Core::M3 => "m3",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Core::M4f => "Cortex-M4F, mps2-an386",
            Core::M3 => "Cortex-M3, mps2-an385",
        }
    }
}

/// The number format of the SceneImage the node receives (and so the kernel it runs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Precision {
    /// The DM's f32 image: the f32 kernel
    F32,
    /// The DM's Q16.16 rewrite of it (`fixed_image::to_fixed`): the fixed-point kernel
    Fixed,
}

impl Precision {
    /// The host node's kernel: the one the firmware built for this precision carries.
    fn kernels(self) -> Kernels {
        match self {
            Precision::F32 => Kernels::F32,
            Precision::Fixed => Kernels::Fixed,
        }
    }
}

#[derive(Parser)]
#[command(about = "Run the NC node loop on Cortex-M under QEMU against the real RC logic")]
struct Args {
    /// The firmware (tests/qemu-node, built for the --core's target and kernel)
    #[arg(long)]
    elf: PathBuf,
    /// The core QEMU runs the firmware on
    #[arg(long, value_enum, default_value_t = Core::M4f)]
    core: Core,
    /// The image's number format: f32, or Q16.16 for the fixed-point kernel (checked against
    /// host-sim's single-node fixed render)
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    precision: Precision,
    /// Scene file to render
    #[arg(long)]
    scene: PathBuf,
    #[arg(long, default_value_t = 48)]
    width: u32,
    #[arg(long, default_value_t = 45)]
    height: u32,
    /// QEMU runs; every run must give the same instruction counts
    #[arg(long, default_value_t = 1)]
    runs: u32,
    /// Give up on a QEMU run after this many seconds (wall clock)
    #[arg(long, default_value_t = 120)]
    timeout_s: u64,
    /// Directory for the link FIFOs and QEMU's output (default: a fresh one under the
    /// system's temporary directory)
    #[arg(long)]
    work: Option<PathBuf>,
    #[arg(long, default_value = "qemu-system-arm")]
    qemu: String,
    /// Flip one bit in these RC -> NC messages (0-based delivery numbers, comma-separated), on
    /// the way into both the host node and the QEMU node: each must count exactly these as
    /// bad messages, recover, and still return the simulator's pixels
    #[arg(long, value_delimiter = ',')]
    corrupt_down: Vec<usize>,
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("qemu-node-rc: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn fifo(path: &Path) -> Result<(), String> {
    if path.exists() {
        fs::remove_file(path).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    let ok = Command::new("mkfifo")
        .arg(path)
        .status()
        .map_err(|e| format!("mkfifo: {e}"))?
        .success();
    ok.then_some(())
        .ok_or_else(|| format!("mkfifo {} failed", path.display()))
}

fn tail(path: &Path) -> String {
    let t = fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = t.lines().collect();
    lines[lines.len().saturating_sub(20)..].join("\n")
}

/// One QEMU run of the node against the RC; returns its outcome and wall time.
fn qemu_run(a: &Args, image: &[u8], work: &Path) -> Result<(RcOutcome, f64), String> {
    fs::create_dir_all(work).map_err(|e| format!("{}: {e}", work.display()))?;
    let (down, up) = (work.join("nc-down"), work.join("nc-up"));
    fifo(&down)?;
    fifo(&up)?;
    let (out, err) = (work.join("qemu.out"), work.join("qemu.err"));
    let elf = fs::canonicalize(&a.elf).map_err(|e| format!("{}: {e}", a.elf.display()))?;
    let file = |p: &Path| File::create(p).map_err(|e| format!("{}: {e}", p.display()));
    let started = Instant::now();
    let child = Command::new(&a.qemu)
        .args(a.core.machine())
        .arg("-nographic")
        .args(["-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=0", "-kernel"])
        .arg(&elf)
        .current_dir(work)
        .stdin(Stdio::null())
        .stdout(file(&out)?)
        .stderr(file(&err)?)
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", a.qemu))?;
    let child = Arc::new(Mutex::new(child));
    let done = Arc::new(AtomicBool::new(false));
    let opened = Arc::new(AtomicBool::new(false));
    // The watchdog: a QEMU that hangs, or dies before opening the link (the RC would block
    // in open() for ever), fails the run loudly.
    let watchdog = {
        let (child, done, opened, err) = (child.clone(), done.clone(), opened.clone(), err.clone());
        // A work directory of our own making goes with us.
        let scratch = a.work.is_none().then(|| work.to_path_buf());
        let leave = move |msg: String| -> ! {
            eprintln!("qemu-node-rc: error: {msg}");
            if let Some(d) = &scratch {
                let _ = fs::remove_dir_all(d);
            }
            std::process::exit(1)
        };
        let limit = Duration::from_secs(a.timeout_s);
        std::thread::spawn(move || loop {
            std::thread::sleep(Duration::from_millis(50));
            if done.load(Ordering::SeqCst) {
                return;
            }
            let mut c = child.lock().unwrap_or_else(|p| p.into_inner());
            if started.elapsed() > limit {
                let _ = c.kill();
                let _ = c.wait();
                leave(format!(
                    "QEMU timed out after {} s (the node loop did not finish)\n{}",
                    limit.as_secs(),
                    tail(&err)
                ));
            }
            if let Ok(Some(status)) = c.try_wait() {
                // Once the link is open the RC sees QEMU's end itself (end of file); before
                // that it would wait in open() for ever. (A grace period: the opens may be
                // just finishing.)
                drop(c);
                let t = Instant::now();
                while !opened.load(Ordering::SeqCst) && t.elapsed() < Duration::from_secs(2) {
                    std::thread::sleep(Duration::from_millis(10));
                }
                if !opened.load(Ordering::SeqCst) {
                    leave(format!(
                        "QEMU exited ({status}) before the run ended\n{}",
                        tail(&err)
                    ));
                }
                return;
            }
        })
    };
    // Same order as the firmware: down, then up (each open waits for the other end).
    let result = (|| {
        let down = OpenOptions::new()
            .write(true)
            .open(&down)
            .map_err(|e| format!("{}: {e}", down.display()))?;
        let up = File::open(&up).map_err(|e| format!("{}: {e}", up.display()))?;
        opened.store(true, Ordering::SeqCst);
        let node = QemuNode::new(BufReader::new(up), down);
        run_rc(image, Corrupt::new(node, a.corrupt_down.clone()))
    })();
    let status = loop {
        let mut c = child.lock().unwrap_or_else(|p| p.into_inner());
        match c.try_wait() {
            Ok(Some(s)) => break Ok(s),
            Ok(None) if result.is_err() => {
                let _ = c.kill();
            }
            Ok(None) => {}
            Err(e) => break Err(e.to_string()),
        }
        drop(c);
        std::thread::sleep(Duration::from_millis(10));
    };
    let wall = started.elapsed().as_secs_f64();
    done.store(true, Ordering::SeqCst);
    let _ = watchdog.join();
    let outcome = result.map_err(|e| format!("{e}\nQEMU's stderr:\n{}", tail(&err)))?;
    let status = status?;
    if !status.success() {
        return Err(format!(
            "QEMU exited with {status} after the run\n{}",
            tail(&err)
        ));
    }
    Ok((outcome, wall))
}

/// The SceneImage the node receives: the DM's f32 image, or its Q16.16 rewrite.
fn scene_image(a: &Args) -> Result<Vec<u8>, String> {
    let desc = load_scene(&a.scene).map_err(|e| e.to_string())?;
    let opts = CompileOptions {
        width: Some(a.width),
        height: Some(a.height),
        ..Default::default()
    };
    let image = compile(&desc, &opts)
        .map_err(|e| format!("{}: {e}", a.scene.display()))?
        .bytes;
    match a.precision {
        Precision::F32 => Ok(image),
        Precision::Fixed => fixed_image(&image).map_err(|e| format!("{}: {e}", a.scene.display())),
    }
}

fn run(a: Args) -> Result<(), String> {
    let image = scene_image(&a)?;
    let name = format!("{} {}x{}", a.scene.display(), a.width, a.height);
    println!(
        "qemu-node: {name}, {} SceneImage {} bytes, node on {}",
        a.precision.kernels().name(),
        image.len(),
        a.core.label()
    );

    let want = simulated_frame(&image)?;
    let single = check_single_render(&image, &want)?;
    let host = run_rc(
        &image,
        Corrupt::new(
            LocalNode::with_kernels(a.precision.kernels()),
            a.corrupt_down.clone(),
        ),
    )
    .map_err(|e| format!("host node: {e}"))?;
    let downs: Vec<&Event> = host
        .transcript
        .iter()
        .filter(|e| matches!(e, Event::Down { .. }))
        .collect();
    for &i in &a.corrupt_down {
        let e = downs.get(i).ok_or_else(|| {
            format!(
                "--corrupt-down {i}: the run has only {} RC -> NC messages",
                downs.len()
            )
        })?;
        println!("  damaging RC -> NC message {i} (one bit): {e}");
    }
    let corrupted = a.corrupt_down.len() as u32;
    check_outcome(&host, &want, corrupted).map_err(|e| format!("host node: {e}"))?;
    println!(
        "  host node (run_node on the host, {}) under the lock-step RC: {} transfers; frame equals the simulator's single-node render (= the {} single render)",
        a.precision.kernels(),
        host.transcript.len(),
        single.name()
    );

    let work = a.work.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("links-qemu-node-{}", std::process::id()))
    });
    let r = qemu_runs(&a, &image, &want, &host, &work, corrupted);
    if a.work.is_none() {
        let _ = fs::remove_dir_all(&work);
    }
    r
}

/// The QEMU runs, each checked against the simulator's frame and the host node's run.
fn qemu_runs(
    a: &Args,
    image: &[u8],
    want: &[u8],
    host: &RcOutcome,
    work: &Path,
    corrupted: u32,
) -> Result<(), String> {
    let mut first: Option<Vec<(String, u64)>> = None;
    for run in 1..=a.runs.max(1) {
        let (q, wall) = qemu_run(a, image, work)?;
        check_outcome(&q, want, corrupted).map_err(|e| format!("QEMU node, run {run}: {e}"))?;
        compare_transcripts(&q, host).map_err(|e| format!("QEMU node, run {run}: {e}"))?;
        let c = &q.end.counters;
        match &first {
            None => first = Some(c.clone()),
            Some(f) if f != c => {
                return Err(format!(
                    "run {run} counted differently from run 1 (QEMU instruction counts must be deterministic):\n  run 1: {f:?}\n  run {run}: {c:?}"
                ))
            }
            Some(_) => {}
        }
        report_run(a, &q, run, corrupted)?;
        println!("  QEMU wall time {wall:.2} s");
    }
    Ok(())
}

/// Print one checked QEMU run: the RC's and the node's counts, the node loop's instructions
/// split into rendering, protocol and link I/O, and the `RESULT` line scripts/qemu-node reads.
fn report_run(a: &Args, q: &RcOutcome, run: u32, corrupted: u32) -> Result<(), String> {
    let get = |k: &str| {
        q.end
            .counter(k)
            .ok_or_else(|| format!("the node's end record lacks {k}"))
    };
    let (total, render, link) = (
        get("instr_total")?,
        get("instr_render")?,
        get("instr_link")?,
    );
    let protocol = total
        .checked_sub(render + link)
        .ok_or("render + link instructions exceed the total")?;
    let pixels = (q.width * q.height) as u64;
    let pct = |x: u64| 100.0 * x as f64 / total as f64;
    let r = &q.root;
    println!(
        "  QEMU node (run_node on {}, {}), run {run}: the same {} transfers byte for byte, the same node report; frame equals the simulator's ({} pixels)",
        a.core.label(),
        a.precision.kernels(),
        q.transcript.len(),
        pixels
    );
    println!(
        "  RC: {} exchanges, {} broadcasts, {} jobs, {} messages accepted, {} polls, {} scene chunks repaired, {} duplicates dropped; node: {} damaged messages counted",
        r.exchanges, r.broadcasts, r.jobs, r.accepted, r.polls, r.repairs, r.out_of_order, corrupted
    );
    println!(
        "  node loop: {total} instructions = render {render} ({:.1}%) + protocol {protocol} ({:.1}%) + link I/O {link} ({:.1}%); {} per pixel, {} of them outside rendering",
        pct(render),
        pct(protocol),
        pct(link),
        total / pixels,
        (protocol + link) / pixels
    );
    // Where the protocol instructions go, from unit costs the firmware measured after the
    // loop (estimates: counts x unit costs).
    let (validate, open, crc, scene_bytes) = (
        get("unit_validate")?,
        get("unit_open")?,
        get("unit_scene_crc")?,
        get("scene_bytes")?.max(1),
    );
    let (validations, opens) = (get("validations")?, get("opens")?);
    let crc_bytes = get("bytes_in")? + get("bytes_out")? + scene_bytes;
    let v_est = validations * validate + opens * open;
    let c_est = crc_bytes * crc / scene_bytes;
    println!(
        "  of the protocol work, about: scene validation {v_est} ({:.1}%: SceneView::new of the {scene_bytes}-byte scene, {validate} instructions, {validations} time(s), once per scene received; SceneView::open_validated, {open} instructions, {opens} times, once per run rendered and per Work reply); CRC-32 {c_est} ({:.1}%: {crc_bytes} bytes at {:.1} per byte); the rest {} ({:.1}%: postcard, RLE, chunk copies, bookkeeping)",
        pct(v_est),
        pct(c_est),
        crc as f64 / scene_bytes as f64,
        protocol.saturating_sub(v_est + c_est),
        pct(protocol.saturating_sub(v_est + c_est))
    );
    println!(
        "RESULT scene={} core={} precision={} w={} h={} pixels={pixels} transfers={} instr_total={total} instr_render={render} instr_protocol={protocol} instr_link={link} {}",
        a.scene.display(),
        a.core.name(),
        a.precision.kernels().name(),
        q.width,
        q.height,
        q.transcript.len(),
        q.end
            .counters
            .iter()
            .filter(|(k, _)| !k.starts_with("instr_"))
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    Ok(())
}
