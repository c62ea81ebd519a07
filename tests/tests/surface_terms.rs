//! The bake's surface terms and the surface lookup (`prt_format::surface`,
//! `prt_runtime::surface`): every front-face surfel is found again by its own position and
//! normal, the lookup keeps the dark room of `fixtures/two_rooms.gltf` dark at both grid
//! phases (the shared wall and the floor that runs under it) and keeps each side of the wall
//! through its surfel cells in its own room's light (format 18), keeps a sunlit atrium's galleries
//! dark, no line where two of its surfaces meet is over-lit, a pocket stays dark, a surface
//! under a sky gets its own share of it rather than its probes', the lookup's explanation adds
//! up to its sample, a bake without terms (unmerged, or told to skip them) samples as the volume lookup, and damaged
//! terms are refused by name.

use prt_bake::BakeSettings;
use prt_format::sh::irradiance_l1_nonlinear;
use prt_format::surface::{dominant_axis, SurfaceSide, SIDE_BIT};
use prt_format::{decode, encode, Asset, FormatError, BRICK_AXIS_MASK, BRICK_BACKFACE};
use prt_runtime::surface::SurfaceSampler;
use prt_runtime::{load_rig, CpuRelighter, LookupSettings, Relit, VolumeSampler};
use prt_tests::{bake_ok, fixture};

/// `asset` relit on the CPU (one bounce) under the two rooms' rig.
fn relit(asset: &Asset) -> Relit {
    relit_by(asset, &load_rig(&fixture("rigs/two_rooms.json")).unwrap())
}

/// `asset` relit on the CPU (one bounce) with `lighting`.
fn relit_by(asset: &Asset, lighting: &prt_runtime::Lighting) -> Relit {
    CpuRelighter::new(asset)
        .unwrap()
        .relight(lighting, 1)
        .unwrap()
}

fn mean(v: [f32; 3]) -> f32 {
    (v[0] + v[1] + v[2]) / 3.0
}

