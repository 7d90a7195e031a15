//! The PC side of the serial link to a real RC (`links upload`, `links readback`), over any
//! byte stream (a serial port, a pseudo-terminal), speaking [`links_core::serial`]:
//!
//! - [`port`]: opening a port, the clock the waits run on, a line with deadlines;
//! - [`upload`](mod@upload): sending a SceneImage;
//! - [`readback`](mod@readback): reading a rendered frame back, assembled by
//!   [`assembly`];
//! - [`film`]: streaming a film (`links upload --frames`): uploads and readback on one line;
//! - [`error`]: why either failed;
//! - [`cli`]: the `links upload` / `links readback` commands around them;
//! - [`sim_film`]: a simulated RC serving a film (two scene banks, the PC's flow control);
//! - [`sim_rc`]: a simulated RC (the firmware's own session) for the tests.

pub mod assembly;
pub mod cli;
pub mod error;
pub mod film;
pub mod port;
pub mod readback;
pub mod sim_film;
pub mod sim_rc;
pub mod upload;

pub use assembly::FrameAssembly;
pub use error::HostSerialError;
pub use film::{stream_film, stream_film_with_clock, FilmEvent, FilmOptions, FilmReport};
pub use port::{open_port, Clock, SystemClock, VirtualClock, DEFAULT_BAUD};
pub use readback::{readback, readback_with_clock, Readback, ReadbackEvent, ReadbackOptions};
pub use upload::{
    upload, upload_deadline, upload_with_clock, UploadOptions, UploadReport, MAX_STALE_ANSWERS,
};

/// The module these items had before the link was split by concept.
pub mod host {
    pub use super::*;
}
