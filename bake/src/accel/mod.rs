//! Acceleration structures over the scene's triangles: the PLOC build, the 8-wide BVH the
//! probes' ray packets are traced through, and the binary BVH the asset carries.

pub mod bvh;
pub mod bvh8;
