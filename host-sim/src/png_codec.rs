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
