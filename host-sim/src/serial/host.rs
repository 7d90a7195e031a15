//! The PC side of the serial link to a real RC (`links upload`, `links readback`), over any
//! byte stream (a serial port, a pseudo-terminal), speaking [`links_core::serial`].
//!
//! Both directions wait with deadlines, never forever: a port's read returns after its own
//! short time-out, and every wait here has an overall one.

use links_core::serial::{
    framed_len, pixel_count, pixels_into, Decoder, Encoder, RcError, SerialError, ToPc, ToRc,
    MAX_CHUNK, MAX_DIM, MAX_TO_PC, MAX_TO_RC,
};
use links_core::wire::CRC32;
use std::cell::Cell;
use std::fmt;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

/// Baud rate when none is given (a USB CDC port ignores it; a UART needs it).
pub const DEFAULT_BAUD: u32 = 115_200;

/// Why an upload or readback failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HostSerialError {
    /// No such port (nothing plugged in, or a wrong name).
    PortMissing { port: String },
    /// The port exists but cannot be opened (permissions, busy, not a tty).
    Open { port: String, reason: String },
    /// Reading or writing the port failed.
    Io { port: String, reason: String },
    /// Nothing usable arrived in time.
    Timeout {
        port: String,
        ms: u64,
        waiting_for: String,
    },
    /// The assembled frame's CRC-32 differs from the one the RC announced.
    FrameCrc {
        frame: u16,
        expected: u32,
        found: u32,
    },
    /// The RC speaks another protocol version.
    Version { found: u8 },
    /// The RC refused the request.
    Rc(RcError),
    /// The RC kept answering with retransmit requests (or pixels stayed missing).
    Retries { what: String, tries: u32 },
    /// A well-formed message that makes no sense here (e.g. pixels outside the frame).
    Protocol(String),
    /// The overall deadline (`--deadline-s`) passed; `doing` says how far it got.
    Deadline {
        port: String,
        ms: u64,
        doing: String,
    },
    /// Readback: the RC began another frame before finishing the one being read, once too
    /// often (`restarts` times; `frame` is the latest).
    FrameRestarts { restarts: u32, frame: u16 },
    /// Readback: more pixels that were not new (repeats, or of another frame) than one
    /// frame plus everything asked for again (`frame`: the frame being read, `None` before
    /// any `FrameHeader`).
    RepeatedPixels {
        frame: Option<u16>,
        stale: u64,
        allowed: u64,
    },
    /// Readback: `messages` messages in a row with neither pixels nor progress (`last`:
    /// the kind of the last one).
    NoProgress { messages: u32, last: &'static str },
    /// Upload: the RC kept taking back bytes it had acknowledged (a `Nak` from `nak` after
    /// `acked` bytes were acknowledged), `tries` sends without progress.
    Rewinds { tries: u32, nak: u32, acked: u32 },
    /// Upload: the RC answered, but its acknowledgements stayed at byte `at` for `tries`
    /// sends (`answers` answers that moved nothing).
    StaleAcks { tries: u32, at: u32, answers: u32 },
    /// Upload: an answer (`Ack`, `Nak`, `SceneDone`) about byte `offset`, past the `sent`
    /// bytes sent so far.
    BeyondSent {
        answer: &'static str,
        offset: u32,
        sent: u32,
    },
}

