//! The DM's last step for the fixed-point backend: an f32 SceneImage rewritten as Q16.16,
//! scaled by the power of two that fits the scene into the format with the most precision
//! left ("model no more than a scene needs").
//!
//! Why a scale and not another Q format: the tracer's intermediates are products of
//! coordinate differences (triangle edge functions, dot products), so the format's range
//! must hold about (2 * extent)^2 * 3. Scaling every length by 2^k so the largest coordinate
//! is at most [`TARGET_EXTENT`] (32) keeps those below 12,288 of the format's 32,767, and
//! leaves 16 + k fraction bits for the scene's own units: exactly the Q(15-k).(16+k) format
//! a per-scene choice would pick, with one code path on the node. Powers of two scale
//! floats exactly, and every quantity the tracer computes is scale-free (directions,
//! normals, unit-space coordinates of ellipsoids and boxes, kernel ratios of density
//! spheres) except point-light falloff, whose colour is pre-multiplied by 2^2k.
//!
//! A scene is rejected, never wrapped: a value outside the format, or a detail smaller than
//! [`MIN_DETAIL_STEPS`] steps after scaling (an ellipsoid axis, box half-size or ball radius
//! the format can't resolve), is a [`FixedError`] naming the record.

use crate::fixed::FRAC_BITS;
use crate::image::{ImageError, SceneView, Section, Word};
use crate::num::Storage;
use core::fmt;
use core::ops::Range;

/// The largest view-space coordinate after scaling.
pub const TARGET_EXTENT: f64 = 32.0;
/// The largest primary-direction component after scaling (a direction is normalised, so
/// its squares must fit: 3 * 32^2 is far inside the format).
pub const TARGET_DIRECTION: f64 = 32.0;
/// The smallest feature size, in steps of the format, a scene may have after scaling.
pub const MIN_DETAIL_STEPS: f64 = 16.0;

use Word::*;

/// Every record that has a word layout: (section, record, its byte range in the image,
/// its words). The range comes from the validated view, checked (`None` never happens for
/// a view of the same bytes; callers report it as an error rather than index blindly).
fn records<'a>(
    view: &'a SceneView<'_>,
) -> impl Iterator<Item = (Section, u32, Option<Range<usize>>, &'static [Word])> + 'a {
    Section::ALL.into_iter().flat_map(move |s| {
        let words = s.words();
        (0..if words.is_some() { view.count(s) } else { 0 })
            .map(move |r| (s, r, view.record_range(s, r), words.unwrap_or(&[])))
    })
}

/// The words of record `r` of section `s` in `bytes`, 4 bytes each, or the error naming
/// the section when the range is not in `bytes`.
fn record_words(
    bytes: &[u8],
    s: Section,
    range: Option<Range<usize>>,
) -> Result<core::slice::ChunksExact<'_, u8>, FixedError> {
    range
        .and_then(|r| bytes.get(r))
        .map(|rec| rec.chunks_exact(4))
        .ok_or(FixedError::Image(ImageError::SectionOutOfBounds {
            section: s as u8,
        }))
}

/// As [`record_words`], to rewrite them.
fn record_words_mut(
    bytes: &mut [u8],
    s: Section,
    range: Option<Range<usize>>,
) -> Result<core::slice::ChunksExactMut<'_, u8>, FixedError> {
    range
        .and_then(|r| bytes.get_mut(r))
        .map(|rec| rec.chunks_exact_mut(4))
        .ok_or(FixedError::Image(ImageError::SectionOutOfBounds {
            section: s as u8,
        }))
}

/// A 4-byte chunk as the f32 it stores.
fn f32_of(w: &[u8]) -> f64 {
    w.first_chunk::<4>()
        .map_or(0.0, |b| f32::from_le_bytes(*b) as f64)
}

/// A 4-byte chunk as a u32.
fn u32_of(w: &[u8]) -> u32 {
    w.first_chunk::<4>().map_or(0, |b| u32::from_le_bytes(*b))
}

/// Words in the longest record layout (an ellipsoid's 27), rounded up.
const MAX_WORDS: usize = 32;