/// The default grid (0.29 m: a probe layer on the wall) and the wall halfway between two
/// layers (0.3 m over x in -4.05..4.05: 27 steps).
fn both_phases() -> [(&'static str, BakeSettings); 2] {
    let midway = BakeSettings {
        spacing: Some(0.3),
        bounds: Some([-4.05, 0.0, -2.0, 4.05, 3.0, 2.0]),
        ..BakeSettings::default()
    };
    [("default", BakeSettings::default()), ("midway", midway)]
}

/// Each front-face surfel's position and normal lead to its own brick (the key of its
/// position, the axis of its normal), or for a part of a brick the bake split at a wall
/// (`prt_bake::merge::split`, format 13) to the first part under its key: the table the
/// lookup searches holds every brick or its first part.
#[test]
fn every_surfel_finds_its_brick() {
    for (name, settings) in both_phases() {
        let asset = bake_ok(&fixture("two_rooms.gltf"), &settings);
        let t = &asset.surface;
        assert!(!t.is_empty(), "{name}: no surface terms");
        let runs = prt_format::surface_key_runs(t, &asset.bricks);
        let mut found = 0;
        for (b, brick) in asset.bricks.iter().enumerate() {
            let b = runs[b].0 as usize;
            if brick.flags & BRICK_BACKFACE != 0 {
                continue;
            }
            let range =
                brick.first_surfel as usize..(brick.first_surfel + brick.surfel_count) as usize;
            for s in &asset.surfels[range] {
                assert_eq!(dominant_axis(s.normal), brick.flags & BRICK_AXIS_MASK);
                let key = t.key_of(s.position);
                assert_eq!(
                    t.find(key, dominant_axis(s.normal)),
                    Some(b as u32),
                    "{name}: {s:?}"
                );
                assert!(t.surfel_in(b as u32, key, s.position).is_some());
                found += 1;
            }
        }
        assert!(found > 1000, "{name}: {found} surfels");
    }
}

/// Points on the dark room's side of the shared wall, and on its floor along the wall's foot
/// (the floor under a zero-thickness wall is one brick with the lit room's), away from the
/// door (the door is at z 0.8..1.8): with the surface lookup their mean irradiance stays
/// below 1% of the same points' on the lit side (the oracle puts the dark wall at 0.3%: one
/// bounce through the door), at both grid phases. The floor with the wall midway between
/// layers 0.5 m apart (stop 35): 0.66%, against 1.28% with the depth moments alone.
#[test]
fn the_surface_lookup_keeps_the_dark_room_dark() {
    for (name, settings) in both_phases() {
        let asset = bake_ok(&fixture("two_rooms.gltf"), &settings);
        let relit = relit(&asset);
        let lookup = LookupSettings::default();
        let s = SurfaceSampler::for_relit(&asset, &relit, &lookup);
        for (what, points) in [
            ("wall", wall_points as fn(f32) -> _),
            ("floor", floor_points),
        ] {
            let average = |side: f32| {
                let pts = points(side);
                let sum: f32 = pts
                    .iter()
                    .map(|(p, n)| mean(s.sample(*p, *n).irradiance))
                    .sum();
                sum / pts.len() as f32
            };
            let (lit, dark) = (average(-1.0), average(1.0));
            assert!(lit > 0.1, "{name} {what}: lit side {lit}");
            assert!(
                dark < 0.01 * lit,
                "{name} {what}: dark side {dark} vs lit side {lit}"
            );
        }
    }
}

/// `SurfaceSampler::explain` (what `prt sample --explain` writes) adds up to the sample: its
/// sample is the lookup's; the probes' irradiance scaled by the near field it reports, plus the
/// sky term, is the irradiance; a point with a surfel lists the probes it weighed and which it
/// sees, a point without one (in the air, off every surface) none seen. On the two rooms under
/// their rig (no sky) and on a street under a sky, where the sky terms add light.
#[test]
fn the_explanation_adds_up_to_the_sample() {
    let asset = bake_ok(&fixture("two_rooms.gltf"), &BakeSettings::default());
    let mut points = wall_points(-1.0);
    points.extend(wall_points(1.0));
    points.extend(floor_points(-1.0));
    let air = ([0.3, 1.4, 0.2], [0.0, 1.0, 0.0]);
    points.push(air);
    let rooms = relit(&asset);
    let s = SurfaceSampler::for_relit(&asset, &rooms, &LookupSettings::default());
    assert!(s.explain(air.0, air.1).surfel.is_none());
    let (with_surfel, _) = explanations_add_up(&asset, &rooms, &points);
    assert!(
        with_surfel * 2 > points.len(),
        "{with_surfel} of {}",
        points.len()
    );

    let street = bake_ok(&fixture("levels/street_2.gltf"), &BakeSettings::default());
    let lighting = load_rig(&fixture("levels/street_2_rig.json")).unwrap();
    let lit = relit_by(&street, &lighting);
    assert!(lit.sky.iter().all(|&l| l > 0.0), "{:?}", lit.sky);
    let on_surfels: Vec<_> = (street.surfels.iter().step_by(97))
        .map(|s| (s.position, s.normal))
        .collect();
    let (with_surfel, with_sky) = explanations_add_up(&street, &lit, &on_surfels);
    assert!(
        with_surfel * 2 > on_surfels.len(),
        "{with_surfel} of {}",
        on_surfels.len()
    );
    assert!(
        with_sky * 10 > with_surfel,
        "{with_sky} of {with_surfel} with a sky term"
    );
}

/// Checks [`the_explanation_adds_up_to_the_sample`]'s sums at `points` of `asset` relit as
/// `relit`; returns how many had a surfel, and how many of those a sky term that changed them.
fn explanations_add_up(
    asset: &Asset,
    relit: &Relit,
    points: &[([f32; 3], [f32; 3])],
) -> (usize, usize) {
    let s = SurfaceSampler::for_relit(asset, relit, &LookupSettings::default());
    let sky = relit.sky.map(|l| std::f32::consts::PI * l);
    let (mut with_surfel, mut with_sky) = (0, 0);
    for &(p, n) in points {
        let e = s.explain(p, n);
        assert_eq!(e.sample, s.sample(p, n), "{p:?}");
        assert!(e.probes.len() <= 8, "{p:?}: {:?}", e.probes);
        let Some(step) = e.surfel else {
            assert!(e.probes.iter().all(|q| q.seen.is_none()), "{p:?}");
            assert_eq!(e.probes_irradiance, e.sample.irradiance, "{p:?}");
            continue;
        };
        with_surfel += 1;
        with_sky += usize::from(step.sky_term != 0.0 && sky != [0.0; 3]);
        assert!(!e.probes.is_empty(), "{p:?}");
        assert!(e.probes.iter().all(|q| q.seen.is_some()), "{p:?}");
        assert_eq!(
            step.sees_a_probe,
            e.probes.iter().any(|q| q.seen == Some(true)),
            "{p:?}"
        );
        assert!(step.agreement > 0.99, "{p:?}: {step:?}");
        // The floor under L2's ringing, from the explanation's own SH and near-field counts.
        let rays = step.near_rays.max(1) as f32;
        let escaping = (rays - step.near_hits as f32) / rays;
        let l1 = irradiance_l1_nonlinear(&e.sample.sh, n);
        let floor = LookupSettings::default().ringing_floor * escaping;
        assert_eq!(step.ringing_floor, l1.map(|l| floor * l), "{p:?}");
        for (ch, l) in sky.iter().enumerate() {
            let (open, all) = (step.escaping[ch], step.hemisphere[ch]);
            let scale = match all > 0.0 {
                true => ((open.max(0.0).min(all) + step.near[ch]) / all).max(0.0),
                false => 1.0,
            };
            let before = e.probes_irradiance[ch] * scale;
            assert_eq!(step.before_floor[ch], before, "{p:?} ch {ch}");
            let near_field = before.max(step.ringing_floor[ch] - before);
            assert_eq!(step.near_field_irradiance[ch], near_field, "{p:?} ch {ch}");
            let want = match sky == [0.0; 3] {
                true => near_field,
                false => (near_field + step.sky_term * l).max(0.0),
            };
            assert_eq!(e.sample.irradiance[ch], want, "{p:?} ch {ch}");
        }
    }
    (with_surfel, with_sky)
}

/// Points on the shared wall, side `side` (+1: the dark room), as (position, normal).
fn wall_points(side: f32) -> Vec<([f32; 3], [f32; 3])> {
    grid(|a, b| ([0.0, 0.3 + 2.4 * a, -1.8 + 2.2 * b], [side, 0.0, 0.0]))
}

/// Points on the floor 6 to 30 cm from the shared wall, side `side` (+1: the dark room), away
/// from the door. Nearer than half a surfel cell (1.9 cm at 0.3 m) the floor's surfel holds both
/// rooms' hits, merged by the bake: a line there takes one side's light or the other's.
fn floor_points(side: f32) -> Vec<([f32; 3], [f32; 3])> {
    grid(|a, b| {
        (
            [side * (0.06 + 0.24 * a), 0.0, -1.8 + 1.6 * b],
            [0.0, 1.0, 0.0],
        )
    })
}

fn grid(f: impl Fn(f32, f32) -> ([f32; 3], [f32; 3])) -> Vec<([f32; 3], [f32; 3])> {
    (0..36)
        .map(|i| f((i / 6) as f32 / 5.0, (i % 6) as f32 / 5.0))
        .collect()
}

/// Without merging there are no bricks to key, and `surface_terms: false` (`prt bake
/// --no-surface-terms`) skips them: the asset carries no terms, and the surface lookup is the
/// default one.
#[test]
fn without_terms_the_lookup_is_the_volume_lookup() {
    let unmerged = BakeSettings {
        cell_size: Some(0.0),
        rays: 64,
        spacing: Some(1.0),
        ..BakeSettings::default()
    };
    let skipped = BakeSettings {
        surface_terms: false,
        ..BakeSettings::default()
    };
    for settings in [unmerged, skipped] {
        let asset = bake_ok(&fixture("two_rooms.gltf"), &settings);
        assert!(asset.surface.is_empty());
        let relit = relit(&asset);
        let lookup = LookupSettings::default();
        let s = SurfaceSampler::for_relit(&asset, &relit, &lookup);
        let plain = VolumeSampler::for_asset(&asset, &relit.sh, &lookup);
        for (p, n) in wall_points(1.0).into_iter().chain(floor_points(-1.0)) {
            assert_eq!(s.sample(p, n), plain.sample(p, n));
        }
    }
}

/// A slot naming a brick that does not exist, a near entry naming a group that does not, a
/// cell naming a surfel its brick does not have, groups out of order, a centre code past the
/// 27 offsets, more hits than rays, a spare bit set, a brick moved off its slot's key, a search bound longer than the table needs, a surfel naming another brick's group,
/// a sky term that is not a number, a sky term missing, sides out of order, a side naming a
/// surfel that does not exist, a side flagged but not listed: each refused, naming the surface
/// section.
#[test]
fn damaged_terms_are_refused() {
    let settings = BakeSettings {
        rays: 64,
        spacing: Some(1.0),
        ..BakeSettings::default()
    };
    let asset = bake_ok(&fixture("two_rooms.gltf"), &settings);
    decode(&encode(&asset).unwrap()).expect("the undamaged asset loads");
    let damages: [fn(&mut Asset); 13] = [
        |a| {
            let s = a.surface.slots.iter_mut().find(|s| s.value != 0).unwrap();
            s.value = (s.value & !0x1fff_ffff) | (a.bricks.len() as u32 + 1);
        },
        |a| a.surface.near[0] = (a.surface.near_ranges.len() as u32) << 8 | 255,
        |a| a.surface.cells[0] = 0xfefe_fefe,
        |a| a.surface.header.rays = 0,
        // Groups out of order: the GPU's per-brick loop would run to 2^32.
        |a| a.surface.groups.swap(1, 2),
        // A centre code past the 27 offsets (format 16).
        |a| a.surface.surfels[0].mask |= 31 << 27,
        // A search bound larger than the slots need: every miss would walk the table.
        |a| a.surface.header.max_probe = a.surface.slots.len() as u32 - 1,
        // A surfel naming a group beyond its brick's.
        |a| a.surface.surfels[0].group_open |= 0xff,
        // More near-field hits than rays (format 16: the hits sit in the normal's word).
        |a| a.surface.surfels[0].normal_hits |= 0xff << 24,
        // A spare bit of the band-2 codes set.
        |a| a.surface.surfels[0].open_l2 |= 1 << 30,
        // A side naming a partner that does not exist (format 18): the lookup reads its terms.
        |a| {
            let n = a.surface.surfels.len() as u32;
            a.surface.surfels[0].open_l2 |= SIDE_BIT;
            a.surface.sides.retain(|s| s.surfel != 0);
            a.surface.sides.insert(
                0,
                SurfaceSide {
                    surfel: 0,
                    partner: n,
                    ..SurfaceSide::default()
                },
            );
        },
        // A brick whose centroid moved to another key than its slot's (the centre probe the
        // lookup reads is its key's).
        |a| {
            let b = a.surface.slots.iter().find_map(|s| s.brick()).unwrap() as usize;
            a.bricks[b].centroid[0] += a.surface.header.brick_size;
        },
        // A sky term that is a NaN (format 14).
        |a| a.surface.sky[0] = 0x7e00,
    ];
    for (i, damage) in damages.iter().enumerate() {
        let mut bad = asset.clone();
        damage(&mut bad);
        match decode(&encode(&bad).unwrap()) {
            Err(FormatError::Invalid { section, .. }) => assert_eq!(section, "surface", "{i}"),
            other => panic!("damage {i}: {other:?}"),
        }
    }
    let mut short = asset.clone();
    short.surface.sky.pop();
    match decode(&encode(&short).unwrap()) {
        Err(FormatError::Count { section, .. }) => assert_eq!(section, "surface"),
        other => panic!("a sky term missing: {other:?}"),
    }
    // Two sides out of order (format 18): the lookup's binary search would miss one. Two
    // traced surfels of one front-face brick, each the other's partner, listed backwards.
    let mut unordered = asset.clone();
    let b = unordered
        .surface
        .slots
        .iter()
        .find_map(|s| s.brick())
        .unwrap() as usize;
    let first = unordered.bricks[b].first_surfel;
    assert!(unordered.bricks[b].surfel_count >= 2);
    let t = &mut unordered.surface;
    t.surfels.iter_mut().for_each(|s| s.open_l2 &= !SIDE_BIT);
    t.surfels[first as usize].open_l2 |= SIDE_BIT;
    t.surfels[first as usize + 1].open_l2 |= SIDE_BIT;
    let side = |surfel: u32, partner: u32| SurfaceSide {
        surfel,
        partner,
        ..SurfaceSide::default()
    };
    t.sides = vec![side(first + 1, first), side(first, first + 1)];
    match decode(&encode(&unordered).unwrap()) {
        Err(e @ FormatError::Invalid { .. }) => {
            assert!(
                e.to_string().contains("not after the side before it"),
                "{e}"
            )
        }
        other => panic!("sides out of order: {other:?}"),
    }
    // A surfel flagged as having a side that is not listed.
    let mut unlisted = asset.clone();
    let free = (0..unlisted.surface.surfels.len())
        .find(|&s| unlisted.surface.surfels[s].open_l2 & SIDE_BIT == 0)
        .unwrap();
    unlisted.surface.surfels[free].open_l2 |= SIDE_BIT;
    match decode(&encode(&unlisted).unwrap()) {
        Err(FormatError::Count { section, .. }) => assert_eq!(section, "surface"),
        other => panic!("a side not listed: {other:?}"),
    }
}

/// A wall through surfel cells (format 18, `prt_bake::merge::sides`): the two rooms' shared
/// wall stands in the middle of the floor's and ceiling's cells beside it (the cell lattice
/// puts walls at round coordinates there), so those cells' hits come from both rooms. Points
/// on the floor and the ceiling within half a cell of the wall, on either side, read their own
/// room at both grid phases: the lit side at least half of what the lit floor 6 to 30 cm out
/// reads, the dark side under 1% of it. Before the sides (stop 66), one surfel of both rooms'
/// hits took the dark room's probes, and the lit side's line read 0.3-1% of its room.
#[test]
fn a_wall_through_a_surfel_cell_parts_its_points() {
    for (name, settings) in both_phases() {
        let asset = bake_ok(&fixture("two_rooms.gltf"), &settings);
        assert!(!asset.surface.sides.is_empty(), "{name}: no sides");
        let relit = relit(&asset);
        let s = SurfaceSampler::for_relit(&asset, &relit, &LookupSettings::default());
        let average = |pts: Vec<([f32; 3], [f32; 3])>| {
            let sum: f32 = pts
                .iter()
                .map(|(p, n)| mean(s.sample(*p, *n).irradiance))
                .sum();
            sum / pts.len() as f32
        };
        let cell = asset.surface.header.brick_size / 4.0;
        let line = |side: f32| {
            average(grid(|a, b| {
                let x = side * cell * (0.05 + 0.4 * a);
                match b < 0.5 {
                    true => ([x, 0.0, -1.8 + 3.0 * b], [0.0, 1.0, 0.0]),
                    false => ([x, 3.0, -1.8 + 3.0 * (b - 0.5)], [0.0, -1.0, 0.0]),
                }
            }))
        };
        let open = average(floor_points(-1.0));
        let (lit, dark) = (line(-1.0), line(1.0));
        eprintln!("{name}: lit floor {open}, by the wall: lit {lit}, dark {dark}");
        assert!(lit > 0.5 * open, "{name}: lit side {lit} against {open}");
        assert!(
            dark < 0.01 * open,
            "{name}: dark side {dark} against {open}"
        );
    }
}

/// A slot naming a later part of a brick the bake split at a wall (format 13): the lookup would
/// count the part's surfels' groups from the wrong brick, past the table's end on the last
/// one. Refused, naming the surface section; the default bake of the two-room fixture splits
/// bricks at its shared wall.
#[test]
fn a_slot_naming_a_later_part_is_refused() {
    let mut asset = bake_ok(&fixture("two_rooms.gltf"), &BakeSettings::default());
    let runs = prt_format::surface_key_runs(&asset.surface, &asset.bricks);
    let later = (0..runs.len()).find(|&b| runs[b].0 as usize != b);
    let b = later.expect("a brick split at a wall") as u32;
    let slot = (asset.surface.slots.iter_mut())
        .find(|s| {
            s.value >> prt_format::surface::SLOT_AXIS_SHIFT
                == asset.bricks[b as usize].flags & BRICK_AXIS_MASK
        })
        .unwrap();
    slot.value = (slot.value & !0x1fff_ffff) | (b + 1);
    match decode(&encode(&asset).unwrap()) {
        Err(FormatError::Invalid { section, .. }) => assert_eq!(section, "surface"),
        other => panic!("{other:?}"),
    }
}

/// A sunlit atrium with two-storey galleries (`fixtures/levels/atrium_1`, a tuning level of
/// the family: sun through the roof opening, hard shadow edges beside dark gallery ceilings
/// and arcade soffits), default bake, against the oracle's 299 points: with the surface terms
/// at most 1% of the open points are lit over 1.5x their truth (measured 2 of 299 with 2048
/// rays, 1 with stop 37's 512; the probe volume alone, 5 of 299 since probes are dilated only
/// where a cell has no valid corner, 6 before: at least twice as many), and the
/// mean error of the open points falls below 15% (7.4% against 9.7%, the mean over colour
/// channels of the relative error; at stop 35's coarser default grid 12.6% against 23.9%).
#[test]
fn a_sunlit_atrium_keeps_its_galleries_dark() {
    let dir = fixture("levels");
    let asset = bake_ok(&dir.join("atrium_1.gltf"), &BakeSettings::default());
    let lighting = load_rig(&dir.join("atrium_1_rig.json")).unwrap();
    let relit = relit_by(&asset, &lighting);
    let points: Vec<_> = reference(&dir.join("refs/atrium_1_surface.json"))
        .into_iter()
        .filter(|p| !p.pocket)
        .map(|p| (p.position, p.normal, p.truth, p.hemi))
        .collect();
    let mut hemi: Vec<f32> = points.iter().map(|p| p.3).collect();
    hemi.sort_by(f32::total_cmp);
    let median = hemi[hemi.len() / 2];
    let score = |surface_terms: bool| {
        let lookup = LookupSettings {
            surface_terms,
            ..LookupSettings::default()
        };
        let s = SurfaceSampler::for_relit(&asset, &relit, &lookup);
        let (mut leaks, mut err) = (0, 0.0);
        for &(p, n, truth, hemi) in &points {
            let e = mean(s.sample(p, n).irradiance);
            leaks += usize::from(e > 1.5 * hemi && e - hemi > 0.05 * median);
            err += (e - truth).abs() / truth.max(1e-3 * median);
        }
        (leaks, err / points.len() as f32)
    };
    let (leaks, err) = score(true);
    let (volume_leaks, volume_err) = score(false);
    let n = points.len();
    eprintln!("surface terms: {leaks} of {n} over-lit, mean {err}; the volume alone: {volume_leaks}, {volume_err}");
    assert!(100 * leaks <= n, "{leaks} of {n} points over-lit");
    assert!(err < 0.15, "mean error {err}");
    assert!(
        volume_leaks >= 2 * leaks.max(1),
        "the volume alone: {volume_leaks} over-lit"
    );
    assert!(
        volume_err > err,
        "the volume alone: {volume_err} against {err}"
    );
}

/// The sky a surface sees, not its probes' (format 14, `prt_bake::sky_terms`): an open street
/// of the level family (`fixtures/levels/street_2`: overhangs, arches, walls that hide most of
/// the sky from the ground beside them), its surfaces black, under a sky of radiance 1 alone.
/// The truth at a point is then pi times the cosine-weighted share of its hemisphere that
/// leaves the scene, traced here with 4,096 rays; at the front-face surfels the lookup with the
/// sky terms is nearer it than the lookup without (measured at 402 surfels: mean absolute
/// error 0.022 against 0.049, of a mean truth of 1.93; 0.033 with stop 55's 64 sky rays, which
/// the bound of 0.6x fails).
#[test]
fn the_sky_term_gives_a_surface_its_own_sky() {
    use glam::Vec3;
    let dir = fixture("levels");
    let mut asset = bake_ok(&dir.join("street_2.gltf"), &BakeSettings::default());
    for s in &mut asset.surfels {
        s.albedo = [0.0; 3];
        s.emission = [0.0; 3];
    }
    let lighting = prt_runtime::Lighting {
        rig: prt_format::LightRig::default(),
        sky: prt_runtime::SkyModel::Constant([1.0; 3]),
    };
    let relit = relit_by(&asset, &lighting);
    assert_eq!(relit.sky, [1.0; 3]);
    let lookup = LookupSettings::default();
    let with = SurfaceSampler::for_relit(&asset, &relit, &lookup);
    let without = SurfaceSampler::new(&asset, &relit.sh, &relit.surfel_radiance, [0.0; 3], &lookup);
    let spacing = asset.header.grid.spacing;
    let traced: Vec<usize> = (0..asset.surfels.len())
        .filter(|&s| with.surfel(asset.surfels[s].position, asset.surfels[s].normal) == Some(s))
        .collect();
    assert!(traced.len() > 1000, "{} surfels with terms", traced.len());
    let rays = 4096;
    let (mut truth_sum, mut err_with, mut err_without) = (0.0f64, 0.0f64, 0.0f64);
    let picked: Vec<usize> = traced.iter().step_by(traced.len() / 400).copied().collect();
    for &s in &picked {
        let (p, n) = (asset.surfels[s].position, asset.surfels[s].normal);
        let nv = Vec3::from(n);
        let o = Vec3::from(p) + nv * 0.01 * spacing;
        let (t, b) = nv.any_orthonormal_pair();
        let open = (0..rays)
            .filter(|&k| {
                let d = prt_bake::surface_terms::cosine_spiral(k, rays, t, b, nv);
                prt_runtime::shadow_rays::closest_hit(&asset.geometry, o, d, f32::MAX).is_none()
            })
            .count();
        let truth = std::f64::consts::PI * open as f64 / f64::from(rays);
        truth_sum += truth;
        err_with += (f64::from(mean(with.sample(p, n).irradiance)) - truth).abs();
        err_without += (f64::from(mean(without.sample(p, n).irradiance)) - truth).abs();
    }
    let count = picked.len() as f64;
    let (err_with, err_without) = (err_with / count, err_without / count);
    eprintln!(
        "{count} surfels, mean truth {:.3}: mean abs error {err_with:.3} with the sky terms, \
         {err_without:.3} without",
        truth_sum / count
    );
    assert!(
        err_with < 0.6 * err_without,
        "{err_with} against {err_without}"
    );
}

/// A point of an oracle reference (`fixtures/levels/refs.py`, `point_refs.py`): mean-RGB
/// irradiance of its SH (`truth`) and exact over the hemisphere (`hemi`), 2 mm off the surface.
struct RefPoint {
    what: String,
    position: [f32; 3],
    normal: [f32; 3],
    truth: f32,
    hemi: f32,
    pocket: bool,
}

fn reference(path: &std::path::Path) -> Vec<RefPoint> {
    let text = std::fs::read_to_string(path).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let vec3 = |v: &serde_json::Value| -> [f32; 3] {
        std::array::from_fn(|i| v[i].as_f64().unwrap() as f32)
    };
    doc["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let n = vec3(&p["normal"]);
            let sh: prt_format::sh::ShRgb = std::array::from_fn(|k| vec3(&p["sh"][k]));
            RefPoint {
                what: p["what"].as_str().unwrap_or_default().to_owned(),
                position: vec3(&p["position"]),
                normal: n,
                truth: mean(prt_format::sh::irradiance(&sh, n)),
                hemi: mean(vec3(&p["e_hemi"])),
                pocket: p["pocket"].as_bool().unwrap_or(false),
            }
        })
        .collect()
}