impl fmt::Display for HostSerialError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HostSerialError::PortMissing { port } => write!(
                f,
                "serial port {port} does not exist (is the RC connected? check the name, e.g. /dev/ttyACM0)"
            ),
            HostSerialError::Open { port, reason } => {
                write!(f, "cannot open serial port {port}: {reason}")
            }
            HostSerialError::Io { port, reason } => write!(f, "serial port {port}: {reason}"),
            HostSerialError::Timeout {
                port,
                ms,
                waiting_for,
            } => write!(
                f,
                "timed out after {ms} ms on {port} waiting for {waiting_for}"
            ),
            HostSerialError::FrameCrc {
                frame,
                expected,
                found,
            } => write!(
                f,
                "frame {frame} failed its CRC check: the RC announced {expected:#010x}, the received pixels give {found:#010x}"
            ),
            HostSerialError::Version { found } => write!(
                f,
                "protocol version mismatch: the RC speaks serial protocol version {found}, this links speaks {} (update the firmware or links)",
                links_core::serial::VERSION
            ),
            HostSerialError::Rc(e) => write!(f, "the RC refused: {e}"),
            HostSerialError::Retries { what, tries } => {
                write!(f, "gave up after {tries} tries: {what}")
            }
            HostSerialError::Protocol(s) => write!(f, "protocol error: {s}"),
            HostSerialError::Deadline { port, ms, doing } => write!(
                f,
                "gave up on {port} at the overall deadline of {ms} ms (--deadline-s): {doing}"
            ),
            HostSerialError::FrameRestarts { restarts, frame } => write!(
                f,
                "the RC restarted the frame {restarts} times without finishing one (now frame {frame}); giving up"
            ),
            HostSerialError::RepeatedPixels {
                frame: Some(frame),
                stale,
                allowed,
            } => write!(
                f,
                "the RC kept repeating pixels: {stale} pixels repeated or of other frames while reading frame {frame} (at most {allowed}: one frame plus what was asked for again); giving up"
            ),
            HostSerialError::RepeatedPixels {
                frame: None,
                stale,
                allowed,
            } => write!(
                f,
                "the RC sent {stale} pixels without a frame header (at most {allowed}: one {MAX_DIM}x{MAX_DIM} frame); giving up"
            ),
            HostSerialError::NoProgress { messages, last } => write!(
                f,
                "the RC sent {messages} messages in a row without progress (last: {last}); giving up"
            ),
            HostSerialError::Rewinds { tries, nak, acked } => write!(
                f,
                "the RC kept taking back acknowledged bytes (a Nak from byte {nak} after {acked} bytes were acknowledged; {tries} sends without progress); giving up"
            ),
            HostSerialError::StaleAcks { tries, at, answers } => write!(
                f,
                "the RC's acknowledgements never passed byte {at} ({answers} answers to {tries} sends without progress); giving up"
            ),
            HostSerialError::BeyondSent {
                answer,
                offset,
                sent,
            } => write!(
                f,
                "the RC's {answer} names byte {offset}, but only {sent} bytes were sent; giving up"
            ),
        }
    }
}

impl std::error::Error for HostSerialError {}

/// Open a serial port for the protocol (8N1, no flow control).
pub fn open_port(
    port: &str,
    baud: u32,
) -> Result<Box<dyn serialport::SerialPort>, HostSerialError> {
    #[cfg(unix)]
    if !std::path::Path::new(port).exists() {
        return Err(HostSerialError::PortMissing { port: port.into() });
    }
    serialport::new(port, baud)
        // The poll interval of reads; the waits below have their own deadlines.
        .timeout(Duration::from_millis(20))
        .open()
        .map_err(|e| match e.kind() {
            serialport::ErrorKind::NoDevice
            | serialport::ErrorKind::Io(std::io::ErrorKind::NotFound) => {
                HostSerialError::PortMissing { port: port.into() }
            }
            _ => HostSerialError::Open {
                port: port.into(),
                reason: e.to_string(),
            },
        })
}

/// Time as the upload and readback loops see it: the system clock, or a virtual one in tests
/// (so that a test of a time-out does not sleep).
pub trait Clock {
    /// Time elapsed since a fixed start.
    fn now(&self) -> Duration;
    /// The port had nothing to read: wait a moment before asking again.
    fn pause(&self);
}

/// The system clock; [`Clock::pause`] sleeps 1 ms.
pub struct SystemClock {
    start: Instant,
}

impl SystemClock {
    pub fn new() -> Self {
        SystemClock {
            start: Instant::now(),
        }
    }
}

impl Default for SystemClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for SystemClock {
    fn now(&self) -> Duration {
        self.start.elapsed()
    }

