//! Scores of the CPU twin's samples at the reference points, as the oracle's `score_surface.py`
//! computes them, so that both give the same numbers (the module docs of `surface` define them);
//! the levels' pocket points are scored apart from the open ones.

use prt_runtime::Sample;

use super::refs::RefPoint;

/// Scores of one sampling against one surface reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointScore {
    pub points: usize,
    /// Points whose `pocket` is false.
    pub open: usize,
    /// Mean and p95 of the relative error (against the reference SH) over the open points.
    pub open_mean: f64,
    pub open_p95: f64,
    /// Open points lit over 1.5x their truth ([`is_over_lit`]).
    pub open_leaks: usize,
    /// Mean relative error over the pocket points, if any.
    pub pocket_mean: Option<f64>,
    /// All points: black where the truth is clearly lit.
    pub black: usize,
    /// All points: no valid probe among the eight (validity 0).
    pub holes: usize,
}

impl PointScore {
    /// Leaking open points, in percent of the open points.
    pub fn leak_percent(&self) -> f64 {
        100.0 * self.open_leaks as f64 / self.open.max(1) as f64
    }
}

pub fn mean_rgb(c: &[f64; 3]) -> f64 {
    (c[0] + c[1] + c[2]) / 3.0
}

/// The leak test of `score_surface.py`, on mean-RGB irradiance: `e` over 1.5x the truth and
/// above it by more than 5% of the median truth (so that dark points' noise does not count).
pub fn is_over_lit(e: f64, truth: f64, median: f64) -> bool {
    e > 1.5 * truth && e - truth > 0.05 * median
}

