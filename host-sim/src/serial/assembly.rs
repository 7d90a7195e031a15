//! One frame being assembled on the PC from the RC's pixel messages, in any order.

use super::HostSerialError;
use links_core::serial::{pixel_count, pixels_into, ToPc, MAX_DIM};

/// One frame being assembled from pixel messages in any order.
pub struct FrameAssembly {
    pub frame: u16,
    pub width: u16,
    pub height: u16,
    pub rgb: Vec<u8>,
    have: Vec<bool>,
    pub(super) count: u64,
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

    pub(super) fn total(&self) -> u64 {
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

    pub(super) fn forget(&mut self) {
        self.have.iter_mut().for_each(|h| *h = false);
        self.count = 0;
    }
}
