//! Probe ray tracing: every probe shoots the same N lattice directions; a hit becomes a surfel
//! sample, a miss sets the ray's bit in the probe's sky mask.

use glam::Vec3;
use prt_format::sh::SH_COUNT;
use prt_scene::{texture, Material, Scene};
use rayon::prelude::*;

use crate::accel::bvh::{SceneBvh, TriangleHit};
use crate::accel::bvh8::PACKET;

/// What one probe ray hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Index of the ray in the lattice.
    pub ray: u32,
    pub position: Vec3,
    /// Unit geometric normal facing the probe.
    pub normal: Vec3,
    pub albedo: [f32; 3],
    pub emission: [f32; 3],
    /// A back face of a single-sided surface: black, and evidence of being inside geometry.
    pub backface: bool,
    /// The ray hit the back side of the triangle's winding, whatever the material's sidedness
    /// (inside a closed, outward-wound solid every hit is one, double-sided or not).
    pub facing_away: bool,
    /// A wall stands in the hit's surfel cell between it and the cell's centre
    /// ([`crate::merge::sides`]): the fold keeps such hits apart from the others of the cell.
    pub across: bool,
}

#[cfg(test)]
impl Hit {
    /// A front-facing hit of ray `ray` on a grey (albedo 0.5), unlit surface: the hit the unit
    /// tests of merging, factor rows and visibility maps build their probes from.
    pub(crate) fn grey(ray: u32, position: Vec3, normal: Vec3) -> Hit {
        Hit {
            ray,
            position,
            normal,
            albedo: [0.5; 3],
            emission: [0.0; 3],
            backface: false,
            facing_away: false,
            across: false,
        }
    }
}

/// Everything one probe's rays found.
#[derive(Clone, Debug, Default)]
pub struct ProbeRays {
    pub hits: Vec<Hit>,
    /// The probe's sky mask record ([`prt_format::sky_mask`]): which rays escaped.
    pub sky_mask: Vec<u32>,
    pub sky_transfer: [f32; SH_COUNT],
    pub sky_rays: u32,
    pub backface_rays: u32,
    /// Hits on the back side of their triangle's winding ([`Hit::facing_away`]).
    pub facing_away_rays: u32,
    /// Traced: false for a grid point the placement left out ([`ProbeRays::not_placed`]).
    pub placed: bool,
}

impl ProbeRays {
    /// A grid point the placement left out ([`crate::placement`]): no rays, no data.
    pub fn not_placed() -> ProbeRays {
        ProbeRays::default()
    }
}

/// Shared, read-only inputs of tracing.
pub struct Tracer<'a> {
    pub scene: &'a Scene,
    pub bvh: &'a SceneBvh,
    pub directions: &'a [Vec3],
    /// The SH basis of each direction ([`prt_format::sh::basis`]), evaluated once for every probe.
    pub basis: Vec<[f32; SH_COUNT]>,
    /// The order the lattice is traced in (`coherent_order`).
    pub order: &'a [u32],
    /// Where each ray's bit sits in a sky mask ([`prt_format::sky_mask::sky_positions`]).
    pub sky_positions: &'a [u32],
    pub weight: f32,
    pub double_sided: bool,
    pub srgb: [f32; 256],
    /// Per triangle, its unit geometric normal and material ([`triangle_shading`]).
    pub shading: Vec<TriangleShading>,
}

/// What shading a hit reads of its triangle, side by side in 16 bytes: one cache miss a hit,
/// where two tables (normals, material indices) cost two.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub struct TriangleShading {
    /// Unit geometric normal, zero for a degenerate triangle.
    pub normal: Vec3,
    /// Index into the scene's materials.
    pub material: u32,
}

