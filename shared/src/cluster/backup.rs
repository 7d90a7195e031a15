//! The serial backup line: LINKS-1's SDLC line from the RC to every NC, as a half-duplex
//! multi-drop UART (RS-485). The RC is the only master; a node speaks only when addressed,
//! once, right after the RC's frame. The line carries roll call and node health, and is the
//! slow fallback that still delivers a scene, work and pixels to a node whose SPI link failed.
//!
//! ## Frame layout
//! ```text
//! SYNC (0x7E) | addr | len | body (len bytes, postcard(Msg)) | CRC-32 (LE, over addr..body)
//! ```
//! `addr` is the node a RC frame is for (1..=[`MAX_ADDR`], or [`BROADCAST`]) or, in a reply,
//! the node that sends it. The message type is the body's first byte (the [`Msg`] variant
//! index). Length-prefixed with a sync byte (no stuffing): a receiver that loses a frame
//! hunts for the next sync byte; a false sync inside a body fails the CRC and the hunt goes
//! on. The CRC is the bus's ([`wire::CRC32`]). Decoding borrows payloads from the received
//! bytes; nothing allocates.
//!
//! ## Conversations
//! - Roll call: [`Msg::RollCall`] to each address in turn; a live node answers
//!   [`Msg::Health`]; no answer within the line's reply timeout = absent ([`RollCall`]).
//! - Scene: [`Msg::Scene`] chunks of at most [`SCENE_DATA`] bytes, addressed (answered
//!   with [`Msg::Ack`]) or broadcast (never answered); a node reports the contiguous bytes it
//!   holds in its health, so the RC resumes from there.
//! - Work: [`Msg::Work`] hands a node one job (answered with [`Msg::Ack`]); [`Msg::Poll`]
//!   asks for its pixels: the node answers with the next [`Msg::Pixels`] chunk (run-length
//!   coded, at most [`PIXEL_DATA`] bytes) or [`Msg::Idle`]. A poll acknowledges the chunks
//!   the RC accepted (`ack`, the next sequence number it expects); a node re-sends an
//!   unacknowledged chunk (stop-and-wait).

use crate::cluster::wire::{self, Job, CRC32, MAX_RUN};
use core::fmt;
use serde::{Deserialize, Serialize};

/// First byte of every frame.
pub const SYNC: u8 = 0x7E;
/// Address of a frame every node takes and none answers.
pub const BROADCAST: u8 = 0xFF;
/// Highest node address (nodes are 1..=MAX_ADDR).
pub const MAX_ADDR: u8 = 64;
/// Largest body (the length byte).
pub const MAX_BODY: usize = 255;
/// Bytes of a frame besides its body: sync, address, length, CRC-32.
pub const FRAME_OVERHEAD: usize = 3 + wire::CRC_LEN;
/// Largest frame on the line.
pub const MAX_FRAME: usize = MAX_BODY + FRAME_OVERHEAD;
/// Run-length bytes in one [`Msg::Pixels`] (56 quadruples; the rest of the body is at most
/// 24 bytes of fields).
pub const PIXEL_DATA: usize = 224;
/// Scene bytes in one [`Msg::Scene`] (the fields take at most 22 bytes).
pub const SCENE_DATA: usize = 224;
/// Firmware identification a node reports: protocol 1 of the backup line, wire protocol
/// [`wire::PROTOCOL_VERSION`].
pub const FIRMWARE_ID: u32 = 0x4C31_0100 | wire::PROTOCOL_VERSION as u32;

/// A node's health, its answer to a roll call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Health {
    /// The frame of the scene it holds (or is receiving).
    pub frame: u16,
    /// Contiguous scene bytes it holds from offset 0, and whether the scene is complete
    /// and CRC-checked.
    pub scene_bytes: u32,
    pub scene_ok: bool,
    /// Jobs it finished (all of whose pixels were acknowledged) over this line.
    pub jobs_done: u32,
    /// Frames it received that failed to decode.
    pub errors: u32,
    /// [`FIRMWARE_ID`] of its firmware.
    pub firmware: u32,
}

