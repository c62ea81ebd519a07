//! The asset's types. Big arrays are `#[repr(C)]` `Pod` structs (sizes asserted below) so that
//! the runtime can upload them to the GPU as they are; the same layouts are declared in WGSL.

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

use crate::factors::{Factors, TransferPrecision};
use crate::rig::Light;
use crate::sh::SH_COUNT;
use crate::surface::SurfaceTerms;

/// One baked asset: everything an engine needs to relight probes at runtime.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Asset {
    pub header: Header,
    /// One per grid point, in grid order (x fastest, then y, then z), placed or not
    /// ([`Probe::slot`]).
    pub probes: Vec<Probe>,
    /// Per placed probe (in slot order, [`Probe::slot`]), which of its rays escaped to the sky,
    /// stored sparse after an index of where each probe's record starts
    /// ([`crate::sky_mask`]; [`Asset::sky_record`]).
    pub sky_mask: Vec<u32>,
    /// Per placed probe, the SH9 projection of its sky directions (`4pi/N sum_{i in sky} Y_k(w_i)`):
    /// multiply by a constant sky radiance to get the probe's sky term without touching the mask.
    pub sky_transfer: Vec<[f32; SH_COUNT]>,
    /// Per placed probe, [`DEPTH_WORDS`] words: the probe's visibility as an octahedral map
    /// ([`crate::depth`]) of the mean and standard deviation of its rays' hit distances in probe
    /// spacings, four bits each, four texels per word. Sampling weights each probe by whether the
    /// shaded point is visible from it (Chebyshev test, Majercik et al. 2019).
    pub probe_depth: Vec<u32>,
    /// The factor tables of the probes that are not dilated, concatenated in probe order;
    /// `Probe::first_factor..+factor_count` is a probe's (a dilated probe's is its source's).
    pub factors: Factors,
    /// Normal-keyed bricks of surfels; a brick's radiance is the weighted mean of its surfels'.
    pub bricks: Vec<Brick>,
    /// Bricks of coarser grids over the bricks, for far hits ([`crate::coarse`]): factors
    /// index them after `bricks`.
    pub coarse: crate::coarse::CoarseBricks,
    /// Surfels, grouped by brick (`Brick::first_surfel..+surfel_count`).
    pub surfels: Vec<Surfel>,
    /// The scene's triangles and a BVH2 over them, for light visibility at surfels.
    pub geometry: Geometry,
    /// The scene's KHR_lights_punctual lights: its default light rig.
    pub lights: Vec<Light>,
    /// Per surfel, the probes it sees and its near field, and how a point finds its surfel
    /// ([`crate::surface`]); empty when the bake did not merge surfels.
    pub surface: SurfaceTerms,
}

impl Asset {
    /// Factor `f`'s stored point: its brick's (or, past the bricks, coarse brick's) centroid
    /// plus its offset, stored divided by the coarse brick's `2^level` (`crate::coarse`). That
    /// is the rays' mean hit point, or for a lobe factor a point beside it on their mean
    /// direction (`crate::lobe`); a continuation slot's is its head brick's centroid.
    /// Validated assets only: `f` and its brick index in range.
    pub fn factor_point(&self, f: usize) -> [f32; 3] {
        let (brick, _) = self.factors.brick_and_rays(f);
        let [centroid_x, centroid_y, centroid_z, scale] = self.factor_frame(brick as usize);
        let offset = self.factors.offset(f);
        let centroid = [centroid_x, centroid_y, centroid_z];
        std::array::from_fn(|a| centroid[a] + offset[a] * scale)
    }

    /// The centroid and the offset multiplier (`2^level`, 1 for a brick) of brick or coarse
    /// brick `b`: what a factor's mean hit point is measured from ([`Asset::factor_point`]).
    pub fn factor_frame(&self, b: usize) -> [f32; 4] {
        match self.bricks.get(b) {
            Some(brick) => {
                let [x, y, z] = brick.centroid;
                [x, y, z, 1.0]
            }
            None => {
                let c = &self.coarse.bricks[b - self.bricks.len()];
                let [x, y, z] = c.centroid;
                [x, y, z, (1u32 << c.level) as f32]
            }
        }
    }

