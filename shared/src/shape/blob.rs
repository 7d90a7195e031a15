//! Density spheres (metaballs): being written.
