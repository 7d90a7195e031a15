//! The lights step: each light carried into view coordinates.

use super::*;

impl Dm<'_> {
    pub(super) fn light(&mut self, l: &Light, view: &Affine) -> Result<(), DmError> {
        let dir_of = |d: [f64; 3]| {
            normalize(mat_vec(&view.a, d))
                .ok_or_else(|| DmError::BadSetting("light direction is zero".into()))
        };
        let (kind, color, pos, dir, ci, co, e, fall) = match l {
            Light::Directional { dir, color } => {
                (0, color, [0.0; 3], dir_of(*dir)?, 1.0, 1.0, 0.0, false)
            }
            Light::Point {
                pos,
                color,
                falloff,
            } => (
                1,
                color,
                view.point(*pos),
                [0.0; 3],
                1.0,
                1.0,
                0.0,
                *falloff,
            ),
            Light::Spot {
                pos,
                dir,
                color,
                inner_deg,
                outer_deg,
                exponent,
            } => (
                2,
                color,
                view.point(*pos),
                dir_of(*dir)?,
                inner_deg.to_radians().cos(),
                outer_deg.to_radians().cos(),
                *exponent,
                false,
            ),
        };
        self.w
            .push(Section::Lights)
            .1
            .u(light::KIND, kind)
            .fs(light::COLOR, color)
            .fs(light::POS, &f32s(pos))
            .fs(light::DIR, &f32s(dir))
            .f(light::COS_INNER, ci as f32)
            .f(light::COS_OUTER, co as f32)
            .f(light::EXPONENT, e)
            .u(light::FALLOFF, u32::from(fall));
        Ok(())
    }
}
