//! The studies the `links sweep` and `links chart` commands run over the renderers and the
//! simulated cluster, and the documents they write: the technique ablation
//! ([`ablation`], [`ablation_cluster`] on the simulated cluster, [`ablation_doc`]), speed against accuracy ([`accuracy`], [`chart`]), the
//! node-count and division sweeps ([`cluster_sweep`]), the board profiles compared
//! ([`board_study`]), a film's DM pipeline on each board ([`film_study`]), the fault sweep ([`faults`]) and the
//! picture of one cluster frame ([`timeline_chart`]).
//! [`report`] writes their tables and the generated sections of the docs;
//! [`sweep_commands`] are the `links sweep` commands over the cluster.

pub mod ablation;
pub mod ablation_cluster;
pub mod ablation_doc;
pub mod accuracy;
pub mod backend;
pub mod board_study;
pub mod chart;
pub mod cluster_sweep;
pub mod faults;
pub mod film_study;
pub mod labels;
pub mod report;
pub mod sweep_commands;
pub mod timeline_chart;
