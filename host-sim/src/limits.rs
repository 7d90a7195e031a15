//! Resource limits of the host tool: the largest image it renders, the largest file of each
//! kind it reads, and [`read_bounded`], the one way the CLI reads a file.
//!
//! Every limit is documented in the README ("Limits") and `docs/scene-format.md`. A file is
//! refused before anything is allocated for it: a path that is not a regular file (a FIFO,
//! `/dev/zero`, a directory) is refused from its metadata without being opened, a file whose
//! size is over the limit is refused from its metadata without being read, and a file that
//! grows while it is read is cut off at `limit + 1` bytes.

use std::fmt;
use std::fs::{File, Metadata};
use std::io::{self, Read};
use std::path::{Path, PathBuf};

/// Largest image side in pixels: `--width`/`--height`, a scene file's `image`, a texture, and
/// the frame of a SceneImage the host renders. A 4096 x 4096 frame is 48 MiB of RGB8.
pub const MAX_IMAGE_SIDE: u32 = 4096;

/// Largest scene file (`.ron`).
pub const MAX_SCENE_BYTES: u64 = 16 << 20;
/// Largest mesh file (Wavefront OBJ).
pub const MAX_MESH_BYTES: u64 = 64 << 20;
/// Largest texture file (PNG, compressed).
pub const MAX_TEXTURE_BYTES: u64 = 64 << 20;
/// Most bytes the PNG decoder may allocate for one texture (its own buffers; the decoded
/// image itself is at most [`MAX_IMAGE_SIDE`]² pixels by the side check).
pub const MAX_TEXTURE_DECODE_BYTES: usize = 64 << 20;
/// Largest compiled SceneImage file (`links check-image`, `links render --image`).
pub const MAX_SCENE_IMAGE_BYTES: u64 = 256 << 20;
/// Largest text file of measurements or documentation the CLI reads (CSV, Markdown) and
/// largest font file.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// Most host threads a render may ask for (`--threads`; 0 means one per core).
pub const MAX_THREADS: usize = 256;
/// Most node computers a model or a simulated cluster may have (`--nodes`).
pub const MAX_NODES: u32 = 256;
/// The simulated SPI bit rate's range in MHz (`--bit-rate-mhz`): at 1 kHz a 4096 x 4096
/// frame of raw RGB still takes well under the 2^64 ps of virtual time.
pub const BIT_RATE_MHZ: (f64, f64) = (0.001, 10_000.0);

/// Most intervals a cluster frame's timeline keeps (`links render --timeline`): about
/// 24 MB of log; photo1 at 512x480 on 256 nodes needs some tens of thousands.
pub const MAX_TIMELINE_INTERVALS: usize = 1_000_000;

/// Why a file was not read.
#[derive(Debug)]
#[non_exhaustive]
pub enum ReadError {
    /// The operating system refused (missing file, no permission, ...).
    Io {
        path: PathBuf,
        what: &'static str,
        source: io::Error,
    },
    /// The path is not a regular file (reading it could block forever or never end).
    NotAFile {
        path: PathBuf,
        what: &'static str,
        /// "a FIFO (named pipe)", "a directory", ...
        kind: &'static str,
    },
    /// A text file (CSV, Markdown) that is not UTF-8.
    NotText {
        path: PathBuf,
        what: &'static str,
        /// Offset of the first byte that is not UTF-8.
        offset: usize,
    },
    /// The file is larger than the limit for its kind.
    TooLarge {
        path: PathBuf,
        what: &'static str,
        /// The size the file system reports, or `limit + 1` when it grew past the limit
        /// while being read (`at_least` is then true).
        size: u64,
        at_least: bool,
        limit: u64,
    },
}

