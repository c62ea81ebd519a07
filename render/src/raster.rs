//! Forward+ stages 1 and 3 (`shaders/render_shade.wgsl`): the depth pre-pass, whose depth buffer
//! the culling stage reads, and the shading pass, which re-draws the scene with a LessEqual test
//! against that depth (no depth writes) so every visible pixel is shaded exactly once. Each has a
//! culled pipeline for single-sided materials and an unculled one for double-sided materials.

use crate::layout::Vertex;

/// Attachments the shading pass writes: radiance (+ lights evaluated in alpha), world position,
/// shading normal. Full float so that tests and `--exr` read exact values.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
pub const TARGETS: usize = 3;

/// The vertex attributes of [`Vertex`] (offsets checked against the struct in a test).
pub const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 6] = [
    attribute(0, wgpu::VertexFormat::Float32x3, 0),
    attribute(1, wgpu::VertexFormat::Uint32, 12),
    attribute(2, wgpu::VertexFormat::Float32x3, 16),
    attribute(3, wgpu::VertexFormat::Float32x2, 32),
    attribute(4, wgpu::VertexFormat::Float32x2, 40),
    attribute(5, wgpu::VertexFormat::Float32x4, 48),
];

const fn attribute(
    location: u32,
    format: wgpu::VertexFormat,
    offset: u64,
) -> wgpu::VertexAttribute {
    wgpu::VertexAttribute {
        format,
        offset,
        shader_location: location,
    }
}

fn vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Vertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &VERTEX_ATTRIBUTES,
    }
}

/// Culled (single-sided) and unculled (double-sided) pipelines of one pass.
pub struct PassPipelines {
    pub culled: wgpu::RenderPipeline,
    pub unculled: wgpu::RenderPipeline,
}

fn pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    depth_pass: bool,
    cull: Option<wgpu::Face>,
) -> wgpu::RenderPipeline {
    let targets: Vec<Option<wgpu::ColorTargetState>> = if depth_pass {
        Vec::new()
    } else {
        (0..TARGETS).map(|_| Some(COLOR_FORMAT.into())).collect()
    };
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(if depth_pass {
            "prt-render depth pre-pass"
        } else {
            "prt-render shade"
        }),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(if depth_pass { "vs_depth" } else { "vs_main" }),
            compilation_options: Default::default(),
            buffers: &[Some(vertex_layout())],
        },
        fragment: (!depth_pass).then(|| wgpu::FragmentState {
            module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &targets,
        }),
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: cull,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(depth_pass),
            depth_compare: Some(if depth_pass {
                wgpu::CompareFunction::Less
            } else {
                wgpu::CompareFunction::LessEqual
            }),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        multiview_mask: None,
        cache: None,
    })
}

/// Both passes' pipelines.
pub fn pipelines(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    depth_layout: &wgpu::PipelineLayout,
    shade_layout: &wgpu::PipelineLayout,
) -> (PassPipelines, PassPipelines) {
    let make = |layout, depth| PassPipelines {
        culled: pipeline(device, module, layout, depth, Some(wgpu::Face::Back)),
        unculled: pipeline(device, module, layout, depth, None),
    };
    (make(depth_layout, true), make(shade_layout, false))
}

/// Draws the scene's two vertex ranges with the matching pipelines.
pub fn draw(pass: &mut wgpu::RenderPass, p: &PassPipelines, single: u32, total: u32) {
    if single > 0 {
        pass.set_pipeline(&p.culled);
        pass.draw(0..single, 0..1);
    }
    if total > single {
        pass.set_pipeline(&p.unculled);
        pass.draw(single..total, 0..1);
    }
}
