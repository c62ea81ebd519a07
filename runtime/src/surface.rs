//! # The surface lookup: probe visibility and near field from the bake's surfel terms
//!
//! [`crate::sample::VolumeSampler`] interpolates the eight probes around a point, weighted by
//! what their depth moments guess about visibility. On levels with hard sun and thin occluders
//! that guess leaks: probes a spacing away see past a gallery's floor, a balcony, a thin
//! wall between layers (issue 31, `docs/surfaces.md`). [`SurfaceSampler`] reads instead what
//! the bake traced at the point's surfel (`prt_format::surface`):
//!
//! 1. **Find the surfel**: the point's brick by key (brick lattice cell, the normal's dominant
//!    axis) in the hash table, then the surfel named for the point's cell of that brick, or the
//!    surfel on the point's side of a wall that crosses that surfel's cell (format 18). No
//!    entry (a surface the probes never saw, an asset baked without merging, a normal at 45
//!    degrees whose axis differs from the surfel's): the default lookup.
//! 2. **Weight the probes** trilinearly, a probe the surfel cannot see by
//!    `prt_format::surface::BLOCKED_WEIGHT` (no depth moments: the mask is exact). A surfel
//!    that sees none of them leaves the weights to the default lookup (its near field still
//!    applies).
//! 3. **Near field**: scale the irradiance, per colour channel, by
//!    `(clamp(open . L, 0, A(n) . L) + hits / rays * near_G) / (A(n) . L)`, `L` the
//!    interpolated radiance SH, `A` the cosine transfer of the surfel's normal, `near_G` the
//!    mean radiance per near hit of the surfel's near group (the surfels of its brick that see
//!    the same probes; [`near_radiance`], one value per group per relight). The clamp holds
//!    the escaping rays to what every direction of the hemisphere brings: with radiance that
//!    is nowhere negative they cannot bring more, but L2's ringing (a bright lobe the near
//!    field blocks, a sunlit court behind a parapet, spreads a third of its peak to the
//!    opposite side) can. It has no constant to tune; [`scale_by_near_field`] says what it
//!    measured.
//! 4. **Floor under L2's ringing**: `F - E` where that is more than the irradiance `E`, `F`
//!    being [`LookupSettings::ringing_floor`] (0.15) times the escaping share of the
//!    non-linear L1 model's irradiance (`prt_format::sh::irradiance_l1_nonlinear`;
//!    [`floor_ringing`]): a bright lobe behind the surface (a dark room's probes looking
//!    through the door) rings L2 below 0 over it.
//! 5. **Sky**: add `pi * sky * L_sky` (clamped at 0), `sky` the surfel's sky term
//!    (`prt_format::surface::sky_term`: the sky it sees less the sky its probes bring it,
//!    `prt_bake::sky_terms`), `L_sky` the sky's mean radiance.
//!
//! The figures that chose it (the family's tuning seeds, and the held-out seeds it was then
//! scored on) are in `docs/results/surface.md` (`prt-bench surface --lookup default`, every
//! lookup at stop 49); today's default in `docs/results/surface_clamp.md` (stop 52).

use prt_format::sh::{ShRgb, SH_COUNT};
use prt_format::surface::{dominant_axis, near_entry, sky_term, SurfaceTerms, BLOCKED_WEIGHT};
use prt_format::Asset;
use rayon::prelude::*;

use crate::sample::{Sample, VolumeSampler};
use crate::settings::LookupSettings;

/// Per near group, the mean radiance its surfels' near-field hits bring (the entries'
/// weighted [`group_radiance`]).
pub fn near_radiance(terms: &SurfaceTerms, group_radiance: &[[f32; 3]]) -> Vec<[f32; 3]> {
    terms
        .near_ranges
        .par_iter()
        .map(|&[first, count]| {
            let mut sum = [0.0f32; 3];
            for &e in &terms.near[first as usize..(first + count) as usize] {
                let (g, w) = near_entry(e);
                let l = group_radiance[g as usize];
                (0..3).for_each(|c| sum[c] += w * l[c]);
            }
            sum
        })
        .collect()
}

