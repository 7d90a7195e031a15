//! The PC <-> RC serial protocol (USB CDC or a UART): scene upload and frame readback.
//!
//! See `docs/serial.md` for the message table and the rules; this is the code.
//!
//! ## Framing
//! ```text
//! 0x00 ++ COBS( postcard(Packet { version, seq, msg }) ++ CRC-32 (4 bytes LE) ) ++ 0x00
//! ```
//! Each frame starts and ends with a zero byte, and COBS removes every zero from the bytes
//! in between, so a receiver that lost its place (garbage, a cut cable, a frame that
//! overflowed its buffer) is back in step at the next zero: at most the frame being
//! received is lost. The CRC is [`crate::wire::CRC32`], as on the cluster bus. The first
//! byte of every packet is [`VERSION`], checked right after the CRC and before the message,
//! so a version mismatch is reported as such and not as garbage.
//!
//! ## Pieces
//! - [`Encoder`]: writes frames into caller buffers and numbers them (`seq`).
//! - [`Decoder`]: takes a byte at a time into a fixed buffer (a `heapless::Vec`) and yields
//!   each frame's [`Packet`], which borrows its payload from that buffer.
//! - [`UploadReceiver`]: the RC side of a scene upload: assembles the SceneImage in a
//!   caller buffer, acknowledges progress and asks for retransmission of bad or lost chunks.
//! - [`FrameStreamer`]: the RC side of readback: turns rows of pixels into messages and
//!   keeps the frame's CRC ([`FrameCrc`]) in whatever order the rows come.
//!
//! Nothing here panics or allocates on any input; every failure is a [`SerialError`].

use crate::wire::{rle_decode, rle_encode, CRC32, CRC_LEN};
use core::fmt;
use postcard::ser_flavors::{crc::CrcModifier, Cobs, Slice};
use serde::{Deserialize, Serialize};

/// Protocol version, the first byte of every packet.
pub const VERSION: u8 = 1;
/// Most scene bytes in one [`ToRc::SceneChunk`].
pub const MAX_CHUNK: usize = 512;
/// Most pixels in one [`ToPc::Pixels`] / [`ToPc::PixelsRle`] message.
pub const MAX_RUN: usize = 256;
/// Largest frame width or height (LINKS-1's 1024 x 1024 frame memory).
pub const MAX_DIM: u16 = 1024;

/// Bytes a frame takes on the line for a packet body (postcard + CRC) of `body` bytes:
/// COBS adds one byte per 254 and one more, plus the two zero delimiters.
pub const fn framed_len(body: usize) -> usize {
    body + body / 254 + 1 + 2
}

/// Upper bound of a PC -> RC frame on the line (a full scene chunk). An RC's [`Decoder`]
/// needs this capacity.
pub const MAX_TO_RC: usize = framed_len(MAX_CHUNK + 24);
/// Upper bound of an RC -> PC frame on the line (a full pixel run). A PC's [`Decoder`] and
/// the RC's transmit buffer need this capacity.
pub const MAX_TO_PC: usize = framed_len(3 * MAX_RUN + 24);

/// One frame's contents: the header and a message ([`ToRc`] or [`ToPc`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Packet<M> {
    /// [`VERSION`] of the sender.
    pub version: u8,
    /// The sender's frame number (wrapping), one more per frame: a gap tells the receiver
    /// that frames were lost.
    pub seq: u16,
    pub msg: M,
}

/// PC -> RC messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ToRc<'a> {
    /// Start (or restart) a scene upload of `len` bytes whose CRC-32 is `crc`. Answered by
    /// [`ToPc::Ack`] or [`ToPc::Error`].
    SceneBegin { len: u32, crc: u32 },
    /// Scene bytes at `offset` (1..=[`MAX_CHUNK`] of them). Answered by [`ToPc::Ack`],
    /// [`ToPc::Nak`] (resend from its offset), [`ToPc::SceneDone`] or [`ToPc::Error`].
    SceneChunk { offset: u32, data: &'a [u8] },
    /// Render `frames` frames of the uploaded scene and stream them back.
    StartRender { frames: u16 },
    /// Readback: send pixels `start .. start + len` (raster order) of `frame` again, then
    /// [`ToPc::FrameEnd`] again (`len` = 0 asks for the `FrameEnd` only).
    Resend { frame: u16, start: u32, len: u32 },
    /// Readback: `frame` arrived whole and passed its CRC.
    FrameAck { frame: u16 },
}