    /// Factor `f`'s SH9 transfer as the table of `probe` holds it: a lobe factor
    /// (`crate::lobe`) decoded about the direction from the probe's ray origin to the factor's
    /// stored point ([`Asset::factor_point`]).
    pub fn factor_transfer(&self, probe: &Probe, f: usize) -> [f32; SH_COUNT] {
        let point = self.factor_point(f);
        let toward = std::array::from_fn(|a| point[a] - probe.position[a]);
        self.factors.transfer(f, self.header.ray_count, toward)
    }

    /// The sky mask record of the probe in `slot` ([`crate::sky_mask::decode`] reads it;
    /// validated assets only).
    pub fn sky_record(&self, slot: usize) -> &[u32] {
        crate::sky_mask::record(&self.sky_mask, slot)
    }

    /// The visibility map ([`DEPTH_WORDS`] words) of probe `p`, found by its slot; `None` for a
    /// probe without data or out of range.
    pub fn visibility_map(&self, p: usize) -> Option<&[u32]> {
        let probe = self.probes.get(p).filter(|probe| probe.has_data())?;
        let slot = probe.slot as usize;
        self.probe_depth
            .get(slot * DEPTH_WORDS..(slot + 1) * DEPTH_WORDS)
    }
}

/// Counts, grid and provenance. Validated against the sections on load.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Name and version of the tool that wrote the asset.
    #[serde(deserialize_with = "string_from_input")]
    pub generator: String,
    /// File name of the baked scene (no directories: assets move between machines).
    #[serde(deserialize_with = "string_from_input")]
    pub source_name: String,
    /// xxh3-64 of the scene file's bytes (the .gltf/.glb itself).
    pub source_hash: u64,
    pub grid: Grid,
    /// Rays per probe: the size N of the Fibonacci lattice.
    pub ray_count: u32,
    pub settings: BakeSettingsRecord,
    pub stats: BakeStats,
}

/// Deserializes a `String` through `deserialize_str`, which bincode serves by borrowing the bytes
/// from the input slice after checking that they are there. Plain `String` deserialization makes
/// bincode allocate the declared length first, so a corrupt length (with a valid checksum) of
/// tens of GiB aborted the process on allocation failure instead of returning an error.
fn string_from_input<'de, D: serde::Deserializer<'de>>(d: D) -> Result<String, D::Error> {
    struct Visitor;
    impl serde::de::Visitor<'_> for Visitor {
        type Value = String;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a string")
        }
        fn visit_str<E: serde::de::Error>(self, s: &str) -> Result<String, E> {
            Ok(s.to_owned())
        }
        fn visit_string<E: serde::de::Error>(self, s: String) -> Result<String, E> {
            Ok(s)
        }
    }
    d.deserialize_str(Visitor)
}

/// The probe grid: probe (i, j, k) sits at `origin + step * (i, j, k)`.
///
/// `spacing` is the spacing the bake was asked for: the scene's length unit for everything
/// relative (surface offsets, the normal bias, visibility distances, ray offsets). `step` is the
/// lattice step along each axis, at most `spacing`: the bake fits a whole number of steps between
/// the bounds' faces so that its outer probes lie on them (`prt_bake::probes`), unless a grid
/// shift moved its layers (`prt_bake::BakeSettings::grid_shift`, not recorded: the grid is).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    pub origin: [f32; 3],
    pub spacing: f32,
    pub step: [f32; 3],
    pub counts: [u32; 3],
}

impl Grid {
    /// A grid with the same step along every axis.
    pub fn cubic(origin: [f32; 3], spacing: f32, counts: [u32; 3]) -> Grid {
        Grid {
            origin,
            spacing,
            step: [spacing; 3],
            counts,
        }
    }

