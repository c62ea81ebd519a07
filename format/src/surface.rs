//! # Surface terms: what the lookup knows about the surface a point lies on (issue 31)
//!
//! Probes a spacing apart cannot tell a floor under a gallery from the sunlit floor beside
//! it, nor the two sides of a thin wall between layers: interpolating them leaks light across
//! occluders. The bake knows better at its surfels, so it stores per surfel what a ray tracer
//! would see there (`prt-bench surface` chose these terms on the level family's tuning seeds,
//! `docs/results/surface_candidates.md`):
//!
//! - **which probes it sees** ([`SurfelTerms::mask`]): one bit per probe of the 3x3x3 around
//!   the surfel's nearest probe, set when a ray from the surfel reaches it. The lookup weights
//!   a probe the surfel cannot see by [`BLOCKED_WEIGHT`] only (exact visibility from the bake,
//!   not the depth moments' estimate);
//! - **its near field** ([`SurfelTerms::open_and_cosine`], [`SurfelTerms::hits`]): of
//!   [`SurfelTermsHeader::rays`] cosine-distributed rays over its hemisphere, those that escape
//!   within [`SurfelTermsHeader::reach`] spacings carry the probes' radiance (`open` is the
//!   mean of their SH9 basis values: a precomputed radiance transfer vector, Sloan et al. 2002),
//!   the others (`hits` of them) the relit radiance of the surfaces they hit. What those bring
//!   is kept per **near group** (the surfels of a brick that see the same probes: one side of
//!   whatever stands on the brick), as the groups its rays hit and their shares
//!   ([`SurfaceTerms::near`], [`near_entry`]): a few bytes per surfel instead of a list each.
//!   The mask, `open`, `hits`, the group and the normal take 16 bytes a surfel since format 16
//!   ([`crate::surfel_terms`]);
//! - **how a point finds its surfel**: a hash table from brick key (the brick lattice cell and
//!   the normal's dominant axis) to brick ([`SurfaceSlot`], [`slot_hash`]), then a table of 64
//!   bytes per brick giving each of its 4x4x4 cells its nearest surfel ([`SurfaceTerms::cells`]).
//!
//! - **which side of a wall in its cell a point is on** ([`SurfaceTerms::sides`], format 18):
//!   where a zero-thickness wall crosses a surfel cell, the bake keeps the hits of each side
//!   apart (`prt_bake::merge::sides`), and the cell's named surfel lists the plane of the wall
//!   and the surfel beyond it ([`SurfaceTerms::side_of`]).
//!
//! - **its sky** ([`SurfaceTerms::sky`], format 14): probes a spacing off the surface see more
//!   or less of the sky than the surface does (a wall under an overhang, a cave's skylight, a
//!   gallery's ceiling beside an open court), and the near field, one spacing long, does not
//!   reach what hides it. The bake stores per surfel the sky the surfel sees less the sky its
//!   probes bring it ([`sky_term`]).
//!
//! The lookup then scales the interpolated irradiance by
//! `(clamp(open . L, 0, A(n) . L) + hits / rays * near) / (A(n) . L)` per colour channel, with
//! `L` the interpolated radiance SH and `A(n)` the clamped-cosine transfer of the surfel's
//! normal (what `open` is when every ray escapes; the clamp since stop 52,
//! `prt_runtime::surface`), and adds pi times the sky term times the sky's mean radiance. All of
//! it is optional: an asset baked without merging, or a point
//! whose brick has no entry, is sampled by the default lookup.

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

/// [`SurfelTerms::open_l2`]'s bit (above its codes) of a surfel listed in
/// [`SurfaceTerms::sides`]: a wall crosses its cell (format 18).
pub const SIDE_BIT: u32 = 1 << 31;

/// A surfel whose cell a wall crosses, and the surfel of the same cell on the wall's other
/// side (format 18): a point `p` of the brick key `key` with
/// `normal . (p - key corner) > offset` lies beyond the wall and reads `partner`'s terms
/// ([`SurfaceTerms::side_of`]). The plane is kept from the key's corner (the brick lattice's,
/// [`SurfaceTerms::key_corner`]), not the origin, so that the normal's rounding moves it by
/// at most a brick's width times its step, wherever the level lies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct SurfaceSide {
    pub surfel: u32,
    pub partner: u32,
    /// The wall's normal in the surfel's plane, towards `partner` ([`encode_normal`]).
    pub normal: u32,
    pub offset: f32,
}
const _: () = assert!(std::mem::size_of::<SurfaceSide>() == 16);

