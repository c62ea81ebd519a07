//! The lookups `prt-bench surface` compares: named `LookupSettings`, picked with `--lookup`, so
//! that a new lookup variant is measured on every case by adding one line to [`LOOKUPS`].

use anyhow::{bail, Result};
use prt_runtime::LookupSettings;

use super::cases::Set;

/// A lookup's name and how to make its settings.
type Variant = (&'static str, fn() -> LookupSettings);

/// Every lookup `--lookup` knows, by name, in table order.
const LOOKUPS: [Variant; 2] = [
    // Hardware trilinear over the probes' validity only: what depth moments are measured against.
    ("trilinear", || LookupSettings {
        depth_moments: false,
        ..LookupSettings::default()
    }),
    // The runtime's: depth moments (DDGI's Chebyshev test), normal bias 0.2 spacings.
    ("default", LookupSettings::default),
];

/// A named lookup.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lookup {
    pub name: &'static str,
    pub settings: LookupSettings,
}

impl Lookup {
    /// What the report says the lookup is.
    pub fn describe(&self) -> String {
        let s = &self.settings;
        format!(
            "{}: {}, normal bias {} spacings",
            self.name,
            if s.depth_moments {
                "depth moments (Chebyshev) and facing weights"
            } else {
                "trilinear over probe validity"
            },
            s.normal_bias
        )
    }
}

/// The lookups of a run: `--lookup`'s, or each case's defaults.
pub struct Lookups {
    chosen: Option<Vec<Lookup>>,
    normal_bias: Option<f32>,
}

impl Lookups {
    /// `names` (none: each case's defaults), each lookup's normal bias replaced by `normal_bias`
    /// (probe spacings) when given.
    pub fn parse(names: &[String], normal_bias: Option<f32>) -> Result<Lookups> {
        let chosen = match names {
            [] => None,
            _ => Some(names.iter().map(|n| by_name(n)).collect::<Result<_>>()?),
        };
        Ok(Lookups {
            chosen,
            normal_bias,
        })
    }

    /// The lookups of a case of `set`. Without `--lookup`: the bundled cases keep the two rows
    /// of the earlier tables (trilinear against the default), the levels the default only.
    pub fn for_set(&self, set: Set) -> Vec<Lookup> {
        let lookups = match &self.chosen {
            Some(chosen) => chosen.clone(),
            None => {
                let names: &[&str] = match set {
                    Set::Bundled => &["trilinear", "default"],
                    _ => &["default"],
                };
                let picked = LOOKUPS.iter().filter(|(n, _)| names.contains(n));
                picked.map(lookup).collect()
            }
        };
        lookups
            .into_iter()
            .map(|mut l| {
                if let Some(bias) = self.normal_bias {
                    l.settings.normal_bias = bias;
                }
                l
            })
            .collect()
    }
}

fn lookup(&(name, settings): &Variant) -> Lookup {
    Lookup {
        name,
        settings: settings(),
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
    fn defaults_per_set_and_the_bias_override() {
        let none = Lookups::parse(&[], None).unwrap();
        let names = |ls: Vec<Lookup>| ls.iter().map(|l| l.name).collect::<Vec<_>>();
        assert_eq!(names(none.for_set(Set::Bundled)), ["trilinear", "default"]);
        assert_eq!(names(none.for_set(Set::HeldOut)), ["default"]);
        assert_eq!(
            none.for_set(Set::Tuning)[0].settings,
            LookupSettings::default()
        );
        let picked = Lookups::parse(&["trilinear".into()], Some(0.1)).unwrap();
        let l = picked.for_set(Set::Tuning);
        assert_eq!((l[0].name, l[0].settings.normal_bias), ("trilinear", 0.1));
        assert!(!l[0].settings.depth_moments);
        let err = Lookups::parse(&["moments".into()], None).err().unwrap();
        assert!(
            err.to_string().contains("known: trilinear, default"),
            "{err}"
        );
    }
}
