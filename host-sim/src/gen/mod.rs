//! Procedural generators for the bundled scenes: being written.
