//! Rendering one picture on a single host (no cluster): the core's per-run renderer over
//! every scanline, spread over host threads. Rows are independent and the statistics are sums, so the image
//! and the counts never depend on the thread count.

use links_core::fixed_image::{to_fixed, FixedError};
use links_core::image::{ImageError, SceneView};
use links_core::num::Real;
use links_core::num::{Fx, Storage};
use links_core::render::{render_run, SceneKey, Stats, Techniques, Tracer, TracerState};
use rayon::prelude::*;
use std::fmt;
use std::time::{Duration, Instant};

/// The number type a render computes with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Precision {
    #[default]
    F32,
    F64,
    /// Q16.16 fixed point on an image the DM rescaled to fit the format.
    Fixed,
}

impl Precision {
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
            Precision::Fixed => "q16.16",
        }
    }
}

impl std::str::FromStr for Precision {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "f32" => Ok(Precision::F32),
            "f64" => Ok(Precision::F64),
            "fixed" | "q16.16" => Ok(Precision::Fixed),
            other => Err(format!(
                "unknown precision '{other}' (expected f32, f64 or fixed)"
            )),
        }
    }
}

/// One rendered picture: RGB8 rows, top first.
#[derive(Clone, Debug)]
pub struct FrameImage {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
    pub stats: Stats,
    pub elapsed: Duration,
}

/// Why [`render_single`] could not render a picture.
#[derive(Debug)]
pub enum FrameError {
    Image(ImageError),
    Fixed(FixedError),
    Threads(String),
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::Image(e) => write!(f, "{e}"),
            FrameError::Fixed(e) => write!(f, "scene does not fit fixed point: {e}"),
            FrameError::Threads(e) => write!(f, "cannot start render threads: {e}"),
        }
    }
}

impl std::error::Error for FrameError {}

/// `image` as the fixed-point kernel reads it: the DM's Q16.16 rewrite of an f32 image, an
/// image that already stores Q16.16 as it is (what the cluster sends nodes computing in
/// fixed point, the same bytes [`render_single`] renders with [`Precision::Fixed`]).
pub fn fixed_image(image: &[u8]) -> Result<Vec<u8>, FrameError> {
    match SceneView::new(image).map_err(FrameError::Image)?.storage() {
        Storage::F32 => Ok(to_fixed(image).map_err(FrameError::Fixed)?.bytes),
        Storage::Q16_16 => Ok(image.to_vec()),
    }
}

/// [`render_single`]'s former name, kept for its callers.
pub use render_single as render_frame;

/// Render every pixel of a SceneImage. An f32 image renders in any precision (the
/// fixed-point backend renders the DM's Q16.16 rewrite of it); an image that already stores
/// Q16.16 renders in fixed point only. `threads` = 0 uses all cores; `progress` is called
/// once per finished scanline (from any thread).
pub fn render_single(
    image: &[u8],
    precision: Precision,
    threads: usize,
    progress: &(dyn Fn() + Sync),
) -> Result<FrameImage, FrameError> {
    let fixed;
    let stored = SceneView::new(image).map_err(FrameError::Image)?.storage();
    let image = if precision == Precision::Fixed && stored == Storage::F32 {
        fixed = to_fixed(image).map_err(FrameError::Fixed)?;
        &fixed.bytes[..]
    } else {
        image
    };
    let view = SceneView::new(image).map_err(FrameError::Image)?;
    match precision {
        Precision::F32 | Precision::F64 => view.check_storage::<f32>(),
        Precision::Fixed => view.check_storage::<Fx>(),
    }
    .map_err(FrameError::Image)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| FrameError::Threads(e.to_string()))?;
    let start = Instant::now();
    let (rgb, stats) = pool.install(|| match precision {
        Precision::F32 => rows::<f32>(view, progress),
        Precision::F64 => rows::<f64>(view, progress),
        Precision::Fixed => rows::<Fx>(view, progress),
    });
    let f = view.camera::<f32>();
    Ok(FrameImage {
        width: f.width,
        height: f.height,
        rgb,
        stats,
        elapsed: start.elapsed(),
    })
}

fn rows<T: Real>(view: SceneView<'_>, progress: &(dyn Fn() + Sync)) -> (Vec<u8>, Stats) {
    let f = view.camera::<f32>();
    let (w, h) = (f.width as usize, f.height as usize);
    let mut rgb = vec![0u8; w * h * 3];
    // Each worker keeps one tracer state and lends it to the tracer of each row, as a
    // node does from run to run: its caches (edge planes, light rectangles, records) stay
    // warm across rows, and no row zero-fills its own ~30 KB. Pixels are those of a tracer
    // per row (tested in the core).
    let key = SceneKey::of(&view, 0);
    let stats: Vec<Stats> = rgb
        .par_chunks_mut(w * 3)
        .enumerate()
        .map_init(
            || Box::new(TracerState::<T>::new()),
            |state, (y, row)| {
                let mut tracer = Tracer::with_state(view, Techniques::ALL, state.as_mut(), key);
                let mut px = vec![[0u8; 3]; w];
                // The run is the whole row, which always lies inside the frame.
                if render_run(&mut tracer, y as u32, 0, &mut px).is_ok() {
                    for (dst, src) in row.chunks_exact_mut(3).zip(&px) {
                        dst.copy_from_slice(src);
                    }
                }
                progress();
                tracer.stats
            },
        )
        .collect();
    let mut total = Stats::default();
    for s in &stats {
        total.add(s);
    }
    debug_assert_eq!(h, stats.len());
    (rgb, total)
}

/// Encode RGB8 rows as a PNG file.
pub fn encode_png(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, png::EncodingError> {
    crate::png_codec::encode_rgb8(width, height, rgb)
}

/// Decode an 8-bit RGB PNG (as written by [`encode_png`]) for comparisons.
pub fn decode_png_rgb(bytes: &[u8]) -> Result<(u32, u32, Vec<u8>), String> {
    let dec = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = dec.read_info().map_err(|e| e.to_string())?;
    let mut buf = vec![0; reader.output_buffer_size().ok_or("PNG too large")?];
    let info = reader.next_frame(&mut buf).map_err(|e| e.to_string())?;
    if info.color_type != png::ColorType::Rgb || info.bit_depth != png::BitDepth::Eight {
        return Err(format!(
            "expected 8-bit RGB, found {:?} {:?}",
            info.color_type, info.bit_depth
        ));
    }
    buf.truncate(info.buffer_size());
    Ok((info.width, info.height, buf))
}

/// Peak signal-to-noise ratio of two RGB8 images in dB (infinite when identical).
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len(), "images differ in size");
    let se: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum();
    if se == 0.0 {
        return f64::INFINITY;
    }
    let mse = se / a.len() as f64;
    10.0 * (255.0f64 * 255.0 / mse).log10()
}
