//! The compute stages, one entry each in [`STAGES`]: its WGSL, how it is dispatched (and so
//! which bind-group sets it has), when an update runs it, and whether it is built at all. Its
//! bindings come from its WGSL ([`super::bindings`]). Adding a stage takes an entry here and a
//! WGSL file in `shaders/` (exported by `prt_shaders`); a new resource name also takes its line
//! in `bindings.rs` and its buffer in `resources.rs`.

use prt_shaders::{
    BOUNCE_SURFELS, BRICK_RADIANCE, COARSE_RADIANCE, CULL_LIGHTS, FILL, GATHER, GATHER_SUBGROUP,
    GATHER_TREE, LIGHT_SAMPLE, MARK_PROBES, NEAR_RADIANCE, OCT_NORMAL, RELIGHT_SURFELS,
    SHADOW_RAYS, STORE_PROBE, SURFEL, TYPES,
};

use super::bindings::{bind_groups, declared_bindings, Set};
use super::changes::Plan;
use super::resources::Resources;
use super::shaders::{self, ShaderConfig};
use super::{dispatch_size, GpuError};
use crate::contract::WORKGROUP;

/// A piece of a stage's WGSL, after the generated constants and `types.wgsl`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Part {
    /// A file of `prt_shaders`.
    File(&'static str),
    /// The gather's reduction: `gather_subgroup.wgsl` where the adapter has subgroups,
    /// `gather_tree.wgsl` otherwise.
    Reduction,
    /// The engine-side sampling snippet, its bindings at group 1.
    Snippet,
}

/// What one invocation of a stage handles, and over which slice of the split arrays its
/// bind-group sets range (one dispatch per set).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Dispatch {
    /// A thread per brick, every brick in one dispatch.
    Bricks,
    /// A thread per near group of the surface lookup, every group in one dispatch.
    Groups,
    /// A thread per coarse brick, every one in one dispatch.
    Coarse,
    /// A thread per brick, one dispatch per surfel chunk (its bricks).
    ChunkBricks,
    /// A thread per surfel, one dispatch per surfel chunk (its surfels).
    ChunkSurfels,
    /// A thread per probe (every probe), one dispatch per factor chunk.
    ChunkProbes,
    /// A workgroup per probe of the update's window, one dispatch per factor chunk.
    Window,
    /// A thread per grid point the coarse levels fill, every one in one dispatch.
    Fills,
}

/// One compute stage.
pub(super) struct Stage {
    /// Pipeline label: `prt` and the stage's name.
    pub(super) label: &'static str,
    /// Its WGSL after the generated constants and `types.wgsl`, in order.
    pub(super) wgsl: &'static [Part],
    pub(super) dispatch: Dispatch,
    /// Whether an update with this plan dispatches it.
    pub(super) runs: fn(&Plan) -> bool,
    /// Built only when bounces feed the volume back ([`crate::settings::Bounces::feeds_back`]).
    pub(super) bounces_only: bool,
}

impl Stage {
    /// Its full WGSL: the generated constants, `types.wgsl` and its parts.
    pub(super) fn source(&self, config: &ShaderConfig) -> String {
        let mut s = shaders::prelude(config);
        s.push_str(TYPES);
        for part in self.wgsl {
            match part {
                Part::File(wgsl) => s.push_str(wgsl),
                Part::Reduction if config.subgroups => s.push_str(GATHER_SUBGROUP),
                Part::Reduction => s.push_str(GATHER_TREE),
                Part::Snippet => s.push_str(&shaders::sample_irradiance_snippet(1)),
            }
        }
        s.replace("VOLUME_FORMAT", config.volume_format)
    }
}

/// Every stage, in dispatch order (the module docs of [`super`] say what each computes).
pub(super) const STAGES: [Stage; 9] = [
    // 1. Per brick: light masks of the changed lights, dirty bricks, shadow-ray cache room.
    Stage {
        label: "prt cull_lights",
        wgsl: &[Part::File(CULL_LIGHTS)],
        dispatch: Dispatch::Bricks,
        runs: |plan| plan.relight(),
        bounces_only: false,
    },
    // 2. Per surfel of a dirty brick: direct irradiance with cached shadow rays.
    Stage {
        label: "prt relight_surfels",
        wgsl: &[
            Part::File(LIGHT_SAMPLE),
            Part::File(SHADOW_RAYS),
            Part::File(OCT_NORMAL),
            Part::File(SURFEL),
            Part::File(RELIGHT_SURFELS),
        ],
        dispatch: Dispatch::ChunkSurfels,
        runs: |plan| plan.relight(),
        bounces_only: false,
    },
    // 3. Per surfel, at the start of a bounce cycle: the volume's irradiance, fed back.
    Stage {
        label: "prt bounce_surfels",
        wgsl: &[
            Part::File(SURFEL),
            Part::File(BOUNCE_SURFELS),
            Part::Snippet,
        ],
        dispatch: Dispatch::ChunkSurfels,
        runs: |plan| plan.bounce,
        bounces_only: true,
    },
    // 4. Per dirty brick: mean and gradient of its radiance, direct plus bounce.
    Stage {
        label: "prt brick_radiance",
        wgsl: &[
            Part::File(OCT_NORMAL),
            Part::File(SURFEL),
            Part::File(BRICK_RADIANCE),
        ],
        dispatch: Dispatch::ChunkBricks,
        runs: |plan| plan.relight() || plan.bounce || plan.fixed_restart,
        bounces_only: false,
    },
    // 5. Per coarse brick over a relit brick: its radiance from its bricks'.
    Stage {
        label: "prt coarse_radiance",
        wgsl: &[Part::File(COARSE_RADIANCE)],
        dispatch: Dispatch::Coarse,
        runs: |plan| plan.relight() || plan.bounce || plan.fixed_restart,
        bounces_only: false,
    },
    // 6. Per near group of the surface lookup: what its near-field rays bring.
    Stage {
        label: "prt near_radiance",
        wgsl: &[Part::File(NEAR_RADIANCE)],
        dispatch: Dispatch::Groups,
        runs: |plan| plan.relight() || plan.bounce || plan.fixed_restart,
        bounces_only: false,
    },
    // 7. Per probe: flag the probes to gather.
    Stage {
        label: "prt mark_probes",
        wgsl: &[Part::File(MARK_PROBES)],
        dispatch: Dispatch::ChunkProbes,
        runs: |plan| plan.lights_changed || plan.sky_changed || plan.bounce,
        bounces_only: false,
    },
    // 8. A workgroup per probe of the window: SH9 RGB into the volume textures.
    Stage {
        label: "prt gather",
        wgsl: &[Part::File(GATHER), Part::File(STORE_PROBE), Part::Reduction],
        dispatch: Dispatch::Window,
        runs: |_| true,
        bounces_only: false,
    },
    // 9. Per grid point the coarse levels fill: its SH from the coarse probes around it.
    Stage {
        label: "prt fill",
        wgsl: &[Part::File(FILL), Part::File(STORE_PROBE)],
        dispatch: Dispatch::Fills,
        runs: |_| true,
        bounces_only: false,
    },
];

