//! The scene layer: what is rendered, from the description a person writes to the bytes a
//! node renders from. Builds on [`crate::math`]; the trace layer reads only [`image`].
//!
//! - [`desc`] (feature `std`): the scene as described, in world coordinates.
//! - [`anim`] (feature `std`): films: a timeline and keyframed tracks over a description, and
//!   the description at each frame.
//! - [`compile`] (feature `std`): the DM, which compiles a description into a SceneImage.
//! - [`image`]: the SceneImage: its byte layout, the zero-copy view nodes render from, its
//!   validation, the writer the DM fills (`std`) and the Q16.16 rewrite (`std`).

#[cfg(feature = "std")]
pub mod anim;
#[cfg(feature = "std")]
pub mod compile;
#[cfg(feature = "std")]
pub mod desc;
pub mod image;
