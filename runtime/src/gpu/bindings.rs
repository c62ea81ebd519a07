//! Bind groups built from the WGSL. Nothing here lists bindings by number: each stage's
//! assembled WGSL declares its bindings (`@group(g) @binding(b) var ... name`), and every bind
//! group is built from those declarations, binding each variable to the resource of
//! [`Resources`] that carries its name ([`Binding::of`]). A shader can therefore renumber,
//! reorder or drop bindings without a Rust change (a new resource name takes one line in
//! [`Binding::of`] and one in [`Binding::resource`]), and a unit test checks, for every stage
//! and shader configuration, that every name is one the runtime provides, that naga reads the
//! same declarations, and that `main` uses each of them (the pipeline layout is derived from
//! what it uses). The engine-side sampling snippet's bind group is built the same way.
//!
//! The split arrays make a stage's bind groups come in *sets*, dispatched in turn: one per
//! factor chunk for the stages that read factors (`mark_probes`, `gather`), one per surfel
//! chunk for those that read surfels (`relight_surfels`, `bounce_surfels`, `brick_radiance`).

use super::resources::Resources;
use super::{shaders, GpuError};

/// Which slice of the split arrays a bind-group set binds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Set {
    Whole,
    Factors(usize),
    Surfels(usize),
}

/// A resource of the runtime, by the WGSL variable name that binds it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Binding {
    Params,
    Lights,
    Probes,
    Factors,
    Chunk,
    Bricks,
    NormalBounds,
    Surfels,
    SurfelRadiance,
    SurfelBounce,
    BrickLights,
    BrickDirty,
    BrickCache,
    ShadowCache,
    LightChanges,
    BrickRadiance,
    ProbeDirty,
    ProbeSh,
    /// The probes the gather visits (`gather_list`).
    GatherList,
    /// The grid points the coarse levels fill (`fill_list`).
    FillList,
    Counters,
    SkyTransfer,
    SkyMask,
    SkyDirections,
    BvhNodes,
    Triangles,
    /// A volume texture as the gather writes it (`volume0`..`volume6`).
    Volume(usize),
    /// A volume texture as the sampling snippet reads it (`prt_volume0`..`prt_volume6`).
    SampledVolume(usize),
    Sampler,
    VolumeInfo,
    DepthMoments,
    ProbePositions,
    /// The surface lookup's tables (`prt_surface`).
    Surface,
    /// Per near group, what its near field brings: written as `near_radiance`, read by the
    /// snippet as `prt_near`.
    NearRadiance,
    SurfaceGroups,
    SurfaceNear,
    GroupRadiance,
    CoarseBricks,
    CoarseChildren,
    BrickMoments,
    /// Per brick and coarse brick, what its factors' offsets are measured from
    /// (`factor_frames`).
    FactorFrames,
}

impl Binding {
    /// The resource a WGSL variable named `name` binds to.
    pub(super) fn of(name: &str) -> Option<Binding> {
        let volume = |prefix: &str| {
            name.strip_prefix(prefix)
                .and_then(|i| i.parse::<usize>().ok())
                .filter(|&i| i < 7)
        };
        if let Some(i) = volume("prt_volume") {
            return Some(Binding::SampledVolume(i));
        }
        if let Some(i) = volume("volume") {
            return Some(Binding::Volume(i));
        }
        Some(match name {
            "params" => Binding::Params,
            "lights" => Binding::Lights,
            "probes" => Binding::Probes,
            "factors" => Binding::Factors,
            "chunk" => Binding::Chunk,
            "bricks" => Binding::Bricks,
            "normal_bounds" => Binding::NormalBounds,
            "surfels" => Binding::Surfels,
            "surfel_radiance" => Binding::SurfelRadiance,
            "surfel_bounce" => Binding::SurfelBounce,
            "brick_lights" => Binding::BrickLights,
            "brick_dirty" => Binding::BrickDirty,
            "brick_cache" => Binding::BrickCache,
            "shadow_cache" => Binding::ShadowCache,
            "light_changes" => Binding::LightChanges,
            "brick_radiance" => Binding::BrickRadiance,
            "probe_dirty" => Binding::ProbeDirty,
            "probe_sh" => Binding::ProbeSh,
            "gather_list" => Binding::GatherList,
            "fill_list" => Binding::FillList,
            "counters" => Binding::Counters,
            "sky_transfer" => Binding::SkyTransfer,
            "sky_mask" => Binding::SkyMask,
            "sky_directions" => Binding::SkyDirections,
            "bvh_nodes" => Binding::BvhNodes,
            "triangles" => Binding::Triangles,
            "prt_sampler" => Binding::Sampler,
            "prt_volume" => Binding::VolumeInfo,
            "prt_depth_moments" => Binding::DepthMoments,
            "prt_probe_positions" => Binding::ProbePositions,
            "prt_surface" => Binding::Surface,
            "prt_near" | "near_radiance" => Binding::NearRadiance,
            "surface_groups" => Binding::SurfaceGroups,
            "surface_near" => Binding::SurfaceNear,
            "group_radiance" => Binding::GroupRadiance,
            "coarse_bricks" => Binding::CoarseBricks,
            "coarse_children" => Binding::CoarseChildren,
            "brick_moments" => Binding::BrickMoments,
            "factor_frames" => Binding::FactorFrames,
            _ => return None,
        })
    }

