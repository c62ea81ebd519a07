//! Surfels as the asset stores them and the runtime uploads them (issue 32: bytes the runtime
//! keeps). In memory every surfel is a [`Surfel`] of f32 fields (80 bytes); on disk and on the
//! GPU an asset's surfels are either that ([`SurfelPrecision::F32`], the exact preset and
//! `--precision f32`) or a [`PackedSurfel`] of 32 bytes ([`SurfelPrecision::Packed`], the
//! default since format 15; 48 bytes in formats 9-14). What the packing keeps, and why it
//! holds at any scale:
//!
//! - **position**: three 16-bit fractions of its brick's bounds (`Brick::min`, `Brick::max`,
//!   which every surfel of the brick lies within): a step of the brick's extent over 65,536,
//!   at most about 8 micrometres on a 1 m grid's half-metre bricks, and no finer than f32 far
//!   from the origin, where the decoded value is f32's anyway. Scaling a level by a power of
//!   two scales the decoded positions exactly.
//! - **gradient weights**: halves of the weight times the power of two just above the brick's
//!   largest extent (a pure number, of the order of the surfel's share of its brick's weight;
//!   relative rounding under 5e-4 where that share is above about 1e-4), exact to scale and
//!   decode on the CPU and the GPU alike, so that a millimetre room and a 10 km level keep the
//!   same precision;
//! - the **normal** octahedral in two snorm16 ([`crate::surface::encode_normal`], under 5e-5
//!   rad), **albedo** and **weight** as IEEE halves (relative rounding under 5e-4; a weight is
//!   a hit count, exact to 2048, and the baker rounds it before the brick fits so that they use
//!   the stored value), **emission** as RGB9E5 (a shared exponent and three 9-bit mantissas:
//!   each channel within 2^-9 of the largest, at most 65,280; a colour that is not finite
//!   stays so, for validation to refuse), and the back-face flag in the brick word's top bit.
//!
//! Surfels were 31% of Sponza's runtime bytes at 80 bytes, 24% at 48.
//!
//! The bake stores surfels that are already what the packing keeps ([`SurfelPrecision::quantize`],
//! once the bricks' bounds are final), so an asset equals itself read back, and the CPU
//! relighter, which reads the f32 fields, sees what `shaders/surfel.wgsl` decodes on the GPU
//! (up to a rounding of the position's multiply-add, which a GPU may fuse). A position is
//! stored as the fraction that decodes nearest it, so quantising is idempotent.

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

use std::borrow::Cow;

use crate::asset::{Brick, Surfel, SurfelPrecision, BRICK_BACKFACE};
use crate::factors::{f16_to_f32, f32_to_f16, pack2, unpack2, TransferPrecision};
use crate::surface::{decode_normal, encode_normal};

impl SurfelPrecision {
    /// The surfels a bake of factor transfers in `transfer` stores: f32 with f32 transfers (the
    /// exact preset, `--precision f32`), packed otherwise.
    pub fn for_transfer(transfer: TransferPrecision) -> SurfelPrecision {
        match transfer {
            TransferPrecision::F32 => SurfelPrecision::F32,
            TransferPrecision::F16 | TransferPrecision::U8 => SurfelPrecision::Packed,
        }
    }

    /// Bytes per stored surfel.
    pub fn bytes(self) -> usize {
        match self {
            SurfelPrecision::F32 => std::mem::size_of::<Surfel>(),
            SurfelPrecision::Packed => std::mem::size_of::<PackedSurfel>(),
        }
    }

    /// Words (u32) per stored surfel, as `shaders/surfel.wgsl` reads them (`SURFEL_WORDS`).
    pub fn words(self) -> usize {
        self.bytes() / 4
    }

    /// `s` as this precision keeps it within `bricks` (its brick's bounds place a packed
    /// position): what the asset reads back and the GPU decodes.
    pub fn quantize(self, s: &Surfel, bricks: &[Brick]) -> Surfel {
        match self {
            SurfelPrecision::F32 => *s,
            SurfelPrecision::Packed => {
                let b = brick_of(bricks, s.brick);
                PackedSurfel::of(s, &b).surfel(&b)
            }
        }
    }