/// What a word is multiplied by when the scene's lengths are scaled by `scale` and the
/// camera's directions by `dir_scale` (`None` for an integer, copied): lengths (and box
/// corners, rounded outward) by 2^k, inverse lengths by 2^-k, a light colour by 2^2k when
/// the light falls off with distance squared, primary-direction components by 2^j, their
/// pixel steps by 2^j times `step_scale` (2^[`camera::STEP_BITS`] in a Q16.16 image).
fn factor(
    kind: Word,
    falloff_light: bool,
    scale: f64,
    dir_scale: f64,
    step_scale: f64,
) -> Option<f64> {
    match kind {
        U => None,
        P => Some(1.0),
        L | Lo | Hi | G => Some(scale),
        I => Some(1.0 / scale),
        C if falloff_light => Some(scale * scale),
        C => Some(1.0),
        D => Some(dir_scale),
        S => Some(dir_scale * step_scale),
    }
}

/// Why a scene can't be expressed in Q16.16.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FixedError {
    /// The input is not a valid f32 SceneImage.
    Image(ImageError),
    /// The scene has no finite extent to scale (empty or non-finite coordinates).
    NoExtent,
    /// A value doesn't fit the format even after scaling.
    OutOfRange {
        section: Section,
        record: u32,
        word: u32,
        value: f64,
    },
    /// A feature is too small for the format at the scale the scene's extent allows.
    DetailBelowPrecision {
        section: Section,
        record: u32,
        /// The feature's size in steps of the format after scaling.
        steps: f64,
    },
    /// The rewritten image does not validate (possible only for an input whose sections
    /// share bytes, so that a word has two meanings and is rewritten as both).
    Rewritten(ImageError),
}

impl fmt::Display for FixedError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            FixedError::Image(e) => write!(f, "{e}"),
            FixedError::NoExtent => write!(f, "the scene has no finite extent to scale"),
            FixedError::OutOfRange {
                section,
                record,
                word,
                value,
            } => write!(
                f,
                "{} record {record}, word {word}: {value} does not fit Q16.16 (|x| < 32768) \
                 at this scene's scale",
                section.name()
            ),
            FixedError::DetailBelowPrecision {
                section,
                record,
                steps,
            } => write!(
                f,
                "{} record {record} is {steps:.1} steps of Q16.16 across at the scale the \
                 scene's extent allows (at least {MIN_DETAIL_STEPS} needed): the scene spans \
                 more orders of magnitude than the fixed-point format holds",
                section.name()
            ),
            FixedError::Rewritten(e) => write!(
                f,
                "the rewritten image is not valid ({e}): the input's sections share bytes"
            ),
        }
    }
}

impl std::error::Error for FixedError {}

impl From<ImageError> for FixedError {
    fn from(e: ImageError) -> Self {
        FixedError::Image(e)
    }
}

/// A converted image and the scale chosen for it.
#[derive(Clone, Debug)]
pub struct FixedImage {
    pub bytes: Vec<u8>,
    /// Lengths were multiplied by 2^scale_exponent.
    pub scale_exponent: i8,
    /// Largest view-space coordinate of the scene (before scaling).
    pub extent: f64,
    /// The smallest feature the check measured, in steps of the format after scaling.
    pub min_detail_steps: f64,
}

/// The power of two that brings `extent` closest to [`TARGET_EXTENT`] from below.
pub fn scale_exponent_for(extent: f64) -> Option<i8> {
    if !(extent.is_finite() && extent > 0.0) {
        return None;
    }
    let k = (TARGET_EXTENT / extent).log2().floor();
    Some(k.clamp(-100.0, 100.0) as i8)
}

/// The first record of an f32 image holding a scalar that is not finite, a node's box only
/// when no other record has one (the DM refuses to write such an image: see
/// [`crate::dm::DmError::BeyondF32`]).
pub fn first_non_finite(image: &[u8]) -> Result<Option<(Section, u32)>, ImageError> {
    let view = SceneView::new(image)?;
    if view.storage() != Storage::F32 {
        return Err(ImageError::UnsupportedFormat {
            found: view.storage() as u8,
        });
    }
    // A record whose range is not in the image counts as bad (never the case for a view of
    // the same bytes): it is named rather than skipped.
    let bad = |(s, _, range, words): &(Section, u32, Option<Range<usize>>, &[Word])| {
        record_words(image, *s, range.clone()).map_or(true, |chunks| {
            chunks
                .zip(words.iter())
                .any(|(w, kind)| *kind != U && !f32_of(w).is_finite())
        })
    };
    // A shape, light or camera record first: the boxes of the nodes above it overflow with it.
    let found = records(&view)
        .filter(|r| r.0 != Section::Nodes)
        .find(bad)
        .or_else(|| records(&view).find(bad))
        .map(|(s, r, _, _)| (s, r));
    Ok(found)
}

