//! The camera-view score of the levels and Sponza: the CPU twin's irradiance at each pixel's
//! first hit against the oracle's per-pixel reference (`fixtures/levels/refs/L_image.json`,
//! fixtures/levels/README.md; `fixtures/surface/sponza_image.json`, the same format).
//!
//! `prt render` adds `albedo / pi * sample_irradiance(p, n)` at each pixel, and its snippet
//! equals the CPU twin (`prt_runtime::VolumeSampler`), so `E` here, the twin's irradiance at the
//! pixel's first hit with the reference's normal (turned towards the camera), is exactly what
//! `prt render` shows as indirect x pi / albedo there (for the runtime's lookups; the ray
//! references of issue 31 are not in the renderer): the image is scored without a GPU, and
//! without the albedo, which cancels.
//!
//! - rel L1: the sum over hit pixels (status 1) of `|E - e_sh|` over the sum of `e_sh` (mean
//!   RGB): against the reference SH's irradiance, as the points' error;
//! - over-lit pixels: hit pixels where `E > 1.5 e_hemi` and `E - e_hemi` is above 5% of the
//!   median hit pixel's `e_hemi` (mean RGB): the points' leak test, per pixel.

use std::path::Path;

use anyhow::{ensure, Context, Result};
use serde_json::Value;

use super::refs::read_json;
use super::score::{is_over_lit, mean_rgb, percentile};

/// A camera view's reference: its size and its hit pixels.
#[derive(Clone, Debug)]
pub struct View {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Pixel>,
}

/// One hit pixel of the reference.
#[derive(Clone, Debug)]
pub struct Pixel {
    /// Row-major index from the top-left pixel.
    pub index: usize,
    pub position: [f32; 3],
    pub normal: [f32; 3],
    /// Irradiance of the reference SH of incident radiance there.
    pub e_sh: [f64; 3],
    /// Exact hemispherical irradiance.
    pub e_hemi: [f64; 3],
}

/// Scores of one sampling of a camera view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageScore {
    pub rel_l1: f64,
    pub over_lit: usize,
    pub hits: usize,
}

impl ImageScore {
    pub fn over_lit_percent(&self) -> f64 {
        100.0 * self.over_lit as f64 / self.hits.max(1) as f64
    }
}

/// The hit pixels (status 1) of an image reference; sky (0) and back faces (2) have no truth.
pub fn read_image(path: &Path) -> Result<View> {
    let doc = read_json(path)?;
    read_columns(&doc).with_context(|| format!("{}: image reference", path.display()))
}

fn read_columns(doc: &Value) -> Result<View> {
    let size = |key: &str| -> Result<usize> {
        let v = doc.get(key).and_then(Value::as_u64);
        Ok(usize::try_from(
            v.with_context(|| format!("no \"{key}\""))?,
        )?)
    };
    let (width, height) = (size("width")?, size("height")?);
    let n = width
        .checked_mul(height)
        .with_context(|| format!("{width} x {height} pixels overflow"))?;
    let status = column(doc, "status", n, 1)?;
    let [position, normal, e_sh, e_hemi] =
        ["position", "normal", "e_sh", "e_hemi"].map(|key| column(doc, key, n, 3));
    let (position, normal, e_sh, e_hemi) = (position?, normal?, e_sh?, e_hemi?);
    let at = |v: &[f64], i: usize| [v[3 * i], v[3 * i + 1], v[3 * i + 2]];
    let pixels = (0..n)
        .filter(|&i| status[i] == 1.0)
        .map(|i| Pixel {
            index: i,
            position: at(&position, i).map(|c| c as f32),
            normal: at(&normal, i).map(|c| c as f32),
            e_sh: at(&e_sh, i),
            e_hemi: at(&e_hemi, i),
        })
        .collect();
    Ok(View {
        width,
        height,
        pixels,
    })
}

