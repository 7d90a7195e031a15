//! PNG textures -> RGB8 ([`desc::Texture`]).

use std::io::Cursor;

use links_core::desc::Texture;
use png::{BitDepth, ColorType, Decoder, Limits, Transformations};

use super::error::SceneError;
use super::values::MAX_IMAGE_SIDE;
use crate::limits::MAX_TEXTURE_DECODE_BYTES;

/// Decodes a PNG into RGB8, top row first. Palette and low-bit-depth images are expanded,
/// 16-bit samples are cut to 8 bits, grey is replicated into R, G and B, alpha is dropped
/// (not composited). Only the first frame of an animated PNG is used.
pub(crate) fn decode_png(bytes: &[u8], file: &str, name: &str) -> Result<Texture, SceneError> {
    let err = |message: String| SceneError::Png {
        file: file.to_string(),
        message,
    };
    // The decoder's own buffers are bounded; the output (at most MAX_IMAGE_SIDE² pixels, by
    // the check below) is allocated here.
    let mut decoder = Decoder::new_with_limits(
        Cursor::new(bytes),
        Limits {
            bytes: MAX_TEXTURE_DECODE_BYTES,
        },
    );
    decoder.set_transformations(Transformations::EXPAND | Transformations::STRIP_16);
    let (width, height) = {
        let info = decoder
            .read_header_info()
            .map_err(|e| err(format!("not a readable PNG: {e}")))?;
        info.size()
    };
    let max = MAX_IMAGE_SIDE as u32;
    if width == 0 || height == 0 || width > max || height > max {
        return Err(err(format!(
            "the texture is {width}x{height} pixels; at most {max}x{max} is supported"
        )));
    }
    let mut reader = decoder
        .read_info()
        .map_err(|e| err(format!("not a readable PNG: {e}")))?;
    let size = reader
        .output_buffer_size()
        .filter(|&n| n <= MAX_TEXTURE_DECODE_BYTES)
        .ok_or_else(|| err("the image is too large to decode".to_string()))?;
    let mut buf = vec![0u8; size];
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|e| err(format!("corrupt PNG data: {e}")))?;
    if frame.bit_depth != BitDepth::Eight {
        return Err(err(format!(
            "unexpected sample depth {:?} after expansion",
            frame.bit_depth
        )));
    }
    let channels = match frame.color_type {
        ColorType::Grayscale => 1,
        ColorType::GrayscaleAlpha => 2,
        ColorType::Rgb => 3,
        ColorType::Rgba => 4,
        ColorType::Indexed => {
            return Err(err("palette image was not expanded".to_string()));
        }
    };
    let (w, h) = (frame.width as usize, frame.height as usize);
    let mut rgb = Vec::with_capacity(w * h * 3);
    for row in buf.chunks(frame.line_size).take(h) {
        for px in row[..w * channels].chunks_exact(channels) {
            match channels {
                1 | 2 => rgb.extend_from_slice(&[px[0], px[0], px[0]]),
                _ => rgb.extend_from_slice(&px[..3]),
            }
        }
    }
    Ok(Texture {
        name: name.to_string(),
        width: frame.width,
        height: frame.height,
        rgb,
    })
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Encodes a PNG in memory.
    pub(in super::super) fn encode_png(
        width: u32,
        height: u32,
        color: ColorType,
        depth: BitDepth,
        palette: Option<&[u8]>,
        data: &[u8],
    ) -> Vec<u8> {
        crate::png_codec::encode(width, height, color, depth, palette, data).unwrap()
    }

    #[test]
    fn rgb8_rgba8_grey_palette_16bit() {
        // 2x1 RGB
        let png = encode_png(
            2,
            1,
            ColorType::Rgb,
            BitDepth::Eight,
            None,
            &[1, 2, 3, 4, 5, 6],
        );
        let t = decode_png(&png, "a.png", "a").unwrap();
        assert_eq!(
            (t.width, t.height, t.rgb.clone()),
            (2, 1, vec![1, 2, 3, 4, 5, 6])
        );

        // 1x2 RGBA: alpha dropped, top row first
        let png = encode_png(
            1,
            2,
            ColorType::Rgba,
            BitDepth::Eight,
            None,
            &[10, 20, 30, 0, 40, 50, 60, 255],
        );
        let t = decode_png(&png, "b.png", "b").unwrap();
        assert_eq!(t.rgb, vec![10, 20, 30, 40, 50, 60]);

        // grey and grey+alpha
        let png = encode_png(2, 1, ColorType::Grayscale, BitDepth::Eight, None, &[7, 200]);
        assert_eq!(
            decode_png(&png, "g.png", "g").unwrap().rgb,
            vec![7, 7, 7, 200, 200, 200]
        );
        let png = encode_png(
            1,
            1,
            ColorType::GrayscaleAlpha,
            BitDepth::Eight,
            None,
            &[9, 1],
        );
        assert_eq!(decode_png(&png, "ga.png", "ga").unwrap().rgb, vec![9, 9, 9]);

        // 1-bit grey expands to 0/255
        let png = encode_png(
            3,
            1,
            ColorType::Grayscale,
            BitDepth::One,
            None,
            &[0b1010_0000],
        );
        assert_eq!(
            decode_png(&png, "g1.png", "g1").unwrap().rgb,
            vec![255, 255, 255, 0, 0, 0, 255, 255, 255]
        );

        // 2-bit palette
        let pal = [255, 0, 0, 0, 255, 0, 0, 0, 255];
        let png = encode_png(
            3,
            1,
            ColorType::Indexed,
            BitDepth::Two,
            Some(&pal),
            &[0b0001_1000],
        );
        assert_eq!(
            decode_png(&png, "p.png", "p").unwrap().rgb,
            vec![255, 0, 0, 0, 255, 0, 0, 0, 255]
        );

        // 16-bit RGB: high bytes kept
        let png = encode_png(
            1,
            1,
            ColorType::Rgb,
            BitDepth::Sixteen,
            None,
            &[0x12, 0x34, 0xab, 0xcd, 0xff, 0x00],
        );
        assert_eq!(
            decode_png(&png, "w.png", "w").unwrap().rgb,
            vec![0x12, 0xab, 0xff]
        );
    }

    #[test]
    fn bad_and_oversized_png() {
        let e = decode_png(b"not a png", "x.png", "x").unwrap_err();
        assert!(matches!(e, SceneError::Png { .. }));
        assert!(
            e.to_string().starts_with("x.png: not a readable PNG"),
            "{e}"
        );

        let png = encode_png(
            4097,
            1,
            ColorType::Grayscale,
            BitDepth::One,
            None,
            &[0; 513],
        );
        let e = decode_png(&png, "big.png", "big").unwrap_err();
        assert!(e.to_string().contains("4097x1"), "{e}");
    }
}