/// The unit geometric normal of every triangle (zero for a degenerate one) beside its
/// material, computed once for all hits, the same bits as at each hit: shading read the
/// triangle's corners (36 bytes, most of them a cache miss) and took a cross product and a
/// square root at every hit.
pub fn triangle_shading(scene: &Scene) -> Vec<TriangleShading> {
    debug_assert_eq!(scene.triangles.len(), scene.materials_of_triangles.len());
    scene
        .triangles
        .par_iter()
        .zip(&scene.materials_of_triangles)
        .map(|(v, &material)| TriangleShading {
            normal: (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero(),
            material,
        })
        .collect()
}

impl Tracer<'_> {
    /// Traces all lattice directions from `origin`.
    pub fn trace_probe(&self, origin: Vec3) -> ProbeRays {
        let n = self.directions.len();
        let mut out = ProbeRays {
            hits: Vec::with_capacity(n),
            placed: true,
            ..ProbeRays::default()
        };
        // A bit per ray at its sky-order position, encoded once the rays are traced.
        let mut sky = vec![0u32; n.div_ceil(32)];
        for packet in self.order.chunks(PACKET) {
            let mut dirs = [Vec3::ZERO; PACKET];
            for (d, &i) in dirs.iter_mut().zip(packet) {
                *d = self.directions[i as usize];
            }
            let hits = self
                .bvh
                .closest_hits(origin, &dirs[..packet.len()], f32::INFINITY);
            for ((&i, &dir), hit) in packet.iter().zip(&dirs).zip(hits) {
                self.record((&mut out, &mut sky), origin, i as usize, dir, hit);
            }
        }
        out.sky_mask = prt_format::sky_mask::encode(&sky, n as u32);
        out
    }

    /// Adds one ray's hit to `out`, or its miss to `out`'s sky transfer and to its bit in `sky`
    /// (at its sky-order position).
    #[inline]
    fn record(
        &self,
        (out, sky): (&mut ProbeRays, &mut [u32]),
        origin: Vec3,
        i: usize,
        dir: Vec3,
        hit: Option<TriangleHit>,
    ) {
        match hit {
            Some(h) => {
                let hit = self.shade(i as u32, origin, dir, h.triangle as usize, h.t);
                out.backface_rays += u32::from(hit.backface);
                out.facing_away_rays += u32::from(hit.facing_away);
                out.hits.push(hit);
            }
            None => {
                let at = self.sky_positions[i] as usize;
                sky[at / 32] |= 1 << (at % 32);
                out.sky_rays += 1;
                let y = &self.basis[i];
                for k in 0..SH_COUNT {
                    out.sky_transfer[k] += self.weight * y[k];
                }
            }
        }
    }

    fn shade(&self, ray: u32, origin: Vec3, dir: Vec3, tri: usize, t: f32) -> Hit {
        let TriangleShading {
            normal: ng,
            material,
        } = self.shading[tri];
        let material = &self.scene.materials[material as usize];
        let front = ng.dot(dir) < 0.0;
        let position = origin + dir * t;
        let facing = if front { ng } else { -ng };
        if !(front || material.double_sided || self.double_sided) {
            return Hit {
                ray,
                position,
                normal: facing,
                albedo: [0.0; 3],
                emission: [0.0; 3],
                backface: true,
                facing_away: true,
                across: false,
            };
        }
        let (albedo, emission) = self.material_at(material, tri, || {
            barycentric(&self.scene.triangles[tri], position)
        });
        Hit {
            ray,
            position,
            normal: facing,
            albedo,
            emission,
            backface: false,
            facing_away: !front,
            across: false,
        }
    }

    /// Albedo (base colour x texture x COLOR_0) and emission (factor x texture) at the point
    /// of barycentric coordinates `b()`, computed only when something varies over the triangle.
    fn material_at(
        &self,
        m: &Material,
        tri: usize,
        b: impl FnOnce() -> [f32; 3],
    ) -> ([f32; 3], [f32; 3]) {
        if !self.scene.has_vertex_colors && m.base_texture.is_none() && m.emissive_texture.is_none()
        {
            return (m.base_color.map(|a| a.clamp(0.0, 1.0)), m.emissive);
        }
        let b = b();
        let attr = &self.scene.attributes[tri];
        let uv = |set: u32| -> [f32; 2] {
            let uv = attr.uv[(set as usize).min(1)];
            (uv[0] * b[0] + uv[1] * b[1] + uv[2] * b[2]).to_array()
        };
        let color = attr.color[0] * b[0] + attr.color[1] * b[1] + attr.color[2] * b[2];
        let mut albedo = [
            m.base_color[0] * color.x,
            m.base_color[1] * color.y,
            m.base_color[2] * color.z,
        ];
        if let Some(tex) = &m.base_texture {
            if let Some(img) = self.scene.images.get(tex.image) {
                let s = texture::sample(img, tex, uv(tex.tex_coord), &self.srgb);
                albedo = std::array::from_fn(|c| albedo[c] * s[c]);
            }
        }
        let mut emission = m.emissive;
        if let (Some(tex), true) = (&m.emissive_texture, emission.iter().any(|&e| e > 0.0)) {
            if let Some(img) = self.scene.images.get(tex.image) {
                let s = texture::sample(img, tex, uv(tex.tex_coord), &self.srgb);
                emission = std::array::from_fn(|c| emission[c] * s[c]);
            }
        }
        (albedo.map(|a| a.clamp(0.0, 1.0)), emission)
    }
}

