//! Base-colour and emissive textures: decoded to 8-bit RGBA with an allocation limit from their
//! encoded size (`decode_images`, instead of `gltf::import_images`, which decodes whatever
//! dimensions a header claims, up to the image crate's 512 MiB default), sampled with the glTF
//! sampler's wrap modes and filter, sRGB-decoded to linear (glTF 2.0 spec, section 3.9.2 and
//! 3.8.4).

use std::io::Cursor;
use std::path::{Path, PathBuf};

use gltf::texture::{MagFilter, WrappingMode};

use crate::check::allocation_budget;
use crate::error::SceneError;

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

/// Decodes the images materials sample to 8-bit RGBA (16-bit and float channels are converted
/// by the image crate), with its allocation limit set to [`allocation_budget`] of the image's
/// encoded size: a small file that claims a huge image is refused before it is decoded.
pub(crate) fn decode_images(
    path: &Path,
    doc: &gltf::Document,
    files: &[Option<PathBuf>],
    buffers: &[gltf::buffer::Data],
) -> Result<Vec<Image>, SceneError> {
    // Only what the bake samples: base colour and emissive. Normal, occlusion and
    // metallic-roughness maps are never decoded (they could only fail the bake).
    let mut used = vec![false; doc.images().len()];
    for m in doc.materials() {
        let pbr = m.pbr_metallic_roughness();
        let textures = [
            pbr.base_color_texture().map(|t| t.texture()),
            m.emissive_texture().map(|t| t.texture()),
        ];
        for t in textures.into_iter().flatten() {
            if let Some(u) = used.get_mut(t.source().index()) {
                *u = true;
            }
        }
    }
    doc.images()
        .map(|img| {
            if !used[img.index()] {
                return Ok(Image {
                    width: 1,
                    height: 1,
                    texels: vec![[255; 4]],
                });
            }
            let uri = match img.source() {
                gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => uri.to_owned(),
                gltf::image::Source::Uri { .. } => "data URI".to_owned(),
                gltf::image::Source::View { .. } => "buffer view".to_owned(),
            };
            let fail = |message: String| SceneError::Image {
                path: path.to_owned(),
                index: img.index(),
                uri: uri.clone(),
                message,
            };
            let file = files.get(img.index()).and_then(Option::as_deref);
            let (bytes, mime) = encoded_image(&img, file, buffers).map_err(&fail)?;
            decode(&bytes, mime.as_deref()).map_err(&fail)
        })
        .collect()
}

/// The encoded bytes of `img` and its MIME type, if stated: from its checked external `file`,
/// its data URI or its buffer view.
fn encoded_image(
    img: &gltf::Image,
    file: Option<&Path>,
    buffers: &[gltf::buffer::Data],
) -> Result<(Vec<u8>, Option<String>), String> {
    match img.source() {
        gltf::image::Source::Uri { uri, mime_type } => {
            if let Some(file) = file {
                let bytes = prt_format::io::read_regular_file(file)
                    .map_err(|e| format!("{}: {e}", file.display()))?;
                return Ok((bytes, mime_type.map(str::to_owned)));
            }
            let rest = uri
                .strip_prefix("data:")
                .ok_or("its file was not checked")?;
            let (meta, payload) = rest.split_once(',').ok_or("a data URI without a comma")?;
            let Some(mime) = meta.strip_suffix(";base64") else {
                return Err("only base64 data URIs are read".into());
            };
            let bytes = base64::decode(payload).map_err(|e| format!("data URI: base64: {e}"))?;
            let mime = Some(mime).filter(|m| !m.is_empty()).or(mime_type);
            Ok((bytes, mime.map(str::to_owned)))
        }
        gltf::image::Source::View { view, mime_type } => {
            let data = buffers
                .get(view.buffer().index())
                .ok_or("its buffer was not loaded")?;
            let bytes = data
                .0
                .get(view.offset()..view.offset() + view.length())
                .ok_or("its buffer view runs past the buffer")?;
            Ok((bytes.to_vec(), Some(mime_type.to_owned())))
        }
    }
}

fn decode(bytes: &[u8], mime: Option<&str>) -> Result<Image, String> {
    use image::ImageFormat;
    let format = match mime {
        Some("image/png") => ImageFormat::Png,
        Some("image/jpeg") => ImageFormat::Jpeg,
        _ => match image::guess_format(bytes) {
            Ok(f @ (ImageFormat::Png | ImageFormat::Jpeg)) => f,
            _ => return Err(format!("not a PNG or JPEG image (MIME type {mime:?})")),
        },
    };
    let budget = allocation_budget(bytes.len() as u64);
    let reader = image::ImageReader::with_format(Cursor::new(bytes), format);
    let (w, h) = reader.into_dimensions().map_err(|e| e.to_string())?;
    let decoded = u64::from(w) * u64::from(h) * 4;
    if decoded > budget {
        return Err(format!(
            "{w} x {h} pixels would take {decoded} bytes decoded from {} encoded, more than {budget}",
            bytes.len()
        ));
    }
    let mut reader = image::ImageReader::with_format(Cursor::new(bytes), format);
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(budget);
    reader.limits(limits);
    let rgba = reader.decode().map_err(|e| e.to_string())?.to_rgba8();
    Ok(Image {
        width: w,
        height: h,
        texels: rgba.pixels().map(|p| p.0).collect(),
    })
}
