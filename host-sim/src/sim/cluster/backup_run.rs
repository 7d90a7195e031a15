//! The backup line inside a cluster simulation: one more task on the executor, the RC's
//! side of the serial line next to its SPI buses. At the start it calls the roll of every
//! node on the line; whenever the RC declares a node dead on SPI, or a node stays silent on
//! SPI for two time-outs without the scene ([`RootState::backup_candidate`]), it calls that
//! node again,
//! and a node that answers (fault injection: "SPI link dead, node alive",
//! [`super::SimConfig::spi_dead`]) is served over the line from then on: the scene of the
//! frame being handed out, one job at a time ([`RootState::backup_assign`]), its pixels
//! polled back into the frame memory ([`RootState::backup_pixels`]): links-core's RC side
//! ([`BackupRc`] over [`RootWork`]) as the RC firmware runs it, over the simulated line. Every
//! frame on the line takes its time on the board profile's line in virtual time.

use super::backup::{BackupSimError, Line, SimLine, SimNode, Work, RC_RGB};
use super::exec::{Delay, Ps, SharedClock};
use super::framemem::{FrameMemory, ViaRoot};
use super::SimConfig;
use links_core::backup::{self, rc, BackupRc, RootWork, Turn, MAX_ADDR};
use links_core::root::RootState;
use std::cell::RefCell;

/// What the backup line did in a cluster simulation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LineCounters {
    /// Frames and bytes on the line, reply timeouts waited out.
    pub frames: u64,
    pub bytes: u64,
    pub timeouts: u64,
    /// Time the line was busy (s).
    pub busy_s: f64,
    /// Nodes absent at the first roll call.
    pub absent: Vec<u16>,
    /// Nodes served over the line (their SPI link dead).
    pub served: Vec<u16>,
    /// Jobs done and pixels returned over the line.
    pub jobs: u32,
    pub pixels: u64,
    /// Compute time of the served nodes' backup renders (s).
    pub compute_s: f64,
}

/// How long the task sleeps when it has nothing to do (no node on the line).
const IDLE_PS: Ps = 1_000_000_000; // 1 ms

/// The line's shared parts.
pub(super) struct LineSetup<'a> {
    pub cfg: &'a SimConfig,
    pub clock: SharedClock,
    pub root: &'a RefCell<RootState>,
    pub fm: &'a RefCell<FrameMemory>,
    pub scenes: Vec<&'a [u8]>,
    pub work: Work<'a>,
    pub counters: &'a RefCell<LineCounters>,
}

/// Run the line until the cluster finishes (or a protocol error, reported as the line's).
pub(super) async fn run_line(s: LineSetup<'_>) -> Result<(), BackupSimError> {
    let on_line = s.cfg.nodes.min(backup::MAX_ADDR as u16);
    let largest = s.scenes.iter().map(|b| b.len()).max().unwrap_or(0);
    let mut banks: Vec<Vec<u8>> = (0..on_line)
        .map(|n| vec![0u8; if is_spi_dead(s.cfg, n) { largest } else { 0 }])
        .collect();
    let mut nodes: Vec<SimNode<'_>> = banks
        .iter_mut()
        .enumerate()
        .map(|(i, b)| SimNode::new(i as u8 + 1, b, true))
        .collect();
    let mut line = Line::new(s.cfg.profile.backup);
    let mut called = vec![false; on_line as usize];
    let mut rc = BackupRc::<{ MAX_ADDR as usize }>::new();
    let sink = RefCell::new(ViaRoot(s.fm));
    let mut work = RootWork {
        root: s.root,
        scenes: &s.scenes[..],
        sink: &sink,
    };
    let mut rgb = [0u8; RC_RGB];
    let calls = {
        let mut sim = SimLine {
            line: &mut line,
            nodes: &mut nodes,
            work: &s.work,
        };
        embassy_futures::block_on(rc::roll_call(&mut sim, on_line as u8))?
    };
    s.counters.borrow_mut().absent = calls.absent().map(|a| a as u16 - 1).collect();
    wait(&s.clock, &line).await;
    while !s.root.borrow().finished() {
        let now = s.clock.borrow().now;
        set_alive(s.cfg, &mut nodes, now);
        line.now = now;
        let mut sim = SimLine {
            line: &mut line,
            nodes: &mut nodes,
            work: &s.work,
        };
        for n in 0..on_line {
            let now_us = sim.line.now / 1_000_000;
            if called[n as usize] || !s.root.borrow().backup_candidate(n, now_us) {
                continue;
            }
            called[n as usize] = true;
            let answer = rc::ask_health(&mut sim, n as u8 + 1).await?;
            let now_us = sim.line.now / 1_000_000;
            if answer.is_some() && s.root.borrow_mut().serve_by_backup(n, now_us) {
                rc.serve(n as u8 + 1);
                s.counters.borrow_mut().served.push(n);
            }
        }
        let mut busy = false;
        for k in 0..MAX_ADDR as usize {
            let before = rc.counters;
            let addr = rc.addr_at(k);
            let turn = rc.turn(k, &mut sim, &mut work, &mut rgb).await?;
            if let (Turn::Work { .. }, Some(a)) = (turn, addr) {
                sim.nodes[a as usize - 1].jobs += 1;
            }
            let mut c = s.counters.borrow_mut();
            c.pixels += rc.counters.pixels - before.pixels;
            c.jobs += rc.counters.jobs - before.jobs;
            busy |= turn != Turn::Nothing;
        }
        if !busy {
            line.now = line.now.max(now + IDLE_PS);
        }
        update(&s, &line, &nodes);
        wait(&s.clock, &line).await;
    }
    update(&s, &line, &nodes);
    Ok(())
}

fn is_spi_dead(cfg: &SimConfig, n: u16) -> bool {
    cfg.spi_dead.iter().any(|d| d.node == n)
}

/// A node is on the line unless it died altogether (`deaths`) and is not merely SPI-dead.
fn set_alive(cfg: &SimConfig, nodes: &mut [SimNode<'_>], now: Ps) {
    for (n, node) in nodes.iter_mut().enumerate() {
        let n = n as u16;
        node.alive = is_spi_dead(cfg, n)
            || !cfg
                .deaths
                .iter()
                .any(|d| d.node == n && (d.at_s * 1e12).round() as Ps <= now);
    }
}

async fn wait(clock: &SharedClock, line: &Line) {
    if line.now > clock.borrow().now {
        Delay::new(clock, line.now).await;
    }
}

fn update(s: &LineSetup<'_>, line: &Line, nodes: &[SimNode<'_>]) {
    let mut c = s.counters.borrow_mut();
    c.frames = line.frames;
    c.bytes = line.bytes;
    c.timeouts = line.timeouts;
    c.busy_s = line.busy as f64 * 1e-12;
    c.compute_s = nodes.iter().map(|n| n.compute as f64 * 1e-12).sum();
}
