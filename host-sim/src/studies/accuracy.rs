//! How far a render in one number type is from the f64 reference: the numerics issue's
//! accuracy measures (PSNR, worst channel error, pixels off by more than 1/255, NaN or
//! infinite colours, and hit-mask mismatches: pixels whose primary ray hit another shape).

use crate::sim::single::psnr;
use links_core::fixed_image::{to_fixed, FixedError};
use links_core::image::{ImageError, SceneView, ShapeRef};
use links_core::num::{Real, Storage};
use std::fmt;

/// Why a comparison couldn't run.
#[derive(Debug)]
pub enum AccuracyError {
    Image(ImageError),
    /// The scene doesn't fit the fixed-point format.
    Fixed(FixedError),
}

impl fmt::Display for AccuracyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AccuracyError::Image(e) => write!(f, "{e}"),
            AccuracyError::Fixed(e) => write!(f, "scene does not fit fixed point: {e}"),
        }
    }
}

impl std::error::Error for AccuracyError {}

impl From<ImageError> for AccuracyError {
    fn from(e: ImageError) -> Self {
        AccuracyError::Image(e)
    }
}

impl From<FixedError> for AccuracyError {
    fn from(e: FixedError) -> Self {
        AccuracyError::Fixed(e)
    }
}
use links_core::render::{to_rgb8, Tracer};
use rayon::prelude::*;

/// One render's pixels (RGB8), non-finite colour count and primary-ray hit per pixel.
struct Probe {
    rgb: Vec<u8>,
    non_finite: usize,
    hits: Vec<Option<ShapeRef>>,
}

fn probe<T: Real>(view: SceneView<'_>) -> Probe {
    let f = view.camera::<f32>();
    let (w, h) = (f.width, f.height);
    let rows: Vec<(Vec<u8>, usize, Vec<Option<ShapeRef>>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut t = Tracer::<T>::new(view);
            let mut rgb = Vec::with_capacity(w as usize * 3);
            let mut bad = 0;
            let mut hits = Vec::with_capacity(w as usize);
            t.begin_run(y);
            for x in 0..w {
                let c = t.pixel(x, y);
                bad += usize::from(!c.is_finite());
                rgb.extend(to_rgb8(c));
            }
            for x in 0..w {
                let ray = t.primary_ray(x, y);
                hits.push(t.first_surface(&ray).map(|(_, s)| s.shape));
            }
            (rgb, bad, hits)
        })
        .collect();
    let mut p = Probe {
        rgb: Vec::new(),
        non_finite: 0,
        hits: Vec::new(),
    };
    for (rgb, bad, hits) in rows {
        p.rgb.extend(rgb);
        p.non_finite += bad;
        p.hits.extend(hits);
    }
    p
}

/// The accuracy of a render against the f64 reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Accuracy {
    pub width: u32,
    pub height: u32,
    pub psnr_db: f64,
    pub max_channel_error: u8,
    /// Share of pixels with some channel off by more than 1/255.
    pub frac_off_by_more_than_1: f64,
    /// Pixels whose colour was NaN or infinite before quantising (tested backend).
    pub non_finite_pixels: usize,
    /// Pixels whose primary ray hit a different shape (or hit vs missed).
    pub hit_mismatches: usize,
    /// Of those, the ones not on a silhouette of the reference (no 4-neighbour of the pixel
    /// hit a different shape in the reference).
    pub hit_mismatches_off_silhouette: usize,
}

/// Compare the f32 render of a SceneImage with its f64 render.
pub fn compare_f32_to_f64(image: &[u8]) -> Result<Accuracy, AccuracyError> {
    compare_to_f64::<f32>(image)
}

/// Compare a render in number type `T` with the f64 render.
/// `image` is the DM's f32 image; a fixed-point `T` renders the DM's Q16.16 rewrite of it
/// (an error when the scene doesn't fit the format).
pub fn compare_to_f64<T: Real>(image: &[u8]) -> Result<Accuracy, AccuracyError> {
    compare_to::<T>(image, &reference(image)?)
}

/// The f64 render of an image, to compare several backends with (rendered once).
pub struct Reference(Probe);

/// Render the f64 reference of an f32 SceneImage.
pub fn reference(image: &[u8]) -> Result<Reference, AccuracyError> {
    Ok(Reference(probe::<f64>(SceneView::new(image)?)))
}

/// Compare a render in number type `T` with an f64 reference made by [`reference`] from
/// the same image.
pub fn compare_to<T: Real>(image: &[u8], reference: &Reference) -> Result<Accuracy, AccuracyError> {
    let view = SceneView::new(image)?;
    let f = view.camera::<f32>();
    let (w, h) = (f.width as usize, f.height as usize);
    let reference = &reference.0;
    let tested = match T::STORAGE {
        Storage::F32 => probe::<T>(view),
        Storage::Q16_16 => {
            let fixed = to_fixed(image)?;
            probe::<T>(SceneView::new(&fixed.bytes)?)
        }
    };
    let max = reference
        .rgb
        .iter()
        .zip(&tested.rgb)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap_or(0);
    let off = reference
        .rgb
        .chunks(3)
        .zip(tested.rgb.chunks(3))
        .filter(|(a, b)| a.iter().zip(*b).any(|(x, y)| x.abs_diff(*y) > 1))
        .count();
    let mut mismatches = 0;
    let mut off_silhouette = 0;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if reference.hits[i] == tested.hits[i] {
                continue;
            }
            mismatches += 1;
            let edge = [(0i64, -1i64), (0, 1), (-1, 0), (1, 0)]
                .iter()
                .any(|(dx, dy)| {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    nx >= 0
                        && ny >= 0
                        && (nx as usize) < w
                        && (ny as usize) < h
                        && reference.hits[ny as usize * w + nx as usize] != reference.hits[i]
                });
            off_silhouette += usize::from(!edge);
        }
    }
    Ok(Accuracy {
        width: w as u32,
        height: h as u32,
        psnr_db: psnr(&reference.rgb, &tested.rgb),
        max_channel_error: max,
        frac_off_by_more_than_1: off as f64 / (w * h) as f64,
        non_finite_pixels: tested.non_finite + reference.non_finite,
        hit_mismatches: mismatches,
        hit_mismatches_off_silhouette: off_silhouette,
    })
}
