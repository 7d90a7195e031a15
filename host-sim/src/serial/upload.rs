//! Sending a SceneImage to the RC (`links upload`): stop-and-wait chunks, each answered
//! before the next, until the RC reports the scene stored.

use super::port::{kind, Clock, Line, SystemClock};
use super::HostSerialError;
use links_core::serial::{
    framed_len, Decoder, RcError, SerialError, ToPc, ToRc, MAX_CHUNK, MAX_TO_PC, MAX_TO_RC,
};
use links_core::wire::CRC32;
use std::io::{Read, Write};
use std::time::Duration;

/// Settings of [`upload`].
#[derive(Clone, Debug)]
pub struct UploadOptions {
    /// How long to wait for the RC's answer to one message before sending it again.
    pub reply_timeout: Duration,
    /// Sends of one message (the first included) before giving up.
    pub tries: u32,
    /// Scene bytes per chunk (1..=[`MAX_CHUNK`]).
    pub chunk: usize,
    /// Send [`ToRc::StartRender`] for this many frames once the scene is stored.
    pub start_render: Option<u16>,
    /// Give up once this much time has passed in all (`None`: no overall deadline).
    pub deadline: Option<Duration>,
}

impl Default for UploadOptions {
    fn default() -> Self {
        UploadOptions {
            reply_timeout: Duration::from_millis(1000),
            tries: 8,
            chunk: MAX_CHUNK,
            start_render: None,
            deadline: None,
        }
    }
}

/// The overall deadline of an upload when none is given: 10 s, plus two full rounds of
/// `tries` reply time-outs, plus four times the line time of the whole upload at `baud`
/// (every chunk a full frame on the line, every answer up to 27 bytes, 10 bits a byte). A
/// USB CDC port is faster than any baud rate, so this only errs long.
pub fn upload_deadline(len: usize, baud: u32, opts: &UploadOptions) -> Duration {
    let chunks = len.div_ceil(opts.chunk.clamp(1, MAX_CHUNK)) as u64 + 1;
    let line_bytes = chunks.saturating_mul((MAX_TO_RC + framed_len(24)) as u64);
    let line_ms = line_bytes.saturating_mul(10_000) / u64::from(baud.max(1));
    Duration::from_secs(10)
        .saturating_add(
            opts.reply_timeout
                .saturating_mul(opts.tries.saturating_mul(2)),
        )
        .saturating_add(Duration::from_millis(line_ms.saturating_mul(4)))
}

/// What an upload did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct UploadReport {
    pub bytes: usize,
    /// Chunk messages sent, retransmissions included.
    pub chunks_sent: u32,
    /// Retransmit requests ([`ToPc::Nak`]) the RC sent.
    pub naks: u32,
    /// Messages sent again after no answer came in time.
    pub timeouts: u32,
    /// Malformed frames received from the RC.
    pub bad_packets: u32,
}

/// Answers (or other messages, or malformed frames) in one wait that move nothing, after
/// which the message counts as unanswered and is sent again.
pub const MAX_STALE_ANSWERS: u32 = 16;

