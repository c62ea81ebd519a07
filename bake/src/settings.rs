//! The bake's settings and their presets.

use prt_format::TransferPrecision;

use crate::error::BakeError;

/// Bake settings. [`BakeSettings::default`] is the production preset; see the other presets for
/// the trade-offs.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeSettings {
    /// Rays per probe (size of the Fibonacci lattice). The main accuracy lever: error falls
    /// roughly as N^-0.75 on scenes with sharp shadows, at a bake cost linear in N. More rays
    /// reach more bricks (more factors per probe), unless far hits share coarse bricks
    /// ([`BakeSettings::far_ratio`]).
    ///
    /// The default, 2048 with a far ratio of 5, was chosen on the level family's tuning seeds,
    /// Sponza and the Cornell reference with `prt-bench frontier --rays 512,2048 --far 0,3,4,5,6`
    /// and `prt-bench accuracy --far-ratio`, against 512 rays without coarse bricks
    /// ([`BakeSettings::fast`], the default until then). Tuning seeds, median / worst level:
    /// 6.7% / 9.2% against 6.9% / 10.0% at the default grid, 4.4% / 5.6% against 4.8% / 7.3% at
    /// half its spacing, at 1.2x the transport bytes (4,722 against 3,928 a probe, median
    /// level) and 2.1x the bake time. Sponza under the sun and two lights
    /// (`fixtures/rigs/sponza_sun_2.json`): 17.9% against 19.1%, and 12.2% against 18.0% at
    /// half the spacing, where 512 rays' noise, not the grid, had set the error. Probe SH
    /// against the converged Mitsuba probes of the Cornell room: 1.89% at 0.1 m and 2.13% at
    /// 0.15 m against the exact 512-ray bake's 3.31% (issue 32 bounds a default at 1.15x of
    /// it). Far ratio 4 keeps 512 rays' bytes but crosses that bound at 0.1 m (3.95%, 1.19x);
    /// far ratio 3 at 0.15 m (4.44%).
    pub rays: u32,
    /// Probe spacing in metres; `None` picks about 4,000 probes over the bounds
    /// ([`crate::probes::DEFAULT_PROBES`]).
    pub spacing: Option<f32>,
    /// Trace only the grid points surfaces need and coarse levels around them
    /// ([`crate::placement`]); the others are not traced, carry no data and are filled from
    /// those levels at runtime (`prt_format::tier`). On by default: on the level family's
    /// held-out seeds the surfaces sample as on the uniform grid (median / worst level 5.9% /
    /// 8.7% against 5.9% / 8.8%), with 9-55% fewer probes with data, and the filled points
    /// differ from a uniform bake's probes by 2.7% (median level) / 6.5% (worst)
    /// (`prt-bench surface --case held-out`, `prt-bench open-air`; docs/results/sparse.md).
    /// Off: every grid point traced, as the exact preset does.
    pub sparse: bool,
    /// Bake bounds `[min x, y, z, max x, y, z]`; `None` uses the scene's bounds.
    pub bounds: Option<[f32; 6]>,
    /// Per axis, moves the grid's layers down by this share of a step ([0, 1); 0: the first
    /// and last layers on the bounds' faces, as by default), with a layer added past the
    /// bounds' maximum: the same steps, other phases (a flat axis keeps its one layer). Where the layers fall beside walls
    /// decides much of a level's error (`docs/limits.md`); `prt-bench surface --grid-shift`
    /// measures it.
    pub grid_shift: [f32; 3],
    /// Refuse grids with more probes than this.
    pub max_probes: u64,
    /// Surfel cell size in metres (a brick is 4x4x4 cells); `None` is
    /// `spacing / cells_per_spacing`; 0 switches merging off (exact, one brick per ray hit,
    /// larger assets and more runtime work).
    pub cell_size: Option<f32>,
    /// Surfel cells per probe spacing when `cell_size` is `None`. Larger values mean smaller
    /// bricks: less merging error at the cost of more factors per probe (runtime gather work and
    /// asset size), and surfels, bricks and surface terms grow with its square. At the default
    /// probe count ([`crate::probes::DEFAULT_PROBES`]) 8 measured as 12 on the level family's
    /// tuning seeds (median level 7.0% against 6.9%, worst 10.0% against 9.9%) at 0.64x the
    /// runtime bytes; 6 saved a quarter more but cost Sponza's detail (16.0% against 14.5% at
    /// 8 and 12.5% at 12; `prt-bench frontier --cells 6,8,12`). Re-measured at stop 62
    /// (docs/results/cells.md): 6 is a quarter fewer bytes at about the same error on five
    /// tuning levels and the bundled scenes, better under Sponza's 31 lights (9.21% against
    /// 10.21% at 1.5 m), worse under its sun (16.54% against 14.81%) and on the open plaza:
    /// 8 stays. 1 to [`MAX_CELLS_PER_SPACING`].
    pub cells_per_spacing: f32,
    /// Hits at least this many brick sizes from their probe go to coarse bricks, one level
    /// coarser each time the distance doubles up to cells of 8 bricks
    /// ([`crate::merge::coarse::FAR_LEVELS`], [`prt_format::coarse`]): a probe's far rays
    /// share factors instead of taking one each. 0 keeps every hit in its own brick's factor.
    /// 5 by default, with 2048 rays ([`BakeSettings::rays`] says why).
    pub far_ratio: f32,
    /// Hits merge into one surfel only when the cosine between their normals is at least this.
    pub merge_normal_cos: f32,
    /// Treat every material as double-sided (for files with inconsistent winding).
    pub double_sided: bool,
    /// A probe is invalid (inside geometry) when more than this fraction of its rays hit back
    /// faces of single-sided surfaces.
    pub invalid_backface_fraction: f32,
    /// A probe that sees no sky is inside geometry when more than this fraction of its rays hit
    /// the back side of their triangle's winding, whatever the material's sidedness: inside a
    /// closed solid with double-sided materials (thick walls) every hit does, while in a room
    /// with inconsistent winding (Sponza) they stay well below.
    pub inside_facing_away_fraction: f32,
    /// Give probes inside geometry their nearest valid neighbour's data ([`crate::dilate`]).
    pub dilate: bool,
    /// Trace the surface terms the lookup reads where a point has a surfel
    /// ([`crate::surface_terms`]: which probes each surfel sees, its near field). Off, the bake
    /// skips that stage (much of a default bake's time: 64 near-field rays and up to 27
    /// visibility rays per surfel) and surfaces are sampled from the probe volume alone.
    /// Merging off has none.
    pub surface_terms: bool,
    /// Move probes that lie on a surface (within 2% of a spacing, as the grid's outer layers do
    /// on a room's walls) 5% of a spacing off it before tracing: a probe on a wall sees both of
    /// its sides and mixes the rooms it separates.
    pub surface_offset: bool,
    /// At most this many probes with data: past it the bake drops the probes between the
    /// points of level 1 (every other grid point) whose light that level's interpolation
    /// predicts best, those that see all their level-1 corners first ([`crate::refine`]), and
    /// the runtime fills them from it. `None` keeps every probe.
    pub probe_budget: Option<usize>,
    /// Sparse bakes drop the probes between the points of level 1 whose prediction error
    /// ([`crate::refine`]) is below this, whatever the budget; 0 keeps them. 0.15 was chosen
    /// on the level family's tuning seeds (`prt-bench surface --case tuning --prune-error E`,
    /// docs/results/refine.md): 3-30% fewer probes with data per level at both spacings
    /// (median 6%), and the same median / worst level (6.6% / 8.6% at the default spacing,
    /// 4.0% / 4.9% at half); with the test's first version 0.2 cost a little (8.7%, 4.1%) and
    /// 0.3 much (worst level 11.9%, leaks 1.7%).
    pub prune_error: f32,
    /// Storage precision of factor transfers; f32 also keeps the surfels in f32 (packed
    /// otherwise, `prt_format::surfel`).
    pub transfer_precision: TransferPrecision,
    /// Move probes that are inside geometry out of it (virtual offset, on by default): through
    /// the nearest back side their rays hit (a single-sided back face, or the inside of a
    /// closed solid), if it is within half a spacing and the probe is valid there.
    pub virtual_offset: bool,
    /// Split a brick where a wall stands on it into a brick per side (`crate::merge::split`; on
    /// by default, `prt bake --no-split-bricks`). On the level family it takes interior_32 (a
    /// room lit only through a door) from 21.2% to 13.6% (22.9% to 9.8% at half the spacing)
    /// and cave_31's over-lit pixels from 3.64% to 3.31%, and moves no other level by more than
    /// 0.5 point; Sponza 10.34% -> 10.44%, 1.7% more runtime bytes (`prt-bench surface`,
    /// docs/results/surface_candidates.md, stop 50).
    pub split_bricks: bool,
    /// Worker threads; `None` uses all cores.
    pub threads: Option<usize>,
    /// Bytes of factor rows held in memory between the trace and the table encoding (whole
    /// chunks of 64 KiB to 64 MiB, at least one, and two more while rows are written); past
    /// it the oldest rows wait in a temporary file in [`std::env::temp_dir`] (`TMPDIR`), and
    /// the asset does not change ([`crate::tables::row_store`]). The rows are what grows with
    /// the probe count: 28 bytes a factor at u8, 52 at f16 and f32.
    pub row_memory: usize,
    /// Folders besides the scene file's own that its buffer and image URIs may reach
    /// ([`prt_scene::Allowed`]; `prt bake --allow-path`). Not recorded in the asset.
    pub allowed: prt_scene::Allowed,
}

