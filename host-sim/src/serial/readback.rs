//! Reading one rendered frame back from the RC (`links readback`): collect its pixels, ask
//! for what is missing, check the frame CRC, acknowledge it.

use super::port::{kind, Clock, Line, SystemClock};
use super::{FrameAssembly, HostSerialError};
use links_core::serial::{
    pixel_count, Decoder, RcError, SerialError, ToPc, ToRc, MAX_DIM, MAX_TO_PC,
};
use links_core::wire::CRC32;
use std::io::{Read, Write};
use std::time::Duration;

/// Settings of [`readback`].
#[derive(Clone, Debug)]
pub struct ReadbackOptions {
    /// Longest silence (no valid message) before giving up, or, once a frame started,
    /// before asking for what is missing.
    pub timeout: Duration,
    /// Retransmit requests for one frame before giving up.
    pub resend_rounds: u32,
    /// Frames begun without finishing the one before: the last one allowed is one less.
    pub max_restarts: u32,
    /// Messages in a row with neither pixels nor progress before giving up.
    pub idle_messages: u32,
    /// Give up once this much time has passed in all (`None`: no overall deadline).
    pub deadline: Option<Duration>,
}

impl Default for ReadbackOptions {
    fn default() -> Self {
        ReadbackOptions {
            timeout: Duration::from_millis(5000),
            resend_rounds: 5,
            max_restarts: 8,
            idle_messages: 1000,
            deadline: None,
        }
    }
}

/// What [`readback`] reports while it runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadbackEvent {
    /// The RC's rendering progress (pixels).
    Rendering { done: u32, total: u32 },
    /// A frame began.
    Header { frame: u16, width: u16, height: u16 },
    /// Distinct pixels received of the frame.
    Pixels { have: u64, total: u64 },
    /// Pixels asked for again.
    Resend { pixels: u32 },
}

/// A frame read back from the RC, CRC-checked.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Readback {
    pub frame: u16,
    pub width: u32,
    pub height: u32,
    /// RGB8 rows, top first.
    pub rgb: Vec<u8>,
    pub crc: u32,
    /// Malformed frames received (each repaired by a retransmission).
    pub bad_packets: u32,
    /// Retransmit requests sent.
    pub resends: u32,
}

/// The counts behind readback's progress rules (see [`readback`]): none of them can grow
/// forever without ending the readback.
struct Watch {
    /// Frames begun before the one being read was finished.
    restarts: u32,
    /// Messages in a row with neither pixels nor progress.
    idle: u32,
    /// Pixels that were not new to the frame being read (repeats, or of other frames;
    /// before any header, every pixel), and how many may be.
    stale: u64,
    allowed: u64,
    /// The largest `done` of a `Progress` that counted as progress.
    best_done: u32,
}

impl Watch {
    fn new() -> Self {
        Watch {
            restarts: 0,
            idle: 0,
            stale: 0,
            // Before a header: the rest of a frame already under way, at most the largest.
            allowed: MAX_DIM as u64 * MAX_DIM as u64,
            best_done: 0,
        }
    }

    /// A frame of `total` pixels began: one frame of repeats is allowed, plus whatever is
    /// asked for again.
    fn new_frame(&mut self, total: u64) {
        (self.stale, self.allowed, self.best_done) = (0, total, 0);
    }

    /// `pixels` were asked for again: as many repeats are allowed.
    fn asked(&mut self, pixels: u64) {
        self.allowed = self.allowed.saturating_add(pixels);
    }

    /// A pixel message of `n` pixels, `fresh` of them new to `frame` (the frame being read).
    pub(super) fn pixels(
        &mut self,
        frame: Option<u16>,
        n: u64,
        fresh: u64,
    ) -> Result<(), HostSerialError> {
        self.idle = 0;
        self.stale = self.stale.saturating_add(n.saturating_sub(fresh));
        if self.stale > self.allowed {
            return Err(HostSerialError::RepeatedPixels {
                frame,
                stale: self.stale,
                allowed: self.allowed,
            });
        }
        Ok(())
    }

    /// Whether `Progress { done, total }` of the frame being read (`a`) is progress: at
    /// least one row further than the last that was, or the whole frame.
    fn progressed(&mut self, a: &FrameAssembly, frame: u16, done: u32, total: u32) -> bool {
        let row = a.width as u32;
        let counts = frame == a.frame
            && total as u64 == a.total()
            && done <= total
            && done > self.best_done
            && (done == total || done - self.best_done >= row);
        if counts {
            self.best_done = done;
        }
        counts
    }

    /// Any other message: `news` if it was progress.
    fn message(
        &mut self,
        news: bool,
        kind: &'static str,
        limit: u32,
    ) -> Result<(), HostSerialError> {
        if news {
            self.idle = 0;
            return Ok(());
        }
        self.idle = self.idle.saturating_add(1);
        if self.idle >= limit {
            return Err(HostSerialError::NoProgress {
                messages: self.idle,
                last: kind,
            });
        }
        Ok(())
    }
}

