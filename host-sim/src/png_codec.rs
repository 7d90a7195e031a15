//! PNG encoding for the host: one encoder behind every PNG the host writes (rendered frames,
//! read-back frames, the generated floor texture, the test textures). The png crate's default
//! (balanced) compression and adaptive filter, so the bytes are reproducible.

pub use png::{BitDepth, ColorType, EncodingError};

/// A PNG of `data` (rows top to bottom, `color`/`depth` samples, `palette` for indexed colour).
pub fn encode(
    width: u32,
    height: u32,
    color: ColorType,
    depth: BitDepth,
    palette: Option<&[u8]>,
    data: &[u8],
) -> Result<Vec<u8>, EncodingError> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_color(color);
        enc.set_depth(depth);
        if let Some(p) = palette {
            enc.set_palette(p.to_vec());
        }
        let mut writer = enc.write_header()?;
        writer.write_image_data(data)?;
        writer.finish()?;
    }
    Ok(out)
}

/// An 8-bit RGB PNG of `rgb` (`width * height * 3` bytes, rows top to bottom).
pub fn encode_rgb8(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, EncodingError> {
    encode(width, height, ColorType::Rgb, BitDepth::Eight, None, rgb)
}

/// An animated PNG (APNG) of 8-bit RGB frames, written one frame at a time so a film never
/// has to be held in memory. Every frame covers the whole canvas; the file loops forever.
/// Viewers without APNG support show the first frame.
pub struct ApngWriter<W: std::io::Write> {
    writer: png::Writer<W>,
}

impl<W: std::io::Write> ApngWriter<W> {
    /// Starts a film of `frames` frames of `width` x `height`, played at `rate` frames per
    /// second (the delay is stored as 100 / round(100 rate) s, so rates to 0.01 are exact).
    pub fn new(
        out: W,
        width: u32,
        height: u32,
        frames: u32,
        rate: f64,
    ) -> Result<Self, EncodingError> {
        let mut enc = png::Encoder::new(out, width, height);
        enc.set_color(ColorType::Rgb);
        enc.set_depth(BitDepth::Eight);
        enc.set_animated(frames, 0)?;
        enc.set_frame_delay(100, frame_delay_den(rate))?;
        let writer = enc.write_header()?;
        Ok(Self { writer })
    }

    /// The next frame: `width * height * 3` bytes, rows top to bottom.
    pub fn frame(&mut self, rgb: &[u8]) -> Result<(), EncodingError> {
        self.writer.write_image_data(rgb)
    }

    /// Ends the file (every announced frame must have been written).
    pub fn finish(self) -> Result<(), EncodingError> {
        self.writer.finish()
    }
}

/// The denominator of a `100 / den` s frame delay for `rate` frames per second, within u16.
fn frame_delay_den(rate: f64) -> u16 {
    let den = (rate * 100.0).round();
    if den.is_nan() || den < 1.0 {
        1
    } else {
        den.min(f64::from(u16::MAX)) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_apng_holds_every_frame_in_order() {
        let frames: Vec<Vec<u8>> = (0..3u8).map(|i| vec![i * 40; 2 * 2 * 3]).collect();
        let mut out = Vec::new();
        let mut w = ApngWriter::new(&mut out, 2, 2, 3, 12.0).unwrap();
        for f in &frames {
            w.frame(f).unwrap();
        }
        w.finish().unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(out))
            .read_info()
            .unwrap();
        let ctl = reader.info().animation_control.unwrap();
        assert_eq!((ctl.num_frames, ctl.num_plays), (3, 0));
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        for f in &frames {
            reader.next_frame(&mut buf).unwrap();
            let fc = reader.info().frame_control.unwrap();
            assert_eq!((fc.delay_num, fc.delay_den), (100, 1200));
            assert_eq!(&buf[..12], &f[..]);
        }
    }

    #[test]
    fn frame_delays_stay_within_u16() {
        assert_eq!(frame_delay_den(24.0), 2400);
        assert_eq!(frame_delay_den(29.97), 2997);
        assert_eq!(frame_delay_den(1e9), u16::MAX);
        assert_eq!(frame_delay_den(0.001), 1);
    }
}