/// RC -> PC messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ToPc<'a> {
    /// Upload: the first `offset` bytes of the scene are stored; send from there.
    Ack { offset: u32 },
    /// Upload: a frame was malformed, or a chunk did not start where expected: send again
    /// from `offset`.
    Nak { offset: u32 },
    /// Upload: all `len` bytes arrived and their CRC-32 is `crc` (the one announced).
    SceneDone { len: u32, crc: u32 },
    /// Readback: a frame of `width` x `height` RGB8 pixels begins.
    FrameHeader { frame: u16, width: u16, height: u16 },
    /// Readback: `rgb` holds RGB8 triples of row `y` from column `x`.
    Pixels {
        frame: u16,
        y: u16,
        x: u16,
        rgb: &'a [u8],
    },
    /// As [`ToPc::Pixels`], `len` pixels run-length coded as by [`crate::wire::rle_encode`].
    PixelsRle {
        frame: u16,
        y: u16,
        x: u16,
        len: u16,
        data: &'a [u8],
    },
    /// Readback: every pixel of `frame` has been sent; `crc` is the CRC-32 of the whole
    /// frame (rows top first, RGB8).
    FrameEnd { frame: u16, crc: u32 },
    /// Rendering progress: `done` of `total` pixels of `frame` finished.
    Progress { frame: u16, done: u32, total: u32 },
    /// The RC refused a request.
    Error { code: RcError },
}

/// Why the RC refused a request (sent in [`ToPc::Error`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RcError {
    /// The scene is larger than the RC's scene buffer.
    SceneTooLarge { len: u32, max: u32 },
    /// An upload of zero bytes.
    EmptyScene,
    /// Every byte arrived but the CRC-32 of the whole scene differs from the announced one;
    /// the upload starts over.
    SceneCrc { expected: u32, found: u32 },
    /// A chunk arrived with no upload in progress.
    NotUploading,
    /// The RC received a packet of another protocol version.
    Version { found: u8 },
    /// A render was asked for before a scene was uploaded.
    NoScene,
}

impl fmt::Display for RcError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            RcError::SceneTooLarge { len, max } => write!(
                f,
                "scene of {len} bytes does not fit the RC's {max}-byte scene buffer"
            ),
            RcError::EmptyScene => write!(f, "empty scene"),
            RcError::SceneCrc { expected, found } => write!(
                f,
                "scene CRC mismatch after upload (announced {expected:#010x}, received {found:#010x})"
            ),
            RcError::NotUploading => write!(f, "scene chunk without a SceneBegin"),
            RcError::Version { found } => write!(
                f,
                "the RC received protocol version {found} (it speaks {VERSION})"
            ),
            RcError::NoScene => write!(f, "no scene uploaded"),
        }
    }
}

impl core::error::Error for RcError {}

/// Why bytes are not a valid frame, or a request cannot be served.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SerialError {
    /// The COBS stuffing is broken (a length byte points past the end of the frame).
    Cobs,
    /// Shorter than a CRC plus a version byte (a truncated frame).
    Truncated,
    /// The CRC does not match.
    BadCrc,
    /// A packet of another protocol version.
    Version { found: u8 },
    /// CRC fine but the contents are no message of this protocol.
    Malformed,
    /// The frame was longer than the receiver's buffer; it was skipped.
    Oversize,
    /// The output buffer is too small for the frame.
    BufferFull,
    /// A request outside the limits (pixels outside the frame, a run longer than
    /// [`MAX_RUN`], a frame larger than [`MAX_DIM`], a chunk longer than [`MAX_CHUNK`]).
    OutOfRange,
    /// A frame ended with pixels missing or counted twice (`folded` of `expected` pixels).
    Incomplete { folded: u32, expected: u32 },
}

impl fmt::Display for SerialError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            SerialError::Cobs => write!(f, "frame has broken COBS stuffing"),
            SerialError::Truncated => write!(f, "frame too short (truncated)"),
            SerialError::BadCrc => write!(f, "frame failed its CRC check"),
            SerialError::Version { found } => write!(
                f,
                "protocol version mismatch: received version {found}, expected {VERSION}"
            ),
            SerialError::Malformed => write!(f, "frame holds no valid message"),
            SerialError::Oversize => write!(f, "frame longer than the receive buffer"),
            SerialError::BufferFull => write!(f, "frame does not fit the output buffer"),
            SerialError::OutOfRange => write!(f, "request outside the protocol's limits"),
            SerialError::Incomplete { folded, expected } => {
                write!(f, "frame ended with {folded} of {expected} pixels sent")
            }
        }
    }
}

