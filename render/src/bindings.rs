//! Bind group layouts and bind groups read from the WGSL: no binding number is written in Rust.
//!
//! Each stage's assembled source declares its bindings (`@group(g) @binding(b) var ... name`).
//! [`StageBindings::new`] reads them with naga: the binding type each declaration implies and the
//! shader stages whose entry points use it, one bind group layout per group. Bind groups are
//! then filled by variable name ([`Resource::of`]), as the runtime fills its own
//! (`prt_runtime::gpu::stages`), so a shader can renumber, reorder or move its bindings without
//! a Rust change, and a unit test checks every name against [`Resource::of`].
//!
//! The runtime lets wgpu derive each compute pipeline's layout from its shader; the renderer
//! builds explicit layouts instead because its four raster pipelines (depth pre-pass and
//! shading, each culled and unculled) share bind groups, and a layout wgpu derives belongs to
//! the one pipeline it came from.

use crate::RenderError;

/// One resource variable a stage's WGSL declares.
#[derive(Clone, Debug, PartialEq)]
pub struct Declared {
    pub group: u32,
    pub binding: u32,
    pub name: String,
    pub ty: wgpu::BindingType,
    /// The shader stages of the entry points that use it.
    pub visibility: wgpu::ShaderStages,
    /// The entry points that use it.
    pub used_by: Vec<String>,
}

/// A resource of the renderer, by the WGSL variable name that binds it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Resource {
    Frame,
    DirectionalLights,
    /// The point and spot lights, in rig order.
    Lights,
    TileLists,
    CullStats,
    /// The depth pre-pass's depth buffer.
    Depth,
    Materials,
    Images,
    Texels,
    BvhNodes,
    BvhTriangles,
}

impl Resource {
    /// The resource a WGSL variable named `name` binds to (the runtime's snippet binds its own).
    pub fn of(name: &str) -> Option<Resource> {
        Some(match name {
            "frame" => Resource::Frame,
            "directional_lights" => Resource::DirectionalLights,
            "lights" => Resource::Lights,
            "tile_lists" => Resource::TileLists,
            "stats" => Resource::CullStats,
            "depth_tex" => Resource::Depth,
            "materials" => Resource::Materials,
            "images" => Resource::Images,
            "texels" => Resource::Texels,
            "bvh_nodes" => Resource::BvhNodes,
            "triangles" => Resource::BvhTriangles,
            _ => return None,
        })
    }
}

/// The naga module of `source` and its validation info.
fn parse(
    label: &'static str,
    source: &str,
) -> Result<(naga::Module, naga::valid::ModuleInfo), RenderError> {
    let err = |message| RenderError::Shader { label, message };
    let module = naga::front::wgsl::parse_str(source).map_err(|e| err(e.emit_to_string(source)))?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| err(e.emit_to_string(source)))?;
    Ok((module, info))
}

/// The binding type a declaration implies: storage buffers are read-only unless the WGSL may
/// store to them, float textures are filterable (the volume's are sampled trilinearly) and
/// samplers filtering unless they compare. `None` for a kind the renderer does not use.
fn binding_type(space: naga::AddressSpace, inner: &naga::TypeInner) -> Option<wgpu::BindingType> {
    use naga::{AddressSpace as Space, ImageClass, ScalarKind, TypeInner};
    let buffer = |ty| wgpu::BindingType::Buffer {
        ty,
        has_dynamic_offset: false,
        min_binding_size: None,
    };
    Some(match (space, inner) {
        (Space::Uniform, _) => buffer(wgpu::BufferBindingType::Uniform),
        (Space::Storage { access }, _) => buffer(wgpu::BufferBindingType::Storage {
            read_only: !access.contains(naga::StorageAccess::STORE),
        }),
        (Space::Handle, TypeInner::Sampler { comparison }) => {
            wgpu::BindingType::Sampler(if *comparison {
                wgpu::SamplerBindingType::Comparison
            } else {
                wgpu::SamplerBindingType::Filtering
            })
        }
        (
            Space::Handle,
            TypeInner::Image {
                dim,
                arrayed,
                class,
            },
        ) => {
            let view_dimension = match (dim, arrayed) {
                (naga::ImageDimension::D1, false) => wgpu::TextureViewDimension::D1,
                (naga::ImageDimension::D2, false) => wgpu::TextureViewDimension::D2,
                (naga::ImageDimension::D2, true) => wgpu::TextureViewDimension::D2Array,
                (naga::ImageDimension::D3, false) => wgpu::TextureViewDimension::D3,
                (naga::ImageDimension::Cube, false) => wgpu::TextureViewDimension::Cube,
                (naga::ImageDimension::Cube, true) => wgpu::TextureViewDimension::CubeArray,
                _ => return None,
            };
            let (sample_type, multisampled) = match class {
                ImageClass::Depth { multi } => (wgpu::TextureSampleType::Depth, *multi),
                ImageClass::Sampled { kind, multi } => (
                    match kind {
                        ScalarKind::Float => wgpu::TextureSampleType::Float { filterable: true },
                        ScalarKind::Sint => wgpu::TextureSampleType::Sint,
                        ScalarKind::Uint => wgpu::TextureSampleType::Uint,
                        _ => return None,
                    },
                    *multi,
                ),
                _ => return None,
            };
            wgpu::BindingType::Texture {
                sample_type,
                view_dimension,
                multisampled,
            }
        }
        _ => return None,
    })
}

