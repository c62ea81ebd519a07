//! Loading light rigs (conventions.md section 3) and their skies.

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
    let text = std::fs::read_to_string(path).map_err(|error| RigLoadError::Io {
        path: path.to_owned(),
        error,
    })?;
    let rig: LightRig = serde_json::from_str(&text).map_err(|e| RigLoadError::Json {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    Lighting::from_rig(rig, path.parent().unwrap_or(Path::new(".")), path)
}
