//! Hostile input (issue 8, "Hostile files" and "Outputs and processes"): one test per case of
//! `fixtures/hostile/` (made by `fixtures/make_hostile.py`) and per crafted asset. Each ends as
//! one clear error naming the file, the item and the value: no panic, no allocation far beyond
//! what the file's size implies, no hang, no file read through a URI scheme or outside the
//! scene's folder (`..`, absolute paths, symlinks) unless that folder is allowed.

use std::path::Path;

use prt_bake::BakeSettings;
use prt_format::{decode, encode, Asset, FormatError};
use prt_runtime::{load_rig, CpuRelighter};
use prt_scene::Allowed;
use prt_tests::{bake_ok, cornell, fixture, rays, ScratchDir};

/// Bakes `fixtures/hostile/<name>` and returns the error's message (one line, naming the file).
fn bake_message(name: &str) -> String {
    let path = fixture(&format!("hostile/{name}"));
    let settings = BakeSettings {
        spacing: Some(0.5),
        ..rays(32)
    };
    let msg = match prt_bake::bake(&path, &settings, &prt_bake::NoProgress) {
        Ok(_) => panic!("{name} baked; expected an error"),
        Err(e) => e.to_string(),
    };
    assert!(
        msg.contains(name),
        "{name}: the message does not name the file: {msg}"
    );
    assert!(!msg.contains('\n'), "{name}: not one line: {msg}");
    msg
}

/// One test per malformed scene: the file bakes to an error whose message holds every fragment.
macro_rules! refused {
    ($($test:ident: $file:literal => [$($fragment:literal),+];)+) => {$(
        #[test]
        fn $test() {
            let msg = bake_message($file);
            for fragment in [$($fragment),+] {
                assert!(msg.contains(fragment), "{}: {msg:?} lacks {fragment:?}", $file);
            }
        }
    )+};
}

refused! {
    // Formats the gltf crate's readers panic on (`unreachable!`, slice asserts).
    color_as_scalar: "color_scalar.gltf" => ["Colors(0)", "Scalar"];
    color_as_mat4: "color_mat4.gltf" => ["accessor 2", "64 bytes"];
    color_as_signed_byte: "color_byte.gltf" => ["Colors(0)", "I8"];
    texcoord_as_normalized_short: "texcoord_short_normalized.gltf" => ["TexCoords(0)", "I16"];
    texcoord_as_uint: "texcoord_uint.gltf" => ["TexCoords(0)", "U32"];
    indices_signed: "indices_signed.gltf" => ["indices", "I16"];
    indices_float: "indices_float.gltf" => ["accessor 3", "bufferView 3"];
    byte_stride_below_element_size: "stride_too_small.gltf" => ["accessor 0", "byteStride 4"];
    accessor_without_elements: "count_zero.gltf" => ["accessor 0", "count 0"];
    attribute_accessor_out_of_range: "attribute_index_out_of_range.gltf" => ["accessor 99", "does not exist"];
    image_view_without_mime_type: "image_view_without_mime.gltf" => ["image 0", "mimeType"];
    // Allocations far beyond the file's size, and instancing that never ends.
    shared_children_instancing: "shared_children.gltf" => ["instances", "2199023255552 triangles"];
    shared_empty_children_instancing: "shared_children_empty.gltf" => ["2199023255551 nodes"];
    sparse_accessor_without_view: "sparse_huge_count.gltf" => ["accessor 0", "2147483648 elements"];
    png_bomb: "png_bomb.gltf" => ["image 0", "bomb.png", "16384 x 16384"];
    // Accepted silently before.
    position_as_byte: "position_byte.gltf" => ["Positions", "I8"];
    position_as_short: "position_short.gltf" => ["Positions", "I16"];
    position_as_uint: "position_uint.gltf" => ["Positions", "U32"];
    position_as_vec2: "position_vec2.gltf" => ["Positions", "Vec2"];
    sparse_index_out_of_range: "sparse_index_out_of_range.gltf" => ["sparse index 0 is 1000"];
    matrix_with_trs: "matrix_and_trs.gltf" => ["node 0", "matrix"];
    version_1: "version_1.gltf" => ["\"1.0\""];
    buffer_shorter_than_byte_length: "buffer_shorter.gltf" => ["buffer 0", "1156"];
    absolute_buffer_uri: "absolute_uri.gltf" => ["buffer 0", "/etc/passwd", "outside the scene's folder", "--allow-path"];
    parent_buffer_uri: "parent_uri.gltf" => ["buffer 0", "../etc/passwd", "outside the scene's folder", "--allow-path"];
    file_scheme_buffer_uri: "file_uri.gltf" => ["buffer 0", "file:///etc/passwd"];
    non_finite_emission_names_the_material: "non_finite_emission.gltf" => ["material 0", "emissiveFactor"];
}