/// The lattice's directions in Morton order of their octahedral map: consecutive rays leave a
/// probe in nearby directions and mostly land in the same bricks (the lattice's own order turns
/// by the golden angle, 137.5 degrees, from one ray to the next). Rays are traced in this
/// order, [`PACKET`] consecutive ones to a packet ([`crate::accel::bvh8`]), whose cone it keeps
/// narrow, and their hits merged in it, so that runs of hits fall in one brick. The order
/// changes float sums (sky transfer, surfel means) in their last bits, never which ray hits
/// what.
pub(crate) fn coherent_order(directions: &[Vec3]) -> Vec<u32> {
    morton_order(directions.len() as u32, |i| {
        prt_format::depth::oct_encode(directions[i as usize].to_array())
    })
}

/// The indices `0..count` in Morton (Z) order of `point(i)`, a point of the square `[-1, 1]^2`
/// (ties by index): neighbouring points, consecutive indices. Rays go to packets in it, by
/// their octahedral map ([`coherent_order`]) or by their projection on the disc about a
/// surfel's normal (`crate::sky_terms::spiral_order`).
pub(crate) fn morton_order(count: u32, point: impl Fn(u32) -> [f32; 2]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..count).collect();
    order.sort_by_key(|&i| {
        let [u, v] = point(i);
        (morton_2d(u, v), i)
    });
    order
}

/// The Morton code (Z order) of a point of the square `[-1, 1]^2`, on a 65,536^2 lattice.
fn morton_2d(u: f32, v: f32) -> u32 {
    let q = |x: f32| ((x * 0.5 + 0.5).clamp(0.0, 1.0) * 65535.0) as u32;
    let spread = |mut x: u32| {
        x &= 0xffff;
        x = (x | x << 8) & 0x00ff_00ff;
        x = (x | x << 4) & 0x0f0f_0f0f;
        x = (x | x << 2) & 0x3333_3333;
        (x | x << 1) & 0x5555_5555
    };
    spread(q(u)) | spread(q(v)) << 1
}

/// Barycentric coordinates of `p` (on the triangle's plane).
fn barycentric(v: &[Vec3; 3], p: Vec3) -> [f32; 3] {
    let (e1, e2, vp) = (v[1] - v[0], v[2] - v[0], p - v[0]);
    let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d20, d21) = (vp.dot(e1), vp.dot(e2));
    let denom = d00 * d11 - d01 * d01;
    if denom.abs() <= f32::MIN_POSITIVE {
        return [1.0, 0.0, 0.0];
    }
    let b1 = (d11 * d20 - d01 * d21) / denom;
    let b2 = (d00 * d21 - d01 * d20) / denom;
    [1.0 - b1 - b2, b1, b2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn barycentric_recovers_vertices_and_interpolates() {
        let v = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let b = barycentric(&v, Vec3::new(0.25, 0.5, 0.0));
        assert!(
            (b[0] - 0.25).abs() < 1e-6 && (b[1] - 0.25).abs() < 1e-6 && (b[2] - 0.5).abs() < 1e-6
        );
    }
}
