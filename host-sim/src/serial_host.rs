//! The PC side of the serial link to a real RC (`links upload`, `links readback`), over any
//! byte stream (a serial port, a pseudo-terminal), speaking [`links_core::serial`].
//!
//! Both directions wait with deadlines, never forever: a port's read returns after its own
//! short time-out, and every wait here has an overall one.

use links_core::serial::{
    pixel_count, pixels_into, Decoder, Encoder, RcError, SerialError, ToPc, ToRc, MAX_CHUNK,
    MAX_DIM, MAX_TO_PC, MAX_TO_RC,
};
use links_core::wire::CRC32;
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

/// A byte stream with deadlines, and the frame encoder for the PC's messages.
struct Line<'p, P> {
    port: &'p mut P,
    name: &'p str,
    buf: [u8; 4096],
    at: usize,
    end: usize,
    enc: Encoder,
    out: [u8; MAX_TO_RC],
}

impl<'p, P: Read + Write> Line<'p, P> {
    fn new(port: &'p mut P, name: &'p str) -> Self {
        Line {
            port,
            name,
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

    /// The next byte, or `None` once `deadline` has passed.
    fn byte(&mut self, deadline: Instant) -> Result<Option<u8>, HostSerialError> {
        loop {
            if self.at < self.end {
                self.at += 1;
                return Ok(Some(self.buf[self.at - 1]));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            match self.port.read(&mut self.buf) {
                Ok(0) => std::thread::sleep(Duration::from_millis(1)),
                Ok(n) => (self.at, self.end) = (0, n),
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::Interrupted
                    ) => {}
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
}

impl Default for UploadOptions {
    fn default() -> Self {
        UploadOptions {
            reply_timeout: Duration::from_millis(1000),
            tries: 8,
            chunk: MAX_CHUNK,
            start_render: None,
        }
    }
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

/// The answers an upload waits for, owned.
enum Answer {
    Ack(u32),
    Nak(u32),
    Done { len: u32, crc: u32 },
}

/// Wait for the RC's answer to an upload message; other messages and malformed frames are
/// skipped (and counted). `None`: nothing in time.
fn answer<P: Read + Write>(
    line: &mut Line<'_, P>,
    dec: &mut Decoder<MAX_TO_PC>,
    report: &mut UploadReport,
    deadline: Instant,
) -> Result<Option<Answer>, HostSerialError> {
    while let Some(b) = line.byte(deadline)? {
        match dec.feed::<ToPc>(b) {
            None => {}
            Some(Err(SerialError::Version { found })) => {
                return Err(HostSerialError::Version { found })
            }
            Some(Err(_)) => report.bad_frames += 1,
            Some(Ok(p)) => match p.msg {
                ToPc::Ack { offset } => return Ok(Some(Answer::Ack(offset))),
                ToPc::Nak { offset } => return Ok(Some(Answer::Nak(offset))),
                ToPc::SceneDone { len, crc } => return Ok(Some(Answer::Done { len, crc })),
                ToPc::Error {
                    code: RcError::Version { found },
                } => return Err(HostSerialError::Version { found }),
                ToPc::Error { code } => return Err(HostSerialError::Rc(code)),
                _ => {}
            },
        }
    }
    Ok(None)
}

/// Send a SceneImage to the RC: `SceneBegin`, then chunks in order, each answered before
/// the next (stop-and-wait; a `Nak` rewinds to its offset, silence resends). `progress`
/// gets the bytes the RC has stored.
pub fn upload<P: Read + Write>(
    port: &mut P,
    name: &str,
    image: &[u8],
    opts: &UploadOptions,
    progress: &dyn Fn(u64),
) -> Result<UploadReport, HostSerialError> {
    let len = u32::try_from(image.len())
        .map_err(|_| HostSerialError::Protocol("scene larger than 4 GiB".into()))?;
    let crc = CRC32.checksum(image);
    let chunk = opts.chunk.clamp(1, MAX_CHUNK);
    let ms = opts.reply_timeout.as_millis() as u64;
    let mut line = Line::new(port, name);
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut report = UploadReport {
        bytes: image.len(),
        ..UploadReport::default()
    };
    // `None`: the SceneBegin is not acknowledged yet; `Some(o)`: send from offset `o`.
    let mut next: Option<u32> = None;
    let mut tries = 0u32;
    loop {
        // Send the current message.
        let sent_end = match next {
            None => {
                line.send(&ToRc::SceneBegin { len, crc })?;
                0
            }
            Some(o) => {
                let end = (o as usize + chunk).min(image.len());
                line.send(&ToRc::SceneChunk {
                    offset: o,
                    data: &image[o as usize..end],
                })?;
                report.chunks_sent += 1;
                end as u32
            }
        };
        tries += 1;
        let deadline = Instant::now() + opts.reply_timeout;
        // Wait for the answer that moves us on (stale ones are skipped).
        let moved = loop {
            match answer(&mut line, &mut dec, &mut report, deadline)? {
                None => {
                    report.timeouts += 1;
                    break false;
                }
                Some(Answer::Ack(a)) if next.is_none() || a >= sent_end => {
                    if a > len {
                        return Err(HostSerialError::Protocol(format!(
                            "the RC acknowledged {a} bytes of a {len}-byte scene"
                        )));
                    }
                    progress(a as u64);
                    next = Some(a);
                    break true;
                }
                Some(Answer::Ack(_)) => {}
                Some(Answer::Nak(a)) => {
                    report.naks += 1;
                    if next.is_some() && a <= len {
                        next = Some(a);
                    }
                    break false;
                }
                Some(Answer::Done { len: l, crc: c }) if next.is_some() => {
                    if (l, c) != (len, crc) {
                        return Err(HostSerialError::Protocol(format!(
                            "the RC stored a scene of {l} bytes, CRC {c:#010x}; sent {len} bytes, CRC {crc:#010x}"
                        )));
                    }
                    progress(len as u64);
                    if let Some(frames) = opts.start_render {
                        line.send(&ToRc::StartRender { frames })?;
                    }
                    return Ok(report);
                }
                Some(Answer::Done { .. }) => {}
            }
        };
        if moved {
            tries = 0;
        } else if tries >= opts.tries {
            let at = next.map_or("the scene header".to_string(), |o| {
                format!("the chunk at byte {o}")
            });
            return Err(if report.timeouts > 0 && report.naks == 0 {
                line.timeout(ms, format!("the RC's answer to {at} ({tries} tries)"))
            } else {
                HostSerialError::Retries {
                    what: format!("the RC kept asking to retransmit {at}"),
                    tries,
                }
            });
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
}

impl Default for ReadbackOptions {
    fn default() -> Self {
        ReadbackOptions {
            timeout: Duration::from_millis(5000),
            resend_rounds: 5,
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

/// Read one frame from the RC: wait for a `FrameHeader`, collect pixels, and at
/// `FrameEnd` (or after a silence) ask for whatever is missing; once whole, check the
/// frame CRC and acknowledge it. A CRC mismatch asks for the whole frame once more before
/// failing.
pub fn readback<P: Read + Write>(
    port: &mut P,
    name: &str,
    opts: &ReadbackOptions,
    progress: &dyn Fn(ReadbackEvent),
) -> Result<Readback, HostSerialError> {
    let ms = opts.timeout.as_millis() as u64;
    let mut line = Line::new(port, name);
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut asm: Option<FrameAssembly> = None;
    let (mut bad_frames, mut resends, mut crc_retry) = (0u32, 0u32, false);
    let mut deadline = Instant::now() + opts.timeout;
    loop {
        let Some(b) = line.byte(deadline)? else {
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
            progress(ReadbackEvent::Resend { pixels: len });
            deadline = Instant::now() + opts.timeout;
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
        deadline = Instant::now() + opts.timeout;
        match packet.msg {
            ToPc::FrameHeader {
                frame,
                width,
                height,
            } => {
                if asm.as_ref().is_none_or(|a| a.frame != frame) {
                    asm = Some(FrameAssembly::new(frame, width, height)?);
                    (resends, crc_retry) = (0, false);
                    progress(ReadbackEvent::Header {
                        frame,
                        width,
                        height,
                    });
                }
            }
            ToPc::Progress { done, total, .. } => {
                progress(ReadbackEvent::Rendering { done, total })
            }
            ToPc::Error {
                code: RcError::Version { found },
            } => return Err(HostSerialError::Version { found }),
            ToPc::Error { code } => return Err(HostSerialError::Rc(code)),
            m @ (ToPc::Pixels { .. } | ToPc::PixelsRle { .. }) => {
                if let Some(a) = &mut asm {
                    if a.put(&m)? {
                        progress(ReadbackEvent::Pixels {
                            have: a.count,
                            total: a.total(),
                        });
                    }
                }
            }
            ToPc::FrameEnd { frame, crc } => {
                let Some(a) = &mut asm else { continue };
                if frame != a.frame {
                    continue;
                }
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
                    progress(ReadbackEvent::Resend { pixels: len });
                    continue;
                }
                let found = CRC32.checksum(&a.rgb);
                if found == crc {
                    line.send(&ToRc::FrameAck { frame })?;
                    let a = asm.take().expect("checked above");
                    return Ok(Readback {
                        frame,
                        width: a.width as u32,
                        height: a.height as u32,
                        rgb: a.rgb,
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
                progress(ReadbackEvent::Resend { pixels: len });
            }
            ToPc::Ack { .. } | ToPc::Nak { .. } | ToPc::SceneDone { .. } => {}
        }
    }
}