/// Bakes `fixtures/hostile/<name>` and asserts a warning holding `fragment`.
fn warns(name: &str, fragment: &str) {
    let (_, report) = prt_bake::bake(
        &fixture(&format!("hostile/{name}")),
        &rays(32),
        &prt_bake::NoProgress,
    )
    .expect("bakes");
    assert!(
        report.warnings.iter().any(|w| w.contains(fragment)),
        "{name}: {:?}",
        report.warnings
    );
}

/// KHR_texture_transform is not implemented: the bake warns instead of ignoring it silently.
#[test]
fn texture_transform_is_warned_about() {
    warns("texture_transform.gltf", "KHR_texture_transform");
}

/// A triangle list of 5 indices: warned about (as the Khronos validator does), the tail ignored.
#[test]
fn index_count_not_a_multiple_of_3_is_warned_about() {
    warns(
        "indices_not_triangles.gltf",
        "5 indices, not a multiple of 3",
    );
}

/// A valid quad scaled by 1e19 (obvhs 0.4 panicked converting its BVH) bakes at its default
/// spacing, and with a spacing far too fine for it the grid is refused before any BVH is built.
#[test]
fn quad_scaled_by_1e19() {
    let path = fixture("hostile/huge_quad.gltf");
    let asset = bake_ok(&path, &rays(32));
    assert!(asset.header.grid.spacing > 1e17, "{:?}", asset.header.grid);
    let e = prt_bake::bake(
        &path,
        &BakeSettings {
            spacing: Some(0.5),
            ..rays(32)
        },
        &prt_bake::NoProgress,
    )
    .map(|_| ())
    .expect_err("refused");
    assert!(e.to_string().contains("more than 2^64"), "{e}");
}

/// A device, a directory or a FIFO given as an input is refused before it is read
/// (`/dev/zero` was read until memory ran out).
#[test]
fn devices_are_not_read_as_inputs() {
    let zero = Path::new("/dev/zero");
    let e = prt_bake::bake(zero, &rays(32), &prt_bake::NoProgress)
        .map(|_| ())
        .expect_err("refused");
    assert!(e.to_string().contains("not a regular file"), "{e}");
    let e = prt_format::read_asset(zero)
        .map(|_| ())
        .expect_err("refused");
    assert!(e.to_string().contains("not a regular file"), "{e}");
    let e = load_rig(zero).map(|_| ()).expect_err("refused");
    assert!(e.to_string().contains("not a regular file"), "{e}");
    let e = prt_format::read_asset(&fixture("hostile"))
        .map(|_| ())
        .expect_err("a directory is refused");
    assert!(e.to_string().contains("not a regular file"), "{e}");
}

/// A rig that is a JSON array is not an empty rig.
#[test]
fn rig_that_is_an_array() {
    let e = load_rig(&fixture("hostile/rig_empty_array.json"))
        .map(|_| ())
        .expect_err("refused");
    let msg = e.to_string();
    assert!(
        msg.contains("rig_empty_array.json") && msg.contains("an array"),
        "{msg}"
    );
}

