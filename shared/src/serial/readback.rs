//! Frame readback: accepted pixel runs become `crate::serial` frames in a byte queue
//! (USB CDC on the board). Runs of the cluster bus (up to 512 pixels) are cut into serial
//! runs (up to 256); the frame CRC is kept in whatever order runs arrive.

use crate::root::PixelSink;
use crate::serial::{Encoder, FrameStreamer, SerialError, MAX_RUN, MAX_TO_PC};
use crate::wire;

/// Where encoded frames go.
pub trait ByteQueue {
    /// Bytes that can be queued now.
    fn free(&self) -> usize;
    /// Queue `bytes` whole, or nothing (returns false).
    fn push(&mut self, bytes: &[u8]) -> bool;
}

impl<Q: ByteQueue + ?Sized> ByteQueue for &mut Q {
    fn free(&self) -> usize {
        (**self).free()
    }
    fn push(&mut self, bytes: &[u8]) -> bool {
        (**self).push(bytes)
    }
}

/// Queue space one accepted bus run can need: two serial frames (a 512-pixel run is two
/// 256-pixel runs) and a progress frame. The bus waits for this much before an exchange.
pub const RUN_RESERVE: usize = (wire::MAX_RUN.div_ceil(MAX_RUN) + 1) * MAX_TO_PC;

/// The readback of one frame.
pub struct Readback<Q> {
    pub queue: Q,
    enc: Encoder,
    streamer: FrameStreamer,
    buf: [u8; MAX_TO_PC],
    /// Frames that did not fit the queue or failed to encode (with [`RUN_RESERVE`] kept
    /// free before every exchange this stays 0).
    pub dropped: u32,
    /// Progress frame every this many pixels (0 = never).
    pub progress_every: u32,
    /// The root logic's frame number whose runs this readback takes (the serial frame
    /// number may differ: the board renders one bus frame per serial frame).
    pub bus_frame: u16,
    last_progress: u32,
}

impl<Q: ByteQueue> Readback<Q> {
    /// Start frame `frame` of `width` x `height` pixels: queues its header.
    pub fn new(
        queue: Q,
        enc: Encoder,
        frame: u16,
        width: u16,
        height: u16,
    ) -> Result<Self, SerialError> {
        let streamer = FrameStreamer::new(frame, width, height)?;
        let mut r = Readback {
            queue,
            enc,
            streamer,
            buf: [0; MAX_TO_PC],
            dropped: 0,
            progress_every: 8 * width as u32,
            bus_frame: frame,
            last_progress: 0,
        };
        let n = r.streamer.header(&mut r.enc, &mut r.buf)?;
        r.send(n);
        Ok(r)
    }

    fn send(&mut self, n: usize) {
        let ok = self.buf.get(..n).is_some_and(|b| self.queue.push(b));
        if !ok {
            self.dropped += 1;
        }
    }

    /// Pixels streamed so far.
    pub fn streamed(&self) -> u32 {
        self.streamer.folded()
    }

    /// Queue the `FrameEnd` (with the whole frame's CRC); fails unless every pixel went
    /// out exactly once (then no `FrameEnd` is sent and the PC reports the frame
    /// incomplete). Hands back the queue, the encoder for the next frame and the streamer
    /// (which can encode the `FrameEnd` again for a `Resend`) either way.
    pub fn end(mut self) -> Ended<Q> {
        let result = match self.streamer.end(&mut self.enc, &mut self.buf) {
            Ok(n) => {
                self.send(n);
                if self.dropped > 0 {
                    Err(SerialError::BufferFull)
                } else {
                    Ok(())
                }
            }
            Err(e) => Err(e),
        };
        Ended {
            queue: self.queue,
            enc: self.enc,
            streamer: self.streamer,
            result,
        }
    }
}

/// What [`Readback::end`] hands back.
pub struct Ended<Q> {
    pub queue: Q,
    pub enc: Encoder,
    pub streamer: FrameStreamer,
    pub result: Result<(), SerialError>,
}

