//! Reading a primitive's accessors: positions into world space, indices, per-vertex
//! attributes and the triangle list of its mode. Plain accessors (no sparse values, a buffer
//! view) are read straight from their buffer; any other goes through the glTF reader.

use std::borrow::Cow;

use glam::{Mat4, Vec2, Vec3, Vec4};
use gltf::mesh::Mode;

/// The elements of a plain accessor (no sparse values, a buffer view), `size` bytes each, read
/// as the glTF reader reads them (gltf 1.4 `accessor::util::Iter`: element `i` at `i * stride`
/// of the view, from the accessor's offset), without its per-element dispatch, which dominates
/// reading large index buffers (docs/results/bake_notes.md). `None` for any other accessor and
/// for one that runs past its view or buffer: the caller then asks the reader, for its values
/// or its refusal. ([`crate::check`] has refused a stride below the element and a count of 0
/// before.)
fn plain_elements<'s>(
    a: &gltf::Accessor,
    buffers: &'s [gltf::buffer::Data],
    size: usize,
) -> Option<impl ExactSizeIterator<Item = &'s [u8]>> {
    if a.sparse().is_some() || a.size() != size {
        return None;
    }
    let view = a.view()?;
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return None;
    }
    let buffer = buffers.get(view.buffer().index())?;
    let view_bytes = buffer
        .0
        .get(view.offset()..view.offset().checked_add(view.length())?)?;
    let end = stride
        .checked_mul(a.count().checked_sub(1)?)?
        .checked_add(size)?
        .checked_add(a.offset())?;
    let bytes = view_bytes.get(a.offset()..end)?;
    Some(bytes.chunks(stride).map(move |e| &e[..size]))
}

/// `N` little-endian f32s from the start of `bytes` (at least `4 N` long).
fn le_f32s<const N: usize>(bytes: &[u8]) -> [f32; N] {
    std::array::from_fn(|k| {
        f32::from_le_bytes([
            bytes[4 * k],
            bytes[4 * k + 1],
            bytes[4 * k + 2],
            bytes[4 * k + 3],
        ])
    })
}

/// A plain index accessor's indices ([`plain_elements`]), `None` as there.
fn plain_indices(a: &gltf::Accessor, buffers: &[gltf::buffer::Data]) -> Option<Vec<u32>> {
    use gltf::accessor::DataType;
    Some(match a.data_type() {
        DataType::U8 => plain_elements(a, buffers, 1)?
            .map(|e| u32::from(e[0]))
            .collect(),
        DataType::U16 => plain_elements(a, buffers, 2)?
            .map(|e| u32::from(u16::from_le_bytes([e[0], e[1]])))
            .collect(),
        DataType::U32 => plain_elements(a, buffers, 4)?
            .map(|e| u32::from_le_bytes([e[0], e[1], e[2], e[3]]))
            .collect(),
        _ => return None,
    })
}

/// Per vertex of a primitive: TEXCOORD_0 and TEXCOORD_1, and COLOR_0, where it has them.
pub(super) type VertexAttributes = ([Option<Vec<Vec2>>; 2], Option<Vec<Vec4>>);

/// A primitive's POSITION values placed by `world`: read straight from the buffer when the
/// accessor is plain ([`plain_elements`]), else through the reader.
pub(super) fn world_positions<'a, 's, F>(
    prim: &gltf::Primitive,
    reader: &gltf::mesh::Reader<'a, 's, F>,
    buffers: &[gltf::buffer::Data],
    world: Mat4,
) -> Result<Vec<Vec3>, String>
where
    F: Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    let Some(accessor) = prim.get(&gltf::Semantic::Positions) else {
        return Err("has no POSITION attribute".into());
    };
    let place = |p: [f32; 3]| world.transform_point3(Vec3::from(p));
    if let Some(elements) = plain_elements(&accessor, buffers, 12) {
        return Ok(elements.map(le_f32s::<3>).map(place).collect());
    }
    let read = reader.read_positions().ok_or_else(|| {
        format!(
            "POSITION accessor {} runs past its buffer view or buffer",
            accessor.index()
        )
    })?;
    Ok(read.map(place).collect())
}

