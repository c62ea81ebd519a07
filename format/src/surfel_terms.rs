//! # A surfel's surface terms in 16 bytes (format 16, issue 32)
//!
//! What the surface lookup reads per surfel ([`crate::surface`] says why each term exists):
//! which of the 27 probes around its nearest probe it sees, its near field (the rays
//! that escape, `open`, and the number that hit), its near group and its normal. Format 15
//! kept them in 32 bytes (`open` as nine IEEE halves, the normal as two snorm16, the centre
//! probe's grid index per surfel); they were the largest array of the lookup, 27.5 of the
//! 35.7 MB `prt_surface` of a 120 m street at 1 m. Now, as four words:
//!
//! | word | bits |
//! |---|---|
//! | `mask` | 0..27 the probes it sees, 27..32 its centre's code ([`CENTRE_SHIFT`]) |
//! | `normal_hits` | 0..12 and 12..24 the octahedral normal as two snorm12, 24..32 `hits` |
//! | `group_open` | 0..8 `group`, then `open` k = 1..3 as signed 8-bit codes at 8, 16, 24 |
//! | `open_l2` | `open` k = 4..8 as signed 6-bit codes at 0, 6, 12, 18, 24; bit 30 spare; bit 31 `SIDE_BIT` (format 18, `crate::surface::SIDE_BIT`) |
//!
//! - **The centre probe** (the surfel's nearest, that the mask's 27 bits are about) is stored
//!   as its offset, -1..=1 along each axis, from its brick key's centre probe
//!   ([`crate::surface::SurfaceTerms::key_centre`], which the runtime hands the GPU once per
//!   brick): a code of 1 + 27 values, 0 for a surfel whose terms were not traced (back
//!   faces). A surfel lies about its key's cell, some half a brick from its centre, so the
//!   offset is -1..=1 wherever a brick is under two lattice steps across: always with the
//!   default cells (a brick is half a spacing, a step at least half a spacing wherever the
//!   grid has three points along the axis). With cells so large that it is not (`--cell-size`),
//!   the bake stores the nearest probe the code can name and traces the mask about it.
//! - **`open`** is coded as its difference from what a surfel with `hits` of its rays blocked
//!   uniformly would see: `e A(n)` with `e` the share of rays that escape and `A(n)` the
//!   clamped-cosine transfer of the decoded normal ([`crate::surface::cosine_transfer`]). The
//!   difference of term `k` is at most `min(e, 1 - e)` times the range of `Y_k` over the
//!   sphere (the rays that escape, or those that hit, against the mean of all), plus the
//!   spiral's own departure from `A(n)` (under 0.01, one ray's share of the range covers it);
//!   codes are steps of that bound. `open_0` is `e Y_00` exactly.
//!
//! What the precision costs: with the Cornell room, fixtures/two_rooms and thick walls baked
//! with the codes' rounding simulated (`prt-bench surface`, default spacing), 8-bit codes for
//! band 1 and 6-bit for band 2 moved the open-point mean by at most 0.02 points (2.81 ->
//! 2.80%, 4.03 -> 4.02%, 2.62 -> 2.63%), as did 12-bit codes of the plain values;
//! 8 / 7 bits of the plain values (not of the difference) cost 0.1 point on Cornell. A
//! normal of two snorm10 moved nothing; two snorm12 are kept. docs/results/packing.md, format
//! 16, has the figures of the level family.

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

use crate::sh::{SH_COUNT, Y1, Y20, Y22, Y2_OFF};

/// Where a surfel's centre code starts in [`SurfelTerms::mask`]: 0 for a surfel whose terms
/// were not traced, else 1 + `(dx + 1) + 3 (dy + 1) + 9 (dz + 1)` with `(dx, dy, dz)` its
/// centre probe's offset from its brick key's ([`centre_code`]).
pub const CENTRE_SHIFT: u32 = 27;

/// Largest centre code.
pub const MAX_CENTRE_CODE: u32 = 27;

/// The centre code, in place, of a traced surfel whose centre probe is `offset` (each -1..=1)
/// from its brick key's.
pub fn centre_code(offset: [i32; 3]) -> u32 {
    let [x, y, z] = offset.map(|v| (v.clamp(-1, 1) + 1) as u32);
    (1 + x + 3 * y + 9 * z) << CENTRE_SHIFT
}

/// Bits of each octahedral normal component ([`SurfelTerms::normal_hits`]).
pub const NORMAL_BITS: u32 = 12;

/// Where `hits` starts in [`SurfelTerms::normal_hits`].
pub const HITS_AT: u32 = 24;

/// Bits of the signed code of `open` term k = 1..8 (index k - 1).
pub const OPEN_BITS: [u32; 8] = [8, 8, 8, 6, 6, 6, 6, 6];

