//! A probe's factor table as stored: one factor per brick its rays hit (the brick, the ray
//! count, the SH transfer k = 1..9 and the rays' mean hit offset), in three precisions. The
//! runtime uploads the table as it is; `shaders/gather.wgsl` decodes the same layouts
//! (`FACTOR_FORMAT`, `FACTOR_WORDS`).

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

use crate::lobe::{a2_level, lobe_terms, r_level};
use crate::sh::SH_COUNT;
use crate::snorm::{snorm8_div4, snorm8_div8};

/// How factor transfer coefficients are stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum TransferPrecision {
    /// 8 x f32 transfer and 3 x f32 offset per factor (56 bytes with brick index and ray count).
    F32,
    /// 8 + 3 IEEE halves per factor (32 bytes with brick index and ray count).
    F16,
    /// 8-byte slots ([`FactorSlot`]): 24-bit brick index, 8-bit ray count, offsets as 6-bit
    /// fields of the brick size, and either the 9-bit `R` and 4-bit band-2 scale of a lobe
    /// about the direction to the factor's stored point ([`crate::lobe`]; one slot, nearly
    /// every factor) or, in a second slot, SH terms 1..3 as 7-bit and 4..8 as 5-bit fields
    /// relative to the factor's DC term: the default. Issue 32 bounds a default's error against the Cornell reference
    /// (0.1 m, 2048 rays) at 3.81% (1.15x the exact 512-ray bake's); see
    /// docs/results/packing.md for each encoding's.
    #[default]
    U8,
}

/// One factor, f32 transfer: brick `brick` contributes its radiance times the SH9 transfer
/// `4pi/N sum_{probe rays i into the brick} Y_k(w_i)` to its probe. `k = 0` is stored exactly as
/// the ray count (`Y_0` is constant), so a probe's bookkeeping (rays into bricks + sky rays = N)
/// is exact whatever the precision; `sh[k-1]` holds `k = 1..9`. `offset` is the mean hit point
/// of those rays relative to the brick's centroid: the radiance the probe sees is the brick's
/// linear model evaluated there, `max(0, L_mean + G . offset)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct FactorF32 {
    pub brick: u32,
    pub rays: u32,
    pub sh: [f32; 8],
    pub offset: [f32; 3],
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<FactorF32>() == 56);

impl FactorF32 {
    /// One finished row (brick, rays, transfer k = 1..9, offset) as an f32 factor.
    pub fn of(&(brick, rays, sh, offset): &FactorRow) -> FactorF32 {
        FactorF32 {
            brick,
            rays,
            sh,
            offset,
            _pad: 0,
        }
    }
}

/// One factor, half-float transfer: as [`FactorF32`]; `sh` packs the 8 halves two per word and
/// `offset` the 3 offset halves (and a zero), low half first (WGSL `unpack2x16float` order).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct FactorF16 {
    pub brick: u32,
    pub rays: u32,
    pub sh: [u32; 4],
    pub offset: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<FactorF16>() == 32);

impl FactorF16 {
    /// One finished row (brick, rays, transfer k = 1..9, offset) as a half-float factor.
    pub fn of(&(brick, rays, sh, o): &FactorRow) -> FactorF16 {
        FactorF16 {
            brick,
            rays,
            sh: std::array::from_fn(|w| pack2(sh[2 * w], sh[2 * w + 1])),
            offset: [pack2(o[0], o[1]), pack2(o[2], 0.0)],
        }
    }
}

/// One factor of [`TransferPrecision::U8`] as the baker builds it, before the asset packs it
/// into one or two [`FactorSlot`]s: `brick_rays` = brick << 8 | rays (1..=255; the baker
/// splits larger counts over several factors of the same brick); `packed` holds 12 bytes, low
/// byte first: offset x, y, z in steps of [`OFFSET_BITS`] (times the `offset_scale` of
/// [`Factors::U8`]), then SH terms 1..8 in steps of their [`SH_BITS`] (a step being the term's [`SH_RANGE`]
/// times the DC term `rays * 4pi/N * Y00` over its levels), a signed byte each, then a zero
/// (the baker's own use while it encodes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct FactorU8 {
    pub brick_rays: u32,
    pub packed: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<FactorU8>() == 16);

