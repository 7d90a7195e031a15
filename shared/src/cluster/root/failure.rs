//! Node failure: hearing from nodes, their deadlines, declaring the silent ones dead,
//! orphaning their work and calling rolls so idle nodes ask for it.

use super::*;
use crate::cluster::link::NodeId;
use crate::cluster::sched::Policy;

impl RootState {
    /// Note an exchange with `node` at `now_us`; a node declared dead is live again. If it
    /// was declared dead while rendering, the time-out was shorter than its run: the time-out
    /// becomes at least twice the silence it was declared dead for. Silences of live nodes
    /// are bounded by their longest run, so this cannot grow without bound, however many
    /// nodes are falsely declared dead at once.
    pub fn heard(&mut self, node: NodeId, now_us: u64) {
        let Some(slot) = self.nodes.get_mut(node as usize) else {
            return;
        };
        if slot.dead {
            slot.dead = false;
            // A false alarm taken to the backup line: back on SPI (the job it holds there
            // is still taken when its pixels come).
            if let Some(e) = self.backup_jobs.iter_mut().find(|e| e.0 == node) {
                e.1 = false;
            }
            self.report.revived += 1;
            if slot.dead_rendering {
                let silence = now_us.saturating_sub(slot.heard_us);
                self.timeout_us = self.timeout_us.max(silence.saturating_mul(2));
            }
            slot.dead_rendering = false;
        }
        slot.heard_us = now_us;
    }

    pub(super) fn nodes_in(&self, first: NodeId, count: u16) -> core::ops::Range<usize> {
        let end = (first as usize + count as usize).min(self.cfg.nodes as usize);
        (first as usize).min(end)..end
    }

    /// Static split: whether node `n`'s region of the frame being handed out is still
    /// waiting for it.
    pub(super) fn owes_region(&self, n: usize) -> bool {
        matches!(self.cfg.policy, Policy::Static { .. })
            && u16::try_from(n).is_ok_and(|n| self.sched.reserved(n))
    }

    /// When live node `n` must have spoken by, if it owes the RC an exchange, as (silence
    /// counted from, deadline): a node holding jobs a time-out after it was last heard; a
    /// node owing its static region (`scene_sent_us`: when its bus finished broadcasting the
    /// scene of the frame being handed out) two time-outs after the later of that and its
    /// last exchange.
    pub(super) fn deadline(&self, n: usize, scene_sent_us: Option<u64>) -> Option<(u64, u64)> {
        let slot = self.nodes.get(n)?;
        if slot.dead || self.timeout_us == 0 {
            return None;
        }
        if slot.jobs.iter().any(|j| j.is_some()) {
            return Some((slot.heard_us, slot.heard_us.saturating_add(self.timeout_us)));
        }
        let sent = scene_sent_us?;
        if !self.owes_region(n) {
            return None;
        }
        let since = slot.heard_us.max(sent);
        Some((
            since,
            since.saturating_add(self.timeout_us.saturating_mul(2)),
        ))
    }

    /// When the first live node of `first..first + count` that owes the RC an exchange times
    /// out (µs). `scene_sent_us`: when this bus finished broadcasting the scene of the frame
    /// being handed out ([`RootState::handing_out`]), if it has.
    pub fn next_deadline(
        &self,
        first: NodeId,
        count: u16,
        scene_sent_us: Option<u64>,
    ) -> Option<u64> {
        self.nodes_in(first, count)
            .filter_map(|n| self.deadline(n, scene_sent_us))
            .map(|(_, d)| d)
            .min()
    }

    /// Declare dead every live node of `first..first + count` that owes the RC an exchange
    /// and has been silent past its deadline at `now_us` (see [`RootState::next_deadline`]),
    /// and issue the static region a dead node owes to that node as an orphan. Call only
    /// while none of them has its ready line up. Returns how many died.
    pub fn expire(
        &mut self,
        first: NodeId,
        count: u16,
        now_us: u64,
        scene_sent_us: Option<u64>,
    ) -> u16 {
        if self.timeout_us == 0 {
            return 0;
        }
        let mut died = 0u16;
        let mut orphaned = 0u16;
        for n in self.nodes_in(first, count) {
            if let Some((since, deadline)) = self.deadline(n, scene_sent_us) {
                if now_us >= deadline {
                    let slot = &mut self.nodes[n];
                    let rendering = slot.jobs.iter().any(|j| j.is_some());
                    slot.dead = true;
                    slot.dead_rendering = rendering;
                    slot.heard_us = since;
                    slot.repair = None;
                    slot.repairing = None;
                    slot.pieces = None;
                    died += 1;
                    if rendering {
                        orphaned += 1;
                    }
                }
            }
            if self.nodes[n].dead && self.orphan_region(n) {
                orphaned += 1;
            }
        }
        self.orphaned = self.orphaned.saturating_add(orphaned);
        self.report.timeouts += died as u32;
        died
    }

    /// Static split: issue dead node `n`'s region of the frame being handed out into its own
    /// slot, as an orphan for a live node to adopt. Returns whether it did.
    pub(super) fn orphan_region(&mut self, n: usize) -> bool {
        if !self.owes_region(n) {
            return false;
        }
        let Some(free) = self.nodes[n].jobs.iter().position(|j| j.is_none()) else {
            return false;
        };
        let Some(region) = self.sched.next_for(n as NodeId) else {
            return false;
        };
        let job = self.new_job(self.sched_frame, region);
        self.nodes[n].jobs[free] = Some(job);
        true
    }

    /// The frame to call a roll ([`Down::Wake`](crate::cluster::wire::Down::Wake)) for on nodes `first..first + count`, if
    /// work waits that no node there can otherwise be asked for: jobs of a dead node (any
    /// bus), or a live node holding no jobs that has not reported the scene of the frame
    /// being handed out although this bus has broadcast it (`broadcast_upto`: frames below it
    /// are fully broadcast here) and no repair is under way. `None` with time-outs off.
    pub fn roll_call(&self, first: NodeId, count: u16, broadcast_upto: u16) -> Option<u16> {
        if self.finished() || self.timeout_us == 0 {
            return None;
        }
        if let Some((d, k)) = self.orphan() {
            return self.nodes[d].jobs[k].map(|j| j.frame);
        }
        let f = self.sched_frame;
        if f >= broadcast_upto || self.sched.exhausted() {
            return None;
        }
        self.nodes[self.nodes_in(first, count)]
            .iter()
            .any(|s| {
                !s.dead
                    && !s.ready_for(f)
                    && s.jobs.iter().all(|j| j.is_none())
                    && s.repair.is_none()
            })
            .then_some(f)
    }

    /// The time-out in force (µs; false alarms raise it, see [`RootState::heard`]).
    pub fn timeout_us(&self) -> u64 {
        self.timeout_us
    }
}
