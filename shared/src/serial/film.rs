//! The RC's film bookkeeping ([`FilmState`]): which of its two scene banks holds which frame,
//! and the flow control that keeps the PC at most one frame ahead of the cluster.
//!
//! Frame `k` lives in bank `k % 2` (see [`bank_of`]). While the cluster renders frame `k`
//! from its bank, frame `k + 1` is uploaded into the other; frame `k`'s bank is released by
//! the PC's `FrameAck { k }` (until then a `Resend` of frame `k` is re-rendered from it), and
//! frame `k + 1` starts once it is stored and frame `k` is released. A `FrameBegin` for a
//! bank still held is refused ([`RcError::FilmBusy`]): the PC waits for `FrameStarted { k }`
//! before it begins frame `k + 1`, so it is never more than one frame ahead.

use super::protocol::RcError;

/// The scene bank (0 = even frames, 1 = odd frames) film frame `frame` is stored in.
pub const fn bank_of(frame: u16) -> usize {
    (frame % 2) as usize
}

/// The frame being uploaded, or stored and waiting for the cluster.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Loading {
    pub frame: u16,
    /// Every byte arrived and passed the CRC.
    pub stored: bool,
}

/// The frame the cluster has: rendering, or rendered and waiting for the PC's `FrameAck`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Current {
    pub frame: u16,
    pub rendered: bool,
}

/// Which frames hold the two scene banks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FilmState {
    pub loading: Option<Loading>,
    pub current: Option<Current>,
    /// The film's length, from the last `FrameBegin` (for the log).
    pub frames: u16,
}

/// What a `FrameBegin` means to the banks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Begin {
    /// A new upload into bank `bank`.
    New { bank: usize },
    /// The same frame again (our answer was lost): the upload in bank `bank` resumes.
    Again { bank: usize },
}

impl FilmState {
    /// The PC begins frame `frame` of a `frames`-frame film: which bank takes it, or why
    /// none can. An unfinished upload of another frame is abandoned (the PC restarted);
    /// a frame stored but not started, or a frame rendering or unacknowledged in the bank
    /// needed, refuses it.
    pub fn begin(&mut self, frame: u16, frames: u16) -> Result<Begin, RcError> {
        let bank = bank_of(frame);
        if let Some(l) = self.loading {
            if l.frame == frame {
                return Ok(Begin::Again { bank });
            }
            if l.stored {
                return Err(RcError::FilmBusy {
                    frame,
                    holder: l.frame,
                });
            }
        }
        // A rendered frame whose successor is not the one begun was given up by the PC (a
        // failed film, begun again): its bank is free.
        if self
            .current
            .is_some_and(|c| c.rendered && c.frame.wrapping_add(1) != frame)
        {
            self.current = None;
        }
        if let Some(c) = self.current.filter(|c| bank_of(c.frame) == bank) {
            return Err(RcError::FilmBusy {
                frame,
                holder: c.frame,
            });
        }
        self.loading = Some(Loading {
            frame,
            stored: false,
        });
        self.frames = frames;
        Ok(Begin::New { bank })
    }

    /// The bank the next scene chunk goes to: the loading frame's (`None`: no film upload).
    pub fn loading_bank(&self) -> Option<usize> {
        self.loading.filter(|l| !l.stored).map(|l| bank_of(l.frame))
    }

    /// The loading frame's upload completed.
    pub fn stored(&mut self) {
        if let Some(l) = &mut self.loading {
            l.stored = true;
        }
    }

    /// The loading frame's upload failed (CRC, refused): its bank is free again.
    pub fn failed(&mut self) {
        self.loading = self.loading.filter(|l| l.stored);
    }

    /// If the cluster is free and a frame is stored, it starts now: its number.
    pub fn start_next(&mut self) -> Option<u16> {
        if self.current.is_some() {
            return None;
        }
        let l = self.loading.filter(|l| l.stored)?;
        self.loading = None;
        self.current = Some(Current {
            frame: l.frame,
            rendered: false,
        });
        Some(l.frame)
    }

    /// The cluster finished frame `frame` (its bank stays held for `Resend`s).
    pub fn rendered(&mut self, frame: u16) {
        if let Some(c) = self.current.as_mut().filter(|c| c.frame == frame) {
            c.rendered = true;
        }
    }

    /// The PC has frame `frame`: its bank is released if it was rendered. Returns whether
    /// it was.
    pub fn acked(&mut self, frame: u16) -> bool {
        let done = self.current.is_some_and(|c| c.frame == frame && c.rendered);
        if done {
            self.current = None;
        }
        done
    }

    /// The frame whose finished scene a `Resend { frame }` re-renders from, and its bank.
    pub fn resend_bank(&self, frame: u16) -> Option<usize> {
        self.current
            .filter(|c| c.frame == frame && c.rendered)
            .map(|c| bank_of(c.frame))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pc_is_never_more_than_one_frame_ahead() {
        let mut f = FilmState::default();
        assert_eq!(f.begin(4, 3), Ok(Begin::New { bank: 0 }));
        assert_eq!(f.loading_bank(), Some(0));
        assert_eq!(f.begin(4, 3), Ok(Begin::Again { bank: 0 }));
        f.stored();
        // Stored, not started: the next frame has nowhere to go yet... but the cluster is
        // free, so it starts at once.
        assert_eq!(f.start_next(), Some(4));
        assert_eq!(f.start_next(), None);
        assert_eq!(f.begin(5, 3), Ok(Begin::New { bank: 1 }));
        f.stored();
        // Frame 5 is stored while 4 renders: frame 6 would need 4's bank.
        assert_eq!(
            f.begin(6, 3),
            Err(RcError::FilmBusy {
                frame: 6,
                holder: 5
            })
        );
        assert_eq!(f.start_next(), None, "4 still renders");
        assert!(!f.acked(4), "not rendered yet");
        f.rendered(4);
        assert_eq!(f.resend_bank(4), Some(0));
        assert_eq!(f.start_next(), None, "4 waits for its FrameAck");
        assert!(f.acked(4));
        assert_eq!(f.start_next(), Some(5));
        assert_eq!(f.begin(6, 3), Ok(Begin::New { bank: 0 }));
        // An odd frame while 5 renders in bank 1: refused.
        f.failed();
        assert_eq!(
            f.begin(7, 3),
            Err(RcError::FilmBusy {
                frame: 7,
                holder: 5
            })
        );
        // The PC gave up after frame 5 rendered (no FrameAck) and begins the film again:
        // frame 5's bank is free for frame 1.
        f.rendered(5);
        assert_eq!(f.begin(1, 3), Ok(Begin::New { bank: 1 }));
        assert_eq!(f.current, None);
    }
}
