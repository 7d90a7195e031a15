//! Handing out work: the schedule of the frame being handed out, topping up a node's job
//! list, and re-issuing a dead node's jobs (orphans) to live nodes.

use super::*;
use crate::cluster::link::NodeId;
use crate::cluster::sched::Scheduler;
use crate::cluster::wire::{Job, Region, JOB_QUEUE};

impl RootState {
    /// A job held by a dead node, as (node, queue index), oldest frame first.
    pub(super) fn orphan(&self) -> Option<(usize, usize)> {
        let mut best: Option<(usize, usize, u16)> = None;
        for (n, slot) in self.nodes[..self.cfg.nodes as usize].iter().enumerate() {
            if !slot.dead {
                continue;
            }
            for (k, j) in slot.jobs.iter().enumerate() {
                if let Some(j) = j {
                    if best.is_none_or(|(_, _, f)| j.frame < f) {
                        best = Some((n, k, j.frame));
                    }
                }
            }
        }
        best.map(|(n, k, _)| (n, k))
    }

    /// Hand one orphaned job to `node` (a fresh id, so the node takes it). Returns whether
    /// it did.
    pub(super) fn adopt(&mut self, node: NodeId) -> bool {
        let Some((d, k)) = self.orphan() else {
            return false;
        };
        let slot = &self.nodes[node as usize];
        let Some(job) = self.nodes[d].jobs[k] else {
            return false;
        };
        let Some(free) = slot.jobs.iter().position(|j| j.is_none()) else {
            return false;
        };
        if slot.dead || !slot.ready_for(job.frame) {
            return false;
        }
        self.nodes[d].jobs[k] = None;
        if self.nodes[d].jobs[0].is_none() {
            self.nodes[d].jobs.swap(0, 1);
        }
        self.nodes[node as usize].jobs[free] = Some(Job {
            id: self.next_job,
            ..job
        });
        self.next_job += 1;
        self.report.reissued += 1;
        true
    }

    /// Move the schedule on to the next frame if the current one is all issued and the
    /// next one's progress slot is free.
    pub(super) fn advance_schedule(&mut self) {
        if !self.sched.exhausted() {
            return;
        }
        let cur = self.sched_frame;
        if let Some(p) = self.prog(cur) {
            p.all_issued = true;
        }
        self.update_complete();
        let next = cur + 1;
        if next >= self.cfg.frames || self.progress[(next % 2) as usize].frame != next {
            return;
        }
        if let Ok(s) = Scheduler::new(
            self.cfg.policy,
            self.width,
            self.height,
            self.cfg.nodes as u32,
        ) {
            let later = self.cfg.frames.saturating_sub(next + 1);
            self.sched = s.followed_by(later as u32);
            self.sched_frame = next;
        }
    }

    /// A new job for `region` of `frame`, counted as issued.
    pub(super) fn new_job(&mut self, frame: u16, region: Region) -> Job {
        let job = Job {
            id: self.next_job,
            frame,
            region,
        };
        self.next_job += 1;
        self.report.jobs += 1;
        if let Some(p) = self.prog(frame) {
            p.issued += 1;
        }
        job
    }

    /// Whether `node` will post again without being asked, for a reply composed ahead of
    /// its line ([`crate::cluster::link::RootBus::ask_ahead`]): it holds jobs once its list
    /// is topped up, as composing any reply does. (Topping up a node still holding a job
    /// later than other replies do, only while more than 2 or 4 times as many jobs as nodes
    /// remain, measured no better: `docs/cluster.md`, "Replies held ahead".)
    pub(super) fn will_post(&mut self, node: NodeId) -> bool {
        if node >= self.cfg.nodes || self.finished() {
            return false;
        }
        self.assign(node);
        self.nodes[node as usize].jobs.iter().any(Option::is_some)
    }

    /// Top up a node's job list (called when composing its exchange reply).
    pub(super) fn assign(&mut self, node: NodeId) {
        loop {
            self.advance_schedule();
            let slot = &self.nodes[node as usize];
            let held = slot.jobs.iter().filter(|j| j.is_some()).count();
            if held >= JOB_QUEUE || (held > 0 && !self.sched.may_prefetch()) {
                return;
            }
            if self.orphaned > 0 && self.adopt(node) {
                continue;
            }
            let slot = &self.nodes[node as usize];
            let frame = self.sched_frame;
            if !slot.ready_for(frame) || self.sched.exhausted() {
                return;
            }
            let Some(region) = self.sched.next_for(node) else {
                return;
            };
            let job = self.new_job(frame, region);
            if let Some(free) = self.nodes[node as usize]
                .jobs
                .iter_mut()
                .find(|j| j.is_none())
            {
                *free = Some(job);
            }
        }
    }
}
