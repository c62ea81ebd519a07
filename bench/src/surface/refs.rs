//! Reading the oracle's surface references (`surface_oracle.py` output): every error names the
//! file and the point at fault.

use std::path::Path;

use anyhow::{bail, Context, Result};
use prt_format::sh::ShRgb;
use serde_json::Value;

/// One reference point: what the oracle measured there.
#[derive(Clone, Debug)]
pub struct RefPoint {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    /// Irradiance of the reference SH at the point (clamped at 0).
    pub e_sh: [f64; 3],
    /// Exact hemispherical irradiance.
    pub e_hemi: [f64; 3],
    /// The truth 10 cm off the surface differs from the truth at 2 mm by more than 1.5x (the
    /// levels' `pocket`; false where the file does not say): a gap narrower than a lookup's
    /// normal offset, scored apart.
    pub pocket: bool,
}

pub struct Reference {
    pub points: Vec<RefPoint>,
    /// The oracle's own time for the whole reference, when recorded.
    pub oracle_seconds: Option<f64>,
}

/// Reads and parses a JSON file.
pub fn read_json(path: &Path) -> Result<Value> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not valid JSON", path.display()))
}

/// Reads a surface reference.
pub fn read_reference(path: &Path) -> Result<Reference> {
    let doc = read_json(path)?;
    let Some(list) = doc.get("points").and_then(Value::as_array) else {
        bail!("{}: no \"points\" array", path.display());
    };
    let points = list
        .iter()
        .enumerate()
        .map(|(i, p)| ref_point(p).with_context(|| format!("{}: point {i}", path.display())))
        .collect::<Result<Vec<_>>>()?;
    if points.is_empty() {
        bail!("{}: no points", path.display());
    }
    Ok(Reference {
        points,
        oracle_seconds: doc.get("seconds").and_then(Value::as_f64),
    })
}

/// `v` as exactly `N` numbers; `what` names it in the error.
fn numbers<const N: usize>(v: Option<&Value>, what: &str) -> Result<[f64; N]> {
    let v: Vec<f64> = v
        .and_then(Value::as_array)
        .map(|a| a.iter().filter_map(Value::as_f64).collect())
        .unwrap_or_default();
    v.try_into()
        .map_err(|_| anyhow::anyhow!("{what} is not {N} numbers"))
}

fn ref_point(p: &Value) -> Result<RefPoint> {
    let vec3 = |key: &str| numbers::<3>(p.get(key), &format!("\"{key}\""));
    let sh_rows = p
        .get("sh")
        .and_then(Value::as_array)
        .filter(|a| a.len() == 9)
        .context("\"sh\" is not 9 [r,g,b] rows")?;
    let mut sh: ShRgb = [[0.0; 3]; 9];
    for (k, row) in sh_rows.iter().enumerate() {
        sh[k] = numbers::<3>(Some(row), &format!("\"sh\"[{k}]"))?.map(|c| c as f32);
    }
    let pocket = match p.get("pocket") {
        None => false,
        Some(v) => v.as_bool().context("\"pocket\" is not true or false")?,
    };
    let normal = vec3("normal")?.map(|c| c as f32);
    Ok(RefPoint {
        position: vec3("position")?.map(|c| c as f32),
        normal,
        e_sh: prt_format::sh::irradiance(&sh, normal).map(f64::from),
        e_hemi: vec3("e_hemi")?,
        pocket,
    })
}
