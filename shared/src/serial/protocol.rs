//! The serial protocol's vocabulary: sizes, the packet header, the messages each way
//! ([`ToRc`], [`ToPc`]) and the errors ([`RcError`] sent to the PC, [`SerialError`] local).

use core::fmt;
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
    /// Readback: `frame` arrived whole and passed its CRC. In a film this also releases
    /// the frame's scene bank on the RC (the next frame may start rendering).
    FrameAck { frame: u16 },
    /// Film: begin the upload of frame `frame` (one of `frames` frames of a film) as a
    /// SceneImage of `len` bytes whose CRC-32 is `crc`, into the RC's free scene bank; the
    /// chunks follow as [`ToRc::SceneChunk`]s. Answered as [`ToRc::SceneBegin`], or by
    /// [`ToPc::Error`] with [`RcError::FilmBusy`] when no bank is free (the PC is more than
    /// one frame ahead). Once stored, the RC starts the frame as soon as the cluster is
    /// free and says so with [`ToPc::FrameStarted`].
    FrameBegin {
        frame: u16,
        frames: u16,
        len: u32,
        crc: u32,
    },
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
    /// Film: frame `frame` (uploaded with [`ToRc::FrameBegin`]) started rendering; its
    /// bank is taken until its [`ToRc::FrameAck`], and the PC may begin the next frame.
    FrameStarted { frame: u16 },
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
    /// Film: `frame` was begun while frame `holder` still holds the scene bank it needs
    /// (rendering, or rendered and not yet acknowledged, or stored and not yet started):
    /// the PC went more than one frame ahead.
    FilmBusy { frame: u16, holder: u16 },
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
            RcError::FilmBusy { frame, holder } => write!(
                f,
                "film frame {frame} begun while frame {holder} still holds a scene bank (the PC is more than one frame ahead)"
            ),
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
