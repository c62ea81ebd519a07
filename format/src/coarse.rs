//! Coarse bricks: the far field of a probe's factor table, brick by brick of a coarser grid.
//!
//! A probe's rays spread apart with distance: 512 rays are about 0.16 rad apart, so beyond a
//! few brick sizes nearly every ray hits a brick of its own and the factor table holds a
//! factor per ray (about 320 of them at 16 bytes on the default grid, 5 KB a probe, in format 8). Rays
//! that travel far are instead grouped by a brick of a coarser level: level `l` covers
//! `2^l x 2^l x 2^l` bricks of one normal key (same dominant axis, same side), and a hit
//! `d` from its probe goes to the level whose brick is at most `2/R` radians wide seen from
//! there (`R` the bake's `far_ratio`), but no coarser than level 3, cells of 8 bricks
//! (`prt_bake::merge::coarse::FAR_LEVELS`); the factor then reads the lowest level whose
//! brick holds all its hits, which may be lower (rays that land in one corner of a cell: a
//! floor seen through a door). That is what the prior art does for radiance caches
//! (Unreal's volumetric lightmap bricks refined near geometry, clipmaps of DDGI-like caches),
//! applied to the transfer: the factor's rays, SH transfer and mean hit point are kept as
//! they are; only the radiance they multiply is the coarse brick's.
//!
//! A coarse brick's radiance is the same linear model as a brick's, fitted by the same
//! weighted least squares over all the surfels of its bricks, computed at run time from its
//! bricks' models without touching a surfel: with `W_c`, `mu_c`, `M_c` a brick's weight,
//! centroid and regularised position moment (`C_c + eps_c I`, [`BrickMoments`]), its
//! radiance mean `m_c` and gradient `G_c = M_c^-1 b_c`, the coarse brick has
//!
//! `mean = sum_c W_c m_c / W`, `gradient = M^-1 sum_c (M_c G_c + W_c (mu_c - mu) m_c)`
//!
//! with `W`, `mu`, `M` its own (`M^-1` stored as [`CoarseBrick::inverse`]). Both equal the fit
//! over the union of the bricks' surfels, because `M_c G_c = b_c = sum_s w_s (p_s - mu_c) L_s`.
//! The stored inverse is multiplied by `2^level` and the factors' offsets from a coarse
//! brick's centroid are divided by it, so that the packed offsets keep the range of one brick.
//!
//! Coarse bricks are numbered after the bricks: a factor whose brick index is
//! `bricks.len() + i` reads coarse brick `i`. A coarse brick has at least two bricks, and none
//! has the same bricks as a coarser one of the same place (the bake uses the finer).

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

/// Coarsest level: bricks of `2^MAX_LEVEL` bricks a side.
pub const MAX_LEVEL: u32 = 7;

/// A coarse brick ([module docs](self)): its bricks and the constants of its fit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct CoarseBrick {
    /// Its bricks: `children[first_child..first_child + child_count]`.
    pub first_child: u32,
    pub child_count: u32,
    /// Sum of its bricks' weights (their surfels' ray hits).
    pub weight: f32,
    /// 1..=[`MAX_LEVEL`]: `2^level` bricks a side.
    pub level: u32,
    /// Weighted mean of its bricks' centroids.
    pub centroid: [f32; 3],
    pub _pad0: u32,
    /// `2^level` times the inverse of its regularised position moment, symmetric: xx, xy, xz,
    /// yy, yz, zz.
    pub inverse: [f32; 6],
    pub _pad1: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<CoarseBrick>() == 64);

/// What a brick contributes to the fit of a coarse brick over it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct BrickMoments {
    /// Sum of its surfels' weights.
    pub weight: f32,
    /// `C + eps I`, the regularised weighted second moment of its surfels' positions about its
    /// centroid, of which its gradient weights are the inverse (symmetric: xx, xy, xz, yy, yz,
    /// zz).
    pub moment: [f32; 6],
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<BrickMoments>() == 32);

/// The coarse bricks of an asset; all empty when its bake made none.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CoarseBricks {
    pub bricks: Vec<CoarseBrick>,
    /// Brick indices, each coarse brick's in a run.
    pub children: Vec<u32>,
    /// Per brick of the asset (empty when there are no coarse bricks).
    pub moments: Vec<BrickMoments>,
}

/// `m x` for a symmetric 3x3 matrix stored as xx, xy, xz, yy, yz, zz.
#[inline]
pub fn symmetric_times(m: &[f32; 6], x: [f32; 3]) -> [f32; 3] {
    [
        m[0] * x[0] + m[1] * x[1] + m[2] * x[2],
        m[1] * x[0] + m[3] * x[1] + m[4] * x[2],
        m[2] * x[0] + m[4] * x[1] + m[5] * x[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_product_reads_each_entry_where_it_belongs() {
        let m = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        assert_eq!(symmetric_times(&m, [1.0, 0.0, 0.0]), [1.0, 2.0, 3.0]);
        assert_eq!(symmetric_times(&m, [0.0, 1.0, 0.0]), [2.0, 4.0, 5.0]);
        assert_eq!(symmetric_times(&m, [0.0, 0.0, 1.0]), [3.0, 5.0, 6.0]);
    }
}