/// Per near group, the weighted mean of its surfels' radiance `radiance` (per surfel,
/// `crate::Relit::surfel_radiance`): a brick's mean, side by side.
pub fn group_radiance(asset: &Asset, radiance: &[[f32; 3]]) -> Vec<[f32; 3]> {
    asset
        .surface
        .group_surfels
        .par_iter()
        .map(|&[first, count]| {
            let range = first as usize..(first + count) as usize;
            let (mut sum, mut weight) = ([0.0f32; 3], 0.0f32);
            for (s, l) in asset.surfels[range.clone()].iter().zip(&radiance[range]) {
                for c in 0..3 {
                    sum[c] += s.weight * l[c];
                }
                weight += s.weight;
            }
            sum.map(|v| v / weight)
        })
        .collect()
}

/// Scales `sample`'s irradiance, per colour channel, by its near field
/// `(clamp(open . L, 0, all . L) + near) / (all . L)`, `L` the sample's SH, `open` and `all`
/// the SH transfer of the near-field rays that escape and of all of them, `near` the radiance
/// the others bring (in the same normalisation), clamped at 0; a channel whose `all . L` is
/// not positive stays as it is.
///
/// The clamp of `open . L` (issue 31, stop 52; `prt-bench surface --lookup default`) cut the
/// levels' leaks where a sunlit court lay behind a parapet or a shell: unseen seeds 24-31,
/// worst leaks 1.0% -> 0.3% and over-lit pixels 3.3% -> 2.6%; the fixtures' two rooms 4.74% ->
/// 4.03% and thick walls 2.98% -> 2.74%; Sponza's and Cornell's means within 0.01 point
/// (docs/results/surface_candidates.md, stop 52).
pub fn scale_by_near_field(
    sample: &mut Sample,
    open: &[f32; SH_COUNT],
    all: &[f32; SH_COUNT],
    near: [f32; 3],
) {
    let (open, all) = (light(&sample.sh, open), light(&sample.sh, all));
    for (ch, e) in sample.irradiance.iter_mut().enumerate() {
        let total = all[ch];
        if total > 0.0 {
            let escaping = open[ch].max(0.0).min(total);
            *e *= ((escaping + near[ch]) / total).max(0.0);
        }
    }
}

/// The lookup's floor under L2's ringing: raises `sample`'s irradiance `E`, per colour
/// channel, to `F - E` where that is more, `F` being `floor` times what the non-linear L1
/// model of its SH gives on `normal` (`prt_format::sh::irradiance_l1_nonlinear`; `floor` is
/// `LookupSettings::ringing_floor` times the share of the surfel's near-field rays that
/// escape). A bright lobe behind the surface (a dark room's probes looking through its door at
/// the lit room) rings L2 below 0 over the surface's hemisphere, which then reads 0 or a
/// fraction of its truth; the L1 model keeps the light's mean and is never negative. Only the
/// escaping rays read the probes' SH (the others bring their near group's relit radiance,
/// which does not ring), hence their share; a surfel whose rays all hit gets no floor.
///
/// The floor fades as L2 rises: `F` where L2 reads 0, nothing from `F / 2` up (in between
/// `F - E`, which falls to `F / 2`: beside a hotspot, a ring darker than either side,
/// docs/limits.md). L2 that reads above 0 is not ringing over the whole hemisphere, and the
/// L1 model also gives the back of a real lobe (a hotspot on the surface's own plane) a share
/// of its mean: stop 70's plain `max(E, F)` lifted the Cornell room's ceiling point over its
/// light 3.3% -> 36.2% off its truth, and moved three of the tuning seeds' figures. This one lifts the same zeros of stop
/// 69's blind interior_220 and leaves the tuning seeds and the Cornell room as without a floor
/// (docs/results/surface_stop71.md). Returns `F` per channel (0 where `floor` is not positive).
pub fn floor_ringing(sample: &mut Sample, normal: [f32; 3], floor: f32) -> [f32; 3] {
    if floor <= 0.0 {
        return [0.0; 3];
    }
    let l1 = prt_format::sh::irradiance_l1_nonlinear(&sample.sh, normal).map(|l| floor * l);
    for (e, l1) in sample.irradiance.iter_mut().zip(l1) {
        *e = e.max(l1 - *e);
    }
    l1
}

