//! Acceleration structures over the scene's triangles, all from one obvhs PLOC build:
//!
//! - [`bvh`]: the build (and the memory it runs in) and [`bvh::SceneBvh`], what the bake
//!   traces through, in a frame scaled so that results do not depend on the scene's scale;
//! - `leaf_order`: the binary tree's triangles in leaf order, which both collapses read;
//! - [`bvh8`]: the 8-wide BVH that traces packets of rays from one probe;
//! - [`asset`]: the flattened binary BVH the asset carries for the runtime's shadow rays.

pub mod asset;
pub mod bvh;
pub mod bvh8;
pub(crate) mod leaf_order;
