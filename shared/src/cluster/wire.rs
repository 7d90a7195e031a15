//! Every message on the RC-NC bus (the "ICD"): versioned, postcard-encoded, CRC-32 checked.
//!
//! ## Message layout
//! ```text
//! postcard(Envelope { version, seq, ack, msg }) ++ CRC-32/ISO-HDLC (4 bytes, little-endian)
//! ```
//! SPI transfers are length-delimited (the link's handshake phase carries the length), so a
//! message needs no COBS stuffing on the bus; a byte stream (serial readback) wraps the same
//! message in COBS. The CRC covers every byte before it; a message whose CRC, version or layout
//! is wrong decodes to a [`WireError`], never a panic.
//!
//! Messages borrow their payloads from the received bytes (pixel runs, scene chunks), so
//! decoding copies nothing and allocates nothing.
//!
//! ## Reliability
//! RC -> NC exchange messages ([`Down::Work`]) carry *state*, not deltas (the node's whole
//! job queue), so a lost one is simply superseded by the next. NC -> RC messages carry a sequence
//! number; the RC acknowledges the highest in-order one in every reply (`ack`), and a node
//! keeps each message in its bank until acknowledged and sends it again otherwise (go-back-N with
//! a window of two: the two DMA banks).

use core::fmt;
use serde::{Deserialize, Serialize};

/// Protocol version carried in every message (4: scene repairs may come in pieces; 5: pixel
/// runs may come delta-coded, [`Up::PixelsDelta`]).
pub const PROTOCOL_VERSION: u8 = 5;
/// Most pixels in one [`Up::Pixels`] message (one full 512-pixel scanline).
pub const MAX_RUN: usize = 512;
/// Bytes of scene image in one broadcast chunk.
pub const SCENE_CHUNK: usize = 1024;
/// The smallest piece of a chunk the RC re-sends point-to-point on a noisy link: a
/// [`Down::Scene`] sent in an exchange may carry any whole number of pieces of one chunk
/// (the last piece of the scene may be short). Broadcasts carry whole chunks.
pub const SCENE_PIECE: usize = 64;
/// Pieces in a chunk.
pub const PIECES_PER_CHUNK: usize = SCENE_CHUNK / SCENE_PIECE;
const _: () = assert!(PIECES_PER_CHUNK <= 16 && SCENE_CHUNK.is_multiple_of(SCENE_PIECE));
/// Largest scene image a node bank holds (the IMSU's 128 KB bank).
pub const MAX_SCENE: usize = 128 * 1024;
/// Scene chunks in a full bank.
pub const MAX_CHUNKS: usize = MAX_SCENE / SCENE_CHUNK;
/// Jobs a node holds at once: the one it renders and the next (prefetch hides the round trip).
pub const JOB_QUEUE: usize = 2;
/// Bytes of CRC at the end of every message.
pub const CRC_LEN: usize = 4;
/// Upper bound of an encoded message (the largest is a full pixel run or a scene chunk).
pub const MAX_MESSAGE: usize = 3 * MAX_RUN + 40;

/// The CRC every message carries (CRC-32/ISO-HDLC, as Ethernet and zip).
pub const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// A sub-screen: what a node renders for one job.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Region {
    /// `len` pixels in raster order from pixel index `start` (= y * width + x): runs of
    /// scanlines, as LINKS-1 hands out (may continue onto the next scanline).
    Span { start: u32, len: u32 },
    /// A rectangle of `w` x `h` pixels with its top-left corner at (x, y).
    Rect { x: u16, y: u16, w: u16, h: u16 },
}

impl Region {
    /// Pixels in the region.
    pub fn pixels(&self) -> u32 {
        match *self {
            Region::Span { len, .. } => len,
            Region::Rect { w, h, .. } => w as u32 * h as u32,
        }
    }

    /// Whether the region lies inside a `width` x `height` frame and is not empty.
    pub fn fits(&self, width: u32, height: u32) -> bool {
        match *self {
            Region::Span { start, len } => {
                len > 0 && (start as u64 + len as u64) <= width as u64 * height as u64
            }
            Region::Rect { x, y, w, h } => {
                w > 0 && h > 0 && x as u32 + w as u32 <= width && y as u32 + h as u32 <= height
            }
        }
    }