/// What [`SurfaceSampler`]'s near-field and floor steps used and gave, for [`SurfelStep`]:
/// the surfel's escaping-ray and cosine transfers, what its near field's hits bring, the
/// irradiance before the floor and the floor.
struct NearFieldStep {
    open: [f32; SH_COUNT],
    all: [f32; SH_COUNT],
    near: [f32; 3],
    before_floor: [f32; 3],
    ringing_floor: [f32; 3],
}

/// `t . L` per colour channel: the light SH radiance `sh` brings through SH transfer `t`.
fn light(sh: &ShRgb, t: &[f32; SH_COUNT]) -> [f32; 3] {
    std::array::from_fn(|ch| (0..SH_COUNT).map(|k| sh[k][ch] * t[k]).sum::<f32>())
}

/// How the surface lookup read one point ([`SurfaceSampler::explain`], `prt sample --explain`):
/// the surfel whose terms stood for it, the probes it weighted, and what the near field and the
/// sky term did to their irradiance. A point lit wrong (a leak, a dark patch) is diagnosed
/// from it: a probe it should not see, a near field that blocks too much, a sky term too small.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Explanation {
    /// The surfel, or `None`: the probe volume's lookup (depth moments) alone.
    pub surfel: Option<SurfelStep>,
    /// The probes around the point with a positive trilinear and probe weight (with a surfel,
    /// around the point moved by the surface bias, even where the surfel sees none of them and
    /// the volume's lookup reads the corners of its own bias).
    pub probes: Vec<ProbeStep>,
    /// The probes' weighted irradiance on the point's normal, before the near field and sky.
    pub probes_irradiance: [f32; 3],
    /// What [`SurfaceSampler::sample`] returns.
    pub sample: Sample,
}

/// The surfel step of an [`Explanation`]; irradiance-like values per colour channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfelStep {
    /// Asset index of the surfel.
    pub index: usize,
    /// Asset index of its brick (a split brick's first part: the one the table names).
    pub brick: usize,
    /// Where it lies.
    pub position: [f32; 3],
    /// Its normal as its terms store it.
    pub normal: [f32; 3],
    /// The cosine between [`Self::normal`] and the point's normal: a point whose normal is far
    /// from it is read with a near field traced for another surface.
    pub agreement: f32,
    /// False where it sees none of the probes: the probes are then weighted by their depth
    /// moments instead.
    pub sees_a_probe: bool,
    /// Its near-field rays that hit a surface within reach.
    pub near_hits: u32,
    /// All its near-field rays.
    pub near_rays: u32,
    /// `open . L` ([`scale_by_near_field`]): the probes' light through its escaping rays, as
    /// the SH gives it; the lookup clamps it to `[0, hemisphere]` (L2 ringing can put it
    /// outside).
    pub escaping: [f32; 3],
    /// `A(n) . L`: the probes' light through its whole hemisphere.
    pub hemisphere: [f32; 3],
    /// What the near field's hits bring (hits / rays times its group's radiance per hit).
    pub near: [f32; 3],
    /// The floor under L2's ringing ([`floor_ringing`]) `F`: `LookupSettings::ringing_floor`
    /// times the escaping share times the non-linear L1 model's irradiance.
    pub ringing_floor: [f32; 3],
    /// The irradiance after the near field, before the ringing floor (`E`).
    pub before_floor: [f32; 3],
    /// The irradiance after the near field and the ringing floor (`max(E, F - E)`), before the
    /// sky term.
    pub near_field_irradiance: [f32; 3],
    /// Its sky term (`prt_format::surface::sky_term`); the lookup adds `pi * sky_term *` the
    /// sky's mean radiance where the sky terms are on.
    pub sky_term: f32,
}

/// A probe of an [`Explanation`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProbeStep {
    /// Grid index.
    pub index: usize,
    /// Where its rays started.
    pub position: [f32; 3],
    /// Whether the surfel sees it (`None`: no surfel, the volume lookup).
    pub seen: Option<bool>,
    /// Its own irradiance on the point's normal.
    pub irradiance: [f32; 3],
}

