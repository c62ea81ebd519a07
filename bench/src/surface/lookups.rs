//! The lookups `prt-bench surface` compares, picked with `--lookup`: named `LookupSettings` (the
//! runtime's lookups) and the reference lookups of issue 31 that trace rays
//! (`crate::ray_lookup`, `crate::surfel_lookup`). A new variant is measured on every case by
//! adding one entry to [`LOOKUPS`].

use anyhow::{bail, Result};
use prt_runtime::LookupSettings;

use super::cases::Set;
use crate::ray_lookup::RaySettings;

/// What samples the volume: the runtime's lookup with `Lookup::settings`, or a reference of
/// issue 31 that traces rays (its trilinear weights take `Lookup::settings`' normal bias; the
/// masked weights of `surfels` its surface bias, as the runtime's surface lookup).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// `prt_runtime::surface::SurfaceSampler` (the volume's `VolumeSampler` where the surface
    /// terms are off or the point has none): what `prt render` shows.
    Runtime,
    /// `crate::ray_lookup::RayLookup`: the ray terms traced from the point.
    Rays(RaySettings),
    /// `crate::surfel_lookup::SurfelLookup`: `rays_light`'s terms traced from the point's surfel.
    Surfels,
    /// `crate::path_lookup::PathLookup`: one-bounce path tracing at the point with this many
    /// rays, no probes.
    Path(u32),
    /// `crate::gather_lookup::GatherLookup`: a gather of this many rays from the point's near
    /// group, or with `per_surfel` from its surfel, hits lit by their relit bricks.
    Gather { rays: u32, per_surfel: bool },
    /// `crate::sky_point_lookup::SkyPointLookup`: the runtime's with the sky's direct share
    /// traced at the point with this many rays instead of the probes'.
    SkyPoint(u32),
}

/// A lookup's name and how to make it.
type Variant = (&'static str, fn() -> (LookupSettings, Kind));

/// The probe volume alone, depth moments or not, at the runtime's normal bias.
fn volume(depth_moments: bool) -> LookupSettings {
    LookupSettings {
        depth_moments,
        surface_terms: false,
        ..LookupSettings::default()
    }
}

/// Trilinear over the probes' validity only, at the runtime's normal bias.
fn trilinear() -> LookupSettings {
    volume(false)
}

/// Every lookup `--lookup` knows, by name, in table order.
const LOOKUPS: [Variant; 12] = [
    // Hardware trilinear over the probes' validity only: what depth moments are measured against.
    ("trilinear", || (trilinear(), Kind::Runtime)),
    // The probe volume with depth moments (DDGI's Chebyshev test), normal bias 0.2 spacings:
    // the runtime's lookup before the surface terms.
    ("moments", || (volume(true), Kind::Runtime)),
    // The runtime's: the bake's surface terms (prt_format::surface: which probes the point's
    // surfel sees, its near field) where the point has a surfel, `moments` elsewhere.
    ("default", || (LookupSettings::default(), Kind::Runtime)),
    // The same without the sky terms (format 14): the sky as the probes see it, as before
    // stop 55.
    ("no_sky", || {
        (
            LookupSettings {
                sky_terms: false,
                ..LookupSettings::default()
            },
            Kind::Runtime,
        )
    }),
    // The same with plain trilinear weights where the point has no surfel: what the depth
    // moments add once surface terms decide the probes at surfaces (docs/results/packing.md).
    ("terms_trilinear", || {
        (
            LookupSettings {
                depth_moments: false,
                ..LookupSettings::default()
            },
            Kind::Runtime,
        )
    }),
    // Rays through the asset's BVH from the point: exact probe visibility and a dark near field.
    ("rays", || (trilinear(), Kind::Rays(RaySettings::default()))),
    // The same, with near-field hits bringing their surface's relit radiance (reach 1 spacing).
    ("rays_light", || {
        (trilinear(), Kind::Rays(RaySettings::with_near_light()))
    }),
    // rays_light's terms decided per surfel, traced at lookup time (the bound the bake's
    // terms were designed against); points without a surfel fall back to `moments`.
    ("surfels", || (volume(true), Kind::Surfels)),
    // The one-bounce truth traced at the point with the rays' count, the probes left out: what
    // the benchmark itself and the probes' radiance cost (settings unused).
    ("path", || {
        (trilinear(), Kind::Path(crate::path_lookup::PATH_RAYS))
    }),
    // What a baked table per near group of the bricks its rays hit would give: no probes where
    // the point has a surfel (one gather per group, shared by its points).
    ("gather", || {
        let rays = crate::gather_lookup::GATHER_RAYS;
        (
            LookupSettings::default(),
            Kind::Gather {
                rays,
                per_surfel: false,
            },
        )
    }),
    // The same per surfel: the bound of a table that fine.
    ("surfel_gather", || {
        let rays = crate::gather_lookup::GATHER_RAYS;
        (
            LookupSettings::default(),
            Kind::Gather {
                rays,
                per_surfel: true,
            },
        )
    }),
    // The runtime's with the probes' direct view of the sky swapped for the point's own,
    // traced with 4,096 rays: what a per-surfel sky term would bring (issue 31, stop 54).
    ("sky_point", || {
        let rays = crate::sky_point_lookup::SKY_RAYS;
        let settings = LookupSettings {
            sky_terms: false,
            ..LookupSettings::default()
        };
        (settings, Kind::SkyPoint(rays))
    }),
];

/// A named lookup.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lookup {
    pub name: &'static str,
    pub settings: LookupSettings,
    pub kind: Kind,
}