    /// The `i`-th scanline piece of the region: (y, x, len), or `None` past the end. A
    /// span yields one piece per scanline it touches, a rectangle one per row.
    pub fn piece(&self, width: u32, i: u32) -> Option<(u32, u32, u32)> {
        match *self {
            Region::Span { start, len } => {
                if width == 0 {
                    return None;
                }
                let end = start.checked_add(len)?;
                let first_y = start / width;
                let y = first_y.checked_add(i)?;
                let row0 = y.checked_mul(width)?;
                let lo = start.max(row0);
                let hi = end.min(row0.checked_add(width)?);
                (lo < hi).then(|| (y, lo - row0, hi - lo))
            }
            Region::Rect { x, y, w, h } => {
                // The row only for an index inside the rectangle (y + i < 2^17 then).
                (i < h as u32).then(|| (y as u32 + i, x as u32, w as u32))
            }
        }
    }
}

/// One unit of work: a region of one animation frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Job {
    /// Globally increasing job number (a node receives its jobs in increasing order).
    pub id: u32,
    /// Animation frame; its scene lives in node bank `frame % 2`.
    pub frame: u16,
    pub region: Region,
}

/// What a node knows about the scene of one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SceneState {
    /// Complete, CRC-checked and validated.
    Ready { frame: u16 },
    /// The broadcast ended but these chunks are missing (bit `c` of word `c / 32` set =
    /// chunk `c`, at byte `c · SCENE_CHUNK`, lost or corrupt). `pieces`: which
    /// [`SCENE_PIECE`]-byte pieces of the first missing chunk the node already holds (bit
    /// `i` = piece `i`), so a repair in pieces sends only the others.
    Missing {
        frame: u16,
        chunks: [u32; MAX_CHUNKS / 32],
        pieces: u16,
    },
    /// Nothing received yet.
    None,
}

/// RC -> NC messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Down<'a> {
    /// Exchange reply: the node's job queue as the RC sees it (jobs it has not reported
    /// finished, oldest first). Idempotent: the node ignores jobs it already took.
    Work { jobs: [Option<Job>; JOB_QUEUE] },
    /// A piece of a scene image written at `offset` (the IMSU's address offset) into the
    /// bank of `frame`, broadcast or, as a repair, in an exchange. Every chunk carries the
    /// scene's length and CRC-32, so a node whose `SceneEnd` was lost still completes.
    Scene {
        frame: u16,
        offset: u32,
        total: u32,
        crc: u32,
        #[serde(serialize_with = "bytes")]
        data: &'a [u8],
    },
    /// End of a scene broadcast: its length and CRC-32.
    SceneEnd { frame: u16, len: u32, crc: u32 },
    /// No more work: the node may stop.
    Stop,
    /// Roll call, broadcast when work waits that no node can be asked for otherwise (a node
    /// was declared dead holding jobs, or a node has not reported frame `frame`'s scene
    /// long after its broadcast) and again, at doubling intervals, while that lasts. An idle
    /// node with a free job slot answers: with a [`Up::Poll`] if it holds `frame`'s scene
    /// (to be handed work), else with a [`SceneState::Missing`] status (to be sent it).
    Wake { frame: u16 },
}

/// NC -> RC messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Up<'a> {
    /// The node's scene changed state (sequenced: delivered reliably).
    Status { scene: SceneState },
    /// Not sequenced, carries nothing: "swap with me so I learn your `ack`" (a node with
    /// unacknowledged messages and nothing new to send).
    Poll,
    /// Finished pixels of job `job`: `rgb` holds RGB8 triples of scanline `y` from column
    /// `x` (the address + colour record, LINKS-1's 54-bit pixel analog, per run). `done`
    /// marks the job's last run.
    Pixels {
        job: u32,
        frame: u16,
        y: u16,
        x: u16,
        #[serde(serialize_with = "bytes")]
        rgb: &'a [u8],
        done: bool,
    },
    /// As [`Up::Pixels`], the `len` pixels run-length coded ([`rle_encode`]): lossless, and
    /// much shorter over flat backgrounds.
    PixelsRle {
        job: u32,
        frame: u16,
        y: u16,
        x: u16,
        len: u16,
        #[serde(serialize_with = "bytes")]
        data: &'a [u8],
        done: bool,
    },
    /// As [`Up::Pixels`], the `len` pixels delta-coded ([`delta_encode`]): lossless, and
    /// shorter than the raw bytes over smooth shading too, where run-length coding is not.
    PixelsDelta {
        job: u32,
        frame: u16,
        y: u16,
        x: u16,
        len: u16,
        #[serde(serialize_with = "bytes")]
        data: &'a [u8],
        done: bool,
    },
}

