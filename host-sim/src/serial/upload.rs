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
    pub bad_frames: u32,
}

/// Answers (or other messages, or malformed frames) in one wait that move nothing, after
/// which the message counts as unanswered and is sent again.
pub const MAX_STALE_ANSWERS: u32 = 16;

/// The answers an upload waits for, owned.
enum Answer {
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
                report.bad_frames += 1;
                return Ok(Some(Answer::Other("malformed frame")));
            }
            Some(Ok(p)) => {
                return match p.msg {
                    ToPc::Ack { offset } => Ok(Some(Answer::Ack(offset))),
                    ToPc::Nak { offset } => Ok(Some(Answer::Nak(offset))),
                    ToPc::SceneDone { len, crc } => Ok(Some(Answer::Done { len, crc })),
                    ToPc::Error {
                        code: RcError::Version { found },
                    } => Err(HostSerialError::Version { found }),
                    ToPc::Error { code } => Err(HostSerialError::Rc(code)),
                    m => Ok(Some(Answer::Other(kind(&m)))),
                }
            }
        }
    }
    Ok(None)
}

/// What the RC did during the sends since the acknowledged offset last grew.
#[derive(Default)]
struct Stall {
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
fn stalled<P: Read + Write>(
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
    let len = u32::try_from(image.len())
        .map_err(|_| HostSerialError::Protocol("scene larger than 4 GiB".into()))?;
    let crc = CRC32.checksum(image);
    let chunk = opts.chunk.clamp(1, MAX_CHUNK);
    let ms = u64::try_from(opts.reply_timeout.as_millis()).unwrap_or(u64::MAX);
    let mut line = Line::new(port, name, clock, opts.deadline);
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut report = UploadReport {
        bytes: image.len(),
        ..UploadReport::default()
    };
    // `None`: the SceneBegin is not acknowledged yet; `Some(o)`: send from offset `o`.
    let mut next: Option<u32> = None;
    // The highest offset the RC acknowledged (progress), and the end of the bytes sent so
    // far (or of those the RC already had): answers past it are about bytes never sent.
    let (mut acked, mut sent) = (0u32, 0u32);
    // Sends since `acked` last grew, and what the RC did meanwhile.
    let mut tries = 0u32;
    let mut stall = Stall::default();
    loop {
        // Send the current message.
        let sent_end = match next {
            None => {
                line.send(&ToRc::SceneBegin { len, crc })?;
                0
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
                report.chunks_sent += 1;
                sent = sent.max(end as u32);
                end as u32
            }
        };
        tries += 1;
        let deadline = line.after(opts.reply_timeout);
        // Answers in this wait that moved nothing.
        let mut useless = 0u32;
        // Wait for the answer that moves us on (stale ones are skipped, up to a point).
        let grew = loop {
            let Some(heard) = answer(&mut line, &mut dec, &mut report, deadline)? else {
                if line.overdue() {
                    return Err(line.deadline_error(format!("{acked} of {len} bytes acknowledged")));
                }
                report.timeouts += 1;
                break false;
            };
            match heard {
                // The answer to SceneBegin: 0, or where an interrupted upload of the same
                // scene stopped.
                Answer::Ack(a) if next.is_none() => {
                    if a > len {
                        return Err(HostSerialError::Protocol(format!(
                            "the RC acknowledged {a} bytes of a {len}-byte scene"
                        )));
                    }
                    progress(a as u64);
                    (next, acked, sent) = (Some(a), a, a);
                    break true;
                }
                Answer::Ack(a) if a > sent => {
                    return Err(HostSerialError::BeyondSent {
                        answer: "Ack",
                        offset: a,
                        sent,
                    })
                }
                Answer::Ack(a) if a >= sent_end => {
                    next = Some(a);
                    if a > acked {
                        acked = a;
                        progress(a as u64);
                        break true;
                    }
                    stall.stale += 1;
                    break false;
                }
                Answer::Nak(a) => {
                    report.naks += 1;
                    if next.is_some() {
                        if a > sent {
                            return Err(HostSerialError::BeyondSent {
                                answer: "Nak",
                                offset: a,
                                sent,
                            });
                        }
                        if a < acked {
                            stall.rewind = Some((a, acked));
                        } else {
                            stall.naks += 1;
                        }
                        next = Some(a);
                    } else {
                        stall.naks += 1;
                    }
                    break false;
                }
                Answer::Done { len: l, crc: c } if next.is_some() => {
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
                    if let Some(frames) = opts.start_render {
                        line.send(&ToRc::StartRender { frames })?;
                    }
                    return Ok(report);
                }
                // Stale: an Ack below what was just sent, a SceneDone before SceneBegin's
                // answer (left from an earlier upload).
                Answer::Ack(_) | Answer::Done { .. } => stall.stale += 1,
                Answer::Other(k) => {
                    stall.other += 1;
                    stall.last_other = k;
                }
            }
            useless += 1;
            if useless >= MAX_STALE_ANSWERS {
                break false;
            }
        };
        if grew {
            tries = 0;
            stall = Stall::default();
        } else if tries >= opts.tries {
            return Err(stalled(&line, &stall, next, acked, tries, ms));
        }
    }
}