    fn pause(&self) {
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// A clock that stands still until the port has nothing to read: each [`Clock::pause`]
/// advances it by `step`. Time-outs then cost no real time.
pub struct VirtualClock {
    now: Cell<Duration>,
    step: Duration,
}

impl VirtualClock {
    pub fn new(step: Duration) -> Self {
        VirtualClock {
            now: Cell::new(Duration::ZERO),
            step,
        }
    }
}

impl Clock for VirtualClock {
    fn now(&self) -> Duration {
        self.now.get()
    }

    fn pause(&self) {
        self.now.set(self.now.get().saturating_add(self.step));
    }
}

/// A byte stream with deadlines, and the frame encoder for the PC's messages.
struct Line<'p, P> {
    port: &'p mut P,
    name: &'p str,
    clock: &'p dyn Clock,
    /// The overall deadline on the clock, and its length in ms (for the message).
    overall: Option<(Duration, u64)>,
    buf: [u8; 4096],
    at: usize,
    end: usize,
    enc: Encoder,
    out: [u8; MAX_TO_RC],
}

impl<'p, P: Read + Write> Line<'p, P> {
    /// A line that gives up `deadline` from now (if any).
    fn new(
        port: &'p mut P,
        name: &'p str,
        clock: &'p dyn Clock,
        deadline: Option<Duration>,
    ) -> Self {
        Line {
            port,
            name,
            clock,
            overall: deadline.map(|d| {
                let ms = u64::try_from(d.as_millis()).unwrap_or(u64::MAX);
                (clock.now().saturating_add(d), ms)
            }),
            buf: [0; 4096],
            at: 0,
            end: 0,
            enc: Encoder::new(),
            out: [0; MAX_TO_RC],
        }
    }

    fn io(&self, e: std::io::Error) -> HostSerialError {
        HostSerialError::Io {
            port: self.name.into(),
            reason: e.to_string(),
        }
    }

    fn timeout(&self, ms: u64, waiting_for: impl Into<String>) -> HostSerialError {
        HostSerialError::Timeout {
            port: self.name.into(),
            ms,
            waiting_for: waiting_for.into(),
        }
    }

    /// The time on the line's clock `d` from now.
    fn after(&self, d: Duration) -> Duration {
        self.clock.now().saturating_add(d)
    }

    /// Whether the overall deadline has passed.
    fn overdue(&self) -> bool {
        self.overall.is_some_and(|(at, _)| self.clock.now() >= at)
    }

    /// The error for the overall deadline, saying how far the job got.
    fn deadline_error(&self, doing: String) -> HostSerialError {
        HostSerialError::Deadline {
            port: self.name.into(),
            ms: self.overall.map_or(0, |(_, ms)| ms),
            doing,
        }
    }

    /// The next byte, or `None` once `deadline` (on the line's clock) or the overall
    /// deadline ([`Line::overdue`]) has passed. Both are checked before every read of the
    /// port, so a flood of bytes does not hide them.
    fn byte(&mut self, deadline: Duration) -> Result<Option<u8>, HostSerialError> {
        loop {
            if self.at < self.end {
                self.at += 1;
                return Ok(Some(self.buf[self.at - 1]));
            }
            if self.clock.now() >= deadline || self.overdue() {
                return Ok(None);
            }
            match self.port.read(&mut self.buf) {
                Ok(0) => self.clock.pause(),
                Ok(n) => (self.at, self.end) = (0, n.min(self.buf.len())),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                    ) =>
                {
                    self.clock.pause()
                }
                Err(e) => return Err(self.io(e)),
            }
        }
    }

    fn send(&mut self, msg: &ToRc<'_>) -> Result<(), HostSerialError> {
        let n = self
            .enc
            .encode(msg, &mut self.out)
            .map_err(|e| HostSerialError::Protocol(e.to_string()))?;
        let r = self
            .port
            .write_all(&self.out[..n])
            .and_then(|_| self.port.flush());
        r.map_err(|e| self.io(e))
    }
}

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