impl ReadError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            ReadError::Io { path, .. }
            | ReadError::NotAFile { path, .. }
            | ReadError::NotText { path, .. }
            | ReadError::TooLarge { path, .. } => path,
        }
    }

    /// What went wrong, without the path and the kind of file: "No such file or directory
    /// (os error 2)", "it is a FIFO (named pipe), not a regular file", "it is 100000000
    /// bytes, over the 16 MiB (16777216 bytes) limit for a scene file".
    pub fn reason(&self) -> String {
        match self {
            ReadError::Io { source, .. } => source.to_string(),
            ReadError::NotAFile { kind, .. } => format!("it is {kind}, not a regular file"),
            ReadError::NotText { offset, .. } => {
                format!("it is not UTF-8 text (invalid byte at offset {offset})")
            }
            ReadError::TooLarge {
                what,
                size,
                at_least,
                limit,
                ..
            } => format!(
                "it is {}{} bytes, over the {} limit for a {what}",
                if *at_least { "more than " } else { "" },
                if *at_least { limit } else { size },
                Bytes(*limit)
            ),
        }
    }

    /// The kind of file, as given to [`read_bounded`].
    pub fn what(&self) -> &'static str {
        match self {
            ReadError::Io { what, .. }
            | ReadError::NotAFile { what, .. }
            | ReadError::NotText { what, .. }
            | ReadError::TooLarge { what, .. } => what,
        }
    }
}

/// `path: cannot read the scene file: reason`.
impl fmt::Display for ReadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: cannot read the {}: {}",
            self.path().display(),
            self.what(),
            self.reason()
        )
    }
}

impl std::error::Error for ReadError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ReadError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// A byte count for messages: `16 MiB (16777216 bytes)`, or `100 bytes`.
pub struct Bytes(pub u64);

impl fmt::Display for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = self.0;
        if b >= 1 << 20 && b.is_multiple_of(1 << 20) {
            write!(f, "{} MiB ({b} bytes)", b >> 20)
        } else {
            write!(f, "{b} bytes")
        }
    }
}

/// What kind of file system object `m` is, when it is not a regular file.
fn irregular_kind(m: &Metadata) -> Option<&'static str> {
    let t = m.file_type();
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() {
            return Some("a character device");
        }
        if t.is_block_device() {
            return Some("a block device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("a special file")
}

/// Opens `path` for reading without waiting for a writer (a FIFO swapped in after the
/// metadata check must not block the open).
fn open_nonblocking(path: &Path) -> io::Result<File> {
    let mut o = std::fs::OpenOptions::new();
    o.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        o.custom_flags(libc::O_NONBLOCK);
    }
    o.open(path)
}

/// Reads the regular file at `path`, at most `max_bytes` of it; `what` names the kind of file
/// in messages ("scene file", "mesh file").
///
/// Refuses without opening anything that is not a regular file, refuses from its metadata a
/// file larger than `max_bytes`, and reads at most `max_bytes + 1` bytes otherwise (a file
/// that grew past the limit is refused too). The buffer is allocated for the size the file
/// system reports, never more than `max_bytes + 1`.
pub fn read_bounded(path: &Path, max_bytes: u64, what: &'static str) -> Result<Vec<u8>, ReadError> {
    let io_err = |source| ReadError::Io {
        path: path.to_path_buf(),
        what,
        source,
    };
    let not_a_file = |kind| ReadError::NotAFile {
        path: path.to_path_buf(),
        what,
        kind,
    };
    let too_large = |size, at_least| ReadError::TooLarge {
        path: path.to_path_buf(),
        what,
        size,
        at_least,
        limit: max_bytes,
    };
    let meta = std::fs::metadata(path).map_err(io_err)?;
    if let Some(kind) = irregular_kind(&meta) {
        return Err(not_a_file(kind));
    }
    if meta.len() > max_bytes {
        return Err(too_large(meta.len(), false));
    }
    let file = open_nonblocking(path).map_err(io_err)?;
    // The path may have been replaced between the two looks: check what was opened.
    let meta = file.metadata().map_err(io_err)?;
    if let Some(kind) = irregular_kind(&meta) {
        return Err(not_a_file(kind));
    }
    let data = read_limited(file, max_bytes, meta.len()).map_err(io_err)?;
    if data.len() as u64 > max_bytes {
        return Err(too_large(max_bytes, true));
    }
    Ok(data)
}

/// Reads `r` to its end or to `max_bytes + 1` bytes, whichever comes first; `size_hint` (the
/// expected length) sizes the buffer up to that bound. More than `max_bytes` bytes returned
/// means the input is over the limit.
pub fn read_limited<R: Read>(r: R, max_bytes: u64, size_hint: u64) -> io::Result<Vec<u8>> {
    let cap = max_bytes.saturating_add(1);
    let initial = usize::try_from(size_hint.min(cap)).unwrap_or(0);
    let mut data = Vec::with_capacity(initial);
    r.take(cap).read_to_end(&mut data)?;
    Ok(data)
}