/// Rewrite an f32 SceneImage as Q16.16, choosing the scale from the scene's extent.
pub fn to_fixed(image: &[u8]) -> Result<FixedImage, FixedError> {
    let view = SceneView::new(image)?;
    if view.storage() != Storage::F32 {
        return Err(FixedError::Image(ImageError::UnsupportedFormat {
            found: view.storage() as u8,
        }));
    }
    // Extent: every length-valued word (coordinates, box corners, axes, radii).
    let mut extent: f64 = 0.0;
    for (s, _, range, words) in records(&view) {
        for (kind, word) in words.iter().zip(record_words(image, s, range)?) {
            if matches!(kind, L | Lo | Hi) {
                let v = f32_of(word);
                if !v.is_finite() {
                    return Err(FixedError::NoExtent);
                }
                extent = extent.max(v.abs());
            }
        }
    }
    // The node boxes (grid coordinates, not words): the root's corners bound them all.
    let root = view.node::<f64>(0).bounds;
    for v in [root.min, root.max] {
        for c in [v.x, v.y, v.z] {
            if c.is_finite() && view.node_count() > 0 {
                extent = extent.max(c.abs());
            }
        }
    }
    let k = scale_exponent_for(extent).ok_or(FixedError::NoExtent)?;
    convert(image, &view, k, extent)
}

/// Rewrite with a given scale exponent (tests use it to probe the format's edges).
pub fn to_fixed_with_scale(image: &[u8], k: i8) -> Result<FixedImage, FixedError> {
    let view = SceneView::new(image)?;
    convert(image, &view, k, f64::NAN)
}

/// 2^j for the camera's direction components: with x0 and dx stored as plain Q16.16, a
/// pixel step of 0.002 would be rounded by 0.4% and the last column's ray bent by a pixel.
fn direction_scale(image: &[u8], view: &SceneView<'_>) -> Result<f64, FixedError> {
    let f = view.camera::<f32>();
    let camera: Vec<f64> = record_words(
        image,
        Section::Camera,
        view.record_range(Section::Camera, 0),
    )?
    .map(f32_of)
    .collect();
    let w = |i: usize| camera.get(i).copied().unwrap_or(0.0);
    let (x0, y0, dx, dy, dz) = (w(2), w(3), w(4), w(5), w(14));
    let m = [
        x0,
        y0,
        dz,
        x0 + dx * f.width as f64,
        y0 - dy * f.height as f64,
    ]
    .iter()
    .fold(0f64, |m, v| m.max(v.abs()));
    Ok(if m.is_finite() && m > 0.0 {
        2f64.powi((TARGET_DIRECTION / m).log2().floor().clamp(-60.0, 60.0) as i32)
    } else {
        1.0
    })
}

/// The same f32 image with every length multiplied by 2^k (exact in binary floating point).
/// The tracer is meant to be scale-free, so a render of it must match the original's:
/// the fixed-point conversion relies on that, and tests check it.
pub fn rescale_f32(image: &[u8], k: i8) -> Result<Vec<u8>, FixedError> {
    let view = SceneView::new(image)?;
    let scale = 2f64.powi(k as i32);
    let mut out = image.to_vec();
    for (s, _, range, words) in records(&view) {
        let falloff = is_falloff_light(image, s, range.clone())?;
        for (kind, word) in words.iter().zip(record_words_mut(&mut out, s, range)?) {
            if let Some(f) = factor(*kind, falloff, scale, 1.0, 1.0) {
                let x = f32_of(word) * f;
                word.copy_from_slice(&(x as f32).to_le_bytes());
            }
        }
    }
    SceneView::new(&out).map_err(FixedError::Rewritten)?;
    Ok(out)
}