/// Serialise a payload as one block of bytes (postcard: varint length + the bytes, exactly
/// what serde's default element-by-element `[u8]` sequence gives, so the wire format is
/// unchanged) instead of one `u8` at a time: a memcpy on the RC's CPU instead of ~7
/// instructions per byte (tests/qemu-bench/src/wire_bench.rs). Decoding already borrows it.
fn bytes<S: serde::Serializer>(b: &&[u8], s: S) -> Result<S::Ok, S::Error> {
    s.serialize_bytes(b)
}

/// Run-length code RGB8 pixels as `(count - 1, r, g, b)` quadruples (runs of up to 256 equal
/// pixels). Returns the coded length, or `None` if it would not fit `out`.
pub fn rle_encode(rgb: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut n = 0;
    let mut px = rgb.chunks_exact(3).peekable();
    while let Some(p) = px.next() {
        let mut count = 1usize;
        while count < 256 && px.peek() == Some(&p) {
            px.next();
            count += 1;
        }
        let q = out.get_mut(n..n + 4)?;
        q[0] = (count - 1) as u8;
        q[1..4].copy_from_slice(p);
        n += 4;
    }
    Some(n)
}

/// Decode [`rle_encode`]'s output into `out`, which must be filled exactly.
pub fn rle_decode(data: &[u8], out: &mut [u8]) -> Result<(), WireError> {
    if !data.len().is_multiple_of(4) {
        return Err(WireError::Malformed);
    }
    let mut at = 0;
    for q in data.chunks_exact(4) {
        let count = q[0] as usize + 1;
        let dst = out
            .get_mut(at..at + 3 * count)
            .ok_or(WireError::Malformed)?;
        for d in dst.chunks_exact_mut(3) {
            d.copy_from_slice(&q[1..4]);
        }
        at += 3 * count;
    }
    if at == out.len() {
        Ok(())
    } else {
        Err(WireError::Malformed)
    }
}

/// A pixel run's place and its RGB8 pixels ([`Up::pixel_run`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelRun<'a> {
    pub job: u32,
    pub frame: u16,
    pub y: u16,
    pub x: u16,
    pub rgb: &'a [u8],
    pub done: bool,
}

impl<'a> Up<'a> {
    /// The pixel run this message carries, a coded one expanded into `buf`: `Ok(None)` for
    /// a message that carries none, [`WireError::Malformed`] for a coding that does not
    /// decode or does not fit `buf`.
    pub fn pixel_run<'b>(&self, buf: &'b mut [u8]) -> Result<Option<PixelRun<'b>>, WireError>
    where
        'a: 'b,
    {
        let (job, frame, y, x, rgb, done) = match *self {
            Up::Pixels {
                job,
                frame,
                y,
                x,
                rgb,
                done,
            } => (job, frame, y, x, rgb, done),
            Up::PixelsRle {
                job,
                frame,
                y,
                x,
                len,
                data,
                done,
            }
            | Up::PixelsDelta {
                job,
                frame,
                y,
                x,
                len,
                data,
                done,
            } => {
                let out = buf
                    .get_mut(..3 * len as usize)
                    .ok_or(WireError::Malformed)?;
                if matches!(self, Up::PixelsRle { .. }) {
                    rle_decode(data, out)?;
                } else {
                    delta_decode(data, out)?;
                }
                (job, frame, y, x, &*out, done)
            }
            Up::Status { .. } | Up::Poll => return Ok(None),
        };
        Ok(Some(PixelRun {
            job,
            frame,
            y,
            x,
            rgb,
            done,
        }))
    }
}

/// How a pixel run is coded on the wire ([`Up::Pixels`], [`Up::PixelsRle`],
/// [`Up::PixelsDelta`]): a node sends the shortest of raw and the codings it may use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PixelCoding {
    /// Raw RGB8 only.
    Raw,
    /// Raw or run-length coded.
    Rle,
    /// Raw, run-length or delta coded.
    Delta,
}

/// How [`code_pixels`] coded a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coded {
    /// Shortest raw: send the pixels as they are.
    Raw,
    /// The first `n` bytes of the buffer, run-length coded.
    Rle(usize),
    /// The first `n` bytes of the buffer, delta coded.
    Delta(usize),
}

impl Coded {
    /// The message carrying `run`: its pixels raw, or the first bytes of `coded` (where
    /// [`code_pixels`] put them) as this coding says.
    pub fn message<'a>(self, run: PixelRun<'a>, coded: &'a [u8]) -> Up<'a> {
        let PixelRun {
            job,
            frame,
            y,
            x,
            rgb,
            done,
        } = run;
        let len = (rgb.len() / 3) as u16;
        match self {
            Coded::Raw => Up::Pixels {
                job,
                frame,
                y,
                x,
                rgb,
                done,
            },
            Coded::Rle(n) => Up::PixelsRle {
                job,
                frame,
                y,
                x,
                len,
                data: &coded[..n.min(coded.len())],
                done,
            },
            Coded::Delta(n) => Up::PixelsDelta {
                job,
                frame,
                y,
                x,
                len,
                data: &coded[..n.min(coded.len())],
                done,
            },
        }
    }
}

