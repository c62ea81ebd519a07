//! The error metric every accuracy figure of prt uses (issue "Relight on the CPU and prove
//! accuracy"): for 64 Fibonacci normals per probe, irradiance from both SH sets (clamped at 0);
//! per-probe relative RMS error = RMS difference / mean reference irradiance (all channels);
//! mean, p95 and max over valid probes. Also the largest coefficient difference relative to the
//! reference's |SH0|, the data-equivalence criterion.

use prt_format::directions::fibonacci_directions;
use prt_format::sh::{self, ShRgb, SH_COUNT};

/// Error statistics of one SH set against a reference.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorStats {
    pub probes: usize,
    pub mean: f64,
    pub p95: f64,
    pub max: f64,
    /// Largest `|c_k - ref_k|` over coefficients and channels, divided by the reference probe's
    /// largest `|SH0|` channel.
    pub max_coeff_rel: f64,
}

/// Relative RMS irradiance error of `ours` against `reference` for one probe.
pub fn probe_error(ours: &ShRgb, reference: &ShRgb, normals: &[[f32; 3]]) -> f64 {
    let mut diff2 = 0.0f64;
    let mut sum = 0.0f64;
    for &n in normals {
        let a = sh::irradiance(ours, n);
        let b = sh::irradiance(reference, n);
        for c in 0..3 {
            diff2 += f64::from(a[c] - b[c]).powi(2);
            sum += f64::from(b[c]);
        }
    }
    let count = (normals.len() * 3) as f64;
    let mean = sum / count;
    if mean <= 0.0 {
        return if diff2 > 0.0 { f64::INFINITY } else { 0.0 };
    }
    (diff2 / count).sqrt() / mean
}

/// Largest `|c_k - ref_k|` over coefficients and channels of one probe, divided by the
/// reference's largest `|SH0|` channel: the data-equivalence criterion.
pub fn coefficient_error(ours: &ShRgb, reference: &ShRgb) -> f64 {
    let dc = reference[0].iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let mut worst = 0.0f64;
    for k in 0..SH_COUNT {
        for c in 0..3 {
            let d = f64::from((ours[k][c] - reference[k][c]).abs()) / f64::from(dc.max(1e-30));
            worst = worst.max(d);
        }
    }
    worst
}

/// Compares probes matched by position (within `tolerance` metres); probes of `ours` that are
/// invalid or have no reference are left out.
pub fn compare(
    ours: &[([f32; 3], bool, ShRgb)],
    reference: &[([f32; 3], ShRgb)],
    tolerance: f32,
) -> ErrorStats {
    let normals = fibonacci_directions(64);
    let mut errors = Vec::new();
    let mut max_coeff_rel = 0.0f64;
    for (pos, valid, sh) in ours {
        if !valid {
            continue;
        }
        let Some((_, r)) = reference
            .iter()
            .find(|(p, _)| (0..3).all(|a| (p[a] - pos[a]).abs() <= tolerance))
        else {
            continue;
        };
        errors.push(probe_error(sh, r, &normals));
        max_coeff_rel = max_coeff_rel.max(coefficient_error(sh, r));
    }
    if errors.is_empty() {
        return ErrorStats::default();
    }
    errors.sort_by(f64::total_cmp);
    let p95_index = ((errors.len() as f64 * 0.95).ceil() as usize).clamp(1, errors.len()) - 1;
    ErrorStats {
        probes: errors.len(),
        mean: errors.iter().sum::<f64>() / errors.len() as f64,
        p95: errors[p95_index],
        max: errors[errors.len() - 1],
        max_coeff_rel,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_sets_have_zero_error_and_scaled_sets_their_scale() {
        let c = sh::constant([0.2, 0.3, 0.5]);
        let ours = [([0.0; 3], true, c)];
        let reference = [([0.0; 3], c)];
        assert_eq!(compare(&ours, &reference, 1e-3).mean, 0.0);
        let brighter = [([0.0; 3], true, c.map(|k| k.map(|v| v * 1.1)))];
        let e = compare(&brighter, &reference, 1e-3);
        assert!((e.mean - 0.1).abs() < 0.02, "{e:?}");
        assert!((e.max_coeff_rel - 0.1 * 0.5 / 0.5).abs() < 1e-3, "{e:?}");
    }
}
