//! Geometry stress (issue 8, "Geometry"): rays through the shared edges and vertices of a closed,
//! watertight box never escape it; sliver, coincident and inverted triangles bake to finite,
//! deterministic assets.

use glam::Vec3;
use prt_bake::bvh::SceneBvh;
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
    let scene = prt_bake::scene::load(&fixture("closed_box_inward.gltf")).unwrap();
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
                if bvh.closest_hit(o, d).is_none() {
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
                    if prt_runtime::visibility::occluded(geo, o, d, 10.0) {
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
