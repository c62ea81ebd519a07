//! What a scene is once read: world-space triangles with their materials and per-vertex
//! attributes, the images they sample, lights and cameras.

use glam::{Vec2, Vec3, Vec4};
use prt_format::Light;

use crate::texture::{Image, TextureRef};

/// Surface description used at ray hits (docs/conventions.md section 4).
#[derive(Clone, Debug)]
pub struct Material {
    pub base_color: [f32; 3],
    pub base_texture: Option<TextureRef>,
    pub emissive: [f32; 3],
    pub emissive_texture: Option<TextureRef>,
    pub double_sided: bool,
}

impl Default for Material {
    /// The glTF default material: white, single-sided, not emissive.
    fn default() -> Self {
        Material {
            base_color: [1.0; 3],
            base_texture: None,
            emissive: [0.0; 3],
            emissive_texture: None,
            double_sided: false,
        }
    }
}

/// Per-vertex attributes of one triangle that shading needs.
#[derive(Clone, Copy, Debug)]
pub struct TriangleAttributes {
    pub uv: [[Vec2; 3]; 2],
    pub color: [Vec4; 3],
}

impl TriangleAttributes {
    /// A triangle without COLOR_0 or texture coordinates.
    pub(crate) const WHITE: TriangleAttributes = TriangleAttributes {
        uv: [[Vec2::ZERO; 3]; 2],
        color: [Vec4::ONE; 3],
    };
}

/// A loaded scene: world-space triangles (front face counter-clockwise), their materials and
/// attributes, the images they sample and the scene's lights.
#[derive(Debug, Default)]
pub struct Scene {
    pub triangles: Vec<[Vec3; 3]>,
    pub materials_of_triangles: Vec<u32>,
    /// Per triangle, or empty when no triangle's shading reads them (no COLOR_0 and no
    /// textured material: Sponza's 187k triangles would write 18 MB for nothing).
    pub attributes: Vec<TriangleAttributes>,
    pub materials: Vec<Material>,
    pub images: Vec<Image>,
    pub lights: Vec<Light>,
    pub degenerate_skipped: u64,
    pub warnings: Vec<String>,
    /// Some primitive has COLOR_0 (else per-hit attributes matter only for textured materials).
    pub has_vertex_colors: bool,
    /// Perspective cameras of the scene's nodes, in node visiting order (renderers default to
    /// the first).
    pub cameras: Vec<Camera>,
}

/// A perspective camera placed by its node (glTF 2.0 spec 3.10: it looks along the node's -Z
/// with +Y up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Unit up direction.
    pub up: Vec3,
    /// Vertical field of view, radians.
    pub yfov: f32,
}

impl Scene {
    /// Axis-aligned bounds of all triangles, `None` when there are none.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut it = self.triangles.iter().flatten();
        let first = *it.next()?;
        Some(it.fold((first, first), |(lo, hi), &v| (lo.min(v), hi.max(v))))
    }
}