    /// Number of probes.
    /// Number of probes (`u64::MAX` when the counts' product overflows; validation refuses it).
    pub fn probe_count(&self) -> u64 {
        self.counts
            .iter()
            .try_fold(1u64, |a, &c| a.checked_mul(u64::from(c)))
            .unwrap_or(u64::MAX)
    }

    /// Linear index of probe (i, j, k): x fastest, then y, then z (3D texture order).
    pub fn index(&self, i: u32, j: u32, k: u32) -> usize {
        (i as usize) + self.counts[0] as usize * (j as usize + self.counts[1] as usize * k as usize)
    }

    /// Probe `(i, j, k)` of linear index `index`: the inverse of [`Grid::index`].
    pub fn ijk(&self, index: usize) -> [u32; 3] {
        let n = self.counts.map(|c| c.max(1) as usize);
        [index % n[0], index / n[0] % n[1], index / (n[0] * n[1])].map(|v| v as u32)
    }

    /// The eight probes around `p` (world space) and their trilinear weights, as a sampler's
    /// `ClampToEdge` reads them: grid coordinate `(p - origin) / step` clamped to the grid,
    /// corner indices clamped to its last layer (so outside the grid, or on its last layer,
    /// several corners are the same probe). Weights are zero for corners the point lies on the
    /// far side of. The one corner walk of the lookup's CPU twin (`prt_runtime::sample`) and of
    /// the bake's sky terms, which interpolate where the lookup does.
    pub fn corners(&self, p: [f32; 3]) -> [(usize, f32); 8] {
        let last: [f32; 3] = std::array::from_fn(|a| self.counts[a].saturating_sub(1) as f32);
        let t: [f32; 3] = std::array::from_fn(|a| {
            ((p[a] - self.origin[a]) / self.step[a])
                .max(0.0)
                .min(last[a])
        });
        let base = t.map(f32::floor);
        std::array::from_fn(|corner| {
            let (mut w, mut ijk) = (1.0f32, [0u32; 3]);
            for a in 0..3 {
                let o = (corner >> a & 1) as f32;
                let f = t[a] - base[a];
                w *= f * o + (1.0 - f) * (1.0 - o);
                ijk[a] = (base[a] + o).min(last[a]) as u32;
            }
            (self.index(ijk[0], ijk[1], ijk[2]), w)
        })
    }

    /// Position of probe (i, j, k).
    pub fn position(&self, i: u32, j: u32, k: u32) -> [f32; 3] {
        [
            self.origin[0] + self.step[0] * i as f32,
            self.origin[1] + self.step[1] * j as f32,
            self.origin[2] + self.step[2] * k as f32,
        ]
    }
}

/// The settings a bake ran with, kept so that an asset tells how it was made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BakeSettingsRecord {
    pub spacing: f32,
    pub bounds: Option<[f32; 6]>,
    pub cell_size: f32,
    pub merge_distance: f32,
    pub merge_normal_cos: f32,
    pub double_sided_override: bool,
    pub invalid_backface_fraction: f32,
    pub transfer_precision: TransferPrecision,
    /// How the surfels are stored ([`crate::surfel`]).
    pub surfel_precision: SurfelPrecision,
    /// Hits farther than this many brick sizes from their probe went to coarse bricks
    /// ([`crate::coarse`]); 0: none did.
    pub far_ratio: f32,
}

/// How an asset stores its surfels (recorded in the header's bake settings; the encodings are
/// `crate::surfel`'s).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum SurfelPrecision {
    /// [`Surfel`] as it is: 80 bytes, every field f32.
    F32,
    /// `PackedSurfel`: 32 bytes (48 in formats 9-14).
    #[default]
    Packed,
}

/// Figures of the bake worth keeping with the asset.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BakeStats {
    pub triangles: u64,
    pub degenerate_triangles_skipped: u64,
    pub rays: u64,
    pub ray_hits: u64,
    pub backface_hits: u64,
    /// Surfels before merging (one per ray hit).
    pub surfels_unmerged: u64,
}

