//! Direct irradiance from punctual lights (docs/conventions.md section 3, KHR_lights_punctual), and
//! the conservative per-brick culling tests that skip a light before any shadow ray is traced.
//!
//! Every formula here has a twin in `shaders/` that must compute the same numbers; the CPU
//! versions are the reference the GPU is tested against.

use glam::Vec3;
use prt_format::{Asset, Brick, Light, LightKind};

use crate::contract::{light_kind_code, GpuLight, GpuNormalBounds, MIN_DISTANCE_SQ};

/// What a merged surfel's inverse square is softened by ([`PreparedLight::irradiance_over`]):
/// `a^2 / 2` for the disk of radius `a` that has a surfel cell's area (`cell_size^2 / pi`).
///
/// A surfel stands for its cell (a probe's rays hit anywhere in it) but is lit at one point, its
/// centroid. Near a point light that point value is far from the cell's mean: Sponza's rig has
/// lights 8 mm from a wall, and at 1.89 m one centroid lay about a centimetre from one, lit
/// 10^4 times its neighbours; its brick's radiance (a mean over its surfels) made the probes
/// that saw it 10x too bright and the surface error 28.9% against 14.5% at 1.5 m. The mean of
/// `h / R^3` over a disk of radius `a` right under a light at height `h` is
/// `2 (1 - h / sqrt(h^2 + a^2)) / a^2`: `2 / a^2` at `h = 0`, `1 / h^2 - 3 a^2 / (4 h^4)` far
/// away; `1 / (h^2 + a^2 / 2)` has both limits. 0 for unmerged bakes (cell size 0), whose
/// surfels are the ray hits themselves, so the exact bake keeps the point value.
pub fn surfel_spread_sq(cell_size: f32) -> f32 {
    cell_size * cell_size / (2.0 * std::f32::consts::PI)
}

/// A light prepared for evaluation: unit direction, premultiplied colour, cone constants.
#[derive(Clone, Copy, Debug)]
pub struct PreparedLight {
    pub kind: LightKind,
    pub position: Vec3,
    /// Unit direction of propagation.
    pub direction: Vec3,
    /// `color * intensity`.
    pub radiant: Vec3,
    /// `1 / range^2`, or 0 without a range.
    pub inv_range_sq: f32,
    pub range: f32,
    pub cos_outer: f32,
    /// `1 / max(1e-3, cos inner - cos outer)` as in the KHR_lights_punctual reference code.
    pub cone_scale: f32,
}

impl PreparedLight {
    pub fn new(l: &Light) -> PreparedLight {
        let cos_outer = l.outer_cone_angle.cos();
        let cos_inner = l.inner_cone_angle.cos();
        PreparedLight {
            kind: l.kind,
            position: Vec3::from(l.position),
            direction: Vec3::from(l.unit_direction()),
            radiant: Vec3::from(l.radiant()),
            inv_range_sq: l.range.map_or(0.0, |r| 1.0 / (r * r)),
            range: l.range.unwrap_or(f32::INFINITY),
            cos_outer,
            cone_scale: 1.0 / (cos_inner - cos_outer).max(1e-3),
        }
    }

    /// Unshadowed irradiance at `p` with unit normal `n`, and the unit direction and distance
    /// towards the light (distance infinite for directional lights).
    #[inline]
    pub fn irradiance(&self, p: Vec3, n: Vec3) -> (Vec3, Vec3, f32) {
        self.irradiance_over(p, n, 0.0)
    }

    /// [`PreparedLight::irradiance`] averaged over a patch around `p`: the inverse square of
    /// a point or spot light softened to `1 / (d^2 + spread_sq)` ([`surfel_spread_sq`]).
    #[inline]
    pub fn irradiance_over(&self, p: Vec3, n: Vec3, spread_sq: f32) -> (Vec3, Vec3, f32) {
        match self.kind {
            LightKind::Directional => {
                let l = -self.direction;
                (self.radiant * n.dot(l).max(0.0), l, f32::INFINITY)
            }
            LightKind::Point | LightKind::Spot => {
                let to_light = self.position - p;
                let d2 = to_light.length_squared();
                let d = d2.sqrt();
                let l = if d > 0.0 { to_light / d } else { Vec3::Y };
                let cos = n.dot(l).max(0.0);
                let x = d2 * self.inv_range_sq;
                let window = (1.0 - x * x).clamp(0.0, 1.0);
                let mut e = cos * window * window / (d2 + spread_sq).max(MIN_DISTANCE_SQ);
                if self.kind == LightKind::Spot {
                    let s = ((self.direction.dot(-l) - self.cos_outer) * self.cone_scale)
                        .clamp(0.0, 1.0);
                    e *= s * s;
                }
                (self.radiant * e, l, d)
            }
        }
    }

