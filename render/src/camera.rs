//! The view: a pinhole camera from `--eye/--target/--fov`, the glTF's first camera, or a framing
//! of the whole scene; and its matrices (world space of docs/conventions.md section 1:
//! right-handed, +Y up; wgpu's 0..1 depth).

use glam::{Mat4, Vec3};

use crate::RenderError;

/// A perspective camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    /// Approximate up direction (made orthogonal to the view direction).
    pub up: Vec3,
    /// Vertical field of view, degrees.
    pub fov_degrees: f32,
}

/// Vertical field of view, degrees, of the whole-scene framing and of `--eye/--target` views
/// without `--fov`.
pub const DEFAULT_FOV: f32 = 50.0;

impl Camera {
    /// Checks the camera: finite, eye apart from target, fov in (0, 180).
    pub fn validate(&self) -> Result<(), RenderError> {
        let finite = self.eye.is_finite() && self.target.is_finite() && self.up.is_finite();
        if !finite {
            return Err(RenderError::Camera(format!(
                "eye {} / target {} must be finite",
                self.eye, self.target
            )));
        }
        if !(self.fov_degrees > 0.0 && self.fov_degrees < 180.0) {
            return Err(RenderError::Camera(format!(
                "--fov {} must lie in (0, 180) degrees",
                self.fov_degrees
            )));
        }
        let d = self.target - self.eye;
        if d.length()
            <= 1e-6
                * self
                    .eye
                    .abs()
                    .max_element()
                    .max(self.target.abs().max_element())
            || d == Vec3::ZERO
        {
            return Err(RenderError::Camera(format!(
                "--eye {} equals --target {}",
                self.eye, self.target
            )));
        }
        Ok(())
    }

    /// The glTF camera placed by its node.
    pub fn from_gltf(c: &prt_scene::Camera) -> Camera {
        Camera {
            eye: c.eye,
            target: c.eye + c.forward,
            up: c.up,
            fov_degrees: c.yfov.to_degrees(),
        }
    }

    /// A view of the whole box `lo..hi`: from the front (+Z) and a little above, far enough for
    /// the bounding sphere to fit the vertical field of view.
    pub fn framing(lo: Vec3, hi: Vec3) -> Camera {
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-6);
        let distance = radius / (0.5 * DEFAULT_FOV.to_radians()).sin();
        let dir = Vec3::new(0.0, 0.35, 1.0).normalize();
        Camera {
            eye: centre + dir * distance,
            target: centre,
            up: Vec3::Y,
            fov_degrees: DEFAULT_FOV,
        }
    }

    /// The up vector used for the view matrix: `up`, or another axis when `up` is parallel to the
    /// view direction.
    fn safe_up(&self) -> Vec3 {
        let f = (self.target - self.eye).normalize();
        for up in [self.up, Vec3::Y, Vec3::Z, Vec3::X] {
            if up.normalize_or_zero().cross(f).length() > 1e-3 {
                return up.normalize();
            }
        }
        Vec3::Y
    }

    /// World to view.
    pub fn view(&self) -> Mat4 {
        glam::camera::rh::view::look_at_mat4(self.eye, self.target, self.safe_up())
    }

    /// View to clip for `aspect` = width / height; near and far planes enclose the box
    /// `lo..hi` seen from the eye (near = far / 1000, relative to the scene).
    pub fn projection(&self, aspect: f32, lo: Vec3, hi: Vec3) -> Mat4 {
        let far_point = Vec3::new(
            if (self.eye.x - lo.x).abs() > (self.eye.x - hi.x).abs() {
                lo.x
            } else {
                hi.x
            },
            if (self.eye.y - lo.y).abs() > (self.eye.y - hi.y).abs() {
                lo.y
            } else {
                hi.y
            },
            if (self.eye.z - lo.z).abs() > (self.eye.z - hi.z).abs() {
                lo.z
            } else {
                hi.z
            },
        );
        let far = (far_point - self.eye).length().max(1e-6) * 1.01;
        glam::camera::rh::proj::directx::perspective(
            self.fov_degrees.to_radians(),
            aspect,
            far * 1e-3,
            far,
        )
    }
}