/// Every message on the backup line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Msg<'a> {
    /// RC: "who is there?" Answered with [`Msg::Health`].
    RollCall,
    /// Node: its health.
    Health(Health),
    /// RC: a piece of frame `frame`'s scene image (`total` bytes, CRC-32 `crc`) at `offset`.
    Scene {
        frame: u16,
        offset: u32,
        total: u32,
        crc: u32,
        #[serde(borrow)]
        data: &'a [u8],
    },
    /// RC: render this job (it replaces a job the node holds). Answered with [`Msg::Ack`].
    Work { job: Job },
    /// RC: send your next pixels; `ack` is the sequence number of the next chunk the RC
    /// expects (every earlier one is accepted).
    Poll { ack: u16 },
    /// Node: nothing to send now (rendering, or no job).
    Idle,
    /// Node: `len` pixels of scanline `y` from column `x` of job `job`, run-length coded as
    /// [`wire::rle_encode`]; `done` marks the job's last chunk.
    Pixels {
        seq: u16,
        job: u32,
        frame: u16,
        y: u16,
        x: u16,
        len: u16,
        done: bool,
        #[serde(borrow)]
        rle: &'a [u8],
    },
    /// Node: an addressed RC frame was taken.
    Ack,
}

/// Why bytes are not a valid backup-line frame, or a frame could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BackupError {
    /// No sync byte where a frame starts.
    NoSync,
    /// Fewer bytes than the frame's length byte announces.
    Truncated,
    /// The CRC does not match.
    BadCrc,
    /// CRC fine, but the body is not a message (or has bytes after it).
    Malformed,
    /// The message does not fit a frame or the buffer.
    TooLong,
    /// An address outside 1..=MAX_ADDR (or broadcast for an RC frame).
    BadAddress { addr: u8 },
}

impl fmt::Display for BackupError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            BackupError::NoSync => write!(f, "backup frame does not start with the sync byte"),
            BackupError::Truncated => write!(f, "backup frame is shorter than its length"),
            BackupError::BadCrc => write!(f, "backup frame failed its CRC check"),
            BackupError::Malformed => write!(f, "backup frame holds no valid message"),
            BackupError::TooLong => write!(f, "backup message does not fit a frame"),
            BackupError::BadAddress { addr } => {
                write!(
                    f,
                    "backup frame address {addr} is not a node (1..={MAX_ADDR})"
                )
            }
        }
    }
}

impl core::error::Error for BackupError {}

/// Whether `addr` may head a frame: a node, or (RC frames only) [`BROADCAST`].
fn address_ok(addr: u8) -> bool {
    (1..=MAX_ADDR).contains(&addr) || addr == BROADCAST
}

