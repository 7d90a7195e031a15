//! Sub-screen scheduling (LINKS-1 4.6): which region of the screen a node renders next.
//!
//! Three policies, all deterministic and heap-free (regions are computed on demand):
//! - [`Policy::Static`]: one region per node, node `i` gets region `i` (no balancing).
//! - [`Policy::Fixed`]: `divisions` equal sub-screens handed out in order to whichever node
//!   asks (dynamic balancing with a fixed grain).
//! - [`Policy::Decreasing`]: LINKS-1's large-first, smaller-near-the-end: each job is
//!   `remaining / (factor · nodes)` pixels, never below `min_pixels` (guided
//!   self-scheduling), so early jobs amortise the traffic and late ones balance the finish.
//!
//! Sub-screens are raster-order runs of pixels ([`Split::Span`], the paper's scanline runs)
//! or rectangles ([`Split::Rect`], a grid as close to square cells as the count allows).

use super::link::NodeId;
use super::wire::Region;
use core::fmt;

/// How the screen is split into sub-screens: raster-order runs of pixels or rectangles (the
/// form of every sub-screen).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Split {
    Span,
    Rect,
}

/// How the screen is divided and handed out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Policy {
    Static { shape: Split },
    Fixed { divisions: u32, shape: Split },
    Decreasing { factor: u32, min_pixels: u32 },
}

impl Policy {
    /// LINKS-1's decreasing sizes with the defaults used in `docs/cluster.md`.
    pub const DECREASING: Policy = Policy::Decreasing {
        factor: 6,
        min_pixels: 128,
    };

    /// The decreasing sizes under a tree of relays (`rc-fw --features relay-root`, and the
    /// simulator's relay trees): a node exchange there crosses two links and waits for the
    /// root's reply to come down, so the frame's last jobs are kept at 192 pixels or more
    /// (the sweep in `docs/cluster.md`, "The smallest job under a relay tree": the
    /// firmware's relay code on 64 F407 nodes 60.20x at 128, 60.45x at 192, 60.47x at 256).
    pub const RELAYED: Policy = Policy::Decreasing {
        factor: 6,
        min_pixels: 192,
    };
}

/// Why a schedule cannot be made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SchedError {
    /// Zero nodes, zero divisions, a zero factor or an empty screen.
    Empty,
    /// More sub-screens than pixels, or a rectangle grid finer than the screen.
    TooFine { divisions: u32 },
    /// A screen larger than a region can address (65535 pixels a side).
    ScreenTooLarge,
}

impl fmt::Display for SchedError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            SchedError::Empty => write!(f, "nothing to schedule (no nodes, divisions or pixels)"),
            SchedError::TooFine { divisions } => {
                write!(
                    f,
                    "{divisions} sub-screens are more than the screen can be split into"
                )
            }
            SchedError::ScreenTooLarge => write!(f, "screen larger than 65535 pixels a side"),
        }
    }
}

impl core::error::Error for SchedError {}

/// Hands out the regions of one frame.
#[derive(Clone, Debug)]
pub struct Scheduler {
    policy: Policy,
    width: u32,
    height: u32,
    nodes: u32,
    /// Rectangle grid (columns, rows) for rectangle shapes.
    grid: (u32, u32),
    /// Next region index (static, fixed) — for static, a bitmap of handed-out nodes.
    next: u32,
    given: [u32; 8],
    /// Next pixel (decreasing).
    next_pixel: u32,
    /// Pixels of the frames that follow this one in the same run (decreasing): the job
    /// sizes shrink towards the end of all the work, not of each frame.
    later: u32,
    /// Regions handed out so far.
    issued: u32,
}

/// The grid `(cols, rows)` with `cols · rows = n` whose cells are closest to square.
fn grid_for(n: u32, width: u32, height: u32) -> (u32, u32) {
    let mut best = (n, 1);
    let mut best_err = f32::MAX;
    let mut rows = 1;
    while rows <= n {
        if n.is_multiple_of(rows) {
            let cols = n / rows;
            let cw = width as f32 / cols as f32;
            let ch = height as f32 / rows as f32;
            let r = if cw > ch { cw / ch } else { ch / cw };
            if r < best_err {
                best_err = r;
                best = (cols, rows);
            }
        }
        rows += 1;
    }
    best
}

