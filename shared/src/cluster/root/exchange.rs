//! One exchange with a node: the RC's reply (jobs, scene repair, acknowledgement) and the
//! node's half taken (status, pixel runs).

use super::state::NodeSlot;
use super::*;
use crate::cluster::link::NodeId;
use crate::cluster::wire::{self, Down, SceneState, Up, SCENE_CHUNK};

impl RootState {
    /// Compose the RC's half of an exchange with `node` into `tx`; returns its length.
    pub(super) fn reply<S: SceneSource + ?Sized>(
        &mut self,
        node: NodeId,
        scenes: &S,
        tx: &mut [u8],
    ) -> usize {
        if node >= self.cfg.nodes {
            return 0;
        }
        let ack = self.nodes[node as usize].expect.wrapping_sub(1);
        let seq = self.report.exchanges as u16;
        let slot = &mut self.nodes[node as usize];
        slot.repairing = None;
        let pieces = slot.pieces;
        let next = slot.repair.and_then(|(frame, map)| {
            // Only chunks the scene has (a node that heard nothing of it asks for all).
            let chunks = scenes
                .scene(frame)
                .map_or(0, |s| s.len().div_ceil(SCENE_CHUNK)) as u32;
            // A chunk part-sent in pieces is finished first.
            if let Some((c, _)) = pieces.filter(|p| p.frame == frame).and_then(|p| p.cycle) {
                if (c as u32) < chunks {
                    return Some((frame, c as u32));
                }
            }
            let c = (0..chunks.min(wire::MAX_CHUNKS as u32))
                .find(|&c| map[(c / 32) as usize] & (1 << (c % 32)) != 0)?;
            Some((frame, c))
        });
        if next.is_none() {
            slot.repair = None;
        }
        if let Some((frame, c)) = next {
            slot.repairing = Some(c);
            if let Some(scene) = scenes.scene(frame) {
                let mut p = match slot.pieces {
                    Some(p) if p.frame == frame => p,
                    _ => Pieces::new(frame),
                };
                let c8 = c as u8;
                let at = match p.cycle {
                    Some((cc, at)) if cc == c8 => at as usize,
                    _ => {
                        if p.high.is_some_and(|h| c8 <= h) {
                            // Sent in full and asked for again: lost on the way.
                            p.size = (p.size / 2).max(wire::SCENE_PIECE as u16);
                            p.streak = 0;
                        } else {
                            p.streak = p.streak.saturating_add(1);
                            if p.streak > 2 {
                                p.size = (p.size * 2).min(SCENE_CHUNK as u16);
                                p.streak = 0;
                            }
                        }
                        0
                    }
                };
                let chunk_start = (c as usize * SCENE_CHUNK).min(scene.len());
                let chunk_end = (chunk_start + SCENE_CHUNK).min(scene.len());
                // Skip the pieces the node says it holds.
                let held = p.have.filter(|h| h.0 == c8).map_or(0, |h| h.1);
                let piece = wire::SCENE_PIECE;
                let mut at = at;
                while at < chunk_end - chunk_start && held & (1u16 << ((at / piece) % 16)) != 0 {
                    at += piece;
                }
                if at >= chunk_end - chunk_start {
                    // It holds them all by its last word: send the rest of the cycle anyway.
                    at = p.cycle.filter(|c| c.0 == c8).map_or(0, |c| c.1 as usize);
                }
                let start = (chunk_start + at).min(chunk_end);
                let end = (start + p.size as usize).min(chunk_end);
                if end >= chunk_end {
                    if let Some((_, map)) = &mut slot.repair {
                        map[(c / 32) as usize] &= !(1 << (c % 32));
                    }
                    p.cycle = None;
                    p.high = Some(p.high.map_or(c8, |h| h.max(c8)));
                } else {
                    p.cycle = Some((c8, (at + p.size as usize) as u16));
                }
                slot.pieces = Some(p);
                let crc = self.scene_crc(frame, scene, scenes.scene_crc(frame));
                let msg = Down::Scene {
                    frame,
                    offset: start as u32,
                    total: scene.len() as u32,
                    crc,
                    data: &scene[start..end],
                };
                self.report.repairs += 1;
                return wire::encode(seq, ack, &msg, tx).unwrap_or(0);
            }
        }
        if self.finished() {
            // A node that missed the Stop broadcast learns it here.
            return wire::encode(seq, ack, &Down::Stop, tx).unwrap_or(0);
        }
        self.assign(node);
        let jobs = self.nodes[node as usize].jobs;
        wire::encode(seq, ack, &Down::Work { jobs }, tx).unwrap_or(0)
    }

