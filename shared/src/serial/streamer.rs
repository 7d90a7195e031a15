//! The RC side of frame readback on the line: [`FrameStreamer`] turns runs of pixels into
//! messages and keeps the frame CRC; [`SpanRuns`] cuts a raster span into runs;
//! [`pixels_into`] / [`pixel_count`] read pixel messages on the PC.

use super::codec::Encoder;
use super::frame_crc::FrameCrc;
use super::protocol::*;
use crate::wire::{rle_decode, rle_encode};

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
