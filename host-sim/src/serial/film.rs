//! Streaming a film to the RC and collecting it (`links upload --frames A..B`): the PC is the
//! DM. Frame `k + 1` is compiled and uploaded (`FrameBegin`, chunks) while the cluster
//! renders frame `k`, and frame `k`'s pixels are read back at the same time, on the one
//! line: one loop reads every RC message and hands upload answers to the upload of the
//! frame being sent ([`super::upload`]'s rules) and pixel messages to the frame being read
//! ([`super::readback`]'s rules). Flow control: frame `k + 1` is begun only after the RC's
//! `FrameStarted { k }`, so the PC is never more than one frame ahead (the RC has two scene
//! banks). Any failure names its frame.

use super::port::{Clock, Line, SystemClock};
use super::readback::Reading;
use super::upload::{answer_of, stalled, Heard, Upload, MAX_STALE_ANSWERS};
use super::{HostSerialError, Readback, ReadbackEvent, ReadbackOptions, UploadOptions};
use links_core::serial::{Decoder, SerialError, ToPc, MAX_TO_PC};
use std::io::{Read, Write};
use std::time::Duration;

/// Settings of [`stream_film`]: the upload's (reply time-out, tries, chunk size) and the
/// readback's (silence time-out, retransmit rounds, progress rules). The overall deadline
/// is the readback's.
#[derive(Clone, Debug, Default)]
pub struct FilmOptions {
    pub upload: UploadOptions,
    pub readback: ReadbackOptions,
}

/// What [`stream_film`] reports while it runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilmEvent {
    /// `stored` of `total` bytes of frame `frame`'s SceneImage are on the RC.
    Upload { frame: u16, stored: u64, total: u64 },
    /// Frame `frame` started rendering on the RC.
    Started { frame: u16 },
    /// Readback progress of the frame being read.
    Read(ReadbackEvent),
}

/// What a film stream did, in all.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FilmReport {
    pub frames: u32,
    /// SceneImage bytes uploaded (all frames).
    pub bytes: u64,
    pub chunks_sent: u32,
    /// Retransmit requests the RC sent during uploads.
    pub naks: u32,
    /// Upload messages sent again after no answer came in time.
    pub timeouts: u32,
    /// Malformed frames received from the RC (upload answers and pixel messages).
    pub bad_packets: u32,
    /// Retransmit requests sent for pixels.
    pub resends: u32,
}

/// A frame's upload under way, and the sends since it last moved.
struct Sending {
    frame: u16,
    up: Upload<Vec<u8>>,
    tries: u32,
    /// Answers since the last send that moved nothing.
    useless: u32,
    /// The end of the bytes the last send carried, and when its answer is due.
    sent_end: u32,
    due: Duration,
}

/// The film under way.
struct Stream<'a> {
    first: u16,
    count: u16,
    opts: &'a FilmOptions,
    events: &'a dyn Fn(FilmEvent),
    /// The frame being uploaded.
    up: Option<Sending>,
    /// A stored frame the RC has not started yet.
    awaiting_start: Option<u16>,
    /// The next frame to upload, and the next to read back.
    next_upload: u32,
    next_read: u32,
    report: FilmReport,
}

/// Stream frames `first .. first + count` to the RC and read them back: `compile(k)` gives
/// frame `k`'s SceneImage (called just before its upload, while the frame before renders);
/// `got` takes each frame once it is whole, CRC-checked and acknowledged, in order.
#[allow(clippy::too_many_arguments)]
pub fn stream_film<P: Read + Write>(
    port: &mut P,
    name: &str,
    first: u16,
    count: u16,
    compile: &mut dyn FnMut(u16) -> Result<Vec<u8>, String>,
    opts: &FilmOptions,
    events: &dyn Fn(FilmEvent),
    got: &mut dyn FnMut(Readback) -> Result<(), HostSerialError>,
) -> Result<FilmReport, HostSerialError> {
    stream_film_with_clock(
        port,
        name,
        (first, count),
        compile,
        opts,
        &SystemClock::new(),
        events,
        got,
    )
}

/// [`stream_film`] on the time of `clock`; `frames` is (first, count).
#[allow(clippy::too_many_arguments)]
pub fn stream_film_with_clock<P: Read + Write>(
    port: &mut P,
    name: &str,
    (first, count): (u16, u16),
    compile: &mut dyn FnMut(u16) -> Result<Vec<u8>, String>,
    opts: &FilmOptions,
    clock: &dyn Clock,
    events: &dyn Fn(FilmEvent),
    got: &mut dyn FnMut(Readback) -> Result<(), HostSerialError>,
) -> Result<FilmReport, HostSerialError> {
    if count == 0 || u32::from(first) + u32::from(count) > 1 << 16 {
        return Err(HostSerialError::Protocol(format!(
            "frames {first}..{}: a film has 1 to 65536 frames numbered below 65536",
            u32::from(first) + u32::from(count)
        )));
    }
    let mut line = Line::new(port, name, clock, opts.readback.deadline);
    let forward = |e: ReadbackEvent| events(FilmEvent::Read(e));
    let mut reading = Reading::new(&opts.readback, &forward);
    let mut st = Stream {
        first,
        count,
        opts,
        events,
        up: None,
        awaiting_start: None,
        next_upload: u32::from(first),
        next_read: u32::from(first),
        report: FilmReport::default(),
    };
    st.begin_next(&mut line, compile)?;
    st.run(&mut line, &mut reading, compile, got)
}

