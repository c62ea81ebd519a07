//! Probe placement: a regular grid with probes at cell centres of the bake bounds.
//!
//! Along each axis the grid has `ceil(extent / spacing)` probes (at least one), centred in the
//! bounds, so probes keep about half a spacing away from the bounds' faces (where the walls of a
//! room usually are). Example: bounds x in [-0.9, 0.9], spacing 0.6 gives x = -0.6, 0, 0.6.

use glam::Vec3;
use prt_format::Grid;

use crate::error::BakeError;

/// Default spacing: aims at about 1,000 probes over the bounds, rounded to two significant
/// digits; for flat bounds, a tenth of the longest extent.
pub fn default_spacing(min: Vec3, max: Vec3) -> f32 {
    let e = (max - min).max(Vec3::ZERO);
    let volume = e.x * e.y * e.z;
    let raw = if volume > 1e-9 * e.max_element().powi(3) && volume > 0.0 {
        (volume / 1000.0).cbrt()
    } else {
        e.max_element() / 10.0
    };
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let scale = 10f32.powf(raw.log10().floor() - 1.0);
    (raw / scale).round() * scale
}

/// The grid for `bounds` and `spacing`, or an error when it would exceed `max_probes`.
pub fn grid(min: Vec3, max: Vec3, spacing: f32, max_probes: u64) -> Result<Grid, BakeError> {
    let extent = (max - min).max(Vec3::ZERO);
    let counts = extent
        .to_array()
        .map(|e| ((f64::from(e) / f64::from(spacing) - 1e-4).ceil()).max(1.0) as u64);
    let count = counts
        .iter()
        .try_fold(1u64, |a, &c| a.checked_mul(c))
        .unwrap_or(u64::MAX);
    if count > max_probes || counts.iter().any(|&c| c > u64::from(u32::MAX)) {
        return Err(BakeError::TooManyProbes {
            counts,
            spacing,
            count,
            max: max_probes,
        });
    }
    let centre = (min + max) * 0.5;
    let origin = std::array::from_fn(|a| centre[a] - (counts[a] - 1) as f32 * spacing * 0.5);
    Ok(Grid {
        origin,
        spacing,
        counts: counts.map(|c| c as u32),
    })
}

/// Probe positions in grid order (x fastest, then y, then z).
pub fn positions(grid: &Grid) -> Vec<Vec3> {
    let [nx, ny, nz] = grid.counts;
    let mut out = Vec::with_capacity(grid.probe_count() as usize);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                out.push(Vec3::from(grid.position(i, j, k)));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_cornell_grid() {
        let g = grid(
            Vec3::new(-0.9, 0.1, -0.9),
            Vec3::new(0.9, 1.9, 0.9),
            0.6,
            100,
        )
        .unwrap();
        assert_eq!(g.counts, [3, 3, 3]);
        let p = positions(&g);
        assert!((p[0] - Vec3::new(-0.6, 0.4, -0.6)).length() < 1e-6);
        assert!((p[26] - Vec3::new(0.6, 1.6, 0.6)).length() < 1e-6);
    }

    #[test]
    fn too_many_probes_is_an_error() {
        assert!(grid(Vec3::ZERO, Vec3::splat(100.0), 0.01, 1000).is_err());
    }

    #[test]
    fn default_spacing_is_sensible() {
        let s = default_spacing(Vec3::ZERO, Vec3::splat(10.0));
        assert!((s - 1.0).abs() < 1e-6, "{s}");
        let flat = default_spacing(Vec3::ZERO, Vec3::new(4.0, 0.0, 4.0));
        assert!((flat - 0.4).abs() < 1e-6, "{flat}");
    }
}