/// Over-lit as `prt-bench surface` and the oracle's scorer count it: over 1.5x the exact
/// hemispherical truth, and by over 5% of the reference's median truth.
fn over_lit(e: f32, p: &RefPoint, median: f32) -> bool {
    e > 1.5 * p.hemi && e - p.hemi > 0.05 * median
}

fn median_hemi(points: &[RefPoint]) -> f32 {
    let mut hemi: Vec<f32> = points.iter().map(|p| p.hemi).collect();
    hemi.sort_by(f32::total_cmp);
    hemi[hemi.len() / 2]
}

/// No seams (issue 31, item 4): along every junction of fixtures/two_rooms.gltf's lit room
/// (floor, ceiling, end, back and shared walls) and along the shared wall's junctions in the
/// dark room, 3, 6 and 12 cm from the corner (`fixtures/surface/two_rooms_seams.json`, 360
/// points with the oracle's truth), no point is over-lit, at both grid phases: the shared wall
/// on a probe layer and halfway between two (the volume alone: 16 there).
#[test]
fn no_over_lit_lines_where_walls_floors_and_ceilings_meet() {
    let points = reference(&fixture("surface/two_rooms_seams.json"));
    let median = median_hemi(&points);
    for (name, settings) in both_phases() {
        let asset = bake_ok(&fixture("two_rooms.gltf"), &settings);
        let relit = relit(&asset);
        let lit = |surface_terms: bool| {
            let lookup = LookupSettings {
                surface_terms,
                ..LookupSettings::default()
            };
            let s = SurfaceSampler::for_relit(&asset, &relit, &lookup);
            let (mut err, mut bad) = (0.0, Vec::new());
            for p in &points {
                let e = mean(s.sample(p.position, p.normal).irradiance);
                err += (e - p.truth).abs() / p.truth.max(1e-3 * median);
                if over_lit(e, p, median) {
                    bad.push(format!(
                        "{} at {:?}: {e} against {}",
                        p.what, p.position, p.hemi
                    ));
                }
            }
            (err / points.len() as f32, bad)
        };
        let (err, bad) = lit(true);
        let (volume_err, volume_bad) = lit(false);
        eprintln!(
            "{name}: mean error {err}, over-lit {} of {}; the volume alone: {volume_err}, {}",
            bad.len(),
            points.len(),
            volume_bad.len()
        );
        assert!(bad.is_empty(), "{name}: over-lit:\n{}", bad.join("\n"));
        // Not dark either (the dark room's points weigh most; measured 6.4% and 6.0% with
        // the default sparse placement since format 18's sides, 9.0% and 37.2% before, 10.9%
        // and 31.7% on the uniform grid then: its fewer probes' hits give the dark room's
        // bricks other radiance models; bound 40% until the sides), and at midway the volume
        // alone does over-light these lines: the check can tell.
        assert!(err < 0.15, "{name}: mean error {err}");
        if name == "midway" {
            assert!(
                !volume_bad.is_empty(),
                "the volume alone over-lights no line"
            );
        }
    }
}