/// The answers an upload waits for, owned.
pub(super) enum Answer {
    Ack(u32),
    Nak(u32),
    Done {
        len: u32,
        crc: u32,
    },
    /// A message that answers nothing here, or a malformed frame (its kind).
    Other(&'static str),
}

/// Wait for the RC's next message during an upload (malformed frames are counted and
/// returned as [`Answer::Other`]). `None`: nothing in time.
fn answer<P: Read + Write>(
    line: &mut Line<'_, P>,
    dec: &mut Decoder<MAX_TO_PC>,
    report: &mut UploadReport,
    deadline: Duration,
) -> Result<Option<Answer>, HostSerialError> {
    while let Some(b) = line.byte(deadline)? {
        match dec.feed::<ToPc>(b) {
            None => {}
            Some(Err(SerialError::Version { found })) => {
                return Err(HostSerialError::Version { found })
            }
            Some(Err(_)) => {
                report.bad_packets += 1;
                return Ok(Some(Answer::Other("malformed frame")));
            }
            Some(Ok(p)) => return answer_of(&p.msg).map(Some),
        }
    }
    Ok(None)
}

/// What an RC message means to an upload (an `Error` ends it).
pub(super) fn answer_of(msg: &ToPc<'_>) -> Result<Answer, HostSerialError> {
    match *msg {
        ToPc::Ack { offset } => Ok(Answer::Ack(offset)),
        ToPc::Nak { offset } => Ok(Answer::Nak(offset)),
        ToPc::SceneDone { len, crc } => Ok(Answer::Done { len, crc }),
        ToPc::Error {
            code: RcError::Version { found },
        } => Err(HostSerialError::Version { found }),
        ToPc::Error { code } => Err(HostSerialError::Rc(code)),
        ref m => Ok(Answer::Other(kind(m))),
    }
}

/// What the RC did during the sends since the acknowledged offset last grew.
#[derive(Default)]
pub(super) struct Stall {
    /// `Nak`s at or past the acknowledged offset (retransmit requests).
    naks: u32,
    /// The last `Nak` below the acknowledged offset: (its offset, the acknowledged one).
    rewind: Option<(u32, u32)>,
    /// `Ack`s and `SceneDone`s that moved nothing.
    stale: u32,
    /// Other messages and malformed frames, and the kind of the last.
    other: u32,
    last_other: &'static str,
}

/// The error once `tries` sends brought no progress: named after what the RC did.
pub(super) fn stalled<P: Read + Write>(
    line: &Line<'_, P>,
    stall: &Stall,
    next: Option<u32>,
    acked: u32,
    tries: u32,
    ms: u64,
) -> HostSerialError {
    let at = next.map_or("the scene header".to_string(), |o| {
        format!("the chunk at byte {o}")
    });
    if let Some((nak, acked)) = stall.rewind {
        HostSerialError::Rewinds { tries, nak, acked }
    } else if stall.naks > 0 {
        HostSerialError::Retries {
            what: format!("the RC kept asking to retransmit {at}"),
            tries,
        }
    } else if stall.stale > 0 {
        HostSerialError::StaleAcks {
            tries,
            at: acked,
            answers: stall.stale,
        }
    } else if stall.other > 0 {
        HostSerialError::NoProgress {
            messages: stall.other,
            last: stall.last_other,
        }
    } else {
        line.timeout(ms, format!("the RC's answer to {at} ({tries} tries)"))
    }
}

/// Send a SceneImage to the RC: `SceneBegin`, then chunks in order, each answered before
/// the next (stop-and-wait; a `Nak` rewinds to its offset, silence resends). `progress`
/// gets the bytes the RC has stored.
///
/// Always ends: `opts.tries` sends in a row that do not raise the highest acknowledged
/// offset end it (whatever the RC answered: silence, `Nak`s, `Ack`s that take nothing
/// further, a `Nak` taking back acknowledged bytes); a wait ends after
/// [`MAX_STALE_ANSWERS`] answers that move nothing; an answer about bytes never sent ends
/// it at once; and so does `opts.deadline`.
pub fn upload<P: Read + Write>(
    port: &mut P,
    name: &str,
    image: &[u8],
    opts: &UploadOptions,
    progress: &dyn Fn(u64),
) -> Result<UploadReport, HostSerialError> {
    upload_with_clock(port, name, image, opts, &SystemClock::new(), progress)
}

/// [`upload`] on the time of `clock`.
pub fn upload_with_clock<P: Read + Write>(
    port: &mut P,
    name: &str,
    image: &[u8],
    opts: &UploadOptions,
    clock: &dyn Clock,
    progress: &dyn Fn(u64),
) -> Result<UploadReport, HostSerialError> {
    let ms = u64::try_from(opts.reply_timeout.as_millis()).unwrap_or(u64::MAX);
    let mut line = Line::new(port, name, clock, opts.deadline);
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut up = Upload::new(image, opts.chunk, None)?;
    // Sends since `acked` last grew.
    let mut tries = 0u32;
    loop {
        let sent_end = up.send(&mut line)?;
        tries += 1;
        match up.wait(&mut line, &mut dec, opts, sent_end, progress)? {
            Heard::Stored => {
                if let Some(frames) = opts.start_render {
                    line.send(&ToRc::StartRender { frames })?;
                }
                return Ok(up.report);
            }
            Heard::Grew => {
                tries = 0;
                up.stall = Stall::default();
            }
            Heard::Stuck | Heard::Useless if tries >= opts.tries => {
                return Err(stalled(&line, &up.stall, up.next, up.acked, tries, ms));
            }
            Heard::Stuck | Heard::Useless => {}
        }
    }
}

/// An upload under way: where it stands, and what the RC did since it last moved.
pub(super) struct Upload<I> {
    image: I,
    len: u32,
    crc: u32,
    /// A film frame: (its number, the film's length): begun with `FrameBegin`.
    film: Option<(u16, u16)>,
    /// Scene bytes per chunk.
    chunk: usize,
    /// `None`: the SceneBegin is not acknowledged yet; `Some(o)`: send from offset `o`.
    pub(super) next: Option<u32>,
    /// The highest offset the RC acknowledged (progress), and the end of the bytes sent so
    /// far (or of those the RC already had): answers past it are about bytes never sent.
    pub(super) acked: u32,
    sent: u32,
    pub(super) report: UploadReport,
    /// What the RC did since `acked` last grew.
    pub(super) stall: Stall,
}

/// What an answer means for the wait it arrived in.
pub(super) enum Heard {
    /// The acknowledged offset grew: the wait ends and the tries start again.
    Grew,
    /// The wait ends without progress (a time-out, a `Nak`, an `Ack` that took nothing).
    Stuck,
    /// The answer moved nothing: keep waiting.
    Useless,
    /// The RC stored the whole scene.
    Stored,
}

impl<I: AsRef<[u8]>> Upload<I> {
    /// An upload of `image` in chunks of `chunk` bytes (clamped to 1..=[`MAX_CHUNK`]); a
    /// film frame when `film` gives (its number, the film's length).
    pub(super) fn new(
        image: I,
        chunk: usize,
        film: Option<(u16, u16)>,
    ) -> Result<Self, HostSerialError> {
        let bytes = image.as_ref();
        let (len, crc, n) = (bytes.len(), CRC32.checksum(bytes), bytes.len());
        let len = u32::try_from(len)
            .map_err(|_| HostSerialError::Protocol("scene larger than 4 GiB".into()))?;
        Ok(Upload {
            image,
            len,
            crc,
            film,
            chunk: chunk.clamp(1, MAX_CHUNK),
            next: None,
            acked: 0,
            sent: 0,
            report: UploadReport {
                bytes: n,
                ..UploadReport::default()
            },
            stall: Stall::default(),
        })
    }

