//! Acceleration structures over the scene's triangles, both from one obvhs PLOC build
//! (Meister & Bittner, "Parallel Locally-Ordered Clustering for Bounding Volume Hierarchy
//! Construction", 2018, with parallel reinsertion):
//!
//! - an uncompressed 8-wide BVH that the bake traces its probe rays with, a packet of rays
//!   from one probe at a time ([`crate::accel::bvh8`]);
//! - the binary BVH it was made from, flattened with children after parents and triangles in
//!   leaf order, which the asset carries so that the runtime (CPU reference and WGSL alike) can
//!   trace shadow rays with a plain stack traversal ([`crate::accel::asset`]).

use glam::Vec3;
use obvhs::{
    bvh2::{node::Bvh2Node, reinsertion::ReinsertionOptimizer, Bvh2},
    ploc::PlocBuilder,
    triangle::Triangle,
    BvhBuildParams,
};
use prt_format::Geometry;
use rayon::prelude::*;

use crate::accel::asset::flatten;
use crate::accel::bvh8::{Bvh8, PACKET};
use crate::accel::leaf_order::LeafOrder;
use crate::error::BakeError;
use crate::memory::written;

/// The power of two nearest `1 / spacing`: the bake traces in a frame where the probe spacing is
/// about one unit. The triangle test's normal and `ng . (v0 - origin)` grow with the square and
/// the cube of the coordinates (a quad scaled by 1e19 overflows f32 in metres), and obvhs 0.4's
/// traversal, which the bake used before [`crate::accel::bvh8`], clamped box entry distances to an
/// absolute 1e-4. Scaled by a power of two, every float operation of the build and traversal is
/// the same at any scene scale short of overflow, so results do not depend on the scale
/// (tests/tests/scale.rs).
pub fn trace_scale(spacing: f32) -> f32 {
    if !(spacing.is_finite() && spacing > 0.0) {
        return 1.0;
    }
    (-spacing.log2()).round().clamp(-100.0, 100.0).exp2()
}

/// `triangles` as obvhs triangles in the tracing frame scaled by `scale` ([`trace_scale`]).
pub(crate) fn traced_triangles(triangles: &[[Vec3; 3]], scale: f32) -> Vec<Triangle> {
    triangles
        .par_iter()
        .map(|t| Triangle {
            v0: (t[0] * scale).into(),
            v1: (t[1] * scale).into(),
            v2: (t[2] * scale).into(),
        })
        .collect()
}

/// Rays per triangle below which [`build_params`] takes obvhs' `fast_build` preset. Against
/// `medium_build` (a wider PLOC search, more reinsertion) it builds faster and gives a tree
/// that traces about 2% slower: the cheaper build pays until the rays are many enough for that
/// 2% to pass what it saves, at about 25 rays a triangle.
pub const FAST_BUILD_RAYS_PER_TRIANGLE: u64 = 24;

/// obvhs' build preset for tracing `rays` rays through `triangles` triangles: the cheaper
/// build when the rays are too few to repay the better tree ([`FAST_BUILD_RAYS_PER_TRIANGLE`]).
/// The asset's BVH comes from the same build.
pub fn build_params(triangles: usize, rays: u64) -> BvhBuildParams {
    if rays < FAST_BUILD_RAYS_PER_TRIANGLE.saturating_mul(triangles as u64) {
        BvhBuildParams::fast_build()
    } else {
        BvhBuildParams::medium_build()
    }
}

/// The binary BVH over `tris` by PLOC and reinsertion, as `params` set them, in `memory` when
/// given (obvhs grows what is too small; glibc may then move a block that large by remapping
/// its pages rather than copying them).
pub(crate) fn ploc(tris: &[Triangle], params: &BvhBuildParams, memory: Option<PlocMemory>) -> Bvh2 {
    let PlocMemory {
        mut builder,
        mut bvh2,
    } = memory.unwrap_or_else(|| PlocMemory {
        builder: PlocBuilder::with_capacity(tris.len()),
        bvh2: Bvh2::default(),
    });
    builder.build_with_bvh(
        &mut bvh2,
        params.ploc_search_distance,
        tris,
        (0..tris.len() as u32).collect(),
        params.sort_precision,
        params.search_depth_threshold,
    );
    ReinsertionOptimizer::default().run(&mut bvh2, params.reinsertion_batch_ratio, None);
    bvh2
}

