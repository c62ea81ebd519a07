//! Irradiance where a renderer samples it, at surfaces: no light through walls (depth-moment weighted
//! lookup), no holes (dilation of probes inside geometry), probes inside double-sided solids
//! detected and probes on surfaces moved off them. Fixtures: `fixtures/two_rooms.gltf` (a lit
//! and a dark room sharing a zero-thickness wall with a door) and `fixtures/thick_walls.gltf`
//! (0.3 m double-sided walls).

use glam::Vec3;
use prt_bake::BakeSettings;
use prt_format::sh::ShRgb;
use prt_format::Asset;
use prt_runtime::{load_rig, CpuRelighter, LookupSettings, VolumeSampler};
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
/// it at 0.3%: one bounce through the door). Two grids: the default one (a probe layer on the
/// wall, moved off it into one room) and the hard case, the wall halfway between two layers
/// (bounds widened by a quarter metre each way at 0.5 m), where plain trilinear interpolation
/// mixes in the lit room's probes a quarter metre away and gives the dark side about a third of
/// the lit side's light.
#[test]
fn no_light_leaks_through_a_shared_wall() {
    let midway = BakeSettings {
        spacing: Some(0.5),
        bounds: Some([-4.25, 0.0, -2.0, 4.25, 3.0, 2.0]),
        ..BakeSettings::default()
    };
    for (name, bake) in [("default", BakeSettings::default()), ("midway", midway)] {
        let asset = bake_ok(&fixture("two_rooms.gltf"), &bake);
        let sh = relit(&asset, "rigs/two_rooms.json");
        let settings = LookupSettings::default();
        let visible = VolumeSampler::for_asset(&asset, &sh, &settings);
        let plain = VolumeSampler::for_asset(
            &asset,
            &sh,
            &LookupSettings {
                depth_moments: false,
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
        assert!(lit > 0.1, "{name}: lit side {lit}");
        assert!(
            dark < 0.01 * lit,
            "{name}: dark side {dark} vs lit side {lit}"
        );
        if name == "midway" {
            let leaky = average(&plain, 1.0);
            assert!(
                leaky > 0.1 * lit,
                "trilinear should leak: {leaky} vs lit {lit}"
            );
        }
    }
}

/// Where all eight probes around a point are inside geometry, the point still gets light:
/// dilation gives those probes their nearest valid neighbours' data. Without it the point is a
/// hole (validity 0, black). The closed, outward-facing 2 m box with probes every 0.5 m: the
/// 4x4x4 probes inside it see only back faces, the outer layer sees the lit outside.
#[test]
fn holes_are_filled_by_dilation() {
    let scene = fixture("closed_box_outward.gltf");
    let base = BakeSettings {
        bounds: Some([-1.25, -1.25, -1.25, 1.25, 1.25, 1.25]),
        spacing: Some(0.5),
        // Every grid point traced: sparse placement leaves the box's inside untraced.
        sparse: false,
        ..BakeSettings::default()
    };
    let settings = LookupSettings {
        normal_bias: 0.0,
        ..LookupSettings::default()
    };
    let inside = [
        ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.4, -0.3, 0.1], [1.0, 0.0, 0.0]),
    ];
    let undilated = bake_ok(
        &scene,
        &BakeSettings {
            dilate: false,
            ..base.clone()
        },
    );
    let sh = relit(&undilated, "rigs/sky_only.json");
    let s = VolumeSampler::for_asset(&undilated, &sh, &settings);
    for (p, n) in inside {
        assert_eq!(
            s.sample(p, n).validity,
            0.0,
            "{p:?} is no hole without dilation"
        );
    }
    let dilated = bake_ok(&scene, &base);
    assert_eq!(dilated.probes.iter().filter(|p| p.is_dilated()).count(), 64);
    dilated_probes_read_their_sources_tables(&dilated);
    // Refine under a budget keeps every source and points the dilated probes at its new run.
    let with_data = |a: &Asset| a.probes.iter().filter(|p| p.has_data()).count();
    let budget = BakeSettings {
        probe_budget: Some(100),
        ..base.clone()
    };
    let refined = bake_ok(&scene, &budget);
    assert!(
        with_data(&refined) < with_data(&dilated),
        "refine dropped nothing"
    );
    dilated_probes_read_their_sources_tables(&refined);
    let sh = relit(&dilated, "rigs/sky_only.json");
    let s = VolumeSampler::for_asset(&dilated, &sh, &settings);
    for (p, n) in inside {
        let got = s.sample(p, n);
        assert!(
            got.validity > 0.0 && mean(got.irradiance) > 0.0,
            "{p:?}: {got:?}"
        );
    }
}

