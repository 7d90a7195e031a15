//! The camera step: the view transform (LINKS-1 4.3: eye at the origin, X right, Y up, +Z
//! into the screen), the camera record, and the screen projection that gives every node its
//! screen rectangle (4.4).

use super::*;

/// The screen projection of view coordinates (pixel centres at integer + ½).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Projection {
    pub(super) x0: f64,
    pub(super) y0: f64,
    pub(super) dx: f64,
    pub(super) dy: f64,
    pub(super) width: u32,
    pub(super) height: u32,
    /// The first and last sub-sample offset within a pixel: ½ and ½ with one sample per
    /// pixel, 1/(2N) and 1 - 1/(2N) with N x N (primary rays pass through x + offset).
    pub(super) sample_lo: f64,
    pub(super) sample_hi: f64,
}

/// Slack in pixels added around projected extents, far above the rounding of a primary
/// ray's direction (~1e-4 px in f32), so clipping never drops a shape a ray can hit.
pub(super) const RECT_SLACK_PX: f64 = 0.05;

impl Projection {
    pub(super) fn full(&self) -> Rect {
        Rect {
            x_lo: 0,
            x_hi: (self.width - 1) as u16,
            y_lo: 0,
            y_hi: (self.height - 1) as u16,
        }
    }

    /// Pixels whose primary ray can meet the convex hull of `pts` (view coordinates).
    pub(super) fn rect_of(&self, pts: &[[f64; 3]]) -> Rect {
        // Primary rays have z > 0 everywhere: nothing entirely behind the eye is visible.
        if pts.iter().all(|p| p[2] <= 0.0) {
            return Rect::EMPTY;
        }
        // A hull that reaches the eye's plane projects without bound.
        let near = 1e-9
            * pts
                .iter()
                .map(|p| p[0].abs().max(p[1].abs()).max(p[2].abs()))
                .fold(0.0, f64::max);
        if pts.iter().any(|p| p[2] <= near) {
            return self.full();
        }
        let (mut sx0, mut sx1, mut sy0, mut sy1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in pts {
            // Continuous screen coordinates: pixel x's centre is at x + ½.
            let sx = (p[0] / p[2] - self.x0) / self.dx;
            let sy = (self.y0 - p[1] / p[2]) / self.dy;
            sx0 = sx0.min(sx);
            sx1 = sx1.max(sx);
            sy0 = sy0.min(sy);
            sy1 = sy1.max(sy);
        }
        // Pixel x holds the extent [s0, s1] when one of its rays, through x + o for o in
        // [sample_lo, sample_hi], can fall inside it: x in [s0 - sample_hi, s1 - sample_lo].
        let (o_lo, o_hi) = (self.sample_lo, self.sample_hi);
        let lo = |v: f64, n: u32| ((v - o_hi - RECT_SLACK_PX).ceil().max(0.0)).min(n as f64) as i64;
        let hi = |v: f64, n: u32| {
            ((v - o_lo + RECT_SLACK_PX).floor().min(n as f64 - 1.0)).max(-1.0) as i64
        };
        let (xl, xh) = (lo(sx0, self.width), hi(sx1, self.width));
        let (yl, yh) = (lo(sy0, self.height), hi(sy1, self.height));
        if xl > xh || yl > yh {
            return Rect::EMPTY;
        }
        Rect {
            x_lo: xl as u16,
            x_hi: xh as u16,
            y_lo: yl as u16,
            y_hi: yh as u16,
        }
    }

    pub(super) fn rect_of_bounds(&self, b: &Bounds) -> Rect {
        if b.is_empty() {
            return Rect::EMPTY;
        }
        let mut pts = [[0.0; 3]; 8];
        for (k, p) in pts.iter_mut().enumerate() {
            for (a, c) in p.iter_mut().enumerate() {
                *c = f64::from(if k >> a & 1 == 0 { b.min[a] } else { b.max[a] });
            }
        }
        self.rect_of(&pts)
    }
}

impl Dm<'_> {
    /// The view transform and the camera record (pixel centres on the z = 1 plane); sets
    /// the projection the screen rectangles use.
    pub(super) fn camera(
        &mut self,
        width: u32,
        height: u32,
        max_depth: u32,
        mode: TransparencyMode,
    ) -> Result<Affine, DmError> {
        let d = self.desc;
        // View transform: rows are the screen's right, up and forward axes in world space.
        let cam = &d.camera;
        let fwd = normalize(sub(cam.look_at, cam.eye))
            .ok_or_else(|| DmError::DegenerateCamera("eye and look_at coincide".into()))?;
        let right = normalize(cross(fwd, cam.up)).ok_or_else(|| {
            DmError::DegenerateCamera("up is parallel to the view direction".into())
        })?;
        let up = cross(right, fwd);
        let rot = [right, up, fwd];
        let view = Affine {
            a: rot,
            t: mat_vec(&rot, cam.eye).map(|v| -v),
        };
        if !(cam.fov_y_deg > 0.0 && cam.fov_y_deg < 180.0) {
            return Err(DmError::DegenerateCamera(format!(
                "fov_y {} not in (0, 180)",
                cam.fov_y_deg
            )));
        }

        // Validated by `run` (1..=MAX_AA).
        let aa = self.opts.aa.unwrap_or(1).clamp(1, camera::MAX_AA);
        // Camera record: pixel centres on the z = 1 plane.
        let tan_half = (cam.fov_y_deg.to_radians() * 0.5).tan();
        let dy = 2.0 * tan_half / height as f64;
        let dx = dy;
        let x0 = -dx * width as f64 * 0.5;
        // Project with the values the renderer will use (rounded to f32).
        self.proj = Projection {
            x0: f64::from(x0 as f32),
            y0: f64::from(tan_half as f32),
            dx: f64::from(dx as f32),
            dy: f64::from(dy as f32),
            width,
            height,
            sample_lo: 0.5 / f64::from(aa),
            sample_hi: 1.0 - 0.5 / f64::from(aa),
        };
        let flags = u32::from(mode == TransparencyMode::NonRefractive)
            | (u32::from(self.opts.no_shadows) << 1)
            | ((aa - 1) << camera::AA_SHIFT);
        self.w
            .push(Section::Camera)
            .1
            .u(camera::WIDTH, width)
            .u(camera::HEIGHT, height)
            .f(camera::X0, x0 as f32)
            .f(camera::Y0, tan_half as f32)
            .f(camera::DX, dx as f32)
            .f(camera::DY, dy as f32)
            .fs(camera::BACKGROUND, &d.background)
            .fs(camera::AMBIENT, &d.ambient)
            .u(camera::MAX_DEPTH, max_depth)
            .u(camera::FLAGS, flags)
            .f(camera::DZ, 1.0);
        Ok(view)
    }
}
