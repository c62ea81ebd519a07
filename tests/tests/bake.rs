//! Bake integration tests: every scene and fixture bakes into a valid asset, bakes are
//! deterministic across thread counts, every ray is accounted for, inside-geometry detection,
//! glTF loading details (textures, transforms, strips/fans, lights, external buffers) and clear
//! errors for bad input.

use std::f32::consts::PI;
use std::path::{Path, PathBuf};

use prt_bake::{BakeError, BakeSettings, NoProgress};
use prt_format::sh::Y00;
use prt_format::{Asset, LightKind, TransferPrecision, BRICK_BACKFACE};
use prt_scene::{Allowed, Scene, SceneError};
use prt_tests::{bake_err, bake_ok, cornell, fixture, point_bounds, rays, ScratchDir};

// ---------------------------------------------------------------------------------------------
// Helpers

/// Files in `dir` whose name ends with `ext`, sorted.
fn files_with_ext(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.is_file() && p.to_string_lossy().ends_with(ext))
        .collect();
    out.sort();
    out
}

/// Loads the scene file `path`, its external files from its own folder only.
fn load(path: &Path) -> Result<Scene, SceneError> {
    prt_scene::load(path, &Allowed::default())
}

fn name_of(p: &Path) -> String {
    p.file_name().unwrap().to_string_lossy().into_owned()
}

/// The asset validates and survives encode -> decode unchanged.
fn assert_valid_and_round_trips(asset: &Asset, what: &str) {
    prt_format::validate::validate(asset).unwrap_or_else(|e| panic!("{what}: invalid: {e}"));
    let bytes = prt_format::encode(asset).unwrap_or_else(|e| panic!("{what}: encode: {e}"));
    let back = prt_format::decode(&bytes).unwrap_or_else(|e| panic!("{what}: decode: {e}"));
    assert!(
        back == *asset,
        "{what}: decode(encode(asset)) differs from asset"
    );
}

/// Bakes `path` with threads 1 and 2, and with 2 and the factor rows through the temporary
/// file (`row_memory` 0: all of them, in chunks of 64 KiB), and asserts byte-identical
/// encodings.
fn assert_deterministic(path: &Path, settings: BakeSettings) {
    let encode_with = |threads, row_memory| {
        let s = BakeSettings {
            threads: Some(threads),
            row_memory,
            ..settings.clone()
        };
        let (asset, report) = prt_bake::bake(path, &s, &prt_bake::NoProgress)
            .unwrap_or_else(|e| panic!("baking {} failed: {e}", path.display()));
        let spilled = report.rows_spilled > 0;
        assert_eq!(
            spilled,
            row_memory == 0,
            "{}: rows through the file",
            path.display()
        );
        prt_format::encode(&asset).expect("encode")
    };
    let one = encode_with(1, settings.row_memory);
    for (two, what) in [
        (encode_with(2, settings.row_memory), "2 threads"),
        (encode_with(2, 0), "2 threads, rows through a file"),
    ] {
        assert_eq!(one.len(), two.len(), "{}: sizes differ", path.display());
        if let Some(i) = one.iter().zip(&two).position(|(a, b)| a != b) {
            panic!(
                "{}: 1 thread and {what} differ first at byte {i} of {}",
                path.display(),
                one.len()
            );
        }
    }
}

/// Sum of factor rays of probe `p`, and of those into back-face bricks.
fn factor_rays(asset: &Asset, p: usize) -> (u64, u64) {
    let probe = &asset.probes[p];
    let (mut all, mut back) = (0u64, 0u64);
    for f in probe.first_factor as usize..(probe.first_factor + probe.factor_count) as usize {
        let (brick, rays) = asset.factors.brick_and_rays(f);
        all += u64::from(rays);
        if asset.bricks[brick as usize].flags & BRICK_BACKFACE != 0 {
            back += u64::from(rays);
        }
    }
    (all, back)
}

/// Sum of the factor transfers (all 9 coefficients) of probe `p`, in f64.
fn transfer_sum(asset: &Asset, p: usize) -> [f64; 9] {
    let probe = &asset.probes[p];
    let mut sum = [0.0f64; 9];
    for f in probe.first_factor as usize..(probe.first_factor + probe.factor_count) as usize {
        let t = asset.factor_transfer(probe, f);
        for k in 0..9 {
            sum[k] += f64::from(t[k]);
        }
    }
    sum
}