    /// The stored bytes of `surfels` (their bricks in `bricks`), for the file and the GPU: f32
    /// surfels as they are, packed ones in one allocation.
    pub fn stored<'a>(self, surfels: &'a [Surfel], bricks: &[Brick]) -> Cow<'a, [u8]> {
        match self {
            SurfelPrecision::F32 => Cow::Borrowed(bytemuck::cast_slice(surfels)),
            SurfelPrecision::Packed => {
                let mut out = Vec::with_capacity(surfels.len() * self.bytes());
                for s in surfels {
                    let b = brick_of(bricks, s.brick);
                    out.extend_from_slice(bytemuck::bytes_of(&PackedSurfel::of(s, &b)));
                }
                Cow::Owned(out)
            }
        }
    }
}

/// Brick `i` of `bricks`, or an empty one (bounds at the origin) for an index out of range:
/// validation refuses such a surfel by its brick index, and nothing here panics first.
pub(crate) fn brick_of(bricks: &[Brick], i: u32) -> Brick {
    bricks
        .get((i & !PACKED_BACKFACE) as usize)
        .copied()
        .unwrap_or_default()
}

/// The largest half: albedo, weight and gradient weights beyond it are stored as it (a half
/// would be infinite).
const HALF_MAX: f32 = 65504.0;

/// Bit of [`PackedSurfel::brick`] that holds [`BRICK_BACKFACE`].
pub const PACKED_BACKFACE: u32 = 1 << 31;

/// Steps of a packed position's fraction of its brick's extent (`shaders/surfel.wgsl` decodes
/// `min + extent * q / POSITION_STEPS`, at most `max`).
pub const POSITION_STEPS: f32 = 65536.0;

/// A surfel in 32 bytes ([`SurfelPrecision::Packed`]; decoded by `shaders/surfel.wgsl`; module
/// docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct PackedSurfel {
    /// The brick, and [`PACKED_BACKFACE`] for a back-face surfel.
    pub brick: u32,
    /// Position x and y as 16-bit fractions of the brick's bounds, x in the low half.
    pub position_xy: u32,
    /// Position z, and the weight as a half.
    pub position_z_weight: u32,
    /// Octahedral unit normal ([`encode_normal`]).
    pub normal: u32,
    /// Gradient weights x and y times the power of two just above the brick's largest extent
    /// (`gradient_exponent`), as halves.
    pub gradient_xy: u32,
    /// Gradient weight z (as above) and albedo red.
    pub gradient_z_albedo_r: u32,
    /// Albedo green and blue.
    pub albedo_gb: u32,
    /// Emission as RGB9E5 ([`rgb9e5`]).
    pub emission: u32,
}
const _: () = assert!(std::mem::size_of::<PackedSurfel>() == 32);

/// A half's value of `v`: the weight the baker gives a surfel, and what the packing keeps of it.
pub fn half_weight(v: f32) -> f32 {
    f16_to_f32(f32_to_f16(saturate(v)))
}

/// `v` within the half range; infinities and NaN stay as they are, so that validation still
/// refuses them when read back.
fn saturate(v: f32) -> f32 {
    if v.is_finite() {
        v.clamp(-HALF_MAX, HALF_MAX)
    } else {
        v
    }
}

/// Biased f32 exponent `E` of the largest extent of `b`'s bounds (0 for a brick of one point):
/// its surfels' gradient weights are stored times `2^(E - 126)`, the power of two just above
/// that extent, so that encoding and decoding (times `2^(126 - E)`) are exact multiplications
/// on the CPU and the GPU alike and a level scaled by a power of two keeps the same halves.
fn gradient_exponent(b: &Brick) -> u32 {
    let largest = (0..3).map(|a| b.max[a] - b.min[a]).fold(0.0f32, f32::max);
    if largest > 0.0 && largest.is_finite() {
        (largest.to_bits() >> 23).min(252)
    } else {
        0
    }
}