    /// The image's length in bytes.
    pub(super) fn bytes(&self) -> usize {
        self.image.as_ref().len()
    }

    /// Send the current message: the SceneBegin (or FrameBegin), or the chunk at `next`.
    /// Returns the end of the bytes it carries (0 for the begin).
    pub(super) fn send<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
    ) -> Result<u32, HostSerialError> {
        let (len, chunk, crc) = (self.len, self.chunk, self.crc);
        let image = self.image.as_ref();
        match self.next {
            None => {
                match self.film {
                    Some((frame, frames)) => line.send(&ToRc::FrameBegin {
                        frame,
                        frames,
                        len,
                        crc,
                    })?,
                    None => line.send(&ToRc::SceneBegin { len, crc })?,
                }
                Ok(0)
            }
            Some(o) => {
                // Everything acknowledged but no SceneDone yet: the last chunk again (the
                // RC answers a repeated last chunk with SceneDone).
                let o = if o >= len {
                    len.saturating_sub(chunk as u32)
                } else {
                    o
                };
                let end = (o as usize).saturating_add(chunk).min(image.len());
                let data = image.get(o as usize..end).ok_or_else(|| {
                    HostSerialError::Protocol(format!("no chunk at byte {o} of {len}"))
                })?;
                line.send(&ToRc::SceneChunk { offset: o, data })?;
                self.report.chunks_sent += 1;
                self.sent = self.sent.max(end as u32);
                Ok(end as u32)
            }
        }
    }

