//! Asset file robustness: exact round trips, and every kind of damage (flipped bytes,
//! truncation, wrong magic/version/checksum, structurally broken assets with a valid checksum)
//! gives a typed error, never a panic.

use std::sync::OnceLock;

use prt_bake::BakeSettings;
use prt_format::{decode, encode, Asset, Factors, FormatError, TransferPrecision, FORMAT_VERSION};
use prt_tests::{bake_ok, cornell, rays};

/// Bytes before the payload: magic (8), version (4), payload length (8).
const PREFIX: usize = 20;
/// Bytes after the payload: the checksum.
const SUFFIX: usize = 8;

/// A small real asset: the Cornell box at 64 rays and 0.5 m spacing (baked once per process).
fn small_asset(precision: TransferPrecision) -> &'static Asset {
    static F16: OnceLock<Asset> = OnceLock::new();
    static F32: OnceLock<Asset> = OnceLock::new();
    static U8: OnceLock<Asset> = OnceLock::new();
    let cell = match precision {
        TransferPrecision::F16 => &F16,
        TransferPrecision::F32 => &F32,
        TransferPrecision::U8 => &U8,
    };
    cell.get_or_init(|| {
        let settings = BakeSettings {
            spacing: Some(0.5),
            transfer_precision: precision,
            ..rays(64)
        };
        bake_ok(&cornell(), &settings)
    })
}

fn small_file() -> Vec<u8> {
    encode(small_asset(TransferPrecision::F16)).expect("encode")
}

/// Recomputes the length field and checksum after the payload was edited, so that decoding
/// gets past the integrity checks and exercises the payload decoder and validation.
fn reseal(bytes: &mut [u8]) {
    let payload = (bytes.len() - PREFIX - SUFFIX) as u64;
    bytes[12..20].copy_from_slice(&payload.to_le_bytes());
    let end = bytes.len() - SUFFIX;
    let sum = xxhash_rust::xxh3::xxh3_64(&bytes[..end]);
    bytes[end..].copy_from_slice(&sum.to_le_bytes());
}

/// Offsets to damage: every one of the first 64 bytes, then about 300 spread over the file
/// (always including the last byte).
fn damage_offsets(len: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (0..64.min(len)).collect();
    let step = (len / 300).max(1);
    v.extend((64..len).step_by(step));
    v.push(len - 1);
    v.dedup();
    v
}

// ---------------------------------------------------------------------------------------------
// Round trips

/// encode -> decode gives back an equal asset, for half and full precision transfers, and the
/// two precisions really store different factor tables.
#[test]
fn round_trip_is_exact_in_both_precisions() {
    for precision in [
        TransferPrecision::F16,
        TransferPrecision::F32,
        TransferPrecision::U8,
    ] {
        let asset = small_asset(precision);
        assert_eq!(asset.factors.precision(), precision);
        assert!(!asset.factors.is_empty());
        let bytes = encode(asset).expect("encode");
        let back = decode(&bytes).expect("decode");
        assert!(
            back == *asset,
            "{precision:?}: round trip changed the asset"
        );
        assert_eq!(
            encode(&back).expect("re-encode"),
            bytes,
            "{precision:?}: re-encode differs"
        );
    }
    assert!(matches!(
        small_asset(TransferPrecision::F16).factors,
        Factors::F16(_)
    ));
    assert!(matches!(
        small_asset(TransferPrecision::F32).factors,
        Factors::F32(_)
    ));
    assert!(matches!(
        small_asset(TransferPrecision::U8).factors,
        Factors::U8 { .. }
    ));
}

/// Assets round-trip through files too (atomic write, read back).
#[test]
fn round_trip_through_a_file() {
    let dir = prt_tests::ScratchDir::new("round_trip_through_a_file");
    let path = dir.path().join("a.prt");
    let asset = small_asset(TransferPrecision::F32);
    let n = prt_format::write_asset_atomic(&path, asset).expect("write");
    assert_eq!(std::fs::metadata(&path).unwrap().len(), n);
    assert!(prt_format::read_asset(&path).expect("read") == *asset);
    assert_eq!(dir.entries(), ["a.prt"], "no temporary file left");
}

