//! `xtask`: the logic of the repository's QEMU scripts, in Rust. The scripts stay launchers
//! (build, run QEMU, keep its output); this binary reads that output, checks it and writes
//! the reports.
//!
//! - `xtask qemu-bench DIR`: `scripts/qemu-bench`'s checks and outputs. `DIR` holds each
//!   target's two runs (`TARGET.run1`, `TARGET.run2`) and `want` (the `scene techniques
//!   backend` of every frame each target must render, in order). Writes `DIR/samples.csv`
//!   (rows of [`links_host::cost::Sample`], the cost model's input) and `DIR/table.md`, and
//!   prints the table.
//!
//! It lives in links-host (not a crate of its own) because its rows are the cost model's
//! type: one struct written here and read by `links calibrate`.

mod checks;
mod report;
mod run_log;

use clap::{Parser, Subcommand};
use run_log::RunLog;
use std::fmt;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// Why a check or a step failed.
#[derive(Debug)]
pub enum BenchError {
    /// A file could not be read or written.
    Io { path: PathBuf, err: std::io::Error },
    /// A line of the benchmark's output lacks a field or has a bad value.
    BadLine { line: String, why: String },
    /// The output does not show what it must.
    Check(String),
}

impl fmt::Display for BenchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BenchError::Io { path, err } => write!(f, "{}: {err}", path.display()),
            BenchError::BadLine { line, why } => write!(f, "{why} in: {line}"),
            BenchError::Check(msg) => f.write_str(msg),
        }
    }
}

impl std::error::Error for BenchError {}

#[derive(Parser)]
#[command(about = "The QEMU scripts' checks and reports")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Check scripts/qemu-bench's runs and write samples.csv and table.md beside them.
    QemuBench {
        /// The directory with TARGET.run1, TARGET.run2 and want.
        dir: PathBuf,
        /// The targets, in the tables' order.
        #[arg(long, num_args = 1.., required = true)]
        targets: Vec<String>,
        /// scripts/qemu-profile's Markdown section, for the doc.
        #[arg(long)]
        profile: Option<PathBuf>,
    },
}

fn read(path: &Path) -> Result<String, BenchError> {
    std::fs::read_to_string(path).map_err(|err| BenchError::Io {
        path: path.into(),
        err,
    })
}

fn write(path: &Path, text: &str) -> Result<(), BenchError> {
    std::fs::write(path, text).map_err(|err| BenchError::Io {
        path: path.into(),
        err,
    })
}

/// The first line a tool prints for `--version` ("?" when it cannot be run).
fn version(tool: &str) -> String {
    Command::new(tool)
        .arg("--version")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|s| s.lines().next().map(str::to_string))
        .unwrap_or_else(|| "?".into())
}

fn qemu_bench(dir: &Path, targets: &[String], profile: Option<&Path>) -> Result<(), BenchError> {
    let want: Vec<String> = read(&dir.join("want"))?
        .lines()
        .filter(|l| !l.is_empty())
        .map(str::to_string)
        .collect();
    let mut logs = Vec::new();
    for t in targets {
        let run1 = read(&dir.join(format!("{t}.run1")))?;
        let run2 = read(&dir.join(format!("{t}.run2")))?;
        if run1 != run2 {
            return Err(BenchError::Check(format!(
                "{t}: the two runs gave different counts (QEMU instruction counts must be deterministic)"
            )));
        }
        let log = RunLog::parse(t, &run1)?;
        checks::target(t, &log, &want)?;
        logs.push((t.clone(), log));
    }
    checks::same_pixels(&logs)?;
    let csv = report::csv(&logs);
    let nrows = csv.lines().count() - 1;
    if nrows != targets.len() * want.len() {
        return Err(BenchError::Check(format!(
            "the CSV has {nrows} samples, not one per target, backend, scene and technique set"
        )));
    }
    write(&dir.join("samples.csv"), &csv)?;
    let profile = profile.map(read).transpose()?;
    let toolchain = format!("{}; {}", version("rustc"), version("qemu-system-arm"));
    let md = report::markdown(&logs, &toolchain, profile.as_deref());
    write(&dir.join("table.md"), &md)?;
    print!("\n=== results\n{md}");
    let scenes: std::collections::BTreeSet<&str> =
        want.iter().filter_map(|w| w.split(' ').next()).collect();
    println!(
        "\nqemu-bench: {} targets x 2 runs deterministic; {nrows} whole-frame samples ({} scene, technique set and backend combinations per target, {} scenes); pixels equal the host's render in each backend",
        targets.len(),
        want.len(),
        scenes.len()
    );
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.cmd {
        Cmd::QemuBench {
            dir,
            targets,
            profile,
        } => qemu_bench(dir, targets, profile.as_deref()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