/// Format 12: a dilated probe has no table of its own. Its run is that of a probe with data that
/// is not dilated (its source), the factors are the sources' tables and nothing more, and the
/// sources' u8 factors are all full (a lobe decodes from the reading probe's position). A
/// dilated probe's run that is no source's, or a lobe in a source's table, is refused.
fn dilated_probes_read_their_sources_tables(asset: &Asset) {
    let own = |p: &&prt_format::Probe| p.has_data() && !p.is_dilated();
    let tables: std::collections::HashSet<(u32, u32)> = (asset.probes.iter().filter(own))
        .map(|p| (p.first_factor, p.factor_count))
        .collect();
    let own_slots: u32 = asset
        .probes
        .iter()
        .filter(own)
        .map(|p| p.factor_count)
        .sum();
    assert_eq!(own_slots as usize, asset.factors.len(), "no copies");
    let dilated: Vec<usize> = (0..asset.probes.len())
        .filter(|&p| asset.probes[p].is_dilated() && asset.probes[p].factor_count > 0)
        .collect();
    assert!(!dilated.is_empty());
    let prt_format::Factors::U8 { factors, .. } = &asset.factors else {
        panic!("u8 factors by default");
    };
    for &p in &dilated {
        let probe = &asset.probes[p];
        assert!(tables.contains(&(probe.first_factor, probe.factor_count)));
        let run = probe.first_factor as usize..(probe.first_factor + probe.factor_count) as usize;
        assert!(factors[run].iter().all(|s| s.rays() == 0 || s.is_full()));
    }
    let mut moved = asset.clone();
    moved.probes[dilated[0]].first_factor += 2;
    let err = prt_format::validate::validate(&moved)
        .unwrap_err()
        .to_string();
    assert!(err.contains("no other probe's table"), "{err}");
    let mut lobe = asset.clone();
    let probe = lobe.probes[dilated[0]];
    if let prt_format::Factors::U8 { factors, .. } = &mut lobe.factors {
        let head = &mut factors[probe.first_factor as usize];
        head.bits &= !prt_format::SLOT_FULL;
    }
    let err = prt_format::validate::validate(&lobe)
        .unwrap_err()
        .to_string();
    assert!(err.contains("lobe factor"), "{err}");
}

/// A probe inside a closed solid with double-sided materials sees only the inside of its faces
/// (the back of their outward winding): it is detected as inside geometry and dilated, while
/// the probes in the room are not. (Without the virtual offset, which by default moves such
/// probes out through the nearest face: `tests/tests/bake.rs`.)
#[test]
fn probes_inside_double_sided_walls_are_detected() {
    let settings = BakeSettings {
        virtual_offset: false,
        // The room's centre traced, not filled.
        sparse: false,
        ..BakeSettings::default()
    };
    let asset = bake_ok(&fixture("thick_walls.gltf"), &settings);
    let inside = asset.probes.iter().filter(|p| p.is_dilated()).count();
    assert!(inside > 0, "no probe detected inside the 0.3 m walls");
    let g = asset.header.grid;
    // The room's centre is open space.
    let centre = Vec3::from(g.origin)
        + Vec3::from(g.counts.map(|c| c as f32 - 1.0)) * Vec3::from(g.step) * 0.5;
    let rel = (centre - Vec3::from(g.origin)) / Vec3::from(g.step);
    let c = g.index(
        rel.x.round() as u32,
        rel.y.round() as u32,
        rel.z.round() as u32,
    );
    assert!(asset.probes[c].is_valid() && !asset.probes[c].is_dilated());
}