/// A staged asset is removed when its commit fails (its destination became a directory) or
/// when it is dropped uncommitted, and the error names the destination.
#[test]
fn a_staged_asset_is_removed_unless_committed() {
    let dir = prt_tests::ScratchDir::new("a_staged_asset_is_removed_unless_committed");
    let path = dir.path().join("a.prt");
    let asset = small_asset(TransferPrecision::U8);
    let (staged, n) = prt_format::stage_asset(&path, asset).expect("stage");
    assert_eq!(dir.entries().len(), 1, "the temporary file");
    assert!(n > 0);
    drop(staged);
    assert!(dir.entries().is_empty(), "left {:?}", dir.entries());

    let (staged, _) = prt_format::stage_asset(&path, asset).expect("stage");
    std::fs::create_dir(&path).unwrap();
    std::fs::write(path.join("x"), b"x").unwrap();
    let e = staged.commit().unwrap_err();
    assert!(e.to_string().contains("a.prt"), "{e}");
    assert_eq!(dir.entries(), ["a.prt"], "temporary file left behind");
}

/// A file written by streaming (the checksum hashed below a 1 MiB buffer) holds exactly the
/// bytes of the in-memory encoding, for an asset of several buffers' worth.
#[test]
fn streamed_file_equals_the_encoding() {
    let dir = prt_tests::ScratchDir::new("streamed_file_equals_the_encoding");
    let path = dir.path().join("big.prt");
    let asset = bake_ok(&cornell(), &rays(512));
    let bytes = encode(&asset).expect("encode");
    // Past the 8 MiB after which the writer starts the disk writes.
    assert!(
        bytes.len() > 8 << 20,
        "{} bytes: want more than 8 MiB",
        bytes.len()
    );
    let n = prt_format::write_asset_atomic(&path, &asset).expect("write");
    assert_eq!(n, bytes.len() as u64);
    assert!(
        std::fs::read(&path).unwrap() == bytes,
        "file differs from encode()"
    );
}

// ---------------------------------------------------------------------------------------------
// Damaged files

/// A byte flipped anywhere is caught, by the check that covers that byte: the magic, the
/// version, the length field, or else the checksum.
#[test]
fn flipped_bytes_are_rejected() {
    let good = small_file();
    for offset in damage_offsets(good.len()) {
        for mask in [0x01u8, 0xff] {
            let mut bad = good.clone();
            bad[offset] ^= mask;
            let e = decode(&bad).expect_err("flipped byte accepted");
            let ok = match offset {
                0..8 => matches!(e, FormatError::BadMagic { .. }),
                8..12 => matches!(e, FormatError::UnsupportedVersion { .. }),
                12..20 => matches!(e, FormatError::LengthMismatch { .. }),
                _ => matches!(e, FormatError::Checksum { .. }),
            };
            assert!(ok, "byte {offset} ^ {mask:#x}: unexpected error {e:?}");
        }
    }
}

/// A truncated (or extended) file is rejected, whatever the length.
#[test]
fn truncated_files_are_rejected() {
    let good = small_file();
    for len in damage_offsets(good.len()) {
        let e = decode(&good[..len]).expect_err("truncated file accepted");
        let ok = if len < PREFIX + SUFFIX {
            matches!(
                e,
                FormatError::TooShort { .. } | FormatError::BadMagic { .. }
            )
        } else {
            matches!(e, FormatError::LengthMismatch { .. })
        };
        assert!(ok, "length {len}: unexpected error {e:?}");
    }
    let mut longer = good.clone();
    longer.push(0);
    assert!(matches!(
        decode(&longer),
        Err(FormatError::LengthMismatch { .. })
    ));
}