impl core::error::Error for SerialError {}

/// Encode one packet into `out` as a complete frame (both delimiters); returns its length.
pub fn encode_packet<M: Serialize>(
    seq: u16,
    msg: &M,
    out: &mut [u8],
) -> Result<usize, SerialError> {
    let (first, rest) = out.split_first_mut().ok_or(SerialError::BufferFull)?;
    *first = 0;
    let packet = Packet {
        version: VERSION,
        seq,
        msg,
    };
    let cobs = Cobs::try_new(Slice::new(rest)).map_err(|_| SerialError::BufferFull)?;
    // CRC innermost: the CRC covers the postcard bytes and is stuffed with them.
    let used = postcard::serialize_with_flavor(&packet, CrcModifier::new(cobs, CRC32.digest()))
        .map_err(|_| SerialError::BufferFull)?;
    Ok(1 + used.len())
}

/// Decode a packet body (COBS already removed: postcard bytes ++ CRC-32), checking CRC and
/// version. The message borrows from `body`.
pub fn decode_body<'a, M: Deserialize<'a>>(body: &'a [u8]) -> Result<Packet<M>, SerialError> {
    if body.len() < CRC_LEN + 1 {
        return Err(SerialError::Truncated);
    }
    let (data, tail) = body.split_at(body.len() - CRC_LEN);
    let want = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
    if CRC32.checksum(data) != want {
        return Err(SerialError::BadCrc);
    }
    match data.first() {
        Some(&VERSION) => {}
        Some(&found) => return Err(SerialError::Version { found }),
        None => return Err(SerialError::Truncated),
    }
    let (packet, rest): (Packet<M>, &[u8]) =
        postcard::take_from_bytes(data).map_err(|_| SerialError::Malformed)?;
    if rest.is_empty() {
        Ok(packet)
    } else {
        Err(SerialError::Malformed)
    }
}

/// Numbers outgoing frames and writes them into caller buffers. One per direction of a
/// link (the RC's upload receiver and frame streamer share the RC's).
#[derive(Clone, Debug, Default)]
pub struct Encoder {
    seq: u16,
}

impl Encoder {
    pub const fn new() -> Self {
        Encoder { seq: 0 }
    }

    /// The sequence number the next frame will carry.
    pub fn next_seq(&self) -> u16 {
        self.seq
    }

    /// Encode `msg` ([`ToRc`] or [`ToPc`]) as a frame into `out`; returns its length. The
    /// sequence number advances only when the frame fits.
    pub fn encode<M: Serialize>(&mut self, msg: &M, out: &mut [u8]) -> Result<usize, SerialError> {
        let n = encode_packet(self.seq, msg, out)?;
        self.seq = self.seq.wrapping_add(1);
        Ok(n)
    }
}

/// Streaming frame decoder with room for `N` line bytes between delimiters (use
/// [`MAX_TO_RC`] on the RC, [`MAX_TO_PC`] on the PC).
pub struct Decoder<const N: usize> {
    buf: heapless::Vec<u8, N>,
    overflow: bool,
    /// The buffer holds the frame returned last; clear before the next byte.
    stale: bool,
    good: u32,
    bad: u32,
}

impl<const N: usize> Default for Decoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Decoder<N> {
    pub const fn new() -> Self {
        Decoder {
            buf: heapless::Vec::new(),
            overflow: false,
            stale: false,
            good: 0,
            bad: 0,
        }
    }

