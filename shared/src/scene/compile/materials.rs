//! The textures and materials steps: texture headers and texels, then each material with
//! its texture mapping.

use super::*;

impl Dm<'_> {
    /// Every texture's header and texels (the byte count checked in u32: the image's texel
    /// section counts bytes in u32).
    pub(super) fn textures(&mut self) -> Result<(), DmError> {
        for (i, t) in self.desc.textures.iter().enumerate() {
            let bytes = t.width.checked_mul(t.height).and_then(|n| n.checked_mul(3));
            if t.width == 0 || t.height == 0 || bytes.map(|n| n as usize) != Some(t.rgb.len()) {
                return Err(DmError::BadIndex {
                    what: format!("texture {i} ('{}') has a bad size", t.name),
                });
            }
            // A palette and one byte per texel when the texture has at most 256 colours
            // (lossless); RGB8 texels otherwise.
            let (off, palette) = match palette_of(&t.rgb) {
                Some((colours, indices)) => {
                    let off = self.w.push_texels(&colours);
                    self.w.push_texels(&indices);
                    (off, (colours.len() / 3) as u32)
                }
                None => (self.w.push_texels(&t.rgb), 0),
            };
            self.w
                .push(Section::Textures)
                .1
                .u(texture::WIDTH, t.width)
                .u(texture::HEIGHT, t.height)
                .u(texture::TEXELS, off)
                .u(texture::PALETTE, palette);
        }
        Ok(())
    }

    /// Materials are named by a byte in triangle leaves.
    pub(super) fn check_material_count(&self) -> Result<(), DmError> {
        if self.desc.materials.len() > 256 {
            return Err(DmError::TooLarge {
                what: format!(
                    "{} materials (a SceneImage holds at most 256)",
                    self.desc.materials.len()
                ),
            });
        }
        Ok(())
    }

    /// Every material, then the ambient records of those with their own ambient colour
    /// (see [`material::OWN_AMBIENT`]): material `i` keeps record `i`, so leaves and shapes
    /// name materials as before, and a scene without ambient colours gets the same bytes.
    pub(super) fn materials(&mut self) -> Result<(), DmError> {
        let d = self.desc;
        let mut next_ambient = d.materials.len();
        for m in &d.materials {
            let ambient = match m.ambient {
                Some(_) => {
                    let at = u16::try_from(next_ambient).map_err(|_| DmError::TooLarge {
                        what: format!("{} materials with ambient records", next_ambient),
                    })?;
                    next_ambient += 1;
                    Some(at)
                }
                None => None,
            };
            self.material(m, ambient)?;
        }
        for a in d.materials.iter().filter_map(|m| m.ambient) {
            self.w
                .push(Section::Materials)
                .1
                .fs(material::DIFFUSE, &a)
                .u(material::TEXTURE, NONE);
        }
        Ok(())
    }

    fn material(&mut self, m: &desc::Material, ambient: Option<u16>) -> Result<(), DmError> {
        let (tex, target, scale) = match &m.map {
            Some(map) => {
                if map.texture as usize >= self.desc.textures.len() {
                    return Err(DmError::BadIndex {
                        what: format!("material '{}' uses missing texture {}", m.name, map.texture),
                    });
                }
                (map.texture, map.target as u8, map.scale)
            }
            None => (NONE, 0, [1.0, 1.0]),
        };
        let flags = if ambient.is_some() {
            material::OWN_AMBIENT
        } else {
            0
        };
        self.w
            .push(Section::Materials)
            .1
            .fs(material::DIFFUSE, &m.diffuse)
            .f(material::SPECULAR, m.specular)
            .f(material::SPECULAR_EDGE, m.specular_edge)
            .f(material::SHININESS, m.shininess)
            .f(material::REFLECT, m.reflect)
            .f(material::REFLECT_EDGE, m.reflect_edge)
            .fs(material::TRANSMIT, &m.transmit)
            .f(material::IOR, m.ior)
            .u(material::TEXTURE, tex)
            .b(material::TARGET, target)
            .b(material::FLAGS, flags)
            .h(material::AMBIENT, ambient.unwrap_or(0))
            .fs(material::SCALE, &scale);
        Ok(())
    }
}

/// The texture as (palette RGB8 bytes in first-use order, one palette index per texel) when it
/// has at most [`texture::MAX_PALETTE`] colours.
pub(super) fn palette_of(rgb: &[u8]) -> Option<(Vec<u8>, Vec<u8>)> {
    let mut colours: Vec<[u8; 3]> = Vec::new();
    let mut index = std::collections::HashMap::new();
    let mut indices = Vec::with_capacity(rgb.len() / 3);
    for c in rgb.chunks_exact(3) {
        let c = [c[0], c[1], c[2]];
        let k = match index.get(&c) {
            Some(&k) => k,
            None => {
                if colours.len() == texture::MAX_PALETTE as usize {
                    return None;
                }
                colours.push(c);
                index.insert(c, (colours.len() - 1) as u8);
                (colours.len() - 1) as u8
            }
        };
        indices.push(k);
    }
    Some((colours.concat(), indices))
}