/// Read one frame from the RC: wait for a `FrameHeader`, collect pixels, and at
/// `FrameEnd` (or after a silence) ask for whatever is missing; once whole, check the
/// frame CRC and acknowledge it. A CRC mismatch asks for the whole frame once more before
/// failing.
///
/// Always ends; besides the silence time-out it gives up when the RC
/// - begins another frame before finishing the one being read, the `opts.max_restarts`th
///   time;
/// - is asked for a frame's missing pixels more than `opts.resend_rounds` times;
/// - sends more pixels that are not new (repeats, or of other frames) than one frame plus
///   all it was asked for again (before any header: more than one `MAX_DIM` x `MAX_DIM`
///   frame);
/// - sends `opts.idle_messages` messages in a row with neither pixels nor progress
///   (progress: a header that begins a frame, or a `Progress` at least a row further);
/// - or `opts.deadline` passes.
pub fn readback<P: Read + Write>(
    port: &mut P,
    name: &str,
    opts: &ReadbackOptions,
    progress: &dyn Fn(ReadbackEvent),
) -> Result<Readback, HostSerialError> {
    readback_with_clock(port, name, opts, &SystemClock::new(), progress)
}

/// [`readback`] on the time of `clock`.
pub fn readback_with_clock<P: Read + Write>(
    port: &mut P,
    name: &str,
    opts: &ReadbackOptions,
    clock: &dyn Clock,
    progress: &dyn Fn(ReadbackEvent),
) -> Result<Readback, HostSerialError> {
    let ms = u64::try_from(opts.timeout.as_millis()).unwrap_or(u64::MAX);
    let mut line = Line::new(port, name, clock, opts.deadline);
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut rb = Reading::new(opts, progress);
    let mut deadline = line.after(opts.timeout);
    loop {
        let Some(b) = line.byte(deadline)? else {
            rb.silence(&mut line, ms)?;
            deadline = line.after(opts.timeout);
            continue;
        };
        let packet = match dec.feed::<ToPc>(b) {
            None => continue,
            Some(Err(SerialError::Version { found })) => {
                return Err(HostSerialError::Version { found })
            }
            Some(Err(_)) => {
                rb.bad_packets += 1;
                continue;
            }
            Some(Ok(p)) => p,
        };
        deadline = line.after(opts.timeout);
        match packet.msg {
            ToPc::Error {
                code: RcError::Version { found },
            } => return Err(HostSerialError::Version { found }),
            ToPc::Error { code } => return Err(HostSerialError::Rc(code)),
            ref m => {
                if let Some(done) = rb.message(&mut line, m)? {
                    return Ok(done);
                }
            }
        }
    }
}

/// A readback under way: the frame being assembled and the counts that bound the session.
pub(super) struct Reading<'o> {
    opts: &'o ReadbackOptions,
    progress: &'o dyn Fn(ReadbackEvent),
    /// The frame being read (`None` before the first header).
    asm: Option<FrameAssembly>,
    pub(super) bad_packets: u32,
    /// Retransmit requests sent for the frame being read.
    resends: u32,
    /// Whether the whole frame was asked for again after a CRC mismatch.
    crc_retry: bool,
    watch: Watch,
}

impl<'o> Reading<'o> {
    /// A readback waiting for its first frame.
    pub(super) fn new(opts: &'o ReadbackOptions, progress: &'o dyn Fn(ReadbackEvent)) -> Self {
        Reading {
            opts,
            progress,
            asm: None,
            bad_packets: 0,
            resends: 0,
            crc_retry: false,
            watch: Watch::new(),
        }
    }

    /// The frame being read, if one began.
    pub(super) fn frame(&self) -> Option<u16> {
        self.asm.as_ref().map(|a| a.frame)
    }

    /// The frame just returned is done: wait for the next one's header (a film).
    pub(super) fn next_frame(&mut self) {
        self.asm = None;
        (self.resends, self.crc_retry) = (0, false);
        self.watch = Watch::new();
    }