    /// Take one byte from the line. Returns `Some` when the byte ends a frame: the packet
    /// (borrowing from the decoder until the next call) or why the frame was bad. Empty
    /// frames (two delimiters in a row) return `None`. A frame longer than `N` is skipped
    /// up to the next delimiter and reported as [`SerialError::Oversize`].
    pub fn feed<'a, M: Deserialize<'a>>(
        &'a mut self,
        byte: u8,
    ) -> Option<Result<Packet<M>, SerialError>> {
        if self.stale {
            self.buf.clear();
            self.stale = false;
        }
        if byte != 0 {
            if !self.overflow && self.buf.push(byte).is_err() {
                self.overflow = true;
            }
            return None;
        }
        self.stale = true;
        if self.overflow {
            self.overflow = false;
            self.bad = self.bad.wrapping_add(1);
            return Some(Err(SerialError::Oversize));
        }
        if self.buf.is_empty() {
            return None;
        }
        let result = match cobs::decode_in_place(&mut self.buf) {
            Ok(n) => decode_body(self.buf.get(..n).unwrap_or(&[])),
            Err(_) => Err(SerialError::Cobs),
        };
        match result {
            Ok(_) => self.good = self.good.wrapping_add(1),
            Err(_) => self.bad = self.bad.wrapping_add(1),
        }
        Some(result)
    }

    /// Forget a partly received frame (e.g. after a line reset).
    pub fn reset(&mut self) {
        self.buf.clear();
        self.overflow = false;
        self.stale = false;
    }

    /// Frames decoded so far.
    pub fn good_frames(&self) -> u32 {
        self.good
    }

    /// Malformed frames seen so far (bad CRC, stuffing, version, layout, oversize).
    pub fn bad_frames(&self) -> u32 {
        self.bad
    }
}

/// What an [`UploadReceiver`] step did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UploadEvent {
    /// The message was not about uploads (the caller handles it).
    Ignored,
    /// An upload of `len` bytes began.
    Started { len: u32 },
    /// `received` bytes are stored (in order from 0).
    Progress { received: u32 },
    /// The scene is complete and CRC-checked: [`UploadReceiver::image`] has it. The RC
    /// broadcasts it to the nodes now.
    Complete { len: u32 },
    /// The upload was refused or failed (the reply says why); the receiver is idle.
    Failed(RcError),
    /// A malformed frame was answered with a [`ToPc::Nak`].
    Nak { offset: u32 },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum UploadState {
    Idle,
    Receiving { len: u32, crc: u32 },
    Done { len: u32, crc: u32 },
}

/// The RC side of a scene upload: stores chunks in order into a caller buffer and answers
/// each frame with one reply (`Ack`, `Nak`, `SceneDone` or `Error`), go-back-N style: a
/// chunk that does not start where the stored bytes end is answered with a `Nak` naming
/// that offset, and so is a malformed frame.
pub struct UploadReceiver<'b> {
    buf: &'b mut [u8],
    state: UploadState,
    received: u32,
    naks: u32,
}

/// A reply frame written into the caller's buffer (`len` bytes; 0 = nothing to send) and
/// what happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reply {
    pub len: usize,
    pub event: UploadEvent,
}

impl<'b> UploadReceiver<'b> {
    /// A receiver storing scenes of up to `buf.len()` bytes.
    pub fn new(buf: &'b mut [u8]) -> Self {
        UploadReceiver {
            buf,
            state: UploadState::Idle,
            received: 0,
            naks: 0,
        }
    }

    /// The uploaded scene, once complete and CRC-checked.
    pub fn image(&self) -> Option<&[u8]> {
        match self.state {
            UploadState::Done { len, .. } => self.buf.get(..len as usize),
            _ => None,
        }
    }

    /// Bytes stored so far in the current upload.
    pub fn received(&self) -> u32 {
        self.received
    }

    /// `Nak`s sent so far (malformed frames and out-of-order chunks).
    pub fn naks(&self) -> u32 {
        self.naks
    }

    /// Handle a decoded PC -> RC message; the reply frame goes into `out`.
    pub fn on_message(
        &mut self,
        msg: &ToRc<'_>,
        enc: &mut Encoder,
        out: &mut [u8],
    ) -> Result<Reply, SerialError> {
        let (reply, event) = match *msg {
            ToRc::SceneBegin { len, crc } => self.begin(len, crc),
            ToRc::SceneChunk { offset, data } => self.chunk(offset, data),
            _ => {
                return Ok(Reply {
                    len: 0,
                    event: UploadEvent::Ignored,
                })
            }
        };
        let len = enc.encode(&reply, out)?;
        Ok(Reply { len, event })
    }

