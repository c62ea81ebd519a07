//! Coarse bricks (`prt_format::coarse`): their radiance, built from their bricks' models, is the
//! linear fit over all their surfels; far rays share them.

use glam::{DMat3, DVec3};
use prt_bake::BakeSettings;
use prt_runtime::relight::coarse_radiance;
use prt_runtime::{load_rig, CpuRelighter};
use prt_tests::{bake_ok as bake, fixture};

/// Every coarse brick's linear model (the stored `2^level` undone) predicts at each of its
/// surfels what the weighted least-squares fit over the union of its bricks' surfels does,
/// computed here from the surfels in f64, to 1e-3 of the brick's radiance scale: the stored
/// gradient weights are halves since format 15 (`prt_format::PackedSurfel`, relative rounding
/// 4.9e-4; 4.8e-4 measured here, 1e-4 held with f32 weights). (Values at the surfels, not the
/// gradients: along a flat brick's normal the fit's gradient is set by the regularisation and
/// float noise, and no surfel or ray lies off the plane.)
#[test]
fn coarse_radiance_is_the_fit_over_all_its_surfels() {
    let scene = fixture("cornell/cornell.gltf");
    let settings = BakeSettings {
        far_ratio: 2.0,
        ..BakeSettings::default()
    };
    let asset = bake(&scene, &settings);
    assert!(asset.coarse.bricks.len() > 100, "coarse bricks made");
    let lighting = load_rig(&fixture("cornell/rig.json")).expect("rig");
    let relighter = CpuRelighter::new(&asset).expect("relighter");
    let lights: Vec<_> = lighting
        .rig
        .lights
        .iter()
        .map(prt_runtime::lights::PreparedLight::new)
        .collect();
    let (irradiance, _) = relighter.direct_irradiance(&lights);
    let surfel_radiance = relighter.surfel_radiance(&irradiance, None);
    let radiance = relighter.brick_radiance(&surfel_radiance);
    let fine = &radiance[..asset.bricks.len()];
    let mut worst = 0.0f64;
    for (i, c) in asset.coarse.bricks.iter().enumerate() {
        let got = coarse_radiance(&asset, c, fine);
        assert_eq!(got, radiance[asset.bricks.len() + i], "the relight's own");
        let run = c.first_child as usize..(c.first_child + c.child_count) as usize;
        let surfels: Vec<usize> = asset.coarse.children[run]
            .iter()
            .flat_map(|&b| {
                let b = &asset.bricks[b as usize];
                b.first_surfel as usize..(b.first_surfel + b.surfel_count) as usize
            })
            .collect();
        let (mean, gradient) = fit(&asset, &surfel_radiance, &surfels);
        let scale = mean.iter().fold(1e-3, |m: f64, v| m.max(v.abs()));
        let inverse_scale = 1.0 / f64::from(1u32 << c.level);
        for &s in &surfels {
            let p = asset.surfels[s].position;
            let d: [f64; 3] = std::array::from_fn(|a| f64::from(p[a] - c.centroid[a]));
            for ch in 0..3 {
                let at = |m: f64, g: [f64; 3]| m + g[0] * d[0] + g[1] * d[1] + g[2] * d[2];
                let ours = at(
                    f64::from(got.mean[ch]),
                    got.gradient[ch].map(|v| f64::from(v) * inverse_scale),
                );
                worst = worst.max((ours - at(mean[ch], gradient[ch])).abs() / scale);
            }
        }
    }
    assert!(worst < 1e-3, "worst relative difference {worst:e}");
}

/// The weighted mean and the regularised least-squares gradient of the surfels' radiance
/// `surfel_radiance` (per surfel, as the runtime keeps it: `CpuRelighter::surfel_radiance`).
fn fit(
    asset: &prt_format::Asset,
    surfel_radiance: &[[f32; 3]],
    surfels: &[usize],
) -> ([f64; 3], [[f64; 3]; 3]) {
    let radiance = |s: usize| surfel_radiance[s].map(f64::from);
    let pos = |s: usize| DVec3::from(asset.surfels[s].position.map(f64::from));
    let w = |s: usize| f64::from(asset.surfels[s].weight);
    let weight: f64 = surfels.iter().map(|&s| w(s)).sum();
    let mu = surfels.iter().map(|&s| pos(s) * w(s)).sum::<DVec3>() / weight;
    let mut c = DMat3::ZERO;
    let mut b = [DVec3::ZERO; 3];
    let mut mean = [0.0; 3];
    for &s in surfels {
        let d = pos(s) - mu;
        c += DMat3::from_cols(d * d.x, d * d.y, d * d.z) * w(s);
        let l = radiance(s);
        for ch in 0..3 {
            b[ch] += d * w(s) * l[ch];
            mean[ch] += w(s) * l[ch] / weight;
        }
    }
    let trace = c.x_axis.x + c.y_axis.y + c.z_axis.z;
    let inv = (c + DMat3::IDENTITY * (1e-3 * trace)).inverse();
    (mean, b.map(|bc| (inv * bc).to_array()))
}