/// An EXR sky whose 313-byte header claims 100000 x 100000 texels is refused before anything is
/// allocated for it (it aborted at 120 GB).
#[test]
fn exr_header_bomb() {
    let e = load_rig(&fixture("hostile/rig_exr_bomb.json"))
        .map(|_| ())
        .expect_err("refused");
    let msg = e.to_string();
    assert!(
        msg.contains("bomb.exr") && msg.contains("100000 x 100000"),
        "{msg}"
    );
}

fn small_cornell() -> Asset {
    bake_ok(
        &cornell(),
        &BakeSettings {
            spacing: Some(0.6),
            bounds: Some([-0.6, 0.4, -0.6, 0.6, 1.6, 0.6]),
            ..rays(64)
        },
    )
}

/// A relight whose light intensities overflow f32 reports it instead of writing `null` SH.
#[test]
fn intensities_that_overflow_are_an_error() {
    let asset = small_cornell();
    let lighting = load_rig(&fixture("hostile/rig_overflow.json")).expect("loads");
    let e = CpuRelighter::new(&asset)
        .unwrap()
        .relight(&lighting, 1)
        .map(|_| ())
        .expect_err("refused");
    assert!(e.to_string().contains("overflow"), "{e}");
}

/// Absurd counts are refused with their value instead of hanging: 4294967295 bounces, 100,000
/// lights on the CPU, 100,000 threads.
#[test]
fn absurd_counts_are_refused() {
    let asset = small_cornell();
    let mut lighting = load_rig(&fixture("cornell/rig.json")).unwrap();
    let relighter = CpuRelighter::new(&asset).unwrap();
    let e = relighter
        .relight(&lighting, u32::MAX)
        .map(|_| ())
        .expect_err("refused");
    assert!(e.to_string().contains("4294967295"), "{e}");
    let one = lighting.rig.lights[0].clone();
    lighting.rig.lights = vec![one; 100_000];
    let e = relighter
        .relight(&lighting, 1)
        .map(|_| ())
        .expect_err("refused");
    assert!(e.to_string().contains("100000 lights"), "{e}");
    let e = prt_bake::bake(
        &cornell(),
        &BakeSettings {
            threads: Some(100_000),
            ..rays(32)
        },
        &prt_bake::NoProgress,
    )
    .map(|_| ())
    .expect_err("refused");
    assert!(e.to_string().contains("threads = 100000"), "{e}");
}

/// Re-encodes `asset` (a valid checksum over crafted content) and decodes it.
fn crafted(asset: &Asset) -> FormatError {
    decode(&encode(asset).unwrap())
        .map(|_| ())
        .expect_err("refused")
}

/// A crafted asset whose BVH nodes share children (a DAG: CPU relight hung traversing it) fails
/// validation although its checksum is right.
#[test]
fn asset_bvh_with_shared_children() {
    let mut asset = small_cornell();
    let nodes = &mut asset.geometry.nodes;
    assert!(nodes.len() >= 5 && nodes[0].count == 0);
    // Node 1 becomes an inner node whose children are nodes 2 and 3, which node 0 also has
    // (node 0's children are 1 and 2): node 2 has two parents.
    let inner = nodes
        .iter()
        .position(|n| n.count == 0 && n.first > 1)
        .unwrap();
    nodes[1] = prt_format::BvhNode {
        count: 0,
        first: 2,
        ..nodes[inner]
    };
    let e = crafted(&asset);
    assert!(e.to_string().contains("tree"), "{e}");
}

/// Grid counts whose product overflows u64 are refused (they were accepted).
#[test]
fn asset_grid_counts_overflow() {
    let mut asset = small_cornell();
    asset.header.grid.counts = [u32::MAX; 3];
    let e = crafted(&asset);
    assert!(e.to_string().contains("counts"), "{e}");
}