/// Another format version (an older one too: version 5 had no probe slots) is refused with the
/// version found and the one supported, and says to re-bake.
#[test]
fn wrong_version_is_unsupported() {
    for version in [0, FORMAT_VERSION - 1, FORMAT_VERSION + 1, u32::MAX] {
        let mut bad = small_file();
        bad[8..12].copy_from_slice(&version.to_le_bytes());
        match decode(&bad) {
            Err(e @ FormatError::UnsupportedVersion { found, supported }) => {
                assert_eq!((found, supported), (version, FORMAT_VERSION));
                assert!(e.to_string().contains(&version.to_string()), "{e}");
                assert!(e.to_string().contains("re-bake"), "{e}");
            }
            other => panic!("version {version}: {other:?}"),
        }
    }
}

/// A wrong stored checksum is a checksum error carrying both values.
#[test]
fn wrong_checksum_is_checksum_error() {
    let mut bad = small_file();
    let end = bad.len() - SUFFIX;
    let stored = u64::from_le_bytes(bad[end..].try_into().unwrap());
    bad[end..].copy_from_slice(&(stored ^ 1).to_le_bytes());
    match decode(&bad) {
        Err(FormatError::Checksum {
            stored: s,
            computed,
        }) => {
            assert_eq!((s, computed), (stored ^ 1, stored));
        }
        other => panic!("{other:?}"),
    }
}

/// Files that are not prt assets (a glTF, a text-mode mangled asset, zeros) are BadMagic or
/// TooShort.
#[test]
fn bad_magic_is_rejected() {
    let glb = std::fs::read(prt_tests::fixture("cornell/cornell.glb")).unwrap();
    assert!(matches!(decode(&glb), Err(FormatError::BadMagic { .. })));
    let mut mangled = small_file();
    mangled[6] = b'\n'; // CR LF -> LF LF
    assert!(matches!(
        decode(&mangled),
        Err(FormatError::BadMagic { .. })
    ));
    assert!(matches!(
        decode(&[0u8; 64]),
        Err(FormatError::BadMagic { .. })
    ));
    assert!(matches!(decode(&[]), Err(FormatError::TooShort { .. })));
    assert!(matches!(
        decode(b"PRTGI\0\r\n"),
        Err(FormatError::TooShort { .. })
    ));
}

/// With a valid checksum, a payload that is cut short does not decode, and one with extra bytes
/// is refused as trailing data.
#[test]
fn resealed_short_or_long_payload_is_rejected() {
    let good = small_file();
    let mut short = good.clone();
    short.remove(good.len() - SUFFIX - 1);
    reseal(&mut short);
    assert!(
        matches!(decode(&short), Err(FormatError::Decode { .. })),
        "{:?}",
        decode(&short).err()
    );

    let mut long = good.clone();
    long.insert(good.len() - SUFFIX, 0);
    reseal(&mut long);
    assert!(
        matches!(
            decode(&long),
            Err(FormatError::TrailingBytes { payload_bytes: 1 })
        ),
        "{:?}",
        decode(&long).err()
    );
}

/// With a valid checksum, a flipped payload byte at any of ~360 offsets either decodes into an
/// asset that passed validation or is an error: never a panic.
#[test]
fn resealed_payload_damage_never_panics() {
    let good = small_file();
    let payload = PREFIX..good.len() - SUFFIX;
    let (mut ok, mut err) = (0, 0);
    for offset in damage_offsets(payload.len()) {
        for mask in [0x01u8, 0x80, 0xff] {
            let mut bad = good.clone();
            bad[PREFIX + offset] ^= mask;
            reseal(&mut bad);
            match decode(&bad) {
                Ok(asset) => {
                    prt_format::validate::validate(&asset)
                        .expect("decode returned an invalid asset");
                    ok += 1;
                }
                Err(_) => err += 1,
            }
        }
    }
    assert!(err > 0 && ok + err > 1000, "ok {ok}, err {err}");
}