impl FactorU8 {
    /// The 8-bit transfer of `rays` (at most [`U8_MAX_RAYS`]) of a probe's `ray_count` rays with
    /// transfer `sh` (k = 1..9), brick and offset left zero for [`FactorU8::place`]. The baker
    /// encodes a probe's transfers as it is traced, before its bricks are numbered.
    #[inline]
    pub fn transfer(rays: u32, sh: [f32; 8], ray_count: u32) -> FactorU8 {
        FactorU8::transfer_with(rays, sh, FactorU8::dc_per_ray(ray_count))
    }

    /// The DC term of one ray of a lattice of `ray_count` rays, `4pi / ray_count * Y00`, the
    /// unit of [`FactorU8::transfer_with`].
    #[inline]
    pub fn dc_per_ray(ray_count: u32) -> f32 {
        crate::directions::direction_weight(ray_count) * crate::sh::Y00
    }

    /// [`FactorU8::transfer`] with the lattice's [`FactorU8::dc_per_ray`] worked out once for
    /// all of a probe's rows (an f64 division a row otherwise). The eight terms are quantised
    /// together (SSE2, in the crate's `snorm` module); one at a time, the baker spent about
    /// 50 ns a row here.
    #[inline]
    pub fn transfer_with(rays: u32, sh: [f32; 8], dc_per_ray: f32) -> FactorU8 {
        let dc = rays as f32 * dc_per_ray;
        // Terms 1..8 in bytes 3..10 of `packed`: snorm8 of the term over a range 127/L times
        // wider is the term in steps of its range over L, clamped to its L levels below.
        let unit: [f32; 8] = std::array::from_fn(|k| sh[k] * SH_UNIT[k]);
        let q = snorm8_div8(unit, dc);
        let q: [u32; 8] = std::array::from_fn(|k| clamp_levels(q[k], SH_BITS[k]));
        FactorU8 {
            brick_rays: rays,
            packed: [
                q[0] << 24,
                q[1] | q[2] << 8 | q[3] << 16 | q[4] << 24,
                q[5] | q[6] << 8 | q[7] << 16,
            ],
        }
    }

    /// The rays' mean direction times the length of their mean vector (`R d`), from the
    /// quantised band-1 terms (`Y_1 = Y1 * (y, z, x)`, so each term over the DC term is
    /// `sqrt(3) R d` along its axis).
    pub fn mean_vector(&self) -> [f32; 3] {
        let term = |k: usize| {
            let i = 3 + k;
            let byte = (self.packed[i / 4] >> (8 * (i % 4))) as u8 as i8;
            f32::from(byte) / levels(SH_BITS[k]) * SH_RANGE[k] / 3f32.sqrt()
        };
        [term(2), term(0), term(1)]
    }

    /// This transfer from brick `brick` (at most [`U8_MAX_BRICK`]) whose rays' mean hit point
    /// is `offset` from its centroid (metres; `offset_scale` as in [`Factors::U8`]).
    #[inline]
    pub fn place(self, brick: u32, offset: [f32; 3], offset_scale: f32) -> FactorU8 {
        let mut packed = self.packed;
        let unit = 127.0 / levels(OFFSET_BITS);
        let o = offset.map(|o| o / unit);
        let q = snorm8_div4([o[0], o[1], o[2], 0.0], offset_scale);
        let q = q.map(|b| clamp_levels(b, OFFSET_BITS));
        packed[0] |= q[0] | q[1] << 8 | q[2] << 16;
        FactorU8 {
            brick_rays: (brick << 8) | (self.brick_rays & 0xff),
            packed,
        }
    }
}

/// Metres per unit of the packed offsets of factors of bricks `brick_size` metres wide.
pub fn u8_offset_scale(brick_size: f32) -> f32 {
    if brick_size > 0.0 {
        brick_size
    } else {
        1.0
    }
}

/// Largest |Y_k / Y_0| of each SH term k = 1..8 over the sphere (`crate::sh::basis`): the range
/// of the packed terms relative to the DC term. Band 1: sqrt(3); the four off-axis terms of
/// band 2: sqrt(15) / 2; `Y20`: sqrt(5).
pub const SH_RANGE: [f32; 8] = {
    use crate::sh::{Y00, Y1, Y20, Y22, Y2_OFF};
    let (l1, off, y20, y22) = (Y1 / Y00, 0.5 * Y2_OFF / Y00, 2.0 * Y20 / Y00, Y22 / Y00);
    [l1, l1, l1, off, off, y20, off, y22]
};