/// Far rays share factors: with a far ratio of 2 the fast preset's Cornell bake keeps under
/// 40% of the factors (34.6% since stop 53's coarsest level of 3; under a third before), and
/// after a light moves the GPU re-gathers every probe whose coarse bricks changed (a coarse
/// brick is dirty when one of its bricks is): it equals the CPU relight.
#[test]
fn coarse_bricks_follow_light_changes_on_the_gpu() {
    use prt_runtime::gpu::{PrtRuntime, RuntimeSettings, VolumeFormat};
    let scene = fixture("cornell/cornell.gltf");
    let off = bake(&scene, &BakeSettings::fast());
    let settings = BakeSettings {
        far_ratio: 2.0,
        ..BakeSettings::fast()
    };
    let asset = bake(&scene, &settings);
    assert_eq!(asset.header.settings.far_ratio, 2.0);
    // Factors, not slots (a u8 factor takes one or two).
    let factors = |a: &prt_format::Asset| a.factors.factor_counts().0;
    assert!(
        factors(&asset) * 5 < factors(&off) * 2,
        "{} factors against {}",
        factors(&asset),
        factors(&off)
    );
    let (device, queue) = prt_tests::gpu_device();
    let mut runtime = PrtRuntime::new(
        &device,
        &queue,
        &asset,
        RuntimeSettings {
            volume_format: VolumeFormat::F32,
            ..RuntimeSettings::default()
        },
    )
    .expect("runtime");
    let mut rig = load_rig(&fixture("cornell/rig.json")).expect("rig");
    // A small ranged light by the floor: moving it relights a few bricks only.
    let mut small = rig.rig.lights[0].clone();
    small.position = [-0.6, 0.2, -0.6];
    small.range = Some(0.4);
    rig.rig.lights.push(small);
    for step in 0..3 {
        if step > 0 {
            rig.rig.lights.last_mut().expect("light").position[0] += 0.25;
        }
        let mut encoder = device.create_command_encoder(&Default::default());
        runtime.update(&mut encoder, &rig, None).expect("update");
        queue.submit([encoder.finish()]);
        if step > 0 {
            let relit = runtime.read_counters().expect("counters").bricks_relit as usize;
            assert!(
                relit > 0 && relit * 4 < asset.bricks.len(),
                "{relit} bricks relit"
            );
        }
        let gpu = runtime.read_probe_sh().expect("read back");
        let cpu = CpuRelighter::new(&asset)
            .expect("relighter")
            .relight(&rig, 1)
            .expect("relight")
            .sh;
        let worst = prt_tests::worst_of_sh0(&asset, &gpu, &cpu);
        assert!(worst <= 1e-4, "update {step}: worst {worst:e} of SH0");
    }
}

/// A coarse brick never reads light across a wall (stop 49). On `interior_28` (a generated
/// level, `fixtures/levels/`) the dark room meets a lit one at a zero-thickness wall at
/// x = 16.869, which coarse cells straddle; the dark room's probes within 0.6 m of it should
/// see what a bake without coarse bricks sees. When one coarse brick was fitted over both
/// rooms' floors, walls and ceilings, they came out brighter (SH0 median 1.066x, p90 1.142x,
/// worst 2.72x); kept apart by links, 1.018x, 1.055x and 1.155x.
#[test]
fn coarse_bricks_do_not_read_light_across_a_wall() {
    let scene = fixture("levels/interior_28.gltf");
    let lighting = load_rig(&fixture("levels/interior_28_rig.json")).expect("rig");
    let relit = |settings: &BakeSettings| {
        let asset = bake(&scene, settings);
        let sh = CpuRelighter::new(&asset)
            .expect("relighter")
            .relight(&lighting, 1)
            .expect("relight")
            .sh;
        (asset, sh)
    };
    let (asset, sh) = relit(&BakeSettings::default());
    assert!(!asset.coarse.bricks.is_empty(), "coarse bricks made");
    let no_coarse = BakeSettings {
        far_ratio: 0.0,
        ..BakeSettings::default()
    };
    let (exact, exact_sh) = relit(&no_coarse);
    assert_eq!(asset.probes.len(), exact.probes.len(), "the same grid");
    let dc = |sh: &prt_format::sh::ShRgb| sh[0].iter().sum::<f32>();
    let mut ratios: Vec<f32> = (0..asset.probes.len())
        .filter(|&i| {
            let [x, _, z] = asset.probes[i].position;
            let both = asset.probes[i].is_valid() && exact.probes[i].is_valid();
            both && (16.269..16.869).contains(&x) && (17.5..23.695).contains(&z)
        })
        .map(|i| dc(&sh[i]) / dc(&exact_sh[i]).max(1e-9))
        .collect();
    assert!(ratios.len() > 50, "{} probes beside the wall", ratios.len());
    ratios.sort_by(f32::total_cmp);
    let at = |q: f32| ratios[((ratios.len() - 1) as f32 * q) as usize];
    assert!(
        at(0.5) < 1.04 && at(0.9) < 1.1,
        "dark-room probes beside the wall against a bake without coarse bricks: median {}, \
         p90 {}, worst {}",
        at(0.5),
        at(0.9),
        at(1.0)
    );
}