impl<Q: ByteQueue> PixelSink for Readback<Q> {
    fn pixels(&mut self, frame: u16, y: u16, x: u16, rgb: &[u8]) {
        if frame != self.bus_frame {
            self.dropped += 1;
            return;
        }
        for (k, run) in rgb.chunks(3 * MAX_RUN).enumerate() {
            let Ok(xk) = u16::try_from(x as usize + k * MAX_RUN) else {
                self.dropped += 1;
                return;
            };
            match self.streamer.run(y, xk, run, &mut self.enc, &mut self.buf) {
                Ok(n) => self.send(n),
                Err(_) => self.dropped += 1,
            }
        }
        let done = self.streamer.folded();
        if self.progress_every > 0 && done - self.last_progress >= self.progress_every {
            self.last_progress = done;
            if let Ok(n) = self.streamer.progress(done, &mut self.enc, &mut self.buf) {
                // Progress is advisory: skipped, not counted, when the queue is short.
                if self.queue.free() >= n {
                    self.send(n);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testkit::serial::read_back;

    struct VecQueue {
        bytes: Vec<u8>,
        cap: usize,
    }

    impl ByteQueue for VecQueue {
        fn free(&self) -> usize {
            self.cap - self.bytes.len()
        }
        fn push(&mut self, b: &[u8]) -> bool {
            if b.len() > self.free() {
                return false;
            }
            self.bytes.extend_from_slice(b);
            true
        }
    }

    #[test]
    fn bus_runs_become_serial_frames_in_any_order() {
        let (w, h) = (600usize, 3usize);
        let want: Vec<u8> = (0..3 * w * h).map(|i| (i % 251) as u8 / 4 * 4).collect();
        let q = VecQueue {
            bytes: Vec::new(),
            cap: 1 << 20,
        };
        let mut rb = Readback::new(q, Encoder::new(), 0, w as u16, h as u16).unwrap();
        rb.progress_every = w as u32;
        // Rows bottom first, each as a 512-pixel bus run and the rest.
        for y in (0..h).rev() {
            for (x, n) in [(0usize, 512usize), (512, w - 512)] {
                let at = 3 * (y * w + x);
                PixelSink::pixels(&mut rb, 0, y as u16, x as u16, &want[at..at + 3 * n]);
            }
        }
        assert_eq!(rb.streamed() as usize, w * h);
        let mut ended = rb.end();
        ended.result.expect("complete");
        // A FrameEnd asked for again carries the same CRC.
        let mut again = [0u8; MAX_TO_PC];
        let n = ended.streamer.end(&mut ended.enc, &mut again).unwrap();
        ended.queue.bytes.extend_from_slice(&again[..n]);
        let got = read_back(&ended.queue.bytes, w, h);
        assert_eq!(got.rgb, want);
        assert_eq!(got.ends.last(), Some(&wire::CRC32.checksum(&want)));
        assert!(got.progress >= 1);
    }

    #[test]
    fn a_full_queue_is_counted_and_the_frame_refused() {
        let q = VecQueue {
            bytes: Vec::new(),
            cap: 64,
        };
        let mut rb = Readback::new(q, Encoder::new(), 0, 300, 1).unwrap();
        // Incompressible: no run-length coding makes it fit.
        let rgb: Vec<u8> = (0..3 * 300).map(|i| (i * 7 % 256) as u8).collect();
        PixelSink::pixels(&mut rb, 0, 0, 0, &rgb);
        PixelSink::pixels(&mut rb, 1, 0, 0, &[7u8; 3]);
        assert!(
            rb.dropped >= 2,
            "a run that did not fit, a pixel of another frame"
        );
        assert!(rb.end().result.is_err());
    }

    #[test]
    fn reserve_covers_the_largest_bus_run() {
        let q = VecQueue {
            bytes: Vec::new(),
            cap: 1 << 16,
        };
        let mut rb = Readback::new(q, Encoder::new(), 0, 512, 2).unwrap();
        rb.progress_every = 1;
        let before = rb.queue.bytes.len();
        // Incompressible pixels: raw frames, the longest.
        let rgb: Vec<u8> = (0..3 * 512).map(|i| (i * 7 % 256) as u8).collect();
        PixelSink::pixels(&mut rb, 0, 1, 0, &rgb);
        assert!(rb.queue.bytes.len() - before <= RUN_RESERVE);
    }
}