/// Put the node boxes on a grid the format holds exactly: per axis the finest power-of-two
/// step of at least one Q16.16 step (in view units: 2^-16 / scale) on which the root box
/// fits i16 coordinates; every box is decoded exactly from the f32 grid and rounded outward
/// onto the new one, so it still contains what it contained.
fn regrid(out: &mut [u8], view: &SceneView<'_>, scale: f64) -> Result<(), FixedError> {
    use crate::image::layout::{camera, node};
    let cam = view
        .record_range(Section::Camera, 0)
        .ok_or(FixedError::Image(ImageError::MissingCamera))?;
    let f32_at = |at: usize| f32_of(view.bytes().get(cam.start + at..).unwrap_or(&[]));
    let old_origin = [0, 4, 8].map(|k| f32_at(camera::GRID_ORIGIN + k));
    let old_step = [0, 4, 8].map(|k| f32_at(camera::GRID_STEP + k));
    let corner = |i: u32, at: usize| -> [f64; 3] {
        let r = view.record_range(Section::Nodes, i).unwrap_or(0..0);
        [0, 2, 4].map(|k| {
            let b = view.bytes().get(r.start + at + k..r.start + at + k + 2);
            b.map_or(0, |b| i16::from_le_bytes([b[0], b[1]])) as f64
        })
    };
    let (lo_q, hi_q) = (corner(0, node::LO), corner(0, node::HI));
    let lsb = 1.0 / ((1u64 << FRAC_BITS) as f64 * scale);
    let mut origin = [0f64; 3];
    let mut step = [0f64; 3];
    for k in 0..3 {
        let lo = old_origin[k] + lo_q[k] * old_step[k];
        let hi = old_origin[k] + hi_q[k] * old_step[k];
        let mut s = lsb.max(old_step[k]);
        loop {
            let o = (0.5 * (lo + hi) / s).round() * s;
            if lo > hi || ((lo - o) / s >= i16::MIN as f64 && (hi - o) / s <= i16::MAX as f64) {
                origin[k] = if lo > hi { 0.0 } else { o };
                step[k] = s;
                break;
            }
            s *= 2.0;
            if !s.is_finite() {
                return Err(FixedError::NoExtent);
            }
        }
    }
    for i in 0..view.count(Section::Nodes) {
        let (lq, hq) = (corner(i, node::LO), corner(i, node::HI));
        let Some(r) = view.record_range(Section::Nodes, i) else {
            continue;
        };
        for k in 0..3 {
            let (lo, hi) = if lq[k] > hq[k] {
                (i16::MAX, i16::MIN)
            } else {
                let v = |q: f64| old_origin[k] + q * old_step[k];
                let t = |x: f64| (x - origin[k]) / step[k];
                let c = |x: f64| x.clamp(i16::MIN as f64, i16::MAX as f64) as i16;
                (c(t(v(lq[k])).floor()), c(t(v(hq[k])).ceil()))
            };
            for (at, q) in [(node::LO + 2 * k, lo), (node::HI + 2 * k, hi)] {
                if let Some(b) = out.get_mut(r.start + at..r.start + at + 2) {
                    b.copy_from_slice(&q.to_le_bytes());
                }
            }
        }
    }
    let one = (1u64 << FRAC_BITS) as f64;
    for k in 0..3 {
        for (at, v) in [
            (camera::GRID_ORIGIN + 4 * k, origin[k]),
            (camera::GRID_STEP + 4 * k, step[k]),
        ] {
            let raw = v * scale * one;
            if raw.abs() > (i32::MAX - 1) as f64 {
                return Err(FixedError::OutOfRange {
                    section: Section::Camera,
                    record: 0,
                    word: (at / 4) as u32,
                    value: v * scale,
                });
            }
            if let Some(b) = out.get_mut(cam.start + at..cam.start + at + 4) {
                b.copy_from_slice(&(raw as i32).to_le_bytes());
            }
        }
    }
    Ok(())
}

/// A point light whose colour falls off with distance squared.
fn is_falloff_light(
    image: &[u8],
    s: Section,
    range: Option<Range<usize>>,
) -> Result<bool, FixedError> {
    if s != Section::Lights {
        return Ok(false);
    }
    let mut words = record_words(image, s, range)?;
    let kind = words.next().map_or(0, u32_of);
    let falloff = words.nth(12).map_or(0, u32_of);
    Ok(kind == 1 && falloff != 0)
}