    /// Why a light cannot reach any surfel of a brick, tested before any shadow ray.
    pub fn cull(&self, brick: &Brick, normals: &NormalBounds) -> Option<CullReason> {
        let (lo, hi) = (Vec3::from(brick.min), Vec3::from(brick.max));
        if self.radiant.max_element() <= 0.0 {
            return Some(CullReason::Dark);
        }
        match self.kind {
            LightKind::Directional => {
                if max_dot(normals, -self.direction, -self.direction) <= 0.0 {
                    return Some(CullReason::Facing);
                }
            }
            LightKind::Point | LightKind::Spot => {
                let nearest = self.position.clamp(lo, hi);
                if nearest.distance(self.position) >= self.range {
                    return Some(CullReason::Range);
                }
                // Directions from the brick's points to the light span this box.
                if max_dot(normals, self.position - hi, self.position - lo) <= 0.0 {
                    return Some(CullReason::Facing);
                }
                if self.kind == LightKind::Spot {
                    let centre = (lo + hi) * 0.5;
                    let radius = (hi - lo).length() * 0.5;
                    let v = centre - self.position;
                    let dist = v.length();
                    if dist > radius {
                        // Angle between the axis and the centre, minus the sphere's half-angle.
                        let cos_axis = (self.direction.dot(v) / dist).clamp(-1.0, 1.0);
                        let half = (radius / dist).clamp(-1.0, 1.0).asin();
                        if cos_axis.acos() - half >= self.cos_outer.clamp(-1.0, 1.0).acos() {
                            return Some(CullReason::Cone);
                        }
                    }
                }
            }
        }
        None
    }
}

/// Why a light was culled for a brick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CullReason {
    Dark,
    Range,
    Cone,
    Facing,
}

/// Component-wise bounds of a brick's surfel normals.
#[derive(Clone, Copy, Debug)]
pub struct NormalBounds {
    pub min: Vec3,
    pub max: Vec3,
}

/// Per-brick component-wise bounds of surfel normals, for facing culls.
pub fn brick_normal_bounds(asset: &Asset) -> Vec<NormalBounds> {
    asset
        .bricks
        .iter()
        .map(|b| {
            let surfels =
                &asset.surfels[b.first_surfel as usize..(b.first_surfel + b.surfel_count) as usize];
            surfels.iter().fold(
                NormalBounds {
                    min: Vec3::INFINITY,
                    max: Vec3::NEG_INFINITY,
                },
                |nb, s| NormalBounds {
                    min: nb.min.min(Vec3::from(s.normal)),
                    max: nb.max.max(Vec3::from(s.normal)),
                },
            )
        })
        .collect()
}

/// A light as the shaders read it.
impl From<&PreparedLight> for GpuLight {
    fn from(l: &PreparedLight) -> Self {
        GpuLight {
            position: l.position.to_array(),
            kind: light_kind_code(l.kind),
            direction: l.direction.to_array(),
            inv_range_sq: l.inv_range_sq,
            radiant: l.radiant.to_array(),
            cos_outer: l.cos_outer,
            cone_scale: l.cone_scale,
            range: l.range.min(f32::MAX),
            _pad: [0; 2],
        }
    }
}

impl From<&NormalBounds> for GpuNormalBounds {
    fn from(n: &NormalBounds) -> Self {
        GpuNormalBounds {
            min: n.min.to_array(),
            max: n.max.to_array(),
            ..Default::default()
        }
    }
}

