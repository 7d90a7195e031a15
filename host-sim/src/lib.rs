//! The host side of LINKS-1: scene files, procedural scene generators, the cluster
//! simulator, the studies that write the docs, the PC side of the serial line and the `links`
//! CLI. The layer map and one frame's data flow: `docs/architecture.md`.

pub mod cli;
pub mod gen;
pub mod gltf_import;
pub mod limits;
pub mod png_codec;
pub mod qemu_node;
pub mod scene_file;
pub mod serial;
pub mod sim;
pub mod studies;
pub mod vec3;

// The paths these modules had before they were grouped into `cli`, `sim`, `studies` and
// `serial`.
pub use cli::image_file as cli_image;
pub use serial::cli as cli_serial;
pub use serial::host as serial_host;
pub use serial::sim_film;
pub use serial::sim_rc;
pub use sim::cluster;
pub use sim::cost;
pub use sim::single as frame;
pub use studies::{ablation, ablation_doc, accuracy, chart};

/// The cluster commands' options and studies, at the path they had before.
pub mod cli_cluster {
    pub use crate::sim::options::*;
    pub use crate::studies::sweep_commands::*;
}
