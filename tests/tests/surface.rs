//! Irradiance where a renderer samples it, at surfaces: no light through walls (visibility-aware
//! lookup), no holes (dilation of probes inside geometry), probes inside double-sided solids
//! detected and probes on surfaces moved off them. Fixtures: `fixtures/two_rooms.gltf` (a lit
//! and a dark room sharing a zero-thickness wall with a door) and `fixtures/thick_walls.gltf`
//! (0.3 m double-sided walls).

use glam::Vec3;
use prt_bake::BakeSettings;
use prt_format::sh::ShRgb;
use prt_format::Asset;
use prt_runtime::gpu::RuntimeSettings;
use prt_runtime::{load_rig, CpuRelighter, VolumeSampler};
use prt_tests::{bake_ok, fixture};

fn relit(asset: &Asset, rig: &str) -> Vec<ShRgb> {
    let lighting = load_rig(&fixture(rig)).unwrap();
    CpuRelighter::new(asset)
        .unwrap()
        .relight(&lighting, 1)
        .unwrap()
        .sh
}

fn mean(v: [f32; 3]) -> f32 {
    (v[0] + v[1] + v[2]) / 3.0
}

/// Points on the shared wall away from the door (z < 0; the door is at z 0.8..1.8), as
/// (position, normal) on the side `side` (+1: the dark room, -1: the lit one).
fn wall_points(side: f32) -> Vec<([f32; 3], [f32; 3])> {
    let mut out = Vec::new();
    for i in 0..6 {
        for j in 0..6 {
            let y = 0.3 + 2.4 * i as f32 / 5.0;
            let z = -1.8 + 1.6 * j as f32 / 5.0;
            out.push(([0.0, y, z], [side, 0.0, 0.0]));
        }
    }
    out
}

/// The dark side of the wall between a lit room and a dark one gets no light from the lit room:
/// with the runtime's lookup its mean irradiance is below 1% of the lit side's (the oracle puts
/// it at 0.3%: one bounce through the door), while plain trilinear interpolation, which mixes
/// in the lit room's probes half a spacing away, gives it about a third of it.
#[test]
fn no_light_leaks_through_a_shared_wall() {
    let asset = bake_ok(&fixture("two_rooms.gltf"), &BakeSettings::default());
    let sh = relit(&asset, "rigs/two_rooms.json");
    let settings = RuntimeSettings::default();
    let visible = VolumeSampler::for_asset(&asset, &sh, &settings);
    let plain = VolumeSampler::for_asset(
        &asset,
        &sh,
        &RuntimeSettings {
            visibility: false,
            ..settings
        },
    );
    let average = |s: &VolumeSampler, side: f32| {
        let pts = wall_points(side);
        pts.iter()
            .map(|(p, n)| mean(s.sample(*p, *n).irradiance))
            .sum::<f32>()
            / pts.len() as f32
    };
    let lit = average(&visible, -1.0);
    let dark = average(&visible, 1.0);
    let leaky = average(&plain, 1.0);
    assert!(lit > 0.1, "lit side {lit}");
    assert!(dark < 0.01 * lit, "dark side {dark} vs lit side {lit}");
    assert!(
        leaky > 0.1 * lit,
        "trilinear should leak: {leaky} vs lit {lit}"
    );
}

/// Where all eight probes around a surface point are inside the thick walls, the point still
/// gets light: dilation gives those probes their neighbours' data. Without it the same points
/// are holes (validity 0, black).
#[test]
fn holes_are_filled_by_dilation() {
    let scene = fixture("thick_walls.gltf");
    let reference: serde_json::Value = serde_json::from_slice(
        &std::fs::read(fixture("surface/thick_walls_surface.json")).unwrap(),
    )
    .unwrap();
    let points: Vec<([f32; 3], [f32; 3])> = reference["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let v =
                |k: &str| -> [f32; 3] { std::array::from_fn(|a| p[k][a].as_f64().unwrap() as f32) };
            (v("position"), v("normal"))
        })
        .collect();
    let settings = RuntimeSettings {
        visibility: false,
        normal_bias: 0.0,
        ..RuntimeSettings::default()
    };
    // A coarse grid, so that whole cells of probes fall inside the walls.
    let base = BakeSettings {
        spacing: Some(0.6),
        ..BakeSettings::default()
    };
    let undilated = bake_ok(
        &scene,
        &BakeSettings {
            dilate: false,
            ..base.clone()
        },
    );
    let sh = relit(&undilated, "rigs/thick_walls.json");
    let s = VolumeSampler::for_asset(&undilated, &sh, &settings);
    let holes: Vec<usize> = (0..points.len())
        .filter(|&i| s.sample(points[i].0, points[i].1).validity == 0.0)
        .collect();
    assert!(!holes.is_empty(), "the coarse grid leaves no hole to fill");

    let dilated = bake_ok(&scene, &base);
    assert!(dilated.probes.iter().any(|p| p.is_dilated()));
    let sh = relit(&dilated, "rigs/thick_walls.json");
    let s = VolumeSampler::for_asset(&dilated, &sh, &settings);
    for &i in &holes {
        let got = s.sample(points[i].0, points[i].1);
        assert!(
            got.validity > 0.0 && mean(got.irradiance) > 0.0,
            "point {i} {:?}: {got:?}",
            points[i]
        );
    }
}

