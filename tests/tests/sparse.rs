//! Sparse placement (`BakeSettings::sparse`, `prt_bake::placement`; issue 32, item 2): probes
//! only at the grid points surfaces need and on coarse levels, the rest recorded without data
//! and filled from a coarse level at runtime (`prt_format::tier`).

// SH maths index parallel arrays with one index; range loops read best.
#![allow(clippy::needless_range_loop)]

use prt_bake::BakeSettings;
use prt_format::depth::MAX_DEPTH;
use prt_format::{
    decode, encode, Asset, DEPTH_TEXELS, DEPTH_WORDS, FILL_HIDDEN_MASK, FILL_HIDDEN_SHIFT,
    FILL_LEVEL_SHIFT, PROBE_FILLED,
};
use prt_runtime::sample::corners;
use prt_runtime::surface::SurfaceSampler;
use prt_runtime::{load_rig, CpuRelighter, LookupSettings};
use prt_tests::{bake_ok, fixture, rays, surface_difference, surfel_points};

/// The two-room fixture (a thin shared wall, a door) at a spacing that leaves air between the
/// rooms' floors and ceilings, 256 rays: uniform and sparse, placement alone (no probe
/// dropped after tracing: `tests/tests/refine.rs`).
fn two_rooms(sparse: bool) -> Asset {
    let settings = BakeSettings {
        spacing: Some(0.25),
        sparse,
        prune_error: 0.0,
        ..rays(256)
    };
    bake_ok(&fixture("two_rooms.gltf"), &settings)
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
        let flags = p.flags
            & !(PROBE_FILLED | 0xf << FILL_LEVEL_SHIFT | FILL_HIDDEN_MASK << FILL_HIDDEN_SHIFT);
        assert_eq!((flags, p.factor_count, p.sky_rays), (0, 0, 0), "{p:?}");
    }
    let filled = asset.probes.iter().filter(|p| p.is_filled()).count();
    assert!(
        filled > 0,
        "the coarse levels fill the air between the rooms"
    );
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
    assert_eq!(summary.filled_probe_count, filled);
}

/// At the surfaces the sparse bake samples as the uniform bake of the same grid does: full
/// validity at every surfel of the uniform bake, and irradiance within a few percent (the two
/// bakes merge different ray hits into their surfels, so they are not equal).
#[test]
fn sparse_and_uniform_bakes_agree_at_surfaces() {
    let (uniform, sparse) = (two_rooms(false), two_rooms(true));
    let points = surfel_points(&uniform);
    let rel = surface_difference(
        (&uniform, &sparse),
        &fixture("rigs/two_rooms.json"),
        (&points, 7),
        |a, b, p| assert!(b.validity >= a.validity - 1e-6, "at {p:?}: {b:?} vs {a:?}"),
    );
    assert!(rel < 0.03, "mean relative difference {rel}");
}

