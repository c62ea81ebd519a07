//! Surfels as the asset stores them and the runtime uploads them (issue 32: bytes the runtime
//! keeps). In memory every surfel is a [`Surfel`] of f32 fields (80 bytes); on disk and on the
//! GPU an asset's surfels are either that ([`SurfelPrecision::F32`], the exact preset and
//! `--precision f32`) or a [`PackedSurfel`] of 48 bytes ([`SurfelPrecision::Packed`], the
//! default): position and gradient weights stay f32 (both carry the scene's scale, from a
//! millimetre room to a 10 km level), the normal is octahedral in two snorm16
//! ([`crate::surface::encode_normal`], under 5e-5 rad), albedo, emission and weight are IEEE
//! halves (relative rounding under 5e-4; a weight is a hit count, exact to 2048, and the baker
//! rounds it before the brick fits so that they use the stored value), and the back-face flag
//! rides in the brick word's top bit. Surfels were 31% of Sponza's runtime bytes at 80 bytes.
//!
//! The bake stores surfels that are already what the packing keeps ([`SurfelPrecision::quantize`]),
//! so an asset equals itself read back, and the CPU relighter, which reads the f32 fields, sees
//! exactly what `shaders/surfel.wgsl` decodes on the GPU.

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

use std::borrow::Cow;

use crate::asset::{Surfel, SurfelPrecision, BRICK_BACKFACE};
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

    /// `s` as this precision keeps it: what the asset reads back and the GPU decodes.
    pub fn quantize(self, s: &Surfel) -> Surfel {
        match self {
            SurfelPrecision::F32 => *s,
            SurfelPrecision::Packed => PackedSurfel::of(s).surfel(),
        }
    }

    /// The stored bytes of `surfels`, for the file and the GPU: f32 surfels as they are,
    /// packed ones in one allocation.
    pub fn stored(self, surfels: &[Surfel]) -> Cow<'_, [u8]> {
        match self {
            SurfelPrecision::F32 => Cow::Borrowed(bytemuck::cast_slice(surfels)),
            SurfelPrecision::Packed => {
                let mut out = Vec::with_capacity(surfels.len() * self.bytes());
                for s in surfels {
                    out.extend_from_slice(bytemuck::bytes_of(&PackedSurfel::of(s)));
                }
                Cow::Owned(out)
            }
        }
    }
}

/// The largest half: emission beyond it is stored as it (a half would be infinite).
const HALF_MAX: f32 = 65504.0;

/// Bit of [`PackedSurfel::brick`] that holds [`BRICK_BACKFACE`].
pub const PACKED_BACKFACE: u32 = 1 << 31;

/// A surfel in 48 bytes ([`SurfelPrecision::Packed`]; decoded by `shaders/surfel.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct PackedSurfel {
    pub position: [f32; 3],
    /// The brick, and [`PACKED_BACKFACE`] for a back-face surfel.
    pub brick: u32,
    pub gradient: [f32; 3],
    /// Octahedral unit normal ([`encode_normal`]).
    pub normal: u32,
    /// Albedo red and green as halves, low half first (WGSL `unpack2x16float` order).
    pub albedo_rg: u32,
    /// Albedo blue and the weight.
    pub albedo_b_weight: u32,
    /// Emission red and green.
    pub emission_rg: u32,
    /// Emission blue and a zero half.
    pub emission_b: u32,
}
const _: () = assert!(std::mem::size_of::<PackedSurfel>() == 48);

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

impl PackedSurfel {
    /// The packing of every surfel of `surfels`.
    pub fn pack_all(surfels: &[Surfel]) -> Vec<PackedSurfel> {
        surfels.iter().map(PackedSurfel::of).collect()
    }