/// Bits of each packed SH term k = 1..8: band 1, which weighs 2.7x band 2 in irradiance
/// (`2pi/3` against `pi/4`), gets 7; band 2 gets 5. With 5 bits for every term (one range
/// for all) Cornell's accuracy at 0.065 m fell from 2.25% to 2.82% and the closed box's
/// 8-bounce furnace was 1.06% off (bound 1%).
pub const SH_BITS: [u32; 8] = [7, 7, 7, 5, 5, 5, 5, 5];

/// Bits of each offset axis of a packed factor (6: a 62nd of the brick).
pub const OFFSET_BITS: u32 = 6;

/// Where term k = 1..8 starts in the 64 bits of a [`FactorU8`]'s offsets and terms, after
/// the three offsets (`packed_bits`).
const SH_AT: [u32; 8] = {
    let mut at = [0; 8];
    let mut p = 3 * OFFSET_BITS;
    let mut k = 0;
    while k < 8 {
        at[k] = p;
        p += SH_BITS[k];
        k += 1;
    }
    assert!(p == 64, "the fields fill the 64 bits");
    at
};

/// Steps on each side of zero of a signed field of `bits` bits.
pub const fn levels(bits: u32) -> f32 {
    ((1u32 << (bits - 1)) - 1) as f32
}

/// Per term, what multiplies it before the snorm8 quantiser (divided by the DC term) gives its
/// steps: `L / (range * 127)`.
const SH_UNIT: [f32; 8] = {
    let mut u = [0.0; 8];
    let mut k = 0;
    while k < 8 {
        u[k] = levels(SH_BITS[k]) / (SH_RANGE[k] * 127.0);
        k += 1;
    }
    u
};

/// A snorm8 byte as a signed field of `bits` bits: clamped to its levels, as a byte.
fn clamp_levels(byte: u32, bits: u32) -> u32 {
    let level = levels(bits) as i8;
    u32::from((byte as u8 as i8).clamp(-level, level) as u8)
}

/// The three offsets (from bit 0) and eight terms (at [`SH_AT`]) of the baker's factor `f` as
/// signed fields of one 64-bit word (its last byte, the baker's own, is dropped).
fn packed_bits(f: &FactorU8) -> u64 {
    let byte = |i: usize| u64::from((f.packed[i / 4] >> (8 * (i % 4))) & 0xff);
    let field = |i: usize, bits: u32| byte(i) & ((1 << bits) - 1);
    let mut v = 0u64;
    for a in 0..3 {
        v |= field(a, OFFSET_BITS) << (a as u32 * OFFSET_BITS);
    }
    for k in 0..8 {
        v |= field(3 + k, SH_BITS[k]) << SH_AT[k];
    }
    v
}

/// The signed field of `bits` bits at bit `at` of `v`, as a float.
fn signed_field(v: u64, at: u32, bits: u32) -> f32 {
    let q = ((v >> at) as u32 & ((1 << bits) - 1)) as i32;
    ((q << (32 - bits)) >> (32 - bits)) as f32
}

/// Where a head's `R` code starts in [`FactorSlot::bits`], after the three offsets.
pub const R_AT: u32 = 3 * OFFSET_BITS;
/// Bit of a head's [`FactorSlot::bits`] set when its terms follow in a continuation slot.
pub const SLOT_FULL: u32 = 1 << (R_AT + crate::lobe::R_BITS);

/// Where a lobe head's band-2 scale code starts in [`FactorSlot::bits`], after [`SLOT_FULL`]
/// (it fills the word).
pub const A2_AT: u32 = R_AT + crate::lobe::R_BITS + 1;
const _: () = assert!(A2_AT + crate::lobe::A2_BITS == 32);

/// Where term k = 1..8 starts in a continuation's 64 bits (`brick_rays | bits << 32`), after
/// its ray count of zero.
pub const TERMS_AT: [u32; 8] = {
    let mut at = [0; 8];
    let mut k = 0;
    while k < 8 {
        at[k] = SH_AT[k] - 3 * OFFSET_BITS + 8;
        k += 1;
    }
    assert!(at[7] + SH_BITS[7] <= 64, "the terms fit the continuation");
    at
};

