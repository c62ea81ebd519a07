//! What changed since the last update, and what this update must therefore do: the changed
//! lights (listed) and the moved ones (a bitset: they lose their cached shadow rays), the sky, and the
//! cycle accounting of amortised updates and bounces ([`super::Bounces`]).

use super::{GpuError, PrtRuntime};
use crate::contract::*;
use crate::lights::PreparedLight;
use crate::rig::Lighting;
use crate::settings::Bounces;
use crate::sky::SkyModel;

/// The lighting state an update was recorded for (to detect changes).
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct State {
    pub(super) lights: Vec<GpuLight>,
    pub(super) sky_mode: u32,
    pub(super) sky_color: [f32; 3],
    pub(super) sky_directions: Vec<[f32; 4]>,
    /// The sky's mean radiance (`crate::SkyModel::mean_radiance`, as the CPU twin takes it).
    pub(super) sky_mean: [f32; 3],
}

/// What one update does ([`PrtRuntime::plan`]).
pub(super) struct Plan {
    pub(super) first: bool,
    pub(super) lights_changed: bool,
    pub(super) sky_changed: bool,
    /// Fixed bounces restart from direct light: bounce radiance cleared, every brick's
    /// radiance rebuilt, every probe gathered again.
    pub(super) fixed_restart: bool,
    /// Feed the volume back into the surfels (stage 3).
    pub(super) bounce: bool,
    /// First probe and probe count gathered.
    pub(super) window: (u32, u32),
}

impl Plan {
    /// Lights changed: cull and relight surfels (stages 1 and 2).
    pub(super) fn relight(&self) -> bool {
        self.lights_changed
    }
}

/// What changed between the lights of two updates (`old` is `None` on the first), as the cull
/// and relight stages read it: the moved lights' bitset (`stride` words: lights whose cached
/// shadow rays are stale), then the changed lights' indices in ascending order. Only a change of
/// colour or intensity of a light that was lit keeps its shadow rays: anything else can light
/// surfels never traced for it.
pub(super) fn light_changes(old: Option<&[GpuLight]>, new: &[GpuLight], stride: usize) -> Vec<u32> {
    let mut words = vec![0u32; stride];
    let count = old.map_or(new.len(), |o| o.len().max(new.len()));
    for i in 0..count {
        let (a, b) = (old.and_then(|o| o.get(i)), new.get(i));
        if old.is_some() && a == b {
            continue;
        }
        let only_brightness = matches!((a, b), (Some(a), Some(b))
            if a.radiant.iter().any(|&c| c > 0.0)
                && GpuLight { radiant: b.radiant, ..*a } == *b);
        if !only_brightness {
            words[i / 32] |= 1 << (i % 32);
        }
        words.push(i as u32);
    }
    words
}

impl PrtRuntime {
    pub(super) fn state_for(&mut self, lighting: &Lighting) -> Result<State, GpuError> {
        let lights = &lighting.rig.lights;
        if lights.len() > self.settings.max_lights {
            return Err(GpuError::TooManyLights {
                count: lights.len(),
                max: self.settings.max_lights,
            });
        }
        let lights = lights
            .iter()
            .map(|l| GpuLight::from(&PreparedLight::new(l)))
            .collect();
        // The sky's mean radiance as the CPU twin takes it (`SkyModel::mean_radiance`).
        let (sky_mode, sky_color, sky_directions, sky_mean) = match &lighting.sky {
            SkyModel::Black => (SKY_BLACK, [0.0; 3], Vec::new(), [0.0; 3]),
            SkyModel::Constant(c) => (SKY_CONSTANT, *c, Vec::new(), *c),
            SkyModel::Equirect { .. } if !self.settings.equirect_sky => {
                return Err(GpuError::NoSkyMask)
            }
            sky @ SkyModel::Equirect { .. } => {
                let cached = self.sky_cache.as_ref().filter(|(s, _, _)| s == sky);
                let (directions, mean) = match cached {
                    Some((_, d, mean)) => (d.clone(), *mean),
                    None => {
                        let lattice = sky.lattice(self.ray_count);
                        let mean = sky.mean_radiance(&lattice);
                        let d: Vec<[f32; 4]> = lattice
                            .into_iter()
                            .flat_map(|(d, l)| [[d[0], d[1], d[2], 0.0], [l[0], l[1], l[2], 0.0]])
                            .collect();
                        self.sky_cache = Some((sky.clone(), d.clone(), mean));
                        (d, mean)
                    }
                };
                (SKY_DIRECTIONS, [0.0; 3], directions, mean)
            }
        };
        Ok(State {
            lights,
            sky_mode,
            sky_color,
            sky_directions,
            sky_mean,
        })
    }

