//! The payload, section by section (a section is a top-level field of [`Asset`]).
//!
//! The bytes are serde + bincode 2's (fixed-width little-endian integers, a struct's fields back
//! to back, a `Vec` as its `u64` length and then its elements). The big sections are vectors of
//! `#[repr(C)]` `Pod` structs of 4-byte fields without padding, whose bincode bytes are the
//! length and then the vector's memory as it is: those are written and read as one slice of
//! bytes instead of field by field. At Sponza's 16,758 probes (230 MB), serde wrote the payload
//! in two passes (size, then bytes) of 0.23-0.29 s, a few bytes a call. The small sections still
//! go through serde; `tests` hold the whole payload to what serde writes and reads, for every
//! factor encoding.

use std::io::Write;

use bytemuck::Pod;
use serde::Serialize;

use crate::asset::SurfelPrecision;
use crate::asset::{Asset, Brick, Geometry, Header, Surfel};
use crate::coarse::CoarseBricks;
use crate::error::FormatError;
use crate::factors::Factors;
use crate::surface::SurfaceTerms;
use crate::surfel::{brick_of, PackedSurfel};

/// Bincode's variant indices of [`Factors`] (its declaration order).
const F32: u32 = 0;
const F16: u32 = 1;
const U8: u32 = 2;

/// Raw bytes of `Pod` slices are bincode's only on little-endian machines; elsewhere serde
/// writes and reads every section.
const RAW: bool = cfg!(target_endian = "little");

/// A failure to write the payload: of the encoding, or of the sink.
pub(crate) enum EncodeTo {
    Format(FormatError),
    Io(std::io::Error),
}

pub(crate) fn config(
) -> bincode::config::Configuration<bincode::config::LittleEndian, bincode::config::Fixint> {
    bincode::config::standard()
        .with_little_endian()
        .with_fixed_int_encoding()
}

/// Writes the payload of `asset` to `out`.
pub(crate) fn write_payload<W: Write>(asset: &Asset, out: &mut W) -> Result<(), EncodeTo> {
    via_serde(out, &asset.header)?;
    pod(out, &asset.probes)?;
    pod(out, &asset.sky_mask)?;
    pod(out, &asset.sky_transfer)?;
    pod(out, &asset.probe_depth)?;
    match &asset.factors {
        Factors::F32(v) => {
            via_serde(out, &F32)?;
            pod(out, v)?;
        }
        Factors::F16(v) => {
            via_serde(out, &F16)?;
            pod(out, v)?;
        }
        Factors::U8 {
            factors,
            offset_scale,
        } => {
            via_serde(out, &U8)?;
            pod(out, factors)?;
            via_serde(out, offset_scale)?;
        }
    }
    pod(out, &asset.bricks)?;
    pod(out, &asset.coarse.bricks)?;
    pod(out, &asset.coarse.children)?;
    pod(out, &asset.coarse.moments)?;
    match asset.header.settings.surfel_precision {
        SurfelPrecision::F32 => pod(out, &asset.surfels)?,
        SurfelPrecision::Packed => packed_surfels(out, &asset.surfels, &asset.bricks)?,
    }
    pod(out, &asset.geometry.nodes)?;
    pod(out, &asset.geometry.triangles)?;
    via_serde(out, &asset.lights)?;
    let t = &asset.surface;
    via_serde(out, &t.header)?;
    pod(out, &t.slots)?;
    pod(out, &t.cells)?;
    pod(out, &t.surfels)?;
    pod(out, &t.groups)?;
    pod(out, &t.group_surfels)?;
    pod(out, &t.near_ranges)?;
    pod(out, &t.near)?;
    pod(out, &t.sky)?;
    pod(out, &t.sides)
}

