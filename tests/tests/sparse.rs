//! Sparse placement (`BakeSettings::sparse`, `prt_bake::placement`; issue 32, item 2): probes
//! only at the grid points surfaces need, the rest recorded without data.

use prt_bake::BakeSettings;
use prt_format::depth::MAX_DEPTH;
use prt_format::{decode, encode, Asset, DEPTH_TEXELS, DEPTH_WORDS};
use prt_runtime::sample::corners;
use prt_runtime::surface::SurfaceSampler;
use prt_runtime::{load_rig, CpuRelighter, LookupSettings};
use prt_tests::{bake_ok, fixture, rays};

/// The two-room fixture (a thin shared wall, a door) at a spacing that leaves air between the
/// rooms' floors and ceilings, 256 rays: uniform and sparse.
fn two_rooms(sparse: bool) -> Asset {
    let settings = BakeSettings {
        spacing: Some(0.25),
        sparse,
        ..rays(256)
    };
    bake_ok(&fixture("two_rooms.gltf"), &settings)
}

/// Front-face surfels: where the lookup reads the probes at surfaces.
fn surfel_points(asset: &Asset) -> Vec<([f32; 3], [f32; 3])> {
    asset
        .surfels
        .iter()
        .filter(|s| s.flags & prt_format::BRICK_BACKFACE == 0)
        .map(|s| (s.position, s.normal))
        .collect()
}

/// A sparse bake places fewer probes than its grid has, keeps every probe the lookup reads at
/// a surfel (at the surfel and moved by the default normal bias), leaves the others without
/// data, validates and round-trips, and says so in its summary.
#[test]
fn sparse_placement_keeps_every_probe_surfaces_read() {
    let asset = two_rooms(true);
    let g = asset.header.grid;
    let placed = asset.probes.iter().filter(|p| p.has_data()).count();
    assert!(
        placed < asset.probes.len() * 9 / 10,
        "{placed} of {} placed",
        asset.probes.len()
    );
    let bias = LookupSettings::default().normal_bias * g.spacing;
    let mut read = 0;
    for (p, n) in surfel_points(&asset) {
        let moved = std::array::from_fn(|a| p[a] + n[a] * bias);
        for at in [p, moved] {
            for (i, w) in corners(&g, at.into()) {
                if w > 0.0 {
                    read += 1;
                    assert!(asset.probes[i].has_data(), "probe {i} read at {at:?}");
                }
            }
        }
    }
    assert!(read > 1000);
    for p in asset.probes.iter().filter(|p| !p.has_data()) {
        assert_eq!((p.flags, p.factor_count, p.sky_rays), (0, 0, 0), "{p:?}");
    }
    assert_eq!(
        asset.probe_depth.len(),
        placed * DEPTH_WORDS,
        "one visibility map per placed probe"
    );
    assert_eq!(decode(&encode(&asset).unwrap()).unwrap(), asset);
    let summary = prt_format::Summary::of(&asset, 0);
    assert_eq!(summary.probes_with_data, placed);
    assert!(summary
        .to_string()
        .contains(&format!("{placed} with data of")));
}

/// At the surfaces the sparse bake samples as the uniform bake of the same grid does: full
/// validity at every surfel of the uniform bake, and irradiance within a few percent (the two
/// bakes merge different ray hits into their surfels, so they are not equal).
#[test]
fn sparse_and_uniform_bakes_agree_at_surfaces() {
    let (uniform, sparse) = (two_rooms(false), two_rooms(true));
    let lighting = load_rig(&fixture("rigs/two_rooms.json")).unwrap();
    let lookup = LookupSettings::default();
    let relit = |a: &Asset| CpuRelighter::new(a).unwrap().relight(&lighting, 1).unwrap();
    let (ru, rs) = (relit(&uniform), relit(&sparse));
    let su = SurfaceSampler::new(&uniform, &ru.sh, &ru.surfel_irradiance, &lookup);
    let ss = SurfaceSampler::new(&sparse, &rs.sh, &rs.surfel_irradiance, &lookup);
    let points = surfel_points(&uniform);
    let (mut diff, mut total) = (0.0f64, 0.0f64);
    for &(p, n) in points.iter().step_by(7) {
        let (a, b) = (su.sample(p, n), ss.sample(p, n));
        assert!(b.validity >= a.validity - 1e-6, "at {p:?}: {b:?} vs {a:?}");
        for c in 0..3 {
            diff += f64::from((a.irradiance[c] - b.irradiance[c]).abs());
            total += f64::from(a.irradiance[c].abs());
        }
    }
    let rel = diff / total;
    assert!(rel < 0.03, "mean relative difference {rel}");
}