/// The array `key` of `doc`: `per_pixel` numbers for each of `pixels`.
fn column(doc: &Value, key: &str, pixels: usize, per_pixel: usize) -> Result<Vec<f64>> {
    let values = doc
        .get(key)
        .and_then(Value::as_array)
        .with_context(|| format!("no \"{key}\" array"))?;
    ensure!(
        values.len() == pixels * per_pixel,
        "\"{key}\" holds {} values, not {pixels} pixels x {per_pixel}",
        values.len()
    );
    values
        .iter()
        .enumerate()
        .map(|(i, v)| {
            v.as_f64()
                .with_context(|| format!("\"{key}\"[{i}] is not a number"))
        })
        .collect()
}

/// Scores `e` (the irradiance sampled at each pixel of `pixels`) as the module docs say.
pub fn score_image(pixels: &[Pixel], e: &[[f64; 3]]) -> ImageScore {
    let sum = |f: &dyn Fn(usize) -> f64| (0..pixels.len()).map(f).sum::<f64>();
    let diff = sum(&|i| (0..3).map(|c| (e[i][c] - pixels[i].e_sh[c]).abs()).sum());
    let truth = sum(&|i| pixels[i].e_sh.iter().sum());
    let hemi: Vec<f64> = pixels.iter().map(|p| mean_rgb(&p.e_hemi)).collect();
    let median = percentile(&hemi, 0.5);
    ImageScore {
        rel_l1: diff / truth.max(f64::MIN_POSITIVE),
        over_lit: (0..pixels.len())
            .filter(|&i| is_over_lit(mean_rgb(&e[i]), hemi[i], median))
            .count(),
        hits: pixels.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pixel(e_sh: [f64; 3], e_hemi: f64) -> Pixel {
        Pixel {
            index: 0,
            position: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            e_sh,
            e_hemi: [e_hemi; 3],
        }
    }

    #[test]
    fn rel_l1_and_over_lit_on_four_pixels() {
        // Truths (mean RGB e_hemi) 1, 1, 2, 0: median 1.
        let pixels = [
            pixel([1.0, 1.0, 1.0], 1.0),
            pixel([1.0, 2.0, 3.0], 1.0),
            pixel([2.0; 3], 2.0),
            pixel([0.0; 3], 0.0),
        ];
        let e = [
            [1.0, 1.0, 1.0], // exact
            [1.0, 2.0, 0.0], // off by 3 in blue: 1.0 mean, under-lit
            [3.1; 3],        // 1.55x its truth: over-lit
            [0.04; 3],       // over a zero truth, but by less than 5% of the median
        ];
        let s = score_image(&pixels, &e);
        // |E - e_sh| summed: 0 + 3 + 3 x 1.1 + 3 x 0.04 = 6.42, over 3 + 6 + 6 + 0 = 15.
        assert!((s.rel_l1 - 6.42 / 15.0).abs() < 1e-12, "{}", s.rel_l1);
        assert_eq!((s.over_lit, s.hits), (1, 4));
        assert_eq!(s.over_lit_percent(), 25.0);
    }

    #[test]
    fn only_hit_pixels_are_read() {
        let doc = serde_json::json!({
            "width": 2, "height": 1, "status": [2, 1],
            "position": [0, 0, 0, 1, 2, 3], "normal": [0, 0, 0, 0, 1, 0],
            "albedo": [0, 0, 0, 0.5, 0.5, 0.5],
            "e_sh": [0, 0, 0, 4, 5, 6], "e_hemi": [0, 0, 0, 7, 8, 9],
        });
        let view = read_columns(&doc).unwrap();
        assert_eq!((view.width, view.height), (2, 1));
        let pixels = view.pixels;
        assert_eq!((pixels.len(), pixels[0].index), (1, 1));
        assert_eq!(pixels[0].position, [1.0, 2.0, 3.0]);
        assert_eq!(
            (pixels[0].e_sh, pixels[0].e_hemi),
            ([4.0, 5.0, 6.0], [7.0, 8.0, 9.0])
        );
        let short = serde_json::json!({"width": 2, "height": 1, "status": [1]});
        let err = read_columns(&short).unwrap_err().to_string();
        assert!(
            err.contains("\"status\" holds 1 values, not 2 pixels x 1"),
            "{err}"
        );
    }
}