/// Encode `msg` for (RC) or from (node) `addr` into `buf`; returns the frame's length.
pub fn encode(addr: u8, msg: &Msg<'_>, buf: &mut [u8]) -> Result<usize, BackupError> {
    if !address_ok(addr) {
        return Err(BackupError::BadAddress { addr });
    }
    let room = buf.len().min(MAX_FRAME);
    if room < FRAME_OVERHEAD {
        return Err(BackupError::TooLong);
    }
    let body_room = (room - FRAME_OVERHEAD).min(MAX_BODY);
    let n = postcard::to_slice(msg, &mut buf[3..3 + body_room])
        .map_err(|_| BackupError::TooLong)?
        .len();
    buf[0] = SYNC;
    buf[1] = addr;
    buf[2] = n as u8; // n <= MAX_BODY = 255
    let crc = CRC32.checksum(&buf[1..3 + n]);
    buf[3 + n..3 + n + wire::CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    Ok(n + FRAME_OVERHEAD)
}

/// Length of the frame starting at `bytes[0]`, once its length byte is in (`None` before).
pub fn frame_len(bytes: &[u8]) -> Option<usize> {
    bytes.get(2).map(|&n| n as usize + FRAME_OVERHEAD)
}

/// Decode one whole frame: its address and message (borrowing from `bytes`).
pub fn decode(bytes: &[u8]) -> Result<(u8, Msg<'_>), BackupError> {
    if bytes.first() != Some(&SYNC) {
        return Err(BackupError::NoSync);
    }
    let len = frame_len(bytes).ok_or(BackupError::Truncated)?;
    let frame = bytes.get(..len).ok_or(BackupError::Truncated)?;
    let (covered, tail) = frame.split_at(len - wire::CRC_LEN);
    let want = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
    if CRC32.checksum(&covered[1..]) != want {
        return Err(BackupError::BadCrc);
    }
    let addr = covered[1];
    if !address_ok(addr) {
        return Err(BackupError::BadAddress { addr });
    }
    match postcard::take_from_bytes::<Msg<'_>>(&covered[3..]) {
        Ok((msg, [])) => Ok((addr, msg)),
        _ => Err(BackupError::Malformed),
    }
}

/// Assembles frames from the bytes a UART receives, one at a time: hunts for [`SYNC`],
/// reads the length, collects the frame. No heap: one frame's buffer.
pub struct FrameReader {
    buf: [u8; MAX_FRAME],
    have: usize,
}

impl Default for FrameReader {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameReader {
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME],
            have: 0,
        }
    }

    /// Take one byte; returns the length of a complete frame now in [`FrameReader::frame`]
    /// (check it with [`decode`]). The next byte starts a new hunt.
    pub fn push(&mut self, b: u8) -> Option<usize> {
        if self.have == 0 && b != SYNC {
            return None;
        }
        // have < MAX_FRAME: a full frame is returned below and `have` reset.
        self.buf[self.have] = b;
        self.have += 1;
        let len = frame_len(&self.buf[..self.have])?;
        if self.have < len {
            return None;
        }
        self.have = 0;
        Some(len)
    }

    /// The last complete frame (the first `len` bytes [`FrameReader::push`] returned).
    pub fn frame(&self, len: usize) -> &[u8] {
        &self.buf[..len.min(MAX_FRAME)]
    }

    /// Drop a partial frame (a reply timeout, the line turned around).
    pub fn reset(&mut self) {
        self.have = 0;
    }
}

/// Run-length code (as [`wire::rle_encode`]) as many whole pixels of `rgb` as fit `out`;
/// returns (pixels taken, bytes written). Each chunk decodes on its own.
pub fn rle_chunk(rgb: &[u8], out: &mut [u8]) -> (usize, usize) {
    let mut taken = 0;
    let mut n = 0;
    let mut px = rgb.chunks_exact(3).peekable();
    while let Some(p) = px.next() {
        let Some(q) = out.get_mut(n..n + 4) else {
            break;
        };
        let mut count = 1usize;
        while count < 256 && px.peek() == Some(&p) {
            px.next();
            count += 1;
        }
        q[0] = (count - 1) as u8;
        q[1..4].copy_from_slice(p);
        n += 4;
        taken += count;
    }
    (taken, n)
}

pub mod line;
mod node;
pub mod rc;
mod render;
mod rollcall;
pub use line::{call_roll, serve, serve_with, LineError, LinePort};
pub use node::{BackupNode, NodeScene};
pub use rc::{
    serve_root, BackupRc, BackupWork, NoLine, PortLine, RcCounters, RcLine, RootWork, ServeConfig,
    Turn,
};
pub use render::{BackupRender, BackupRenderError, Piece};
pub use rollcall::{RollCall, RollCallStep};

/// Most pixels a node holds for the line at once (one scanline piece).
pub const OUTBOX_PIXELS: usize = MAX_RUN;

#[cfg(test)]
mod tests;