/// The frame a factor's lobe is decoded in: its brick's (or coarse brick's) centroid, the
/// metres per unit of its packed offset, and the ray origin of the probe whose table holds it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LobeFrame {
    pub centroid: [f32; 3],
    pub offset_metres: f32,
    pub origin: [f32; 3],
}

/// One slot of a [`TransferPrecision::U8`] table, 8 bytes. A factor takes one slot, a lobe
/// factor ([`crate::lobe`]), or two, a head with [`SLOT_FULL`] set and a continuation slot
/// that holds its eight terms. `shaders/gather.wgsl` decodes the same.
///
/// - A head: `brick_rays` = brick << 8 | rays (1..=255, as [`FactorU8`]); `bits` holds the
///   three offsets as signed [`OFFSET_BITS`]-bit fields from bit 0 (times the `offset_scale`
///   of [`Factors::U8`]), then the lobe's `R` code ([`crate::lobe::R_BITS`] bits at
///   [`R_AT`]), then [`SLOT_FULL`], then the lobe's band-2 scale code
///   ([`crate::lobe::A2_BITS`] bits at [`A2_AT`]); a full head's lobe codes are zero.
/// - A continuation: a ray count of zero (its low byte), so that a reader striding over slots
///   skips it, and SH term k = 1..8 as a signed field of `SH_BITS[k - 1]` bits at
///   `TERMS_AT[k - 1]` of the 64-bit word `brick_rays | bits << 32`, in steps of the term's
///   [`SH_RANGE`] times the DC term over its levels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct FactorSlot {
    pub brick_rays: u32,
    pub bits: u32,
}
const _: () = assert!(std::mem::size_of::<FactorSlot>() == 8);

impl FactorSlot {
    /// The slots of the baker's factor `f`: one lobe slot where `frame` is given and the lobe
    /// about the direction from its origin to the factor's mean hit point (as decoded) fits
    /// the factor's terms ([`crate::lobe::fit`]), else a full head and its continuation.
    pub fn pack(f: &FactorU8, frame: Option<LobeFrame>) -> (FactorSlot, Option<FactorSlot>) {
        let v = packed_bits(f);
        let offsets = (v & ((1 << R_AT) - 1)) as u32;
        let head = |bits| FactorSlot {
            brick_rays: f.brick_rays,
            bits,
        };
        let lobe = frame.and_then(|fr| {
            let unit = |a: u32| signed_field(v, a * OFFSET_BITS, OFFSET_BITS) / levels(OFFSET_BITS);
            let toward: [f32; 3] = std::array::from_fn(|a| {
                fr.centroid[a] + unit(a as u32) * fr.offset_metres - fr.origin[a]
            });
            let terms: [f32; 8] = std::array::from_fn(|k| {
                signed_field(v, SH_AT[k], SH_BITS[k]) / levels(SH_BITS[k]) * SH_RANGE[k]
            });
            crate::lobe::fit(&terms, toward)
        });
        match lobe {
            Some((q, q2)) => (head(offsets | q << R_AT | q2 << A2_AT), None),
            None => {
                let c = (v >> R_AT) << 8;
                let rest = FactorSlot {
                    brick_rays: c as u32,
                    bits: (c >> 32) as u32,
                };
                (head(offsets | SLOT_FULL), Some(rest))
            }
        }
    }

    /// Rays of a head; 0 for a continuation.
    pub fn rays(&self) -> u32 {
        self.brick_rays & 0xff
    }

    /// Brick of a head.
    pub fn brick(&self) -> u32 {
        self.brick_rays >> 8
    }

    /// A head whose terms follow in a continuation.
    pub fn is_full(&self) -> bool {
        self.rays() != 0 && self.bits & SLOT_FULL != 0
    }

    /// A lobe head's `R` code.
    pub fn r_code(&self) -> u32 {
        self.bits >> R_AT & crate::lobe::R_TOP
    }

    /// A lobe head's band-2 scale code.
    pub fn a2_code(&self) -> u32 {
        self.bits >> A2_AT & crate::lobe::A2_TOP
    }