/// The name of a message's kind, for error messages.
fn kind(msg: &ToPc<'_>) -> &'static str {
    match msg {
        ToPc::Ack { .. } => "Ack",
        ToPc::Nak { .. } => "Nak",
        ToPc::SceneDone { .. } => "SceneDone",
        ToPc::FrameHeader { .. } => "FrameHeader",
        ToPc::Pixels { .. } => "Pixels",
        ToPc::PixelsRle { .. } => "PixelsRle",
        ToPc::FrameEnd { .. } => "FrameEnd",
        ToPc::Progress { .. } => "Progress",
        ToPc::Error { .. } => "Error",
    }
}

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
    pub bad_frames: u32,
    /// Retransmit requests sent.
    pub resends: u32,
}

/// One frame being assembled from pixel messages in any order.
pub struct FrameAssembly {
    pub frame: u16,
    pub width: u16,
    pub height: u16,
    pub rgb: Vec<u8>,
    have: Vec<bool>,
    count: u64,
}

impl FrameAssembly {
    pub fn new(frame: u16, width: u16, height: u16) -> Result<Self, HostSerialError> {
        if !(1..=MAX_DIM).contains(&width) || !(1..=MAX_DIM).contains(&height) {
            return Err(HostSerialError::Protocol(format!(
                "frame header of {width}x{height} pixels (1..={MAX_DIM} each)"
            )));
        }
        let n = width as usize * height as usize;
        Ok(FrameAssembly {
            frame,
            width,
            height,
            rgb: vec![0; 3 * n],
            have: vec![false; n],
            count: 0,
        })
    }

    fn total(&self) -> u64 {
        self.have.len() as u64
    }

    /// Store a pixel message's pixels; returns whether it belonged to this frame.
    pub fn put(&mut self, msg: &ToPc<'_>) -> Result<bool, HostSerialError> {
        let (frame, y, x) = match *msg {
            ToPc::Pixels { frame, y, x, .. } | ToPc::PixelsRle { frame, y, x, .. } => (frame, y, x),
            _ => return Ok(false),
        };
        if frame != self.frame {
            return Ok(false);
        }
        let n = pixel_count(msg);
        if n == 0 || y >= self.height || x as usize + n > self.width as usize {
            return Err(HostSerialError::Protocol(format!(
                "{n} pixels at ({x}, {y}) do not fit the {}x{} frame",
                self.width, self.height
            )));
        }
        let first = y as usize * self.width as usize + x as usize;
        pixels_into(msg, &mut self.rgb[3 * first..3 * (first + n)])
            .map_err(|e| HostSerialError::Protocol(e.to_string()))?;
        for h in &mut self.have[first..first + n] {
            if !*h {
                *h = true;
                self.count += 1;
            }
        }
        Ok(true)
    }

    /// The raster span from the first to the last missing pixel: (start, len).
    pub fn missing_span(&self) -> Option<(u32, u32)> {
        let first = self.have.iter().position(|h| !h)?;
        let last = self.have.iter().rposition(|h| !h)?;
        Some((first as u32, (last - first + 1) as u32))
    }

