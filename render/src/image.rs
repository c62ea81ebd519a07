//! From linear radiance to files a person opens: exposure, the Khronos PBR Neutral tone mapper
//! (Khronos 3D Commerce, "PBR Neutral", 2024: keeps base colours under light up to 0.8 exactly,
//! compresses highlights towards white), sRGB encoding (IEC 61966-2-1), 8-bit PNG; linear EXR;
//! and the per-tile light-count heat map with its legend.

use std::path::Path;

use crate::RenderError;

/// Khronos PBR Neutral of one linear RGB value.
pub fn pbr_neutral(c: [f32; 3]) -> [f32; 3] {
    const START: f32 = 0.8 - 0.04;
    const DESATURATION: f32 = 0.15;
    let x = c[0].min(c[1]).min(c[2]);
    let offset = if x < 0.08 { x - 6.25 * x * x } else { 0.04 };
    let mut c = c.map(|v| v - offset);
    let peak = c[0].max(c[1]).max(c[2]);
    if peak < START {
        return c;
    }
    let d = 1.0 - START;
    let new_peak = 1.0 - d * d / (peak + d - START);
    c = c.map(|v| v * new_peak / peak);
    let g = 1.0 - 1.0 / (DESATURATION * (peak - new_peak) + 1.0);
    c.map(|v| v + (new_peak - v) * g)
}

/// sRGB encoding of a linear value in [0, 1].
pub fn srgb_encode(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// 8-bit sRGB pixels of linear radiance times `2^exposure_ev`, tone-mapped. Non-finite values
/// show as magenta so that they are never hidden.
pub fn tone_map(radiance: &[[f32; 4]], exposure_ev: f32) -> Vec<[u8; 3]> {
    let scale = exposure_ev.exp2();
    radiance
        .iter()
        .map(|p| {
            if !(p[0].is_finite() && p[1].is_finite() && p[2].is_finite()) {
                return [255, 0, 255];
            }
            let t = pbr_neutral([p[0] * scale, p[1] * scale, p[2] * scale].map(|v| v.max(0.0)));
            t.map(|v| (srgb_encode(v) * 255.0 + 0.5) as u8)
        })
        .collect()
}

/// Writes encoded `bytes` to `path` the project's one way: atomically (temp file, then rename),
/// never over a device or directory (`prt_format::io::write_bytes_atomic`).
fn write_file(path: &Path, bytes: &[u8]) -> Result<(), RenderError> {
    prt_format::io::write_bytes_atomic(path, bytes).map_err(|e| RenderError::Write {
        path: path.to_owned(),
        message: match e {
            prt_format::FormatError::Io { error, .. } => error.to_string(),
            other => other.to_string(),
        },
    })
}

/// Writes an 8-bit sRGB PNG.
pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[[u8; 3]],
) -> Result<(), RenderError> {
    let mut bytes = Vec::new();
    let encoded = (|| {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = enc.write_header()?;
        writer.write_image_data(bytemuck::cast_slice(pixels))?;
        writer.finish()
    })();
    encoded.map_err(|e| RenderError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    write_file(path, &bytes)
}

/// Writes linear RGB radiance as a 32-bit float OpenEXR.
pub fn write_exr(
    path: &Path,
    width: u32,
    height: u32,
    radiance: &[[f32; 4]],
) -> Result<(), RenderError> {
    use exr::prelude::{Image, SpecificChannels, Vec2, WritableImage};
    let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
        let p = radiance[y * width as usize + x];
        (p[0], p[1], p[2])
    });
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_channels((width as usize, height as usize), channels)
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| RenderError::Write {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
    write_file(path, bytes.get_ref())
}

/// A colour ramp from dark blue through green and yellow to red (t in [0, 1]).
fn ramp(t: f32) -> [f32; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [0.05, 0.05, 0.35],
        [0.0, 0.45, 0.85],
        [0.1, 0.75, 0.2],
        [0.95, 0.85, 0.1],
        [0.85, 0.1, 0.05],
    ];
    let x = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f32;
    let i = (x as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    std::array::from_fn(|c| STOPS[i][c] + (STOPS[i + 1][c] - STOPS[i][c]) * f)
}

/// 3x5 glyphs of the legend's characters (bit 2 is the left column).
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'L' => [4, 4, 4, 4, 7],
        'I' => [7, 2, 2, 2, 7],
        'G' => [7, 4, 5, 5, 7],
        'H' => [5, 5, 7, 5, 5],
        'T' => [7, 2, 2, 2, 2],
        'S' => [7, 4, 7, 1, 7],
        'P' => [7, 5, 7, 4, 4],
        'E' => [7, 4, 7, 4, 7],
        'R' => [7, 5, 6, 5, 5],
        'O' => [7, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'F' => [7, 4, 7, 4, 4],
        'W' => [5, 5, 7, 7, 5],
        ':' => [0, 2, 0, 2, 0],
        _ => [0; 5],
    }
}

