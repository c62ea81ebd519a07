//! Loading light rigs (docs/conventions.md section 3) and their skies.

use std::path::{Path, PathBuf};

use prt_format::rig::RigError;
use prt_format::LightRig;

use crate::sky::SkyModel;

/// Why a rig could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum RigLoadError {
    #[error("{path}: cannot read: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: not a light rig: {message}")]
    Json { path: PathBuf, message: String },
    #[error("{path}: {error}")]
    Invalid { path: PathBuf, error: RigError },
    #[error("{path}: sky image {exr}: {message}")]
    Exr {
        path: PathBuf,
        exr: PathBuf,
        message: String,
    },
}

/// A validated rig and its sky, ready to relight with.
#[derive(Clone, Debug)]
pub struct Lighting {
    pub rig: LightRig,
    pub sky: SkyModel,
}

impl Lighting {
    /// Lights of `rig` with its sky; an `exr` sky is resolved relative to `base`.
    pub fn from_rig(rig: LightRig, base: &Path, origin: &Path) -> Result<Lighting, RigLoadError> {
        rig.validate().map_err(|error| RigLoadError::Invalid {
            path: origin.to_owned(),
            error,
        })?;
        let sky = match &rig.sky {
            None => SkyModel::Black,
            Some(s) => match (&s.color, &s.exr) {
                (Some(c), _) => SkyModel::Constant(c.map(|v| v * s.intensity)),
                (None, Some(exr)) => {
                    let file = base.join(exr);
                    SkyModel::load_exr(&file, s.intensity).map_err(|message| RigLoadError::Exr {
                        path: origin.to_owned(),
                        exr: file.clone(),
                        message,
                    })?
                }
                (None, None) => SkyModel::Black,
            },
        };
        Ok(Lighting { rig, sky })
    }
}

/// Reads, parses and validates a rig JSON file.
pub fn load_rig(path: &Path) -> Result<Lighting, RigLoadError> {
    load_rig_with_warnings(path).map(|(lighting, _)| lighting)
}

/// Fields a KHR_lights_punctual light (glTF 2.0 spec, 5.x "extensions", "extras") may carry
/// that a rig accepts without interpreting them (docs/conventions.md section 3).
const IGNORED_LIGHT_FIELDS: [&str; 3] = ["name", "extensions", "extras"];
/// The fields a rig light is read from.
const LIGHT_FIELDS: [&str; 8] = [
    "type",
    "position",
    "direction",
    "color",
    "intensity",
    "range",
    "inner_cone_angle",
    "outer_cone_angle",
];

/// [`load_rig`], plus a warning for every other unknown field of a light (ignored, not refused:
/// a rig written for another tool should still load; a typo in a known field name still shows).
pub fn load_rig_with_warnings(path: &Path) -> Result<(Lighting, Vec<String>), RigLoadError> {
    let io_err = |error| RigLoadError::Io {
        path: path.to_owned(),
        error,
    };
    let bytes = prt_format::read_regular_file(path).map_err(io_err)?;
    let json_err = |e: serde_json::Error| RigLoadError::Json {
        path: path.to_owned(),
        message: e.to_string(),
    };
    let mut value: serde_json::Value = serde_json::from_slice(&bytes).map_err(json_err)?;
    if !value.is_object() {
        return Err(RigLoadError::Json {
            path: path.to_owned(),
            message: format!(
                "expected an object with \"lights\" (and optionally \"sky\"), found {}",
                match value {
                    serde_json::Value::Array(_) => "an array",
                    serde_json::Value::Null => "null",
                    serde_json::Value::Bool(_) => "a boolean",
                    serde_json::Value::Number(_) => "a number",
                    _ => "a string",
                }
            ),
        });
    }
    let mut warnings = Vec::new();
    if let Some(lights) = value.get_mut("lights").and_then(|l| l.as_array_mut()) {
        for (i, light) in lights.iter_mut().enumerate() {
            if let Some(fields) = light.as_object_mut() {
                fields.retain(|key, _| {
                    if LIGHT_FIELDS.contains(&key.as_str()) {
                        return true;
                    }
                    if !IGNORED_LIGHT_FIELDS.contains(&key.as_str()) {
                        warnings.push(format!(
                            "{}: light {i}: unknown field {key:?} ignored",
                            path.display()
                        ));
                    }
                    false
                });
            }
        }
    }
    let rig: LightRig = serde_json::from_value(value).map_err(json_err)?;
    let lighting = Lighting::from_rig(rig, path.parent().unwrap_or(Path::new(".")), path)?;
    Ok((lighting, warnings))
}