impl Scheduler {
    /// Most nodes a static split addresses.
    pub const MAX_NODES: u32 = 256;

    pub fn new(policy: Policy, width: u32, height: u32, nodes: u32) -> Result<Self, SchedError> {
        if width == 0 || height == 0 || nodes == 0 || nodes > Self::MAX_NODES {
            return Err(SchedError::Empty);
        }
        if width > u16::MAX as u32 || height > u16::MAX as u32 {
            return Err(SchedError::ScreenTooLarge);
        }
        let total = width * height;
        let (count, shape) = match policy {
            Policy::Static { shape } => (nodes, shape),
            Policy::Fixed { divisions, shape } => (divisions, shape),
            Policy::Decreasing { factor, min_pixels } => {
                if factor == 0 || min_pixels == 0 {
                    return Err(SchedError::Empty);
                }
                (1, Split::Span)
            }
        };
        if count == 0 {
            return Err(SchedError::Empty);
        }
        if count > total {
            return Err(SchedError::TooFine { divisions: count });
        }
        let grid = if shape == Split::Rect {
            let g = grid_for(count, width, height);
            if g.0 > width || g.1 > height {
                return Err(SchedError::TooFine { divisions: count });
            }
            g
        } else {
            (0, 0)
        };
        Ok(Self {
            policy,
            width,
            height,
            nodes,
            grid,
            next: 0,
            given: [0; 8],
            next_pixel: 0,
            later: 0,
            issued: 0,
        })
    }

    /// This frame followed by `frames` more of the same size in the run (a film, or a
    /// still repeated): under [`Policy::Decreasing`] a job is `remaining / (factor · nodes)`
    /// of all the pixels still to come, never more than the frame's first job, so the jobs
    /// shrink only at the end of the run's last frame. The next frame's jobs are handed out
    /// as soon as this one's are all issued, so the end of a frame that another follows is
    /// no barrier and its small jobs would cost exchanges for nothing. Guided
    /// self-scheduling over the whole run; the other policies are unchanged.
    pub fn followed_by(mut self, frames: u32) -> Self {
        self.later = (self.width * self.height).saturating_mul(frames);
        self
    }

    /// The next job's length under the decreasing policy, `remaining` pixels left in this
    /// frame (> 0).
    fn decreasing_len(&self, remaining: u32, factor: u32, min_pixels: u32) -> u32 {
        let per = factor.saturating_mul(self.nodes);
        let cap = (self.width * self.height).div_ceil(per);
        let share = remaining.saturating_add(self.later).div_ceil(per).min(cap);
        share.max(min_pixels).min(remaining)
    }

    pub fn policy(&self) -> Policy {
        self.policy
    }

    /// Regions handed out so far.
    pub fn issued(&self) -> u32 {
        self.issued
    }

    /// Region `i` of `count` equal pieces of the screen in the given shape.
    fn piece(&self, i: u32, count: u32, shape: Split) -> Region {
        match shape {
            Split::Span => {
                let total = self.width as u64 * self.height as u64;
                let a = (total * i as u64 / count as u64) as u32;
                let b = (total * (i as u64 + 1) / count as u64) as u32;
                Region::Span {
                    start: a,
                    len: b - a,
                }
            }
            Split::Rect => {
                let (cols, rows) = self.grid;
                let (c, r) = (i % cols, i / cols);
                let x0 = self.width * c / cols;
                let x1 = self.width * (c + 1) / cols;
                let y0 = self.height * r / rows;
                let y1 = self.height * (r + 1) / rows;
                Region::Rect {
                    x: x0 as u16,
                    y: y0 as u16,
                    w: (x1 - x0) as u16,
                    h: (y1 - y0) as u16,
                }
            }
        }
    }