/// `2^(e - 126)` and its inverse `2^(126 - e)` for a [`gradient_exponent`] `e` (1..=252), from
/// their bits as `shaders/surfel.wgsl` builds them.
fn gradient_units(e: u32) -> (f32, f32) {
    (
        f32::from_bits((e + 1) << 23),
        f32::from_bits((253 - e) << 23),
    )
}

/// The position a packed fraction `q` stands for along an axis of bounds `lo..=hi` (as
/// `shaders/surfel.wgsl` decodes it; at most `hi`).
fn decode_fraction(q: u32, lo: f32, hi: f32) -> f32 {
    (lo + (hi - lo) * (q as f32 * (1.0 / POSITION_STEPS))).min(hi)
}

/// The fraction whose decoded position is nearest `p` within `lo..=hi`: the rounded one or a
/// neighbour (the decode rounds twice in f32, so that the rounded fraction alone would not
/// always decode to its own position again).
fn encode_fraction(p: f32, lo: f32, hi: f32) -> u32 {
    let e = hi - lo;
    if e <= 0.0 || !e.is_finite() {
        return 0;
    }
    let top = POSITION_STEPS - 1.0;
    let q = ((p - lo) / e * POSITION_STEPS).round().clamp(0.0, top) as u32;
    let candidates = [q.saturating_sub(1), q, (q + 1).min(top as u32)];
    let miss = |c: u32| (decode_fraction(c, lo, hi) - p).abs();
    // The first of the nearest: deterministic where two decode alike.
    candidates
        .into_iter()
        .fold(q, |best, c| if miss(c) < miss(best) { c } else { best })
}

/// Mantissa bits of [`rgb9e5`]'s channels.
const E5_MANTISSA: i32 = 9;
/// Exponent bias of [`rgb9e5`].
const E5_BIAS: i32 = 15;
/// What turns an [`rgb9e5`] exponent into the biased f32 exponent of its step,
/// `127 - bias - mantissa bits` (injected into `shaders/surfel.wgsl`).
pub const RGB9E5_EXPONENT_OFFSET: u32 = (127 - E5_BIAS - E5_MANTISSA) as u32;
/// The largest value [`rgb9e5`] holds for a finite colour: `(2^9 - 2) / 2^9 * 2^16` (the
/// largest mantissa at the largest exponent, in all three channels, is [`RGB9E5_NOT_FINITE`]).
pub const RGB9E5_MAX: f32 = 65280.0;

/// The word [`rgb9e5`] gives a colour with an infinite or NaN channel, and [`from_rgb9e5`]
/// reads as NaN: validation refuses it when the asset is read back, as it did the halves of
/// formats 9-14. The shader never sees it (validated assets only).
pub const RGB9E5_NOT_FINITE: u32 = u32::MAX;

/// `rgb` (clamped to [0, [`RGB9E5_MAX`]]; negative values as 0) in the shared-exponent format
/// of `EXT_texture_shared_exponent`: 9-bit mantissas red, green, blue from bit 0, 5-bit
/// exponent at bit 27. Each channel keeps its value to within 2^-9 of the largest.
pub fn rgb9e5(rgb: [f32; 3]) -> u32 {
    if rgb.iter().any(|v| !v.is_finite()) {
        return RGB9E5_NOT_FINITE;
    }
    let c = rgb.map(|v| if v > 0.0 { v.min(RGB9E5_MAX) } else { 0.0 });
    let largest = c[0].max(c[1]).max(c[2]);
    if largest <= 0.0 {
        return 0;
    }
    // floor(log2(largest)) from the bits (exact, unlike a float log), at least -B - 1.
    let floor_log2 = ((largest.to_bits() >> 23) as i32 - 127).max(-E5_BIAS - 1);
    let mut exponent = floor_log2 + 1 + E5_BIAS;
    // 2^(e - B - N) from its bits (e - B - N is within -25..=7 here).
    let step = |e: i32| f32::from_bits(((e - E5_BIAS - E5_MANTISSA + 127) as u32) << 23);
    if (largest / step(exponent) + 0.5).floor() >= (1 << E5_MANTISSA) as f32 {
        exponent += 1;
    }
    let m = c.map(|v| ((v / step(exponent) + 0.5).floor() as u32).min((1 << E5_MANTISSA) - 1));
    m[0] | m[1] << 9 | m[2] << 18 | (exponent as u32) << 27
}

