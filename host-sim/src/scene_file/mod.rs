//! Scene files: the human-written RON format (`docs/scene-format.md`) and its loader, which
//! produces the semantic model [`links_core::desc::SceneDesc`].
//!
//! Loading happens in two steps:
//! 1. **Parse** ([`format`]): ron + serde into file-format structs. Every number, vector and
//!    shape is validated while it is read (finite, positive, non-degenerate, ...), so ron
//!    attaches the position of the offending value to the error; [`locate`] moves that position
//!    from where ron stopped (just after a value) to where the value starts.
//! 2. **Resolve** ([`resolve`]): material and texture names become indices, meshes (OBJ) and
//!    textures (PNG) are loaded relative to the scene's directory. A bad name or an unreadable
//!    file is located by replaying the parse primed to fail at that name (see
//!    [`format::Ref`]), so these errors carry an exact line and column too.
//!
//! Every error is a [`SceneError`] whose `Display` is `file:line:col: message`.

mod compile_at;
mod error;
mod format;
mod locate;
pub(crate) mod obj;
mod resolve;
pub(crate) mod texture;
mod tracks;
mod values;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tracks_tests;

use std::path::Path;

use links_core::anim::Film;
use links_core::desc::SceneDesc;

use crate::limits::{read_bounded, MAX_SCENE_BYTES};
use ron::extensions::Extensions;

pub use compile_at::{compile_at, CompileAtError};
pub use error::SceneError;

use format::{RefScope, SceneFile};

/// Reads and validates the scene file at `path`; meshes and textures are found relative to the
/// file's directory. Errors name `path` as given. Files are read with
/// [`crate::limits::read_bounded`]: a path that is not a regular file, or a scene, mesh or
/// texture over its limit in [`crate::limits`], is refused before it is read.
pub fn load_scene(path: &Path) -> Result<SceneDesc, SceneError> {
    load_film(path).map(|film| first_frame(&film))
}

/// The scene of a film's first frame: every track at its first key's value (the loader
/// checked each key, so this frame always exists).
fn first_frame(film: &Film) -> SceneDesc {
    film.scene_at(film.timeline().start)
        .unwrap_or_else(|_| film.base().clone())
}

/// Reads a scene file as a film: the scene as written, its frames (a file without `frames`
/// is a still, the one frame 0..1) and its tracks, every one checked. Otherwise as
/// [`load_scene`].
pub fn load_film(path: &Path) -> Result<Film, SceneError> {
    let bytes =
        read_bounded(path, MAX_SCENE_BYTES, "scene file").map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source: Box::new(source),
        })?;
    let file_name = path.display().to_string();
    let text = match std::str::from_utf8(&bytes) {
        Ok(t) => t,
        Err(e) => {
            let valid = std::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or_default();
            let (line, col) = locate::line_col(valid, valid.len());
            return Err(SceneError::Syntax {
                file: file_name,
                line,
                col,
                message: "invalid UTF-8: a scene file must be UTF-8 text".to_string(),
            });
        }
    };
    let base_dir = path.parent().unwrap_or_else(|| Path::new(""));
    parse_film(text, &file_name, base_dir)
}

/// Parses and validates scene `text`. `file_name` is used in error messages; relative mesh and
/// texture paths are resolved against `base_dir`.
pub fn parse_scene(text: &str, file_name: &str, base_dir: &Path) -> Result<SceneDesc, SceneError> {
    parse_film(text, file_name, base_dir).map(|film| first_frame(&film))
}

/// Parses and validates scene `text` as a film (see [`load_film`]).
pub fn parse_film(text: &str, file_name: &str, base_dir: &Path) -> Result<Film, SceneError> {
    // A byte-order mark is not RON; it is also not a column anybody can see.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    if let Some((offset, message)) = locate::non_decimal_number(text) {
        let (line, col) = locate::line_col(text, offset);
        return Err(SceneError::Syntax {
            file: file_name.to_string(),
            line,
            col,
            message,
        });
    }
    let file = parse_file(text, file_name, None)?;
    resolve::Resolver::new(text, file_name, base_dir).film(file)
}

/// The RON dialect of scene files: `implicit_some` is on, so optional values are written
/// plainly (`cut: (normal: ...)`); `Some(...)` and `None` are accepted too.
fn ron_options() -> ron::Options {
    ron::Options::default()
        .with_default_extension(Extensions::IMPLICIT_SOME)
        .with_recursion_limit(RECURSION_LIMIT)
}

/// ron's nesting limit: each cluster level costs 5 and the scene around them up to 13, so
/// this allows 50 levels of clusters.
const RECURSION_LIMIT: usize = 5 * 50 + 13;

/// One parse of the text into the file-format structs; `fail` primes a [`format::Ref`] replay.
fn parse_file(text: &str, file_name: &str, fail: Option<u32>) -> Result<SceneFile, SceneError> {
    let _scope = RefScope::new(fail);
    ron_options()
        .from_str::<SceneFile>(text)
        .map_err(|e| ron_error(text, file_name, e))
}

/// Converts ron's error, moving the position to the start of the offending value where ron
/// reports the end of it (our checks, wrong lengths and types, missing fields).
fn ron_error(text: &str, file_name: &str, e: ron::error::SpannedError) -> SceneError {
    use ron::error::Error as E;
    let start = e.span.start;
    let at_value = matches!(
        e.code,
        E::Message(_)
            | E::MissingStructField { .. }
            | E::ExpectedDifferentLength { .. }
            | E::InvalidValueForType { .. }
    );
    let (line, col) = if at_value {
        let offset = locate::offset_of(text, start.line, start.col);
        locate::line_col(text, locate::value_start(text, offset))
    } else {
        (start.line, start.col)
    };
    let file = file_name.to_string();
    match e.code {
        E::Message(message) => SceneError::Invalid {
            file,
            line,
            col,
            message,
        },
        E::ExceededRecursionLimit => SceneError::Syntax {
            file,
            line,
            col,
            message: "nested too deeply: clusters can be nested about 50 levels deep".to_string(),
        },
        E::MissingStructField { field, outer } => SceneError::Syntax {
            file,
            line,
            col,
            message: match outer {
                Some(outer) => format!("missing field `{field}` in `{outer}`"),
                None => format!("missing field `{field}`"),
            },
        },
        code => SceneError::Syntax {
            file,
            line,
            col,
            message: code.to_string(),
        },
    }
}
