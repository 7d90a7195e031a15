//! The RC side of the QEMU node check: the real root logic
//! (`links_core::root::run_bus`) drives one node computer in lock step, frame by frame, over
//! the IMSU link, and the frame it assembles is checked against the simulator's.
//!
//! The node is either the firmware's `run_node` under QEMU ([`QemuNode`], `tests/qemu-node`
//! on Cortex-M4F with the f32 kernel or on Cortex-M3 with the Q16.16 kernel: records over two
//! FIFOs that the firmware opens through semihosting) or the same `run_node` compiled for the
//! host ([`LocalNode`], with the same kernel). Both speak the same record
//! protocol (see `tests/qemu-node/src/main.rs`): the node reports each frame it posts (its
//! ready line goes up) and each time it waits for the link; the RC acts only while the node
//! waits. So the sequence of transfers depends on the two programs alone, not on host timing:
//! the QEMU node must send the very bytes the host node sends ([`compare_transcripts`]), and
//! the RC must assemble exactly the pixels of the simulator's single-node render
//! ([`check_outcome`]).
//!
//! By concept: [`record`] (the link's records, what a node side reports, the transcript's
//! events), [`bus`] (the lock-step bus the root logic drives, and [`run_rc`]), [`checks`]
//! (the simulator's frame, the outcome and transcript checks, damaged messages), [`local`]
//! (the host's node) and [`stream`] (the QEMU node over its FIFOs).

pub mod bus;
pub mod checks;
pub mod local;
pub mod record;
pub mod stream;

pub use bus::{run_rc, run_rc_buffered, RcOutcome};
pub use checks::{
    check_outcome, check_single_render, compare_transcripts, simulated_frame, Corrupt,
};
pub use local::LocalNode;
pub use record::{Event, NodeEnd, NodeSide, Settled};
pub use stream::{QemuNode, StreamNode};

#[cfg(test)]
mod tests;
