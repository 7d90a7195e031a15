//! The host side of LINKS-1: scene files, procedural scene generators, and the `links` CLI.

pub mod cli;
pub mod cli_image;
pub mod cost;
pub mod gen;
pub mod limits;
pub mod png_codec;
pub mod qemu_node;
pub mod scene_file;
pub mod serial;
pub mod sim;
pub mod sim_rc;
pub mod studies;
pub mod vec3;

// The paths these modules had before they were grouped into `sim`, `studies` and `serial`.
pub use serial::cli as cli_serial;
pub use serial::host as serial_host;
pub use sim::cluster;
pub use sim::single as frame;
pub use studies::{ablation, ablation_doc, accuracy, chart};

/// The cluster commands' options and studies, at the path they had before.
pub mod cli_cluster {
    pub use crate::sim::options::*;
    pub use crate::studies::sweep_commands::*;
}