/// The colour of an [`rgb9e5`] word (as `shaders/surfel.wgsl` decodes it; NaN for
/// [`RGB9E5_NOT_FINITE`]).
pub fn from_rgb9e5(w: u32) -> [f32; 3] {
    if w == RGB9E5_NOT_FINITE {
        return [f32::NAN; 3];
    }
    // 2^(exponent - B - N) from its bits, as the shader builds it.
    let step = f32::from_bits(((w >> 27) + RGB9E5_EXPONENT_OFFSET) << 23);
    [w & 511, (w >> 9) & 511, (w >> 18) & 511].map(|m| m as f32 * step)
}

impl PackedSurfel {
    /// The packing of every surfel of `surfels`, each within its brick of `bricks`.
    pub fn pack_all(surfels: &[Surfel], bricks: &[Brick]) -> Vec<PackedSurfel> {
        (surfels.iter())
            .map(|s| PackedSurfel::of(s, &brick_of(bricks, s.brick)))
            .collect()
    }

    /// The packing of `s`, a surfel of brick `b` (finite albedo and weight beyond the half
    /// range are stored as its largest value, emission as RGB9E5's; the brick index below
    /// 2^31, as validation requires; a position outside the brick's bounds as the nearest
    /// point within them).
    pub fn of(s: &Surfel, b: &Brick) -> PackedSurfel {
        let a = s.albedo.map(saturate);
        let backface = if s.flags & BRICK_BACKFACE != 0 {
            PACKED_BACKFACE
        } else {
            0
        };
        let q: [u32; 3] =
            std::array::from_fn(|i| encode_fraction(s.position[i], b.min[i], b.max[i]));
        let e = gradient_exponent(b);
        let g = s.gradient.map(|v| match e {
            0 => 0.0,
            e => v * gradient_units(e).0,
        });
        PackedSurfel {
            brick: (s.brick & !PACKED_BACKFACE) | backface,
            position_xy: q[0] | q[1] << 16,
            position_z_weight: q[2] | u32::from(f32_to_f16(saturate(s.weight))) << 16,
            normal: encode_normal(s.normal),
            gradient_xy: pack2(saturate(g[0]), saturate(g[1])),
            gradient_z_albedo_r: pack2(saturate(g[2]), a[0]),
            albedo_gb: pack2(a[1], a[2]),
            emission: rgb9e5(s.emission),
        }
    }