/// Every gathered probe: factor rays + sky rays = N exactly, and the k = 0 transfers plus the
/// sky's solid angle cover the sphere (4pi); the probes' own tables' back-face factor rays add
/// up to the header's back-face hits (exactly when every probe is valid: an invalid probe's
/// rays are counted there but make no table). Invalid probes (inside geometry, nothing to
/// dilate from) are never gathered and carry no factor table.
fn assert_bookkeeping(asset: &Asset, what: &str) {
    let n = asset.header.ray_count;
    let four_pi = 4.0 * std::f64::consts::PI;
    let mut back_total = 0u64;
    let all_valid = asset.probes.iter().all(|p| p.is_valid() && !p.is_dilated());
    for (p, probe) in asset.probes.iter().enumerate() {
        if !probe.is_valid() {
            assert_eq!(
                probe.factor_count, 0,
                "{what}: invalid probe {p} has a table"
            );
            continue;
        }
        let (rays, back) = factor_rays(asset, p);
        assert_eq!(
            rays + u64::from(probe.sky_rays),
            u64::from(n),
            "{what}: probe {p}: {rays} factor rays + {} sky rays != {n}",
            probe.sky_rays
        );
        if !probe.is_dilated() {
            back_total += back;
        }
        let solid_angle = transfer_sum(asset, p)[0] / f64::from(Y00)
            + four_pi * f64::from(probe.sky_rays) / f64::from(n);
        assert!(
            ((solid_angle - four_pi) / four_pi).abs() < 1e-5,
            "{what}: probe {p}: factors + sky cover {solid_angle} sr, not 4pi"
        );
    }
    let header_back = asset.header.stats.backface_hits;
    match all_valid {
        true => assert_eq!(back_total, header_back, "{what}: back-face rays"),
        false => assert!(back_total <= header_back, "{what}: back-face rays"),
    }
}

fn approx(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tol)
}

// ---------------------------------------------------------------------------------------------
// 1. Everything bakes into a valid asset that round-trips

/// The public scenes in fixtures/scenes (sponza at a 3 m spacing) bake at 64 rays into assets that
/// validate and round-trip through the file encoding.
#[test]
fn shared_scenes_bake_validate_and_round_trip() {
    let scenes = files_with_ext(&fixture("scenes"), ".glb");
    assert!(
        scenes.len() >= 4,
        "expected the 4 shared scenes, found {scenes:?}"
    );
    for path in scenes {
        let name = name_of(&path);
        let settings = BakeSettings {
            spacing: name.starts_with("sponza").then_some(3.0),
            ..rays(64)
        };
        let asset = bake_ok(&path, &settings);
        assert_eq!(asset.header.source_name, name);
        assert!(asset.header.stats.triangles > 0, "{name}: no triangles");
        assert_valid_and_round_trips(&asset, &name);
    }
}

/// The reference Cornell box bakes from both its .gltf and its .glb form, and both give the
/// same geometry and sky visibility.
#[test]
fn reference_cornell_gltf_and_glb_bake_alike() {
    let gltf = bake_ok(&cornell(), &rays(64));
    let glb = bake_ok(&fixture("cornell/cornell.glb"), &rays(64));
    assert_valid_and_round_trips(&gltf, "cornell.gltf");
    assert_valid_and_round_trips(&glb, "cornell.glb");
    assert_eq!(gltf.header.grid, glb.header.grid);
    assert_eq!(gltf.geometry, glb.geometry);
    assert_eq!(gltf.sky_mask, glb.sky_mask);
}

/// Every good fixture (fixtures/*.gltf except empty.gltf, two_files/scene.gltf and
/// bad/degenerate.gltf) bakes into a valid asset that round-trips.
#[test]
fn good_fixtures_bake_validate_and_round_trip() {
    let mut paths: Vec<PathBuf> = files_with_ext(&fixture(""), ".gltf")
        .into_iter()
        .filter(|p| name_of(p) != "empty.gltf")
        .collect();
    assert!(paths.len() >= 6, "fixtures missing: {paths:?}");
    paths.push(fixture("two_files/scene.gltf"));
    paths.push(fixture("bad/degenerate.gltf"));
    for path in paths {
        let name = name_of(&path);
        let asset = bake_ok(&path, &rays(64));
        assert!(asset.header.stats.triangles > 0, "{name}: no triangles");
        assert_valid_and_round_trips(&asset, &name);
    }
}

/// empty.gltf (no triangles) with explicit bounds gives probes that see only sky: sky_rays = N,
/// no factors, no bricks.
#[test]
fn empty_scene_with_bounds_is_all_sky() {
    let settings = BakeSettings {
        bounds: Some([-0.5, -0.5, -0.5, 0.5, 0.5, 0.5]),
        spacing: Some(1.0),
        ..rays(64)
    };
    let asset = bake_ok(&fixture("empty.gltf"), &settings);
    assert_valid_and_round_trips(&asset, "empty.gltf");
    assert_eq!(asset.probes.len(), 8);
    for (i, p) in asset.probes.iter().enumerate() {
        assert_eq!(p.sky_rays, 64, "probe {i}");
        assert_eq!(p.factor_count, 0, "probe {i}");
        assert!(p.is_valid(), "probe {i}");
    }
    assert!(asset.factors.is_empty() && asset.bricks.is_empty() && asset.surfels.is_empty());
    for slot in 0..asset.sky_transfer.len() {
        let mask = prt_format::sky_mask::decode(asset.sky_record(slot), asset.header.ray_count);
        assert!(mask.iter().all(|&w| w == u32::MAX), "every ray is sky");
    }
    // The sky transfer of the full sphere is the constant function: c0 = 4pi Y00, rest ~0.
    let t = asset.sky_transfer[0];
    assert!((t[0] - 4.0 * PI * Y00).abs() < 1e-4, "{t:?}");
}