/// Fine bricks split where a wall stands on them (`prt_bake::merge::split`, format 13). In
/// `fixtures/levels/interior_32` a room lit only through a door sits beside a lit one behind a
/// zero-thickness wall, and the walls that run on under it put both rooms' surfels in one
/// brick, a cell at the corner holding hits of both sides. The surfels of the dark room that
/// no light reaches read from their brick's fit at most half the level's median surfel
/// radiance (measured 0.23x: light through the door still grades some parts), where one fit
/// over the brick's parts together (the brick before the split, fitted here) gives some of
/// them over twice the median (measured 6.9x).
#[test]
fn bricks_split_at_a_wall_keep_the_dark_side_dark() {
    let scene = fixture("levels/interior_32.gltf");
    let lighting = load_rig(&fixture("levels/interior_32_rig.json")).expect("rig");
    let asset = bake(&scene, &BakeSettings::default());
    let relighter = CpuRelighter::new(&asset).expect("relighter");
    let relit = relighter.relight(&lighting, 1).expect("relight");
    let (e, l) = (relit.surfel_irradiance, relit.surfel_radiance);
    let models = relighter.brick_radiance(&l);
    let runs = prt_format::surface_key_runs(&asset.surface, &asset.bricks);
    let sum = |v: [f32; 3]| f64::from(v[0] + v[1] + v[2]);
    let radiance = |s: usize| {
        let a = asset.surfels[s].albedo;
        sum(std::array::from_fn(|c| a[c] * e[s][c])) * std::f64::consts::FRAC_1_PI
    };
    let mut lit: Vec<f64> = (0..asset.surfels.len())
        .map(radiance)
        .filter(|&l| l > 0.0)
        .collect();
    lit.sort_by(f64::total_cmp);
    let median = lit[lit.len() / 2];
    let dark = |p: [f32; 3]| (23.3..27.2).contains(&p[0]) && (14.95..19.94).contains(&p[2]);
    let (mut split, mut whole, mut unlit, mut parts) = (0.0f64, 0.0f64, 0, 0);
    for (b, brick) in asset.bricks.iter().enumerate() {
        if brick.flags & prt_format::BRICK_BACKFACE != 0 || runs[b].0 as usize != b {
            continue;
        }
        parts += usize::from(runs[b].1 as usize > b + 1);
        let run: Vec<usize> = (b..runs[b].1 as usize)
            .flat_map(|p| {
                let q = &asset.bricks[p];
                q.first_surfel as usize..(q.first_surfel + q.surfel_count) as usize
            })
            .collect();
        let (mean, gradient) = fit(&asset, &l, &run);
        let w = |s: usize| f64::from(asset.surfels[s].weight);
        let pos = |s: usize| DVec3::from(asset.surfels[s].position.map(f64::from));
        let mu = run.iter().map(|&s| pos(s) * w(s)).sum::<DVec3>()
            / run.iter().map(|&s| w(s)).sum::<f64>();
        for &s in &run {
            let surfel = &asset.surfels[s];
            if !dark(surfel.position) || sum(e[s]) > 0.0 || sum(surfel.emission) > 0.0 {
                continue;
            }
            unlit += 1;
            let own = &asset.bricks[surfel.brick as usize];
            let offset: [f32; 3] = std::array::from_fn(|a| surfel.position[a] - own.centroid[a]);
            split = split.max(sum(models[surfel.brick as usize].at(offset)));
            let d = pos(s) - mu;
            let at = (0..3).map(|c| (mean[c] + DVec3::from(gradient[c]).dot(d)).max(0.0));
            whole = whole.max(at.sum());
        }
    }
    assert!(
        unlit > 100 && parts > 0,
        "{unlit} unlit surfels, {parts} split bricks"
    );
    assert!(
        split <= 0.5 * median && whole >= 2.0 * median,
        "unlit dark-room surfels read up to {split:e} (split), {whole:e} (one fit), median {median:e}"
    );
}