impl Default for BakeSettings {
    fn default() -> Self {
        BakeSettings {
            rays: 2048,
            spacing: None,
            sparse: true,
            bounds: None,
            grid_shift: [0.0; 3],
            max_probes: 1 << 20,
            cell_size: None,
            cells_per_spacing: 8.0,
            far_ratio: 5.0,
            merge_normal_cos: 0.9,
            double_sided: false,
            invalid_backface_fraction: 0.1,
            inside_facing_away_fraction: 0.75,
            dilate: true,
            surface_terms: true,
            surface_offset: true,
            probe_budget: None,
            prune_error: 0.15,
            transfer_precision: TransferPrecision::U8,
            virtual_offset: true,
            split_bricks: true,
            threads: None,
            row_memory: 256 << 20,
            allowed: prt_scene::Allowed::default(),
        }
    }
}

impl BakeSettings {
    /// The surfel cell size of a bake at `spacing` ([`BakeSettings::cell_size`]).
    pub fn cell_size_for(&self, spacing: f32) -> f32 {
        self.cell_size.unwrap_or(spacing / self.cells_per_spacing)
    }

    /// Higher accuracy: 8x the rays of [`BakeSettings::fast`] (2x the default's), bricks a third
    /// the size of an eighth-cell brick (half of a twelfth-cell one) and no coarse bricks. On
    /// the Cornell reference (27 probes at 0.6 m) it brought the mean irradiance error from
    /// 4.0% (512 rays, cells of a twelfth) to 0.5% (p95 1.3%), at 5.6x the factors per probe
    /// (runtime gather work and asset size) and 8x the trace time. It keeps every traced probe
    /// (no [`BakeSettings::prune_error`]).
    pub fn high_quality() -> Self {
        BakeSettings {
            rays: 4096,
            cells_per_spacing: 24.0,
            far_ratio: 0.0,
            prune_error: 0.0,
            ..Self::default()
        }
    }

