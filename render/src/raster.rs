//! Forward+ stages 1 and 3 (`shaders/render_shade.wgsl`), one render pass each: the depth
//! pre-pass, whose depth buffer the culling stage reads, and the shading pass, which re-draws the
//! scene with a LessEqual test against that depth (no depth writes) so every visible pixel is
//! shaded exactly once (both vertex stages compute `@invariant` clip positions, so the depths
//! compare equal). Each has a culled pipeline for single-sided materials and an unculled one for
//! double-sided materials (docs/conventions.md section 4): the scene's vertices come sorted that
//! way, so each pass is two draws.
//!
//! The four pipelines share one set of bind group layouts, read from the shading WGSL
//! ([`crate::bindings`]); the depth pre-pass's layout holds only the groups `vs_depth` uses.

use crate::bindings::StageBindings;
use crate::layout::Vertex;
use crate::RenderError;

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

/// A pass's entry points in `render_shade.wgsl`; the depth pre-pass has no fragment stage.
#[derive(Clone, Copy)]
struct EntryPoints {
    vertex: &'static str,
    fragment: Option<&'static str>,
}

const DEPTH_PASS: EntryPoints = EntryPoints {
    vertex: "vs_depth",
    fragment: None,
};
const SHADE_PASS: EntryPoints = EntryPoints {
    vertex: "vs_main",
    fragment: Some("fs_main"),
};

impl EntryPoints {
    fn names(self) -> Vec<&'static str> {
        std::iter::once(self.vertex).chain(self.fragment).collect()
    }
}

fn pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    pass: EntryPoints,
    cull: Option<wgpu::Face>,
) -> wgpu::RenderPipeline {
    let depth_pass = pass.fragment.is_none();
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
            entry_point: Some(pass.vertex),
            compilation_options: Default::default(),
            buffers: &[Some(vertex_layout())],
        },
        fragment: pass.fragment.map(|entry_point| wgpu::FragmentState {
            module,
            entry_point: Some(entry_point),
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

/// Both passes: their bindings (read from the shading WGSL, see [`crate::bindings`]) and
/// pipelines.
pub struct Raster {
    pub bindings: StageBindings,
    pub depth: PassPipelines,
    pub shade: PassPipelines,
    /// Bind groups the depth pre-pass sets (groups 0 to this, exclusive); the shading pass sets
    /// every group.
    pub depth_groups: usize,
}

impl Raster {
    pub fn new(device: &wgpu::Device) -> Result<Raster, RenderError> {
        let source = crate::shaders::shade_source();
        let bindings = StageBindings::new(device, "prt-render shade", &source)?;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("prt-render shade"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let make = |pass: EntryPoints| {
            let layout = bindings.pipeline_layout(device, &pass.names());
            PassPipelines {
                culled: pipeline(device, &module, &layout, pass, Some(wgpu::Face::Back)),
                unculled: pipeline(device, &module, &layout, pass, None),
            }
        };
        let depth_groups = bindings.groups_used_by(&DEPTH_PASS.names());
        let depth = make(DEPTH_PASS);
        let shade = make(SHADE_PASS);
        Ok(Raster {
            bindings,
            depth,
            shade,
            depth_groups,
        })
    }
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
