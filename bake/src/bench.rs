//! What `prt-bench bake` (bench/) needs of the bake's internals to time the bake against bare
//! tracing of the same rays: the triangles and BVH of the frame the bake traces in, the order
//! and packet size it traces a probe's rays in, and the grid points before any probe moves.
//!
//! The one door for the benchmarks: the internals behind it stay `pub(crate)` and may change
//! with the bake, while these few signatures are kept for the benchmark. Always compiled rather
//! than behind a cargo feature: thin wrappers that cost nothing where unused, checked by every
//! build, lint and doc run, where a feature (which the workspace would switch on anyway through
//! the bench crate) would leave them unchecked in `cargo check -p prt-bake`. Not an engine API.

use glam::Vec3;
use obvhs::triangle::Triangle;
use prt_format::Grid;

use crate::accel::bvh::SceneBvh;
use crate::error::BakeError;

pub use crate::accel::bvh::trace_scale;

/// Rays from one probe traced together as a packet ([`SceneBvh::closest_hits`] takes at most
/// this many).
pub const PACKET: usize = crate::accel::bvh8::PACKET;

/// `triangles` as obvhs triangles in the tracing frame scaled by `scale` ([`trace_scale`]): what
/// the bake builds its BVH over, so a baseline built from them traces the bake's rays.
pub fn traced_triangles(triangles: &[[Vec3; 3]], scale: f32) -> Vec<Triangle> {
    crate::accel::bvh::traced_triangles(triangles, scale)
}

/// The bake's BVH over `triangles` in the frame of `scale`, built with the preset the bake picks
/// for `rays` rays in all.
pub fn scene_bvh(triangles: &[[Vec3; 3]], scale: f32, rays: u64) -> Result<SceneBvh, BakeError> {
    SceneBvh::build_checked(triangles, scale, rays, None, || ()).map(|(bvh, ())| bvh)
}

/// The order the bake traces the lattice `directions` in, [`PACKET`] consecutive ones to a
/// packet.
pub fn coherent_order(directions: &[Vec3]) -> Vec<u32> {
    crate::trace::coherent_order(directions)
}

/// The points of `grid` in grid order (x fastest, then y, then z), before the bake moves any
/// probe off a surface or out of geometry.
pub fn grid_points(grid: &Grid) -> Vec<Vec3> {
    crate::probes::positions(grid)
}
