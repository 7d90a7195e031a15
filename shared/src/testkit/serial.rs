//! Serial readback as the PC decodes it, for tests that check what the RC sent.

use crate::serial::{pixel_count, pixels_into, Decoder, Packet, ToPc, MAX_TO_PC};

/// What the RC sent, decoded ([`read_back`]).
#[derive(Clone, Debug, Default)]
pub struct ReadBack {
    /// The frame's RGB8 pixels (rows top first; zero where nothing arrived).
    pub rgb: Vec<u8>,
    /// The CRC of every `FrameEnd`, in order.
    pub ends: Vec<u32>,
    /// Pixel messages.
    pub runs: usize,
    /// Progress messages.
    pub progress: usize,
}

/// Decode the RC's bytes of a `w` x `h` frame. Panics on an invalid frame, a header of
/// other dimensions or a message a readback does not carry.
pub fn read_back(bytes: &[u8], w: usize, h: usize) -> ReadBack {
    let mut dec = Decoder::<MAX_TO_PC>::new();
    let mut out = ReadBack {
        rgb: vec![0u8; 3 * w * h],
        ..ReadBack::default()
    };
    for &b in bytes {
        let Some(r) = dec.feed::<ToPc>(b) else {
            continue;
        };
        let p: Packet<ToPc> = r.expect("every frame the RC sends is valid");
        match p.msg {
            ToPc::Pixels { y, x, .. } | ToPc::PixelsRle { y, x, .. } => {
                let at = 3 * (y as usize * w + x as usize);
                let n = pixel_count(&p.msg);
                pixels_into(&p.msg, &mut out.rgb[at..at + 3 * n]).expect("pixels decode");
                out.runs += 1;
            }
            ToPc::FrameEnd { crc, .. } => out.ends.push(crc),
            ToPc::Progress { .. } => out.progress += 1,
            ToPc::FrameHeader { width, height, .. } => {
                assert_eq!((width as usize, height as usize), (w, h))
            }
            other => panic!("unexpected {other:?}"),
        }
    }
    out
}