    /// The next region for `node`, or `None` when this node gets nothing more.
    pub fn next_for(&mut self, node: NodeId) -> Option<Region> {
        let total = self.width * self.height;
        let region = match self.policy {
            Policy::Static { shape } => {
                let n = node as u32;
                if n >= self.nodes {
                    return None;
                }
                let (w, b) = ((n / 32) as usize, 1u32 << (n % 32));
                if self.given[w] & b != 0 {
                    return None;
                }
                self.given[w] |= b;
                self.next += 1;
                self.piece(n, self.nodes, shape)
            }
            Policy::Fixed { divisions, shape } => {
                if self.next >= divisions {
                    return None;
                }
                self.next += 1;
                self.piece(self.next - 1, divisions, shape)
            }
            Policy::Decreasing { factor, min_pixels } => {
                let remaining = total - self.next_pixel;
                if remaining == 0 {
                    return None;
                }
                let len = self.decreasing_len(remaining, factor, min_pixels);
                let start = self.next_pixel;
                self.next_pixel += len;
                Region::Span { start, len }
            }
        };
        self.issued += 1;
        Some(region)
    }

    /// Static split: whether `node`'s region is still waiting for it (not handed out yet).
    /// Always `false` for the other policies (no region belongs to a node).
    pub fn reserved(&self, node: NodeId) -> bool {
        let n = node as u32;
        matches!(self.policy, Policy::Static { .. })
            && n < self.nodes
            && self.given[(n / 32) as usize] & (1 << (n % 32)) == 0
    }

    /// Whether every region has been handed out.
    pub fn exhausted(&self) -> bool {
        match self.policy {
            Policy::Static { .. } => self.next >= self.nodes,
            Policy::Fixed { divisions, .. } => self.next >= divisions,
            Policy::Decreasing { .. } => self.next_pixel >= self.width * self.height,
        }
    }

    /// About how many regions are still to come (exact for static and fixed).
    pub fn remaining(&self) -> u32 {
        match self.policy {
            Policy::Static { .. } => self.nodes - self.next,
            Policy::Fixed { divisions, .. } => divisions - self.next,
            Policy::Decreasing { factor, min_pixels } => {
                let remaining = self.width * self.height - self.next_pixel;
                if remaining == 0 {
                    return 0;
                }
                let len = self.decreasing_len(remaining, factor, min_pixels);
                remaining.div_ceil(len.max(1))
            }
        }
    }