impl Lookup {
    /// What the report says the lookup is.
    pub fn describe(&self) -> String {
        let s = &self.settings;
        let bias = s.normal_bias;
        match self.kind {
            Kind::SkyPoint(rays) => format!(
                "{}: the runtime's lookup with the probes' direct view of the sky replaced by \
                 the point's own ({rays} cosine rays to the sky; \
                 bench/src/sky_point_lookup.rs)",
                self.name
            ),
            Kind::Runtime if s.surface_terms => format!(
                "{}: the bake's surface terms where the point has a surfel (which probes it \
                 sees, its near field, a floor under L2's ringing of {} of the L1 model, {}; \
                 prt_runtime::surface; its probes weighed {} spacings off the surface), {} \
                 elsewhere, normal bias {bias} spacings",
                self.name,
                s.ringing_floor,
                if s.sky_terms {
                    "its sky term"
                } else {
                    "no sky term"
                },
                s.surface_bias,
                if s.depth_moments {
                    "depth moments"
                } else {
                    "trilinear over probe validity"
                }
            ),
            Kind::Runtime if s.depth_moments => format!(
                "{}: depth moments (Chebyshev) and facing weights, normal bias {bias} spacings",
                self.name
            ),
            Kind::Runtime => format!(
                "{}: trilinear over probe validity, normal bias {bias} spacings",
                self.name
            ),
            Kind::Rays(r) => format!(
                "{}: trilinear over probe validity, normal bias {bias} spacings, exact probe \
                 visibility: {}, near field: {}, near hits {} (rays through the asset's BVH \
                 from the point, bench/src/ray_lookup.rs)",
                self.name,
                r.visibility,
                r.near_field
                    .map_or("none".into(), |reach| format!("{reach} spacings")),
                if r.near_light {
                    "bring their brick's relit radiance"
                } else {
                    "are dark"
                }
            ),
            Kind::Gather { rays, per_surfel } => format!(
                "{}: {rays} cosine rays from the point's {} through the asset's BVH, hits lit \
                 by the relit brick they hit (its linear model), escapes by the sky; the \
                 runtime's lookup where the point has no surfel (bench/src/gather_lookup.rs)",
                self.name,
                if per_surfel {
                    "surfel"
                } else {
                    "surfel's near group (its centroid and mean normal)"
                }
            ),
            Kind::Path(rays) => format!(
                "{}: one-bounce path tracing at the point, no probes: {rays} cosine rays \
                 through the asset's BVH, hits lit by the rig behind shadow rays, escapes the \
                 sky's radiance (bench/src/path_lookup.rs)",
                self.name
            ),
            Kind::Surfels => format!(
                "{}: rays_light's visibility and near field decided per surfel, as a bake would \
                 store them (the point's nearest surfel of its normal's nearest brick; none: the \
                 default lookup), its probes weighed {} spacings off the surface, normal bias \
                 {bias} spacings (bench/src/surfel_lookup.rs)",
                self.name, s.surface_bias
            ),
        }
    }

    /// Whether sampling needs the probes relit with the sky alone over black surfaces.
    pub fn needs_sky(&self) -> bool {
        matches!(self.kind, Kind::SkyPoint(_))
    }

    /// Whether sampling needs the relit bricks (`crate::ray_lookup::NearLight`).
    pub fn needs_bricks(&self) -> bool {
        match self.kind {
            Kind::Runtime | Kind::SkyPoint(_) => false,
            Kind::Rays(r) => r.near_light,
            Kind::Surfels | Kind::Path(_) | Kind::Gather { .. } => true,
        }
    }
}

/// What a run changes in every lookup it samples with, where given.
#[derive(Clone, Copy, Debug, Default)]
pub struct Overrides {
    /// Each lookup's normal bias (probe spacings).
    pub normal_bias: Option<f32>,
    /// The near-field reach of the ray lookups that have one (`rays`, `rays_light`; probe
    /// spacings).
    pub reach: Option<f32>,
    /// The path lookup's rays per point, the gather lookups' rays per gather, and
    /// `sky_point`'s rays per point.
    pub path_rays: Option<u32>,
    /// The surface lookup's floor under L2's ringing (`LookupSettings::ringing_floor`).
    pub ringing_floor: Option<f32>,
}