/// Code `rgb` as the shortest of raw and what `coding` allows, into `out` (ties go to the
/// simpler coding).
pub fn code_pixels(coding: PixelCoding, rgb: &[u8], out: &mut [u8]) -> Coded {
    let rle = match coding {
        PixelCoding::Raw => None,
        PixelCoding::Rle | PixelCoding::Delta => rle_encode(rgb, out).filter(|&n| n < rgb.len()),
    };
    if coding == PixelCoding::Delta {
        let best = rle.unwrap_or(rgb.len());
        if let Some(n) = delta_encode(rgb, out).filter(|&n| n < best) {
            return Coded::Delta(n);
        }
        // `out` now holds the delta coding: code the winner again.
        if let Some(n) = rle {
            return match rle_encode(rgb, out) {
                Some(m) if m == n => Coded::Rle(n),
                _ => Coded::Raw,
            };
        }
        return Coded::Raw;
    }
    rle.map_or(Coded::Raw, Coded::Rle)
}

// Delta coding ([`delta_encode`]): one tag byte per operation, each pixel coded against the
// one before it (the run starts from black), channel differences wrapping modulo 256.
/// `00rrggbb`: each channel differs by -2..=1 (stored + 2).
const DELTA_SMALL: u8 = 0b00 << 6;
/// `01nnnnnn`: the previous pixel again, n + 1 times (1..=64).
const DELTA_RUN: u8 = 0b01 << 6;
/// `10gggggg rrrrbbbb`: green differs by -32..=31 (stored + 32), red and blue by green's
/// difference -8..=7 (stored + 8): shading changes the three channels together.
const DELTA_LUMA: u8 = 0b10 << 6;
/// `11000000 r g b`: the pixel itself. Other `11` tags are not used (malformed).
const DELTA_LITERAL: u8 = 0b11 << 6;
const DELTA_MAX_RUN: usize = 64;

/// Delta-code RGB8 pixels (see the tag constants above): a run of equal pixels takes one
/// byte per 64, a small change one byte, a shading step two, anything else four. Returns the
/// coded length, or `None` if it would not fit `out`.
pub fn delta_encode(rgb: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut n = 0;
    let mut prev = [0u8; 3];
    let mut run = 0usize;
    let mut put = |n: &mut usize, bytes: &[u8]| -> Option<()> {
        out.get_mut(*n..*n + bytes.len())?.copy_from_slice(bytes);
        *n += bytes.len();
        Some(())
    };
    for p in rgb.chunks_exact(3) {
        let p = [p[0], p[1], p[2]];
        if p == prev {
            run += 1;
            if run == DELTA_MAX_RUN {
                put(&mut n, &[DELTA_RUN | (run - 1) as u8])?;
                run = 0;
            }
            continue;
        }
        if run > 0 {
            put(&mut n, &[DELTA_RUN | (run - 1) as u8])?;
            run = 0;
        }
        let d = |c: usize| p[c].wrapping_sub(prev[c]) as i8 as i16;
        let (dr, dg, db) = (d(0), d(1), d(2));
        let (rg, bg) = (dr - dg, db - dg);
        if (-2..=1).contains(&dr) && (-2..=1).contains(&dg) && (-2..=1).contains(&db) {
            let v = ((dr + 2) << 4 | (dg + 2) << 2 | (db + 2)) as u8;
            put(&mut n, &[DELTA_SMALL | v])?;
        } else if (-32..=31).contains(&dg) && (-8..=7).contains(&rg) && (-8..=7).contains(&bg) {
            let v = [
                DELTA_LUMA | (dg + 32) as u8,
                ((rg + 8) << 4 | (bg + 8)) as u8,
            ];
            put(&mut n, &v)?;
        } else {
            put(&mut n, &[DELTA_LITERAL, p[0], p[1], p[2]])?;
        }
        prev = p;
    }
    if run > 0 {
        put(&mut n, &[DELTA_RUN | (run - 1) as u8])?;
    }
    Some(n)
}