/// The surface lookup of an asset relit to probe SH `sh` and brick radiance `bricks`.
pub struct SurfaceSampler<'a> {
    asset: &'a Asset,
    sh: &'a [ShRgb],
    trilinear: VolumeSampler<'a>,
    fallback: VolumeSampler<'a>,
    near: Vec<[f32; 3]>,
    /// pi times the sky's mean radiance: what a sky term of 1 adds.
    sky: [f32; 3],
    /// `LookupSettings::surface_terms`.
    enabled: bool,
    /// `LookupSettings::ringing_floor` ([`floor_ringing`]).
    ringing_floor: f32,
}

impl<'a> SurfaceSampler<'a> {
    /// The lookup of `asset` relit to `sh` (per probe) and surfel radiance `radiance`
    /// (`crate::Relit::surfel_radiance`) under a sky of mean radiance `sky`
    /// (`crate::Relit::sky`); the trilinear weights take `lookup`'s surface bias, and the
    /// fallback is `lookup` itself.
    pub fn new(
        asset: &'a Asset,
        sh: &'a [ShRgb],
        radiance: &[[f32; 3]],
        sky: [f32; 3],
        lookup: &LookupSettings,
    ) -> Self {
        let trilinear = LookupSettings {
            depth_moments: false,
            normal_bias: lookup.surface_bias,
            ..*lookup
        };
        SurfaceSampler {
            asset,
            sh,
            trilinear: VolumeSampler::for_asset(asset, sh, &trilinear),
            fallback: VolumeSampler::for_asset(asset, sh, lookup),
            near: near_radiance(&asset.surface, &group_radiance(asset, radiance)),
            sky: match lookup.sky_terms {
                true => sky.map(|l| std::f32::consts::PI * l),
                false => [0.0; 3],
            },
            enabled: lookup.surface_terms,
            ringing_floor: lookup.ringing_floor,
        }
    }

    /// The lookup of `asset` as the CPU relight `relit` left it ([`Self::new`] with its SH,
    /// surfel radiance and sky).
    pub fn for_relit(asset: &'a Asset, relit: &'a crate::Relit, lookup: &LookupSettings) -> Self {
        Self::new(asset, &relit.sh, &relit.surfel_radiance, relit.sky, lookup)
    }

    /// The sample at `position` for a surface with unit normal `normal`.
    pub fn sample(&self, position: [f32; 3], normal: [f32; 3]) -> Sample {
        self.lookup::<false>(position, normal).sample
    }

    /// [`Self::sample`] and how it was made: both come from one [`Self::lookup`], so they
    /// cannot differ.
    pub fn explain(&self, position: [f32; 3], normal: [f32; 3]) -> Explanation {
        self.lookup::<true>(position, normal)
    }