/// A probe inside a closed solid with double-sided materials sees only the inside of its faces
/// (the back of their outward winding): it is detected as inside geometry and dilated, while
/// the probes in the room are not.
#[test]
fn probes_inside_double_sided_walls_are_detected() {
    let asset = bake_ok(&fixture("thick_walls.gltf"), &BakeSettings::default());
    let inside = asset.probes.iter().filter(|p| p.is_dilated()).count();
    assert!(inside > 0, "no probe detected inside the 0.3 m walls");
    let g = asset.header.grid;
    // The room's centre is open space.
    let centre =
        Vec3::from(g.origin) + Vec3::from(g.counts.map(|c| c as f32 - 1.0)) * g.spacing * 0.5;
    let rel = (centre - Vec3::from(g.origin)) / g.spacing;
    let c = g.index(
        rel.x.round() as u32,
        rel.y.round() as u32,
        rel.z.round() as u32,
    );
    assert!(asset.probes[c].is_valid() && !asset.probes[c].is_dilated());
}

/// A grid that coincides with the shared wall (spacing 0.23 puts a probe plane exactly at x = 0):
/// those probes move a tenth of a spacing off the wall (flagged PROBE_OFFSET), and none is left
/// on it. Switched off, they stay on the wall.
#[test]
fn probes_on_a_wall_move_off_it() {
    let scene = fixture("two_rooms.gltf");
    let settings = BakeSettings {
        spacing: Some(0.23),
        ..BakeSettings::default()
    };
    let asset = bake_ok(&scene, &settings);
    let g = asset.header.grid;
    let on_wall = |x: f32| x.abs() < 0.02 * g.spacing;
    let grid_on_wall = (0..g.counts[0])
        .filter(|&i| on_wall(g.origin[0] + i as f32 * g.spacing))
        .count();
    assert_eq!(grid_on_wall, 1, "the grid has a probe plane on the wall");
    // The doorway (y < 2, z 0.8..1.8) is open space: probes there stay.
    let in_door = |p: &[f32; 3]| p[1] < 2.0 && (0.8..=1.8).contains(&p[2]);
    for p in &asset.probes {
        assert!(
            !on_wall(p.position[0]) || in_door(&p.position),
            "probe left on the wall at {:?}",
            p.position
        );
    }
    let moved = asset
        .probes
        .iter()
        .filter(|p| p.flags & prt_format::PROBE_OFFSET != 0)
        .count();
    assert!(
        moved >= (g.counts[1] * g.counts[2]) as usize / 2,
        "{moved} probes moved"
    );
    let fixed = bake_ok(
        &scene,
        &BakeSettings {
            surface_offset: false,
            ..settings
        },
    );
    assert!(fixed.probes.iter().any(|p| on_wall(p.position[0])));
}

/// A probe's visibility map holds the distance to what it sees, in spacings: at the centre of
/// the closed 2 m box, the walls are 1 m away along the axes.
#[test]
fn visibility_maps_hold_distances_in_spacings() {
    let asset = bake_ok(
        &fixture("closed_box_inward.gltf"),
        &BakeSettings {
            bounds: Some([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0]),
            spacing: Some(2.0 / 3.0),
            ..BakeSettings::default()
        },
    );
    let g = asset.header.grid;
    let p = g.index(1, 1, 1);
    assert_eq!(g.position(1, 1, 1), [0.0; 3]);
    let words = &asset.probe_depth[p * prt_format::DEPTH_WORDS..(p + 1) * prt_format::DEPTH_WORDS];
    for d in [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]] {
        let (m, dev) = prt_format::depth::moments(words, prt_format::depth::texel_of(d));
        let want = 1.0 / g.spacing;
        assert!((m - want).abs() < 0.05 * want, "{d:?}: mean {m} vs {want}");
        assert!(dev < 0.1 * want, "{d:?}: deviation {dev}");
    }
}