    /// A continuation's SH term k = 1..8 in units of its range ([`SH_RANGE`]) times the DC
    /// term, in [-1, 1].
    pub fn term(&self, k: usize) -> f32 {
        let v = u64::from(self.brick_rays) | u64::from(self.bits) << 32;
        signed_field(v, TERMS_AT[k - 1], SH_BITS[k - 1]) / levels(SH_BITS[k - 1])
    }

    /// A head's offset axis `a` in units of the offset scale, in [-1, 1].
    pub fn offset_unit(&self, a: usize) -> f32 {
        let v = u64::from(self.bits);
        signed_field(v, a as u32 * OFFSET_BITS, OFFSET_BITS) / levels(OFFSET_BITS)
    }
}

/// Largest brick index of the 8-bit encoding (24 bits).
pub const U8_MAX_BRICK: u32 = (1 << 24) - 1;
/// Largest ray count of one 8-bit factor.
pub const U8_MAX_RAYS: u32 = 255;

/// A factor row as the baker produces it: brick, rays, transfer k = 1..9, offset.
pub type FactorRow = (u32, u32, [f32; 8], [f32; 3]);

/// Splits a row with more than [`U8_MAX_RAYS`] rays into several rows of the same brick and
/// offset whose rays and transfers add up to the original (the gather is linear, so the probe's
/// SH is unchanged); a row of fewer rays comes back as it is, without the division for its
/// share (exactly 1, so the same bits): nearly every row is one, and the baker's encoding of
/// each waited for that division (2.3% of a bake's samples at Sponza's 1.0 m; skipping it, the
/// rows of the first 16,000 probes were made in 291-329 ms of CPU time against 286-343 ms,
/// medians 307 and 326 ms, five alternating release bakes).
pub fn split_row_for_u8(row: FactorRow) -> impl Iterator<Item = FactorRow> {
    let (brick, rays, sh, offset) = row;
    let mut left = rays;
    std::iter::from_fn(move || {
        (left > 0).then(|| {
            let part = left.min(U8_MAX_RAYS);
            left -= part;
            if part == rays {
                return row;
            }
            let share = part as f32 / rays as f32;
            (brick, part, sh.map(|v| v * share), offset)
        })
    })
}

/// Two halves in a word, `a` in the low half (WGSL `pack2x16float` order).
pub(crate) fn pack2(a: f32, b: f32) -> u32 {
    u32::from(f32_to_f16(a)) | (u32::from(f32_to_f16(b)) << 16)
}

/// The two halves of a word, low half first.
pub(crate) fn unpack2(w: u32) -> (f32, f32) {
    (f16_to_f32(w as u16), f16_to_f32((w >> 16) as u16))
}

/// The factor tables of all probes, concatenated, in one of the [`TransferPrecision`]s.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Factors {
    F32(Vec<FactorF32>),
    F16(Vec<FactorF16>),
    U8 {
        /// Slots ([`FactorSlot`]): a probe's `first_factor..+factor_count` counts slots.
        factors: Vec<FactorSlot>,
        /// Metres of offset per unit of the packed offset (the brick size).
        offset_scale: f32,
    },
}

impl Default for Factors {
    fn default() -> Self {
        Factors::U8 {
            factors: Vec::new(),
            offset_scale: 1.0,
        }
    }
}