/// The surface lookup's default bias in probe spacings: how far along its normal a point with
/// a surfel is moved before its probes are weighed (`prt_runtime::LookupSettings::
/// surface_bias`), and where the bake interpolates the probes' sky for the sky terms
/// (`prt_bake::sky_terms`), so that the two read the probes at the same place. Stop 69 chose
/// 0.1 against the volume's 0.2 (docs/results/surface_stop69.md).
pub const SURFACE_BIAS: f32 = 0.1;

/// Weight a probe keeps when the surfel cannot see it: small enough that the visible probes
/// decide. (A surfel that sees none of the point's probes leaves their weights to the default
/// lookup.)
pub const BLOCKED_WEIGHT: f32 = 1e-4;

/// Bits of [`SurfelTerms::mask`] that say which of the 27 probes the surfel sees (its centre
/// code sits above them, [`crate::surfel_terms::CENTRE_SHIFT`]).
pub const PROBE_BITS: u32 = (1 << 27) - 1;

/// [`SurfaceSlot::value`]: the axis sits above the brick index plus one (0: an empty slot).
pub const SLOT_AXIS_SHIFT: u32 = 29;

/// Most bricks the table can name ([`SLOT_AXIS_SHIFT`] bits, minus the empty value).
pub const MAX_TABLE_BRICKS: u32 = (1 << SLOT_AXIS_SHIFT) - 2;

/// Words of [`SurfaceTerms::cells`] per brick: 64 cells of one byte.
pub const CELL_WORDS: usize = 16;

/// [`SurfaceTerms::cells`] byte of a cell with no surfel to name (none near enough among the
/// first 255 it may name).
pub const NO_SURFEL: u8 = 0xff;

/// The bake's settings for the terms, and the brick lattice.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SurfelTermsHeader {
    /// Where the brick lattice starts (world space): brick key `floor((p - anchor) / brick_size)`.
    pub anchor: [f32; 3],
    /// Edge of a brick in metres; 0 when the asset has no surface terms.
    pub brick_size: f32,
    /// Longest run of slots a search walks before it finds its key or an empty slot.
    pub max_probe: u32,
    /// Near-field rays per surfel (at most 255: [`SurfelTerms::hits`] is a byte).
    pub rays: u32,
    /// Reach of the near-field rays in probe spacings.
    pub reach: f32,
}

/// One slot of the brick table: a brick key and `(axis << SLOT_AXIS_SHIFT) | (brick + 1)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct SurfaceSlot {
    pub key: [i32; 3],
    pub value: u32,
}
const _: () = assert!(std::mem::size_of::<SurfaceSlot>() == 16);

impl SurfaceSlot {
    /// The brick the slot names, `None` for an empty slot.
    #[inline]
    pub fn brick(&self) -> Option<u32> {
        (self.value & ((1 << SLOT_AXIS_SHIFT) - 1)).checked_sub(1)
    }
}

pub use crate::surfel_terms::{cosine_transfer, mask_bit, SurfelTerms};

/// [`SurfaceTerms::near`] entry: bits 8.. the near group hit, bits 0..8 its weight in 255ths
/// of the group's near hits.
pub const NEAR_WEIGHT_BITS: u32 = 8;

/// Most near groups an asset can have (the entries' group bits).
pub const MAX_GROUPS: u32 = 1 << (32 - NEAR_WEIGHT_BITS);

/// A near entry's group and weight (the weight in (0, 1]).
pub fn near_entry(entry: u32) -> (u32, f32) {
    let mask = (1 << NEAR_WEIGHT_BITS) - 1;
    (
        entry >> NEAR_WEIGHT_BITS,
        (entry & mask) as f32 / mask as f32,
    )
}

