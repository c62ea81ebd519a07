//! Light rigs: the lights and sky a probe volume is relit with (docs/conventions.md section 3).
//!
//! One type serves the rig JSON (`--lights FILE`), the KHR_lights_punctual lights a bake keeps as
//! the scene's default rig, and the runtime. Field names are those of KHR_lights_punctual plus
//! `position` / `direction`, so a rig file reads like the glTF extension.

use serde::{Deserialize, Serialize};

/// The kind of a punctual light.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LightKind {
    /// `intensity` (lux) x `color` is the irradiance on a surface facing the light.
    Directional,
    /// `intensity` (candela, taken as W/sr) x `color` is the radiant intensity.
    Point,
    /// A point light times the cone factor `s^2` (KHR_lights_punctual reference falloff).
    Spot,
}

/// A punctual light, KHR_lights_punctual semantics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Light {
    #[serde(rename = "type")]
    pub kind: LightKind,
    /// World position (point, spot).
    #[serde(default)]
    pub position: [f32; 3],
    /// Direction of propagation (directional, spot); need not be normalised, must not be zero.
    #[serde(default = "default_direction")]
    pub direction: [f32; 3],
    #[serde(default = "default_color")]
    pub color: [f32; 3],
    #[serde(default = "default_intensity")]
    pub intensity: f32,
    /// Range of the smooth window `clamp(1 - (d/r)^4, 0, 1)^2`; `None` is pure inverse square.
    #[serde(default)]
    pub range: Option<f32>,
    /// Half-angle (radians) inside which a spot is at full intensity. glTF default 0.
    #[serde(default)]
    pub inner_cone_angle: f32,
    /// Half-angle (radians) beyond which a spot is dark. glTF default pi/4.
    #[serde(default = "default_outer")]
    pub outer_cone_angle: f32,
}

fn default_direction() -> [f32; 3] {
    [0.0, 0.0, -1.0]
}
fn default_color() -> [f32; 3] {
    [1.0; 3]
}
fn default_intensity() -> f32 {
    1.0
}
fn default_outer() -> f32 {
    std::f32::consts::FRAC_PI_4
}

/// The sky seen by rays that escape: a constant radiance or an equirectangular EXR image,
/// times `intensity`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sky {
    #[serde(default)]
    pub color: Option<[f32; 3]>,
    /// Path of an equirectangular EXR, relative to the rig file.
    #[serde(default)]
    pub exr: Option<String>,
    #[serde(default = "default_intensity")]
    pub intensity: f32,
}

/// Lights plus an optional sky (no sky: black).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightRig {
    #[serde(default)]
    pub lights: Vec<Light>,
    #[serde(default)]
    pub sky: Option<Sky>,
}

/// Why a light or sky is not acceptable.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RigError {
    #[error("lights[{index}]: {field} = {value} is not finite")]
    NotFinite {
        index: usize,
        field: &'static str,
        value: String,
    },
    #[error("lights[{index}]: direction {value:?} has zero length")]
    ZeroDirection { index: usize, value: [f32; 3] },
    #[error("lights[{index}]: negative {field} {value}")]
    Negative {
        index: usize,
        field: &'static str,
        value: f32,
    },
    #[error("lights[{index}]: inner_cone_angle {inner} is larger than outer_cone_angle {outer}")]
    InnerBeyondOuter {
        index: usize,
        inner: f32,
        outer: f32,
    },
    #[error("lights[{index}]: outer_cone_angle {outer} is outside (0, pi/2]")]
    OuterOutOfRange { index: usize, outer: f32 },
    #[error("lights[{index}]: range {range} must be positive")]
    Range { index: usize, range: f32 },
    #[error("sky: {0}")]
    Sky(String),
}

impl Light {
    /// Checks the values a light needs to be meaningful; `index` names it in the error.
    pub fn validate(&self, index: usize) -> Result<(), RigError> {
        let finite = |field: &'static str, v: &[f32]| {
            if v.iter().all(|x| x.is_finite()) {
                Ok(())
            } else {
                Err(RigError::NotFinite {
                    index,
                    field,
                    value: format!("{v:?}"),
                })
            }
        };
        finite("position", &self.position)?;
        finite("direction", &self.direction)?;
        finite("color", &self.color)?;
        finite("intensity", &[self.intensity])?;
        finite(
            "cone angles",
            &[self.inner_cone_angle, self.outer_cone_angle],
        )?;
        if self.intensity < 0.0 {
            return Err(RigError::Negative {
                index,
                field: "intensity",
                value: self.intensity,
            });
        }
        if let Some(&c) = self.color.iter().find(|&&c| c < 0.0) {
            return Err(RigError::Negative {
                index,
                field: "color",
                value: c,
            });
        }
        if self.kind != LightKind::Point {
            let d = self.direction;
            if d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= 1e-20 {
                return Err(RigError::ZeroDirection { index, value: d });
            }
        }
        if self.kind == LightKind::Spot {
            let (inner, outer) = (self.inner_cone_angle, self.outer_cone_angle);
            if !(outer > 0.0 && outer <= std::f32::consts::FRAC_PI_2 + 1e-6) {
                return Err(RigError::OuterOutOfRange { index, outer });
            }
            if inner < 0.0 {
                return Err(RigError::Negative {
                    index,
                    field: "inner_cone_angle",
                    value: inner,
                });
            }
            if inner > outer {
                return Err(RigError::InnerBeyondOuter {
                    index,
                    inner,
                    outer,
                });
            }
        }
        if let Some(range) = self.range {
            if !(range > 0.0 && range.is_finite()) {
                return Err(RigError::Range { index, range });
            }
        }
        Ok(())
    }

    /// Unit direction of propagation.
    pub fn unit_direction(&self) -> [f32; 3] {
        let d = self.direction;
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        [d[0] / len, d[1] / len, d[2] / len]
    }

    /// `color * intensity`.
    pub fn radiant(&self) -> [f32; 3] {
        self.color.map(|c| c * self.intensity)
    }
}

impl LightRig {
    /// Validates every light and the sky.
    pub fn validate(&self) -> Result<(), RigError> {
        for (i, l) in self.lights.iter().enumerate() {
            l.validate(i)?;
        }
        if let Some(sky) = &self.sky {
            if !(sky.intensity.is_finite() && sky.intensity >= 0.0) {
                return Err(RigError::Sky(format!(
                    "intensity {} must be finite and non-negative",
                    sky.intensity
                )));
            }
            match (&sky.color, &sky.exr) {
                (Some(_), Some(_)) => {
                    return Err(RigError::Sky("give either color or exr, not both".into()))
                }
                (None, None) => return Err(RigError::Sky("needs color or exr".into())),
                (Some(c), None) if c.iter().any(|v| !v.is_finite() || *v < 0.0) => {
                    return Err(RigError::Sky(format!(
                        "color {c:?} must be finite and non-negative"
                    )))
                }
                _ => {}
            }
        }
        Ok(())
    }
}
