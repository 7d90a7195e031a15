//! The DM stage of the animation pipeline: the machine that compiles each frame's
//! SceneImage runs ahead of the RC, one frame at a time, taking `dm_f` of virtual time for
//! frame `f` (a fixed time per frame, or each frame's from the [`super::dmcost`] model);
//! frame `f`'s scene exists from `dm_0 + ... + dm_f` on and the RC may not broadcast it
//! before. The DM keeps every compiled frame until the RC takes it (it does not wait for the
//! nodes' banks: those gate the RC's broadcast). The scenes themselves are compiled before the simulation
//! (the DM's output is a pure function of its input); only their availability is timed.
//! The DM delivers each scene with its CRC-32, so the RC does not read the whole image
//! before it can broadcast the first chunk.

use super::exec::{Delay, Ps, SharedClock};
use links_core::root::SceneSource;

/// Scenes that appear in virtual time.
pub struct DmStage<'a, S> {
    scenes: &'a [S],
    /// Each scene's CRC-32, delivered with it (the DM wrote the bytes).
    crcs: Vec<u32>,
    clock: SharedClock,
    /// When each frame's scene exists (non-decreasing).
    ready_at: Vec<Ps>,
}

impl<'a, S: AsRef<[u8]>> DmStage<'a, S> {
    /// `per_frame` picoseconds of DM time per frame (0: every scene exists at time 0).
    pub fn new(scenes: &'a [S], clock: &SharedClock, per_frame: Ps) -> Self {
        Self::with_times(scenes, clock, &vec![per_frame; scenes.len()])
    }

    /// `dm_ps[f]` picoseconds of DM time for frame `f` (missing entries: 0).
    pub fn with_times(scenes: &'a [S], clock: &SharedClock, dm_ps: &[Ps]) -> Self {
        let mut t: Ps = 0;
        let ready_at = (0..scenes.len())
            .map(|f| {
                t = t.saturating_add(dm_ps.get(f).copied().unwrap_or(0));
                t
            })
            .collect();
        Self {
            scenes,
            crcs: scenes
                .iter()
                .map(|s| links_core::wire::CRC32.checksum(s.as_ref()))
                .collect(),
            clock: clock.clone(),
            ready_at,
        }
    }

    /// When frame `frame`'s scene exists.
    pub fn produced_at(&self, frame: u16) -> Ps {
        self.ready_at.get(frame as usize).copied().unwrap_or(0)
    }
}

impl<S: AsRef<[u8]>> SceneSource for DmStage<'_, S> {
    fn scene(&self, frame: u16) -> Option<&[u8]> {
        self.scenes.get(frame as usize).map(|s| s.as_ref())
    }

    fn scene_crc(&self, frame: u16) -> Option<u32> {
        self.crcs.get(frame as usize).copied()
    }

    fn produced(&self, frame: u16) -> bool {
        self.clock.borrow().now >= self.produced_at(frame)
    }

    async fn wait_produced(&self, frame: u16) {
        if !self.produced(frame) {
            Delay::new(&self.clock, self.produced_at(frame)).await;
        }
    }
}