/// Probe flag: the probe is valid (not inside geometry).
pub const PROBE_VALID: u32 = 1;
/// Probe flag: the probe was inside geometry at its grid position and was moved out of it
/// (virtual offset), or lay on a surface and was moved off it; `Probe::position` is where its
/// rays start (and where visibility-aware sampling measures distances from), its texel stays at
/// the grid position.
pub const PROBE_OFFSET: u32 = 2;
/// Probe flag (with [`PROBE_VALID`]): the probe is inside geometry and was *dilated*: it reads
/// the factor table of its nearest valid neighbour (its `first_factor..+factor_count` are the
/// neighbour's, whose u8 factors are all full so that they decode the same from here; since
/// format 12, no copy), and its sky mask and sky transfer are copies of the neighbour's, so a
/// surface whose eight surrounding probes are all inside geometry still gets light. It keeps
/// its own visibility map, which sees the geometry around it at short range: visibility-aware
/// sampling therefore weights it down wherever a real probe sees the point.
pub const PROBE_DILATED: u32 = 4;
/// Probe flag (without [`PROBE_VALID`], on a grid point without data): a sparse bake did not
/// trace this point, and the runtime *fills* it after every gather with the trilinear
/// interpolation of the coarse level around it ([`crate::tier`]), the level in the flags' bits
/// from [`FILL_LEVEL_SHIFT`] ([`Probe::fill_level`]); lookups weigh it 1, like a valid probe,
/// and, having no visibility map, by its facing term alone.
pub const PROBE_FILLED: u32 = 8;
/// Where a filled probe's level ([`crate::tier`], 1..=[`crate::tier::LEVELS`]) sits in its
/// flags: four bits.
pub const FILL_LEVEL_SHIFT: u32 = 8;
/// The bits of a filled probe's level, after shifting by [`FILL_LEVEL_SHIFT`].
pub const FILL_LEVEL_MASK: u32 = 0xf;
/// Where a filled probe's *hidden corners* sit in its flags ([`Probe::fill_hidden`]): bit `c`
/// set when a wall stands between the point and corner `c` of its level's cell
/// ([`crate::tier::corners`]' order), which its fill then leaves out. Sparse placement fills
/// only points no surface separates from their corners (none hidden); the bake's refine stage
/// also fills probes it traced beside surfaces where the level's points predict them
/// (`prt_bake::refine`), and traces which corners they see.
pub const FILL_HIDDEN_SHIFT: u32 = 16;
/// The bits of a filled probe's hidden corners, after shifting by [`FILL_HIDDEN_SHIFT`].
pub const FILL_HIDDEN_MASK: u32 = 0xff;
/// Side of the octahedral visibility map.
pub const DEPTH_MAP_SIDE: u32 = 16;
/// Texels of a visibility map (a byte each: mean and standard deviation of distance, four bits
/// each; `crate::depth::quantise`).
pub const DEPTH_TEXELS: usize = (DEPTH_MAP_SIDE * DEPTH_MAP_SIDE) as usize;
/// Words of visibility data per probe (four texels per word): 256 bytes.
pub const DEPTH_WORDS: usize = DEPTH_TEXELS / 4;

/// [`Probe::slot`] of a grid point the bake placed no probe at.
pub const NO_SLOT: u32 = u32::MAX;

/// A probe: where it is, whether it may be used, where its factor table starts, and where its
/// sky and visibility data sit.
///
/// Every grid point has a record. A bake with sparse placement (`prt_bake::placement`) traces
/// only the points surfaces need and leaves the others out; those, and probes inside geometry
/// with no valid neighbour to copy, have no data: [`NO_SLOT`], not valid, no factors, no sky or
/// visibility data, never gathered, and weighted 0 by every lookup, except the points the
/// coarse levels fill ([`PROBE_FILLED`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct Probe {
    /// Where the probe's rays start: its grid position, unless [`PROBE_OFFSET`] is set.
    pub position: [f32; 3],
    /// [`PROBE_VALID`], [`PROBE_OFFSET`], [`PROBE_DILATED`], [`PROBE_FILLED`].
    pub flags: u32,
    /// Its factor table in [`Asset::factors`] (in slots for u8 tables: a factor takes one or
    /// two, [`crate::FactorSlot`]); a dilated probe's is its source's ([`PROBE_DILATED`]).
    pub first_factor: u32,
    pub factor_count: u32,
    /// Rays that escaped to the sky (their solid angle is `4pi * sky_rays / N`).
    pub sky_rays: u32,
    /// The probe's index among the probes with data, in grid order: where its sky mask, sky
    /// transfer and visibility map sit in their sections; [`NO_SLOT`] for a probe without.
    pub slot: u32,
}
const _: () = assert!(std::mem::size_of::<Probe>() == 32);

