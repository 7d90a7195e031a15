//! The frame memory: 1024 x 1024 RGB8 (LINKS-1's), two banks so animation frame `f + 1`
//! can be collected while frame `f` is still finishing; fed by a pixel collector.
//!
//! As a **snoop** receiver the collector decodes every NC -> RC frame on the bus itself
//! (checking its CRC independently of the RC) and writes the pixel runs it carries, so pixels
//! never cross the RC. A duplicate (a re-sent frame) writes the same values again; a
//! corrupt one is dropped here just as the RC drops it.

use links_core::root::PixelSink;
use links_core::wire::{self, Up};

/// Side of the (square) frame memory.
pub const FRAME_MEMORY_SIDE: usize = 1024;

pub struct FrameMemory {
    banks: [Vec<u8>; 2],
    /// The newest frame written into each bank.
    holds: [Option<u16>; 2],
    /// Runs of a frame older than the one its bank now holds (from a node declared dead
    /// that delivered late), dropped.
    pub stale: u64,
    /// Pixel runs written, pixels written, frames rejected by CRC.
    pub runs: u64,
    pub pixels: u64,
    pub bad_messages: u64,
}

impl Default for FrameMemory {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameMemory {
    pub fn new() -> Self {
        let n = FRAME_MEMORY_SIDE * FRAME_MEMORY_SIDE * 3;
        Self {
            banks: [vec![0; n], vec![0; n]],
            holds: [None; 2],
            stale: 0,
            runs: 0,
            pixels: 0,
            bad_messages: 0,
        }
    }

    /// Write a run of RGB8 pixels of animation frame `frame` at (x, y). Runs that leave the
    /// memory are clipped.
    pub fn put(&mut self, frame: u16, y: u16, x: u16, rgb: &[u8]) {
        let (x, y) = (x as usize, y as usize);
        if y >= FRAME_MEMORY_SIDE || x >= FRAME_MEMORY_SIDE {
            return;
        }
        let b = (frame % 2) as usize;
        match self.holds[b] {
            Some(h) if h > frame => {
                self.stale += 1;
                return;
            }
            _ => self.holds[b] = Some(frame),
        }
        let n = (rgb.len() / 3).min(FRAME_MEMORY_SIDE - x);
        let at = (y * FRAME_MEMORY_SIDE + x) * 3;
        self.banks[(frame % 2) as usize][at..at + 3 * n].copy_from_slice(&rgb[..3 * n]);
        self.runs += 1;
        self.pixels += n as u64;
    }

    /// Capture one NC -> RC frame off the wire.
    pub fn snoop(&mut self, bytes: &[u8]) {
        let mut buf = [0u8; 3 * wire::MAX_RUN];
        match wire::decode::<Up>(bytes).and_then(|env| env.msg.pixel_run(&mut buf)) {
            Ok(Some(r)) => self.put(r.frame, r.y, r.x, r.rgb),
            Ok(None) => {}
            Err(_) => self.bad_messages += 1,
        }
    }

    /// The top-left `width` x `height` of frame `frame`'s bank, RGB8 rows.
    pub fn read(&self, frame: u16, width: u32, height: u32) -> Vec<u8> {
        let bank = &self.banks[(frame % 2) as usize];
        let (w, h) = (
            (width as usize).min(FRAME_MEMORY_SIDE),
            (height as usize).min(FRAME_MEMORY_SIDE),
        );
        let mut out = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            let at = y * FRAME_MEMORY_SIDE * 3;
            out.extend_from_slice(&bank[at..at + w * 3]);
        }
        out
    }
}

/// The RC's sink when pixels go through the RC (no snooping collector).
pub struct ViaRoot<'a>(pub &'a std::cell::RefCell<FrameMemory>);

impl PixelSink for ViaRoot<'_> {
    fn pixels(&mut self, frame: u16, y: u16, x: u16, rgb: &[u8]) {
        self.0.borrow_mut().put(frame, y, x, rgb);
    }
}
