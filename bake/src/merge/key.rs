//! Brick keys: which brick a ray hit belongs to, by its world cell and its normal's dominant
//! axis, so that the two sides of a thin wall never share a brick.

use glam::Vec3;
use prt_format::BRICK_BACKFACE;

use crate::trace::Hit;

/// Dominant axis of a normal: 0..6 for +X, -X, +Y, -Y, +Z, -Z
/// ([`prt_format::surface::dominant_axis`], which the lookup shares).
pub fn dominant_axis(n: Vec3) -> u32 {
    prt_format::surface::dominant_axis(n.to_array())
}

/// Brick cell (x, y, z) and flags (dominant axis | backface).
pub(crate) type Key = (i32, i32, i32, u32);

/// A hit's brick flags: its normal's dominant axis, and whether it is a back face.
pub(crate) fn flags_of(h: &Hit) -> u32 {
    dominant_axis(h.normal) | if h.backface { BRICK_BACKFACE } else { 0 }
}

/// The key of the brick of `hit` in the lattice of `brick_size` bricks from `anchor`: its cell
/// and flags. The fold and the coarse cells of far hits ([`crate::merge::coarse`]) both take
/// it from here, so that a hit's coarse cell is its brick's, bit for bit.
#[inline]
pub(crate) fn brick_key(hit: &Hit, anchor: Vec3, brick_size: f32) -> Key {
    let c = ((hit.position - anchor) / brick_size)
        .to_array()
        .map(floor_i32);
    (c[0], c[1], c[2], flags_of(hit))
}

/// The centre of the surfel cell of `p` (cells of `cell_size` from `anchor`, four to a brick),
/// found as the fold finds a hit's cell ([`crate::merge::fold::BrickFolder::fold`]): its
/// brick's corner, then the cell within it, so that a point on a cell boundary lies in the same
/// cell for both.
#[inline]
pub(crate) fn cell_centre(p: Vec3, anchor: Vec3, cell_size: f32) -> Vec3 {
    let brick_size = 4.0 * cell_size;
    let key = ((p - anchor) / brick_size).to_array().map(floor_i32);
    let origin = anchor + Vec3::new(key[0] as f32, key[1] as f32, key[2] as f32) * brick_size;
    let cell = cell_in_brick(p, origin, cell_size).map(|c| c as f32);
    origin + (Vec3::from(cell) + 0.5) * cell_size
}

/// The cell (0..4 along each axis) of `p` in the brick whose corner is `origin`, cells of
/// `cell_size`: the fold's and [`cell_centre`]'s.
#[inline]
pub(crate) fn cell_in_brick(p: Vec3, origin: Vec3, cell_size: f32) -> [u32; 3] {
    ((p - origin) / cell_size)
        .to_array()
        .map(|c| floor_i32(c).clamp(0, 3) as u32)
}

/// `v.floor() as i32` (saturating, NaN to 0) by truncation: the baseline x86-64 target has no
/// SSE4.1 `roundps`, so `floor` is a call to a software routine, and the fold takes six a hit.
#[inline]
pub(crate) fn floor_i32(v: f32) -> i32 {
    let t = v as i32;
    if t as f32 > v {
        t.saturating_sub(1)
    } else {
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`floor_i32`] is `floor` then a saturating cast, for every 61st float of all 2^32 bit
    /// patterns (NaNs among them), the infinities, and around every integer near zero.
    #[test]
    fn floor_by_truncation_is_floor() {
        let check = |v: f32| assert_eq!(floor_i32(v), v.floor() as i32, "{v:e}");
        for bits in (0..=u32::MAX).step_by(61) {
            check(f32::from_bits(bits));
        }
        check(f32::INFINITY);
        check(f32::NEG_INFINITY);
        for n in -300..300 {
            let v = n as f32;
            for w in [
                v,
                v.next_down(),
                v.next_up(),
                v + 0.5,
                -0.0,
                2147483520.0,
                -2147483648.0,
            ] {
                check(w);
            }
        }
    }
}