    /// The surfel these bytes hold as a surfel of brick `b`, as `shaders/surfel.wgsl` decodes
    /// it.
    pub fn surfel(&self, b: &Brick) -> Surfel {
        let q = [
            self.position_xy & 0xffff,
            self.position_xy >> 16,
            self.position_z_weight & 0xffff,
        ];
        let position = std::array::from_fn(|i| decode_fraction(q[i], b.min[i], b.max[i]));
        let e = gradient_exponent(b);
        let (gx, gy) = unpack2(self.gradient_xy);
        let (gz, ar) = unpack2(self.gradient_z_albedo_r);
        let (ag, ab) = unpack2(self.albedo_gb);
        let gradient = [gx, gy, gz].map(|v| match e {
            0 => 0.0,
            e => v * gradient_units(e).1,
        });
        Surfel {
            position,
            brick: self.brick & !PACKED_BACKFACE,
            normal: decode_normal(self.normal),
            weight: f16_to_f32((self.position_z_weight >> 16) as u16),
            albedo: [ar, ag, ab],
            flags: if self.brick & PACKED_BACKFACE != 0 {
                BRICK_BACKFACE
            } else {
                0
            },
            emission: from_rgb9e5(self.emission),
            gradient,
            ..Surfel::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn surfel() -> Surfel {
        Surfel {
            position: [1e4 + 0.123_456_7, -3.25, 1e-3],
            brick: 1,
            normal: [0.6, 0.0, -0.8],
            weight: 37.0,
            albedo: [0.8, 0.02, 0.5],
            flags: BRICK_BACKFACE,
            emission: [0.0, 2.5, 1e5],
            gradient: [1e-3, -3.0, 0.25],
            ..Surfel::default()
        }
    }

    /// Brick 1 around [`surfel`]'s position, half a metre wide.
    fn bricks() -> Vec<Brick> {
        let b = Brick {
            min: [1e4, -3.5, -0.2],
            max: [1e4 + 0.5, -3.0, 0.3],
            ..Brick::default()
        };
        vec![Brick::default(), b]
    }

    /// What the packing keeps: the position within a 65,536th of the brick (and inside it),
    /// gradient weights, albedo and weight within half rounding, the normal within 5e-5 rad,
    /// emission within RGB9E5's step of its largest channel, the brick and the back-face flag;
    /// quantising twice changes nothing, so an asset reads back equal.
    #[test]
    fn packing_keeps_what_the_runtime_reads() {
        let (s, bricks) = (surfel(), bricks());
        let q = SurfelPrecision::Packed.quantize(&s, &bricks);
        for a in 0..3 {
            let (lo, hi) = (bricks[1].min[a], bricks[1].max[a]);
            // A step of the brick, or f32's own step at 1e4 m (2^-10) where that is coarser.
            let step = ((hi - lo) / 65536.0).max(2f32.powi(-10));
            assert!((q.position[a] - s.position[a]).abs() <= step);
            assert!(q.position[a] >= lo && q.position[a] <= hi);
            assert!((q.gradient[a] - s.gradient[a]).abs() <= 5e-4 * s.gradient[a].abs());
            assert!((q.albedo[a] - s.albedo[a]).abs() <= 5e-4 * s.albedo[a]);
        }
        assert_eq!((q.brick, q.flags, q.weight), (s.brick, s.flags, s.weight));
        let dot: f32 = (0..3).map(|a| q.normal[a] * s.normal[a]).sum();
        assert!(dot.min(1.0).acos() < 5e-5, "{:?}", q.normal);
        assert_eq!(q.emission[0], 0.0);
        assert!((q.emission[1] - 2.5).abs() <= RGB9E5_MAX / 512.0);
        assert_eq!(q.emission[2], RGB9E5_MAX);
        assert_eq!(SurfelPrecision::Packed.quantize(&q, &bricks), q);
        assert_eq!(SurfelPrecision::F32.quantize(&s, &bricks), s);
        assert_eq!(half_weight(4097.0), 4096.0);
        let both = [s, q];
        let bytes = SurfelPrecision::Packed.stored(&both, &bricks);
        assert_eq!(bytes.len(), 2 * SurfelPrecision::Packed.bytes());
        assert_eq!(bytes[..32], bytes[32..]);
        assert_eq!(SurfelPrecision::F32.stored(&[s], &bricks).len(), 80);
        assert_eq!(SurfelPrecision::Packed.words(), 8);
    }

    /// A packed position scales with the level: the same surfel and brick scaled by powers of
    /// two decode to the scaled position exactly, and its gradient weights to the inverse.
    #[test]
    fn packed_positions_and_gradients_scale_exactly() {
        let (s, bricks) = (surfel(), bricks());
        let q = SurfelPrecision::Packed.quantize(&s, &bricks);
        for k in [-10, -3, 4, 13] {
            let f = 2f32.powi(k);
            let scaled = Surfel {
                position: s.position.map(|v| v * f),
                gradient: s.gradient.map(|v| v / f),
                ..s
            };
            let b = bricks[1];
            let sb = [
                Brick::default(),
                Brick {
                    min: b.min.map(|v| v * f),
                    max: b.max.map(|v| v * f),
                    ..b
                },
            ];
            let qs = SurfelPrecision::Packed.quantize(&scaled, &sb);
            assert_eq!(qs.position, q.position.map(|v| v * f), "2^{k}");
            assert_eq!(qs.gradient, q.gradient.map(|v| v / f), "2^{k}");
        }
    }

    /// Quantising is idempotent over normals in every octant and positions across the brick,
    /// so a baked asset (quantised once) reads back with the same surfels.
    #[test]
    fn quantised_surfels_are_fixed_points() {
        let bricks = bricks();
        let directions = crate::directions::fibonacci_directions(20_000);
        for (i, n) in directions.into_iter().enumerate() {
            let t = i as f32 / 20_000.0;
            let s = Surfel {
                normal: n,
                weight: 1.0,
                brick: 1,
                position: [1e4 + 0.5 * t, -3.5 + 0.5 * (1.0 - t), -0.2 + 0.5 * t * t],
                ..Surfel::default()
            };
            let q = SurfelPrecision::Packed.quantize(&s, &bricks);
            assert_eq!(SurfelPrecision::Packed.quantize(&q, &bricks), q, "{n:?}");
        }
    }

    /// Quantising is idempotent for bricks of any extent anywhere (the decode rounds twice in
    /// f32: the nearest fraction is kept, not the rounded one).
    #[test]
    fn quantised_positions_are_fixed_points_at_any_extent() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f32 / (1u64 << 53) as f32
        };
        for _ in 0..100_000 {
            let origin = 10f32.powf(1.0 + 2.0 * next()) * if next() < 0.5 { -1.0 } else { 1.0 };
            let lo = [origin, origin * 0.5, -origin];
            let extent = 0.3 + 0.4 * next();
            let b = Brick {
                min: lo,
                max: lo.map(|v| v + extent),
                ..Brick::default()
            };
            let s = Surfel {
                position: lo.map(|v| v + extent * next()),
                weight: 1.0,
                gradient: [next() - 0.5, 0.25, -1e-3],
                brick: 1,
                ..Surfel::default()
            };
            let bricks = [Brick::default(), b];
            let q = SurfelPrecision::Packed.quantize(&s, &bricks);
            assert_eq!(
                SurfelPrecision::Packed.quantize(&q, &bricks),
                q,
                "{s:?} in {b:?}"
            );
        }
    }