/// Upper bound of `dot(n, v)` for n in the normal box and v in the box `[vlo, vhi]`
/// (interval arithmetic per axis).
fn max_dot(n: &NormalBounds, a: Vec3, b: Vec3) -> f32 {
    let (vlo, vhi) = (a.min(b), a.max(b));
    let mut sum = 0.0;
    for i in 0..3 {
        let c = [
            n.min[i] * vlo[i],
            n.min[i] * vhi[i],
            n.max[i] * vlo[i],
            n.max[i] * vhi[i],
        ];
        sum += c.into_iter().fold(f32::NEG_INFINITY, f32::max);
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    fn light(kind: LightKind) -> Light {
        Light {
            kind,
            position: [0.0, 2.0, 0.0],
            direction: [0.0, -1.0, 0.0],
            color: [1.0, 0.9, 0.8],
            intensity: 5.0,
            range: Some(6.0),
            inner_cone_angle: 0.3,
            outer_cone_angle: 0.6,
        }
    }

    #[test]
    fn point_light_matches_fixture_table() {
        // fixtures/README.md, lights.gltf: point light at (0,2,0), I = 5 (1,0.9,0.8), range 6.
        let l = PreparedLight::new(&light(LightKind::Point));
        let (e, _, d) = l.irradiance(Vec3::ZERO, Vec3::Y);
        assert!((d - 2.0).abs() < 1e-6);
        assert!((e.x - 1.21933).abs() < 1e-4, "{e}");
        let (e, _, _) = l.irradiance(Vec3::new(0.0, 0.0, 1.5), Vec3::Y);
        assert!((e.x - 0.60200).abs() < 1e-4, "{e}");
    }

    #[test]
    fn spot_cone_and_directional() {
        let mut s = light(LightKind::Spot);
        s.position = [1.0, 2.0, 0.0];
        s.range = None;
        s.intensity = 10.0;
        s.color = [1.0; 3];
        let l = PreparedLight::new(&s);
        assert!((l.irradiance(Vec3::new(1.0, 0.0, 0.0), Vec3::Y).0.x - 2.5).abs() < 1e-5);
        assert!((l.irradiance(Vec3::ZERO, Vec3::Y).0.x - 0.50528).abs() < 1e-4);
        assert_eq!(l.irradiance(Vec3::new(0.0, 0.0, 1.5), Vec3::Y).0.x, 0.0);
        let mut d = light(LightKind::Directional);
        d.intensity = 2.0;
        d.color = [1.0; 3];
        let l = PreparedLight::new(&d);
        assert!((l.irradiance(Vec3::ZERO, Vec3::Y).0.x - 2.0).abs() < 1e-6);
        assert_eq!(l.irradiance(Vec3::ZERO, -Vec3::Y).0.x, 0.0);
    }

    /// A surfel's softened light is the mean over a disk of its cell's area under a point light
    /// within 25% at heights from a hundredth of the cell up, where the point value at the
    /// disk's centre is off by 50x at a hundredth of the cell (and more closer in); at any
    /// cell size (the softening scales with it).
    #[test]
    fn softened_inverse_square_is_the_mean_over_a_surfel_cell() {
        for cell in [1e-3f32, 0.25, 40.0] {
            let a = cell / std::f32::consts::PI.sqrt();
            for h_over_cell in [0.01f32, 0.1, 0.3, 1.0, 10.0] {
                let h = h_over_cell * cell;
                let l = PreparedLight::new(&Light {
                    position: [0.0, h, 0.0],
                    range: None,
                    color: [1.0; 3],
                    intensity: 1.0,
                    ..light(LightKind::Point)
                });
                // The disk's mean in rings (midpoint rule in r^2: equal areas).
                let rings = 100_000;
                let mean: f64 = (0..rings)
                    .map(|i| {
                        let r = a * ((i as f32 + 0.5) / rings as f32).sqrt();
                        f64::from(l.irradiance(Vec3::new(r, 0.0, 0.0), Vec3::Y).0.x)
                    })
                    .sum::<f64>()
                    / f64::from(rings);
                let soft = l.irradiance_over(Vec3::ZERO, Vec3::Y, surfel_spread_sq(cell));
                let ratio = f64::from(soft.0.x) / mean;
                assert!((0.8..1.25).contains(&ratio), "cell {cell}, h {h}: {ratio}");
                if h_over_cell == 0.01 {
                    let point = f64::from(l.irradiance(Vec3::ZERO, Vec3::Y).0.x);
                    assert!(
                        point > 50.0 * mean,
                        "cell {cell}: point {point}, mean {mean}"
                    );
                }
            }
            let l = PreparedLight::new(&light(LightKind::Point));
            let p = Vec3::new(0.3, 0.0, 0.1);
            assert_eq!(l.irradiance_over(p, Vec3::Y, 0.0), l.irradiance(p, Vec3::Y));
        }
    }

    #[test]
    fn culling_is_conservative() {
        let l = PreparedLight::new(&light(LightKind::Spot));
        let up = NormalBounds {
            min: Vec3::Y,
            max: Vec3::Y,
        };
        let brick = |c: Vec3| Brick {
            min: (c - 0.1).to_array(),
            max: (c + 0.1).to_array(),
            ..Brick::default()
        };
        assert_eq!(l.cull(&brick(Vec3::ZERO), &up), None);
        assert_eq!(
            l.cull(&brick(Vec3::new(0.0, 0.0, 9.0)), &up),
            Some(CullReason::Range)
        );
        assert_eq!(
            l.cull(&brick(Vec3::new(3.0, 0.0, 0.0)), &up),
            Some(CullReason::Cone)
        );
        let down = NormalBounds {
            min: -Vec3::Y,
            max: -Vec3::Y,
        };
        assert_eq!(l.cull(&brick(Vec3::ZERO), &down), Some(CullReason::Facing));
    }
}
