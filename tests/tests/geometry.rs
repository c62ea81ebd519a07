//! Geometry stress (issue 8, "Geometry"): rays through the shared edges and vertices of a closed,
//! watertight box never escape it; sliver, coincident and inverted triangles bake to finite,
//! deterministic assets.

use glam::Vec3;
use prt_bake::accel::bvh::SceneBvh;
use prt_bake::BakeSettings;
use prt_tests::{bake_ok, fixture, rays};

/// Origins inside the 2 m box `closed_box_inward.gltf`.
const ORIGINS: [[f32; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [0.3, -0.2, 0.1],
    [-0.7, 0.6, -0.5],
    [0.9, 0.9, 0.9],
];

/// Rays aimed exactly at every vertex of the box and at 33 points along each of its edges
/// (including each face's diagonal, the edge its two triangles share) from four origins inside
/// it, in the bake's traced frame at three scales: every one hits a triangle. The goal is zero
/// escaping rays: a leak through a shared edge would let sky into a closed room.
#[test]
fn rays_through_edges_and_vertices_of_a_closed_box_never_escape() {
    let scene = prt_scene::load(&fixture("closed_box_inward.gltf"), &Default::default()).unwrap();
    let tris = &scene.triangles;
    let mut targets: Vec<Vec3> = Vec::new();
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            for s in 0..=32 {
                targets.push(a.lerp(b, s as f32 / 32.0));
            }
        }
    }
    let mut escaped = 0;
    let mut tried = 0;
    for scale in [1.0, 1.0 / 1024.0, 1024.0] {
        let bvh = SceneBvh::build(tris, scale);
        for o in ORIGINS.map(Vec3::from) {
            for &t in &targets {
                let d = (t - o).normalize();
                tried += 1;
                if bvh.closest_hit(o, d, f32::INFINITY).is_none() {
                    escaped += 1;
                }
            }
        }
    }
    assert_eq!(
        escaped, 0,
        "{escaped} of {tried} rays escaped the closed box"
    );
}

/// A dense grid of probes inside the closed box, 4096 rays each: no ray reaches the sky.
#[test]
fn no_bake_ray_escapes_a_closed_box() {
    let asset = bake_ok(
        &fixture("closed_box_inward.gltf"),
        &BakeSettings {
            spacing: Some(0.19),
            bounds: Some([-0.95, -0.95, -0.95, 0.95, 0.95, 0.95]),
            ..rays(4096)
        },
    );
    let sky: u64 = asset.probes.iter().map(|p| u64::from(p.sky_rays)).sum();
    assert_eq!(
        sky,
        0,
        "{sky} of {} rays escaped",
        asset.probes.len() * 4096
    );
}

/// The runtime's shadow rays (CPU reference of the GPU traversal) against the asset's own copy of
/// the box's geometry: rays from inside aimed at every vertex and along every edge are occluded.
#[test]
fn shadow_rays_through_edges_are_occluded() {
    let asset = bake_ok(
        &fixture("closed_box_inward.gltf"),
        &BakeSettings {
            spacing: Some(1.0),
            ..rays(32)
        },
    );
    let geo = &asset.geometry;
    let mut blocked = 0;
    let mut tried = 0;
    for t in &geo.triangles {
        let v = [t.v0, t.v1, t.v2].map(Vec3::from);
        for k in 0..3 {
            for s in 0..=32 {
                let target = v[k].lerp(v[(k + 1) % 3], s as f32 / 32.0);
                for o in ORIGINS.map(Vec3::from) {
                    let d = (target - o).normalize();
                    tried += 1;
                    // Far beyond the box: the ray must stop at its wall.
                    if prt_runtime::shadow_rays::occluded(geo, o, d, 10.0) {
                        blocked += 1;
                    }
                }
            }
        }
    }
    assert_eq!(
        blocked,
        tried,
        "{} of {tried} shadow rays passed through the box",
        tried - blocked
    );
}

/// The closed box with extra instances of its own mesh written into the file, as `nodes`.
fn box_with(dir: &std::path::Path, name: &str, extra: serde_json::Value) -> std::path::PathBuf {
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(fixture("closed_box_inward.gltf")).unwrap()).unwrap();
    for node in extra.as_array().unwrap() {
        let nodes = doc["nodes"].as_array_mut().unwrap();
        nodes.push(node.clone());
        let i = nodes.len() - 1;
        doc["scenes"][0]["nodes"]
            .as_array_mut()
            .unwrap()
            .push(i.into());
    }
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
    path
}

/// Coincident triangles (the box instanced twice), an inverted (mirrored) instance on top of it
/// and sliver triangles (an instance squashed to 2 um, inside the box) bake to valid, finite,
/// deterministic assets; the coincident and mirrored copies leave the probes sealed (no sky ray)
/// and their furnace light within 1% of the single box's.
#[test]
fn coincident_inverted_and_sliver_triangles() {
    let dir = prt_tests::ScratchDir::new("geometry-cases");
    let settings = BakeSettings {
        spacing: Some(0.5),
        bounds: Some([-0.5, -0.5, -0.5, 0.5, 0.5, 0.5]),
        ..rays(256)
    };
    let furnace = prt_runtime::load_rig(&fixture("rigs/no_lights.json")).unwrap();
    let relight = |asset: &prt_format::Asset| {
        prt_runtime::CpuRelighter::new(asset)
            .unwrap()
            .relight(&furnace, 1)
            .unwrap()
            .sh
    };
    let single = bake_ok(&fixture("closed_box_inward.gltf"), &settings);
    let reference = relight(&single);
    let cases = [
        ("coincident.gltf", serde_json::json!([{"mesh": 0}])),
        (
            "mirrored.gltf",
            serde_json::json!([{"mesh": 0, "scale": [-1.0, 1.0, 1.0]}]),
        ),
        (
            "sliver.gltf",
            serde_json::json!([{"mesh": 0, "scale": [0.3, 1e-6, 0.3], "translation": [0.0, 0.25, 0.0]}]),
        ),
    ];
    for (name, extra) in cases {
        let path = box_with(dir.path(), name, extra);
        let asset = bake_ok(&path, &settings);
        let again = bake_ok(
            &path,
            &BakeSettings {
                threads: Some(1),
                ..settings.clone()
            },
        );
        assert!(
            prt_format::encode(&asset).unwrap() == prt_format::encode(&again).unwrap(),
            "{name}: not deterministic"
        );
        let sh = relight(&asset);
        assert!(
            sh.iter().flatten().flatten().all(|v| v.is_finite()),
            "{name}"
        );
        if name != "sliver.gltf" {
            let sky: u32 = asset.probes.iter().map(|p| p.sky_rays).sum();
            assert_eq!(sky, 0, "{name}: rays escaped");
            for (a, b) in sh.iter().zip(&reference) {
                let rel = (a[0][0] - b[0][0]).abs() / b[0][0];
                assert!(rel < 0.01, "{name}: SH0 {} vs {}", a[0][0], b[0][0]);
            }
        }
    }
}
