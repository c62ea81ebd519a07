//! Pictures of the camera views (`prt-bench surface --pictures DIR`): what a person would look
//! at instead of the rel L1 and over-lit columns. One PNG per level, spacing and lookup, three
//! panels side by side:
//!
//! 1. the reference's irradiance (`e_sh`, the oracle's SH at each hit pixel);
//! 2. the lookup's irradiance `E` at the same pixels, with the same exposure;
//! 3. where they disagree: red where the pixel is over-lit by the points' leak test (`E > 1.5
//!    e_hemi` and by over 5% of the median), blue where under-lit by the mirror test (`E <
//!    e_hemi / 1.5` and by over 5% of the median), the reference in grey elsewhere.
//!
//! Irradiance is shown, not shaded colour: albedo and direct light would hide the indirect
//! light the benchmark is about. Exposure: `1 - exp(-E / median)` (the median hit pixel's
//! reference maps to 63%), then the sRGB curve. Sky and back faces are black.

use std::path::Path;

use anyhow::{Context, Result};

use super::image::View;
use super::score::{is_over_lit, mean_rgb, percentile};

/// Writes `dir/name.png`: the three panels of `view` sampled as `e` (one per hit pixel).
pub fn write(dir: &Path, name: &str, view: &View, e: &[[f64; 3]]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let (w, h) = (view.width, view.height);
    let hemi: Vec<f64> = view.pixels.iter().map(|p| mean_rgb(&p.e_hemi)).collect();
    let median = percentile(&hemi, 0.5).max(f64::MIN_POSITIVE);
    let tone = |v: [f64; 3]| v.map(|c| srgb(1.0 - (-c.max(0.0) / median).exp()));
    let mut out = vec![[0u8; 3]; 3 * w * h];
    for (i, p) in view.pixels.iter().enumerate() {
        let (x, y) = (p.index % w, p.index / w);
        let row = y * 3 * w;
        out[row + x] = tone(p.e_sh);
        out[row + w + x] = tone(e[i]);
        let (got, truth) = (mean_rgb(&e[i]), hemi[i]);
        out[row + 2 * w + x] = if is_over_lit(got, truth, median) {
            [230, 40, 30]
        } else if is_over_lit(truth, got, median) {
            [40, 90, 230]
        } else {
            let g = tone([truth; 3])[0] / 2;
            [g, g, g]
        };
    }
    let path = dir.join(format!("{name}.png"));
    prt_render::image::write_png(&path, 3 * w as u32, h as u32, &out)
        .with_context(|| format!("writing {}", path.display()))
}

/// Linear [0, 1] to an 8-bit sRGB value.
fn srgb(v: f64) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::image::Pixel;

    /// A 2x1 view: an exact pixel (grey in the third panel) and an over-lit one (red).
    #[test]
    fn panels_and_colours() {
        let pixel = |index, e: f64| Pixel {
            index,
            position: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
            e_sh: [e; 3],
            e_hemi: [e; 3],
        };
        let view = View {
            width: 2,
            height: 1,
            pixels: vec![pixel(0, 1.0), pixel(1, 1.0)],
        };
        let dir = std::env::temp_dir().join(format!("prt-pictures-{}", std::process::id()));
        write(&dir, "t", &view, &[[1.0; 3], [2.0; 3]]).unwrap();
        let decoder = png::Decoder::new(std::io::BufReader::new(
            std::fs::File::open(dir.join("t.png")).unwrap(),
        ));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut buf).unwrap();
        let px = |i: usize| [buf[3 * i], buf[3 * i + 1], buf[3 * i + 2]];
        assert_eq!((reader.info().width, reader.info().height), (6, 1));
        assert_eq!(
            px(0),
            px(2),
            "the exact pixel looks the same in both panels"
        );
        assert!(px(3)[0] > px(1)[0], "the over-lit pixel is brighter");
        assert_eq!(px(5), [230, 40, 30]);
        let g = px(4);
        assert!(g[0] == g[1] && g[1] == g[2], "{g:?}");
        std::fs::remove_dir_all(dir).unwrap();
    }
}