/// A pocket (issue 31): fixtures/pocket.gltf's box stands 4 cm from the wall, closer than the
/// lookup's normal offset (0.2 spacings), so the volume alone samples the room in front of the
/// gap. The oracle (`fixtures/surface/pocket_points.json`, 41 pocket points on the gap's two
/// faces) puts them at 1.0% of the other points' irradiance. With the surface terms their mean
/// stays under 2% of it (measured 0.56%) and at most 2 are over-lit by the scorer's rule
/// (measured none; 7 at stop 35's coarser grid, on the box's face by the gap's mouth); the
/// probe volume alone lights them at 9.9%, 21 over-lit.
#[test]
fn a_pocket_stays_dark() {
    let points = reference(&fixture("surface/pocket_points.json"));
    let median = median_hemi(&points);
    let asset = bake_ok(&fixture("pocket.gltf"), &BakeSettings::default());
    let lighting = load_rig(&fixture("rigs/pocket.json")).unwrap();
    let relit = relit_by(&asset, &lighting);
    let (pockets, open): (Vec<&RefPoint>, Vec<&RefPoint>) = points.iter().partition(|p| p.pocket);
    assert!(pockets.len() >= 40, "{} pocket points", pockets.len());
    let open_truth = open.iter().map(|p| p.hemi).sum::<f32>() / open.len() as f32;
    let pocket_truth = pockets.iter().map(|p| p.hemi).sum::<f32>() / pockets.len() as f32;
    assert!(
        pocket_truth < 0.02 * open_truth,
        "the reference's pocket: {pocket_truth}"
    );
    let score = |surface_terms: bool| {
        let lookup = LookupSettings {
            surface_terms,
            ..LookupSettings::default()
        };
        let s = SurfaceSampler::for_relit(&asset, &relit, &lookup);
        let e: Vec<f32> = pockets
            .iter()
            .map(|p| mean(s.sample(p.position, p.normal).irradiance))
            .collect();
        let lit = pockets
            .iter()
            .zip(&e)
            .filter(|(p, e)| over_lit(**e, p, median))
            .count();
        (e.iter().sum::<f32>() / e.len() as f32 / open_truth, lit)
    };
    let (terms, terms_lit) = score(true);
    let (volume, volume_lit) = score(false);
    eprintln!(
        "pocket over open truth: {terms} ({terms_lit} over-lit) with the terms, {volume} \
         ({volume_lit}) without; the truth {}",
        pocket_truth / open_truth
    );
    assert!(terms < 0.02, "pocket at {terms} of the open points");
    assert!(volume > 3.0 * terms, "the volume alone: {volume}");
    assert!(terms_lit <= 2, "{terms_lit} over-lit pocket points");
    assert!(
        volume_lit > 2 * terms_lit,
        "the volume alone: {volume_lit} over-lit"
    );
}