/// Where the code of `open` term k = 1..8 starts in its word (`group_open` for k = 1..3,
/// `open_l2` for 4..8).
pub const OPEN_AT: [u32; 8] = [8, 16, 24, 0, 6, 12, 18, 24];

/// Range (largest less smallest) of `Y_k` over the sphere, k = 0..8 (docs/conventions.md
/// section 2): the bound of an `open` term's difference, per share of rays (k = 0 has no
/// code: `open_0` follows from the hits).
pub const OPEN_RANGE: [f32; SH_COUNT] = [
    0.0,
    2.0 * Y1,
    2.0 * Y1,
    2.0 * Y1,
    Y2_OFF,
    Y2_OFF,
    3.0 * Y20,
    Y2_OFF,
    2.0 * Y22,
];

/// A surfel's terms (module docs). 16 bytes; `shaders/sample_irradiance.wgsl` decodes the
/// same words.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct SurfelTerms {
    /// Bit `(dx + 1) + 3 (dy + 1) + 9 (dz + 1)`: the surfel sees the probe at grid position
    /// `centre + (dx, dy, dz)` ([`Self::centre`]); its centre code from [`CENTRE_SHIFT`].
    pub mask: u32,
    /// The unit normal `A(n)` is taken at (octahedral, two snorm12: x from bit 0, y from
    /// [`NORMAL_BITS`]) and, from [`HITS_AT`], the near-field rays that hit a surface within
    /// reach (of [`crate::surface::SurfelTermsHeader::rays`]).
    pub normal_hits: u32,
    /// The surfel's near group (bits 0..8), counted from the first group of the first brick of
    /// its key's run (`crate::surface_key_runs`), and the codes of `open` k = 1..3.
    pub group_open: u32,
    /// The codes of `open` k = 4..8.
    pub open_l2: u32,
}
const _: () = assert!(std::mem::size_of::<SurfelTerms>() == 16);

/// The bit of [`SurfelTerms::mask`] for probe `probe` around centre `centre`, or `None`
/// when it is not among the 27.
pub fn mask_bit(centre: [i32; 3], probe: [i32; 3]) -> Option<u32> {
    let d: [i32; 3] = std::array::from_fn(|a| probe[a] - centre[a]);
    d.iter()
        .all(|v| (-1..=1).contains(v))
        .then(|| ((d[0] + 1) + 3 * (d[1] + 1) + 9 * (d[2] + 1)) as u32)
}

/// `A(n)`: the mean of `Y_k(w)` over cosine-distributed directions `w` about unit `n`, the
/// `open` ([`SurfelTerms::open_and_cosine`]) of a surfel whose rays all escape (`A_l / pi * Y_k(n)` with the
/// clamped cosine's `A_l` = pi, 2pi/3, pi/4).
pub fn cosine_transfer(n: [f32; 3]) -> [f32; SH_COUNT] {
    let y = crate::sh::basis(n);
    const A: [f32; SH_COUNT] = [
        1.0,
        2.0 / 3.0,
        2.0 / 3.0,
        2.0 / 3.0,
        0.25,
        0.25,
        0.25,
        0.25,
        0.25,
    ];
    std::array::from_fn(|k| A[k] * y[k])
}

/// Levels either side of zero of a signed `bits`-bit code.
fn levels(bits: u32) -> f32 {
    ((1u32 << (bits - 1)) - 1) as f32
}

/// The signed field of `bits` bits at `at` of `word` in units of its levels, [-1, 1] but for
/// the most negative code (the inverse of [`field`]; `prt_unit_field` in WGSL).
fn unit_field(word: u32, at: u32, bits: u32) -> f32 {
    (((word << (32 - at - bits)) as i32) >> (32 - bits)) as f32 / levels(bits)
}

/// `v` in [-1, 1] as a signed `bits`-bit field at `at`.
fn field(v: f32, at: u32, bits: u32) -> u32 {
    let q = (v.clamp(-1.0, 1.0) * levels(bits)).round() as i32;
    (q as u32 & ((1u32 << bits) - 1)) << at
}

/// A unit normal's octahedral projection, in [-1, 1]^2.
pub(crate) fn oct_fold(n: [f32; 3]) -> [f32; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    let (x, y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let sign = |v: f32| if v >= 0.0 { 1.0 } else { -1.0 };
        return [(1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y)];
    }
    [x, y]
}

/// The unit normal of an octahedral projection, computed as the WGSL snippet does
/// (`prt_oct_unfold`).
pub fn oct_unfold(x: f32, y: f32) -> [f32; 3] {
    let z = 1.0 - x.abs() - y.abs();
    let t = (-z).max(0.0);
    let x = x + if x >= 0.0 { -t } else { t };
    let y = y + if y >= 0.0 { -t } else { t };
    let len = (x * x + y * y + z * z).sqrt();
    [x / len, y / len, z / len]
}