/// A grid that coincides with the shared wall (spacing 0.25 puts a probe plane exactly at x = 0):
/// those probes move 5% of a spacing off the wall (flagged PROBE_OFFSET), and none is left
/// on it. Switched off, they stay on the wall.
#[test]
fn probes_on_a_wall_move_off_it() {
    let scene = fixture("two_rooms.gltf");
    let settings = BakeSettings {
        spacing: Some(0.25),
        ..BakeSettings::default()
    };
    let asset = bake_ok(&scene, &settings);
    let g = asset.header.grid;
    let on_wall = |x: f32| x.abs() < 0.02 * g.spacing;
    let grid_on_wall = (0..g.counts[0])
        .filter(|&i| on_wall(g.origin[0] + i as f32 * g.step[0]))
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

/// A probe's depth moments hold the distance to what it sees, in spacings: at the centre of
/// the closed 2 m box, the walls are 1 m away along the axes.
#[test]
fn depth_moments_hold_distances_in_spacings() {
    let asset = bake_ok(
        &fixture("closed_box_inward.gltf"),
        &BakeSettings {
            bounds: Some([
                -2.0 / 3.0,
                -2.0 / 3.0,
                -2.0 / 3.0,
                2.0 / 3.0,
                2.0 / 3.0,
                2.0 / 3.0,
            ]),
            spacing: Some(2.0 / 3.0),
            // The centre, 1.5 spacings from every wall, traced (sparse placement fills it).
            sparse: false,
            ..BakeSettings::default()
        },
    );
    let g = asset.header.grid;
    assert_eq!(g.position(1, 1, 1), [0.0; 3]);
    let words = asset.visibility_map(g.index(1, 1, 1)).unwrap();
    for d in [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]] {
        let (m, dev) = prt_format::depth::moments(words, prt_format::depth::texel_of(d));
        let want = 1.0 / g.spacing;
        // Within half a step of the moments' square-root scale (`prt_format::depth`).
        let scale = |v: f32| (v / prt_format::depth::MAX_DEPTH).sqrt() * 15.0;
        assert!(
            (scale(m) - scale(want)).abs() <= 0.5,
            "{d:?}: mean {m} vs {want}"
        );
        assert!(dev < 0.1 * want, "{d:?}: deviation {dev}");
    }
}

/// Probes on the walls of a closed room (a grid whose outer planes coincide with the walls of
/// the inward-facing 2 m box) move into the room, never out of it, whichever wall they are on.
#[test]
fn probes_on_room_walls_move_into_the_room() {
    let asset = bake_ok(
        &fixture("closed_box_inward.gltf"),
        &BakeSettings {
            bounds: Some([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0]),
            spacing: Some(0.5),
            ..BakeSettings::default()
        },
    );
    let g = asset.header.grid;
    assert_eq!(
        g.position(0, 0, 0),
        [-1.0; 3],
        "the grid's outer planes are the walls"
    );
    let moved = asset
        .probes
        .iter()
        .filter(|p| p.flags & prt_format::PROBE_OFFSET != 0)
        .count();
    assert_eq!(moved, 125 - 27, "every probe on a wall or corner moves");
    for p in &asset.probes {
        assert!(
            p.position.iter().all(|c| c.abs() < 1.0 - 0.04 * g.spacing),
            "probe at {:?} is not inside the room",
            p.position
        );
        assert!(p.is_valid() && !p.is_dilated(), "{:?}", p.position);
    }
}