/// Bytes of the payload of `asset` (a pass that copies nothing).
pub(crate) fn payload_size(asset: &Asset) -> Result<usize, FormatError> {
    /// Counts what it is given.
    struct Count(usize);
    impl Write for Count {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0 += buf.len();
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let mut count = Count(0);
    write_payload(asset, &mut count).map_err(|e| match e {
        EncodeTo::Format(e) => e,
        EncodeTo::Io(e) => FormatError::Encode(e.to_string()),
    })?;
    Ok(count.0)
}

fn via_serde<W: Write, T: Serialize>(out: &mut W, value: &T) -> Result<(), EncodeTo> {
    bincode::serde::encode_into_std_write(value, out, config())
        .map(|_| ())
        .map_err(|e| match e {
            bincode::error::EncodeError::Io { inner, .. } => EncodeTo::Io(inner),
            other => EncodeTo::Format(FormatError::Encode(other.to_string())),
        })
}

fn pod<W: Write, T: Pod + Serialize>(out: &mut W, v: &[T]) -> Result<(), EncodeTo> {
    if !RAW {
        return via_serde(out, &v);
    }
    out.write_all(&(v.len() as u64).to_le_bytes())
        .map_err(EncodeTo::Io)?;
    // In pieces of 1 MiB: whole sections of 80 MB in one write each made the file's sync take
    // 0.7-1.2 s instead of 0.25-0.3 s (Sponza at 1.0 m, ext4 on a virtual disk).
    for chunk in bytemuck::cast_slice::<T, u8>(v).chunks(1 << 20) {
        out.write_all(chunk).map_err(EncodeTo::Io)?;
    }
    Ok(())
}

/// `surfels` packed ([`PackedSurfel`]), the bytes `pod` writes of a vector of them, packed a
/// piece at a time: a packed copy of every surfel would add 32 bytes a surfel to the peak
/// memory of a bake's write.
fn packed_surfels<W: Write>(
    out: &mut W,
    surfels: &[Surfel],
    bricks: &[Brick],
) -> Result<(), EncodeTo> {
    if !RAW {
        return via_serde(out, &PackedSurfel::pack_all(surfels, bricks));
    }
    out.write_all(&(surfels.len() as u64).to_le_bytes())
        .map_err(EncodeTo::Io)?;
    for piece in surfels.chunks(1 << 14) {
        out.write_all(&SurfelPrecision::Packed.stored(piece, bricks))
            .map_err(EncodeTo::Io)?;
    }
    Ok(())
}

/// Reads the payload one section at a time; an error names the section it is in.
pub(crate) struct Sections<'a> {
    pub payload: &'a [u8],
    pub at: usize,
}

impl Sections<'_> {
    /// The whole asset, section after section.
    pub fn asset(&mut self) -> Result<Asset, FormatError> {
        let header: Header = self.via_serde("header")?;
        let surfel_precision = header.settings.surfel_precision;
        let probes = self.pod("probes")?;
        let sky_mask = self.pod("sky_mask")?;
        let sky_transfer = self.pod("sky_transfer")?;
        let probe_depth = self.pod("probe_depth")?;
        let factors = self.factors()?;
        let bricks: Vec<Brick> = self.pod("bricks")?;
        let coarse = CoarseBricks {
            bricks: self.pod("coarse")?,
            children: self.pod("coarse")?,
            moments: self.pod("coarse")?,
        };
        let surfels = self.surfels(surfel_precision, &bricks)?;
        Ok(Asset {
            header,
            probes,
            sky_mask,
            sky_transfer,
            probe_depth,
            factors,
            bricks,
            coarse,
            surfels,
            geometry: Geometry {
                nodes: self.pod("geometry")?,
                triangles: self.pod("geometry")?,
            },
            lights: self.via_serde("lights")?,
            surface: SurfaceTerms {
                header: self.via_serde("surface")?,
                slots: self.pod("surface")?,
                cells: self.pod("surface")?,
                surfels: self.pod("surface")?,
                groups: self.pod("surface")?,
                group_surfels: self.pod("surface")?,
                near_ranges: self.pod("surface")?,
                near: self.pod("surface")?,
                sky: self.pod("surface")?,
                sides: self.pod("surface")?,
            },
        })
    }

    /// The surfels, stored at `precision` ([`crate::surfel`]; a packed surfel's position is a
    /// fraction of its brick's bounds, in `bricks`).
    fn surfels(
        &mut self,
        precision: SurfelPrecision,
        bricks: &[Brick],
    ) -> Result<Vec<Surfel>, FormatError> {
        Ok(match precision {
            SurfelPrecision::F32 => self.pod("surfels")?,
            SurfelPrecision::Packed => self
                .pod::<PackedSurfel>("surfels")?
                .iter()
                .map(|p| p.surfel(&brick_of(bricks, p.brick)))
                .collect(),
        })
    }

    fn factors(&mut self) -> Result<Factors, FormatError> {
        let at = self.at;
        Ok(match self.via_serde::<u32>("factors")? {
            F32 => Factors::F32(self.pod("factors")?),
            F16 => Factors::F16(self.pod("factors")?),
            U8 => Factors::U8 {
                factors: self.pod("factors")?,
                offset_scale: self.via_serde("factors")?,
            },
            other => return Err(self.error("factors", at, format!("unknown encoding {other}"))),
        })
    }

    fn via_serde<T: serde::de::DeserializeOwned>(
        &mut self,
        section: &'static str,
    ) -> Result<T, FormatError> {
        let rest = &self.payload[self.at..];
        let (value, used) = bincode::serde::decode_from_slice(rest, config()).map_err(|e| {
            let message = match e {
                bincode::error::DecodeError::UnexpectedEnd { additional } => too_early(additional),
                other => other.to_string(),
            };
            self.error(section, self.at, message)
        })?;
        self.at += used;
        Ok(value)
    }

    fn pod<T: Pod + serde::de::DeserializeOwned>(
        &mut self,
        section: &'static str,
    ) -> Result<Vec<T>, FormatError> {
        if !RAW {
            return self.via_serde(section);
        }
        let start = self.at;
        let len: u64 = self.via_serde(section)?;
        let rest = self.payload.len() - self.at;
        let size = std::mem::size_of::<T>();
        let fits = usize::try_from(len)
            .ok()
            .and_then(|n| Some((n, n.checked_mul(size)?)))
            .filter(|&(_, b)| b <= rest);
        let Some((n, bytes)) = fits else {
            let message =
                format!("{len} elements of {size} bytes declared, {rest} bytes of payload left");
            return Err(self.error(section, start, message));
        };
        let mut v = vec![T::zeroed(); n];
        bytemuck::cast_slice_mut(&mut v).copy_from_slice(&self.payload[self.at..self.at + bytes]);
        self.at += bytes;
        Ok(v)
    }

    fn error(&self, section: &'static str, offset: usize, message: String) -> FormatError {
        FormatError::Decode {
            section,
            offset,
            message,
        }
    }
}