/// Everything the surface lookup reads (module docs). Empty vectors and a zero
/// `header.brick_size`: none.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SurfaceTerms {
    pub header: SurfelTermsHeader,
    /// Open-addressed hash table of the front-face bricks, a power of two long.
    pub slots: Vec<SurfaceSlot>,
    /// Per brick, [`CELL_WORDS`] words: byte `x + 4 (y + 4 z)` is the index, counted from the
    /// brick's first surfel, of the surfel nearest the centre of cell (x, y, z), its own or a
    /// later part's of its key (format 13, `crate::surface_key_runs`), or [`NO_SURFEL`].
    pub cells: Vec<u32>,
    /// One per surfel.
    pub surfels: Vec<SurfelTerms>,
    /// Per brick, its first near group; the `group` of its surfels and of its key's later
    /// parts' counts from there.
    pub groups: Vec<u32>,
    /// Per near group, its surfels (`first, count`: consecutive, within one brick).
    pub group_surfels: Vec<[u32; 2]>,
    /// Per near group, its field: `near[first..first + count]`.
    pub near_ranges: Vec<[u32; 2]>,
    /// The groups the near-field rays hit and their shares ([`near_entry`]).
    pub near: Vec<u32>,
    /// Per surfel, its sky term ([`sky_term`]) as an IEEE half, two a word (surfel `2w` in
    /// the low half of word `w`); format 14.
    pub sky: Vec<u32>,
    /// The surfels whose cell a wall crosses ([`SIDE_BIT`]), sorted by surfel; format 18.
    pub sides: Vec<SurfaceSide>,
}

/// Surfel `surfel`'s sky term: the share of its cosine-weighted hemisphere that sees the sky
/// (the scene's outside) less the share its probes' interpolated view of the sky brings
/// through its near field's escaping rays (`prt_bake::sky_terms`). The lookup adds pi times
/// it times the sky's mean radiance to the irradiance (`prt_runtime::surface`); 0 where the
/// asset has none.
pub fn sky_term(sky: &[u32], surfel: usize) -> f32 {
    sky.get(surfel / 2).map_or(0.0, |w| {
        crate::f16_to_f32((w >> (16 * (surfel % 2))) as u16)
    })
}

impl SurfaceTerms {
    /// Whether the asset carries surface terms.
    pub fn is_empty(&self) -> bool {
        self.header.brick_size <= 0.0 || self.slots.is_empty()
    }

    /// How many surfels the bake traced terms for (front faces), and how many of those reach
    /// none of the 27 probes around them: a gap or pocket narrower than the probes' spacing, or
    /// a surface outside the grid. The lookup cannot tell which probes light those: their
    /// points take the probe volume's weights (their near field still applies).
    pub fn traced_and_blind(&self) -> (usize, usize) {
        self.surfels
            .iter()
            .filter(|s| s.is_traced())
            .fold((0, 0), |(t, b), s| {
                (t + 1, b + usize::from(s.mask & PROBE_BITS == 0))
            })
    }

    /// The brick key of `p`.
    pub fn key_of(&self, p: [f32; 3]) -> [i32; 3] {
        let h = &self.header;
        std::array::from_fn(|a| ((p[a] - h.anchor[a]) / h.brick_size).floor() as i32)
    }

    /// The probe the centres of the surfels under brick key `key` are stored from
    /// ([`SurfelTerms::centre`]; format 16): the grid point of `grid` nearest the centre of
    /// the key's lattice cell. The runtime computes it once per brick, on the CPU, and hands
    /// it to the GPU with the brick (`prt_runtime::contract::SurfaceLayout`), so both read the
    /// same.
    pub fn key_centre(&self, grid: &crate::Grid, key: [i32; 3]) -> [i32; 3] {
        let h = &self.header;
        let p = std::array::from_fn(|a| h.anchor[a] + (key[a] as f32 + 0.5) * h.brick_size);
        centre_probe(grid.origin, grid.step, grid.counts, p)
    }

    /// [`Self::key_centre`] of brick `brick`'s key (of its centroid: the key the table files
    /// it under, which validation checks): the bake, the CPU lookup and the runtime's upload
    /// for the GPU all take it from here.
    pub fn brick_centre(&self, grid: &crate::Grid, brick: &crate::Brick) -> [i32; 3] {
        self.key_centre(grid, self.key_of(brick.centroid))
    }

    /// The brick of key `key` and dominant normal axis `axis` (0..6), if the table has it.
    pub fn find(&self, key: [i32; 3], axis: u32) -> Option<u32> {
        if self.slots.is_empty() {
            return None;
        }
        let mask = self.slots.len() as u32 - 1;
        let start = slot_hash(key, axis);
        for i in 0..=self.header.max_probe {
            let s = &self.slots[(start.wrapping_add(i) & mask) as usize];
            if s.value == 0 {
                return None;
            }
            if s.key == key && s.value >> SLOT_AXIS_SHIFT == axis {
                return s.brick();
            }
        }
        None
    }