/// empty.gltf without bounds has nothing to place probes around: NoTriangles.
#[test]
fn empty_scene_without_bounds_is_no_triangles() {
    let e = bake_err(&fixture("empty.gltf"), &rays(64));
    assert!(matches!(e, BakeError::NoTriangles { .. }), "{e:?}");
    assert!(e.to_string().contains("empty.gltf"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// 2. Determinism

/// Cornell at 512 rays: 1 and 2 threads, rows in memory or through a file, give
/// byte-identical assets.
#[test]
fn deterministic_across_threads_cornell() {
    assert_deterministic(&cornell(), rays(512));
}

/// room.glb: 1 and 2 threads, rows in memory or through a file, give byte-identical assets.
#[test]
fn deterministic_across_threads_room() {
    assert_deterministic(&fixture("scenes/room.glb"), rays(128));
}

/// Sponza (187k triangles, BVH built in parallel): 1 and 2 threads, rows in memory or through
/// a file, give byte-identical assets, BVH included.
#[test]
fn deterministic_across_threads_sponza() {
    let settings = BakeSettings {
        spacing: Some(2.5),
        ..rays(128)
    };
    assert_deterministic(&fixture("scenes/sponza_lod4.glb"), settings);
}

// ---------------------------------------------------------------------------------------------
// 4. Bookkeeping

/// Every ray of every probe is accounted for exactly once (factor rays + sky rays = N), the
/// back-face bricks hold exactly the back-face rays, and the k = 0 transfers plus the sky cover
/// 4pi, in both precisions and on scenes with and without sky.
#[test]
fn every_ray_is_accounted_for() {
    for precision in [TransferPrecision::F16, TransferPrecision::F32] {
        let settings = BakeSettings {
            transfer_precision: precision,
            ..rays(256)
        };
        assert_bookkeeping(&bake_ok(&cornell(), &settings), "cornell");
        let room = bake_ok(&fixture("scenes/room.glb"), &settings);
        assert_bookkeeping(&room, "room.glb");
    }
    let sponza = BakeSettings {
        spacing: Some(3.0),
        ..rays(128)
    };
    let asset = bake_ok(&fixture("scenes/sponza_lod4.glb"), &sponza);
    assert!(
        asset.header.stats.backface_hits > 0,
        "sponza has back faces"
    );
    assert_bookkeeping(&asset, "sponza");
}

/// Merging changes how rays are grouped, never how many each probe sends where: with and
/// without merging, every probe has the same sky rays, back-face rays, rays into bricks and
/// summed SH transfer, and merging gives far fewer factors (at 4096 rays, where many rays of a
/// probe land in the same brick).
#[test]
fn merging_keeps_per_probe_totals() {
    // Without dilation, so that every factor comes from the probe's own ray hits, and every
    // probe kept (`prt_bake::refine` drops different ones from the two bakes).
    let base = BakeSettings {
        spacing: Some(0.5),
        transfer_precision: TransferPrecision::F32,
        dilate: false,
        prune_error: 0.0,
        ..rays(4096)
    };
    let unmerged = bake_ok(
        &cornell(),
        &BakeSettings {
            cell_size: Some(0.0),
            ..base.clone()
        },
    );
    let merged = bake_ok(&cornell(), &base);
    assert_eq!(unmerged.probes.len(), merged.probes.len());
    assert_bookkeeping(&unmerged, "unmerged");
    assert_bookkeeping(&merged, "merged");
    for (p, (u, m)) in unmerged.probes.iter().zip(&merged.probes).enumerate() {
        assert_eq!(u.sky_rays, m.sky_rays, "probe {p}");
        assert_eq!(
            factor_rays(&unmerged, p),
            factor_rays(&merged, p),
            "probe {p}"
        );
        let (tu, tm) = (transfer_sum(&unmerged, p), transfer_sum(&merged, p));
        for k in 0..9 {
            assert!(
                (tu[k] - tm[k]).abs() < 1e-4,
                "probe {p} k {k}: {} vs {}",
                tu[k],
                tm[k]
            );
        }
    }
    // Unmerged: one factor per ray hit of the gathered probes (invalid ones carry no table).
    // Merged: one per brick a probe sees.
    let gathered_hits: u64 = unmerged
        .probes
        .iter()
        .filter(|p| p.is_valid())
        .map(|p| u64::from(unmerged.header.ray_count - p.sky_rays))
        .sum();
    // Factors, not slots (a u8 factor takes one or two).
    let factors = |a: &Asset| a.factors.factor_counts().0;
    assert_eq!(factors(&unmerged) as u64, gathered_hits);
    let (fu, fm) = (factors(&unmerged), factors(&merged));
    assert!(
        fm * 3 < fu,
        "merged bake has {fm} factors, unmerged {fu}: expected far fewer"
    );
    let weight: f64 = merged.surfels.iter().map(|s| f64::from(s.weight)).sum();
    assert_eq!(
        weight, merged.header.stats.ray_hits as f64,
        "surfel weights = ray hits"
    );
}

// ---------------------------------------------------------------------------------------------
// 5. Inside-geometry detection and the furnace box

/// A probe inside a closed single-sided box whose faces point outwards sees only back faces:
/// invalid. A probe above it sees the top face and the sky: valid.
#[test]
fn probe_inside_outward_box_is_invalid() {
    let path = fixture("closed_box_outward.gltf");
    let inside = BakeSettings {
        bounds: Some([-0.1, -0.1, -0.1, 0.1, 0.1, 0.1]),
        spacing: Some(1.0),
        ..rays(256)
    };
    let asset = bake_ok(&path, &inside);
    assert_eq!(asset.probes.len(), 1);
    let p = asset.probes[0];
    assert!(approx(p.position, [0.0; 3], 1e-6), "{:?}", p.position);
    assert!(
        !p.is_valid(),
        "probe at the origin of an outward box must be invalid"
    );
    assert_eq!(asset.header.stats.backface_hits, 256);
    assert_eq!(p.sky_rays, 0);

    let above = BakeSettings {
        bounds: point_bounds([0.0, 3.0, 0.0]),
        ..rays(256)
    };
    let asset = bake_ok(&path, &above);
    let p = asset.probes[0];
    assert!(
        p.is_valid() && p.sky_rays > 0 && asset.header.stats.backface_hits == 0,
        "{p:?}"
    );
}

/// A probe inside the inward box (a closed room) is valid, sees no sky, and every surfel has
/// albedo 0.5 and emission 0.5 (emissiveFactor 1 x KHR_materials_emissive_strength 0.5).
#[test]
fn probe_inside_inward_box_sees_the_furnace() {
    let settings = BakeSettings {
        bounds: Some([-0.1, -0.1, -0.1, 0.1, 0.1, 0.1]),
        spacing: Some(1.0),
        ..rays(1024)
    };
    let asset = bake_ok(&fixture("closed_box_inward.gltf"), &settings);
    assert_eq!(asset.probes.len(), 1);
    let p = asset.probes[0];
    assert!(p.is_valid(), "{p:?}");
    assert_eq!((p.sky_rays, asset.header.stats.backface_hits), (0, 0));
    assert!(!asset.surfels.is_empty());
    for (i, s) in asset.surfels.iter().enumerate() {
        assert!(
            approx(s.albedo, [0.5; 3], 1e-5),
            "surfel {i} albedo {:?}",
            s.albedo
        );
        assert!(
            approx(s.emission, [0.5; 3], 1e-5),
            "surfel {i} emission {:?}",
            s.emission
        );
    }
}

// ---------------------------------------------------------------------------------------------
// 6. Loading

/// Expected albedo of textured_quad.gltf at (x, z) by the README's rule: u = x + 1 (REPEAT),
/// v = z + 1 (MIRRORED_REPEAT), 2x2 texels red green / blue white (v = 0 is the top row), times
/// COLOR_0 = 0.5.
fn textured_quad_albedo(x: f32, z: f32) -> [f32; 3] {
    const TEXELS: [[[f32; 3]; 2]; 2] = [
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        [[0.0, 0.0, 1.0], [1.0, 1.0, 1.0]],
    ];
    let col = ((2.0 * (x + 1.0)).floor() as i64).rem_euclid(2) as usize;
    let m = ((2.0 * (z + 1.0)).floor() as i64).rem_euclid(4);
    let row = if m >= 2 { 3 - m } else { m } as usize;
    TEXELS[row][col].map(|c| 0.5 * c)
}

/// Distance of `c` from the nearest texel boundary (texels are 0.5 m wide in x and z).
fn off_boundary(c: f32) -> f32 {
    let f = (c * 2.0).rem_euclid(1.0);
    f.min(1.0 - f) * 0.5
}

/// textured_quad.gltf: every ray hit's albedo is the texel the README's layout rule gives at its
/// (x, z) (texture decode, UV, REPEAT and MIRRORED_REPEAT, nearest filter, COLOR_0), and the
/// README's table holds at its eight points.
#[test]
fn textured_quad_albedo_follows_the_texel_layout() {
    assert_eq!(
        textured_quad_albedo(-0.75, 0.75),
        [0.5, 0.0, 0.0],
        "helper vs README"
    );
    let settings = BakeSettings {
        bounds: point_bounds([0.0, 0.5, 0.0]),
        cell_size: Some(0.0),
        ..rays(4096)
    };
    let asset = bake_ok(&fixture("textured_quad.gltf"), &settings);
    let mut checked = 0;
    for s in &asset.surfels {
        let [x, y, z] = s.position;
        assert!(y.abs() < 1e-4, "hit off the quad: {:?}", s.position);
        if off_boundary(x) < 0.02 || off_boundary(z) < 0.02 {
            continue;
        }
        let expect = textured_quad_albedo(x, z);
        assert!(
            approx(s.albedo, expect, 1e-3),
            "at ({x}, {z}): {:?}, expected {expect:?}",
            s.albedo
        );
        checked += 1;
    }
    assert!(checked > 1000, "only {checked} surfels checked");

    let table: [((f32, f32), [f32; 3]); 8] = [
        ((-0.75, -0.75), [0.5, 0.0, 0.0]),
        ((-0.25, -0.75), [0.0, 0.5, 0.0]),
        ((-0.75, -0.25), [0.0, 0.0, 0.5]),
        ((-0.25, -0.25), [0.5, 0.5, 0.5]),
        ((0.25, -0.75), [0.5, 0.0, 0.0]),
        ((-0.75, 0.25), [0.0, 0.0, 0.5]),
        ((-0.75, 0.75), [0.5, 0.0, 0.0]),
        ((0.75, 0.75), [0.0, 0.5, 0.0]),
    ];
    for ((x, z), expect) in table {
        let near: Vec<_> = asset
            .surfels
            .iter()
            .filter(|s| (s.position[0] - x).abs() < 0.15 && (s.position[2] - z).abs() < 0.15)
            .collect();
        assert!(!near.is_empty(), "no ray hit near ({x}, {z})");
        for s in near {
            assert!(
                approx(s.albedo, expect, 1e-3),
                "near ({x}, {z}): {:?}",
                s.albedo
            );
        }
    }
}

fn normal_of(t: &[glam::Vec3; 3]) -> glam::Vec3 {
    (t[1] - t[0]).cross(t[2] - t[0])
}

/// Whether triangle `t` has the vertices `v` in some order.
fn same_vertices(t: &[glam::Vec3; 3], v: [[f32; 3]; 3]) -> bool {
    v.iter()
        .all(|p| t.iter().any(|q| q.distance(glam::Vec3::from(*p)) < 1e-5))
}

/// nested_transforms.gltf: TRS parent x matrix child, one mesh instanced twice. Two world
/// triangles at the README's positions; the mirrored instance (determinant -8) has its winding
/// flipped so its front face is +X; 4 points/lines primitives skipped with warnings.
#[test]
fn nested_transforms_compose_and_mirror() {
    let scene = load(&fixture("nested_transforms.gltf")).expect("load");
    assert_eq!(scene.triangles.len(), 2, "{:?}", scene.triangles);
    let plain = scene
        .triangles
        .iter()
        .find(|t| same_vertices(t, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
        .expect("identity instance at (0,0,0) (1,0,0) (0,1,0)");
    let n = normal_of(plain).normalize();
    assert!(
        n.distance(glam::Vec3::Z) < 1e-5,
        "identity instance normal {n}"
    );
    let mirrored = scene
        .triangles
        .iter()
        .find(|t| same_vertices(t, [[0.0, 1.0, -1.0], [0.0, 1.0, 1.0], [0.0, 3.0, -1.0]]))
        .unwrap_or_else(|| panic!("mirrored instance missing: {:?}", scene.triangles));
    let n = normal_of(mirrored).normalize();
    assert!(
        n.distance(glam::Vec3::X) < 1e-5,
        "mirrored instance normal {n}, expected +X"
    );

    let skipped: Vec<&String> = scene
        .warnings
        .iter()
        .filter(|w| w.contains("skipped"))
        .collect();
    assert_eq!(skipped.len(), 4, "{:?}", scene.warnings);
    assert_eq!(
        skipped.iter().filter(|w| w.contains("Points")).count(),
        2,
        "{skipped:?}"
    );
    assert_eq!(
        skipped.iter().filter(|w| w.contains("Lines")).count(),
        2,
        "{skipped:?}"
    );
}

/// strips_fans.gltf: strip, uint32 fan and non-indexed list give 7 triangles, all facing +Z,
/// with the README's total area, and the default (white) material.
#[test]
fn strips_and_fans_triangulate() {
    let scene = load(&fixture("strips_fans.gltf")).expect("load");
    assert_eq!(scene.triangles.len(), 7);
    let mut area = 0.0;
    for t in &scene.triangles {
        let n = normal_of(t);
        assert!(
            n.normalize().distance(glam::Vec3::Z) < 1e-5,
            "normal {n} of {t:?}"
        );
        area += 0.5 * n.length();
    }
    assert!((area - 3.06066).abs() < 1e-4, "total area {area}");
    for &m in &scene.materials_of_triangles {
        let m = &scene.materials[m as usize];
        assert_eq!(m.base_color, [1.0; 3]);
        assert!(!m.double_sided);
    }
}

/// The triangles a scene declares to the bake as soon as its document is checked (the BVH
/// build's memory is made ready from the count beside the rest of the load): every triangle of
/// its triangle lists, strips and fans, per instance, before degenerate ones are dropped, and
/// none of its points or lines, also for a scene whose buffer is a file of its own
/// (`two_files`).
#[test]
fn declared_triangles_are_what_the_loader_reads() {
    let cases = [
        "strips_fans.gltf",
        "nested_transforms.gltf",
        "two_files/scene.gltf",
        "cornell/cornell.gltf",
        "scenes/room.glb",
        "scenes/sponza_lod4.glb",
    ];
    for case in cases {
        let path = fixture(case);
        let bytes = std::fs::read(&path).expect("read");
        let checked = prt_scene::check(&path, &bytes, &Allowed::default()).expect("check");
        let declared = checked.declared_triangles();
        let scene = prt_scene::read(checked).expect("read");
        let read = scene.triangles.len() as u64 + scene.degenerate_skipped;
        assert_eq!(declared as u64, read, "{case}");
    }
}

/// lights.gltf: the three KHR_lights_punctual lights with their kinds, node positions,
/// directions (node -Z, rotated to -Y), colours, intensities, range and cone angles.
#[test]
fn gltf_lights_are_read() {
    let scene = load(&fixture("lights.gltf")).expect("load");
    assert_eq!(scene.lights.len(), 3, "{:?}", scene.lights);
    let of = |kind| {
        let found: Vec<_> = scene.lights.iter().filter(|l| l.kind == kind).collect();
        assert_eq!(found.len(), 1, "{kind:?}: {:?}", scene.lights);
        found[0].clone()
    };
    let down = [0.0, -1.0, 0.0];

    let point = of(LightKind::Point);
    assert!(approx(point.position, [0.0, 2.0, 0.0], 1e-6), "{point:?}");
    assert!(approx(point.color, [1.0, 0.9, 0.8], 1e-6), "{point:?}");
    assert_eq!(point.intensity, 5.0);
    assert_eq!(point.range, Some(6.0));

    let spot = of(LightKind::Spot);
    assert!(approx(spot.position, [1.0, 2.0, 0.0], 1e-6), "{spot:?}");
    assert!(approx(spot.unit_direction(), down, 1e-5), "{spot:?}");
    assert_eq!(spot.intensity, 10.0);
    assert!((spot.inner_cone_angle - 0.3).abs() < 1e-6, "{spot:?}");
    assert!((spot.outer_cone_angle - 0.6).abs() < 1e-6, "{spot:?}");
    assert_eq!(spot.range, None);

    let sun = of(LightKind::Directional);
    assert!(approx(sun.unit_direction(), down, 1e-5), "{sun:?}");
    assert_eq!(sun.intensity, 2.0);

    // The bake keeps them as the asset's default rig.
    let asset = bake_ok(&fixture("lights.gltf"), &rays(64));
    assert_eq!(asset.lights, scene.lights);
}

/// two_files/scene.gltf resolves its external scene.bin relative to the .gltf, not the working
/// directory: it loads given a relative path from another directory and an absolute path.
///
/// Changing the working directory is process-wide; every other test here uses absolute paths.
#[test]
fn external_buffer_resolves_relative_to_the_gltf() {
    let absolute = fixture("two_files/scene.gltf")
        .canonicalize()
        .expect("fixture");
    let old = std::env::current_dir().expect("cwd");
    std::env::set_current_dir(fixture("")).expect("cd fixtures");
    let relative = load(Path::new("two_files/scene.gltf"));
    let scratch = ScratchDir::new("external_buffer");
    std::env::set_current_dir(scratch.path()).expect("cd scratch");
    let from_elsewhere = load(&absolute);
    std::env::set_current_dir(old).expect("cd back");
    for (what, loaded) in [("relative", relative), ("absolute", from_elsewhere)] {
        let scene = loaded.unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(scene.triangles.len(), 2, "{what}");
    }
}

// ---------------------------------------------------------------------------------------------
// 7. Bad input

/// Each file in fixtures/bad (except degenerate.gltf) fails with an error naming the file and,
/// where it applies, the offending item; never a panic.
#[test]
fn bad_fixtures_fail_with_clear_errors() {
    let files = files_with_ext(&fixture("bad"), ".gltf");
    assert!(files.len() >= 10, "{files:?}");
    for path in files {
        let name = name_of(&path);
        if name == "degenerate.gltf" {
            continue;
        }
        let e = bake_err(&path, &rays(64));
        let msg = e.to_string();
        assert!(
            msg.contains(&name),
            "{name}: message does not name the file: {msg}"
        );
        assert!(
            !msg.contains('\n'),
            "{name}: message is not one line: {msg}"
        );
        let item_ok = match name.as_str() {
            "missing_buffer.gltf" => msg.contains("does_not_exist.bin"),
            "index_out_of_range.gltf" => msg.contains("99"),
            "nan_positions.gltf" => msg.contains("NaN") || msg.contains("non-finite"),
            "accessor_out_of_range.gltf" => msg.contains("accessor"),
            "points_only.gltf" => matches!(e, BakeError::NoTriangles { .. }),
            // Formats the gltf crate's readers would panic on: refused before reading.
            "color_vec2.gltf" => msg.contains("Colors(0)") && msg.contains("Vec2"),
            "texcoord_byte.gltf" => msg.contains("TexCoords(0)") && msg.contains("I8"),
            "broken_json.gltf" | "not_gltf.gltf" => {
                matches!(e, BakeError::Scene(SceneError::Gltf { .. }))
            }
            _ => true,
        };
        assert!(
            item_ok,
            "{name}: error does not name the problem: {e:?} / {msg}"
        );
    }
}

/// degenerate.gltf bakes, keeping the one good triangle and counting the two zero-area ones
/// (one with distinct indices of equal positions, one collinear).
#[test]
fn degenerate_triangles_are_skipped_and_counted() {
    let (asset, report) =
        prt_bake::bake(&fixture("bad/degenerate.gltf"), &rays(64), &NoProgress).expect("bake");
    assert_eq!(asset.header.stats.degenerate_triangles_skipped, 2);
    assert_eq!(asset.header.stats.triangles, 1);
    assert!(
        report.warnings.iter().any(|w| w.contains("degenerate")),
        "{:?}",
        report.warnings
    );
}

/// Bad settings and a missing file are errors that name the offending value.
#[test]
fn bad_settings_are_errors_with_the_value() {
    let missing = fixture("no_such_scene.gltf");
    let e = bake_err(&missing, &rays(64));
    assert!(
        matches!(e, BakeError::Io { .. }) && e.to_string().contains("no_such_scene.gltf"),
        "{e}"
    );

    let cases: [(BakeSettings, &str); 7] = [
        (
            BakeSettings {
                spacing: Some(0.0),
                ..rays(64)
            },
            "spacing = 0",
        ),
        (
            BakeSettings {
                spacing: Some(-1.5),
                ..rays(64)
            },
            "-1.5",
        ),
        (
            BakeSettings {
                bounds: Some([0.25, 0.0, 0.0, -0.75, 1.0, 1.0]),
                ..rays(64)
            },
            "-0.75",
        ),
        (rays(0), "rays = 0"),
        (
            BakeSettings {
                threads: Some(0),
                ..rays(64)
            },
            "threads = 0",
        ),
        (
            BakeSettings {
                far_ratio: -2.0,
                ..rays(64)
            },
            "far_ratio = -2",
        ),
        (
            BakeSettings {
                far_ratio: f32::NAN,
                ..rays(64)
            },
            "far_ratio = NaN",
        ),
    ];
    for (settings, value) in cases {
        let e = bake_err(&cornell(), &settings);
        assert!(matches!(e, BakeError::Setting { .. }), "{value}: {e:?}");
        assert!(
            e.to_string().contains(value),
            "message does not contain {value:?}: {e}"
        );
    }

    let tiny = BakeSettings {
        spacing: Some(0.05),
        max_probes: 100,
        ..rays(64)
    };
    match bake_err(&cornell(), &tiny) {
        e @ BakeError::TooManyProbes { count, max, .. } => {
            let msg = e.to_string();
            assert_eq!(max, 100);
            assert!(
                count > 100 && msg.contains(&count.to_string()) && msg.contains("100"),
                "{msg}"
            );
        }
        e => panic!("expected TooManyProbes, got {e:?}"),
    }
}

/// bake_to_file writes the asset atomically: on success the directory holds just the asset,
/// which reads back equal; when the bake fails, or the final rename fails, it holds no output
/// and no temporary file.
#[test]
fn bake_to_file_is_atomic() {
    let dir = ScratchDir::new("bake_to_file_is_atomic");
    let out = dir.path().join("cornell.prt");
    let (asset, report) =
        prt_bake::bake_to_file(&cornell(), &out, &rays(64), &NoProgress).expect("bake_to_file");
    assert_eq!(dir.entries(), ["cornell.prt"]);
    assert_eq!(std::fs::metadata(&out).unwrap().len(), report.file_bytes);
    assert!(prt_format::read_asset(&out).expect("read back") == asset);
    std::fs::remove_file(&out).unwrap();

    // Failing inputs: nothing written.
    for input in [
        fixture("bad/broken_json.gltf"),
        fixture("no_such_scene.gltf"),
    ] {
        let r = prt_bake::bake_to_file(&input, &out, &rays(64), &NoProgress);
        assert!(r.is_err(), "{}", input.display());
        assert!(
            dir.entries().is_empty(),
            "{}: left {:?}",
            input.display(),
            dir.entries()
        );
    }

    // The output path is a directory: refused before the bake (the rename over it failing
    // after the write is `tests/tests/format.rs`), and nothing is left.
    std::fs::create_dir(&out).unwrap();
    let e = prt_bake::bake_to_file(&cornell(), &out, &rays(64), &NoProgress).unwrap_err();
    assert!(matches!(e, BakeError::Format { .. }), "{e:?}");
    assert_eq!(dir.entries(), ["cornell.prt"], "temporary file left behind");

    // The output directory does not exist.
    let nowhere = dir.path().join("missing_dir/out.prt");
    assert!(prt_bake::bake_to_file(&cornell(), &nowhere, &rays(64), &NoProgress).is_err());
    assert_eq!(dir.entries(), ["cornell.prt"]);
}

/// Virtual offset: a probe just inside the outward box (0.05 m below its top face) moves through
/// the nearest back face, is valid there, and says so; one deep inside stays put and invalid;
/// one just inside a thick wall of double-sided faces moves out into the room.
#[test]
fn virtual_offset_moves_probes_out_of_geometry() {
    let scene = fixture("closed_box_outward.gltf");
    let near_top = BakeSettings {
        spacing: Some(1.0),
        bounds: point_bounds([0.0, 0.95, 0.0]),
        virtual_offset: true,
        ..rays(256)
    };
    let asset = bake_ok(&scene, &near_top);
    let p = asset.probes[0];
    assert!(p.is_valid(), "moved probe is valid: {p:?}");
    assert_ne!(p.flags & prt_format::PROBE_OFFSET, 0);
    // PAST_FACE (0.05) spacings past the face.
    let past = 1.0 + prt_bake::offset::PAST_FACE;
    assert!((p.position[1] - past).abs() < 1e-3, "{p:?}");
    let deep = BakeSettings {
        bounds: point_bounds([0.0, 0.0, 0.0]),
        ..near_top
    };
    let asset = bake_ok(&scene, &deep);
    assert!(!asset.probes[0].is_valid());
    assert_eq!(asset.probes[0].flags & prt_format::PROBE_OFFSET, 0);
    assert_eq!(asset.probes[0].position, [0.0, 0.0, 0.0]);

    // A thick wall of double-sided faces (fixtures/thick_walls.gltf, the north wall spans z
    // -2.3..-2): a probe 1 cm inside it sees only the insides of its faces, and moves out
    // through the one facing the room; without the offset it stays inside (moved off the face
    // by the surface offset, the other way), dilated.
    let walls = fixture("thick_walls.gltf");
    let in_wall = BakeSettings {
        spacing: Some(1.0),
        bounds: point_bounds([0.3, 1.5, -2.01]),
        ..rays(256)
    };
    let asset = bake_ok(&walls, &in_wall);
    let p = asset.probes[0];
    assert!(p.is_valid() && !p.is_dilated(), "{p:?}");
    let past = -2.0 + prt_bake::offset::PAST_FACE;
    assert!((p.position[2] - past).abs() < 1e-3, "{p:?}");
    let kept = BakeSettings {
        virtual_offset: false,
        ..in_wall
    };
    let asset = bake_ok(&walls, &kept);
    let p = asset.probes[0];
    assert!(!p.is_valid() || p.is_dilated(), "{p:?}");
    assert!(p.position[2] < -2.0, "still in the wall: {p:?}");
}

/// Scene diagnostics: inconsistent winding is reported with the share of edges affected and the
/// `--double-sided` hint (not when baking double-sided); a grid mostly inside geometry is
/// reported with its count and the likely reason; a sound scene gets neither.
#[test]
fn scene_diagnostics_warn_about_winding_and_invalid_probes() {
    let box_settings = BakeSettings {
        bounds: Some([-0.9, -0.9, -0.9, 0.9, 0.9, 0.9]),
        spacing: Some(0.6),
        ..rays(64)
    };
    let mixed = fixture("mixed_winding_box.gltf");
    let (_, report) = prt_bake::bake(&mixed, &box_settings, &NoProgress).unwrap();
    assert!(
        report.warnings.iter().any(|w| w.contains("shared edges")
            && w.contains("inconsistent")
            && w.contains("--double-sided")),
        "{:?}",
        report.warnings
    );
    let (_, report) = prt_bake::bake(
        &mixed,
        &BakeSettings {
            double_sided: true,
            ..box_settings
        },
        &NoProgress,
    )
    .unwrap();
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);

    let sponza = fixture("scenes/sponza_lod4.glb");
    let (asset, report) = prt_bake::bake(
        &sponza,
        &BakeSettings {
            spacing: Some(3.0),
            // The inside warning counts the traced probes at the validity stage, before the
            // refine stage drops any.
            prune_error: 0.0,
            ..rays(64)
        },
        &NoProgress,
    )
    .unwrap();
    let inside = asset
        .probes
        .iter()
        .filter(|p| !p.is_valid() || p.is_dilated())
        .count();
    assert!(2 * inside > asset.probes.len());
    assert!(
        report.warnings.iter().any(|w| w
            .contains(&format!("{inside} of {} probes", asset.probes.len()))
            && w.contains("--double-sided")),
        "{:?}",
        report.warnings
    );
    // The exact count, as sorting the corners by position and then the edges found it (the
    // hashed count must not lose or merge edges).
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.contains("(1 of 249798 shared edges inconsistent)")),
        "{:?}",
        report.warnings
    );

    let (_, report) = prt_bake::bake(&cornell(), &rays(64), &NoProgress).unwrap();
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
}