    /// The sample and, with `EXPLAIN`, how it was made (the probes as the lookup weighs them,
    /// in the same pass, and the surfel step). Without `EXPLAIN` only the sample and
    /// `probes_irradiance` are filled and nothing else is computed: the relight's bounces
    /// sample every surfel.
    fn lookup<const EXPLAIN: bool>(&self, position: [f32; 3], normal: [f32; 3]) -> Explanation {
        let probes = std::cell::RefCell::new(Vec::new());
        let record = |i: usize, at: glam::Vec3, seen: Option<bool>| {
            if EXPLAIN {
                probes.borrow_mut().push(ProbeStep {
                    index: i,
                    position: at.to_array(),
                    seen,
                    irradiance: prt_format::sh::irradiance(&self.sh[i], normal),
                });
            }
        };
        let Some((brick, surfel)) = self.surfel_of(position, normal) else {
            let sample = self.fallback.sample_weighted(position, normal, |i, at| {
                record(i, at, None);
                1.0
            });
            return Explanation {
                surfel: None,
                probes: probes.into_inner(),
                probes_irradiance: sample.irradiance,
                sample,
            };
        };
        let st = &self.asset.surface;
        let terms = &st.surfels[surfel];
        let grid = &self.asset.header.grid;
        let centre = st.brick_centre(grid, &self.asset.bricks[brick]);
        let seen = std::cell::Cell::new(false);
        let mut out = self.trilinear.sample_weighted(position, normal, |i, at| {
            let visible = terms.sees(centre, grid, i);
            record(i, at, Some(visible));
            seen.set(seen.get() || visible);
            if visible {
                1.0
            } else {
                BLOCKED_WEIGHT
            }
        });
        if !seen.get() {
            // The volume's lookup weighs the corners of the point moved by its own normal bias,
            // which may be others than those listed (`Explanation::probes`).
            out = self.fallback.sample(position, normal);
        }
        let probes_irradiance = out.irradiance;
        let field = self.near_field(&mut out, brick, surfel, normal);
        let near_field_irradiance = out.irradiance;
        self.add_sky(&mut out, surfel);
        let step = EXPLAIN.then(|| {
            let stored = terms.normal();
            SurfelStep {
                index: surfel,
                brick,
                position: self.asset.surfels[surfel].position,
                normal: stored,
                agreement: (0..3).map(|a| stored[a] * normal[a]).sum(),
                sees_a_probe: seen.get(),
                near_hits: terms.hits(),
                near_rays: st.header.rays,
                escaping: light(&out.sh, &field.open),
                hemisphere: light(&out.sh, &field.all),
                near: field.near,
                ringing_floor: field.ringing_floor,
                before_floor: field.before_floor,
                near_field_irradiance,
                sky_term: sky_term(&self.asset.surface.sky, surfel),
            }
        });
        Explanation {
            surfel: step,
            probes: probes.into_inner(),
            probes_irradiance,
            sample: out,
        }
    }

    /// Steps 3 and 4 of the module docs on `out`, `surfel`'s sample: scales it by the near
    /// field, then floors it under L2's ringing. Returns what the explanation reports of them.
    fn near_field(
        &self,
        out: &mut Sample,
        brick: usize,
        surfel: usize,
        normal: [f32; 3],
    ) -> NearFieldStep {
        let st = &self.asset.surface;
        let terms = &st.surfels[surfel];
        let (open, all) = terms.open_and_cosine(st.header.rays);
        let share = terms.hits() as f32 / st.header.rays as f32;
        let group = st.groups[brick] + terms.group();
        let near = self.near[group as usize].map(|l| share * l);
        scale_by_near_field(out, &open, &all, near);
        let escaping = terms.escaping_share(st.header.rays);
        let before_floor = out.irradiance;
        let ringing_floor = floor_ringing(out, normal, self.ringing_floor * escaping);
        NearFieldStep {
            open,
            all,
            near,
            before_floor,
            ringing_floor,
        }
    }

    /// Adds the surfel's sky term times pi times the sky's mean radiance (clamped at 0; step
    /// 5 of the module docs).
    fn add_sky(&self, out: &mut Sample, surfel: usize) {
        if self.sky != [0.0; 3] {
            let sky = sky_term(&self.asset.surface.sky, surfel);
            for (e, l) in out.irradiance.iter_mut().zip(self.sky) {
                *e = (*e + sky * l).max(0.0);
            }
        }
    }

    /// The surfel (asset index) whose terms stand for the point, if any: where it is `None`,
    /// [`Self::sample`] is the probe volume's lookup.
    pub fn surfel(&self, position: [f32; 3], normal: [f32; 3]) -> Option<usize> {
        self.surfel_of(position, normal).map(|(_, s)| s)
    }