impl SurfelTerms {
    /// The terms of a surfel with normal `normal` (unit), probe mask `mask` (with its centre
    /// code, [`centre_code`]), near group `group`, `hits` of `rays` near-field rays hitting and
    /// `open` the mean over the rays of `Y_k` for those that escape.
    pub fn new(
        mask: u32,
        group: u8,
        normal: [f32; 3],
        hits: u8,
        open: &[f32; SH_COUNT],
        rays: u32,
    ) -> SurfelTerms {
        let [x, y] = oct_fold(normal);
        let mut t = SurfelTerms {
            mask,
            normal_hits: field(x, 0, NORMAL_BITS)
                | field(y, NORMAL_BITS, NORMAL_BITS)
                | u32::from(hits) << HITS_AT,
            group_open: u32::from(group),
            open_l2: 0,
        };
        let (escaping, bound, a) = t.open_frame(rays);
        for k in 1..SH_COUNT {
            let code = field(
                (open[k] - escaping * a[k]) / (bound * OPEN_RANGE[k]),
                OPEN_AT[k - 1],
                OPEN_BITS[k - 1],
            );
            match k {
                1..=3 => t.group_open |= code,
                _ => t.open_l2 |= code,
            }
        }
        t
    }

    /// The surfel's centre probe (grid position), whose brick key's centre probe is
    /// `key_centre` ([`crate::surface::SurfaceTerms::key_centre`]).
    pub fn centre(&self, key_centre: [i32; 3]) -> [i32; 3] {
        let c = (self.mask >> CENTRE_SHIFT).max(1) as i32 - 1;
        let offset = [c % 3, c / 3 % 3, c / 9];
        std::array::from_fn(|a| key_centre[a] + offset[a] - 1)
    }

    /// Whether the surfel sees grid point `probe` of `grid` ([`Self::centre`] from
    /// `key_centre`): its bit of [`SurfelTerms::mask`], or true for a probe outside the 27.
    /// The lookup weights a probe it does not see by [`crate::surface::BLOCKED_WEIGHT`]
    /// (`prt_runtime::surface`, and the bake's sky terms, which interpolate as it does).
    pub fn sees(&self, key_centre: [i32; 3], grid: &crate::Grid, probe: usize) -> bool {
        let ijk = grid.ijk(probe).map(|v| v as i32);
        mask_bit(self.centre(key_centre), ijk).is_none_or(|b| self.mask >> b & 1 != 0)
    }

    /// Whether the bake traced the surfel's terms (a front face).
    pub fn is_traced(&self) -> bool {
        self.mask >> CENTRE_SHIFT != 0
    }

    /// Near-field rays that hit a surface within reach.
    pub fn hits(&self) -> u32 {
        self.normal_hits >> HITS_AT
    }

    /// The share of its `rays` near-field rays that escape, `(rays - hits) / rays` (as
    /// `prt_sample_surface` computes it; at least one ray).
    pub fn escaping_share(&self, rays: u32) -> f32 {
        let n = rays.max(1) as f32;
        (n - self.hits() as f32) / n
    }

    /// The near group, counted from its key's first brick's first group.
    pub fn group(&self) -> u32 {
        self.group_open & 0xff
    }

    /// The unit normal (as decoded: `A(n)` is taken at it).
    pub fn normal(&self) -> [f32; 3] {
        let snorm = |at| unit_field(self.normal_hits, at, NORMAL_BITS).max(-1.0);
        oct_unfold(snorm(0), snorm(NORMAL_BITS))
    }

    /// What `open`'s codes of a surfel with `rays` near-field rays are taken from (module
    /// docs): the escaping share `e`, the bound per unit of range `min(e, 1 - e) + 1 / rays`,
    /// and `A(n)` at the decoded normal.
    fn open_frame(&self, rays: u32) -> (f32, f32, [f32; SH_COUNT]) {
        let escaping = self.escaping_share(rays);
        let bound = escaping.min(1.0 - escaping) + 1.0 / rays.max(1) as f32;
        (escaping, bound, cosine_transfer(self.normal()))
    }

