//! Probe placement: a regular grid whose outer probes lie on the faces of the bake bounds.
//!
//! Along each axis the bounds' extent is cut into `ceil(extent / spacing)` equal steps (at most
//! the spacing asked for), giving one more probe than steps, the first and last on the bounds'
//! faces; a flat axis (under [`FLAT_STEPS`] spacings) gets one probe in the middle. Example: bounds x in [-0.9, 0.9] at spacing
//! 0.5 gives 4 steps of 0.45: x = -0.9, -0.45, 0, 0.45, 0.9. `BakeSettings::grid_shift` moves
//! the layers down by a share of a step and adds one past the bounds (a flat axis keeps its
//! one): the same steps at another phase, for measuring what the phase does.
//!
//! Why on the faces: the bounds' faces are usually where a level's outer walls, floor and ceiling
//! are, and those surfaces are much of what a renderer shades. A layer of probes on a wall is
//! moved just off it (`offset::SURFACE_OFFSET`), where it sees what the wall sees, and a point on
//! the wall interpolates between that layer and the next. With probes at cell centres (half a
//! spacing from the wall, the previous placement), a wall point was extrapolated from probes that
//! see the room from inside it: the Cornell ceiling next to its light, seen from 0.1 m below, came
//! out at half its irradiance. Steps per axis rather than one step, so that the outer layers land
//! on every face: with one step, a layer that ends up a fraction of a step outside a wall sees
//! only the wall's back and has to be filled from inside. On the faces, `prt-bench surface`
//! measures about half the mean error of cell centres on Cornell.

use glam::Vec3;
use prt_format::Grid;

use crate::error::BakeError;

/// Probes the default spacing aims at over a volume. Chosen with `prt-bench frontier` on the
/// level family's tuning seeds (docs/results/frontier.md): density, not the lookup, is what
/// lowers the surface error between probes. At 4,000 probes (0.63x the spacing of 1,000) and
/// surfel cells of an eighth of the spacing (`BakeSettings::cells_per_spacing`) the median
/// level measured 6.9% against 9.4% at 1,000 probes and a twelfth, the worst 10.0% against
/// 11.9%, the worst leaks 0.7% against 1.0%, at 1.9x the runtime bytes (40.5 MB against
/// 21.7 MB, the median level) and 1.5x the bake time; 2,000 probes measured as 1,000 did at a
/// sixth, but left fixtures/two_rooms' shared wall halfway between two layers (14.4% against
/// 8.4%).
pub const DEFAULT_PROBES: f32 = 4000.0;

/// Default spacing: aims at about [`DEFAULT_PROBES`] probes over the bounds, rounded to two
/// significant digits; for flat bounds, a tenth of the longest extent.
pub fn default_spacing(min: Vec3, max: Vec3) -> f32 {
    let e = (max - min).max(Vec3::ZERO);
    let volume = e.x * e.y * e.z;
    let raw = if volume > 1e-9 * e.max_element().powi(3) && volume > 0.0 {
        (volume / DEFAULT_PROBES).cbrt()
    } else {
        e.max_element() / 10.0
    };
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let scale = 10f32.powf(raw.log10().floor() - 1.0);
    (raw / scale).round() * scale
}

/// An axis whose extent is below this many spacings is flat: one probe, in the middle (two
/// layers closer than a quarter spacing would see the same light).
pub const FLAT_STEPS: f64 = 0.25;