/// A primitive's vertex indices (`0..vertex_count` when it has none), each checked against
/// `vertex_count`: read straight from the buffer when the accessor is plain
/// ([`plain_indices`]), else through the reader.
pub(super) fn vertex_indices<'a, 's, F>(
    prim: &gltf::Primitive,
    reader: &gltf::mesh::Reader<'a, 's, F>,
    buffers: &[gltf::buffer::Data],
    vertex_count: usize,
) -> Result<Vec<u32>, String>
where
    F: Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    let indices: Vec<u32> = match prim.indices() {
        Some(a) => match plain_indices(&a, buffers) {
            Some(ix) => ix,
            None => match reader.read_indices() {
                Some(ix) => ix.into_u32().collect(),
                None => {
                    return Err(format!(
                        "index accessor {} runs past its buffer view or buffer",
                        a.index()
                    ))
                }
            },
        },
        None => (0..vertex_count as u32).collect(),
    };
    match indices
        .iter()
        .enumerate()
        .find(|(_, &ix)| ix as usize >= vertex_count)
    {
        Some((i, &ix)) => Err(format!(
            "index {i} is {ix}, but there are only {vertex_count} vertices"
        )),
        None => Ok(indices),
    }
}

/// A primitive's texture coordinates (read only when its material is `textured`; their counts
/// checked either way) and COLOR_0.
pub(super) fn vertex_attributes<'a, 's, F>(
    reader: &gltf::mesh::Reader<'a, 's, F>,
    vertex_count: usize,
    textured: bool,
) -> Result<VertexAttributes, String>
where
    F: Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    let mut uvs = [None, None];
    for (set, uv) in uvs.iter_mut().enumerate() {
        if let Some(t) = reader.read_tex_coords(set as u32) {
            let t = t.into_f32();
            if t.len() != vertex_count {
                return Err(format!("TEXCOORD_{set} count differs from POSITION"));
            }
            if textured {
                *uv = Some(t.map(Vec2::from).collect());
            }
        }
    }
    let colors: Option<Vec<Vec4>> = reader
        .read_colors(0)
        .map(|c| c.into_rgba_f32().map(Vec4::from).collect());
    if colors.as_ref().is_some_and(|c| c.len() != vertex_count) {
        return Err("COLOR_0 count differs from POSITION".into());
    }
    Ok((uvs, colors))
}