    /// Whether a node already holding a job may be given a second one to queue: only while
    /// more regions remain than nodes, so a queued job never idles another node. Never for a
    /// static split (each node has exactly one region).
    pub fn may_prefetch(&self) -> bool {
        !matches!(self.policy, Policy::Static { .. }) && self.remaining() > self.nodes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn coverage(mut s: Scheduler, w: u32, h: u32, nodes: u16) -> (u32, [u8; 64 * 60]) {
        let mut seen = [0u8; 64 * 60];
        let mut n = 0;
        let mut node = 0;
        let mut idle = 0;
        while idle < nodes {
            match s.next_for(node) {
                Some(r) => {
                    idle = 0;
                    n += 1;
                    assert!(r.fits(w, h), "{r:?}");
                    let mut i = 0;
                    while let Some((y, x, len)) = r.piece(w, i) {
                        for px in x..x + len {
                            seen[(y * w + px) as usize] += 1;
                        }
                        i += 1;
                    }
                }
                None => idle += 1,
            }
            node = (node + 1) % nodes;
        }
        assert!(s.exhausted());
        (n, seen)
    }

    #[test]
    fn every_policy_covers_every_pixel_exactly_once() {
        let policies = [
            Policy::Static { shape: Split::Span },
            Policy::Static { shape: Split::Rect },
            Policy::Fixed {
                divisions: 7,
                shape: Split::Span,
            },
            Policy::Fixed {
                divisions: 48,
                shape: Split::Rect,
            },
            Policy::Fixed {
                divisions: 3840,
                shape: Split::Span,
            },
            Policy::DECREASING,
            Policy::Decreasing {
                factor: 1,
                min_pixels: 1,
            },
        ];
        for p in policies {
            for later in [0, 1, 7] {
                let s = Scheduler::new(p, 64, 60, 6).unwrap().followed_by(later);
                let (_, seen) = coverage(s, 64, 60, 6);
                assert!(seen.iter().all(|&c| c == 1), "{p:?}, {later} frames after");
            }
        }
    }

    /// With frames after it, a frame's decreasing jobs keep the size of its first one (the
    /// run's remaining work is large) instead of shrinking to the floor at its end; the
    /// run's last frame shrinks as a single frame does.
    #[test]
    fn a_followed_frames_jobs_shrink_only_with_the_runs_work() {
        let p = Policy::Decreasing {
            factor: 2,
            min_pixels: 64,
        };
        let lens = |later| {
            let mut s = Scheduler::new(p, 64, 60, 4).unwrap().followed_by(later);
            let mut v = Vec::new();
            while let Some(r) = s.next_for(0) {
                v.push(r.pixels());
            }
            v
        };
        // Alone: 480, 420, ... down to the 64-pixel floor (3840 pixels, factor 2, 4 nodes).
        let alone = lens(0);
        assert_eq!(alone[..2], [480, 420]);
        assert!(alone.len() > 8 && *alone.last().unwrap() <= 64);
        // Followed by one frame or more: the run's remaining work never drops below a
        // frame's, so every job is the first one's 480 pixels (3840 / 8).
        assert_eq!(lens(1), [480; 8]);
        assert_eq!(lens(3), [480; 8]);
        // The count of regions still to come follows the same sizes.
        let s = Scheduler::new(p, 64, 60, 4).unwrap().followed_by(3);
        assert_eq!(s.remaining(), 8);
        assert_eq!(Scheduler::new(p, 64, 60, 4).unwrap().remaining(), 8);
    }

    #[test]
    fn counts_and_sizes() {
        let (n, _) = coverage(
            Scheduler::new(
                Policy::Fixed {
                    divisions: 48,
                    shape: Split::Rect,
                },
                64,
                60,
                4,
            )
            .unwrap(),
            64,
            60,
            4,
        );
        assert_eq!(n, 48);
        // 8 columns x 6 rows of 8x10 cells.
        assert_eq!(grid_for(48, 64, 60), (8, 6));
        assert_eq!(grid_for(1024, 512, 480), (32, 32));
        assert_eq!(grid_for(64, 512, 480), (8, 8));
        // Decreasing: the first job is remaining / (factor * nodes), the sizes shrink to the
        // floor.
        let p = Policy::Decreasing {
            factor: 2,
            min_pixels: 64,
        };
        let mut s = Scheduler::new(p, 64, 60, 4).unwrap();
        assert_eq!(s.next_for(0), Some(Region::Span { start: 0, len: 480 }));
        assert_eq!(
            s.next_for(1),
            Some(Region::Span {
                start: 480,
                len: 420
            })
        );
        let mut last = 0;
        while let Some(r) = s.next_for(0) {
            last = r.pixels();
        }
        assert!(last <= 64);
        // Static: each node exactly once.
        let mut s = Scheduler::new(Policy::Static { shape: Split::Span }, 64, 60, 4).unwrap();
        assert_eq!(
            s.next_for(2),
            Some(Region::Span {
                start: 1920,
                len: 960
            })
        );
        assert_eq!(s.next_for(2), None);
        assert_eq!(s.next_for(9), None);
        assert!(!s.may_prefetch());
        // Regions not yet handed out are reserved for their nodes.
        assert!(!s.reserved(2) && s.reserved(0) && s.reserved(3) && !s.reserved(4));
        assert_eq!(s.next_for(0).map(|r| r.pixels()), Some(960));
        assert!(!s.reserved(0));
        let d = Scheduler::new(Policy::DECREASING, 64, 60, 4).unwrap();
        assert!(!d.reserved(0));
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert_eq!(
            Scheduler::new(Policy::DECREASING, 64, 60, 0).unwrap_err(),
            SchedError::Empty
        );
        assert_eq!(
            Scheduler::new(
                Policy::Fixed {
                    divisions: 0,
                    shape: Split::Span
                },
                4,
                4,
                1
            )
            .unwrap_err(),
            SchedError::Empty
        );
        assert_eq!(
            Scheduler::new(
                Policy::Fixed {
                    divisions: 17,
                    shape: Split::Span
                },
                4,
                4,
                1
            )
            .unwrap_err(),
            SchedError::TooFine { divisions: 17 }
        );
        assert_eq!(
            Scheduler::new(
                Policy::Fixed {
                    divisions: 7,
                    shape: Split::Rect
                },
                4,
                4,
                1
            )
            .unwrap_err(),
            SchedError::TooFine { divisions: 7 }
        );
    }
}
