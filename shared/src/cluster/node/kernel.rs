//! Which tracing kernel a node runs: the one the SceneImage it receives is stored for.
//!
//! An f32 image is traced by `Tracer<f32>`, a Q16.16 image (the DM's fixed-point rewrite) by
//! `Tracer<Fx>`: the DM decides the number format, the node follows it. A node carries
//! one kernel ([`Tracing<f32>`] or [`Tracing<Fx>`], the smaller firmware) or both
//! ([`TracingByImage`]); [`RunRenderer::kernels`] says which, and `run_node` stops with
//! [`super::NodeError::NoKernel`] when a scene arrives that none of them reads.

use super::RunRenderer;
use crate::image::SceneView;
use crate::num::{Fx, Real, Storage};
use crate::render::{render_run, RenderError, Rgb8, SceneKey, Stats, Techniques};
use crate::render::{Tracer, TracerState};
use core::fmt;

/// The kernels a node carries, named by the image storage each reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kernels {
    /// `Tracer<f32>` only (hard-float on the Cortex-M4F, soft-float on the M3).
    F32,
    /// `Tracer<Fx>` (Q16.16) only.
    Fixed,
    /// Both: the image picks.
    Both,
}

impl Kernels {
    /// Whether one of these kernels reads an image stored as `storage`.
    pub const fn run(self, storage: Storage) -> bool {
        matches!(
            (self, storage),
            (Kernels::Both, _) | (Kernels::F32, Storage::F32) | (Kernels::Fixed, Storage::Q16_16)
        )
    }

    /// The single kernel of number type `T`.
    pub const fn of<T: Real>() -> Kernels {
        match T::STORAGE {
            Storage::F32 => Kernels::F32,
            Storage::Q16_16 => Kernels::Fixed,
        }
    }

    /// The set in words (`links render --node-kernels`).
    pub const fn name(self) -> &'static str {
        match self {
            Kernels::F32 => "f32",
            Kernels::Fixed => "fixed",
            Kernels::Both => "both",
        }
    }
}

impl fmt::Display for Kernels {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Kernels::F32 => "the f32 kernel",
            Kernels::Fixed => "the Q16.16 kernel",
            Kernels::Both => "the f32 and Q16.16 kernels",
        })
    }
}

/// The real renderer of one kernel: a [`Tracer`] in number type `T`, working in one
/// [`TracerState`] it keeps from run to run (its caches stay warm while the scene stays the
/// same). It reads images stored for `T` only ([`Kernels::of`]).
pub struct Tracing<T: Real> {
    state: TracerState<T>,
}

impl<T: Real> Default for Tracing<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> Tracing<T> {
    pub fn new() -> Self {
        Self {
            state: TracerState::new(),
        }
    }
}

/// A number type a node kernel runs in, with its run entry instantiated here, in links-core:
/// [`Tracing`]`<T>` calls it instead of instantiating the tracer in the firmware's crate. Two
/// crates that both instantiate `Tracer<Fx, _>` (the firmware through `Tracing<Fx>`, this one
/// through [`TracingByImage`]) each carry a copy of the kernel, and LLVM linked calls across
/// the two: the G0B1 node's flash held the shading, shadow and shape code twice (two
/// `intersect_shape` of ~40 KB each).
pub trait KernelNumber: Real {
    fn trace_run(
        state: &mut TracerState<Self>,
        scene: SceneView<'_>,
        frame: u16,
        at: (u32, u32),
        out: &mut [Rgb8],
    ) -> Result<Stats, RenderError>;
}

/// One non-generic entry per number type, each instantiating the tracer here in links-core.
macro_rules! kernel_number {
    ($($t:ty),*) => {$(
        impl KernelNumber for $t {
            fn trace_run(
                state: &mut TracerState<$t>,
                scene: SceneView<'_>,
                frame: u16,
                at: (u32, u32),
                out: &mut [Rgb8],
            ) -> Result<Stats, RenderError> {
                trace_run(state, scene, frame, at, out)
            }
        }
    )*};
}
kernel_number!(f32, Fx);

/// One run with `state`'s tracer (all techniques).
fn trace_run<T: Real>(
    state: &mut TracerState<T>,
    scene: SceneView<'_>,
    frame: u16,
    (y, x): (u32, u32),
    out: &mut [Rgb8],
) -> Result<Stats, RenderError> {
    let key = SceneKey::of(&scene, frame);
    let mut t = Tracer::with_state(scene, Techniques::ALL, state, key);
    render_run(&mut t, y, x, out)?;
    Ok(t.stats)
}