    /// The packing of `s` (finite albedo, emission and weight beyond the half range are stored
    /// as its largest value; the brick index below 2^31, as validation requires).
    pub fn of(s: &Surfel) -> PackedSurfel {
        let (a, e) = (s.albedo.map(saturate), s.emission.map(saturate));
        let backface = if s.flags & BRICK_BACKFACE != 0 {
            PACKED_BACKFACE
        } else {
            0
        };
        PackedSurfel {
            position: s.position,
            brick: (s.brick & !PACKED_BACKFACE) | backface,
            gradient: s.gradient,
            normal: encode_normal(s.normal),
            albedo_rg: pack2(a[0], a[1]),
            albedo_b_weight: pack2(a[2], saturate(s.weight)),
            emission_rg: pack2(e[0], e[1]),
            emission_b: pack2(e[2], 0.0),
        }
    }

    /// The surfel these bytes hold, as `shaders/surfel.wgsl` decodes it.
    pub fn surfel(&self) -> Surfel {
        let (ar, ag) = unpack2(self.albedo_rg);
        let (ab, weight) = unpack2(self.albedo_b_weight);
        let (er, eg) = unpack2(self.emission_rg);
        let (eb, _) = unpack2(self.emission_b);
        Surfel {
            position: self.position,
            brick: self.brick & !PACKED_BACKFACE,
            normal: decode_normal(self.normal),
            weight,
            albedo: [ar, ag, ab],
            flags: if self.brick & PACKED_BACKFACE != 0 {
                BRICK_BACKFACE
            } else {
                0
            },
            emission: [er, eg, eb],
            gradient: self.gradient,
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
            brick: 123_456,
            normal: [0.6, 0.0, -0.8],
            weight: 37.0,
            albedo: [0.8, 0.02, 0.5],
            flags: BRICK_BACKFACE,
            emission: [0.0, 2.5, 1e5],
            gradient: [1e-7, -3.0, 2e5],
            ..Surfel::default()
        }
    }

    /// What the packing keeps: position and gradient exactly, the normal within 5e-5 rad,
    /// albedo and emission within half rounding, the brick and the back-face flag; quantising
    /// twice changes nothing, so an asset reads back equal.
    #[test]
    fn packing_keeps_what_the_runtime_reads() {
        let s = surfel();
        let q = SurfelPrecision::Packed.quantize(&s);
        assert_eq!((q.position, q.gradient), (s.position, s.gradient));
        assert_eq!((q.brick, q.flags, q.weight), (s.brick, s.flags, s.weight));
        let dot: f32 = (0..3).map(|a| q.normal[a] * s.normal[a]).sum();
        assert!(dot.min(1.0).acos() < 5e-5, "{:?}", q.normal);
        for a in 0..3 {
            assert!((q.albedo[a] - s.albedo[a]).abs() <= 5e-4 * s.albedo[a]);
        }
        assert_eq!(q.emission, [0.0, 2.5, HALF_MAX]);
        assert_eq!(SurfelPrecision::Packed.quantize(&q), q);
        assert_eq!(SurfelPrecision::F32.quantize(&s), s);
        assert_eq!(half_weight(4097.0), 4096.0);
        let both = [s, q];
        let bytes = SurfelPrecision::Packed.stored(&both);
        assert_eq!(bytes.len(), 2 * SurfelPrecision::Packed.bytes());
        assert_eq!(bytes[..48], bytes[48..]);
        assert_eq!(SurfelPrecision::F32.stored(&[s]).len(), 80);
        assert_eq!(SurfelPrecision::Packed.words(), 12);
    }

    /// Quantising is idempotent over normals in every octant, so a baked asset (quantised once)
    /// reads back with the same normals.
    #[test]
    fn quantised_normals_are_fixed_points() {
        let directions = crate::directions::fibonacci_directions(20_000);
        for n in directions {
            let s = Surfel {
                normal: n,
                weight: 1.0,
                ..Surfel::default()
            };
            let q = SurfelPrecision::Packed.quantize(&s);
            assert_eq!(SurfelPrecision::Packed.quantize(&q), q, "{n:?}");
        }
    }
}