/// The irradiance the shader shows for each sample: validity 0 counts as black (`E = 0`).
pub fn irradiance(samples: &[Sample]) -> Vec<[f64; 3]> {
    samples
        .iter()
        .map(|s| {
            if s.validity > 0.0 {
                s.irradiance.map(f64::from)
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// Scores `samples` (one per reference point) against `points`. Floor and thresholds use the
/// median and the mean over all points, pockets included, as `score_surface.py` does.
pub fn score_points(points: &[RefPoint], samples: &[Sample]) -> PointScore {
    let e = irradiance(samples);
    let hemi: Vec<f64> = points.iter().map(|p| mean_rgb(&p.e_hemi)).collect();
    let median = percentile(&hemi, 0.5);
    let scene_mean = mean(&hemi);
    let floor = 1e-3 * median;
    let err: Vec<f64> = e
        .iter()
        .zip(points)
        .map(|(e, p)| {
            let diff = (0..3).map(|c| (e[c] - p.e_sh[c]).abs()).sum::<f64>() / 3.0;
            diff / mean_rgb(&p.e_sh).max(floor)
        })
        .collect();
    let of = |pocket: bool| -> Vec<usize> {
        (0..err.len())
            .filter(|&i| points[i].pocket == pocket)
            .collect()
    };
    let (open, pockets) = (of(false), of(true));
    let open_err: Vec<f64> = open.iter().map(|&i| err[i]).collect();
    let pocket_err: Vec<f64> = pockets.iter().map(|&i| err[i]).collect();
    PointScore {
        points: err.len(),
        open: open.len(),
        open_mean: mean(&open_err),
        open_p95: percentile(&open_err, 0.95),
        open_leaks: open
            .iter()
            .filter(|&&i| is_over_lit(mean_rgb(&e[i]), hemi[i], median))
            .count(),
        pocket_mean: (!pocket_err.is_empty()).then(|| mean(&pocket_err)),
        black: (0..err.len())
            .filter(|&i| mean_rgb(&e[i]) < 0.01 * scene_mean && hemi[i] > 0.05 * scene_mean)
            .count(),
        holes: samples.iter().filter(|s| s.validity <= 0.0).count(),
    }
}

/// One CSV line per point (header first): position, normal, pocket flag, the reference's SH
/// and hemispherical irradiance, the lookup's, the relative error and whether it is over-lit,
/// all as [`score_points`] computes them, so that a row of the report can be taken apart.
pub fn points_csv(points: &[RefPoint], samples: &[Sample]) -> String {
    use std::fmt::Write;
    let e = irradiance(samples);
    let hemi: Vec<f64> = points.iter().map(|p| mean_rgb(&p.e_hemi)).collect();
    let median = percentile(&hemi, 0.5);
    let floor = 1e-3 * median;
    let mut csv = String::from("i,x,y,z,nx,ny,nz,pocket,e_sh,e_hemi,e,rel_err,over_lit\n");
    for (i, (p, e)) in points.iter().zip(&e).enumerate() {
        let diff = (0..3).map(|c| (e[c] - p.e_sh[c]).abs()).sum::<f64>() / 3.0;
        let err = diff / mean_rgb(&p.e_sh).max(floor);
        let [x, y, z] = p.position;
        let [nx, ny, nz] = p.normal;
        let _ = writeln!(
            csv,
            "{i},{x},{y},{z},{nx},{ny},{nz},{},{:.6e},{:.6e},{:.6e},{err:.5},{}",
            u8::from(p.pocket),
            mean_rgb(&p.e_sh),
            hemi[i],
            mean_rgb(e),
            u8::from(is_over_lit(mean_rgb(e), hemi[i], median))
        );
    }
    csv
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

/// The `q` quantile with linear interpolation between order statistics (numpy's default).
pub fn percentile(values: &[f64], q: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n => {
            let h = (n - 1) as f64 * q;
            let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
            v[lo] + (h - lo as f64) * (v[hi] - v[lo])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(truth: f64, pocket: bool) -> RefPoint {
        RefPoint {
            position: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
            e_sh: [truth; 3],
            e_hemi: [truth; 3],
            pocket,
        }
    }

    fn sample(e: f32, validity: f32) -> Sample {
        Sample {
            irradiance: [e; 3],
            validity,
            ..Sample::default()
        }
    }

    #[test]
    fn percentile_matches_numpy_linear() {
        let v = [4.0, 1.0, 3.0, 2.0];
        assert_eq!(percentile(&v, 0.5), 2.5);
        assert!((percentile(&v, 0.95) - 3.85).abs() < 1e-12);
        assert_eq!(percentile(&[7.0], 0.95), 7.0);
    }

    #[test]
    fn leaks_black_and_holes_follow_their_thresholds() {
        let points = [point(1.0, false), point(1.0, false), point(0.0, false)];
        // Exact, a hole (black where the truth is lit), and a leak into the dark point.
        let samples = [sample(1.0, 1.0), sample(5.0, 0.0), sample(0.5, 1.0)];
        let s = score_points(&points, &samples);
        assert_eq!((s.open_leaks, s.black, s.holes, s.points), (1, 1, 1, 3));
        // The floor is 1e-3 of the median truth (1).
        assert!((s.open_mean - (0.0 + 1.0 + 0.5 / 1e-3) / 3.0).abs() < 1e-9);
        assert_eq!(s.pocket_mean, None);
        assert!((s.leak_percent() - 100.0 / 3.0).abs() < 1e-9);
    }

    #[test]
    fn pockets_are_scored_apart() {
        let points = [
            point(1.0, false),
            point(1.0, false),
            point(1.0, true),
            point(2.0, false),
        ];
        // The pocket leaks (3x its truth): its error goes to the pocket mean, not the leaks.
        let samples = [
            sample(1.0, 1.0),
            sample(1.5, 1.0),
            sample(3.0, 1.0),
            sample(2.0, 1.0),
        ];
        let s = score_points(&points, &samples);
        assert_eq!((s.open, s.open_leaks), (3, 0));
        assert!((s.open_mean - 0.5 / 3.0).abs() < 1e-12);
        assert_eq!(s.pocket_mean, Some(2.0));
    }
}