fn convert(
    image: &[u8],
    view: &SceneView<'_>,
    k: i8,
    extent: f64,
) -> Result<FixedImage, FixedError> {
    let scale = 2f64.powi(k as i32);
    let dir_scale = direction_scale(image, view)?;
    let mut out = image.to_vec();
    // The header's format and scale bytes (a view exists, so the header does too).
    if let Some(h) = out.get_mut(6..8) {
        h.copy_from_slice(&[Storage::Q16_16 as u8, k as u8]);
    }
    let one = (1u64 << FRAC_BITS) as f64;
    let mut min_detail = f64::INFINITY;
    let mut regrid_needed = false;
    for (s, r, range, words) in records(view) {
        let falloff_light = is_falloff_light(image, s, range.clone())?;
        // The f32 words of the record, read before they are rewritten.
        let mut f32s = [0f64; MAX_WORDS];
        for (v, word) in f32s.iter_mut().zip(record_words(image, s, range.clone())?) {
            *v = f32_of(word);
        }
        let rec = record_words_mut(&mut out, s, range)?;
        for (w, ((kind, word), &v)) in words.iter().zip(rec).zip(f32s.iter()).enumerate() {
            let step_scale = (1u32 << crate::image::camera::STEP_BITS) as f64;
            let Some(f) = factor(*kind, falloff_light, scale, dir_scale, step_scale) else {
                continue;
            };
            let x = v * f;
            let steps = x * one;
            let raw = match kind {
                Lo => steps.floor(),
                Hi => steps.ceil(),
                _ => steps.round(),
            };
            // The node grid's step must stay exact (then so does every grid point); a step
            // below the format's resolution is replaced below by a coarser grid.
            if *kind == G && (raw != steps || raw < 1.0) {
                regrid_needed = true;
            }
            if !raw.is_finite() || raw.abs() > (i32::MAX - 1) as f64 {
                return Err(FixedError::OutOfRange {
                    section: s,
                    record: r,
                    word: w as u32,
                    value: if x.is_finite() { x } else { v },
                });
            }
            word.copy_from_slice(&(raw as i32).to_le_bytes());
        }
        // Detail: the smallest axis of an ellipsoid or box (1 / largest row of its
        // view-to-unit matrix) and a ball's radius, in steps after scaling.
        let detail = match s {
            Section::Ellipsoids | Section::Boxes => {
                let mut worst: f64 = 0.0;
                for row in 0..3 {
                    let n2: f64 = (0..3)
                        .map(|c| f32s.get(3 + 3 * row + c).map_or(0.0, |v| v.powi(2)))
                        .sum();
                    worst = worst.max(n2.sqrt());
                }
                Some(scale / worst * one)
            }
            Section::Balls => Some(f32s.get(3).map_or(0.0, |v| v.abs()) * scale * one),
            _ => None,
        };
        if let Some(steps) = detail {
            min_detail = min_detail.min(steps);
            if steps.is_nan() || steps < MIN_DETAIL_STEPS {
                return Err(FixedError::DetailBelowPrecision {
                    section: s,
                    record: r,
                    steps,
                });
            }
        }
    }
    if regrid_needed {
        regrid(&mut out, view, scale)?;
    }
    // Only a valid image leaves the DM.
    SceneView::new(&out).map_err(FixedError::Rewritten)?;
    Ok(FixedImage {
        bytes: out,
        scale_exponent: k,
        extent,
        min_detail_steps: min_detail,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_fits_the_extent_with_most_precision() {
        assert_eq!(scale_exponent_for(32.0), Some(0));
        assert_eq!(scale_exponent_for(31.9), Some(0));
        assert_eq!(scale_exponent_for(16.0), Some(1));
        assert_eq!(scale_exponent_for(10.0), Some(1));
        assert_eq!(scale_exponent_for(33.0), Some(-1));
        assert_eq!(scale_exponent_for(1000.0), Some(-5));
        assert_eq!(scale_exponent_for(0.001), Some(14));
        assert_eq!(scale_exponent_for(0.0), None);
        assert_eq!(scale_exponent_for(f64::INFINITY), None);
    }

    /// A valid f32 image whose light record shares its bytes with the camera record (the
    /// validator checks each section, not that they are disjoint): the light's colour words
    /// are the camera's height, x0, y0.
    fn light_over_camera() -> Vec<u8> {
        use crate::image::layout::{TABLE_AT, TABLE_ENTRY_SIZE};
        use crate::testkit::scene::SceneBuilder;
        let mut b = SceneBuilder::new(Storage::F32);
        // Width 2 reads as a spot light's kind.
        b.camera(2, 3, [-1.0, 1.0, 0.5, 0.5], 0.0)
            .grey_material()
            .triangle([-1.0, -1.0, 2.0, 1.0, -1.0, 2.0, 0.0, 1.0, 2.0])
            .node([-1.0, -1.0, 1.0], [1.0, 1.0, 3.0], 1, 0);
        let mut img = b.finish();
        let camera_at = img[TABLE_AT..TABLE_AT + 4].to_vec();
        let lights = TABLE_AT + TABLE_ENTRY_SIZE * Section::Lights as usize;
        img[lights..lights + 4].copy_from_slice(&camera_at);
        img[lights + 4..lights + 8].copy_from_slice(&1u32.to_le_bytes());
        img
    }

    #[test]
    fn a_rewrite_that_would_not_validate_is_an_error() {
        // Found by the image fuzzer: converting the light's colour turned the camera's
        // height (3, a subnormal as an f32) into 0, and to_fixed returned that image.
        let img = light_over_camera();
        let view = SceneView::new(&img).expect("the input is valid");
        assert_eq!(view.light_count(), 1);
        assert_eq!(
            to_fixed(&img).err(),
            Some(FixedError::Rewritten(ImageError::BadValue {
                section: Section::Camera as u8,
                record: 0
            }))
        );
    }

    /// The primary directions of a 512-pixel row in the Q16.16 image: within a step and a
    /// half of the f32 image's, computed exactly, at every column (with dx stored as plain
    /// Q16.16, up to half a step per pixel: 128 steps at the far column).
    #[test]
    fn pixel_steps_keep_every_column_within_a_step_and_a_half() {
        use crate::num::{Fx, Real};
        use crate::testkit::scene::SceneBuilder;
        let (w, h) = (512u32, 480u32);
        let (x0, y0) = (-0.388_234_9f32, 0.363_970_2f32);
        let (dx, dy) = (-2.0 * x0 / w as f32, 2.0 * y0 / h as f32);
        let mut b = SceneBuilder::new(Storage::F32);
        b.camera(w, h, [x0, y0, dx, dy], 0.2)
            .grey_material()
            .triangle([-1.0, -1.0, 2.0, 1.0, -1.0, 2.0, 0.0, 1.0, 2.0])
            .node([-1.0, -1.0, 1.0], [1.0, 1.0, 3.0], 1, 0);
        let img = b.finish();
        let fixed = to_fixed(&img).expect("fits");
        let exact = SceneView::new(&img).unwrap().camera::<f64>();
        let cam = SceneView::new(&fixed.bytes).unwrap().camera::<Fx>();
        // The direction scale: dz is 1 in the f32 image.
        let j = cam.dz.to_f64();
        assert_eq!(j, 32.0);
        let step = 1.0 / 65536.0;
        for (n, x0f, dxf, x0q, down) in [
            (w, exact.x0, exact.dx, cam.x0, false),
            (h, -exact.y0, exact.dy, -cam.y0, true),
        ] {
            let across = |s: Fx| if down { cam.down(s) } else { cam.across(s) };
            let mut worst = 0f64;
            for x in 0..n {
                let s = x as f64 + 0.5;
                let want = (x0f + s * dxf) * j;
                let got = (x0q + across(Fx::from_f64(s))).to_f64();
                worst = worst.max((got - want).abs() / step);
            }
            assert!(worst <= 1.5, "{worst} steps");
            // Plain Q16.16 dx: the far column's error grows with the column.
            let coarse = Fx::from_f64(dxf * j);
            let far = (x0q + Fx::from_f64(n as f64 - 0.5) * coarse).to_f64();
            let want = (x0f + (n as f64 - 0.5) * dxf) * j;
            assert!(
                (far - want).abs() / step > 20.0,
                "{n}: {}",
                (far - want).abs() / step
            );
        }
    }

    #[test]
    fn layouts_cover_whole_records() {
        for s in Section::ALL {
            if let Some(words) = s.words() {
                assert_eq!(words.len() * 4, s.record_size(), "{}", s.name());
                assert!(words.len() <= MAX_WORDS, "{}", s.name());
            }
        }
    }
}