impl<T: KernelNumber> RunRenderer for Tracing<T> {
    fn render(
        &mut self,
        scene: SceneView<'_>,
        frame: u16,
        y: u32,
        x: u32,
        out: &mut [Rgb8],
    ) -> Result<Stats, RenderError> {
        T::trace_run(&mut self.state, scene, frame, (y, x), out)
    }

    fn kernels(&self) -> Kernels {
        Kernels::of::<T>()
    }

    fn forget(&mut self) {
        self.state.forget();
    }
}

/// Both kernels, one state: the state of the kernel the last image needed (a node renders
/// one image storage at a time, so the RAM is that of one [`TracerState`]; a scene of the
/// other storage starts the other kernel with empty caches).
pub enum TracingByImage {
    F32(TracerState<f32>),
    Fixed(TracerState<Fx>),
}

impl Default for TracingByImage {
    fn default() -> Self {
        TracingByImage::F32(TracerState::new())
    }
}

impl RunRenderer for TracingByImage {
    fn render(
        &mut self,
        scene: SceneView<'_>,
        frame: u16,
        y: u32,
        x: u32,
        out: &mut [Rgb8],
    ) -> Result<Stats, RenderError> {
        match (scene.storage(), &mut *self) {
            (Storage::F32, TracingByImage::F32(s)) => f32::trace_run(s, scene, frame, (y, x), out),
            (Storage::Q16_16, TracingByImage::Fixed(s)) => {
                Fx::trace_run(s, scene, frame, (y, x), out)
            }
            (Storage::F32, TracingByImage::Fixed(_)) => {
                *self = TracingByImage::F32(TracerState::new());
                self.render(scene, frame, y, x, out)
            }
            (Storage::Q16_16, TracingByImage::F32(_)) => {
                *self = TracingByImage::Fixed(TracerState::new());
                self.render(scene, frame, y, x, out)
            }
        }
    }

    fn kernels(&self) -> Kernels {
        Kernels::Both
    }

    fn forget(&mut self) {
        match self {
            TracingByImage::F32(s) => s.forget(),
            TracingByImage::Fixed(s) => s.forget(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed_image::to_fixed;
    use crate::testkit::scene::tiny_image;

    #[test]
    fn a_kernel_set_runs_exactly_its_storages() {
        use Storage::{F32, Q16_16};
        let runs = |k: Kernels| [k.run(F32), k.run(Q16_16)];
        assert_eq!(runs(Kernels::F32), [true, false]);
        assert_eq!(runs(Kernels::Fixed), [false, true]);
        assert_eq!(runs(Kernels::Both), [true, true]);
        assert_eq!(Kernels::of::<f32>(), Kernels::F32);
        assert_eq!(Kernels::of::<f64>(), Kernels::F32);
        assert_eq!(Kernels::of::<Fx>(), Kernels::Fixed);
    }

    /// Every pixel of `image`'s frame, one row-run at a time, through `r`.
    fn frame(r: &mut impl RunRenderer, image: &[u8], frame: u16) -> Vec<Rgb8> {
        let view = SceneView::new(image).expect("valid image");
        let c = view.camera::<f32>();
        let mut px = vec![[0u8; 3]; (c.width * c.height) as usize];
        for (y, row) in px.chunks_mut(c.width as usize).enumerate() {
            r.render(view, frame, y as u32, 0, row)
                .expect("run inside the frame");
        }
        px
    }

    /// Switching storages back and forth gives each image the pixels of its own kernel and
    /// keeps the state of the last one (tests/tests/fuzz.rs runs it on photo1, whose two
    /// kernels' pixels differ).
    #[test]
    fn tracing_by_image_renders_each_image_with_its_own_kernel() {
        let f = tiny_image(8, &[(1, 0)]);
        let q = to_fixed(&f).expect("the tiny scene fits Q16.16").bytes;
        let want_f = frame(&mut Tracing::<f32>::new(), &f, 0);
        let want_q = frame(&mut Tracing::<Fx>::new(), &q, 0);
        let mut both = TracingByImage::default();
        assert_eq!(frame(&mut both, &q, 0), want_q);
        assert!(matches!(both, TracingByImage::Fixed(_)));
        assert_eq!(frame(&mut both, &f, 1), want_f);
        assert_eq!(frame(&mut both, &q, 2), want_q);
        assert_eq!(both.kernels(), Kernels::Both);
    }
}