impl Factors {
    /// Factors, or for u8 tables slots (a factor takes one or two).
    pub fn len(&self) -> usize {
        match self {
            Factors::F32(f) => f.len(),
            Factors::F16(f) => f.len(),
            Factors::U8 { factors, .. } => factors.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Factors (not slots: a u8 factor takes one or two), and of them lobe factors
    /// ([`crate::lobe`]; none but in u8 tables), in one pass.
    pub fn factor_counts(&self) -> (usize, usize) {
        match self {
            Factors::U8 { factors, .. } => factors.iter().fold((0, 0), |(all, lobes), f| {
                let head = f.rays() != 0;
                (
                    all + usize::from(head),
                    lobes + usize::from(head && !f.is_full()),
                )
            }),
            other => (other.len(), 0),
        }
    }

    pub fn precision(&self) -> TransferPrecision {
        match self {
            Factors::F32(_) => TransferPrecision::F32,
            Factors::F16(_) => TransferPrecision::F16,
            Factors::U8 { .. } => TransferPrecision::U8,
        }
    }

    /// Brick index and ray count of factor `f`; a continuation slot of a u8 table
    /// ([`FactorSlot`]) has no rays and names its head's brick.
    #[inline]
    pub fn brick_and_rays(&self, f: usize) -> (u32, u32) {
        match self {
            Factors::F32(t) => (t[f].brick, t[f].rays),
            Factors::F16(t) => (t[f].brick, t[f].rays),
            Factors::U8 { factors, .. } => match factors[f].rays() {
                0 => (f.checked_sub(1).map_or(0, |h| factors[h].brick()), 0),
                rays => (factors[f].brick(), rays),
            },
        }
    }

    /// Full SH9 transfer of factor `f` for a bake of `ray_count` rays. A lobe factor
    /// ([`crate::lobe`]) is decoded about `toward`, the direction from the ray origin of the
    /// probe whose table holds it to its stored point (`Asset::factor_transfer` finds it);
    /// the other factors ignore it. A continuation slot's transfer is zero.
    pub fn transfer(&self, f: usize, ray_count: u32, toward: [f32; 3]) -> [f32; SH_COUNT] {
        let (_, rays) = self.brick_and_rays(f);
        let mut t = [0.0; SH_COUNT];
        t[0] = rays as f32 * crate::directions::direction_weight(ray_count) * crate::sh::Y00;
        match self {
            Factors::F32(v) => t[1..].copy_from_slice(&v[f].sh),
            Factors::F16(v) => {
                for (w, &word) in v[f].sh.iter().enumerate() {
                    (t[1 + 2 * w], t[2 + 2 * w]) = unpack2(word);
                }
            }
            Factors::U8 { factors, .. } if factors[f].is_full() => {
                // A head at the end of the table (refused by validation) reads no terms.
                if let Some(rest) = factors.get(f + 1) {
                    for k in 1..SH_COUNT {
                        t[k] = rest.term(k) * SH_RANGE[k - 1] * t[0];
                    }
                }
            }
            Factors::U8 { factors, .. } => {
                let lobe = lobe_terms(
                    r_level(factors[f].r_code()),
                    a2_level(factors[f].a2_code()),
                    toward,
                );
                for k in 1..SH_COUNT {
                    t[k] = lobe[k - 1] * t[0];
                }
            }
        }
        t
    }

    /// Offset of factor `f`'s mean hit point from its brick's centroid.
    pub fn offset(&self, f: usize) -> [f32; 3] {
        match self {
            Factors::F32(v) => v[f].offset,
            Factors::F16(v) => {
                let (x, y) = unpack2(v[f].offset[0]);
                let (z, _) = unpack2(v[f].offset[1]);
                [x, y, z]
            }
            Factors::U8 {
                factors,
                offset_scale,
            } => match factors[f].rays() {
                0 => [0.0; 3],
                _ => std::array::from_fn(|a| factors[f].offset_unit(a) * offset_scale),
            },
        }
    }

    /// Builds the table in the requested precision for a bake of `ray_count` rays.
    /// `brick_size` (metres) scales packed offsets; for `U8`, rows must have at most
    /// [`U8_MAX_RAYS`] rays and bricks up to [`U8_MAX_BRICK`] (see [`split_row_for_u8`]),
    /// and every factor is full (two slots: without the probes' origins, no lobes).
    pub fn build(
        rows: &[FactorRow],
        precision: TransferPrecision,
        ray_count: u32,
        brick_size: f32,
    ) -> Self {
        match precision {
            TransferPrecision::U8 => {
                let offset_scale = u8_offset_scale(brick_size);
                let factors = rows
                    .iter()
                    .flat_map(|&(brick, rays, sh, offset)| {
                        let f = FactorU8::transfer(rays, sh, ray_count);
                        let (head, rest) =
                            FactorSlot::pack(&f.place(brick, offset, offset_scale), None);
                        std::iter::once(head).chain(rest)
                    })
                    .collect();
                Factors::U8 {
                    factors,
                    offset_scale,
                }
            }
            TransferPrecision::F32 => Factors::F32(rows.iter().map(FactorF32::of).collect()),
            TransferPrecision::F16 => Factors::F16(rows.iter().map(FactorF16::of).collect()),
        }
    }

    /// The factors of `ranges`, concatenated in their order, in the same precision.
    pub fn select(&self, ranges: &[std::ops::Range<usize>]) -> Self {
        fn pick<T: Copy>(v: &[T], ranges: &[std::ops::Range<usize>]) -> Vec<T> {
            ranges
                .iter()
                .flat_map(|r| v[r.clone()].iter().copied())
                .collect()
        }
        match self {
            Factors::F32(v) => Factors::F32(pick(v, ranges)),
            Factors::F16(v) => Factors::F16(pick(v, ranges)),
            Factors::U8 {
                factors,
                offset_scale,
            } => Factors::U8 {
                factors: pick(factors, ranges),
                offset_scale: *offset_scale,
            },
        }
    }

    /// Bytes one factor (of u8 tables, one slot) takes.
    pub fn bytes_per_factor(&self) -> usize {
        match self {
            Factors::F32(_) => std::mem::size_of::<FactorF32>(),
            Factors::F16(_) => std::mem::size_of::<FactorF16>(),
            Factors::U8 { .. } => std::mem::size_of::<FactorSlot>(),
        }
    }
}

/// IEEE 754 binary16 bits from f32, round to nearest even (values beyond the half range become
/// infinity; transfers stay far inside it: |transfer| <= 4pi * Y00).
pub fn f32_to_f16(x: f32) -> u16 {
    half::f16::from_f32(x).to_bits()
}

/// f32 from IEEE 754 binary16 bits.
pub fn f16_to_f32(h: u16) -> f32 {
    half::f16::from_bits(h).to_f32()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The factor's bytes as the loops before the quantiser took several terms at a time put
    /// them: term k of the transfer in byte 3 + k (in steps of its range), offset axis a in
    /// byte a; the packing keeps each field, and the decoded transfer and offset are within
    /// half a step of the exact ones.
    #[test]
    fn transfer_and_offset_bytes_keep_their_places() {
        let q = |v: f32, bits: u32| {
            let l = levels(bits);
            ((v.clamp(-1.0, 1.0) * l).round() as i8 as u8) as u32
        };
        for (rays, n) in [(1, 512), (37, 512), (255, 4096)] {
            let dc = rays as f32 * FactorU8::dc_per_ray(n);
            let sh = std::array::from_fn(|k| (k as f32 - 3.5) * 0.45 * dc);
            let mut packed = [0u32; 3];
            for k in 0..8 {
                let b = 3 + k;
                packed[b / 4] |= q(sh[k] / SH_RANGE[k] / dc, SH_BITS[k]) << (8 * (b % 4));
            }
            let offset = [0.3, -0.7, 0.05];
            let scale = 0.8;
            for (a, &o) in offset.iter().enumerate() {
                packed[0] |= q(o / scale, OFFSET_BITS) << (8 * a);
            }
            let got = FactorU8::transfer(rays, sh, n).place(99, offset, scale);
            assert_eq!(got.packed, packed, "{rays} rays of {n}");
            assert_eq!(got.brick_rays, 99 << 8 | rays);
            let (head, rest) = FactorSlot::pack(&got, None);
            let table = Factors::U8 {
                factors: vec![head, rest.expect("full without a frame")],
                offset_scale: scale,
            };
            let t = table.transfer(0, n, [0.0; 3]);
            assert_eq!(table.transfer(1, n, [0.0; 3]), [0.0; SH_COUNT]);
            assert_eq!(table.brick_and_rays(1), (99, 0));
            for k in 1..SH_COUNT {
                let step = SH_RANGE[k - 1] * dc / levels(SH_BITS[k - 1]);
                assert!(
                    (t[k] - sh[k - 1]).abs() <= 0.5 * step + 1e-6,
                    "term {k}: {t:?}"
                );
            }
            for a in 0..3 {
                let step = scale / levels(OFFSET_BITS);
                assert!((table.offset(0)[a] - offset[a]).abs() <= 0.5 * step + 1e-6);
            }
            assert_eq!(table.brick_and_rays(0), (99, rays));
        }
        // The extremes of every field survive the packing with their signs.
        let mut f = FactorU8::default();
        let bytes = [31u32, 0xe1, 0, 63, 0xc1, 1, 15, 0xf1, 0, 7, 0xf9];
        for (i, v) in bytes.iter().enumerate() {
            f.packed[i / 4] |= v << (8 * (i % 4));
        }
        f.brick_rays = 7 << 8 | 3;
        let (head, rest) = FactorSlot::pack(&f, None);
        let rest = rest.expect("full");
        assert!(head.is_full() && !rest.is_full());
        assert_eq!((head.rays(), rest.rays()), (3, 0));
        assert_eq!(head.bits >> A2_AT, 0);
        let offsets: Vec<f32> = (0..3).map(|a| head.offset_unit(a) * 31.0).collect();
        assert_eq!(offsets, [31.0, -31.0, 0.0]);
        let terms: Vec<f32> = (1..9)
            .map(|k| rest.term(k) * levels(SH_BITS[k - 1]))
            .collect();
        assert_eq!(terms, [63.0, -63.0, 1.0, 15.0, -15.0, 0.0, 7.0, -7.0]);
    }

    /// A factor whose rays are a narrow bundle toward its mean hit point is one slot, whose
    /// transfer decoded about that direction is within the fit's tolerance of its terms; about
    /// no frame, or with terms no lobe about that direction has, it is two.
    #[test]
    fn a_bundle_toward_its_hit_point_is_one_slot() {
        let (n, rays) = (512, 20);
        let dc = rays as f32 * FactorU8::dc_per_ray(n);
        let d = [0.48f32, 0.6, 0.64];
        let y = crate::sh::basis(d);
        // A bundle of R = 0.9 about d, band 2 that of a uniform cone of that R (R (2R - 1)).
        let (r, a2) = (0.9, 0.72);
        let sh: [f32; 8] =
            std::array::from_fn(|k| dc * y[k + 1] / crate::sh::Y00 * if k < 3 { r } else { a2 });
        let scale = 0.5;
        let f = FactorU8::transfer(rays, sh, n).place(5, [0.1, 0.0, -0.1], scale);
        // The brick's centroid 3 m from the origin along d, minus the offset.
        let frame = LobeFrame {
            centroid: [3.0 * d[0] - 0.1, 3.0 * d[1], 3.0 * d[2] + 0.1],
            offset_metres: scale,
            origin: [0.0; 3],
        };
        let (head, rest) = FactorSlot::pack(&f, Some(frame));
        assert_eq!(rest, None);
        assert!(!head.is_full());
        let table = Factors::U8 {
            factors: vec![head],
            offset_scale: scale,
        };
        let toward = [3.0 * d[0], 3.0 * d[1], 3.0 * d[2]];
        let t = table.transfer(0, n, toward);
        // Within the fit's tolerance of the quantised terms, which are within half a step.
        for k in 1..SH_COUNT {
            let tolerance = match k {
                1..=3 => crate::lobe::BAND1_TOLERANCE,
                _ => crate::lobe::BAND2_TOLERANCE,
            } + 0.5 / levels(SH_BITS[k - 1]);
            assert!((t[k] - sh[k - 1]).abs() <= tolerance * SH_RANGE[k - 1] * dc);
        }
        // Band 2 of the opposite sign: no lobe has it.
        let odd: [f32; 8] = std::array::from_fn(|k| if k < 3 { sh[k] } else { -sh[k] });
        let g = FactorU8::transfer(rays, odd, n).place(5, [0.1, 0.0, -0.1], scale);
        assert!(FactorSlot::pack(&g, Some(frame)).1.is_some());
    }

    #[test]
    fn half_round_trip() {
        for &x in &[
            0.0f32,
            1.0,
            -2.5,
            0.000_061_035_156,
            1e-7,
            65504.0,
            3.544_907_7,
            -0.123_456,
        ] {
            let y = f16_to_f32(f32_to_f16(x));
            assert!((x - y).abs() <= x.abs() * 1e-3 + 6e-8, "{x} -> {y}");
        }
        assert_eq!(f16_to_f32(f32_to_f16(1e6)), f32::INFINITY);
        assert_eq!(f32_to_f16(1.0), 0x3c00);
        assert_eq!(f32_to_f16(-2.0), 0xc000);
    }
}