    /// Take a node's half of an exchange.
    pub(super) fn take<P: PixelSink>(&mut self, node: NodeId, bytes: &[u8], sink: &mut P) {
        if node >= self.cfg.nodes {
            self.report.rejected += 1;
            return;
        }
        let env = match wire::decode::<Up>(bytes) {
            Ok(e) => e,
            Err(_) => {
                self.report.bad_messages += 1;
                return;
            }
        };
        let slot = &mut self.nodes[node as usize];
        if env.msg == Up::Poll {
            self.report.polls += 1;
            return;
        }
        if env.seq != slot.expect {
            self.report.out_of_order += 1;
            return;
        }
        slot.expect = slot.expect.wrapping_add(1);
        self.report.accepted += 1;
        match env.msg {
            Up::Poll => {}
            Up::Status { scene } => slot.take_status(scene),
            msg @ (Up::Pixels { .. } | Up::PixelsRle { .. } | Up::PixelsDelta { .. }) => {
                self.take_pixels(node, msg, sink)
            }
        }
    }

    /// Take a run of pixels (plain or coded) that `node` sent in sequence.
    fn take_pixels<P: PixelSink>(&mut self, node: NodeId, msg: Up<'_>, sink: &mut P) {
        let slot = &mut self.nodes[node as usize];
        let mut buf = [0u8; 3 * wire::MAX_RUN];
        let Ok(Some(run)) = msg.pixel_run(&mut buf) else {
            self.report.rejected += 1;
            return;
        };
        let wire::PixelRun {
            job,
            frame,
            y,
            x,
            rgb,
            done,
        } = run;
        let Some(k) = slot
            .jobs
            .iter()
            .position(|j| j.is_some_and(|j| j.id == job && j.frame == frame))
        else {
            self.report.rejected += 1;
            return;
        };
        let n = rgb.len() / 3;
        if rgb.len() % 3 != 0 || y as u32 >= self.height || x as u32 + n as u32 > self.width {
            self.report.rejected += 1;
            return;
        }
        sink.pixels(frame, y, x, rgb);
        self.report.pixels += n as u64;
        if done {
            slot.jobs[k] = None;
            if slot.jobs[0].is_none() {
                slot.jobs.swap(0, 1);
            }
            if let Some(p) = self.prog(frame) {
                p.done += 1;
            }
            self.advance_schedule();
            self.update_complete();
        }
    }
}

impl NodeSlot {
    /// Take a node's report of its scene (ready, or the chunks it lacks).
    fn take_status(&mut self, scene: SceneState) {
        let slot = self;
        match scene {
            SceneState::Ready { frame } => {
                slot.ready[(frame % 2) as usize] = Some(frame);
                if slot.repair.is_some_and(|(f, _)| f == frame) {
                    slot.repair = None;
                }
                if slot.pieces.is_some_and(|p| p.frame == frame) {
                    slot.pieces = None;
                }
            }
            SceneState::Missing {
                frame,
                mut chunks,
                pieces,
            } => {
                // What it holds of its first missing chunk.
                let first = (0..wire::MAX_CHUNKS as u32)
                    .find(|&c| chunks[(c / 32) as usize] & (1 << (c % 32)) != 0);
                if let (Some(p), Some(c)) = (&mut slot.pieces, first) {
                    if p.frame == frame {
                        p.have = Some((c as u8, pieces));
                    }
                }
                // A chunk being sent in pieces that the node now has is done.
                if let Some(p) = &mut slot.pieces {
                    if let Some((c, _)) = p.cycle {
                        if p.frame == frame && chunks[(c / 32) as usize] & (1 << (c % 32)) == 0 {
                            p.cycle = None;
                        }
                    }
                }
                // The node wrote this before our reply in this exchange reached it.
                if let Some(c) = slot.repairing {
                    chunks[(c / 32) as usize] &= !(1 << (c % 32));
                }
                slot.repair = Some((frame, chunks));
            }
            SceneState::None => {}
        }
    }
}