    /// Cycles (passes of the gather over every valid probe) a change of lighting owes: `n` for
    /// [`Bounces::Fixed`]`(n)`, no end for [`Bounces::Feedback`].
    fn cycles_owed(&self) -> u32 {
        match self.settings.bounces {
            Bounces::Fixed(n) => n.max(1),
            Bounces::Feedback { .. } => u32::MAX,
        }
    }

    /// Moves the gather's cursor past the `gathered` probes of this update and counts a cycle
    /// when every valid probe has been gathered.
    pub(super) fn advance(&mut self, gathered: u32) {
        self.cursor = (self.cursor + gathered) % self.gather_count.max(1);
        self.cycle_gathered += gathered;
        if self.cycle_gathered >= self.gather_count {
            self.cycle_gathered = 0;
            // Feedback needs only "the first cycle is done": stop counting there, so that it
            // never reaches the owed (unbounded) count and goes idle.
            if matches!(self.settings.bounces, Bounces::Fixed(_)) || self.cycles_done == 0 {
                self.cycles_done += 1;
            }
        }
    }

    /// Updates still owed at `budget` probes per update: the rest of this cycle and the cycles
    /// after it (with [`Bounces::Feedback`] only the first cycle after a change counts).
    pub(super) fn pending(&self, budget: u32) -> u32 {
        let owed = self.cycles_owed();
        if self.cycles_done >= owed {
            return 0;
        }
        let budget = budget.max(1);
        let rest =
            (self.gather_count - self.cycle_gathered.min(self.gather_count)).div_ceil(budget);
        match self.settings.bounces {
            Bounces::Feedback { .. } if self.cycles_done > 0 => 0,
            Bounces::Feedback { .. } => rest,
            Bounces::Fixed(_) => rest.saturating_add(
                (owed - self.cycles_done - 1).saturating_mul(self.gather_count.div_ceil(budget)),
            ),
        }
    }

    /// What this update does, given the new lighting state and the number of changed lights;
    /// `None` when there is nothing to do. A change starts the cycles again. Cycles are counted
    /// in probes gathered, so a budget that changes between updates neither skips probes nor
    /// miscounts bounces.
    pub(super) fn plan(&mut self, new: &State, changed: u32, budget: Option<u32>) -> Option<Plan> {
        let first = self.state.is_none();
        let sky_changed = self.state.as_ref().is_none_or(|old| {
            old.sky_mode != new.sky_mode
                || old.sky_color != new.sky_color
                || old.sky_directions != new.sky_directions
        });
        let budget = budget
            .unwrap_or(self.gather_count)
            .clamp(1, self.gather_count.max(1));
        let lights_changed = changed > 0 || first;
        let restart = lights_changed || sky_changed;
        if restart {
            self.cycle_gathered = 0;
            self.cycles_done = 0;
        } else if self.cycles_done >= self.cycles_owed() {
            return None;
        }
        let feedback = matches!(self.settings.bounces, Bounces::Feedback { .. });
        // A fixed bounce count starts again from direct light: the old bounce light goes, and
        // every brick's radiance is rebuilt without it (its direct radiance stays).
        let fixed_restart = restart && self.settings.bounces.feeds_back() && !feedback && !first;
        // Stage 3 runs at the start of every cycle after the first since the change (fixed), or
        // of every cycle but the very first (feedback).
        let bounce = self.settings.bounces.feeds_back()
            && self.cycle_gathered == 0
            && (self.cycles_done >= 1 || (feedback && !first));
        Some(Plan {
            first,
            lights_changed,
            sky_changed,
            fixed_restart,
            bounce,
            window: (self.cursor, budget.min(self.gather_count)),
        })
    }
}