/// What obvhs' PLOC builds a binary BVH in, its pages already written, so that the build does
/// not stop at each first touch of a page: PLOC touches its arrays from its serial passes, where
/// a page fault holds up every thread. The bake makes it beside the load, whose single thread
/// leaves the pool's other threads idle (`prt_scene::read`).
pub struct PlocMemory {
    builder: PlocBuilder,
    bvh2: Bvh2,
}

impl PlocMemory {
    /// Room for `n` triangles, every page written once: the sorted leaves and their copy, the
    /// Morton codes (two 64-bit codes a slot with obvhs' `SortPrecision::U64`, which both build
    /// presets the bake uses take), and the nodes.
    pub fn faulted(n: usize) -> PlocMemory {
        let node = Bvh2Node::default();
        let mut builder = PlocBuilder::new();
        builder.current_nodes = written(n, node);
        builder.next_nodes = written(n, node);
        builder.mortons = written(n.div_ceil(2), [0; 2]);
        let bvh2 = Bvh2 {
            nodes: written((2 * n).saturating_sub(1), node),
            ..Bvh2::default()
        };
        PlocMemory { builder, bvh2 }
    }
}

/// The scene's BVHs.
pub struct SceneBvh {
    /// The tracing frame's scale ([`trace_scale`]); the asset's geometry stays in world units.
    scale: f32,
    bvh8: Bvh8,
    /// Asset geometry: flattened BVH2 and its triangles.
    pub geometry: Geometry,
}

/// A closest hit: original triangle index and distance.
#[derive(Clone, Copy, Debug)]
pub struct TriangleHit {
    pub triangle: u32,
    pub t: f32,
}

impl SceneBvh {
    /// Builds both BVHs (in parallel on the current rayon pool), the traced one in the frame
    /// scaled by `scale` (a power of two, [`trace_scale`]), for many rays ([`build_params`]).
    pub fn build(triangles: &[[Vec3; 3]], scale: f32) -> SceneBvh {
        SceneBvh::build_beside(triangles, scale, u64::MAX, None, || ()).0
    }

    /// [`SceneBvh::build`] for tracing about `rays` rays ([`build_params`]), PLOC working in
    /// `memory` when given, running `beside` on the pool while the binary BVH is collapsed into
    /// the two the bake uses. PLOC and reinsertion take every thread; the collapse (the
    /// triangles put in leaf order by one walk, `LeafOrder`, then the two trees walked out of
    /// it side by side) is serial work that leaves room on the pool. A single-sided bake runs
    /// its winding check there: beside the PLOC build, which takes every thread, it only
    /// lengthens the stage.
    pub fn build_beside<R: Send>(
        triangles: &[[Vec3; 3]],
        scale: f32,
        rays: u64,
        memory: Option<PlocMemory>,
        beside: impl FnOnce() -> R + Send,
    ) -> (SceneBvh, R) {
        if triangles.is_empty() {
            let empty = SceneBvh {
                scale,
                bvh8: Bvh8::default(),
                geometry: Geometry::default(),
            };
            return (empty, beside());
        }
        let tris = traced_triangles(triangles, scale);
        let bvh2 = ploc(&tris, &build_params(triangles.len(), rays), memory);
        let collapse = || {
            let order = LeafOrder::of(&bvh2);
            let (bvh8, geometry) = rayon::join(
                || Bvh8::from_bvh2(&bvh2, &order, &tris),
                || flatten(&bvh2, &order, triangles, 1.0 / scale),
            );
            SceneBvh {
                scale,
                bvh8,
                geometry,
            }
        };
        rayon::join(collapse, beside)
    }