    /// The pure 512-direction lattice with every hit in its own brick's factor (the default
    /// until 2048 rays with coarse far bricks replaced it): what the data-equivalence tests
    /// against the reference renderer use, at a quarter of the default's trace time.
    pub fn fast() -> Self {
        BakeSettings {
            rays: 512,
            far_ratio: 0.0,
            ..Self::default()
        }
    }

    /// The exact one-bounce estimate for accuracy tests: 512 rays ([`BakeSettings::fast`]), no
    /// merging, f32 transfers, every grid point traced, and probes inside geometry left where
    /// the grid put them (a reference is computed at given probe positions). Largest assets
    /// and runtime work.
    pub fn exact() -> Self {
        BakeSettings {
            sparse: false,
            prune_error: 0.0,
            cell_size: Some(0.0),
            transfer_precision: TransferPrecision::F32,
            virtual_offset: false,
            ..Self::fast()
        }
    }

    /// Refuses settings the bake cannot run with, naming the setting and its value.
    pub(crate) fn check(&self) -> Result<(), BakeError> {
        let bad = |name, value: String, reason| {
            Err(BakeError::Setting {
                name,
                value,
                reason,
            })
        };
        if self.rays == 0 || self.rays > prt_format::validate::MAX_RAYS {
            return bad("rays", self.rays.to_string(), "must be in 1..=1048576");
        }
        if let Some(s) = self.spacing {
            if !(s.is_finite() && s > 0.0) {
                return bad(
                    "spacing",
                    s.to_string(),
                    "must be a positive number of metres",
                );
            }
        }
        if let Some(b) = self.bounds {
            if b.iter().any(|v| !v.is_finite()) {
                return bad("bounds", format!("{b:?}"), "must be finite");
            }
            if (0..3).any(|a| b[a] > b[a + 3]) {
                return bad(
                    "bounds",
                    format!("{b:?}"),
                    "min is above max (inverted bounds)",
                );
            }
        }
        if let Some(c) = self.cell_size {
            if !(c.is_finite() && c >= 0.0) {
                return bad("cell_size", c.to_string(), "must be >= 0 (0: no merging)");
            }
        }
        if !(self.far_ratio.is_finite() && self.far_ratio >= 0.0) {
            return bad(
                "far_ratio",
                self.far_ratio.to_string(),
                "must be finite and at least 0 (0: no coarse bricks)",
            );
        }
        if let Some(v) = (self.grid_shift.iter()).find(|v| !(0.0..1.0).contains(*v)) {
            return bad(
                "grid_shift",
                v.to_string(),
                "each axis's share of a step must be in [0, 1)",
            );
        }
        if !(self.prune_error.is_finite() && self.prune_error >= 0.0) {
            return bad(
                "prune_error",
                self.prune_error.to_string(),
                "must be finite and at least 0 (0: drop probes only past the budget)",
            );
        }
        if self.probe_budget == Some(0) {
            return bad("probe_budget", "0".into(), "must be at least 1 probe");
        }
        // A cell wider than the spacing would merge hits a probe apart into one surfel (and
        // below 1e-38 per spacing the cell is no longer a finite size); past 256 a default
        // grid's cells pass a ray hit each, which merging is for.
        if !(1.0..=MAX_CELLS_PER_SPACING).contains(&self.cells_per_spacing) {
            return bad(
                "cells_per_spacing",
                self.cells_per_spacing.to_string(),
                "must be between 1 and 256 (surfel cells per probe spacing)",
            );
        }
        if !(-1.0..=1.0).contains(&self.merge_normal_cos) {
            return bad(
                "merge_normal_cos",
                self.merge_normal_cos.to_string(),
                "must be in [-1, 1]",
            );
        }
        if !(0.0..=1.0).contains(&self.invalid_backface_fraction) {
            return bad(
                "invalid_backface_fraction",
                self.invalid_backface_fraction.to_string(),
                "must be in [0, 1]",
            );
        }
        if !(0.0..=1.0).contains(&self.inside_facing_away_fraction) {
            return bad(
                "inside_facing_away_fraction",
                self.inside_facing_away_fraction.to_string(),
                "must be in [0, 1]",
            );
        }
        if let Some(t) = self.threads.filter(|&t| t == 0 || t > MAX_THREADS) {
            return bad(
                "threads",
                t.to_string(),
                "must be in 1..=1024 (more threads than cores only add overhead)",
            );
        }
        Ok(())
    }
}

/// Most worker threads a bake starts.
pub const MAX_THREADS: usize = 1024;

/// Most surfel cells per probe spacing ([`BakeSettings::cells_per_spacing`]): `--quality high`
/// takes 24.
pub const MAX_CELLS_PER_SPACING: f32 = 256.0;
