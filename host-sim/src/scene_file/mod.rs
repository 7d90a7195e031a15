//! Scene files: being written.