/// An 8-bit RGB image to draw the legend on.
struct Canvas<'a> {
    img: &'a mut [[u8; 3]],
    width: u32,
    height: u32,
}

impl Canvas<'_> {
    /// Draws `text` with its top-left corner at (x, y), `scale` pixels per glyph dot.
    fn text(&mut self, x: u32, y: u32, scale: u32, text: &str, colour: [u8; 3]) {
        for (i, c) in text.chars().enumerate() {
            let g = glyph(c.to_ascii_uppercase());
            for (row, bits) in g.iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) == 0 {
                        continue;
                    }
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let px = x + (i as u32 * 4 + col) * scale + dx;
                            let py = y + row as u32 * scale + dy;
                            if px < self.width && py < self.height {
                                self.img[(py * self.width + px) as usize] = colour;
                            }
                        }
                    }
                }
            }
        }
    }
}

/// The heat map: each tile's light count on a colour ramp from 0 to the busiest tile, blended
/// over the grey base image (`base`, already tone-mapped), with a legend bar labelled with the
/// counts along the bottom (when the image is at least 64 pixels wide and 32 high). Tiles whose
/// list overflowed (lights dropped) are outlined in white.
pub struct Heatmap<'a> {
    pub width: u32,
    pub height: u32,
    pub tile: u32,
    pub tiles_x: u32,
    /// Count words of the tile lists (`Renderer::read_tile_counts`).
    pub counts: &'a [u32],
}

impl Heatmap<'_> {
    pub fn draw(&self, base: &[[u8; 3]]) -> Vec<[u8; 3]> {
        let (w, h) = (self.width, self.height);
        let count_of = |word: u32| word & !crate::layout::TILE_OVERFLOW;
        let busiest = self
            .counts
            .iter()
            .map(|&c| count_of(c))
            .max()
            .unwrap_or(0)
            .max(1);
        let mut img: Vec<[u8; 3]> = Vec::with_capacity(base.len());
        for y in 0..h {
            for x in 0..w {
                let (tx, ty) = (x / self.tile, y / self.tile);
                let word = self.counts[(ty * self.tiles_x + tx) as usize];
                let count = count_of(word);
                let b = base[(y * w + x) as usize];
                let grey = (f32::from(b[0]) + f32::from(b[1]) + f32::from(b[2])) / (3.0 * 255.0);
                let heat = ramp(count as f32 / busiest as f32);
                let edge = x % self.tile == 0 || y % self.tile == 0;
                let px = if word & crate::layout::TILE_OVERFLOW != 0 && edge {
                    [255; 3]
                } else {
                    heat.map(|c| ((0.7 * c + 0.3 * grey) * 255.0) as u8)
                };
                img.push(px);
            }
        }
        if w >= 64 && h >= 32 {
            self.legend(&mut img, busiest);
        }
        img
    }

    fn legend(&self, img: &mut [[u8; 3]], busiest: u32) {
        let (w, h) = (self.width, self.height);
        let scale = (h / 180).max(1);
        let bar_h = 6 * scale;
        let text_h = 5 * scale;
        let top = h.saturating_sub(bar_h + text_h + 4 * scale);
        for y in top..h {
            for x in 0..w {
                img[(y * w + x) as usize] = [16, 16, 16];
            }
        }
        let margin = 2 * scale;
        let bar_w = w.saturating_sub(2 * margin).max(1);
        for y in top + margin..(top + margin + bar_h).min(h) {
            for x in margin..margin + bar_w {
                let c = ramp((x - margin) as f32 / bar_w as f32);
                img[(y * w + x) as usize] = c.map(|v| (v * 255.0) as u8);
            }
        }
        let text_y = top + margin + bar_h + scale;
        let white = [240; 3];
        let mut canvas = Canvas {
            img,
            width: w,
            height: h,
        };
        canvas.text(margin, text_y, scale, "0", white);
        let mid = format!("{}", busiest / 2);
        canvas.text(margin + bar_w / 2, text_y, scale, &mid, white);
        let max = format!("{busiest}");
        let max_x = (margin + bar_w).saturating_sub(max.len() as u32 * 4 * scale);
        canvas.text(max_x, text_y, scale, &max, white);
        canvas.text(margin + bar_w / 5, text_y, scale, "LIGHTS PER TILE", white);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neutral_keeps_dim_colours_and_compresses_highlights() {
        // Below the compression start only the small toe offset applies.
        let c = pbr_neutral([0.5, 0.3, 0.2]);
        assert!(
            (c[0] - 0.46).abs() < 1e-6 && (c[2] - 0.16).abs() < 1e-6,
            "{c:?}"
        );
        let hi = pbr_neutral([100.0, 100.0, 100.0]);
        assert!(hi.iter().all(|&v| v > 0.99 && v <= 1.0), "{hi:?}");
        assert_eq!(pbr_neutral([0.0; 3]), [0.0; 3]);
    }

    #[test]
    fn srgb_end_points() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_encode(0.2140) - 0.5).abs() < 1e-3);
    }
}
