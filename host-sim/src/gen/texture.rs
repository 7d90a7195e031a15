//! The floor texture (the "mapped floor" of LINKS-1's Photo 2) and a PNG encoder.
//!
//! A 4 x 4 checker of cream marble and terracotta tiles with grey grout lines, a little
//! per-tile tone variation, soft mottling and per-pixel grain. It repeats seamlessly (grout
//! lines are centred on the image edges and every noise term wraps with the image), so a scene
//! can tile it across a large floor. Deterministic: the "randomness" is an integer hash.

/// Tiles along each side of the texture.
pub const FLOOR_TILES: u32 = 4;

/// A 32-bit integer hash (the "lowbias32" finaliser), for deterministic noise.
fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// A hash of a lattice point (with a salt) in [0, 1).
fn hash01(x: u32, y: u32, salt: u32) -> f64 {
    let h =
        hash(x.wrapping_mul(0x9e37_79b9) ^ hash(y.wrapping_add(salt.wrapping_mul(0x85eb_ca6b))));
    (h >> 8) as f64 / (1u32 << 24) as f64
}

/// Smooth value noise with `cells` lattice cells across `[0, 1)`, wrapping at 1.
fn value_noise(u: f64, v: f64, cells: u32, salt: u32) -> f64 {
    let (x, y) = (u * cells as f64, v * cells as f64);
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let c = |i: f64, j: f64| {
        let wrap = |k: f64| (k as i64).rem_euclid(cells as i64) as u32;
        hash01(wrap(i), wrap(j), salt)
    };
    let a = c(xi, yi) + (c(xi + 1.0, yi) - c(xi, yi)) * sx;
    let b = c(xi, yi + 1.0) + (c(xi + 1.0, yi + 1.0) - c(xi, yi + 1.0)) * sx;
    a + (b - a) * sy
}

/// The floor texture: `w x h` RGB8 pixels, row-major, top row first.
pub fn floor_texture(w: u32, h: u32) -> Vec<u8> {
    let mut out = Vec::with_capacity(w as usize * h as usize * 3);
    let cream = [226.0, 214.0, 192.0];
    let terracotta = [158.0, 84.0, 58.0];
    let grout = [92.0, 90.0, 86.0];
    for py in 0..h {
        for px in 0..w {
            // Position in tiles, at the pixel centre.
            let u = (px as f64 + 0.5) / w as f64;
            let v = (py as f64 + 0.5) / h as f64;
            let (tx, ty) = (u * FLOOR_TILES as f64, v * FLOOR_TILES as f64);
            let (ix, iy) = (tx.floor() as u32, ty.floor() as u32);
            let (fx, fy) = (tx - tx.floor(), ty - ty.floor());
            // Distance to the nearest tile edge, in tiles.
            let edge = fx.min(1.0 - fx).min(fy).min(1.0 - fy);
            let grout_half = 0.022;
            let grain = hash01(px, py, 7) - 0.5;
            let rgb = if edge < grout_half {
                let g = 1.0 + 0.08 * grain;
                grout.map(|c| c * g)
            } else {
                let dark = (ix + iy) % 2 == 1;
                let base = if dark { terracotta } else { cream };
                // Per-tile tone, soft mottling (marble-ish veins on the light tiles),
                // grain, and a slight darkening towards the bevelled tile edges.
                let tone = 1.0 + 0.07 * (hash01(ix, iy, 3) - 0.5);
                let mottle = value_noise(u, v, 16, 11 + dark as u32) - 0.5;
                let vein = if dark {
                    0.0
                } else {
                    let n = value_noise(u, v, 8, 21) + 0.5 * value_noise(u, v, 32, 22);
                    let s = (n * 9.0).fract();
                    let d = s.min(1.0 - s);
                    (0.08 - d).max(0.0) * -1.1
                };
                let bevel = ((edge - grout_half) / 0.03).min(1.0);
                let shade =
                    tone * (1.0 + 0.10 * mottle + 0.05 * grain + vein) * (0.88 + 0.12 * bevel);
                base.map(|c| c * shade)
            };
            for c in rgb {
                out.push(c.round().clamp(0.0, 255.0) as u8);
            }
        }
    }
    out
}

/// Encodes `w x h` RGB8 pixels as a PNG file.
pub fn encode_png(w: u32, h: u32, rgb: &[u8]) -> Result<Vec<u8>, png::EncodingError> {
    crate::png_codec::encode_rgb8(w, h, rgb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_texture_size_and_determinism() {
        let t = floor_texture(64, 32);
        assert_eq!(t.len(), 64 * 32 * 3);
        assert_eq!(t, floor_texture(64, 32));
    }

    #[test]
    fn floor_texture_is_two_tone_with_grout() {
        let (w, h) = (256u32, 256u32);
        let t = floor_texture(w, h);
        let px = |x: u32, y: u32| {
            let i = ((y * w + x) * 3) as usize;
            [t[i], t[i + 1], t[i + 2]]
        };
        let luma = |p: [u8; 3]| p[0] as u32 + p[1] as u32 + p[2] as u32;
        // Centres of tile (0, 0) (light) and (1, 0) (dark), and a grout line between them.
        let light = px(32, 32);
        let dark = px(96, 32);
        let grout = px(64, 32);
        assert!(luma(light) > luma(dark) + 150, "{light:?} vs {dark:?}");
        assert!(dark[0] > dark[2] + 40, "terracotta is reddish: {dark:?}");
        assert!(luma(grout) < luma(light) && grout != dark, "{grout:?}");
        // Seamless: the left and right columns (and top and bottom rows) are both grout.
        for k in [0, 100, 200] {
            assert!(luma(px(0, k)) < 300 && luma(px(w - 1, k)) < 300);
            assert!(luma(px(k, 0)) < 300 && luma(px(k, h - 1)) < 300);
        }
        // Not flat: some variation inside one tile.
        let mut vals: Vec<u32> = (10..50).map(|x| luma(px(x, 20))).collect();
        vals.dedup();
        assert!(vals.len() > 5);
    }

    #[test]
    fn png_round_trip() {
        let (w, h) = (256, 128);
        let rgb = floor_texture(w, h);
        let bytes = encode_png(w, h, &rgb).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        assert_eq!(&bytes[12..16], b"IHDR");
        assert_eq!(u32::from_be_bytes(bytes[16..20].try_into().unwrap()), w);
        assert_eq!(u32::from_be_bytes(bytes[20..24].try_into().unwrap()), h);
        let decoder = png::Decoder::new(std::io::Cursor::new(&bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (w, h));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        assert_eq!(&buf[..info.buffer_size()], &rgb[..]);
        assert!(encode_png(w, h, &rgb[..10]).is_err());
    }
}