fn shader_stage(stage: naga::ShaderStage) -> wgpu::ShaderStages {
    match stage {
        naga::ShaderStage::Vertex => wgpu::ShaderStages::VERTEX,
        naga::ShaderStage::Fragment => wgpu::ShaderStages::FRAGMENT,
        naga::ShaderStage::Compute => wgpu::ShaderStages::COMPUTE,
        _ => wgpu::ShaderStages::NONE,
    }
}

/// Every resource variable `source` declares and one of its entry points uses, sorted by group
/// and binding. Unused ones are left out: the shared preludes declare bindings some stages never
/// touch (the culling stage includes the shadow-ray traversal's BVH), and those need no resource.
pub fn reflect(label: &'static str, source: &str) -> Result<Vec<Declared>, RenderError> {
    let (module, info) = parse(label, source)?;
    let mut declared = Vec::new();
    for (handle, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let mut visibility = wgpu::ShaderStages::NONE;
        let mut used_by = Vec::new();
        for (i, entry) in module.entry_points.iter().enumerate() {
            if !info.get_entry_point(i)[handle].is_empty() {
                visibility |= shader_stage(entry.stage);
                used_by.push(entry.name.clone());
            }
        }
        if used_by.is_empty() {
            continue;
        }
        let name = var.name.clone().unwrap_or_default();
        let ty = binding_type(var.space, &module.types[var.ty].inner).ok_or_else(|| {
            RenderError::Shader {
                label,
                message: format!("`{name}` is a kind of binding the renderer does not make"),
            }
        })?;
        declared.push(Declared {
            group: rb.group,
            binding: rb.binding,
            name,
            ty,
            visibility,
            used_by,
        });
    }
    declared.sort_by_key(|d| (d.group, d.binding));
    Ok(declared)
}

/// The layout entries of `group` among `declared`.
pub fn layout_entries(declared: &[Declared], group: u32) -> Vec<wgpu::BindGroupLayoutEntry> {
    declared
        .iter()
        .filter(|d| d.group == group)
        .map(|d| wgpu::BindGroupLayoutEntry {
            binding: d.binding,
            visibility: d.visibility,
            ty: d.ty,
            count: None,
        })
        .collect()
}

/// A stage's declared bindings and one bind group layout per group they use.
pub struct StageBindings {
    label: &'static str,
    pub declared: Vec<Declared>,
    pub layouts: Vec<wgpu::BindGroupLayout>,
}

impl StageBindings {
    /// Reflects `source` and makes its bind group layouts.
    pub fn new(
        device: &wgpu::Device,
        label: &'static str,
        source: &str,
    ) -> Result<StageBindings, RenderError> {
        let declared = reflect(label, source)?;
        let groups = declared.iter().map(|d| d.group + 1).max().unwrap_or(0);
        let layouts = (0..groups)
            .map(|g| {
                device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some(label),
                    entries: &layout_entries(&declared, g),
                })
            })
            .collect();
        Ok(StageBindings {
            label,
            declared,
            layouts,
        })
    }

    /// Groups 0 to the last one any of `entry_points` uses: a pipeline layout's groups.
    pub fn groups_used_by(&self, entry_points: &[&str]) -> usize {
        self.declared
            .iter()
            .filter(|d| d.used_by.iter().any(|e| entry_points.contains(&e.as_str())))
            .map(|d| d.group as usize + 1)
            .max()
            .unwrap_or(0)
    }

    /// A pipeline layout over the groups `entry_points` use.
    pub fn pipeline_layout(
        &self,
        device: &wgpu::Device,
        entry_points: &[&str],
    ) -> wgpu::PipelineLayout {
        let groups: Vec<Option<&wgpu::BindGroupLayout>> = self.layouts
            [..self.groups_used_by(entry_points)]
            .iter()
            .map(Some)
            .collect();
        device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(self.label),
            bind_group_layouts: &groups,
            immediate_size: 0,
        })
    }

    /// The bind group of `group`, each variable bound to `resource(declaration)`.
    pub fn bind_group<'a>(
        &self,
        device: &wgpu::Device,
        group: u32,
        resource: impl Fn(&Declared) -> Result<wgpu::BindingResource<'a>, RenderError>,
    ) -> Result<wgpu::BindGroup, RenderError> {
        let entries = self
            .declared
            .iter()
            .filter(|d| d.group == group)
            .map(|d| {
                Ok(wgpu::BindGroupEntry {
                    binding: d.binding,
                    resource: resource(d)?,
                })
            })
            .collect::<Result<Vec<_>, RenderError>>()?;
        Ok(device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: &self.layouts[group as usize],
            entries: &entries,
        }))
    }

    /// The bind group of `group`, each variable bound by name ([`Resource::of`]) to
    /// `resource(Resource)`.
    pub fn named_group<'a>(
        &self,
        device: &wgpu::Device,
        group: u32,
        resource: impl Fn(Resource) -> wgpu::BindingResource<'a>,
    ) -> Result<wgpu::BindGroup, RenderError> {
        self.bind_group(device, group, |d| {
            Resource::of(&d.name)
                .map(&resource)
                .ok_or_else(|| RenderError::Shader {
                    label: self.label,
                    message: format!(
                        "`{}` (group {}, binding {}) is no resource of the renderer",
                        d.name, d.group, d.binding
                    ),
                })
        })
    }
}