/// With a valid checksum, a string length far beyond the payload (the generator and source names
/// are the first payload fields) is an error, not an attempt to allocate it: lengths of tens of
/// GiB used to abort the process with "memory allocation failed".
#[test]
fn resealed_huge_string_lengths_are_errors() {
    let good = small_file();
    let generator_len = small_asset(TransferPrecision::F16).header.generator.len();
    let source_name_at = PREFIX + 8 + generator_len;
    for at in [PREFIX, source_name_at] {
        let stored = u64::from_le_bytes(good[at..at + 8].try_into().unwrap());
        assert!(
            stored < 100,
            "offset {at} does not hold a string length ({stored})"
        );
        for len in [
            u64::MAX,
            1 << 40,
            (1 << 36) - 1,
            (1 << 36) - 4096,
            1 << 35,
            1 << 31,
            1000,
        ] {
            let mut bad = good.clone();
            bad[at..at + 8].copy_from_slice(&len.to_le_bytes());
            reseal(&mut bad);
            let e = decode(&bad).expect_err("huge string length accepted");
            assert!(
                matches!(e, FormatError::Decode { .. }),
                "length {len} at {at}: {e:?}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Structurally broken assets with a valid checksum

/// Encodes a damaged copy of the small asset (with a valid checksum) and decodes it.
fn decode_damaged(damage: impl FnOnce(&mut Asset)) -> Result<Asset, FormatError> {
    let mut asset = small_asset(TransferPrecision::F16).clone();
    damage(&mut asset);
    decode(&encode(&asset).expect("encode damaged asset"))
}

fn assert_invalid(what: &str, section: &str, damage: impl FnOnce(&mut Asset)) {
    match decode_damaged(damage) {
        Err(FormatError::Invalid { section: s, .. }) if s == section => {}
        other => panic!("{what}: expected Invalid in {section}, got {other:?}"),
    }
}

fn assert_count(what: &str, section: &str, damage: impl FnOnce(&mut Asset)) {
    match decode_damaged(damage) {
        Err(FormatError::Count { section: s, .. }) if s == section => {}
        other => panic!("{what}: expected Count of {section}, got {other:?}"),
    }
}

/// A u8 table's slots pair up (`prt_format::FactorSlot`): a continuation without its full
/// head, a full head without its continuation, and a probe table that splits a pair are
/// refused, naming the section.
#[test]
fn u8_slot_pairs_are_checked() {
    let asset = small_asset(TransferPrecision::U8);
    let Factors::U8 { factors: slots, .. } = &asset.factors else {
        panic!("a u8 bake has a u8 table")
    };
    let lobes = slots
        .iter()
        .filter(|s| s.rays() != 0 && !s.is_full())
        .count();
    let full = slots.iter().filter(|s| s.is_full()).count();
    assert!(
        lobes > 0 && full > 0,
        "{lobes} lobes and {full} full factors"
    );
    let damaged = |damage: &dyn Fn(&mut Asset)| {
        let mut a = asset.clone();
        damage(&mut a);
        decode(&encode(&a).expect("encode damaged asset"))
    };
    let invalid = |what: &str, section: &str, r: Result<Asset, FormatError>| match r {
        Err(FormatError::Invalid { section: s, .. }) if s == section => {}
        other => panic!("{what}: expected Invalid in {section}, got {other:?}"),
    };
    // A full head made a lobe: its continuation has no head.
    let head = slots.iter().position(|s| s.is_full()).unwrap();
    invalid(
        "continuation without its head",
        "factors",
        damaged(&|a| u8_slots(a)[head].bits &= !prt_format::SLOT_FULL),
    );
    // A lobe head followed by another head, marked full.
    let lobe = (0..slots.len() - 1)
        .find(|&f| slots[f].rays() != 0 && !slots[f].is_full() && slots[f + 1].rays() != 0)
        .unwrap();
    invalid(
        "full head without its continuation",
        "factors",
        damaged(&|a| {
            let s = &mut u8_slots(a)[lobe];
            s.bits = (s.bits & ((1 << prt_format::R_AT) - 1)) | prt_format::SLOT_FULL;
        }),
    );
    // A probe whose table ends with a continuation gives it to the next probe with a table.
    let ends = |p: &prt_format::Probe| (p.first_factor + p.factor_count) as usize;
    let p = (0..asset.probes.len())
        .find(|&p| {
            let probe = &asset.probes[p];
            let later = asset.probes[p + 1..].iter().any(|q| q.factor_count > 0);
            probe.factor_count > 2 && slots[ends(probe) - 1].rays() == 0 && later
        })
        .expect("a probe whose table ends with a full factor, and a table after it");
    invalid(
        "a table that splits a full factor",
        "probes",
        damaged(&|a| {
            a.probes[p].factor_count -= 1;
            for q in a.probes.iter_mut().skip(p + 1) {
                q.first_factor -= 1;
                if q.factor_count > 0 {
                    q.factor_count += 1;
                    break;
                }
            }
        }),
    );
}

/// The slots of a u8 table.
fn u8_slots(a: &mut Asset) -> &mut Vec<prt_format::FactorSlot> {
    match &mut a.factors {
        Factors::U8 { factors, .. } => factors,
        _ => panic!("not a u8 table"),
    }
}

/// Sets the brick index of factor `f` in either precision.
fn set_factor_brick(factors: &mut Factors, f: usize, brick: u32) {
    match factors {
        Factors::F16(v) => v[f].brick = brick,
        Factors::F32(v) => v[f].brick = brick,
        Factors::U8 { factors, .. } => {
            factors[f].brick_rays = (brick << 8) | (factors[f].brick_rays & 0xff)
        }
    }
}

/// Every index, count and float that the runtime relies on is checked on load: damaged assets
/// re-encoded with a valid checksum are Invalid (naming the section) or Count errors.
#[test]
fn structurally_broken_assets_are_invalid() {
    let asset = small_asset(TransferPrecision::F16);
    assert!(asset.probes.len() >= 2 && asset.bricks.len() >= 2 && asset.surfels.len() >= 4);
    let bricks = asset.bricks.len() as u32;

    assert_invalid("factor brick out of range", "factors", |a| {
        set_factor_brick(&mut a.factors, 0, bricks)
    });
    assert_invalid("factor with 0 rays", "factors", |a| match &mut a.factors {
        Factors::F16(v) => v[0].rays = 0,
        Factors::F32(v) => v[0].rays = 0,
        Factors::U8 { factors, .. } => factors[0].brick_rays &= !0xff,
    });
    assert_invalid("factor with NaN transfer", "factors", |a| {
        match &mut a.factors {
            Factors::F16(v) => v[0].sh[1] = 0x7e00, // a half NaN in the low half
            Factors::F32(v) => v[0].sh[2] = f32::NAN,
            Factors::U8 { offset_scale, .. } => *offset_scale = f32::NAN,
        }
    });
    assert_invalid("probe first_factor off by one", "probes", |a| {
        a.probes[1].first_factor += 1
    });
    assert_invalid("probe with NaN position", "probes", |a| {
        a.probes[0].position[1] = f32::NAN
    });
    assert_invalid("sky rays beyond ray count", "probes", |a| {
        a.probes[0].sky_rays = a.header.ray_count + 1
    });
    assert_invalid("probe slots out of order", "probes", |a| {
        a.probes[1].slot += 1
    });
    assert_invalid("a probe left out that keeps its flags", "probes", |a| {
        // The last probe, its sky and visibility data gone with its slot.
        let last = a.probes.last_mut().unwrap();
        assert!(last.is_valid());
        last.slot = prt_format::NO_SLOT;
        let slots = a.sky_transfer.len() - 1;
        a.sky_mask = prt_format::sky_mask::with_index((0..slots).map(|s| a.sky_record(s).to_vec()));
        a.sky_transfer.pop();
        a.probe_depth
            .truncate(a.probe_depth.len() - prt_format::DEPTH_WORDS);
    });
    // The sky and visibility sections hold one entry per placed probe (the sections are
    // checked before the records).
    assert_count("a sky mask for a probe not placed", "sky_mask", |a| {
        a.probes[0].slot = prt_format::NO_SLOT
    });
    assert_count("last probe claims an extra factor", "factors", |a| {
        a.probes.last_mut().unwrap().factor_count += 1
    });
    assert_count("missing sky transfer", "sky_transfer", |a| {
        a.sky_transfer.pop();
    });
    assert_count("missing sky mask word", "sky_mask", |a| {
        a.sky_mask.pop();
    });
    // 64 rays: two mask words, a bitmap word each for mixed and full words.
    assert_invalid("a sky mask word marked mixed and full", "sky_mask", |a| {
        let at = a.sky_mask[0] as usize;
        a.sky_mask[at] |= 1;
        a.sky_mask[at + 1] |= 1;
    });
    assert_invalid(
        "a sky mask word past the rays marked full",
        "sky_mask",
        |a| {
            let at = a.sky_mask[0] as usize;
            a.sky_mask[at + 1] |= 1 << 2;
        },
    );
    // The index in front of the records: a record's end before its start, past the array.
    assert_invalid("a sky mask index that runs backwards", "sky_mask", |a| {
        a.sky_mask.swap(1, 2);
    });
    assert_invalid("a sky mask index past the array", "sky_mask", |a| {
        a.sky_mask[1] = u32::MAX;
    });
    assert_count("a sky mask index of one probe too many", "sky_mask", |a| {
        a.sky_mask[0] += 1;
    });
    assert_invalid("an empty sky mask word stored as mixed", "sky_mask", |a| {
        let slot = (0..a.sky_transfer.len())
            .find(|&s| a.sky_mask[a.sky_mask[s] as usize] != 0)
            .expect("a probe sees sky over part of a word");
        let at = a.sky_mask[slot] as usize;
        a.sky_mask[at + 2] = 0;
    });
    assert_invalid("NaN sky transfer", "sky_transfer", |a| {
        a.sky_transfer[1][4] = f32::NAN
    });
    assert_count("short visibility maps", "probe_depth", |a| {
        a.probe_depth.pop();
    });
    assert_invalid("dilated but not valid", "probes", |a| {
        a.probes[0].flags = prt_format::PROBE_DILATED
    });
    assert_count("grid larger than the probe list", "probes", |a| {
        a.header.grid.counts[0] += 1
    });
    assert_invalid("zero ray count", "header", |a| a.header.ray_count = 0);
    assert_invalid("NaN cell size", "header.settings", |a| {
        a.header.settings.cell_size = f32::NAN
    });
    assert_invalid("negative cell size", "header.settings", |a| {
        a.header.settings.cell_size = -0.5
    });
    assert_invalid("cell size whose square overflows", "header.settings", |a| {
        a.header.settings.cell_size = 1e20
    });
    assert_invalid("zero spacing", "header.grid", |a| {
        a.header.grid.spacing = 0.0
    });
    assert_invalid("NaN surfel albedo", "surfels", |a| {
        a.surfels[3].albedo[0] = f32::NAN
    });
    assert_invalid("infinite surfel emission", "surfels", |a| {
        a.surfels[2].emission[2] = f32::INFINITY
    });
    assert_invalid("zero surfel weight", "surfels", |a| {
        a.surfels[1].weight = 0.0
    });
    assert_invalid("surfel listed in the wrong brick", "surfels", |a| {
        let first = a.bricks[0].first_surfel as usize;
        a.surfels[first].brick = 1;
    });
    assert_invalid("surfel list cut short", "bricks", |a| {
        a.surfels.pop();
    });
    assert_invalid("brick axis out of range", "bricks", |a| {
        a.bricks[0].flags |= 7
    });
    assert_invalid("brick first_surfel wrong", "bricks", |a| {
        a.bricks[1].first_surfel += 1
    });
    assert_invalid("BVH node pointing at itself", "geometry.nodes", |a| {
        a.geometry.nodes[0].count = 0;
        a.geometry.nodes[0].first = 0;
    });
    assert_invalid("BVH leaf past the triangles", "geometry.nodes", |a| {
        let leaf = a.geometry.nodes.iter().position(|n| n.count > 0).unwrap();
        a.geometry.nodes[leaf].first = a.geometry.triangles.len() as u32;
    });
    assert_invalid("NaN triangle vertex", "geometry.triangles", |a| {
        a.geometry.triangles[0].v1[0] = f32::NAN
    });
    assert_invalid("light with negative intensity", "lights", |a| {
        let light: prt_format::Light =
            serde_json::from_str(r#"{"type": "point", "intensity": -5}"#).unwrap();
        a.lights.push(light);
    });
}

/// The error messages of a broken asset name the section, index and value.
#[test]
fn invalid_asset_messages_name_the_item() {
    let e = decode_damaged(|a| a.probes[1].first_factor += 1000).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("probes[1]") && msg.contains("first_factor"),
        "{msg}"
    );
    let bricks = small_asset(TransferPrecision::F16).bricks.len();
    let e = decode_damaged(|a| set_factor_brick(&mut a.factors, 2, 99_999)).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("factors[2]") && msg.contains("99999") && msg.contains(&bricks.to_string()),
        "{msg}"
    );
}

/// A small asset with coarse bricks (far hits from a twice-the-brick distance on).
fn coarse_asset() -> &'static Asset {
    static COARSE: OnceLock<Asset> = OnceLock::new();
    COARSE.get_or_init(|| {
        let settings = BakeSettings {
            spacing: Some(0.5),
            far_ratio: 2.0,
            ..rays(64)
        };
        bake_ok(&cornell(), &settings)
    })
}

/// Coarse bricks round-trip, and every index, count and float of theirs is checked on load.
#[test]
fn broken_coarse_bricks_are_invalid() {
    let asset = coarse_asset();
    let c = &asset.coarse;
    assert!(c.bricks.len() >= 2 && c.moments.len() == asset.bricks.len());
    assert!(decode(&encode(asset).expect("encode")).expect("decode") == *asset);
    let damaged = |damage: &dyn Fn(&mut Asset)| {
        let mut a = asset.clone();
        damage(&mut a);
        decode(&encode(&a).expect("encode damaged asset"))
    };
    let invalid = |what: &str, section: &str, damage: &dyn Fn(&mut Asset)| match damaged(damage) {
        Err(FormatError::Invalid { section: s, .. }) if s == section => {}
        other => panic!("{what}: expected Invalid in {section}, got {other:?}"),
    };
    let all = (asset.bricks.len() + c.bricks.len()) as u32;
    invalid("factor past the coarse bricks", "factors", &|a| {
        set_factor_brick(&mut a.factors, 0, all)
    });
    invalid("child past the bricks", "coarse", &|a| {
        a.coarse.children[0] = a.bricks.len() as u32
    });
    invalid("one child", "coarse", &|a| {
        a.coarse.bricks[0].child_count = 1
    });
    invalid("children out of order", "coarse", &|a| {
        a.coarse.bricks[1].first_child += 1
    });
    invalid("level 0", "coarse", &|a| a.coarse.bricks[0].level = 0);
    invalid("NaN inverse", "coarse", &|a| {
        a.coarse.bricks[0].inverse[2] = f32::NAN
    });
    invalid("zero weight", "coarse", &|a| {
        a.coarse.bricks[1].weight = 0.0
    });
    invalid("NaN moment", "coarse.moments", &|a| {
        a.coarse.moments[0].moment[0] = f32::NAN
    });
    invalid("moments without coarse bricks", "coarse", &|a| {
        a.coarse.bricks.clear();
        a.coarse.children.clear();
        for p in &mut a.probes {
            p.factor_count = 0;
            p.first_factor = 0;
        }
        a.factors = Factors::U8 {
            factors: Vec::new(),
            offset_scale: 1.0,
        };
    });
    match damaged(&|a| {
        a.coarse.moments.pop();
    }) {
        Err(FormatError::Count { section, .. }) => assert_eq!(section, "coarse.moments"),
        other => panic!("short moments: {other:?}"),
    }
    match damaged(&|a| a.coarse.children.push(0)) {
        Err(FormatError::Count { section, .. }) => assert_eq!(section, "coarse.children"),
        other => panic!("extra child: {other:?}"),
    }
}