    /// Take one RC message other than an upload answer: `Some` once a frame is whole and
    /// acknowledged.
    pub(super) fn message<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        msg: &ToPc<'_>,
    ) -> Result<Option<Readback>, HostSerialError> {
        let kind = kind(msg);
        let mut news = false;
        match *msg {
            ToPc::FrameHeader {
                frame,
                width,
                height,
            } => news = self.header(frame, width, height)?,
            ToPc::Progress { frame, done, total } => {
                (self.progress)(ReadbackEvent::Rendering { done, total });
                news = self
                    .asm
                    .as_ref()
                    .is_some_and(|a| self.watch.progressed(a, frame, done, total));
            }
            ToPc::Pixels { .. } | ToPc::PixelsRle { .. } => {
                self.pixels(msg)?;
                return Ok(None);
            }
            ToPc::FrameEnd { frame, crc } => {
                if let Some(done) = self.frame_end(line, frame, crc)? {
                    return Ok(Some(done));
                }
            }
            _ => {}
        }
        self.watch.message(news, kind, self.opts.idle_messages)?;
        Ok(None)
    }

    /// Ask for `len` pixels of `frame` from raster position `start` again.
    pub(super) fn resend<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        frame: u16,
        start: u32,
        len: u32,
    ) -> Result<(), HostSerialError> {
        line.send(&ToRc::Resend { frame, start, len })?;
        self.resends += 1;
        self.watch.asked(len as u64);
        (self.progress)(ReadbackEvent::Resend { pixels: len });
        Ok(())
    }

    /// Nothing arrived in time: past the overall deadline, or before any frame, give up;
    /// otherwise ask for what is missing (up to `opts.resend_rounds` times).
    pub(super) fn silence<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        ms: u64,
    ) -> Result<(), HostSerialError> {
        if line.overdue() {
            let doing = self
                .asm
                .as_ref()
                .map_or("waiting for a frame header".into(), |a| {
                    format!(
                        "frame {}: {} of {} pixels received",
                        a.frame,
                        a.count,
                        a.total()
                    )
                });
            return Err(line.deadline_error(doing));
        }
        let Some(a) = &self.asm else {
            return Err(line.timeout(ms, "a frame from the RC"));
        };
        let resends = self.resends;
        if resends >= self.opts.resend_rounds {
            return Err(line.timeout(
                ms,
                format!(
                    "the rest of frame {} ({} of {} pixels received, {resends} retransmit requests)",
                    a.frame,
                    a.count,
                    a.total()
                ),
            ));
        }
        let (start, len) = a.missing_span().unwrap_or((0, 0));
        let frame = a.frame;
        self.resend(line, frame, start, len)
    }

    /// A `FrameHeader`: whether it begins a new frame (progress); a frame begun before the
    /// one being read was finished counts as a restart.
    pub(super) fn header(
        &mut self,
        frame: u16,
        width: u16,
        height: u16,
    ) -> Result<bool, HostSerialError> {
        if self.asm.as_ref().is_some_and(|a| a.frame == frame) {
            return Ok(false);
        }
        if self.asm.is_some() {
            self.watch.restarts += 1;
            if self.watch.restarts >= self.opts.max_restarts {
                return Err(HostSerialError::FrameRestarts {
                    restarts: self.watch.restarts,
                    frame,
                });
            }
        }
        let a = FrameAssembly::new(frame, width, height)?;
        self.watch.new_frame(a.total());
        self.asm = Some(a);
        (self.resends, self.crc_retry) = (0, false);
        (self.progress)(ReadbackEvent::Header {
            frame,
            width,
            height,
        });
        Ok(true)
    }

    /// A pixel message: stored if it belongs to the frame being read, counted either way.
    fn pixels(&mut self, m: &ToPc<'_>) -> Result<(), HostSerialError> {
        // At least one pixel per message, so that even empty ones add up.
        let n = pixel_count(m).max(1) as u64;
        let mut fresh = 0;
        if let Some(a) = &mut self.asm {
            let before = a.count;
            if a.put(m)? {
                fresh = a.count - before;
                (self.progress)(ReadbackEvent::Pixels {
                    have: a.count,
                    total: a.total(),
                });
            }
        }
        self.watch
            .pixels(self.asm.as_ref().map(|a| a.frame), n, fresh)
    }

    /// A `FrameEnd` of the frame being read: ask for what is missing, or check the CRC and
    /// acknowledge the frame (`Some`), or, once, ask for the whole frame again.
    pub(super) fn frame_end<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        frame: u16,
        crc: u32,
    ) -> Result<Option<Readback>, HostSerialError> {
        let Some(a) = self.asm.as_mut().filter(|a| a.frame == frame) else {
            return Ok(None);
        };
        if let Some((start, len)) = a.missing_span() {
            if self.resends >= self.opts.resend_rounds {
                return Err(HostSerialError::Retries {
                    what: format!("frame {frame} still lacks {} pixels", a.total() - a.count),
                    tries: self.resends,
                });
            }
            self.resend(line, frame, start, len)?;
            return Ok(None);
        }
        let found = CRC32.checksum(&a.rgb);
        if found == crc {
            line.send(&ToRc::FrameAck { frame })?;
            let rgb = std::mem::take(&mut a.rgb);
            return Ok(Some(Readback {
                frame,
                width: a.width as u32,
                height: a.height as u32,
                rgb,
                crc,
                bad_packets: self.bad_packets,
                resends: self.resends,
            }));
        }
        if self.crc_retry {
            return Err(HostSerialError::FrameCrc {
                frame,
                expected: crc,
                found,
            });
        }
        // Once: forget every pixel and ask for the whole frame again.
        self.crc_retry = true;
        a.forget();
        let len = a.total() as u32;
        self.resend(line, frame, 0, len)?;
        Ok(None)
    }
}
