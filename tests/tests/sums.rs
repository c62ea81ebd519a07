//! Sums (issue 8, "Sums"): the GPU gather's f32 parallel reduction against the CPU reference,
//! which accumulates in f64, for probes with 16 to 131,072 factors (one probe in the
//! closed box, no merging: every ray hit its own factor). Measured: 6.7e-8 of SH0 at 16 factors,
//! 3.4e-7 at 1,024, 3.3e-6 at 16,384, 3.8e-6 at 131,072: the subgroup reduction does not drift.

use prt_bake::BakeSettings;
use prt_runtime::gpu::{relight_once, RuntimeSettings};
use prt_runtime::{load_rig, CpuRelighter};
use prt_tests::{bake_ok, brighter, fixture, point_bounds};

#[test]
fn gpu_gather_sums_match_the_f64_reference_up_to_100k_factors() {
    let lighting = load_rig(&fixture("rigs/point_spot_sun_sky.json")).unwrap();
    let mut report = Vec::new();
    for rays in [16u32, 1024, 16384, 131072] {
        let asset = bake_ok(
            &fixture("closed_box_inward.gltf"),
            &BakeSettings {
                rays,
                cell_size: Some(0.0),
                bounds: point_bounds([0.1, 0.2, 0.3]),
                ..BakeSettings::default()
            },
        );
        // Factors, not slots (a u8 factor takes one or two).
        let factors = asset.factors.factor_counts().0 as u32;
        assert!(factors >= rays * 9 / 10, "{factors} factors of {rays} rays");
        let cpu = CpuRelighter::new(&asset)
            .unwrap()
            .relight(&lighting, 1)
            .unwrap()
            .sh;
        let gpu = relight_once(&asset, &lighting, RuntimeSettings::default())
            .unwrap()
            .sh;
        let dc = cpu[0][0].iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let mut worst = 0.0f32;
        for k in 0..9 {
            for c in 0..3 {
                worst = worst.max((gpu[0][k][c] - cpu[0][k][c]).abs() / dc);
            }
        }
        report.push((factors, worst));
        assert!(
            worst < 2e-5,
            "{factors} factors: GPU differs by {worst} of SH0"
        );
    }
    eprintln!("gather: (factors, worst |GPU - f64| / SH0) {report:?}");
}

/// The f16 volume's range rule: a rig (lights and sky) 2^20 times brighter than the Cornell rig
/// pushes SH past 65504; those probes are counted as clamped (`Counters::probes_clamped`), none
/// are at the rig's own brightness, and the f32 SH the gather writes stay linear either way (a
/// power of two, so that the surfels' radiance words scale exactly: `prt_runtime::radiance_word`
/// rounds a 1e6 times brighter surfel a little differently).
#[test]
fn f16_volume_clamping_is_counted() {
    let asset = bake_ok(
        &fixture("cornell/cornell.gltf"),
        &BakeSettings {
            spacing: Some(0.5),
            ..BakeSettings::default()
        },
    );
    let base = load_rig(&fixture("cornell/rig.json")).unwrap();
    let gain = 1_048_576.0;
    let bright = brighter(&base, gain);
    let relit = relight_once(&asset, &base, RuntimeSettings::default()).unwrap();
    let (sh, counters) = (relit.sh, relit.counters);
    assert_eq!(counters.probes_clamped, 0);
    let relit = relight_once(&asset, &bright, RuntimeSettings::default()).unwrap();
    let (sh_bright, counters) = (relit.sh, relit.counters);
    assert!(counters.probes_clamped > 0, "{counters:?}");
    // The GPU memory adds up and counts the volume's seven texels per grid point (f16).
    let (allocations, total) = relit.memory;
    assert_eq!(total, allocations.iter().map(|a| a.bytes).sum::<u64>());
    let volume = allocations
        .iter()
        .find(|a| a.name.contains("SH volume"))
        .unwrap();
    assert_eq!(volume.bytes, 7 * 8 * asset.probes.len() as u64);
    assert!(allocations.windows(2).all(|w| w[0].bytes >= w[1].bytes));
    for (a, b) in sh.iter().zip(&sh_bright) {
        let dc = a[0].iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1e-12);
        let rel = (b[0][0] / gain - a[0][0]).abs() / dc;
        assert!(rel < 1e-4, "SH0 {} vs {}", b[0][0] / gain, a[0][0]);
    }
}