    /// The brick the table found (a split brick's first part) and the surfel (asset indices)
    /// whose terms stand for the point, if any: the one the cell table names, or its partner
    /// beyond a wall in its cell (`SurfaceTerms::side_of`, format 18). The surfel's near group
    /// is the brick's `groups` entry plus its `group` (format 13: counted from the first
    /// part's groups).
    pub fn surfel_of(&self, position: [f32; 3], normal: [f32; 3]) -> Option<(usize, usize)> {
        let t = &self.asset.surface;
        if !self.enabled || t.is_empty() {
            return None;
        }
        let key = t.key_of(position);
        let brick = t.find(key, dominant_axis(normal))?;
        let within = t.surfel_in(brick, key, position)?;
        let named = self.asset.bricks[brick as usize].first_surfel + within;
        let surfel = t.side_of(named, key, position) as usize;
        t.surfels[surfel]
            .is_traced()
            .then_some((brick as usize, surfel))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Escaping rays bring at most what the whole hemisphere does and never less than nothing
    /// (L2 ringing can put `open . L` outside both); a near field brighter than the probes'
    /// light in its directions still brightens the point.
    #[test]
    fn escaping_light_is_held_to_the_hemisphere() {
        let mut sh = [[0.0f32; 3]; SH_COUNT];
        sh[0] = [1.0, 2.0, 4.0];
        let scaled = |open_dc: f32, near: f32, all_dc: f32| {
            let mut sample = Sample {
                sh,
                irradiance: [1.0; 3],
                validity: 1.0,
            };
            let mut open = [0.0; SH_COUNT];
            open[0] = open_dc;
            let mut all = [0.0; SH_COUNT];
            all[0] = all_dc;
            scale_by_near_field(&mut sample, &open, &all, [near; 3]);
            sample.irradiance
        };
        assert_eq!(scaled(1.5, 0.0, 1.0), [1.0; 3], "more than the hemisphere");
        assert_eq!(
            scaled(-0.5, 1.0, 1.0),
            [1.0, 0.5, 0.25],
            "less than nothing"
        );
        assert_eq!(
            scaled(0.5, 1.0, 1.0),
            [1.5, 1.0, 0.75],
            "a bright near field"
        );
        assert_eq!(
            scaled(0.5, 1.0, -1.0),
            [1.0; 3],
            "no hemisphere to scale by"
        );
    }

    /// A unit light 127 degrees from a surface's normal (over a faint ambient in one channel):
    /// L2 rings below 0 there (the irradiance clamps to 0), the floor lifts it to its share of
    /// the L1 model's, and it leaves a surface facing the light, which L2 lights more. On a
    /// surface the light reaches at 37 degrees the floor fades: L2 stands over half the floor
    /// and reads `F - E` under it.
    #[test]
    fn the_floor_lifts_ringing_and_nothing_else() {
        let mut sh = [[0.0f32; 3]; SH_COUNT];
        let ambient = prt_format::sh::constant([0.005; 3]);
        prt_format::sh::accumulate(&mut sh, [0.0, 0.0, -1.0], 1.0, [1.0, 1.0, 0.0]);
        (0..SH_COUNT).for_each(|k| sh[k][0] += ambient[k][0]);
        let floored = |n: [f32; 3], floor: f32| {
            let mut s = Sample {
                sh,
                irradiance: prt_format::sh::irradiance(&sh, n),
                validity: 1.0,
            };
            let f = floor_ringing(&mut s, n, floor);
            (s.irradiance, f)
        };
        let sample = |n: [f32; 3], floor: f32| floored(n, floor).0;
        let side = [0.0, 0.8, 0.6];
        assert_eq!(sample(side, 0.0)[0], 0.0, "L2 rings below 0 here");
        let l1 = prt_format::sh::irradiance_l1_nonlinear(&sh, side)[0];
        assert!(l1 > 0.0);
        assert_eq!(sample(side, 0.5)[0], 0.5 * l1);
        assert_eq!(sample(side, 0.5)[2], 0.0, "a channel without light");
        let facing = [0.0, 0.0, -1.0];
        assert_eq!(
            sample(facing, 0.5),
            sample(facing, 0.0),
            "L2 stands where brighter"
        );
        // Where L2 reads more than half the floor it stands, though the floor is higher: the
        // back of a real lobe, not ringing (stop 70's max(E, F) lifted it to F).
        let slant = [0.0, 0.6, -0.8];
        let e = sample(slant, 0.0)[0];
        let l1 = prt_format::sh::irradiance_l1_nonlinear(&sh, slant)[0];
        assert!(e > 0.0 && l1 > 0.0, "{e} {l1}");
        assert_eq!(sample(slant, 1.5 * e / l1)[0], e, "faded out");
        let (low, f) = floored(slant, 4.0 * e / l1);
        assert!(f[0] > 2.0 * e, "{f:?} {e}");
        assert_eq!(low[0], f[0] - e, "F - E under half the floor");
    }
}
