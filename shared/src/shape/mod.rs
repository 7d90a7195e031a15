//! The primitives of LINKS-1 (section 2): a closed set, dispatched by `match`, never `dyn`.

pub mod blob;
pub mod boxshape;
pub mod ellipsoid;
pub mod triangle;