fn too_early(additional: usize) -> String {
    format!("the payload ends {additional} bytes too early")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::asset::*;
    use crate::factors::*;

    /// An asset with a few of everything (not a valid one: the sections only need to be
    /// non-empty and distinct), factors in `factors`.
    fn sample(factors: Factors) -> Asset {
        Asset {
            header: Header {
                generator: "test".into(),
                source_name: "scene.glb".into(),
                source_hash: 0x0123_4567_89ab_cdef,
                grid: Grid::cubic([1.0, 2.0, 3.0], 0.5, [1, 1, 1]),
                ray_count: 512,
                settings: BakeSettingsRecord {
                    spacing: 0.5,
                    bounds: Some([0.0, 0.0, 0.0, 1.0, 1.0, 1.0]),
                    cell_size: 0.04,
                    merge_distance: 0.04,
                    merge_normal_cos: 0.9,
                    double_sided_override: true,
                    invalid_backface_fraction: 0.1,
                    transfer_precision: TransferPrecision::U8,
                    surfel_precision: crate::SurfelPrecision::F32,
                    far_ratio: 2.0,
                },
                stats: BakeStats::default(),
            },
            probes: vec![Probe {
                first_factor: 7,
                ..Probe::default()
            }],
            sky_mask: vec![1, u32::MAX, 0x1234_5678],
            sky_transfer: vec![[0.5; 9]],
            probe_depth: vec![9, 8],
            factors,
            bricks: vec![Brick {
                centroid: [1.0, -2.0, 3.5],
                flags: 5,
                ..Brick::default()
            }],
            coarse: crate::coarse::CoarseBricks {
                bricks: vec![crate::coarse::CoarseBrick {
                    child_count: 2,
                    level: 3,
                    ..Default::default()
                }],
                children: vec![0, 0],
                moments: vec![crate::coarse::BrickMoments {
                    weight: 2.5,
                    ..Default::default()
                }],
            },
            surfels: vec![Surfel {
                weight: 3.0,
                ..Surfel::default()
            }],
            geometry: Geometry {
                nodes: vec![BvhNode {
                    count: 2,
                    ..BvhNode::default()
                }],
                triangles: vec![Triangle::default(); 2],
            },
            lights: Vec::new(),
            surface: crate::surface::SurfaceTerms {
                header: crate::surface::SurfelTermsHeader {
                    brick_size: 0.5,
                    rays: 64,
                    ..Default::default()
                },
                slots: vec![crate::surface::SurfaceSlot {
                    key: [1, -2, 3],
                    value: 7,
                }],
                cells: vec![0x0302_0100; 16],
                surfels: vec![crate::surface::SurfelTerms {
                    mask: crate::surfel_terms::centre_code([0; 3]) | 1,
                    ..Default::default()
                }],
                groups: vec![0],
                group_surfels: vec![[0, 1]],
                near_ranges: vec![[0, 1]],
                near: vec![0x1ff],
                sky: vec![0x3c00],
                sides: vec![crate::surface::SurfaceSide {
                    surfel: 0,
                    partner: 0,
                    normal: 0x7fff,
                    offset: 0.25,
                }],
            },
        }
    }

    fn every_encoding() -> Vec<Asset> {
        let f32 = FactorF32 {
            brick: 0x0102_0304,
            rays: 9,
            sh: [0.25; 8],
            offset: [-1.0, 0.0, 2.0],
            _pad: 0,
        };
        let f16 = FactorF16 {
            brick: 77,
            ..FactorF16::default()
        };
        let u8 = FactorSlot {
            brick_rays: 0xdead_beef,
            bits: 1,
        };
        vec![
            sample(Factors::F32(vec![f32, f32])),
            sample(Factors::F16(vec![f16])),
            sample(Factors::U8 {
                factors: vec![u8; 3],
                offset_scale: 0.125,
            }),
            sample(Factors::U8 {
                factors: Vec::new(),
                offset_scale: 1.0,
            }),
        ]
    }

    fn serde_bytes<T: Serialize>(value: &T) -> Vec<u8> {
        bincode::serde::encode_to_vec(value, config()).unwrap()
    }

    fn read(payload: &[u8]) -> Result<Asset, FormatError> {
        Sections { payload, at: 0 }.asset()
    }

    /// The section writer writes serde's bytes, and the reader reads them back; packed
    /// surfels are serde's bytes of their packing, read back as they were quantised.
    #[test]
    fn payload_is_serdes() {
        for asset in every_encoding() {
            let serde = serde_bytes(&asset);
            let mut ours = Vec::new();
            assert!(write_payload(&asset, &mut ours).is_ok());
            assert_eq!(ours, serde, "{:?}", asset.factors);
            assert_eq!(payload_size(&asset).unwrap(), serde.len());
            assert_eq!(read(&serde).unwrap(), asset);

            let mut packed = asset.clone();
            packed.header.settings.surfel_precision = SurfelPrecision::Packed;
            let surfels = std::mem::take(&mut packed.surfels);
            let mut ours = Vec::new();
            assert!(write_payload(&packed, &mut ours).is_ok());
            let sizes = |a: &Asset| serde_bytes(a).len() - size_of::<Surfel>() * a.surfels.len();
            assert_eq!(sizes(&packed), ours.len());
            packed.surfels = surfels;
            let mut ours = Vec::new();
            assert!(write_payload(&packed, &mut ours).is_ok());
            assert_eq!(
                ours.len(),
                sizes(&packed) + size_of::<PackedSurfel>() * packed.surfels.len()
            );
            assert_eq!(payload_size(&packed).unwrap(), ours.len());
            let back = read(&ours).unwrap();
            assert_eq!(back.surfels[0].weight, 3.0);
            packed.surfels = packed
                .surfels
                .iter()
                .map(|s| SurfelPrecision::Packed.quantize(s, &packed.bricks))
                .collect();
            assert_eq!(back, packed);
        }
    }

    /// A length that runs past the payload (or whose byte count overflows), a truncated payload
    /// and an unknown factor encoding are errors naming the section, not panics or huge
    /// allocations.
    #[test]
    fn bad_payloads_are_errors() {
        let asset = &every_encoding()[2];
        let bytes = serde_bytes(asset);
        let probes_at = serde_bytes(&asset.header).len();
        let one_too_many =
            ((bytes.len() - probes_at - 8) / std::mem::size_of::<Probe>() + 1) as u64;
        for len in [one_too_many, u64::MAX / 2, u64::MAX] {
            let mut bad = bytes.clone();
            bad[probes_at..probes_at + 8].copy_from_slice(&len.to_le_bytes());
            let e = read(&bad).unwrap_err();
            let ok = matches!(&e, FormatError::Decode { section: "probes", offset, message }
                if *offset == probes_at && message.contains("bytes of payload left"));
            assert!(ok, "length {len}: {e}");
        }
        let e = read(&bytes[..bytes.len() - 3]).unwrap_err();
        assert!(
            matches!(
                e,
                FormatError::Decode {
                    section: "surface",
                    ..
                }
            ),
            "{e}"
        );
        let factors_at = probes_at
            + serde_bytes(&asset.probes).len()
            + serde_bytes(&asset.sky_mask).len()
            + serde_bytes(&asset.sky_transfer).len()
            + serde_bytes(&asset.probe_depth).len();
        let mut bad = bytes.clone();
        bad[factors_at..factors_at + 4].copy_from_slice(&3u32.to_le_bytes());
        let e = read(&bad).unwrap_err();
        let ok = matches!(&e, FormatError::Decode { section: "factors", message, .. }
            if message.contains("unknown encoding 3"));
        assert!(ok, "{e}");
    }
}
