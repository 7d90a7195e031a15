//! Why an upload or a readback failed: one error type for both directions of the link.

use links_core::serial::{RcError, MAX_DIM};
use std::fmt;

/// Why an upload or readback failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HostSerialError {
    /// No such port (nothing plugged in, or a wrong name).
    PortMissing { port: String },
    /// Film frame `frame` failed (upload or readback) for `error`.
    Film {
        frame: u32,
        error: Box<HostSerialError>,
    },
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
            HostSerialError::Film { frame, error } => write!(f, "film frame {frame}: {error}"),
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