    /// Handle a frame the [`Decoder`] rejected: answered with a `Nak` from the stored
    /// length (or an `Error` naming the version, for a version mismatch).
    pub fn on_bad_frame(
        &mut self,
        err: SerialError,
        enc: &mut Encoder,
        out: &mut [u8],
    ) -> Result<Reply, SerialError> {
        let (reply, event) = match err {
            SerialError::Version { found } => {
                let code = RcError::Version { found };
                (ToPc::Error { code }, UploadEvent::Failed(code))
            }
            _ => self.nak(),
        };
        let len = enc.encode(&reply, out)?;
        Ok(Reply { len, event })
    }

    fn nak(&mut self) -> (ToPc<'static>, UploadEvent) {
        self.naks = self.naks.wrapping_add(1);
        let offset = self.received;
        (ToPc::Nak { offset }, UploadEvent::Nak { offset })
    }

    fn fail(&mut self, code: RcError) -> (ToPc<'static>, UploadEvent) {
        self.state = UploadState::Idle;
        self.received = 0;
        (ToPc::Error { code }, UploadEvent::Failed(code))
    }

    fn begin(&mut self, len: u32, crc: u32) -> (ToPc<'static>, UploadEvent) {
        if len == 0 {
            return self.fail(RcError::EmptyScene);
        }
        let max = u32::try_from(self.buf.len()).unwrap_or(u32::MAX);
        if len > max {
            return self.fail(RcError::SceneTooLarge { len, max });
        }
        if self.state == (UploadState::Receiving { len, crc }) {
            // A repeated SceneBegin (our Ack was lost): keep what is stored.
            let offset = self.received;
            return (
                ToPc::Ack { offset },
                UploadEvent::Progress { received: offset },
            );
        }
        self.state = UploadState::Receiving { len, crc };
        self.received = 0;
        (ToPc::Ack { offset: 0 }, UploadEvent::Started { len })
    }

    fn chunk(&mut self, offset: u32, data: &[u8]) -> (ToPc<'static>, UploadEvent) {
        let (len, crc) = match self.state {
            UploadState::Idle => return self.fail(RcError::NotUploading),
            // A repeated last chunk (our SceneDone was lost): say it again.
            UploadState::Done { len, crc } => {
                return (ToPc::SceneDone { len, crc }, UploadEvent::Complete { len })
            }
            UploadState::Receiving { len, crc } => (len, crc),
        };
        let end = offset as u64 + data.len() as u64;
        if data.is_empty() || data.len() > MAX_CHUNK || end > len as u64 || offset > self.received {
            return self.nak();
        }
        let Some(dst) = self.buf.get_mut(offset as usize..end as usize) else {
            return self.nak();
        };
        dst.copy_from_slice(data);
        self.received = self.received.max(end as u32);
        if self.received < len {
            let offset = self.received;
            return (
                ToPc::Ack { offset },
                UploadEvent::Progress { received: offset },
            );
        }
        let found = CRC32.checksum(self.buf.get(..len as usize).unwrap_or(&[]));
        if found != crc {
            return self.fail(RcError::SceneCrc {
                expected: crc,
                found,
            });
        }
        self.state = UploadState::Done { len, crc };
        (ToPc::SceneDone { len, crc }, UploadEvent::Complete { len })
    }
}

/// CRC-32 register without initial value or final xor: linear over GF(2), so the CRC of a
/// frame can be assembled from its runs in any order.
const CRC32_RAW: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::Algorithm {
    width: 32,
    poly: 0x04c1_1db7,
    init: 0,
    refin: true,
    refout: true,
    xorout: 0,
    check: 0x2dfd_2d88,
    residue: 0,
});

/// The reflected CRC-32 polynomial.
const POLY_REFLECTED: u32 = 0xedb8_8320;

/// a · b mod P in the reflected representation (bit 31 = x^0).
fn gf2_mul(a: u32, mut b: u32) -> u32 {
    let mut product = 0;
    let mut bit = 1u32 << 31;
    while bit != 0 {
        if a & bit != 0 {
            product ^= b;
        }
        b = if b & 1 != 0 {
            (b >> 1) ^ POLY_REFLECTED
        } else {
            b >> 1
        };
        bit >>= 1;
    }
    product
}

/// The CRC register `reg` after `n` more zero bytes: reg · x^(8n) mod P.
fn shift_zeros(reg: u32, mut n: u64) -> u32 {
    // x^8 in the reflected representation.
    let mut power = 1u32 << (31 - 8);
    let mut result = reg;
    while n != 0 {
        if n & 1 != 0 {
            result = gf2_mul(result, power);
        }
        power = gf2_mul(power, power);
        n >>= 1;
    }
    result
}