/// Triangle list of a primitive in glTF vertex order (spec 3.7.2.1): strips alternate winding so
/// every triangle keeps the orientation of the first; fans share vertex 0. A list is the indices
/// themselves, not a copy (2.2 MB at Sponza).
pub(super) fn triangulate(mode: Mode, ix: &[u32]) -> Cow<'_, [[u32; 3]]> {
    match mode {
        Mode::Triangles => Cow::Borrowed(bytemuck::cast_slice(&ix[..ix.len() / 3 * 3])),
        Mode::TriangleStrip => (0..ix.len().saturating_sub(2))
            .map(|i| {
                if i % 2 == 0 {
                    [ix[i], ix[i + 1], ix[i + 2]]
                } else {
                    [ix[i + 1], ix[i], ix[i + 2]]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..ix.len().saturating_sub(1))
            .map(|i| [ix[i], ix[i + 1], ix[0]])
            .collect(),
        _ => Cow::Borrowed(&[]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_strips_and_fans_follow_gltf_order() {
        assert_eq!(
            triangulate(Mode::Triangles, &[0, 1, 2, 3, 4, 5, 6]),
            vec![[0, 1, 2], [3, 4, 5]]
        );
        assert_eq!(
            triangulate(Mode::TriangleStrip, &[0, 1, 2, 3]),
            vec![[0, 1, 2], [2, 1, 3]]
        );
        assert_eq!(
            triangulate(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![[1, 2, 0], [2, 3, 0]]
        );
    }

    /// The plain accessor path reads what the glTF reader reads: positions interleaved (stride
    /// 20, offset 4), indices of every width at an offset, and a sparse accessor left to the
    /// reader.
    #[test]
    fn plain_accessors_read_as_the_gltf_reader_does() {
        let mut buffer: Vec<u8> = Vec::new();
        for v in 0..4u8 {
            buffer.extend([0xee; 4]);
            for x in [f32::from(v), 0.5 * f32::from(v), -1.25] {
                buffer.extend(x.to_le_bytes());
            }
            buffer.extend([0xdd; 4]);
        }
        buffer.extend([0xcc, 0xcc, 0, 0, 1, 0, 2, 0, 0, 0, 2, 0, 3, 0]); // u16 from 82
        buffer.extend([9, 0, 1, 2, 0, 2, 3, 0, 0, 0]); // u8 from 95, padded
        for i in [0u32, 3, 2, 2, 1, 0] {
            buffer.extend(i.to_le_bytes()); // u32 from 104
        }
        buffer.extend(1u32.to_le_bytes()); // sparse index, from 128
        for x in [7.0f32, 8.0, 9.0] {
            buffer.extend(x.to_le_bytes()); // sparse value, from 132
        }
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
            "meshes":[{{"primitives":[
                {{"attributes":{{"POSITION":0}},"indices":1}},
                {{"attributes":{{"POSITION":0}},"indices":2}},
                {{"attributes":{{"POSITION":4}},"indices":3}}]}}],
            "buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}}],
            "bufferViews":[{{"buffer":0,"byteLength":80,"byteStride":20}},
                {{"buffer":0,"byteOffset":80,"byteLength":14}},
                {{"buffer":0,"byteOffset":94,"byteLength":8}},
                {{"buffer":0,"byteOffset":104,"byteLength":24}},
                {{"buffer":0,"byteOffset":128,"byteLength":4}},
                {{"buffer":0,"byteOffset":132,"byteLength":12}}],
            "accessors":[
                {{"bufferView":0,"byteOffset":4,"componentType":5126,"count":4,"type":"VEC3",
                  "min":[0,0,-1.25],"max":[3,1.5,-1.25]}},
                {{"bufferView":1,"byteOffset":2,"componentType":5123,"count":6,"type":"SCALAR"}},
                {{"bufferView":2,"byteOffset":1,"componentType":5121,"count":6,"type":"SCALAR"}},
                {{"bufferView":3,"componentType":5125,"count":6,"type":"SCALAR"}},
                {{"bufferView":0,"byteOffset":4,"componentType":5126,"count":4,"type":"VEC3",
                  "min":[0,0,-1.25],"max":[7,8,9],
                  "sparse":{{"count":1,"indices":{{"bufferView":4,"componentType":5125}},
                    "values":{{"bufferView":5}}}}}}]}}"#,
            buffer.len(),
            base64::encode(&buffer)
        );
        let (doc, buffers, _) = gltf::import_slice(json.as_bytes()).unwrap();
        let (mut sparse, mut indices) = (0, Vec::new());
        for prim in doc
            .meshes()
            .flat_map(|m| m.primitives().collect::<Vec<_>>())
        {
            let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
            let expected: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
            let a = prim.get(&gltf::Semantic::Positions).unwrap();
            match plain_elements(&a, &buffers, 12) {
                Some(e) => assert_eq!(e.map(le_f32s::<3>).collect::<Vec<_>>(), expected),
                None => {
                    assert!(a.sparse().is_some(), "accessor {}", a.index());
                    assert_eq!(expected[1], [7.0, 8.0, 9.0]);
                    sparse += 1;
                }
            }
            let expected: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
            let got = plain_indices(&prim.indices().unwrap(), &buffers);
            assert_eq!(
                got.as_ref(),
                Some(&expected),
                "{:?}",
                prim.indices().unwrap()
            );
            indices.push(expected);
        }
        assert_eq!(
            indices,
            [[0, 1, 2, 0, 2, 3], [0, 1, 2, 0, 2, 3], [0, 3, 2, 2, 1, 0]]
        );
        assert_eq!(sparse, 1);
    }
}