impl Stream<'_> {
    fn end(&self) -> u32 {
        u32::from(self.first) + u32::from(self.count)
    }

    /// The frame a failure now is about: the one being uploaded, else the one being read.
    fn blame(&self, e: HostSerialError) -> HostSerialError {
        let frame = self
            .up
            .as_ref()
            .map_or(self.next_read, |s| u32::from(s.frame));
        HostSerialError::Film {
            frame,
            error: Box::new(e),
        }
    }

    /// The main loop: every RC message to the upload or the readback, time-outs to both.
    fn run<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        reading: &mut Reading<'_>,
        compile: &mut dyn FnMut(u16) -> Result<Vec<u8>, String>,
        got: &mut dyn FnMut(Readback) -> Result<(), HostSerialError>,
    ) -> Result<FilmReport, HostSerialError> {
        let silence = self.opts.readback.timeout;
        let ms = u64::try_from(silence.as_millis()).unwrap_or(u64::MAX);
        let mut dec = Decoder::<MAX_TO_PC>::new();
        let mut quiet_until = line.after(silence);
        loop {
            let due = self.up.as_ref().map(|s| s.due);
            let wait = due.map_or(quiet_until, |d| d.min(quiet_until));
            let Some(b) = line.byte(wait)? else {
                if line.overdue() {
                    let doing =
                        format!("{} of {} frames read back", self.report.frames, self.count);
                    return Err(self.blame(line.deadline_error(doing)));
                }
                if due.is_some_and(|d| line.after(Duration::ZERO) >= d) {
                    self.upload_timeout(line).map_err(|e| self.blame(e))?;
                } else {
                    self.silence(line, reading, ms)?;
                    quiet_until = line.after(silence);
                }
                continue;
            };
            let msg = match dec.feed::<ToPc>(b) {
                None => continue,
                Some(Err(SerialError::Version { found })) => {
                    return Err(HostSerialError::Version { found })
                }
                Some(Err(_)) => {
                    self.report.bad_packets += 1;
                    continue;
                }
                Some(Ok(p)) => p.msg,
            };
            quiet_until = line.after(silence);
            if let Some(done) = self.message(line, reading, compile, &msg)? {
                self.report.resends += done.resends;
                let frame = done.frame;
                if u32::from(frame) != self.next_read {
                    let e = HostSerialError::Protocol(format!(
                        "the RC sent frame {frame} where frame {} was due",
                        self.next_read
                    ));
                    return Err(self.blame(e));
                }
                got(done).map_err(|e| self.blame(e))?;
                reading.next_frame();
                self.report.frames += 1;
                self.next_read += 1;
                if self.next_read >= self.end() {
                    self.report.bad_packets += reading_bad(reading);
                    return Ok(self.report.clone());
                }
            }
        }
    }

    /// One RC message: an upload answer, `FrameStarted`, or readback.
    fn message<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        reading: &mut Reading<'_>,
        compile: &mut dyn FnMut(u16) -> Result<Vec<u8>, String>,
        msg: &ToPc<'_>,
    ) -> Result<Option<Readback>, HostSerialError> {
        match *msg {
            ToPc::Ack { .. } | ToPc::Nak { .. } | ToPc::SceneDone { .. } | ToPc::Error { .. } => {
                let answer = answer_of(msg).map_err(|e| self.blame(e))?;
                if self.up.is_some() {
                    self.upload_answer(line, answer)
                        .map_err(|e| self.blame(e))?;
                }
                Ok(None)
            }
            ToPc::FrameStarted { frame } => {
                self.started(line, compile, frame)?;
                Ok(None)
            }
            // A lost `FrameStarted`: the frame's header says it too.
            ToPc::FrameHeader { frame, .. } if self.awaiting_start == Some(frame) => {
                self.started(line, compile, frame)?;
                self.read(line, reading, msg)
            }
            _ => self.read(line, reading, msg),
        }
    }

    /// A readback message, to the frame being read.
    fn read<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        reading: &mut Reading<'_>,
        msg: &ToPc<'_>,
    ) -> Result<Option<Readback>, HostSerialError> {
        reading
            .message(line, msg)
            .map_err(|e| self.blame_read(reading, e))
    }

    /// The RC started `frame`: if it is the one stored (or still being sent: the RC had it
    /// whole and our `SceneDone` was lost), begin the next.
    fn started<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        compile: &mut dyn FnMut(u16) -> Result<Vec<u8>, String>,
        frame: u16,
    ) -> Result<(), HostSerialError> {
        if let Some(s) = self.up.take_if(|s| s.frame == frame) {
            self.report.bytes += s.up.bytes() as u64;
            self.awaiting_start = Some(frame);
        }
        if self.awaiting_start != Some(frame) {
            return Ok(());
        }
        self.awaiting_start = None;
        (self.events)(FilmEvent::Started { frame });
        self.begin_next(line, compile)
    }

    /// Compile and begin the next frame's upload, if any is left.
    fn begin_next<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        compile: &mut dyn FnMut(u16) -> Result<Vec<u8>, String>,
    ) -> Result<(), HostSerialError> {
        if self.next_upload >= self.end() {
            return Ok(());
        }
        let frame = self.next_upload as u16;
        let image = compile(frame).map_err(|e| HostSerialError::Film {
            frame: u32::from(frame),
            error: Box::new(HostSerialError::Protocol(format!("the DM failed: {e}"))),
        })?;
        self.next_upload += 1;
        let up = Upload::new(image, self.opts.upload.chunk, Some((frame, self.count)))
            .map_err(|e| self.blame(e))?;
        self.up = Some(Sending {
            frame,
            up,
            tries: 0,
            useless: 0,
            sent_end: 0,
            due: Duration::ZERO,
        });
        self.send(line).map_err(|e| self.blame(e))
    }

    /// Fold the upload's counts into the film's.
    fn count(&mut self) {
        if let Some(s) = self.up.as_mut() {
            let rep = std::mem::take(&mut s.up.report);
            self.report.chunks_sent += rep.chunks_sent;
            self.report.naks += rep.naks;
            self.report.timeouts += rep.timeouts;
        }
    }

    /// Send the upload's current message and set when its answer is due.
    fn send<P: Read + Write>(&mut self, line: &mut Line<'_, P>) -> Result<(), HostSerialError> {
        let timeout = self.opts.upload.reply_timeout;
        let Some(s) = self.up.as_mut() else {
            return Ok(());
        };
        s.sent_end = s.up.send(line)?;
        s.tries += 1;
        s.useless = 0;
        s.due = line.after(timeout);
        self.count();
        Ok(())
    }

    /// No answer to the upload's last message in time: send it again, or give up.
    fn upload_timeout<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
    ) -> Result<(), HostSerialError> {
        self.report.timeouts += 1;
        self.retry(line)
    }

    /// The last send brought no progress: again, unless the tries are used up.
    fn retry<P: Read + Write>(&mut self, line: &mut Line<'_, P>) -> Result<(), HostSerialError> {
        let tries = self.opts.upload.tries;
        let ms = u64::try_from(self.opts.upload.reply_timeout.as_millis()).unwrap_or(u64::MAX);
        if let Some(s) = self.up.as_ref().filter(|s| s.tries >= tries) {
            let u = &s.up;
            return Err(stalled(line, &u.stall, u.next, u.acked, s.tries, ms));
        }
        self.send(line)
    }

    /// An answer to the upload of the frame being sent.
    fn upload_answer<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        answer: super::upload::Answer,
    ) -> Result<(), HostSerialError> {
        let events = self.events;
        let Some(s) = self.up.as_mut() else {
            return Ok(());
        };
        let (frame, total) = (s.frame, s.up.bytes() as u64);
        let progress = |n: u64| {
            events(FilmEvent::Upload {
                frame,
                stored: n,
                total,
            })
        };
        let heard = s.up.heard(answer, s.sent_end, &progress);
        self.count();
        match heard? {
            Heard::Stored => {
                self.up = None;
                self.report.bytes += total;
                self.awaiting_start = Some(frame);
                Ok(())
            }
            Heard::Grew => {
                if let Some(s) = self.up.as_mut() {
                    s.tries = 0;
                    s.up.stall = Default::default();
                }
                self.send(line)
            }
            Heard::Stuck => self.retry(line),
            Heard::Useless => {
                let again = self.up.as_mut().is_some_and(|s| {
                    s.useless += 1;
                    s.useless >= MAX_STALE_ANSWERS
                });
                if again {
                    return self.retry(line);
                }
                Ok(())
            }
        }
    }

    /// Silence on the line for the readback's time-out.
    fn silence<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        reading: &mut Reading<'_>,
        ms: u64,
    ) -> Result<(), HostSerialError> {
        if reading.frame().is_some() {
            return reading
                .silence(line, ms)
                .map_err(|e| self.blame_read(reading, e));
        }
        if self.up.is_some() {
            // The upload's own time-outs cover it.
            return Ok(());
        }
        let e = line.timeout(ms, format!("frame {} from the RC", self.next_read));
        Err(HostSerialError::Film {
            frame: self.next_read,
            error: Box::new(e),
        })
    }

    fn blame_read(&self, reading: &Reading<'_>, e: HostSerialError) -> HostSerialError {
        HostSerialError::Film {
            frame: reading.frame().map_or(self.next_read, u32::from),
            error: Box::new(e),
        }
    }
}

fn reading_bad(reading: &Reading<'_>) -> u32 {
    reading.bad_packets
}