    /// RGB9E5 keeps each channel within 2^-9 of the largest, clamps to its range, reads
    /// negative values as 0 and its own values back exactly, and keeps a colour that is not
    /// finite not finite (validation refuses it).
    #[test]
    fn rgb9e5_round_trips() {
        for c in [
            [1.0, 0.5, 0.25],
            [3e-4, 7.0, 0.0],
            [65000.0, 1.0, 1e-9],
            [0.1, 0.2, 0.3],
        ] {
            let d = from_rgb9e5(rgb9e5(c));
            let largest = c[0].max(c[1]).max(c[2]);
            for a in 0..3 {
                assert!((d[a] - c[a]).abs() <= largest / 512.0, "{c:?} {d:?}");
            }
            assert_eq!(from_rgb9e5(rgb9e5(d)), d);
        }
        assert_eq!(
            from_rgb9e5(rgb9e5([1e9, 0.0, -2.0])),
            [RGB9E5_MAX, 0.0, 0.0]
        );
        assert_eq!(rgb9e5([RGB9E5_MAX; 3]), rgb9e5([1e30; 3]));
        assert_ne!(rgb9e5([1e30; 3]), RGB9E5_NOT_FINITE);
        assert!(from_rgb9e5(rgb9e5([1.0, f32::NAN, 0.0]))[0].is_nan());
        assert!(from_rgb9e5(rgb9e5([f32::INFINITY, 0.0, 0.0]))[0].is_nan());
        assert_eq!(rgb9e5([0.0; 3]), 0);
    }
}
