//! The byte stream under both directions of the link: opening a serial port, the clock the
//! waits run on (the system's, or a virtual one in tests), and [`Line`], a port with
//! deadlines and the encoder for the PC's messages.
//!
//! Both directions wait with deadlines, never forever: a port's read returns after its own
//! short time-out, and every wait here has an overall one.

use super::HostSerialError;
use links_core::serial::{Encoder, ToPc, ToRc, MAX_TO_RC};
use std::cell::Cell;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

/// Baud rate when none is given (a USB CDC port ignores it; a UART needs it).
pub const DEFAULT_BAUD: u32 = 115_200;

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
pub(super) struct Line<'p, P> {
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
    pub(super) fn new(
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

    pub(super) fn io(&self, e: std::io::Error) -> HostSerialError {
        HostSerialError::Io {
            port: self.name.into(),
            reason: e.to_string(),
        }
    }

    pub(super) fn timeout(&self, ms: u64, waiting_for: impl Into<String>) -> HostSerialError {
        HostSerialError::Timeout {
            port: self.name.into(),
            ms,
            waiting_for: waiting_for.into(),
        }
    }

    /// The time on the line's clock `d` from now.
    pub(super) fn after(&self, d: Duration) -> Duration {
        self.clock.now().saturating_add(d)
    }

    /// Whether the overall deadline has passed.
    pub(super) fn overdue(&self) -> bool {
        self.overall.is_some_and(|(at, _)| self.clock.now() >= at)
    }

    /// The error for the overall deadline, saying how far the job got.
    pub(super) fn deadline_error(&self, doing: String) -> HostSerialError {
        HostSerialError::Deadline {
            port: self.name.into(),
            ms: self.overall.map_or(0, |(_, ms)| ms),
            doing,
        }
    }

    /// The next byte, or `None` once `deadline` (on the line's clock) or the overall
    /// deadline ([`Line::overdue`]) has passed. Both are checked before every read of the
    /// port, so a flood of bytes does not hide them.
    pub(super) fn byte(&mut self, deadline: Duration) -> Result<Option<u8>, HostSerialError> {
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

    pub(super) fn send(&mut self, msg: &ToRc<'_>) -> Result<(), HostSerialError> {
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

/// The name of a message's kind, for error messages.
pub(super) fn kind(msg: &ToPc<'_>) -> &'static str {
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
        ToPc::FrameStarted { .. } => "FrameStarted",
    }
}