/// The CRC-32 ([`CRC32`]) of a byte string of known length built from pieces added in any
/// order: the RC folds in pixel runs as nodes return them and still announces the CRC of
/// the whole frame in raster order. Each byte must be added exactly once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameCrc {
    len: u64,
    acc: u32,
}

impl FrameCrc {
    /// For a string of `len` bytes.
    pub const fn new(len: u64) -> Self {
        FrameCrc { len, acc: 0 }
    }

    /// Add the bytes `data` found at `offset`. Pieces past the end are refused.
    pub fn add(&mut self, offset: u64, data: &[u8]) -> Result<(), SerialError> {
        let end = offset
            .checked_add(data.len() as u64)
            .filter(|&e| e <= self.len)
            .ok_or(SerialError::OutOfRange)?;
        self.acc ^= shift_zeros(CRC32_RAW.checksum(data), self.len - end);
        Ok(())
    }

    /// The CRC-32 of the whole string (as `CRC32.checksum(whole)` once every byte is in).
    pub fn value(&self) -> u32 {
        // The initial all-ones register travels through every byte; the final xor.
        self.acc ^ shift_zeros(0xffff_ffff, self.len) ^ 0xffff_ffff
    }
}

/// The RC side of readback: one frame's messages. Rows (or shorter runs) may be given in
/// any order; each pixel exactly once through [`FrameStreamer::run`], so that
/// [`FrameStreamer::end`] can announce the CRC of the whole frame. Answers to
/// [`ToRc::Resend`] go through [`FrameStreamer::resend`], which does not count again.
#[derive(Clone, Debug)]
pub struct FrameStreamer {
    frame: u16,
    width: u16,
    height: u16,
    crc: FrameCrc,
    folded: u32,
}

impl FrameStreamer {
    /// A frame of `width` x `height` pixels (each 1..=[`MAX_DIM`]).
    pub fn new(frame: u16, width: u16, height: u16) -> Result<Self, SerialError> {
        if !(1..=MAX_DIM).contains(&width) || !(1..=MAX_DIM).contains(&height) {
            return Err(SerialError::OutOfRange);
        }
        Ok(FrameStreamer {
            frame,
            width,
            height,
            crc: FrameCrc::new(3 * width as u64 * height as u64),
            folded: 0,
        })
    }

    pub fn frame(&self) -> u16 {
        self.frame
    }

    pub fn width(&self) -> u16 {
        self.width
    }

    pub fn height(&self) -> u16 {
        self.height
    }

    /// Pixels counted so far.
    pub fn folded(&self) -> u32 {
        self.folded
    }

    /// The [`ToPc::FrameHeader`] frame.
    pub fn header(&self, enc: &mut Encoder, out: &mut [u8]) -> Result<usize, SerialError> {
        enc.encode(
            &ToPc::FrameHeader {
                frame: self.frame,
                width: self.width,
                height: self.height,
            },
            out,
        )
    }

    /// A [`ToPc::Progress`] frame (`done` pixels of the frame finished).
    pub fn progress(
        &self,
        done: u32,
        enc: &mut Encoder,
        out: &mut [u8],
    ) -> Result<usize, SerialError> {
        let total = self.width as u32 * self.height as u32;
        enc.encode(
            &ToPc::Progress {
                frame: self.frame,
                done: done.min(total),
                total,
            },
            out,
        )
    }

    /// The frame for `rgb` (1..=[`MAX_RUN`] RGB8 pixels) of row `y` from column `x`,
    /// counted into the frame CRC. Run-length coded when that is shorter. `out` needs
    /// [`MAX_TO_PC`] bytes for any run.
    pub fn run(
        &mut self,
        y: u16,
        x: u16,
        rgb: &[u8],
        enc: &mut Encoder,
        out: &mut [u8],
    ) -> Result<usize, SerialError> {
        let offset = self.check(y, x, rgb)?;
        let n = self.message(y, x, rgb, enc, out)?;
        self.crc.add(offset, rgb)?;
        self.folded = self.folded.saturating_add((rgb.len() / 3) as u32);
        Ok(n)
    }