/// The lookups of a run: `--lookup`'s, or each case's defaults.
pub struct Lookups {
    chosen: Option<Vec<Lookup>>,
    overrides: Overrides,
}

impl Lookups {
    /// `names` (none: each case's defaults), with `overrides`.
    pub fn parse(names: &[String], overrides: Overrides) -> Result<Lookups> {
        let chosen = match names {
            [] => None,
            _ => Some(names.iter().map(|n| by_name(n)).collect::<Result<_>>()?),
        };
        Ok(Lookups { chosen, overrides })
    }

    /// The lookups of a case of `set`. Without `--lookup`: the bundled cases keep the two rows
    /// of the earlier tables (trilinear against the default), and every case gets the three
    /// references of issue 31's candidates (`rays`, `rays_light`, `surfels`;
    /// `docs/results/surface_candidates.md`).
    pub fn for_set(&self, set: Set) -> Vec<Lookup> {
        let lookups = match &self.chosen {
            Some(chosen) => chosen.clone(),
            None => {
                let names: &[&str] = match set {
                    Set::Bundled => &[
                        "trilinear",
                        "moments",
                        "default",
                        "rays",
                        "rays_light",
                        "surfels",
                    ],
                    _ => &["moments", "default", "rays", "rays_light", "surfels"],
                };
                let picked = LOOKUPS.iter().filter(|(n, _)| names.contains(n));
                picked.map(lookup).collect()
            }
        };
        lookups
            .into_iter()
            .map(|mut l| {
                let o = self.overrides;
                if let Some(bias) = o.normal_bias {
                    l.settings.normal_bias = bias;
                }
                if let Some(floor) = o.ringing_floor {
                    l.settings.ringing_floor = floor;
                }
                match &mut l.kind {
                    Kind::Rays(r) if r.near_field.is_some() => {
                        r.near_field = o.reach.or(r.near_field);
                    }
                    Kind::Path(rays) | Kind::Gather { rays, .. } | Kind::SkyPoint(rays) => {
                        *rays = o.path_rays.unwrap_or(*rays)
                    }
                    _ => {}
                }
                l
            })
            .collect()
    }
}

fn lookup(&(name, make): &Variant) -> Lookup {
    let (settings, kind) = make();
    Lookup {
        name,
        settings,
        kind,
    }
}

fn by_name(name: &str) -> Result<Lookup> {
    match LOOKUPS.iter().find(|(n, _)| *n == name) {
        Some(l) => Ok(lookup(l)),
        None => {
            let known: Vec<&str> = LOOKUPS.iter().map(|(n, _)| *n).collect();
            bail!(
                "--lookup {name}: unknown lookup (known: {})",
                known.join(", ")
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_per_set_and_the_overrides() {
        let none = Lookups::parse(&[], Overrides::default()).unwrap();
        let names = |ls: Vec<Lookup>| ls.iter().map(|l| l.name).collect::<Vec<_>>();
        assert_eq!(
            names(none.for_set(Set::Bundled)),
            [
                "trilinear",
                "moments",
                "default",
                "rays",
                "rays_light",
                "surfels"
            ]
        );
        assert_eq!(
            names(none.for_set(Set::HeldOut)),
            ["moments", "default", "rays", "rays_light", "surfels"]
        );
        assert!(matches!(none.for_set(Set::HeldOut)[2].kind, Kind::Rays(_)));
        assert_eq!(
            none.for_set(Set::Tuning)[1].settings,
            LookupSettings::default()
        );
        assert!(!none.for_set(Set::Tuning)[0].settings.surface_terms);
        let overrides = Overrides {
            normal_bias: Some(0.1),
            reach: Some(2.0),
            path_rays: Some(64),
            ringing_floor: Some(0.5),
        };
        let names = ["trilinear".into(), "rays".into(), "path".into()];
        let picked = Lookups::parse(&names, overrides).unwrap();
        let l = picked.for_set(Set::Tuning);
        assert_eq!((l[0].name, l[0].settings.normal_bias), ("trilinear", 0.1));
        assert_eq!(l[0].settings.ringing_floor, 0.5);
        assert!(!l[0].settings.depth_moments);
        assert!(matches!(l[1].kind, Kind::Rays(r) if r.near_field == Some(2.0)));
        assert_eq!(l[2].kind, Kind::Path(64));
        let err = Lookups::parse(&["nearest".into()], Overrides::default())
            .err()
            .unwrap();
        assert!(
            err.to_string()
                .contains("known: trilinear, moments, default, no_sky, terms_trilinear, rays, rays_light, surfels, path, gather, surfel_gather, sky_point"),
            "{err}"
        );
    }
}
