//! Base-colour and emissive textures: decoded 8-bit RGBA, sampled with the glTF sampler's wrap
//! modes and filter, sRGB-decoded to linear (glTF 2.0 spec, section 3.9.2 and 3.8.4).

use gltf::texture::{MagFilter, WrappingMode};

/// A decoded image as 8-bit RGBA (colour channels as stored: sRGB-encoded for colour textures).
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[u8; 4]>,
}

/// How a material samples one image.
#[derive(Clone, Copy, Debug)]
pub struct TextureRef {
    pub image: usize,
    pub tex_coord: u32,
    pub wrap_s: WrappingMode,
    pub wrap_t: WrappingMode,
    pub nearest: bool,
}

/// sRGB transfer function decoded for all 256 byte values (IEC 61966-2-1).
pub fn srgb_to_linear_table() -> [f32; 256] {
    std::array::from_fn(|i| {
        let c = i as f32 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    })
}

impl Image {
    /// Converts the pixel formats gltf decodes to 8-bit RGBA. Float formats are clamped to [0, 1]
    /// and quantised; 16-bit formats keep their high byte.
    pub fn from_gltf(data: &gltf::image::Data) -> Result<Image, String> {
        use gltf::image::Format;
        let (w, h) = (data.width, data.height);
        let n = (w as usize) * (h as usize);
        let p = &data.pixels;
        let f32_at = |i: usize| {
            let b = [p[4 * i], p[4 * i + 1], p[4 * i + 2], p[4 * i + 3]];
            (f32::from_le_bytes(b).clamp(0.0, 1.0) * 255.0 + 0.5) as u8
        };
        let channels = match data.format {
            Format::R8 | Format::R16 => 1,
            Format::R8G8 | Format::R16G16 => 2,
            Format::R8G8B8 | Format::R16G16B16 | Format::R32G32B32FLOAT => 3,
            Format::R8G8B8A8 | Format::R16G16B16A16 | Format::R32G32B32A32FLOAT => 4,
        };
        let bytes_per_channel = match data.format {
            Format::R8 | Format::R8G8 | Format::R8G8B8 | Format::R8G8B8A8 => 1,
            Format::R32G32B32FLOAT | Format::R32G32B32A32FLOAT => 4,
            _ => 2,
        };
        if p.len() != n * channels * bytes_per_channel {
            return Err(format!(
                "{} bytes of pixels for {w}x{h} {:?}",
                p.len(),
                data.format
            ));
        }
        let channel = |texel: usize, c: usize| -> u8 {
            let i = texel * channels + c;
            match bytes_per_channel {
                1 => p[i],
                2 => p[2 * i + 1],
                _ => f32_at(i),
            }
        };
        let texels = (0..n)
            .map(|t| match channels {
                1 => {
                    let v = channel(t, 0);
                    [v, v, v, 255]
                }
                2 => {
                    let v = channel(t, 0);
                    [v, v, v, channel(t, 1)]
                }
                3 => [channel(t, 0), channel(t, 1), channel(t, 2), 255],
                _ => [channel(t, 0), channel(t, 1), channel(t, 2), channel(t, 3)],
            })
            .collect();
        Ok(Image {
            width: w,
            height: h,
            texels,
        })
    }
}

fn wrap(i: i64, n: i64, mode: WrappingMode) -> usize {
    (match mode {
        WrappingMode::Repeat => i.rem_euclid(n),
        WrappingMode::ClampToEdge => i.clamp(0, n - 1),
        WrappingMode::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m >= n {
                2 * n - 1 - m
            } else {
                m
            }
        }
    }) as usize
}

/// Linear RGB of `image` at `uv`, sRGB-decoded through `lut`.
pub fn sample(image: &Image, tex: &TextureRef, uv: [f32; 2], lut: &[f32; 256]) -> [f32; 3] {
    let (w, h) = (i64::from(image.width), i64::from(image.height));
    if w == 0 || h == 0 || !uv[0].is_finite() || !uv[1].is_finite() {
        return [1.0; 3];
    }
    let fetch = |x: i64, y: i64| -> [f32; 3] {
        let t = image.texels[wrap(y, h, tex.wrap_t) * w as usize + wrap(x, w, tex.wrap_s)];
        [lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize]]
    };
    // Clamp huge coordinates so that the float-to-int conversion stays exact.
    let x = (f64::from(uv[0]) * w as f64).clamp(-1e12, 1e12);
    let y = (f64::from(uv[1]) * h as f64).clamp(-1e12, 1e12);
    if tex.nearest {
        return fetch(x.floor() as i64, y.floor() as i64);
    }
    let (x, y) = (x - 0.5, y - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let (a, b) = (fetch(x0, y0), fetch(x0 + 1, y0));
    let (c, d) = (fetch(x0, y0 + 1), fetch(x0 + 1, y0 + 1));
    std::array::from_fn(|i| {
        let top = a[i] + (b[i] - a[i]) * fx;
        let bottom = c[i] + (d[i] - c[i]) * fx;
        top + (bottom - top) * fy
    })
}

/// Whether a sampler asks for nearest-texel magnification.
pub fn is_nearest(filter: Option<MagFilter>) -> bool {
    matches!(filter, Some(MagFilter::Nearest))
}