    fn forget(&mut self) {
        self.have.iter_mut().for_each(|h| *h = false);
        self.count = 0;
    }
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
    fn pixels(&mut self, frame: Option<u16>, n: u64, fresh: u64) -> Result<(), HostSerialError> {
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
    let mut asm: Option<FrameAssembly> = None;
    let (mut bad_frames, mut resends, mut crc_retry) = (0u32, 0u32, false);
    let mut watch = Watch::new();
    let mut deadline = line.after(opts.timeout);
    loop {
        let Some(b) = line.byte(deadline)? else {
            if line.overdue() {
                let doing = asm
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
            // Silence.
            let Some(a) = &asm else {
                return Err(line.timeout(ms, "a frame from the RC"));
            };
            if resends >= opts.resend_rounds {
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
            line.send(&ToRc::Resend {
                frame: a.frame,
                start,
                len,
            })?;
            resends += 1;
            watch.asked(len as u64);
            progress(ReadbackEvent::Resend { pixels: len });
            deadline = line.after(opts.timeout);
            continue;
        };
        let packet = match dec.feed::<ToPc>(b) {
            None => continue,
            Some(Err(SerialError::Version { found })) => {
                return Err(HostSerialError::Version { found })
            }
            Some(Err(_)) => {
                bad_frames += 1;
                continue;
            }
            Some(Ok(p)) => p,
        };
        deadline = line.after(opts.timeout);
        let kind = kind(&packet.msg);
        // Whether this (non-pixel) message is progress.
        let mut news = false;
        match packet.msg {
            ToPc::FrameHeader {
                frame,
                width,
                height,
            } => {
                if asm.as_ref().is_none_or(|a| a.frame != frame) {
                    if asm.is_some() {
                        watch.restarts += 1;
                        if watch.restarts >= opts.max_restarts {
                            return Err(HostSerialError::FrameRestarts {
                                restarts: watch.restarts,
                                frame,
                            });
                        }
                    }
                    let a = FrameAssembly::new(frame, width, height)?;
                    watch.new_frame(a.total());
                    asm = Some(a);
                    (resends, crc_retry, news) = (0, false, true);
                    progress(ReadbackEvent::Header {
                        frame,
                        width,
                        height,
                    });
                }
            }
            ToPc::Progress { frame, done, total } => {
                progress(ReadbackEvent::Rendering { done, total });
                news = asm
                    .as_ref()
                    .is_some_and(|a| watch.progressed(a, frame, done, total));
            }
            ToPc::Error {
                code: RcError::Version { found },
            } => return Err(HostSerialError::Version { found }),
            ToPc::Error { code } => return Err(HostSerialError::Rc(code)),
            m @ (ToPc::Pixels { .. } | ToPc::PixelsRle { .. }) => {
                // At least one pixel per message, so that even empty ones add up.
                let n = pixel_count(&m).max(1) as u64;
                let mut fresh = 0;
                if let Some(a) = &mut asm {
                    let before = a.count;
                    if a.put(&m)? {
                        fresh = a.count - before;
                        progress(ReadbackEvent::Pixels {
                            have: a.count,
                            total: a.total(),
                        });
                    }
                }
                watch.pixels(asm.as_ref().map(|a| a.frame), n, fresh)?;
                continue;
            }
            ToPc::FrameEnd { frame, crc } => {
                if let Some(a) = asm.as_mut().filter(|a| a.frame == frame) {
                    if let Some((start, len)) = a.missing_span() {
                        if resends >= opts.resend_rounds {
                            return Err(HostSerialError::Retries {
                                what: format!(
                                    "frame {frame} still lacks {} pixels",
                                    a.total() - a.count
                                ),
                                tries: resends,
                            });
                        }
                        line.send(&ToRc::Resend { frame, start, len })?;
                        resends += 1;
                        watch.asked(len as u64);
                        progress(ReadbackEvent::Resend { pixels: len });
                    } else {
                        let found = CRC32.checksum(&a.rgb);
                        if found == crc {
                            line.send(&ToRc::FrameAck { frame })?;
                            let rgb = std::mem::take(&mut a.rgb);
                            return Ok(Readback {
                                frame,
                                width: a.width as u32,
                                height: a.height as u32,
                                rgb,
                                crc,
                                bad_frames,
                                resends,
                            });
                        }
                        if crc_retry {
                            return Err(HostSerialError::FrameCrc {
                                frame,
                                expected: crc,
                                found,
                            });
                        }
                        // Once: forget every pixel and ask for the whole frame again.
                        crc_retry = true;
                        a.forget();
                        let len = a.total() as u32;
                        line.send(&ToRc::Resend {
                            frame,
                            start: 0,
                            len,
                        })?;
                        resends += 1;
                        watch.asked(len as u64);
                        progress(ReadbackEvent::Resend { pixels: len });
                    }
                }
            }
            ToPc::Ack { .. } | ToPc::Nak { .. } | ToPc::SceneDone { .. } => {}
        }
        watch.message(news, kind, opts.idle_messages)?;
    }
}
