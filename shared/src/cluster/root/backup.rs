//! The RC's bookkeeping for nodes served over the serial backup line
//! ([`crate::backup`]): a node declared dead on its SPI link that still answers the
//! backup line's roll call gets work (one job at a time, an orphan first) and returns its
//! pixels over the line. Its job is kept apart from its SPI job list (in a table of
//! [`BACKUP_NODES`] entries), whose jobs stay orphans for the SPI nodes (or for itself) to
//! adopt.

use super::*;
use crate::cluster::link::NodeId;
use crate::cluster::wire::Job;

impl RootState {
    /// Whether the RC should look for `node` on the backup line at `now_us`: declared dead
    /// on SPI, or silent on SPI for two time-outs without holding the scene of the frame
    /// being handed out (its link died before it could report it).
    pub fn backup_candidate(&self, node: NodeId, now_us: u64) -> bool {
        let Some(slot) = self.nodes.get(node as usize) else {
            return false;
        };
        if node >= self.cfg.nodes || self.by_backup(node) {
            return false;
        }
        let silent = now_us.saturating_sub(slot.heard_us) >= self.timeout_us.saturating_mul(2);
        slot.dead
            || (self.timeout_us > 0
                && silent
                && !slot.ready_for(self.sched_frame)
                && slot.jobs.iter().all(Option::is_none))
    }

    /// Serve `node` over the backup line from now on (it answered a roll call after
    /// [`RootState::backup_candidate`]); it counts as dead on SPI. Returns false for a node
    /// that is not a candidate, or when [`BACKUP_NODES`] nodes are served already.
    pub fn serve_by_backup(&mut self, node: NodeId, now_us: u64) -> bool {
        if !self.backup_candidate(node, now_us) {
            return false;
        }
        let Some(entry) = self
            .backup_jobs
            .iter_mut()
            .find(|e| e.0 == node || e.0 == NodeId::MAX)
        else {
            return false;
        };
        (entry.0, entry.1) = (node, true);
        self.nodes[node as usize].dead = true;
        true
    }

    /// Whether `node` is served over the backup line.
    pub fn by_backup(&self, node: NodeId) -> bool {
        self.backup_jobs.iter().any(|e| e.0 == node && e.1)
    }

    /// The backup node reported frame `frame`'s scene complete and CRC-checked.
    pub fn backup_scene_ready(&mut self, node: NodeId, frame: u16) {
        if self.by_backup(node) {
            if let Some(slot) = self.nodes.get_mut(node as usize) {
                slot.ready[(frame % 2) as usize] = Some(frame);
            }
        }
    }

    /// The job backup node `node` holds (also after it came back on SPI), or a new one: an orphan of a dead node first
    /// (a fresh id), else the next region of the frame being handed out if the node holds
    /// its scene. `None`: nothing to do for it now.
    pub fn backup_assign(&mut self, node: NodeId) -> Option<Job> {
        let k = self.backup_entry(node)?;
        if let Some(j) = self.backup_jobs[k].2 {
            return Some(j);
        }
        if !self.backup_jobs[k].1 {
            return None;
        }
        if self.finished() {
            return None;
        }
        self.advance_schedule();
        let job = match self.orphan() {
            Some((d, k)) if self.nodes[node as usize].ready_for(self.nodes[d].jobs[k]?.frame) => {
                let j = self.nodes[d].jobs[k].take()?;
                if self.nodes[d].jobs[0].is_none() {
                    self.nodes[d].jobs.swap(0, 1);
                }
                self.report.reissued += 1;
                self.next_job += 1;
                Job {
                    id: self.next_job - 1,
                    ..j
                }
            }
            _ => {
                let frame = self.sched_frame;
                if !self.nodes[node as usize].ready_for(frame) || self.sched.exhausted() {
                    return None;
                }
                let region = self.sched.next_for(node)?;
                self.new_job(frame, region)
            }
        };
        self.backup_jobs[k].2 = Some(job);
        Some(job)
    }

    /// Backup node `node` stopped answering on the line: it is no longer served there, and
    /// the job it held becomes an orphan for the other nodes (SPI or backup) to adopt, as a
    /// dead SPI node's jobs do. Returns false when its SPI job list has no free slot for the
    /// job (it then stays with the node, served again if it answers a later roll call).
    pub fn backup_lost(&mut self, node: NodeId) -> bool {
        let Some(k) = self.backup_entry(node) else {
            return false;
        };
        self.backup_jobs[k].1 = false;
        if let Some(job) = self.backup_jobs[k].2 {
            let Some(free) = self.nodes[node as usize]
                .jobs
                .iter_mut()
                .find(|j| j.is_none())
            else {
                return false;
            };
            *free = Some(job);
        }
        // The entry is free for another node.
        self.backup_jobs[k] = (NodeId::MAX, false, None);
        true
    }

    /// The index of `node`'s entry in the backup table.
    fn backup_entry(&self, node: NodeId) -> Option<usize> {
        self.backup_jobs.iter().position(|e| e.0 == node)
    }

    /// Take a run of pixels backup node `node` returned for its job `job` (RGB8 of
    /// scanline `y` from column `x`); `done`: the job's last. Returns whether it was taken.
    #[allow(clippy::too_many_arguments)]
    pub fn backup_pixels<P: PixelSink>(
        &mut self,
        node: NodeId,
        job: u32,
        y: u16,
        x: u16,
        rgb: &[u8],
        done: bool,
        sink: &mut P,
    ) -> bool {
        let entry = self.backup_entry(node);
        let Some((k, held)) = entry
            .and_then(|k| Some((k, self.backup_jobs[k].2?)))
            .filter(|(_, j)| j.id == job)
        else {
            self.report.rejected += 1;
            return false;
        };
        let n = rgb.len() / 3;
        if !rgb.len().is_multiple_of(3)
            || y as u32 >= self.height
            || x as u32 + n as u32 > self.width
        {
            self.report.rejected += 1;
            return false;
        }
        sink.pixels(held.frame, y, x, rgb);
        self.report.accepted += 1;
        self.report.backup_runs += 1;
        self.report.pixels += n as u64;
        if done {
            self.backup_jobs[k].2 = None;
            if let Some(p) = self.prog(held.frame) {
                p.done += 1;
            }
            self.advance_schedule();
            self.update_complete();
        }
        true
    }
}