    /// The resource itself, for the bind-group set `set`.
    pub(super) fn resource<'a>(self, r: &'a Resources, set: Set) -> wgpu::BindingResource<'a> {
        let (f, s) = match set {
            Set::Whole => (0, 0),
            Set::Factors(c) => (c, 0),
            Set::Surfels(c) => (0, c),
        };
        let b = |buffer: &'a wgpu::Buffer| buffer.as_entire_binding();
        match self {
            Binding::Params => b(&r.state.params),
            Binding::Lights => b(&r.state.lights),
            Binding::Probes => b(&r.asset.probes),
            Binding::Factors => b(&r.chunk_factors[f]),
            Binding::Chunk => match set {
                Set::Surfels(c) => b(&r.chunk_surfels[c][3]),
                _ => b(&r.chunk_uniforms[f]),
            },
            Binding::Bricks => b(&r.asset.bricks),
            Binding::NormalBounds => b(&r.asset.normal_bounds),
            Binding::Surfels => b(&r.chunk_surfels[s][0]),
            Binding::SurfelRadiance => b(&r.chunk_surfels[s][1]),
            Binding::SurfelBounce => b(&r.chunk_surfels[s][2]),
            Binding::BrickLights => b(&r.state.brick_lights),
            Binding::BrickDirty => b(&r.state.brick_dirty),
            Binding::BrickCache => b(&r.state.brick_cache),
            Binding::ShadowCache => b(&r.state.shadow_cache),
            Binding::LightChanges => b(&r.state.light_changes),
            Binding::BrickRadiance => b(&r.state.brick_radiance),
            Binding::ProbeDirty => b(&r.state.probe_dirty),
            Binding::ProbeSh => b(&r.state.probe_sh),
            Binding::GatherList => b(&r.asset.gather_list),
            Binding::FillList => b(&r.asset.fill_list),
            Binding::Counters => b(&r.state.counters),
            Binding::SkyTransfer => b(&r.asset.sky_transfer),
            Binding::SkyMask => b(&r.asset.sky_mask),
            Binding::SkyDirections => b(&r.state.sky_directions),
            Binding::BvhNodes => b(&r.asset.bvh_nodes),
            Binding::Triangles => b(&r.asset.triangles),
            Binding::Volume(i) | Binding::SampledVolume(i) => {
                wgpu::BindingResource::TextureView(&r.views[i])
            }
            Binding::Sampler => wgpu::BindingResource::Sampler(&r.sampler),
            Binding::VolumeInfo => b(&r.volume_info),
            Binding::DepthMoments => b(&r.asset.depth_moments),
            Binding::ProbePositions => b(&r.asset.probe_positions),
            Binding::Surface => b(&r.asset.surface),
            Binding::NearRadiance => b(&r.state.near_radiance),
            Binding::SurfaceGroups => b(&r.asset.surface_groups),
            Binding::SurfaceNear => b(&r.asset.surface_near),
            Binding::GroupRadiance => b(&r.state.group_radiance),
            Binding::CoarseBricks => b(&r.asset.coarse_bricks),
            Binding::CoarseChildren => b(&r.asset.coarse_children),
            Binding::BrickMoments => b(&r.asset.brick_moments),
            Binding::FactorFrames => b(&r.asset.factor_frames),
        }
    }

    /// The layout type of a binding of the sampling snippet, as any shader stage reads it
    /// (`None` for the compute stages' own resources).
    pub(super) fn snippet_type(self) -> Option<wgpu::BindingType> {
        let buffer = |ty| wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        Some(match self {
            Binding::SampledVolume(_) => wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: true },
                view_dimension: wgpu::TextureViewDimension::D3,
                multisampled: false,
            },
            Binding::Sampler => wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
            Binding::VolumeInfo => buffer(wgpu::BufferBindingType::Uniform),
            Binding::DepthMoments
            | Binding::ProbePositions
            | Binding::Surface
            | Binding::NearRadiance => buffer(wgpu::BufferBindingType::Storage { read_only: true }),
            _ => return None,
        })
    }
}

/// The `(binding, resource)` of every variable the engine-side sampling snippet declares
/// (`shaders/sample_irradiance.wgsl`), in source order.
pub(super) fn snippet_bindings() -> Vec<(u32, Binding)> {
    declared_bindings(&shaders::sample_irradiance_snippet(0))
        .into_iter()
        .filter_map(|(_, binding, name)| Some((binding, Binding::of(&name)?)))
        .collect()
}

