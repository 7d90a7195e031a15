//! `links sweep film`: a film's DM pipeline on each board profile. For every board: ONE
//! simulation of the film's frames on `nodes` nodes (frame n+1 broadcast into the nodes'
//! other bank while frame n renders, the DM's time per frame from the [`DmCost`] model on the
//! PC) and its one-node reference, giving the film's steady-state interval and speed-up, the
//! DM's time and the broadcast bytes per frame; beside it, the old figure: the steady state
//! of the film's first frame repeated ([`steady_state_interval`]).

use std::ops::Range;

use links_core::anim::Film;
use links_core::board::BoardProfile;
use links_core::dm::CompileOptions;

use crate::cluster::dmcost::{DmCost, DmMachine};
use crate::cluster::{steady_state_interval, RunCache, SimConfig, SimError};
use crate::sim::film::{compile_film, dm_model_note, simulate_film, FilmError};

/// One board's row.
#[derive(Clone, Debug, PartialEq)]
pub struct FilmPoint {
    pub board: &'static str,
    pub nodes: u16,
    pub frames: usize,
    pub film_s: f64,
    pub steady_s: f64,
    pub one_node_steady_s: f64,
    pub speedup: f64,
    /// The repeated-still speed-up (frame 0 eight times) for comparison.
    pub still_speedup: f64,
    pub dm_pc_ms: f64,
    pub dm_rc_ms: f64,
    pub broadcast_per_frame: f64,
    pub image_bytes: f64,
}

/// The study's rows, one per board.
pub fn film_points(
    film: &Film,
    frames: Range<u32>,
    opts: &CompileOptions,
    nodes: u16,
    boards: &[BoardProfile],
    progress: &dyn Fn(&str),
) -> Result<Vec<FilmPoint>, FilmError> {
    progress("compiling the frames (the DM)");
    let images = compile_film(film, frames, opts, &DmCost::ESTIMATE)?;
    let n = images.images.len();
    let mut points = Vec::new();
    for board in boards {
        progress(&format!(
            "simulating {} frames on {nodes} and 1 {} nodes",
            n, board.name
        ));
        // The board as it can be built (a relay tree past one bus's nodes on the F407).
        let cfg = SimConfig {
            cache: Some(RunCache::new()),
            ..SimConfig::buildable(*board, nodes)
        };
        let run = simulate_film(&images, &cfg, DmMachine::PC).map_err(FilmError::Sim)?;
        progress(&format!("simulating frame 0 repeated on {}", board.name));
        let first = images
            .images
            .first()
            .ok_or(FilmError::Sim(SimError::Config(
                "the film has no frames in the range".into(),
            )))?;
        let still = steady_state_interval(first, &cfg, 8).map_err(FilmError::Sim)?;
        let one = SimConfig {
            cache: Some(RunCache::new()),
            ..SimConfig::buildable(*board, 1)
        };
        let still_one =
            steady_state_interval(&images.images[0], &one, 4).map_err(FilmError::Sim)?;
        let rc = DmMachine::rc_core(board);
        let instr = images.dm_instructions.iter().sum::<f64>() / n.max(1) as f64;
        points.push(FilmPoint {
            board: board.name,
            nodes,
            frames: n,
            film_s: run.report.time_s,
            steady_s: run.steady_s(),
            one_node_steady_s: run.one_node_steady_s(),
            speedup: run.speedup(),
            still_speedup: still_one / still,
            dm_pc_ms: run.dm_s_per_frame() * 1e3,
            dm_rc_ms: rc.seconds(instr) * 1e3,
            broadcast_per_frame: run.broadcast_bytes_per_frame(),
            image_bytes: images.mean_bytes(),
        });
    }
    Ok(points)
}

/// The rows as a Markdown table with the model's note.
pub fn film_table(points: &[FilmPoint]) -> String {
    let mut s = String::from(
        "| board | nodes | frames | film (s, virtual) | steady s/frame | 1 node s/frame | film speed-up | repeated-still speed-up | DM ms/frame (PC, simulated) | DM ms/frame (on the RC's core) | broadcast B/frame | scene image B (mean) |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for p in points {
        s.push_str(&format!(
            "| {} | {} | {} | {:.3} | {:.4} | {:.3} | {:.2}x | {:.2}x | {:.2} | {:.1} | {:.0} | {:.0} |\n",
            p.board,
            p.nodes,
            p.frames,
            p.film_s,
            p.steady_s,
            p.one_node_steady_s,
            p.speedup,
            p.still_speedup,
            p.dm_pc_ms,
            p.dm_rc_ms,
            p.broadcast_per_frame,
            p.image_bytes
        ));
    }
    s.push('\n');
    s.push_str(&dm_model_note());
    s
}