    /// The corner of brick key `key`'s lattice cell.
    pub fn key_corner(&self, key: [i32; 3]) -> [f32; 3] {
        let h = &self.header;
        std::array::from_fn(|a| h.anchor[a] + key[a] as f32 * h.brick_size)
    }

    /// The surfel (asset index) whose terms stand for point `p` of brick key `key` where the
    /// cell table named `surfel`: its partner when a wall crosses its cell and `p` lies beyond
    /// it ([`SurfaceSide`]), else `surfel`.
    pub fn side_of(&self, surfel: u32, key: [i32; 3], p: [f32; 3]) -> u32 {
        if self.surfels[surfel as usize].open_l2 & SIDE_BIT == 0 {
            return surfel;
        }
        self.side_beyond(surfel, key, p).unwrap_or(surfel)
    }

    /// [`Self::side_of`] by the sides alone (the bake's near fields read it before the terms'
    /// [`SIDE_BIT`]s are set): the partner of `surfel` when `p` lies beyond its wall.
    pub fn side_beyond(&self, surfel: u32, key: [i32; 3], p: [f32; 3]) -> Option<u32> {
        let i = self
            .sides
            .binary_search_by_key(&surfel, |s| s.surfel)
            .ok()?;
        let side = &self.sides[i];
        let (n, o) = (decode_normal(side.normal), self.key_corner(key));
        let d: f32 = (0..3).map(|a| n[a] * (p[a] - o[a])).sum();
        (d > side.offset).then_some(side.partner)
    }

    /// The cell (`x + 4 (y + 4 z)`, 0..64) of `p` in brick key `key`, as the lookup finds it:
    /// every point of the key in exactly one.
    pub fn cell_of(&self, key: [i32; 3], p: [f32; 3]) -> usize {
        let cell = self.header.brick_size / 4.0;
        let origin = self.key_corner(key);
        let c: [u32; 3] =
            std::array::from_fn(|a| (((p[a] - origin[a]) / cell).floor()).clamp(0.0, 3.0) as u32);
        (c[0] + 4 * (c[1] + 4 * c[2])) as usize
    }

    /// The centre of cell `c` ([`Self::cell_of`]'s numbering) of brick key `key`: where the
    /// bake's cell table measures each surfel's distance from.
    pub fn cell_centre(&self, key: [i32; 3], c: usize) -> [f32; 3] {
        let (corner, cell) = (self.key_corner(key), self.header.brick_size / 4.0);
        let at = [c % 4, c / 4 % 4, c / 16];
        std::array::from_fn(|a| corner[a] + (at[a] as f32 + 0.5) * cell)
    }

    /// Index in the brick of the surfel of `p`'s cell in brick `brick` of key `key`, if any.
    pub fn surfel_in(&self, brick: u32, key: [i32; 3], p: [f32; 3]) -> Option<u32> {
        let byte = self.cell_of(key, p);
        let word = self.cells.get(brick as usize * CELL_WORDS + byte / 4)?;
        let s = (word >> (8 * (byte % 4))) as u8;
        (s != NO_SURFEL).then_some(u32::from(s))
    }
}

/// Dominant axis of a normal: 0..6 for +X, -X, +Y, -Y, +Z, -Z (ties to the lower axis). The
/// bake keys its bricks by it; the lookup finds a point's brick by it.
pub fn dominant_axis(n: [f32; 3]) -> u32 {
    let a = n.map(f32::abs);
    let (axis, v) = if a[0] >= a[1] && a[0] >= a[2] {
        (0, n[0])
    } else if a[1] >= a[2] {
        (1, n[1])
    } else {
        (2, n[2])
    };
    2 * axis + u32::from(v < 0.0)
}

/// A unit normal as two snorm16 of its octahedral projection (WGSL's `pack2x16snorm` layout:
/// x in the low half).
pub fn encode_normal(n: [f32; 3]) -> u32 {
    let [x, y] = crate::surfel_terms::oct_fold(n);
    let q = |v: f32| u32::from((v.clamp(-1.0, 1.0) * 32767.0).round() as i16 as u16);
    q(x) | q(y) << 16
}