/// The `(group, binding, name)` of every resource variable `src` declares, in source order.
pub fn declared_bindings(src: &str) -> Vec<(u32, u32, String)> {
    let number = |line: &str, key: &str| -> Option<u32> {
        let rest = &line[line.find(key)? + key.len()..];
        rest[..rest.find(')')?].trim().parse().ok()
    };
    src.lines()
        .filter_map(|line| {
            let group = number(line, "@group(")?;
            let binding = number(line, "@binding(")?;
            let rest = line[line.find(" var")? + 4..].trim_start();
            let rest = match rest.strip_prefix('<') {
                Some(r) => &r[r.find('>')? + 1..],
                None => rest,
            };
            let name = rest.split(':').next()?.trim();
            Some((group, binding, name.to_string()))
        })
        .collect()
}

/// The bind groups of `pipeline` (labelled `label`) for `set`: each group's entries are the
/// variables `declared` in its WGSL ([`declared_bindings`]), bound by name.
pub(super) fn bind_groups(
    device: &wgpu::Device,
    r: &Resources,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    declared: &[(u32, u32, String)],
    set: Set,
) -> Result<Vec<wgpu::BindGroup>, GpuError> {
    let groups = declared.iter().map(|d| d.0 + 1).max().unwrap_or(0);
    (0..groups)
        .map(|g| {
            let entries = declared
                .iter()
                .filter(|d| d.0 == g)
                .map(|(_, binding, name)| {
                    let resource = Binding::of(name)
                        .ok_or_else(|| {
                            GpuError::Device(format!(
                                "{label} declares `{name}`, which the runtime does not provide"
                            ))
                        })?
                        .resource(r, set);
                    Ok(wgpu::BindGroupEntry {
                        binding: *binding,
                        resource,
                    })
                })
                .collect::<Result<Vec<_>, GpuError>>()?;
            Ok(device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout: &pipeline.get_bind_group_layout(g),
                entries: &entries,
            }))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::stages::STAGES;
    use super::*;

    /// Every binding every stage declares (with every shader configuration) is one the runtime
    /// provides, no (group, binding) is declared twice, and the parser reads each declaration
    /// form in use.
    #[test]
    fn every_declared_binding_has_a_resource() {
        assert_eq!(
            declared_bindings(
                "@group(1) @binding(3) var<storage, read_write> shadow_cache: array<u32>;\n\
                 @group(0) @binding(12) var prt_volume4: texture_3d<f32>;\n\
                 fn f() { var x = 1; }"
            ),
            vec![
                (1, 3, "shadow_cache".to_string()),
                (0, 12, "prt_volume4".to_string())
            ]
        );
        for config in shaders::tests::configs() {
            for stage in &STAGES {
                let src = stage.source(&config);
                let declared = declared_bindings(&src);
                let stage = stage.label;
                assert!(!declared.is_empty(), "{stage}");
                let mut seen = std::collections::HashSet::new();
                for (g, b, name) in &declared {
                    assert!(
                        Binding::of(name).is_some(),
                        "{stage} declares unknown `{name}`"
                    );
                    assert!(seen.insert((*g, *b)), "{stage}: ({g}, {b}) twice");
                }
                // naga agrees with the line parser, and `main` uses every binding (the
                // pipeline's layout is derived from what it uses: an unused one would make
                // the bind group invalid).
                let module = naga::front::wgsl::parse_str(&src).expect("parses");
                let info = naga::valid::Validator::new(
                    naga::valid::ValidationFlags::all(),
                    naga::valid::Capabilities::all(),
                )
                .validate(&module)
                .expect("valid");
                let main = module
                    .entry_points
                    .iter()
                    .position(|e| e.name == "main")
                    .expect("main");
                let mut from_naga = Vec::new();
                for (handle, var) in module.global_variables.iter() {
                    let Some(rb) = &var.binding else { continue };
                    let name = var.name.clone().unwrap_or_default();
                    assert!(
                        !info.get_entry_point(main)[handle].is_empty(),
                        "{stage}: `{name}` declared but unused"
                    );
                    from_naga.push((rb.group, rb.binding, name));
                }
                let mut parsed = declared.clone();
                parsed.sort();
                from_naga.sort();
                assert_eq!(parsed, from_naga, "{stage}");
            }
        }
    }

    /// Every variable the sampling snippet declares is a runtime resource with a layout type,
    /// each number once: `volume_layout_entries` and `volume_bind_group` cover the snippet.
    #[test]
    fn every_snippet_binding_has_a_resource_and_a_type() {
        let declared = declared_bindings(&shaders::sample_irradiance_snippet(0));
        let bound = snippet_bindings();
        assert_eq!(bound.len(), declared.len(), "{declared:?}");
        assert!(bound.iter().all(|(_, b)| b.snippet_type().is_some()));
        let mut numbers: Vec<u32> = bound.iter().map(|b| b.0).collect();
        numbers.sort_unstable();
        numbers.dedup();
        assert_eq!(numbers.len(), bound.len());
    }
}