/// Decode [`delta_encode`]'s output into `out`, which must be filled exactly (whole pixels);
/// anything else (a truncated operation, an unused tag, too many or too few pixels) is
/// [`WireError::Malformed`].
pub fn delta_decode(data: &[u8], out: &mut [u8]) -> Result<(), WireError> {
    if !out.len().is_multiple_of(3) {
        return Err(WireError::Malformed);
    }
    let mut prev = [0u8; 3];
    let (mut i, mut at) = (0usize, 0usize);
    while let Some(&tag) = data.get(i) {
        let px = match tag & 0b1100_0000 {
            DELTA_RUN => {
                // The one operation of several pixels.
                let count = (tag & 0x3f) as usize + 1;
                let dst = out
                    .get_mut(at..at + 3 * count)
                    .ok_or(WireError::Malformed)?;
                for d in dst.chunks_exact_mut(3) {
                    d.copy_from_slice(&prev);
                }
                at += 3 * count;
                i += 1;
                continue;
            }
            DELTA_SMALL => {
                i += 1;
                let d = |s: u8| ((tag >> s) & 3).wrapping_sub(2);
                [
                    prev[0].wrapping_add(d(4)),
                    prev[1].wrapping_add(d(2)),
                    prev[2].wrapping_add(d(0)),
                ]
            }
            DELTA_LUMA => {
                let &b = data.get(i + 1).ok_or(WireError::Malformed)?;
                i += 2;
                let dg = (tag & 0x3f).wrapping_sub(32);
                [
                    prev[0].wrapping_add(dg.wrapping_add((b >> 4).wrapping_sub(8))),
                    prev[1].wrapping_add(dg),
                    prev[2].wrapping_add(dg.wrapping_add((b & 0x0f).wrapping_sub(8))),
                ]
            }
            _ => {
                if tag != DELTA_LITERAL {
                    return Err(WireError::Malformed);
                }
                let p = data.get(i + 1..i + 4).ok_or(WireError::Malformed)?;
                i += 4;
                [p[0], p[1], p[2]]
            }
        };
        // Every other operation is one pixel.
        out.get_mut(at..at + 3)
            .ok_or(WireError::Malformed)?
            .copy_from_slice(&px);
        at += 3;
        prev = px;
    }
    if at == out.len() {
        Ok(())
    } else {
        Err(WireError::Malformed)
    }
}

/// A message as sent: its header fields (version, sequence, acknowledgement) and its payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Envelope<M> {
    pub version: u8,
    /// Sender's sequence number (NC messages; 0 in broadcasts).
    pub seq: u16,
    /// RC messages: the highest in-order NC sequence number received. NC messages: the last
    /// RC exchange it decoded (diagnostic only).
    pub ack: u16,
    pub msg: M,
}

/// Why bytes are not a valid message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireError {
    /// Shorter than the CRC, or the CRC does not match.
    BadCrc,
    /// CRC fine but the contents are not a message of this protocol.
    Malformed,
    /// A message of another protocol version.
    Version { found: u8 },
    /// The output buffer is too small for the message.
    BufferFull,
}

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            WireError::BadCrc => write!(f, "frame failed its CRC check"),
            WireError::Malformed => write!(f, "frame holds no valid message"),
            WireError::Version { found } => write!(
                f,
                "frame of protocol version {found} (expected {PROTOCOL_VERSION})"
            ),
            WireError::BufferFull => write!(f, "frame does not fit the buffer"),
        }
    }
}

impl core::error::Error for WireError {}