    /// Wait for the answer that moves the upload on (stale ones are skipped, up to
    /// [`MAX_STALE_ANSWERS`]); never [`Heard::Useless`].
    fn wait<P: Read + Write>(
        &mut self,
        line: &mut Line<'_, P>,
        dec: &mut Decoder<MAX_TO_PC>,
        opts: &UploadOptions,
        sent_end: u32,
        progress: &dyn Fn(u64),
    ) -> Result<Heard, HostSerialError> {
        let deadline = line.after(opts.reply_timeout);
        // Answers in this wait that moved nothing.
        let mut useless = 0u32;
        loop {
            let Some(heard) = answer(line, dec, &mut self.report, deadline)? else {
                if line.overdue() {
                    let (acked, len) = (self.acked, self.len);
                    return Err(line.deadline_error(format!("{acked} of {len} bytes acknowledged")));
                }
                self.report.timeouts += 1;
                return Ok(Heard::Stuck);
            };
            match self.heard(heard, sent_end, progress)? {
                Heard::Useless => {}
                h => return Ok(h),
            }
            useless += 1;
            if useless >= MAX_STALE_ANSWERS {
                return Ok(Heard::Stuck);
            }
        }
    }

    /// Take in one answer to the message that was sent up to `sent_end`.
    pub(super) fn heard(
        &mut self,
        heard: Answer,
        sent_end: u32,
        progress: &dyn Fn(u64),
    ) -> Result<Heard, HostSerialError> {
        let (len, crc, sent) = (self.len, self.crc, self.sent);
        let stall = &mut self.stall;
        match heard {
            // The answer to SceneBegin: 0, or where an interrupted upload of the same
            // scene stopped.
            Answer::Ack(a) if self.next.is_none() => {
                if a > len {
                    return Err(HostSerialError::Protocol(format!(
                        "the RC acknowledged {a} bytes of a {len}-byte scene"
                    )));
                }
                progress(a as u64);
                (self.next, self.acked, self.sent) = (Some(a), a, a);
                Ok(Heard::Grew)
            }
            Answer::Ack(a) if a > sent => Err(HostSerialError::BeyondSent {
                answer: "Ack",
                offset: a,
                sent,
            }),
            Answer::Ack(a) if a >= sent_end => {
                self.next = Some(a);
                if a > self.acked {
                    self.acked = a;
                    progress(a as u64);
                    return Ok(Heard::Grew);
                }
                stall.stale += 1;
                Ok(Heard::Stuck)
            }
            Answer::Nak(a) => {
                self.report.naks += 1;
                if self.next.is_some() {
                    if a > sent {
                        return Err(HostSerialError::BeyondSent {
                            answer: "Nak",
                            offset: a,
                            sent,
                        });
                    }
                    if a < self.acked {
                        stall.rewind = Some((a, self.acked));
                    } else {
                        stall.naks += 1;
                    }
                    self.next = Some(a);
                } else {
                    stall.naks += 1;
                }
                Ok(Heard::Stuck)
            }
            Answer::Done { len: l, crc: c } if self.next.is_some() => {
                if (l, c) != (len, crc) {
                    return Err(HostSerialError::Protocol(format!(
                        "the RC stored a scene of {l} bytes, CRC {c:#010x}; sent {len} bytes, CRC {crc:#010x}"
                    )));
                }
                if sent < len {
                    return Err(HostSerialError::BeyondSent {
                        answer: "SceneDone",
                        offset: len,
                        sent,
                    });
                }
                progress(len as u64);
                Ok(Heard::Stored)
            }
            // Stale: an Ack below what was just sent, a SceneDone before SceneBegin's
            // answer (left from an earlier upload).
            Answer::Ack(_) | Answer::Done { .. } => {
                stall.stale += 1;
                Ok(Heard::Useless)
            }
            Answer::Other(k) => {
                stall.other += 1;
                stall.last_other = k;
                Ok(Heard::Useless)
            }
        }
    }
}
