//! The QEMU bench's output, typed: the `RUN`, `OP`, `CAL` and `END` lines the firmware
//! (`tests/qemu-bench/src/main.rs`) prints through semihosting, each `KEY key=value ...`.

use crate::BenchError;
use links_core::render::Stats;
use links_host::cost::Sample;
use std::collections::HashMap;

/// One whole frame rendered on the target (a `RUN` line).
#[derive(Clone, Debug)]
pub struct Run {
    /// The CSV row: target, backend, scene, technique set, pixels, instructions, counters.
    pub sample: Sample,
    pub width: u64,
    pub height: u64,
    pub mismatched: u64,
    pub stats_match: bool,
    /// FNV-1a of the frame's pixels.
    pub hash: String,
}

/// One micro-benchmark (an `OP` line): instructions per call, as printed (`123.45`).
#[derive(Clone, Debug)]
pub struct Op {
    /// The operation, with its blob group when it has one.
    pub key: String,
    pub backend: String,
    pub per_op: f64,
}

/// One target's output, in the order printed.
#[derive(Clone, Debug, Default)]
pub struct RunLog {
    pub runs: Vec<Run>,
    pub ops: Vec<Op>,
    /// `(measured_instr, expected_instr)` of each loop of known length (`CAL` lines).
    pub calibrations: Vec<(i64, i64)>,
    /// Whether an `END ok=true` line came.
    pub ended_ok: bool,
}

/// The `key=value` fields of a line after its first word.
fn fields(line: &str) -> HashMap<&str, &str> {
    line.split_whitespace()
        .skip(1)
        .filter_map(|f| f.split_once('='))
        .collect()
}

/// A field's text, or an error naming the line.
fn text<'a>(f: &HashMap<&str, &'a str>, key: &str, line: &str) -> Result<&'a str, BenchError> {
    f.get(key).copied().ok_or_else(|| BenchError::BadLine {
        line: line.into(),
        why: format!("no {key}"),
    })
}

/// A field's count, or an error naming the line.
fn count(f: &HashMap<&str, &str>, key: &str, line: &str) -> Result<u64, BenchError> {
    let v = text(f, key, line)?;
    v.parse().map_err(|_| BenchError::BadLine {
        line: line.into(),
        why: format!("{key}={v} is not a count"),
    })
}

impl RunLog {
    /// Reads one target's output.
    pub fn parse(target: &str, output: &str) -> Result<RunLog, BenchError> {
        let mut log = RunLog::default();
        for line in output.lines() {
            let f = fields(line);
            match line.split_whitespace().next() {
                Some("RUN") => log.runs.push(Self::run(target, &f, line)?),
                Some("OP") => {
                    let mut key = text(&f, "name", line)?.to_string();
                    if let Some(g) = f.get("group") {
                        let balls = text(&f, "balls", line)?;
                        let kernel = text(&f, "kernel", line)?;
                        key = format!("{key} (group {g}, {balls} balls, {kernel})");
                    }
                    let per_op = text(&f, "per_op", line)?;
                    log.ops.push(Op {
                        key,
                        backend: text(&f, "backend", line)?.into(),
                        per_op: per_op.parse().map_err(|_| BenchError::BadLine {
                            line: line.into(),
                            why: format!("per_op={per_op} is not a number"),
                        })?,
                    });
                }
                Some("CAL") => {
                    let signed = |k| -> Result<i64, BenchError> {
                        let v = count(&f, k, line)?;
                        i64::try_from(v).map_err(|_| BenchError::BadLine {
                            line: line.into(),
                            why: format!("{k} too large"),
                        })
                    };
                    log.calibrations
                        .push((signed("measured_instr")?, signed("expected_instr")?));
                }
                Some("END") => log.ended_ok |= f.get("ok") == Some(&"true"),
                _ => {}
            }
        }
        Ok(log)
    }

    fn run(target: &str, f: &HashMap<&str, &str>, line: &str) -> Result<Run, BenchError> {
        let mut values = [0u64; Stats::COUNT];
        for (v, name) in values.iter_mut().zip(Stats::NAMES) {
            *v = count(f, name, line)?;
        }
        Ok(Run {
            sample: Sample {
                target: target.into(),
                backend: text(f, "backend", line)?.into(),
                scene: text(f, "scene", line)?.into(),
                techniques: text(f, "techniques", line)?.into(),
                pixels: count(f, "pixels", line)?,
                stats: Stats::from_values(values),
                instructions: count(f, "instr", line)?,
            },
            width: count(f, "w", line)?,
            height: count(f, "h", line)?,
            mismatched: count(f, "mismatched", line)?,
            stats_match: text(f, "stats_match", line)? == "true",
            hash: text(f, "hash", line)?.into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_each_kind_of_line() {
        let mut run = String::from(
            "RUN scene=glass techniques=all backend=f32 w=16 h=15 pixels=240 bytes=9 instr=1000 validate_instr=5",
        );
        for (i, n) in Stats::NAMES.iter().enumerate() {
            run += &format!(" {n}={i}");
        }
        run += " mismatched=0 max_diff=0 stats_match=true hash=00ff host_hash=00ff";
        let out = format!(
            "hello\n{run}\nOP name=sqrt backend=f32 n=4 hits=0 instr=8 empty_loop=1 per_op=2.00\n\
             OP name=blob group=1 balls=3 kernel=wyvill backend=f32 n=1 hits=0 instr=8 empty_loop=1 per_op=8.50\n\
             CAL measured_instr=1000 expected_instr=990\nEND ok=true\n"
        );
        let log = RunLog::parse("m4", &out).unwrap();
        let r = &log.runs[0];
        assert_eq!(
            (r.sample.instructions, r.sample.pixels, r.width),
            (1000, 240, 16)
        );
        assert_eq!(r.sample.stats.shadow_rays, 1);
        assert_eq!(log.ops[1].key, "blob (group 1, 3 balls, wyvill)");
        assert_eq!(log.calibrations, [(1000, 990)]);
        assert!(log.ended_ok);
        assert!(RunLog::parse("m4", "RUN scene=x\n").is_err());
    }
}