    /// [`SceneBvh::build_beside`], with a panic inside obvhs ended as an error naming the
    /// scene's extent in metres (0.4's CWBVH conversion, which the bake used before
    /// [`crate::accel::bvh8`], indexed out of bounds on boxes near f32's range, e.g. a quad scaled by
    /// 1e19; `tests/tests/hostile.rs`). A panic of `beside` is reported the same way.
    pub fn build_checked<R: Send>(
        triangles: &[[Vec3; 3]],
        scale: f32,
        rays: u64,
        memory: Option<PlocMemory>,
        beside: impl FnOnce() -> R + Send + std::panic::UnwindSafe,
    ) -> Result<(SceneBvh, R), BakeError> {
        // Triangle indices are u32, u32::MAX meaning no hit.
        if triangles.len() >= u32::MAX as usize {
            return Err(BakeError::Setting {
                name: "scene",
                value: format!("{} triangles", triangles.len()),
                reason: "more than 2^32 - 2 triangles",
            });
        }
        let build = || SceneBvh::build_beside(triangles, scale, rays, memory, beside);
        prt_scene::catch_panic(build).map_err(|message| {
            let extent = triangles
                .iter()
                .flatten()
                .fold(0.0f32, |m, v| m.max(v.abs().max_element()));
            BakeError::Bvh {
                message,
                extent,
                unit: 1.0 / scale,
            }
        })
    }

    /// Closest hit along `origin + t dir`, `t` in `[0, tmax]` (ties to the lowest triangle).
    #[inline]
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, tmax: f32) -> Option<TriangleHit> {
        self.closest_hits(origin, &[dir], tmax)[0]
    }

    /// The triangles within `radius` (along each axis) of `centre`, for short rays there
    /// ([`Near::closest_hit`]): one traversal for many rays, and none for most probes, which
    /// have nothing that near.
    pub fn near(&self, centre: Vec3, radius: f32) -> Near<'_> {
        let (c, r) = (centre * self.scale, Vec3::splat(radius * self.scale));
        Near {
            bvh: self,
            leaves: self.bvh8.leaves_in(c - r, c + r),
        }
    }

    /// [`SceneBvh::closest_hit`] of up to `PACKET` rays from one origin, traced as a packet
    /// (each ray gets the hit it gets alone).
    #[inline]
    pub fn closest_hits(
        &self,
        origin: Vec3,
        dirs: &[Vec3],
        tmax: f32,
    ) -> [Option<TriangleHit>; PACKET] {
        self.bvh8
            .closest_hits(origin * self.scale, dirs, tmax * self.scale)
            .map(|hit| self.unscaled(hit))
    }

    /// Which of up to `PACKET` rays from one origin hit anything within `tmax` (bit `k` for ray
    /// `k`): exactly those [`SceneBvh::closest_hits`] finds a hit for, each stopped at its
    /// first (`Bvh8::occluded`). For visibility: shadow rays, sky rays, probe-to-probe segments.
    #[inline]
    pub fn occluded(&self, origin: Vec3, dirs: &[Vec3], tmax: f32) -> u32 {
        self.bvh8
            .occluded(origin * self.scale, dirs, tmax * self.scale)
    }

    /// A hit of the traced frame, its distance back in world units.
    fn unscaled(&self, hit: Option<(u32, f32)>) -> Option<TriangleHit> {
        hit.map(|(triangle, t)| TriangleHit {
            triangle,
            t: t / self.scale,
        })
    }
}

/// The triangles near a point ([`SceneBvh::near`]).
pub struct Near<'a> {
    bvh: &'a SceneBvh,
    leaves: Vec<(u32, u8)>,
}

impl Near<'_> {
    /// [`SceneBvh::closest_hit`], exact for rays whose first `tmax` stays in the box the
    /// triangles were gathered from.
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, tmax: f32) -> Option<TriangleHit> {
        if self.leaves.is_empty() {
            return None;
        }
        let (bvh, scale) = (self.bvh, self.bvh.scale);
        let hit = bvh
            .bvh8
            .closest_hit_among(&self.leaves, origin * scale, dir, tmax * scale);
        bvh.unscaled(hit)
    }
}