/// The grid for `bounds` and `spacing`, its layers moved down by `shift` steps
/// (`crate::BakeSettings::grid_shift`), or an error when it would exceed `max_probes`.
pub fn grid(
    (min, max): (Vec3, Vec3),
    (spacing, shift): (f32, [f32; 3]),
    max_probes: u64,
) -> Result<Grid, BakeError> {
    let extent = (max - min).max(Vec3::ZERO);
    // A shifted axis has one layer more for the same steps.
    let extra = shift.map(|s| u64::from(s > 0.0));
    let counts: [u64; 3] = std::array::from_fn(|a| {
        let steps = f64::from(extent[a]) / f64::from(spacing);
        if steps < FLAT_STEPS {
            1
        } else {
            let layers = ((steps - 1e-4).ceil().max(1.0) as u64).saturating_add(1);
            layers.saturating_add(extra[a])
        }
    });
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
    let step: [f32; 3] = std::array::from_fn(|a| {
        if counts[a] > 1 {
            let steps = counts[a] - 1 - extra[a];
            ((f64::from(extent[a]) / steps as f64) as f32).min(spacing)
        } else {
            spacing
        }
    });
    let origin = std::array::from_fn(|a| match counts[a] > 1 {
        true => min[a] - shift[a] * step[a],
        false => centre[a],
    });
    Ok(Grid {
        origin,
        spacing,
        step,
        counts: counts.map(|c| c as u32),
    })
}

/// Probe positions in grid order (x fastest, then y, then z).
pub(crate) fn positions(grid: &Grid) -> Vec<Vec3> {
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
        let bounds = (Vec3::new(-0.9, 0.1, -0.9), Vec3::new(0.9, 1.9, 0.9));
        let g = grid(bounds, (0.6, [0.0; 3]), 100).unwrap();
        assert_eq!(g.counts, [4, 4, 4]);
        let p = positions(&g);
        assert!((p[0] - Vec3::new(-0.9, 0.1, -0.9)).length() < 1e-6);
        assert!((p[63] - Vec3::new(0.9, 1.9, 0.9)).length() < 1e-6);
    }

    #[test]
    fn outer_probes_lie_on_the_bounds_faces() {
        // x: extent 1.0 at spacing 0.3 is 4 steps of 0.25; y is flat; z: 0.6 is 2 steps of 0.3.
        let bounds = (Vec3::ZERO, Vec3::new(1.0, 0.0, 0.6));
        let g = grid(bounds, (0.3, [0.0; 3]), 100).unwrap();
        assert_eq!(g.counts, [5, 1, 3]);
        assert_eq!(g.step, [0.25, 0.3, 0.3]);
        let p = positions(&g);
        assert!((p[0] - Vec3::ZERO).length() < 1e-6, "{}", p[0]);
        assert!(
            (p[1] - Vec3::new(0.25, 0.0, 0.0)).length() < 1e-6,
            "{}",
            p[1]
        );
        assert!(
            (p[14] - Vec3::new(1.0, 0.0, 0.6)).length() < 1e-6,
            "{}",
            p[14]
        );
    }

    /// A shift moves the layers by its share of a step and adds one past the maximum: the
    /// same steps, every point of the bounds still between two layers; a flat axis keeps its
    /// single layer in the middle.
    #[test]
    fn a_shifted_grid_keeps_its_steps() {
        let bounds = (Vec3::ZERO, Vec3::new(1.0, 0.0, 0.6));
        let g = grid(bounds, (0.3, [0.4, 0.5, 0.0]), 100).unwrap();
        assert_eq!(g.counts, [6, 1, 3]);
        assert_eq!(g.step, [0.25, 0.3, 0.3]);
        let p = positions(&g);
        assert!(
            (p[0] - Vec3::new(-0.1, 0.0, 0.0)).length() < 1e-6,
            "{}",
            p[0]
        );
        assert!(
            (p[17] - Vec3::new(1.15, 0.0, 0.6)).length() < 1e-6,
            "{}",
            p[17]
        );
    }

    #[test]
    fn too_many_probes_is_an_error() {
        let bounds = (Vec3::ZERO, Vec3::splat(100.0));
        assert!(grid(bounds, (0.01, [0.0; 3]), 1000).is_err());
    }

    #[test]
    fn default_spacing_is_sensible() {
        // 10 m cube: 1000 / 4000 m^3 per probe, 0.63 m.
        let s = default_spacing(Vec3::ZERO, Vec3::splat(10.0));
        assert!((s - 0.63).abs() < 1e-6, "{s}");
        let flat = default_spacing(Vec3::ZERO, Vec3::new(4.0, 0.0, 4.0));
        assert!((flat - 0.4).abs() < 1e-6, "{flat}");
    }
}