    /// As [`FrameStreamer::run`] but not counted: pixels sent again for a
    /// [`ToRc::Resend`].
    pub fn resend(
        &self,
        y: u16,
        x: u16,
        rgb: &[u8],
        enc: &mut Encoder,
        out: &mut [u8],
    ) -> Result<usize, SerialError> {
        self.check(y, x, rgb)?;
        self.message(y, x, rgb, enc, out)
    }

    /// The [`ToPc::FrameEnd`] frame with the whole frame's CRC; refused unless every pixel
    /// was counted exactly once (as far as the count shows).
    pub fn end(&self, enc: &mut Encoder, out: &mut [u8]) -> Result<usize, SerialError> {
        let expected = self.width as u32 * self.height as u32;
        if self.folded != expected {
            return Err(SerialError::Incomplete {
                folded: self.folded,
                expected,
            });
        }
        enc.encode(
            &ToPc::FrameEnd {
                frame: self.frame,
                crc: self.crc.value(),
            },
            out,
        )
    }

    /// The row pieces (y, x, pixels) of the raster span `start .. start + len`, each at
    /// most [`MAX_RUN`] pixels: the runs to send for a [`ToRc::Resend`]. Empty when the
    /// span leaves the frame.
    pub fn span_runs(&self, start: u32, len: u32) -> SpanRuns {
        let total = self.width as u64 * self.height as u64;
        let ok = start as u64 + len as u64 <= total;
        SpanRuns {
            width: self.width as u32,
            at: start,
            end: if ok { start + len } else { start },
        }
    }

    fn check(&self, y: u16, x: u16, rgb: &[u8]) -> Result<u64, SerialError> {
        let n = rgb.len() / 3;
        if !rgb.len().is_multiple_of(3)
            || n == 0
            || n > MAX_RUN
            || y >= self.height
            || x as usize + n > self.width as usize
        {
            return Err(SerialError::OutOfRange);
        }
        Ok(3 * (y as u64 * self.width as u64 + x as u64))
    }

    fn message(
        &self,
        y: u16,
        x: u16,
        rgb: &[u8],
        enc: &mut Encoder,
        out: &mut [u8],
    ) -> Result<usize, SerialError> {
        let mut coded = [0u8; 3 * MAX_RUN];
        let frame = self.frame;
        match rle_encode(rgb, &mut coded) {
            Some(m) if m < rgb.len() => enc.encode(
                &ToPc::PixelsRle {
                    frame,
                    y,
                    x,
                    len: (rgb.len() / 3) as u16,
                    data: coded.get(..m).unwrap_or(&[]),
                },
                out,
            ),
            _ => enc.encode(&ToPc::Pixels { frame, y, x, rgb }, out),
        }
    }
}

/// Iterator over the row pieces of a raster span, from [`FrameStreamer::span_runs`]:
/// `(y, x, pixels)`.
#[derive(Clone, Debug)]
pub struct SpanRuns {
    width: u32,
    at: u32,
    end: u32,
}

impl Iterator for SpanRuns {
    type Item = (u16, u16, u16);

    fn next(&mut self) -> Option<Self::Item> {
        if self.at >= self.end || self.width == 0 {
            return None;
        }
        let y = self.at / self.width;
        let x = self.at % self.width;
        let n = (self.width - x).min(self.end - self.at).min(MAX_RUN as u32);
        self.at += n;
        Some((y as u16, x as u16, n as u16))
    }
}

/// The RGB8 pixels a [`ToPc::Pixels`] or [`ToPc::PixelsRle`] message carries, written into
/// `out` (which must be exactly 3 x its pixel count long; see [`pixel_count`]).
pub fn pixels_into(msg: &ToPc<'_>, out: &mut [u8]) -> Result<(), SerialError> {
    match *msg {
        ToPc::Pixels { rgb, .. } if rgb.len() == out.len() => {
            out.copy_from_slice(rgb);
            Ok(())
        }
        ToPc::PixelsRle { data, .. } => rle_decode(data, out).map_err(|_| SerialError::Malformed),
        _ => Err(SerialError::Malformed),
    }
}

/// The number of pixels a pixel message carries (0 for other messages or a byte count
/// that is no whole number of pixels).
pub fn pixel_count(msg: &ToPc<'_>) -> usize {
    match *msg {
        ToPc::Pixels { rgb, .. } if rgb.len().is_multiple_of(3) => rgb.len() / 3,
        ToPc::PixelsRle { len, .. } => len as usize,
        _ => 0,
    }
}

#[cfg(test)]
mod tests;