impl Probe {
    /// Gathered and sampled: a real probe or a dilated one.
    pub fn is_valid(&self) -> bool {
        self.flags & PROBE_VALID != 0
    }

    /// Has data: a slot ([`Probe::slot`]) in the per-probe sections.
    pub fn has_data(&self) -> bool {
        self.slot != NO_SLOT
    }

    /// Inside geometry, reading a neighbour's table ([`PROBE_DILATED`]).
    pub fn is_dilated(&self) -> bool {
        self.flags & PROBE_DILATED != 0
    }

    /// Filled from a coarse level at runtime ([`PROBE_FILLED`]).
    pub fn is_filled(&self) -> bool {
        self.flags & PROBE_FILLED != 0
    }

    /// The corners of its level's cell a filled probe leaves out ([`FILL_HIDDEN_SHIFT`]).
    pub fn fill_hidden(&self) -> u32 {
        self.flags >> FILL_HIDDEN_SHIFT & FILL_HIDDEN_MASK
    }

    /// The level a filled probe is interpolated from ([`FILL_LEVEL_SHIFT`]).
    pub fn fill_level(&self) -> u32 {
        self.flags >> FILL_LEVEL_SHIFT & FILL_LEVEL_MASK
    }

    /// Weight of the probe when the volume is sampled: 1 for a valid (or dilated) probe and a
    /// filled grid point, 0 for an invalid one.
    pub fn sample_weight(&self) -> f32 {
        if self.is_valid() || self.is_filled() {
            1.0
        } else {
            0.0
        }
    }
}

/// Brick flag: the brick holds back-face hits of single-sided surfaces, which are black
/// (docs/conventions.md section 4); relighting skips it.
pub const BRICK_BACKFACE: u32 = 1 << 3;
/// Mask of the dominant normal axis in `Brick::flags`: 0..6 for +X, -X, +Y, -Y, +Z, -Z.
pub const BRICK_AXIS_MASK: u32 = 0x7;

/// A brick: 4x4x4 surfel cells of one world cell and one dominant normal axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct Brick {
    /// Bounds of its surfels' positions (for light culling by range and cone).
    pub min: [f32; 3],
    pub first_surfel: u32,
    pub max: [f32; 3],
    pub surfel_count: u32,
    /// Weighted mean position of its surfels: the point its mean radiance stands for.
    pub centroid: [f32; 3],
    /// Axis (see [`BRICK_AXIS_MASK`]) and [`BRICK_BACKFACE`].
    pub flags: u32,
}
const _: () = assert!(std::mem::size_of::<Brick>() == 48);

/// A surfel: a sample of a lit surface that probe rays hit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct Surfel {
    pub position: [f32; 3],
    /// Brick this surfel belongs to.
    pub brick: u32,
    /// Unit geometric normal, turned towards the rays that hit it.
    pub normal: [f32; 3],
    /// Number of ray hits merged into it: its weight in the brick's mean radiance.
    pub weight: f32,
    /// Diffuse albedo (linear RGB).
    pub albedo: [f32; 3],
    /// [`BRICK_BACKFACE`] when it is a back-face hit of a single-sided surface.
    pub flags: u32,
    /// Emitted radiance (linear RGB).
    pub emission: [f32; 3],
    pub _pad0: u32,
    /// Gradient weight: the brick's radiance gradient is `sum_s gradient_s * L_s` (per colour
    /// channel), the weighted least-squares fit of a linear radiance model over the brick's
    /// surfels, precomputed because it depends only on their positions and weights.
    pub gradient: [f32; 3],
    pub _pad1: u32,
}
const _: () = assert!(std::mem::size_of::<Surfel>() == 80);