/// Reads a UTF-8 text file with [`read_bounded`].
pub fn read_text_bounded(
    path: &Path,
    max_bytes: u64,
    what: &'static str,
) -> Result<String, ReadError> {
    let bytes = read_bounded(path, max_bytes, what)?;
    String::from_utf8(bytes).map_err(|e| ReadError::NotText {
        path: path.to_path_buf(),
        what,
        offset: e.utf8_error().valid_up_to(),
    })
}

/// A number in `lo..=hi` from the command line (for clap's `value_parser`); `what` says what
/// the range is, e.g. "an image side is 1 to 4096 pixels".
fn parse_in<T>(s: &str, lo: T, hi: T, what: impl FnOnce() -> String) -> Result<T, String>
where
    T: std::str::FromStr + PartialOrd,
{
    match s.trim().parse::<T>() {
        Ok(v) if v >= lo && v <= hi => Ok(v),
        _ => Err(what()),
    }
}

/// `--width`, `--height`: 1..=[`MAX_IMAGE_SIDE`].
pub fn parse_image_side(s: &str) -> Result<u32, String> {
    parse_in(s, 1, MAX_IMAGE_SIDE, || {
        format!("an image side is 1 to {MAX_IMAGE_SIDE} pixels")
    })
}

/// `--threads`: 0 (one per core) ..=[`MAX_THREADS`].
pub fn parse_threads(s: &str) -> Result<usize, String> {
    parse_in(s, 0, MAX_THREADS, || {
        format!("expected 0 (one per core) to {MAX_THREADS} threads")
    })
}

/// `--max-depth`: 0..=[`links_core::image::MAX_DEPTH_LIMIT`].
pub fn parse_max_depth(s: &str) -> Result<u32, String> {
    let max = links_core::image::MAX_DEPTH_LIMIT;
    parse_in(s, 0, max, || {
        format!("the recursion depth is 0 to {max} (the SceneImage limit)")
    })
}

/// `--bit-rate-mhz`: within [`BIT_RATE_MHZ`] (not NaN).
pub fn parse_bit_rate_mhz(s: &str) -> Result<f64, String> {
    let (lo, hi) = BIT_RATE_MHZ;
    parse_in(s, lo, hi, || {
        format!("the SPI bit rate is {lo} to {hi} MHz")
    })
}