    /// `open` (the mean over the near-field rays of `Y_k` for those that escape) as stored, for
    /// a surfel of `rays` rays, and `A(n)` at its normal: the lookup reads both, and the codes
    /// are taken from the latter.
    pub fn open_and_cosine(&self, rays: u32) -> ([f32; SH_COUNT], [f32; SH_COUNT]) {
        let (escaping, bound, a) = self.open_frame(rays);
        let open = std::array::from_fn(|k| {
            let base = escaping * a[k];
            if k == 0 {
                return base;
            }
            let word = if k < 4 { self.group_open } else { self.open_l2 };
            let code = unit_field(word, OPEN_AT[k - 1], OPEN_BITS[k - 1]);
            base + code * (bound * OPEN_RANGE[k])
        });
        (open, a)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Unit normals on every octant and the axes (`crate::surface`'s tests share them).
    pub(crate) fn normals() -> Vec<[f32; 3]> {
        let mut n = vec![
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
        ];
        for i in 0..200 {
            let (a, b) = (i as f32 * 0.7, i as f32 * 1.3);
            n.push([a.sin() * b.cos(), a.sin() * b.sin(), a.cos()]);
        }
        n
    }

    /// The fields come back as stored: mask, hits, group exactly, the normal within 2e-3.
    #[test]
    fn fields_round_trip() {
        for (i, n) in normals().into_iter().enumerate() {
            let (hits, group) = ((i * 7 % 65) as u8, (i * 13 % 256) as u8);
            let offset = [i as i32 % 3 - 1, i as i32 / 3 % 3 - 1, i as i32 / 9 % 3 - 1];
            let bits = (i as u32).wrapping_mul(0x9e37_79b9) & crate::surface::PROBE_BITS;
            let mask = centre_code(offset) | bits;
            let t = SurfelTerms::new(mask, group, n, hits, &[0.0; SH_COUNT], 64);
            assert_eq!(
                (t.mask, t.hits(), t.group()),
                (mask, hits.into(), group.into())
            );
            assert!(t.is_traced() && !SurfelTerms::default().is_traced());
            let centre = [4, 5, 6];
            assert_eq!(
                t.centre(centre),
                std::array::from_fn(|a| centre[a] + offset[a])
            );
            let got = t.normal();
            for a in 0..3 {
                assert!((got[a] - n[a]).abs() < 2e-3, "{n:?} -> {got:?}");
            }
        }
    }

    /// `open` of any subset of a surfel's rays decodes within half a step of its bound, and
    /// exactly for the DC term, at every share of hits; all rays escaping or none decode as
    /// the cosine transfer and as zero.
    #[test]
    fn open_terms_round_trip_within_half_a_step() {
        let rays = 64u32;
        for (i, n) in normals().into_iter().enumerate().step_by(7) {
            let cross = |a: [f32; 3], b: [f32; 3]| {
                [
                    a[1] * b[2] - a[2] * b[1],
                    a[2] * b[0] - a[0] * b[2],
                    a[0] * b[1] - a[1] * b[0],
                ]
            };
            let axis = if n[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            let c = cross(n, axis);
            let len = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            let t0 = c.map(|v| v / len);
            let t1 = cross(n, t0);
            let dirs: Vec<[f32; 3]> = (0..rays)
                .map(|k| {
                    // A cosine-distributed Fibonacci spiral, as the bake's.
                    let u = (k as f32 + 0.5) / rays as f32;
                    let (r, phi) = (u.sqrt(), k as f32 * 2.399_963);
                    let (a, b, z) = (r * phi.cos(), r * phi.sin(), (1.0 - u).sqrt());
                    std::array::from_fn(|i| t0[i] * a + t1[i] * b + n[i] * z)
                })
                .collect();
            for hits in [0u32, 1, 9, 32, 50, 63, 64] {
                // The hit rays: a run of them (a wall on one side), rotated per normal.
                let hit = |k: u32| (k + i as u32 * 5) % rays < hits;
                let mut open = [0.0f32; SH_COUNT];
                for (k, d) in dirs.iter().enumerate() {
                    if !hit(k as u32) {
                        let y = crate::sh::basis(*d);
                        (0..SH_COUNT).for_each(|j| open[j] += y[j] / rays as f32);
                    }
                }
                let t = SurfelTerms::new(centre_code([0; 3]), 0, n, hits as u8, &open, rays);
                let (got, _) = t.open_and_cosine(rays);
                let e = (rays - hits) as f32 / rays as f32;
                let bound = e.min(1.0 - e) + 1.0 / rays as f32;
                assert!((got[0] - open[0]).abs() < 1e-6, "{hits}: {got:?} {open:?}");
                for k in 1..SH_COUNT {
                    let half = 0.5 * bound * OPEN_RANGE[k] / levels(OPEN_BITS[k - 1]);
                    assert!(
                        (got[k] - open[k]).abs() <= half * 1.001 + 1e-6,
                        "{n:?} hits {hits} term {k}: {} vs {}",
                        got[k],
                        open[k]
                    );
                }
                if hits == rays {
                    assert_eq!(got, [0.0; SH_COUNT]);
                }
            }
        }
    }
}
