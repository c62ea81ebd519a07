//! Repeatability (issue 8, "Repeatability"): 20 bakes of one scene, ten with one thread and ten
//! with two, give identical bytes; 20 CPU relights give identical SH bits; GPU relights in
//! separate devices give identical SH bits.

use prt_bake::BakeSettings;
use prt_format::encode;
use prt_runtime::gpu::{relight_once, RuntimeSettings};
use prt_runtime::{load_rig, CpuRelighter};
use prt_tests::{bake_ok, fixture, rays};

fn bits(sh: &[prt_format::sh::ShRgb]) -> Vec<u32> {
    sh.iter().flatten().flatten().map(|v| v.to_bits()).collect()
}

#[test]
fn twenty_bakes_and_relights_are_identical() {
    let scene = fixture("two_rooms.gltf");
    let bytes: Vec<Vec<u8>> = (0..20)
        .map(|i| {
            let settings = BakeSettings {
                threads: Some(1 + i % 2),
                spacing: Some(0.8),
                ..rays(128)
            };
            encode(&bake_ok(&scene, &settings)).unwrap()
        })
        .collect();
    for (i, b) in bytes.iter().enumerate() {
        assert!(b == &bytes[0], "bake {i} differs from bake 0");
    }
    let asset = prt_format::decode(&bytes[0]).unwrap();
    let lighting = load_rig(&fixture("rigs/two_rooms.json")).unwrap();
    let relighter = CpuRelighter::new(&asset).unwrap();
    let first = bits(&relighter.relight(&lighting, 2).unwrap().sh);
    for i in 1..20 {
        let again = bits(&relighter.relight(&lighting, 2).unwrap().sh);
        assert!(again == first, "CPU relight {i} differs");
    }
    let gpu = |_| {
        bits(
            &relight_once(&asset, &lighting, RuntimeSettings::default())
                .unwrap()
                .sh,
        )
    };
    let runs: Vec<Vec<u32>> = (0..3).map(gpu).collect();
    assert!(
        runs.iter().all(|r| r == &runs[0]),
        "GPU relights differ between devices"
    );
}

/// With far hits in coarse bricks, bakes on one or two threads, with factor rows in memory or
/// spilled to the temporary file, give the same bytes.
#[test]
fn coarse_brick_bakes_are_identical_at_any_thread_count() {
    let scene = fixture("two_rooms.gltf");
    let bake = |threads: usize, row_memory: usize| {
        let settings = BakeSettings {
            threads: Some(threads),
            spacing: Some(0.8),
            far_ratio: 2.0,
            row_memory,
            ..rays(128)
        };
        encode(&bake_ok(&scene, &settings)).unwrap()
    };
    let first = bake(1, BakeSettings::default().row_memory);
    assert!(!prt_format::decode(&first).unwrap().coarse.bricks.is_empty());
    for (threads, row_memory) in [(2, BakeSettings::default().row_memory), (2, 1), (1, 1)] {
        assert!(
            bake(threads, row_memory) == first,
            "{threads} threads, {row_memory} bytes of rows in memory"
        );
    }
}

/// The sky stage's second pass (`prt_bake::sky_terms::MORE_SKY_RAYS`) picks its surfels from
/// the first pass's terms: Cornell's default bake traces 4,012 of its 92,266 surfels again
/// (stop 65), and gives the same bytes with one thread and with two.
#[test]
fn sky_terms_traced_twice_are_identical_at_any_thread_count() {
    let scene = fixture("cornell/cornell.gltf");
    let bake = |threads: usize| {
        let settings = BakeSettings {
            threads: Some(threads),
            ..BakeSettings::default()
        };
        encode(&bake_ok(&scene, &settings)).unwrap()
    };
    assert!(
        bake(1) == bake(2),
        "Cornell's default bake differs between one and two threads"
    );
}