/// Bricks and probes of the asset, for the dispatches that cover them all.
#[derive(Clone, Copy, Debug)]
pub(super) struct Counts {
    pub(super) bricks: u32,
    pub(super) probes: u32,
    /// Near groups of the surface lookup.
    pub(super) groups: u32,
    /// Coarse bricks (`prt_format::coarse`).
    pub(super) coarse: u32,
    /// Grid points the coarse levels fill (`prt_format::tier`).
    pub(super) fills: u32,
}

/// A stage's pipeline and its bind-group sets.
pub(super) struct Pipeline {
    stage: &'static Stage,
    pipeline: wgpu::ComputePipeline,
    /// Per set: its bind groups, and the threads it dispatches (unused by [`Dispatch::Window`],
    /// whose workgroups are the update's window).
    sets: Vec<(Vec<wgpu::BindGroup>, u32)>,
}

impl Pipeline {
    /// Builds `stage`'s pipeline from its WGSL and binds every variable it declares by name.
    pub(super) fn new(
        device: &wgpu::Device,
        r: &Resources,
        stage: &'static Stage,
        config: &ShaderConfig,
        counts: Counts,
    ) -> Result<Pipeline, GpuError> {
        let source = stage.source(config);
        let declared = declared_bindings(&source);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(stage.label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(stage.label),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let sets = sets(stage.dispatch, r, counts)
            .into_iter()
            .map(|(set, threads)| {
                let groups = bind_groups(device, r, stage.label, &pipeline, &declared, set)?;
                Ok((groups, threads))
            })
            .collect::<Result<_, GpuError>>()?;
        Ok(Pipeline {
            stage,
            pipeline,
            sets,
        })
    }

    /// Records this stage's dispatches for `plan` (none when it does not run), one per set.
    pub(super) fn record(&self, pass: &mut wgpu::ComputePass, plan: &Plan) {
        if !(self.stage.runs)(plan) {
            return;
        }
        pass.set_pipeline(&self.pipeline);
        for (groups, threads) in &self.sets {
            let workgroups = match self.stage.dispatch {
                Dispatch::Window => plan.window.1,
                _ => threads.div_ceil(WORKGROUP),
            };
            if workgroups == 0 {
                continue;
            }
            for (i, bg) in groups.iter().enumerate() {
                pass.set_bind_group(i as u32, bg, &[]);
            }
            let (x, y) = dispatch_size(workgroups);
            pass.dispatch_workgroups(x, y, 1);
        }
    }
}

/// The bind-group sets of a stage dispatched as `dispatch`, each with the threads it runs.
fn sets(dispatch: Dispatch, r: &Resources, counts: Counts) -> Vec<(Set, u32)> {
    let surfel_chunks = |threads: fn(&crate::contract::SurfelChunk) -> u32| {
        (r.surfel_chunks.iter().enumerate())
            .map(|(c, s)| (Set::Surfels(c), threads(s)))
            .collect()
    };
    let factor_chunks = |threads: u32| {
        (0..r.chunks.len())
            .map(|c| (Set::Factors(c), threads))
            .collect()
    };
    match dispatch {
        Dispatch::Bricks => vec![(Set::Whole, counts.bricks)],
        Dispatch::Groups => vec![(Set::Whole, counts.groups)],
        Dispatch::Coarse => vec![(Set::Whole, counts.coarse)],
        Dispatch::Fills => vec![(Set::Whole, counts.fills)],
        Dispatch::ChunkBricks => surfel_chunks(|s| s.brick_end - s.brick_begin),
        Dispatch::ChunkSurfels => surfel_chunks(|s| s.surfel_end - s.surfel_begin),
        Dispatch::ChunkProbes => factor_chunks(counts.probes),
        Dispatch::Window => factor_chunks(0),
    }
}