/// Sparse bakes, with the probes the refine stage drops under its threshold and a budget
/// (`prt_bake::refine`), are byte-identical on one thread and two.
#[test]
fn sparse_bakes_are_identical_at_any_thread_count() {
    let bake = |threads: usize| {
        let settings = BakeSettings {
            spacing: Some(0.4),
            sparse: true,
            probe_budget: Some(150),
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
    let s = SurfaceSampler::for_relit(&sparse, &relit, &lookup);
    let points = surfel_points(&sparse);
    assert!(!points.is_empty());
    for (p, n) in points {
        assert!(s.sample(p, n).validity > 0.0, "no probe around {p:?}");
    }
}

/// A level with no surface in the bounds bakes sparse without a panic: no probe placed near a
/// surface, a warning that says so, only the coarsest level traced (the corners of 5 x 5 x 5),
/// the rest filled from it, an asset that validates and samples the sky everywhere.
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
    let with_data = asset.probes.iter().filter(|p| p.has_data()).count();
    assert_eq!(
        with_data, 8,
        "the coarsest level: the first and last index of each axis"
    );
    let placed = prt_bake::Placed {
        grid: 125,
        traced: 8,
        busy_cells: [0; 3],
        filled: [0, 0, 117],
    };
    assert_eq!(report.placed, Some(placed));
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.contains("sparse placement found no surface")),
        "{:?}",
        report.warnings
    );
    prt_format::validate::validate(&asset).unwrap();
    let relit = CpuRelighter::new(&asset)
        .unwrap()
        .relight(&load_rig(&fixture("rigs/sky_only.json")).unwrap(), 1)
        .unwrap();
    let lookup = LookupSettings::default();
    let s = SurfaceSampler::for_relit(&asset, &relit, &lookup);
    // A constant sky of radiance 1 everywhere: E = pi on any surface, through the fills.
    for at in [[0.0; 3], [0.3, -0.6, 0.9], [1.0, 1.0, 1.0]] {
        let got = s.sample(at, [0.0, 1.0, 0.0]);
        assert_eq!(got.validity, 1.0);
        for e in got.irradiance {
            assert!((e - std::f32::consts::PI).abs() < 0.05, "{at:?}: {got:?}");
        }
    }
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
        sparse: false,
        ..rays(256)
    };
    let asset = bake_ok(&fixture("closed_box_outward.gltf"), &settings);
    // Share of a probe's texels whose mean hit distance saturates (sky, or beyond about 3.7
    // spacings: the top value, which reads as MAX_DEPTH).
    let open = |p: usize| {
        let words = asset.visibility_map(p).unwrap();
        let far = (0..DEPTH_TEXELS)
            .filter(|&t| prt_format::depth::moments(words, t).0 == MAX_DEPTH)
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

/// A 2 m box lit by a point light, a spot, a sun and a sky, baked sparse in bounds that reach
/// 3.75 m past it: the fine tier around the box, the coarse levels and their fills beyond.
fn box_in_the_open() -> (Asset, Vec<prt_format::sh::ShRgb>) {
    let settings = BakeSettings {
        bounds: Some([-1.25, -1.25, -1.25, 4.75, 4.75, 4.75]),
        spacing: Some(0.5),
        sparse: true,
        ..rays(256)
    };
    let asset = bake_ok(&fixture("closed_box_outward.gltf"), &settings);
    let lighting = load_rig(&fixture("rigs/point_spot_sun_sky.json")).unwrap();
    let relit = CpuRelighter::new(&asset)
        .unwrap()
        .relight(&lighting, 1)
        .unwrap();
    (asset, relit.sh)
}

/// Where a coarse level alone covers a point, the lookup returns the trilinear interpolation
/// of that level's probes, exactly: the fills between them reproduce it (`prt_format::tier`).
#[test]
fn a_coarse_level_is_interpolated_exactly() {
    let (asset, sh) = box_in_the_open();
    let g = asset.header.grid;
    assert_eq!(g.counts, [13, 13, 13]);
    // Points of the top level (every 8th and the last) at indices 8 and 12, 2.75 m and 4.75 m:
    // no surface in the cell between, filled from level 2 or 3, whose cells there are the same.
    assert!([10, 9, 11]
        .iter()
        .all(|&i| asset.probes[g.index(i, i, 9)].fill_level() >= 2));
    let (lo, hi) = (8u32, 12u32);
    let corners: Vec<usize> = (0..8)
        .map(|c| {
            let at = |bit: u32| if c >> bit & 1 == 1 { hi } else { lo };
            g.index(at(0), at(1), at(2))
        })
        .collect();
    for &c in &corners {
        assert!(asset.probes[c].is_valid() && !asset.probes[c].is_dilated());
    }
    let filled = (0..asset.probes.len())
        .filter(|&p| asset.probes[p].is_filled())
        .count();
    assert!(filled > 1000, "{filled} filled");
    let lookup = LookupSettings {
        depth_moments: false,
        normal_bias: 0.0,
        ..LookupSettings::default()
    };
    let sampler = prt_runtime::VolumeSampler::for_asset(&asset, &sh, &lookup);
    let (a, b) = (g.position(lo, lo, lo), g.position(hi, hi, hi));
    for p in [[3.6, 4.1, 3.3], [2.8, 4.7, 4.0], [4.2, 3.0, 2.9]] {
        let t: [f32; 3] = std::array::from_fn(|i| (p[i] - a[i]) / (b[i] - a[i]));
        let mut expected = [[0.0f32; 3]; 9];
        for (c, &q) in corners.iter().enumerate() {
            let w: f32 = (0..3)
                .map(|i| if c >> i & 1 == 1 { t[i] } else { 1.0 - t[i] })
                .product();
            for k in 0..9 {
                for ch in 0..3 {
                    expected[k][ch] += w * sh[q][k][ch];
                }
            }
        }
        let got = sampler.sample(p, [0.0, 1.0, 0.0]);
        assert!((got.validity - 1.0).abs() < 1e-5, "{got:?}");
        for k in 0..9 {
            for ch in 0..3 {
                let (x, y) = (got.sh[k][ch], expected[k][ch]);
                let scale = expected[0][ch].abs();
                assert!((x - y).abs() <= 1e-5 * scale, "{p:?} k {k}: {x} vs {y}");
            }
        }
    }
}

/// No seam where the fine tier meets the coarse one: along lines from the box's faces out
/// into the air the coarse levels fill, the trilinear lookup is continuous at every grid face it
/// crosses (a jump would be a seam), and the default lookup finds probes everywhere.
#[test]
fn the_lookup_is_seam_free_across_the_tier_boundary() {
    let (asset, sh) = box_in_the_open();
    let g = asset.header.grid;
    let trilinear = LookupSettings {
        depth_moments: false,
        normal_bias: 0.0,
        ..LookupSettings::default()
    };
    let sampler = prt_runtime::VolumeSampler::for_asset(&asset, &sh, &trilinear);
    let default = LookupSettings::default();
    let full = prt_runtime::VolumeSampler::for_asset(&asset, &sh, &default);
    let (mut faces, mut mixed) = (0, 0);
    for (axis, offset) in [(0, [0.1, 0.2]), (1, [0.3, -0.4]), (2, [0.7, 1.3])] {
        let at = |x: f32| -> [f32; 3] {
            let mut p = [0.0; 3];
            p[axis] = x;
            p[(axis + 1) % 3] = offset[0];
            p[(axis + 2) % 3] = offset[1];
            p
        };
        let n = {
            let mut n = [0.0; 3];
            n[axis] = 1.0;
            n
        };
        // Grid faces x = origin + i * step from just outside the box to the far bound.
        for i in 5..12 {
            let x = g.origin[axis] + g.step[axis] * i as f32;
            let (below, above) = (
                sampler.sample(at(x - 1e-4), n),
                sampler.sample(at(x + 1e-4), n),
            );
            // Validity is continuous too (the corners inside the box weigh 0 on both sides).
            let (u, v) = (below.validity, above.validity);
            assert!(
                u > 0.99 && (u - v).abs() < 1e-3,
                "face {i}: validity {u} vs {v}"
            );
            for k in 0..9 {
                for ch in 0..3 {
                    let (u, v) = (below.sh[k][ch], above.sh[k][ch]);
                    let scale = below.sh[0][ch].abs().max(1e-6);
                    assert!(
                        (u - v).abs() <= 2e-3 * scale,
                        "axis {axis} face {i} k {k}: {u} vs {v}"
                    );
                }
            }
            faces += 1;
        }
        // Every point of the line has probes around it with the default lookup too, and the
        // line passes cells whose corners are partly traced and partly filled.
        for s in 0..200 {
            let x = 1.05 + 3.6 * s as f32 / 199.0;
            let p = at(x);
            assert!(full.sample(p, n).validity > 0.5, "{p:?}");
            let cs = corners(&g, p.into());
            let fill = cs
                .iter()
                .filter(|&&(c, w)| w > 0.0 && asset.probes[c].is_filled())
                .count();
            let traced = cs
                .iter()
                .filter(|&&(c, w)| w > 0.0 && asset.probes[c].has_data())
                .count();
            mixed += usize::from(fill > 0 && traced > 0 && fill + traced == 8);
        }
    }
    assert_eq!(faces, 21);
    assert!(mixed > 0, "no cell mixes the tiers");
}

/// Validation refuses fills the runtime could not compute: a point filled although it has
/// data, from a level that does not exist, where no point of its level around it is valid, or
/// from a filled point.
#[test]
fn broken_fills_are_invalid() {
    let settings = BakeSettings {
        bounds: Some([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0]),
        spacing: Some(0.5),
        sparse: true,
        ..rays(64)
    };
    let asset = bake_ok(&fixture("empty.gltf"), &settings);
    let g = asset.header.grid;
    let message = |damage: &dyn Fn(&mut Asset)| prt_tests::refused(&asset, damage);
    let corner = g.index(4, 4, 4);
    let e = message(&|a| a.probes[corner].flags |= PROBE_FILLED);
    assert!(e.contains("filled, yet with data"), "{e}");
    let first_filled = asset.probes.iter().position(|p| p.is_filled()).unwrap();
    let e = message(&|a| a.probes[first_filled].flags = PROBE_FILLED | 5 << FILL_LEVEL_SHIFT);
    assert!(e.contains("filled from level 5"), "{e}");
    let e = message(&|a| {
        for p in a.probes.iter_mut().filter(|p| p.has_data()) {
            p.flags = 0;
        }
    });
    assert!(
        e.contains("none of the level's probes around it (0, 4) is valid"),
        "{e}"
    );
    // The last coarse point (the last probe with data; no factors in an empty scene) left out
    // and marked filled: it would be filled from itself, and its neighbours from it.
    let e = message(&|a| {
        let last = &mut a.probes[corner];
        *last = prt_format::Probe {
            position: last.position,
            flags: PROBE_FILLED | 3 << FILL_LEVEL_SHIFT,
            first_factor: last.first_factor,
            slot: prt_format::NO_SLOT,
            ..prt_format::Probe::default()
        };
        let slots = a.sky_transfer.len() - 1;
        a.sky_mask = prt_format::sky_mask::with_index((0..slots).map(|s| a.sky_record(s).to_vec()));
        a.sky_transfer.pop();
        a.probe_depth.truncate(a.probe_depth.len() - DEPTH_WORDS);
    });
    assert!(e.contains("which is filled itself"), "{e}");
}

/// A grid shift (`BakeSettings::grid_shift`) bakes the same steps with the layers moved down
/// by its share of a step and one more layer past the bounds, into a valid asset; a share
/// outside [0, 1) or NaN is refused, naming the setting.
#[test]
fn a_shifted_grid_keeps_its_steps() {
    let plain = BakeSettings {
        spacing: Some(0.5),
        ..rays(64)
    };
    let shifted = BakeSettings {
        grid_shift: [0.5, 0.0, 0.25],
        ..plain.clone()
    };
    let (a, b) = (
        bake_ok(&fixture("two_rooms.gltf"), &plain).header.grid,
        bake_ok(&fixture("two_rooms.gltf"), &shifted).header.grid,
    );
    assert_eq!(a.step, b.step);
    assert_eq!(b.counts, [a.counts[0] + 1, a.counts[1], a.counts[2] + 1]);
    for (axis, share) in [(0, 0.5), (1, 0.0), (2, 0.25)] {
        let moved = a.origin[axis] - b.origin[axis];
        assert!(
            (moved - share * a.step[axis]).abs() < 1e-5,
            "{axis}: {moved}"
        );
    }
    for bad in [1.0, -0.1, f32::NAN] {
        let settings = BakeSettings {
            grid_shift: [0.0, bad, 0.0],
            ..plain.clone()
        };
        let e = prt_tests::bake_err(&fixture("two_rooms.gltf"), &settings).to_string();
        assert!(e.contains("grid_shift"), "{e}");
    }
}