/// Encode a message into `buf`; returns the message's length.
pub fn encode<M: Serialize>(
    seq: u16,
    ack: u16,
    msg: &M,
    buf: &mut [u8],
) -> Result<usize, WireError> {
    let env = Envelope {
        version: PROTOCOL_VERSION,
        seq,
        ack,
        msg,
    };
    // The body first, then one CRC pass over it: the same bytes as postcard's CRC flavour
    // (`to_slice_crc32`), which updates the digest byte by byte as it serialises and costs
    // the RC three times the instructions per byte on the Cortex-M4F (16 against ~6 per
    // byte of a scene chunk: tests/qemu-bench/src/wire_bench.rs).
    let room = buf
        .len()
        .checked_sub(CRC_LEN)
        .ok_or(WireError::BufferFull)?;
    let n = postcard::to_slice(&env, &mut buf[..room])
        .map_err(|_| WireError::BufferFull)?
        .len();
    let crc = CRC32.checksum(&buf[..n]);
    buf[n..n + CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    Ok(n + CRC_LEN)
}

/// Decode a message (checking CRC and version). The message borrows from `bytes`.
pub fn decode<'a, M: Deserialize<'a>>(bytes: &'a [u8]) -> Result<Envelope<M>, WireError> {
    if bytes.len() < CRC_LEN {
        return Err(WireError::BadCrc);
    }
    let (body, tail) = bytes.split_at(bytes.len() - CRC_LEN);
    let want = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
    if CRC32.checksum(body) != want {
        return Err(WireError::BadCrc);
    }
    // The version is the first byte (a u8 encodes as itself).
    match body.first() {
        Some(&PROTOCOL_VERSION) => {}
        Some(&v) => return Err(WireError::Version { found: v }),
        None => return Err(WireError::Malformed),
    }
    let (env, rest): (Envelope<M>, &[u8]) =
        postcard::take_from_bytes(body).map_err(|_| WireError::Malformed)?;
    if !rest.is_empty() {
        return Err(WireError::Malformed);
    }
    Ok(env)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip<'a, M>(msg: M, buf: &'a mut [u8]) -> Envelope<M>
    where
        M: Serialize + Deserialize<'a> + PartialEq + fmt::Debug + Copy,
    {
        let n = encode(7, 3, &msg, buf).expect("fits");
        let env: Envelope<M> = decode(&buf[..n]).expect("decodes");
        assert_eq!(env.msg, msg);
        assert_eq!((env.version, env.seq, env.ack), (PROTOCOL_VERSION, 7, 3));
        env
    }

    #[test]
    fn every_message_round_trips() {
        let job = Job {
            id: 9,
            frame: 1,
            region: Region::Span { start: 5, len: 700 },
        };
        let rect = Job {
            id: 10,
            frame: 1,
            region: Region::Rect {
                x: 1,
                y: 2,
                w: 3,
                h: 4,
            },
        };
        let data = [1u8, 2, 3, 250];
        let rgb = [7u8; 3 * MAX_RUN];
        let downs = [
            Down::Work {
                jobs: [Some(job), Some(rect)],
            },
            Down::Work { jobs: [None, None] },
            Down::Scene {
                frame: 3,
                offset: 1024,
                total: 90536,
                crc: 7,
                data: &data,
            },
            Down::SceneEnd {
                frame: 3,
                len: 90536,
                crc: 0xdead_beef,
            },
            Down::Stop,
            Down::Wake { frame: 4 },
        ];
        for d in downs {
            roundtrip(d, &mut [0u8; MAX_MESSAGE]);
        }
        let ups = [
            Up::Status {
                scene: SceneState::Ready { frame: 2 },
            },
            Up::Status {
                scene: SceneState::Missing {
                    frame: 2,
                    chunks: [1, 0, 0, 1 << 31],
                    pieces: 0b1010_0000_0000_0001,
                },
            },
            Up::Status {
                scene: SceneState::None,
            },
            Up::Poll,
            Up::Pixels {
                job: 4,
                frame: 0,
                y: 479,
                x: 0,
                rgb: &rgb,
                done: true,
            },
            Up::PixelsRle {
                job: 4,
                frame: 0,
                y: 479,
                x: 0,
                len: 512,
                data: &data,
                done: false,
            },
        ];
        for u in ups {
            roundtrip(u, &mut [0u8; MAX_MESSAGE]);
        }
    }

    #[test]
    fn largest_messages_fit_max_message() {
        let rgb = [0xffu8; 3 * MAX_RUN];
        let up = Up::Pixels {
            job: u32::MAX,
            frame: u16::MAX,
            y: u16::MAX,
            x: u16::MAX,
            rgb: &rgb,
            done: true,
        };
        let mut buf = [0u8; MAX_MESSAGE];
        let n = encode(u16::MAX, u16::MAX, &up, &mut buf).expect("fits");
        assert!(n <= MAX_MESSAGE);
        let chunk = [0xffu8; SCENE_CHUNK];
        let d = Down::Scene {
            frame: u16::MAX,
            offset: u32::MAX,
            total: u32::MAX,
            crc: u32::MAX,
            data: &chunk,
        };
        assert!(encode(u16::MAX, u16::MAX, &d, &mut buf).expect("fits") <= MAX_MESSAGE);
    }

    #[test]
    fn encode_equals_postcards_crc_flavour() {
        let rgb = [0x21u8; 700];
        let msgs = [
            Up::Pixels {
                job: 77,
                frame: 3,
                y: 9,
                x: 4,
                rgb: &rgb,
                done: true,
            },
            Up::Poll,
        ];
        for m in msgs {
            let (mut a, mut b) = ([0u8; MAX_MESSAGE], [0u8; MAX_MESSAGE]);
            let n = encode(5, 6, &m, &mut a).unwrap();
            let env = Envelope {
                version: PROTOCOL_VERSION,
                seq: 5,
                ack: 6,
                msg: &m,
            };
            let want = postcard::to_slice_crc32(&env, &mut b, CRC32.digest()).unwrap();
            assert_eq!(&a[..n], &*want);
            // The payload as a block gives the bytes of serde's element-wise sequence.
            if let Up::Pixels { rgb, .. } = m {
                let mut seq = [0u8; MAX_MESSAGE];
                let mut blk = [0u8; MAX_MESSAGE];
                struct Blk<'a>(&'a [u8]);
                impl Serialize for Blk<'_> {
                    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                        bytes(&self.0, s)
                    }
                }
                let s1 = postcard::to_slice(rgb, &mut seq).unwrap().len();
                let s2 = postcard::to_slice(&Blk(rgb), &mut blk).unwrap().len();
                assert_eq!(seq[..s1], blk[..s2]);
            }
            // Exactly full fits; one byte less does not.
            let mut c = [0u8; MAX_MESSAGE];
            assert_eq!(encode(5, 6, &m, &mut c[..n]), Ok(n));
            assert_eq!(
                encode(5, 6, &m, &mut c[..n - 1]),
                Err(WireError::BufferFull)
            );
        }
    }

    #[test]
    fn exact_size_of_a_pixel_message() {
        // version 1 + seq 1 + ack 1 + variant 1 + job 1 + frame 1 + y 1 + x 1
        // + len varint 2 + 384 bytes + done 1 + crc 4 = 399
        let rgb = [0u8; 384];
        let up = Up::Pixels {
            job: 1,
            frame: 0,
            y: 5,
            x: 0,
            rgb: &rgb,
            done: false,
        };
        let mut buf = [0u8; MAX_MESSAGE];
        assert_eq!(encode(1, 0, &up, &mut buf), Ok(399));
    }

    #[test]
    fn crc_catches_every_single_bit_flip() {
        let rgb = [0x5au8; 64];
        let up = Up::Pixels {
            job: 1,
            frame: 0,
            y: 5,
            x: 3,
            rgb: &rgb,
            done: true,
        };
        let mut buf = [0u8; MAX_MESSAGE];
        let n = encode(1, 0, &up, &mut buf).unwrap();
        for bit in 0..n * 8 {
            let mut b = buf;
            b[bit / 8] ^= 1 << (bit % 8);
            assert_eq!(decode::<Up>(&b[..n]), Err(WireError::BadCrc), "bit {bit}");
        }
        assert_eq!(decode::<Up>(&buf[..n - 1]), Err(WireError::BadCrc));
        assert_eq!(decode::<Up>(&[]), Err(WireError::BadCrc));
    }

    #[test]
    fn wrong_version_and_garbage_are_errors_not_panics() {
        let mut buf = [0u8; 64];
        let n = encode(0, 0, &Down::Stop, &mut buf).unwrap();
        // The next version, and versions 1 (before `Down::Wake`) and 2 (`Wake` without its
        // frame).
        for v in [PROTOCOL_VERSION + 1, 1, 2] {
            buf[0] = v;
            let crc = CRC32.checksum(&buf[..n - 4]).to_le_bytes();
            buf[n - 4..n].copy_from_slice(&crc);
            assert_eq!(
                decode::<Down>(&buf[..n]),
                Err(WireError::Version { found: v })
            );
        }
        // Valid CRC over bytes that are no message.
        let mut g = [PROTOCOL_VERSION, 0, 0, 99, 0, 0, 0, 0];
        let crc = CRC32.checksum(&g[..4]).to_le_bytes();
        g[4..].copy_from_slice(&crc);
        assert_eq!(decode::<Down>(&g), Err(WireError::Malformed));
        assert_eq!(
            encode(0, 0, &Down::Stop, &mut [0u8; 3]),
            Err(WireError::BufferFull)
        );
    }

    #[test]
    fn rle_round_trips_and_rejects_bad_input() {
        let mut rgb = [0u8; 3 * 600];
        for (i, p) in rgb.chunks_exact_mut(3).enumerate() {
            let v = if i < 300 { 9 } else { (i / 7) as u8 };
            p.copy_from_slice(&[v, v / 2, 1]);
        }
        let mut coded = [0u8; 4 * 600];
        let n = rle_encode(&rgb, &mut coded).unwrap();
        // 300 equal pixels: two quadruples (256 + 44); then runs of 7 (the first short).
        assert_eq!(n, 4 * (2 + 300usize.div_ceil(7) + 1));
        let mut back = [0u8; 3 * 600];
        rle_decode(&coded[..n], &mut back).unwrap();
        assert_eq!(back, rgb);
        assert_eq!(
            rle_decode(&coded[..n - 1], &mut back),
            Err(WireError::Malformed)
        );
        assert_eq!(
            rle_decode(&coded[..n - 4], &mut back),
            Err(WireError::Malformed)
        );
        assert_eq!(
            rle_decode(&coded[..n], &mut back[..30]),
            Err(WireError::Malformed)
        );
        assert_eq!(rle_encode(&rgb, &mut coded[..7]), None);
        assert_eq!(rle_encode(&[], &mut coded), Some(0));
    }

    #[test]
    fn delta_round_trips_codes_shading_short_and_rejects_bad_input() {
        // A shaded gradient (steps of 1-9 per channel), a flat stretch, noise.
        let mut rgb = [0u8; 3 * 600];
        let mut state = 0x2545_f491_u32;
        for (i, p) in rgb.chunks_exact_mut(3).enumerate() {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            let v = match i {
                0..200 => [(40 + i / 2) as u8, (60 + i) as u8, (i * 9 / 8) as u8],
                200..400 => [9, 9, 200],
                _ => state.to_le_bytes()[..3].try_into().unwrap(),
            };
            p.copy_from_slice(&v);
        }
        let mut coded = [0u8; 4 * 600];
        let n = delta_encode(&rgb, &mut coded).unwrap();
        let mut back = [0u8; 3 * 600];
        delta_decode(&coded[..n], &mut back).unwrap();
        assert_eq!(back, rgb);
        // The gradient alone: one or two bytes a pixel, where RLE needs four.
        let g = delta_encode(&rgb[..600], &mut coded).unwrap();
        assert!(g <= 2 * 200 && g > 200, "{g}");
        assert_eq!(rle_encode(&rgb[..600], &mut [0u8; 4 * 200]), Some(800));
        // The flat stretch: 200 pixels in a literal and four run bytes (199 = 64 + 64 + 64
        // + 7 repeats).
        assert_eq!(delta_encode(&rgb[600..1200], &mut coded), Some(4 + 4));
        // Every single-pixel step from black codes and decodes, through each tag.
        for v in [
            [0, 0, 0],
            [1, 0, 255],
            [254, 254, 254],
            [20, 30, 25],
            [200, 7, 9],
        ] {
            let n = delta_encode(&v, &mut coded).unwrap();
            let mut one = [0u8; 3];
            delta_decode(&coded[..n], &mut one).unwrap();
            assert_eq!(one, v);
        }
        let n = delta_encode(&rgb, &mut coded).unwrap();
        assert_eq!(
            delta_decode(&coded[..n - 1], &mut back),
            Err(WireError::Malformed)
        );
        assert_eq!(
            delta_decode(&coded[..n], &mut back[..30]),
            Err(WireError::Malformed)
        );
        assert_eq!(
            delta_decode(&[0b1100_0001], &mut [0u8; 3]),
            Err(WireError::Malformed)
        );
        assert_eq!(
            delta_decode(&[DELTA_LUMA], &mut [0u8; 3]),
            Err(WireError::Malformed)
        );
        assert_eq!(delta_decode(&[], &mut [0u8; 2]), Err(WireError::Malformed));
        assert_eq!(delta_encode(&rgb, &mut coded[..7]), None);
        assert_eq!(delta_encode(&[], &mut coded), Some(0));
    }

    #[test]
    fn region_pieces() {
        let s = Region::Span { start: 10, len: 30 };
        assert_eq!(s.piece(16, 0), Some((0, 10, 6)));
        assert_eq!(s.piece(16, 1), Some((1, 0, 16)));
        assert_eq!(s.piece(16, 2), Some((2, 0, 8)));
        assert_eq!(s.piece(16, 3), None);
        let r = Region::Rect {
            x: 2,
            y: 3,
            w: 4,
            h: 2,
        };
        assert_eq!(r.piece(16, 1), Some((4, 2, 4)));
        assert_eq!(r.piece(16, 2), None);
        assert!(r.fits(6, 5) && !r.fits(5, 5));
        assert!(!Region::Span { start: 0, len: 0 }.fits(4, 4));
        assert_eq!(
            Region::Span {
                start: u32::MAX,
                len: 2
            }
            .piece(16, 0),
            None
        );
    }

    #[test]
    fn pieces_far_past_a_rectangles_end_are_none() {
        // Found by the wire fuzzer: the row was computed before the index was checked.
        let r = Region::Rect {
            x: 0,
            y: 5,
            w: 1,
            h: 1,
        };
        assert_eq!(r.piece(8, u32::MAX), None);
        assert_eq!(r.piece(8, u32::MAX - 4), None);
        assert_eq!(r.piece(8, 0), Some((5, 0, 1)));
    }
}