/// `sweep ablation --nodes`: 1..=[`MAX_NODES`].
pub fn parse_nodes(s: &str) -> Result<u32, String> {
    parse_in(s, 1, MAX_NODES, || {
        format!("a cluster has 1 to {MAX_NODES} node computers")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("links-limits-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        let _ = std::fs::remove_file(&p);
        p
    }

    #[test]
    fn a_small_file_is_read_whole() {
        let p = scratch("small.txt");
        std::fs::write(&p, b"hello").unwrap();
        assert_eq!(read_bounded(&p, 5, "scene file").unwrap(), b"hello");
    }

    #[test]
    fn a_file_over_the_limit_is_refused_with_its_size_and_the_limit() {
        let p = scratch("big.bin");
        let f = File::create(&p).unwrap();
        // Sparse: no disk space used, and nothing is read.
        f.set_len(100_000_000).unwrap();
        let e = read_bounded(&p, 16 << 20, "scene file").unwrap_err();
        assert!(matches!(
            e,
            ReadError::TooLarge {
                size: 100_000_000,
                at_least: false,
                ..
            }
        ));
        assert_eq!(
            e.to_string(),
            format!(
                "{}: cannot read the scene file: it is 100000000 bytes, over the 16 MiB \
                 (16777216 bytes) limit for a scene file",
                p.display()
            )
        );
        // One byte over a small limit.
        std::fs::write(&p, b"123456").unwrap();
        let e = read_bounded(&p, 5, "mesh file").unwrap_err();
        assert!(
            matches!(
                e,
                ReadError::TooLarge {
                    size: 6,
                    limit: 5,
                    ..
                }
            ),
            "{e}"
        );
    }

    /// A reader that counts what is taken from it and never ends (like `/dev/zero`).
    struct Endless<'a>(&'a mut u64);

    impl Read for Endless<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            buf.fill(0);
            *self.0 += buf.len() as u64;
            Ok(buf.len())
        }
    }

    #[test]
    fn an_endless_input_is_read_only_to_one_byte_past_the_limit() {
        let mut taken = 0;
        let data = read_limited(Endless(&mut taken), 1000, 0).unwrap();
        assert_eq!(data.len(), 1001);
        assert_eq!(taken, 1001);
        // A size hint beyond the limit does not allocate beyond it.
        let mut taken = 0;
        let data = read_limited(Endless(&mut taken), 10, u64::MAX).unwrap();
        assert_eq!((data.len(), taken), (11, 11));
        assert!(data.capacity() < 64, "capacity {}", data.capacity());
    }

    #[cfg(unix)]
    #[test]
    fn devices_and_directories_are_refused_unopened() {
        let e = read_bounded(Path::new("/dev/zero"), 1 << 20, "scene file").unwrap_err();
        assert_eq!(
            e.to_string(),
            "/dev/zero: cannot read the scene file: it is a character device, not a regular file"
        );
        let dir = std::env::temp_dir();
        let e = read_bounded(&dir, 1 << 20, "mesh file").unwrap_err();
        assert!(
            matches!(
                e,
                ReadError::NotAFile {
                    kind: "a directory",
                    ..
                }
            ),
            "{e}"
        );
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_refused_without_waiting_for_a_writer() {
        let p = scratch("pipe");
        let made = std::process::Command::new("mkfifo")
            .arg(&p)
            .status()
            .unwrap();
        assert!(made.success());
        // A writer that blocks until someone opens the FIFO for reading, then writes a scene
        // and closes: if `read_bounded` opened the FIFO it would read this and succeed
        // instead of hanging, so a regression fails below rather than blocking the test.
        let writer = {
            let p = p.clone();
            std::thread::spawn(move || {
                use std::io::Write;
                let mut w = std::fs::OpenOptions::new().write(true).open(&p).unwrap();
                w.write_all(b"Scene()").unwrap();
            })
        };
        let r = read_bounded(&p, 1 << 20, "scene file");
        // Release the writer (a non-blocking open for reading never waits).
        let release = open_nonblocking(&p).unwrap();
        writer.join().unwrap();
        drop(release);
        let e = r.unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{}: cannot read the scene file: it is a FIFO (named pipe), not a regular file",
                p.display()
            )
        );
    }

    #[test]
    fn text_must_be_utf8() {
        let p = scratch("latin1.csv");
        std::fs::write(&p, b"a,b\n\xe9,1\n").unwrap();
        let e = read_text_bounded(&p, 100, "CSV file").unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{}: cannot read the CSV file: it is not UTF-8 text (invalid byte at offset 4)",
                p.display()
            )
        );
        std::fs::write(&p, "a,b\né,1\n").unwrap();
        assert_eq!(
            read_text_bounded(&p, 100, "CSV file").unwrap(),
            "a,b\né,1\n"
        );
    }

    #[test]
    fn a_missing_file_names_the_path() {
        let e = read_bounded(Path::new("no/such/file.obj"), 10, "mesh file").unwrap_err();
        assert!(matches!(e, ReadError::Io { .. }));
        assert!(
            e.to_string()
                .starts_with("no/such/file.obj: cannot read the mesh file: "),
            "{e}"
        );
    }

    #[test]
    fn command_line_numbers() {
        assert_eq!(parse_image_side("4096"), Ok(4096));
        assert_eq!(parse_image_side("1"), Ok(1));
        for bad in ["0", "4097", "65535", "-1", "x", "99999999999"] {
            assert_eq!(
                parse_image_side(bad),
                Err("an image side is 1 to 4096 pixels".to_string()),
                "{bad}"
            );
        }
        assert_eq!(parse_threads("0"), Ok(0));
        assert_eq!(parse_threads("256"), Ok(256));
        assert!(parse_threads("257").is_err());
        assert_eq!(parse_max_depth("16"), Ok(16));
        assert!(parse_max_depth("17").is_err());
        assert_eq!(parse_nodes("256"), Ok(256));
        assert!(parse_nodes("0").is_err());
        assert!(parse_nodes("4000000000").is_err());
        assert_eq!(parse_bit_rate_mhz("42"), Ok(42.0));
        for bad in ["0", "1e-300", "NaN", "inf", "1e5"] {
            assert!(parse_bit_rate_mhz(bad).is_err(), "{bad}");
        }
    }
}
