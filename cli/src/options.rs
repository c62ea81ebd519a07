//! Option values several commands of `prt` and `prt-bench` take. The `parse_*` functions are
//! clap value parsers: their `String` errors are printed after the option's name.

use anyhow::{bail, Result};
use glam::Vec3;
use prt_render::Camera;

/// Parses a comma-separated list of numbers.
pub fn parse_numbers(s: &str) -> Result<Vec<f32>, String> {
    s.split(',')
        .map(|t| t.trim().parse::<f32>().map_err(|e| format!("{t:?}: {e}")))
        .collect()
}

/// Parses `MINX,MINY,MINZ,MAXX,MAXY,MAXZ`.
pub fn parse_bounds(s: &str) -> Result<[f32; 6], String> {
    let v = parse_numbers(s)?;
    v.try_into()
        .map_err(|v: Vec<f32>| format!("expected 6 comma-separated numbers, got {}", v.len()))
}

/// Parses `X,Y,Z`.
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v = parse_numbers(s)?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Vec3::new(x, y, z)),
        [_, _, _] => Err("coordinates must be finite".into()),
        _ => Err(format!("expected X,Y,Z, got {} numbers", v.len())),
    }
}

/// Parses `WxH`.
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WxH, got {s:?}"))?;
    let parse = |t: &str| t.trim().parse::<u32>().map_err(|e| format!("{t:?}: {e}"));
    Ok((parse(w)?, parse(h)?))
}

/// The camera of `--eye`, `--target` and `--fov` (both or neither of the first two; `None`: the
/// scene's own camera or framing).
pub fn camera_of(
    eye: Option<Vec3>,
    target: Option<Vec3>,
    fov: Option<f32>,
) -> Result<Option<Camera>> {
    Ok(match (eye, target) {
        (Some(eye), Some(target)) => Some(Camera {
            eye,
            target,
            up: Vec3::Y,
            fov_degrees: fov.unwrap_or(prt_render::camera::DEFAULT_FOV),
        }),
        (None, None) => None,
        _ => bail!("--eye and --target go together"),
    })
}

/// `--normal-bias` in probe spacings, or the runtime's default: finite and non-negative.
pub fn normal_bias(arg: Option<f32>) -> Result<f32> {
    let bias = arg.unwrap_or(prt_runtime::LookupSettings::default().normal_bias);
    anyhow::ensure!(
        bias.is_finite() && bias >= 0.0,
        "--normal-bias {bias}: expected a finite number of probe spacings >= 0"
    );
    Ok(bias)
}