/// The unit normal of [`encode_normal`]'s bits, computed as the WGSL snippet does.
pub fn decode_normal(bits: u32) -> [f32; 3] {
    let f = |h: u32| (f32::from(h as u16 as i16) / 32767.0).max(-1.0);
    crate::surfel_terms::oct_unfold(f(bits & 0xffff), f(bits >> 16))
}

/// Where the search for a brick key starts in the table (before masking by its length); the
/// WGSL snippet computes the same (`shaders/sample_irradiance.wgsl`).
pub fn slot_hash(key: [i32; 3], axis: u32) -> u32 {
    let mut h = (key[0] as u32).wrapping_mul(0x8da6_b343);
    h ^= (key[1] as u32).wrapping_mul(0xd816_3841);
    h ^= (key[2] as u32).wrapping_mul(0xcb1a_b31f);
    h ^= axis.wrapping_mul(0x9e37_79b9);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^ (h >> 15)
}

/// Grid index (i, j, k) of the probe nearest `p` in a grid of `origin`, `step` and `counts`:
/// the centre of a surfel's [`SurfelTerms::mask`].
pub fn centre_probe(origin: [f32; 3], step: [f32; 3], counts: [u32; 3], p: [f32; 3]) -> [i32; 3] {
    std::array::from_fn(|a| {
        let last = counts[a].saturating_sub(1) as f32;
        ((p[a] - origin[a]) / step[a]).round().clamp(0.0, last) as i32
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sh::SH_COUNT;

    /// Every inserted key is found, absent keys are not, whatever the table's collisions.
    #[test]
    fn the_table_finds_what_it_holds() {
        let keys: Vec<([i32; 3], u32)> = (0..300)
            .map(|i| ([i % 7 - 3, i / 7 % 5, -(i / 35)], (i % 6) as u32))
            .collect();
        let len = 1024usize;
        let mut slots = vec![SurfaceSlot::default(); len];
        let mut max_probe = 0;
        for (b, &(key, axis)) in keys.iter().enumerate() {
            let mut i = 0;
            loop {
                let at = (slot_hash(key, axis).wrapping_add(i) as usize) & (len - 1);
                if slots[at].value == 0 {
                    slots[at] = SurfaceSlot {
                        key,
                        value: axis << SLOT_AXIS_SHIFT | (b as u32 + 1),
                    };
                    max_probe = max_probe.max(i);
                    break;
                }
                i += 1;
            }
        }
        let t = SurfaceTerms {
            header: SurfelTermsHeader {
                brick_size: 1.0,
                max_probe,
                ..Default::default()
            },
            slots,
            ..Default::default()
        };
        for (b, &(key, axis)) in keys.iter().enumerate() {
            assert_eq!(t.find(key, axis), Some(b as u32));
        }
        assert_eq!(t.find([100, 0, 0], 0), None);
        assert_eq!(t.find(keys[0].0, 6), None);
    }

    /// Normals survive the octahedral encoding to within 1e-4, on every octant and the axes.
    #[test]
    fn normals_round_trip() {
        for v in crate::surfel_terms::tests::normals() {
            let got = decode_normal(encode_normal(v));
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            for a in 0..3 {
                assert!((got[a] - v[a] / len).abs() < 1e-4, "{v:?} -> {got:?}");
            }
        }
    }

    #[test]
    fn mask_bits_cover_the_27_probes_once() {
        let mut seen = 0u32;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let bit = mask_bit([5, 5, 5], [5 + dx, 5 + dy, 5 + dz]).unwrap();
                    assert_eq!(seen & 1 << bit, 0);
                    seen |= 1 << bit;
                }
            }
        }
        assert_eq!(seen, PROBE_BITS);
        assert_eq!(mask_bit([5, 5, 5], [7, 5, 5]), None);
    }

    /// `A(n) . L` is the clamped-cosine irradiance over pi: a constant radiance 1 gives 1.
    #[test]
    fn the_cosine_transfer_of_a_constant_sky_is_one() {
        let mut l = [0.0f32; SH_COUNT];
        l[0] = 1.0 / crate::sh::basis([0.0, 0.0, 1.0])[0];
        for n in [[0.0, 0.0, 1.0], [0.6, 0.0, -0.8], [0.0, -1.0, 0.0]] {
            let a = cosine_transfer(n);
            let dot: f32 = (0..SH_COUNT).map(|k| a[k] * l[k]).sum();
            assert!((dot - 1.0).abs() < 1e-6, "{dot}");
        }
    }
}