/// Sparse bakes are byte-identical on one thread and two.
#[test]
fn sparse_bakes_are_identical_at_any_thread_count() {
    let bake = |threads: usize| {
        let settings = BakeSettings {
            spacing: Some(0.4),
            sparse: true,
            threads: Some(threads),
            ..rays(128)
        };
        encode(&bake_ok(&fixture("two_rooms.gltf"), &settings)).unwrap()
    };
    assert!(bake(1) == bake(2));
}

/// A sparse bake fills holes (cells with no valid corner) only where a surface passes: inside
/// a closed 2 m box, whose 4x4x4 inner probes the uniform bake dilates (no surface there
/// needs them), it dilates none, and every surfel of the box's faces still samples with
/// probes around it.
#[test]
fn sparse_bakes_fill_only_the_holes_surfaces_need() {
    let bake = |sparse: bool| {
        let settings = BakeSettings {
            bounds: Some([-1.25, -1.25, -1.25, 1.25, 1.25, 1.25]),
            spacing: Some(0.5),
            sparse,
            ..rays(256)
        };
        bake_ok(&fixture("closed_box_outward.gltf"), &settings)
    };
    let (uniform, sparse) = (bake(false), bake(true));
    let dilated = |a: &Asset| a.probes.iter().filter(|p| p.is_dilated()).count();
    assert_eq!((dilated(&uniform), dilated(&sparse)), (64, 0));
    let lighting = load_rig(&fixture("rigs/sky_only.json")).unwrap();
    let relit = CpuRelighter::new(&sparse)
        .unwrap()
        .relight(&lighting, 1)
        .unwrap();
    let lookup = LookupSettings::default();
    let s = SurfaceSampler::new(&sparse, &relit.sh, &relit.surfel_irradiance, &lookup);
    let points = surfel_points(&sparse);
    assert!(!points.is_empty());
    for (p, n) in points {
        assert!(s.sample(p, n).validity > 0.0, "no probe around {p:?}");
    }
}

/// A level with no surface in the bounds bakes sparse without a panic: no probe placed, a
/// warning that says so, an asset that validates and samples to validity 0.
#[test]
fn sparse_bake_of_nothing_warns() {
    let settings = BakeSettings {
        bounds: Some([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0]),
        spacing: Some(0.5),
        sparse: true,
        ..rays(64)
    };
    let (asset, report) =
        prt_bake::bake(&fixture("empty.gltf"), &settings, &prt_bake::NoProgress).unwrap();
    assert!(asset.probes.iter().all(|p| !p.has_data()));
    assert_eq!(report.placed, Some((0, asset.probes.len())));
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.contains("--sparse placed no probe")),
        "{:?}",
        report.warnings
    );
    prt_format::validate::validate(&asset).unwrap();
    let relit = CpuRelighter::new(&asset)
        .unwrap()
        .relight(&load_rig(&fixture("rigs/sky_only.json")).unwrap(), 1)
        .unwrap();
    let lookup = LookupSettings::default();
    let s = SurfaceSampler::new(&asset, &relit.sh, &relit.surfel_irradiance, &lookup);
    let got = s.sample([0.0; 3], [0.0, 1.0, 0.0]);
    assert_eq!(got.validity, 0.0);
    assert!(got.irradiance.iter().all(|v| *v == 0.0));
}

/// A dilated probe carries its source's factors and sky but keeps its own visibility map in
/// its slot: inside a closed 2 m box (uniform bake, 4x4x4 dilated probes) the maps in the
/// dilated probes' slots see the box's walls within the maps' range nearly everywhere, while
/// the measured probes outside it, their sources, see the sky over much of theirs.
#[test]
fn dilated_probes_keep_their_own_visibility_maps() {
    let settings = BakeSettings {
        bounds: Some([-1.25, -1.25, -1.25, 1.25, 1.25, 1.25]),
        spacing: Some(0.5),
        ..rays(256)
    };
    let asset = bake_ok(&fixture("closed_box_outward.gltf"), &settings);
    // Share of a probe's texels whose mean hit distance saturates (sky, or beyond the range).
    let open = |p: usize| {
        let words = asset.visibility_map(p).unwrap();
        let far = (0..DEPTH_TEXELS)
            .filter(|&t| prt_format::depth::moments(words, t).0 >= 0.99 * MAX_DEPTH)
            .count();
        far as f32 / DEPTH_TEXELS as f32
    };
    let dilated: Vec<usize> = (0..asset.probes.len())
        .filter(|&p| asset.probes[p].is_dilated())
        .collect();
    assert_eq!(dilated.len(), 64);
    for p in dilated {
        assert!(open(p) < 0.3, "dilated probe {p}: {} open", open(p));
    }
    // The measured probes, their sources, are all outside the box.
    for (q, probe) in asset.probes.iter().enumerate() {
        if probe.is_valid() && !probe.is_dilated() {
            assert!(open(q) > 0.3, "measured probe {q}: {} open", open(q));
        }
    }
}
