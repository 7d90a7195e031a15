//! Simulated renders on the host: one picture on the host's own threads ([`single`]), and
//! the whole LINKS-1 cluster in deterministic virtual time ([`cluster`]), with the option
//! types the `links` commands build a cluster run from ([`options`]) and the op-count cycle
//! model that turns a node's operation counts into time ([`cost`]).

pub mod cluster;
pub mod cost;
pub mod film;
pub mod options;
pub mod single;
