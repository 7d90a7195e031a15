//! Compiled SceneImage files on the command line: `links check-image FILE` and
//! `links render --image FILE` (the bytes `links info --image` writes and `links upload`
//! sends), so an upload can be debugged on the host. Also the section table `links info`
//! prints.

use std::fmt;
use std::path::{Path, PathBuf};

use links_core::image::{ImageError, SceneView, Section};
use links_core::num::Storage;

use crate::frame::Precision;
use crate::limits::{read_bounded, ReadError, MAX_IMAGE_SIDE, MAX_SCENE_IMAGE_BYTES};

/// Why a SceneImage file can't be used.
#[derive(Debug)]
#[non_exhaustive]
pub enum ImageFileError {
    /// The file could not be read (missing, not a regular file, over
    /// [`MAX_SCENE_IMAGE_BYTES`]).
    Read(ReadError),
    /// The bytes are not a valid SceneImage; the error names the section and record.
    Invalid { path: PathBuf, source: ImageError },
    /// A valid image whose frame is larger than the host renders ([`MAX_IMAGE_SIDE`]).
    FrameTooLarge {
        path: PathBuf,
        width: u32,
        height: u32,
    },
    /// The image stores its scalars in a format the requested render can't read.
    Precision {
        path: PathBuf,
        storage: Storage,
        asked: &'static str,
    },
}

impl fmt::Display for ImageFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImageFileError::Read(e) => write!(f, "{e}"),
            ImageFileError::Invalid { path, source } => {
                write!(f, "{}: not a valid SceneImage: {source}", path.display())
            }
            ImageFileError::FrameTooLarge {
                path,
                width,
                height,
            } => write!(
                f,
                "{}: the frame is {width}x{height} pixels; the host renders 1 to \
                 {MAX_IMAGE_SIDE} pixels per side",
                path.display()
            ),
            ImageFileError::Precision {
                path,
                storage,
                asked,
            } => write!(
                f,
                "{}: the image stores {} scalars, which {asked} can't read{}",
                path.display(),
                storage.name(),
                match storage {
                    Storage::Q16_16 => " (render it with --precision fixed)",
                    Storage::F32 => "",
                }
            ),
        }
    }
}

impl std::error::Error for ImageFileError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ImageFileError::Read(e) => Some(e),
            ImageFileError::Invalid { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// Reads a SceneImage file (bounded, see [`crate::limits`]) and validates it with
/// [`SceneView::new`]: header, every section's bounds and every cross-reference.
pub fn read_image(path: &Path) -> Result<Vec<u8>, ImageFileError> {
    let bytes = read_bounded(path, MAX_SCENE_IMAGE_BYTES, "SceneImage file")
        .map_err(ImageFileError::Read)?;
    SceneView::new(&bytes).map_err(|source| ImageFileError::Invalid {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(bytes)
}

/// Checks that the host can render the frame of a valid image at `path`.
pub fn check_frame(path: &Path, view: &SceneView<'_>) -> Result<(), ImageFileError> {
    let f = view.camera::<f32>();
    if f.width > MAX_IMAGE_SIDE || f.height > MAX_IMAGE_SIDE {
        return Err(ImageFileError::FrameTooLarge {
            path: path.to_path_buf(),
            width: f.width,
            height: f.height,
        });
    }
    Ok(())
}

/// The number type a render of the image at `path` uses: what was asked for (f32 when
/// nothing was), or fixed point for an image that stores Q16.16.
pub fn precision_for(
    path: &Path,
    view: &SceneView<'_>,
    asked: Option<Precision>,
) -> Result<Precision, ImageFileError> {
    let refuse = |asked| ImageFileError::Precision {
        path: path.to_path_buf(),
        storage: view.storage(),
        asked,
    };
    match (view.storage(), asked) {
        (Storage::Q16_16, None | Some(Precision::Fixed)) => Ok(Precision::Fixed),
        (Storage::Q16_16, Some(p)) => Err(refuse(match p {
            Precision::F64 => "an f64 render",
            _ => "an f32 render",
        })),
        (Storage::F32, p) => Ok(p.unwrap_or(Precision::F32)),
    }
}

/// The section table of `links info` and `links check-image`: a heading naming `name`, the
/// size and the frame (`<name>: SceneImage <N> bytes (<W>x<H>)`), the number format, then one
/// row per non-empty section; with `shares`, each row also gives the section's share of the
/// whole image, and a last row the bytes outside the sections (the header).
pub fn describe(name: &str, view: &SceneView<'_>, shares: bool) -> Vec<String> {
    let f = view.camera::<f32>();
    let format = match view.storage() {
        Storage::F32 => "f32".to_string(),
        Storage::Q16_16 => format!("q16.16, lengths scaled by 2^{}", view.scale_exponent()),
    };
    let total = view.bytes().len();
    let share = |bytes: usize| {
        if shares {
            format!(" {:>6.1}%", 100.0 * bytes as f64 / total.max(1) as f64)
        } else {
            String::new()
        }
    };
    // The first line's form is an interface (scripts and checks read it): keep it as is.
    let mut lines = vec![
        format!(
            "{name}: SceneImage {total} bytes ({}x{})",
            f.width, f.height
        ),
        format!("  number format: {format}"),
        format!(
            "  {:<16} {:>8} {:>10}{}",
            "section",
            "records",
            "bytes",
            if shares { "   share" } else { "" }
        ),
    ];
    let mut in_sections = 0usize;
    for s in Section::ALL {
        if view.count(s) > 0 {
            let bytes = view.section_bytes(s);
            in_sections = in_sections.saturating_add(bytes);
            lines.push(format!(
                "  {:<16} {:>8} {:>10}{}",
                s.name(),
                view.count(s),
                bytes,
                share(bytes)
            ));
        }
    }
    if shares {
        let rest = total.saturating_sub(in_sections);
        lines.push(format!(
            "  {:<16} {:>8} {:>10}{}",
            "header",
            "",
            rest,
            share(rest)
        ));
    }
    lines
}

/// `links render --image`: the image at `path`, validated, with a frame the host renders,
/// and the number type to render it in ([`precision_for`]).
pub fn for_render(
    path: &Path,
    asked: Option<Precision>,
) -> Result<(Vec<u8>, Precision), ImageFileError> {
    let bytes = read_image(path)?;
    let view = SceneView::new(&bytes).map_err(|source| ImageFileError::Invalid {
        path: path.to_path_buf(),
        source,
    })?;
    check_frame(path, &view)?;
    let precision = precision_for(path, &view, asked)?;
    Ok((bytes, precision))
}

/// `links check-image`: the table of a valid image, or why it is not one.
pub fn check_image(path: &Path) -> Result<Vec<String>, ImageFileError> {
    let bytes = read_image(path)?;
    let view = SceneView::new(&bytes).map_err(|source| ImageFileError::Invalid {
        path: path.to_path_buf(),
        source,
    })?;
    let mut lines = describe(&path.display().to_string(), &view, false);
    lines.push(match check_frame(path, &view) {
        Ok(()) => "valid".to_string(),
        Err(_) => format!(
            "valid, but the host renders frames of at most {MAX_IMAGE_SIDE}x{MAX_IMAGE_SIDE} \
             pixels"
        ),
    });
    Ok(lines)
}