/// Scene geometry for visibility tests: triangles in BVH order and a binary BVH over them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Geometry {
    pub nodes: Vec<BvhNode>,
    pub triangles: Vec<Triangle>,
}

impl Geometry {
    /// Stack entries a depth-first traversal needs: the BVH's depth plus one (nodes are numbered
    /// with children after parents, so one pass gives every depth).
    pub fn stack_needed(&self) -> usize {
        if self.nodes.is_empty() {
            return 0;
        }
        let mut depth = vec![0u32; self.nodes.len()];
        let mut deepest = 0;
        for (i, n) in self.nodes.iter().enumerate() {
            deepest = deepest.max(depth[i]);
            if n.count == 0 {
                let next = depth[i] + 1;
                for child in [n.first as usize, n.first as usize + 1] {
                    if let Some(d) = depth.get_mut(child) {
                        *d = next;
                    }
                }
            }
        }
        deepest as usize + 1
    }
}

/// Barycentric tolerance of every ray/triangle test against the asset's geometry (bake tracer,
/// CPU and GPU shadow rays): a hit counts when each barycentric coordinate is at least
/// `-EDGE_TOLERANCE`. Exact tests let rays aimed at an edge shared by two triangles pass between
/// them when both round it outside; the tolerance is relative (barycentrics have no unit), so it
/// means the same at every scene scale. It widens each triangle by a millionth of its size.
pub const EDGE_TOLERANCE: f32 = 1e-6;

/// A BVH2 node. `count > 0`: a leaf holding triangles `first..first+count`. `count == 0`: an
/// inner node whose children are nodes `first` and `first + 1`. Node 0 is the root.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct BvhNode {
    pub min: [f32; 3],
    pub count: u32,
    pub max: [f32; 3],
    pub first: u32,
}
const _: () = assert!(std::mem::size_of::<BvhNode>() == 32);

/// A triangle's three vertices, padded to 16-byte rows for WGSL storage buffers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct Triangle {
    pub v0: [f32; 3],
    pub _pad0: u32,
    pub v1: [f32; 3],
    pub _pad1: u32,
    pub v2: [f32; 3],
    pub _pad2: u32,
}
const _: () = assert!(std::mem::size_of::<Triangle>() == 48);

/// Per brick of `bricks`, the run of bricks it shares its key with: `(first, end)`, the
/// consecutive front-face bricks whose centroids lie under one key with one normal axis.
/// The bake splits a brick where a wall stands on it into parts that keep its key, one
/// after another (format 13); the table names the first, whose cells name any part's
/// surfels (counted from the first's first surfel) and whose near groups a surfel's
/// [`crate::surface::SurfelTerms::group`] counts from.
pub fn surface_key_runs(terms: &SurfaceTerms, bricks: &[Brick]) -> Vec<(u32, u32)> {
    let key = |b: &Brick| {
        (b.flags & BRICK_BACKFACE == 0)
            .then(|| (terms.key_of(b.centroid), b.flags & BRICK_AXIS_MASK))
    };
    let keys: Vec<_> = bricks.iter().map(key).collect();
    let mut runs = vec![(0u32, 0u32); bricks.len()];
    let mut first = 0;
    for b in 0..bricks.len() {
        if b == 0 || keys[b].is_none() || keys[b] != keys[b - 1] {
            first = b;
        }
        runs[b].0 = first as u32;
    }
    let mut end = bricks.len();
    for b in (0..bricks.len()).rev() {
        if b + 1 == bricks.len() || keys[b].is_none() || keys[b] != keys[b + 1] {
            end = b + 1;
        }
        runs[b].1 = end as u32;
    }
    runs
}