/// A payload cut short (length and checksum fixed up) names the section it ends in and what
/// is missing, instead of printing `UnexpectedEnd { additional: 2 }`. Cut 6 bytes into the
/// surface terms' sky terms (the sides after them, format 18, are an empty list here: a
/// length of 8 bytes), so that the declared length passes what is left.
#[test]
fn decode_errors_name_the_section() {
    let asset = small_cornell();
    assert!(asset.surface.sides.is_empty());
    let bytes = encode(&asset).unwrap();
    let cut = bytes.len() - 8 - 8 - 6;
    let mut short = bytes[..cut].to_vec();
    let payload = (short.len() - 20) as u64;
    short[12..20].copy_from_slice(&payload.to_le_bytes());
    let checksum = xxhash_rust::xxh3::xxh3_64(&short);
    short.extend_from_slice(&checksum.to_le_bytes());
    let e = decode(&short).map(|_| ()).expect_err("refused");
    let msg = e.to_string();
    assert!(
        msg.contains("section surface") && msg.contains("bytes of payload left"),
        "{msg}"
    );
}

/// Buffer URIs that resolve outside the scene file's folder (issue 30 item 7): through `..`, as
/// an absolute path, and through a symlink in the folder that leads out of it. Each is refused
/// by default, naming the file, the buffer, the URI and the flag that allows it, and read once
/// its folder is allowed (also by the bake, through `BakeSettings::allowed`); a data URI needs
/// nothing.
#[test]
fn files_outside_the_scene_folder_need_an_allowed_folder() {
    let dir = ScratchDir::new("outside_the_folder");
    let (scenes, textures) = (dir.path().join("scenes"), dir.path().join("textures"));
    std::fs::create_dir_all(&scenes).unwrap();
    std::fs::create_dir_all(&textures).unwrap();
    std::fs::copy(fixture("two_files/scene.bin"), textures.join("quad.bin")).unwrap();
    std::os::unix::fs::symlink(textures.join("quad.bin"), scenes.join("link.bin")).unwrap();
    let gltf = std::fs::read_to_string(fixture("two_files/scene.gltf")).unwrap();
    assert!(gltf.contains("\"uri\": \"scene.bin\""));
    let absolute = textures.join("quad.bin").display().to_string();
    let allowed = Allowed {
        dirs: vec![textures.clone()],
    };
    for (case, uri) in [
        ("dotdot", "../textures/quad.bin"),
        ("absolute", absolute.as_str()),
        ("symlink", "link.bin"),
    ] {
        let path = scenes.join(format!("{case}.gltf"));
        let text = gltf.replace("\"uri\": \"scene.bin\"", &format!("\"uri\": {uri:?}"));
        std::fs::write(&path, text).unwrap();
        let msg = prt_scene::load(&path, &Allowed::default())
            .map(|_| ())
            .expect_err(case)
            .to_string();
        for fragment in [
            &format!("{case}.gltf: buffer 0 ({uri})"),
            "outside the scene's folder",
            "--allow-path",
        ] {
            assert!(msg.contains(fragment), "{case}: {msg:?} lacks {fragment:?}");
        }
        let scene = prt_scene::load(&path, &allowed).unwrap_or_else(|e| panic!("{case}: {e}"));
        assert_eq!(scene.triangles.len(), 2, "{case}");
        let e = prt_bake::bake(&path, &rays(32), &prt_bake::NoProgress)
            .map(|_| ())
            .expect_err(case);
        assert_eq!(e.to_string(), msg, "{case}");
        let settings = BakeSettings {
            allowed: allowed.clone(),
            ..rays(32)
        };
        bake_ok(&path, &settings);
    }
    // Allowing other folders does not open this one, and one that does not exist is named.
    let elsewhere = Allowed {
        dirs: vec![fixture(""), dir.path().join("no_such_folder")],
    };
    let msg = prt_scene::load(&scenes.join("dotdot.gltf"), &elsewhere)
        .map(|_| ())
        .expect_err("refused")
        .to_string();
    assert!(msg.contains("and the allowed folders"), "{msg}");
    assert!(
        msg.contains("allowed folder ") && msg.contains("no_such_folder"),
        "{msg}"
    );
    // The fixture with a data URI buffer and image loads as before.
    prt_scene::load(&fixture("textured_quad.gltf"), &Allowed::default()).expect("data URIs");
}
