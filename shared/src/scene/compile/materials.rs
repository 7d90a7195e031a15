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
            let off = self.w.push_texels(&t.rgb);
            self.w
                .push(Section::Textures)
                .1
                .u(texture::WIDTH, t.width)
                .u(texture::HEIGHT, t.height)
                .u(texture::TEXELS, off);
        }
        Ok(())
    }

    pub(super) fn material(&mut self, m: &desc::Material) -> Result<(), DmError> {
        let (tex, target, scale) = match &m.map {
            Some(map) => {
                if map.texture as usize >= self.desc.textures.len() {
                    return Err(DmError::BadIndex {
                        what: format!("material '{}' uses missing texture {}", m.name, map.texture),
                    });
                }
                (map.texture, map.target as u32, map.scale)
            }
            None => (NONE, 0, [1.0, 1.0]),
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
            .u(material::TARGET, target)
            .fs(material::SCALE, &scale);
        Ok(())
    }
}
