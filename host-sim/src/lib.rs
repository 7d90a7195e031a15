//! The host side of LINKS-1: scene files, procedural scene generators, and the `links` CLI.

pub mod ablation;
pub mod ablation_doc;
pub mod accuracy;
pub mod chart;
pub mod cli;
pub mod cli_cluster;
pub mod cli_image;
pub mod cli_serial;
pub mod cluster;
pub mod cost;
pub mod frame;
pub mod gen;
pub mod limits;
pub mod png_codec;
pub mod qemu_node;
pub mod scene_file;
pub mod serial_host;
pub mod sim_rc;
pub mod vec3;
